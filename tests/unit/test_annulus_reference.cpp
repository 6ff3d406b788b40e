// The annular-shear references: boundary conditions met, the local solution's shear band
// ends at the yield radius, the nonlocal finite-difference solve converges at second
// order and tends to the local solution as A -> 0.
#include <catch2/catch.hpp>

#include <cmath>

#include "granmpm/annulus_reference.hpp"

using namespace granmpm;

namespace {
AnnulusParams params(double A) {
  AnnulusParams a; // Ri 0.2, Ro 0.4, Omega 0.1, p 900 and the chute's granular parameters
  a.gp.A = A;
  return a;
}
} // namespace

TEST_CASE("annulus references meet the boundary conditions", "[reference]") {
  for (bool local : {true, false}) {
    const AnnulusParams a = params(0.48);
    const AnnulusReference R(a, local, 2001);
    INFO("local " << local << " T " << R.T());
    REQUIRE(R.omega(a.Ri) == Approx(a.Omega).epsilon(1e-10));
    REQUIRE(R.omega(a.Ro) == Approx(0.0).margin(1e-14));
    REQUIRE(R.T() > 0);
    // Monotonic: the angular velocity falls from the inner to the outer wall.
    for (size_t i = 1; i < R.r().size(); ++i) REQUIRE(R.w()[i] <= R.w()[i - 1]);
  }
  // Odd in Omega.
  AnnulusParams m = params(0.48);
  m.Omega = -0.1;
  const AnnulusReference N(m, false), P(params(0.48), false);
  REQUIRE(N.v_theta(0.25) == Approx(-P.v_theta(0.25)));
  REQUIRE(N.T() == Approx(-P.T()));
}

TEST_CASE("local annulus solution: the shear band ends at the yield radius tau = mu_s p", "[reference]") {
  const AnnulusParams a = params(0.48);
  const AnnulusReference R(a, true);
  const double ry = R.yield_radius();
  REQUIRE(ry > a.Ri);
  REQUIRE(ry < a.Ro); // these parameters leave an unsheared outer layer
  // tau(r_y) = T / r_y^2 = mu_s p
  REQUIRE(R.T() / (ry * ry) == Approx(a.gp.mu_s * a.p).epsilon(1e-12));
  REQUIRE(R.omega(ry * (1 + 1e-9)) == 0.0);
  REQUIRE(R.omega(ry * 0.99) > 0.0);
  REQUIRE(R.gdot(ry * 1.01) == 0.0);
  // Inside the band: dw/dr = -gdot/r with gdot the local law at mu = T/(p r^2).
  const double r = 0.23, e = 1e-6;
  const double dw = (R.omega(r + e) - R.omega(r - e)) / (2 * e);
  const double mu = R.T() / (a.p * r * r);
  const double gdot = std::sqrt(a.p / a.gp.rho_s) * (mu - a.gp.mu_s) / (a.gp.b * a.gp.d);
  REQUIRE(dw == Approx(-gdot / r).epsilon(1e-6));
}

TEST_CASE("nonlocal annulus reference with g = 0 at the walls: the condition holds, w(Ri) = Omega, and the torque rises", "[reference]") {
  AnnulusParams a = params(0.48);
  const AnnulusReference flux(a, false, 2001);
  a.zero_g_walls = true;
  const AnnulusReference R(a, false, 2001);
  INFO("T zero flux " << flux.T() << ", T with g = 0 " << R.T());
  REQUIRE(R.g().front() == 0.0);
  REQUIRE(R.g().back() == 0.0);
  REQUIRE(R.omega(a.Ri) == Approx(a.Omega).epsilon(1e-10));
  REQUIRE(R.omega(a.Ro) == Approx(0.0).margin(1e-14));
  // Less fluidity at the walls: a larger torque is needed for the same Omega.
  REQUIRE(R.T() > flux.T());
}

TEST_CASE("nonlocal annulus reference: second-order grid convergence", "[reference]") {
  for (bool zero : {false, true}) {
  AnnulusParams a = params(0.48);
  a.zero_g_walls = zero; // zero flux or g = 0 at the walls
  const AnnulusReference fine(a, false, 32001);
  double e[3];
  const int ns[3] = {501, 1001, 2001};
  for (int k = 0; k < 3; ++k) {
    const AnnulusReference R(a, false, ns[k]);
    double m = std::fabs(R.T() - fine.T()) / fine.T();
    for (double r = a.Ri; r <= a.Ro; r += 0.01) m = std::max(m, std::fabs(R.v_theta(r) - fine.v_theta(r)) / (a.Omega * a.Ri));
    e[k] = m;
  }
  INFO("g = 0 at the walls " << zero << ": errors " << e[0] << " " << e[1] << " " << e[2]);
  REQUIRE(std::log2(e[0] / e[1]) > 1.8);
  REQUIRE(std::log2(e[1] / e[2]) > 1.8);
  REQUIRE(e[2] < 1e-5);
  }
}

TEST_CASE("nonlocal annulus reference tends to the local solution as A -> 0", "[reference]") {
  const AnnulusReference L(params(0.48), true);
  double prev = 1e300;
  for (double A : {0.1, 0.01, 0.001}) {
    const AnnulusParams a = params(A);
    const AnnulusReference N(a, false, 4001);
    double m = 0;
    for (double r = a.Ri; r <= a.Ro; r += 0.005) m = std::max(m, std::fabs(N.v_theta(r) - L.v_theta(r)) / (a.Omega * a.Ri));
    INFO("A " << A << ": max |v_nonlocal - v_local| / (Omega Ri) = " << m);
    REQUIRE(m < prev);
    prev = m;
  }
  REQUIRE(prev < 2e-3);
  // A = 0 exactly: the nonlocal solve is the local law (up to the trapezoidal rule).
  const AnnulusReference Z(params(0.0), false, 4001);
  REQUIRE(Z.T() == Approx(L.T()).epsilon(1e-5));
}
