// Per-face wall parameters (issue 17; -dem_wall_mu_<face>, -dem_wall_e_<face>). References:
//  - a disk sliding on a floor with its own mu decelerates at g mu_floor (while it slides:
//    it spins up at 2 mu g / r until v = omega r = 2 v0 / 3, at t* = v0 / (3 mu g)), not at the
//    other faces' mu;
//  - a grain hitting a face with its own e rebounds with that e (the calibrated damping:
//    within the first-order error 0.7 / N of the head-on test, item 1), the other faces
//    with theirs.
#include "harness.hpp"

#include <cmath>

#include "granmpm/dem/dem.hpp"

using namespace granmpm;

namespace {

dem::Config one_grain(const std::vector<double> &grain, const std::array<double, 3> &g) {
  dem::Config c;
  c.dim = 2;
  c.lo = {0, 0, 0};
  c.hi = {1, 0.5, 0};
  c.gravity = g;
  c.scene = dem::Scene::List;
  c.grains = grain;
  c.contact.kn = 1e5;
  c.contact.e = 0.5;
  c.contact.mu = 0.5;
  c.wall = c.contact;
  c.wall.mu = 0.6;
  c.quiet = true;
  c.fields = false;
  c.overlap_tol = 0.1;
  return c;
}

// The grain's velocity (and spin) every step for nsteps.
std::vector<dem::GrainRecord> run(const dem::Config &c, int nsteps, double *dt) {
  std::vector<dem::GrainRecord> out;
  gmtest::on_ranks(1, [&](MPI_Comm comm) {
    dem::Engine e(comm, c);
    e.setup();
    *dt = e.dt();
    for (int s = 0; s < nsteps; ++s) {
      e.step();
      auto g = e.gather();
      if (gmtest::world_rank() == 0) out.push_back(g.at(0));
    }
  });
  return out;
}

} // namespace

TEST_CASE("DEM walls: a disk slides on a floor with its own mu at a = g mu_floor", "[dem][walls]") {
  const double r = 0.01, m = 2500 * M_PI * r * r, g = 9.81, kn = 1e5, v0 = 1.0;
  for (double mu_floor : {0.2, 0.35}) {
    // At its static overlap m g / k_n on the floor, sliding at v0.
    dem::Config c = one_grain({0.2, r - m * g / kn, r, v0, 0}, {0, -g, 0});
    c.face_mu[2] = mu_floor; // ylo
    double dt = 0;
    const double tstar = v0 / (3 * mu_floor * g);
    const int n = (int)(1.5 * tstar / 4e-4);
    const auto h = run(c, n, &dt);
    if (gmtest::world_rank() != 0) continue;
    // Deceleration over the middle of the sliding phase, and the end of sliding.
    const int i1 = (int)(0.2 * tstar / dt), i2 = (int)(0.8 * tstar / dt);
    const double a = (h[i2].v[0] - h[i1].v[0]) / ((i2 - i1) * dt);
    const double alpha = (h[i2].w[2] - h[i1].w[2]) / ((i2 - i1) * dt);
    INFO("mu_floor " << mu_floor << ": rel. error of a " << (a + g * mu_floor) / (g * mu_floor) << ", of the spin-up " << (-alpha - 2 * mu_floor * g / r) / (2 * mu_floor * g / r) << "; a " << a << " (g mu " << g * mu_floor << "), spin-up " << alpha << " (2 mu g / r " << 2 * mu_floor * g / r << "), final v "
                     << h.back().v[0] << " omega r " << -h.back().w[2] * r << " (2 v0 / 3 " << 2 * v0 / 3 << ")");
    REQUIRE(std::fabs(a + g * mu_floor) < 1e-9 * g * mu_floor); // measured 2e-13: exact while it slides
    REQUIRE(std::fabs(-alpha - 2 * mu_floor * g / r) < 1e-9 * 2 * mu_floor * g / r);
    // Then it rolls: v = omega r = 2 v0 / 3 (angular momentum about the contact point).
    REQUIRE(std::fabs(h.back().v[0] - 2 * v0 / 3) < 0.01 * v0);
    REQUIRE(std::fabs(-h.back().w[2] * r - h.back().v[0]) < 0.01 * v0);
  }
}

TEST_CASE("DEM walls: each face restitutes with its own e", "[dem][walls]") {
  // Without gravity a grain flies at the xhi face (its own e) and then at the xlo face (the wall e).
  const double e_xhi = 0.9, e_wall = 0.5;
  dem::Config c = one_grain({0.8, 0.25, 0.01, 1.0, 0}, {0, 0, 0});
  c.face_e[1] = e_xhi;
  double dt = 0;
  const auto h = run(c, 12000, &dt);
  if (gmtest::world_rank() != 0) return;
  // After the first bounce: -e_xhi; after the second (at xlo): +e_xhi e_wall.
  double v1 = 0, v2 = 0;
  for (const auto &q : h) {
    if (q.v[0] < 0 && q.contacts == 0 && v1 == 0) v1 = q.v[0];
    if (v1 != 0 && q.v[0] > 0 && q.contacts == 0) v2 = q.v[0];
  }
  const double tol = 0.7 / 20; // item 1's measured first-order error at 20 steps per contact
  INFO("rebound at xhi " << -v1 << " (e " << e_xhi << "), then at xlo " << v2 / -v1 << " (e " << e_wall << ")");
  REQUIRE(std::fabs(-v1 - e_xhi) < tol);
  REQUIRE(std::fabs(v2 / -v1 - e_wall) < tol);
  REQUIRE(std::fabs(-v1 - e_wall) > 0.3); // the faces differ
}
