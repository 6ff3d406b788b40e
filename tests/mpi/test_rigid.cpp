// Rigid bodies in the solver: momentum exchange with the grid (the force on the bodies is
// the grid's momentum change), 1/2/3 ranks equal for the annulus, the deep-penetration
// stop, and the annular-shear verification against the 1D references.
#include "harness.hpp"

#include "granmpm/scene.hpp"

using namespace granmpm;
using gmtest::bcast;

namespace {

Config annulus(int n, MaterialKind m) {
  Config c;
  c.dim = 2;
  c.scene = SceneKind::Annulus;
  c.material = m;
  c.set_scene_param("-annulus_ri", 0.2);
  c.set_scene_param("-annulus_ro", 0.4);
  c.set_scene_param("-annulus_omega", 0.1);
  c.lo = {-0.45, -0.45, 0};
  c.hi = {0.45, 0.45, 0};
  c.cells = {n, n, 1};
  c.bc = {{{BC::Sticky, BC::Sticky}, {BC::Sticky, BC::Sticky}, {BC::Periodic, BC::Periodic}}};
  c.gravity = {0, 0, 0};
  c.gravity_ramp = 0;
  c.p0 = 900;
  c.ppc = 2;
  c.E = 1e6;
  c.nu = 0.3;
  c.rho = 1500;
  c.t_end = 0.1;
  gmtest::quiet(c, "annulus");
  return c;
}

} // namespace

TEST_CASE("momentum exchange: the force on the bodies is minus the grid's momentum change at their nodes", "[parallel][rigid]") {
  // No gravity, no wall reached, APIC: internal forces sum to zero and the transfers
  // conserve momentum, so every step the particles' momentum changes by -(F_box + F_disk) dt.
  const Config c = gmtest::block_and_bodies();
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    double worst = 0, fmax = 0;
    gmtest::on_ranks(n, [&](MPI_Comm comm) {
      Simulation<2> sim(comm, c);
      sim.setup();
      const double dt = 2e-3;
      for (int s = 0; s < 40; ++s) {
        const Totals t0 = sim.totals();
        sim.step(dt);
        const Totals t1 = sim.totals();
        const std::vector<double> &f = sim.bodies->forces();
        for (int d = 0; d < 2; ++d) {
          const double fd = f[d] + f[4 + d];
          fmax = std::max(fmax, std::fabs(fd));
          worst = std::max(worst, std::fabs((t1.momentum[d] - t0.momentum[d]) + fd * dt));
        }
      }
    });
    worst = bcast(worst);
    fmax = bcast(fmax);
    INFO(n << " ranks: largest force " << fmax << " N/m, largest momentum mismatch " << worst << " kg m/s per step");
    REQUIRE(fmax > 1.0);              // the bodies are hit
    REQUIRE(worst < 1e-12 * fmax * 2e-3); // measured 9.2e-13 kg m/s against F dt = 72 kg m/s
  }
}

TEST_CASE("in the solver, the rotating disk's contact nodes move exactly with omega x r, the ring's are at rest", "[parallel][rigid]") {
  const Config c = annulus(20, MaterialKind::MuI);
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    long checked = 0;
    double worst = 0;
    gmtest::on_ranks(n, [&](MPI_Comm comm) {
      Simulation<2> sim(comm, c);
      sim.setup();
      for (int s = 0; s < 5; ++s) sim.step(4e-4);
      // The grid holds [m, v_new, dv] of the last step's grid update (poses at its start).
      RigidBodies<2> B = *sim.bodies;
      B.set_time(sim.time - 4e-4);
      NodeView<2> g = sim.grid.begin_global();
      long mine = 0;
      double err = 0;
      for (int j = sim.grid.xs[1]; j < sim.grid.xs[1] + sim.grid.xm[1]; ++j)
        for (int i = sim.grid.xs[0]; i < sim.grid.xs[0] + sim.grid.xm[0]; ++i) {
          const double *nd = g.at(i, j, 0);
          const double x[2] = {sim.grid.node_x(0, i), sim.grid.node_x(1, j)};
          if (nd[0] <= 0) continue;
          for (size_t k = 0; k < 2; ++k) {
            if (!(B.sdf(k, x) < 0.5 * sim.grid.h)) continue;
            const double w = B.spec(k).omega;
            err = std::max(err, std::fabs(nd[1] - (-w * x[1])) + std::fabs(nd[2] - w * x[0]));
            ++mine;
          }
        }
      sim.grid.end_global();
      MPI_Allreduce(&mine, &checked, 1, MPI_LONG, MPI_SUM, comm);
      MPI_Allreduce(&err, &worst, 1, MPI_DOUBLE, MPI_MAX, comm);
    });
    INFO(n << " ranks: " << bcast(checked) << " contact nodes, largest |v - omega x r| " << bcast(worst));
    REQUIRE(bcast(checked) > 50);
    REQUIRE(bcast(worst) < 1e-15); // round-off of x - c (measured 9.4e-19)
  }
}

TEST_CASE("annulus on 1, 2 and 3 ranks gives the same particles and body forces", "[parallel][rigid]") {
  for (int variant = 0; variant < 3; ++variant) {
    const MaterialKind m = variant == 1 ? MaterialKind::Nonlocal : MaterialKind::MuI;
    Config c = annulus(20, m);
    c.set_scene_param("-annulus_ri", 0.15);
    c.vol_cell_average = variant == 2; // cell-averaged tr L: a cell's particles are on one rank
    const double dt = 4e-4;
    const auto ref = gmtest::run_steps<2>(1, c, 40, dt);
    for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
      const auto par = gmtest::run_steps<2>(n, c, 40, dt);
      const double d = bcast(gmtest::world_rank() == 0 ? gmtest::max_rel_diff(ref, par) : 0.0);
      INFO("material " << to_string(m) << (c.vol_cell_average ? " with -volumetric_average" : "") << ", ranks " << n << ": max relative difference " << d);
      REQUIRE(d >= 0);
      // The steady fluidity solve is iterative (KSP rtol 1e-8): round-off differences grow.
      REQUIRE(d < (m == MaterialKind::Nonlocal ? 1e-6 : 1e-12));
    }
    REQUIRE(bcast((long)ref.size()) > 0);
  }
}

// The 3D Taylor-Couette form of the annulus scene (cylinders along z, gravity along -z,
// slip bottom, free top, lithostatic initial stress), coarse: a few steps on 1, 2, 3 ranks.
TEST_CASE("3D annulus (Taylor-Couette) on 1, 2 and 3 ranks gives the same particles, top-surface profile and torque", "[parallel][rigid]") {
  for (int variant = 0; variant < 3; ++variant) {
    const MaterialKind m = variant == 0 ? MaterialKind::MuI : MaterialKind::Nonlocal;
    Config c = annulus(22, m);
    gmtest::taylor_couette_cell(c);
    c.p0 = 0;
    c.E = 1e5;
    c.gran.d = 0.004;
    c.body_fluidity_bc = variant == 2 ? BodyFluidityBC::Zero : BodyFluidityBC::ZeroFlux;
    const double dt = 1e-3;
    const auto ref = gmtest::run_steps<3>(1, c, 10, dt);
    c.dt = dt;
    c.t_end = 10 * dt;
    const auto mref = gmtest::run_scene<3>(1, c);
    for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
      const auto par = gmtest::run_steps<3>(n, c, 10, dt);
      const double d = bcast(gmtest::world_rank() == 0 ? gmtest::max_rel_diff(ref, par) : 0.0);
      const auto mpar = gmtest::run_scene<3>(n, c);
      const double dw = std::fabs(mpar.at("omega_min_top") - mref.at("omega_min_top")), dT = std::fabs(mpar.at("inner_torque") - mref.at("inner_torque"));
      INFO("variant " << variant << ", ranks " << n << ": max relative difference " << d << "; omega_min_top " << mref.at("omega_min_top") << " diff " << dw
                      << "; torque " << mref.at("inner_torque") << " diff " << dT);
      REQUIRE(d >= 0);
      // The steady fluidity solve is iterative (KSP rtol 1e-8): round-off differences grow.
      REQUIRE(d < (m == MaterialKind::Nonlocal ? 1e-6 : 1e-12));
      REQUIRE(dw <= (m == MaterialKind::Nonlocal ? 1e-6 : 1e-12));
      REQUIRE(dT <= (m == MaterialKind::Nonlocal ? 1e-6 : 1e-12) * std::fabs(mref.at("inner_torque")));
    }
    REQUIRE(bcast((long)ref.size()) > 0);
    REQUIRE(std::fabs(mref.at("inner_torque")) > 0);
  }
}

TEST_CASE("particles inside a body: put back and counted within a cell, a stop naming the body deeper", "[guards][rigid]") {
  // Particles are never seeded inside bodies; here one is moved into the box by hand,
  // 0.3 cells deep (put back onto the surface) or 2 cells deep (the run stops).
  Config c = gmtest::block_and_bodies();
  c.v0 = {0, 0, 0};
  c.set_scene_param("-spin", 0);
  c.bodies.resize(1);
  c.bodies[0].angle = 0;
  c.bodies[0].center = {1.6, 0.8, 0}; // faces at x = 1.3 .. 1.9, y = 0.5 .. 1.1
  c.bodies[0].half = {0.3, 0.3, 0};
  const int64_t id = 16 * 40 + 23;    // the block particle at (1.175, 0.825)
  for (double depth : {0.03, 0.2}) {
    for (int n = 1; n <= std::min(2, gmtest::world_size()); ++n) {
      long threw = 0, found = 0, corrections = -1;
      double xnew = 0;
      gmtest::on_ranks(n, [&](MPI_Comm comm) {
        Simulation<2> sim(comm, c);
        sim.setup();
        ParticleView<2> P = sim.particles.get();
        long mine = 0;
        for (PetscInt p = 0; p < P.n; ++p)
          if (P.id[p] == id) {
            P.x[2 * p] = 1.3 + depth;
            mine = 1;
          }
        sim.particles.restore(P);
        MPI_Allreduce(&mine, &found, 1, MPI_LONG, MPI_SUM, comm);
        std::string msg;
        try {
          sim.step(1e-4);
          corrections = sim.body_corrections;
          for (const auto &r : sim.gather(0))
            if (r.id == id) xnew = r.x[0];
        } catch (const UserError &e) {
          threw = 1;
          msg = e.what();
        }
        if (gmtest::world_rank() == 0 && threw)
          found += (msg.find("inside rigid body 0 (-body0_shape box)") != std::string::npos && msg.find("reduce -dt") != std::string::npos) ? 10 : 0;
      });
      found = bcast(found);
      threw = bcast(threw);
      INFO("depth " << depth << " m, " << n << " ranks");
      if (depth < 0.1) {
        REQUIRE(found == 1);
        REQUIRE(threw == 0);
        REQUIRE(bcast(corrections) == 1);
        REQUIRE(bcast(xnew) == Approx(1.3).margin(1e-12));
      } else {
        REQUIRE(threw == 1);
        REQUIRE(found == 11); // the message names the body and the remedy
      }
    }
  }
}

TEST_CASE("annular shear, local mu(I) and nonlocal: v_theta(r) against the 1D references at two resolutions", "[verification][annulus]") {
  // Read at t = 0.1 s: the torque on the inner disk is steady from about 0.06 s; later the
  // mean pressure creeps up (a discretisation drift, first order in h, docs/rigid_bodies.md)
  // while the references assume p = p0. Measured relative L2 errors (GIMP, APIC, 2 ppc):
  //   local    36 cells 1.852e-01, 72 cells 6.080e-02
  //   nonlocal 36 cells 1.339e-01, 72 cells 7.851e-02
  // Bounds: measured + 20%; refinement must cut the error (ratios measured 0.33 and 0.59).
  const double bound36[2] = {0.222, 0.161}, bound72[2] = {0.073, 0.094}, ratio[2] = {0.45, 0.72};
  int k = 0;
  for (MaterialKind m : {MaterialKind::MuI, MaterialKind::Nonlocal}) {
    const auto m36 = gmtest::run_scene<2>(1, annulus(36, m));
    const auto m72 = gmtest::run_scene<2>(1, annulus(72, m));
    const double e36 = m36.at("l2_rel"), e72 = m72.at("l2_rel");
    INFO(to_string(m) << ": relative L2 error 36 cells " << e36 << ", 72 cells " << e72 << "; torque " << m72.at("inner_torque") << " vs reference "
                      << m72.at("reference_torque") << "; mean pressure " << m72.at("mean_pressure"));
    REQUIRE(e36 < bound36[k]);
    REQUIRE(e72 < bound72[k]);
    REQUIRE(e72 < ratio[k] * e36);
    // The material's reaction on the inner disk balances the reference torque 2 pi T.
    REQUIRE(-m72.at("inner_torque") == Approx(m72.at("reference_torque")).epsilon(0.15));
    REQUIRE(m72.at("body_corrections") == 0);
    ++k;
  }
}

TEST_CASE("nonlocal annular shear with g = 0 at the bodies (-body_fluidity_bc zero): v_theta(r) against the 1D reference with g = 0 at the walls", "[verification][annulus]") {
  // The two 1D references (zero flux / g = 0 at both walls) differ by 23% (relative L2 at
  // the 36-cell bins), so a run with the wrong condition cannot meet these bounds.
  // Measured relative L2 errors at t = 0.1 s: 36 cells 5.875e-02, 72 cells 2.416e-02
  // (ratio 0.41); torque on the disk at 72 cells -327.8 N m/m against 2 pi T = 321.9.
  // Bounds: measured + 20%; refinement must cut the error (ratio below 0.5).
  Config c36 = annulus(36, MaterialKind::Nonlocal), c72 = annulus(72, MaterialKind::Nonlocal);
  c36.body_fluidity_bc = c72.body_fluidity_bc = BodyFluidityBC::Zero;
  const auto m36 = gmtest::run_scene<2>(1, c36);
  const auto m72 = gmtest::run_scene<2>(1, c72);
  const double e36 = m36.at("l2_rel"), e72 = m72.at("l2_rel");
  INFO("relative L2 error 36 cells " << e36 << ", 72 cells " << e72 << "; torque " << m72.at("inner_torque") << " vs reference " << m72.at("reference_torque"));
  REQUIRE(e36 < 0.0705);
  REQUIRE(e72 < 0.029);
  REQUIRE(e72 < 0.5 * e36);
  REQUIRE(-m72.at("inner_torque") == Approx(m72.at("reference_torque")).epsilon(0.15));
}
