// DEM contact kernels (include/granmpm/dem/contact.hpp) against closed forms: the seed's
// damping formula, the no-attraction restitution, exact action-reaction, the Coulomb cap,
// Hertz's force law and the rolling torque.
#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

#include "granmpm/dem/contact.hpp"
#include "granmpm/dem/quaternion.hpp"

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

// ---- Orientation quaternions (include/granmpm/dem/quaternion.hpp) ----

namespace {
// Rodrigues: b rotated by the angle th about the unit axis n (the closed form).
V3 rodrigues(const V3 &b, const V3 &n, double th) {
  return std::cos(th) * b + std::sin(th) * cross(n, b) + ((1 - std::cos(th)) * dot(n, b)) * n;
}
double dist(const V3 &a, const V3 &b) { return norm(a - b); }
} // namespace

TEST_CASE("DEM orientation: one rotation step is the closed-form rotation", "[dem]") {
  const V3 bs[3] = {{1, 0, 0}, {0.3, -0.8, 0.52}, {0, 0, 1}};
  const V3 axes[3] = {{0, 0, 1}, {0.6, 0.0, 0.8}, {-0.48, 0.6, 0.64}};
  double worst = 0;
  // Angles |w| h from 0 through the series branch (a = |w| h / 2 < 1e-3) and its edge to pi.
  for (double th : {0.0, 1e-12, 1e-7, 1.9e-3, 1.999999e-3, 2.000001e-3, 0.05, 1.0, 3.0})
    for (const V3 &n : axes)
      for (const V3 &b : bs) {
        const double h = 1e-4, wm = th / h;
        const Quat q = rotate(Quat{}, wm * n, h);
        worst = std::max(worst, dist(rotate_vector(q, b), rodrigues(b, n, th)));
        CHECK(std::fabs(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z - 1) < 1e-15);
      }
  INFO("largest difference from Rodrigues " << worst);
  CHECK(worst < 1e-14);
  // Either side of the switch to the series (a = 1e-3), both branches are cos(a), sin(a) to
  // round-off (|w| = 1, so h = 2 a).
  for (double h : {2e-3 * (1 - 1e-9), 2e-3 * (1 + 1e-9), 1e-9}) {
    const Quat r = rotation_step(V3{0, 0, 1}, h);
    CHECK(std::fabs(r.w - std::cos(0.5 * h)) < 2e-16);
    CHECK(std::fabs(r.z - std::sin(0.5 * h)) < 2e-19);
    CHECK(r.x == 0);
  }
}

TEST_CASE("DEM orientation: rotate_all gives rotate's bits for every grain", "[dem]") {
  // Spins from 0 through the series range to beyond it (a = |w| h / 2 up to 0.5), mixed.
  const int n = 64;
  std::vector<Quat> q(n), ref(n);
  std::vector<V3> w(n);
  const double h = 1e-3;
  for (int i = 0; i < n; ++i) {
    const double t = 0.37 * i;
    const double wm = i % 7 == 3 ? 1000.0 * (1 + i % 3) : (i % 5) * 10.0 * std::pow(10.0, i % 3); // a up to 1.5
    w[i] = wm * V3{std::cos(t) * std::sin(1.3 * t), std::sin(t) * std::sin(1.3 * t), std::cos(1.3 * t)};
    q[i] = ref[i] = rotate(Quat{}, V3{std::sin(t), 0.4, std::cos(t)}, 0.7); // some unit quaternion
  }
  for (int s = 0; s < 3; ++s) {
    rotate_all(q.data(), w.data(), n, h);
    for (int i = 0; i < n; ++i) ref[i] = rotate(ref[i], w[i], h);
  }
  int beyond = 0, same = 0;
  for (int i = 0; i < n; ++i) {
    beyond += !(0.25 * h * h * dot(w[i], w[i]) < kSeriesA2);
    same += q[i].w == ref[i].w && q[i].x == ref[i].x && q[i].y == ref[i].y && q[i].z == ref[i].z;
  }
  INFO(beyond << " of " << n << " grains beyond the series' range");
  CHECK(beyond > 3);
  CHECK(beyond < n - 10);
  CHECK(same == n);
}

TEST_CASE("DEM orientation: many steps at a constant spin and composed rotations", "[dem]") {
  // 20000 steps of 0.005 rad about a tilted axis: 100 rad, against one closed-form rotation.
  const V3 n{-0.48, 0.6, 0.64}, b{0.3, -0.8, 0.52};
  const double h = 1e-5, wm = 500; // 0.005 rad per step
  Quat q;
  for (int s = 0; s < 20000; ++s) q = rotate(q, wm * n, h);
  const double err = dist(rotate_vector(q, b), rodrigues(b, n, 20000 * wm * h));
  INFO("after 100 rad: difference " << err);
  CHECK(err < 2e-13); // measured 2.1e-14 (round-off of 20000 steps)
  // Composition: R2 after R1 about different axes (world-frame spins), the order matters.
  const V3 n1{1, 0, 0}, n2{0, 0.6, 0.8};
  Quat c = rotate(Quat{}, 2.0 * n1, 0.4); // 0.8 rad about x
  c = rotate(c, 3.0 * n2, 0.5);           // then 1.5 rad about n2
  const V3 want = rodrigues(rodrigues(b, n1, 0.8), n2, 1.5);
  CHECK(dist(rotate_vector(c, b), want) < 1e-14);
  CHECK(dist(rotate_vector(c, b), rodrigues(rodrigues(b, n2, 1.5), n1, 0.8)) > 0.1);
}
