// Checkpoint and restart: everything needed to continue a run, in one HDF5 file written
// collectively under a temporary name and renamed (a kill mid-write leaves the previous
// checkpoint intact).
//
// Contents: every particle field, in rank order with the per-rank counts, so that a
// restart on the same number of ranks rebuilds each rank's particles in the same order
// and continues bitwise identically; the nodal fluidity (the initial guess of the next
// solve); time, step count, the speed and plastic limit that set the next automatic step;
// the output frames written so far; the scene signature (a restart must match it) and all
// options of the run, for the record. A restart on a different number of ranks reads the
// particles in even slabs and migrates them to their owners (identical to round-off).
#pragma once

#include <string>

namespace granmpm {

template <int dim>
class Simulation;

template <int dim>
struct Checkpoint {
  static void write(Simulation<dim> &sim, const std::string &path);
  // Replaces the particles and run state of a set-up simulation.
  static void read(Simulation<dim> &sim, const std::string &path);
};

} // namespace granmpm
