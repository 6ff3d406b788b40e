// Rigid bodies in the standalone DEM (granmpm -dem with -body<k>_*: dem::Config::bodies; the
// engine moves them itself, src/dem/bodies.cpp). References:
//  - conservation: frictional grains thrown off-centre at a free dynamic body (2D: a disk;
//    3D: a box, free to turn about z) without gravity or walls in reach; grains + body
//    conserve linear momentum to round-off every step while the body takes a good share
//    of it and spins;
//  - 1, 2 and 3 ranks give the same bits (the body's forces are summed in grain-id order);
//  - a checkpoint restart continues bit for bit (the bodies' state is in the checkpoint).
#include "dem_records.hpp"
#include "harness.hpp"

#include "granmpm/dem/dem.hpp"

using namespace granmpm;
using gmtest::bcast;
using gmtest::grain_diff;

namespace {

dem::Config thrown_block(int dim) {
  dem::Config c;
  c.dim = dim;
  c.lo = {0, 0, 0};
  c.hi = {1.2, 1, dim == 3 ? 0.4 : 1.0};
  c.radius = 0.01;
  c.dist = dem::RadiusDist::Uniform;
  c.spread = 0.15;
  c.contact.kn = dim == 3 ? 2e4 : 1e5;
  c.contact.e = 0.5;
  c.contact.mu = 0.5;
  c.wall = c.contact;
  c.block_lo = {0.2, 0.42, 0.15};
  c.block_hi = {0.32, 0.56, 0.27};
  c.jitter = 0.5;
  c.v0 = {2.0, 0.0, 0};
  c.vrand = 0.2;
  BodySpec b;
  b.motion = BodyMotion::Dynamic;
  b.center = {0.45, 0.52, 0.21};
  if (dim == 2) {
    b.shape = BodyShape::Disk;
    b.radius = 0.05;
    b.mass = 10; // kg/m; the grains: 30 disks, 24 kg/m
  } else {
    b.shape = BodyShape::Box;
    b.half = {0.04, 0.04, 0.04};
    b.mass = 0.5; // kg; the grains: 150 spheres, 1.6 kg
  }
  b.inertia = uniform_inertia(b);
  b.index = 0;
  c.bodies = {b};
  c.quiet = true;
  c.fields = false;
  c.output_dir = gmtest::outdir("dem_standalone_bodies");
  return c;
}

struct Run {
  std::vector<double> body; // x, y, vx, vy, omega after each step
  std::vector<dem::GrainRecord> g;
  double worst = 0, scale = 0; // largest change of any momentum component, |P|
  long wall_contacts = 0, body_contact_steps = 0;
};

Run run(int n, int dim, long nsteps, long ck_at = -1, const std::string &restart = "") {
  Run out;
  dem::Config c = thrown_block(dim);
  c.restart = restart;
  const std::string ck = gmtest::outdir("dem_standalone_bodies") + "_ck" + std::to_string(dim) + ".h5";
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    dem::Engine e(comm, c);
    e.setup();
    const double M = c.bodies[0].mass;
    auto momentum = [&](double *p) {
      double loc[3] = {0, 0, 0};
      for (long i = 0; i < e.owned(); ++i)
        for (int k = 0; k < 3; ++k) loc[k] += e.mass(i) * (&e.velocities()[i].x)[k];
      MPI_Allreduce(MPI_IN_PLACE, loc, 3, MPI_DOUBLE, MPI_SUM, comm);
      for (int k = 0; k < 3; ++k) p[k] = loc[k] + M * e.body_states()[0].v[k];
    };
    double p0[3];
    momentum(p0);
    out.scale = std::sqrt(p0[0] * p0[0] + p0[1] * p0[1] + p0[2] * p0[2]);
    for (long s = e.steps(); s < nsteps; ++s) {
      e.step();
      double p[3];
      momentum(p);
      for (int k = 0; k < 3; ++k) out.worst = std::max(out.worst, std::fabs(p[k] - p0[k]));
      const BodyMotionState &b = e.body_states()[0];
      out.body.insert(out.body.end(), {b.pose.c[0], b.pose.c[1], b.v[0], b.v[1], b.omega});
      const dem::Summary m = e.summary();
      out.wall_contacts += m.wall_contacts; // (bodies count as walls here)
      if (e.body_force()[0] != 0) ++out.body_contact_steps;
      if (s + 1 == ck_at) e.write_checkpoint(ck);
    }
    auto g = e.gather();
    if (gmtest::world_rank() == 0) out.g = std::move(g);
  });
  out.worst = bcast(out.worst);
  out.scale = bcast(out.scale);
  out.wall_contacts = bcast(out.wall_contacts);
  out.body_contact_steps = bcast(out.body_contact_steps);
  long nb = bcast((long)out.body.size());
  out.body.resize(nb);
  MPI_Bcast(out.body.data(), (int)nb, MPI_DOUBLE, 0, MPI_COMM_WORLD);
  return out;
}

} // namespace

TEST_CASE("DEM standalone bodies: grains and a free body conserve momentum; 1, 2 and 3 ranks give the same bits", "[parallel][dem][bodies]") {
  for (int dim : {2, 3}) {
    const long nsteps = dim == 2 ? 1500 : 1500;
    const Run one = run(1, dim, nsteps);
    const size_t last = one.body.size() - 5;
    const double M = thrown_block(dim).bodies[0].mass;
    INFO("dim " << dim << ": body v " << one.body[last + 2] << " " << one.body[last + 3] << ", omega " << one.body[last + 4] << "; momentum change " << one.worst
                << " of " << one.scale << "; steps touching the body " << one.body_contact_steps << ", contacts counted on walls and the body " << one.wall_contacts);
    // The premise: the grains hit the body, which takes a good share of their momentum and spins.
    REQUIRE(one.body_contact_steps > 50);
    REQUIRE(M * one.body[last + 2] > 0.1 * one.scale);
    REQUIRE(std::fabs(one.body[last + 4]) > 0.1);
    REQUIRE(one.worst < 1e-13 * one.scale * nsteps);
    for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
      const Run many = run(n, dim, nsteps);
      double db = 0;
      for (size_t q = 0; q < one.body.size(); ++q) db = std::max(db, std::fabs(many.body[q] - one.body[q]));
      const double dg = bcast(gmtest::world_rank() == 0 ? grain_diff(many.g, one.g) : 0.0);
      INFO(n << " ranks: body max diff " << db << ", grains " << dg << ", momentum change " << many.worst);
      REQUIRE(many.worst < 1e-13 * many.scale * nsteps);
      // The bodies' force sums run in grain-id order on every rank count (sum_body_hits),
      // so body and grains keep the same bits.
      REQUIRE(db == 0.0);
      REQUIRE(dg == 0.0);
    }
  }
}

TEST_CASE("DEM standalone bodies: a checkpoint restart continues bit for bit", "[parallel][dem][bodies][checkpoint]") {
  for (int dim : {2, 3}) {
    const std::string ck = gmtest::outdir("dem_standalone_bodies") + "_ck" + std::to_string(dim) + ".h5";
    const int n = std::min(2, gmtest::world_size());
    const Run full = run(n, dim, 900, 500);
    const Run cont = run(n, dim, 900, -1, ck);
    INFO("dim " << dim << ", " << n << " ranks");
    const size_t tail = cont.body.size();
    REQUIRE(tail == 400 * 5);
    for (size_t q = 0; q < tail; ++q) REQUIRE(cont.body[q] == full.body[full.body.size() - tail + q]);
    REQUIRE(bcast(gmtest::world_rank() == 0 ? grain_diff(full.g, cont.g) : 0.0) == 0.0);
  }
}
