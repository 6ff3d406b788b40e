// Rigid-body kernels: signed distances and normals of every shape, the rigid transform,
// the kinematics, the contact rule and the force/torque sums at grid nodes.
#include <catch2/catch.hpp>

#include <cmath>
#include <random>

#include "granmpm/rigid_body.hpp"

using namespace granmpm;

namespace {
BodySpec make(BodyShape s) {
  BodySpec b;
  b.shape = s;
  return b;
}
} // namespace

TEST_CASE("disk and ring: distance and outward normal", "[rigid]") {
  BodySpec d = make(BodyShape::Disk);
  d.radius = 0.5;
  d.center = {1, 2, 0};
  const BodyPose P = body_pose_at(d, 0);
  const double x[2] = {1 + 0.6, 2 + 0.8}; // r = 1
  SdfResult s = body_sdf<2>(d, P, x);
  REQUIRE(s.d == Approx(0.5));
  REQUIRE(s.n[0] == Approx(0.6));
  REQUIRE(s.n[1] == Approx(0.8));
  const double in[2] = {1.3, 2.0};
  REQUIRE(body_sdf<2>(d, P, in).d == Approx(-0.2));
  // Ring: solid outside the radius; the normal points to the axis.
  BodySpec r = d;
  r.shape = BodyShape::Ring;
  s = body_sdf<2>(r, P, x);
  REQUIRE(s.d == Approx(-0.5));
  REQUIRE(s.n[0] == Approx(-0.6));
  REQUIRE(s.n[1] == Approx(-0.8));
  REQUIRE(body_sdf<2>(r, P, in).d == Approx(0.2));
  // 3D: a cylinder along z, whatever z.
  BodySpec c = d;
  const double x3[3] = {1.6, 2.8, -7.0};
  s = body_sdf<3>(c, body_pose_at(c, 0), x3);
  REQUIRE(s.d == Approx(0.5));
  REQUIRE(s.n[2] == 0.0);
}

TEST_CASE("plane: half-space below the plane, normal at the body angle", "[rigid]") {
  BodySpec p = make(BodyShape::Plane);
  p.center = {0, 1, 0};
  p.angle = M_PI / 2; // normal +y: a floor at y = 1
  const BodyPose P = body_pose_at(p, 0);
  const double above[2] = {3.0, 1.25}, below[2] = {-2.0, 0.5};
  SdfResult s = body_sdf<2>(p, P, above);
  REQUIRE(s.d == Approx(0.25));
  REQUIRE(s.n[0] == Approx(0.0).margin(1e-15));
  REQUIRE(s.n[1] == Approx(1.0));
  REQUIRE(body_sdf<2>(p, P, below).d == Approx(-0.5));
  // Inclined at 45 degrees through the origin.
  p.center = {0, 0, 0};
  p.angle = M_PI / 4;
  const double q[2] = {1.0, 1.0};
  REQUIRE(body_sdf<2>(p, body_pose_at(p, 0), q).d == Approx(std::sqrt(2.0)));
}

TEST_CASE("box: exact distance outside (faces and corners), nearest face inside, rigid transform", "[rigid]") {
  BodySpec b = make(BodyShape::Box);
  b.half = {1.0, 0.5, 0.25};
  const BodyPose P = body_pose_at(b, 0);
  const double face[2] = {1.5, 0.1}, corner[2] = {1.3, 0.9}, inside[2] = {0.2, 0.4};
  SdfResult s = body_sdf<2>(b, P, face);
  REQUIRE(s.d == Approx(0.5));
  REQUIRE(s.n[0] == Approx(1.0));
  s = body_sdf<2>(b, P, corner);
  REQUIRE(s.d == Approx(0.5)); // (0.3, 0.4)
  REQUIRE(s.n[0] == Approx(0.6));
  REQUIRE(s.n[1] == Approx(0.8));
  s = body_sdf<2>(b, P, inside);
  REQUIRE(s.d == Approx(-0.1)); // nearest face y = 0.5
  REQUIRE(s.n[1] == Approx(1.0));
  // 3D box: the z faces count.
  const double top[3] = {0.1, 0.1, 0.75};
  s = body_sdf<3>(b, P, top);
  REQUIRE(s.d == Approx(0.5));
  REQUIRE(s.n[2] == Approx(1.0));
  // Rotated by 90 degrees about a moved centre: the long side is along y now.
  b.center = {2, 3, 0};
  b.angle = M_PI / 2;
  const BodyPose R = body_pose_at(b, 0);
  const double q[2] = {2.0, 3.0 + 1.5};
  s = body_sdf<2>(b, R, q);
  REQUIRE(s.d == Approx(0.5));
  REQUIRE(s.n[0] == Approx(0.0).margin(1e-12));
  REQUIRE(s.n[1] == Approx(1.0));
  const double q2[2] = {2.0 + 0.75, 3.0};
  REQUIRE(body_sdf<2>(b, R, q2).d == Approx(0.25));
}

TEST_CASE("normals are the gradient of the signed distance", "[rigid]") {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> U(-2, 2);
  for (BodyShape sh : {BodyShape::Plane, BodyShape::Box, BodyShape::Disk, BodyShape::Ring}) {
    BodySpec b = make(sh);
    b.radius = 0.7;
    b.half = {0.8, 0.4, 0.3};
    b.center = {0.1, -0.2, 0};
    b.angle = 0.3;
    const BodyPose P = body_pose_at(b, 0);
    for (int t = 0; t < 200; ++t) {
      const double x[2] = {U(rng), U(rng)};
      const SdfResult s = body_sdf<2>(b, P, x);
      const double e = 1e-7;
      double g[2];
      for (int d = 0; d < 2; ++d) {
        double xp[2] = {x[0], x[1]}, xm[2] = {x[0], x[1]};
        xp[d] += e;
        xm[d] -= e;
        g[d] = (body_sdf<2>(b, P, xp).d - body_sdf<2>(b, P, xm).d) / (2 * e);
      }
      // Skip points next to the box's medial axis, where the gradient jumps.
      if (std::fabs(std::hypot(g[0], g[1]) - 1) > 1e-5) continue;
      INFO("shape " << to_string(sh) << " at " << x[0] << ", " << x[1]);
      REQUIRE(s.n[0] == Approx(g[0]).margin(1e-5));
      REQUIRE(s.n[1] == Approx(g[1]).margin(1e-5));
    }
  }
}

TEST_CASE("kinematics: pose after t and rigid velocity omega x r + V", "[rigid]") {
  BodySpec b = make(BodyShape::Box);
  b.center = {1, 2, 3};
  b.velocity = {0.5, -1, 2};
  b.omega = 0.25;
  b.angle = 0.1;
  const BodyPose P = body_pose_at(b, 2.0);
  REQUIRE(P.c[0] == Approx(2.0));
  REQUIRE(P.c[1] == Approx(0.0));
  REQUIRE(P.c[2] == Approx(7.0));
  REQUIRE(P.angle == Approx(0.6));
  const double x[3] = {3.0, 1.0, 0.0};
  double v[3];
  body_velocity_at<3>(b, P, x, v);
  REQUIRE(v[0] == Approx(0.5 - 0.25 * (1.0 - 0.0)));
  REQUIRE(v[1] == Approx(-1 + 0.25 * (3.0 - 2.0)));
  REQUIRE(v[2] == Approx(2.0));
}

TEST_CASE("contact rule: sticky imposes the body velocity; friction removes approach and applies Coulomb", "[rigid]") {
  const double vb[2] = {0.3, -0.1}, n[2] = {0.0, 1.0};
  double v[2] = {5.0, -7.0};
  REQUIRE(contact_velocity<2>(BodyContact::Sticky, 0, vb, n, v));
  REQUIRE(v[0] == vb[0]);
  REQUIRE(v[1] == vb[1]);
  // Approaching (relative normal -1), tangential relative 2, mu 0.5: tangential 2 - 0.5.
  double w[2] = {0.3 + 2.0, -0.1 - 1.0};
  REQUIRE(contact_velocity<2>(BodyContact::Friction, 0.5, vb, n, w));
  REQUIRE(w[0] == Approx(0.3 + 1.5));
  REQUIRE(w[1] == Approx(-0.1));
  // Large friction stops the sliding, never reverses it.
  double s[2] = {0.3 + 2.0, -0.1 - 1.0};
  contact_velocity<2>(BodyContact::Friction, 10, vb, n, s);
  REQUIRE(s[0] == Approx(0.3));
  // Separating: untouched.
  double f[2] = {1.0, 0.5};
  REQUIRE_FALSE(contact_velocity<2>(BodyContact::Friction, 0.5, vb, n, f));
  REQUIRE(f[0] == 1.0);
  REQUIRE(f[1] == 0.5);
}

TEST_CASE("rotating disk imposes exactly omega x r at its sticky contact nodes; force and torque are the grid's momentum change", "[rigid]") {
  BodySpec d = make(BodyShape::Disk);
  d.center = {0.05, -0.02, 0};
  d.radius = 0.3;
  d.omega = 1.7;
  d.velocity = {0.2, 0.1, 0};
  const double h = 0.05, dt = 1e-3;
  RigidBodies<2> B({d}, h, 0.5);
  B.set_time(0.4);
  B.begin_forces();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1, 1);
  double dp[2] = {0, 0}, dL = 0;
  int contact = 0, free_nodes = 0;
  const BodyPose P = B.pose(0);
  for (int i = -12; i <= 12; ++i)
    for (int j = -12; j <= 12; ++j) {
      const double x[2] = {i * h, j * h}, m = 1 + 0.5 * U(rng);
      double v[2] = {U(rng), U(rng)}, v0[2] = {v[0], v[1]};
      B.apply(x, m, v, dt);
      const double sd = body_sdf<2>(d, P, x).d;
      if (sd < 0.5 * h) {
        ++contact;
        const double ex[2] = {0.2 - 1.7 * (x[1] - P.c[1]), 0.1 + 1.7 * (x[0] - P.c[0])};
        REQUIRE(v[0] == Approx(ex[0]).epsilon(1e-14));
        REQUIRE(v[1] == Approx(ex[1]).epsilon(1e-14));
      } else {
        ++free_nodes;
        REQUIRE(v[0] == v0[0]);
        REQUIRE(v[1] == v0[1]);
      }
      for (int k = 0; k < 2; ++k) dp[k] += m * (v[k] - v0[k]);
      dL += (x[0] - P.c[0]) * m * (v[1] - v0[1]) - (x[1] - P.c[1]) * m * (v[0] - v0[0]);
    }
  REQUIRE(contact > 100);
  REQUIRE(free_nodes > 100);
  // F dt = - (momentum given to the grid), T dt = - (angular momentum about the centre).
  const std::vector<double> &f = B.forces();
  REQUIRE(f[0] * dt == Approx(-dp[0]).epsilon(1e-12));
  REQUIRE(f[1] * dt == Approx(-dp[1]).epsilon(1e-12));
  REQUIRE(f[3] * dt == Approx(-dL).epsilon(1e-12));
  // dt = 0 (a node not owned): velocity still imposed, no force counted.
  B.begin_forces();
  double v[2] = {1, 1};
  const double x[2] = {P.c[0], P.c[1]}; // the centre at t = 0.4: velocity V
  B.apply(x, 1.0, v, 0.0);
  REQUIRE(B.forces()[0] == 0.0);
  REQUIRE(v[0] == Approx(0.2));
}

TEST_CASE("piecewise-linear path: positions and segment velocities against the analytic path", "[rigid]") {
  BodySpec b = make(BodyShape::Box);
  // Dive 0.1 m in 1 s, drag 0.6 m in 3 s, lift 0.1 m in 1 s (the blade's path).
  b.path = {{{1.0, 0.0, 0.3, 0.0}}, {{2.0, 0.0, 0.2, 0.0}}, {{5.0, 0.6, 0.2, 0.0}}, {{6.0, 0.6, 0.3, 0.0}}};
  b.omega = 0.5;
  b.angle = 0.2;
  struct Case {
    double t, x, y, vx, vy;
  } cases[] = {{0.0, 0.0, 0.3, 0, 0},           // before the first waypoint: at rest there
               {1.0, 0.0, 0.3, 0, -0.1},        // on a waypoint: the next segment's slope
               {1.25, 0.0, 0.275, 0, -0.1},     // diving
               {2.0, 0.0, 0.2, 0.2, 0},         // start of the drag
               {3.5, 0.3, 0.2, 0.2, 0},         // dragging at 0.2 m/s
               {5.5, 0.6, 0.25, 0, 0.1},        // lifting
               {6.0, 0.6, 0.3, 0, 0},           // at and after the last waypoint: at rest
               {9.0, 0.6, 0.3, 0, 0}};
  for (const Case &k : cases) {
    const BodyPose P = body_pose_at(b, k.t);
    double v[3];
    kinematic_velocity_at(b, k.t, v);
    INFO("t = " << k.t);
    REQUIRE(P.c[0] == Approx(k.x).margin(1e-15));
    REQUIRE(P.c[1] == Approx(k.y).margin(1e-15));
    REQUIRE(v[0] == Approx(k.vx).margin(1e-15));
    REQUIRE(v[1] == Approx(k.vy).margin(1e-15));
    REQUIRE(P.angle == Approx(0.2 + 0.5 * k.t));
  }
  // The path is continuous and its velocity integrates to it: midpoint sums over each segment.
  for (int i = 0; i < 3; ++i) {
    const double t0 = b.path[i][0], t1 = b.path[i + 1][0];
    double x = body_pose_at(b, t0).c[0], y = body_pose_at(b, t0).c[1];
    const int n = 64;
    for (int s = 0; s < n; ++s) {
      double v[3];
      kinematic_velocity_at(b, t0 + (s + 0.5) * (t1 - t0) / n, v);
      x += v[0] * (t1 - t0) / n;
      y += v[1] * (t1 - t0) / n;
    }
    REQUIRE(x == Approx(body_pose_at(b, t1 - 1e-12).c[0]).margin(1e-9));
    REQUIRE(y == Approx(body_pose_at(b, t1 - 1e-12).c[1]).margin(1e-9));
  }
}

TEST_CASE("dynamic body step: symplectic Euler under a constant force, damping, locks", "[rigid]") {
  BodySpec b = make(BodyShape::Disk);
  b.motion = BodyMotion::Dynamic;
  b.radius = 0.1;
  b.mass = 2.0;
  b.inertia = uniform_inertia(b);
  REQUIRE(b.inertia == Approx(0.5 * 2.0 * 0.01));
  b.force = {1.0, 0.0, 0.0};
  b.torque = 0.003;
  const double F[4] = {0.5, 4.0, 0.0, 0.002}, g[3] = {0.0, -9.81, 0.0}, dt = 1e-3;
  BodyMotionState s;
  s.pose.c[0] = 0.1;
  s.v[0] = 0.3;
  const int n = 1000;
  for (int i = 0; i < n; ++i) dynamic_body_step<2>(b, F, g, dt, s);
  // v_n = v0 + n a dt, x_n = x0 + n v0 dt + a dt^2 n (n + 1) / 2 (velocity first).
  const double ax = (0.5 + 1.0) / 2.0, ay = 4.0 / 2.0 - 9.81, alpha = (0.002 + 0.003) / b.inertia;
  REQUIRE(s.v[0] == Approx(0.3 + n * ax * dt).epsilon(1e-12));
  REQUIRE(s.v[1] == Approx(n * ay * dt).epsilon(1e-12));
  REQUIRE(s.pose.c[0] == Approx(0.1 + n * 0.3 * dt + ax * dt * dt * n * (n + 1) / 2).epsilon(1e-12));
  REQUIRE(s.pose.c[1] == Approx(ay * dt * dt * n * (n + 1) / 2).epsilon(1e-12));
  REQUIRE(s.omega == Approx(n * alpha * dt).epsilon(1e-12));
  REQUIRE(s.pose.angle == Approx(alpha * dt * dt * n * (n + 1) / 2).epsilon(1e-12));
  REQUIRE(s.v[2] == 0.0);

  // Damping alone: v_n = v0 / (1 + c dt)^n (backward Euler), -> exp(-c t) as dt -> 0.
  BodySpec d = b;
  d.force = {0, 0, 0};
  d.torque = 0;
  d.damping = 5.0;
  d.angular_damping = 2.0;
  BodyMotionState q;
  q.v[0] = 1.0;
  q.omega = 3.0;
  const double zero[4] = {0, 0, 0, 0}, nog[3] = {0, 0, 0};
  for (int i = 0; i < n; ++i) dynamic_body_step<2>(d, zero, nog, dt, q);
  REQUIRE(q.v[0] == Approx(std::pow(1.0 + 5.0 * dt, -n)).epsilon(1e-12));
  REQUIRE(q.omega == Approx(3.0 * std::pow(1.0 + 2.0 * dt, -n)).epsilon(1e-12));
  REQUIRE(q.v[0] == Approx(std::exp(-5.0)).epsilon(5.0 * 5.0 * dt)); // first order in dt

  // Locks: x and rot keep the prescribed velocity and omega whatever the force; y is free.
  BodySpec w = b;
  w.lock = {{true, false, false, true}};
  w.velocity = {0.4, 0.0, 0.0};
  w.omega = -2.0;
  BodyMotionState r;
  for (int i = 0; i < n; ++i) dynamic_body_step<2>(w, F, g, dt, r);
  REQUIRE(r.v[0] == 0.4);
  REQUIRE(r.omega == -2.0);
  REQUIRE(r.pose.c[0] == Approx(0.4 * n * dt).epsilon(1e-12));
  REQUIRE(r.pose.angle == Approx(-2.0 * n * dt).epsilon(1e-12));
  REQUIRE(r.v[1] == Approx(n * ay * dt).epsilon(1e-12));
}

TEST_CASE("RigidBodies: a dynamic body keeps its state across set_time and round-trips through state()", "[rigid]") {
  BodySpec k = make(BodyShape::Disk), d = make(BodyShape::Box);
  k.velocity = {0.1, 0, 0};
  d.motion = BodyMotion::Dynamic;
  d.mass = 3;
  d.inertia = 0.1;
  d.center = {0.5, 0.5, 0};
  RigidBodies<2> B({k, d}, 0.05, 0.5);
  B.begin_forces();
  B.forces()[4 + 1] = 6.0; // fy on the box: a = 2 m/s^2 upward, g down 1
  const double g[3] = {0, -1, 0};
  B.advance(0.0, 0.01, g);
  REQUIRE(B.velocity(1)[1] == Approx(0.01 * (2.0 - 1.0)));
  REQUIRE(B.pose(1).c[1] == Approx(0.5 + 0.01 * 0.01));
  REQUIRE(B.pose(0).c[0] == Approx(0.1 * 0.01)); // kinematic: at t + dt
  B.set_time(5.0);
  REQUIRE(B.pose(1).c[1] == Approx(0.5 + 0.01 * 0.01)); // untouched by set_time
  RigidBodies<2> C({k, d}, 0.05, 0.5);
  REQUIRE(C.set_state(B.state()));
  REQUIRE(C.state() == B.state());
  REQUIRE_FALSE(C.set_state(std::vector<double>(5, 0.0)));
}

TEST_CASE("outline for output: box corners on it, sides cut by arc length, closed perimeter; circle; plane segment", "[rigid]") {
  BodySpec b = make(BodyShape::Box);
  b.half = {0.005, 0.05, 0.1}; // the blade: sides 1 cm and 10 cm
  BodyPose P;
  P.c[0] = 0.3;
  P.c[1] = 0.2;
  P.angle = 0.4;
  const double mid[3] = {0, 0, 0};
  const int n = 128;
  const auto x = body_outline(b, P, mid, 1.0, 0.0, n);
  REQUIRE((int)x.size() == n);
  REQUIRE(body_outline_closed(b));
  double len = 0, smin = 1e300, smax = 0;
  int corners = 0;
  for (int i = 0; i < n; ++i) {
    const auto &p = x[i], &q = x[(i + 1) % n]; // closed: the last point joins the first
    const double s = std::hypot(q[0] - p[0], q[1] - p[1]);
    len += s;
    smin = std::min(smin, s);
    smax = std::max(smax, s);
    double w[3] = {p[0], p[1], 0}, l[3];
    to_body_frame<2>(P, w, l);
    REQUIRE(std::fabs(std::max(std::fabs(l[0]) / b.half[0], std::fabs(l[1]) / b.half[1]) - 1) < 1e-12); // on the boundary
    corners += std::fabs(std::fabs(l[0]) - b.half[0]) < 1e-12 && std::fabs(std::fabs(l[1]) - b.half[1]) < 1e-12;
  }
  CHECK(corners == 4);
  CHECK(len == Approx(4 * (b.half[0] + b.half[1])).epsilon(1e-12)); // the perimeter: corners are points
  // 6 and 58 segments on the 1 and 10 cm sides: 1.67 and 1.72 mm.
  CHECK(smax / smin < 1.04);
  BodySpec d = make(BodyShape::Disk);
  d.radius = 0.2;
  const auto c = body_outline(d, P, mid, 1.0, 0.0, n);
  for (int i = 0; i < n; ++i) CHECK(std::hypot(c[i][0] - P.c[0], c[i][1] - P.c[1]) == Approx(0.2).epsilon(1e-14));
  CHECK(std::hypot(c[1][0] - c[0][0], c[1][1] - c[0][1]) == Approx(2 * 0.2 * std::sin(M_PI / n)).epsilon(1e-12));
  BodySpec pl = make(BodyShape::Plane);
  REQUIRE(!body_outline_closed(pl));
  const auto s = body_outline(pl, P, mid, 0.5, 0.0, n);
  CHECK(std::hypot(s[n - 1][0] - s[0][0], s[n - 1][1] - s[0][1]) == Approx(1.0).epsilon(1e-12)); // 2 L
}
