// Seed 004's scenes (issue 20): the 3D Taylor-Couette cell with the dynamical nonlocal model
// (the model the seed uses there) on 1, 2 and 3 ranks, and the annulus scene accepting every
// material (its 1D reference skipped where it does not apply).
#include "harness.hpp"

#include "granmpm/scene.hpp"

using namespace granmpm;
using gmtest::bcast;

namespace {

// Seed 004's Taylor-Couette cell (Table 1, second set: d 4 mm, mu_s 0.38, mu_2 0.64,
// I_0 0.278, rho_s 2550, A 0.48, t0 1e-4 s), coarse (h = 5 d) and soft (E 1e5 Pa).
Config taylor_couette(FluidityStepKind step) {
  Config c;
  c.scene = SceneKind::Annulus;
  c.material = MaterialKind::Dynamic;
  c.fluidity_step = step;
  gmtest::taylor_couette_cell(c);
  c.gravity_ramp = 0;
  c.p0 = 0;
  c.ppc = 2;
  c.E = 1e5;
  c.nu = 0.3;
  c.rho = 1530;
  c.gran.rho_c = 1377;
  c.gran.d = 0.004;
  c.gran.mu_s = 0.38;
  c.gran.mu_2 = 0.64;
  c.gran.I_0 = 0.278;
  c.gran.rho_s = 2550;
  c.gran.A = 0.48;
  c.gran.b = (c.gran.mu_2 - c.gran.mu_s) / c.gran.I_0;
  c.t0 = 1e-4;
  c.t_end = 1;
  c.output_dir = gmtest::outdir("taylor_couette_dynamic");
  c.output_final = false;
  c.progress_interval = 0;
  c.quiet = true;
  return c;
}

} // namespace

TEST_CASE("3D Taylor-Couette with the dynamical model on 1, 2 and 3 ranks: same particles, fluidity, top-surface profile and torque", "[parallel][scenes]") {
  for (FluidityStepKind step : {FluidityStepKind::Explicit, FluidityStepKind::Implicit}) {
    Config c = taylor_couette(step);
    // The explicit fluidity step's stability limit (local relaxation) falls to 8e-5 s as the
    // material yields; the implicit step takes the momentum step's 1e-3 s.
    const bool expl = step == FluidityStepKind::Explicit;
    const double dt = expl ? 2e-5 : 1e-3;
    const int steps = expl ? 40 : 10;
    const auto ref = gmtest::run_steps<3>(1, c, steps, dt);
    // The dynamical model amplifies round-off (tests/mpi/test_rank_models.cpp): bound the
    // rank differences by the 1-rank effect of a 1e-13 change of rho, measured here.
    Config pert = c;
    pert.rho = c.rho * (1 + 1e-13);
    const auto sens_run = gmtest::run_steps<3>(1, pert, steps, dt);
    const double sens = bcast(gmtest::world_rank() == 0 ? gmtest::max_rel_diff(ref, sens_run) : 0.0);
    c.dt = dt;
    c.t_end = steps * dt;
    const auto mref = gmtest::run_scene<3>(1, c);
    double gmax = 0;
    if (gmtest::world_rank() == 0)
      for (const auto &r : ref) gmax = std::max(gmax, r.g);
    gmax = bcast(gmax);
    for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
      const auto par = gmtest::run_steps<3>(n, c, steps, dt);
      const double d = bcast(gmtest::world_rank() == 0 ? gmtest::max_rel_diff(ref, par) : 0.0);
      const auto mpar = gmtest::run_scene<3>(n, c);
      const double dw = std::fabs(mpar.at("omega_min_top") - mref.at("omega_min_top")), dT = std::fabs(mpar.at("inner_torque") - mref.at("inner_torque"));
      INFO((expl ? "explicit" : "implicit") << " fluidity step, ranks " << n << ": max relative difference " << d << "; 1-rank sensitivity to a 1e-13 change of rho " << sens
                                            << "; largest g " << gmax << "; omega_min_top " << mref.at("omega_min_top") << " diff " << dw << "; torque "
                                            << mref.at("inner_torque") << " diff " << dT);
      REQUIRE(d >= 0); // same count and ids
      REQUIRE(d < 10 * sens + 1e-14);
      REQUIRE(d < 1e-8);
      REQUIRE(dw <= 1e-8);
      REQUIRE(dT <= 1e-8 * std::fabs(mref.at("inner_torque")));
    }
    REQUIRE(bcast((long)ref.size()) > 0);
    REQUIRE(gmax > 100 * c.g0); // the material yields: g grew from g0
    REQUIRE(std::fabs(mref.at("inner_torque")) > 0);
  }
}

TEST_CASE("2D annulus accepts the dynamical model and skips the 1D reference it does not have", "[scenes]") {
  Config c;
  c.dim = 2;
  c.scene = SceneKind::Annulus;
  c.material = MaterialKind::Dynamic;
  c.lo = {-0.45, -0.45, 0};
  c.hi = {0.45, 0.45, 0};
  c.cells = {20, 20, 1};
  c.bc = {{{BC::Sticky, BC::Sticky}, {BC::Sticky, BC::Sticky}, {BC::Periodic, BC::Periodic}}};
  c.gravity = {0, 0, 0};
  c.p0 = 900;
  c.E = 1e6;
  c.rho = 1500;
  c.dt = 4e-4;
  c.t_end = 4e-3;
  c.output_dir = gmtest::outdir("annulus_dynamic");
  c.output_final = false;
  c.progress_interval = 0;
  c.quiet = true;
  const auto m = gmtest::run_scene<2>(1, c);
  CHECK(m.count("l2_rel") == 0);                                // no reference applies
  CHECK(std::fabs(m.at("mean_pressure") - 900) < 0.05 * 900);   // the confinement is kept
  CHECK(scene_has_reference(c));                                // (the chute's dynamical reference)
  c.material = MaterialKind::LinearElastic;
  CHECK(!scene_has_reference(c));
}
