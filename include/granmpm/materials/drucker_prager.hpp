// Rate-independent Drucker-Prager plasticity in the hypoelastic Jaumann frame (seed 000
// appendix B: friction angle 30 deg, a small cohesion "for numerical purposes", no support
// below a density threshold; model.md §3.3). Pure per-particle kernel.
//
// Yield surface, in the invariants of model.md (tau = sqrt(J2), p = -tr(sigma)/3):
//   f = tau - (alpha p + k) <= 0.
// Seed 000 gives only phi and "a small cohesion", not how alpha and k follow from them, so
// the match to Mohr-Coulomb (phi, c) is a parameter (DPMatch):
//   PlaneStrain (default): alpha = sin(phi), k = c cos(phi). Exact Mohr-Coulomb match in
//     plane strain for this flow rule: deviatoric, codirectional plastic flow with
//     D_zz = 0 drives s_zz -> 0 in plastic flow, so sigma_zz = (s1 + s2)/2, tau is the Mohr
//     circle radius, p its centre, and MC reads tau = p sin(phi) + c cos(phi). It also
//     matches the mu = tau/p convention of the mu(I) kernels (simple shear with isotropic
//     normal stress: mu = sin(phi)). 2D runs are plane strain, so this is the default.
//   Compression: alpha = 2 sqrt3 sin(phi)/(3 - sin(phi)), k = 2 sqrt3 c cos(phi)/(3 - sin(phi))
//     (outer cone, touches MC on the triaxial-compression meridian; the usual 3D choice).
//   Extension: the same with 3 + sin(phi) (inner cone, triaxial extension meridian).
//
// Flow rule: non-associated, deviatoric (zero dilatancy, volume preserving) and
// codirectional with the trial deviator, as in the other granular kernels (model.md §3.1).
// The return is therefore radial in the deviatoric plane at fixed trial pressure and has
// the closed form sigma = -p_tr I + (tau_y/tau_tr) dev(sigma_tr), tau_y = alpha p_tr + k.
// The plastic shear increment is dgamma_p = (tau_tr - tau_y)/G (tau drops by G dgamma_p).
//
// Tension / apex: the cone's apex is at p = -k/alpha <= 0. With the no-tension rule of the
// granular kernels (model.md §3.1 pressure guard) a trial state with p_tr <= 0 is
// stress-free; that cut-off lies at or in front of the apex, so the apex itself (where the
// deviatoric return has no admissible point at fixed p) is never a return target.
// Density: rho < rho_c is stress-free (seed 000 uses rho_c = 0.9 rho_0).
#pragma once

#include "granmpm/materials/elastic.hpp"
#include "granmpm/materials/local_mu_i.hpp"
#include "granmpm/names.hpp"

#include <cmath>

namespace granmpm {

enum class DPMatch { PlaneStrain = 0, Compression = 1, Extension = 2 };
GM_NAMES(DPMatch, "plane_strain", "compression", "extension")

struct DruckerPrager {
  ElasticModuli el;
  double phi = 0;      // friction angle [rad]
  double cohesion = 0; // Mohr-Coulomb cohesion c >= 0 [Pa]; small, numerical
  double rho_c = 0;    // stress-free below this density
  DPMatch match = DPMatch::PlaneStrain;

  static ModelInfo info() {
    ModelInfo m{"drucker_prager", "Drucker-Prager plasticity (seed 000 appendix B)", {}, {{"gdot", 1}}, true};
    m.params.push_back({"-friction_angle", "Drucker-Prager friction angle [degrees]", 30, 0, 90, true, true, " degrees"});
    m.params.push_back({"-cohesion", "Drucker-Prager cohesion [Pa] (small, for numerics)", 0, 0});
    ParamDecl match{"-dp_match", "Drucker-Prager cone matched to Mohr-Coulomb in", 0};
    match.choices = names_list<DPMatch>();
    m.params.push_back(match);
    return m;
  }
  static DruckerPrager make(const MaterialInputs &in) {
    return {in.el, in.param("-friction_angle") * M_PI / 180.0, in.param("-cohesion"), in.gran->rho_c, (DPMatch)(int)in.param("-dp_match")};
  }
  double step(Mat3 &sigma, const Mat3 &L, const PointIn &in, const PointState &) const { return update(sigma, L, in.dt, in.rho); }

  // alpha = m sin(phi), k = m c cos(phi) with the meridian factor m of the chosen match.
  double match_factor() const {
    const double s = std::sin(phi);
    switch (match) {
    case DPMatch::Compression: return 2.0 * std::sqrt(3.0) / (3.0 - s);
    case DPMatch::Extension: return 2.0 * std::sqrt(3.0) / (3.0 + s);
    default: return 1.0;
    }
  }
  double alpha() const { return match_factor() * std::sin(phi); }
  double k() const { return match_factor() * cohesion * std::cos(phi); }
  double yield_tau(double p) const { return alpha() * p + k(); }

  // Returns the equivalent plastic shear rate gdot_p = dgamma_p/dt (0 for elastic or
  // stress-free steps), the rate form of the plastic multiplier as in LocalMuI::update.
  inline double update(Mat3 &sigma, const Mat3 &L, double dt, double rho) const {
    const Mat3 D = 0.5 * (L + L.transpose());
    const Mat3 W = 0.5 * (L - L.transpose());
    // Trial state: the Hypoelastic (Jaumann) step, written identically.
    sigma += dt * (el.apply(D) + jaumann_spin(sigma, W));
    const double p = pressure(sigma);
    if (!(p > 0) || rho < rho_c) {
      sigma.setZero();
      return 0.0;
    }
    const double tau_tr = tau_of(sigma), tau_y = yield_tau(p);
    if (tau_tr <= tau_y) return 0.0;
    // Radial return of the deviator at fixed p; tau_y > 0 here since p > 0, k >= 0.
    const Mat3 I = Mat3::Identity();
    sigma = (tau_y / tau_tr) * (sigma + p * I) - p * I;
    const double dgamma = (tau_tr - tau_y) / el.G;
    return dt > 0 ? dgamma / dt : 0.0;
  }
};

} // namespace granmpm
