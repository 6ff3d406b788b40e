// Multi-option checks of a run configuration (see config_checks.hpp). Each refusal names
// the physical reason and the option to change; warnings flag runs that are possible but
// outside what the models or the grid resolve.
#include "granmpm/config_checks.hpp"
#include "granmpm/material.hpp"
#include "granmpm/scene.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <sstream>

#include "granmpm/materials/elastic.hpp"

namespace granmpm {

namespace {

std::string fmt(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

std::string bytes(double b) {
  std::ostringstream s;
  s.precision(3);
  if (b >= 1e9) s << b / 1e9 << " GB";
  else s << b / 1e6 << " MB";
  return s.str();
}

// A box corner left at its default (+-1e300) means "to the domain's face".
bool unbounded(double v) { return !(std::fabs(v) < 1e299); }

const char *axis(int d) { return d == 0 ? "x" : d == 1 ? "y" : "z"; }

// Grid nodes per direction, as Grid::create lays them out (2 padding cells beyond walls).
double nodes_along(const Config &c, int d) { return c.is_periodic(d) ? c.cells[d] : c.cells[d] + 1.0 + 2 * 2; }

constexpr double kLight = 2.99792458e8; // [m/s]

} // namespace

double wave_speed(const Config &c) { return std::sqrt(ElasticModuli::from_E_nu(c.E, c.nu).p_wave() / c.rho); }

void check_speed(std::vector<Finding> &out, const std::string &opt, double s) {
  if (!(s < kLight)) out.push_back({true, opt + " gives a speed of " + fmt(s) + " m/s, at or beyond the speed of light; give a physical value"});
}

void check_initial_pressure(const Config &c, std::vector<Finding> &out) {
  const double K = c.E / (3 * (1 - 2 * c.nu));
  if (c.p0 >= K)
    out.push_back({true, "-p0 " + fmt(c.p0) + " Pa reaches the bulk modulus K = E/(3(1-2nu)) = " + fmt(K) + " Pa: the initial volumetric strain p0/K would be >= 1; lower -p0 or raise -E"});
  else if (c.p0 > 0.1 * K)
    out.push_back({false, "-p0 " + fmt(c.p0) + " Pa is " + fmt(c.p0 / K) + " of the bulk modulus: the initial strain is large for the small-strain elastic part; raise -E"});
}

LatticeCount lattice_count(const Config &c, int d) {
  LatticeCount r;
  const double h = (c.hi[0] - c.lo[0]) / c.cells[0];
  const int pad = c.is_periodic(d) ? 0 : 2;
  const double x0 = c.lo[d] - pad * h;
  const double blo = c.body_lo[d], bhi = c.body_hi[d];
  // The same arithmetic as Particles::seed, so that the counts agree to the last point.
  for (int cell = pad; cell < pad + c.cells[d]; ++cell)
    for (int s = 0; s < c.ppc; ++s) {
      const double x = x0 + (cell + (s + 0.5) / c.ppc) * h;
      if (!(x < blo || x >= bhi)) r.in_domain += 1;
    }
  // Points of the box's lattice (spacing h/ppc, continued beyond the domain) outside it.
  const double sp = h / c.ppc;
  auto points = [&](double a, double b) { // lattice points lo + (i + 1/2) sp in [a, b)
    if (!(b > a)) return 0.0;
    const double i0 = std::ceil((a - c.lo[d]) / sp - 0.5), i1 = std::ceil((b - c.lo[d]) / sp - 0.5);
    return std::max(0.0, i1 - i0);
  };
  if (!unbounded(blo)) r.outside += points(blo, std::min(bhi, c.lo[d]));
  if (!unbounded(bhi)) r.outside += points(std::max(blo, c.hi[d]), bhi);
  return r;
}

double seeded_particles_bound(const Config &c) {
  double n = 1;
  for (int d = 0; d < c.dim; ++d) n *= lattice_count(c, d).in_domain;
  return n;
}

double clipped_particles(const Config &c) {
  double all = 1;
  for (int d = 0; d < c.dim; ++d) {
    const LatticeCount l = lattice_count(c, d);
    all *= l.in_domain + l.outside;
  }
  return all - seeded_particles_bound(c);
}

namespace {
// The sections of physics_checks; each appends its findings.
struct Checks {
  const Config &c;
  std::vector<Finding> &out;
  double h;     // cell size
  bool gran_mu; // a mu(I) family material
  double smallest = 1e300; // smallest non-periodic domain extent (grid_checks)
  void refuse(const std::string &m) { out.push_back({true, m}); }
  void warn(const std::string &m) { out.push_back({false, m}); }
};
// The grid and the material box.
void grid_checks(Checks &k) {
  const Config &c = k.c;
  const double h = k.h;
  auto refuse = [&](const std::string &m) { k.refuse(m); };
  auto warn = [&](const std::string &m) { k.warn(m); };
  // Number range of the grid: coordinates must resolve a cell, node indices fit PetscInt.
  double extent = 0, nodes = 1, smallest = 1e300;
  for (int d = 0; d < c.dim; ++d) {
    extent = std::max({extent, std::fabs(c.lo[d]), std::fabs(c.hi[d])});
    nodes *= nodes_along(c, d);
    if (!c.is_periodic(d)) smallest = std::min(smallest, c.hi[d] - c.lo[d]); // a periodic direction bounds no grain
  }
  if (h < 1e-10 * extent)
    refuse("-cells: the cell size " + fmt(h) + " m is below the resolution of double-precision coordinates of magnitude " + fmt(extent) +
           " m (h/|x| < 1e-10): particle positions could not move by a fraction of a cell; shift -domain_lo/-domain_hi towards 0 or use fewer -cells");
  if (nodes * (1 + 2 * c.dim) > 2147483647.0 && sizeof(PetscInt) == 4)
    refuse("-cells: " + fmt(nodes) + " grid nodes times " + std::to_string(1 + 2 * c.dim) + " unknowns exceed the 32-bit index range of this PETSc build; use fewer -cells");

  // The material box: ordered, inside the domain (unless -body_clip), wider than the
  // particle spacing in every direction.
  bool box_ok = true;
  for (int d = 0; d < c.dim; ++d)
    if (!(c.body_lo[d] < c.body_hi[d])) {
      refuse(std::string("-body_lo/-body_hi: the material box is empty in ") + axis(d) + " (lo " + fmt(c.body_lo[d]) + " >= hi " + fmt(c.body_hi[d]) + "); give -body_lo below -body_hi");
      box_ok = false;
    }
  if (box_ok) {
    std::string outside_dirs;
    for (int d = 0; d < c.dim; ++d) {
      const double tol = 1e-9 * h;
      const bool below = !unbounded(c.body_lo[d]) && c.body_lo[d] < c.lo[d] - tol, above = !unbounded(c.body_hi[d]) && c.body_hi[d] > c.hi[d] + tol;
      if (below || above) outside_dirs += std::string(outside_dirs.empty() ? "" : ", ") + axis(d) + (below ? " (lo " + fmt(c.body_lo[d]) + " < " + fmt(c.lo[d]) + ")" : "") +
                                           (above ? " (hi " + fmt(c.body_hi[d]) + " > " + fmt(c.hi[d]) + ")" : "");
      const double lo = std::max(c.body_lo[d], c.lo[d]), hi = std::min(c.body_hi[d], c.hi[d]);
      if (!(hi > lo)) {
        refuse(std::string("-body_lo/-body_hi: the material box lies outside the domain in ") + axis(d) + " (box " + fmt(c.body_lo[d]) + " .. " + fmt(c.body_hi[d]) + ", domain " +
               fmt(c.lo[d]) + " .. " + fmt(c.hi[d]) + ")");
        box_ok = false;
      } else if (lattice_count(c, d).in_domain == 0) {
        refuse(std::string("-body_lo/-body_hi: the material box is ") + fmt(hi - lo) + " m thin in " + axis(d) + ", less than the particle spacing h/ppc = " + fmt(h / c.ppc) +
               " m, and holds no particle; widen it, or refine with -cells or -ppc");
        box_ok = false;
      }
    }
    if (box_ok && !outside_dirs.empty()) {
      const double n = clipped_particles(c);
      if (!c.body_clip)
        refuse("-body_lo/-body_hi: the material box extends outside the domain in " + outside_dirs + "; " + fmt(n) +
               " particles of it would be dropped: fit it to -domain_lo/-domain_hi, or add -body_clip to clip it");
      else
        warn("-body_clip: the material box extends outside the domain in " + outside_dirs + "; " + fmt(n) + " of its particles were dropped");
    }
  }

  if (c.density == DensityMethod::Hybrid && !(c.sobel_threshold >= 0))
    refuse("-sobel_threshold must be >= 0 (a gradient magnitude; got " + fmt(c.sobel_threshold) + ")");
  k.smallest = smallest;
}

// The densities, the grain size, the moduli, the pressure and the time step.
void material_checks(Checks &k) {
  const Config &c = k.c;
  const double smallest = k.smallest;
  const double h = k.h;
  const bool gran_mu = k.gran_mu;
  auto refuse = [&](const std::string &m) { k.refuse(m); };
  auto warn = [&](const std::string &m) { k.warn(m); };
  // Densities.
  if (gran_mu && c.rho > c.gran.rho_s)
    refuse("-rho " + fmt(c.rho) + " exceeds the grain density -rho_s " + fmt(c.gran.rho_s) + ": the packing fraction rho/rho_s would be above 1; lower -rho or raise -rho_s");
  if (c.granular() && c.gran.rho_c > 0 && c.rho < c.gran.rho_c)
    warn("-rho " + fmt(c.rho) + " is below the critical density -rho_c " + fmt(c.gran.rho_c) + ": the material starts disconnected and stress-free");

  // Grain size and rheology rate scale sqrt(p/rho_s)/(b d): the mu(I) rheology is for
  // grains of a micrometre and up; far below, 1/(b d) leaves the range of doubles.
  if (gran_mu && c.gran.d < 1e-9)
    refuse("-d " + fmt(c.gran.d) + " m: a grain below a nanometre is outside the granular rheology's validity (and its rate scale sqrt(p/rho_s)/(b d) overflows); give the grain diameter in metres");
  else if (gran_mu && c.gran.b * c.gran.d < 1e-12)
    refuse("-b " + fmt(c.gran.b) + " with -d " + fmt(c.gran.d) + ": b d = " + fmt(c.gran.b * c.gran.d) + " m puts the rheology's rate scale sqrt(p/rho_s)/(b d) beyond the range of doubles; check -b (or -mu_2, -I_0) and -d");
  // Grain size against the domain. (A grain larger than a cell is allowed: seed 000's
  // chute has d = h, the nonlocal length being a model parameter rather than a grain.)
  if (gran_mu && c.gran.d >= smallest)
    refuse("-d: the grain diameter " + fmt(c.gran.d) + " m is not smaller than the domain (" + fmt(smallest) + " m across): the continuum model does not apply; lower -d");

  // Moduli, pressure and the time step.
  const double c_wave = wave_speed(c);
  if (!std::isfinite(c_wave) || c_wave >= kLight)
    refuse("-E/-rho: the elastic wave speed sqrt(M/rho) = " + fmt(c_wave) + " m/s reaches the speed of light: no material is that stiff or light; lower -E or raise -rho");
  double vmax = 0;
  for (int d = 0; d < c.dim; ++d) vmax = std::max(vmax, std::fabs(c.v0[d]));
  if (std::isfinite(c_wave) && c_wave > 0 && vmax < kLight) { // faster: refused below
    const double dt = c.dt > 0 ? c.dt : c.cfl * h / (c_wave + vmax);
    if (c.time_integrator == TimeIntegrator::Explicit && dt <= 1e-14 * c.t_end)
      refuse("-t_end " + fmt(c.t_end) + " s with a time step of " + fmt(dt) + " s" + (c.dt > 0 ? std::string(" (-dt)") : " (-cfl " + fmt(c.cfl) + " times h/(c + |v|))") +
             ": t + dt rounds to t in double precision (dt/t_end < 1e-14); lower -t_end, " + (c.dt > 0 ? "raise -dt" : "raise -cfl") + " or coarsen -cells");
    else if (c.time_integrator == TimeIntegrator::Explicit && c.max_steps < 0 && c.t_end / dt > 1e9)
      warn("-t_end " + fmt(c.t_end) + " s needs about " + fmt(c.t_end / dt) + " explicit steps of " + fmt(dt) + " s; set -max_steps or a shorter -t_end");
    // Explicit grid damping v += -damping v dt: the factor 1 - damping dt must stay >= 0.
    if (c.time_integrator == TimeIntegrator::Explicit && c.damping * dt > 1)
      refuse("-damping " + fmt(c.damping) + " 1/s with a time step of " + fmt(dt) + " s: the explicit damping factor 1 - damping dt = " + fmt(1 - c.damping * dt) +
             " is negative and reverses the velocities; lower -damping below 1/dt or -dt");
    if (vmax > c_wave) warn("-velocity " + fmt(vmax) + " m/s exceeds the elastic wave speed " + fmt(c_wave) + " m/s: the initial motion is supersonic");
  }
  if (c.gravity_ramp > c.t_end) {
    bool g = false;
    for (int d = 0; d < c.dim; ++d) g = g || c.gravity[d] != 0;
    if (g) warn("-gravity_ramp " + fmt(c.gravity_ramp) + " s exceeds -t_end " + fmt(c.t_end) + " s: gravity never reaches its full value");
  }
}

// Prescribed speeds.
void motion_checks(Checks &k) {
  const Config &c = k.c;
  // Prescribed speeds: no motion the options give can reach the speed of light (a value
  // like 1e308 would otherwise end as 'unstable; reduce -dt', naming the wrong cause).
  {
    double size = 0, g = 0, v = 0;
    for (int d = 0; d < c.dim; ++d) {
      size = std::max(size, c.hi[d] - c.lo[d]);
      g += c.gravity[d] * c.gravity[d];
      v = std::max(v, std::fabs(c.v0[d]));
    }
    auto speed = [&](const std::string &opt, double s) { check_speed(k.out, opt, s); };
    speed("-velocity", v);
    speed("-gravity (times -t_end)", std::sqrt(g) * c.t_end);
    for (const BodySpec &B : c.bodies) {
      const std::string b = "-body" + std::to_string(B.index) + "_";
      double bv = 0;
      for (int d = 0; d < c.dim; ++d) bv = std::max(bv, std::fabs(B.velocity[d]));
      speed(b + "velocity", bv);
      speed(b + "omega (times the domain size)", std::fabs(B.omega) * size);
      for (size_t i = 1; i < B.path.size(); ++i) {
        double dist = 0;
        for (int d = 1; d <= c.dim; ++d) dist = std::max(dist, std::fabs(B.path[i][d] - B.path[i - 1][d]));
        speed(b + "path", dist / (B.path[i][0] - B.path[i - 1][0]));
      }
    }
  }
}

// The rigid bodies against the cell size, then the scene's own checks (SceneRules::checks).
void scene_checks(Checks &k) {
  const Config &c = k.c;
  const double h = k.h;
  auto warn = [&](const std::string &m) { k.warn(m); };
  // Rigid bodies against the cell size.
  for (const BodySpec &B : c.bodies)
    if ((B.shape == BodyShape::Disk) && B.radius < h)
      warn("-body" + std::to_string(B.index) + "_radius " + fmt(B.radius) + " m is below the cell size " + fmt(h) + " m: the disk touches the material at one or two grid nodes only");
  scene_rules(c.scene).checks(c, k.out);
}

} // namespace

std::vector<Finding> physics_checks(const Config &c) {
  std::vector<Finding> out;
  const double h = (c.hi[0] - c.lo[0]) / c.cells[0];
  const bool gran_mu = c.material == MaterialKind::MuI || c.material == MaterialKind::Nonlocal || c.material == MaterialKind::Dynamic;
  Checks k{c, out, h, gran_mu};
  grid_checks(k);
  material_checks(k);
  motion_checks(k);
  scene_checks(k);
  return out;
}

std::string check_procs(const Config &c, int nranks) {
  int given = 1, free_dirs = 0;
  std::string list;
  for (int d = 0; d < c.dim; ++d) {
    if (c.procs[d] > 0) {
      given *= c.procs[d];
      list += std::string(list.empty() ? "" : " x ") + std::to_string(c.procs[d]);
    } else ++free_dirs;
  }
  for (int d = c.dim; d < 3; ++d)
    if (c.procs[d] > 1) return std::string("-da_processors_") + axis(d) + " " + std::to_string(c.procs[d]) + " splits a direction a " + std::to_string(c.dim) + "D run does not have; remove it";
  if (list.empty()) return "";
  const std::string asked = "-da_processors_x/y/z ask for " + list + (list.find('x') != std::string::npos ? " = " + std::to_string(given) : std::string()) + " ranks";
  if (free_dirs == 0 && given != nranks)
    return asked + " but the run has " + std::to_string(nranks) + "; make their product equal to the -n of mpiexec";
  if (nranks % given != 0)
    return asked + ", which does not divide the " + std::to_string(nranks) + " ranks of the run; change them or the -n of mpiexec";
  return "";
}

MemoryEstimate estimate_memory(const Config &c) {
  MemoryEstimate m;
  const int dim = c.dim;
  m.nodes = 1;
  for (int d = 0; d < dim; ++d) m.nodes *= nodes_along(c, d);
  m.particles = seeded_particles_bound(c);
  const bool apic = c.transfer == TransferKind::APIC;
  int model_doubles = 0; // the fields the material model declares (materials/model.hpp)
  for (const FieldDecl &f : material_entry(c.material).info.fields) model_doubles += f.bs;
  // Grid: global and ghosted local vectors of 1 + 2 dim dofs (mass, momentum, force; 8 in
  // 3D, transfer.hpp), and the DMDA's local-to-global map (one PetscInt per node, plus its
  // scatter: 2 more).
  const int ndof = dim == 3 ? 8 : 1 + 2 * dim;
  m.grid_bytes = m.nodes * (2.0 * ndof * 8 + 3 * sizeof(PetscInt));
  // Particles: the registered fields (Particles::create) and the seeding buffers.
  const double doubles = 2 * dim + 1 + 1 + 6 + (apic ? dim * dim : 0) + model_doubles;
  m.particle_bytes = m.particles * (8 * doubles + 8 /*id*/ + 4 /*rank*/ + 8.0 * dim + 8 /*seeding buffers*/);
  // Solvers: AIJ matrices at 8 bytes per value + one PetscInt column index per value.
  const double box1 = dim == 2 ? 9 : 27, box2 = dim == 2 ? 25 : 125, aij = 8 + sizeof(PetscInt);
  double per_node = 0;
  if (c.material == MaterialKind::Nonlocal && c.time_integrator != TimeIntegrator::ImplicitCoupled)
    // 7 vectors, CG's 4, the matrix, hypre's copy of it and its AMG hierarchy (about 3x the
    // matrix: measured by mallinfo2 in tests/mpi/test_rank_models.cpp).
    per_node += 7 * 8 + 4 * 8 + 5 * box1 * aij;
  if (c.material == MaterialKind::Dynamic) {
    per_node += 12 * 8;
    if (c.fluidity_step == FluidityStepKind::Implicit) per_node += box1 * aij + 32 * 8 /*GMRES(30)*/ + 8 /*Jacobi*/;
  }
  if (c.density != DensityMethod::Local) per_node += 2 * 8;
  if (c.time_integrator != TimeIntegrator::Explicit) {
    const int nd = dim + (c.time_integrator == TimeIntegrator::ImplicitCoupled ? 1 : 0);
    // Vectors, SNES work vectors, GMRES(30) basis, the width-2 box preconditioner matrix
    // (nd x nd blocks over 5^dim neighbours) and its ILU/block-Jacobi factor of equal size.
    per_node += nd * 8.0 * (6 + 5 + 32) + 2 * nd * nd * box2 * aij;
  }
  m.solver_bytes = m.nodes * per_node;
  return m;
}

std::string check_memory(const MemoryEstimate &m, double available, const std::string &where) {
  if (!(available > 0) || m.total() <= available) return "";
  return "the run needs about " + bytes(m.total()) + " (grid " + bytes(m.grid_bytes) + " for " + fmt(m.nodes) + " nodes, particles " + bytes(m.particle_bytes) + " for " + fmt(m.particles) +
         ", solvers " + bytes(m.solver_bytes) + ") but " + bytes(available) + " are available (" + where +
         "); use fewer -cells or -ppc, or more nodes (-memory_check 0 skips this estimate)";
}

int nonfinite_component(const std::string &text) {
  std::string tok;
  int i = 0;
  for (size_t p = 0; p <= text.size(); ++p) {
    if (p == text.size() || text[p] == ',') {
      char *end = nullptr;
      const double v = std::strtod(tok.c_str(), &end);
      if (!tok.empty() && end != tok.c_str() && *end == 0 && !std::isfinite(v)) return i;
      tok.clear();
      ++i;
    } else tok += text[p];
  }
  return -1;
}

int int_overflow_component(const std::string &text, long long max) {
  std::string tok;
  int i = 0;
  for (size_t p = 0; p <= text.size(); ++p) {
    if (p == text.size() || text[p] == ',') {
      errno = 0;
      char *end = nullptr;
      const long long v = std::strtoll(tok.c_str(), &end, 10);
      if (!tok.empty() && end != tok.c_str() && *end == 0 && (errno == ERANGE || v > max || v < -max - 1)) return i;
      tok.clear();
      ++i;
    } else tok += text[p];
  }
  return -1;
}

} // namespace granmpm
