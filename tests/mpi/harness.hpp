// Helpers for the MPI tests: run a piece of work on the first n ranks of the world (a
// sub-communicator), and compare gathered particle states. Every rank evaluates the same
// REQUIREs on broadcast numbers, so a failure never leaves other ranks in a collective.
#pragma once

#include <catch2/catch.hpp>
#include <petscsys.h>

#include <algorithm>
#include <array>
#include <fstream>
#include <cmath>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "granmpm/grid.hpp"
#include "granmpm/particles.hpp"
#include "granmpm/simulation.hpp"

namespace gmtest {

inline int world_rank() {
  int r;
  MPI_Comm_rank(PETSC_COMM_WORLD, &r);
  return r;
}
inline int world_size() {
  int s;
  MPI_Comm_size(PETSC_COMM_WORLD, &s);
  return s;
}

// Runs f(comm) on ranks [0, n); other ranks wait. Returns on every rank.
inline void on_ranks(int n, const std::function<void(MPI_Comm)> &f) {
  MPI_Comm sub;
  MPI_Comm_split(PETSC_COMM_WORLD, world_rank() < n ? 0 : MPI_UNDEFINED, world_rank(), &sub);
  if (sub != MPI_COMM_NULL) {
    f(sub);
    MPI_Comm_free(&sub);
  }
  MPI_Barrier(PETSC_COMM_WORLD);
}

inline double bcast(double v) {
  MPI_Bcast(&v, 1, MPI_DOUBLE, 0, PETSC_COMM_WORLD);
  return v;
}
inline long bcast(long v) {
  MPI_Bcast(&v, 1, MPI_LONG, 0, PETSC_COMM_WORLD);
  return v;
}

// Largest difference between two id-sorted particle lists, each field relative to that
// field's largest magnitude; -1 if ids or counts differ.
inline double max_rel_diff(const std::vector<granmpm::ParticleRecord> &a, const std::vector<granmpm::ParticleRecord> &b) {
  if (a.size() != b.size()) return -1;
  double sx = 1e-300, sv = 1e-300, ss = 1e-300, sg = 1e-300, sm = 1e-300;
  for (const auto &r : a) {
    for (int d = 0; d < 3; ++d) {
      sx = std::max(sx, std::fabs(r.x[d]));
      sv = std::max(sv, std::fabs(r.v[d]));
    }
    for (int c = 0; c < 6; ++c) ss = std::max(ss, std::fabs(r.s[c]));
    sg = std::max(sg, std::fabs(r.g));
    sm = std::max(sm, std::fabs(r.vol));
  }
  double e = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].id != b[i].id) return -1;
    for (int d = 0; d < 3; ++d) {
      e = std::max(e, std::fabs(a[i].x[d] - b[i].x[d]) / sx);
      e = std::max(e, std::fabs(a[i].v[d] - b[i].v[d]) / sv);
    }
    for (int c = 0; c < 6; ++c) e = std::max(e, std::fabs(a[i].s[c] - b[i].s[c]) / ss);
    e = std::max(e, std::fabs(a[i].g - b[i].g) / sg);
    e = std::max(e, std::fabs(a[i].vol - b[i].vol) / sm);
  }
  return e;
}

// Runs a Simulation<dim> for nsteps on the first n ranks; returns the id-sorted states
// on world rank 0 (empty elsewhere).
template <int dim>
std::vector<granmpm::ParticleRecord> run_steps(int n, const granmpm::Config &cfg, int nsteps, double dt) {
  std::vector<granmpm::ParticleRecord> out;
  on_ranks(n, [&](MPI_Comm comm) {
    granmpm::Simulation<dim> sim(comm, cfg);
    sim.setup();
    for (int s = 0; s < nsteps; ++s) sim.step(dt);
    auto recs = sim.gather(0);
    if (world_rank() == 0) out = std::move(recs);
  });
  return out;
}

// Runs a whole scene (Simulation::run) on the first n ranks; metrics broadcast to all.
template <int dim>
std::map<std::string, double> run_scene(int n, const granmpm::Config &cfg) {
  std::map<std::string, double> m;
  on_ranks(n, [&](MPI_Comm comm) {
    granmpm::Simulation<dim> sim(comm, cfg);
    sim.setup();
    m = sim.run();
  });
  // Broadcast the map from rank 0 (keys are the same on every rank that ran).
  long count = bcast((long)m.size());
  std::vector<std::string> keys;
  for (auto &kv : m) keys.push_back(kv.first);
  std::map<std::string, double> all;
  for (long i = 0; i < count; ++i) {
    std::string k = world_rank() == 0 ? keys[i] : std::string();
    long len = bcast((long)k.size());
    k.resize(len);
    MPI_Bcast(k.data(), (int)len, MPI_CHAR, 0, PETSC_COMM_WORLD);
    all[k] = bcast(world_rank() == 0 ? m[k] : 0.0);
  }
  return all;
}

// Output directory for test runs (inside the build tree).
inline std::string outdir(const std::string &name) { return "test_output/" + name; }

// The output tail of a test's run: results in outdir(name), no final snapshot, no
// progress lines, only errors printed.
inline void quiet(granmpm::Config &c, const std::string &name) {
  c.output_dir = outdir(name);
  c.output_final = false;
  c.progress_interval = 0;
  c.quiet = true;
}

// A grid and its seeded particles, without a Simulation (the particle-level tests:
// migration, faces, outlets).
template <int dim>
struct SeededGrid {
  granmpm::Grid<dim> grid;
  granmpm::Particles<dim> particles;
  SeededGrid(MPI_Comm comm, const granmpm::Config &c) {
    grid.create(comm, c);
    particles.create(comm, grid, granmpm::ParticleFieldSet{});
    particles.seed(c, grid);
  }
};

// A 2D block scene (default material, 1 PPC) filling the box [0, x] x [0, y] of nx x ny
// cells with the faces bc (x: lo, hi; y: lo, hi), results in outdir(name).
inline granmpm::Config box2d(double x, double y, int nx, int ny, std::array<granmpm::BC, 4> bc, const std::string &name) {
  using namespace granmpm;
  Config c;
  c.dim = 2;
  c.scene = SceneKind::Block;
  c.lo = {0, 0, 0};
  c.hi = {x, y, 0};
  c.cells = {nx, ny, 1};
  c.bc = {{{bc[0], bc[1]}, {bc[2], bc[3]}, {BC::Periodic, BC::Periodic}}};
  c.output_dir = outdir(name);
  return c;
}

// The second column (v) of a profile.csv a run wrote on world rank 0 (empty elsewhere).
inline std::vector<double> read_profile(const std::string &dir) {
  std::vector<double> v;
  if (world_rank() != 0) return v;
  std::ifstream f(dir + "/profile.csv");
  std::string line;
  std::getline(f, line);
  while (std::getline(f, line)) v.push_back(std::stod(line.substr(line.find(',') + 1)));
  return v;
}

// A pre-compressed (p0 = 100 Pa) hypoelastic block (E = 1e5, nu = 0.3, rho = 1000, 2 PPC)
// that spins about z: the base of the parallel, implicit and rigid-body block tests, which
// set the box, the body, the faces, the velocity and the spin rate.
inline granmpm::Config hypo_block(int dim) {
  using namespace granmpm;
  Config c;
  c.dim = dim;
  c.scene = SceneKind::Block;
  c.material = MaterialKind::Hypoelastic;
  c.E = 1e5;
  c.nu = 0.3;
  c.rho = 1000;
  c.ppc = 2;
  c.set_scene_param("-spin", 2.0);
  c.p0 = 100;
  c.gravity_ramp = 0;
  return c;
}

// The elastic bar of examples/bar.opts (length 25, E = 100, rho = 1, c = 10, one period
// T = 10, amplitude 0.1) with n cells along it, 2 PPC, GIMP, FLIP (alpha 1), USF.
inline granmpm::Config bar_config(int n) {
  using namespace granmpm;
  Config c;
  c.dim = 2;
  c.scene = SceneKind::Bar;
  c.material = MaterialKind::LinearElastic;
  c.E = 100;
  c.nu = 0;
  c.rho = 1;
  const double h = 25.0 / n;
  c.lo = {0, 0, 0};
  c.hi = {25 + 4 * h, 4 * h, 0}; // room beyond the free end
  c.cells = {n + 4, 4, 1};
  c.body_hi = {25, 1e9, 1e9};
  c.bc = {{{BC::Sticky, BC::Free}, {BC::Periodic, BC::Periodic}, {BC::Periodic, BC::Periodic}}};
  c.gravity = {0, 0, 0};
  c.gravity_ramp = 0;
  c.t_end = 10;
  c.ppc = 2;
  c.shape = ShapeKind::GIMP;
  c.transfer = TransferKind::FLIP;
  c.flip_alpha = 1.0;
  c.update = UpdateOrder::USF;
  c.set_scene_param("-bar_amplitude", 0.1);
  quiet(c, "bar");
  return c;
}

// A pre-compressed, spinning hypoelastic block thrown at a tilted box (friction contact)
// next to a translating and rotating disk (sticky), no gravity, far from the walls.
// Dynamic: both bodies free (box 150 kg/m, disk 100 kg/m: the block is 640 kg/m at
// 1000 kg/m^3 and their contact nodes hold at most ~50 kg/m, inside the added-mass limit).
inline granmpm::Config block_and_bodies(granmpm::BodyMotion motion = granmpm::BodyMotion::Kinematic) {
  using namespace granmpm;
  Config c = hypo_block(2);
  c.lo = {0, 0, 0};
  c.hi = {2.0, 1.6, 0};
  c.cells = {20, 16, 1};
  c.bc = {{{BC::Sticky, BC::Sticky}, {BC::Sticky, BC::Sticky}, {BC::Periodic, BC::Periodic}}};
  c.body_lo = {0.4, 0.4, 0};
  c.body_hi = {1.2, 1.2, 0};
  c.v0 = {1.5, 0.3, 0};
  c.set_scene_param("-spin", 1.0);
  c.gravity = {0, 0, 0};
  BodySpec box;
  box.shape = BodyShape::Box;
  box.center = {1.3, 0.8, 0};
  box.half = {0.12, 0.3, 0};
  box.angle = 0.35;
  box.contact = BodyContact::Friction;
  box.friction = 0.4;
  BodySpec disk;
  disk.shape = BodyShape::Disk;
  disk.center = {0.8, 0.3, 0};
  disk.radius = 0.12;
  disk.omega = 3.0;
  disk.velocity = {0.2, 0.1, 0};
  disk.index = 1;
  if (motion == BodyMotion::Dynamic) {
    box.motion = disk.motion = motion;
    box.mass = 150;
    disk.mass = 100;
    box.inertia = uniform_inertia(box);
    disk.inertia = uniform_inertia(disk);
  }
  c.bodies = {box, disk};
  quiet(c, motion == BodyMotion::Dynamic ? "dynbodies" : "bodies");
  return c;
}

// The collapse scenes' soil (examples/collapse.opts): local mu(I) with mu_s = 0.3
// (calibrated), d = 1 mm, rho_c = 0.9 rho, E = 1e6 Pa; geostatic start, no gravity ramp.
inline granmpm::Config collapse_soil(int dim) {
  using namespace granmpm;
  Config c;
  c.dim = dim;
  c.scene = SceneKind::Collapse;
  c.material = MaterialKind::MuI;
  c.gran.mu_s = 0.3;
  c.gran.b = 18.754;
  c.gran.d = 1e-3;
  c.gran.rho_s = 2450;
  c.gran.rho_c = 1350;
  c.rho = 1500;
  c.E = 1e6;
  c.nu = 0.3;
  c.gravity = {0, -9.81, 0};
  c.gravity_ramp = 0;
  c.geostatic = true;
  c.p0 = 0;
  c.ppc = 2;
  c.output_final = false;
  c.progress_interval = 0;
  c.quiet = true;
  return c;
}

// The coarse 3D Taylor-Couette cell used by the rigid-body and scene tests: cylinders of
// radius 0.1 and 0.2 m about z (inner one at 0.25 rad/s), 22 x 22 x 3 cells, material up to
// 0.04 m, sticky sides, slip bottom, free top, gravity along z.
inline void taylor_couette_cell(granmpm::Config &c) {
  using granmpm::BC;
  c.dim = 3;
  c.set_scene_param("-annulus_ri", 0.1);
  c.set_scene_param("-annulus_ro", 0.2);
  c.set_scene_param("-annulus_omega", 0.25);
  c.lo = {-0.22, -0.22, 0};
  c.hi = {0.22, 0.22, 0.06};
  c.cells = {22, 22, 3};
  c.body_lo = {-0.2, -0.2, 0};
  c.body_hi = {0.2, 0.2, 0.04};
  c.bc = {{{BC::Sticky, BC::Sticky}, {BC::Sticky, BC::Sticky}, {BC::Slip, BC::Free}}};
  c.gravity = {0, 0, -9.81};
}

} // namespace gmtest
