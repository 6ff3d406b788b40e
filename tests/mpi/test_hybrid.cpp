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

#include <cstring>

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
  for (long q = 0; q < e.owned(); ++q) {
    const dem::V3 v = e.velocities()[q];
    loc[0] += e.mass(q) * v.x;
    loc[1] += e.mass(q) * v.y;
    loc[2] += e.mass(q) * v.z;
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
  double x[2], m, w, r;
};

// Rank 0 gets every material point's (id, x, m, w), sorted by id; collective.
std::vector<Shared> gather_points(Simulation<2> &sim) {
  std::vector<double> loc;
  ParticleView<2> P = sim.particles.get();
  const double *W = P.field(sim.particles.field_index("hybrid_weight"));
  for (PetscInt p = 0; p < P.n; ++p) loc.insert(loc.end(), {(double)P.id[p], P.x[2 * p], P.x[2 * p + 1], P.m[p], W[p]});
  sim.particles.restore(P);
  int n = (int)loc.size(), size;
  MPI_Comm_size(sim.comm, &size);
  std::vector<int> cnt(size), off(size, 0);
  MPI_Gather(&n, 1, MPI_INT, cnt.data(), 1, MPI_INT, 0, sim.comm);
  for (int r = 1; r < size; ++r) off[r] = off[r - 1] + cnt[r - 1];
  std::vector<double> all(sim.rank == 0 ? off[size - 1] + cnt[size - 1] : 0);
  MPI_Gatherv(loc.data(), n, MPI_DOUBLE, all.data(), cnt.data(), off.data(), MPI_DOUBLE, 0, sim.comm);
  std::vector<Shared> out;
  for (size_t k = 0; k + 5 <= all.size(); k += 5) out.push_back({(int64_t)all[k], {all[k + 1], all[k + 2]}, all[k + 3], all[k + 4], 0});
  std::sort(out.begin(), out.end(), [](const Shared &a, const Shared &b) { return a.id < b.id; });
  return out;
}

std::vector<Shared> grains_of(const std::vector<dem::GrainRecord> &g) {
  std::vector<Shared> out;
  for (const auto &q : g) out.push_back({q.id, {q.x[0], q.x[1]}, q.m, q.m / (2500 * M_PI * q.r * q.r), q.r});
  return out;
}

struct Driven {
  double worst = 0;                          // largest momentum change over a step without a zone update
  long shares[4] = {0, 0, 0, 0};             // HybridModule::share_counts at the end
  std::vector<Shared> pts0, gr0, pts1, gr1;  // before and after one more update_zones
  std::vector<ParticleRecord> mpm;           // final state (before that update)
  std::vector<dem::GrainRecord> dem;
  std::vector<int> zones;                    // of the extra update
};

// The band box with the oracle driving the shares (every 5 steps), then one more update by
// hand on the final state, gathered before and after it.
Driven run_driven(int n, int nsteps, int ck_at = -1, const std::string &restart = "") {
  Driven out;
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
      o.rule.band_distance = 4 * s.grid.h; // the band 3.4 to 4.6 cells inside the contour:
      o.rule.half_width = 0.6 * s.grid.h;  // the overlap's lowest cells are band, its middle continuum
      o.drive = true;
      static_cast<HybridModule<2> &>(*s.modules.back()).set_oracle(s, o);
    };
    sim.setup();
    DemModule<2> *d = sim.find<DemModule<2>>();
    HybridModule<2> *h = sim.find<HybridModule<2>>();
    for (int s = (int)sim.nsteps; s < nsteps; ++s) {
      double p0[3], p1[3], scale;
      momentum(sim, *d, p0, &scale);
      sim.step(kDt);
      momentum(sim, *d, p1, &scale);
      if ((s + 1) % 5 != 0)
        out.worst = std::max(out.worst, std::sqrt((p1[0] - p0[0]) * (p1[0] - p0[0]) + (p1[1] - p0[1]) * (p1[1] - p0[1])) / scale);
      if (s + 1 == ck_at) sim.write_checkpoint(ck);
    }
    auto fin = sim.gather(0);
    auto fing = d->engine().gather();
    auto p0 = gather_points(sim);
    auto g0 = grains_of(d->engine().gather());
    h->update_zones(sim);
    auto p1 = gather_points(sim);
    auto g1 = grains_of(d->engine().gather());
    if (gmtest::world_rank() == 0) {
      for (int k = 0; k < 4; ++k) out.shares[k] = h->share_counts()[k];
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
  return out;
}

// The independent reference of one share update: the pure kernels on the state before it
// give the zones and which species each cell
// holds; each point and grain must then carry w = 1 / 0.5 / 0 (points: C / band / D; grains
// 1 - that), or all of its mass where the other species is absent, or be gone where w = 0,
// with its mass scaled by exactly the change of share. Returns a description of the first
// mismatch ("" if none) and counts the changed and removed ones.
std::string check_shares(const Driven &z, long changed[2], long removed[2]) {
  using namespace granmpm::hybrid;
  CellGrid<2> G;
  G.lo[0] = G.lo[1] = 0;
  G.h = 0.025;
  G.n[0] = G.n[1] = 16;
  std::vector<double> x, r, dense((size_t)G.size(), 0.0), grain((size_t)G.size(), 0.0);
  for (const auto &g : z.gr0) {
    x.insert(x.end(), {g.x[0], g.x[1]});
    r.push_back(g.r);
    grain[(size_t)cell_index<2>(G, g.x)] = 1;
  }
  for (const auto &p : z.pts0) dense[(size_t)cell_index<2>(G, p.x)] = 1;
  ZoneRule rule;
  rule.band_distance = 4 * G.h;
  rule.half_width = 0.6 * G.h;
  const std::vector<Zone> zones = oracle_zones<2>(G, packing_fraction<2>(G, x, r), dense, 0.3, rule);
  for (size_t c = 0; c < zones.size(); ++c)
    if ((int)zones[c] != z.zones[c]) return "zone of cell " + std::to_string(c);
  auto zone = [&](const double *p) { return zones[(size_t)cell_index<2>(G, p)]; };
  auto check = [&](const std::vector<Shared> &before, const std::vector<Shared> &after, bool points, long &nch, long &nrm) -> std::string {
    size_t k = 0;
    for (const Shared &b : before) {
      double w = continuum_weight(zone(b.x), rule);
      if (!points) w = 1 - w;
      const size_t c = (size_t)cell_index<2>(G, b.x);
      if (w < 1 && !((points ? grain : dense)[c] > 0)) w = 1;
      const bool there = k < after.size() && after[k].id == b.id;
      if (w == 0) {
        if (there) return std::string(points ? "point " : "grain ") + std::to_string(b.id) + " kept with share 0";
        ++nrm;
        continue;
      }
      if (!there) return std::string(points ? "point " : "grain ") + std::to_string(b.id) + " removed";
      const Shared &a = after[k++];
      if (std::fabs(a.w - w) > 1e-14) return std::string(points ? "point " : "grain ") + std::to_string(b.id) + " share " + std::to_string(a.w) + " expected " + std::to_string(w);
      if (std::fabs(a.m - b.m * w / b.w) > 1e-14 * b.m) return std::string(points ? "point " : "grain ") + std::to_string(b.id) + " mass not scaled by the share";
      nch += a.w != b.w;
    }
    return k == after.size() ? "" : "extra entries after the update";
  };
  std::string e = check(z.pts0, z.pts1, true, changed[0], removed[0]);
  return e.empty() ? check(z.gr0, z.gr1, false, changed[1], removed[1]) : e;
}

} // namespace

TEST_CASE("hybrid zones drive the shares: rule checked against the pure kernels, momentum per step, 1, 2, 3 ranks", "[parallel][hybrid]") {
  const int nsteps = 23, r0 = gmtest::world_rank() == 0;
  const Driven one = run_driven(1, nsteps);
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    const Driven z = n == 1 ? one : run_driven(n, nsteps);
    long changed[2] = {0, 0}, removed[2] = {0, 0};
    const std::string err = r0 ? check_shares(z, changed, removed) : "";
    INFO(n << " ranks: " << (err.empty() ? "shares as the rule" : err) << "; during the run: points changed/removed " << z.shares[0] << "/" << z.shares[1] << ", grains "
           << z.shares[2] << "/" << z.shares[3] << "; last update: points " << changed[0] << "/" << removed[0] << ", grains " << changed[1] << "/" << removed[1]
           << "; worst momentum change over a coupled step " << z.worst);
    REQUIRE(bcast(r0 ? (long)err.empty() : 0L) == 1);
    // The premise: shares change and grains and points are removed during the run.
    REQUIRE(bcast(r0 ? z.shares[0] : 0L) > 0);
    REQUIRE(bcast(r0 ? z.shares[2] : 0L) > 0);
    REQUIRE(bcast(r0 ? z.shares[3] + z.shares[1] : 0L) > 0);
    REQUIRE(z.worst < 1e-13);
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

TEST_CASE("hybrid zones drive the shares: checkpoint and restart continue bit for bit", "[parallel][hybrid][checkpoint]") {
  const std::string ck = gmtest::outdir("hybrid") + "/driven_ck.h5";
  for (int n = 1; n <= std::min(2, gmtest::world_size()); ++n) {
    const Driven full = run_driven(n, 18, 12);
    const Driven cont = run_driven(n, 18, -1, ck);
    INFO(n << " ranks");
    Both a{full.mpm, full.dem}, b{cont.mpm, cont.dem};
    REQUIRE(bcast(gmtest::world_rank() == 0 ? (long)(bitwise(a, b) && full.zones == cont.zones) : 0L) == 1);
  }
}
