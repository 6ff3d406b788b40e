#include "granmpm/chute_reference.hpp"

#include <algorithm>
#include <cmath>

namespace granmpm {

double chute_local_speed(const ChuteParams &c, double s) {
  const double rg = c.rho * c.g;
  const double half = 0.5 * c.L;
  const double xc = c.gp.mu_s * c.p0 / rg; // edge of the plug
  const double a = std::max(std::fabs(s), xc);
  if (a >= half) return 0.0;
  // |v(s)| = (1/(b d)) sqrt(p0/rho_s) * integral_a^{L/2} (rho g s'/p0 - mu_s) ds'
  const double integral = rg / (2.0 * c.p0) * (half * half - a * a) - c.gp.mu_s * (half - a);
  return std::sqrt(c.p0 / c.gp.rho_s) / (c.gp.b * c.gp.d) * integral;
}

NonlocalChuteReference::NonlocalChuteReference(const ChuteParams &c, int n) {
  const double half = 0.5 * c.L;
  ds_ = half / (n - 1);
  s_.resize(n);
  g_.resize(n);
  v_.resize(n);
  std::vector<double> mu(n), w(n), gl(n);
  for (int i = 0; i < n; ++i) {
    s_[i] = i * ds_;
    mu[i] = c.rho * c.g * s_[i] / c.p0;
    w[i] = std::fabs(mu[i] - c.gp.mu_s);
    const double gdot = mu[i] > c.gp.mu_s ? std::sqrt(c.p0 / c.gp.rho_s) * (mu[i] - c.gp.mu_s) / (c.gp.b * c.gp.d) : 0.0;
    gl[i] = mu[i] > 0 ? gdot / mu[i] : 0.0;
  }
  const double k = std::pow(c.gp.A * c.gp.d, 2);
  if (k == 0) {
    g_ = gl; // A = 0: the local model
  } else {
    // Tridiagonal rows: -k (g_{i-1} - 2 g_i + g_{i+1}) / ds^2 + w_i g_i = w_i gl_i, with
    // ghost points g_{-1} = g_1 and g_n = g_{n-2} (zero flux).
    std::vector<double> lo(n, 0), di(n, 0), up(n, 0), rhs(n, 0);
    const double r = k / (ds_ * ds_);
    for (int i = 0; i < n; ++i) {
      di[i] = 2 * r + w[i];
      rhs[i] = w[i] * gl[i];
      if (i > 0) lo[i] = -r;
      if (i < n - 1) up[i] = -r;
    }
    up[0] = -2 * r;
    lo[n - 1] = -2 * r;
    // Thomas algorithm (diagonally dominant: w >= 0).
    for (int i = 1; i < n; ++i) {
      const double f = lo[i] / di[i - 1];
      di[i] -= f * up[i - 1];
      rhs[i] -= f * rhs[i - 1];
    }
    g_[n - 1] = rhs[n - 1] / di[n - 1];
    for (int i = n - 2; i >= 0; --i) g_[i] = (rhs[i] - up[i] * g_[i + 1]) / di[i];
  }
  // |v(s)| = integral_s^{L/2} mu g, trapezoidal from the wall.
  v_[n - 1] = 0;
  for (int i = n - 2; i >= 0; --i) v_[i] = v_[i + 1] + 0.5 * ds_ * (mu[i] * g_[i] + mu[i + 1] * g_[i + 1]);
}

double NonlocalChuteReference::interp(const std::vector<double> &f, double s) const {
  s = std::fabs(s);
  const int n = (int)s_.size();
  if (s >= s_[n - 1]) return f[n - 1];
  const int i = std::min((int)(s / ds_), n - 2);
  const double t = (s - s_[i]) / ds_;
  return (1 - t) * f[i] + t * f[i + 1];
}

double NonlocalChuteReference::speed(double s) const { return interp(v_, s); }
double NonlocalChuteReference::fluidity(double s) const { return interp(g_, s); }

} // namespace granmpm
