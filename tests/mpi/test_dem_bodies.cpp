// Rigid bodies as contact partners of the DEM grains (issue 17; src/dem/bodies.cpp).
// References:
//  - a kinematic plane is the same partner as the box face it replaces: a frictional grain
//    thrown obliquely against a plane at x = 0.2 (normal +x) follows the same trajectory,
//    bit for bit, as against the wall -dem_lo x = 0.2, and the impulse the plane reports
//    is the grain's momentum change less gravity's (Newton's third law, to round-off);
//  - two-way coupling in an MPM run (-hybrid_dem): frictional grains thrown at a free
//    dynamic disk without gravity; grains + body (+ the untouched MPM block) conserve
//    linear momentum to round-off every step while the body picks up momentum and spin;
//    1, 2 and 3 ranks agree to round-off; a checkpoint restart continues bitwise.
#include "dem_records.hpp"
#include "harness.hpp"

#include <cstring>

#include "granmpm/dem/module.hpp"

using namespace granmpm;
using gmtest::bcast;
using gmtest::grain_diff;

namespace {

dem::Config thrown_grain(double wall_x) {
  dem::Config c;
  c.dim = 2;
  c.lo = {wall_x, 0, 0};
  c.hi = {1, 1, 0};
  c.gravity = {-9.81, -3.0, 0};
  c.scene = dem::Scene::List;
  c.grains = {0.3, 0.5, 0.01, -1.0, 0.8}; // x, y, r, vx, vy
  c.contact.kn = 1e5;
  c.contact.e = 0.5;
  c.contact.mu = 0.3;
  c.wall = c.contact;
  c.quiet = true;
  c.fields = false;
  return c;
}

struct Drop {
  dem::GrainRecord g{};
  std::vector<double> impulse; // summed over the run (plane only)
  long wall_steps = 0;         // steps with a wall or body contact
  double t = 0;                // the run's length
};

Drop drop(bool plane) {
  Drop out;
  gmtest::on_ranks(1, [&](MPI_Comm comm) {
    dem::Engine e(comm, thrown_grain(plane ? 0.0 : 0.2));
    if (plane) {
      BodySpec p;
      p.shape = BodyShape::Plane;
      p.center = {0.2, 0.5, 0};
      BodyMotionState s;
      s.pose = body_pose_at(p, 0);
      e.set_bodies({p}, {s}, 0.0);
    }
    e.setup();
    std::vector<double> imp(4, 0.0);
    for (int s = 0; s < 1000; ++s) {
      e.step();
      out.wall_steps += e.summary().wall_contacts;
      if (plane) {
        const auto d = e.take_body_impulse();
        for (int q = 0; q < 4; ++q) imp[q] += d[q];
      }
    }
    auto g = e.gather();
    if (gmtest::world_rank() == 0) out.g = g.at(0);
    out.impulse = imp;
    out.t = e.time();
  });
  return out;
}

} // namespace

TEST_CASE("DEM bodies: a kinematic plane is the same contact partner as the wall it replaces", "[dem][bodies]") {
  const Drop wall = drop(false), plane = drop(true);
  if (gmtest::world_rank() != 0) return;
  INFO("wall contact steps " << wall.wall_steps << ", x " << wall.g.x[0] << " " << plane.g.x[0] << ", w " << wall.g.w[2] << " " << plane.g.w[2]);
  REQUIRE(wall.wall_steps > 20);       // it hit the wall (and then rolls down it) ...
  REQUIRE(std::fabs(wall.g.w[2]) > 1); // ... with friction spinning it
  REQUIRE(plane.wall_steps == wall.wall_steps);
  for (int k = 0; k < 3; ++k) {
    REQUIRE(plane.g.x[k] == wall.g.x[k]);
    REQUIRE(plane.g.v[k] == wall.g.v[k]);
    REQUIRE(plane.g.w[k] == wall.g.w[k]);
  }
  // The plane's impulse balances the grain's momentum change less gravity's impulse.
  const dem::Config c = thrown_grain(0.2);
  const double m = plane.g.m, t_run = plane.t;
  for (int k = 0; k < 2; ++k) {
    const double dp = m * (plane.g.v[k] - c.grains[3 + k]) - m * c.gravity[k] * t_run;
    INFO("component " << k << ": grain's contact impulse " << dp << ", plane's " << plane.impulse[k]);
    REQUIRE(std::fabs(dp) > 1e-3);
    REQUIRE(std::fabs(dp + plane.impulse[k]) < 1e-12 * (std::fabs(dp) + m * 10 * t_run));
  }
}

namespace {

constexpr double kDt = 1e-3; // MPM step
constexpr int kSub = 8;      // DEM sub-steps per MPM step

// A resting stress-free MPM block in the corner of a slip box without gravity, a free
// dynamic disk in the middle, grains thrown at it off-centre (frictional: it spins).
Config host() {
  Config c = gmtest::hypo_block(2);
  c.lo = {0, 0, 0};
  c.hi = {0.4, 0.4, 0};
  c.cells = {16, 16, 1};
  c.body_lo = {0.02, 0.32, 0};
  c.body_hi = {0.08, 0.38, 0};
  c.bc = {{{BC::Slip, BC::Slip}, {BC::Slip, BC::Slip}, {BC::Periodic, BC::Periodic}}};
  c.gravity = {0, 0, 0};
  c.set_scene_param("-spin", 0);
  c.p0 = 0;
  BodySpec disk;
  disk.shape = BodyShape::Disk;
  disk.motion = BodyMotion::Dynamic;
  disk.center = {0.25, 0.25, 0};
  disk.radius = 0.04;
  disk.contact = BodyContact::Friction;
  disk.mass = 2.0;
  disk.inertia = uniform_inertia(disk);
  c.bodies = {disk};
  c.output_dir = gmtest::outdir("dem_bodies");
  c.output_final = false;
  c.quiet = true;
  return c;
}

dem::Config grains(const Config &h) {
  dem::Config c;
  c.dim = 2;
  c.radius = 0.006;
  c.dist = dem::RadiusDist::Uniform;
  c.spread = 0.15;
  c.contact.kn = 1e5;
  c.contact.e = 0.4;
  c.contact.mu = 0.5;
  c.wall = c.contact;
  c.block_lo = {0.17, 0.05, 0};
  c.block_hi = {0.31, 0.19, 0};
  c.jitter = 0.6;
  c.v0 = {0.2, 1.5, 0};
  c.vrand = 0.1;
  c.dt = kDt / kSub;
  return DemModule<2>::hosted(h, c);
}

struct Coupled {
  std::vector<double> body;   // x, y, vx, vy, omega of each step
  double worst = 0, scale = 0; // largest momentum change over the run, momentum scale
  std::vector<dem::GrainRecord> g;
  long contacts_with_body = 0;
};

Coupled coupled(int n, int nsteps, int ck_at = -1, const std::string &restart = "") {
  Coupled out;
  Config c = host();
  c.restart = restart;
  const std::string ck = gmtest::outdir("dem_bodies") + "/ck.h5";
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    Simulation<2> sim(comm, c);
    sim.extra_modules = [&](Simulation<2> &s) { s.modules.push_back(std::make_unique<DemModule<2>>(s, grains(s.cfg))); };
    sim.setup();
    DemModule<2> *d = sim.find<DemModule<2>>();
    auto momentum = [&](double *p) {
      const Totals t = sim.totals();
      double loc[2] = {0, 0};
      const dem::Engine &e = d->engine();
      for (long i = 0; i < e.owned(); ++i)
        for (int k = 0; k < 2; ++k) loc[k] += e.mass(i) * (&d->engine().velocities()[i].x)[k];
      MPI_Allreduce(MPI_IN_PLACE, loc, 2, MPI_DOUBLE, MPI_SUM, comm);
      for (int k = 0; k < 2; ++k) p[k] = t.momentum[k] + loc[k] + sim.bodies->spec(0).mass * sim.bodies->velocity(0)[k];
    };
    double p0[2];
    momentum(p0);
    out.scale = std::hypot(p0[0], p0[1]);
    for (int s = (int)sim.nsteps; s < nsteps; ++s) {
      sim.step(kDt);
      double p[2];
      momentum(p);
      out.worst = std::max({out.worst, std::fabs(p[0] - p0[0]), std::fabs(p[1] - p0[1])});
      out.body.insert(out.body.end(), {sim.bodies->pose(0).c[0], sim.bodies->pose(0).c[1], sim.bodies->velocity(0)[0], sim.bodies->velocity(0)[1], sim.bodies->omega(0)});
      if (s + 1 == ck_at) sim.write_checkpoint(ck);
    }
    auto g = d->engine().gather();
    if (gmtest::world_rank() == 0) out.g = std::move(g);
  });
  out.worst = bcast(out.worst);
  out.scale = bcast(out.scale);
  long nb = bcast((long)out.body.size()); // every rank of the world holds rank 0's
  out.body.resize(nb);
  MPI_Bcast(out.body.data(), (int)nb, MPI_DOUBLE, 0, MPI_COMM_WORLD);
  return out;
}

} // namespace

TEST_CASE("DEM bodies: grains and a dynamic body conserve momentum; 1, 2 and 3 ranks agree", "[parallel][dem][bodies]") {
  const int nsteps = 90;
  const Coupled one = coupled(1, nsteps);
  const size_t last = one.body.size() - 5;
  INFO("body: v " << one.body[last + 2] << " " << one.body[last + 3] << ", omega " << one.body[last + 4] << "; momentum change " << one.worst << " of " << one.scale);
  // The premise: the grains hit the body, which takes a good share of their momentum and spins.
  REQUIRE(host().bodies[0].mass * one.body[last + 3] > 0.03 * one.scale);
  REQUIRE(std::fabs(one.body[last + 4]) > 0.1);
  REQUIRE(one.worst < 1e-13 * one.scale * nsteps);
  for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
    const Coupled many = coupled(n, nsteps);
    double db = 0;
    for (size_t q = 0; q < one.body.size(); ++q) db = std::max(db, std::fabs(many.body[q] - one.body[q]));
    const double dg = bcast(gmtest::world_rank() == 0 ? grain_diff(many.g, one.g) : 0.0);
    INFO(n << " ranks: body max diff " << db << ", grains " << dg << ", momentum change " << many.worst);
    REQUIRE(many.worst < 1e-13 * many.scale * nsteps);
    REQUIRE(db < 1e-11);
    REQUIRE(dg >= 0);
    // Grain velocities and spins are O(1) and each collision amplifies the round-off of the
    // ranks' summation order: measured 3.1e-14 at -O2 and 7.4e-11 in the Debug sanitizer build
    // (CI). A missing ghost contact or body impulse would differ by a contact's impulse, 1e-3+.
    REQUIRE(dg < 1e-9);
  }
}

TEST_CASE("DEM bodies: a checkpoint restart with a dynamic body continues bit for bit", "[parallel][dem][bodies][checkpoint]") {
  const std::string ck = gmtest::outdir("dem_bodies") + "/ck.h5";
  for (int n = 1; n <= std::min(2, gmtest::world_size()); ++n) {
    const Coupled full = coupled(n, 60, 35);
    const Coupled cont = coupled(n, 60, -1, ck);
    INFO(n << " ranks");
    const size_t tail = cont.body.size();
    REQUIRE(tail == 25 * 5);
    for (size_t q = 0; q < tail; ++q) REQUIRE(cont.body[q] == full.body[full.body.size() - tail + q]);
    REQUIRE(bcast(gmtest::world_rank() == 0 ? grain_diff(full.g, cont.g) : 0.0) == 0.0);
  }
}
