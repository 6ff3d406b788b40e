// Pure kernels of the steady fluidity system: the cell quadrature against the analytic
// integrals of the Q1 products, and the particle (point) quadrature against it.
#include <catch2/catch.hpp>

#include <cmath>

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
