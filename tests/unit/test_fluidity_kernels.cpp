// Pure kernels of the steady fluidity system: the cell quadrature against the analytic
// integrals of the Q1 products, and the particle (point) quadrature against it.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <vector>

#include "granmpm/fluidity.hpp"

using namespace granmpm;

namespace {
// int_0^h int_0^h f(x, y) dx dy by 8-point Gauss-Legendre per direction (exact for the
// degree-2-per-direction Q1 products).
template <class F>
double integrate2(double h, F f) {
  const double xg[4] = {0.1834346424956498, 0.5255324099163290, 0.7966664774136267, 0.9602898564975363};
  const double wg[4] = {0.3626837833783620, 0.3137066458778873, 0.2223810344533745, 0.1012285362903763};
  double s = 0;
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 8; ++j) {
      const double xi = 0.5 * (1 + (i < 4 ? -xg[i] : xg[i - 4])), wi = 0.5 * wg[i % 4];
      const double yj = 0.5 * (1 + (j < 4 ? -xg[j] : xg[j - 4])), wj = 0.5 * wg[j % 4];
      s += wi * wj * f(xi * h, yj * h);
    }
  return s * h * h;
}
double S(int a, double x, double y, double h) { return ((a & 1) ? x / h : 1 - x / h) * ((a & 2) ? y / h : 1 - y / h); }
double dS(int a, int d, double x, double y, double h) {
  if (d == 0) return ((a & 1) ? 1 / h : -1 / h) * ((a & 2) ? y / h : 1 - y / h);
  return ((a & 1) ? x / h : 1 - x / h) * ((a & 2) ? 1 / h : -1 / h);
}
} // namespace

TEST_CASE("fluidity cell quadrature equals the analytic Q1 integrals", "[fluidity][kernel]") {
  const double h = 0.03, phi = 0.7, Wm = 0.13, F = 2.5e-4, k = 5.76e-4;
  double Ke[16] = {0}, fe[4] = {0};
  fluidity_cell_contribution<2>(h, phi, Wm, F, k, Ke, fe);
  for (int a = 0; a < 4; ++a) {
    REQUIRE(fe[a] == Approx(F / 4).epsilon(1e-14));
    for (int b = 0; b < 4; ++b) {
      const double m = integrate2(h, [&](double x, double y) { return S(a, x, y, h) * S(b, x, y, h); });
      const double s = integrate2(h, [&](double x, double y) { return dS(a, 0, x, y, h) * dS(b, 0, x, y, h) + dS(a, 1, x, y, h) * dS(b, 1, x, y, h); });
      REQUIRE(Ke[a * 4 + b] == Approx(Wm * m + phi * k * s).epsilon(1e-12));
    }
  }
  // Positive definite (the point quadrature's element matrix has rank 1 + dim = 3 of 4):
  // the smallest eigenvalue of the checkerboard mode (+1 -1 -1 +1) is positive.
  const double c[4] = {1, -1, -1, 1};
  double q = 0;
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b) q += c[a] * Ke[a * 4 + b] * c[b];
  REQUIRE(q > 0.01 * Wm * h * h);
}

TEST_CASE("fluidity point quadrature: uniform particles converge to the cell integrals", "[fluidity][kernel]") {
  // n x n particles filling the cell, each with volume (h/n)^2: the midpoint rule, whose
  // error on these quadratic integrands falls as 1/n^2 (the mass term; the stiffness term
  // is linear per direction in the cross factor and converges the same way).
  const double h = 0.05, w = 0.2, gl = 1.5, k = 5.76e-4;
  double Kc[16] = {0}, fc[4] = {0};
  fluidity_cell_contribution<2>(h, 1.0, w, w * gl * h * h, k, Kc, fc);
  double prev = 0;
  for (int n : {2, 4, 8}) {
    double Ke[16] = {0}, fe[4] = {0};
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        const double xi[2] = {(i + 0.5) / n, (j + 0.5) / n};
        fluidity_element_contribution<2>(xi, h, (h / n) * (h / n), w, gl, k, Ke, fe);
      }
    double err = 0;
    for (int a = 0; a < 16; ++a) err = std::max(err, std::fabs(Ke[a] - Kc[a]));
    for (int a = 0; a < 4; ++a) REQUIRE(fe[a] == Approx(fc[a]).epsilon(1e-12)); // linear: exact
    if (n > 2) REQUIRE(err == Approx(prev / 4).epsilon(0.05));                 // second order
    prev = err;
  }
}

namespace {
// A symmetric diagonally dominant band matrix (n, half-bandwidth bw) as dense and band.
struct BandCase {
  PetscInt n;
  int bw;
  std::vector<double> dense, band;
  BandCase(PetscInt n_, int bw_, unsigned seed) : n(n_), bw(bw_), dense(n_ * n_, 0.0), band(n_ * (bw_ + 1), 0.0) {
    for (PetscInt i = 0; i < n; ++i)
      for (PetscInt j = std::max<PetscInt>(0, i - bw); j <= i; ++j) {
        seed = seed * 1103515245u + 12345u;
        const double r = ((seed >> 8) & 0xffff) / 65536.0 - 0.5;
        const double v = i == j ? 2.0 * bw + 1 : r;
        dense[i * n + j] = dense[j * n + i] = v;
        band[i * (bw + 1) + bw - (i - j)] = v;
      }
  }
};
// Gaussian elimination with partial pivoting on a dense copy: the independent reference.
std::vector<double> dense_solve(std::vector<double> A, std::vector<double> b, PetscInt n) {
  for (PetscInt k = 0; k < n; ++k) {
    PetscInt piv = k;
    for (PetscInt i = k + 1; i < n; ++i)
      if (std::fabs(A[i * n + k]) > std::fabs(A[piv * n + k])) piv = i;
    for (PetscInt j = 0; j < n; ++j) std::swap(A[k * n + j], A[piv * n + j]);
    std::swap(b[k], b[piv]);
    for (PetscInt i = k + 1; i < n; ++i) {
      const double f = A[i * n + k] / A[k * n + k];
      for (PetscInt j = k; j < n; ++j) A[i * n + j] -= f * A[k * n + j];
      b[i] -= f * b[k];
    }
  }
  for (PetscInt k = n - 1; k >= 0; --k) {
    for (PetscInt j = k + 1; j < n; ++j) b[k] -= A[k * n + j] * b[j];
    b[k] /= A[k * n + k];
  }
  return b;
}
} // namespace

TEST_CASE("band Cholesky, solve and matvec agree with a dense solve", "[fluidity][kernel]") {
  for (int bw : {0, 1, 3, 7, 12}) {
    const BandCase c(40, bw, 7u + bw);
    std::vector<double> x(c.n), f(c.n), y(c.n);
    for (PetscInt i = 0; i < c.n; ++i) x[i] = std::sin(0.3 * i) + 0.1 * i;
    band_matvec(c.n, bw, c.band.data(), x.data(), f.data());
    for (PetscInt i = 0; i < c.n; ++i) {
      double s = 0;
      for (PetscInt j = 0; j < c.n; ++j) s += c.dense[i * c.n + j] * x[j];
      REQUIRE(f[i] == Approx(s).epsilon(1e-14).margin(1e-14));
    }
    const std::vector<double> ref = dense_solve(c.dense, f, c.n);
    std::vector<double> L = c.band;
    REQUIRE(band_cholesky(c.n, bw, L.data()) == 0);
    y = f;
    band_solve(c.n, bw, L.data(), y.data());
    for (PetscInt i = 0; i < c.n; ++i) REQUIRE(y[i] == Approx(ref[i]).epsilon(1e-12).margin(1e-12));
    std::vector<double> z(c.n), work(4 * c.n);
    REQUIRE(band_pcg(c.n, bw, c.band.data(), L.data(), f.data(), z.data(), 1e-12, 5, work.data()) == 1);
    for (PetscInt i = 0; i < c.n; ++i) REQUIRE(z[i] == Approx(ref[i]).epsilon(1e-11).margin(1e-11));
  }
}

TEST_CASE("band LU and solve agree with a dense solve on non-symmetric diagonally dominant matrices", "[fluidity][kernel]") {
  // Independent reference: dense Gaussian elimination with partial pivoting.
  for (int bw : {0, 1, 4, 7, 9}) { // 1-8: the fixed-bandwidth kernels, 0 and 9 the generic one
    const PetscInt n = 37, w = 2 * bw + 1;
    std::vector<double> dense(n * n, 0.0), band(n * w, 0.0), f(n);
    unsigned seed = 11u + bw;
    for (PetscInt i = 0; i < n; ++i) {
      double off = 0;
      for (PetscInt j = std::max<PetscInt>(0, i - bw); j <= std::min<PetscInt>(n - 1, i + bw); ++j) {
        if (j == i) continue;
        seed = seed * 1103515245u + 12345u;
        const double r = ((seed >> 8) & 0xffff) / 65536.0 - 0.7; // not symmetric, mostly negative
        dense[i * n + j] = r;
        band[i * w + bw + (j - i)] = r;
        off += std::fabs(r);
      }
      dense[i * n + i] = band[i * w + bw] = off + 0.05 + 0.01 * (i % 3); // barely dominant, as I - theta Delta_h for large theta
      f[i] = std::cos(0.7 * i) - 0.2;
    }
    for (PetscInt i = 0; i < n; i += 5) dense[i * n + i] = band[i * w + bw] += 1.0; // strictly dominant somewhere
    const std::vector<double> ref = dense_solve(dense, f, n);
    std::vector<double> lu = band, x = f;
    REQUIRE(band_lu(n, bw, lu.data()));
    band_lu_solve(n, bw, lu.data(), x.data());
    double scale = 0;
    for (PetscInt i = 0; i < n; ++i) scale = std::max(scale, std::fabs(ref[i]));
    for (PetscInt i = 0; i < n; ++i) REQUIRE(x[i] == Approx(ref[i]).margin(1e-11 * scale));
  }
  std::vector<double> z(3 * 3, 0.0); // a zero pivot is reported, not divided by
  REQUIRE_FALSE(band_lu(3, 1, z.data()));
}

TEST_CASE("band solver: a singular consistent system (1D Neumann Laplacian) is solved by PCG on the shifted factor", "[fluidity][kernel]") {
  // -u'' with zero-flux ends: null space = constants. f = A x0 is consistent; the factor
  // meets a zero last pivot, replaces it, and CG reaches a solution (x0 up to a constant).
  const PetscInt n = 30;
  std::vector<double> A(n * 2, 0.0), x0(n), f(n), L, x(n), work(4 * n), r(n);
  for (PetscInt i = 0; i < n; ++i) {
    A[i * 2 + 1] = (i == 0 || i == n - 1) ? 1.0 : 2.0;
    if (i > 0) A[i * 2] = -1.0;
    x0[i] = std::cos(0.2 * i);
  }
  band_matvec(n, 1, A.data(), x0.data(), f.data());
  L = A;
  REQUIRE(band_cholesky(n, 1, L.data()) == 1);
  const int it = band_pcg(n, 1, A.data(), L.data(), f.data(), x.data(), 1e-10, 50, work.data());
  REQUIRE(it >= 1);
  band_matvec(n, 1, A.data(), x.data(), r.data());
  double rn = 0, fn = 0;
  for (PetscInt i = 0; i < n; ++i) {
    rn += (r[i] - f[i]) * (r[i] - f[i]);
    fn += f[i] * f[i];
  }
  REQUIRE(std::sqrt(rn / fn) <= 1e-10);
  for (PetscInt i = 1; i < n; ++i) REQUIRE((x[i] - x[0]) == Approx(x0[i] - x0[0]).margin(1e-8));
}

TEST_CASE("fluidity_source6 equals fluidity_source on the matrix form", "[fluidity][kernel]") {
  GranularParams gp;
  const double cases[4][6] = {{-900, -1000, -950, 300, 0, 0}, {-900, -900, -900, 10, 0, 0}, {-500, -800, -650, -120, 40, 30}, {100, -50, 0, 20, 0, 0}};
  for (const auto &s : cases) {
    const FluiditySource a = fluidity_source(gp, sym6_to_mat(s)), b = fluidity_source6(gp, s);
    REQUIRE(b.weight == Approx(a.weight).epsilon(1e-13).margin(1e-15));
    REQUIRE(b.g_loc == Approx(a.g_loc).epsilon(1e-13).margin(1e-15));
  }
}
