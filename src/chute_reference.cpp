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
  integrate_velocity(c);
}

void NonlocalChuteReference::integrate_velocity(const ChuteParams &c) {
  // |v(s)| = integral_s^{L/2} mu g, trapezoidal from the wall.
  const int n = (int)s_.size();
  v_.assign(n, 0.0);
  auto mu = [&](int i) { return c.rho * c.g * s_[i] / c.p0; };
  for (int i = n - 2; i >= 0; --i) v_[i] = v_[i + 1] + 0.5 * ds_ * (mu(i) * g_[i] + mu(i + 1) * g_[i + 1]);
}

DynamicChuteReference::DynamicChuteReference(const ChuteParams &c, int n) {
  const double half = 0.5 * c.L;
  ds_ = half / (n - 1);
  s_.resize(n);
  std::vector<double> mu(n), cc(n);
  g_.assign(n, 0.0);
  for (int i = 0; i < n; ++i) {
    s_[i] = i * ds_;
    mu[i] = c.rho * c.g * s_[i] / c.p0;
    cc[i] = c.gp.b * std::sqrt(c.gp.rho_s * c.gp.d * c.gp.d / c.p0) * mu[i];
    g_[i] = mu[i] > c.gp.mu_s ? (mu[i] - c.gp.mu_s) / cc[i] : 0.0; // g_loc
  }
  const double k = std::pow(c.gp.A * c.gp.d, 2), r = k / (ds_ * ds_);
  if (k > 0) {
    std::vector<double> lo(n), di(n), up(n), f(n), dg(n);
    for (newton_iterations = 0; newton_iterations < 100; ++newton_iterations) {
      double fmax = 0, gmax = 0;
      for (int i = 0; i < n; ++i) {
        const double gm = g_[i > 0 ? i - 1 : 1], gp = g_[i < n - 1 ? i + 1 : n - 2]; // ghost points: g' = 0
        f[i] = -r * (gm - 2 * g_[i] + gp) + (c.gp.mu_s - mu[i]) * g_[i] + cc[i] * g_[i] * g_[i];
        di[i] = 2 * r + (c.gp.mu_s - mu[i]) + 2 * cc[i] * g_[i];
        lo[i] = i > 0 ? -r : 0;
        up[i] = i < n - 1 ? -r : 0;
        fmax = std::max(fmax, std::fabs(f[i]));
        gmax = std::max(gmax, std::fabs(g_[i]));
      }
      up[0] = -2 * r;
      lo[n - 1] = -2 * r;
      // Thomas algorithm on J dg = -f.
      for (int i = 0; i < n; ++i) dg[i] = -f[i];
      for (int i = 1; i < n; ++i) {
        const double m = lo[i] / di[i - 1];
        di[i] -= m * up[i - 1];
        dg[i] -= m * dg[i - 1];
      }
      dg[n - 1] /= di[n - 1];
      for (int i = n - 2; i >= 0; --i) dg[i] = (dg[i] - up[i] * dg[i + 1]) / di[i];
      double step = 0;
      for (int i = 0; i < n; ++i) {
        g_[i] = std::max(0.0, g_[i] + dg[i]);
        step = std::max(step, std::fabs(dg[i]));
      }
      if (step < 1e-13 * gmax) break;
    }
  }
  integrate_velocity(c);
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
