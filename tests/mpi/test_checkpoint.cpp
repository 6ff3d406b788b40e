// Checkpoint/restart: continuing from a checkpoint reproduces the uninterrupted run
// bitwise on the same number of ranks and to round-off on another number of ranks.
#include "harness.hpp"

#include <cstring>

using namespace granmpm;
using gmtest::bcast;

namespace {

Config nonlocal_chute() {
  Config c; // seed 000 chute, steady nonlocal fluidity; starts sheared so g != 0 at once
  c.cells = {20, 8, 1};
  c.hi = {0.5, 0.4, 0};
  c.ppc = 2;
  c.chute_prestress = true;
  c.gravity_ramp = 0;
  c.output_dir = gmtest::outdir("checkpoint");
  c.output_final = false;
  c.progress_interval = 0;
  c.quiet = true;
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

} // namespace

TEST_CASE("restart reproduces the uninterrupted run: nonlocal chute", "[checkpoint][parallel]") {
  PetscOptionsSetValue(NULL, "-fluidity_ksp_rtol", "1e-12");
  check<2>(nonlocal_chute());
  PetscOptionsClearValue(NULL, "-fluidity_ksp_rtol");
}

TEST_CASE("restart reproduces the uninterrupted run: 3D APIC block", "[checkpoint][parallel]") {
  Config c;
  c.dim = 3;
  c.scene = SceneKind::Block;
  c.material = MaterialKind::Hypoelastic;
  c.E = 1e5;
  c.rho = 1000;
  c.lo = {0, 0, 0};
  c.hi = {1.5, 0.6, 0.4};
  c.cells = {15, 6, 4};
  c.bc = {{{BC::Periodic, BC::Periodic}, {BC::Slip, BC::Slip}, {BC::Periodic, BC::Periodic}}};
  c.body_lo = {0.2, 0.1, 0};
  c.body_hi = {1.1, 0.5, 0.4};
  c.ppc = 2;
  c.v0 = {4, 0, 0.5};
  c.spin = 2;
  c.p0 = 100;
  c.gravity = {0, -9.81, 0};
  c.gravity_ramp = 0;
  c.shape = ShapeKind::BSpline2;
  c.output_dir = gmtest::outdir("checkpoint");
  c.output_final = false;
  c.progress_interval = 0;
  c.quiet = true;
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
