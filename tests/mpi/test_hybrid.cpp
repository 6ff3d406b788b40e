// The DEM grains as a species of the MPM simulation (DemModule, dem/module.hpp), and the
// hybrid coupling. References:
//  - two species that do not touch: each evolves exactly as its own solver alone (the MPM
//    Simulation without grains, the standalone dem::Engine at the sub-step dt): bitwise
//    on 1 rank; 2 and 3 ranks (with a repartition of the MPM grid mid-run, which migrates
//    the grains too) equal to 1 rank to round-off;
//  - checkpoint/restart of both species continues bitwise on the same rank count.
#include "harness.hpp"

#include <cstring>

#include "granmpm/dem/module.hpp"

using namespace granmpm;
using gmtest::bcast;

namespace {

constexpr double kDt = 1e-3;   // MPM step
constexpr int kSub = 8;        // DEM sub-steps per MPM step (kDt / kSub is exact)

// A spinning hypoelastic block on the left of a slip box under gravity.
Config mpm_side() {
  Config c = gmtest::hypo_block(2);
  c.lo = {0, 0, 0};
  c.hi = {0.4, 0.3, 0};
  c.cells = {16, 12, 1};
  c.body_lo = {0.02, 0.02, 0};
  c.body_hi = {0.12, 0.12, 0};
  c.bc = {{{BC::Slip, BC::Slip}, {BC::Slip, BC::Slip}, {BC::Periodic, BC::Periodic}}};
  c.gravity = {0, -9.81, 0};
  c.v0 = {0.3, 0, 0};
  c.spin = 1.0;
  c.output_dir = gmtest::outdir("hybrid");
  c.output_final = false;
  c.quiet = true;
  return c;
}

// Polydisperse frictional disks thrown down and sideways on the right of the same box,
// across the rank cuts of 2 and 3 ranks: contacts form and break, grains change rank.
dem::Config dem_side(const Config &host) {
  dem::Config c;
  c.dim = 2;
  c.radius = 0.006;
  c.dist = dem::RadiusDist::Uniform;
  c.spread = 0.15;
  c.contact.kn = 1e5;
  c.contact.e = 0.4;
  c.contact.mu = 0.5;
  c.wall = c.contact;
  c.wall.mu = 0.7;
  c.block_lo = {0.17, 0.03, 0};
  c.block_hi = {0.39, 0.2, 0};
  c.jitter = 0.6;
  c.v0 = {0.3, -1.0, 0};
  c.vrand = 0.3;
  c.dt = kDt / kSub;
  c.quiet = true;
  c.fields = false;
  return DemModule<2>::hosted(host, c); // the standalone run gets the same box and faces
}

struct Both {
  std::vector<ParticleRecord> mpm;
  std::vector<dem::GrainRecord> dem;
  long substeps = 0;
  long ranks_with_grains = 0;           // ranks holding > 10 grains just before the repartition
  long moved = 0;                       // grains that changed rank in the repartition
};

// MPM + DEM for nsteps (repartition after step `split` when >= 0; a checkpoint after step
// `ck_at` when >= 0; from `restart` when not empty).
Both run_both(int n, int nsteps, int split = -1, int ck_at = -1, const std::string &restart = "") {
  Both out;
  Config c = mpm_side();
  c.restart = restart;
  const std::string ck = gmtest::outdir("hybrid") + "/ck.h5";
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    Simulation<2> sim(comm, c);
    sim.extra_modules = [&](Simulation<2> &s) { s.modules.push_back(std::make_unique<DemModule<2>>(s, dem_side(s.cfg))); };
    sim.setup();
    for (int s = (int)sim.nsteps; s < nsteps; ++s) {
      sim.step(kDt);
      if (s + 1 == split) {
        DemModule<2> *d = sim.find<DemModule<2>>();
        const auto before = d->engine().gather_owned_ids();
        long mine = d->engine().owned() > 10;
        MPI_Allreduce(MPI_IN_PLACE, &mine, 1, MPI_LONG, MPI_SUM, comm);
        out.ranks_with_grains = mine;
        sim.repartition(sim.balanced_split());
        const auto after = d->engine().gather_owned_ids();
        long moved = 0;
        for (int64_t id : after) moved += !std::binary_search(before.begin(), before.end(), id);
        MPI_Allreduce(MPI_IN_PLACE, &moved, 1, MPI_LONG, MPI_SUM, comm);
        out.moved = moved;
      }
      if (s + 1 == ck_at) sim.write_checkpoint(ck);
    }
    DemModule<2> *d = sim.find<DemModule<2>>();
    auto g = d->engine().gather();
    auto p = sim.gather(0);
    if (gmtest::world_rank() == 0) {
      out.mpm = std::move(p);
      out.dem = std::move(g);
      out.substeps = d->substeps();
    }
  });
  out.substeps = bcast(out.substeps);
  out.ranks_with_grains = bcast(out.ranks_with_grains);
  out.moved = bcast(out.moved);
  return out;
}

std::vector<dem::GrainRecord> dem_alone(int nsteps) {
  std::vector<dem::GrainRecord> out;
  gmtest::on_ranks(1, [&](MPI_Comm comm) {
    dem::Engine e(comm, dem_side(mpm_side()));
    e.setup();
    for (long s = 0; s < (long)nsteps * kSub; ++s) e.step();
    auto g = e.gather();
    if (gmtest::world_rank() == 0) out = std::move(g);
  });
  return out;
}

// Largest difference over positions, velocities, spins and spring sums; -1 if the grain
// ids or contact counts differ.
double grain_diff(const std::vector<dem::GrainRecord> &a, const std::vector<dem::GrainRecord> &b) {
  if (a.size() != b.size()) return -1;
  double e = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].id != b[i].id || a[i].contacts != b[i].contacts) return -1;
    for (int k = 0; k < 3; ++k)
      e = std::max({e, std::fabs(a[i].x[k] - b[i].x[k]), std::fabs(a[i].v[k] - b[i].v[k]), std::fabs(a[i].w[k] - b[i].w[k])});
    e = std::max(e, std::fabs(a[i].hist_sum - b[i].hist_sum));
  }
  return e;
}

bool bitwise(const Both &a, const Both &b) {
  if (a.mpm.size() != b.mpm.size() || a.dem.size() != b.dem.size()) return false;
  for (size_t i = 0; i < a.mpm.size(); ++i)
    if (std::memcmp(&a.mpm[i], &b.mpm[i], sizeof(ParticleRecord)) != 0) return false;
  return grain_diff(a.dem, b.dem) == 0.0;
}

long total_contacts(const std::vector<dem::GrainRecord> &g) {
  long n = 0;
  for (const auto &r : g) n += r.contacts;
  return n;
}

} // namespace

TEST_CASE("DEM module: MPM and DEM species that do not touch each run as their own solver alone", "[parallel][hybrid]") {
  const int nsteps = 60;
  const Both one = run_both(1, nsteps);
  const auto mpm = gmtest::run_steps<2>(1, mpm_side(), nsteps, kDt);
  const auto dem = dem_alone(nsteps);
  REQUIRE(one.substeps == (long)nsteps * kSub);
  const int r0 = gmtest::world_rank() == 0;
  // The premise: the grains collide (with each other and the walls) during the run.
  REQUIRE(bcast(r0 ? total_contacts(one.dem) : 0L) > 50);
  REQUIRE(bcast(r0 ? (long)one.dem.size() : 0L) > 150);
  // 1 rank: bitwise both.
  REQUIRE(bcast(r0 ? gmtest::max_rel_diff(one.mpm, mpm) : 0.0) == 0.0);
  REQUIRE(bcast(r0 ? grain_diff(one.dem, dem) : 0.0) == 0.0);
  for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
    const Both many = run_both(n, nsteps, nsteps / 2);
    const double dm = bcast(r0 ? gmtest::max_rel_diff(many.mpm, one.mpm) : 0.0);
    const double dd = bcast(r0 ? grain_diff(many.dem, one.dem) : 0.0);
    INFO(n << " ranks (repartitioned at step " << nsteps / 2 << ", " << many.moved << " grains moved): MPM max rel diff " << dm << ", DEM max diff " << dd);
    REQUIRE(many.ranks_with_grains >= 2); // the grains span the rank cuts
    REQUIRE(many.moved > 10);     // the repartition migrates grains
    REQUIRE(dm >= 0);
    REQUIRE(dm < 1e-12);
    REQUIRE(dd >= 0);
    REQUIRE(dd < 1e-12);
  }
}

TEST_CASE("DEM module: checkpoint and restart continue both species bit for bit", "[parallel][hybrid][checkpoint]") {
  const std::string ck = gmtest::outdir("hybrid") + "/ck.h5";
  for (int n = 1; n <= std::min(2, gmtest::world_size()); ++n) {
    const Both full = run_both(n, 40, -1, 25);
    const Both cont = run_both(n, 40, -1, -1, ck);
    INFO(n << " ranks");
    REQUIRE(cont.substeps == full.substeps);
    REQUIRE(bcast(gmtest::world_rank() == 0 ? (long)bitwise(full, cont) : 0L) == 1);
  }
}
