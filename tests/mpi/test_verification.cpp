// Verification against independent references: the elastic bar (analytic first mode),
// the elastic column (static stress), the vertical chute (local analytic and nonlocal 1D
// reference). Thresholds are the values measured with this code (bench/ and
// docs/verification.md) plus about 20%: the runs are deterministic, so a change beyond
// that is a real change in accuracy. Observed orders are asserted where refinement is run.
#include "harness.hpp"

#include <fstream>

using namespace granmpm;
using gmtest::bcast;

namespace {

Config bar(int n, ShapeKind shape, double amplitude) {
  Config c = gmtest::bar_config(n);
  c.shape = shape;
  c.set_scene_param("-bar_amplitude", amplitude);
  return c;
}

Config column(int n, ShapeKind shape) {
  Config c;
  c.dim = 2;
  c.scene = SceneKind::Column;
  c.material = MaterialKind::LinearElastic;
  c.E = 1e6;
  c.nu = 0.3;
  c.rho = 1000;
  c.lo = {0, 0, 0};
  c.hi = {0.5, 1.5, 0};
  c.cells = {n, 3 * n, 1};
  c.body_hi = {1e9, 1.0, 1e9}; // column of height 1 m
  c.bc = {{{BC::Slip, BC::Slip}, {BC::Slip, BC::Free}, {BC::Periodic, BC::Periodic}}};
  c.gravity = {0, -10, 0};
  c.gravity_ramp = 0.5;
  c.damping = 20; // quasi-static settling
  c.t_end = 2;
  c.ppc = 2;
  c.shape = shape;
  c.transfer = TransferKind::APIC;
  c.output_dir = gmtest::outdir("column");
  c.output_final = false;
  c.progress_interval = 0;
  c.quiet = true;
  return c;
}

Config chute(int n, MaterialKind m) {
  Config c; // the defaults are seed 000's Table 4.1 chute
  c.material = m;
  c.cells = {n, 4, 1};
  c.hi = {0.5, 4.0 / n, 0};
  c.output_dir = gmtest::outdir("chute");
  c.output_final = false;
  c.progress_interval = 0;
  c.quiet = true;
  return c;
}

// Column collapse of aspect ratio a (2D plane strain), h = L0/20: the parameters of
// examples/collapse.opts (local mu(I), mu_s = 0.3 calibrated, d = 1 mm, rho_c = 0.9 rho).
Config collapse(double a) {
  Config c = gmtest::collapse_soil(2);
  const double L0 = 0.2, H0 = a * L0, h = L0 / 20;
  const double W = std::round((L0 * (1 + 1.3 * std::max(1.2 * a, 1.9 * std::pow(a, 2.0 / 3.0))) + 0.1) / h) * h;
  const double Ht = std::round((1.1 * H0 + 0.06) / h) * h;
  c.lo = {0, 0, 0};
  c.hi = {W, Ht, 0};
  c.cells = {(int)std::lround(W / h), (int)std::lround(Ht / h), 1};
  c.body_hi = {L0, H0, 1e9};
  c.bc = {{{BC::Slip, BC::Slip}, {BC::Sticky, BC::Free}, {BC::Periodic, BC::Periodic}}};
  c.t_end = 6 * std::sqrt(H0 / 9.81);
  c.output_dir = gmtest::outdir("collapse");
  return c;
}

} // namespace

TEST_CASE("column collapse, a = 0.5 and a = 2: runout within 15% of the 2D law of Lube et al. 2005", "[verification][collapse]") {
  // Lube's law is an experimental fit, not an exact solution; the bound is 15%.
  // Measured at h = L0/20 (docs/verification.md, bench/collapse.py): a = 0.5: 0.542 against
  // 0.6 (-9.7%); a = 2: 2.504 against 2.523 (-0.8%; between the two regimes the laws are
  // interpolated). At h = L0/40: 0.539 (-10%) and 2.466 (-2.3%): the deviation is the
  // model's, not the grid's. With the chute's mu_s = 0.3819 a = 0.5 is 22% short (see docs).
  for (double a : {0.5, 2.0}) {
    const auto m = gmtest::run_scene<2>(1, collapse(a));
    const double runout = m.at("runout"), law = m.at("lube_runout");
    INFO("a = " << a << ": runout " << runout << ", Lube et al. 2005 " << law);
    REQUIRE(std::fabs(runout / law - 1) < 0.15);
    REQUIRE(m.at("runout_99") <= runout); // the 99% mass front lies behind the tip
  }
}

TEST_CASE("elastic bar, small amplitude: velocity and energy errors fall at first order for every shape", "[verification]") {
  // Amplitude 1e-4 (strain 1e-5) keeps the updated-Lagrangian MPM within linear theory;
  // the error is then the scheme's: symplectic-Euler time error with dt ~ h (measured
  // orders 0.96-1.05, docs/verification.md).
  const double bound100[3] = {3.3e-3, 3.3e-3, 1.0e-2}; // measured 2.75e-3, 2.74e-3, 8.35e-3
  int k = 0;
  for (auto sh : {ShapeKind::Linear, ShapeKind::GIMP, ShapeKind::BSpline2}) {
    std::vector<double> ev, ee;
    for (int n : {25, 50, 100}) {
      const auto m = gmtest::run_scene<2>(1, bar(n, sh, 1e-4));
      ev.push_back(m.at("velocity_error_max"));
      ee.push_back(m.at("energy_drift_max"));
    }
    for (size_t i = 1; i < ev.size(); ++i) {
      INFO("shape " << (int)sh << ": velocity error " << ev[i] << " energy drift " << ee[i]);
      REQUIRE(std::log2(ev[i - 1] / ev[i]) > 0.9);
      REQUIRE(std::log2(ee[i - 1] / ee[i]) > 0.9);
    }
    REQUIRE(ev.back() < bound100[k++]);
  }
}

TEST_CASE("elastic bar, amplitude 0.1 (the issue's case): errors fall under refinement", "[verification]") {
  // At 1% strain the error plateaus near 2e-3 (geometric nonlinearity) beyond 100 cells.
  std::vector<double> ev;
  for (int n : {25, 50, 100}) ev.push_back(gmtest::run_scene<2>(1, bar(n, ShapeKind::GIMP, 0.1)).at("velocity_error_max"));
  REQUIRE(ev[1] < ev[0]);
  REQUIRE(ev[2] < ev[1]);
  REQUIRE(ev[2] < 2.4e-3); // measured 1.98e-3
}

TEST_CASE("elastic bar in 3D matches the 2D plane-strain run", "[verification]") {
  // Periodic in y and z, nu = 0: the 3D bar is the same 1D problem, through the 3D kernels.
  for (int n : {25, 50}) {
    Config c2 = bar(n, ShapeKind::GIMP, 0.1), c3 = c2;
    c3.dim = 3;
    c3.hi[2] = c3.hi[1];
    c3.cells[2] = 4;
    const auto m2 = gmtest::run_scene<2>(1, c2), m3 = gmtest::run_scene<3>(1, c3);
    INFO("n " << n << ": 2D " << m2.at("velocity_error_max") << " 3D " << m3.at("velocity_error_max"));
    REQUIRE(m3.at("velocity_error_max") == Approx(m2.at("velocity_error_max")).epsilon(1e-6));
    REQUIRE(m3.at("energy_drift_max") == Approx(m2.at("energy_drift_max")).epsilon(1e-6));
  }
}

TEST_CASE("elastic column settles to sigma_yy = -rho g (H - y)", "[verification]") {
  std::vector<double> e;
  for (int n : {10, 20}) e.push_back(gmtest::run_scene<2>(1, column(n, ShapeKind::GIMP)).at("stress_error_rms"));
  INFO("rms error / (rho g H): " << e[0] << ", " << e[1]);
  REQUIRE(e[0] < 1.4e-2); // measured 1.14e-2
  REQUIRE(e[1] < 6.2e-3); // measured 5.09e-3
  REQUIRE(std::log2(e[0] / e[1]) > 0.9);
}

TEST_CASE("vertical chute, local mu(I): profile against the analytic solution", "[verification][chute]") {
  const double e20 = gmtest::run_scene<2>(1, chute(20, MaterialKind::MuI)).at("l2_rel");
  const double e40 = gmtest::run_scene<2>(1, chute(40, MaterialKind::MuI)).at("l2_rel");
  INFO("relative L2 error: 20 cells " << e20 << ", 40 cells " << e40);
  REQUIRE(e20 < 1.25e-2); // measured 1.03e-2
  REQUIRE(e40 < 4.3e-3);  // measured 3.53e-3
  REQUIRE(e40 < 0.5 * e20);
}

TEST_CASE("vertical chute, nonlocal fluidity: profile against the 1D reference", "[verification][chute]") {
  const double e20 = gmtest::run_scene<2>(1, chute(20, MaterialKind::Nonlocal)).at("l2_rel");
  const double e40 = gmtest::run_scene<2>(1, chute(40, MaterialKind::Nonlocal)).at("l2_rel");
  INFO("relative L2 error: 20 cells " << e20 << ", 40 cells " << e40);
  REQUIRE(e20 < 1.2e-2); // measured 9.90e-3
  REQUIRE(e40 < 2.5e-3); // measured 2.09e-3
  REQUIRE(e40 < 0.3 * e20);
}

TEST_CASE("vertical chute, nonlocal: 1, 2 and 3 ranks give the same state", "[parallel][chute]") {
  PetscOptionsSetValue(NULL, "-fluidity_ksp_rtol", "1e-12");
  Config c = chute(20, MaterialKind::Nonlocal);
  c.cells = {20, 8, 1};
  c.hi = {0.5, 0.4, 0};
  c.ppc = 2;
  const double dt = 5e-5;
  const auto ref = gmtest::run_steps<2>(1, c, 300, dt);
  for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
    const auto par = gmtest::run_steps<2>(n, c, 300, dt);
    const double d = bcast(gmtest::world_rank() == 0 ? gmtest::max_rel_diff(ref, par) : 0.0);
    INFO("ranks " << n << ": max relative difference " << d);
    REQUIRE(d >= 0);
    REQUIRE(d < 1e-8); // fluidity solved to rtol 1e-12 by AMG, which depends on the partition
  }
  PetscOptionsClearValue(NULL, "-fluidity_ksp_rtol");
}

TEST_CASE("A = 0 reduces the nonlocal models to the local model: same chute profile", "[verification][dynamic]") {
  Config local = chute(20, MaterialKind::MuI), steady = chute(20, MaterialKind::Nonlocal), dyn = chute(20, MaterialKind::Dynamic);
  steady.gran.A = dyn.gran.A = 0;
  std::vector<std::vector<double>> prof;
  for (const Config &c : {local, steady, dyn}) {
    gmtest::run_scene<2>(1, c);
    prof.push_back(gmtest::read_profile(c.output_dir));
  }
  double d_steady = 0, d_dyn = 0, vmax = 0;
  if (gmtest::world_rank() == 0)
    for (size_t i = 0; i < prof[0].size(); ++i) {
      vmax = std::max(vmax, std::fabs(prof[0][i]));
      d_steady = std::max(d_steady, std::fabs(prof[1][i] - prof[0][i]));
      d_dyn = std::max(d_dyn, std::fabs(prof[2][i] - prof[0][i]));
    }
  d_steady = bcast(d_steady) / bcast(vmax);
  d_dyn = bcast(d_dyn) / bcast(vmax);
  INFO("max |v - v_local| / max |v|: steady nonlocal " << d_steady << ", dynamical " << d_dyn);
  // The steady states coincide (differences 4e-9 and 4e-6 at t = 2.5 s); at 1.25 s the last
  // of the transient remains: measured 1.7e-6 (steady, A = 0) and 7.9e-6 (dynamical), three
  // orders below the discretisation error (1e-2).
  REQUIRE(d_steady < 1e-5);
  REQUIRE(d_dyn < 5e-5);
}

TEST_CASE("dynamical fluidity: chute against its steady 1D reference, implicit step", "[verification][dynamic]") {
  // The dynamical model's steady state is its own ODE, (A d)^2 g'' = (mu_s - mu) g +
  // b sqrt(rho_s d^2/p) mu g^2, not the steady model's (2.6% apart in plug speed here).
  Config c20 = chute(20, MaterialKind::Dynamic), c40 = chute(40, MaterialKind::Dynamic);
  const double e20 = gmtest::run_scene<2>(1, c20).at("l2_rel");
  const double e40 = gmtest::run_scene<2>(1, c40).at("l2_rel");
  INFO("relative L2 error: 20 cells " << e20 << ", 40 cells " << e40);
  REQUIRE(e20 < 1.08e-2); // measured 8.89e-3 (explicit step: 8.78e-3)
  REQUIRE(e40 < 2.6e-3);  // measured 2.16e-3
  REQUIRE(e40 < 0.3 * e20);
}

TEST_CASE("dynamical fluidity: explicit and implicit steps agree below the explicit limit; implicit stable 15x above it", "[verification][dynamic]") {
  Config c = chute(20, MaterialKind::Dynamic);
  c.set_scene_param("-chute_prestress", 1);
  c.gravity_ramp = 0;
  c.t_end = 0.3;
  c.dt = 5e-5; // explicit diffusion limit 1.1e-4, local limit ~2.9e-4
  std::vector<std::vector<double>> prof;
  for (auto fs : {FluidityStepKind::Explicit, FluidityStepKind::Implicit}) {
    c.fluidity_step = fs;
    gmtest::run_scene<2>(1, c);
    prof.push_back(gmtest::read_profile(c.output_dir));
  }
  double e2 = 0, r2 = 0;
  for (size_t i = 0; i < prof[0].size(); ++i) {
    e2 += std::pow(prof[0][i] - prof[1][i], 2);
    r2 += prof[0][i] * prof[0][i];
  }
  const double d = bcast(gmtest::world_rank() == 0 ? std::sqrt(e2 / r2) : 0.0);
  INFO("relative L2 difference explicit vs implicit at dt = 5e-5: " << d);
  REQUIRE(d < 3e-4); // measured 2.0e-4: the implicit step's O(theta h^2) difference
  // t0 = 5e-6: explicit diffusion limit 5.4e-6 s; the automatic (CFL) step is 8.3e-5 s.
  Config f = chute(20, MaterialKind::Dynamic);
  f.t0 = 5e-6;
  const double e = gmtest::run_scene<2>(1, f).at("l2_rel");
  INFO("implicit step 15x above the explicit limit: relative error " << e);
  REQUIRE(e < 1.2e-2); // measured 9.67e-3 (8.78e-3 at t0 = 1e-4)
}

TEST_CASE("3D chute, periodic in z, reproduces the 2D plane-strain run: dynamical NGF and Drucker-Prager", "[verification][dynamic]") {
  // Plane strain is the 3D problem with no z motion; the 3D kernels (Hencky/Mandel with full
  // 3x3 tensors, the 3D grid Laplacian, the Drucker-Prager cone) must give the 2D profile.
  // Measured at t = 0.3 s: max |v3 - v2| / max |v2| = 5.1e-9 (dynamical; implicit fluidity
  // solves to rtol 1e-10) and 0 (Drucker-Prager).
  for (MaterialKind m : {MaterialKind::Dynamic, MaterialKind::DruckerPrager}) {
    Config c2 = chute(20, m);
    c2.set_scene_param("-chute_prestress", 1);
    c2.gravity_ramp = 0;
    c2.t_end = 0.1;
    Config c3 = c2;
    c3.dim = 3;
    c3.cells = {20, 4, 4};
    c3.lo = {c2.lo[0], c2.lo[1], 0};
    c3.hi = {c2.hi[0], c2.hi[1], c2.hi[1] - c2.lo[1]};
    c3.gravity = {0, c2.gravity[1], 0};
    c3.output_dir = gmtest::outdir("chute3d");
    gmtest::run_scene<2>(1, c2);
    gmtest::run_scene<3>(1, c3);
    const std::vector<double> v[2] = {gmtest::read_profile(c2.output_dir), gmtest::read_profile(c3.output_dir)};
    double d = 0, vmax = 0;
    if (gmtest::world_rank() == 0) {
      REQUIRE(v[0].size() == v[1].size());
      for (size_t i = 0; i < v[0].size(); ++i) {
        vmax = std::max(vmax, std::fabs(v[0][i]));
        d = std::max(d, std::fabs(v[1][i] - v[0][i]));
      }
    }
    d = bcast(d);
    vmax = bcast(vmax);
    INFO(to_string(m) << ": max |v3 - v2| = " << d << ", max |v2| = " << vmax);
    REQUIRE(vmax > 1e-3); // it flows
    REQUIRE(d < 1e-6 * vmax);
  }
}
