// Worked example of docs/architecture.md "Add a scene": a scene defined in this file, added
// with one registration line, run through Simulation::run and checked against an analytic
// solution.
//
// The scene: an elastic block thrown upwards with speed V0 in free space under gravity g
// (all faces free, the domain large enough that it touches none). Its own option:
// -throw_speed V0 (declared here: -help lists it, Config::from_options reads it, its range
// is checked, the restart signature holds it). Its rule: it needs gravity. Its diagnostic:
// the centre-of-mass velocity, which must follow V0 - g t exactly (the grid forces are
// internal, the transfers conserve momentum), to round-off.
#include "harness.hpp"

#include "granmpm/scene.hpp"

#include <limits>

using namespace granmpm;

namespace {

constexpr double kG = 9.81;

template <int dim>
class ThrowScene final : public SceneCase<dim> {
public:
  const std::vector<SceneOption> &options() const override {
    static const std::vector<SceneOption> o = {{{"-throw_speed", "Upward speed V0 of the thrown block [m/s]", 0.5, 0, std::numeric_limits<double>::infinity(), true}}};
    return o;
  }
  void init_particle(const Config &c, const double *, const double *, double *v, double *) const override { v[dim - 1] = c.scene_param("-throw_speed"); }
  void validate(const Config &c) const override {
    if (c.gravity[c.dim - 1] == 0) throw UserError("-scene throw_test: the block is thrown against gravity; set -gravity");
  }
  void finalize(State<dim> &sim, Metrics &m) override {
    const Totals t = sim.totals();
    m["vcm"] = t.momentum[dim - 1] / t.mass;
    m["vcm_exact"] = sim.cfg.scene_param("-throw_speed") + sim.cfg.gravity[dim - 1] * sim.time;
  }
};

// The one registration line.
const SceneKind kThrow = register_scene<ThrowScene>("throw_test");

Config throw_config() {
  Config c = gmtest::hypo_block(2); // E 1e5, nu 0.3, rho 1000, 2 PPC
  c.scene = kThrow;
  c.material = MaterialKind::LinearElastic;
  c.set_scene_param("-throw_speed", 0.7);
  c.p0 = 0;
  c.lo = {0, 0, 0};
  c.hi = {1, 1, 0};
  c.cells = {10, 10, 1};
  c.body_lo = {0.3, 0.3, 0};
  c.body_hi = {0.7, 0.5, 0};
  c.bc = {{{BC::Free, BC::Free}, {BC::Free, BC::Free}, {BC::Free, BC::Free}}};
  c.gravity = {0, -kG, 0};
  c.t_end = 0.05; // the block rises by about 2 cm
  gmtest::quiet(c, "scene_plugin");
  return c;
}

// Config::from_options with these options set in the PETSc options database (cleared after).
Config from_cli(const std::vector<std::pair<const char *, const char *>> &opts) {
  for (const auto &o : opts) PetscOptionsSetValue(NULL, o.first, o.second);
  struct Clear {
    const std::vector<std::pair<const char *, const char *>> &o;
    ~Clear() {
      for (const auto &x : o) PetscOptionsClearValue(NULL, x.first);
    }
  } clear{opts};
  return Config::from_options(PETSC_COMM_WORLD);
}

} // namespace

TEST_CASE("a test scene's own option: read by Config::from_options, range-checked, in the signature", "[parallel][scene]") {
  const Config c = from_cli({{"-scene", "throw_test"}, {"-throw_speed", "0.7"}});
  REQUIRE(c.scene == kThrow);
  REQUIRE(c.scene_param("-throw_speed") == 0.7);
  bool signed_ = false;
  for (const auto &kv : c.signature()) signed_ = signed_ || (kv.first == "-throw_speed" && kv.second == "0.69999999999999996");
  REQUIRE(signed_);
  REQUIRE(from_cli({{"-scene", "throw_test"}}).scene_param("-throw_speed") == 0.5); // its default
  REQUIRE_THROWS_WITH(from_cli({{"-scene", "throw_test"}, {"-throw_speed", "-1"}}), "-throw_speed must be > 0 (got -1)");
  REQUIRE_THROWS_WITH(from_cli({{"-scene", "throw_test"}, {"-throw_speed", "inf"}}), Catch::Contains("-throw_speed: 'inf' is not a finite number"));
  Config other;
  REQUIRE_THROWS_WITH(other.set_scene_param("-throw_speeed", 1), Catch::Contains("no scene declares the option -throw_speeed"));
}

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
    REQUIRE(std::fabs(exact - (0.7 - kG * t)) < 1e-15); // -throw_speed reached the scene
    REQUIRE(std::fabs(vcm - exact) < 1e-12 * 0.7);     // momentum balance: round-off only
    if (n == 1) v1 = vcm;
    REQUIRE(std::fabs(vcm - v1) < 1e-13 * 0.7);
  }
}
