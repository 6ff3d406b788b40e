// Transfer kernels on a plain node array (no PETSc): P2G conserves mass and momentum,
// APIC reproduces an affine velocity field exactly, for every kernel in 2D and 3D.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "granmpm/transfer.hpp"

using namespace granmpm;

namespace {

template <int dim>
struct Box {
  std::vector<double> data;
  NodeView<dim> view;
  explicit Box(int n) {
    size_t total = NodeView<dim>::NDOF;
    for (int d = 0; d < 3; ++d) {
      view.gs[d] = 0;
      view.gm[d] = d < dim ? n : 1;
      total *= view.gm[d];
    }
    data.assign(total, 0.0);
    view.a = data.data();
  }
};

template <int dim, class S>
void check_conservation_and_affine(const S &sh) {
  const int n = 12;
  const double h = 0.5, inv_h = 2.0, x0[3] = {0, 0, 0};
  Box<dim> box(n);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(3.0 * h, (n - 4.0) * h), M(0.5, 2.0), V(-1, 1);
  // Affine field v(x) = a + B x.
  double a[3], B[3][3];
  for (int d = 0; d < 3; ++d) {
    a[d] = V(rng);
    for (int e = 0; e < 3; ++e) B[d][e] = V(rng);
  }
  const int np = 200;
  std::vector<double> x(np * dim), v(np * dim), m(np), C(np * dim * dim);
  double mtot = 0, ptot[3] = {0, 0, 0};
  for (int p = 0; p < np; ++p) {
    m[p] = M(rng);
    for (int d = 0; d < dim; ++d) x[p * dim + d] = U(rng);
    for (int d = 0; d < dim; ++d) {
      v[p * dim + d] = a[d];
      for (int e = 0; e < dim; ++e) v[p * dim + d] += B[d][e] * x[p * dim + e];
      for (int e = 0; e < dim; ++e) C[(p * dim + d) * dim + e] = B[d][e];
    }
    mtot += m[p];
    for (int d = 0; d < dim; ++d) ptot[d] += m[p] * v[p * dim + d];
  }
  Stencil<dim, S> st;
  for (int p = 0; p < np; ++p) {
    st.compute(sh, &x[p * dim], x0, inv_h);
    P2GInput<dim> in{m[p], 1.0, &v[p * dim], &C[p * dim * dim], nullptr, nullptr};
    p2g_particle(st, in, h, box.view);
  }
  // Conservation: grid mass and momentum equal particle totals (APIC's C(x_i - x_p)
  // terms sum to zero by linear reproduction).
  double gm = 0, gp[3] = {0, 0, 0};
  const size_t nn = box.data.size() / NodeView<dim>::NDOF;
  for (size_t q = 0; q < nn; ++q) {
    const double *node = &box.data[q * NodeView<dim>::NDOF];
    gm += node[0];
    for (int d = 0; d < dim; ++d) gp[d] += node[1 + d];
  }
  REQUIRE(gm == Approx(mtot).epsilon(1e-14));
  for (int d = 0; d < dim; ++d) REQUIRE(gp[d] == Approx(ptot[d]).epsilon(1e-13).margin(1e-12));
  // Grid velocity: v_i = (mv)_i / m_i, stored where G2P reads it; dv = 0.
  for (size_t q = 0; q < nn; ++q) {
    double *node = &box.data[q * NodeView<dim>::NDOF];
    for (int d = 0; d < dim; ++d) {
      node[1 + d] = node[0] > 0 ? node[1 + d] / node[0] : 0.0;
      node[1 + dim + d] = 0;
    }
  }
  // G2P: velocity and the APIC matrix reproduce the affine field exactly.
  G2POutput<dim> o;
  const bool grad_form = std::is_same<S, LinearShape>::value;
  for (int p = 0; p < np; ++p) {
    st.compute(sh, &x[p * dim], x0, inv_h);
    g2p_particle(st, h, box.view, o);
    double Cn[dim * dim];
    apic_C(o, grad_form, Cn);
    for (int d = 0; d < dim; ++d) {
      REQUIRE(o.v_pic[d] == Approx(v[p * dim + d]).margin(1e-12));
      for (int e = 0; e < dim; ++e) {
        REQUIRE(Cn[d * dim + e] == Approx(B[d][e]).margin(1e-10));
        REQUIRE(o.L[d][e] == Approx(B[d][e]).margin(1e-10)); // velocity gradient is exact too
      }
    }
  }
}

// The term-by-term formulas (one product per node and term, the kernels before they were
// factored by rows), kept as the reference the factored kernels must reproduce.
template <int dim, class Shape>
void p2g_reference(const Stencil<dim, Shape> &st, const P2GInput<dim> &in, double h, const NodeView<dim> &g) {
  constexpr int N = Shape::N;
  double sig[dim][dim] = {};
  if (in.s6) {
    sig[0][0] = in.s6[0];
    sig[1][1] = in.s6[1];
    sig[0][1] = sig[1][0] = in.s6[3];
    if constexpr (dim == 3) {
      sig[2][2] = in.s6[2];
      sig[1][2] = sig[2][1] = in.s6[4];
      sig[0][2] = sig[2][0] = in.s6[5];
    }
  }
  const int kN = (dim == 3) ? N : 1;
  for (int c = 0; c < kN; ++c) {
    const double wz = (dim == 3) ? st.w[dim - 1][c] : 1.0;
    const double dwz = (dim == 3) ? st.dw[dim - 1][c] : 0.0;
    const double fz = (dim == 3) ? st.frac[dim - 1][c] * h : 0.0;
    const int k = (dim == 3) ? st.base[2] + c : 0;
    for (int b = 0; b < N; ++b) {
      const int j = st.base[1] + b;
      const double wy = st.w[1][b], dwy = st.dw[1][b], fy = st.frac[1][b] * h;
      double *row = g.at(st.base[0], j, k);
      for (int a = 0; a < N; ++a) {
        const double wx = st.w[0][a], dwx = st.dw[0][a], fx = st.frac[0][a] * h;
        const double w = wx * wy * wz;
        double grad[dim];
        grad[0] = dwx * wy * wz;
        grad[1] = wx * dwy * wz;
        if constexpr (dim == 3) grad[2] = wx * wy * dwz;
        double dx[dim];
        dx[0] = fx;
        dx[1] = fy;
        if constexpr (dim == 3) dx[2] = fz;
        double *n = row + (size_t)a * NodeView<dim>::NDOF;
        const double mw = in.m * w;
        n[0] += mw;
        for (int d = 0; d < dim; ++d) {
          double vd = in.v[d];
          if (in.C)
            for (int e = 0; e < dim; ++e) vd += in.C[d * dim + e] * dx[e];
          n[1 + d] += mw * vd;
        }
        if (in.s6) {
          for (int d = 0; d < dim; ++d) {
            double f = 0;
            for (int e = 0; e < dim; ++e) f -= sig[d][e] * grad[e];
            n[1 + dim + d] += in.vol * f;
          }
        }
        if (in.bacc)
          for (int d = 0; d < dim; ++d) n[1 + dim + d] += mw * in.bacc[d];
      }
    }
  }
}

template <int dim, class Shape>
void g2p_reference(const Stencil<dim, Shape> &st, double h, const NodeView<dim> &g, G2POutput<dim> &o) {
  constexpr int N = Shape::N;
  for (int d = 0; d < dim; ++d) {
    o.v_pic[d] = o.dv[d] = 0;
    for (int e = 0; e < dim; ++e) o.L[d][e] = o.B[d][e] = 0;
  }
  // D is diagonal for tensor-product kernels because sum_k w_k (x_k - x_p) = 0 in 1D.
  for (int d = 0; d < dim; ++d) {
    double s = 0;
    for (int a = 0; a < N; ++a) s += st.w[d][a] * st.frac[d][a] * st.frac[d][a];
    o.D[d] = s * h * h;
  }
  const int kN = (dim == 3) ? N : 1;
  for (int c = 0; c < kN; ++c) {
    const double wz = (dim == 3) ? st.w[dim - 1][c] : 1.0;
    const double dwz = (dim == 3) ? st.dw[dim - 1][c] : 0.0;
    const double fz = (dim == 3) ? st.frac[dim - 1][c] * h : 0.0;
    const int k = (dim == 3) ? st.base[2] + c : 0;
    for (int b = 0; b < N; ++b) {
      const int j = st.base[1] + b;
      const double wy = st.w[1][b], dwy = st.dw[1][b], fy = st.frac[1][b] * h;
      const double *row = g.at(st.base[0], j, k);
      for (int a = 0; a < N; ++a) {
        const double wx = st.w[0][a], dwx = st.dw[0][a], fx = st.frac[0][a] * h;
        const double w = wx * wy * wz;
        double grad[dim], dx[dim];
        grad[0] = dwx * wy * wz;
        grad[1] = wx * dwy * wz;
        dx[0] = fx;
        dx[1] = fy;
        if constexpr (dim == 3) {
          grad[2] = wx * wy * dwz;
          dx[2] = fz;
        }
        const double *n = row + (size_t)a * NodeView<dim>::NDOF;
        for (int d = 0; d < dim; ++d) {
          const double vd = n[1 + d];
          o.v_pic[d] += w * vd;
          o.dv[d] += w * n[1 + dim + d];
          for (int e = 0; e < dim; ++e) {
            o.L[d][e] += vd * grad[e];
            o.B[d][e] += w * vd * dx[e];
          }
        }
      }
    }
  }
}


// Random particles with every input (affine C, stress, body acceleration) on random
// nodal data: the factored kernels equal the term-by-term sums to round-off.
template <int dim, class S>
void check_against_reference(const S &sh) {
  const int n = 10;
  const double h = 0.3, inv_h = 1.0 / h, x0[3] = {0, 0, 0};
  Box<dim> fast(n), ref(n);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> U(3.0 * h, (n - 4.0) * h), V(-1, 1);
  Stencil<dim, S> st;
  double scale = 0;
  for (int p = 0; p < 300; ++p) {
    double x[dim], v[dim], C[dim * dim], s6[6], b[dim];
    for (int d = 0; d < dim; ++d) x[d] = U(rng), v[d] = V(rng), b[d] = V(rng);
    for (auto &c : C) c = 10 * V(rng);
    for (auto &c : s6) c = 1e3 * V(rng);
    const double m = 1 + V(rng) * 0.5, vol = 0.01 * (1.5 + V(rng));
    st.compute(sh, x, x0, inv_h);
    const int variant = p % 4; // all inputs, no C, no force, body acceleration only
    P2GInput<dim> in{m, vol, v, variant == 1 ? nullptr : C, variant >= 2 ? nullptr : s6, variant == 2 ? nullptr : b};
    p2g_particle(st, in, h, fast.view);
    p2g_reference(st, in, h, ref.view);
  }
  for (size_t q = 0; q < ref.data.size(); ++q) scale = std::max(scale, std::fabs(ref.data[q]));
  REQUIRE(scale > 0);
  for (size_t q = 0; q < ref.data.size(); ++q) REQUIRE(fast.data[q] == Approx(ref.data[q]).margin(1e-14 * scale));
  // G2P on random nodal velocities and increments.
  for (double &a : ref.data) a = V(rng);
  for (int p = 0; p < 300; ++p) {
    double x[dim];
    for (int d = 0; d < dim; ++d) x[d] = U(rng);
    st.compute(sh, x, x0, inv_h);
    G2POutput<dim> a, r;
    g2p_particle(st, h, ref.view, a);
    g2p_reference(st, h, ref.view, r);
    for (int d = 0; d < dim; ++d) {
      REQUIRE(a.v_pic[d] == Approx(r.v_pic[d]).margin(1e-14));
      REQUIRE(a.dv[d] == Approx(r.dv[d]).margin(1e-14));
      REQUIRE(a.D[d] == r.D[d]);
      for (int e = 0; e < dim; ++e) {
        REQUIRE(a.L[d][e] == Approx(r.L[d][e]).margin(1e-14 * inv_h));
        REQUIRE(a.B[d][e] == Approx(r.B[d][e]).margin(1e-14 * h));
      }
    }
  }
}

} // namespace

TEST_CASE("P2G conserves mass and momentum; APIC reproduces affine velocity", "[transfer]") {
  SECTION("linear 2D") { check_conservation_and_affine<2>(LinearShape{}); }
  SECTION("linear 3D") { check_conservation_and_affine<3>(LinearShape{}); }
  SECTION("gimp 2D") { check_conservation_and_affine<2>(GIMPShape{0.25}); }
  SECTION("gimp 3D") { check_conservation_and_affine<3>(GIMPShape{0.25}); }
  SECTION("bspline2 2D") { check_conservation_and_affine<2>(BSpline2Shape{}); }
  SECTION("bspline2 3D") { check_conservation_and_affine<3>(BSpline2Shape{}); }
}

TEST_CASE("P2G internal force of a uniform stress sums to zero and balances the body force", "[transfer]") {
  // A uniform stress field exerts no net force on an isolated body: sum_i f_i =
  // -sum_p V_p sigma . sum_i grad S_ip = 0; gravity gives sum m_p g.
  const int n = 10;
  const double h = 1.0, x0[3] = {0, 0, 0};
  Box<2> box(n);
  const double s6[6] = {-3.0, 2.0, 0.5, 1.25, 0, 0}, g[2] = {0.0, -9.81}, v[2] = {0, 0};
  Stencil<2, BSpline2Shape> st;
  double mtot = 0;
  for (double y = 3.1; y < 6.0; y += 0.45)
    for (double x = 3.05; x < 6.0; x += 0.5) {
      const double xp[2] = {x, y};
      st.compute(BSpline2Shape{}, xp, x0, 1.0 / h);
      P2GInput<2> in{2.0, 0.3, v, nullptr, s6, g};
      p2g_particle(st, in, h, box.view);
      mtot += 2.0;
    }
  double f[2] = {0, 0};
  for (size_t q = 0; q < box.data.size() / 5; ++q)
    for (int d = 0; d < 2; ++d) f[d] += box.data[q * 5 + 3 + d];
  REQUIRE(f[0] == Approx(0.0).margin(1e-12));
  REQUIRE(f[1] == Approx(mtot * g[1]).epsilon(1e-14));
}

TEST_CASE("Factored P2G and G2P equal the term-by-term formulas", "[transfer]") {
  SECTION("linear 2D") { check_against_reference<2>(LinearShape{}); }
  SECTION("linear 3D") { check_against_reference<3>(LinearShape{}); }
  SECTION("gimp 2D") { check_against_reference<2>(GIMPShape{0.25}); }
  SECTION("gimp 3D") { check_against_reference<3>(GIMPShape{0.25}); }
  SECTION("bspline2 2D") { check_against_reference<2>(BSpline2Shape{}); }
  SECTION("bspline2 3D") { check_against_reference<3>(BSpline2Shape{}); }
}
