// bare_mpm2d: the 2D yardstick beside ../shared/bench/bare_mpm3d.cpp: one explicit MPM step of
// the case of bench/throughput.py in 2D (plane strain), with nothing but the arithmetic.
// Quadratic B-splines, APIC (affine matrix C), USL, linear elastic (small strain from F), a
// padded periodic grid, particles in cell order, double precision, one thread, no MPI, no I/O.
// Case: elastic block filling a periodic unit square, 2 particles per cell per direction,
// velocity (3, 2), dt = 0.25 h / c (c the P-wave speed), E = 1e6 Pa, nu = 0.3, rho = 1500.
// Usage: bare_mpm2d CELLS STEPS  -> "bare_mpm2d: particles N steps S wall W s rate R p-steps/s ..."
// Build: g++ -O3 -march=native -std=c++17 bare_mpm2d.cpp -o bare_mpm2d
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

namespace {
struct Particle {
  double x[2], v[2], C[4], F[4], s[4]; // s: 2x2 in-plane stress (sigma_zz plays no part in the forces)
};

// Quadratic B-spline weights of one coordinate: first node b, offset fx in [0,1) of xi - 0.5.
inline void weights(double x, double inv_h, int &b, double &fx, double w[3]) {
  const double X = x * inv_h - 0.5;
  b = int(std::floor(X));
  fx = X - b;
  w[0] = 0.5 * (1 - fx) * (1 - fx);
  w[1] = 0.75 - (fx - 0.5) * (fx - 0.5);
  w[2] = 0.5 * fx * fx;
}
} // namespace

int main(int argc, char **argv) {
  const int n = argc > 1 ? std::atoi(argv[1]) : 500;
  const int steps = argc > 2 ? std::atoi(argv[2]) : 40;
  const double h = 1.0 / n, inv_h = n, E = 1e6, nu = 0.3, rho = 1500.0;
  const double mu = E / (2 * (1 + nu)), lam = E * nu / ((1 + nu) * (1 - 2 * nu));
  const double c = std::sqrt((lam + 2 * mu) / rho), dt = 0.25 * h / c;
  const int ppd = 2;
  const double vol = (h / ppd) * (h / ppd), mp = rho * vol;
  std::vector<Particle> ps;
  ps.reserve(size_t(n) * n * ppd * ppd);
  // Seeded cell by cell, so consecutive particles share their 9 nodes.
  for (int cj = 0; cj < n; ++cj)
    for (int ci = 0; ci < n; ++ci)
      for (int sj = 0; sj < ppd; ++sj)
        for (int si = 0; si < ppd; ++si) {
          Particle p{};
          p.x[0] = (ci * ppd + si + 0.5) * h / ppd;
          p.x[1] = (cj * ppd + sj + 0.5) * h / ppd;
          p.v[0] = 3;
          p.v[1] = 2;
          p.F[0] = p.F[3] = 1;
          ps.push_back(p);
        }
  // Padded grid: node i in -1..n+1 is stored at i+1 (y rows, x fastest); the periodic ghost
  // layers are folded onto their images after P2G and refilled before G2P.
  const int m = n + 3;
  const size_t nn = size_t(m) * m;
  std::vector<double> gm(nn), gv(2 * nn);
  auto at = [m](int i, int j) { return size_t(j + 1) * m + (i + 1); };
  auto src = [n](int i) { return i < 0 ? i + n : (i >= n ? i - n : i); };
  const double k4 = 4 * inv_h * inv_h; // D^-1 of quadratic B-splines
  const auto t0 = std::chrono::steady_clock::now();
  for (int s = 0; s < steps; ++s) {
    std::fill(gm.begin(), gm.end(), 0.0);
    std::fill(gv.begin(), gv.end(), 0.0);
    // P2G: mass and momentum with the APIC term, the stress folded in (MLS form).
    for (const Particle &p : ps) {
      int b[2];
      double fx[2], w[2][3];
      for (int d = 0; d < 2; ++d) weights(p.x[d], inv_h, b[d], fx[d], w[d]);
      double A[4];
      for (int q = 0; q < 4; ++q) A[q] = mp * p.C[q] - dt * vol * k4 * p.s[q];
      for (int bj = 0; bj < 3; ++bj)
        for (int ai = 0; ai < 3; ++ai) {
          const double dx0 = (ai - fx[0] - 0.5) * h, dx1 = (bj - fx[1] - 0.5) * h;
          const double wt = w[0][ai] * w[1][bj];
          const size_t id = at(b[0] + ai, b[1] + bj);
          gm[id] += wt * mp;
          gv[2 * id] += wt * (mp * p.v[0] + A[0] * dx0 + A[1] * dx1);
          gv[2 * id + 1] += wt * (mp * p.v[1] + A[2] * dx0 + A[3] * dx1);
        }
    }
    for (int j = -1; j <= n + 1; ++j)
      for (int i = -1; i <= n + 1; ++i) {
        const int si = src(i), sj = src(j);
        if (si == i && sj == j) continue;
        const size_t g = at(i, j), o = at(si, sj);
        gm[o] += gm[g];
        gv[2 * o] += gv[2 * g];
        gv[2 * o + 1] += gv[2 * g + 1];
      }
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const size_t id = at(i, j);
        if (gm[id] > 0) {
          const double im = 1.0 / gm[id];
          gv[2 * id] *= im;
          gv[2 * id + 1] *= im;
        }
      }
    for (int j = -1; j <= n + 1; ++j)
      for (int i = -1; i <= n + 1; ++i) {
        const int si = src(i), sj = src(j);
        if (si == i && sj == j) continue;
        const size_t g = at(i, j), o = at(si, sj);
        gv[2 * g] = gv[2 * o];
        gv[2 * g + 1] = gv[2 * o + 1];
      }
    // G2P: velocity, affine matrix, move, F update, elastic stress.
    for (Particle &p : ps) {
      int b[2];
      double fx[2], w[2][3];
      for (int d = 0; d < 2; ++d) weights(p.x[d], inv_h, b[d], fx[d], w[d]);
      double v[2] = {0, 0}, B[4] = {0, 0, 0, 0};
      for (int bj = 0; bj < 3; ++bj)
        for (int ai = 0; ai < 3; ++ai) {
          const double dx[2] = {(ai - fx[0] - 0.5) * h, (bj - fx[1] - 0.5) * h};
          const double wt = w[0][ai] * w[1][bj];
          const size_t id = at(b[0] + ai, b[1] + bj);
          for (int d = 0; d < 2; ++d) {
            const double g = gv[2 * id + d];
            v[d] += wt * g;
            B[2 * d] += wt * g * dx[0];
            B[2 * d + 1] += wt * g * dx[1];
          }
        }
      for (int q = 0; q < 4; ++q) p.C[q] = k4 * B[q];
      for (int d = 0; d < 2; ++d) {
        p.v[d] = v[d];
        p.x[d] += dt * v[d];
        p.x[d] -= std::floor(p.x[d]);
      }
      double Fn[4];
      for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 2; ++j) Fn[2 * i + j] = p.F[2 * i + j] + dt * (p.C[2 * i] * p.F[j] + p.C[2 * i + 1] * p.F[2 + j]);
      for (int q = 0; q < 4; ++q) p.F[q] = Fn[q];
      const double e00 = p.F[0] - 1, e11 = p.F[3] - 1, e01 = 0.5 * (p.F[1] + p.F[2]), tr = e00 + e11;
      p.s[0] = 2 * mu * e00 + lam * tr;
      p.s[3] = 2 * mu * e11 + lam * tr;
      p.s[1] = p.s[2] = 2 * mu * e01;
    }
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  double chk = 0;
  for (const Particle &p : ps) chk += p.v[0] + p.x[1];
  std::printf("bare_mpm2d: particles %zu steps %d wall %.3f s rate %.4g p-steps/s checksum %.6g\n", ps.size(), steps, wall,
              double(ps.size()) * steps / wall, chk);
  return 0;
}
