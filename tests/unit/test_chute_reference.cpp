// The chute references themselves: the local profile against its closed form at the
// plug, the nonlocal finite-difference solve against its own grid convergence and its
// A -> 0 limit.
#include <catch2/catch.hpp>

#include <cmath>

#include "granmpm/chute_reference.hpp"

using namespace granmpm;

TEST_CASE("local chute profile: plug speed of seed 000 and shape", "[reference]") {
  ChuteParams c;
  // Plug speed from model.md: about 0.0197 m/s for the Table 4.1 parameters.
  REQUIRE(chute_local_speed(c, 0.0) == Approx(0.019655).epsilon(1e-3));
  REQUIRE(chute_local_speed(c, 0.5) == 0.0);
  // Plug: constant for |s| < x_c = mu_s p0/(rho g).
  const double xc = c.gp.mu_s * c.p0 / (c.rho * c.g);
  REQUIRE(chute_local_speed(c, 0.99 * xc) == chute_local_speed(c, 0.0));
  // Slope in the flowing zone equals the local law: |dv/ds| = sqrt(p0/(rho_s d^2))(mu - mu_s)/b.
  const double s = 0.4, ds = 1e-6;
  const double slope = (chute_local_speed(c, s - ds) - chute_local_speed(c, s + ds)) / (2 * ds);
  const double mu = c.rho * c.g * s / c.p0;
  REQUIRE(slope == Approx(std::sqrt(c.p0 / (c.gp.rho_s * c.gp.d * c.gp.d)) * (mu - c.gp.mu_s) / c.gp.b).epsilon(1e-6));
}

TEST_CASE("nonlocal chute reference converges at second order", "[reference]") {
  ChuteParams c;
  const NonlocalChuteReference fine(c, 256001);
  // The coefficients have a kink at mu = mu_s, so the error constant depends on where the
  // kink falls between grid points and successive halvings are irregular (orders 0.7-2.9
  // measured); over a factor 16 in spacing the order is 2.
  auto err = [&](int n) {
    const NonlocalChuteReference r(c, n);
    double e = 0;
    for (double s = 0; s <= 0.5; s += 0.001) e = std::max(e, std::fabs(r.speed(s) - fine.speed(s)));
    return e;
  };
  const double order = 0.5 * (std::log(err(251) / err(4001)) + std::log(err(501) / err(8001))) / std::log(16.0);
  REQUIRE(order == Approx(2.0).margin(0.25));
  // 5001 points (what the runs use) is within 1e-7 relative of the converged profile.
  const NonlocalChuteReference r(c, 5001);
  REQUIRE(std::fabs(r.speed(0) - fine.speed(0)) < 1e-7 * fine.speed(0));
  // Plug speed of seed 000's public code: about 0.0211 m/s.
  REQUIRE(r.speed(0.0) == Approx(0.0211).epsilon(3e-3));
}

TEST_CASE("nonlocal chute reference tends to the local profile as A -> 0", "[reference]") {
  ChuteParams c;
  double prev = 1e9;
  for (double A : {0.48, 0.1, 0.02, 0.004}) {
    c.gp.A = A;
    const NonlocalChuteReference r(c, 20001);
    double e = 0;
    for (double s = 0; s <= 0.5; s += 0.005) e = std::max(e, std::fabs(r.speed(s) - chute_local_speed(c, s)));
    REQUIRE(e < prev);
    prev = e;
  }
  REQUIRE(prev < 2e-3 * chute_local_speed(c, 0));
  // The nonlocal model is faster than the local one for the seed's parameters (fig. A-3).
  c.gp.A = 0.48;
  REQUIRE(NonlocalChuteReference(c).speed(0) > chute_local_speed(c, 0));
}
