// Steady nonlocal granular fluidity (seed 000 Algorithm 2; model.md section 3.1).
// The fluidity g = gdot_p / mu solves, on the grid,
//   -(A d)^2 lap g + |mu - mu_s| g = |mu - mu_s| g_loc
// (FluiditySolver assembles and solves it). These kernels give the per-particle inputs of
// that system from the stress at the start of the step, and the stress update once g is
// known (Algorithm 3 with gdot = mu g).
#pragma once

#include "granmpm/materials/local_mu_i.hpp"

namespace granmpm {

struct FluiditySource {
  double weight; // |mu - mu_s|: the screening coefficient at the particle
  double g_loc;  // local fluidity gdot_loc / mu (0 where mu <= mu_s or p <= 0)
};

inline FluiditySource fluidity_source(const GranularParams &gp, const Mat3 &sigma) {
  const double p = pressure(sigma);
  if (!(p > 0)) return {gp.mu_s, 0.0}; // stress-free point: mu = 0, no local flow
  const double tau = tau_of(sigma);
  const double mu = tau / p;
  const double gl = (mu > gp.mu_s) ? gdot_local(gp, p, tau) / mu : 0.0;
  return {std::fabs(mu - gp.mu_s), gl};
}

// Stress update once g is known.
//  explicit (seed 000 Algorithm 2/3): gdot = mu_n g with mu_n and the flow direction from
//    the stress at the start of the step. Stable only for G dt / eta < 2 in flowing
//    regions (eta = b d sqrt(rho_s p)); Simulation limits the automatic step accordingly.
//  implicit: gdot = mu_{n+1} g with mu_{n+1} = tau_{n+1}/p_tr along the trial deviator,
//    which has the closed form tau_{n+1} = tau_tr p / (p + G dt g) (as in seed 004) and
//    no step limit from the plastic relaxation.
struct NonlocalNGF {
  ElasticModuli el;
  GranularParams gp;
  StressUpdate scheme = StressUpdate::Implicit;
  double k = 0; // (A d)^2, the coefficient of the nonlocal term (nonlocal_k)

  static ModelInfo info() { return {"nonlocal", "steady nonlocal granular fluidity (seed 000 Alg. 2)", {}, {{"fluidity", 1}, {"gdot", 1}}, true}; }
  static NonlocalNGF make(const MaterialInputs &in) { return {in.el, *in.gran, in.stress_update, nonlocal_k(*in.gran)}; }
  double step(Mat3 &sigma, const Mat3 &L, const PointIn &in, const PointState &) const { return update(sigma, L, in.dt, in.rho, in.g); }
  bool limits_dt() const { return scheme == StressUpdate::Explicit; }
  double stable_rate(const Mat3 &sigma_n, const PointIn &in) const { return explicit_plastic_rate(el, gp, sigma_n, true, in.g); }
  double dt_limit(double rate_max, double, double, int) const { return rate_max > 0 ? 2.0 / rate_max : 1e300; }

  // g: the fluidity mapped back from the grid to this particle.
  inline double update(Mat3 &sigma, const Mat3 &L, double dt, double rho, double g) const {
    const Mat3 D = 0.5 * (L + L.transpose());
    const Mat3 W = 0.5 * (L - L.transpose());
    const Mat3 sigma_n = sigma;
    Mat3 tr = sigma_n + dt * (el.apply(D) + jaumann_spin(sigma_n, W));
    double gdot = 0;
    if (scheme == StressUpdate::Implicit) {
      const double p = pressure(tr), tau_tr = tau_of(tr);
      if (p > 0 && g > 0 && tau_tr > 0 && dt > 0) {
        // tau = tau_tr s, s = p / (p + G dt g) in (0, 1]: the trial deviator scaled by s at
        // the trial pressure (what plastic_correct along the trial direction gives, without
        // recomputing the deviator, its norm and tau; never capped since s > 0).
        const double s = p / (p + el.G * dt * g);
        tr = s * tr - ((1.0 - s) * p) * Mat3::Identity();
        gdot = tau_tr * (1.0 - s) / (el.G * dt);
      }
    } else {
      const double p = pressure(sigma_n);
      if (p > 0 && g > 0) gdot = plastic_correct(tr, sigma_n, el.G, dt, (tau_of(sigma_n) / p) * g);
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
