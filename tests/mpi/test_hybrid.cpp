// The DEM grains as a species of the MPM simulation (DemModule, dem/module.hpp), and the
// hybrid coupling. References:
//  - two species that do not touch: each evolves exactly as its own solver alone (the MPM
//    Simulation without grains, the standalone dem::Engine at the sub-step dt): bitwise
//    on 1 rank; 2 and 3 ranks (with a repartition of the MPM grid mid-run, which migrates
//    the grains too) equal to 1 rank to round-off;
//  - checkpoint/restart of both species continues bitwise on the same rank count;
//  - the coupling with a fixed band: with no gravity and no walls (periodic box) the total
//    momentum of material points and grains (each with its mass share) is conserved to
//    round-off over every step while the constraint moves momentum between them; 1, 2 and
//    3 ranks agree to round-off; checkpoint/restart continues bitwise.
#include "harness.hpp"

#include <array>
#include <cstring>
#include <map>

#include "granmpm/dem/module.hpp"
#include "granmpm/hybrid/module.hpp"

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
  c.set_scene_param("-spin", 1.0);
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

namespace {

// A periodic box without gravity: a spinning, pre-compressed block above (continuum zone
// and band, y in [0.15, 0.35]) moving down and sideways, disks below (discrete zone and
// band, y in [0.05, 0.25]) thrown up: they meet in the band y in [0.15, 0.25].
// 3D: a 0.2 x 0.4 x 0.1 box (h = 0.025), spheres of radius 4 mm.
template <int dim>
Config band_mpm() {
  Config c = gmtest::hypo_block(dim);
  c.lo = {0, 0, 0};
  c.hi = {dim == 3 ? 0.2 : 0.4, 0.4, dim == 3 ? 0.1 : 0};
  c.cells = {dim == 3 ? 8 : 16, 16, dim == 3 ? 4 : 1};
  c.body_lo = {0, 0.15, 0};
  c.body_hi = {dim == 3 ? 0.2 : 0.4, 0.35, dim == 3 ? 0.1 : 0};
  c.bc = {{{BC::Periodic, BC::Periodic}, {BC::Periodic, BC::Periodic}, {BC::Periodic, BC::Periodic}}};
  c.gravity = {0, 0, 0};
  c.v0 = {0.5, -0.3, 0};
  c.set_scene_param("-spin", 1.0);
  c.output_dir = gmtest::outdir("hybrid");
  c.output_final = false;
  c.quiet = true;
  return c;
}

hybrid::FixedBand band_y() {
  hybrid::FixedBand b;
  b.axis = 1;
  b.lo = 0.15;
  b.hi = 0.25;
  b.continuum_hi = true;
  b.band_weight = 0.5;
  return b;
}

template <int dim>
dem::Config band_dem() {
  dem::Config c;
  c.dim = dim;
  c.radius = 0.004;
  c.dist = dem::RadiusDist::Uniform;
  c.spread = 0.1;
  c.contact.kn = dim == 3 ? 2e3 : 1e5;
  c.contact.e = 0.5;
  c.contact.mu = 0.4;
  c.wall = c.contact;
  c.block_lo = {0, dim == 3 ? 0.1 : 0.05, 0};
  c.block_hi = {dim == 3 ? 0.2 : 0.4, 0.25, dim == 3 ? 0.1 : 0};
  c.jitter = 0.5;
  c.v0 = {0, 0.4, 0};
  c.vrand = 0.3;
  c.quiet = true;
  c.fields = false;
  return c;
}

struct Coupled {
  std::vector<ParticleRecord> mpm;
  std::vector<dem::GrainRecord> dem;
  double worst = 0;       // largest |change of total momentum| over a step / momentum scale
  long constrained = 0;   // node constraints over the run
  double transferred = 0; // sum |lambda| over the run
};

template <int dim>
void momentum(Simulation<dim> &sim, DemModule<dim> &d, double p[3], double *scale) {
  const Totals t = sim.totals();
  dem::Engine &e = d.engine();
  double loc[4] = {0, 0, 0, 0};
  // With the grains' pending half kicks (dem::Engine::pending_impulse): a conversion that
  // removes a grain hands its impulse over while its partners still take theirs. Without
  // removals they cancel pair by pair (no walls, no gravity in these boxes).
  for (long q = 0; q < e.owned(); ++q) {
    const dem::V3 v = e.velocities()[q], J = e.pending_impulse(q);
    loc[0] += e.mass(q) * v.x + J.x;
    loc[1] += e.mass(q) * v.y + J.y;
    loc[2] += e.mass(q) * v.z + J.z;
    loc[3] += e.mass(q) * std::sqrt(v.x * v.x + v.y * v.y + v.z * v.z);
  }
  MPI_Allreduce(MPI_IN_PLACE, loc, 4, MPI_DOUBLE, MPI_SUM, sim.comm);
  for (int k = 0; k < 3; ++k) p[k] = (k < dim ? t.momentum[k] : 0.0) + loc[k];
  *scale = loc[3] + t.mass * t.vmax;
}

template <int dim>
Coupled run_coupled(int n, int nsteps, int ck_at = -1, const std::string &restart = "") {
  Coupled out;
  Config c = band_mpm<dim>();
  c.restart = restart;
  const std::string ck = gmtest::outdir("hybrid") + "/band_ck.h5";
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    Simulation<dim> sim(comm, c);
    sim.extra_modules = [&](Simulation<dim> &s) {
      for (auto &m : hybrid_modules<dim>(s, band_dem<dim>(), band_y())) s.modules.push_back(std::move(m));
    };
    sim.setup();
    DemModule<dim> *d = sim.template find<DemModule<dim>>();
    HybridModule<dim> *h = sim.template find<HybridModule<dim>>();
    for (int s = (int)sim.nsteps; s < nsteps; ++s) {
      double p0[3], p1[3], scale;
      momentum(sim, *d, p0, &scale);
      sim.step(kDt);
      momentum(sim, *d, p1, &scale);
      out.worst = std::max(out.worst, std::sqrt((p1[0] - p0[0]) * (p1[0] - p0[0]) + (p1[1] - p0[1]) * (p1[1] - p0[1]) + (p1[2] - p0[2]) * (p1[2] - p0[2])) / scale);
      if (s + 1 == ck_at) sim.write_checkpoint(ck);
    }
    long nodes = h->constrained_nodes();
    double lam = h->transferred();
    MPI_Allreduce(MPI_IN_PLACE, &nodes, 1, MPI_LONG, MPI_SUM, comm);
    MPI_Allreduce(MPI_IN_PLACE, &lam, 1, MPI_DOUBLE, MPI_SUM, comm);
    auto g = d->engine().gather();
    auto p = sim.gather(0);
    if (gmtest::world_rank() == 0) {
      out.mpm = std::move(p);
      out.dem = std::move(g);
      out.constrained = nodes;
      out.transferred = lam;
    }
  });
  out.worst = bcast(out.worst);
  out.constrained = bcast(out.constrained);
  out.transferred = bcast(out.transferred);
  return out;
}

} // namespace

TEST_CASE("hybrid fixed band: momentum through the band is conserved; 1, 2, 3 ranks agree", "[parallel][hybrid]") {
  const int nsteps = 30;
  const Coupled one = run_coupled<2>(1, nsteps);
  const int r0 = gmtest::world_rank() == 0;
  INFO("1 rank: worst relative momentum change per step " << one.worst << ", " << one.constrained << " node constraints, sum |lambda| " << one.transferred);
  // The premise: the phases share nodes and the constraint moves momentum.
  REQUIRE(one.constrained > 100);
  REQUIRE(one.transferred > 0);
  REQUIRE(one.worst < 1e-13);
  // The grains carry their share: half their mass if they started in the band, all of it
  // if they started in the discrete zone (2500 kg/m^3 disks).
  long half = 0, whole = 0, other = 0;
  if (r0)
    for (const auto &g : one.dem) {
      const double w = g.m / (2500 * M_PI * g.r * g.r);
      (std::fabs(w - 0.5) < 1e-14 ? half : std::fabs(w - 1) < 1e-14 ? whole : other) += 1;
    }
  REQUIRE(bcast(half) > 100);
  REQUIRE(bcast(whole) > 100);
  REQUIRE(bcast(other) == 0);
  for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
    const Coupled many = run_coupled<2>(n, nsteps);
    const double dm = bcast(r0 ? gmtest::max_rel_diff(many.mpm, one.mpm) : 0.0);
    const double dd = bcast(r0 ? grain_diff(many.dem, one.dem) : 0.0);
    INFO(n << " ranks: MPM max rel diff " << dm << ", DEM max diff " << dd << ", worst momentum change " << many.worst);
    REQUIRE(many.worst < 1e-13);
    REQUIRE(many.constrained == one.constrained);
    REQUIRE(dm >= 0);
    REQUIRE(dm < 1e-12);
    REQUIRE(dd >= 0);
    // The grid sums (P2G, the grains' rasterisation) add up in a rank-dependent order: the
    // constraint hands the grains 1e-16-relative differences each step, which their stiff
    // contacts amplify (measured on 2 ranks: 5e-13 after 5 steps, 1e-11 after 10, 7e-11
    // after 30); the coupling itself moves velocities by O(0.1).
    REQUIRE(dd < 1e-9);
  }
}

TEST_CASE("hybrid fixed band: checkpoint and restart continue bit for bit", "[parallel][hybrid][checkpoint]") {
  const std::string ck = gmtest::outdir("hybrid") + "/band_ck.h5";
  for (int n = 1; n <= std::min(2, gmtest::world_size()); ++n) {
    const Coupled full = run_coupled<2>(n, 20, 12);
    const Coupled cont = run_coupled<2>(n, 20, -1, ck);
    INFO(n << " ranks");
    Both a{full.mpm, full.dem}, b{cont.mpm, cont.dem};
    REQUIRE(bcast(gmtest::world_rank() == 0 ? (long)bitwise(a, b) : 0L) == 1);
  }
}

TEST_CASE("hybrid fixed band in 3D: momentum through the band is conserved on 1, 2, 3 ranks", "[parallel][hybrid]") {
  const int nsteps = 10;
  const Coupled one = run_coupled<3>(1, nsteps);
  INFO("3D, 1 rank: worst relative momentum change per step " << one.worst << ", " << one.constrained << " node constraints, sum |lambda| " << one.transferred);
  REQUIRE(one.constrained > 100);
  REQUIRE(one.transferred > 0);
  REQUIRE(one.worst < 1e-13);
  const int r0 = gmtest::world_rank() == 0;
  for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
    const Coupled many = run_coupled<3>(n, nsteps);
    const double dm = bcast(r0 ? gmtest::max_rel_diff(many.mpm, one.mpm) : 0.0);
    const double dd = bcast(r0 ? grain_diff(many.dem, one.dem) : 0.0);
    INFO("3D, " << n << " ranks: MPM max rel diff " << dm << ", DEM max diff " << dd << ", worst momentum change " << many.worst);
    REQUIRE(many.worst < 1e-13);
    REQUIRE(many.constrained == one.constrained);
    REQUIRE(dm >= 0);
    REQUIRE(dm < 1e-12);
    REQUIRE(dd >= 0);
    REQUIRE(dd < 1e-9); // round-off amplified by the contacts, as in 2D
  }
}

// -on_instability checkpoint_and_abort keeps a backup of every module: the grains restored
// from one continue exactly as the uninterrupted run (the same rebuild of the lists as a
// restart), on 1 and 2 ranks.
TEST_CASE("DEM module: backup and restore continue the grains bit for bit", "[parallel][hybrid]") {
  for (int n = 1; n <= std::min(2, gmtest::world_size()); ++n) {
    std::vector<dem::GrainRecord> straight, restored;
    gmtest::on_ranks(n, [&](MPI_Comm comm) {
      for (int pass = 0; pass < 2; ++pass) {
        Simulation<2> sim(comm, mpm_side());
        sim.extra_modules = [&](Simulation<2> &s) { s.modules.push_back(std::make_unique<DemModule<2>>(s, dem_side(s.cfg))); };
        sim.setup();
        DemModule<2> *d = sim.find<DemModule<2>>();
        for (int s = 0; s < 15; ++s) {
          sim.step(kDt);
          if (pass == 1 && s + 1 == 10) d->backup(sim);
        }
        if (pass == 1) { // back to step 10, then 5 more DEM steps
          d->restore(sim);
          for (int s = 0; s < 5; ++s) d->begin_step(sim, kDt);
        }
        auto g = d->engine().gather();
        if (gmtest::world_rank() == 0) (pass == 0 ? straight : restored) = std::move(g);
      }
    });
    INFO(n << " ranks");
    REQUIRE(bcast(gmtest::world_rank() == 0 ? (long)straight.size() : 0L) > 100);
    REQUIRE(bcast(gmtest::world_rank() == 0 ? grain_diff(straight, restored) : 1.0) == 0.0);
  }
}

namespace {

struct Zoned {
  std::vector<int> zones; // per cell, rank 0's copy
  bool same_on_ranks = true;
  long counts[6] = {0, 0, 0, 0, 0, 0};
  long updates = 0;
  std::vector<ParticleRecord> mpm;
  std::vector<dem::GrainRecord> dem;
};

// The band box of run_coupled with the zone oracle every 5 steps: band centred 2 cells
// inside the dense contour, half a cell wide on either side.
Zoned run_zoned(int n, int nsteps) {
  Zoned out;
  const Config c = band_mpm<2>();
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    Simulation<2> sim(comm, c);
    sim.extra_modules = [&](Simulation<2> &s) {
      for (auto &m : hybrid_modules<2>(s, band_dem<2>(), band_y())) s.modules.push_back(std::move(m));
    };
    sim.setup();
    HybridModule<2> *h = sim.find<HybridModule<2>>();
    HybridModule<2>::Oracle o;
    o.every = 5;
    o.rule.band_distance = 2 * sim.grid.h;
    o.rule.half_width = 0.5 * sim.grid.h;
    h->set_oracle(sim, o);
    for (int s = 0; s < nsteps; ++s) sim.step(kDt);
    std::vector<int> z;
    for (auto q : h->zones()) z.push_back((int)q);
    std::vector<int> z0 = z;
    MPI_Bcast(z0.data(), (int)z0.size(), MPI_INT, 0, comm);
    int same = z0 == z, all = 0;
    MPI_Allreduce(&same, &all, 1, MPI_INT, MPI_MIN, comm);
    auto g = h ? sim.find<DemModule<2>>()->engine().gather() : std::vector<dem::GrainRecord>();
    auto p = sim.gather(0);
    if (gmtest::world_rank() == 0) {
      out.zones = z;
      out.same_on_ranks = all != 0;
      for (int k = 0; k < 6; ++k) out.counts[k] = h->zone_counts()[k];
      out.updates = h->zone_updates();
      out.mpm = std::move(p);
      out.dem = std::move(g);
    }
  });
  return out;
}

} // namespace

TEST_CASE("hybrid zone oracle: zones from phi, equal to a serial recomputation on 1, 2, 3 ranks", "[parallel][hybrid]") {
  using namespace granmpm::hybrid;
  const int nsteps = 20; // the last update is at step 20: the gathered final state's zones
  const int r0 = gmtest::world_rank() == 0;
  Zoned one = run_zoned(1, nsteps);
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    Zoned z = n == 1 ? one : run_zoned(n, nsteps);
    int ok_ref = 1, ok_one = 1, all3 = 1, ok_counts = 1;
    long ref_counts[6] = {0, 0, 0, 0, 0, 0};
    if (r0) {
      // The independent reference: the pure kernels on rank 0's gathered grains and points.
      CellGrid<2> G;
      G.lo[0] = G.lo[1] = 0;
      G.h = 0.025;
      G.n[0] = G.n[1] = 16;
      std::vector<double> x, r, dense((size_t)G.size(), 0.0);
      for (const auto &g : z.dem) {
        x.push_back(g.x[0]);
        x.push_back(g.x[1]);
        r.push_back(g.r);
      }
      for (const auto &p : z.mpm) dense[(size_t)cell_index<2>(G, p.x)] = 1;
      ZoneRule rule;
      rule.band_distance = 2 * G.h;
      rule.half_width = 0.5 * G.h;
      const std::vector<Zone> ref = oracle_zones<2>(G, packing_fraction<2>(G, x, r), dense, 0.3, rule);
      ok_ref = (long)ref.size() == (long)z.zones.size();
      int seen[3] = {0, 0, 0};
      for (size_t c = 0; ok_ref && c < ref.size(); ++c) {
        ok_ref = ok_ref && (int)ref[c] == z.zones[c];
        seen[(int)ref[c]] = 1;
      }
      all3 = seen[0] && seen[1] && seen[2];
      for (const auto &p : z.mpm) ++ref_counts[(int)ref[(size_t)cell_index<2>(G, p.x)]];
      for (size_t q = 0; q < r.size(); ++q) ++ref_counts[3 + (int)ref[(size_t)cell_index<2>(G, &x[2 * q])]];
      for (int k = 0; k < 6; ++k) ok_counts = ok_counts && ref_counts[k] == z.counts[k];
      ok_one = z.zones == one.zones;
    }
    INFO(n << " ranks: material points C/B/D " << z.counts[0] << "/" << z.counts[1] << "/" << z.counts[2] << ", grains " << z.counts[3] << "/" << z.counts[4] << "/" << z.counts[5]
           << ", reference " << ref_counts[0] << "/" << ref_counts[1] << "/" << ref_counts[2] << ", " << ref_counts[3] << "/" << ref_counts[4] << "/" << ref_counts[5]);
    REQUIRE(bcast(r0 ? z.updates : 0L) == nsteps / 5 + 1);
    REQUIRE(bcast(r0 ? (long)z.same_on_ranks : 0L) == 1);
    REQUIRE(bcast((long)all3) == 1); // the premise: the box has all three zones
    REQUIRE(bcast((long)ok_ref) == 1);
    REQUIRE(bcast((long)ok_counts) == 1);
    REQUIRE(bcast((long)ok_one) == 1);
  }
}

namespace {

// A material point or grain as the zone-driven test compares them: id, position, mass,
// share (material points: hybrid_weight; grains: carried / full mass), radius (grains).
struct Shared {
  int64_t id;
  double x[2], m, w, r, v[2];
};

// Rank 0 gets every material point's (id, x, m, w), sorted by id; collective.
std::vector<Shared> gather_points(Simulation<2> &sim) {
  std::vector<double> loc;
  ParticleView<2> P = sim.particles.get();
  const double *W = P.field(sim.particles.field_index("hybrid_weight"));
  for (PetscInt p = 0; p < P.n; ++p) loc.insert(loc.end(), {(double)P.id[p], P.x[2 * p], P.x[2 * p + 1], P.m[p], W[p], P.v[2 * p], P.v[2 * p + 1]});
  sim.particles.restore(P);
  int n = (int)loc.size(), size;
  MPI_Comm_size(sim.comm, &size);
  std::vector<int> cnt(size), off(size, 0);
  MPI_Gather(&n, 1, MPI_INT, cnt.data(), 1, MPI_INT, 0, sim.comm);
  for (int r = 1; r < size; ++r) off[r] = off[r - 1] + cnt[r - 1];
  std::vector<double> all(sim.rank == 0 ? off[size - 1] + cnt[size - 1] : 0);
  MPI_Gatherv(loc.data(), n, MPI_DOUBLE, all.data(), cnt.data(), off.data(), MPI_DOUBLE, 0, sim.comm);
  std::vector<Shared> out;
  for (size_t k = 0; k + 7 <= all.size(); k += 7) out.push_back({(int64_t)all[k], {all[k + 1], all[k + 2]}, all[k + 3], all[k + 4], 0, {all[k + 5], all[k + 6]}});
  std::sort(out.begin(), out.end(), [](const Shared &a, const Shared &b) { return a.id < b.id; });
  return out;
}

std::vector<Shared> grains_of(const std::vector<dem::GrainRecord> &g) {
  std::vector<Shared> out;
  for (const auto &q : g) out.push_back({q.id, {q.x[0], q.x[1]}, q.m, q.m / (2500 * M_PI * q.r * q.r), q.r, {q.v[0], q.v[1]}});
  return out;
}

struct Driven {
  double worst = 0;                          // largest momentum change over a step, zone updates and conversions included
  double mass0 = 0, mass1 = 0;               // total mass (points + grains) at the start and the end of the run
  double balance = 0;                        // HybridModule::mass_balance at the end
  double handed[2] = {0, 0};                 // HybridModule::share_mass at the end
  long homogenised = 0, enriched = 0, beside = 0, partial = 0; // grains made; cells enriched next to grains, in part
  long shares[4] = {0, 0, 0, 0};             // HybridModule::share_counts at the end
  std::vector<Shared> pts0, gr0, pts1, gr1;  // before and after one more update_zones
  Driven *setup = nullptr;                   // where to put the set-up's update (fixed band -> zones), the same fields
  std::vector<ParticleRecord> mpm;           // final state (before that update)
  std::vector<dem::GrainRecord> dem;
  std::vector<int> zones;                    // of the extra update
};

// Points and grains, each with its carried mass, over all ranks.
double both_mass(Simulation<2> &sim, DemModule<2> &d) {
  double m = 0;
  for (long q = 0; q < d.engine().owned(); ++q) m += d.engine().mass(q);
  MPI_Allreduce(MPI_IN_PLACE, &m, 1, MPI_DOUBLE, MPI_SUM, sim.comm);
  return sim.totals().mass + m;
}

// The band box with the oracle driving the shares (every 5 steps), then one more update by
// hand on the final state, gathered before and after it. homog: with homogenisation (and
// the band of run_homog); enrich: with enrichment; bd: the band's distance inside the
// contour in cells (40: the whole box is discrete, the points hand their mass to the grains).
Driven run_driven(int n, int nsteps, int ck_at = -1, const std::string &restart = "", bool homog = false, bool enrich = false, double bd = 4, Driven *setup = nullptr) {
  Driven out;
  out.setup = setup;
  Config c = band_mpm<2>();
  c.body_lo[1] = 0.16; // above the fixed band's lo: the grains below it (full share) share cells with points
  c.restart = restart;
  const std::string ck = gmtest::outdir("hybrid") + "/driven_ck.h5";
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    Simulation<2> sim(comm, c);
    sim.extra_fields = {{"hybrid_weight", 1}, {"hybrid_zone", 1}};
    sim.extra_modules = [&](Simulation<2> &s) {
      hybrid::FixedBand b = band_y();
      b.lo = 0.155;
      for (auto &m : hybrid_modules<2>(s, band_dem<2>(), b)) s.modules.push_back(std::move(m));
      HybridModule<2>::Oracle o;
      o.every = 5;
      o.rule.band_distance = bd * s.grid.h; // the band 3.4 to 4.6 cells inside the contour:
      o.rule.half_width = 0.6 * s.grid.h;  // the overlap's lowest cells are band, its middle continuum
      if (homog) { // as run_homog: the grains' own layer is continuum and homogenises
        o.rule.band_distance = s.grid.h;
        o.rule.half_width = 0.4 * s.grid.h;
      }
      o.drive = true;
      o.homogenise = homog;
      o.enrich = enrich;
      // The set-up's update turns the fixed band's shares into the zones': the most changes.
      auto &dm = static_cast<DemModule<2> &>(*s.modules[s.modules.size() - 2]);
      auto &hm = static_cast<HybridModule<2> &>(*s.modules.back());
      const bool fresh = restart.empty();
      std::vector<Shared> q0, r0, q1, r1;
      if (fresh) {
        q0 = gather_points(s);
        r0 = grains_of(dm.engine().gather());
      }
      hm.set_oracle(s, o);
      if (fresh && out.setup) {
        q1 = gather_points(s);
        r1 = grains_of(dm.engine().gather());
        if (gmtest::world_rank() == 0) {
          out.setup->pts0 = q0;
          out.setup->gr0 = r0;
          out.setup->pts1 = q1;
          out.setup->gr1 = r1;
          for (auto q : hm.zones()) out.setup->zones.push_back((int)q);
        }
      }
    };
    sim.setup();
    DemModule<2> *d = sim.find<DemModule<2>>();
    HybridModule<2> *h = sim.find<HybridModule<2>>();
    out.mass0 = both_mass(sim, *d);
    for (int s = (int)sim.nsteps; s < nsteps; ++s) {
      double p0[3], p1[3], scale;
      momentum(sim, *d, p0, &scale);
      sim.step(kDt);
      momentum(sim, *d, p1, &scale);
      // Every step, the zone updates (steps 5, 10, ...) and their conversions included.
      out.worst = std::max(out.worst, std::sqrt((p1[0] - p0[0]) * (p1[0] - p0[0]) + (p1[1] - p0[1]) * (p1[1] - p0[1])) / scale);
      if (s + 1 == ck_at) sim.write_checkpoint(ck);
    }
    out.mass1 = both_mass(sim, *d);
    auto fin = sim.gather(0);
    auto fing = d->engine().gather();
    auto p0 = gather_points(sim);
    auto g0 = grains_of(d->engine().gather());
    h->update_zones(sim);
    auto p1 = gather_points(sim);
    auto g1 = grains_of(d->engine().gather());
    if (gmtest::world_rank() == 0) {
      for (int k = 0; k < 4; ++k) out.shares[k] = h->share_counts()[k];
      out.handed[0] = h->share_mass()[0];
      out.handed[1] = h->share_mass()[1];
      out.balance = h->mass_balance();
      out.homogenised = h->homogenised();
      out.enriched = h->enriched();
      out.beside = h->enrich_beside();
      out.partial = h->enrich_partial();
      out.pts0 = p0;
      out.gr0 = g0;
      out.pts1 = p1;
      out.gr1 = g1;
      out.mpm = fin;
      out.dem = fing;
      for (auto q : h->zones()) out.zones.push_back((int)q);
    }
  });
  out.worst = bcast(out.worst);
  out.mass0 = bcast(out.mass0);
  out.mass1 = bcast(out.mass1);
  return out;
}

// The independent reference of one share update: the pure kernels on the state before it
// give the zones; every cell (points and grains by their positions, which the update does not
// move) must keep its mass and linear momentum to round-off while they pass between the
// species; a point may only be removed in a discrete cell and a grain in a continuum cell
// (share 0: all of its mass went to the other species); no species gains mass in a cell
// where the other one is absent; a grain's share stays in (0, 1]. Returns a description of
// the first mismatch ("" if none) and counts the changed and removed ones.
std::string check_shares(const Driven &z, long changed[2], long removed[2], double *worst_cell, double bd) {
  using namespace granmpm::hybrid;
  CellGrid<2> G;
  G.lo[0] = G.lo[1] = 0;
  G.h = 0.025;
  G.n[0] = G.n[1] = 16;
  const size_t N = (size_t)G.size();
  std::vector<double> x, r, dense(N, 0.0), grain(N, 0.0);
  for (const auto &g : z.gr0) {
    x.insert(x.end(), {g.x[0], g.x[1]});
    r.push_back(g.r);
    grain[(size_t)cell_index<2>(G, g.x)] = 1;
  }
  for (const auto &p : z.pts0) dense[(size_t)cell_index<2>(G, p.x)] = 1;
  ZoneRule rule;
  rule.band_distance = bd * G.h;
  rule.half_width = 0.6 * G.h;
  const std::vector<Zone> zones = oracle_zones<2>(G, packing_fraction<2>(G, x, r), dense, 0.3, rule);
  for (size_t c = 0; c < zones.size(); ++c)
    if ((int)zones[c] != z.zones[c]) return "zone of cell " + std::to_string(c);
  // Per cell: mass, momentum x, y before and after; scale sum m |v| before.
  std::vector<double> bal(N * 7, 0.0);
  auto add = [&](const Shared &s, int at) {
    double *b = &bal[(size_t)cell_index<2>(G, s.x) * 7];
    b[at] += s.m;
    b[at + 1] += s.m * s.v[0];
    b[at + 2] += s.m * s.v[1];
    if (at == 0) b[6] += s.m * (std::fabs(s.v[0]) + std::fabs(s.v[1])) + s.m;
  };
  auto check = [&](const std::vector<Shared> &before, const std::vector<Shared> &after, bool points, long &nch, long &nrm) -> std::string {
    const std::string what = points ? "point " : "grain ";
    size_t k = 0;
    for (const Shared &b : before) {
      add(b, 0);
      const size_t c = (size_t)cell_index<2>(G, b.x);
      const bool there = k < after.size() && after[k].id == b.id;
      if (!there) {
        if (zones[c] != (points ? Zone::Discrete : Zone::Continuum)) return what + std::to_string(b.id) + " removed outside the zone of the other species";
        if (!((points ? grain : dense)[c] > 0)) return what + std::to_string(b.id) + " removed from a cell without the other species";
        ++nrm;
        continue;
      }
      const Shared &a = after[k++];
      add(a, 3);
      if (a.x[0] != b.x[0] || a.x[1] != b.x[1]) return what + std::to_string(b.id) + " moved";
      if (!points && !(a.w > 0 && a.w <= 1 + 1e-14)) return what + std::to_string(b.id) + " share " + std::to_string(a.w);
      if (a.m != b.m && !((points ? grain : dense)[c] > 0)) return what + std::to_string(b.id) + " mass changed in a cell without the other species";
      nch += a.m != b.m;
    }
    return k == after.size() ? "" : "extra entries after the update";
  };
  std::string e = check(z.pts0, z.pts1, true, changed[0], removed[0]);
  if (e.empty()) e = check(z.gr0, z.gr1, false, changed[1], removed[1]);
  if (!e.empty()) return e;
  double worst = 0;
  for (size_t c = 0; c < N; ++c) {
    const double *b = &bal[c * 7];
    if (!(b[6] > 0)) continue;
    const double d = std::max({std::fabs(b[3] - b[0]), std::fabs(b[4] - b[1]), std::fabs(b[5] - b[2])}) / b[6];
    worst = std::max(worst, d);
    if (d > 1e-13) return "cell " + std::to_string(c) + ": mass or momentum changed by " + std::to_string(d) + " of its scale";
  }
  if (worst_cell) *worst_cell = worst;
  return "";
}

} // namespace

TEST_CASE("hybrid zones drive the shares: each cell hands mass and momentum over to round-off, 1, 2, 3 ranks", "[parallel][hybrid]") {
  const int nsteps = 23, r0 = gmtest::world_rank() == 0;
  // bd 4: the band inside the block, grains hand their mass to the points; bd 40: the whole
  // box is discrete, the points hand theirs to the band's grains (up to a grain's full mass).
  for (double bd : {4.0, 40.0}) {
    Driven first; // the set-up's update of each run
    const Driven one = run_driven(1, nsteps, -1, "", false, false, bd, &first);
    for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
      const Driven z = n == 1 ? one : run_driven(n, nsteps, -1, "", false, false, bd, &first);
      long changed[2] = {0, 0}, removed[2] = {0, 0}, changed0[2] = {0, 0}, removed0[2] = {0, 0};
      double cell = 0, cell0 = 0;
      std::string err = r0 ? check_shares(z, changed, removed, &cell, bd) : "";
      if (r0 && err.empty()) err = check_shares(first, changed0, removed0, &cell0, bd);
      INFO("the set-up's update: points changed/removed " << changed0[0] << "/" << removed0[0] << ", grains " << changed0[1] << "/" << removed0[1]
                                                       << ", worst cell balance " << cell0);
      REQUIRE(bcast(r0 ? changed0[0] + changed0[1] : 0L) > 0); // the premise: the per-cell check sees hand-overs
      INFO("band " << bd << " cells inside, " << n << " ranks: " << (err.empty() ? "shares as the rule" : err) << "; during the run: points changed/removed " << z.shares[0]
                   << "/" << z.shares[1] << ", grains " << z.shares[2] << "/" << z.shares[3] << ", handed " << z.handed[0] << " kg points -> grains, " << z.handed[1]
                   << " kg grains -> points; last update: points " << changed[0] << "/" << removed[0] << ", grains " << changed[1] << "/" << removed[1]
                   << ", worst cell balance " << cell << "; worst momentum change over a step (zone updates included) " << z.worst << "; mass " << z.mass0 << " -> "
                   << z.mass1);
      REQUIRE(bcast(r0 ? (long)err.empty() : 0L) == 1);
      // The premise: mass passes (grains -> points at bd 4, points -> grains at bd 40) and
      // grains or points give all of theirs.
      REQUIRE(bcast(r0 ? z.shares[0] : 0L) > 0);
      REQUIRE(bcast(r0 ? z.shares[2] : 0L) > 0);
      REQUIRE(bcast(r0 ? z.shares[3] + z.shares[1] : 0L) > 0);
      REQUIRE(bcast(r0 ? z.handed[bd > 10 ? 0 : 1] : 0.0) > 0);
      REQUIRE(z.worst < 1e-13);
      REQUIRE(std::fabs(z.mass1 - z.mass0) < 1e-13 * z.mass0);
      REQUIRE(bcast(r0 ? std::fabs(z.balance) : 1.0) < 1e-13 * z.mass0);
      if (n > 1) {
        const double dm = bcast(r0 ? gmtest::max_rel_diff(z.mpm, one.mpm) : 0.0);
        const double dd = bcast(r0 ? grain_diff(z.dem, one.dem) : 0.0);
        INFO("MPM max rel diff " << dm << ", DEM max diff " << dd);
        REQUIRE(bcast(r0 ? (long)(z.mpm.size() == one.mpm.size() && z.dem.size() == one.dem.size()) : 0L) == 1);
        REQUIRE(bcast(r0 ? (long)(z.zones == one.zones) : 0L) == 1);
        REQUIRE(dm < 1e-12);
        REQUIRE(dd < 1e-9); // as the fixed band's (contacts amplify the grid sums' round-off)
      }
    }
  }
}

// The whole-run checks of the conversion runs on n ranks: the total mass of points and grains
// at the end equals the start's and the zone updates' balance is round-off, the momentum is
// unchanged over every step, and on 2 and 3 ranks points and grains agree with 1 rank's run
// (grains to 1e-9 as the fixed band's: contacts amplify the grid sums' round-off; >= 0
// catches a NaN).
static void require_conserved_and_rank_equal(const Driven &z, const Driven &one, int n) {
  const int r0 = gmtest::world_rank() == 0;
  REQUIRE(std::fabs(z.mass1 - z.mass0) < 1e-13 * z.mass0);
  REQUIRE(bcast(r0 ? std::fabs(z.balance) : 1.0) < 1e-13 * z.mass0);
  REQUIRE(z.worst < 1e-13);
  if (n == 1) return;
  const double dm = bcast(r0 ? gmtest::max_rel_diff(z.mpm, one.mpm) : 0.0);
  const double dd = bcast(r0 ? grain_diff(z.dem, one.dem) : 0.0);
  INFO("MPM max rel diff " << dm << ", DEM max diff " << dd);
  REQUIRE(dm >= 0);
  REQUIRE(dm < 1e-12);
  REQUIRE(dd >= 0);
  REQUIRE(dd < 1e-9);
}

// The whole run with zone updates, shares, homogenisation and enrichment: the total mass of
// points and grains at the end equals the start's, and the total momentum (periodic box, no
// gravity) is unchanged over every step, the conversion steps included; 1, 2, 3 ranks.
TEST_CASE("hybrid zone changes with conversions: total mass and momentum of points and grains conserved over the run, 1, 2, 3 ranks", "[parallel][hybrid]") {
  const int nsteps = 33, r0 = gmtest::world_rank() == 0;
  const Driven one = run_driven(1, nsteps, -1, "", true, true);
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    const Driven z = n == 1 ? one : run_driven(n, nsteps, -1, "", true, true);
    INFO(n << " ranks: mass " << z.mass0 << " -> " << z.mass1 << " (relative " << (z.mass1 - z.mass0) / z.mass0 << "), balance of the zone updates " << z.balance
           << " kg; handed " << z.handed[0] << " kg points -> grains, " << z.handed[1] << " kg grains -> points; points changed/emptied " << z.shares[0] << "/" << z.shares[1]
           << ", grains " << z.shares[2] << "/" << z.shares[3] << "; homogenised " << z.homogenised << ", enriched " << z.enriched << " grains (cells next to grains " << z.beside << ", in part " << z.partial << "); worst momentum change over a step "
           << z.worst);
    // The premise: every kind of conversion happens.
    REQUIRE(bcast(r0 ? z.homogenised : 0L) > 0);
    REQUIRE(bcast(r0 ? z.enriched : 0L) > 0);
    REQUIRE(bcast(r0 ? z.handed[0] + z.handed[1] : 0.0) > 0);
    require_conserved_and_rank_equal(z, one, n);
  }
}

// Enrichment next to grains: the whole box discrete (band 40 cells inside the contour), so
// the material points' cells, with the band's grains in and around them, convert with the
// grains already there (hybrid::enrich_cell: on the sites clear of them). References: the total
// mass and momentum over every step (conservation), 1 against 2 and 3 ranks.
TEST_CASE("hybrid enrichment next to grains: mass and momentum conserved over the run, 1, 2, 3 ranks", "[parallel][hybrid]") {
  const int nsteps = 23, r0 = gmtest::world_rank() == 0;
  const Driven one = run_driven(1, nsteps, -1, "", false, true, 40);
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    const Driven z = n == 1 ? one : run_driven(n, nsteps, -1, "", false, true, 40);
    INFO(n << " ranks: mass " << z.mass0 << " -> " << z.mass1 << " (relative " << (z.mass1 - z.mass0) / z.mass0 << "), balance of the zone updates " << z.balance
           << " kg; handed " << z.handed[0] << " kg points -> grains; enriched " << z.enriched << " grains (cells next to grains " << z.beside << ", in part "
           << z.partial << "); worst momentum change over a step " << z.worst);
    REQUIRE(bcast(r0 ? z.beside : 0L) > 0); // the premise (cells in part: the unit test of enrich_cell)
    require_conserved_and_rank_equal(z, one, n);
  }
}

TEST_CASE("hybrid zones drive the shares: checkpoint and restart continue bit for bit", "[parallel][hybrid][checkpoint]") {
  const std::string ck = gmtest::outdir("hybrid") + "/driven_ck.h5";
  for (int n = 1; n <= std::min(2, gmtest::world_size()); ++n) {
    // With homogenisation: grains convert at the updates of steps 5, 10 and 15 (the last one
    // after the restart at 12 reads the zones of step 10 from the checkpoint).
    const Driven full = run_driven(n, 18, 12, "", true);
    const Driven cont = run_driven(n, 18, -1, ck, true);
    INFO(n << " ranks: " << full.mpm.size() << " material points at the end");
    REQUIRE(bcast(gmtest::world_rank() == 0 ? (long)full.mpm.size() : 0L) > 512); // the premise: grains were converted
    Both a{full.mpm, full.dem}, b{cont.mpm, cont.dem};
    REQUIRE(bcast(gmtest::world_rank() == 0 ? (long)(bitwise(a, b) && full.zones == cont.zones) : 0L) == 1);
  }
}

namespace {

struct Homog {
  double before[4] = {0, 0, 0, 0}, after[4] = {0, 0, 0, 0}; // mass, momentum x, y, momentum scale
  long converted = 0, points_before = 0, grains_before = 0, points_after = 0, grains_after = 0;
  std::vector<ParticleRecord> mpm; // after the conversion
  std::vector<dem::GrainRecord> dem0, dem1, dem2; // dem2: after the enrichment
  double enr_before[4] = {0, 0, 0, 0}, enr_after[4] = {0, 0, 0, 0};
  long enriched = 0, enriched_points = 0, skipped = 0, points_enriched = 0, beside = 0, partial = 0;
  std::map<int64_t, std::array<double, 3>> kick; // before the conversion: each grain's pending half kick / m
};

// Totals over both species (each with its carried mass): mass, momentum, momentum scale.
template <int dim>
void totals(Simulation<dim> &sim, DemModule<dim> &d, double t[4]) {
  double p[3], scale;
  momentum(sim, d, p, &scale);
  dem::Engine &e = d.engine();
  double m = 0;
  for (long q = 0; q < e.owned(); ++q) m += e.mass(q);
  MPI_Allreduce(MPI_IN_PLACE, &m, 1, MPI_DOUBLE, MPI_SUM, sim.comm);
  t[0] = sim.totals().mass + m;
  t[1] = p[0];
  t[2] = p[1];
  t[3] = scale;
}

// Rank 0 gets every grain's pending half kick as a velocity (id -> J / m); collective.
template <int dim>
std::map<int64_t, std::array<double, 3>> pending_kicks(DemModule<dim> &d, MPI_Comm comm) {
  dem::Engine &e = d.engine();
  std::vector<double> loc;
  for (long q = 0; q < e.owned(); ++q) {
    const dem::V3 J = e.pending_impulse(q);
    loc.insert(loc.end(), {(double)e.id(q), J.x / e.mass(q), J.y / e.mass(q), J.z / e.mass(q)});
  }
  int n = (int)loc.size(), size, rank;
  MPI_Comm_size(comm, &size);
  MPI_Comm_rank(comm, &rank);
  std::vector<int> cnt(size), off(size, 0);
  MPI_Gather(&n, 1, MPI_INT, cnt.data(), 1, MPI_INT, 0, comm);
  for (int r = 1; r < size; ++r) off[r] = off[r - 1] + cnt[r - 1];
  std::vector<double> all(rank == 0 ? off[size - 1] + cnt[size - 1] : 0);
  MPI_Gatherv(loc.data(), n, MPI_DOUBLE, all.data(), cnt.data(), off.data(), MPI_DOUBLE, 0, comm);
  std::map<int64_t, std::array<double, 3>> out;
  for (size_t k = 0; k + 4 <= all.size(); k += 4) out[(int64_t)all[k]] = {all[k + 1], all[k + 2], all[k + 3]};
  return out;
}

// The band box with zones driving the shares (band 0.6 to 1.4 cells inside the contour: the
// grains' own layer is continuum below the material points), 10 steps without conversions,
// one more zone update by hand, then homogenise() alone between two totals.
template <int dim>
Homog run_homog(int n) {
  Homog out;
  Config c = band_mpm<dim>();
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    Simulation<dim> sim(comm, c);
    sim.extra_fields = {{"hybrid_weight", 1}, {"hybrid_zone", 1}};
    sim.extra_modules = [&](Simulation<dim> &s) {
      for (auto &m : hybrid_modules<dim>(s, band_dem<dim>(), band_y())) s.modules.push_back(std::move(m));
      typename HybridModule<dim>::Oracle o;
      o.every = 5;
      o.rule.band_distance = s.grid.h;
      o.rule.half_width = 0.4 * s.grid.h;
      o.drive = true;
      static_cast<HybridModule<dim> &>(*s.modules.back()).set_oracle(s, o);
    };
    sim.setup();
    DemModule<dim> *d = sim.template find<DemModule<dim>>();
    HybridModule<dim> *h = sim.template find<HybridModule<dim>>();
    for (int s = 0; s < 10; ++s) sim.step(kDt);
    h->update_zones(sim);
    auto g0 = d->engine().gather();
    auto kick = pending_kicks(*d, comm);
    const long np0 = sim.particles.global_size();
    totals(sim, *d, out.before);
    h->homogenise(sim);
    totals(sim, *d, out.after);
    auto g1 = d->engine().gather();
    auto p1 = sim.gather(0);
    const long np1 = sim.particles.global_size();
    totals(sim, *d, out.enr_before);
    h->enrich(sim);
    totals(sim, *d, out.enr_after);
    auto g2 = d->engine().gather();
    const long np2 = sim.particles.global_size();
    if (gmtest::world_rank() == 0) {
      out.converted = h->homogenised();
      out.points_before = np0;
      out.points_after = np1;
      out.kick = std::move(kick);
      out.dem0 = std::move(g0);
      out.dem1 = std::move(g1);
      out.mpm = std::move(p1);
      out.dem2 = std::move(g2);
      out.enriched = h->enriched();
      out.enriched_points = h->enriched_points();
      out.skipped = h->enrich_skipped();
      out.beside = h->enrich_beside();
      out.partial = h->enrich_partial();
      out.points_enriched = np1 - np2;
    }
  });
  for (int k = 0; k < 4; ++k) {
    out.before[k] = bcast(out.before[k]);
    out.after[k] = bcast(out.after[k]);
    out.enr_before[k] = bcast(out.enr_before[k]);
    out.enr_after[k] = bcast(out.enr_after[k]);
  }
  return out;
}

} // namespace

TEST_CASE("hybrid homogenisation: grains become material points, mass and momentum conserved, 2D and 3D, 1, 2, 3 ranks", "[parallel][hybrid]") {
  const int r0 = gmtest::world_rank() == 0;
  for (int dim = 2; dim <= 3; ++dim) {
  const Homog one = dim == 2 ? run_homog<2>(1) : run_homog<3>(1);
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    const Homog z = n == 1 ? one : dim == 2 ? run_homog<2>(n) : run_homog<3>(n);
    const double dm = std::fabs(z.after[0] - z.before[0]) / z.before[0];
    const double dp = std::hypot(z.after[1] - z.before[1], z.after[2] - z.before[2]) / z.before[3];
    // Each converted grain is a new point with the grain's id + kConvertedId, mass, position
    // and velocity; every grain not converted is unchanged.
    long matched = 0, bad = 0, stressed = 0;
    if (r0) {
      std::map<int64_t, const dem::GrainRecord *> left;
      for (const auto &g : z.dem1) left[g.id] = &g;
      std::map<int64_t, const ParticleRecord *> pts;
      for (const auto &p : z.mpm) pts[p.id] = &p;
      for (const auto &g : z.dem0) {
        if (left.count(g.id)) {
          const auto *k = left[g.id];
          bad += k->m != g.m || k->v[0] != g.v[0] || k->x[1] != g.x[1];
          continue;
        }
        auto it = pts.find(HybridModule<2>::kConvertedId + g.id);
        if (it == pts.end()) {
          ++bad;
          continue;
        }
        const ParticleRecord &p = *it->second;
        const std::array<double, 3> kv = z.kick.at(g.id); // the point takes the grain's pending half kick along
        // Contacts only push (f_n >= 0, the tangential force is normal to the branch):
        // the trace of sum F (x) l is <= 0, < 0 where the cell's grains touch.
        bad += p.m != g.m || p.x[0] != g.x[0] || p.x[1] != g.x[1] || p.x[2] != g.x[2] || std::fabs(p.v[0] - (g.v[0] + kv[0])) > 1e-14 * (1 + std::fabs(g.v[0])) || std::fabs(p.v[1] - (g.v[1] + kv[1])) > 1e-14 * (1 + std::fabs(g.v[1])) ||
               std::fabs(p.v[2] - (g.v[2] + kv[2])) > 1e-14 * (1 + std::fabs(g.v[2])) || !(p.vol > 0) || !(p.s[0] + p.s[1] + p.s[2] <= 0);
        stressed += p.s[0] + p.s[1] + p.s[2] < 0;
        ++matched;
      }
    }
    INFO(dim << "D, " << n << " ranks: " << matched << " grains converted (module: " << z.converted << "), " << stressed << " with a compressive stress, " << bad << " mismatches; relative mass change " << dm << ", momentum change " << dp
           << "; points " << z.points_before << " -> " << z.points_after);
    REQUIRE(bcast(r0 ? matched : 0L) > 20); // the premise: a layer of grains converts
    REQUIRE(bcast(r0 ? stressed : 0L) > matched / 2);
    REQUIRE(bcast(r0 ? z.converted : 0L) == bcast(r0 ? matched : 0L));
    REQUIRE(bcast(r0 ? z.points_after - z.points_before : 0L) == bcast(r0 ? matched : 0L));
    REQUIRE(bcast(r0 ? bad : 1L) == 0);
    REQUIRE(dm < 1e-14);
    REQUIRE(dp < 1e-14);
    if (n > 1) {
      const double dmpm = bcast(r0 ? gmtest::max_rel_diff(z.mpm, one.mpm) : 0.0);
      INFO("points after the conversion: max rel diff to 1 rank " << dmpm);
      REQUIRE(dmpm >= 0); // the same points (-1: not the same count)
      REQUIRE(dmpm < 1e-12);
    }
  }
}
}
// The homogenisation's stress comes from dem::Engine::dipoles: for two disks at rest pressed
// by delta along the unit vector n, each carries the normal force k_n delta (linear law, no
// damping at rest, no tangential spring yet) at the branch r n, so its dipole is
// -k_n delta r n (x) n exactly (analytic reference; also with 3 ranks cutting the box).
// Enrichment on the same run, right after the homogenisation: the material points of the
// cells that stayed discrete (the top of the block) become grains.
TEST_CASE("hybrid enrichment: material points become grains, mass and momentum conserved, no overlap, 2D and 3D, 1, 2, 3 ranks", "[parallel][hybrid]") {
  const int r0 = gmtest::world_rank() == 0;
  for (int dim = 2; dim <= 3; ++dim) {
    const Homog one = dim == 2 ? run_homog<2>(1) : run_homog<3>(1);
    for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
      const Homog z = n == 1 ? one : dim == 2 ? run_homog<2>(n) : run_homog<3>(n);
      const double dm = std::fabs(z.enr_after[0] - z.enr_before[0]) / z.enr_before[0];
      double dp = 0;
      for (int k = 1; k <= 2; ++k) dp = std::max(dp, std::fabs(z.enr_after[k] - z.enr_before[k]) / z.enr_before[3]);
      // Overlaps among the new grains and with the grains already there (over r of the pair).
      double ov_new = 0, ov_old = 0;
      long fresh = 0;
      if (r0)
        for (size_t a = 0; a < z.dem2.size(); ++a) {
          const bool na = z.dem2[a].id >= HybridModule<2>::kEnrichedId;
          fresh += na;
          for (size_t b = a + 1; b < z.dem2.size(); ++b) {
            const bool nb = z.dem2[b].id >= HybridModule<2>::kEnrichedId;
            if (!na && !nb) continue;
            double d2 = 0;
            for (int k = 0; k < 3; ++k) d2 += (z.dem2[a].x[k] - z.dem2[b].x[k]) * (z.dem2[a].x[k] - z.dem2[b].x[k]);
            const double ov = (z.dem2[a].r + z.dem2[b].r - std::sqrt(d2)) / std::min(z.dem2[a].r, z.dem2[b].r);
            (na && nb ? ov_new : ov_old) = std::max(na && nb ? ov_new : ov_old, ov);
          }
        }
      INFO(dim << "D, " << n << " ranks: " << z.enriched_points << " points -> " << z.enriched << " grains (" << fresh << " new in the gather), " << z.skipped
                << " cells skipped, " << z.beside << " converted next to grains, " << z.partial << " in part; relative mass change " << dm << ", momentum change " << dp << "; largest overlap among new grains " << ov_new << ", with old ones " << ov_old);
      REQUIRE(bcast(r0 ? z.enriched : 0L) > 10); // the premise: the top layer converts
      REQUIRE(bcast(r0 ? fresh : 0L) == bcast(r0 ? z.enriched : 0L));
      REQUIRE(bcast(r0 ? z.points_enriched : 0L) == bcast(r0 ? z.enriched_points : -1L));
      REQUIRE(dm < 1e-14);
      REQUIRE(dp < 1e-14);
      REQUIRE(bcast(r0 ? ov_new : 1.0) <= 0.05); // -dem_overlap_tol
      REQUIRE(bcast(r0 ? ov_old : 1.0) <= 0.05); // with the grains already there too
      if (n > 1) {
        const double dd = bcast(r0 ? grain_diff(z.dem2, one.dem2) : 0.0);
        INFO("grains after the enrichment: max diff to 1 rank " << dd);
        REQUIRE(dd >= 0);
        REQUIRE(dd < 1e-9);
      }
    }
  }
}

TEST_CASE("contact dipoles: two pressed disks give -k_n delta r n (x) n each", "[parallel][hybrid]") {
  const double r = 0.01, delta = 0.02 * r, kn = 1e5, ang = 0.5236; // about 30 degrees
  const double n[2] = {std::cos(ang), std::sin(ang)}, c0[2] = {0.1, 0.1};
  for (int np = 1; np <= std::min(3, gmtest::world_size()); ++np) {
    double worst = 0;
    long seen = 0;
    gmtest::on_ranks(np, [&](MPI_Comm comm) {
      dem::Config c;
      c.dim = 2;
      c.lo = {0, 0, 0};
      c.hi = {0.2, 0.2, 0};
      c.radius = r;
      c.contact.kn = kn;
      c.wall = c.contact;
      c.scene = dem::Scene::List;
      const double d = 2 * r - delta;
      c.grains = {c0[0], c0[1], r, 0, 0, c0[0] + d * n[0], c0[1] + d * n[1], r, 0, 0};
      c.quiet = true;
      c.fields = false;
      dem::Engine e(comm, c);
      e.setup();
      const auto D = e.dipoles();
      const double ref[6] = {-kn * delta * r * n[0] * n[0], -kn * delta * r * n[1] * n[1], 0, -kn * delta * r * n[0] * n[1], 0, 0};
      double w = 0;
      for (const auto &a : D)
        for (int k = 0; k < 6; ++k) w = std::max(w, std::fabs(a[k] - ref[k]) / (kn * delta * r));
      long cnt = (long)D.size();
      MPI_Allreduce(MPI_IN_PLACE, &w, 1, MPI_DOUBLE, MPI_MAX, comm);
      MPI_Allreduce(MPI_IN_PLACE, &cnt, 1, MPI_LONG, MPI_SUM, comm);
      if (gmtest::world_rank() == 0) {
        worst = w;
        seen = cnt;
      }
    });
    INFO(np << " ranks: largest relative error of a dipole component " << bcast(worst));
    REQUIRE(bcast(seen) == 2);
    REQUIRE(bcast(worst) < 1e-12);
  }
}
