// Isotropic elasticity in rate form: the elastic part shared by every hypoelastic model.
// Pure per-particle kernels: no PETSc, no MPI.
#pragma once

#include "granmpm/materials/model.hpp"
#include "granmpm/materials/moduli.hpp"
#include "granmpm/tensor.hpp"

namespace granmpm {

// Jaumann co-rotational term W sigma - sigma W (sigma_dot = C:D + W sigma - sigma W) of a
// symmetric sigma (every stress here is: stored as six numbers) and an antisymmetric W:
// then sigma W = -(W sigma)^T, so one product suffices (the second one was a third of the
// mu(I) update).
inline Mat3 jaumann_spin(const Mat3 &sigma, const Mat3 &W) {
  const Mat3 M = W * sigma;
  return M + M.transpose();
}

// The elastic trial stress sigma + dt (C:D [+ W sigma - sigma W]) of a symmetric sigma, with
// D and W the symmetric and antisymmetric parts of L, element by element. (As Eigen
// expressions it compiled to packet loads of matrices just stored element by element, which
// store forwarding cannot serve: a stall on each, a third of the elastic and mu(I) updates.)
inline Mat3 elastic_trial(const ElasticModuli &el, const Mat3 &sigma, const Mat3 &L, double dt, bool spin) {
  const double ltr = el.lambda * (L(0, 0) + L(1, 1) + L(2, 2)), G2 = 2.0 * el.G;
  double M[3][3] = {}; // W sigma; sigma W = -(W sigma)^T
  if (spin)
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k) M[i][j] += 0.5 * (L(i, k) - L(k, i)) * sigma(k, j);
  Mat3 t;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) t(i, j) = sigma(i, j) + dt * ((i == j ? ltr : 0.0) + G2 * (0.5 * (L(i, j) + L(j, i))) + (M[i][j] + M[j][i]));
  return t;
}

// Small-strain linear elasticity: sigma += dt C:D. No objective rate, so only valid for
// small rotations (the bar and column verification cases).
struct LinearElastic {
  ElasticModuli el;
  static ModelInfo info() { return {"elastic", "small-strain linear elasticity (no objective rate)", {}, {}}; }
  static LinearElastic make(const MaterialInputs &in) { return {in.el}; }
  double step(Mat3 &sigma, const Mat3 &L, const PointIn &in, const PointState &) const { return update(sigma, L, in.dt); }
  inline double update(Mat3 &sigma, const Mat3 &L, double dt) const {
    sigma = elastic_trial(el, sigma, L, dt, false);
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
    sigma = elastic_trial(el, sigma, L, dt, true);
    return 0.0;
  }
};

} // namespace granmpm
