// Elemental and hybrid density rules (seed 000 section 3.4) on 1, 2 and 3 ranks.
#include "harness.hpp"

#include "granmpm/density.hpp"

using namespace granmpm;
using gmtest::bcast;

namespace {
// A 10 x 6-cell block of material (4 particles per cell) in a 20 x 10-cell box.
Config block(DensityMethod m) {
  Config c;
  c.dim = 2;
  c.scene = SceneKind::Block;
  c.material = MaterialKind::LinearElastic;
  c.lo = {0, 0, 0};
  c.hi = {2, 1, 0};
  c.cells = {20, 10, 1};
  c.bc = {{{BC::Slip, BC::Slip}, {BC::Slip, BC::Slip}, {BC::Periodic, BC::Periodic}}};
  c.body_lo = {0.5, 0.2, 0};
  c.body_hi = {1.5, 0.8, 0};
  c.ppc = 2;
  c.p0 = 0;
  c.gravity = {0, 0, 0};
  c.density = m;
  c.output_dir = gmtest::outdir("density");
  c.quiet = true;
  return c;
}

// Doubles every particle volume (as if the local rule had drifted), applies the cell rule,
// and counts particles given the elemental volume (h^2/4) and those left alone.
void count(int n, DensityMethod m, long &elemental, long &kept, long &edges) {
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    Simulation<2> sim(comm, block(m));
    sim.setup();
    ParticleView<2> P = sim.particles.get();
    for (PetscInt p = 0; p < P.n; ++p) P.vol[p] *= 2;
    sim.particles.restore(P);
    edges = sim.density->apply(sim.particles);
    const double v0 = sim.grid.h * sim.grid.h / 4;
    long loc[2] = {0, 0};
    P = sim.particles.get();
    for (PetscInt p = 0; p < P.n; ++p) {
      if (std::fabs(P.vol[p] - v0) < 1e-12 * v0) loc[0]++;
      else if (std::fabs(P.vol[p] - 2 * v0) < 1e-12 * v0) loc[1]++;
    }
    sim.particles.restore(P);
    long glob[2];
    MPI_Allreduce(loc, glob, 2, MPI_LONG, MPI_SUM, comm);
    elemental = glob[0];
    kept = glob[1];
  });
}
} // namespace

TEST_CASE("elemental density gives every particle its cell's density", "[density][parallel]") {
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    long e = 0, k = 0, edges = 0;
    count(n, DensityMethod::Elemental, e, k, edges);
    REQUIRE(bcast(e) == 240);
    REQUIRE(bcast(k) == 0);
  }
}

TEST_CASE("hybrid density: Sobel edges keep the local rule, the interior takes the cell density", "[density][parallel]") {
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    long e = 0, k = 0, edges = 0;
    count(n, DensityMethod::Hybrid, e, k, edges);
    INFO("ranks " << n);
    // Interior cells: 8 x 4 = 32 (x 4 particles); the block's outer ring of 28 cells is edge.
    REQUIRE(bcast(e) == 32 * 4);
    REQUIRE(bcast(k) == 28 * 4);
    // Edge cells: the ring inside the block plus the ring of empty cells around it (12 x 8 - 10 x 6).
    REQUIRE(bcast(edges) == 28 + (12 * 8 - 60));
  }
}
