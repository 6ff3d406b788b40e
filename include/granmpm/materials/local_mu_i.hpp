// Local mu(I) rheology, linearised about mu_s (Henann & Kamrin 2013), in the hypoelastic
// Jaumann frame of seed 000 (Algorithms 1 and 3). Pure per-particle kernels.
//
//   gdot_p = sqrt(p / (rho_s d^2)) (mu - mu_s) / b   if mu > mu_s, else 0
//          = (tau - mu_s p) / eta,  eta = b d sqrt(rho_s p)
//
// Plastic flow is deviatoric and codirectional with the stress deviator:
// Dp = gdot_p N / sqrt(2), N = sigma0/|sigma0|, so that tau drops by G dt gdot_p.
#pragma once

#include "granmpm/materials/elastic.hpp"

#include <algorithm>
#include <sstream>
#include <string>
#include <vector>

namespace granmpm {

struct GranularParams {
  double mu_s = 0.3819;  // static friction coefficient
  double mu_2 = 0.6435;  // limiting friction (only used to derive b)
  double I_0 = 0.278;    // inertial number scale (only used to derive b)
  double b = 18.754;     // (mu_2 - mu_s)/I_0 unless given directly
  double d = 0.05;       // grain diameter [m]
  double rho_s = 2450;   // grain (solid) density [kg/m^3]
  double A = 0.48;       // nonlocal amplitude
  double rho_c = 0;      // critical density below which the material is stress-free
};

// The granular family's options, declared once here with the parameters they set (the
// models mu_i, nonlocal and dynamic use them all; drucker_prager uses -rho_c): Config
// registers and parses them with -help from this table, the restart signature records the
// `signed_` ones (-mu_2 and -I_0 only derive b; -A is signed with the fluidity options),
// and granular_error checks them.
struct GranularOption {
  const char *option, *help;
  double GranularParams::*value;
  bool signed_;
};
inline const std::vector<GranularOption> &granular_options() {
  static const std::vector<GranularOption> v = {
      {"-mu_s", "Static friction coefficient mu_s", &GranularParams::mu_s, true},
      {"-mu_2", "Limiting friction coefficient mu_2 (> mu_s; with -I_0 gives b)", &GranularParams::mu_2, false},
      {"-I_0", "Inertial number scale I_0 (> 0; with -mu_2 gives b)", &GranularParams::I_0, false},
      {"-b", "Rheology slope b = (mu_2 - mu_s)/I_0 (overrides -mu_2/-I_0)", &GranularParams::b, true},
      {"-d", "Grain diameter [m]", &GranularParams::d, true},
      {"-rho_s", "Grain (solid) density [kg/m^3]", &GranularParams::rho_s, true},
      {"-A", "Nonlocal amplitude A (>= 0)", &GranularParams::A, false},
      {"-rho_c", "Critical density: below it a granular point is stress-free [kg/m^3]", &GranularParams::rho_c, true},
  };
  return v;
}

namespace granular_detail {
inline std::string fmt(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}
inline std::string mu2_I0_error(const GranularParams &g) {
  if (!(g.mu_2 > g.mu_s)) return "-mu_2 must be > -mu_s (got mu_2 = " + fmt(g.mu_2) + ", mu_s = " + fmt(g.mu_s) + ")";
  if (!(g.I_0 > 0)) return "-I_0 must be > 0 (got " + fmt(g.I_0) + ")";
  return "";
}
} // namespace granular_detail

// b from mu_2 and I_0 (when those are given and -b is not): the one place it is derived.
// Returns the error, or "".
inline std::string derive_b(GranularParams &g) {
  const std::string e = granular_detail::mu2_I0_error(g);
  if (e.empty()) g.b = (g.mu_2 - g.mu_s) / g.I_0;
  return e;
}

// The family's rules, one line naming the option ("": none broken).
inline std::string granular_error(const GranularParams &g) {
  using granular_detail::fmt;
  if (!(g.mu_s > 0)) return "-mu_s must be > 0 (got " + fmt(g.mu_s) + ")";
  if (!(g.b > 0)) return "-b must be > 0 (got " + fmt(g.b) + ")";
  if (!(g.d > 0)) return "-d must be > 0 (got " + fmt(g.d) + ")";
  if (!(g.rho_s > 0)) return "-rho_s must be > 0 (got " + fmt(g.rho_s) + ")";
  if (!(g.A >= 0)) return "-A must be >= 0 (got " + fmt(g.A) + ")";
  if (!(g.rho_c >= 0 && g.rho_c <= g.rho_s)) return "-rho_c must be in [0, rho_s = " + fmt(g.rho_s) + "] (got " + fmt(g.rho_c) + ")";
  return granular_detail::mu2_I0_error(g);
}

// (A d)^2, the coefficient of the nonlocal term: the one place it is formed (NonlocalNGF
// holds it as k; the fluidity solvers, which are built from the options, call this).
inline double nonlocal_k(const GranularParams &gp) { return std::pow(gp.A * gp.d, 2); }

// Local plastic shear rate for pressure p > 0 and shear stress tau.
inline double gdot_local(const GranularParams &g, double p, double tau) {
  if (!(p > 0)) return 0.0;
  const double excess = tau - g.mu_s * p;
  if (excess <= 0) return 0.0;
  return excess / (g.b * g.d * std::sqrt(g.rho_s * p));
}

// Remove sqrt(2) G dt gdot along the unit deviator direction N = dev/|dev| of `dir`,
// i.e. lower tau by G dt gdot. The correction is capped at the trial tau so that it never
// reverses the deviator (model.md, Algorithm 3 guard); returns the gdot actually applied.
// The same with the direction's deviator dev, its squared norm dev:dev and the trial tau
// given (the implicit update has them already).
inline double plastic_correct_dev(Mat3 &sigma_tr, const Mat3 &dev, double nrm2, double tau_tr, double G, double dt, double gdot) {
  if (gdot <= 0) return 0.0;
  const double nrm = std::sqrt(nrm2);
  if (nrm <= 0) return 0.0;
  if (G * dt * gdot > tau_tr) gdot = tau_tr / (G * dt);
  const double k = std::sqrt(2.0) * G * dt * gdot / nrm;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) sigma_tr(i, j) -= k * dev(i, j);
  return gdot;
}
inline double plastic_correct(Mat3 &sigma_tr, const Mat3 &dir, double G, double dt, double gdot) {
  if (gdot <= 0) return 0.0;
  const Mat3 dev = deviator(dir);
  return plastic_correct_dev(sigma_tr, dev, dev.cwiseProduct(dev).sum(), tau_of(sigma_tr), G, dt, gdot);
}

// Stress-free (no tension) rule shared by the granular models: p <= 0 or rho < rho_c.
inline bool stress_free(const GranularParams &g, const Mat3 &sigma, double rho) {
  return !(pressure(sigma) > 0) || rho < g.rho_c;
}

enum class StressUpdate { Implicit = 0, Explicit = 1 };

// Explicit updates are stable for G dt d(gdot)/d(tau) < 2: the rate G d(gdot)/d(tau) at a
// particle from the stress at the start of the step (with its fluidity g if has_g).
inline double explicit_plastic_rate(const ElasticModuli &el, const GranularParams &gp, const Mat3 &s, bool has_g, double g) {
  const double pn = pressure(s);
  if (!(pn > 0)) return 0.0;
  double r = 0;
  if (tau_of(s) > gp.mu_s * pn) r = 1.0 / (gp.b * gp.d * std::sqrt(gp.rho_s * pn));
  if (has_g) r = std::max(r, g / pn);
  return el.G * r;
}

struct LocalMuI {
  ElasticModuli el;
  GranularParams gp;
  StressUpdate scheme = StressUpdate::Implicit;

  static ModelInfo info() { return {"mu_i", "local mu(I) rheology (seed 000 Alg. 1/3)", {}, {{"gdot", 1}}, true}; }
  static LocalMuI make(const MaterialInputs &in) { return {in.el, *in.gran, in.stress_update}; }
  double step(Mat3 &sigma, const Mat3 &L, const PointIn &in, const PointState &) const { return update(sigma, L, in.dt, in.rho); }
  bool limits_dt() const { return scheme == StressUpdate::Explicit; }
  double stable_rate(const Mat3 &sigma_n, const PointIn &) const { return explicit_plastic_rate(el, gp, sigma_n, false, 0.0); }
  double dt_limit(double rate_max, double, double, int) const { return rate_max > 0 ? 2.0 / rate_max : 1e300; }

  // Returns the plastic shear rate used.
  inline double update(Mat3 &sigma, const Mat3 &L, double dt, double rho) const {
    const Mat3 sigma_n = sigma;
    Mat3 tr = elastic_trial(el, sigma_n, L, dt, true);
    double gdot = 0;
    if (scheme == StressUpdate::Implicit) {
      // Algorithm 1: closed-form backward-Euler return on tau at fixed trial pressure.
      // The trial deviator and its norm are formed once, element by element (tau_of and
      // plastic_correct each formed them again, as Eigen expressions: see elastic_trial).
      const double p = pressure(tr);
      if (p > 0) {
        Mat3 dev;
        double nrm2 = 0;
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            dev(i, j) = tr(i, j) + (i == j ? p : 0.0);
            nrm2 += dev(i, j) * dev(i, j);
          }
        const double tau = std::sqrt(0.5 * nrm2);
        if (tau > gp.mu_s * p) {
          const double eta = gp.b * gp.d * std::sqrt(gp.rho_s * p);
          gdot = (tau - gp.mu_s * p) / (eta + el.G * dt);
          gdot = plastic_correct_dev(tr, dev, nrm2, tau, el.G, dt, gdot);
        }
      }
    } else {
      // Algorithm 3: rate and direction from the stress at the start of the step.
      gdot = gdot_local(gp, pressure(sigma_n), tau_of(sigma_n));
      gdot = plastic_correct(tr, sigma_n, el.G, dt, gdot);
    }
    if (stress_free(gp, tr, rho)) {
      sigma.setZero();
      return 0.0;
    }
    sigma = tr;
    return gdot;
  }
};

} // namespace granmpm
