// Kinematic rigid bodies on the background grid (issue 8).
//
// A body is a solid region described by a signed distance function (SDF): sdf(x) < 0
// inside the solid, > 0 in the material, and its gradient n = grad sdf is the unit
// outward normal of the solid (pointing into the material). Shapes, in the body frame:
//
//   plane : the half-space below the plane through the centre with normal n = (cos a, sin a)
//           rotated by the body angle a (the solid is on the -n side); sdf = (x - c) . n
//   box   : the rectangle (2D) / box (3D) of half extents -body<k>_half, rotated by the angle
//           about z
//   disk  : the disk of radius R (2D) / the cylinder of radius R with its axis along z (3D)
//   ring  : the inside-out cylinder: everything outside radius R is solid (an outer wall)
//
// Motion (-body<k>_motion):
//   kinematic (default): the centre follows a piecewise-linear path of waypoints (t_i, c_i)
//     (-body<k>_path; held at the first/last waypoint before/after them) or moves with a
//     constant velocity V; the angle grows at a constant angular velocity omega about z.
//   dynamic: mass M and moment of inertia I about the z axis through the centre (2D: per
//     unit depth, kg/m and kg m^2/m, like the N/m forces of the 2D grid), driven by the
//     contact force F and torque T of the grid, gravity M g, an applied force/torque and
//     optional damping. Locked degrees of freedom (x, y, z, rot) keep the constant velocity
//     V / omega of the options. Integrated once per step (dynamic_body_step) with the
//     reduced F, T, so every rank holds the same body state.
// In both cases the body's velocity at x is V + omega e_z x (x - c).
//
// Contact on the grid (Simulation::grid_update, after the explicit velocity update and
// before the wall boundary conditions): a node with mass whose sdf is below
// layer * h (-body_contact_layer, default 0.5 cells) is a contact node:
//   sticky   : v = v_body
//   friction : relative velocity w = v - v_body; if w . n < 0 (approaching) the normal part
//              is removed and Coulomb friction takes mu |w . n| off the tangential speed
//              (never reversing it); if w . n >= 0 the node separates freely.
// The layer of half a cell puts the outermost constrained node, on average over how the
// wall cuts the cells, on the wall itself (sdf < 0 alone would on average move the
// effective wall half a cell into the body).
//
// Order within a step: the grid contact of both grid updates of a step uses the body's
// pose and velocity at the START of the step; the force summed in the grid update with
// forces then advances a dynamic body (symplectic Euler, like the grid: v first, then
// the pose with the new v), and kinematic bodies are moved to the end-of-step time.
//
// Force and torque on a body: the impulse the body gives the grid at its contact nodes
// is sum m_i (v_after - v_before); the material pushes back on the body with
//   F = - sum m_i (v_after - v_before) / dt,  T = - sum (x_i - c) x m_i (v_after - v_before) / dt
// (owned nodes only, then MPI_Allreduce). Only the explicit-force grid update of a step
// contributes (USF/MUSL's second, force-free grid update does not count twice).
//
// Everything in this header except the RigidBodies class is pure (no PETSc, no MPI).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "granmpm/names.hpp"

namespace granmpm {

enum class BodyShape { Plane = 0, Box = 1, Disk = 2, Ring = 3 };
enum class BodyContact { Sticky = 0, Friction = 1 };
enum class BodyMotion { Kinematic = 0, Dynamic = 1 };
GM_NAMES(BodyShape, "plane", "box", "disk", "ring")
GM_NAMES(BodyContact, "sticky", "friction")
GM_NAMES(BodyMotion, "kinematic", "dynamic")
inline const char *to_string(BodyShape s) { return name_of(s); }

// What the options give for one body.
struct BodySpec {
  BodyShape shape = BodyShape::Disk;
  std::array<double, 3> center{{0, 0, 0}};
  double radius = 0.1;                          // disk, ring
  std::array<double, 3> half{{0.1, 0.1, 0.1}};   // box half extents
  double angle = 0;                             // initial rotation about z [rad]; plane: normal direction
  double omega = 0;                             // angular velocity about z [rad/s]
  std::array<double, 3> velocity{{0, 0, 0}};     // translation velocity [m/s]
  BodyContact contact = BodyContact::Sticky;
  double friction = 0;                          // Coulomb coefficient (friction contact)
  int index = 0;                                // k of its -body<k>_ options (messages)
  BodyMotion motion = BodyMotion::Kinematic;
  // Kinematic path: waypoints {t, x, y, z} with strictly increasing t (empty: constant velocity).
  std::vector<std::array<double, 4>> path;
  // Dynamic bodies. 2D: per unit depth (kg/m, kg m^2/m, N/m, N m/m).
  double mass = 0;                              // M [kg]
  double inertia = 0;                           // I about z through the centre [kg m^2]
  std::array<double, 3> force{{0, 0, 0}};       // applied force [N]
  double torque = 0;                            // applied torque about z [N m]
  double damping = 0;                           // linear velocity damping rate [1/s]
  double angular_damping = 0;                   // angular velocity damping rate [1/s]
  std::array<bool, 4> lock{{false, false, false, false}}; // x, y, z, rot: follow velocity/omega
};

// Moment of inertia about z of a uniform solid disk (z-cylinder) or box of mass M; 0 for
// shapes without a finite extent (plane, ring).
inline double uniform_inertia(const BodySpec &B) {
  if (B.shape == BodyShape::Disk) return 0.5 * B.mass * B.radius * B.radius;
  if (B.shape == BodyShape::Box) return B.mass * (B.half[0] * B.half[0] + B.half[1] * B.half[1]) / 3.0;
  return 0;
}

// Signed distance and outward unit normal at x.
struct SdfResult {
  double d = 0;
  double n[3] = {0, 0, 0};
};

// Body pose: centre and rotation angle about z.
struct BodyPose {
  double c[3] = {0, 0, 0};
  double angle = 0;
};

// x in the body frame: R(-angle) (x - c).
template <int dim>
inline void to_body_frame(const BodyPose &P, const double *x, double *q) {
  const double dx = x[0] - P.c[0], dy = x[1] - P.c[1];
  const double ca = std::cos(P.angle), sa = std::sin(P.angle);
  q[0] = ca * dx + sa * dy;
  q[1] = -sa * dx + ca * dy;
  q[2] = dim == 3 ? x[2] - P.c[2] : 0.0;
}

// A body-frame vector back to the world frame: R(angle) u.
inline void to_world_vector(const BodyPose &P, const double *u, double *w) {
  const double ca = std::cos(P.angle), sa = std::sin(P.angle);
  w[0] = ca * u[0] - sa * u[1];
  w[1] = sa * u[0] + ca * u[1];
  w[2] = u[2];
}

// Body-frame SDFs. Each returns the distance and fills the body-frame normal.
inline double sdf_plane_local(const double *q, double *n) {
  n[0] = 1;
  n[1] = n[2] = 0;
  return q[0];
}

// Disk (2D) / z-cylinder (3D): distance in the xy plane.
inline double sdf_disk_local(const double *q, double R, double *n) {
  const double r = std::hypot(q[0], q[1]);
  if (r > 0) {
    n[0] = q[0] / r;
    n[1] = q[1] / r;
  } else {
    n[0] = 1;
    n[1] = 0;
  }
  n[2] = 0;
  return r - R;
}

// Ring: solid outside radius R; the normal points to the axis.
inline double sdf_ring_local(const double *q, double R, double *n) {
  const double d = -sdf_disk_local(q, R, n);
  n[0] = -n[0];
  n[1] = -n[1];
  return d;
}

// Box of half extents hx, hy (, hz): exact Euclidean SDF, normal from its gradient.
template <int dim>
inline double sdf_box_local(const double *q, const double *half, double *n) {
  double a[3] = {0, 0, 0}, o[3] = {0, 0, 0}, out2 = 0;
  int imax = 0;
  double dmax = -1e300;
  for (int d = 0; d < dim; ++d) {
    a[d] = std::fabs(q[d]) - half[d];
    o[d] = std::max(a[d], 0.0);
    out2 += o[d] * o[d];
    if (a[d] > dmax) {
      dmax = a[d];
      imax = d;
    }
  }
  n[0] = n[1] = n[2] = 0;
  if (out2 > 0) {
    const double r = std::sqrt(out2);
    for (int d = 0; d < dim; ++d) n[d] = (q[d] < 0 ? -1.0 : 1.0) * o[d] / r;
    return r;
  }
  n[imax] = q[imax] < 0 ? -1.0 : 1.0; // inside: the nearest face
  return dmax;
}

// World-frame SDF of a shape at a pose.
template <int dim>
inline SdfResult body_sdf(const BodySpec &B, const BodyPose &P, const double *x) {
  double q[3], nl[3] = {0, 0, 0};
  to_body_frame<dim>(P, x, q);
  SdfResult r;
  switch (B.shape) {
  case BodyShape::Plane: r.d = sdf_plane_local(q, nl); break;
  case BodyShape::Box: r.d = sdf_box_local<dim>(q, B.half.data(), nl); break;
  case BodyShape::Disk: r.d = sdf_disk_local(q, B.radius, nl); break;
  case BodyShape::Ring: r.d = sdf_ring_local(q, B.radius, nl); break;
  }
  to_world_vector(P, nl, r.n);
  return r;
}

// Rigid velocity at x: V + omega e_z x (x - c).
template <int dim>
inline void body_velocity_at(const double *V, double omega, const BodyPose &P, const double *x, double *v) {
  v[0] = V[0] - omega * (x[1] - P.c[1]);
  v[1] = V[1] + omega * (x[0] - P.c[0]);
  if (dim == 3) v[2] = V[2];
}
template <int dim>
inline void body_velocity_at(const BodySpec &B, const BodyPose &P, const double *x, double *v) {
  body_velocity_at<dim>(B.velocity.data(), B.omega, P, x, v);
}

// Piecewise-linear path: position c and velocity v at time t. Within [t_i, t_i+1) the
// velocity is that segment's slope (right-continuous at waypoints); before the first and
// from the last waypoint on, the body rests there (v = 0).
inline void path_state(const std::vector<std::array<double, 4>> &path, double t, double *c, double *v) {
  const size_t n = path.size();
  for (int d = 0; d < 3; ++d) v[d] = 0;
  if (t < path[0][0]) {
    for (int d = 0; d < 3; ++d) c[d] = path[0][1 + d];
    return;
  }
  if (t >= path[n - 1][0]) {
    for (int d = 0; d < 3; ++d) c[d] = path[n - 1][1 + d];
    return;
  }
  size_t i = 0;
  while (!(t < path[i + 1][0])) ++i;
  const double dt = path[i + 1][0] - path[i][0], s = (t - path[i][0]) / dt;
  for (int d = 0; d < 3; ++d) {
    c[d] = path[i][1 + d] + s * (path[i + 1][1 + d] - path[i][1 + d]);
    v[d] = (path[i + 1][1 + d] - path[i][1 + d]) / dt;
  }
}

// Pose after time t from the initial one (kinematic: path or constant V; constant omega).
inline BodyPose body_pose_at(const BodySpec &B, double t) {
  BodyPose P;
  if (!B.path.empty()) {
    double v[3];
    path_state(B.path, t, P.c, v);
  } else
    for (int d = 0; d < 3; ++d) P.c[d] = B.center[d] + t * B.velocity[d];
  P.angle = B.angle + t * B.omega;
  return P;
}

// Velocity of a kinematic body at time t.
inline void kinematic_velocity_at(const BodySpec &B, double t, double *v) {
  if (!B.path.empty()) {
    double c[3];
    path_state(B.path, t, c, v);
  } else
    for (int d = 0; d < 3; ++d) v[d] = B.velocity[d];
}

// State of a dynamic body.
struct BodyMotionState {
  BodyPose pose;
  double v[3] = {0, 0, 0};
  double omega = 0;
};

// The 8 numbers of a body's motion state in checkpoints: c[3], angle, v[3], omega.
inline void append_motion_state(std::vector<double> &out, const BodyMotionState &s) {
  out.insert(out.end(), s.pose.c, s.pose.c + 3);
  out.push_back(s.pose.angle);
  out.insert(out.end(), s.v, s.v + 3);
  out.push_back(s.omega);
}
inline void read_motion_state(const double *q, BodyMotionState &s) {
  std::copy_n(q, 3, s.pose.c);
  s.pose.angle = q[3];
  std::copy_n(q + 4, 3, s.v);
  s.omega = q[7];
}

// One step of a dynamic body (symplectic Euler, as the grid): F[0..2] and F[3] are the
// contact force and torque of this step, g the gravity acceleration. Damping is taken
// implicitly (v / (1 + c dt): stable for any rate). Locked degrees of freedom take the
// prescribed velocity / omega. Then the pose moves with the new velocity.
template <int dim>
inline void dynamic_body_step(const BodySpec &B, const double *F, const double *g, double dt, BodyMotionState &s) {
  for (int d = 0; d < dim; ++d) {
    if (B.lock[d]) s.v[d] = B.velocity[d];
    else s.v[d] = (s.v[d] + dt * ((F[d] + B.force[d]) / B.mass + g[d])) / (1.0 + dt * B.damping);
  }
  if (B.lock[3]) s.omega = B.omega;
  else s.omega = (s.omega + dt * (F[3] + B.torque) / B.inertia) / (1.0 + dt * B.angular_damping);
  for (int d = 0; d < dim; ++d) s.pose.c[d] += dt * s.v[d];
  s.pose.angle += dt * s.omega;
}

// n points on the outline of body B at pose P in the xy plane at height z (for output),
// spaced by arc length: a circle for a disk/ring (equal angles), the boundary of a box
// (every corner a point, each side cut into segments of nearly equal length: n/2 split
// between an x side and a y side in proportion to their lengths), a segment of length
// 2 L centred at the point of the plane nearest to `mid` for a plane. The outline of a
// disk, ring or box is closed (the last point joins the first); a plane's is open.
inline bool body_outline_closed(const BodySpec &B) { return B.shape != BodyShape::Plane; }
inline std::vector<std::array<double, 3>> body_outline(const BodySpec &B, const BodyPose &P, const double *mid, double L, double z, int n) {
  std::vector<std::array<double, 3>> out(n);
  // Box: segments per x side and per y side (n even, both >= 1).
  const int half_n = n / 2;
  const int nx = B.shape == BodyShape::Box ? std::min(half_n - 1, std::max(1, (int)std::lround(half_n * B.half[0] / (B.half[0] + B.half[1])))) : 0;
  const int ny = half_n - nx;
  for (int i = 0; i < n; ++i) {
    double q[3] = {0, 0, 0};
    if (B.shape == BodyShape::Disk || B.shape == BodyShape::Ring) {
      const double th = 2 * M_PI * i / n;
      q[0] = B.radius * std::cos(th);
      q[1] = B.radius * std::sin(th);
    } else if (B.shape == BodyShape::Box) { // counter-clockwise from corner (-hx, -hy)
      const double hx = B.half[0], hy = B.half[1];
      if (i < nx) q[0] = -hx + 2 * hx * i / nx, q[1] = -hy;
      else if (i < nx + ny) q[0] = hx, q[1] = -hy + 2 * hy * (i - nx) / ny;
      else if (i < 2 * nx + ny) q[0] = hx - 2 * hx * (i - nx - ny) / nx, q[1] = hy;
      else q[0] = -hx, q[1] = hy - 2 * hy * (i - 2 * nx - ny) / ny;
    } else { // plane x = 0 in the body frame: along its y axis, through the foot of mid
      double m[3];
      to_body_frame<2>(P, mid, m);
      q[1] = m[1] + L * (2.0 * i / (n - 1) - 1.0);
    }
    double w[3];
    to_world_vector(P, q, w);
    out[i] = {{P.c[0] + w[0], P.c[1] + w[1], z}};
  }
  return out;
}

// Contact rule at one node: v is the node velocity (in/out), vb the body velocity there,
// n the body's outward normal. Returns true if the node velocity was changed.
template <int dim>
inline bool contact_velocity(BodyContact kind, double mu, const double *vb, const double *n, double *v) {
  if (kind == BodyContact::Sticky) {
    for (int d = 0; d < dim; ++d) v[d] = vb[d];
    return true;
  }
  double w[3] = {0, 0, 0}, wn = 0;
  for (int d = 0; d < dim; ++d) {
    w[d] = v[d] - vb[d];
    wn += w[d] * n[d];
  }
  if (wn >= 0) return false; // separating or sliding along: free
  double wt[3] = {0, 0, 0}, wt2 = 0;
  for (int d = 0; d < dim; ++d) {
    wt[d] = w[d] - wn * n[d];
    wt2 += wt[d] * wt[d];
  }
  const double wtn = std::sqrt(wt2);
  const double f = wtn > 0 ? std::max(0.0, 1.0 - mu * (-wn) / wtn) : 0.0;
  for (int d = 0; d < dim; ++d) v[d] = vb[d] + f * wt[d];
  return true;
}

// Rigid bodies of a run: their specs, their state (pose, velocity) at the current time,
// and the force and torque of the last step. The grid loop calls apply() per node; the
// caller reduces forces() and contact_mass() over the ranks, then calls advance().
template <int dim>
class RigidBodies {
public:
  RigidBodies() = default;
  RigidBodies(const std::vector<BodySpec> &specs, double h, double layer_cells) : specs_(specs), layer_(layer_cells * h) {
    state_.resize(specs.size());
    force_.assign(specs.size() * 4, 0.0);
    contact_.assign(specs.size() * 2, 0.0);
    for (size_t k = 0; k < specs.size(); ++k) { // dynamic bodies start from their options
      BodyMotionState &s = state_[k];
      s.pose = body_pose_at(specs[k], 0);
      for (int d = 0; d < 3; ++d) s.v[d] = specs[k].velocity[d];
      s.omega = specs[k].omega;
    }
    set_time(0);
  }
  size_t size() const { return specs_.size(); }
  const BodySpec &spec(size_t k) const { return specs_[k]; }
  const BodyPose &pose(size_t k) const { return state_[k].pose; }
  const double *velocity(size_t k) const { return state_[k].v; }
  double omega(size_t k) const { return state_[k].omega; }
  bool dynamic(size_t k) const { return specs_[k].motion == BodyMotion::Dynamic; }
  double layer() const { return layer_; }

  // Kinematic bodies to their prescribed state at time t (dynamic bodies keep theirs).
  void set_time(double t) {
    for (size_t k = 0; k < specs_.size(); ++k) {
      if (dynamic(k)) continue;
      state_[k].pose = body_pose_at(specs_[k], t);
      kinematic_velocity_at(specs_[k], t, state_[k].v);
      state_[k].omega = specs_[k].omega;
    }
  }
  // End of a step from t to t + dt: dynamic bodies integrate the (reduced) force sums of
  // the step with gravity g; kinematic bodies move to t + dt.
  void advance(double t, double dt, const double *g) {
    for (size_t k = 0; k < specs_.size(); ++k)
      if (dynamic(k)) dynamic_body_step<dim>(specs_[k], &force_[4 * k], g, dt, state_[k]);
    set_time(t + dt);
  }
  // Starts a step's force sums (local, before the reduction).
  void begin_forces() {
    std::fill(force_.begin(), force_.end(), 0.0);
    std::fill(contact_.begin(), contact_.end(), 0.0);
  }

  // Contact at the node at x with mass m; v in/out. When dt > 0 the momentum change is
  // added to the force sums (the caller passes dt = 0 for nodes it does not own).
  // Bodies are applied in order; a node in several layers ends with the last one's rule.
  void apply(const double *x, double m, double *v, double dt) {
    for (size_t k = 0; k < specs_.size(); ++k) {
      const BodyPose &P = state_[k].pose;
      const SdfResult s = body_sdf<dim>(specs_[k], P, x);
      if (!(s.d < layer_)) continue;
      double vb[3] = {0, 0, 0}, v0[3] = {0, 0, 0};
      body_velocity_at<dim>(state_[k].v, state_[k].omega, P, x, vb);
      for (int d = 0; d < dim; ++d) v0[d] = v[d];
      if (!contact_velocity<dim>(specs_[k].contact, specs_[k].friction, vb, s.n, v) || dt <= 0) continue;
      double dp[3] = {0, 0, 0};
      for (int d = 0; d < dim; ++d) {
        dp[d] = m * (v[d] - v0[d]);
        force_[4 * k + d] -= dp[d] / dt;
      }
      // Torque about z through the centre (the z-component of (x - c) x F).
      const double rx = x[0] - P.c[0], ry = x[1] - P.c[1];
      force_[4 * k + 3] -= (rx * dp[1] - ry * dp[0]) / dt;
      // Grid mass the body pushes this step (the added-mass stability check).
      contact_[2 * k] += m;
      contact_[2 * k + 1] += m * (rx * rx + ry * ry);
    }
  }
  // Force sums of this rank (4 per body: fx, fy, fz, torque_z); reduced by the caller.
  std::vector<double> &forces() { return force_; }
  const std::vector<double> &forces() const { return force_; }
  // Mass and z-moment of inertia (about the centre) of the grid nodes each body changed
  // in the last force update (2 per body); reduced by the caller.
  std::vector<double> &contact_mass() { return contact_; }

  // Everything that evolves: 8 numbers per body (c[3], angle, v[3], omega), then the 4
  // force sums per body (checkpoints).
  std::vector<double> state() const {
    std::vector<double> out;
    for (const BodyMotionState &s : state_) append_motion_state(out, s);
    out.insert(out.end(), force_.begin(), force_.end());
    return out;
  }
  bool set_state(const std::vector<double> &in) {
    if (in.size() != 12 * specs_.size()) return false;
    for (size_t k = 0; k < specs_.size(); ++k) read_motion_state(&in[8 * k], state_[k]);
    std::copy(in.begin() + 8 * specs_.size(), in.end(), force_.begin());
    return true;
  }

  // Is x inside body k deeper than 0 (sdf < 0)?
  double sdf(size_t k, const double *x) const { return body_sdf<dim>(specs_[k], state_[k].pose, x).d; }
  SdfResult sdf_full(size_t k, const double *x) const { return body_sdf<dim>(specs_[k], state_[k].pose, x); }

private:
  std::vector<BodySpec> specs_;
  std::vector<BodyMotionState> state_;
  std::vector<double> force_, contact_;
  double layer_ = 0;
};

} // namespace granmpm
