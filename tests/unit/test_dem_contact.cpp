// DEM contact kernels (include/granmpm/dem/contact.hpp) against closed forms: the seed's
// damping formula, the no-attraction restitution, exact action-reaction, the Coulomb cap,
// Hertz's force law and the rolling torque.
#include <catch2/catch.hpp>

#include <cmath>

#include "granmpm/dem/contact.hpp"

using namespace granmpm::dem;

namespace {
// Closed-form restitution of the underdamped no-attraction linear contact (zeta < 1).
double ec_closed(double z) {
  const double w = std::sqrt(1 - z * z), th = M_PI - std::atan2(2 * z * w, 1 - 2 * z * z);
  return -std::exp(-z * th / w) * (std::cos(th) - z / w * std::sin(th));
}
} // namespace

TEST_CASE("DEM damping: the seed's gamma_n(e) with the mean mass is the effective-mass form", "[dem]") {
  for (double e : {0.1, 0.5, 0.9}) {
    const double k = 1e5, m = 0.3; // two grains of mass m: m_eff = m/2
    const double seed = std::sqrt(m * k) * (-2 * std::log(e)) / std::sqrt(2 * (M_PI * M_PI + std::log(e) * std::log(e)));
    CHECK(gamma_from_e(e, k, 0.5 * m) == Approx(seed).epsilon(1e-14));
    ContactParams p;
    p.e = e;
    p.damping = Damping::Seed;
    p.finalize();
    CHECK(p.damp * std::sqrt(k * 0.5 * m) == Approx(seed).epsilon(1e-14));
  }
}

TEST_CASE("DEM damping: the calibrated gamma_n restitutes e without attraction", "[dem]") {
  for (double e : {0.1, 0.3, 0.5, 0.9, 0.99}) {
    ContactParams p;
    p.e = e;
    p.finalize();
    CHECK(clamped_restitution(0.5 * p.damp, nullptr) == Approx(e).epsilon(1e-9));
  }
  // The RK4 reference against the closed form where one exists.
  for (double z : {0.05, 0.3, 0.6, 0.9}) CHECK(clamped_restitution(z, nullptr) == Approx(ec_closed(z)).epsilon(1e-9));
  ContactParams one;
  one.e = 1.0;
  one.finalize();
  CHECK(one.damp == 0.0);
}

TEST_CASE("DEM contact: swapping the grains negates the force exactly", "[dem]") {
  ContactParams p;
  p.mu = 0.4;
  p.mu_roll = 0.1;
  p.finalize();
  const V3 xi{0.1, 0.2, 0.3}, xj{0.1 + 0.017, 0.2 - 0.011, 0.3 + 0.004};
  const double ri = 0.011, rj = 0.0097;
  const V3 vi{0.3, -0.2, 0.1}, vj{-0.1, 0.05, 0.2}, wi{3, -1, 2}, wj{-2, 4, 1};
  V3 hi{1e-5, -2e-6, 3e-6}, hj = -hi;
  for (int s = 0; s < 5; ++s) {
    const ContactResult a = contact(p, xj - xi, ri, rj, vi - vj, wi, wj, 0.01, 1e-6, hi, 1e-5);
    const ContactResult b = contact(p, xi - xj, rj, ri, vj - vi, wj, wi, 0.01, 1e-6, hj, 1e-5);
    CHECK(a.fn > 0);
    CHECK(a.force.x == -b.force.x);
    CHECK(a.force.y == -b.force.y);
    CHECK(a.force.z == -b.force.z);
    CHECK(hi.x == -hj.x);
    CHECK(hi.z == -hj.z);
    CHECK(a.troll.y == -b.troll.y);
    // Torques from the same tangential force at the two contact arms.
    CHECK(a.torque.x / ri == Approx(b.torque.x / rj).epsilon(1e-12));
  }
}

TEST_CASE("DEM contact: Coulomb cap, no attraction, Hertz, rolling torque", "[dem]") {
  ContactParams p;
  p.mu = 0.3;
  p.e = 0.5;
  p.finalize();
  const double r = 0.01, m = 0.01;
  // Fast sliding on a wall: |f_t| = mu f_n and the spring matches the capped force.
  V3 h{};
  const ContactResult s = contact(p, {0, -0.0099, 0}, r, 0, {2.0, -0.1, 0}, {}, {}, m, 1e-7, h, 1e-5);
  const V3 ft = s.force - dot(s.force, V3{0, -1, 0}) * V3{0, -1, 0};
  CHECK(norm(ft) == Approx(p.mu * s.fn).epsilon(1e-12));
  CHECK(ft.x < 0);
  // Separating faster than the spring pushes: no pull.
  V3 h2{};
  const ContactResult t = contact(p, {0, -0.00999, 0}, r, 0, {0, 50.0, 0}, {}, {}, m, 1e-7, h2, 1e-5);
  CHECK(t.fn == 0.0);
  CHECK(norm(t.force) == 0.0);
  // Hertz, elastic: F = k_n sqrt(R delta) delta.
  ContactParams hz;
  hz.law = Law::Hertz;
  hz.e = 1.0;
  hz.kn = 1e6;
  hz.finalize();
  V3 h3{};
  const double delta = 2e-4;
  const ContactResult q = contact(hz, {0, -(r - delta), 0}, r, 0, {}, {}, {}, m, 1e-7, h3, 1e-5);
  CHECK(q.fn == Approx(hz.kn * std::sqrt(r * delta) * delta).epsilon(1e-12));
  // Rolling: mu_r R f_n against the spin, capped by what stops the spin in one step.
  ContactParams rr = p;
  rr.mu_roll = 0.05;
  V3 h4{};
  const ContactResult fast = contact(rr, {0, -0.0099, 0}, r, 0, {}, {0, 0, 100.0}, {}, m, 1e-7, h4, 1e-5);
  CHECK(fast.troll.z == Approx(-rr.mu_roll * r * fast.fn).epsilon(1e-12));
  V3 h5{};
  const ContactResult slow = contact(rr, {0, -0.0099, 0}, r, 0, {}, {0, 0, 1e-6}, {}, m, 1e-7, h5, 1e-5);
  CHECK(slow.troll.z == Approx(-1e-7 * 1e-6 / 1e-5).epsilon(1e-12));
}
