// Checkpoint/restart: continuing from a checkpoint reproduces the uninterrupted run
// bitwise on the same number of ranks and to round-off on another number of ranks.
#include "harness.hpp"

#include <cstring>
#include <limits>

using namespace granmpm;
using gmtest::bcast;

namespace {

Config nonlocal_chute() {
  Config c; // seed 000 chute, steady nonlocal fluidity; starts sheared so g != 0 at once
  c.cells = {20, 8, 1};
  c.hi = {0.5, 0.4, 0};
  c.ppc = 2;
  c.set_scene_param("-chute_prestress", 1);
  c.gravity_ramp = 0;
  gmtest::quiet(c, "checkpoint");
  return c;
}

// Runs to max_steps (writing a checkpoint every `every` steps) and gathers the result.
template <int dim>
std::vector<ParticleRecord> run(int n, Config c, long max_steps, long every, const std::string &restart) {
  c.max_steps = max_steps;
  c.checkpoint_interval = every;
  c.checkpoint_file = gmtest::outdir("checkpoint") + "/ck.h5";
  c.restart = restart;
  std::vector<ParticleRecord> out;
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    Simulation<dim> sim(comm, c);
    sim.setup();
    sim.run();
    auto r = sim.gather(0);
    if (gmtest::world_rank() == 0) out = std::move(r);
  });
  return out;
}

bool bitwise_equal(const std::vector<ParticleRecord> &a, const std::vector<ParticleRecord> &b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (std::memcmp(&a[i], &b[i], sizeof(ParticleRecord)) != 0) return false;
  return true;
}

template <int dim>
void check(const Config &c) {
  const std::string ck = gmtest::outdir("checkpoint") + "/ck.h5";
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    // Uninterrupted: 60 steps; interrupted: checkpoint at 40, restart, 20 more steps.
    const auto full = run<dim>(n, c, 60, 0, "");
    run<dim>(n, c, 40, 40, "");
    const auto cont = run<dim>(n, c, 60, 0, ck);
    const long same = bcast((long)(gmtest::world_rank() == 0 ? bitwise_equal(full, cont) : 0));
    INFO("ranks " << n);
    REQUIRE(same == 1);
    // Restart the same checkpoint on another rank count: round-off.
    const int m = n % std::min(3, gmtest::world_size()) + 1;
    run<dim>(n, c, 40, 40, "");
    const auto other = run<dim>(m, c, 60, 0, ck);
    const double d = bcast(gmtest::world_rank() == 0 ? gmtest::max_rel_diff(full, other) : 0.0);
    INFO("checkpoint from " << n << " ranks continued on " << m << ": max relative difference " << d);
    REQUIRE(d >= 0);
    REQUIRE(d < 1e-8); // the fluidity solve (rtol 1e-12 here) depends on the partition
  }
}

// A hypoelastic block (E = 1e5, rho = 1000, 2 PPC, moving at v0) in the box [0, hi] under
// gravity from t = 0, writing nothing but checkpoints: the base of the block restart tests.
Config box_block(int dim, const std::array<double, 3> &hi, const std::array<int, 3> &cells, const std::array<std::array<BC, 2>, 3> &bc,
                 const std::array<double, 3> &body_lo, const std::array<double, 3> &body_hi, const std::array<double, 3> &v0) {
  Config c;
  c.dim = dim;
  c.scene = SceneKind::Block;
  c.material = MaterialKind::Hypoelastic;
  c.E = 1e5;
  c.rho = 1000;
  c.lo = {0, 0, 0};
  c.hi = hi;
  c.cells = cells;
  c.bc = bc;
  c.body_lo = body_lo;
  c.body_hi = body_hi;
  c.ppc = 2;
  c.v0 = v0;
  c.gravity = {0, -9.81, 0};
  c.gravity_ramp = 0;
  gmtest::quiet(c, "checkpoint");
  return c;
}

} // namespace

TEST_CASE("restart reproduces the uninterrupted run: nonlocal chute", "[checkpoint][parallel]") {
  PetscOptionsSetValue(NULL, "-fluidity_ksp_rtol", "1e-12");
  check<2>(nonlocal_chute());
  PetscOptionsClearValue(NULL, "-fluidity_ksp_rtol");
}

TEST_CASE("restart reproduces the uninterrupted run: 3D APIC block", "[checkpoint][parallel]") {
  Config c = box_block(3, {1.5, 0.6, 0.4}, {15, 6, 4}, {{{BC::Periodic, BC::Periodic}, {BC::Slip, BC::Slip}, {BC::Periodic, BC::Periodic}}}, {0.2, 0.1, 0}, {1.1, 0.5, 0.4},
                       {4, 0, 0.5});
  c.set_scene_param("-spin", 2);
  c.p0 = 100;
  c.shape = ShapeKind::BSpline2;
  check<3>(c);
}

TEST_CASE("restart refuses a checkpoint of another scene and names the option", "[checkpoint]") {
  Config c = nonlocal_chute();
  run<2>(1, c, 5, 5, "");
  Config other = c;
  other.cells = {40, 16, 1};
  other.restart = gmtest::outdir("checkpoint") + "/ck.h5";
  std::string msg;
  gmtest::on_ranks(1, [&](MPI_Comm comm) {
    try {
      Simulation<2> sim(comm, other);
      sim.setup();
    } catch (const UserError &e) {
      msg = e.what();
    }
  });
  if (gmtest::world_rank() == 0) {
    REQUIRE(msg.find("another scene") != std::string::npos);
    REQUIRE(msg.find("-cells") != std::string::npos);
  }
}

namespace {

// A 2D elastic block in the left fifth of a long box: on 2 or 3 ranks (split along x) the
// ranks to the right own no particle at all.
Config left_block() {
  return box_block(2, {2.0, 0.25, 0}, {40, 5, 1}, {{{BC::Slip, BC::Slip}, {BC::Sticky, BC::Slip}, {BC::Periodic, BC::Periodic}}}, {0, 0, 0}, {0.3, 0.2, 0}, {0.5, 0, 0});
}

// Sets up c, edits the particle of global id `id` (wherever it lives), writes a checkpoint,
// and returns the message of the restart from it ("" if accepted).
std::string corrupted_restart(int n, const Config &c, int64_t id, const std::function<void(ParticleView<2> &, PetscInt)> &edit) {
  const std::string ck = gmtest::outdir("checkpoint") + "/bad.h5";
  std::string msg;
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    {
      Simulation<2> sim(comm, c);
      sim.setup();
      ParticleView<2> P = sim.particles.get();
      for (PetscInt p = 0; p < P.n; ++p)
        if (P.id[p] == id) edit(P, p);
      sim.particles.restore(P);
      sim.write_checkpoint(ck);
    }
    Config r = c;
    r.restart = ck;
    try {
      Simulation<2> sim(comm, r);
      sim.setup();
    } catch (const UserError &e) {
      msg = e.what();
    }
  });
  return msg;
}

} // namespace

TEST_CASE("restart with particles on some ranks only reproduces the uninterrupted run", "[checkpoint][parallel]") {
  const Config c = left_block();
  // The premise: on 2 and 3 ranks some rank holds no particle at the checkpoint (step 40).
  for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
    long empty_ranks = 0;
    Config k = c;
    k.max_steps = 40;
    gmtest::on_ranks(n, [&](MPI_Comm comm) {
      Simulation<2> sim(comm, k);
      sim.setup();
      sim.run();
      long mine = sim.particles.local_size() == 0;
      MPI_Allreduce(&mine, &empty_ranks, 1, MPI_LONG, MPI_SUM, comm);
    });
    empty_ranks = bcast(empty_ranks);
    INFO("ranks " << n);
    REQUIRE(empty_ranks >= 1);
  }
  check<2>(c);
}

TEST_CASE("restart refuses non-physical particle data and names the dataset", "[checkpoint]") {
  const Config c = left_block();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (int n = 1; n <= std::min(2, gmtest::world_size()); ++n) {
    INFO("ranks " << n);
    const std::string m1 = corrupted_restart(n, c, 7, [&](ParticleView<2> &P, PetscInt p) { P.x[2 * p + 1] = nan; });
    const std::string m2 = corrupted_restart(n, c, 7, [&](ParticleView<2> &P, PetscInt p) { P.x[2 * p] = 2.5; });
    const std::string m3 = corrupted_restart(n, c, 7, [&](ParticleView<2> &P, PetscInt p) { P.m[p] = -P.m[p]; });
    const std::string m4 = corrupted_restart(n, c, 7, [&](ParticleView<2> &P, PetscInt p) { P.id[p] = 8; });
    const std::string m5 = corrupted_restart(n, c, 7, [&](ParticleView<2> &P, PetscInt p) { P.s[6 * p + 3] = std::numeric_limits<double>::infinity(); });
    if (gmtest::world_rank() == 0) {
      CHECK(m1.find("dataset /particles/DMSwarmPIC_coor") != std::string::npos);
      CHECK(m1.find("non-finite") != std::string::npos);
      CHECK(m2.find("dataset /particles/DMSwarmPIC_coor") != std::string::npos);
      CHECK(m2.find("outside the domain (x = 2.5") != std::string::npos);
      CHECK(m3.find("dataset /particles/mass") != std::string::npos);
      CHECK(m3.find("not positive") != std::string::npos);
      CHECK(m4.find("dataset /particles/DMSwarm_pid holds particle id 8 twice") != std::string::npos);
      CHECK(m5.find("dataset /particles/stress") != std::string::npos);
    }
  }
  // The unedited checkpoint is accepted.
  REQUIRE(corrupted_restart(1, c, 7, [](ParticleView<2> &, PetscInt) {}).empty());
}
