// DemModule<dim>: the DEM grains (dem::Engine, docs/dem.md) as a species of the MPM
// Simulation (module.hpp). The grains keep their own BASIC DMSwarm, neighbour search and
// contact law; what the host gives them:
//  - the decomposition: the MPM grid's DMDA ownership and owner-rank rule (Grid::owner_rank),
//    re-read after every repartition (rebuild), so both species of a region live on one rank;
//  - the box, its periodic directions and outlet faces (-domain_lo/-domain_hi, -bc_xlo..),
//    the gravity with its ramp (-gravity, -gravity_ramp), the clock and the checkpoints
//    (-checkpoint_file/-restart: grains and contact springs under "dem_*"); every other
//    face is a DEM wall (-dem_wall_*);
//  - grain snapshots (HDF5 + XDMF, as granmpm -dem writes them, with each grain's mass
//    share in a hybrid run) at the start, every -output_interval steps and at the end;
//  - dem_summary.csv in the MPM's output directory: step, time, grains, grains and mass
//    removed through outlets, kinetic energy, contacts (every 10 MPM steps);
//  - the rigid bodies (-body<k>_*): contact partners of the grains with the wall law; the
//    grains' impulse over a step joins the grid's in the body forces (bodies.csv, dynamic
//    bodies' motion);
//  - the time step: each MPM step of dt runs n = ceil(dt / dt_DEM) DEM sub-steps of dt / n
//    (dt_DEM from -dem_dt or -dem_steps_per_contact, the standalone rule).
// Without coupling the two species never interact: each evolves as its own solver alone.
#pragma once

#include <cstdio>
#include <memory>
#include <string>

#include "granmpm/dem/dem.hpp"
#include "granmpm/module.hpp"

namespace granmpm {

template <int dim>
class DemModule : public Module<dim> {
public:
  // c: the grain species; its box, periodicity, outlets and gravity are replaced by the
  // host's (c.dim must be dim). Builds the grains (collective).
  // host_snapshots: a coupling that changes the grains after this module's end_step (the
  // hybrid's zone updates) writes the step snapshots itself (snapshot_if_due, after its
  // changes), and the t = 0 one is written at the first step (after the host's set-up).
  DemModule(State<dim> &S, dem::Config c, bool host_snapshots = false);
  ~DemModule() override;
  std::string name() const override { return "DEM grains"; }
  void begin_step(State<dim> &S, double dt) override;
  void end_grid(State<dim> &S, double dt, bool with_force) override;
  void end_step(State<dim> &S, double dt) override;
  void rebuild(State<dim> &S) override;
  void write_checkpoint(const State<dim> &S, CheckpointIO &io) const override;
  void read_checkpoint(State<dim> &S, CheckpointIO &io) override;
  void backup(const State<dim> &S) override;
  void restore(State<dim> &S) override;
  std::string summary() const override;
  dem::Engine &engine() { return *engine_; }
  long substeps() const { return substeps_; }
  // The engine's configuration for a host: c with the host's box, faces and gravity.
  static dem::Config hosted(const Config &host, dem::Config c);
  // The grain snapshot of this step when the MPM's output is due (its -output_interval or
  // the last step); end_step's, or the host's with host_snapshots.
  void snapshot_if_due(const State<dim> &S, double dt);

private:
  std::unique_ptr<dem::Engine> engine_;
  long substeps_ = 0;
  double cpu_steps_ = 0, cpu_summary_ = 0; // this process's CPU seconds in the sub-steps and in the per-step summaries
  std::string summary_;
  dem::Backup backup_;
  long backup_substeps_ = 0;
  int snap_ = 0; // grain snapshots written (grains_NNNNN.h5/.xmf, grains.xmf)
  bool host_snapshots_ = false, first_due_ = false; // first_due_: the t = 0 snapshot waits for the first step
  std::FILE *csv_ = nullptr; // <output_dir>/dem_summary.csv (rank 0): a row every 10 MPM steps
};

// The -dem_* options of the grains in this MPM run (-hybrid_dem; hybrid/module.hpp's
// grain_modules builds the modules); refuses the options the host decides.
template <int dim>
dem::Config dem_module_config(const State<dim> &S);

} // namespace granmpm
