// Thin modules around the fluidity solvers and the cell density (modules.hpp): they call
// the solvers' public interface at the step's fixed points; the solvers stay as they are.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "granmpm/checkpoint.hpp"
#include "granmpm/density.hpp"
#include "granmpm/dynamic_fluidity.hpp"
#include "granmpm/fluidity.hpp"
#include "granmpm/modules.hpp"

namespace granmpm {

// ---------------------------------------------------------------------------------------
// Silo plate

template <int dim>
SiloPlate<dim>::SiloPlate(const Grid<dim> &grid, double y, double width, double xc, double zc) {
  j_ = (int)std::lround((y - grid.x0[1]) * grid.inv_h);
  r2_ = 0.25 * width * width;
  c_[0] = xc;
  c_[1] = zc;
}

template <int dim>
double SiloPlate<dim>::effective_width(const Grid<dim> &grid) const {
  double r = 0;
  for (int i = 0; i < grid.M[0]; ++i) {
    const double dx = grid.node_x(0, i) - c_[0];
    if (open(dx, 0.0)) r = std::max(r, std::fabs(dx));
  }
  return 2 * (r + grid.h);
}

// ---------------------------------------------------------------------------------------
// Steady fluidity

template <int dim>
SteadyFluidityModule<dim>::SteadyFluidityModule(const State<dim> &S) : solver(make(S)) {}

template <int dim>
SteadyFluidityModule<dim>::~SteadyFluidityModule() = default;

template <int dim>
std::unique_ptr<FluiditySolver<dim>> SteadyFluidityModule<dim>::make(const State<dim> &S) const {
  auto f = std::make_unique<FluiditySolver<dim>>(S.grid, S.cfg);
  const RigidBodies<dim> *bodies = S.bodies.get();
  if (bodies && S.cfg.body_fluidity_bc == BodyFluidityBC::Zero)
    f->set_zero_nodes([bodies](const double *x) { // the grid contact nodes (poses of the current step)
      for (size_t k = 0; k < bodies->size(); ++k)
        if (bodies->sdf(k, x) < bodies->layer()) return true; // layer() is in metres
      return false;
    });
  return f;
}

template <int dim>
void SteadyFluidityModule<dim>::begin_step(State<dim> &S, double) {
  // From the stress and positions at the start of the step.
  GM_CALL(PetscLogStagePush(log_stage(LogStage::Fluidity)));
  solver->solve(S.particles, S.cfg.fluidity_map, S.nsteps, change_for_ == S.nsteps ? change_all_ : nullptr);
  change_for_ = -1;
  GM_CALL(PetscLogStagePop());
}

template <int dim>
int SteadyFluidityModule<dim>::reduce_ahead(State<dim> &S, double *local) {
  // After the step's last change of the stress; migration, sorting and repartitioning
  // before the next begin_step move particles but do not change these maxima.
  ParticleView<dim> P = S.particles.get();
  const bool used = solver->change_ahead(P, S.nsteps + 1, local);
  S.particles.restore(P);
  change_for_ = used ? S.nsteps + 1 : -1; // called before the step count moves on
  return used ? 2 : 0;
}

template <int dim>
void SteadyFluidityModule<dim>::reduced_ahead(const double *global) { std::copy(global, global + 2, change_all_); }

template <int dim>
void SteadyFluidityModule<dim>::rebuild(State<dim> &S) {
  // New solver on the new layout; the nodal fluidity (next solve's initial guess) is
  // carried over in PETSc's natural ordering, so it is the same field exactly.
  std::unique_ptr<FluiditySolver<dim>> fresh = make(S);
  copy_across_layouts(S.comm, solver->da(), solver->solution(), fresh->da(), fresh->solution());
  fresh->last_iterations = solver->last_iterations;
  fresh->solves = solver->solves;
  fresh->iterations_total = solver->iterations_total;
  fresh->pc_setups = solver->pc_setups;
  fresh->skipped = solver->skipped;
  fresh->set_state(solver->state());
  solver = std::move(fresh);
}

template <int dim>
void SteadyFluidityModule<dim>::write_checkpoint(const State<dim> &S, CheckpointIO &io) const {
  // Nodal fluidity (the initial guess of the next solve) and the solve schedule.
  const double *g;
  GM_CALL(VecGetArrayRead(solver->solution(), &g));
  io.write_box("/fluidity_g", g, S.grid.M, S.grid.xs, S.grid.xm, 1);
  GM_CALL(VecRestoreArrayRead(solver->solution(), &g));
  io.write_attr("fluidity_schedule", solver->state()); // solve interval, next solve
}

template <int dim>
void SteadyFluidityModule<dim>::read_checkpoint(State<dim> &S, CheckpointIO &io) {
  if (io.has_dataset("/fluidity_g")) {
    double *g;
    GM_CALL(VecGetArray(solver->solution(), &g));
    io.read_box("/fluidity_g", g, S.grid.xs, S.grid.xm, 1);
    GM_CALL(VecRestoreArray(solver->solution(), &g));
  }
  if (io.has_attr("fluidity_schedule") && !solver->set_state(io.read_attr("fluidity_schedule")))
    io.bad("the fluidity solve schedule in the checkpoint has the wrong size");
}

template <int dim>
void SteadyFluidityModule<dim>::backup(const State<dim> &) {
  // The nodal g is part of the state a checkpoint holds (the next solve's guess) and its
  // schedule decides when the next solve happens: without them the "last good"
  // checkpoint would carry the g of a later (unstable) step.
  const PetscScalar *g = nullptr;
  PetscInt m = 0;
  GM_CALL(VecGetLocalSize(solver->solution(), &m));
  GM_CALL(VecGetArrayRead(solver->solution(), &g));
  backup_g_.assign(g, g + m);
  GM_CALL(VecRestoreArrayRead(solver->solution(), &g));
  backup_schedule_ = solver->state();
}

template <int dim>
void SteadyFluidityModule<dim>::restore(State<dim> &) {
  if (backup_g_.empty()) return; // called after the repartition: the layout is the backup's again
  PetscScalar *g = nullptr;
  PetscInt m = 0;
  GM_CALL(VecGetLocalSize(solver->solution(), &m));
  if ((size_t)m != backup_g_.size()) throw std::logic_error("restore_state: the fluidity layout differs from the backup's");
  GM_CALL(VecGetArray(solver->solution(), &g));
  std::copy(backup_g_.begin(), backup_g_.end(), g);
  GM_CALL(VecRestoreArray(solver->solution(), &g));
  solver->set_state(backup_schedule_);
}

// ---------------------------------------------------------------------------------------
// Dynamical fluidity

template <int dim>
DynamicFluidityModule<dim>::DynamicFluidityModule(const State<dim> &S, std::vector<double> &lap_out)
    : solver(std::make_unique<DynamicFluidity<dim>>(S.grid, S.cfg)), lap(lap_out) {}

template <int dim>
DynamicFluidityModule<dim>::~DynamicFluidityModule() = default;

template <int dim>
void DynamicFluidityModule<dim>::begin_step(State<dim> &S, double dt) {
  // Laplacian of g at the particles from the connected particles at the start of the
  // step; the implicit step diffuses over this step's dt first (no step limit).
  GM_CALL(PetscLogStagePush(log_stage(LogStage::Fluidity)));
  ParticleView<dim> P = S.particles.get();
  solver->laplacian(P.x, P.m, P.g, P.p_prev, P.mu_prev, P.n, dt, S.cfg.fluidity_step == FluidityStepKind::Implicit, lap);
  S.particles.restore(P);
  GM_CALL(PetscLogStagePop());
}

template <int dim>
void DynamicFluidityModule<dim>::rebuild(State<dim> &S) {
  // Its nodal fields are rebuilt from the particles every step: nothing to carry over.
  std::unique_ptr<DynamicFluidity<dim>> fresh = std::make_unique<DynamicFluidity<dim>>(S.grid, S.cfg);
  fresh->last_iterations = solver->last_iterations;
  fresh->solves = solver->solves;
  solver = std::move(fresh);
}

// ---------------------------------------------------------------------------------------
// Cell density

template <int dim>
DensityModule<dim>::DensityModule(const State<dim> &S) : density(std::make_unique<CellDensity<dim>>(S.grid, S.cfg)) {}

template <int dim>
DensityModule<dim>::~DensityModule() = default;

template <int dim>
void DensityModule<dim>::end_step(State<dim> &S, double) {
  density->apply(S.particles);
}

template <int dim>
void DensityModule<dim>::rebuild(State<dim> &S) {
  density = std::make_unique<CellDensity<dim>>(S.grid, S.cfg);
}

template class SiloPlate<2>;
template class SiloPlate<3>;
template class SteadyFluidityModule<2>;
template class SteadyFluidityModule<3>;
template class DynamicFluidityModule<2>;
template class DynamicFluidityModule<3>;
template class DensityModule<2>;
template class DensityModule<3>;

} // namespace granmpm
