// Small tensor helpers on Eigen fixed-size types. Stress is stored per particle as six
// numbers (xx, yy, zz, xy, yz, xz) in 2D and 3D alike: plane strain keeps sigma_zz, so the
// constitutive kernels always work with the 3D invariants.
#pragma once

#include <Eigen/Dense>
#include <cmath>

namespace granmpm {

using Mat3 = Eigen::Matrix3d;
using Vec3 = Eigen::Vector3d;

inline Mat3 sym6_to_mat(const double *s) {
  Mat3 m; // element by element: the comma initializer was not inlined (once per particle and step)
  m(0, 0) = s[0], m(0, 1) = s[3], m(0, 2) = s[5];
  m(1, 0) = s[3], m(1, 1) = s[1], m(1, 2) = s[4];
  m(2, 0) = s[5], m(2, 1) = s[4], m(2, 2) = s[2];
  return m;
}

inline void mat_to_sym6(const Mat3 &m, double *s) {
  s[0] = m(0, 0);
  s[1] = m(1, 1);
  s[2] = m(2, 2);
  s[3] = 0.5 * (m(0, 1) + m(1, 0));
  s[4] = 0.5 * (m(1, 2) + m(2, 1));
  s[5] = 0.5 * (m(0, 2) + m(2, 0));
}

// Pressure p = -tr(sigma)/3 (compression positive).
inline double pressure6(const double *s) { return -(s[0] + s[1] + s[2]) / 3.0; }

// Equivalent shear stress tau = sqrt(sigma0:sigma0 / 2) of a symmetric tensor in sym6 form.
inline double tau6(const double *s) {
  const double p = pressure6(s);
  const double a = s[0] + p, b = s[1] + p, c = s[2] + p;
  const double j2 = 0.5 * (a * a + b * b + c * c) + s[3] * s[3] + s[4] * s[4] + s[5] * s[5];
  return std::sqrt(j2);
}

inline double pressure(const Mat3 &s) { return -s.trace() / 3.0; }
inline Mat3 deviator(const Mat3 &s) { return s - (s.trace() / 3.0) * Mat3::Identity(); }
inline double tau_of(const Mat3 &s) {
  const Mat3 d = deviator(s);
  return std::sqrt(0.5 * d.cwiseProduct(d).sum());
}

} // namespace granmpm
