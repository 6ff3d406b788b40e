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
// momentum to round-off. Each force pass gathers every rank's contact forces on the bodies
// and sums them in grain-id order (sum_body_hits): the bodies' forces, impulses and so
// their motion have the same bits on every rank and every rank count.
#include <algorithm>
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
void Engine::body_reaction(int64_t id, int b, const V3 &xi, double ri, const V3 &d, const ContactResult &res) {
  const V3 F = -res.force;
  const V3 xl = xi + (ri / norm(d)) * d; // where the grain's torque r n x F_t says it acts
  const double *c = bnow_[b].pose.c;
  bhits_.push_back({id, b, {F.x, F.y, F.z, (xl.x - c[0]) * F.y - (xl.y - c[1]) * F.x - res.troll.z}});
}

// A grain has one entry per body, so (grain id, body) orders the contacts of a pass the
// same way on every decomposition; every rank sums all of them in that order.
void Engine::sum_body_hits() {
  std::vector<BodyHit> all;
  {
    const int n = (int)(bhits_.size() * sizeof(BodyHit));
    std::vector<int> cnt(size_), off(size_ + 1, 0);
    MPI_Allgather(&n, 1, MPI_INT, cnt.data(), 1, MPI_INT, comm_);
    for (int r = 0; r < size_; ++r) off[r + 1] = off[r] + cnt[r];
    all.resize(off[size_] / sizeof(BodyHit));
    MPI_Allgatherv(bhits_.data(), n, MPI_BYTE, all.data(), cnt.data(), off.data(), MPI_BYTE, comm_);
  }
  std::sort(all.begin(), all.end(), [](const BodyHit &p, const BodyHit &q) { return p.id != q.id ? p.id < q.id : p.b < q.b; });
  std::fill(bf_.begin(), bf_.end(), 0.0);
  for (const BodyHit &h : all)
    for (int q = 0; q < 4; ++q) bf_[4 * h.b + q] += h.f[q];
  bhits_.clear();
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

std::vector<double> Engine::take_body_impulse(std::vector<double> *last) {
  std::vector<double> imp = bimp_; // (every rank holds the whole sum: sum_body_hits)
  std::fill(bimp_.begin(), bimp_.end(), 0.0);
  if (last) *last = bprev_;
  return imp;
}

// ---- The standalone run's own bodies (Config::bodies, granmpm -dem) ----
//
// Without a host the engine moves the bodies itself, as velocity Verlet like the grains:
// a dynamic body's half kick with the last pass's contact force F(t) (and its applied force,
// gravity), the drift of its pose through the grains' step at that half-step velocity
// (set_body_states: the contacts see it, as the grains' damping sees theirs), and the step's
// impulse I = h/2 (F(t) + F(t + h)) (take_body_impulse: exactly the momentum the grains lost
// to it) for its new velocity V + I / M. Grains + free body conserve momentum to round-off.
// Forward Euler: no half kick (the pose moves at V), I = h F(t). Damping is implicit, as in
// dynamic_body_step; locked degrees of freedom keep their prescribed velocity. Kinematic
// bodies follow their path (bodies_at).

void Engine::own_bodies_setup() {
  std::vector<BodyMotionState> s(c_.bodies.size());
  for (size_t k = 0; k < s.size(); ++k) { // as RigidBodies starts them: the options' velocity
    const BodySpec &B = c_.bodies[k];
    s[k].pose = body_pose_at(B, 0);
    for (int d = 0; d < 3; ++d) s[k].v[d] = B.velocity[d];
    s[k].omega = B.omega;
  }
  set_bodies(c_.bodies, s, 0.0);
  bst_ = s;
  blast_.assign(4 * s.size(), 0.0);
  bmean_ = blast_;
  own_bodies_ = true;
}

namespace {
// v of a free degree of freedom after h of the acceleration a with implicit damping c.
double kick(double v, double a, double h, double c) { return (v + h * a) / (1.0 + h * c); }
} // namespace

void Engine::step_with_bodies() {
  const double h = dt_;
  const bool verlet = c_.integrator == Integrator::Verlet;
  const int dim = c_.dim;
  std::vector<BodyMotionState> half = bst_;
  for (size_t k = 0; k < bspec_.size(); ++k) {
    const BodySpec &B = bspec_[k];
    if (B.motion != BodyMotion::Dynamic || !verlet) continue;
    const double *F = &blast_[4 * k];
    for (int d = 0; d < dim; ++d)
      half[k].v[d] = B.lock[d] ? B.velocity[d] : kick(bst_[k].v[d], (F[d] + B.force[d]) / B.mass + c_.gravity[d], 0.5 * h, B.damping);
    half[k].omega = B.lock[3] ? B.omega : kick(bst_[k].omega, (F[3] + B.torque) / B.inertia, 0.5 * h, B.angular_damping);
  }
  set_body_states(half, t_);
  step(h);
  const std::vector<double> imp = take_body_impulse(&blast_);
  for (size_t k = 0; k < bspec_.size(); ++k) {
    const BodySpec &B = bspec_[k];
    BodyMotionState &s = bst_[k];
    const double *I = &imp[4 * k];
    for (int q = 0; q < 4; ++q) bmean_[4 * k + q] = I[q] / h;
    if (B.motion != BodyMotion::Dynamic) { // exactly its path at the new time
      s.pose = body_pose_at(B, t_);
      kinematic_velocity_at(B, t_, s.v);
      s.omega = B.omega;
      continue;
    }
    s.pose = bnow_[k].pose; // where the step's contacts saw it
    for (int d = 0; d < dim; ++d)
      s.v[d] = B.lock[d] ? B.velocity[d] : kick(s.v[d] + I[d] / B.mass, B.force[d] / B.mass + c_.gravity[d], h, B.damping);
    s.omega = B.lock[3] ? B.omega : kick(s.omega + I[3] / B.inertia, B.torque / B.inertia, h, B.angular_damping);
  }
}

// bodies.csv in the output directory, as an MPM run writes it: time, body, centre,
// velocity, omega, the mean contact force and torque over the last step (0 at the start), angle;
// every Config::bodies_interval steps, and when forced (the first and last step), once per step.
void Engine::write_bodies_csv(bool force) {
  const long every = std::max(1L, c_.bodies_interval);
  if (!own_bodies_ || bcsv_step_ == step_ || (!force && step_ % every != 0)) return;
  bcsv_step_ = step_;
  std::string err;
  if (rank_ == 0) {
    const std::string path = c_.output_dir + "/bodies.csv";
    if (!bcsv_) {
      bcsv_ = std::fopen(path.c_str(), c_.restart.empty() ? "w" : "a");
      if (bcsv_ && c_.restart.empty())
        std::fprintf(bcsv_, c_.dim == 3 ? "time,body,x,y,z,vx,vy,vz,omega,fx,fy,fz,torque,angle\n" : "time,body,x,y,vx,vy,omega,fx,fy,torque,angle\n");
    }
    if (!bcsv_) err = "cannot write " + path + ": check -dem_output_dir";
    for (size_t k = 0; bcsv_ && k < bst_.size(); ++k) {
      const BodyMotionState &s = bst_[k];
      std::fprintf(bcsv_, "%.9e,%zu", t_, k);
      for (int d = 0; d < c_.dim; ++d) std::fprintf(bcsv_, ",%.9e", s.pose.c[d]);
      for (int d = 0; d < c_.dim; ++d) std::fprintf(bcsv_, ",%.9e", s.v[d]);
      std::fprintf(bcsv_, ",%.9e", s.omega);
      for (int d = 0; d < c_.dim; ++d) std::fprintf(bcsv_, ",%.9e", bmean_[4 * k + d]);
      std::fprintf(bcsv_, ",%.9e,%.9e\n", bmean_[4 * k + 3], s.pose.angle);
    }
    if (bcsv_ && (std::fflush(bcsv_) != 0 || std::ferror(bcsv_))) err = "cannot write " + path + " (write failed): check -dem_output_dir";
  }
  collective_fail(comm_, !err.empty(), err);
}

} // namespace granmpm::dem
