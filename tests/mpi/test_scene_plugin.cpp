// Worked example of docs/architecture.md "Add a scene": a scene defined in this file, added
// with one registration line, run through Simulation::run and checked against an analytic
// solution.
//
// The scene: an elastic block thrown upwards with speed V0 in free space under gravity g
// (all faces free, the domain large enough that it touches none). Its rule: it needs
// gravity. Its diagnostic: the centre-of-mass velocity, which must follow V0 - g t exactly
// (the grid forces are internal, the transfers conserve momentum), to round-off.
#include "harness.hpp"

#include "granmpm/scene.hpp"

using namespace granmpm;

namespace {

constexpr double kV0 = 0.5, kG = 9.81;

template <int dim>
class ThrowScene final : public SceneCase<dim> {
public:
  void init_particle(const Config &, const double *, const double *, double *v, double *) const override { v[dim - 1] = kV0; }
  void validate(const Config &c) const override {
    if (c.gravity[c.dim - 1] == 0) throw UserError("-scene throw_test: the block is thrown against gravity; set -gravity");
  }
  void finalize(State<dim> &sim, Metrics &m) override {
    const Totals t = sim.totals();
    m["vcm"] = t.momentum[dim - 1] / t.mass;
    m["vcm_exact"] = kV0 + sim.cfg.gravity[dim - 1] * sim.time;
  }
};

// The one registration line.
const SceneKind kThrow = register_scene<ThrowScene>("throw_test");

Config throw_config() {
  Config c = gmtest::hypo_block(2); // E 1e5, nu 0.3, rho 1000, 2 PPC
  c.scene = kThrow;
  c.material = MaterialKind::LinearElastic;
  c.spin = 0;
  c.p0 = 0;
  c.lo = {0, 0, 0};
  c.hi = {1, 1, 0};
  c.cells = {10, 10, 1};
  c.body_lo = {0.3, 0.3, 0};
  c.body_hi = {0.7, 0.5, 0};
  c.bc = {{{BC::Free, BC::Free}, {BC::Free, BC::Free}, {BC::Free, BC::Free}}};
  c.gravity = {0, -kG, 0};
  c.t_end = 0.05; // the block rises by about 2 cm
  c.output_dir = gmtest::outdir("scene_plugin");
  c.output_final = false;
  c.progress_interval = 0;
  c.quiet = true;
  return c;
}

} // namespace

TEST_CASE("a scene defined in a test, registered with one line: thrown block, centre-of-mass velocity V0 - g t", "[parallel][scene]") {
  // The registry names it: -scene parses it, messages print it.
  REQUIRE(parse_scene("-scene", "throw_test") == kThrow);
  REQUIRE(std::string(to_string(kThrow)) == "throw_test");
  REQUIRE(scene_names().find("|throw_test") != std::string::npos);
  // Its own rule runs in Config::validate.
  Config bad = throw_config();
  bad.gravity = {0, 0, 0};
  REQUIRE_THROWS_WITH(bad.validate(), Catch::Contains("-scene throw_test"));

  const Config c = throw_config();
  double v1 = 0;
  for (int n = 1; n <= std::min(3, gmtest::world_size()); ++n) {
    double vcm = 0, exact = 0, t = 0;
    gmtest::on_ranks(n, [&](MPI_Comm comm) {
      Simulation<2> sim(comm, c);
      sim.setup();
      const auto m = sim.run();
      vcm = m.at("vcm");
      exact = m.at("vcm_exact");
      t = sim.time;
    });
    vcm = gmtest::bcast(vcm);
    exact = gmtest::bcast(exact);
    t = gmtest::bcast(t);
    INFO(n << " ranks: t = " << t << ", v_cm " << vcm << ", exact " << exact);
    REQUIRE(t > 0.9 * c.t_end);
    REQUIRE(std::fabs(vcm - exact) < 1e-12 * kV0); // momentum balance: round-off only
    if (n == 1) v1 = vcm;
    REQUIRE(std::fabs(vcm - v1) < 1e-13 * kV0);
  }
}
