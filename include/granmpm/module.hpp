// Module<dim>: a part of the solver that a scene may or may not need (rigid bodies, the
// silo plate, the fluidity solvers, the cell density; later DEM grains and the hybrid
// coupling). Simulation::setup chooses the set once from the scene; Simulation::step calls
// every module at fixed points of the step, in the order they were added:
//
//   begin_step                      start of the step, before any transfer
//   begin_grid / node / end_grid    the grid update (each P2G-G2P pass): node() on every
//                                   owned node with mass, after the explicit velocity update
//                                   and before constrain() and the walls; end_grid after the
//                                   loop (reductions, checks; collective)
//   constrain                       a velocity projection on a node (the silo plate): applied
//                                   after node() by the explicit update and to the fixed
//                                   directions of the implicit solver
//   end_step                        after the constitutive update, before migration
//   rebuild                         after a repartition re-created the grid
//   write/read_checkpoint           its own datasets and attributes
//   backup / restore                -on_instability checkpoint_and_abort
//
// Hooks are virtual, called once per step or once per node (never per particle: particle
// loops stay in the transfer and material kernels). docs/architecture.md: how to add one.
#pragma once

#include <cstddef>
#include <memory>
#include <string>

#include "granmpm/state.hpp"

namespace granmpm {

class CheckpointIO;

// A grid node as the node pass sees it: global index, position, mass.
struct NodeAt {
  int i, j, k;
  double x[3];
  double m;
};

template <int dim>
class Module {
public:
  virtual ~Module() = default;
  virtual std::string name() const = 0;
  virtual void begin_step(State<dim> &, double /*dt*/) {}
  // Only modules that say so are called per node.
  virtual bool has_node_pass() const { return false; }
  virtual bool has_constraint() const { return false; }
  virtual void begin_grid(State<dim> &, double /*dt*/, bool /*with_force*/) {}
  virtual void node(const NodeAt &, double * /*v*/, double /*dt*/, bool /*with_force*/) {}
  virtual void constrain(const NodeAt &, double * /*v*/) const {}
  virtual void end_grid(State<dim> &, double /*dt*/, bool /*with_force*/) {}
  virtual void end_step(State<dim> &, double /*dt*/) {}
  // Values (>= 0) the next begin_step needs as maxima over the ranks, known after every
  // end_step: the migration's reduction carries them (a collective less per step on small
  // scenes). reduce_ahead writes at most kAheadMax local values and returns their count;
  // reduced_ahead receives the maxima, at the same step on every rank.
  static constexpr int kAheadMax = 2;
  virtual int reduce_ahead(State<dim> &, double * /*local*/) { return 0; }
  virtual void reduced_ahead(const double * /*global*/) {}
  virtual void rebuild(State<dim> &) {}
  virtual void write_checkpoint(const State<dim> &, CheckpointIO &) const {}
  virtual void read_checkpoint(State<dim> &, CheckpointIO &) {}
  virtual void backup(const State<dim> &) {}
  virtual void restore(State<dim> &) {}
  // A line for the end-of-run summary ("" for none).
  virtual std::string summary() const { return ""; }
};

// The object a module owns, under the name the rest of the code and the tests use
// (sim.fluidity->solves): follows the module's object through rebuilds.
template <class T>
class Owned {
public:
  void bind(const std::unique_ptr<T> *slot) { slot_ = slot; }
  T *get() const { return slot_ ? slot_->get() : nullptr; }
  T *operator->() const { return get(); }
  T &operator*() const { return *get(); }
  explicit operator bool() const { return get() != nullptr; }
  bool operator==(std::nullptr_t) const { return get() == nullptr; }
  bool operator!=(std::nullptr_t) const { return get() != nullptr; }

private:
  const std::unique_ptr<T> *slot_ = nullptr;
};

} // namespace granmpm
