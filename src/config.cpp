// Options parsing and validation. Every option is registered inside one
// PetscOptionsBegin/End block so `granmpm -help` prints it with its default; values are
// validated afterwards so that bad input stops with one line naming the option.
#include "granmpm/config.hpp"
#include "granmpm/body_options.hpp"
#include "granmpm/option_names.hpp"
#include "granmpm/scene.hpp"
#include "options_util.hpp"

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

int Config::nper() const {
  int n = 0;
  for (int d = 0; d < dim; ++d) n += is_periodic(d);
  return n;
}

namespace {

using opt::bad;
using opt::fmt;
using opt::read_vec;

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
  char material[64] = "nonlocal", outdir[PETSC_MAX_PATH_LEN] = "output", ckfile[PETSC_MAX_PATH_LEN] = "", restart[PETSC_MAX_PATH_LEN] = "";
  std::map<std::string, std::string> names; // the options given by a name of an enum (opt::name_option)
  PetscReal lo[3], hi[3], blo[3], bhi[3], v0[3], grav[3];
  PetscInt cells[3];
  PetscInt nlo = 0, nhi = 0, nblo = 0, nbhi = 0, nv0 = 0, ngrav = 0, ncells = 0;
  PetscBool dt_conflict = PETSC_FALSE;
  std::map<std::string, bool> gran_set; // which granular options were given
  std::string nonfinite; // the first real option given a non-finite value (inf, nan, 1e400), or an integer beyond PetscInt
  std::map<std::string, std::string> model_names; // named model parameters given (-dp_match)
  BodyOptions bodies; // -body<k>_*: the body component's options
};


// An option named by an enum value (opt::name_option): inside the section readers.
#define GM_NAME(name, help, value, more)                                                   \
  do {                                                                                     \
    const PetscErrorCode e_ = opt::name_option(PetscOptionsObject, r.names, name, help, value, failed, more); \
    if (e_) return e_;                                                                     \
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


// The material models' own parameters as they declare them (materials/model.hpp).
// (Called inside read_options' PetscOptionsBegin block, whose item list it is given.)
PetscErrorCode read_model_params(PetscOptionItems *PetscOptionsObject, Config &c, Raw &r, const char *&failed) {
  std::string &notes_ = r.nonfinite;
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

// The scene, domain, boundaries, material box, initial state and body forces.
PetscErrorCode read_geometry(PetscOptionItems *PetscOptionsObject, Config &c, Raw &r, const char *&failed) {
  std::string &notes_ = r.nonfinite;
  PetscBool flag;
  PetscInt dim = c.dim, ppc = c.ppc;
  const char *faces[3][2] = {{"-bc_xlo", "-bc_xhi"}, {"-bc_ylo", "-bc_yhi"}, {"-bc_zlo", "-bc_zhi"}};
  PetscFunctionBeginUser;
  GM_OPT("-dim", PetscOptionsInt("-dim", "Spatial dimension: 2 (plane strain) or 3", NULL, dim, &dim, &flag));
  { // the names come from the scene registry (src/scene.cpp)
    char buf[64];
    std::snprintf(buf, sizeof buf, "%s", to_string(c.scene));
    GM_OPT("-scene", PetscOptionsString("-scene", ("Scene: " + scene_names() + " (initial state and diagnostics)").c_str(), NULL, buf, buf, sizeof buf, &flag));
    r.names["-scene"] = buf;
  }
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
      GM_NAME(faces[d][s], "Boundary of this face", c.bc[d][s], "");
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
  PetscBool geo = (PetscBool)c.geostatic;
  GM_OPT("-geostatic", PetscOptionsBool("-geostatic", "Start the material from the geostatic stress sigma_yy = -rho g (top - y), sigma_xx = sigma_zz = nu/(1-nu) sigma_yy", NULL, geo, &geo, &flag));
  c.geostatic = geo;
  GM_OPT("-gravity", PetscOptionsRealArray("-gravity", "Gravity gx,gy[,gz] [m/s^2]", NULL, r.grav, &r.ngrav, &flag));
  if (!flag) r.ngrav = 0;
  GM_OPT("-gravity_ramp", PetscOptionsReal("-gravity_ramp", "Time over which gravity ramps linearly from 0 [s] (0: at once)", NULL, c.gravity_ramp, &c.gravity_ramp, &flag));
  GM_OPT("-wall_friction", PetscOptionsReal("-wall_friction", "Coulomb friction coefficient of slip faces (0: frictionless)", NULL, c.wall_friction, &c.wall_friction, &flag));
  GM_OPT("-damping", PetscOptionsReal("-damping", "Grid velocity damping rate [1/s] (quasi-static runs)", NULL, c.damping, &c.damping, &flag));

  c.dim = (int)dim;
  c.ppc = (int)ppc;
  PetscFunctionReturn(0);
}

// The material: its name, the elastic and granular parameters, the fluidity options and the models' own parameters.
PetscErrorCode read_material(PetscOptionItems *PetscOptionsObject, Config &c, Raw &r, const char *&failed) {
  std::string &notes_ = r.nonfinite;
  PetscBool flag;
  PetscInt fpi = c.fluidity_pc_interval;
  PetscFunctionBeginUser;
  GM_OPT("-material", PetscOptionsString("-material", ("Constitutive model: " + material_names()).c_str(), NULL, r.material, r.material, sizeof r.material, &flag));
  GM_OPT("-E", PetscOptionsReal("-E", "Young's modulus [Pa]", NULL, c.E, &c.E, &flag));
  GM_OPT("-nu", PetscOptionsReal("-nu", "Poisson's ratio (-1 < nu < 0.5)", NULL, c.nu, &c.nu, &flag));
  GM_OPT("-rho", PetscOptionsReal("-rho", "Initial bulk density [kg/m^3]", NULL, c.rho, &c.rho, &flag));
  for (const GranularOption &o : granular_options()) { // the granular family's table (materials/local_mu_i.hpp)
    double &v = c.gran.*o.value;
    PetscBool set = PETSC_FALSE;
    GM_OPT(o.option, PetscOptionsReal(o.option, o.help, NULL, v, &v, &set));
    r.gran_set[o.option] = set;
  }
  GM_NAME("-stress_update", "Granular stress update", c.stress_update, " (implicit: mu(I) seed 000 Alg. 1, nonlocal tau = tau_tr p/(p + G dt g); explicit: seed 000 Alg. 2/3, needs G dt/eta < 2)");
  GM_NAME("-fluidity_map", "Fluidity grid->particle map", c.fluidity_map, "");
  GM_OPT("-fluidity_pc_interval", PetscOptionsInt("-fluidity_pc_interval", "Rebuild the steady fluidity preconditioner every N solves (also when the active set changes or a solve fails); above 1 a restart equals the uninterrupted run only to the KSP tolerance", NULL, fpi, &fpi, &flag));
  GM_NAME("-body_fluidity_bc", "Steady fluidity (-material nonlocal) at rigid-body contact nodes", c.body_fluidity_bc, " (zero: g = 0, as seed 004's code)");
  GM_NAME("-fluidity_bc", "Fluidity boundary condition at walls", c.fluidity_bc, " (dirichlet: g = g_loc)");
  GM_NAME("-fluidity_solver", "Fluidity linear solver (steady model; the dynamical model's implicit step: direct = LU)", c.fluidity_solver,
          " (auto: direct when the band Cholesky cost is small; direct: band Cholesky of the whole system on rank 0 in a fixed node order, CG on it to -fluidity_ksp_rtol, 1 iteration; iterative: CG + BoomerAMG, tune with -fluidity_ksp_*, -fluidity_pc_*)");
  {
    PetscInt frm = c.fluidity_resolve_max;
    GM_OPT("-fluidity_resolve_max", PetscOptionsInt("-fluidity_resolve_max", "Steady fluidity: solve at least every N steps (N = 1: every step); in between g = g_loc + the nonlocal part g - g_loc of the last solve, per particle", NULL, frm, &frm, &flag));
    c.fluidity_resolve_max = (int)frm;
  }
  GM_NAME("-fluidity_quadrature", "Steady fluidity system integrated", c.fluidity_quadrature,
          " (particle: at the particles; cell: exactly over each cell with the cell means of |mu - mu_s|, |mu - mu_s| g_loc and the filled fraction)");
  GM_OPT("-fluidity_resolve_tol", PetscOptionsReal("-fluidity_resolve_tol", "Steady fluidity: target error of the skipped steps, max|g - (g_loc + last nonlocal part)| / max|g| at the next solve; the solve interval adapts to it (and a change of g_loc by 10x this forces a solve)", NULL, c.fluidity_resolve_tol, &c.fluidity_resolve_tol, &flag));
  PetscBool vavg = (PetscBool)c.vol_cell_average;
  GM_OPT("-volumetric_average", PetscOptionsBool("-volumetric_average", "Replace each particle's volumetric strain rate tr L by the volume-weighted mean over its cell (B-bar-like, against volumetric locking of plastic flow)", NULL, vavg, &vavg, &flag));
  c.vol_cell_average = vavg;
  GM_NAME("-density", "Density update", c.density, " (seed 000 3.4)");
  GM_OPT("-sobel_threshold", PetscOptionsReal("-sobel_threshold", "Hybrid density: Sobel gradient magnitude of particles-per-cell marking an edge cell", NULL, c.sobel_threshold, &c.sobel_threshold, &flag));

  {
    const PetscErrorCode e = read_model_params(PetscOptionsObject, c, r, failed);
    if (e) return e;
  }
  GM_NAME("-fluidity_step", "Dynamical fluidity step", c.fluidity_step, " (explicit: seed 004, limits dt; implicit: backward Euler, KSP for the diffusion, coupled local update)");
  GM_NAME("-fluidity_laplacian", "Dynamical fluidity Laplacian on the grid", c.fluidity_laplacian, " (compact: 5/7-point; box: isotropic 9/27-point)");
  c.fluidity_pc_interval = (int)fpi;
  PetscFunctionReturn(0);
}

// The MPM scheme and the implicit momentum step (SNES options themselves take the prefix -implicit_).
PetscErrorCode read_scheme(PetscOptionItems *PetscOptionsObject, Config &c, Raw &r, const char *&failed) {
  std::string &notes_ = r.nonfinite;
  PetscBool flag;
  PetscFunctionBeginUser;
  GM_NAME("-shape", "Shape functions", c.shape, "");
  GM_NAME("-transfer", "Particle velocity transfer", c.transfer, "");
  GM_OPT("-flip_alpha", PetscOptionsReal("-flip_alpha", "FLIP fraction of the PIC/FLIP blend, in [0,1]", NULL, c.flip_alpha, &c.flip_alpha, &flag));
  GM_NAME("-update", "Update ordering", c.update, "");

  // Implicit momentum step (SNES options themselves take the prefix -implicit_).
  GM_NAME("-time_integrator", "Momentum time integration", c.time_integrator,
          " (explicit: symplectic Euler, CFL-limited; implicit: backward Euler on grid velocities, SNES with prefix -implicit_; implicit_coupled: -material nonlocal, grid velocities and the steady fluidity g in one SNES system)");
  GM_NAME("-implicit_jacobian", "Implicit step Jacobian", c.implicit.assembled_jacobian ? ImplicitJacobian::Assembled : ImplicitJacobian::MfOperator,
          " (mf_operator: finite-difference J, assembled M/dt + dt K_elastic as preconditioner; assembled: that matrix as J, exact for -material elastic only)");
  GM_OPT("-implicit_theta", PetscOptionsReal("-implicit_theta", "Implicit step: 1 = backward Euler (default, damps high frequencies), 0.5 = implicit midpoint (second order, no numerical damping); stress and motion use theta v_{n+1} + (1-theta) v_n", NULL, c.implicit.theta, &c.implicit.theta, &flag));
  GM_NAME("-implicit_tangent", "Implicit step preconditioner stiffness", c.implicit.scaled_tangent ? ImplicitTangent::Scaled : ImplicitTangent::Elastic,
          " (elastic: the elastic moduli everywhere, default; scaled: granular materials, per particle, shear modulus times tau/tau_trial of the stress return at the current iterate, none where stress-free)");
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
  PetscFunctionReturn(0);
}

// Time stepping, output, checkpoints, guards, ranks, the annulus scene, load balance.
PetscErrorCode read_run(PetscOptionItems *PetscOptionsObject, Config &c, Raw &r, const char *&failed) {
  std::string &notes_ = r.nonfinite;
  PetscBool flag;
  PetscInt px = 0, py = 0, pz = 0, cki = (PetscInt)c.checkpoint_interval;
  PetscInt max_steps = (PetscInt)c.max_steps, oi = (PetscInt)c.output_interval, pi = (PetscInt)c.progress_interval;
  PetscBool unstable = (PetscBool)c.dt_allow_unstable, quiet = (PetscBool)c.quiet, ofinal = (PetscBool)c.output_final, overwrite = (PetscBool)c.output_overwrite;
  PetscFunctionBeginUser;
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
  GM_NAME("-on_instability", "On NaN, energy blow-up or a runaway particle", c.checkpoint_on_instability ? OnInstability::CheckpointAndAbort : OnInstability::Abort, " (checkpoint_and_abort writes the last good step)");
  GM_OPT("-energy_bound_factor", PetscOptionsReal("-energy_bound_factor", "Instability guard: the kinetic energy may not exceed this multiple of the energy the scene supplies (initial kinetic + elastic + gravity work)", NULL, c.energy_bound_factor, &c.energy_bound_factor, &flag));
  PetscBool memchk = (PetscBool)c.memory_check;
  GM_OPT("-memory_check", PetscOptionsBool("-memory_check", "Refuse at set-up when the estimated memory (grid, particles, solvers) exceeds MemAvailable summed over the run's nodes", NULL, memchk, &memchk, &flag));
  c.memory_check = memchk;
  GM_OPT("-da_processors_x", PetscOptionsInt("-da_processors_x", "MPI ranks along x (0: chosen to minimise the halo)", NULL, px, &px, &flag));
  GM_OPT("-da_processors_y", PetscOptionsInt("-da_processors_y", "MPI ranks along y (0: chosen)", NULL, py, &py, &flag));
  GM_OPT("-da_processors_z", PetscOptionsInt("-da_processors_z", "MPI ranks along z (0: chosen)", NULL, pz, &pz, &flag));
  PetscInt balint = (PetscInt)c.balance_interval, sortint = (PetscInt)c.sort_interval;
  GM_OPT("-balance_threshold", PetscOptionsReal("-balance_threshold", "Load balance: repartition the grid when max/mean particles per rank exceeds this (> 1; 0: never)", NULL, c.balance_threshold, &c.balance_threshold, &flag));
  GM_OPT("-balance_interval", PetscOptionsInt("-balance_interval", "Load balance: steps between imbalance checks (>= 1)", NULL, balint, &balint, &flag));
  GM_OPT("-sort_interval", PetscOptionsInt("-sort_interval", "Reorder each rank's particles by cell index every N steps, for memory locality (0: never; default 20)", NULL, sortint, &sortint, &flag));
  c.balance_interval = balint;
  c.sort_interval = sortint;
  c.max_steps = max_steps;
  c.output_interval = oi;
  c.progress_interval = pi;
  c.dt_allow_unstable = unstable;
  c.quiet = quiet;
  c.output_final = ofinal;
  c.output_overwrite = overwrite;
  c.procs = {(int)px, (int)py, (int)pz};
  c.checkpoint_interval = cki;
  PetscFunctionReturn(0);
}

// Every option, in one PetscOptionsBegin/End block so that -help lists them with their
// defaults: the core's sections, then the components' (the rigid bodies, the scenes).
PetscErrorCode read_options(MPI_Comm comm, Config &c, Raw &r, const char *&failed) {
  PetscErrorCode e = 0;
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm, NULL, "GranMPM options (with no options: the nonlocal vertical chute of seed 000, 20 cells across)", NULL);
  if (!e) e = read_geometry(PetscOptionsObject, c, r, failed);
  if (!e) e = read_material(PetscOptionsObject, c, r, failed);
  if (!e) e = read_scheme(PetscOptionsObject, c, r, failed);
  if (!e) e = read_run(PetscOptionsObject, c, r, failed);
  if (!e) e = r.bodies.read(PetscOptionsObject, c, failed, r.nonfinite);
  if (!e) e = read_scene_options(PetscOptionsObject, c, failed, r.nonfinite);
  PetscOptionsEnd();
  PetscFunctionReturn(e);
}


} // namespace

namespace {

// A value PETSc could not parse: one line naming the option.
[[noreturn]] void read_error(PetscErrorCode ierr, const char *failed) {
  const char *text = nullptr;
  char *specific = nullptr;
  PetscErrorMessage(ierr, &text, &specific);
  char val[256] = "";
  PetscBool set = PETSC_FALSE;
  if (failed) PetscOptionsGetString(NULL, NULL, failed, val, sizeof val, &set);
  bad(std::string(failed ? failed : "options") + ": invalid value '" + val + "'" + (specific && *specific ? std::string(" (") + specific + ")" : std::string()) +
      "; see granmpm -help");
}

// The array options (2D runs keep only the first two entries of the 3-vectors; the
// defaults' z entries stay).
void convert_arrays(Config &c, const Raw &r) {
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
}

// The options given by the name of an enum value (their texts in r.names).
template <class E>
E named(const Raw &r, const char *opt) {
  return parse_name<E>(opt, r.names.at(opt));
}
void convert_names(Config &c, const Raw &r) {
  const char *faces[3][2] = {{"-bc_xlo", "-bc_xhi"}, {"-bc_ylo", "-bc_yhi"}, {"-bc_zlo", "-bc_zhi"}};
  for (int d = 0; d < 3; ++d)
    for (int s = 0; s < 2; ++s) c.bc[d][s] = named<BC>(r, faces[d][s]);
  c.scene = parse_scene("-scene", r.names.at("-scene"));
  c.fluidity_step = named<FluidityStepKind>(r, "-fluidity_step");
  c.fluidity_laplacian = named<LaplacianStencil>(r, "-fluidity_laplacian");
  c.shape = named<ShapeKind>(r, "-shape");
  c.transfer = named<TransferKind>(r, "-transfer");
  c.update = named<UpdateOrder>(r, "-update");
  c.time_integrator = named<TimeIntegrator>(r, "-time_integrator");
  c.implicit.assembled_jacobian = named<ImplicitJacobian>(r, "-implicit_jacobian") == ImplicitJacobian::Assembled;
  c.implicit.scaled_tangent = named<ImplicitTangent>(r, "-implicit_tangent") == ImplicitTangent::Scaled;
  c.stress_update = named<StressUpdate>(r, "-stress_update");
  c.fluidity_map = named<FluidityMap>(r, "-fluidity_map");
  c.fluidity_bc = named<FluidityBC>(r, "-fluidity_bc");
  c.fluidity_quadrature = named<FluidityQuadrature>(r, "-fluidity_quadrature");
  c.fluidity_solver = named<FluiditySolverKind>(r, "-fluidity_solver");
  c.body_fluidity_bc = named<BodyFluidityBC>(r, "-body_fluidity_bc");
  c.density = named<DensityMethod>(r, "-density");
  c.checkpoint_on_instability = named<OnInstability>(r, "-on_instability") == OnInstability::CheckpointAndAbort;
}

// -material from the registry, the models' named parameters, b from mu_2 and I_0.
void convert_material(Config &c, const Raw &r) {
  int k = -1;
  for (size_t i = 0; i < material_registry().size(); ++i)
    if (material_registry()[i].info.name == std::string(r.material)) k = (int)i;
  if (k < 0) bad(std::string("-material: unknown value '") + r.material + "' (choose " + material_names() + ")");
  c.material = (MaterialKind)k;
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
  // b: given directly, or derived from mu_2 and I_0 when those are given and -b is not.
  if (!r.gran_set.at("-b") && (r.gran_set.at("-mu_2") || r.gran_set.at("-I_0"))) {
    const std::string e = derive_b(c.gran);
    if (!e.empty()) bad(e);
    c.b_given = false;
  }
}

// Before anything is allocated: the estimate against MemAvailable of every node of the
// run (read by one rank per node, summed over the nodes).
void check_node_memory(MPI_Comm comm, const Config &c) {
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

} // namespace

Config Config::from_options(MPI_Comm comm) {
  Config c;
  Raw r;
  const char *failed = nullptr;
  PetscPushErrorHandler(PetscReturnErrorHandler, NULL); // report bad values as one line
  const PetscErrorCode ierr = read_options(comm, c, r, failed);
  PetscPopErrorHandler();
  if (ierr) read_error(ierr, failed);
  if (!r.nonfinite.empty()) bad(r.nonfinite);
  if (c.dim != 2 && c.dim != 3) bad("-dim must be 2 or 3 (got " + std::to_string(c.dim) + ")");
  if (r.dt_conflict) bad("-dt and -dt_auto both given: use a fixed -dt or -dt_auto, not both");
  convert_arrays(c, r);
  convert_names(c, r);
  r.bodies.finish(c);
  convert_material(c, r);
  c.output_dir = r.outdir;
  c.checkpoint_file = r.ckfile;
  c.restart = r.restart;
  c.validate();
  int nranks = 1;
  MPI_Comm_size(comm, &nranks);
  const std::string procs = check_procs(c, nranks);
  if (!procs.empty()) bad(procs);
  for (const Finding &f : physics_checks(c)) {
    if (f.error) bad(f.msg);
    PetscFPrintf(comm, PETSC_STDERR, "granmpm: warning: %s\n", f.msg.c_str());
  }
  if (c.memory_check) check_node_memory(comm, c);
  return c;
}

namespace {

using opt::exact;

// The material and the scheme details of the signature.
void material_signature(const Config &c, Signature &s) {
  auto flag = [](bool b) { return std::string(b ? "true" : "false"); };
  s.push_back({"-E", exact(c.E)});
  s.push_back({"-nu", exact(c.nu)});
  s.push_back({"-rho", exact(c.rho)});
  s.push_back({"-density", std::to_string((int)c.density)});
  s.push_back({"-sobel_threshold", exact(c.sobel_threshold)});
  s.push_back({"-volumetric_average", flag(c.vol_cell_average)});
  s.push_back({"-update", std::to_string((int)c.update)});
  if (c.transfer == TransferKind::FLIP) s.push_back({"-flip_alpha", exact(c.flip_alpha)});
  if (c.granular()) {
    for (const GranularOption &o : granular_options())
      if (o.signed_) s.push_back({o.option, exact(c.gran.*o.value)});
    s.push_back({"-stress_update", std::to_string((int)c.stress_update)});
  }
  if (c.material == MaterialKind::Nonlocal || c.material == MaterialKind::Dynamic) {
    s.push_back({"-A", exact(c.gran.A)});
    s.push_back({"-fluidity_map", std::to_string((int)c.fluidity_map)});
    s.push_back({"-fluidity_bc", std::to_string((int)c.fluidity_bc)});
    s.push_back({"-fluidity_laplacian", std::to_string((int)c.fluidity_laplacian)});
  }
  for (const ParamDecl &p : material_entry(c.material).info.params)
    s.push_back({p.option, p.choices.empty() ? exact(c.param(p.option)) : std::to_string((int)c.param(p.option))});
}

// The initial state and the scene's own options (rigid bodies are part of the scene: their
// pose at the restart time follows from these).
void scene_signature(const Config &c, Signature &s) {
  auto flag = [](bool b) { return std::string(b ? "true" : "false"); };
  s.push_back({"-p0", exact(c.p0)});
  s.push_back({"-velocity", opt::vec(c.v0, c.dim)});
  s.push_back({"-body_lo", opt::vec(c.body_lo, c.dim)});
  s.push_back({"-body_hi", opt::vec(c.body_hi, c.dim)});
  s.push_back({"-geostatic", flag(c.geostatic)});
  scene_rules(c.scene).signature(c, s);
  BodyOptions::signature(c, s);
  if (scene_has_bodies(c)) {
    s.push_back({"-body_contact_layer", exact(c.body_contact_layer)});
    s.push_back({"-body_fluidity_bc", std::to_string((int)c.body_fluidity_bc)});
  }
}

} // namespace

// Full precision (opt::exact): a restart must not accept a changed value that prints alike.
// Physics: geometry, body forces, boundaries, material, scheme details, the initial state.
// Time, output and solver options (-t_end, -dt, -cfl, -output_*, -fluidity_step,
// -time_integrator, -implicit_*, KSP/SNES options, load balance) may change.
std::vector<std::pair<std::string, std::string>> Config::signature() const {
  Signature s;
  s.push_back({"-dim", std::to_string(dim)});
  s.push_back({"-scene", to_string(scene)});
  s.push_back({"-domain_lo", opt::vec(lo, dim)});
  s.push_back({"-domain_hi", opt::vec(hi, dim)});
  std::string cl;
  for (int d = 0; d < dim; ++d) cl += (d ? "," : "") + std::to_string(cells[d]);
  s.push_back({"-cells", cl});
  const char *faces[3][2] = {{"-bc_xlo", "-bc_xhi"}, {"-bc_ylo", "-bc_yhi"}, {"-bc_zlo", "-bc_zhi"}};
  for (int d = 0; d < dim; ++d)
    for (int f = 0; f < 2; ++f) s.push_back({faces[d][f], to_string(bc[d][f])});
  s.push_back({"-material", to_string(material)});
  s.push_back({"-shape", name_of(shape)});
  s.push_back({"-transfer", name_of(transfer)});
  s.push_back({"-ppc", std::to_string(ppc)});
  s.push_back({"-gravity", opt::vec(gravity, dim)});
  s.push_back({"-gravity_ramp", exact(gravity_ramp)});
  s.push_back({"-damping", exact(damping)});
  s.push_back({"-wall_friction", exact(wall_friction)});
  material_signature(*this, s);
  scene_signature(*this, s);
  return s;
}


} // namespace granmpm
