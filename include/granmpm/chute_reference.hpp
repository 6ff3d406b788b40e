// Steady vertical-chute reference solutions (seed 000 appendix A; model.md section 4.1),
// computed for whatever parameters a run uses. Pure functions, no PETSc.
//
// Chute of width L, walls at s = +-L/2 (s measured from the centre line), steady state:
// p = p0 everywhere and sigma_xy = rho g s, so mu(s) = rho g |s| / p0.
#pragma once

#include <vector>

#include "granmpm/materials/local_mu_i.hpp"

namespace granmpm {

struct ChuteParams {
  GranularParams gp;
  double L = 1.0;    // width [m]
  double rho = 1500; // bulk density [kg/m^3]
  double g = 0.8;    // gravity magnitude [m/s^2]
  double p0 = 900;   // pressure [Pa]
};

// Local mu(I), analytic (appendix A.1): speed |v_y| at distance s from the centre line.
double chute_local_speed(const ChuteParams &c, double s);

// Nonlocal steady fluidity (appendix A.2): (A d)^2 g'' = |mu - mu_s| (g - g_loc) on
// [0, L/2] with g' = 0 at both ends, second-order finite differences on n points; then
// |dv/ds| = mu g integrated by the trapezoidal rule from v = 0 at the wall.
class NonlocalChuteReference {
public:
  NonlocalChuteReference(const ChuteParams &c, int n = 5001);
  double speed(double s) const; // |v_y| at distance s from the centre line (linear interp.)
  double fluidity(double s) const;
  const std::vector<double> &s() const { return s_; }
  const std::vector<double> &g() const { return g_; }
  const std::vector<double> &v() const { return v_; }

private:
protected:
  NonlocalChuteReference() = default;
  std::vector<double> s_, g_, v_;
  double ds_ = 0;
  double interp(const std::vector<double> &f, double s) const;
  void integrate_velocity(const ChuteParams &c);
};

// Steady state of the dynamical fluidity model (seed 004 eq. 6 with dg/dt = 0):
//   (A d)^2 g'' = (mu_s - mu) g + b sqrt(rho_s d^2 / p0) mu g^2,  g' = 0 at s = 0 and L/2,
// the flowing (positive) branch, by Newton's method on second-order finite differences
// from g = g_loc. Its homogeneous solution is g_loc, like the steady model's, but it is a
// different equation where g differs from g_loc: (A d)^2 g'' = |mu - mu_s| (g/g_loc)(g - g_loc)
// for mu > mu_s. The dynamical model converges to this profile, not to the steady one.
class DynamicChuteReference : public NonlocalChuteReference {
public:
  DynamicChuteReference(const ChuteParams &c, int n = 5001);
  int newton_iterations = 0;
};

} // namespace granmpm
