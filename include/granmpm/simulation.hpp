// Simulation<dim>: owns the grid, the particles, the optional fluidity solver and the
// output, and runs explicit MPM steps. Simulation::step() reads as the algorithm:
//
//   [fluidity solve] -> P2G -> grid update + BCs -> G2P -> constitutive update -> migrate
//
// with the USF/MUSL variants re-ordering those calls. Each part is a PETSc log stage, so
// -log_view shows where the time goes. What a scene does not need (fluidity, APIC
// matrix, plastic-rate field) is decided once in setup(), never inside particle loops.
#pragma once

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <variant>
#include <vector>

#include "granmpm/config.hpp"
#include "granmpm/grid.hpp"
#include "granmpm/materials/elastic.hpp"
#include "granmpm/materials/local_mu_i.hpp"
#include "granmpm/materials/drucker_prager.hpp"
#include "granmpm/materials/dynamic_ngf.hpp"
#include "granmpm/materials/nonlocal_ngf.hpp"
#include "granmpm/particles.hpp"
#include "granmpm/rigid_body.hpp"

namespace granmpm {

// Set by the SIGTERM/SIGINT handler of main(); the run loop checkpoints and stops (the
// metric "interrupted" is then the signal number; main exits with 128 + it).
extern volatile std::sig_atomic_t stop_signal;
// Set by the SIGUSR1 handler of main(); the run loop writes a checkpoint and continues.
extern volatile std::sig_atomic_t checkpoint_signal;

template <int dim>
class FluiditySolver;
template <int dim>
class Output;
template <int dim>
class CellDensity;
template <int dim>
class DynamicFluidity;
template <int dim>
class ImplicitSolver;

// The dynamical model with how its fluidity is stepped.
struct DynamicNGF {
  DynamicNGFParams P;
  FluidityStep mode;
};
using Material = std::variant<LinearElastic, Hypoelastic, LocalMuI, NonlocalNGF, DynamicNGF, DruckerPrager>;
using Shape = std::variant<LinearShape, GIMPShape, BSpline2Shape>;

// One particle's state, gathered for comparisons and diagnostics.
struct ParticleRecord {
  int64_t id;
  double x[3], v[3], s[6], m, vol, g;
};

struct Totals {
  long n = 0;
  double mass = 0, momentum[3] = {0, 0, 0}, kinetic = 0, vmax = 0;
};

template <int dim>
class Simulation {
public:
  Simulation(MPI_Comm comm, const Config &cfg);
  ~Simulation();

  void setup();
  // Runs to t_end (or max_steps): step, progress lines, output, scene diagnostics.
  // Returns the scene's metrics (errors against its reference).
  std::map<std::string, double> run();
  // One step of size dt (explicit; or implicit, which may take a smaller step after a
  // failed solve). Returns the step taken.
  double step(double dt);
  // Largest stable step from the CFL condition h / (c + |v|max), times -cfl (collective).
  double cfl_dt() const { return cfg.cfl * dt_limit(); }
  // Stability limit of the explicit step: min of the CFL limit h/(c + |v|max) and, for the
  // explicit granular stress updates, the plastic relaxation limit 2/max(G dgdot/dtau).
  double dt_limit() const { return std::min(dt_cfl_limit(), plastic_limit); }
  double dt_cfl_limit() const;

  Totals totals() const;                                 // collective
  std::vector<ParticleRecord> gather(int root = 0) const; // collective; sorted by id on root
  double gravity_factor(double t) const;
  // Velocity of the last grid update interpolated to each local particle (dim per
  // particle): the velocity the particles move with, free of FLIP's particle-level noise.
  std::vector<double> grid_velocity_at_particles();

  const Config cfg;
  MPI_Comm comm;
  int rank = 0, size = 1;
  double time = 0;
  long nsteps = 0;
  double wave_speed = 0; // elastic P-wave speed
  Grid<dim> grid;
  Particles<dim> particles;
  std::unique_ptr<FluiditySolver<dim>> fluidity;        // steady nonlocal model (not with implicit_coupled)
  std::unique_ptr<DynamicFluidity<dim>> dyn_fluidity;   // dynamical model
  std::unique_ptr<Output<dim>> output;
  std::unique_ptr<CellDensity<dim>> density; // elemental/hybrid rules only
  std::unique_ptr<ImplicitSolver<dim>> implicit; // -time_integrator implicit|implicit_coupled only
  // Rigid bodies (-body<k>_*, or the annulus scene's two): grid contact in grid_update,
  // force/torque per step, dynamic bodies advanced at the end of step(), bodies.csv; none
  // when no body is given.
  std::unique_ptr<RigidBodies<dim>> bodies;
  std::vector<std::string> body_names; // how messages name body k (its options)
  long body_corrections = 0; // particles put back onto a body surface they entered by < 1 cell
  Material material;
  Shape shape;
  // Called once after the first step (main checks for unused options there: solver
  // options such as -fluidity_ksp_view are only read during the first solve).
  std::function<void()> after_first_step;
  double vmax = 0;            // max particle speed after the last step
  double plastic_limit = 1e300; // explicit stress updates only (see dt_limit)
  std::string stage_summary;  // what setup decided to build

  // The parts of a step (public for tests; step() is the only caller in the solver).
  enum G2PMode : unsigned { kVel = 1, kL = 2, kMove = 4, kStoreXv = 8, kApplyXv = 16, kC = 32 };
  void p2g(bool with_force);
  void grid_update(double dt, bool with_force);
  void g2p(double dt, unsigned mode);
  void constitutive(double dt);
  void density_update();
  void solve_fluidity();
  void migrate();
  void init_hyperelastic_state();
  // Particles found inside a body (sdf < 0) after the move: put back onto its surface if
  // less than a cell deep (counted, reported at the end), else the run stops naming the body.
  void body_particles();
  void write_bodies_row(); // one row per body to <output_dir>/bodies.csv (rank 0)

  void write_checkpoint(const std::string &path);

  // Load balance. imbalance(): max/mean particles per rank (collective).
  double imbalance() const;
  // The tensor-product split of the current particles: per direction, the per-cell
  // particle counts summed over the other directions, cut into nproc[d] equal shares
  // (balanced_ranges, >= 2 nodes per rank for the width-2 halo). Collective.
  std::vector<std::vector<PetscInt>> balanced_split() const;
  // Every -balance_interval steps (run()): if imbalance() > -balance_threshold and the
  // balanced split lowers it, repartition to it and print the imbalance before/after.
  // Returns true if it repartitioned. Collective.
  bool rebalance();
  // The steady fluidity solver on the current grid, with the body condition (-body_fluidity_bc).
  std::unique_ptr<FluiditySolver<dim>> new_fluidity_solver();
  // The single rebuild path: re-creates the grid with ownership ranges l[d] (nodes per
  // rank per direction), every object built on its DMDA (fluidity solvers, cell density,
  // implicit solver; the nodal fluidity is carried over), and migrates the particles.
  void repartition(const std::vector<std::vector<PetscInt>> &l);
  // Bytes held per particle (swarm fields and the per-particle
  // step buffers of this class) and per grid node (the transfer grid's global and ghosted
  // vectors; fluidity, density and implicit solvers are not counted),
  // summed over ranks and divided by the global particle / node count. Collective.
  struct Footprint {
    double per_particle = 0, per_node = 0;
  };
  Footprint footprint() const;
  // -sort_interval: reorder the particles by cell (Particles::sort_by_cell).
  void sort_particles();
  long rebalances = 0;
  double imbalance_before = 0, imbalance_after = 0; // of the last repartition by rebalance()

private:
  friend class ImplicitSolver<dim>;
  // -on_instability checkpoint_and_abort: the state at the start of the last step before
  // the first sign of instability (instability_sign), restored when a guard stops the run.
  void backup_state();
  void restore_state();
  bool instability_sign(double dt) const;
  std::vector<std::vector<char>> backup_;
  std::vector<double> backup_scalars_, backup_bodies_;
  std::vector<double> backup_g_, backup_fluidity_schedule_; // steady solver: nodal g (next guess), schedule
  std::vector<std::vector<PetscInt>> backup_ranges_;
  bool sign_seen_ = false;
  double ke_backup_ = 0; // kinetic energy of the backed-up state
  double ke_ = 0, energy_bound_ = 0;
  std::string hint_; // appended to instability messages
  double energy_available(const Totals &t);
  template <class S>
  void p2g_impl(const S &s, bool with_force);
  template <class S>
  void g2p_impl(const S &s, double dt, unsigned mode);
  struct G2PFault { // first particle of a G2P pass that failed a guard
    enum Kind { Moved, NonFinite };
    PetscInt p = -1;
    Kind kind = Moved;
    double u2 = 0; // squared speed it moved with (Moved)
  };
  std::string g2p_fault_text(const ParticleView<dim> &P, const G2PFault &f, double dt) const;

  std::vector<double> Lbuf_, xvel_, lapbuf_;
  std::vector<long> cellbuf_; // -volumetric_average: owned-cell index of each particle when L was computed
  std::FILE *bodies_csv_ = nullptr;
  double last_dt_ = 0;
  double body_acc_[3] = {0, 0, 0};
  double m_min_ = 0;
  PetscLogStage st_migrate_ = 0, st_p2g_ = 0, st_grid_ = 0, st_g2p_ = 0, st_const_ = 0, st_fluid_ = 0, st_out_ = 0;
};

} // namespace granmpm
