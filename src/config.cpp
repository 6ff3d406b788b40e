// Options parsing and validation. Every option is registered inside one
// PetscOptionsBegin/End block so `granmpm -help` prints it with its default; values are
// validated afterwards so that bad input stops with one line naming the option.
#include "granmpm/config.hpp"
#include "granmpm/option_names.hpp"

#include <fstream>

#include "granmpm/config_checks.hpp"
#include "granmpm/material.hpp"

#include <cmath>
#include <cstring>
#include <sstream>
#include <vector>

namespace granmpm {

void collective_fail(MPI_Comm comm, bool failed, const std::string &msg) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  int mine = failed ? rank : size, first = size;
  MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, comm);
  if (first == size) return;
  int len = (rank == first) ? (int)msg.size() : 0;
  MPI_Bcast(&len, 1, MPI_INT, first, comm);
  std::string text(len, ' ');
  if (rank == first) text = msg;
  MPI_Bcast(text.data(), len, MPI_CHAR, first, comm);
  throw UserError(text);
}

const char *to_string(BC b) { return name_of(b); }
const char *to_string(SceneKind s) { return name_of(s); }

int Config::nper() const {
  int n = 0;
  for (int d = 0; d < dim; ++d) n += is_periodic(d);
  return n;
}

namespace {

std::string fmt(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// Names of per-body options that failed to parse (outlive the call).
const char *keep(const std::string &s) {
  static std::string buf;
  buf = s;
  return buf.c_str();
}

[[noreturn]] void bad(const std::string &msg) { throw UserError(msg); }

int choose(const char *opt, const std::string &val, const std::vector<const char *> &choices) {
  std::string list;
  for (size_t i = 0; i < choices.size(); ++i) {
    if (val == choices[i]) return (int)i;
    list += (i ? "|" : "");
    list += choices[i];
  }
  bad(std::string(opt) + ": unknown value '" + val + "' (choose " + list + ")");
}

// Raw strings and arrays read inside the options block, converted afterwards.
struct Raw {
  char scene[64] = "chute", material[64] = "nonlocal", shape[64] = "gimp", transfer[64] = "apic",
       update[64] = "usl", stress_update[64] = "implicit", fmap[64] = "interpolate", fbc[64] = "zero_flux", bfbc[64] = "zero_flux",
       density[64] = "local", outdir[PETSC_MAX_PATH_LEN] = "output", ckfile[PETSC_MAX_PATH_LEN] = "", restart[PETSC_MAX_PATH_LEN] = "",
       oninst[64] = "abort", integrator[64] = "explicit", ijac[64] = "mf_operator", itan[64] = "elastic", fstep[64] = "implicit", flap[64] = "compact";
  char bc[3][2][64] = {{"sticky", "sticky"}, {"periodic", "periodic"}, {"periodic", "periodic"}};
  PetscReal lo[3], hi[3], blo[3], bhi[3], v0[3], grav[3];
  PetscInt cells[3];
  PetscInt nlo = 0, nhi = 0, nblo = 0, nbhi = 0, nv0 = 0, ngrav = 0, ncells = 0;
  PetscBool b_set = PETSC_FALSE, mu2_set = PETSC_FALSE, I0_set = PETSC_FALSE, dt_conflict = PETSC_FALSE;
  // Rigid bodies.
  char bshape[Config::kMaxBodies][64] = {}, bcontact[Config::kMaxBodies][64] = {};
  PetscReal bcenter[Config::kMaxBodies][3] = {}, bhalf[Config::kMaxBodies][3] = {}, bvel[Config::kMaxBodies][3] = {};
  PetscInt nbcenter[Config::kMaxBodies] = {}, nbhalf[Config::kMaxBodies] = {}, nbvel[Config::kMaxBodies] = {};
  PetscBool bset[Config::kMaxBodies] = {};
  BodySpec bspec[Config::kMaxBodies];
  char bmotion[Config::kMaxBodies][64] = {}, block[Config::kMaxBodies][64] = {}, bpath[Config::kMaxBodies][4096] = {};
  PetscReal bforce[Config::kMaxBodies][3] = {};
  PetscInt nbforce[Config::kMaxBodies] = {};
  PetscBool binertia_set[Config::kMaxBodies] = {};
  std::string bdyn_opt[Config::kMaxBodies]; // a dynamic-only option given (for a kinematic body: an error)
  std::string nonfinite; // the first real option given a non-finite value (inf, nan, 1e400), or an integer beyond PetscInt
  char fsolver[64] = "auto", fquad[64] = "particle";
  std::map<std::string, std::string> model_names; // named model parameters given (-dp_match)
};


// PETSc wraps integers beyond its PetscInt range (4294967297 -> 1): note the first.
void note_int_range(Raw &r, const char *name) {
  if (!r.nonfinite.empty()) return;
  char val[4096] = "";
  PetscBool set = PETSC_FALSE;
  if (PetscOptionsGetString(NULL, NULL, name, val, sizeof val, &set) || !set) return;
  const int i = int_overflow_component(val, (long long)PETSC_MAX_INT);
  if (i < 0) return;
  const bool vec = std::strchr(val, ',') != nullptr;
  r.nonfinite = std::string(name) + ": '" + val + "' is beyond the integer range of this build (" + std::to_string((long long)PETSC_MAX_INT) + ")" +
                (vec ? " (component " + std::to_string(i + 1) + ")" : std::string()) + "; give a smaller value";
}

// PETSc parses inf and nan as reals: note the first real option whose text holds one.
void note_nonfinite(Raw &r, const char *name) {
  if (!r.nonfinite.empty()) return;
  char val[4096] = "";
  PetscBool set = PETSC_FALSE;
  if (PetscOptionsGetString(NULL, NULL, name, val, sizeof val, &set) || !set) return;
  const int i = nonfinite_component(val);
  if (i < 0) return;
  const bool vec = std::strchr(val, ',') != nullptr;
  r.nonfinite = std::string(name) + ": '" + val + "' is not a finite number" + (vec ? " (component " + std::to_string(i + 1) + ")" : std::string()) +
                "; give a finite value (values beyond +-1.8e308 overflow to inf)";
}

// Stops reading at the first option whose value PETSc cannot parse, remembering its name.
#define GM_OPT(name, ...)                                                                  \
  do {                                                                                     \
    PetscErrorCode e_ = (__VA_ARGS__);                                                     \
    if (e_) {                                                                              \
      failed = name;                                                                       \
      return e_;                                                                           \
    }                                                                                      \
    if (std::strncmp(#__VA_ARGS__, "PetscOptionsReal", 16) == 0) note_nonfinite(r, name); \
    if (std::strncmp(#__VA_ARGS__, "PetscOptionsInt", 15) == 0) note_int_range(r, name);  \
  } while (0)

// Every registered model's own parameters, each option once (models may share one).
std::vector<const ParamDecl *> declared_params() {
  std::vector<const ParamDecl *> out;
  for (const MaterialEntry &e : material_registry())
    for (const ParamDecl &p : e.info.params) {
      bool seen = false;
      for (const ParamDecl *q : out) seen = seen || std::strcmp(q->option, p.option) == 0;
      if (!seen) out.push_back(&p);
    }
  return out;
}

std::string material_names() {
  std::string s;
  for (const MaterialEntry &e : material_registry()) s += (s.empty() ? "" : "|") + std::string(e.info.name);
  return s;
}

// The value's range as a message says it: "> 0", ">= 0", "in (0, 90) degrees".
std::string range_text(const ParamDecl &p) {
  std::string r;
  if (std::isfinite(p.lo) && std::isfinite(p.hi)) r = std::string("in ") + (p.lo_open ? "(" : "[") + fmt(p.lo) + ", " + fmt(p.hi) + (p.hi_open ? ")" : "]");
  else if (std::isfinite(p.lo)) r = std::string(p.lo_open ? "> " : ">= ") + fmt(p.lo);
  else if (std::isfinite(p.hi)) r = std::string(p.hi_open ? "< " : "<= ") + fmt(p.hi);
  else r = "finite";
  return r + p.unit;
}

// The material models' own parameters as they declare them (materials/model.hpp).
// (Called inside read_options' PetscOptionsBegin block, whose item list it is given.)
PetscErrorCode read_model_params(PetscOptionItems *PetscOptionsObject, Config &c, Raw &r, const char *&failed) {
  PetscBool flag;
  PetscFunctionBeginUser;
  for (const ParamDecl *p : declared_params()) {
    if (!p->choices.empty()) {
      char buf[64] = "";
      const std::string first = p->choices.substr(0, p->choices.find('|'));
      std::snprintf(buf, sizeof buf, "%s", first.c_str());
      GM_OPT(p->option, PetscOptionsString(p->option, (std::string(p->help) + ": " + p->choices).c_str(), NULL, buf, buf, sizeof buf, &flag));
      if (flag) r.model_names[p->option] = buf;
    } else {
      double v = p->def;
      GM_OPT(p->option, PetscOptionsReal(p->option, p->help, NULL, v, &v, &flag));
      if (flag) *c.param_slot(p->option) = v;
    }
  }
  PetscFunctionReturn(0);
}

PetscErrorCode read_options(MPI_Comm comm, Config &c, Raw &r, const char *&failed) {
  PetscInt px = 0, py = 0, pz = 0, cki = (PetscInt)c.checkpoint_interval, fpi = c.fluidity_pc_interval;
  PetscInt dim = c.dim, ppc = c.ppc, max_steps = (PetscInt)c.max_steps, oi = (PetscInt)c.output_interval,
           pi = (PetscInt)c.progress_interval;
  PetscBool flag, unstable = (PetscBool)c.dt_allow_unstable, quiet = (PetscBool)c.quiet,
                  ofinal = (PetscBool)c.output_final, overwrite = (PetscBool)c.output_overwrite;
  const char *faces[3][2] = {{"-bc_xlo", "-bc_xhi"}, {"-bc_ylo", "-bc_yhi"}, {"-bc_zlo", "-bc_zhi"}};
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm, NULL, "GranMPM options (with no options: the nonlocal vertical chute of seed 000, 20 cells across)", NULL);
  GM_OPT("-dim", PetscOptionsInt("-dim", "Spatial dimension: 2 (plane strain) or 3", NULL, dim, &dim, &flag));
  GM_OPT("-scene", PetscOptionsString("-scene", ("Scene: " + names_list<SceneKind>() + " (initial state and diagnostics)").c_str(), NULL, r.scene, r.scene, sizeof r.scene, &flag));
  r.nlo = r.nhi = r.ncells = r.nblo = r.nbhi = r.nv0 = r.ngrav = 3;
  for (int d = 0; d < 3; ++d) {
    r.lo[d] = c.lo[d];
    r.hi[d] = c.hi[d];
    r.cells[d] = c.cells[d];
    r.blo[d] = c.body_lo[d];
    r.bhi[d] = c.body_hi[d];
    r.v0[d] = c.v0[d];
    r.grav[d] = c.gravity[d];
  }
  GM_OPT("-domain_lo", PetscOptionsRealArray("-domain_lo", "Lower corner of the domain x,y[,z] [m]", NULL, r.lo, &r.nlo, &flag));
  if (!flag) r.nlo = 0;
  GM_OPT("-domain_hi", PetscOptionsRealArray("-domain_hi", "Upper corner of the domain x,y[,z] [m]", NULL, r.hi, &r.nhi, &flag));
  if (!flag) r.nhi = 0;
  GM_OPT("-cells", PetscOptionsIntArray("-cells", "Grid cells per direction nx,ny[,nz] (square/cubic cells required)", NULL, r.cells, &r.ncells, &flag));
  if (!flag) r.ncells = 0;
  for (int d = 0; d < 3; ++d)
    for (int s = 0; s < 2; ++s)
      GM_OPT(faces[d][s], PetscOptionsString(faces[d][s], ("Boundary of this face: " + names_list<BC>()).c_str(), NULL, r.bc[d][s], r.bc[d][s], sizeof r.bc[d][s], &flag));
  GM_OPT("-body_lo", PetscOptionsRealArray("-body_lo", "Lower corner of the material box (default: the domain)", NULL, r.blo, &r.nblo, &flag));
  if (!flag) r.nblo = 0;
  GM_OPT("-body_hi", PetscOptionsRealArray("-body_hi", "Upper corner of the material box (default: the domain)", NULL, r.bhi, &r.nbhi, &flag));
  if (!flag) r.nbhi = 0;
  PetscBool bclip = (PetscBool)c.body_clip;
  GM_OPT("-body_clip", PetscOptionsBool("-body_clip", "Clip a material box (-body_lo/-body_hi) that extends beyond the domain, reporting the particles dropped (default: refuse)", NULL, bclip, &bclip, &flag));
  c.body_clip = bclip;
  GM_OPT("-ppc", PetscOptionsInt("-ppc", "Particles per cell per direction (1-8)", NULL, ppc, &ppc, &flag));
  GM_OPT("-velocity", PetscOptionsRealArray("-velocity", "Initial uniform velocity vx,vy[,vz] [m/s]", NULL, r.v0, &r.nv0, &flag));
  if (!flag) r.nv0 = 0;
  GM_OPT("-p0", PetscOptionsReal("-p0", "Initial isotropic pressure [Pa] (chute, block, annulus)", NULL, c.p0, &c.p0, &flag));
  GM_OPT("-spin", PetscOptionsReal("-spin", "Block scene: initial rigid rotation rate about the z axis through the body centre [rad/s]", NULL, c.spin, &c.spin, &flag));
  PetscBool pre = (PetscBool)c.chute_prestress;
  GM_OPT("-chute_prestress", PetscOptionsBool("-chute_prestress", "Chute scene: start from the steady shear stress (use with -gravity_ramp 0)", NULL, pre, &pre, &flag));
  c.chute_prestress = pre;
  PetscBool geo = (PetscBool)c.geostatic;
  GM_OPT("-geostatic", PetscOptionsBool("-geostatic", "Start the material from the geostatic stress sigma_yy = -rho g (top - y), sigma_xx = sigma_zz = nu/(1-nu) sigma_yy", NULL, geo, &geo, &flag));
  c.geostatic = geo;
  GM_OPT("-silo_plate_y", PetscOptionsReal("-silo_plate_y", "Silo scene: height of the bottom plate (its nodes are sticky outside the orifice) [m]", NULL, c.silo_plate_y, &c.silo_plate_y, &flag));
  GM_OPT("-silo_orifice", PetscOptionsReal("-silo_orifice", "Silo scene: orifice width D [m]", NULL, c.silo_orifice, &c.silo_orifice, &flag));
  GM_OPT("-silo_orifice_x", PetscOptionsReal("-silo_orifice_x", "Silo scene: x of the orifice centre [m]", NULL, c.silo_orifice_x, &c.silo_orifice_x, &flag));
  GM_OPT("-silo_orifice_z", PetscOptionsReal("-silo_orifice_z", "Silo scene (3D): z of the orifice centre [m]", NULL, c.silo_orifice_z, &c.silo_orifice_z, &flag));
  GM_OPT("-bar_amplitude", PetscOptionsReal("-bar_amplitude", "Bar scene: first-mode velocity amplitude [m/s]", NULL, c.bar_amplitude, &c.bar_amplitude, &flag));
  GM_OPT("-gravity", PetscOptionsRealArray("-gravity", "Gravity gx,gy[,gz] [m/s^2]", NULL, r.grav, &r.ngrav, &flag));
  if (!flag) r.ngrav = 0;
  GM_OPT("-gravity_ramp", PetscOptionsReal("-gravity_ramp", "Time over which gravity ramps linearly from 0 [s] (0: at once)", NULL, c.gravity_ramp, &c.gravity_ramp, &flag));
  GM_OPT("-wall_friction", PetscOptionsReal("-wall_friction", "Coulomb friction coefficient of slip faces (0: frictionless)", NULL, c.wall_friction, &c.wall_friction, &flag));
  GM_OPT("-damping", PetscOptionsReal("-damping", "Grid velocity damping rate [1/s] (quasi-static runs)", NULL, c.damping, &c.damping, &flag));

  GM_OPT("-material", PetscOptionsString("-material", ("Constitutive model: " + material_names()).c_str(), NULL, r.material, r.material, sizeof r.material, &flag));
  GM_OPT("-E", PetscOptionsReal("-E", "Young's modulus [Pa]", NULL, c.E, &c.E, &flag));
  GM_OPT("-nu", PetscOptionsReal("-nu", "Poisson's ratio (-1 < nu < 0.5)", NULL, c.nu, &c.nu, &flag));
  GM_OPT("-rho", PetscOptionsReal("-rho", "Initial bulk density [kg/m^3]", NULL, c.rho, &c.rho, &flag));
  GM_OPT("-mu_s", PetscOptionsReal("-mu_s", "Static friction coefficient mu_s", NULL, c.gran.mu_s, &c.gran.mu_s, &flag));
  GM_OPT("-mu_2", PetscOptionsReal("-mu_2", "Limiting friction coefficient mu_2 (> mu_s; with -I_0 gives b)", NULL, c.gran.mu_2, &c.gran.mu_2, &r.mu2_set));
  GM_OPT("-I_0", PetscOptionsReal("-I_0", "Inertial number scale I_0 (> 0; with -mu_2 gives b)", NULL, c.gran.I_0, &c.gran.I_0, &r.I0_set));
  GM_OPT("-b", PetscOptionsReal("-b", "Rheology slope b = (mu_2 - mu_s)/I_0 (overrides -mu_2/-I_0)", NULL, c.gran.b, &c.gran.b, &r.b_set));
  GM_OPT("-d", PetscOptionsReal("-d", "Grain diameter [m]", NULL, c.gran.d, &c.gran.d, &flag));
  GM_OPT("-rho_s", PetscOptionsReal("-rho_s", "Grain (solid) density [kg/m^3]", NULL, c.gran.rho_s, &c.gran.rho_s, &flag));
  GM_OPT("-A", PetscOptionsReal("-A", "Nonlocal amplitude A (>= 0)", NULL, c.gran.A, &c.gran.A, &flag));
  GM_OPT("-rho_c", PetscOptionsReal("-rho_c", "Critical density: below it a granular point is stress-free [kg/m^3]", NULL, c.gran.rho_c, &c.gran.rho_c, &flag));
  GM_OPT("-stress_update", PetscOptionsString("-stress_update", "Granular stress update: implicit (mu(I): seed 000 Alg. 1; nonlocal: tau = tau_tr p/(p + G dt g))|explicit (seed 000 Alg. 2/3; needs G dt/eta < 2)", NULL, r.stress_update, r.stress_update, sizeof r.stress_update, &flag));
  GM_OPT("-fluidity_map", PetscOptionsString("-fluidity_map", ("Fluidity grid->particle map: " + names_list<FluidityMap>()).c_str(), NULL, r.fmap, r.fmap, sizeof r.fmap, &flag));
  GM_OPT("-fluidity_pc_interval", PetscOptionsInt("-fluidity_pc_interval", "Rebuild the steady fluidity preconditioner every N solves (also when the active set changes or a solve fails); above 1 a restart equals the uninterrupted run only to the KSP tolerance", NULL, fpi, &fpi, &flag));
  GM_OPT("-body_fluidity_bc", PetscOptionsString("-body_fluidity_bc", "Steady fluidity (-material nonlocal) at rigid-body contact nodes: zero_flux|zero (g = 0, as seed 004's code)", NULL, r.bfbc, r.bfbc, sizeof r.bfbc, &flag));
  GM_OPT("-fluidity_bc", PetscOptionsString("-fluidity_bc", "Fluidity boundary condition at walls: zero_flux|dirichlet (g = g_loc)", NULL, r.fbc, r.fbc, sizeof r.fbc, &flag));
  GM_OPT("-fluidity_solver", PetscOptionsString("-fluidity_solver", "Fluidity linear solver (steady model; the dynamical model's implicit step: direct = LU): auto (direct when the band Cholesky cost is small) | direct (band Cholesky of the whole system on rank 0 in a fixed node order, CG on it to -fluidity_ksp_rtol: 1 iteration) | iterative (CG + BoomerAMG; tune with -fluidity_ksp_*, -fluidity_pc_*)", NULL, r.fsolver, r.fsolver, sizeof r.fsolver, &flag));
  {
    PetscInt frm = c.fluidity_resolve_max;
    GM_OPT("-fluidity_resolve_max", PetscOptionsInt("-fluidity_resolve_max", "Steady fluidity: solve at least every N steps (N = 1: every step); in between g = g_loc + the nonlocal part g - g_loc of the last solve, per particle", NULL, frm, &frm, &flag));
    c.fluidity_resolve_max = (int)frm;
  }
  GM_OPT("-fluidity_quadrature", PetscOptionsString("-fluidity_quadrature", "Steady fluidity system integrated at the particles (particle) or exactly over each cell with the cell means of |mu - mu_s|, |mu - mu_s| g_loc and the filled fraction (cell)", NULL, r.fquad, r.fquad, sizeof r.fquad, &flag));
  GM_OPT("-fluidity_resolve_tol", PetscOptionsReal("-fluidity_resolve_tol", "Steady fluidity: target error of the skipped steps, max|g - (g_loc + last nonlocal part)| / max|g| at the next solve; the solve interval adapts to it (and a change of g_loc by 10x this forces a solve)", NULL, c.fluidity_resolve_tol, &c.fluidity_resolve_tol, &flag));
  PetscBool vavg = (PetscBool)c.vol_cell_average;
  GM_OPT("-volumetric_average", PetscOptionsBool("-volumetric_average", "Replace each particle's volumetric strain rate tr L by the volume-weighted mean over its cell (B-bar-like, against volumetric locking of plastic flow)", NULL, vavg, &vavg, &flag));
  c.vol_cell_average = vavg;
  GM_OPT("-density", PetscOptionsString("-density", ("Density update: " + names_list<DensityMethod>() + " (seed 000 3.4)").c_str(), NULL, r.density, r.density, sizeof r.density, &flag));
  GM_OPT("-sobel_threshold", PetscOptionsReal("-sobel_threshold", "Hybrid density: Sobel gradient magnitude of particles-per-cell marking an edge cell", NULL, c.sobel_threshold, &c.sobel_threshold, &flag));

  {
    const PetscErrorCode e = read_model_params(PetscOptionsObject, c, r, failed);
    if (e) return e;
  }
  GM_OPT("-fluidity_step", PetscOptionsString("-fluidity_step", "Dynamical fluidity step: explicit (seed 004; limits dt) | implicit (backward Euler: KSP for the diffusion, coupled local update)", NULL, r.fstep, r.fstep, sizeof r.fstep, &flag));
  GM_OPT("-fluidity_laplacian", PetscOptionsString("-fluidity_laplacian", "Dynamical fluidity Laplacian on the grid: compact (5/7-point) | box (isotropic 9/27-point)", NULL, r.flap, r.flap, sizeof r.flap, &flag));
  GM_OPT("-shape", PetscOptionsString("-shape", ("Shape functions: " + names_list<ShapeKind>()).c_str(), NULL, r.shape, r.shape, sizeof r.shape, &flag));
  GM_OPT("-transfer", PetscOptionsString("-transfer", ("Particle velocity transfer: " + names_list<TransferKind>()).c_str(), NULL, r.transfer, r.transfer, sizeof r.transfer, &flag));
  GM_OPT("-flip_alpha", PetscOptionsReal("-flip_alpha", "FLIP fraction of the PIC/FLIP blend, in [0,1]", NULL, c.flip_alpha, &c.flip_alpha, &flag));
  GM_OPT("-update", PetscOptionsString("-update", ("Update ordering: " + names_list<UpdateOrder>()).c_str(), NULL, r.update, r.update, sizeof r.update, &flag));

  // Implicit momentum step (SNES options themselves take the prefix -implicit_).
  GM_OPT("-time_integrator", PetscOptionsString("-time_integrator", "Momentum time integration: explicit (symplectic Euler, CFL-limited) | implicit (backward Euler on grid velocities, SNES with prefix -implicit_) | implicit_coupled (-material nonlocal: grid velocities and the steady fluidity g in one SNES system)", NULL, r.integrator, r.integrator, sizeof r.integrator, &flag));
  GM_OPT("-implicit_jacobian", PetscOptionsString("-implicit_jacobian", "Implicit step Jacobian: mf_operator (finite-difference J, assembled M/dt + dt K_elastic as preconditioner) | assembled (that matrix as J: exact for -material elastic only)", NULL, r.ijac, r.ijac, sizeof r.ijac, &flag));
  GM_OPT("-implicit_theta", PetscOptionsReal("-implicit_theta", "Implicit step: 1 = backward Euler (default, damps high frequencies), 0.5 = implicit midpoint (second order, no numerical damping); stress and motion use theta v_{n+1} + (1-theta) v_n", NULL, c.implicit.theta, &c.implicit.theta, &flag));
  GM_OPT("-implicit_tangent", PetscOptionsString("-implicit_tangent", "Implicit step preconditioner stiffness: elastic (the elastic moduli everywhere; default) | scaled (granular materials: per particle, shear modulus times tau/tau_trial of the stress return at the current iterate, none where stress-free)", NULL, r.itan, r.itan, sizeof r.itan, &flag));
  PetscBool iadapt = (PetscBool)c.implicit.dt_adapt;
  GM_OPT("-implicit_dt_adapt", PetscOptionsBool("-implicit_dt_adapt", "Implicit step: grow dt after easy solves, halve dt and retry the step when SNES fails", NULL, iadapt, &iadapt, &flag));
  c.implicit.dt_adapt = iadapt;
  PetscInt igrow = c.implicit.grow_its, iretry = c.implicit.max_retries;
  GM_OPT("-implicit_grow_its", PetscOptionsInt("-implicit_grow_its", "Implicit step: grow dt when SNES converged in at most this many iterations", NULL, igrow, &igrow, &flag));
  c.implicit.grow_its = (int)igrow;
  GM_OPT("-implicit_grow_factor", PetscOptionsReal("-implicit_grow_factor", "Implicit step: factor by which dt grows (>= 1)", NULL, c.implicit.grow_factor, &c.implicit.grow_factor, &flag));
  GM_OPT("-implicit_dt_max", PetscOptionsReal("-implicit_dt_max", "Implicit step: largest dt when adapting [s] (0: no cap)", NULL, c.implicit.dt_max, &c.implicit.dt_max, &flag));
  GM_OPT("-implicit_dt_min", PetscOptionsReal("-implicit_dt_min", "Implicit step: stop with an error when a failed step would go below this dt [s] (0: 1e-4 times the first step)", NULL, c.implicit.dt_min, &c.implicit.dt_min, &flag));
  GM_OPT("-implicit_max_retries", PetscOptionsInt("-implicit_max_retries", "Implicit step: halvings of dt allowed for one step before stopping with an error", NULL, iretry, &iretry, &flag));
  c.implicit.max_retries = (int)iretry;
  GM_OPT("-implicit_force_tol", PetscOptionsReal("-implicit_force_tol", "Implicit step: SNES absolute tolerance as a fraction of the step's force scale || |M v_n|/dt + |M b| + sum_p V_p |sigma_n grad N| || (unless -implicit_snes_atol is given)", NULL, c.implicit.force_tol, &c.implicit.force_tol, &flag));

  GM_OPT("-dt", PetscOptionsReal("-dt", "Fixed time step [s]; 0 = automatic (see -dt_auto)", NULL, c.dt, &c.dt, &flag));
  PetscBool dtauto = PETSC_FALSE;
  GM_OPT("-dt_auto", PetscOptionsBool("-dt_auto", "Time step from the CFL condition every step, cfl * h/(c+|v|max) (the default when -dt is not given)", NULL, dtauto, &dtauto, &flag));
  if (dtauto && c.dt > 0) r.dt_conflict = PETSC_TRUE;
  GM_OPT("-cfl", PetscOptionsReal("-cfl", "Courant number for the automatic step and the stability check (0,1]", NULL, c.cfl, &c.cfl, &flag));
  GM_OPT("-dt_allow_unstable", PetscOptionsBool("-dt_allow_unstable", "Run even if -dt exceeds the CFL limit", NULL, unstable, &unstable, &flag));
  GM_OPT("-t_end", PetscOptionsReal("-t_end", "End time [s]", NULL, c.t_end, &c.t_end, &flag));
  GM_OPT("-max_steps", PetscOptionsInt("-max_steps", "Stop after this many steps (-1: no limit)", NULL, max_steps, &max_steps, &flag));

  GM_OPT("-output_dir", PetscOptionsString("-output_dir", "Directory for HDF5/XDMF output and CSV results", NULL, r.outdir, r.outdir, sizeof r.outdir, &flag));
  GM_OPT("-output_interval", PetscOptionsInt("-output_interval", "Steps between HDF5/XDMF outputs (0: final state only)", NULL, oi, &oi, &flag));
  GM_OPT("-output_final", PetscOptionsBool("-output_final", "Write the final state to HDF5/XDMF", NULL, ofinal, &ofinal, &flag));
  GM_OPT("-progress_interval", PetscOptionsInt("-progress_interval", "Steps between progress lines (0: none)", NULL, pi, &pi, &flag));
  GM_OPT("-output_overwrite", PetscOptionsBool("-output_overwrite", "Allow a new run into an -output_dir holding another run's results (its snapshots and XDMF are removed first)", NULL, overwrite, &overwrite, &flag));
  GM_OPT("-quiet", PetscOptionsBool("-quiet", "Print only errors and the final summary", NULL, quiet, &quiet, &flag));
  GM_OPT("-checkpoint_interval", PetscOptionsInt("-checkpoint_interval", "Steps between checkpoints (0: none; SIGTERM/SIGINT always write one)", NULL, cki, &cki, &flag));
  GM_OPT("-checkpoint_file", PetscOptionsString("-checkpoint_file", "Checkpoint file (default <output_dir>/checkpoint.h5)", NULL, r.ckfile, r.ckfile, sizeof r.ckfile, &flag));
  GM_OPT("-restart", PetscOptionsString("-restart", "Continue from this checkpoint file", NULL, r.restart, r.restart, sizeof r.restart, &flag));
  GM_OPT("-on_instability", PetscOptionsString("-on_instability", "On NaN, energy blow-up or a runaway particle: abort|checkpoint_and_abort (writes the last good step)", NULL, r.oninst, r.oninst, sizeof r.oninst, &flag));
  GM_OPT("-energy_bound_factor", PetscOptionsReal("-energy_bound_factor", "Instability guard: the kinetic energy may not exceed this multiple of the energy the scene supplies (initial kinetic + elastic + gravity work)", NULL, c.energy_bound_factor, &c.energy_bound_factor, &flag));
  PetscBool memchk = (PetscBool)c.memory_check;
  GM_OPT("-memory_check", PetscOptionsBool("-memory_check", "Refuse at set-up when the estimated memory (grid, particles, solvers) exceeds MemAvailable summed over the run's nodes", NULL, memchk, &memchk, &flag));
  c.memory_check = memchk;
  GM_OPT("-da_processors_x", PetscOptionsInt("-da_processors_x", "MPI ranks along x (0: chosen to minimise the halo)", NULL, px, &px, &flag));
  GM_OPT("-da_processors_y", PetscOptionsInt("-da_processors_y", "MPI ranks along y (0: chosen)", NULL, py, &py, &flag));
  GM_OPT("-da_processors_z", PetscOptionsInt("-da_processors_z", "MPI ranks along z (0: chosen)", NULL, pz, &pz, &flag));
  GM_OPT("-annulus_ri", PetscOptionsReal("-annulus_ri", "Annulus scene: radius of the inner rotating disk Ri [m]", NULL, c.annulus_ri, &c.annulus_ri, &flag));
  GM_OPT("-annulus_ro", PetscOptionsReal("-annulus_ro", "Annulus scene: radius of the fixed outer ring Ro [m] (> Ri)", NULL, c.annulus_ro, &c.annulus_ro, &flag));
  GM_OPT("-annulus_omega", PetscOptionsReal("-annulus_omega", "Annulus scene: angular velocity of the inner disk [rad/s] (counter-clockwise > 0)", NULL, c.annulus_omega, &c.annulus_omega, &flag));
  GM_OPT("-body_contact_layer", PetscOptionsReal("-body_contact_layer", "Rigid bodies: grid nodes with signed distance < layer * h are contact nodes (cells, in [0, 2])", NULL, c.body_contact_layer, &c.body_contact_layer, &flag));
  PetscInt bint = (PetscInt)c.bodies_interval;
  GM_OPT("-bodies_interval", PetscOptionsInt("-bodies_interval", "Rigid bodies: steps between rows of <output_dir>/bodies.csv (also at every output step and the last step)", NULL, bint, &bint, &flag));
  c.bodies_interval = bint;
  PetscInt balint = (PetscInt)c.balance_interval, sortint = (PetscInt)c.sort_interval;
  GM_OPT("-balance_threshold", PetscOptionsReal("-balance_threshold", "Load balance: repartition the grid when max/mean particles per rank exceeds this (> 1; 0: never)", NULL, c.balance_threshold, &c.balance_threshold, &flag));
  GM_OPT("-balance_interval", PetscOptionsInt("-balance_interval", "Load balance: steps between imbalance checks (>= 1)", NULL, balint, &balint, &flag));
  GM_OPT("-sort_interval", PetscOptionsInt("-sort_interval", "Reorder each rank's particles by cell index every N steps, for memory locality (0: never; default 20)", NULL, sortint, &sortint, &flag));
  c.balance_interval = balint;
  c.sort_interval = sortint;
  for (int k = 0; k < Config::kMaxBodies; ++k) {
    const std::string b = "-body" + std::to_string(k) + "_";
    BodySpec &B = r.bspec[k];
    GM_OPT(keep(b + "shape"), PetscOptionsString((b + "shape").c_str(), ("Kinematic rigid body k (0-3): " + names_list<BodyShape>() + " (disk: a cylinder along z in 3D; ring: solid outside -bodyK_radius)").c_str(), NULL, r.bshape[k], r.bshape[k], sizeof r.bshape[k], &r.bset[k]));
    // The other options of body k are read (and listed by -help) for body 0 and for bodies
    // that are given; options of a body without -bodyK_shape are reported as unused.
    if (!(r.bset[k] || k == 0)) continue;
    r.nbcenter[k] = r.nbhalf[k] = r.nbvel[k] = 3;
    for (int d = 0; d < 3; ++d) {
      r.bcenter[k][d] = B.center[d];
      r.bhalf[k][d] = B.half[d];
      r.bvel[k][d] = B.velocity[d];
    }
    GM_OPT(keep(b + "center"), PetscOptionsRealArray((b + "center").c_str(), "Body k: centre x,y[,z] [m] (plane: a point on it)", NULL, r.bcenter[k], &r.nbcenter[k], &flag));
    if (!flag) r.nbcenter[k] = 0;
    GM_OPT(keep(b + "radius"), PetscOptionsReal((b + "radius").c_str(), "Body k: radius of a disk or ring [m]", NULL, B.radius, &B.radius, &flag));
    GM_OPT(keep(b + "half"), PetscOptionsRealArray((b + "half").c_str(), "Body k: half extents hx,hy[,hz] of a box [m]", NULL, r.bhalf[k], &r.nbhalf[k], &flag));
    if (!flag) r.nbhalf[k] = 0;
    double deg = B.angle * 180.0 / M_PI;
    GM_OPT(keep(b + "angle"), PetscOptionsReal((b + "angle").c_str(), "Body k: initial rotation about z [degrees] (plane: direction of its outward normal, 0 = +x)", NULL, deg, &deg, &flag));
    B.angle = deg * M_PI / 180.0;
    GM_OPT(keep(b + "omega"), PetscOptionsReal((b + "omega").c_str(), "Body k: constant angular velocity about z through its centre [rad/s]", NULL, B.omega, &B.omega, &flag));
    GM_OPT(keep(b + "velocity"), PetscOptionsRealArray((b + "velocity").c_str(), "Body k: constant velocity vx,vy[,vz] [m/s]", NULL, r.bvel[k], &r.nbvel[k], &flag));
    if (!flag) r.nbvel[k] = 0;
    if (r.bcontact[k][0] == 0) std::strcpy(r.bcontact[k], "sticky");
    GM_OPT(keep(b + "contact"), PetscOptionsString((b + "contact").c_str(), "Body k: grid contact sticky (nodes take the body velocity)|friction (no penetration, Coulomb friction, separation allowed)", NULL, r.bcontact[k], r.bcontact[k], sizeof r.bcontact[k], &flag));
    GM_OPT(keep(b + "friction"), PetscOptionsReal((b + "friction").c_str(), "Body k: Coulomb friction coefficient of friction contact (>= 0)", NULL, B.friction, &B.friction, &flag));
    if (r.bmotion[k][0] == 0) std::strcpy(r.bmotion[k], "kinematic");
    GM_OPT(keep(b + "motion"), PetscOptionsString((b + "motion").c_str(), "Body k: kinematic (prescribed path/velocity and omega) | dynamic (moved by contact forces, gravity, applied force/torque)", NULL, r.bmotion[k], r.bmotion[k], sizeof r.bmotion[k], &flag));
    GM_OPT(keep(b + "path"), PetscOptionsString((b + "path").c_str(), "Body k (kinematic): piecewise-linear path of the centre, waypoints 't0,x0,y0[,z0];t1,x1,y1[,z1];...' with increasing t (instead of -bodyK_center/-bodyK_velocity)", NULL, r.bpath[k], r.bpath[k], sizeof r.bpath[k], &flag));
    GM_OPT(keep(b + "mass"), PetscOptionsReal((b + "mass").c_str(), "Body k (dynamic): mass [kg; 2D: kg per unit depth]", NULL, B.mass, &B.mass, &flag));
    if (flag) r.bdyn_opt[k] = b + "mass";
    GM_OPT(keep(b + "inertia"), PetscOptionsReal((b + "inertia").c_str(), "Body k (dynamic): moment of inertia about z through the centre [kg m^2; 2D: per unit depth] (default: a uniform disk/box of -bodyK_mass)", NULL, B.inertia, &B.inertia, &r.binertia_set[k]));
    if (r.binertia_set[k]) r.bdyn_opt[k] = b + "inertia";
    r.nbforce[k] = 3;
    GM_OPT(keep(b + "force"), PetscOptionsRealArray((b + "force").c_str(), "Body k (dynamic): applied force fx,fy[,fz] [N; 2D: N/m] (gravity acts as well)", NULL, r.bforce[k], &r.nbforce[k], &flag));
    if (flag) r.bdyn_opt[k] = b + "force";
    if (!flag) r.nbforce[k] = 0;
    GM_OPT(keep(b + "torque"), PetscOptionsReal((b + "torque").c_str(), "Body k (dynamic): applied torque about z [N m; 2D: N m/m]", NULL, B.torque, &B.torque, &flag));
    if (flag) r.bdyn_opt[k] = b + "torque";
    GM_OPT(keep(b + "damping"), PetscOptionsReal((b + "damping").c_str(), "Body k (dynamic): linear velocity damping rate [1/s] (>= 0)", NULL, B.damping, &B.damping, &flag));
    if (flag) r.bdyn_opt[k] = b + "damping";
    GM_OPT(keep(b + "angular_damping"), PetscOptionsReal((b + "angular_damping").c_str(), "Body k (dynamic): angular velocity damping rate [1/s] (>= 0)", NULL, B.angular_damping, &B.angular_damping, &flag));
    if (flag) r.bdyn_opt[k] = b + "angular_damping";
    GM_OPT(keep(b + "lock"), PetscOptionsString((b + "lock").c_str(), "Body k (dynamic): comma-separated degrees of freedom x,y,z,rot that keep the constant -bodyK_velocity/-bodyK_omega (none: all free)", NULL, r.block[k], r.block[k], sizeof r.block[k], &flag));
    if (flag) r.bdyn_opt[k] = b + "lock";
  }
  PetscOptionsEnd();
  c.dim = (int)dim;
  c.ppc = (int)ppc;
  c.max_steps = max_steps;
  c.output_interval = oi;
  c.fluidity_pc_interval = (int)fpi;
  c.progress_interval = pi;
  c.dt_allow_unstable = unstable;
  c.quiet = quiet;
  c.output_final = ofinal;
  c.output_overwrite = overwrite;
  c.procs = {(int)px, (int)py, (int)pz};
  c.checkpoint_interval = cki;
  PetscFunctionReturn(0);
}

void read_vec(const char *opt, int n, const PetscReal *src, int dim, std::array<double, 3> &dst) {
  if (n == 0) return;
  if (n != dim) bad(std::string(opt) + ": expected " + std::to_string(dim) + " comma-separated values for -dim " + std::to_string(dim) + ", got " + std::to_string(n));
  for (int d = 0; d < dim; ++d) dst[d] = src[d];
}

// -body<k>_lock: comma-separated x,y,z,rot (z in 3D only) or none.
void parse_lock(const char *opt, const std::string &text, int dim, std::array<bool, 4> &lock) {
  lock = {{false, false, false, false}};
  if (text.empty() || text == "none") return;
  std::istringstream in(text);
  for (std::string tok; std::getline(in, tok, ',');) {
    const std::vector<const char *> names = {"x", "y", "z", "rot"};
    int i = -1;
    for (int j = 0; j < 4; ++j)
      if (tok == names[j]) i = j;
    if (i < 0 || (i == 2 && dim == 2)) bad(std::string(opt) + ": unknown degree of freedom '" + tok + "' (a comma-separated list of " + (dim == 2 ? "x,y,rot" : "x,y,z,rot") + ", or none)");
    lock[i] = true;
  }
}

// -body<k>_path: waypoints 't,x,y[,z]' separated by ';', at least two, t strictly increasing.
std::vector<std::array<double, 4>> parse_path(const char *opt, const std::string &text, int dim) {
  std::vector<std::array<double, 4>> path;
  std::istringstream in(text);
  for (std::string wp; std::getline(in, wp, ';');) {
    std::array<double, 4> w{{0, 0, 0, 0}};
    std::istringstream ws(wp);
    int n = 0;
    for (std::string num; std::getline(ws, num, ',');) {
      char *end = nullptr;
      const double v = std::strtod(num.c_str(), &end);
      if (num.empty() || end == num.c_str() || *end != 0 || !std::isfinite(v) || n > dim)
        bad(std::string(opt) + ": waypoint " + std::to_string(path.size()) + " '" + wp + "' is not t,x,y" + (dim == 3 ? ",z" : "") + " (waypoints 't,x,y" + (dim == 3 ? ",z" : "") + "' separated by ';')");
      w[n++] = v;
    }
    if (n != dim + 1)
      bad(std::string(opt) + ": waypoint " + std::to_string(path.size()) + " '" + wp + "' has " + std::to_string(n) + " numbers, expected " + std::to_string(dim + 1) + " (t,x,y" + (dim == 3 ? ",z" : "") + ")");
    if (!path.empty() && !(w[0] > path.back()[0]))
      bad(std::string(opt) + ": waypoint times must increase (waypoint " + std::to_string(path.size()) + " at t = " + fmt(w[0]) + " after t = " + fmt(path.back()[0]) + ")");
    path.push_back(w);
  }
  if (path.size() < 2) bad(std::string(opt) + ": needs at least two waypoints 't,x,y" + (dim == 3 ? ",z" : "") + "' separated by ';'");
  return path;
}

} // namespace

Config Config::from_options(MPI_Comm comm) {
  Config c;
  Raw r;
  const char *failed = nullptr;
  PetscPushErrorHandler(PetscReturnErrorHandler, NULL); // report bad values as one line
  const PetscErrorCode ierr = read_options(comm, c, r, failed);
  PetscPopErrorHandler();
  if (ierr) {
    const char *text = nullptr;
    char *specific = nullptr;
    PetscErrorMessage(ierr, &text, &specific);
    char val[256] = "";
    PetscBool set = PETSC_FALSE;
    if (failed) PetscOptionsGetString(NULL, NULL, failed, val, sizeof val, &set);
    bad(std::string(failed ? failed : "options") + ": invalid value '" + val + "'" + (specific && *specific ? std::string(" (") + specific + ")" : std::string()) +
        "; see granmpm -help");
  }
  if (!r.nonfinite.empty()) bad(r.nonfinite);
  if (c.dim != 2 && c.dim != 3) bad("-dim must be 2 or 3 (got " + std::to_string(c.dim) + ")");
  if (r.dt_conflict) bad("-dt and -dt_auto both given: use a fixed -dt or -dt_auto, not both");
  // 2D runs keep only the first two entries of the 3-vectors; the defaults' z entries stay.
  read_vec("-domain_lo", (int)r.nlo, r.lo, c.dim, c.lo);
  read_vec("-domain_hi", (int)r.nhi, r.hi, c.dim, c.hi);
  if (r.ncells) {
    if (r.ncells != c.dim) bad("-cells: expected " + std::to_string(c.dim) + " comma-separated integers, got " + std::to_string(r.ncells));
    for (int d = 0; d < c.dim; ++d) c.cells[d] = (int)r.cells[d];
  }
  read_vec("-body_lo", (int)r.nblo, r.blo, c.dim, c.body_lo);
  read_vec("-body_hi", (int)r.nbhi, r.bhi, c.dim, c.body_hi);
  read_vec("-velocity", (int)r.nv0, r.v0, c.dim, c.v0);
  read_vec("-gravity", (int)r.ngrav, r.grav, c.dim, c.gravity);
  if (c.dim == 2) c.gravity[2] = c.v0[2] = 0;
  const char *faces[3][2] = {{"-bc_xlo", "-bc_xhi"}, {"-bc_ylo", "-bc_yhi"}, {"-bc_zlo", "-bc_zhi"}};
  for (int d = 0; d < 3; ++d)
    for (int s = 0; s < 2; ++s) c.bc[d][s] = parse_name<BC>(faces[d][s], r.bc[d][s]);
  c.scene = parse_name<SceneKind>("-scene", r.scene);
  for (int k = 0; k < Config::kMaxBodies; ++k) {
    if (!r.bset[k]) continue;
    const std::string b = "-body" + std::to_string(k) + "_";
    BodySpec B = r.bspec[k];
    B.shape = parse_name<BodyShape>(b + "shape", r.bshape[k]);
    B.contact = parse_name<BodyContact>(b + "contact", r.bcontact[k]);
    std::array<double, 3> tmp = B.center;
    read_vec((b + "center").c_str(), (int)r.nbcenter[k], r.bcenter[k], c.dim, tmp);
    B.center = tmp;
    tmp = B.half;
    read_vec((b + "half").c_str(), (int)r.nbhalf[k], r.bhalf[k], c.dim, tmp);
    B.half = tmp;
    tmp = B.velocity;
    read_vec((b + "velocity").c_str(), (int)r.nbvel[k], r.bvel[k], c.dim, tmp);
    B.velocity = tmp;
    tmp = B.force;
    read_vec((b + "force").c_str(), (int)r.nbforce[k], r.bforce[k], c.dim, tmp);
    B.force = tmp;
    if (c.dim == 2) B.center[2] = B.velocity[2] = B.force[2] = 0;
    B.motion = parse_name<BodyMotion>(b + "motion", r.bmotion[k]);
    parse_lock((b + "lock").c_str(), r.block[k], c.dim, B.lock);
    if (B.motion == BodyMotion::Kinematic && !r.bdyn_opt[k].empty()) bad(r.bdyn_opt[k] + " applies to dynamic bodies only: add " + b + "motion dynamic or remove it");
    if (r.bpath[k][0]) {
      B.path = parse_path((b + "path").c_str(), r.bpath[k], c.dim);
      if (r.nbcenter[k] || r.nbvel[k]) bad(b + "path gives the centre and its velocity: remove " + b + (r.nbcenter[k] ? "center" : "velocity"));
      if (B.motion == BodyMotion::Dynamic) bad(b + "path prescribes a kinematic body's motion: remove it or use " + b + "motion kinematic");
      for (int d = 0; d < 3; ++d) B.center[d] = B.path[0][1 + d];
    }
    if (B.motion == BodyMotion::Dynamic && !r.binertia_set[k]) B.inertia = uniform_inertia(B); // 0 for a plane or ring: validate() asks for it
    B.index = k;
    c.bodies.push_back(B);
  }
  {
    int k = -1;
    for (size_t i = 0; i < material_registry().size(); ++i)
      if (material_registry()[i].info.name == std::string(r.material)) k = (int)i;
    if (k < 0) bad(std::string("-material: unknown value '") + r.material + "' (choose " + material_names() + ")");
    c.material = (MaterialKind)k;
  }
  for (const auto &kv : r.model_names)
    for (const ParamDecl *p : declared_params())
      if (kv.first == p->option) {
        std::vector<std::string> names;
        std::istringstream in(p->choices);
        for (std::string n; std::getline(in, n, '|');) names.push_back(n);
        std::vector<const char *> ptrs;
        for (const std::string &n : names) ptrs.push_back(n.c_str());
        *c.param_slot(p->option) = choose(p->option, kv.second, ptrs);
      }
  c.fluidity_step = (FluidityStepKind)choose("-fluidity_step", r.fstep, {"explicit", "implicit"});
  c.fluidity_laplacian = (LaplacianStencil)choose("-fluidity_laplacian", r.flap, {"compact", "box"});
  c.shape = parse_name<ShapeKind>("-shape", r.shape);
  c.transfer = parse_name<TransferKind>("-transfer", r.transfer);
  c.update = parse_name<UpdateOrder>("-update", r.update);
  c.time_integrator = (TimeIntegrator)choose("-time_integrator", r.integrator, {"explicit", "implicit", "implicit_coupled"});
  c.implicit.assembled_jacobian = choose("-implicit_jacobian", r.ijac, {"mf_operator", "assembled"}) == 1;
  c.implicit.scaled_tangent = choose("-implicit_tangent", r.itan, {"elastic", "scaled"}) == 1;
  c.stress_update = (StressUpdate)choose("-stress_update", r.stress_update, {"implicit", "explicit"});
  c.fluidity_map = parse_name<FluidityMap>("-fluidity_map", r.fmap);
  c.fluidity_bc = (FluidityBC)choose("-fluidity_bc", r.fbc, {"zero_flux", "dirichlet"});
  c.fluidity_quadrature = (FluidityQuadrature)choose("-fluidity_quadrature", r.fquad, {"particle", "cell"});
  c.fluidity_solver = (FluiditySolverKind)choose("-fluidity_solver", r.fsolver, {"auto", "direct", "iterative"});
  c.body_fluidity_bc = (BodyFluidityBC)choose("-body_fluidity_bc", r.bfbc, {"zero_flux", "zero"});
  c.density = parse_name<DensityMethod>("-density", r.density);
  c.output_dir = r.outdir;
  c.checkpoint_file = r.ckfile;
  c.restart = r.restart;
  c.checkpoint_on_instability = choose("-on_instability", r.oninst, {"abort", "checkpoint_and_abort"}) == 1;
  // b: given directly, or derived from mu_2 and I_0 when those are given and -b is not.
  if (!r.b_set && (r.mu2_set || r.I0_set)) {
    if (!(c.gran.mu_2 > c.gran.mu_s)) bad("-mu_2 must be > -mu_s (got mu_2 = " + fmt(c.gran.mu_2) + ", mu_s = " + fmt(c.gran.mu_s) + ")");
    if (!(c.gran.I_0 > 0)) bad("-I_0 must be > 0 (got " + fmt(c.gran.I_0) + ")");
    c.gran.b = (c.gran.mu_2 - c.gran.mu_s) / c.gran.I_0;
    c.b_given = false;
  }
  c.validate();
  int nranks = 1;
  MPI_Comm_size(comm, &nranks);
  const std::string procs = check_procs(c, nranks);
  if (!procs.empty()) bad(procs);
  for (const Finding &f : physics_checks(c)) {
    if (f.error) bad(f.msg);
    PetscFPrintf(comm, PETSC_STDERR, "granmpm: warning: %s\n", f.msg.c_str());
  }
  if (c.memory_check) {
    // Before anything is allocated: the estimate against MemAvailable of every node of
    // the run (read by one rank per node, summed over the nodes).
    MPI_Comm node;
    MPI_Comm_split_type(comm, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node);
    int node_rank = 0;
    MPI_Comm_rank(node, &node_rank);
    MPI_Comm_free(&node);
    double mine[2] = {0, 0}, sum[2] = {0, 0};
    if (node_rank == 0) {
      std::ifstream f("/proc/meminfo");
      std::string key;
      double kb = 0;
      while (f >> key >> kb)
        if (key == "MemAvailable:") mine[0] = kb * 1024.0;
        else f.ignore(256, '\n');
      mine[1] = 1;
    }
    MPI_Allreduce(mine, sum, 2, MPI_DOUBLE, MPI_SUM, comm);
    const std::string msg = check_memory(estimate_memory(c), sum[0], "MemAvailable of /proc/meminfo summed over the " + fmt(sum[1]) + " node(s) of the run");
    if (!msg.empty()) bad(msg);
  }
  return c;
}

std::vector<std::pair<std::string, std::string>> Config::signature() const {
  std::vector<std::pair<std::string, std::string>> s;
  // Full precision: a restart must not accept a changed value that prints alike.
  auto exact = [](double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%.17g", v);
    return std::string(b);
  };
  auto vec = [&](const std::array<double, 3> &a) {
    std::string r;
    for (int d = 0; d < dim; ++d) r += (d ? "," : "") + exact(a[d]);
    return r;
  };
  s.push_back({"-dim", std::to_string(dim)});
  s.push_back({"-scene", to_string(scene)});
  s.push_back({"-domain_lo", vec(lo)});
  s.push_back({"-domain_hi", vec(hi)});
  std::string cl;
  for (int d = 0; d < dim; ++d) cl += (d ? "," : "") + std::to_string(cells[d]);
  s.push_back({"-cells", cl});
  const char *faces[3][2] = {{"-bc_xlo", "-bc_xhi"}, {"-bc_ylo", "-bc_yhi"}, {"-bc_zlo", "-bc_zhi"}};
  for (int d = 0; d < dim; ++d)
    for (int f = 0; f < 2; ++f) s.push_back({faces[d][f], to_string(bc[d][f])});
  s.push_back({"-material", to_string(material)});
  const char *shapes[] = {"linear", "gimp", "bspline2"}, *transfers[] = {"pic", "flip", "apic"};
  s.push_back({"-shape", shapes[(int)shape]});
  s.push_back({"-transfer", transfers[(int)transfer]});
  s.push_back({"-ppc", std::to_string(ppc)});
  // Physics: body forces, boundaries, material, scheme details, the initial state. Time,
  // output and solver options (-t_end, -dt, -cfl, -output_*, -fluidity_step,
  // -time_integrator, -implicit_*, KSP/SNES options, load balance) may change.
  auto flag = [](bool b) { return std::string(b ? "true" : "false"); };
  s.push_back({"-gravity", vec(gravity)});
  s.push_back({"-gravity_ramp", exact(gravity_ramp)});
  s.push_back({"-damping", exact(damping)});
  s.push_back({"-wall_friction", exact(wall_friction)});
  s.push_back({"-E", exact(E)});
  s.push_back({"-nu", exact(nu)});
  s.push_back({"-rho", exact(rho)});
  s.push_back({"-density", std::to_string((int)density)});
  s.push_back({"-sobel_threshold", exact(sobel_threshold)});
  s.push_back({"-volumetric_average", flag(vol_cell_average)});
  s.push_back({"-update", std::to_string((int)update)});
  if (transfer == TransferKind::FLIP) s.push_back({"-flip_alpha", exact(flip_alpha)});
  if (granular()) {
    s.push_back({"-mu_s", exact(gran.mu_s)});
    s.push_back({"-b", exact(gran.b)});
    s.push_back({"-d", exact(gran.d)});
    s.push_back({"-rho_s", exact(gran.rho_s)});
    s.push_back({"-rho_c", exact(gran.rho_c)});
    s.push_back({"-stress_update", std::to_string((int)stress_update)});
  }
  if (material == MaterialKind::Nonlocal || material == MaterialKind::Dynamic) {
    s.push_back({"-A", exact(gran.A)});
    s.push_back({"-fluidity_map", std::to_string((int)fluidity_map)});
    s.push_back({"-fluidity_bc", std::to_string((int)fluidity_bc)});
    s.push_back({"-fluidity_laplacian", std::to_string((int)fluidity_laplacian)});
  }
  for (const ParamDecl &p : material_entry(material).info.params)
    s.push_back({p.option, p.choices.empty() ? exact(param(p.option)) : std::to_string((int)param(p.option))});
  s.push_back({"-p0", exact(p0)});
  s.push_back({"-velocity", vec(v0)});
  s.push_back({"-body_lo", vec(body_lo)});
  s.push_back({"-body_hi", vec(body_hi)});
  s.push_back({"-geostatic", flag(geostatic)});
  if (scene == SceneKind::Block) s.push_back({"-spin", exact(spin)});
  if (scene == SceneKind::Bar) s.push_back({"-bar_amplitude", exact(bar_amplitude)});
  if (scene == SceneKind::Chute) s.push_back({"-chute_prestress", flag(chute_prestress)});
  if (scene == SceneKind::Silo) {
    s.push_back({"-silo_plate_y", exact(silo_plate_y)});
    s.push_back({"-silo_orifice", exact(silo_orifice)});
    s.push_back({"-silo_orifice_x", exact(silo_orifice_x)});
    if (dim == 3) s.push_back({"-silo_orifice_z", exact(silo_orifice_z)});
  }
  // Rigid bodies are part of the scene: their pose at the restart time follows from these.
  if (scene == SceneKind::Annulus) {
    s.push_back({"-annulus_ri", exact(annulus_ri)});
    s.push_back({"-annulus_ro", exact(annulus_ro)});
    s.push_back({"-annulus_omega", exact(annulus_omega)});
  }
  for (const BodySpec &b : bodies) {
    const std::string k = "-body" + std::to_string(b.index) + "_";
    s.push_back({k + "shape", name_of(b.shape)});
    s.push_back({k + "center", vec(b.center)});
    s.push_back({k + "radius", exact(b.radius)});
    s.push_back({k + "half", vec(b.half)});
    s.push_back({k + "angle", exact(b.angle)});
    s.push_back({k + "omega", exact(b.omega)});
    s.push_back({k + "velocity", vec(b.velocity)});
    s.push_back({k + "contact", b.contact == BodyContact::Sticky ? "sticky" : "friction"});
    s.push_back({k + "friction", exact(b.friction)});
    s.push_back({k + "motion", b.motion == BodyMotion::Dynamic ? "dynamic" : "kinematic"});
    std::string path, lock;
    for (const auto &w : b.path) {
      path += path.empty() ? "" : ";";
      for (int d = 0; d <= dim; ++d) path += (d ? "," : "") + exact(w[d]);
    }
    const char *dofs[] = {"x", "y", "z", "rot"};
    for (int d = 0; d < 4; ++d)
      if (b.lock[d]) lock += (lock.empty() ? "" : ",") + std::string(dofs[d]);
    s.push_back({k + "path", path.empty() ? "none" : path});
    if (b.motion == BodyMotion::Dynamic) {
      s.push_back({k + "mass", exact(b.mass)});
      s.push_back({k + "inertia", exact(b.inertia)});
      s.push_back({k + "force", vec(b.force)});
      s.push_back({k + "torque", exact(b.torque)});
      s.push_back({k + "damping", exact(b.damping)});
      s.push_back({k + "angular_damping", exact(b.angular_damping)});
      s.push_back({k + "lock", lock.empty() ? "none" : lock});
    }
  }
  if (!bodies.empty() || scene == SceneKind::Annulus) {
    s.push_back({"-body_contact_layer", exact(body_contact_layer)});
    s.push_back({"-body_fluidity_bc", std::to_string((int)body_fluidity_bc)});
  }
  return s;
}

void Config::validate() const {
  const char *axes = "xyz";
  if (dim != 2 && dim != 3) bad("-dim must be 2 or 3 (got " + std::to_string(dim) + ")");
  double h = 0;
  for (int d = 0; d < dim; ++d) {
    const std::string ax(1, axes[d]);
    if (!(hi[d] > lo[d])) bad("-domain_hi must exceed -domain_lo in " + ax + " (got " + fmt(lo[d]) + " .. " + fmt(hi[d]) + ")");
    if (cells[d] < 1) bad("-cells must be >= 1 in every direction (got " + std::to_string(cells[d]) + " in " + ax + ")");
    const double hd = (hi[d] - lo[d]) / cells[d];
    if (d == 0) h = hd;
    else if (std::fabs(hd - h) > 1e-9 * h)
      bad("-cells: cells must be square (spacing " + fmt(h) + " in x but " + fmt(hd) + " in " + ax + "); adjust -cells or -domain_lo/-domain_hi");
    if ((bc[d][0] == BC::Periodic) != (bc[d][1] == BC::Periodic))
      bad("-bc_" + ax + "lo/-bc_" + ax + "hi: periodic must be set on both faces of a direction");
    if (bc[d][0] == BC::Periodic && cells[d] < 4) bad("-cells: a periodic direction needs at least 4 cells (got " + std::to_string(cells[d]) + " in " + ax + ")");
  }
  if (ppc < 1 || ppc > 8) bad("-ppc must be in 1..8 (got " + std::to_string(ppc) + ")");
  if (!(E > 0)) bad("-E must be > 0 (got " + fmt(E) + ")");
  if (!(nu > -1.0 && nu < 0.5)) bad("-nu must satisfy -1 < nu < 0.5 (got " + fmt(nu) + ")");
  if (!(rho > 0)) bad("-rho must be > 0 (got " + fmt(rho) + ")");
  if (!(cfl > 0 && cfl <= 1)) bad("-cfl must be in (0, 1] (got " + fmt(cfl) + ")");
  if (!(dt >= 0)) bad("-dt must be >= 0 (0 = automatic; got " + fmt(dt) + ")");
  if (!(t_end > 0)) bad("-t_end must be > 0 (got " + fmt(t_end) + ")");
  if (!(flip_alpha >= 0 && flip_alpha <= 1)) bad("-flip_alpha must be in [0, 1] (got " + fmt(flip_alpha) + ")");
  if (!(gravity_ramp >= 0)) bad("-gravity_ramp must be >= 0 (got " + fmt(gravity_ramp) + ")");
  if (!(wall_friction >= 0)) bad("-wall_friction must be >= 0 (got " + fmt(wall_friction) + ")");
  if (!(damping >= 0)) bad("-damping must be >= 0 (got " + fmt(damping) + ")");
  if (!(p0 >= 0)) bad("-p0 must be >= 0 (got " + fmt(p0) + ")");
  if (output_interval < 0) bad("-output_interval must be >= 0 (got " + std::to_string(output_interval) + ")");
  if (fluidity_pc_interval < 1) bad("-fluidity_pc_interval must be >= 1 (got " + std::to_string(fluidity_pc_interval) + ")");
  if (fluidity_resolve_max < 1) bad("-fluidity_resolve_max must be >= 1 (got " + std::to_string(fluidity_resolve_max) + ")");
  if (!(fluidity_resolve_tol >= 0)) bad("-fluidity_resolve_tol must be >= 0 (got " + fmt(fluidity_resolve_tol) + ")");
  if (progress_interval < 0) bad("-progress_interval must be >= 0 (got " + std::to_string(progress_interval) + ")");
  if (output_dir.empty()) bad("-output_dir must not be empty");
  if (checkpoint_interval < 0) bad("-checkpoint_interval must be >= 0 (got " + std::to_string(checkpoint_interval) + ")");
  if (!(energy_bound_factor > 1)) bad("-energy_bound_factor must be > 1 (got " + fmt(energy_bound_factor) + ")");
  for (int d = 0; d < 3; ++d)
    if (procs[d] < 0) bad(std::string("-da_processors_") + "xyz"[d] + " must be >= 0 (got " + std::to_string(procs[d]) + ")");
  for (const ParamDecl &p : material_entry(material).info.params)
    if (p.choices.empty() && !p.valid(param(p.option))) bad(std::string(p.option) + " must be " + range_text(p) + " (got " + fmt(param(p.option)) + ")");
  if (material == MaterialKind::DruckerPrager && !(gran.rho_c >= 0)) bad("-rho_c must be >= 0 (got " + fmt(gran.rho_c) + ")");
  if (material == MaterialKind::MuI || material == MaterialKind::Nonlocal || material == MaterialKind::Dynamic) {
    if (!(gran.mu_s > 0)) bad("-mu_s must be > 0 (got " + fmt(gran.mu_s) + ")");
    if (!(gran.b > 0)) bad("-b must be > 0 (got " + fmt(gran.b) + ")");
    if (!(gran.d > 0)) bad("-d must be > 0 (got " + fmt(gran.d) + ")");
    if (!(gran.rho_s > 0)) bad("-rho_s must be > 0 (got " + fmt(gran.rho_s) + ")");
    if (!(gran.A >= 0)) bad("-A must be >= 0 (got " + fmt(gran.A) + ")");
    if (!(gran.rho_c >= 0 && gran.rho_c <= gran.rho_s)) bad("-rho_c must be in [0, rho_s = " + fmt(gran.rho_s) + "] (got " + fmt(gran.rho_c) + ")");
    if (!(gran.mu_2 > gran.mu_s)) bad("-mu_2 must be > -mu_s (got mu_2 = " + fmt(gran.mu_2) + ", mu_s = " + fmt(gran.mu_s) + ")");
    if (!(gran.I_0 > 0)) bad("-I_0 must be > 0 (got " + fmt(gran.I_0) + ")");
  }
  if (time_integrator == TimeIntegrator::ImplicitCoupled) {
    if (material != MaterialKind::Nonlocal)
      bad(std::string("-time_integrator implicit_coupled solves the steady nonlocal fluidity with the momentum and needs -material nonlocal (got ") + to_string(material) +
          "); use -time_integrator implicit for elastic|hypoelastic|mu_i|drucker_prager");
    if (gran.A == 0) bad("-time_integrator implicit_coupled: -A 0 has no fluidity equation (g = g_loc); use -material mu_i with -time_integrator implicit");
    if (fluidity_bc != FluidityBC::ZeroFlux) bad("-fluidity_bc dirichlet is not supported with -time_integrator implicit_coupled; use -fluidity_bc zero_flux");
    if (stress_update != StressUpdate::Implicit)
      bad("-stress_update explicit is not supported with -time_integrator implicit_coupled (its plastic flow is stable only for G dt / eta < 2); use -stress_update implicit");
    if (implicit.theta != 1.0) bad("-implicit_theta must be 1 with -time_integrator implicit_coupled (the fluidity equation holds at the end of the step; got " + fmt(implicit.theta) + ")");
  }
  if (time_integrator == TimeIntegrator::Implicit || time_integrator == TimeIntegrator::ImplicitCoupled) {
    if (time_integrator == TimeIntegrator::Implicit && (material == MaterialKind::Nonlocal || material == MaterialKind::Dynamic))
      bad(std::string("-time_integrator implicit does not support -material ") + to_string(material) +
          " (the fluidity is not part of the implicit solve); use -material elastic|hypoelastic|mu_i|drucker_prager, -time_integrator implicit_coupled (nonlocal) or -time_integrator explicit");
    if (!material_entry(material).info.implicit)
      bad(std::string("-time_integrator implicit does not support -material ") + to_string(material) + " (its particle state is not part of the implicit solve); use -time_integrator explicit");
    if (update != UpdateOrder::USL) bad("-update usf|musl order the explicit step only; the implicit step has its own order (omit -update or use usl)");
    if (wall_friction > 0) bad("-wall_friction: Coulomb wall friction is not supported with -time_integrator implicit (slip faces are frictionless there)");
    if (!bodies.empty() || scene == SceneKind::Annulus)
      bad("-time_integrator implicit does not support rigid bodies (-body<k>_shape, -scene annulus): their contact acts in the explicit grid update; use -time_integrator explicit");
    if (vol_cell_average) bad("-volumetric_average is not supported with -time_integrator implicit; use -time_integrator explicit");
    if (implicit.assembled_jacobian && material != MaterialKind::LinearElastic)
      bad("-implicit_jacobian assembled is the exact Jacobian only for -material elastic; use -implicit_jacobian mf_operator");
    if (!(implicit.theta >= 0.5 && implicit.theta <= 1)) bad("-implicit_theta must be in [0.5, 1] (got " + fmt(implicit.theta) + ")");
    if (implicit.grow_its < 0) bad("-implicit_grow_its must be >= 0 (got " + std::to_string(implicit.grow_its) + ")");
    if (!(implicit.grow_factor >= 1)) bad("-implicit_grow_factor must be >= 1 (got " + fmt(implicit.grow_factor) + ")");
    if (!(implicit.dt_max >= 0)) bad("-implicit_dt_max must be >= 0 (got " + fmt(implicit.dt_max) + ")");
    if (!(implicit.dt_min >= 0)) bad("-implicit_dt_min must be >= 0 (got " + fmt(implicit.dt_min) + ")");
    if (implicit.max_retries < 0) bad("-implicit_max_retries must be >= 0 (got " + std::to_string(implicit.max_retries) + ")");
    if (!(implicit.force_tol > 0)) bad("-implicit_force_tol must be > 0 (got " + fmt(implicit.force_tol) + ")");
  }
  if (scene == SceneKind::Chute) {
    if (!is_periodic(1)) bad("-scene chute: the chute is periodic in y (set -bc_ylo periodic -bc_yhi periodic)");
  }
  if (scene == SceneKind::Silo) {
    if (!(silo_plate_y > lo[1] && silo_plate_y < hi[1])) bad("-silo_plate_y must lie inside the domain in y (got " + fmt(silo_plate_y) + ")");
    if (!(silo_orifice > 0)) bad("-silo_orifice must be > 0 (got " + fmt(silo_orifice) + ")");
    if (bc[1][0] != BC::Outlet) bad("-scene silo: particles leave below the plate, set -bc_ylo outlet");
  }
  if (body_fluidity_bc == BodyFluidityBC::Zero && material != MaterialKind::Nonlocal)
    bad("-body_fluidity_bc zero acts on the steady fluidity solve: it needs -material nonlocal (got " + std::string(to_string(material)) + ")");
  if (body_fluidity_bc == BodyFluidityBC::Zero && bodies.empty() && scene != SceneKind::Annulus)
    bad("-body_fluidity_bc zero needs rigid bodies (-body<k>_shape or -scene annulus)");
  if (!(body_contact_layer >= 0 && body_contact_layer <= 2)) bad("-body_contact_layer must be in [0, 2] cells (got " + fmt(body_contact_layer) + ")");
  if (!(balance_threshold == 0 || balance_threshold > 1))
    bad("-balance_threshold must be > 1 (max/mean particles per rank) or 0 to never rebalance (got " + fmt(balance_threshold) + ")");
  if (balance_interval < 1) bad("-balance_interval must be >= 1 (got " + std::to_string(balance_interval) + ")");
  if (sort_interval < 0) bad("-sort_interval must be >= 0 (0: never; got " + std::to_string(sort_interval) + ")");
  if (bodies_interval < 1) bad("-bodies_interval must be >= 1 (got " + std::to_string(bodies_interval) + ")");
  if ((int)bodies.size() > kMaxBodies) bad("at most " + std::to_string(kMaxBodies) + " rigid bodies (-body0_ .. -body3_)");
  for (size_t k = 0; k < bodies.size(); ++k) {
    const BodySpec &B = bodies[k];
    const std::string b = "-body" + std::to_string(B.index) + "_";
    if ((B.shape == BodyShape::Disk || B.shape == BodyShape::Ring) && !(B.radius > 0)) bad(b + "radius must be > 0 (got " + fmt(B.radius) + ")");
    if (B.shape == BodyShape::Box)
      for (int d = 0; d < dim; ++d)
        if (!(B.half[d] > 0)) bad(b + "half must be > 0 in every direction (got " + fmt(B.half[d]) + " in " + std::string(1, axes[d]) + ")");
    if (!(B.friction >= 0)) bad(b + "friction must be >= 0 (got " + fmt(B.friction) + ")");
    if (!std::isfinite(B.omega)) bad(b + "omega must be finite");
    if (B.path.size() == 1) bad(b + "path needs at least two waypoints");
    for (size_t i = 1; i < B.path.size(); ++i)
      if (!(B.path[i][0] > B.path[i - 1][0])) bad(b + "path: waypoint times must increase");
    if (B.motion == BodyMotion::Dynamic) {
      if (!B.path.empty()) bad(b + "path prescribes a kinematic body's motion: remove it or use " + b + "motion kinematic");
      if (!(B.mass > 0)) bad(b + "mass must be > 0 for a dynamic body (got " + fmt(B.mass) + ")");
      if (!B.lock[3] && !(B.inertia > 0))
        bad(b + "inertia must be > 0 for a dynamic body with free rotation (got " + fmt(B.inertia) + (B.shape == BodyShape::Plane || B.shape == BodyShape::Ring ? std::string("; a ") + name_of(B.shape) + " has no default" : std::string()) + "): give it, or " + b + "lock rot");
      if (!(B.damping >= 0)) bad(b + "damping must be >= 0 (got " + fmt(B.damping) + ")");
      if (!(B.angular_damping >= 0)) bad(b + "angular_damping must be >= 0 (got " + fmt(B.angular_damping) + ")");
    }
  }
  if (scene == SceneKind::Annulus) {
    if (!(annulus_ri > 0)) bad("-annulus_ri must be > 0 (got " + fmt(annulus_ri) + ")");
    if (!(annulus_ro > annulus_ri)) bad("-annulus_ri must be < -annulus_ro (got Ri = " + fmt(annulus_ri) + ", Ro = " + fmt(annulus_ro) + ")");
    for (int d = 0; d < 2; ++d)
      if (!(0.5 * (hi[d] - lo[d]) > annulus_ro)) bad("-scene annulus: the domain must contain the outer ring's circle (half width " + fmt(0.5 * (hi[d] - lo[d])) + " m in " + std::string(1, axes[d]) + " <= -annulus_ro " + fmt(annulus_ro) + "); enlarge -domain_lo/-domain_hi");
    if (is_periodic(0) || is_periodic(1)) bad("-scene annulus: the domain faces must not be periodic (set -bc_xlo/-bc_xhi/-bc_ylo/-bc_yhi sticky)");
    if (dim == 2 && (gravity[0] != 0 || gravity[1] != 0)) bad("-scene annulus has no gravity in 2D (its reference assumes uniform pressure): set -gravity 0,0");
    // 3D (Taylor-Couette): the cylinders' axis is z, so gravity may only act along z.
    if (dim == 3 && (gravity[0] != 0 || gravity[1] != 0)) bad("-scene annulus in 3D: gravity must be along the cylinders' axis z (set -gravity 0,0,gz)");
    if (!bodies.empty()) bad("-scene annulus builds its own two bodies from -annulus_ri/-annulus_ro/-annulus_omega: remove the -body<k>_ options");
    // Every material is accepted: the scene skips its 1D reference where it does not apply (scene.cpp).
  }
  if (scene == SceneKind::Bar) {
    if (bc[0][0] != BC::Sticky) bad("-scene bar: the bar is fixed at x = domain_lo (set -bc_xlo sticky)");
  }
}

} // namespace granmpm
