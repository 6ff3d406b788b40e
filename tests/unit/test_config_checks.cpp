// config_checks: multi-option physics checks, material-box counts, rank layout, memory
// estimate and non-finite detection. Reference counts are worked out by hand below.
#include <catch2/catch.hpp>

#include <string>

#include "granmpm/config_checks.hpp"

using namespace granmpm;

namespace {

// Errors and warnings of physics_checks whose text contains `what`.
int count(const Config &c, bool error, const std::string &what) {
  int n = 0;
  for (const Finding &f : physics_checks(c))
    if (f.error == error && f.msg.find(what) != std::string::npos) ++n;
  return n;
}
int errors(const Config &c) {
  int n = 0;
  for (const Finding &f : physics_checks(c)) n += f.error;
  return n;
}

// Domain [0,1] x [0,0.5], 10 x 5 cells, 2 particles per cell per direction: lattice
// x = 0.025, 0.075, ..., 0.975 (spacing 0.05).
Config box_config() {
  Config c;
  c.scene = SceneKind::Block;
  c.material = MaterialKind::LinearElastic;
  c.lo = {0, 0, 0};
  c.hi = {1, 0.5, 0};
  c.cells = {10, 5, 1};
  c.bc = {{{{BC::Sticky, BC::Sticky}}, {{BC::Sticky, BC::Sticky}}, {{BC::Sticky, BC::Sticky}}}};
  c.ppc = 2;
  c.p0 = 0;
  return c;
}

} // namespace

TEST_CASE("the default configuration passes every physics check without a warning", "[config_checks]") {
  Config c;
  CHECK(physics_checks(c).empty());
  CHECK(check_procs(c, 1).empty());
  CHECK(check_procs(c, 3).empty());
}

TEST_CASE("material box lattice counts and clipping", "[config_checks]") {
  Config c = box_config();
  // Unbounded box: the whole domain, 20 x 10 points.
  CHECK(lattice_count(c, 0).in_domain == 20);
  CHECK(lattice_count(c, 0).outside == 0);
  CHECK(seeded_particles_bound(c) == 200);
  CHECK(clipped_particles(c) == 0);
  // x in [0.1, 0.33): 0.125, 0.175, 0.225, 0.275, 0.325.
  c.body_lo = {0.1, -1e300, 0};
  c.body_hi = {0.33, 1e300, 0};
  CHECK(lattice_count(c, 0).in_domain == 5);
  CHECK(seeded_particles_bound(c) == 50);
  CHECK(errors(c) == 0);
  // x in [-0.2, 0.33): 7 inside and -0.025, -0.075, -0.125, -0.175 outside, times 10 in y.
  c.body_lo[0] = -0.2;
  CHECK(lattice_count(c, 0).in_domain == 7);
  CHECK(lattice_count(c, 0).outside == 4);
  CHECK(clipped_particles(c) == 40);
  CHECK(count(c, true, "extends outside the domain in x (lo -0.2 < 0); 40 particles of it would be dropped") == 1);
  c.body_clip = true;
  CHECK(errors(c) == 0);
  CHECK(count(c, false, "40 of its particles were dropped") == 1);
  // Beyond the top as well: y in [0, 0.7) adds 4 rows of 11 (7 + 4) points outside.
  c.body_lo[1] = 0;
  c.body_hi[1] = 0.7;
  CHECK(clipped_particles(c) == 11 * 14 - 7 * 10);
  c.body_clip = false;
  CHECK(count(c, true, "in x (lo -0.2 < 0), y (hi 0.7 > 0.5)") == 1);
}

TEST_CASE("an empty, thin or misplaced material box is refused with its cause", "[config_checks]") {
  Config c = box_config();
  c.body_lo = {0.6, 0, 0};
  c.body_hi = {0.4, 0.5, 0};
  CHECK(count(c, true, "the material box is empty in x (lo 0.6 >= hi 0.4)") == 1);
  c.body_lo = {0.26, 0, 0};
  c.body_hi = {0.27, 0.5, 0}; // between lattice points 0.225 and 0.275
  CHECK(count(c, true, "m thin in x, less than the particle spacing h/ppc = 0.05 m") == 1);
  c.body_hi[0] = 0.28; // holds 0.275
  CHECK(errors(c) == 0);
  c.body_lo = {1.2, 0, 0};
  c.body_hi = {1.5, 0.5, 0};
  CHECK(count(c, true, "lies outside the domain in x") == 1);
}

TEST_CASE("physically impossible parameter combinations are refused", "[config_checks]") {
  Config c; // the nonlocal chute
  SECTION("chute without confining pressure") {
    c.p0 = 0;
    CHECK(count(c, true, "-scene chute with -p0 0") == 1);
  }
  SECTION("packing fraction above 1") {
    c.rho = 2500;
    CHECK(count(c, true, "-rho 2500 exceeds the grain density -rho_s 2450") == 1);
    c.material = MaterialKind::LinearElastic; // no grain density in an elastic model
    CHECK(count(c, true, "exceeds the grain density") == 0);
  }
  SECTION("grain as large as the domain") {
    c.gran.d = 1.0; // the chute is 1 m wide (its periodic height bounds no grain)
    CHECK(count(c, true, "-d: the grain diameter 1 m is not smaller than the domain") == 1);
    c.gran.d = 0.2; // as high as the periodic chute: allowed (seed 000's 80-cell chute is d high)
    CHECK(count(c, true, "not smaller than the domain") == 0);
  }
  SECTION("pressure at the bulk modulus") {
    c.E = 1e8;
    c.nu = 0.3; // K = 1e8 / 1.2
    c.p0 = 1e8 / 1.2;
    CHECK(count(c, true, "reaches the bulk modulus") == 1);
    c.p0 = 0.2 * 1e8 / 1.2;
    CHECK(errors(c) == 0);
    CHECK(count(c, false, "of the bulk modulus") == 1);
  }
  SECTION("wave speed at the speed of light") {
    c.E = 1e22;
    c.rho = 1e3; // sqrt(M/rho) with M = 1.35 E: 3.7e9 m/s
    CHECK(count(c, true, "reaches the speed of light") == 1);
    c.E = 1e13; // 1.2e5 m/s: stiff, possible
    CHECK(count(c, true, "speed of light") == 0);
  }
  SECTION("time step below the resolution of t") {
    c.dt = 1e-16;
    c.t_end = 10;
    CHECK(count(c, true, "t + dt rounds to t") == 1);
    c.dt = 5e-9; // 2e9 steps: possible, but a warning without -max_steps
    CHECK(errors(c) == 0);
    CHECK(count(c, false, "explicit steps") == 1);
    c.max_steps = 10;
    CHECK(count(c, false, "explicit steps") == 0);
  }
  SECTION("cells below coordinate resolution") {
    c.lo = {1e9, 0, 0};
    c.hi = {1e9 + 0.0625, 0.015625, 0};
    c.cells = {4, 1, 1};
    CHECK(count(c, true, "below the resolution of double-precision coordinates") == 1);
  }
}

TEST_CASE("a silo orifice that opens no plate node is refused", "[config_checks]") {
  Config c;
  c.scene = SceneKind::Silo;
  c.material = MaterialKind::MuI;
  c.lo = {0, 0, 0};
  c.hi = {0.4, 0.5, 0};
  c.cells = {80, 100, 1}; // h = 0.005, nodes at multiples of 0.005
  c.bc = {{{{BC::Slip, BC::Slip}}, {{BC::Outlet, BC::Free}}, {{BC::Sticky, BC::Sticky}}}};
  c.p0 = 0;
  c.gran.d = 1e-3;
  c.set_scene_param("-silo_plate_y", 0.1);
  c.set_scene_param("-silo_orifice_x", 0.2025); // half-way between nodes 0.200 and 0.205
  c.set_scene_param("-silo_orifice", 0.004);    // |dx| = 0.0025 > 0.002: no node open
  CHECK(count(c, true, "opens no node of the plate") == 1);
  c.set_scene_param("-silo_orifice", 0.006); // 0.0025 < 0.003: nodes 0.200 and 0.205 open
  CHECK(count(c, true, "opens no node") == 0);
  CHECK(count(c, false, "narrower than 5 grain diameters") == 0); // 0.006 > 5 d = 0.005
  c.set_scene_param("-silo_orifice_x", 0.9); // outside the domain
  CHECK(count(c, true, "opens no node") == 1);
}

TEST_CASE("-da_processors_x/y/z against the rank count", "[config_checks]") {
  Config c;
  c.procs = {2, 0, 0};
  CHECK(check_procs(c, 2).empty());
  CHECK(check_procs(c, 4).empty());
  CHECK(check_procs(c, 3).find("ask for 2 ranks, which does not divide the 3 ranks") != std::string::npos);
  c.procs = {1, 2, 0};
  CHECK(check_procs(c, 2).empty());
  CHECK(check_procs(c, 3).find("ask for 1 x 2 = 2 ranks but the run has 3") != std::string::npos);
  c.procs = {0, 0, 2};
  CHECK(check_procs(c, 2).find("-da_processors_z 2 splits a direction a 2D run does not have") != std::string::npos);
}

TEST_CASE("memory estimate: counted bytes per node and particle", "[config_checks]") {
  Config c = box_config(); // elastic, APIC, explicit: no solver
  const MemoryEstimate m = estimate_memory(c);
  // Nodes: (10 + 1 + 4) x (5 + 1 + 4) with the two padding cells beyond each wall.
  CHECK(m.nodes == 150);
  CHECK(m.particles == 200);
  // Grid: 5 dofs in a global and a local vector, plus 3 PetscInt of index maps per node.
  CHECK(m.grid_bytes == 150 * (2 * 5 * 8 + 3 * sizeof(PetscInt)));
  // Particles: x, v (2+2), m, vol, stress (6), APIC C (4) = 16 doubles; id 8, rank 4;
  // seeding buffers 2 doubles + 1 id.
  CHECK(m.particle_bytes == 200 * (16 * 8 + 12 + 16 + 8));
  CHECK(m.solver_bytes == 0);
  // The 20000 x 8000 nonlocal chute of issue 14 needs more than 24 GB (this machine).
  Config big;
  big.hi = {0.5, 0.4, 0.2};
  big.cells = {20000, 8000, 4};
  const MemoryEstimate b = estimate_memory(big);
  CHECK(b.total() > 1e11 * 0.5);
  const std::string msg = check_memory(b, 24e9, "test");
  CHECK(msg.find("but 24 GB are available (test)") != std::string::npos);
  CHECK(check_memory(m, 24e9, "test").empty());
  CHECK(check_memory(b, 0, "unknown").empty()); // no MemAvailable: no refusal
}

TEST_CASE("non-finite components of real option text", "[config_checks]") {
  CHECK(nonfinite_component("1e8") == -1);
  CHECK(nonfinite_component("inf") == 0);
  CHECK(nonfinite_component("-inf") == 0);
  CHECK(nonfinite_component("NaN") == 0);
  CHECK(nonfinite_component("1e400") == 0);
  CHECK(nonfinite_component("0,nan") == 1);
  CHECK(nonfinite_component("1,2,Infinity") == 2);
  CHECK(nonfinite_component("abc") == -1); // PETSc's parser reports it
  CHECK(nonfinite_component("1,2") == -1);
}

TEST_CASE("grain sizes and rheology slopes beyond the number range are refused (fuzz finding)", "[config_checks]") {
  Config c; // the nonlocal chute; -d 4.9e-324 made its reference NaN (1/(b d) = inf)
  c.gran.d = 4.9e-324;
  CHECK(count(c, true, "a grain below a nanometre") == 1);
  c.gran.d = 1e-6;
  CHECK(errors(c) == 0);
  c.gran.b = 1e-7;
  CHECK(count(c, true, "beyond the range of doubles") == 1);
  c.material = MaterialKind::LinearElastic; // no rheology: not checked
  CHECK(errors(c) == 0);
}

TEST_CASE("prescribed speeds at the speed of light are refused, naming the option (fuzz finding)", "[config_checks]") {
  Config c;
  c.scene = SceneKind::Annulus;
  c.set_scene_param("-annulus_omega", 1.7976931348623157e308); // ended as "particle moved inf cells ... reduce -dt"
  CHECK(count(c, true, "-annulus_omega (times -annulus_ri) gives a speed of") == 1);
  Config v;
  v.v0 = {3e8, 0, 0};
  CHECK(count(v, true, "-velocity gives a speed of 3e+08 m/s") == 1);
  v.v0 = {0, 0, 0};
  v.gravity = {0, -1e300, 0};
  CHECK(count(v, true, "-gravity (times -t_end)") == 1);
  Config b;
  BodySpec d;
  d.shape = BodyShape::Disk;
  d.radius = 0.05;
  d.path = {{{0, 0, 0.1, 0}}, {{1e-12, 1, 0.1, 0}}}; // 1 m in 1e-12 s
  b.bodies = {d};
  CHECK(count(b, true, "-body0_path gives a speed of") == 1);
}

TEST_CASE("explicit damping, bar amplitude and the Sobel threshold against their limits", "[config_checks]") {
  Config c; // chute: h = 0.05, c = sqrt(1.346e8/1500) = 299.6 m/s, dt = 0.5 h/c = 8.34e-5 s
  c.damping = 1e4; // damping dt = 0.83: allowed
  CHECK(errors(c) == 0);
  c.damping = 2e4; // 1.67: reverses velocities
  CHECK(count(c, true, "the explicit damping factor 1 - damping dt") == 1);
  Config bar; // E = 100, rho = 1, nu = 0: c = 10 m/s
  bar.scene = SceneKind::Bar;
  bar.material = MaterialKind::LinearElastic;
  bar.E = 100;
  bar.nu = 0;
  bar.rho = 1;
  bar.p0 = 0;
  bar.set_scene_param("-bar_amplitude", 0.1);
  CHECK(physics_checks(bar).empty());
  bar.set_scene_param("-bar_amplitude", 2);
  CHECK(count(bar, false, "strain amplitude v/c = 0.2") == 1);
  bar.set_scene_param("-bar_amplitude", 10);
  CHECK(count(bar, true, "reaches the wave speed 10 m/s") == 1);
  Config h;
  h.density = DensityMethod::Hybrid;
  h.sobel_threshold = -1;
  CHECK(count(h, true, "-sobel_threshold must be >= 0") == 1);
}

TEST_CASE("integer option text beyond the PetscInt range (fuzz finding: -ppc 4294967297 ran as -ppc 1)", "[config_checks]") {
  const long long max = 2147483647;
  CHECK(int_overflow_component("8", max) == -1);
  CHECK(int_overflow_component("2147483647", max) == -1);
  CHECK(int_overflow_component("-2147483648", max) == -1);
  CHECK(int_overflow_component("2147483648", max) == 0);
  CHECK(int_overflow_component("4294967297", max) == 0);
  CHECK(int_overflow_component("20,99999999999", max) == 1);
  CHECK(int_overflow_component("99999999999999999999999", max) == 0); // beyond long long too
  CHECK(int_overflow_component("abc", max) == -1);                     // PETSc's parser reports it
  CHECK(int_overflow_component("1.5", max) == -1);
}
