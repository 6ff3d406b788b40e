// Shape-function kernels: partition of unity, linear reproduction and zero gradient sum,
// for each kernel in 1D and as tensor products in 2D and 3D, at many positions.
#include <catch2/catch.hpp>

#include <random>

#include "granmpm/shape.hpp"

using namespace granmpm;

namespace {

template <int dim, class S>
void check_kernel(const S &s) {
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> U(3.0, 9.0);
  const double h = 0.37, inv_h = 1 / h, x0[3] = {-1.1, 0.4, 2.0};
  for (int trial = 0; trial < 500; ++trial) {
    double xp[3];
    for (int d = 0; d < dim; ++d) xp[d] = x0[d] + U(rng) * h;
    // Include particles exactly on nodes and cell centres.
    if (trial == 0)
      for (int d = 0; d < dim; ++d) xp[d] = x0[d] + 5 * h;
    if (trial == 1)
      for (int d = 0; d < dim; ++d) xp[d] = x0[d] + 5.5 * h;
    Stencil<dim, S> st;
    st.compute(s, xp, x0, inv_h);
    constexpr int N = S::N;
    const int total = dim == 3 ? N * N * N : N * N;
    double sw = 0, sx[3] = {0, 0, 0}, sg[3] = {0, 0, 0}, sxg[3][3] = {{0}};
    for (int q = 0; q < total; ++q) {
      const int a = q % N, b = (q / N) % N, c = q / (N * N);
      const int idx[3] = {a, b, c};
      double w = 1, grad[3] = {1, 1, 1};
      for (int d = 0; d < dim; ++d) {
        w *= st.w[d][idx[d]];
        for (int e = 0; e < dim; ++e) grad[e] *= (e == d) ? st.dw[d][idx[d]] : st.w[d][idx[d]];
      }
      for (int d = 0; d < dim; ++d) {
        const double xi = x0[d] + (st.base[d] + idx[d]) * h;
        sx[d] += w * xi;
        sg[d] += grad[d];
        for (int e = 0; e < dim; ++e) sxg[d][e] += xi * grad[e];
      }
      sw += w;
      REQUIRE(w >= -1e-15);
    }
    REQUIRE(sw == Approx(1.0).margin(1e-14));
    for (int d = 0; d < dim; ++d) {
      REQUIRE(sx[d] == Approx(xp[d]).margin(1e-13));  // linear reproduction
      REQUIRE(sg[d] == Approx(0.0).margin(1e-12));    // gradients sum to zero
      for (int e = 0; e < dim; ++e) REQUIRE(sxg[d][e] == Approx(d == e ? 1.0 : 0.0).margin(1e-12)); // grad of x is I
    }
  }
}

// Compare analytic derivatives with central differences of the weights.
template <class S>
void check_derivative(const S &s) {
  const double eps = 1e-6;
  for (double xi = 2.013; xi < 7.0; xi += 0.0917) {
    double w[S::N], dw[S::N], wp[S::N], dwp[S::N], wm[S::N], dwm[S::N];
    const int b = s.eval(xi, w, dw);
    const int bp = s.eval(xi + eps, wp, dwp), bm = s.eval(xi - eps, wm, dwm);
    if (bp != b || bm != b) continue; // skip support switches
    for (int k = 0; k < S::N; ++k) REQUIRE(dw[k] == Approx((wp[k] - wm[k]) / (2 * eps)).margin(1e-6));
  }
}

} // namespace

TEST_CASE("linear tent kernel", "[shape]") {
  check_kernel<2>(LinearShape{});
  check_kernel<3>(LinearShape{});
  check_derivative(LinearShape{});
}

TEST_CASE("uGIMP kernel for 1, 2 and 4 particles per cell", "[shape]") {
  for (double lp : {0.5, 0.25, 0.125}) {
    check_kernel<2>(GIMPShape{lp});
    check_kernel<3>(GIMPShape{lp});
    check_derivative(GIMPShape{lp});
  }
}

TEST_CASE("quadratic B-spline kernel", "[shape]") {
  check_kernel<2>(BSpline2Shape{});
  check_kernel<3>(BSpline2Shape{});
  check_derivative(BSpline2Shape{});
}

TEST_CASE("GIMP weight equals the tent averaged over the particle domain", "[shape]") {
  // Independent reference: numerically integrate the tent over [x - lp, x + lp].
  const double lp = 0.25;
  GIMPShape s{lp};
  for (double xi = 3.0; xi < 4.0; xi += 0.05) {
    double w[3], dw[3];
    const int b = s.eval(xi, w, dw);
    for (int k = 0; k < 3; ++k) {
      const int n = 20000;
      double sum = 0;
      for (int q = 0; q < n; ++q) {
        const double y = xi - lp + (q + 0.5) * (2 * lp / n);
        sum += std::max(0.0, 1.0 - std::fabs(y - (b + k)));
      }
      REQUIRE(w[k] == Approx(sum / n).margin(1e-8));
    }
  }
}
