#include "h5util.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "granmpm/output.hpp"

namespace granmpm::h5 {

std::string Check::free_space(const std::string &file) {
  std::error_code ec;
  const std::filesystem::path dir = std::filesystem::path(file).parent_path();
  const std::filesystem::space_info si = std::filesystem::space(dir.empty() ? "." : dir, ec);
  return ec ? std::string() : "; " + std::to_string((unsigned long long)si.available) + " bytes free there";
}

namespace {
// HDF5's own error stack is not printed: every failure becomes one message naming the file.
void quiet_hdf5() { H5Eset_auto2(H5E_DEFAULT, NULL, NULL); }
} // namespace

hid_t create(MPI_Comm comm, const std::string &path) {
  quiet_hdf5();
  hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
  H5Pset_fapl_mpio(fapl, comm, MPI_INFO_NULL);
  hid_t f = -1;
  H5E_BEGIN_TRY { f = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl); } // the caller names the cause
  H5E_END_TRY;
  H5Pclose(fapl);
  return f;
}

hid_t open_read(MPI_Comm comm, const std::string &path) {
  quiet_hdf5();
  hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
  H5Pset_fapl_mpio(fapl, comm, MPI_INFO_NULL);
  hid_t f = -1;
  H5E_BEGIN_TRY { f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, fapl); }
  H5E_END_TRY;
  H5Pclose(fapl);
  return f;
}

TmpFile::TmpFile(MPI_Comm comm, const std::string &path, const std::string &option) : comm_(comm), path_(path), tmp_(path + ".tmp"), option_(option) {
  errno = 0;
  file_ = create(comm, tmp_);
  int ok = file_ >= 0, all_ok = 0, err = file_ >= 0 ? 0 : errno;
  MPI_Allreduce(&ok, &all_ok, 1, MPI_INT, MPI_MIN, comm);
  MPI_Allreduce(MPI_IN_PLACE, &err, 1, MPI_INT, MPI_MAX, comm);
  if (!all_ok) {
    if (file_ >= 0) H5Fclose(file_);
    file_ = -1;
    done_ = true; // nothing of ours to remove (the name may be another file or directory)
    // Say why: the directory is missing or not a directory, or the name is taken.
    std::string why = err ? std::strerror(err) : "HDF5 could not create it";
    const std::filesystem::path dir = std::filesystem::path(tmp_).parent_path();
    std::error_code ec;
    if (!dir.empty() && !std::filesystem::is_directory(dir, ec)) why = "directory " + dir.string() + " does not exist";
    else if (std::filesystem::is_directory(tmp_, ec)) why = "a directory of that name is in the way";
    else if (::access(dir.empty() ? "." : dir.c_str(), W_OK) != 0) why = "directory " + dir.string() + " is not writable: " + std::strerror(errno);
    throw UserError("cannot create " + tmp_ + " (" + why + "): check " + option_);
  }
}

TmpFile::~TmpFile() {
  if (done_) return;
  H5E_BEGIN_TRY { H5Fclose(file_); }
  H5E_END_TRY;
  int rank = 0;
  MPI_Comm_rank(comm_, &rank);
  if (rank == 0) std::remove(tmp_.c_str());
}

void TmpFile::publish() {
  const herr_t e = H5Fclose(file_);
  done_ = true;
  int rank = 0;
  MPI_Comm_rank(comm_, &rank);
  int bad = e < 0;
  MPI_Allreduce(MPI_IN_PLACE, &bad, 1, MPI_INT, MPI_MAX, comm_);
  std::string why = bad ? "HDF5 failed to close it (disk full?)" : "";
  if (rank == 0) {
    if (why.empty()) why = sync_and_rename(tmp_, path_);
    if (!why.empty()) std::remove(tmp_.c_str());
  }
  collective_fail(comm_, !why.empty(), "cannot write " + path_ + " (" + why + "): check " + option_);
}

uint64_t checksum_rows(const void *buf, size_t nrows, size_t row_bytes, uint64_t first_row) {
  // splitmix64's finalizer: a bijection of 64-bit words with good avalanche.
  auto mix = [](uint64_t z) {
    z += 0x9e3779b97f4a7c15ULL;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  };
  const unsigned char *b = (const unsigned char *)buf;
  uint64_t sum = 0;
  for (size_t r = 0; r < nrows; ++r) {
    uint64_t h = mix(first_row + r);
    for (size_t k = 0; k < row_bytes; k += 8) {
      uint64_t w = 0;
      std::memcpy(&w, b + r * row_bytes + k, std::min<size_t>(8, row_bytes - k));
      h = mix(h ^ w);
    }
    sum += h;
  }
  return sum;
}

namespace {
// Checksum attribute of a dataset: 16 hex digits.
void store_checksum(hid_t file, const std::string &name, uint64_t local, const Check &chk) {
  if (chk.comm == MPI_COMM_NULL) return;
  uint64_t sum = 0;
  MPI_Allreduce(&local, &sum, 1, MPI_UINT64_T, MPI_SUM, chk.comm);
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", (unsigned long long)sum);
  hid_t ds = H5Dopen2(file, name.c_str(), H5P_DEFAULT);
  chk.id(ds, "open dataset " + name);
  attr_string(ds, "checksum", hex);
  H5Dclose(ds);
}
void verify_checksum(hid_t file, const std::string &name, uint64_t local, bool reduce, const Check &chk) {
  if (chk.comm == MPI_COMM_NULL) return;
  uint64_t sum = local;
  if (reduce) MPI_Allreduce(&local, &sum, 1, MPI_UINT64_T, MPI_SUM, chk.comm);
  hid_t ds = H5Dopen2(file, name.c_str(), H5P_DEFAULT);
  chk.id(ds, "open dataset " + name);
  const std::string stored = has_attr(ds, "checksum") ? read_attr_string(ds, "checksum", chk) : "missing";
  H5Dclose(ds);
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", (unsigned long long)sum);
  if (stored != hex)
    throw UserError("dataset " + name + " in " + chk.file + " fails its checksum (stored " + stored + ", computed " + hex +
                    "): the file is corrupt; restart from an intact checkpoint");
}
size_t type_bytes(hid_t type) { return H5Tget_size(type); }
// Checksum of an owned box (local x fastest) as rows of the file's (z, y, x) node order.
uint64_t box_checksum(const double *buf, const hsize_t *g, const int *xs, const int *xm, int comps) {
  uint64_t sum = 0;
  long q = 0;
  for (int k = 0; k < xm[2]; ++k)
    for (int j = 0; j < xm[1]; ++j)
      for (int i = 0; i < xm[0]; ++i, ++q)
        sum += checksum_rows(buf + q * comps, 1, comps * sizeof(double), ((uint64_t)(xs[2] + k) * g[1] + (xs[1] + j)) * g[2] + (xs[0] + i));
  return sum;
}
} // namespace

namespace {
// A data transfer can fail on some ranks only (a full disk): every rank learns of it, so
// that all stop together instead of waiting in the next collective call.
void agree(herr_t e, const std::string &what, const Check &chk) {
  int bad = e < 0;
  if (chk.comm != MPI_COMM_NULL) MPI_Allreduce(MPI_IN_PLACE, &bad, 1, MPI_INT, MPI_MAX, chk.comm);
  chk(bad ? -1 : 0, what);
}

hid_t collective() {
  hid_t dx = H5Pcreate(H5P_DATASET_XFER);
  H5Pset_dxpl_mpio(dx, H5FD_MPIO_COLLECTIVE);
  return dx;
}
} // namespace

namespace {
// Rows [offset, offset + nrows) of a (rows x cols) dataset, collectively: a rank with no
// rows selects nothing but still takes part in the collective transfer.
void transfer_rows(hid_t ds, const std::string &name, hid_t type, void *buf, hsize_t nrows, hsize_t offset, hsize_t cols, bool write,
                   const Check &chk) {
  hid_t fs = H5Dget_space(ds);
  if (H5Sget_simple_extent_npoints(fs) == 0) { // no data anywhere (an empty swarm): nothing to transfer
    H5Sclose(fs);
    return;
  }
  const int rank = H5Sget_simple_extent_ndims(fs);
  hsize_t ldims[2] = {nrows, cols}, start[2] = {offset, 0};
  hid_t ms = H5Screate_simple(rank, ldims, NULL);
  if (nrows > 0) chk(H5Sselect_hyperslab(fs, H5S_SELECT_SET, start, NULL, ldims, NULL), "select rows of " + name);
  else {
    H5Sselect_none(fs);
    H5Sselect_none(ms);
  }
  hid_t dx = collective();
  if (write) agree(H5Dwrite(ds, type, ms, fs, dx, buf), "write " + name, chk);
  else agree(H5Dread(ds, type, ms, fs, dx, buf), "read " + name, chk);
  H5Pclose(dx);
  H5Sclose(ms);
  H5Sclose(fs);
}
} // namespace

void write_rows(hid_t file, const std::string &name, hid_t type, const void *buf, hsize_t nrows, hsize_t offset, hsize_t global_rows, hsize_t cols,
                const Check &chk) {
  hsize_t gdims[2] = {global_rows, cols};
  hid_t fs = H5Screate_simple(cols > 1 ? 2 : 1, gdims, NULL);
  hid_t ds = H5Dcreate2(file, name.c_str(), type, fs, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  H5Sclose(fs);
  chk.id(ds, "create dataset " + name);
  transfer_rows(ds, name, type, const_cast<void *>(buf), nrows, offset, cols, true, chk);
  H5Dclose(ds);
  store_checksum(file, name, checksum_rows(buf, nrows, cols * type_bytes(type), offset), chk);
}

void read_rows(hid_t file, const std::string &name, hid_t type, void *buf, hsize_t nrows, hsize_t offset, hsize_t cols, const Check &chk,
               bool every_rank_all_rows) {
  hid_t ds = -1;
  H5E_BEGIN_TRY { ds = H5Dopen2(file, name.c_str(), H5P_DEFAULT); }
  H5E_END_TRY;
  chk.id(ds, "open dataset " + name);
  transfer_rows(ds, name, type, buf, nrows, offset, cols, false, chk);
  H5Dclose(ds);
  verify_checksum(file, name, checksum_rows(buf, nrows, cols * type_bytes(type), offset), !every_rank_all_rows, chk);
}

std::vector<hsize_t> shape(hid_t file, const std::string &name) {
  hid_t ds = -1;
  H5E_BEGIN_TRY { ds = H5Dopen2(file, name.c_str(), H5P_DEFAULT); }
  H5E_END_TRY;
  if (ds < 0) return {};
  hid_t fs = H5Dget_space(ds);
  std::vector<hsize_t> dims(H5Sget_simple_extent_ndims(fs));
  H5Sget_simple_extent_dims(fs, dims.data(), NULL);
  H5Sclose(fs);
  H5Dclose(ds);
  return dims;
}

void write_box(hid_t file, const std::string &name, const double *buf, const int *M, const int *xs, const int *xm, int comps, const Check &chk,
               const bool *wrap) {
  const int rank = comps > 1 ? 4 : 3;
  bool w[3] = {false, false, false};
  for (int d = 0; d < 3; ++d) w[d] = wrap && wrap[d];
  // File axes are z, y, x (, comps); direction d is file axis 2 - d.
  hsize_t g[4] = {(hsize_t)(M[2] + w[2]), (hsize_t)(M[1] + w[1]), (hsize_t)(M[0] + w[0]), (hsize_t)comps};
  hsize_t l[4] = {(hsize_t)xm[2], (hsize_t)xm[1], (hsize_t)xm[0], (hsize_t)comps};
  hid_t fs = H5Screate_simple(rank, g, NULL);
  hid_t ds = H5Dcreate2(file, name.c_str(), H5T_NATIVE_DOUBLE, fs, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  chk.id(ds, "create dataset " + name);
  hid_t ms = H5Screate_simple(rank, l, NULL);
  hid_t dx = collective();
  // Subset 0 is the owned box itself; subset S (bits = wrapped directions) copies the
  // owned layer 0 in those directions to layer M there. Every rank takes part in every
  // write (collective), selecting nothing if it does not own layer 0 of S's directions.
  for (int S = 0; S < 8; ++S) {
    bool skip = false, mine = true;
    hsize_t fstart[4] = {(hsize_t)xs[2], (hsize_t)xs[1], (hsize_t)xs[0], 0}, mstart[4] = {0, 0, 0, 0}, cnt[4] = {l[0], l[1], l[2], l[3]};
    for (int d = 0; d < 3; ++d)
      if (S >> d & 1) {
        if (!w[d]) skip = true;
        mine = mine && xs[d] == 0;
        fstart[2 - d] = (hsize_t)M[d];
        cnt[2 - d] = 1;
      }
    if (skip) continue;
    if (mine) {
      chk(H5Sselect_hyperslab(fs, H5S_SELECT_SET, fstart, NULL, cnt, NULL), "select box of " + name);
      chk(H5Sselect_hyperslab(ms, H5S_SELECT_SET, mstart, NULL, cnt, NULL), "select box of " + name);
    } else {
      H5Sselect_none(fs);
      H5Sselect_none(ms);
    }
    agree(H5Dwrite(ds, H5T_NATIVE_DOUBLE, ms, fs, dx, buf), "write " + name, chk);
  }
  H5Pclose(dx);
  H5Sclose(ms);
  H5Sclose(fs);
  H5Dclose(ds);
  store_checksum(file, name, box_checksum(buf, g, xs, xm, comps), chk);
}

void read_box(hid_t file, const std::string &name, double *buf, const int *xs, const int *xm, int comps, const Check &chk) {
  hid_t ds = -1;
  H5E_BEGIN_TRY { ds = H5Dopen2(file, name.c_str(), H5P_DEFAULT); }
  H5E_END_TRY;
  chk.id(ds, "open dataset " + name);
  const int rank = comps > 1 ? 4 : 3;
  hsize_t l[4] = {(hsize_t)xm[2], (hsize_t)xm[1], (hsize_t)xm[0], (hsize_t)comps};
  hsize_t s[4] = {(hsize_t)xs[2], (hsize_t)xs[1], (hsize_t)xs[0], 0};
  hid_t fs = H5Dget_space(ds);
  hsize_t g[4] = {0, 0, 0, 0};
  if (H5Sget_simple_extent_ndims(fs) != rank) chk(-1, "read " + name + " (another number of components)");
  H5Sget_simple_extent_dims(fs, g, NULL);
  hid_t ms = H5Screate_simple(rank, l, NULL);
  chk(H5Sselect_hyperslab(fs, H5S_SELECT_SET, s, NULL, l, NULL), "select box of " + name);
  hid_t dx = collective();
  agree(H5Dread(ds, H5T_NATIVE_DOUBLE, ms, fs, dx, buf), "read " + name, chk);
  H5Pclose(dx);
  H5Sclose(ms);
  H5Sclose(fs);
  H5Dclose(ds);
  verify_checksum(file, name, box_checksum(buf, g, xs, xm, comps), true, chk);
}

void group(hid_t file, const std::string &name) { H5Gclose(H5Gcreate2(file, name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT)); }

void attr_double(hid_t obj, const std::string &name, double v) { attr_doubles(obj, name, {v}); }

void attr_doubles(hid_t obj, const std::string &name, const std::vector<double> &v) {
  hsize_t n = v.size() ? v.size() : 1;
  hid_t sp = H5Screate_simple(1, &n, NULL);
  hid_t a = H5Acreate2(obj, name.c_str(), H5T_NATIVE_DOUBLE, sp, H5P_DEFAULT, H5P_DEFAULT);
  const double zero = 0;
  H5Awrite(a, H5T_NATIVE_DOUBLE, v.size() ? v.data() : &zero);
  H5Aclose(a);
  H5Sclose(sp);
}

void attr_string(hid_t obj, const std::string &name, const std::string &v) {
  hid_t t = H5Tcopy(H5T_C_S1);
  H5Tset_size(t, v.size() + 1);
  hid_t sp = H5Screate(H5S_SCALAR);
  hid_t a = H5Acreate2(obj, name.c_str(), t, sp, H5P_DEFAULT, H5P_DEFAULT);
  H5Awrite(a, t, v.c_str());
  H5Aclose(a);
  H5Sclose(sp);
  H5Tclose(t);
}

bool has_attr(hid_t obj, const std::string &name) { return H5Aexists(obj, name.c_str()) > 0; }

double read_attr_double(hid_t obj, const std::string &name, const Check &chk) {
  const std::vector<double> v = read_attr_doubles(obj, name, chk);
  return v.empty() ? 0.0 : v[0];
}

std::vector<double> read_attr_doubles(hid_t obj, const std::string &name, const Check &chk) {
  if (!has_attr(obj, name)) chk(-1, "find attribute " + name);
  hid_t a = H5Aopen(obj, name.c_str(), H5P_DEFAULT);
  hid_t sp = H5Aget_space(a);
  std::vector<double> v(H5Sget_simple_extent_npoints(sp));
  chk(H5Aread(a, H5T_NATIVE_DOUBLE, v.data()), "read attribute " + name);
  H5Sclose(sp);
  H5Aclose(a);
  return v;
}

std::string read_attr_string(hid_t obj, const std::string &name, const Check &chk) {
  if (!has_attr(obj, name)) chk(-1, "find attribute " + name);
  hid_t a = H5Aopen(obj, name.c_str(), H5P_DEFAULT);
  hid_t t = H5Aget_type(a);
  std::string s(H5Tget_size(t), '\0');
  chk(H5Aread(a, t, s.data()), "read attribute " + name);
  H5Tclose(t);
  H5Aclose(a);
  s.resize(s.find('\0') == std::string::npos ? s.size() : s.find('\0'));
  return s;
}

} // namespace granmpm::h5
