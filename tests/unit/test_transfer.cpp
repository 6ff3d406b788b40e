// Transfer kernels on a plain node array (no PETSc): P2G conserves mass and momentum,
// APIC reproduces an affine velocity field exactly, for every kernel in 2D and 3D.
#include <catch2/catch.hpp>

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
