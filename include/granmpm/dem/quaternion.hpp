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
// |w| h about w / |w|, (cos a, sin(a) w / |w|) with a = |w| h / 2. Below a = 1e-3 the
// series of cos a and sin(a) / a to a^6 (truncation a^8 / 40320 < 3e-29, far below round-
// off): exact at w = 0 (no division by |w|) and without cancellation for tiny spins.
inline Quat rotation_step(const V3 &wv, double h) {
  const double wm = norm(wv), a = 0.5 * h * wm;
  double c, s; // cos a, and sin(a) / |w| (the factor of the vector part)
  if (a < 1e-3) {
    const double a2 = a * a;
    c = 1.0 - a2 * (1.0 / 2 - a2 * (1.0 / 24 - a2 * (1.0 / 720)));
    s = 0.5 * h * (1.0 - a2 * (1.0 / 6 - a2 * (1.0 / 120 - a2 * (1.0 / 5040))));
  } else {
    c = std::cos(a);
    s = std::sin(a) / wm;
  }
  return {c, s * wv.x, s * wv.y, s * wv.z};
}

// q after spinning at the world-frame angular velocity w for h: exp(h w / 2) q (dq/dt =
// (0, w) q / 2 integrated exactly for a constant w), renormalised so that round-off does
// not let |q| drift over millions of steps.
inline Quat rotate(const Quat &q, const V3 &wv, double h) {
  const Quat r = qmul(rotation_step(wv, h), q);
  const double n = 1.0 / std::sqrt(r.w * r.w + r.x * r.x + r.y * r.y + r.z * r.z);
  return {n * r.w, n * r.x, n * r.y, n * r.z};
}

// The body-frame vector b in the world frame: R(q) b = b + 2 w (u x b) + 2 u x (u x b), u the
// vector part of q (unit q).
inline V3 rotate_vector(const Quat &q, const V3 &b) {
  const V3 u{q.x, q.y, q.z};
  const V3 t = 2.0 * cross(u, b);
  return b + q.w * t + cross(u, t);
}

} // namespace granmpm::dem
