// Run configuration: every parameter of a GranMPM run, read once at start-up from the
// PETSc options database (command line, -options_file, -options_file_yaml) by
// Config::from_options, which registers each option so that `granmpm -help` lists it.
// Tests build a Config directly.
#pragma once

#include <array>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <petscsys.h>

#include "granmpm/materials/local_mu_i.hpp"
#include "granmpm/rigid_body.hpp"
#include "granmpm/shape.hpp"
#include "granmpm/transfer.hpp"

namespace granmpm {

// A user-facing error: bad input or an unrecoverable run condition. main() prints it as
// one line ("granmpm: error: ...") and exits with status 1. Thrown identically on every
// rank (options are global; run-time checks are reduced first, see collective_fail).
struct UserError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A PETSc call failed; PETSc has already printed its trace.
struct PetscFailure : std::runtime_error {
  PetscErrorCode code;
  explicit PetscFailure(PetscErrorCode c) : std::runtime_error("PETSc error"), code(c) {}
};

#define GM_CALL(...)                                                                       \
  do {                                                                                     \
    PetscErrorCode gm_ierr_ = (__VA_ARGS__);                                               \
    if (PetscUnlikely(gm_ierr_)) throw ::granmpm::PetscFailure(gm_ierr_);                  \
  } while (0)

// Every rank calls this with its own verdict; if any rank failed, every rank throws the
// message of the lowest failing rank. Keeps one-rank failures from hanging the others.
void collective_fail(MPI_Comm comm, bool failed, const std::string &msg);

enum class BC { Sticky = 0, Slip = 1, Periodic = 2, Free = 3, Outlet = 4 };
// The built-in models, in their registration order (src/materials.cpp); models registered
// later (register_material, material.hpp) take the next values.
enum class MaterialKind { LinearElastic = 0, Hypoelastic = 1, MuI = 2, Nonlocal = 3, Dynamic = 4, DruckerPrager = 5 };
enum class FluidityStepKind { Explicit = 0, Implicit = 1 };
enum class LaplacianStencil { Compact = 0, Box = 1 };
enum class UpdateOrder { USL = 0, USF = 1, MUSL = 2 };
// The built-in scenes, in the order of GM_SCENES (src/scene.cpp), whose list gives the names.
enum class SceneKind { Block = 0, Bar = 1, Column = 2, Chute = 3, Collapse = 4, Silo = 5, Annulus = 6 };
enum class FluidityMap { Interpolate = 0, CellAverage = 1 };
enum class FluidityBC { ZeroFlux = 0, Dirichlet = 1 };
enum class FluiditySolverKind { Auto = 0, Direct = 1, Iterative = 2 };
enum class FluidityQuadrature { Particle = 0, Cell = 1 };
// Steady fluidity at rigid-body contact nodes: natural zero flux, or g = 0 (seed 004's code).
enum class BodyFluidityBC { ZeroFlux = 0, Zero = 1 };
enum class DensityMethod { Local = 0, Elemental = 1, Hybrid = 2 };
enum class TimeIntegrator { Explicit = 0, Implicit = 1, ImplicitCoupled = 2 };

// Implicit (backward Euler) momentum step: see include/granmpm/implicit.hpp.
struct ImplicitParams {
  bool assembled_jacobian = false; // -implicit_jacobian assembled (exact for -material elastic only)
  double theta = 1.0;              // 1: backward Euler; 0.5: implicit midpoint (no numerical damping)
  bool scaled_tangent = false;     // preconditioner moduli scaled by the granular stress return
  bool dt_adapt = true;            // grow dt after easy solves, halve and retry after failures
  int grow_its = 4;                // grow dt when SNES converged in at most this many iterations
  double grow_factor = 1.25;
  double dt_max = 0;               // 0: no cap (other than t_end)
  double dt_min = 0;               // 0: 1e-4 times the first step
  int max_retries = 10;            // halvings of one step before giving up
  double force_tol = 1e-10;        // SNES atol = force_tol * the step's force scale
};

const char *to_string(BC);
const char *to_string(MaterialKind);
const char *to_string(SceneKind);
std::string scene_names(); // "block|bar|..." from the scene registry (scene.hpp)
SceneKind parse_scene(const std::string &opt, const std::string &val);

struct Config {
  int dim = 2;

  // Scene and geometry.
  SceneKind scene = SceneKind::Chute;
  std::array<double, 3> lo{{-0.5, 0.0, 0.0}};
  std::array<double, 3> hi{{0.5, 0.2, 0.2}};
  std::array<int, 3> cells{{20, 4, 4}};
  // bc[d][0] lower face, bc[d][1] upper face.
  std::array<std::array<BC, 2>, 3> bc{{{{BC::Sticky, BC::Sticky}}, {{BC::Periodic, BC::Periodic}}, {{BC::Periodic, BC::Periodic}}}};
  std::array<double, 3> body_lo{{-1e300, -1e300, -1e300}}; // clipped to the domain
  std::array<double, 3> body_hi{{1e300, 1e300, 1e300}};
  bool body_clip = false; // -body_clip: a material box beyond the domain is clipped (and the dropped particles counted) instead of refused
  int ppc = 1; // particles per cell per direction
  std::array<double, 3> v0{{0, 0, 0}};
  double p0 = 900;           // initial isotropic pressure [Pa] (chute, block, annulus)
  bool geostatic = false;         // start from sigma_yy = -rho g (top - y), sigma_xx = sigma_zz = K0 sigma_yy
  // The scenes' own options (-spin, -bar_amplitude, -chute_prestress, -silo_*, -annulus_*:
  // declared by each scene, SceneRules::options in scene.hpp), by option name: the values
  // given. scene_param() falls back to the declaring scene's default; set_scene_param()
  // refuses a name no scene declares. (Defined in src/scene.cpp.)
  std::map<std::string, double> scene_params;
  double scene_param(const std::string &option) const;
  void set_scene_param(const std::string &option, double value);
  // Kinematic rigid bodies (-body<k>_*, k < kMaxBodies; see rigid_body.hpp).
  static constexpr int kMaxBodies = 4;
  std::vector<BodySpec> bodies;
  double body_contact_layer = 0.5; // contact nodes: sdf < layer * h
  BodyFluidityBC body_fluidity_bc = BodyFluidityBC::ZeroFlux;
  long bodies_interval = 100;      // steps between rows of bodies.csv
  std::array<double, 3> gravity{{0, -0.8, 0}};
  double gravity_ramp = 0.5; // linear ramp time of gravity [s]; 0 = applied at once
  double damping = 0;        // grid velocity damping rate [1/s]
  double wall_friction = 0;  // Coulomb friction coefficient of slip faces

  // Material.
  MaterialKind material = MaterialKind::Nonlocal;
  double E = 1e8, nu = 0.3, rho = 1500;
  GranularParams gran;
  bool b_given = true; // b from -b (default) or from (mu_2 - mu_s)/I_0
  StressUpdate stress_update = StressUpdate::Implicit;
  FluidityMap fluidity_map = FluidityMap::Interpolate;
  FluidityBC fluidity_bc = FluidityBC::ZeroFlux;
  // Rebuild the fluidity preconditioner every N solves. Default 1: a restart is then
  // bitwise identical (a reused preconditioner cannot be rebuilt from a checkpoint);
  // 20 made the 80-cell chute 2.4x cheaper in the Fluidity stage at the same error.
  int fluidity_pc_interval = 1;
  // Steady fluidity solve (FluiditySolver): direct (band Cholesky on rank 0) or iterative
  // (CG + BoomerAMG); auto picks direct when its factor is cheap (also LU for the
  // dynamical model's implicit step). Re-solved when g_loc at some particle moved by more than
  // fluidity_resolve_tol * max|g| since the last solve, and every fluidity_resolve_max
  // steps; in between g = g_loc + (g - g_loc) of the last solve, per particle.
  FluiditySolverKind fluidity_solver = FluiditySolverKind::Auto;
  int fluidity_resolve_max = 50;
  // Quadrature of the steady fluidity system: at the particles, or exact over each cell
  // with the cell means of the coefficients (positive definite element matrices).
  FluidityQuadrature fluidity_quadrature = FluidityQuadrature::Particle;
  double fluidity_resolve_tol = 1e-3;
  DensityMethod density = DensityMethod::Local;
  // Volumetric strain rate averaged over each cell (B-bar-like): tr L of every particle is
  // replaced by the volume-weighted mean over the particles of its cell (against volumetric
  // locking of isochoric plastic flow on the grid).
  bool vol_cell_average = false;
  // Dynamical nonlocal fluidity (hyperelastic, seed 004). t0 and g0 are declared by the
  // model (dynamic_ngf.hpp: -t0, -g0) and stored here (param_slot) because code and tests
  // set them by name; the other models' own parameters live in model_params.
  double t0 = 1e-4; // fluidity time scale [s]
  double g0 = 1e-8; // initial fluidity [1/s] (g = 0 is a fixed point)
  FluidityStepKind fluidity_step = FluidityStepKind::Implicit;
  LaplacianStencil fluidity_laplacian = LaplacianStencil::Compact;
  // The material model's own parameters (its ParamDecl list, materials/model.hpp), by
  // option name: the values given; param() falls back to the model's default.
  std::map<std::string, double> model_params;
  double param(const std::string &option) const;
  double *param_slot(const std::string &option); // where from_options stores it
  double sobel_threshold = 1.0;

  // MPM scheme.
  ShapeKind shape = ShapeKind::GIMP;
  TransferKind transfer = TransferKind::APIC;
  double flip_alpha = 0.99;
  UpdateOrder update = UpdateOrder::USL;
  TimeIntegrator time_integrator = TimeIntegrator::Explicit;
  ImplicitParams implicit;

  // Time.
  double dt = 0;           // 0: automatic from CFL
  double cfl = 0.5;        // Courant number of the automatic step and of the stability check
  bool dt_allow_unstable = false;
  double t_end = 1.25;
  long max_steps = -1;     // -1: no limit

  // Output.
  std::string output_dir = "output";
  long output_interval = 0; // steps between HDF5/XDMF outputs; 0 = only at the end
  bool output_final = true;
  bool output_overwrite = false; // a new run may replace another run's results in output_dir
  long progress_interval = 1000;
  bool quiet = false;
  std::array<int, 3> procs{{0, 0, 0}}; // ranks per direction (-da_processors_x/y/z), 0: decide
  // Load balance: every balance_interval steps, when max/mean particles per rank exceeds
  // balance_threshold (> 1; 0 = never), the DMDA ownership ranges are recomputed from the
  // per-cell particle counts and the particles migrate (Simulation::rebalance).
  double balance_threshold = 0;
  long balance_interval = 20;
  // Particles reordered by cell index every sort_interval steps (0 = never), for locality.
  // 20: +14-36% particle-steps/s on the 3D B-spline APIC block, neutral in 2D
  // (bench/sorting.py, docs/performance.md).
  long sort_interval = 20;

  // Reliability.
  long checkpoint_interval = 0;   // steps between checkpoints; 0 = none (SIGTERM still writes one)
  std::string checkpoint_file;    // default <output_dir>/checkpoint.h5
  std::string restart;            // checkpoint to continue from
  bool checkpoint_on_instability = false; // -on_instability checkpoint_and_abort
  double energy_bound_factor = 10; // kinetic energy may not exceed this multiple of the energy available
  bool memory_check = true;        // refuse at set-up when the estimated memory exceeds MemAvailable (config_checks.hpp)

  // Derived.
  int nper() const; // periodic directions count (for messages)
  std::string checkpoint_path() const { return checkpoint_file.empty() ? output_dir + "/checkpoint.h5" : checkpoint_file; }
  // The options that define the scene (geometry, material, scheme) as "-option value"
  // lines: a restart must match them.
  std::vector<std::pair<std::string, std::string>> signature() const;
  bool is_periodic(int d) const { return bc[d][0] == BC::Periodic; }
  bool granular() const; // the model's ModelInfo::granular (src/materials.cpp)

  // Reads and validates all options; throws UserError with a one-line cause.
  static Config from_options(MPI_Comm comm);
  // Validates a Config built in code (also called by from_options).
  void validate() const;

private:
  void validate_domain() const; // src/config_validate.cpp
  void validate_material() const;
  void validate_implicit() const;
  void validate_scene() const;
};

} // namespace granmpm
