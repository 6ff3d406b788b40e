// Output<dim>: parallel HDF5 snapshots of particle and grid fields, and XDMF index files
// (particles.xmf, grid.xmf, and bodies.xmf when there are rigid bodies: kOutlinePoints
// points on each body's outline with its rigid velocity) that ParaView opens as time series.
//
// Each snapshot is one file <output_dir>/snap_NNNNNN.h5, written collectively through
// MPI-IO (each rank writes its particles at the offset of an exclusive scan, and its owned
// grid box as a hyperslab), first under a temporary name and then renamed, so a reader
// never sees a half-written file. Any HDF5 failure stops the run with the file name.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace granmpm {

template <int dim>
class Simulation;
template <int dim>
class Scene;

template <int dim>
class Output {
public:
  static constexpr int kOutlinePoints = 128; // per rigid body in /bodies/outline
  explicit Output(Simulation<dim> &sim);
  void write(Scene<dim> &scene);
  int count() const { return (int)frames_.size(); }
  // Last file written.
  std::string last_file;
  // The snapshots written so far (kept in checkpoints so a restarted run continues the
  // numbering and the XDMF time series).
  struct Frame {
    double t;
    std::string file;
    long np;
  };
  const std::vector<Frame> &frames() const { return frames_; }
  void set_frames(const std::vector<Frame> &f) { frames_ = f; }

private:
  Simulation<dim> &sim_;
  std::vector<Frame> frames_;
  void write_xdmf() const;
};

} // namespace granmpm
