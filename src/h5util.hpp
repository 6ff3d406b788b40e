// Internal helpers for collective parallel HDF5 I/O (output snapshots and checkpoints).
// Every function is collective over the file's communicator; HDF5 failures become a
// UserError naming the file.
#pragma once

#include <hdf5.h>

#include <cstdint>
#include <string>
#include <vector>

#include "granmpm/config.hpp"

namespace granmpm::h5 {

// comm: the file's communicator; with it, write_rows/write_box store a checksum of each
// dataset and read_rows/read_box verify it (without it, no checksums).
struct Check {
  std::string file;
  MPI_Comm comm = MPI_COMM_NULL;
  void operator()(herr_t e, const std::string &what) const {
    if (e < 0) throw UserError("HDF5 failed to " + what + " in " + file + ": check the path (exists, writable, enough space" + free_space(file) + ")");
  }
  // "; N bytes free there" (the file system's free space), or "".
  static std::string free_space(const std::string &file);
  void id(hid_t h, const std::string &what) const { (*this)(h < 0 ? -1 : 0, what); }
};

// Create (write) or open (read) a file on comm through MPI-IO; returns < 0 on failure.
hid_t create(MPI_Comm comm, const std::string &path);
hid_t open_read(MPI_Comm comm, const std::string &path);

// A file written collectively under <path>.tmp. publish() closes it, fsyncs it, renames it
// over <path> and fsyncs the directory, so that a reader (or a restart after a crash) sees
// the old complete file or the new complete file, never a partial one. Destroyed without
// publish() (an exception), it closes and removes the temporary. Failures throw UserError
// with the cause (errno text) and the option that sets the path.
class TmpFile {
public:
  TmpFile(MPI_Comm comm, const std::string &path, const std::string &option);
  ~TmpFile();
  TmpFile(const TmpFile &) = delete;
  TmpFile &operator=(const TmpFile &) = delete;
  hid_t id() const { return file_; }
  const std::string &tmp() const { return tmp_; }
  void publish();

private:
  MPI_Comm comm_;
  std::string path_, tmp_, option_;
  hid_t file_ = -1;
  bool done_ = false;
};

// Position-dependent checksum of rows [first_row, first_row + nrows) of row_bytes each: a
// sum over rows of a mix of the row's bytes and its global index, so that partial sums of
// any split into slabs add up (mod 2^64) to the same value. Every changed byte changes it.
uint64_t checksum_rows(const void *buf, size_t nrows, size_t row_bytes, uint64_t first_row);

// (global_rows x cols) dataset; this rank supplies rows [offset, offset + nrows).
void write_rows(hid_t file, const std::string &name, hid_t type, const void *buf, hsize_t nrows, hsize_t offset, hsize_t global_rows, hsize_t cols,
                const Check &chk);
// every_rank_all_rows: each rank reads the whole dataset (the checksum is then local).
void read_rows(hid_t file, const std::string &name, hid_t type, void *buf, hsize_t nrows, hsize_t offset, hsize_t cols, const Check &chk,
               bool every_rank_all_rows = false);
// Shape of a dataset (empty if it does not exist).
std::vector<hsize_t> shape(hid_t file, const std::string &name);

// Grid dataset (Mz, My, Mx[, comps]); this rank writes / reads its owned box.
// wrap (optional, per direction x, y, z): the dataset gets one more layer in that
// direction, a copy of layer 0 (the periodic image of node 0), so that a viewer's grid
// spans the whole periodic domain.
void write_box(hid_t file, const std::string &name, const double *buf, const int *M, const int *xs, const int *xm, int comps, const Check &chk,
               const bool *wrap = nullptr);
void read_box(hid_t file, const std::string &name, double *buf, const int *xs, const int *xm, int comps, const Check &chk);

void group(hid_t file, const std::string &name);
// Attributes on the root group (identical values on every rank).
void attr_double(hid_t obj, const std::string &name, double v);
void attr_doubles(hid_t obj, const std::string &name, const std::vector<double> &v);
void attr_string(hid_t obj, const std::string &name, const std::string &v);
bool has_attr(hid_t obj, const std::string &name);
double read_attr_double(hid_t obj, const std::string &name, const Check &chk);
std::vector<double> read_attr_doubles(hid_t obj, const std::string &name, const Check &chk);
std::string read_attr_string(hid_t obj, const std::string &name, const Check &chk);

} // namespace granmpm::h5
