// DEM sphere orientations (quaternion.hpp, Engine::step): a free sphere spinning at a constant
// angular velocity turns exactly as the closed-form rotation over many radians. (1, 2, 3
// ranks and restarts compare the orientations with everything else: test_dem.cpp.)
#include "harness.hpp"

#include "granmpm/dem/dem.hpp"

using namespace granmpm::dem;
using gmtest::bcast;

namespace {
V3 rodrigues(const V3 &b, const V3 &n, double th) {
  return std::cos(th) * b + std::sin(th) * cross(n, b) + ((1 - std::cos(th)) * dot(n, b)) * n;
}
} // namespace

TEST_CASE("DEM orientation: a spinning sphere turns as the exact rotation over many radians", "[dem]") {
  Config c;
  c.dim = 3;
  c.lo = {0, 0, 0};
  c.hi = {0.1, 0.1, 0.1};
  c.scene = Scene::List;
  c.grains = {0.05, 0.05, 0.05, 0.01, 0, 0, 0};
  c.w0 = {3, -4, 12}; // |w| = 13 rad/s about a tilted axis
  c.contact.kn = 100; // (only sets the step: the sphere touches nothing)
  c.wall = c.contact;
  c.fields = false;
  c.quiet = true;
  c.output_dir = gmtest::outdir("dem_orientation");
  const V3 w{c.w0[0], c.w0[1], c.w0[2]}, n = (1.0 / 13.0) * w;
  double worst = 0, turned = 0, wdrift = 0;
  gmtest::on_ranks(1, [&](MPI_Comm comm) {
    Engine e(comm, c);
    e.setup();
    const long steps = (long)std::ceil(200.0 / 13.0 / e.dt()); // 200 rad
    for (long s = 1; s <= steps; ++s) {
      e.step();
      if (s % 500 && s != steps) continue;
      const GrainRecord g = e.gather().at(0);
      const Quat q{g.q[0], g.q[1], g.q[2], g.q[3]};
      const double th = 13.0 * (s * e.dt()); // (not time(): its running sum of dt carries ~1e-12 of round-off)
      for (const V3 &b : {V3{1, 0, 0}, V3{0, 1, 0}, V3{0, 0, 1}}) worst = std::max(worst, norm(rotate_vector(q, b) - rodrigues(b, n, th)));
      wdrift = std::max(wdrift, norm(V3{g.w[0], g.w[1], g.w[2]} - w));
      turned = th;
    }
  });
  worst = bcast(worst);
  INFO("turned " << bcast(turned) << " rad; largest difference of the rotated frame " << worst << "; spin change " << bcast(wdrift));
  CHECK(bcast(turned) > 199);
  CHECK(bcast(wdrift) == 0.0); // no torque: the spin is held exactly
  CHECK(worst < 3e-13); // measured 2.9e-14 after 9400 steps, 200 rad
}
