// Rate-independent Drucker-Prager kernel (seed 000 appendix B) against hand-computed
// cone parameters, exact return identities and the Hypoelastic (Jaumann) elastic step.
#include <catch2/catch.hpp>

#include "granmpm/materials/drucker_prager.hpp"

#include <cmath>

using namespace granmpm;

namespace {
const double kPi = 3.14159265358979323846;
// Seed 000 appendix B: phi = 30 deg, E = 1e8 Pa (OCR "108"), nu = 0.3, small cohesion.
DruckerPrager seed_dp(double c = 10.0, double rho_c = 0.0) {
  return DruckerPrager{ElasticModuli::from_E_nu(1e8, 0.3), 30.0 * kPi / 180.0, c, rho_c};
}
Mat3 shear_L(double rate) {
  Mat3 L = Mat3::Zero();
  L(0, 1) = rate;
  return L;
}
Mat3 iso(double p) { return -p * Mat3::Identity(); }
Mat3 diag(double a, double b, double c) { return Vec3(a, b, c).asDiagonal(); }
} // namespace

TEST_CASE("Drucker-Prager: cone parameters match Mohr-Coulomb on the chosen meridian", "[drucker_prager]") {
  DruckerPrager dp = seed_dp(100.0);
  const double s = 0.5, c30 = std::sqrt(3.0) / 2, c = 100.0;
  // Plane strain (default): alpha = sin phi, k = c cos phi.
  REQUIRE(dp.alpha() == Approx(0.5).epsilon(1e-15));
  REQUIRE(dp.k() == Approx(c * c30).epsilon(1e-15));
  dp.match = DPMatch::Compression;
  REQUIRE(dp.alpha() == Approx(2 * std::sqrt(3.0) * s / (3 - s)).epsilon(1e-15)); // 0.6928
  REQUIRE(dp.k() == Approx(2 * std::sqrt(3.0) * c * c30 / (3 - s)).epsilon(1e-15));
  dp.match = DPMatch::Extension;
  REQUIRE(dp.alpha() == Approx(2 * std::sqrt(3.0) * s / (3 + s)).epsilon(1e-15));

  // Mohr-Coulomb failure states (compression positive, s1 >= s2 >= s3 principal pressures):
  // s1 + h = (s3 + h)(1 + sin)/(1 - sin), h = c cot(phi). Each must lie on its cone.
  const double h = c * c30 / s, s3 = 1000, s1 = (s3 + h) * (1 + s) / (1 - s) - h;
  auto on_cone = [&](DPMatch m, const Mat3 &sigma) {
    DruckerPrager d = seed_dp(c);
    d.match = m;
    return tau_of(sigma) / d.yield_tau(pressure(sigma));
  };
  // Triaxial compression s2 = s3 (tension-positive sigma = -s).
  REQUIRE(on_cone(DPMatch::Compression, diag(-s1, -s3, -s3)) == Approx(1.0).epsilon(1e-13));
  // Triaxial extension s2 = s1.
  REQUIRE(on_cone(DPMatch::Extension, diag(-s1, -s1, -s3)) == Approx(1.0).epsilon(1e-13));
  // Plane strain with the flow rule's s_zz = 0: s2 = (s1 + s3)/2.
  REQUIRE(on_cone(DPMatch::PlaneStrain, diag(-s1, -s3, -(s1 + s3) / 2)) == Approx(1.0).epsilon(1e-13));
}

TEST_CASE("Drucker-Prager: elastic steps are the Hypoelastic Jaumann step", "[drucker_prager]") {
  const DruckerPrager dp = seed_dp();
  const Hypoelastic h{dp.el};
  Mat3 s = iso(1e4);
  s(0, 1) = s(1, 0) = 2e3; // tau/p = 0.2 < alpha = 0.5
  s(1, 2) = s(2, 1) = -1e3;
  Mat3 e = s;
  Mat3 L;
  L << -0.3, 1.0, 0.2, -0.4, 0.1, 0.0, 0.3, -0.2, -0.1;
  for (int i = 0; i < 100; ++i) {
    REQUIRE(dp.update(s, L, 1e-6, 1500) == 0.0);
    h.update(e, L, 1e-6);
  }
  REQUIRE((s - e).norm() == 0.0); // same arithmetic
  REQUIRE(tau_of(s) < dp.yield_tau(pressure(s)));
}

TEST_CASE("Drucker-Prager: a plastic step returns onto the cone at fixed pressure", "[drucker_prager]") {
  for (DPMatch m : {DPMatch::PlaneStrain, DPMatch::Compression}) {
    DruckerPrager dp = seed_dp(50.0);
    dp.match = m;
    const double p = 1e4, dt = 1e-5;
    Mat3 s = iso(p);
    s(0, 1) = s(1, 0) = 0.99 * dp.yield_tau(p);
    s(0, 0) += 300;
    s(1, 1) -= 300;
    Mat3 L = shear_L(20.0);
    L(1, 0) = -3.0;
    L(2, 2) = 0.5; // with a volume change: the trial pressure differs from p
    Mat3 tr = s;
    Hypoelastic{dp.el}.update(tr, L, dt);
    const double p_tr = pressure(tr), tau_tr = tau_of(tr), tau_y = dp.yield_tau(p_tr);
    REQUIRE(tau_tr > tau_y);
    const double gd = dp.update(s, L, dt, 1500);
    REQUIRE(tau_of(s) == Approx(tau_y).epsilon(1e-13)); // on the yield surface
    REQUIRE(pressure(s) == Approx(p_tr).epsilon(1e-14)); // deviatoric return
    REQUIRE(gd == Approx((tau_tr - tau_y) / (dp.el.G * dt)).epsilon(1e-12));
    // Radial: the deviator keeps the trial direction.
    REQUIRE((deviator(s) * (tau_tr / tau_y) - deviator(tr)).norm() < 1e-12 * deviator(tr).norm());
    REQUIRE((s - s.transpose()).norm() == 0.0);
  }
}

TEST_CASE("Drucker-Prager: tension, the apex and low density are stress-free", "[drucker_prager]") {
  const DruckerPrager dp = seed_dp(10.0, 1400.0);
  // Isotropic extension into tension.
  Mat3 s = iso(100);
  const Mat3 Lx = Mat3::Identity();
  REQUIRE(dp.update(s, Lx, 1e-3, 1500) == 0.0);
  REQUIRE(s.norm() == 0.0);
  // Exactly zero pressure with a deviator: stress-free (the tension cut-off at p = 0 lies
  // in front of the apex p = -k/alpha < 0).
  Mat3 z = Mat3::Zero();
  z(0, 1) = z(1, 0) = 5.0;
  REQUIRE(dp.update(z, Mat3::Zero(), 1e-6, 1500) == 0.0);
  REQUIRE(z.norm() == 0.0);
  // Small positive pressure, large shear: returns to tau = alpha p + k, which the cohesion
  // keeps positive near the apex.
  Mat3 a = iso(1.0);
  a(0, 1) = a(1, 0) = 1e3;
  REQUIRE(dp.update(a, Mat3::Zero(), 1e-6, 1500) > 0.0);
  REQUIRE(pressure(a) == Approx(1.0).epsilon(1e-14));
  REQUIRE(tau_of(a) == Approx(0.5 * 1.0 + 10.0 * std::sqrt(3.0) / 2).epsilon(1e-13));
  // Below the critical density: stress-free under compression too.
  Mat3 u = iso(1e4);
  REQUIRE(dp.update(u, -Mat3::Identity(), 1e-6, 1300) == 0.0);
  REQUIRE(u.norm() == 0.0);
  // Zero stress and zero rate stays zero, no NaN.
  Mat3 o = Mat3::Zero();
  REQUIRE(dp.update(o, Mat3::Zero(), 1e-6, 1500) == 0.0);
  REQUIRE(o.norm() == 0.0);
}

TEST_CASE("Drucker-Prager: constant simple shear reaches and stays at tau = alpha p + k", "[drucker_prager]") {
  const DruckerPrager dp = seed_dp(20.0);
  const double p = 5e3, rate = 1.0, dt = 1e-6;
  Mat3 s = iso(p);
  const Mat3 L = shear_L(rate);
  const double tau_y = dp.yield_tau(p);
  // Elastic phase: sigma_xy = G rate t to O((rate t)^2) (Jaumann normal stresses).
  const int n_y = static_cast<int>(tau_y / (dp.el.G * rate * dt)); // steps to yield
  int first_plastic = -1;
  for (int n = 0; n < 3 * n_y; ++n) {
    const double gd = dp.update(s, L, dt, 1500);
    REQUIRE(pressure(s) == Approx(p).epsilon(1e-12)); // isochoric, spin and return traceless
    if (gd > 0 && first_plastic < 0) first_plastic = n;
    if (first_plastic >= 0) {
      REQUIRE(gd > 0);
      REQUIRE(tau_of(s) == Approx(tau_y).epsilon(1e-13));
    } else {
      REQUIRE(s(0, 1) == Approx(dp.el.G * rate * dt * (n + 1)).epsilon(1e-4));
    }
  }
  REQUIRE(std::abs(first_plastic - n_y) <= 1);
  // In sustained flow the whole shear rate is plastic: gdot_p -> rate (elastic
  // co-rotation terms are O(tau/G) ~ 1e-4).
  REQUIRE(dp.update(s, L, dt, 1500) == Approx(rate).epsilon(1e-3));
}

TEST_CASE("Drucker-Prager: objectivity under rigid rotation", "[drucker_prager]") {
  const DruckerPrager dp = seed_dp(10.0);
  Mat3 W = Mat3::Zero();
  W(0, 1) = 0.3;
  W(1, 0) = -0.3;
  const int n = 1000;
  const double dt = 1e-3;
  // Inside the cone: as the Jaumann test in test_materials.cpp.
  Mat3 s;
  s << -100, 30, 0, 30, -50, 0, 0, 0, -70;
  const double p0 = pressure(s), t0 = tau_of(s);
  for (int k = 0; k < n; ++k) REQUIRE(dp.update(s, W, dt, 1500) == 0.0);
  REQUIRE(pressure(s) == Approx(p0).epsilon(1e-12));
  REQUIRE(tau_of(s) == Approx(t0).epsilon(2e-3));
  // On the cone: the forward-Euler spin grows tau by O((W dt)^2) per step, which the
  // return clips, so the state stays on the cone exactly and p is untouched.
  Mat3 c = iso(1e4);
  c(0, 1) = c(1, 0) = dp.yield_tau(1e4);
  const Mat3 c0 = c;
  for (int k = 0; k < n; ++k) dp.update(c, W, dt, 1500);
  REQUIRE(pressure(c) == Approx(1e4).epsilon(1e-12));
  REQUIRE(tau_of(c) == Approx(dp.yield_tau(1e4)).epsilon(1e-12));
  REQUIRE((c - c0).norm() > 0.1 * dp.yield_tau(1e4)); // it did rotate
  // Change of observer: the same deformation seen in a rotated frame gives the rotated
  // stress (isotropy), through elastic and plastic steps.
  const double th = 0.7;
  Mat3 Q = Mat3::Identity();
  Q(0, 0) = Q(2, 2) = std::cos(th);
  Q(0, 2) = std::sin(th);
  Q(2, 0) = -std::sin(th);
  Mat3 L;
  L << -0.2, 3.0, 0.1, 0.5, 0.1, -0.4, 0.0, 1.0, 0.05;
  Mat3 a = iso(2e3), b = Q * a * Q.transpose();
  const Mat3 Lq = Q * L * Q.transpose();
  double ga = 0, gb = 0;
  for (int k = 0; k < 2000; ++k) {
    ga += dp.update(a, L, 1e-6, 1500);
    gb += dp.update(b, Lq, 1e-6, 1500);
  }
  REQUIRE(ga > 0); // reached the cone
  REQUIRE(gb == Approx(ga).epsilon(1e-9));
  REQUIRE((b - Q * a * Q.transpose()).norm() < 1e-9 * a.norm());
}
