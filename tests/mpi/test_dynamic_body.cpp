// Dynamic (two-way coupled) rigid bodies in the solver: total momentum of bodies and
// particles, the same body trajectory on 1, 2 and 3 ranks, force balance of a body
// resting on an elastic bed, and bitwise restarts.
#include "harness.hpp"

#include <cstring>

using namespace granmpm;
using gmtest::bcast;

namespace {

// An elastic bed (1 m x 0.3 m, E = 1e6 Pa, rho = 1000) on a sticky floor between slip
// walls; a dynamic box (0.3 m x 0.1 m, 60 kg/m, friction 0.5) placed on its surface;
// gravity ramped in over 0.2 s; grid and body damping 10 1/s to settle.
Config box_on_bed() {
  Config c;
  c.dim = 2;
  c.scene = SceneKind::Block;
  c.material = MaterialKind::LinearElastic;
  c.E = 1e6;
  c.nu = 0.3;
  c.rho = 1000;
  c.p0 = 0;
  c.ppc = 2;
  c.lo = {0, 0, 0};
  c.hi = {1.0, 0.6, 0};
  c.cells = {20, 12, 1};
  c.body_hi = {1.0, 0.3, 0};
  c.bc = {{{BC::Slip, BC::Slip}, {BC::Sticky, BC::Free}, {BC::Periodic, BC::Periodic}}};
  c.gravity = {0, -9.81, 0};
  c.gravity_ramp = 0.2;
  c.damping = 10;
  BodySpec box;
  box.shape = BodyShape::Box;
  box.motion = BodyMotion::Dynamic;
  box.center = {0.5, 0.35, 0};
  box.half = {0.15, 0.05, 0};
  box.contact = BodyContact::Friction;
  box.friction = 0.5;
  box.mass = 60;
  box.inertia = uniform_inertia(box);
  box.damping = 10;
  box.angular_damping = 10;
  c.bodies = {box};
  c.output_dir = gmtest::outdir("dynbed");
  c.output_final = false;
  c.progress_interval = 0;
  c.quiet = true;
  return c;
}

// Momentum of bodies + particles and the body trajectories on 1, 2 and 3 ranks, for the
// block thrown at two free dynamic bodies (in 3D: the same in a periodic slab 0.4 m deep,
// the bodies are cylinders along z).
template <int dim>
void check_momentum_and_ranks(const Config &c, double momentum_tol) {
  const int nsteps = 60;
  const double dt = 2e-3;
  std::vector<double> ref; // body states of every step on 1 rank
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    double worst = 0, pscale = 0, dv_body = 0;
    std::vector<double> traj;
    gmtest::on_ranks(n, [&](MPI_Comm comm) {
      Simulation<dim> sim(comm, c);
      sim.setup();
      auto total = [&](double *p) {
        const Totals t = sim.totals();
        for (int d = 0; d < dim; ++d) {
          p[d] = t.momentum[d];
          for (size_t k = 0; k < sim.bodies->size(); ++k) p[d] += sim.bodies->spec(k).mass * sim.bodies->velocity(k)[d];
        }
      };
      double p0[3];
      total(p0);
      pscale = std::hypot(p0[0], p0[1], dim == 3 ? p0[2] : 0.0);
      const double v0 = sim.bodies->velocity(1)[0];
      for (int s = 0; s < nsteps; ++s) {
        sim.step(dt);
        double p[3];
        total(p);
        worst = std::max(worst, std::hypot(p[0] - p0[0], p[1] - p0[1], dim == 3 ? p[2] - p0[2] : 0.0));
        const std::vector<double> st = sim.bodies->state();
        traj.insert(traj.end(), st.begin(), st.begin() + 16);
      }
      dv_body = std::fabs(sim.bodies->velocity(1)[0] - v0) + std::fabs(sim.bodies->velocity(0)[0]);
    });
    worst = bcast(worst);
    pscale = bcast(pscale);
    dv_body = bcast(dv_body);
    INFO(dim << "D, " << n << " ranks: total momentum " << pscale << " kg m/s, largest change " << worst << ", body velocity change " << dv_body);
    REQUIRE(dv_body > 0.1);               // the bodies are hit and pushed
    REQUIRE(worst < momentum_tol * pscale);
    if (n == 1) ref = traj;
    else {
      double d = 0, scale = 0;
      if (gmtest::world_rank() == 0) {
        REQUIRE(traj.size() == ref.size());
        for (size_t i = 0; i < ref.size(); ++i) {
          d = std::max(d, std::fabs(traj[i] - ref[i]));
          scale = std::max(scale, std::fabs(ref[i]));
        }
      }
      d = bcast(d);
      scale = bcast(scale);
      INFO(n << " ranks vs 1: largest difference of a body position/angle/velocity " << d << " (scale " << scale << ")");
      REQUIRE(d < 1e-12 * scale); // the reduced sums differ in the order of addition only (2D: measured 5.3e-15 / 3.6e-15 on 2 / 3 ranks)
    }
  }
}

} // namespace

TEST_CASE("dynamic bodies: bodies + particles conserve momentum; 1, 2 and 3 ranks give the same body trajectories", "[parallel][rigid]") {
  // No gravity, no wall reached, APIC transfers: the particles' momentum changes by
  // -(sum F) dt per step (test_rigid.cpp), and each body's by +F dt (its update), so the
  // total is conserved to round-off.
  // Measured 8.0e-13 of 975 kg m/s (8e-16 relative) on 1-3 ranks.
  check_momentum_and_ranks<2>(gmtest::block_and_bodies(BodyMotion::Dynamic), 1e-13);
}

TEST_CASE("dynamic bodies in 3D: bodies + particles conserve momentum; 1, 2 and 3 ranks give the same body trajectories", "[parallel][rigid]") {
  Config c = gmtest::block_and_bodies(BodyMotion::Dynamic);
  c.dim = 3;
  c.hi[2] = 0.4;
  c.cells[2] = 4; // a periodic direction needs 4 cells
  c.body_lo[2] = 0;
  c.body_hi[2] = 0.4;
  c.bodies[0].half[2] = 1.0; // the box spans the periodic slab (the disk is a z-cylinder)
  c.output_dir = gmtest::outdir("dynbodies3d");
  // Measured 4.1e-10 of 403 kg m/s (1.0e-12 relative) on 1 rank: conserved, but about 1000x
  // the 2D round-off; where 3D loses the last digits was not traced. Bound 1e-11 relative.
  // 2 and 3 ranks vs 1: body states equal to 1.3e-15 / 1.8e-15.
  check_momentum_and_ranks<3>(c, 1e-11);
}

TEST_CASE("a dynamic box settles on an elastic bed: contact force = weight, velocity -> 0", "[rigid]") {
  Config c = box_on_bed();
  c.t_end = 1.0;
  const double W = 60 * 9.81;
  // The residual oscillation decays under the damping. Measured (same scene through
  // granmpm, mean fy over the last 0.2 s, relative error / largest speed): t_end 0.6 s
  // 4.3e-4 / 8.3e-4 m/s, 1.0 s 1.5e-4 / 4.1e-4 m/s, 1.4 s 4.0e-5 / 2.1e-4 m/s.
  // Bounds at t_end = 1 s: about 6x and 2.5x the measured values.
  const double TOL_FORCE = 1e-3, TOL_SPEED = 1e-3;
  double fmean = 0, vmax_late = 0, settle = 0;
  long rows = 0;
  gmtest::on_ranks(1, [&](MPI_Comm comm) {
    Simulation<2> sim(comm, c);
    sim.setup();
    const double y0 = sim.bodies->pose(0).c[1];
    while (sim.time < c.t_end - 1e-12) {
      sim.step(std::min(sim.cfl_dt(), c.t_end - sim.time));
      if (sim.time > 0.8) { // the last 0.2 s
        fmean += sim.bodies->forces()[1];
        vmax_late = std::max(vmax_late, std::hypot(sim.bodies->velocity(0)[0], sim.bodies->velocity(0)[1]));
        ++rows;
      }
    }
    settle = y0 - sim.bodies->pose(0).c[1];
  });
  fmean = bcast(fmean / rows);
  vmax_late = bcast(vmax_late);
  settle = bcast(settle);
  INFO("mean contact force over t = 0.8 .. 1 s " << fmean << " N/m against the weight " << W << "; largest body speed there " << vmax_late
                                                 << " m/s; sinkage " << settle << " m");
  REQUIRE(settle > 0);                            // it sank into the bed
  REQUIRE(fmean == Approx(W).epsilon(TOL_FORCE)); // see below
  REQUIRE(vmax_late < TOL_SPEED);
}

TEST_CASE("restart with a dynamic body reproduces the uninterrupted run bitwise", "[checkpoint][rigid]") {
  Config c = box_on_bed();
  c.checkpoint_file = gmtest::outdir("dynbed") + "/ck.h5";
  for (int n = 1; n <= std::min(2, gmtest::world_size()); ++n) {
    auto run = [&](long max_steps, long every, const std::string &restart, std::vector<double> &bodies) {
      Config r = c;
      r.max_steps = max_steps;
      r.checkpoint_interval = every;
      r.restart = restart;
      r.dt = 5e-4;
      std::vector<ParticleRecord> out;
      gmtest::on_ranks(n, [&](MPI_Comm comm) {
        Simulation<2> sim(comm, r);
        sim.setup();
        sim.run();
        auto g = sim.gather(0);
        if (gmtest::world_rank() == 0) {
          out = std::move(g);
          bodies = sim.bodies->state();
        }
      });
      return out;
    };
    std::vector<double> bf, bc, bdummy;
    const auto full = run(300, 0, "", bf);
    run(200, 200, "", bdummy);
    const auto cont = run(300, 0, c.checkpoint_file, bc);
    long same = 0;
    if (gmtest::world_rank() == 0) {
      same = full.size() == cont.size() && bf == bc && bf.size() == 12;
      for (size_t i = 0; same && i < full.size(); ++i) same = std::memcmp(&full[i], &cont[i], sizeof(ParticleRecord)) == 0;
    }
    INFO(n << " ranks");
    REQUIRE(bcast(same) == 1);
  }
}
