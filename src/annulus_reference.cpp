#include "granmpm/annulus_reference.hpp"

#include <algorithm>
#include <cmath>

namespace granmpm {

namespace {
// Local shear rate at friction coefficient mu (linearised mu(I), as the chute's reference).
double gdot_loc(const AnnulusParams &a, double mu) {
  return mu > a.gp.mu_s ? std::sqrt(a.p / a.gp.rho_s) * (mu - a.gp.mu_s) / (a.gp.b * a.gp.d) : 0.0;
}
} // namespace

double annulus_local_omega(const AnnulusParams &a, double T, double r) {
  // w(r) = int_r^{min(r_y, Ro)} c (T/(p s^3) - mu_s/s) ds,  c = sqrt(p/rho_s)/(b d).
  const double ry = std::sqrt(T / (a.gp.mu_s * a.p)), top = std::min(ry, a.Ro);
  if (r >= top) return 0.0;
  const double c = std::sqrt(a.p / a.gp.rho_s) / (a.gp.b * a.gp.d);
  return c * (T / (2 * a.p) * (1 / (r * r) - 1 / (top * top)) - a.gp.mu_s * std::log(top / r));
}

AnnulusReference::AnnulusReference(const AnnulusParams &a_in, bool local, int n) : a_(a_in), local_(local) {
  // The problem is odd in Omega: solve for |Omega| and flip the sign of w and T.
  sign_ = a_in.Omega < 0 ? -1.0 : 1.0;
  a_.Omega = std::fabs(a_in.Omega);
  const AnnulusParams &a = a_;
  dr_ = (a.Ro - a.Ri) / (n - 1);
  r_.resize(n);
  for (int i = 0; i < n; ++i) r_[i] = a.Ri + i * dr_;
  // Bracket: T = 0 does not flow (w = 0); grow the upper bound until w(Ri) > Omega.
  double lo = 0, hi = a.gp.mu_s * a.p * a.Ri * a.Ri;
  while (solve(hi) < a.Omega && hi < 1e300) {
    lo = hi;
    hi *= 2;
  }
  for (bisection_iterations = 0; bisection_iterations < 200; ++bisection_iterations) {
    const double mid = 0.5 * (lo + hi);
    if (solve(mid) < a.Omega) lo = mid;
    else hi = mid;
    if (hi - lo <= 1e-15 * hi) break;
  }
  T_ = a.Omega > 0 ? 0.5 * (lo + hi) : 0.0;
  solve(T_);
}

double AnnulusReference::solve(double T) {
  const int n = (int)r_.size();
  w_.assign(n, 0.0);
  g_.assign(n, 0.0);
  gd_.assign(n, 0.0);
  std::vector<double> mu(n), wt(n), gl(n);
  for (int i = 0; i < n; ++i) {
    mu[i] = T / (a_.p * r_[i] * r_[i]);
    wt[i] = std::fabs(mu[i] - a_.gp.mu_s);
    gl[i] = mu[i] > 0 ? gdot_loc(a_, mu[i]) / mu[i] : 0.0;
  }
  if (local_) {
    for (int i = 0; i < n; ++i) {
      w_[i] = annulus_local_omega(a_, T, r_[i]);
      gd_[i] = gdot_loc(a_, mu[i]);
      g_[i] = gl[i];
    }
    return w_[0];
  }
  const double k = std::pow(a_.gp.A * a_.gp.d, 2);
  if (k == 0) {
    g_ = gl;
  } else {
    // Rows: -k/dr^2 (1/r_i) [r_{i+1/2} (g_{i+1} - g_i) - r_{i-1/2} (g_i - g_{i-1})] + w_i g_i = w_i gl_i;
    // zero flux through ghost points g_{-1} = g_1, g_n = g_{n-2} (the two half-radii of
    // an end row then multiply the same difference: 2 r_i / r_i = 2).
    std::vector<double> lo(n, 0), di(n, 0), up(n, 0), rhs(n, 0);
    const double q = k / (dr_ * dr_);
    for (int i = 0; i < n; ++i) {
      const double rm = (r_[i] - 0.5 * dr_) / r_[i], rp = (r_[i] + 0.5 * dr_) / r_[i];
      di[i] = q * (rm + rp) + wt[i];
      rhs[i] = wt[i] * gl[i];
      lo[i] = -q * rm;
      up[i] = -q * rp;
    }
    up[0] = -q * 2;
    di[0] = q * 2 + wt[0];
    lo[n - 1] = -q * 2;
    di[n - 1] = q * 2 + wt[n - 1];
    if (a_.zero_g_walls) { // Dirichlet g = 0 at both walls
      di[0] = di[n - 1] = 1;
      up[0] = lo[n - 1] = rhs[0] = rhs[n - 1] = 0;
    }
    // Thomas algorithm (diagonally dominant: w >= 0).
    for (int i = 1; i < n; ++i) {
      const double f = lo[i] / di[i - 1];
      di[i] -= f * up[i - 1];
      rhs[i] -= f * rhs[i - 1];
    }
    g_[n - 1] = rhs[n - 1] / di[n - 1];
    for (int i = n - 2; i >= 0; --i) g_[i] = (rhs[i] - up[i] * g_[i + 1]) / di[i];
  }
  for (int i = 0; i < n; ++i) gd_[i] = mu[i] * g_[i];
  // w(r) = int_r^Ro gdot / s ds, trapezoidal from the outer wall.
  for (int i = n - 2; i >= 0; --i) w_[i] = w_[i + 1] + 0.5 * dr_ * (gd_[i] / r_[i] + gd_[i + 1] / r_[i + 1]);
  return w_[0];
}

double AnnulusReference::interp(const std::vector<double> &f, double r) const {
  const int n = (int)r_.size();
  if (r <= r_[0]) return f[0];
  if (r >= r_[n - 1]) return f[n - 1];
  const int i = std::min((int)((r - r_[0]) / dr_), n - 2);
  const double t = (r - r_[i]) / dr_;
  return (1 - t) * f[i] + t * f[i + 1];
}

double AnnulusReference::omega(double r) const {
  if (local_) return sign_ * annulus_local_omega(a_, T_, std::max(r, a_.Ri));
  return sign_ * interp(w_, r);
}
double AnnulusReference::gdot(double r) const { return interp(gd_, r); } // magnitude
double AnnulusReference::yield_radius() const { return std::sqrt(T_ / (a_.gp.mu_s * a_.p)); }

} // namespace granmpm
