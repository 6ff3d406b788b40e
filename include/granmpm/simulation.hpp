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

#include "granmpm/implicit.hpp"
#include "granmpm/modules.hpp"
#include "granmpm/state.hpp"

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

template <int dim>
class Simulation final : public State<dim>, public StepOps<dim> {
public:
  using State<dim>::cfg, State<dim>::comm, State<dim>::rank, State<dim>::size, State<dim>::time, State<dim>::nsteps, State<dim>::wave_speed,
      State<dim>::vmax, State<dim>::plastic_limit, State<dim>::grid, State<dim>::particles, State<dim>::material, State<dim>::shape,
      State<dim>::bodies, State<dim>::body_names, State<dim>::body_corrections, State<dim>::output, State<dim>::modules, State<dim>::totals,
      State<dim>::gather, State<dim>::gravity_factor, State<dim>::grid_velocity_at_particles;
  Simulation(MPI_Comm comm, const Config &cfg);
  ~Simulation() = default;

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

  // The solvers of the modules that hold them (null when the scene has none).
  Owned<FluiditySolver<dim>> fluidity;      // steady nonlocal model (not with implicit_coupled)
  Owned<DynamicFluidity<dim>> dyn_fluidity; // dynamical model
  Owned<CellDensity<dim>> density;          // elemental/hybrid rules only
  std::unique_ptr<ImplicitSolver<dim>> implicit; // -time_integrator implicit|implicit_coupled only
  // Called once after the first step (main checks for unused options there: solver
  // options such as -fluidity_ksp_view are only read during the first solve).
  std::function<void()> after_first_step;
  // Called in setup after the built-in modules are added: a test (or a tool) appends its
  // own modules to modules (docs/architecture.md, "add a module").
  std::function<void(Simulation &)> extra_modules;
  // Optional particle fields a test's modules need (registered at set-up; name, doubles).
  std::vector<std::pair<std::string, int>> extra_fields;
  std::string stage_summary;  // what setup decided to build

  // The parts of a step (public for tests; step() is the only caller in the solver).
  using typename StepOps<dim>::G2PMode;
  using StepOps<dim>::kVel, StepOps<dim>::kL, StepOps<dim>::kMove, StepOps<dim>::kStoreXv, StepOps<dim>::kApplyXv, StepOps<dim>::kC;
  void p2g(bool with_force) override;
  void grid_update(double dt, bool with_force);
  void g2p(double dt, unsigned mode) override;
  void constitutive(double dt) override;
  double min_node_mass() const override { return m_min_; }
  const double *body_acceleration() const override { return body_acc_; }
  void migrate();
  void init_material_state();

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
  // The single rebuild path: re-creates the grid with ownership ranges l[d] (nodes per
  // rank per direction), every object built on its DMDA (Module::rebuild of each module,
  // the implicit solver), and migrates the particles.
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
  // -on_instability checkpoint_and_abort: the state at the start of the last step before
  // the first sign of instability (instability_sign), restored when a guard stops the run.
  void backup_state();
  void restore_state();
  bool instability_sign(double dt) const;
  std::vector<std::vector<char>> backup_;
  std::vector<double> backup_scalars_;
  std::vector<std::vector<PetscInt>> backup_ranges_;
  bool sign_seen_ = false;
  double ke_backup_ = 0; // kinetic energy of the backed-up state
  double ke_ = 0;
  double &energy_bound_ = this->energy_bound;
  std::string hint_; // appended to instability messages
  double energy_available(const Totals &t);
  template <class S>
  void p2g_impl(const S &s, bool with_force);
  template <class S>
  void g2p_impl(const S &s, double dt, unsigned mode);
  void energy_guard(double ke_all, double vm, PetscInt fastest); // G2P's energy check (collective)
  struct G2PFault { // first particle of a G2P pass that failed a guard
    enum Kind { Moved, NonFinite };
    PetscInt p = -1;
    Kind kind = Moved;
    double u2 = 0; // squared speed it moved with (Moved)
  };
  std::string g2p_fault_text(const ParticleView<dim> &P, const G2PFault &f, double dt) const;

  std::vector<double> Lbuf_, xvel_, lapbuf_;
  // The constitutive update fused into G2P (every pass with kL unless -volumetric_average
  // needs every L first): Lbuf_ then holds one chunk, and constitutive() only reports.
  static constexpr PetscInt kChunk = 256;
  bool fused_ = false;
  UpdateStats fused_st_;
  double fused_all_[3] = {0, 0, 0}; // fused_st_'s guard and limits, reduced with G2P's
  void update_chunk(ParticleView<dim> &P, PetscInt begin, PetscInt end, double dt, UpdateStats &st);
  void finish_constitutive(ParticleView<dim> &P, const UpdateStats &st, const double *reduced = nullptr);
  std::vector<long> cellbuf_; // -volumetric_average: owned-cell index of each particle when L was computed
  void add_modules();
  std::string describe(const ParticleFieldSet &fs) const;
  // Pieces of run() (run.cpp).
  double next_dt() const;
  int handle_signals();
  long signals_[2] = {0, 0}; // {stop, checkpoint} signal flags, max over the ranks (migrate)
  bool signals_reduced_ = false;
  double step_or_restore(double dt);
  void progress_line(double dt, double wall, double sim_t0);
  void print_summary(int interrupted, double wall, long np1, double rss_sum, double imb_start, double imb_end, const Footprint &fp) const;
  // The modules, for the loops of the step (the list does not change after setup).
  const std::vector<Module<dim> *> &modules_view() const { return module_ptrs_; }
  std::vector<Module<dim> *> module_ptrs_;
  BodyModule<dim> *body_module_ = nullptr;
  double last_dt_ = 0;
  double body_acc_[3] = {0, 0, 0};
  double m_min_ = 0;
  PetscLogStage st_migrate_ = 0, st_p2g_ = 0, st_grid_ = 0, st_g2p_ = 0, st_const_ = 0, st_out_ = 0;
};

} // namespace granmpm
