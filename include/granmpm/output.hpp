// Output<dim>: parallel HDF5 snapshots of particle, grid and rigid-body fields, and the
// XDMF index files (particles.xmf, grid.xmf, and bodies.xmf when there are rigid bodies)
// that ParaView opens as time series. The XDMF is written so that each of ParaView's
// readers (Xdmf3ReaderS, its default for .xmf; Xdmf3ReaderT; the legacy XDMFReader) shows
// the same cells, arrays and components (tests/cli/paraview_check.py checks it):
//   particles: one vertex cell per particle (explicit connectivity: without it the Xdmf3
//     readers make no cells, and the default Surface view draws nothing); the stress as
//     the full symmetric tensor (9 components) and as named scalars stress_xx, stress_yy,
//     stress_zz, stress_xy (+ stress_yz, stress_xz in 3D): the readers pass 6-component
//     arrays through but ParaView labels them in an order of its own, and it labels 9
//     components 0..8; F (dynamical model) as the full tensor in VTK's order for 9
//     components, column-major (component i + 3 j is F_ij; ParaView's Python calculator
//     then sees F[:, i, j] = F_ij), so /particles/F row p reshaped C-order is F^T;
//   grid: nodal mass, velocity and `active` (1 where the mass is at least
//     kGridMassFraction of a full cell's, rho h^dim; velocity is written as 0 elsewhere,
//     where momentum / (nearly nothing) is noise); on periodic axes one more node layer, a
//     copy of layer 0, so the grid spans the whole periodic domain;
//   bodies: one polyline cell per body through kOutlinePoints points spaced by arc length
//     (closed for a disk, ring or box; open for a plane).
//
// Each snapshot is one file <output_dir>/snap_NNNNNN.h5, written collectively through
// MPI-IO (each rank writes its particles at the offset of an exclusive scan, and its owned
// grid box as a hyperslab), first under a temporary name and then renamed, so a reader
// never sees a half-written file. Any HDF5 failure stops the run with the file name.
#pragma once

#include <mpi.h>

#include <cstdio>
#include <string>
#include <utility>
#include <vector>

namespace granmpm {

struct Config;

// Every file GranMPM writes is written under <path>.tmp and then published: fsync, rename
// over <path>, fsync of the directory. A crash or a full disk leaves the previous complete
// file (or none), never a partial one. Returns "" or the cause (errno text).
std::string sync_and_rename(const std::string &tmp, const std::string &path);
// Text output (CSV) on one rank: open_atomic opens <path>.tmp; close_atomic checks every
// write, publishes it and throws UserError naming the cause and `option`, removing the
// temporary, on any failure.
std::FILE *open_atomic(const std::string &path, const std::string &option = "-output_dir");
void close_atomic(std::FILE *f);
// A new run (not a restart) into a directory holding another run's results (snapshots,
// XDMF, checkpoints, CSV) is refused unless -output_overwrite: collective, before set-up.
void check_output_dir(MPI_Comm comm, const Config &cfg);

template <int dim>
struct State;
template <int dim>
class Scene;

template <int dim>
class Output {
public:
  static constexpr int kOutlinePoints = 128; // per rigid body in /bodies/outline
  // Grid nodes with less mass than this fraction of rho h^dim are written as empty. The
  // wheel example (GIMP, ppc 2) measured: nodes below 1e-6 of a full cell reach 20-950
  // times the largest particle speed, between 1e-5 and 1e-3 up to 9 times; above 1e-3 at
  // most 2.4 times (contact nodes on the spinning rim).
  static constexpr double kGridMassFraction = 1e-3;
  // Creates and probes the output directory (not with -help: that only lists options).
  explicit Output(const State<dim> &sim);
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
  // Frames of a checkpoint written into from_dir. Their files are named relative to the
  // output directory; a restart into another -output_dir links to the old files that still
  // exist (by relative path) and leaves the missing ones out of the XDMF, and says so.
  void set_frames(const std::vector<Frame> &f, const std::string &from_dir = "");

private:
  const State<dim> &sim_;
  std::vector<Frame> frames_;
  void write_xdmf() const;
};

} // namespace granmpm
