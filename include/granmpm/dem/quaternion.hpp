// Orientation of a 3D grain as a unit quaternion q = (w, x, y, z): the rotation taking the
// grain's body frame to the world frame (q = (1, 0, 0, 0) at creation). Pure kernels (no
// PETSc, no MPI), unit-tested against the closed-form rotation (tests/unit/test_dem_contact.cpp).
//
// Spheres need no orientation for their dynamics (contacts see only centres and spins); it
// is carried for output (ParaView's glyph orientation, "Quaternion" mode: w, x, y, z) and
// for later non-spherical or textured grains.
#pragma once

#include <cmath>

#include "granmpm/dem/contact.hpp"

namespace granmpm::dem {

struct Quat {
  double w = 1, x = 0, y = 0, z = 0;
};

// Hamilton product a b (rotation b first, then a).
inline Quat qmul(const Quat &a, const Quat &b) {
  return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y, a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
          a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}

// exp(h w / 2) for the world-frame angular velocity w held over h: the rotation by the angle
// |w| h about w / |w|, (cos a, sin(a) w / |w|) with a = |w| h / 2. Below a = 0.05 (every
// step of a DEM run: |w| up to ~1e3 rad/s at steps of ~1e-5 s gives a ~ 5e-3) the series
// of cos a and sin(a) / a to a^8 (truncation below a^10 / 3628800 < 3e-20, far below
// round-off), which needs only a^2: no square root or trigonometry per grain and step (they
// tripled the cost of the time integration), exact at w = 0, no division by |w|.
constexpr double kSeriesA2 = 2.5e-3; // a^2 below which rotation_step uses the series

// cos a and sin(a) / |w| by the series, for a^2 = a2 < kSeriesA2.
inline void rotation_series(double a2, double h, double &c, double &s) {
  c = 1.0 - a2 * (1.0 / 2 - a2 * (1.0 / 24 - a2 * (1.0 / 720 - a2 * (1.0 / 40320))));
  s = 0.5 * h * (1.0 - a2 * (1.0 / 6 - a2 * (1.0 / 120 - a2 * (1.0 / 5040 - a2 * (1.0 / 362880)))));
}

inline Quat rotation_step(const V3 &wv, double h) {
  const double a2 = 0.25 * h * h * dot(wv, wv);
  double c, s; // cos a, and sin(a) / |w| (the factor of the vector part)
  if (a2 < kSeriesA2) {
    rotation_series(a2, h, c, s);
  } else {
    const double wm = norm(wv), a = 0.5 * h * wm;
    c = std::cos(a);
    s = std::sin(a) / wm;
  }
  return {c, s * wv.x, s * wv.y, s * wv.z};
}

// r / |r| for |r| = 1 to round-off: |r|^2 = 1 + e with e of round-off size, so one Newton
// step for 1/sqrt, (3 - |r|^2) / 2 = 1 - e/2 (error 3 e^2 / 8, ~1e-32), is the exact factor
// to round-off, without a square root and a division.
inline Quat renormalised(const Quat &r) {
  const double n = 0.5 * (3.0 - (r.w * r.w + r.x * r.x + r.y * r.y + r.z * r.z));
  return {n * r.w, n * r.x, n * r.y, n * r.z};
}

// q after spinning at the world-frame angular velocity w for h: exp(h w / 2) q (dq/dt =
// (0, w) q / 2 integrated exactly for a constant w), renormalised so that round-off does
// not let |q| drift over millions of steps.
inline Quat rotate(const Quat &q, const V3 &wv, double h) { return renormalised(qmul(rotation_step(wv, h), q)); }

// rotate(q[i], w[i], h) for i < n, the same bits. The series branch runs as one pass without
// a branch or a call (with the per-grain branch to cos/sin in the loop, this update was two
// thirds of the time integration); the grains spinning beyond its range, if any, are
// turned by rotate() in a second pass.
inline void rotate_all(Quat *__restrict q, const V3 *__restrict w, long n, double h) {
  bool all_series = true;
  for (long i = 0; i < n; ++i) {
    const V3 wv = w[i];
    const double a2 = 0.25 * h * h * dot(wv, wv);
    const bool series = a2 < kSeriesA2;
    all_series = all_series && series;
    double c, s;
    rotation_series(a2, h, c, s);
    const Quat r = renormalised(qmul({c, s * wv.x, s * wv.y, s * wv.z}, q[i]));
    if (series) q[i] = r;
  }
  if (all_series) return;
  for (long i = 0; i < n; ++i)
    if (!(0.25 * h * h * dot(w[i], w[i]) < kSeriesA2)) q[i] = rotate(q[i], w[i], h);
}

// The body-frame vector b in the world frame: R(q) b = b + 2 w (u x b) + 2 u x (u x b), u the
// vector part of q (unit q).
inline V3 rotate_vector(const Quat &q, const V3 &b) {
  const V3 u{q.x, q.y, q.z};
  const V3 t = 2.0 * cross(u, b);
  return b + q.w * t + cross(u, t);
}

} // namespace granmpm::dem
