// Run-time guards: a non-finite velocity or stress, or a particle moving more than a cell
// in one step, stops the run on every rank with a message naming the particle.
#include "harness.hpp"

using namespace granmpm;
using gmtest::bcast;

namespace {
Config block() {
  Config c;
  c.dim = 2;
  c.scene = SceneKind::Block;
  c.material = MaterialKind::Hypoelastic;
  c.E = 1e5;
  c.rho = 1000;
  c.lo = {0, 0, 0};
  c.hi = {2, 1, 0};
  c.cells = {20, 10, 1};
  c.bc = {{{BC::Periodic, BC::Periodic}, {BC::Slip, BC::Slip}, {BC::Periodic, BC::Periodic}}};
  c.body_lo = {0.5, 0.2, 0};
  c.body_hi = {1.5, 0.8, 0};
  c.ppc = 2;
  c.p0 = 10;
  c.gravity = {0, 0, 0};
  c.output_dir = gmtest::outdir("guards");
  c.quiet = true;
  return c;
}

// Sets up the block on n ranks, lets `prepare` change its particles, takes one step and
// returns the error message it raised (on every rank; empty if none).
std::string step_error(int n, const std::function<void(ParticleView<2> &)> &prepare) {
  std::string msg;
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    Simulation<2> sim(comm, block());
    sim.setup();
    ParticleView<2> P = sim.particles.get();
    prepare(P);
    sim.particles.restore(P);
    try {
      sim.step(1e-3);
    } catch (const UserError &e) {
      msg = e.what();
    }
  });
  int len = (int)msg.size();
  MPI_Bcast(&len, 1, MPI_INT, 0, PETSC_COMM_WORLD);
  msg.resize(len);
  MPI_Bcast(msg.data(), len, MPI_CHAR, 0, PETSC_COMM_WORLD);
  return msg;
}

// Corrupts particle 420 (lattice (20, 10): inside the block) with f, then step_error.
std::string corrupt_and_step(int n, const std::function<void(ParticleView<2> &, PetscInt)> &f) {
  return step_error(n, [&](ParticleView<2> &P) {
    for (PetscInt p = 0; p < P.n; ++p)
      if (P.id[p] == 420) f(P, p);
  });
}
} // namespace

TEST_CASE("guards: NaN velocity, NaN stress, runaway particle", "[guards][parallel]") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    INFO("ranks " << n);
    std::string m = corrupt_and_step(n, [&](ParticleView<2> &P, PetscInt p) { P.v[2 * p] = nan; });
    REQUIRE(m.find("non-finite") != std::string::npos);
    m = corrupt_and_step(n, [&](ParticleView<2> &P, PetscInt p) { P.s[6 * p + 3] = nan; });
    REQUIRE(m.find("non-finite") != std::string::npos);
    m = corrupt_and_step(n, [&](ParticleView<2> &P, PetscInt p) { P.v[2 * p + 1] = 1e6; });
    REQUIRE(m.find("cells in one step") != std::string::npos);
    REQUIRE(m.find("-dt") != std::string::npos);
  }
}

TEST_CASE("guards: kinetic energy beyond what the scene can supply", "[guards][parallel]") {
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    // Energy from nowhere: every particle suddenly at 30 m/s (0.3 cell per 1e-3 s step).
    const std::string msg = step_error(n, [](ParticleView<2> &P) {
      for (PetscInt p = 0; p < P.n; ++p) P.v[2 * p] = 30;
    });
    INFO("ranks " << n << ": " << msg);
    REQUIRE(msg.find("the kinetic energy reached") != std::string::npos);
    REQUIRE(msg.find("-energy_bound_factor") != std::string::npos);
  }
}

TEST_CASE("corner cases: an isolated particle, empty ranks, zero stress stay finite for every model", "[guards][parallel]") {
  for (auto mat : {MaterialKind::LinearElastic, MaterialKind::Hypoelastic, MaterialKind::MuI, MaterialKind::Nonlocal, MaterialKind::Dynamic,
                   MaterialKind::DruckerPrager}) {
    for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
      Config c = block();
      c.material = mat;
      c.E = 1e6;
      c.gravity = {0, -9.81, 0};
      c.gravity_ramp = 0;
      // One particle (ppc 1, a body smaller than a cell): every other rank is empty.
      c.ppc = 1;
      c.body_lo = {1.0, 0.5, 0};
      c.body_hi = {1.06, 0.56, 0};
      c.p0 = 0;
      double vy = 0;
      long count = 0;
      gmtest::on_ranks(n, [&](MPI_Comm comm) {
        Simulation<2> sim(comm, c);
        sim.setup();
        for (int s = 0; s < 50; ++s) sim.step(1e-3);
        Totals t = sim.totals();
        count = t.n;
        vy = t.momentum[1] / t.mass;
      });
      INFO("material " << (int)mat << ", ranks " << n);
      REQUIRE(bcast(count) == 1);
      // A lone particle falls freely: stress-free granular point or unstressed elastic one.
      REQUIRE(bcast(vy) == Approx(-9.81 * 50e-3).epsilon(1e-10));
    }
  }
}

TEST_CASE("stages: each scene builds only what it needs", "[stages]") {
  auto build = [](MaterialKind m, TransferKind t, bool &fluid, bool &gfield, bool &gdot, bool &apic) {
    Config c = block();
    c.material = m;
    c.transfer = t;
    gmtest::on_ranks(1, [&](MPI_Comm comm) {
      Simulation<2> sim(comm, c);
      sim.setup();
      fluid = sim.fluidity != nullptr;
      gfield = gdot = apic = false;
      for (const auto &f : sim.particles.field_meta()) {
        gfield |= f.name == "fluidity";
        gdot |= f.name == "gdot";
        apic |= f.name == "apic_C";
      }
    });
  };
  bool fluid, g, gd, ap;
  build(MaterialKind::MuI, TransferKind::FLIP, fluid, g, gd, ap);
  if (gmtest::world_rank() == 0) {
    REQUIRE(!fluid); // a local mu(I) scene creates no fluidity KSP
    REQUIRE(!g);     // and no fluidity field
    REQUIRE(gd);
    REQUIRE(!ap);
  }
  build(MaterialKind::Nonlocal, TransferKind::APIC, fluid, g, gd, ap);
  if (gmtest::world_rank() == 0) {
    REQUIRE(fluid);
    REQUIRE(g);
    REQUIRE(ap);
  }
  build(MaterialKind::LinearElastic, TransferKind::PIC, fluid, g, gd, ap);
  if (gmtest::world_rank() == 0) {
    REQUIRE(!fluid);
    REQUIRE(!g);
    REQUIRE(!gd);
    REQUIRE(!ap);
  }
}
