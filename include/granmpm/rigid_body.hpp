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
// Kinematics: a body moves with constant velocity V and constant angular velocity omega
// about z through its centre c (rigid transform: position c(t), angle a(t)). Its velocity
// at x is V + omega e_z x (x - c).
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
// Force and torque on a body: the impulse the body gives the grid at its contact nodes
// is sum m_i (v_after - v_before); the material pushes back on the body with
//   F = - sum m_i (v_after - v_before) / dt,  T = - sum (x_i - c) x m_i (v_after - v_before) / dt
// (owned nodes only, then MPI_Allreduce). Only the explicit-force grid update of a step
// contributes (USF/MUSL's second, force-free grid update does not count twice).
//
// Everything in this header except the RigidBodies class is pure (no PETSc, no MPI).
#pragma once

#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace granmpm {

enum class BodyShape { Plane = 0, Box = 1, Disk = 2, Ring = 3 };
enum class BodyContact { Sticky = 0, Friction = 1 };

inline const char *to_string(BodyShape s) {
  switch (s) {
  case BodyShape::Plane: return "plane";
  case BodyShape::Box: return "box";
  case BodyShape::Disk: return "disk";
  case BodyShape::Ring: return "ring";
  }
  return "?";
}

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
};

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
inline void body_velocity_at(const BodySpec &B, const BodyPose &P, const double *x, double *v) {
  v[0] = B.velocity[0] - B.omega * (x[1] - P.c[1]);
  v[1] = B.velocity[1] + B.omega * (x[0] - P.c[0]);
  if (dim == 3) v[2] = B.velocity[2];
}

// Pose after time t from the initial one (constant V and omega).
inline BodyPose body_pose_at(const BodySpec &B, double t) {
  BodyPose P;
  for (int d = 0; d < 3; ++d) P.c[d] = B.center[d] + t * B.velocity[d];
  P.angle = B.angle + t * B.omega;
  return P;
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

// Kinematic bodies of a run: their specs, their pose at the current time, and the force
// and torque of the last step. The grid loop calls apply() per node; finish_step() reduces.
template <int dim>
class RigidBodies {
public:
  RigidBodies() = default;
  RigidBodies(const std::vector<BodySpec> &specs, double h, double layer_cells) : specs_(specs), layer_(layer_cells * h) {
    poses_.resize(specs.size());
    force_.assign(specs.size() * 4, 0.0);
    set_time(0);
  }
  size_t size() const { return specs_.size(); }
  const BodySpec &spec(size_t k) const { return specs_[k]; }
  const BodyPose &pose(size_t k) const { return poses_[k]; }
  double layer() const { return layer_; }

  void set_time(double t) {
    for (size_t k = 0; k < specs_.size(); ++k) poses_[k] = body_pose_at(specs_[k], t);
  }
  // Starts a step's force sums (local, before the reduction).
  void begin_forces() { std::fill(force_.begin(), force_.end(), 0.0); }

  // Contact at the node at x with mass m; v in/out. When dt > 0 the momentum change is
  // added to the force sums (the caller passes dt = 0 for nodes it does not own).
  // Bodies are applied in order; a node in several layers ends with the last one's rule.
  void apply(const double *x, double m, double *v, double dt) {
    for (size_t k = 0; k < specs_.size(); ++k) {
      const SdfResult s = body_sdf<dim>(specs_[k], poses_[k], x);
      if (!(s.d < layer_)) continue;
      double vb[3] = {0, 0, 0}, v0[3] = {0, 0, 0};
      body_velocity_at<dim>(specs_[k], poses_[k], x, vb);
      for (int d = 0; d < dim; ++d) v0[d] = v[d];
      if (!contact_velocity<dim>(specs_[k].contact, specs_[k].friction, vb, s.n, v) || dt <= 0) continue;
      double dp[3] = {0, 0, 0};
      for (int d = 0; d < dim; ++d) {
        dp[d] = m * (v[d] - v0[d]);
        force_[4 * k + d] -= dp[d] / dt;
      }
      // Torque about z through the centre (the z-component of (x - c) x F).
      force_[4 * k + 3] -= ((x[0] - poses_[k].c[0]) * dp[1] - (x[1] - poses_[k].c[1]) * dp[0]) / dt;
    }
  }
  // Force sums of this rank (4 per body: fx, fy, fz, torque_z); reduced by the caller.
  std::vector<double> &forces() { return force_; }
  const std::vector<double> &forces() const { return force_; }

  // Is x inside body k deeper than 0 (sdf < 0)?
  double sdf(size_t k, const double *x) const { return body_sdf<dim>(specs_[k], poses_[k], x).d; }
  SdfResult sdf_full(size_t k, const double *x) const { return body_sdf<dim>(specs_[k], poses_[k], x); }

private:
  std::vector<BodySpec> specs_;
  std::vector<BodyPose> poses_;
  std::vector<double> force_;
  double layer_ = 0;
};

} // namespace granmpm
