// The built-in modules (module.hpp): rigid bodies, the silo plate, the steady and the
// dynamical fluidity solvers, the cell density. Simulation::setup adds the ones the scene
// needs (add_modules); each owns its solver objects, checkpoint fields and rebuild.
#pragma once

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "granmpm/module.hpp"

namespace granmpm {

template <int dim>
class FluiditySolver;
template <int dim>
class DynamicFluidity;
template <int dim>
class CellDensity;

// Rigid bodies on the grid: contact at each node with mass (node pass), the force and
// contact-mass reductions and the added-mass checks (end_grid), the body update and the
// particles that entered a body (end_step), bodies.csv (record), the body state in
// checkpoints. The bodies themselves are State::bodies (output and scenes read them).
template <int dim>
class BodyModule : public Module<dim> {
public:
  ~BodyModule() override;
  std::string name() const override { return "rigid bodies"; }
  void begin_step(State<dim> &S, double dt) override;
  bool has_node_pass() const override { return true; }
  void begin_grid(State<dim> &S, double dt, bool with_force) override;
  void node(const NodeAt &n, double *v, double dt, bool with_force) override;
  void end_grid(State<dim> &S, double dt, bool with_force) override;
  void end_step(State<dim> &S, double dt) override;
  void write_checkpoint(const State<dim> &S, CheckpointIO &io) const override;
  void read_checkpoint(State<dim> &S, CheckpointIO &io) override;
  void backup(const State<dim> &S) override;
  void restore(State<dim> &S) override;
  // One row per body to <output_dir>/bodies.csv (rank 0): at the start (start = true, a
  // fresh run only), every -bodies_interval steps, every output step and at t_end.
  void record(const State<dim> &S, bool start);

private:
  RigidBodies<dim> *B_ = nullptr; // State::bodies, set in begin_step
  std::FILE *csv_ = nullptr;
  std::vector<double> backup_;
  void particles_inside(State<dim> &S);
  void write_row(const State<dim> &S);
};

// The silo's bottom plate at node row j: sticky outside the orifice (a velocity
// constraint, so the implicit solver fixes those directions too).
template <int dim>
class SiloPlate : public Module<dim> {
public:
  SiloPlate(const Grid<dim> &grid, double y, double width, double xc, double zc);
  std::string name() const override { return "silo plate"; }
  bool has_constraint() const override { return true; }
  void constrain(const NodeAt &n, double *v) const override {
    if (n.j != j_) return;
    const double dx = n.x[0] - c_[0], dz = dim == 3 ? n.x[2] - c_[1] : 0.0;
    if (!open(dx, dz))
      for (int e = 0; e < dim; ++e) v[e] = 0;
  }
  // A plate node is open when it lies strictly inside the orifice; a node on its edge (to
  // round-off, relative 1e-9) is sticky, so the opening between the innermost sticky
  // nodes is the given width whenever that is representable on the grid.
  bool open(double dx, double dz) const { return dx * dx + dz * dz < r2_ * (1 - 1e-9); }
  // 2D: the gap between the innermost sticky plate nodes (what the flow sees); 3D: the
  // diameter of the disc of open nodes plus one cell, as a measure of the same kind.
  double effective_width(const Grid<dim> &grid) const;

private:
  int j_ = 0;
  double r2_ = 0, c_[2] = {0, 0};
};

// Steady nonlocal fluidity (FluiditySolver, KSP, prefix -fluidity_): solved at the start
// of each step from the stress and positions then; its nodal g (the next solve's guess)
// and schedule are carried over repartitions and kept in checkpoints.
template <int dim>
class SteadyFluidityModule : public Module<dim> {
public:
  explicit SteadyFluidityModule(const State<dim> &S);
  ~SteadyFluidityModule() override;
  std::string name() const override { return "steady fluidity"; }
  void begin_step(State<dim> &S, double dt) override;
  int reduce_ahead(State<dim> &S, double *local) override;
  void reduced_ahead(const double *global) override;
  void rebuild(State<dim> &S) override;
  void write_checkpoint(const State<dim> &S, CheckpointIO &io) const override;
  void read_checkpoint(State<dim> &S, CheckpointIO &io) override;
  void backup(const State<dim> &S) override;
  void restore(State<dim> &S) override;
  std::unique_ptr<FluiditySolver<dim>> solver;

private:
  std::vector<double> backup_g_, backup_schedule_;
  double change_all_[2] = {0, 0}; // the solve schedule's reduction, done by the migration
  long change_for_ = -1;           // the step change_all_ is for (-1: none)
  std::unique_ptr<FluiditySolver<dim>> make(const State<dim> &S) const;
};

// Dynamical fluidity (DynamicFluidity): the Laplacian of g at the particles from the
// connected particles at the start of the step, read by the constitutive update.
template <int dim>
class DynamicFluidityModule : public Module<dim> {
public:
  // lap: where the constitutive update reads the Laplacian (a per-particle step buffer).
  DynamicFluidityModule(const State<dim> &S, std::vector<double> &lap);
  ~DynamicFluidityModule() override;
  std::string name() const override { return "dynamical fluidity"; }
  void begin_step(State<dim> &S, double dt) override;
  void rebuild(State<dim> &S) override;
  std::unique_ptr<DynamicFluidity<dim>> solver;
  std::vector<double> &lap; // per local particle, this step
};

// Elemental / hybrid density rules (CellDensity), applied after the constitutive update.
template <int dim>
class DensityModule : public Module<dim> {
public:
  explicit DensityModule(const State<dim> &S);
  ~DensityModule() override;
  std::string name() const override { return "cell density"; }
  void end_step(State<dim> &S, double dt) override;
  void rebuild(State<dim> &S) override;
  std::unique_ptr<CellDensity<dim>> density;
};

} // namespace granmpm
