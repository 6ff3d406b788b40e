// Constitutive kernels against hand-computed single-particle cases.
#include <catch2/catch.hpp>

#include "granmpm/materials/drucker_prager.hpp"
#include "granmpm/materials/elastic.hpp"
#include "granmpm/materials/local_mu_i.hpp"
#include "granmpm/materials/nonlocal_ngf.hpp"

using namespace granmpm;

namespace {
Mat3 shear_L(double gdot) {
  Mat3 L = Mat3::Zero();
  L(0, 1) = gdot; // v_x = gdot y: D_xy = gdot/2, W_xy = gdot/2
  return L;
}
Mat3 iso(double p) { return -p * Mat3::Identity(); }
} // namespace

TEST_CASE("elastic moduli and uniaxial strain increment", "[materials]") {
  const ElasticModuli el = ElasticModuli::from_E_nu(1e8, 0.3);
  REQUIRE(el.K == Approx(1e8 / (3 * 0.4)));
  REQUIRE(el.G == Approx(1e8 / 2.6));
  REQUIRE(el.p_wave() == Approx(1e8 * 0.7 / (1.3 * 0.4))); // E(1-nu)/((1+nu)(1-2nu))
  LinearElastic m{el};
  Mat3 s = Mat3::Zero(), L = Mat3::Zero();
  L(0, 0) = 1e-3;
  m.update(s, L, 0.5);
  REQUIRE(s(0, 0) == Approx(el.p_wave() * 5e-4));
  REQUIRE(s(1, 1) == Approx(el.lambda * 5e-4));
  REQUIRE(s(2, 2) == Approx(el.lambda * 5e-4)); // plane strain keeps sigma_zz
  REQUIRE(s(0, 1) == 0.0);
}

TEST_CASE("Jaumann rate: a rigid rotation leaves the stress invariants unchanged to O(dt^2)", "[materials]") {
  const ElasticModuli el = ElasticModuli::from_E_nu(1e6, 0.25);
  Hypoelastic m{el};
  Mat3 s;
  s << -100, 30, 0, 30, -50, 0, 0, 0, -70;
  const double p0 = pressure(s), t0 = tau_of(s);
  Mat3 W = Mat3::Zero();
  W(0, 1) = 0.3;
  W(1, 0) = -0.3;
  const int n = 1000;
  const double dt = 1e-3;
  for (int k = 0; k < n; ++k) m.update(s, W, dt);
  REQUIRE(pressure(s) == Approx(p0).epsilon(1e-12));
  REQUIRE(tau_of(s) == Approx(t0).epsilon(2e-3)); // forward Euler on the spin: O(W^2 dt t)
  REQUIRE(s(0, 1) != Approx(30.0));               // but the stress did rotate
}

TEST_CASE("local mu(I), implicit update (Algorithm 1): tau_{n+1} = tau_tr - G dt gdot exactly", "[materials]") {
  GranularParams gp;
  const ElasticModuli el = ElasticModuli::from_E_nu(1e8, 0.3);
  LocalMuI m{el, gp, StressUpdate::Implicit};
  const double p = 900, dt = 1e-5, rate = 5.0;
  // Start just below yield: tau_n = 0.37 p, sigma_xy only.
  Mat3 s = iso(p);
  s(0, 1) = s(1, 0) = 0.37 * p;
  const Mat3 L = shear_L(rate);
  // Hand computation of the trial state: D_xy = rate/2 adds 2 G D dt to sigma_xy;
  // the Jaumann term adds (sigma_yy - sigma_xx) W_xy dt = 0 for an isotropic normal part,
  // and 2 W sigma_xy dt to the normal components (equal and opposite).
  const double sxy_tr = 0.37 * p + el.G * rate * dt;
  const double w = 0.5 * rate, dn = 2 * w * 0.37 * p * dt;
  const double sxx_tr = -p + dn, syy_tr = -p - dn;
  const double tau_tr = std::sqrt(sxy_tr * sxy_tr + dn * dn);
  const double eta = gp.b * gp.d * std::sqrt(gp.rho_s * p);
  const double gdot = (tau_tr - gp.mu_s * p) / (eta + el.G * dt);
  REQUIRE(tau_tr > gp.mu_s * p);
  const double gd = m.update(s, L, dt, 1500);
  REQUIRE(gd == Approx(gdot).epsilon(1e-12));
  REQUIRE(tau_of(s) == Approx(tau_tr - el.G * dt * gdot).epsilon(1e-12));
  REQUIRE(pressure(s) == Approx(p).epsilon(1e-14));
  // The return is radial: the deviator keeps the direction of the trial deviator.
  REQUIRE(s(0, 1) / (s(0, 0) + p) == Approx(sxy_tr / (sxx_tr + p)).epsilon(1e-10));
  REQUIRE(syy_tr == Approx(-p - dn));
}

TEST_CASE("local mu(I), explicit update (Algorithm 3) uses the stress at the start of the step", "[materials]") {
  GranularParams gp;
  const ElasticModuli el = ElasticModuli::from_E_nu(1e8, 0.3);
  LocalMuI m{el, gp, StressUpdate::Explicit};
  const double p = 900, dt = 1e-6;
  Mat3 s = iso(p);
  s(0, 1) = s(1, 0) = 0.5 * p; // flowing: mu = 0.5 > mu_s
  const double gdot_n = std::sqrt(p / (gp.rho_s * gp.d * gp.d)) * (0.5 - gp.mu_s) / gp.b;
  Mat3 L = Mat3::Zero(); // no deformation: pure relaxation
  const double gd = m.update(s, L, dt, 1500);
  REQUIRE(gd == Approx(gdot_n).epsilon(1e-12));
  REQUIRE(tau_of(s) == Approx(0.5 * p - el.G * dt * gdot_n).epsilon(1e-12));
}

TEST_CASE("granular models: below mu_s elastic, tension stress-free, low density stress-free", "[materials]") {
  GranularParams gp;
  gp.rho_c = 1400;
  const ElasticModuli el = ElasticModuli::from_E_nu(1e8, 0.3);
  LocalMuI m{el, gp, StressUpdate::Implicit};
  Mat3 s = iso(900);
  s(0, 1) = s(1, 0) = 0.2 * 900;
  Mat3 e = s;
  Hypoelastic h{el};
  const Mat3 L = shear_L(1.0);
  h.update(e, L, 1e-7);
  REQUIRE(m.update(s, L, 1e-7, 1500) == 0.0);
  REQUIRE((s - e).norm() < 1e-9);
  // Extension into tension: p <= 0 after the trial step -> zero stress.
  Mat3 t = iso(1.0);
  Mat3 Lx = Mat3::Zero();
  Lx(0, 0) = Lx(1, 1) = 1.0;
  m.update(t, Lx, 1e-3, 1500);
  REQUIRE(t.norm() == 0.0);
  // Density below rho_c -> zero stress.
  Mat3 u = iso(900);
  m.update(u, Mat3::Zero(), 1e-6, 1300);
  REQUIRE(u.norm() == 0.0);
}

TEST_CASE("nonlocal: fluidity source and the implicit return tau = tau_tr p/(p + G dt g)", "[materials]") {
  GranularParams gp;
  const ElasticModuli el = ElasticModuli::from_E_nu(1e8, 0.3);
  const double p = 900;
  Mat3 s = iso(p);
  s(0, 1) = s(1, 0) = 0.6 * p;
  const FluiditySource src = fluidity_source(gp, s);
  REQUIRE(src.weight == Approx(0.6 - gp.mu_s));
  REQUIRE(src.g_loc == Approx(std::sqrt(p / (gp.rho_s * gp.d * gp.d)) * (0.6 - gp.mu_s) / (gp.b * 0.6)));
  Mat3 s2 = iso(p);
  s2(0, 1) = s2(1, 0) = 0.2 * p;
  REQUIRE(fluidity_source(gp, s2).g_loc == 0.0);
  REQUIRE(fluidity_source(gp, s2).weight == Approx(gp.mu_s - 0.2));
  REQUIRE(fluidity_source(gp, Mat3::Zero()).g_loc == 0.0);

  NonlocalNGF m{el, gp, StressUpdate::Implicit};
  const double g = 0.3, dt = 2e-5;
  Mat3 a = s;
  const double gd = m.update(a, Mat3::Zero(), dt, 1500, g);
  const double tau = 0.6 * p * p / (p + el.G * dt * g);
  REQUIRE(tau_of(a) == Approx(tau).epsilon(1e-12));
  REQUIRE(gd == Approx(g * tau / p).epsilon(1e-12)); // gdot = mu_{n+1} g
  NonlocalNGF me{el, gp, StressUpdate::Explicit};
  Mat3 b = s;
  const double gde = me.update(b, Mat3::Zero(), 1e-7, 1500, g);
  REQUIRE(gde == Approx(0.6 * g).epsilon(1e-12)); // gdot = mu_n g
}

TEST_CASE("granular corner cases: p -> 0, tau = 0, mu exactly mu_s give finite stresses for mu(I), nonlocal and Drucker-Prager", "[materials]") {
  GranularParams gp;
  const ElasticModuli el = ElasticModuli::from_E_nu(1e8, 0.3);
  const LocalMuI mi{el, gp, StressUpdate::Implicit}, me{el, gp, StressUpdate::Explicit};
  const NonlocalNGF ni{el, gp, StressUpdate::Implicit}, ne{el, gp, StressUpdate::Explicit};
  const DruckerPrager dp{el, 30.0 * 3.14159265358979323846 / 180.0, 0.0, 0.0};
  auto finite = [](const Mat3 &s, double r) { return s.allFinite() && std::isfinite(r); };
  auto all_models = [&](Mat3 s0, const Mat3 &L, double dt, double g, auto &&check) {
    Mat3 s = s0;
    double r = mi.update(s, L, dt, 1500);
    check(s, r);
    s = s0;
    r = me.update(s, L, dt, 1500);
    check(s, r);
    s = s0;
    r = ni.update(s, L, dt, 1500, g);
    check(s, r);
    s = s0;
    r = ne.update(s, L, dt, 1500, g);
    check(s, r);
    s = s0;
    r = dp.update(s, L, dt, 1500);
    check(s, r);
  };
  // Tiny and denormal pressures with a deviator at mu = 0.5 > mu_s, under shear.
  for (double p : {1e-12, 1e-300, 4.9e-324}) {
    Mat3 s0 = iso(p);
    s0(0, 1) = s0(1, 0) = 0.5 * p;
    all_models(s0, shear_L(1.0), 1e-6, 10.0, [&](const Mat3 &s, double r) { REQUIRE(finite(s, r)); });
    all_models(s0, Mat3::Zero(), 1e-6, 0.0, [&](const Mat3 &s, double r) { REQUIRE(finite(s, r)); });
  }
  // tau = 0: an isotropic state without deformation stays exactly where it is, no flow.
  all_models(iso(900), Mat3::Zero(), 1e-5, 0.0, [&](const Mat3 &s, double r) {
    REQUIRE(finite(s, r));
    REQUIRE((s - iso(900)).norm() < 1e-9 * 900);
    REQUIRE(r == 0.0);
  });
  // mu exactly mu_s (the yield point of the local models), no deformation: finite, no flow
  // for the local models (the nonlocal one flows at its given g, tested above).
  Mat3 s0 = iso(900);
  s0(0, 1) = s0(1, 0) = gp.mu_s * 900;
  Mat3 s = s0;
  REQUIRE(mi.update(s, Mat3::Zero(), 1e-5, 1500) == 0.0);
  REQUIRE((s - s0).norm() < 1e-9 * 900);
  s = s0;
  // The explicit update evaluates mu = tau/p of the stored stress, which is mu_s only to
  // round-off: a flow rate at round-off level (measured 1.5e-17 1/s) is allowed.
  const double r_e = me.update(s, Mat3::Zero(), 1e-5, 1500);
  REQUIRE(std::fabs(r_e) < 1e-12);
  REQUIRE((s - s0).norm() < 1e-9 * 900);
  s = s0;
  const double r = ni.update(s, Mat3::Zero(), 1e-5, 1500, 0.0); // g = 0 at mu = mu_s
  REQUIRE(finite(s, r));
  REQUIRE(r == 0.0);
}
