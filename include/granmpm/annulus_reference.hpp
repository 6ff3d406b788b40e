// Steady 2D annular (cylindrical Couette) shear references, computed for whatever
// parameters a run uses. Pure functions, no PETSc.
//
// Material between an inner cylinder of radius Ri rotating at Omega and a fixed outer
// cylinder of radius Ro, no gravity, plane strain. Steady axisymmetric state:
//   - torque balance: d(r^2 tau)/dr = 0, so tau(r) = T / r^2 with T constant;
//   - ASSUMPTION: uniform pressure p = p0 (no gravity; the initial isotropic pressure of
//     the scene is kept at steady state to a good approximation: normal-stress differences
//     of the hypoelastic model are neglected), so mu(r) = tau / p = T / (p r^2);
//   - kinematics: v_theta = r w(r); the shear rate is gdot = r |dw/dr| and, since tau
//     falls with r, dw/dr = -gdot / r;
//   - boundary conditions w(Ri) = Omega, w(Ro) = 0 (sticky walls): T is found by
//     bisection on w(Ri; T) = Omega (w(Ri) grows monotonically with T).
//
// Local mu(I) (the same linearised law as the chute's local reference):
//   gdot = sqrt(p/rho_s) (mu - mu_s) / (b d) where mu > mu_s, else 0;
//   w(r) = int_r^Ro gdot(s)/s ds in closed form; the yield radius r_y = sqrt(T/(mu_s p))
//   (where tau = mu_s p) is the edge of the shear band: w = 0 for r >= r_y.
//
// Nonlocal (the steady nonlocal granular fluidity of -material nonlocal, the same equation
// form as NonlocalChuteReference, with the axisymmetric Laplacian):
//   (A d)^2 (1/r) d/dr (r dg/dr) = |mu - mu_s| (g - g_loc),  g_loc = gdot_loc / mu,
//   dg/dr = 0 at r = Ri and Ro (zero flux; or g = 0 there with zero_g_walls), gdot = mu g,
// on n uniform points with second-order finite differences (conservative form
// (1/r_i) [r_{i+1/2} (g_{i+1} - g_i) - r_{i-1/2} (g_i - g_{i-1})] / dr^2, ghost points
// for the zero flux), then w by the trapezoidal rule from w(Ro) = 0.
#pragma once

#include <vector>

#include "granmpm/materials/local_mu_i.hpp"

namespace granmpm {

struct AnnulusParams {
  GranularParams gp;
  double Ri = 0.2, Ro = 0.4; // radii [m]
  double Omega = 0.1;        // inner angular velocity [rad/s]
  double p = 900;            // uniform pressure [Pa]
  bool zero_g_walls = false; // nonlocal: g = 0 at both walls (-body_fluidity_bc zero) instead of zero flux
};

// Local mu(I): closed-form angular velocity for a given torque T (per unit depth, divided
// by nothing: tau(r) = T / r^2).
double annulus_local_omega(const AnnulusParams &a, double T, double r);

class AnnulusReference {
public:
  // local = true: the local mu(I) solution (closed form in r, T by bisection); otherwise
  // the nonlocal finite-difference solution on n points (A = 0 gives the local law).
  AnnulusReference(const AnnulusParams &a, bool local, int n = 2001);
  double T() const { return sign_ * T_; }          // tau r^2 (the sign of Omega)
  double yield_radius() const;                     // sqrt(T / (mu_s p))
  double omega(double r) const;                    // angular velocity (linear interpolation)
  double v_theta(double r) const { return r * omega(r); }
  double gdot(double r) const;                     // shear rate
  const std::vector<double> &r() const { return r_; }
  const std::vector<double> &w() const { return w_; } // for |Omega|
  const std::vector<double> &g() const { return g_; }
  int bisection_iterations = 0;

private:
  AnnulusParams a_;
  bool local_ = true;
  double T_ = 0, dr_ = 0, sign_ = 1;
  std::vector<double> r_, w_, g_, gd_;
  double solve(double T); // fills the profiles for T; returns w(Ri)
  double interp(const std::vector<double> &f, double r) const;
};

} // namespace granmpm
