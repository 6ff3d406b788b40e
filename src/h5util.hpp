// Internal helpers for collective parallel HDF5 I/O (output snapshots and checkpoints).
// Every function is collective over the file's communicator; HDF5 failures become a
// UserError naming the file.
#pragma once

#include <hdf5.h>

#include <string>
#include <vector>

#include "granmpm/config.hpp"

namespace granmpm::h5 {

struct Check {
  std::string file;
  void operator()(herr_t e, const std::string &what) const {
    if (e < 0) throw UserError("HDF5 failed to " + what + " in " + file + ": check the path (exists, writable, enough space)");
  }
  void id(hid_t h, const std::string &what) const { (*this)(h < 0 ? -1 : 0, what); }
};

// Create (write) or open (read) a file on comm through MPI-IO; returns < 0 on failure.
hid_t create(MPI_Comm comm, const std::string &path);
hid_t open_read(MPI_Comm comm, const std::string &path);

// (global_rows x cols) dataset; this rank supplies rows [offset, offset + nrows).
void write_rows(hid_t file, const std::string &name, hid_t type, const void *buf, hsize_t nrows, hsize_t offset, hsize_t global_rows, hsize_t cols,
                const Check &chk);
void read_rows(hid_t file, const std::string &name, hid_t type, void *buf, hsize_t nrows, hsize_t offset, hsize_t cols, const Check &chk);
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
