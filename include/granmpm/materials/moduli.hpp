// Isotropic elastic moduli from (E, nu): shared by every model and by the material
// interface (model.hpp). Pure.
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

} // namespace granmpm
