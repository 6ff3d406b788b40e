// Parallel correctness: the same scene on 1, 2 and 3 ranks gives the same particles (ids,
// count, state) to round-off; migration keeps every particle, including long jumps past
// neighbour ranks; P2G/G2P conserve mass and momentum on any number of ranks.
#include "harness.hpp"

#include "granmpm/grid.hpp"
#include "granmpm/particles.hpp"

using namespace granmpm;
using gmtest::bcast;

namespace {

// A hypoelastic block moving fast along periodic x and spinning, pre-compressed, under
// gravity, between slip walls in y: particles cross rank boundaries every step.
Config moving_block(int dim, ShapeKind shape, TransferKind tr, UpdateOrder up) {
  Config c = gmtest::hypo_block(dim);
  c.lo = {0, 0, 0};
  c.hi = {3.0, 1.2, 0.6};
  c.cells = {30, 12, 6};
  c.bc = {{{BC::Periodic, BC::Periodic}, {BC::Slip, BC::Slip}, {BC::Periodic, BC::Periodic}}};
  c.body_lo = {0.4, 0.25, 0.0};
  c.body_hi = {2.2, 0.95, 0.6};
  c.v0 = {4.0, 0.0, 0.5};
  c.set_scene_param("-spin", 2.0);
  c.gravity = {0, -9.81, 0};
  c.shape = shape;
  c.transfer = tr;
  c.update = up;
  gmtest::quiet(c, "parallel");
  return c;
}

template <int dim>
void compare_ranks(const Config &c, int nsteps) {
  // dt: 0.4 of the CFL limit (wave speed ~12 m/s, speed ~6 m/s, h = 0.1).
  const double dt = 2e-3;
  const auto ref = gmtest::run_steps<dim>(1, c, nsteps, dt);
  for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
    const auto par = gmtest::run_steps<dim>(n, c, nsteps, dt);
    const double d = bcast(gmtest::world_rank() == 0 ? gmtest::max_rel_diff(ref, par) : 0.0);
    INFO("ranks " << n << ": max relative difference " << d);
    REQUIRE(d >= 0);      // same count and ids
    REQUIRE(d < 1e-12);   // same states to round-off
  }
  const long count = bcast((long)ref.size());
  REQUIRE(count > 0);
}

} // namespace

TEST_CASE("2D moving block: 1, 2, 3 ranks give the same particles", "[parallel]") {
  for (auto sh : {ShapeKind::Linear, ShapeKind::GIMP, ShapeKind::BSpline2}) {
    compare_ranks<2>(moving_block(2, sh, TransferKind::APIC, UpdateOrder::USL), 40);
  }
  compare_ranks<2>(moving_block(2, ShapeKind::BSpline2, TransferKind::FLIP, UpdateOrder::MUSL), 40);
  compare_ranks<2>(moving_block(2, ShapeKind::GIMP, TransferKind::PIC, UpdateOrder::USF), 40);
}

TEST_CASE("3D moving block: 1, 2, 3 ranks give the same particles", "[parallel]") {
  Config c = moving_block(3, ShapeKind::BSpline2, TransferKind::APIC, UpdateOrder::USL);
  c.cells = {15, 6, 4};
  c.ppc = 2;
  c.hi = {1.5, 0.6, 0.4};
  c.body_lo = {0.2, 0.1, 0.0};
  c.body_hi = {1.1, 0.5, 0.4};
  compare_ranks<3>(c, 25);
}

TEST_CASE("particles cross rank boundaries every step and none are lost", "[parallel]") {
  // 50 m/s with dt = 1e-3 moves every particle half a cell (one particle spacing) per step.
  Config c = moving_block(2, ShapeKind::BSpline2, TransferKind::APIC, UpdateOrder::USL);
  c.v0 = {50.0, 0.0, 0.0};
  const int n = std::min(3, gmtest::world_size());
  long min_sent = 1L << 40, count0 = 0, count1 = 0;
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    Simulation<2> sim(comm, c);
    sim.setup();
    count0 = sim.particles.global_size();
    for (int s = 0; s < 20; ++s) {
      sim.p2g(true);
      sim.grid_update(1e-3, true);
      sim.g2p(1e-3, Simulation<2>::kVel | Simulation<2>::kC | Simulation<2>::kL | Simulation<2>::kMove);
      sim.constitutive(1e-3);
      const MigrateStats st = sim.particles.migrate(sim.grid);
      min_sent = std::min(min_sent, st.sent);
    }
    count1 = sim.particles.global_size();
  });
  count0 = bcast(count0);
  count1 = bcast(count1);
  min_sent = bcast(min_sent);
  REQUIRE(count1 == count0);
  if (n > 1) REQUIRE(min_sent > 0); // some particles changed rank at every single step
}

TEST_CASE("migration: long jumps past neighbour ranks keep every particle and its data", "[parallel]") {
  // 60 x 6 cells, walls: PETSc splits along x, so on 3 ranks a jump from the first to the
  // last third passes the middle rank.
  Config c = gmtest::box2d(6.0, 0.6, 60, 6, {BC::Slip, BC::Slip, BC::Slip, BC::Slip}, "migrate");
  c.ppc = 2;
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    long before = 0, after = 0, misplaced = 0, bad_data = 0, idsum0 = 0, idsum1 = 0;
    gmtest::on_ranks(n, [&](MPI_Comm comm) {
      gmtest::SeededGrid<2> s(comm, c);
      Grid<2> &g = s.grid;
      Particles<2> &P = s.particles;
      before = P.global_size();
      // Tag each particle's velocity with its id, then send every particle with an even id
      // 4.5 m to the right if it is in the left quarter (jumping over ranks), and shift
      // the rest by a fraction of a cell.
      ParticleView<2> v = P.get();
      long s0 = 0;
      for (PetscInt p = 0; p < v.n; ++p) {
        v.v[2 * p] = (double)v.id[p];
        v.v[2 * p + 1] = -(double)v.id[p];
        s0 += v.id[p];
        if (v.x[2 * p] < 1.5 && v.id[p] % 2 == 0) v.x[2 * p] += 4.5;
        else v.x[2 * p + 1] = std::min(0.6, v.x[2 * p + 1] + 0.037);
      }
      P.restore(v);
      MPI_Allreduce(&s0, &idsum0, 1, MPI_LONG, MPI_SUM, comm);
      P.migrate(g);
      after = P.global_size();
      v = P.get();
      long mis = 0, bad = 0, s1 = 0;
      for (PetscInt p = 0; p < v.n; ++p) {
        mis += g.owner_rank(v.x + 2 * p) != g.rank;
        bad += v.v[2 * p] != (double)v.id[p] || v.v[2 * p + 1] != -(double)v.id[p];
        s1 += v.id[p];
      }
      P.restore(v);
      MPI_Allreduce(&mis, &misplaced, 1, MPI_LONG, MPI_SUM, comm);
      MPI_Allreduce(&bad, &bad_data, 1, MPI_LONG, MPI_SUM, comm);
      MPI_Allreduce(&s1, &idsum1, 1, MPI_LONG, MPI_SUM, comm);
    });
    INFO("ranks " << n);
    REQUIRE(bcast(before) == 60 * 6 * 4);
    REQUIRE(bcast(after) == bcast(before));
    REQUIRE(bcast(misplaced) == 0);
    REQUIRE(bcast(bad_data) == 0);
    REQUIRE(bcast(idsum1) == bcast(idsum0));
  }
}

TEST_CASE("a particle leaving a wall face stops the run with a message on every rank", "[parallel]") {
  const Config c = gmtest::box2d(2.0, 1.0, 20, 10, {BC::Slip, BC::Free, BC::Slip, BC::Slip}, "leave");
  int threw = 0;
  std::string msg;
  gmtest::on_ranks(std::min(2, gmtest::world_size()), [&](MPI_Comm comm) {
    gmtest::SeededGrid<2> s(comm, c);
    Particles<2> &P = s.particles;
    ParticleView<2> v = P.get();
    for (PetscInt p = 0; p < v.n; ++p)
      if (v.id[p] == 7) v.x[2 * p] = 2.3;
    P.restore(v);
    try {
      P.migrate(s.grid);
    } catch (const UserError &e) {
      threw = 1;
      msg = e.what();
    }
  });
  if (gmtest::world_rank() < 2) {
    REQUIRE(threw == 1);
    REQUIRE(msg.find("particle 7 left the domain through the xhi face") != std::string::npos);
    REQUIRE(msg.find("-bc_xhi") != std::string::npos);
  }
}

TEST_CASE("outlet faces remove and count particles", "[parallel]") {
  const Config c = gmtest::box2d(2.0, 1.0, 20, 10, {BC::Slip, BC::Slip, BC::Outlet, BC::Slip}, "outlet");
  long removed = 0, before = 0, after = 0;
  gmtest::on_ranks(std::min(3, gmtest::world_size()), [&](MPI_Comm comm) {
    gmtest::SeededGrid<2> s(comm, c);
    Particles<2> &P = s.particles;
    before = P.global_size();
    ParticleView<2> v = P.get();
    for (PetscInt p = 0; p < v.n; ++p)
      if (v.x[2 * p + 1] < 0.25) v.x[2 * p + 1] -= 0.3; // the bottom 2 rows (1 ppc) fall out
    P.restore(v);
    removed = P.migrate(s.grid).removed;
    after = P.global_size();
  });
  REQUIRE(bcast(removed) == 20 * 2);
  REQUIRE(bcast(after) == bcast(before) - 20 * 2);
}

TEST_CASE("P2G and G2P conserve mass and momentum on any number of ranks", "[parallel]") {
  // Fully periodic domain, no gravity, an elastic spinning, moving, compressed block:
  // total mass is exact and total momentum is conserved to round-off over many steps
  // (internal forces sum to zero because the gradients of a partition of unity do).
  for (auto sh : {ShapeKind::Linear, ShapeKind::GIMP, ShapeKind::BSpline2})
    for (auto tr : {TransferKind::PIC, TransferKind::FLIP, TransferKind::APIC}) {
      Config c = moving_block(2, sh, tr, UpdateOrder::USL);
      c.bc[1][0] = c.bc[1][1] = BC::Periodic;
      c.gravity = {0, 0, 0};
      double m0 = 0, m1 = 0, p0[3] = {0, 0, 0}, p1[3] = {0, 0, 0}, gm = 0, gp[2] = {0, 0}, pscale = 0;
      gmtest::on_ranks(std::min(3, gmtest::world_size()), [&](MPI_Comm comm) {
        Simulation<2> sim(comm, c);
        sim.setup();
        Totals t0 = sim.totals();
        m0 = t0.mass;
        for (int d = 0; d < 2; ++d) p0[d] = t0.momentum[d];
        pscale = t0.mass * t0.vmax;
        // Grid totals right after P2G.
        sim.p2g(false);
        double loc[3] = {0, 0, 0};
        NodeView<2> g = sim.grid.begin_global();
        for (int j = sim.grid.xs[1]; j < sim.grid.xs[1] + sim.grid.xm[1]; ++j)
          for (int i = sim.grid.xs[0]; i < sim.grid.xs[0] + sim.grid.xm[0]; ++i) {
            const double *n = g.at(i, j, 0);
            for (int q = 0; q < 3; ++q) loc[q] += n[q];
          }
        sim.grid.end_global();
        double glob[3];
        MPI_Allreduce(loc, glob, 3, MPI_DOUBLE, MPI_SUM, comm);
        gm = glob[0];
        gp[0] = glob[1];
        gp[1] = glob[2];
        for (int s = 0; s < 30; ++s) sim.step(2e-3);
        Totals t1 = sim.totals();
        m1 = t1.mass;
        for (int d = 0; d < 2; ++d) p1[d] = t1.momentum[d];
      });
      INFO("shape " << (int)sh << " transfer " << (int)tr);
      REQUIRE(bcast(gm) == Approx(bcast(m0)).epsilon(1e-14));
      REQUIRE(bcast(m1) == bcast(m0));
      const double ps = bcast(pscale);
      for (int d = 0; d < 2; ++d) {
        REQUIRE(std::fabs(bcast(gp[d]) - bcast(p0[d])) < 1e-13 * ps);
        REQUIRE(std::fabs(bcast(p1[d]) - bcast(p0[d])) < 1e-12 * ps);
      }
    }
}
