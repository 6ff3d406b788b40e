// The parallel DEM engine: 1, 2 and 3 ranks give the same grains bit for bit (positions,
// velocities, spins, orientations, contact counts, springs); checkpoint/restart is bitwise; an elastic gas
// conserves energy with a drift falling as dt^2 (velocity Verlet) and as dt (Euler); a
// settled packing carries its weight (contact stress against rho g depth).
#include "harness.hpp"

#include <cstdio>

#include "granmpm/dem/dem.hpp"

using namespace granmpm::dem;
using gmtest::bcast;

namespace {

// Polydisperse frictional disks falling into a box with a periodic x, rough floor and
// walls, a spin and a sideways throw: contacts form and break, grains cross ranks and the
// periodic face, springs slip and stick.
Config settling(int dim) {
  Config c;
  c.dim = dim;
  c.lo = {0, 0, 0};
  c.hi = {0.24, 0.3, 0.12};
  c.periodic = {true, false, dim == 3};
  c.gravity = {0, -9.81, 0};
  c.radius = 0.008;
  c.dist = RadiusDist::Uniform;
  c.spread = 0.15;
  c.contact.kn = dim == 3 ? 2e4 : 1e6;
  c.contact.e = 0.4;
  c.contact.mu = 0.5;
  c.contact.mu_roll = dim == 3 ? 0.05 : 0.0;
  c.wall = c.contact;
  c.wall.mu = 0.7;
  c.block_lo = {0, 0.02, 0};
  c.block_hi = {0.24, dim == 3 ? 0.12 : 0.2, 0.12};
  c.jitter = 0.6;
  c.v0 = {0.5, -1.0, 0};
  c.vrand = 0.3;
  c.fields = false;
  c.quiet = true;
  c.output_dir = gmtest::outdir("dem");
  return c;
}

std::vector<GrainRecord> run_dem(int n, const Config &c, long steps, long *rebuilds = nullptr) {
  std::vector<GrainRecord> out;
  long rb = 0;
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    Engine e(comm, c);
    e.setup();
    for (long s = 0; s < steps; ++s) e.step();
    auto g = e.gather();
    rb = e.timers().rebuilds;
    if (gmtest::world_rank() == 0) out = std::move(g);
  });
  if (rebuilds) *rebuilds = bcast(rb);
  return out;
}

// Largest absolute difference over every field; -1 if ids, counts or contact counts differ.
double diff(const std::vector<GrainRecord> &a, const std::vector<GrainRecord> &b) {
  if (a.size() != b.size()) return -1;
  double e = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].id != b[i].id || a[i].contacts != b[i].contacts) return -1;
    for (int k = 0; k < 3; ++k) {
      e = std::max(e, std::fabs(a[i].x[k] - b[i].x[k]));
      e = std::max(e, std::fabs(a[i].v[k] - b[i].v[k]));
      e = std::max(e, std::fabs(a[i].w[k] - b[i].w[k]));
    }
    for (int k = 0; k < 4; ++k) e = std::max(e, std::fabs(a[i].q[k] - b[i].q[k])); // orientation
    e = std::max(e, std::fabs(a[i].hist_sum - b[i].hist_sum));
  }
  return e;
}

long total_contacts(const std::vector<GrainRecord> &a) {
  long n = 0;
  for (auto &g : a) n += g.contacts;
  return n;
}

} // namespace

TEST_CASE("DEM: 1, 2, 3 ranks give the same grains bit for bit", "[parallel][dem]") {
  for (int dim : {2, 3}) {
    const Config c = settling(dim);
    long rb = 0;
    const long steps = dim == 2 ? 3000 : 3000;
    const auto ref = run_dem(1, c, steps, &rb);
    const long contacts = bcast(total_contacts(ref));
    const long count = bcast((long)ref.size());
    INFO("dim " << dim << ": " << count << " grains, " << contacts << " contact entries, " << rb << " rebuilds");
    REQUIRE(count > 100);
    REQUIRE(contacts > count);  // a dense, touching packing by now
    REQUIRE(rb > 5);            // grains moved through several list rebuilds
    double turned = 0; // the largest rotation angle of a grain (3D: its quaternion's)
    for (const GrainRecord &g : ref) turned = std::max(turned, 2 * std::acos(std::min(1.0, std::fabs(g.q[0]))));
    turned = bcast(turned);
    INFO("largest rotation " << turned << " rad");
    if (dim == 3) REQUIRE(turned > 0.1);
    for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
      const auto par = run_dem(n, c, steps);
      const double d = bcast(gmtest::world_rank() == 0 ? diff(ref, par) : 0.0);
      INFO("ranks " << n << ": largest difference " << d);
      REQUIRE(d == 0.0);
    }
  }
}

// -dem_orientation false: no orientation kept (nothing else reads it), so every other field
// has the same bits as with it, on 1 and 2-3 ranks; its checkpoint restarts a run that keeps
// orientations with unrotated grains and the same positions, velocities and springs.
TEST_CASE("DEM: without orientations every other result is the same bits", "[parallel][dem][checkpoint]") {
  for (int dim : {2, 3}) {
    INFO("dim " << dim);
    const Config c = settling(dim);
    Config off = c;
    off.orientation = false;
    const long n1 = 300, n2 = 200;
    auto ref = run_dem(1, c, n1 + n2);
    double turned = 0;
    for (GrainRecord &g : ref) {
      turned = std::max(turned, std::fabs(g.q[3]) + std::fabs(g.q[1]));
      g.q[0] = 1, g.q[1] = g.q[2] = g.q[3] = 0; // without orientations: the identity
    }
    REQUIRE(bcast(turned) > 0.01); // (the grains did turn with orientations kept)
    for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
      const auto par = run_dem(n, off, n1 + n2); // (collective: every rank calls it)
      const double d = bcast(gmtest::world_rank() == 0 ? diff(ref, par) : 0.0);
      INFO("ranks " << n << ": largest difference from the run with orientations " << d);
      REQUIRE(d == 0.0);
    }
    const int nr = std::min(2, gmtest::world_size());
    const std::string ck = gmtest::outdir("dem") + "_ck_off.h5";
    if (gmtest::world_rank() == 0) std::system(("mkdir -p " + gmtest::outdir("dem")).c_str());
    MPI_Barrier(PETSC_COMM_WORLD);
    double bytes_q = -1;
    gmtest::on_ranks(nr, [&](MPI_Comm comm) {
      Engine e(comm, off);
      e.setup();
      for (long s = 0; s < n1; ++s) e.step();
      for (const Engine::Container &k : e.containers())
        if (std::string(k.name) == "orientation") bytes_q = (double)k.bytes;
      e.write_checkpoint(ck);
    });
    CHECK(bcast(bytes_q) == 0.0); // nothing kept
    Config r = c;
    r.restart = ck;
    std::vector<GrainRecord> res;
    gmtest::on_ranks(nr, [&](MPI_Comm comm) {
      Engine e(comm, r);
      e.setup();
      for (long s = 0; s < n2; ++s) e.step();
      auto g = e.gather();
      if (gmtest::world_rank() == 0) res = std::move(g);
    });
    double unit = 0, turned2 = 0; // the restarted orientations: unit, turned over n2 steps only
    for (GrainRecord &g : res) {
      unit = std::max(unit, std::fabs(g.q[0] * g.q[0] + g.q[1] * g.q[1] + g.q[2] * g.q[2] + g.q[3] * g.q[3] - 1));
      turned2 = std::max(turned2, std::fabs(g.q[3]) + std::fabs(g.q[1]));
      g.q[0] = 1, g.q[1] = g.q[2] = g.q[3] = 0;
    }
    CHECK(bcast(unit) < 1e-15);
    CHECK(bcast(turned2) > 0);
    const double d = bcast(gmtest::world_rank() == 0 ? diff(ref, res) : 0.0);
    INFO("restart with orientations from the checkpoint without: largest difference " << d);
    REQUIRE(d == 0.0);
  }
}

TEST_CASE("DEM: checkpoint and restart continue bit for bit", "[parallel][dem][checkpoint]") {
  for (int dim : {2, 3}) { // 3D: the orientations too
    INFO("dim " << dim);
    Config c = settling(dim);
    const long n1 = 700, n2 = 500;
    const int nr = std::min(2, gmtest::world_size());
    const auto ref = run_dem(nr, c, n1 + n2);
    const std::string ck = gmtest::outdir("dem") + "_ck.h5";
    if (gmtest::world_rank() == 0) std::system(("mkdir -p " + gmtest::outdir("dem")).c_str());
    MPI_Barrier(PETSC_COMM_WORLD);
    gmtest::on_ranks(nr, [&](MPI_Comm comm) {
      Engine e(comm, c);
      e.setup();
      for (long s = 0; s < n1; ++s) e.step();
      e.write_checkpoint(ck);
    });
    Config r = c;
    r.restart = ck;
    std::vector<GrainRecord> res;
    long step = 0;
    gmtest::on_ranks(nr, [&](MPI_Comm comm) {
      Engine e(comm, r);
      e.setup();
      for (long s = 0; s < n2; ++s) e.step();
      step = e.steps();
      auto g = e.gather();
      if (gmtest::world_rank() == 0) res = std::move(g);
    });
    REQUIRE(bcast(step) == n1 + n2);
    const double d = bcast(gmtest::world_rank() == 0 ? diff(ref, res) : 0.0);
    INFO("largest difference after restart " << d);
    REQUIRE(d == 0.0);
  }
}
