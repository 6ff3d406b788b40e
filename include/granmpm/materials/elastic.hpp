// Isotropic elasticity in rate form: the elastic part shared by every hypoelastic model.
// Pure per-particle kernels: no PETSc, no MPI.
#pragma once

#include "granmpm/tensor.hpp"

namespace granmpm {

struct ElasticModuli {
  double E = 0, nu = 0, K = 0, G = 0, lambda = 0;
  static ElasticModuli from_E_nu(double E, double nu) {
    ElasticModuli m;
    m.E = E;
    m.nu = nu;
    m.K = E / (3.0 * (1.0 - 2.0 * nu));
    m.G = E / (2.0 * (1.0 + nu));
    m.lambda = m.K - 2.0 * m.G / 3.0;
    return m;
  }
  // P-wave modulus K + 4G/3: sets the elastic wave speed c = sqrt(M/rho) of the CFL limit.
  double p_wave() const { return K + 4.0 * G / 3.0; }
  // C : D for the isotropic stiffness C = (K - 2G/3) I(x)I + 2G II.
  Mat3 apply(const Mat3 &D) const { return lambda * D.trace() * Mat3::Identity() + 2.0 * G * D; }
};

// Jaumann co-rotational term W sigma - sigma W (sigma_dot = C:D + W sigma - sigma W).
inline Mat3 jaumann_spin(const Mat3 &sigma, const Mat3 &W) { return W * sigma - sigma * W; }

// Small-strain linear elasticity: sigma += dt C:D. No objective rate, so only valid for
// small rotations (the bar and column verification cases).
struct LinearElastic {
  ElasticModuli el;
  inline double update(Mat3 &sigma, const Mat3 &L, double dt) const {
    const Mat3 D = 0.5 * (L + L.transpose());
    sigma += dt * el.apply(D);
    return 0.0;
  }
};

// Hypoelastic with the Jaumann rate: objective under rigid rotation.
struct Hypoelastic {
  ElasticModuli el;
  inline double update(Mat3 &sigma, const Mat3 &L, double dt) const {
    const Mat3 D = 0.5 * (L + L.transpose());
    const Mat3 W = 0.5 * (L - L.transpose());
    sigma += dt * (el.apply(D) + jaumann_spin(sigma, W));
    return 0.0;
  }
};

} // namespace granmpm
