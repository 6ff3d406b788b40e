// A host's rigid bodies (rigid_body.hpp) as contact partners of the DEM grains.
//
// A body is one more wall entry of each grain near it (face 2 dim + 1 + k, spring key
// -(face + 1)), so its tangential springs travel, migrate and checkpoint like the walls'.
// Geometry from the body's signed distance s(x) and normal n at the grain centre: the
// nearest surface point is x - s n, so the kernel gets d = -s n (a grain centre inside
// the body, s <= 0, is an error: the step is too long for the body's or grain's speed).
// The relative velocity is the grain's minus the body's rigid velocity at that point.
// The body takes the opposite force at x + r d / |d| (where the grain's torque r n x F_t
// puts it) with its torque about z through the body centre, and the opposite rolling
// torque: linear and angular (z) momentum balance contact by contact.
//
// Lists: body k enters grain i's list when s_k(x_i) < r_i + skin; since the list build
// a grain moved at most D and the body surface at most B (translation + rotation times
// the reach), so the list stays complete while D + B <= skin (Engine::step rebuilds
// otherwise; the grain-grain rule 2 D <= skin is unchanged).
//
// Impulse: the grains' velocity updates take each force pass in halves (Verlet: 0.5 h at
// the end of its step and 0.5 h at the start of the next; Euler: h at the start of the
// next), and the body sums its force the same way (bimp_), so grains + body conserve
// momentum to round-off. take_body_impulse reduces it over the ranks once per host step
// and leaves the last pass's force on rank 0 only, so the state to checkpoint is the
// same on every rank count.
#include <cmath>

#include "granmpm/config.hpp"
#include "granmpm/dem/dem.hpp"
#include "internal.hpp"

namespace granmpm::dem {

using namespace detail;

void Engine::set_bodies(std::vector<BodySpec> specs, const std::vector<BodyMotionState> &start, double t0) {
  bspec_ = std::move(specs);
  bf_.assign(4 * bspec_.size(), 0.0);
  bprev_ = bimp_ = bf_;
  set_body_states(start, t0);
  blist_ = bnow_;
}

void Engine::set_body_states(const std::vector<BodyMotionState> &start, double t0) {
  bstart_ = start;
  bt0_ = t0;
  bodies_at(t0);
}

void Engine::bodies_at(double t) {
  bnow_.resize(bspec_.size());
  for (size_t k = 0; k < bspec_.size(); ++k) {
    const BodySpec &B = bspec_[k];
    BodyMotionState &s = bnow_[k];
    if (B.motion == BodyMotion::Kinematic) { // exactly its path at t
      s.pose = body_pose_at(B, t);
      kinematic_velocity_at(B, t, s.v);
      s.omega = B.omega;
    } else { // on at the host's start-of-step velocity
      s = bstart_[k];
      const double tau = t - bt0_;
      for (int d = 0; d < 3; ++d) s.pose.c[d] += tau * s.v[d];
      s.pose.angle += tau * s.omega;
    }
  }
}

double Engine::body_drift() const {
  double worst = 0;
  for (size_t k = 0; k < bspec_.size(); ++k) {
    const BodyPose &a = blist_[k].pose, &b = bnow_[k].pose;
    const double dc = std::sqrt((b.c[0] - a.c[0]) * (b.c[0] - a.c[0]) + (b.c[1] - a.c[1]) * (b.c[1] - a.c[1]) + (b.c[2] - a.c[2]) * (b.c[2] - a.c[2]));
    // Reach of a rotation about z: a box's corners; a plane's points where grains can be
    // (the box corners); disks and rings are unchanged by it.
    double reach = 0;
    const BodySpec &B = bspec_[k];
    if (B.shape == BodyShape::Box) reach = std::hypot(B.half[0], B.half[1]);
    if (B.shape == BodyShape::Plane)
      for (int cx = 0; cx < 2; ++cx)
        for (int cy = 0; cy < 2; ++cy)
          reach = std::max(reach, std::hypot((cx ? c_.hi[0] : c_.lo[0]) - a.c[0], (cy ? c_.hi[1] : c_.lo[1]) - a.c[1]));
    worst = std::max(worst, dc + std::fabs(b.angle - a.angle) * reach);
  }
  return worst;
}

namespace {
SdfResult sdf_at(int dim, const BodySpec &B, const BodyPose &P, const V3 &x) {
  const double xx[3] = {x.x, x.y, x.z};
  return dim == 3 ? body_sdf<3>(B, P, xx) : body_sdf<2>(B, P, xx);
}
} // namespace

void Engine::body_lists(long i, std::vector<int> &faces, double &max_ov, bool first) const {
  for (size_t k = 0; k < bspec_.size(); ++k) {
    const SdfResult s = sdf_at(c_.dim, bspec_[k], bnow_[k].pose, x_[i]);
    if (s.d < r_[i] + c_.skin) faces.push_back(-(2 * c_.dim + 2 + (int)k));
    if (first) max_ov = std::max(max_ov, (r_[i] - s.d) / r_[i]);
  }
}

V3 Engine::wall_sep(int face, const V3 &xi, V3 &vw) const {
  vw = V3{};
  const int dim = c_.dim;
  if (face < 2 * dim) {
    V3 d{};
    const int k = face / 2;
    comp(d, k) = (face % 2 == 0 ? c_.lo[k] : c_.hi[k]) - comp(xi, k);
    return d;
  }
  if (face == 2 * dim) return plate_point(xi) - xi;
  const int b = face - 2 * dim - 1;
  const SdfResult s = sdf_at(dim, bspec_[b], bnow_[b].pose, xi);
  if (!(s.d > 0)) return V3{}; // inside: no contact direction (check_bodies reports it)
  const V3 d = -s.d * V3{s.n[0], s.n[1], s.n[2]};
  const V3 xs = xi + d;
  const double xx[3] = {xs.x, xs.y, xs.z};
  double v[3] = {0, 0, 0};
  if (dim == 3) body_velocity_at<3>(bnow_[b].v, bnow_[b].omega, bnow_[b].pose, xx, v);
  else body_velocity_at<2>(bnow_[b].v, bnow_[b].omega, bnow_[b].pose, xx, v);
  vw = {v[0], v[1], v[2]};
  return d;
}

// The force and torque (about z through the body centre) on body b from the contact of
// grain i (at xi, radius ri, partner direction d) whose force on the grain is res.
void Engine::body_reaction(int b, const V3 &xi, double ri, const V3 &d, const ContactResult &res) {
  const V3 F = -res.force;
  const V3 xl = xi + (ri / norm(d)) * d; // where the grain's torque r n x F_t says it acts
  const double *c = bnow_[b].pose.c;
  double *o = &bf_[4 * b];
  o[0] += F.x;
  o[1] += F.y;
  o[2] += F.z;
  o[3] += (xl.x - c[0]) * F.y - (xl.y - c[1]) * F.x - res.troll.z;
}

void Engine::check_bodies(std::string &msg) const {
  if (!body_msg_.empty()) msg = body_msg_;
  for (long i = 0; i < nown_ && msg.empty(); ++i)
    for (size_t k = 0; k < bspec_.size(); ++k)
      if (!(sdf_at(c_.dim, bspec_[k], bnow_[k].pose, x_[i]).d > 0)) {
        msg = "grain " + std::to_string(id_[i]) + " has its centre inside rigid body " + std::to_string(k) + " (-body" + std::to_string(bspec_[k].index) +
              "_*) at t = " + std::to_string(t_) + ": lower -dt (the host step) or -dem_dt, stiffen -dem_wall_kn, or slow the body";
        break;
      }
}

std::vector<double> Engine::take_body_impulse() {
  const size_t n = bimp_.size();
  std::vector<double> buf(2 * n), all(2 * n);
  std::copy(bimp_.begin(), bimp_.end(), buf.begin());
  std::copy(bprev_.begin(), bprev_.end(), buf.begin() + n);
  MPI_Allreduce(buf.data(), all.data(), (int)buf.size(), MPI_DOUBLE, MPI_SUM, comm_);
  std::fill(bimp_.begin(), bimp_.end(), 0.0);
  for (size_t q = 0; q < n; ++q) bprev_[q] = rank_ == 0 ? all[n + q] : 0.0;
  return std::vector<double>(all.begin(), all.begin() + n);
}

} // namespace granmpm::dem
