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

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "granmpm/state.hpp"

namespace granmpm {

// What a module sees of an open checkpoint (Module::write_checkpoint/read_checkpoint):
// attributes (identical on every rank) and nodal fields on the owned grid box.
class CheckpointIO {
public:
  CheckpointIO(int64_t file, const void *check, std::string path) : file_(file), chk_(check), path_(std::move(path)) {}
  void write_attr(const std::string &name, const std::vector<double> &v);
  bool has_attr(const std::string &name) const;
  std::vector<double> read_attr(const std::string &name) const;
  bool has_dataset(const std::string &name) const;
  // Owned box xs..xs+xm of a grid with M nodes per direction, comps values per node.
  void write_box(const std::string &name, const double *owned, const int *M, const int *xs, const int *xm, int comps);
  void read_box(const std::string &name, double *owned, const int *xs, const int *xm, int comps);
  // Rows of cols doubles (a module's particles, e.g. the DEM grains): this rank's n rows at
  // row offset off of N in all (collective); read_all_rows gives every rank all N rows.
  void write_rows(const std::string &name, const double *rows, long n, long off, long N, int cols);
  void read_all_rows(const std::string &name, double *rows, long N, int cols);
  // Stops the restart: "-restart <path>: <why>".
  [[noreturn]] void bad(const std::string &why) const;

private:
  int64_t file_;
  const void *chk_;
  std::string path_;
};

template <int dim>
struct Checkpoint {
  static void write(const State<dim> &S, const std::string &path);
  // Replaces the particles and run state of a set-up simulation; repartition(l) re-creates
  // the grid (and what is built on it) with the checkpoint's ownership ranges.
  static void read(State<dim> &S, const std::string &path, const std::function<void(const Ranges &)> &repartition);
};

} // namespace granmpm
