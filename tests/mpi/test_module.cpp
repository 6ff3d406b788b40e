// The module recipe of docs/architecture.md, worked: a test-only module that counts the
// grid nodes its node pass visits and the hooks the step calls. Reference: a block at rest
// filling nx x ny (x nz) whole cells with linear shape functions puts mass on exactly
// (nx+1)(ny+1)(nz+1) nodes, so every grid pass visits that many nodes summed over the
// ranks; the same on 1, 2 and 3 ranks, and the particles are bitwise those of a run
// without the module.
#include "harness.hpp"

using namespace granmpm;
using gmtest::bcast;

namespace {

template <int dim>
class NodeCounter : public Module<dim> {
public:
  std::string name() const override { return "node counter (test)"; }
  bool has_node_pass() const override { return true; }
  void begin_step(State<dim> &, double) override { ++steps; }
  void begin_grid(State<dim> &, double, bool) override { mine = 0; }
  void node(const NodeAt &, double *, double, bool) override { ++mine; }
  void end_grid(State<dim> &S, double, bool) override {
    long all = 0;
    MPI_Allreduce(&mine, &all, 1, MPI_LONG, MPI_SUM, S.comm);
    per_pass.push_back(all);
  }
  void end_step(State<dim> &, double) override { ++ends; }
  void rebuild(State<dim> &) override { ++rebuilds; }
  long mine = 0, steps = 0, ends = 0, rebuilds = 0;
  std::vector<long> per_pass;
};

// A block at rest, no gravity, stress-free: nothing moves, the node set is fixed.
Config resting_block(int dim, UpdateOrder up) {
  Config c = gmtest::hypo_block(dim);
  c.p0 = 0;
  c.set_scene_param("-spin", 0);
  c.v0 = c.gravity = c.lo = {0, 0, 0};
  c.hi = {2.0, 1.0, 0.6};
  c.cells = {20, 10, 6};
  c.body_lo = {0.5, 0.2, 0.1};
  c.body_hi = {1.5, 0.8, 0.5}; // 10 x 6 (x 4) cells
  c.bc = {{{BC::Slip, BC::Slip}, {BC::Slip, BC::Slip}, {BC::Slip, BC::Slip}}};
  c.shape = ShapeKind::Linear;
  c.update = up;
  gmtest::quiet(c, "module");
  return c;
}

struct Counts {
  std::vector<long> per_pass;
  long steps = 0, ends = 0, rebuilds = 0;
  std::vector<ParticleRecord> with, without;
};

template <int dim>
Counts run(int n, const Config &c, int nsteps) {
  Counts out;
  gmtest::on_ranks(n, [&](MPI_Comm comm) {
    Simulation<dim> sim(comm, c);
    NodeCounter<dim> *counter = nullptr;
    sim.extra_modules = [&](Simulation<dim> &s) {
      auto m = std::make_unique<NodeCounter<dim>>();
      counter = m.get();
      s.modules.push_back(std::move(m));
    };
    sim.setup();
    for (int s = 0; s < nsteps; ++s) sim.step(1e-3);
    if (n > 1) sim.repartition(sim.balanced_split()); // one rebuild
    out.with = sim.gather(0);
    if (gmtest::world_rank() == 0) {
      out.per_pass = counter->per_pass;
      out.steps = counter->steps;
      out.ends = counter->ends;
      out.rebuilds = counter->rebuilds;
    }
  });
  out.without = gmtest::run_steps<dim>(n, c, nsteps, 1e-3);
  return out;
}

template <int dim>
void check(UpdateOrder up, int passes_per_step) {
  const Config c = resting_block(dim, up);
  const long nodes = dim == 2 ? 11L * 7 : 11L * 7 * 5;
  const int nsteps = 3;
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    const Counts k = run<dim>(n, c, nsteps);
    INFO(dim << "D, " << n << " rank(s), update order " << (int)up);
    REQUIRE(bcast((long)k.per_pass.size()) == (long)nsteps * passes_per_step);
    for (size_t p = 0; p < (size_t)nsteps * passes_per_step; ++p) REQUIRE(bcast(gmtest::world_rank() == 0 ? k.per_pass[p] : 0L) == nodes);
    REQUIRE(bcast(k.steps) == nsteps);
    REQUIRE(bcast(k.ends) == nsteps);
    REQUIRE(bcast(k.rebuilds) == (n > 1 ? 1L : 0L));
    // The module only counts: the particles are those of a run without it, bitwise.
    const double d = bcast(gmtest::world_rank() == 0 ? gmtest::max_rel_diff(k.with, k.without) : 0.0);
    REQUIRE(d == 0.0);
  }
}

// A moving, spinning, pre-compressed block: the counts agree on 1, 2 and 3 ranks and the
// particles are bitwise those of a run without the module.
template <int dim>
void check_moving() {
  Config c = resting_block(dim, UpdateOrder::USL);
  c.v0 = {2.0, 0.5, 0.0};
  c.set_scene_param("-spin", 1.0);
  c.p0 = 100;
  c.gravity = {0, -9.81, 0};
  const int nsteps = 20;
  const Counts ref = run<dim>(1, c, nsteps);
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    const Counts k = n == 1 ? ref : run<dim>(n, c, nsteps);
    INFO(dim << "D moving block, " << n << " rank(s)");
    REQUIRE(bcast(gmtest::world_rank() == 0 && k.per_pass == ref.per_pass ? 1L : 0L) == 1);
    const double d = bcast(gmtest::world_rank() == 0 ? gmtest::max_rel_diff(k.with, k.without) : 0.0);
    REQUIRE(d == 0.0);
  }
  REQUIRE(bcast(ref.per_pass.empty() ? 0L : ref.per_pass.back()) > 11L * 7); // it moved onto more nodes
}

} // namespace

TEST_CASE("a test-only module counts the grid nodes with mass on 1, 2 and 3 ranks", "[parallel][module]") {
  check<2>(UpdateOrder::USL, 1);
  check<2>(UpdateOrder::MUSL, 2);
  check<3>(UpdateOrder::USL, 1);
  check_moving<2>();
}
