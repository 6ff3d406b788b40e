// Isotropic elasticity in rate form: the elastic part shared by every hypoelastic model.
// Pure per-particle kernels: no PETSc, no MPI.
#pragma once

#include "granmpm/materials/model.hpp"
#include "granmpm/materials/moduli.hpp"
#include "granmpm/tensor.hpp"

namespace granmpm {

// Jaumann co-rotational term W sigma - sigma W (sigma_dot = C:D + W sigma - sigma W).
inline Mat3 jaumann_spin(const Mat3 &sigma, const Mat3 &W) { return W * sigma - sigma * W; }

// Small-strain linear elasticity: sigma += dt C:D. No objective rate, so only valid for
// small rotations (the bar and column verification cases).
struct LinearElastic {
  ElasticModuli el;
  static ModelInfo info() { return {"elastic", "small-strain linear elasticity (no objective rate)", {}, {}}; }
  static LinearElastic make(const MaterialInputs &in) { return {in.el}; }
  double step(Mat3 &sigma, const Mat3 &L, const PointIn &in, const PointState &) const { return update(sigma, L, in.dt); }
  inline double update(Mat3 &sigma, const Mat3 &L, double dt) const {
    const Mat3 D = 0.5 * (L + L.transpose());
    sigma += dt * el.apply(D);
    return 0.0;
  }
};

// Hypoelastic with the Jaumann rate: objective under rigid rotation.
struct Hypoelastic {
  ElasticModuli el;
  static ModelInfo info() { return {"hypoelastic", "hypoelasticity with the Jaumann rate", {}, {}}; }
  static Hypoelastic make(const MaterialInputs &in) { return {in.el}; }
  double step(Mat3 &sigma, const Mat3 &L, const PointIn &in, const PointState &) const { return update(sigma, L, in.dt); }
  inline double update(Mat3 &sigma, const Mat3 &L, double dt) const {
    const Mat3 D = 0.5 * (L + L.transpose());
    const Mat3 W = 0.5 * (L - L.transpose());
    sigma += dt * (el.apply(D) + jaumann_spin(sigma, W));
    return 0.0;
  }
};

} // namespace granmpm
