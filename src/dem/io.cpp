// DEM output (summary CSV, HDF5+XDMF grain snapshots), checkpoint/restart, and the
// `granmpm -dem` driver.
#include <algorithm>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <unordered_map>

#include "../h5util.hpp"
#include "granmpm/checkpoint.hpp"
#include "granmpm/config.hpp"
#include "granmpm/dem/dem.hpp"
#include "granmpm/output.hpp"

namespace granmpm { // set by main()'s SIGTERM/SIGINT and SIGUSR1 handlers (src/simulation.cpp)
extern volatile std::sig_atomic_t stop_signal;
extern volatile std::sig_atomic_t checkpoint_signal;
} // namespace granmpm

namespace granmpm::dem {

namespace {

long exscan(MPI_Comm comm, long n, long *total) {
  long off = 0;
  MPI_Exscan(&n, &off, 1, MPI_LONG, MPI_SUM, comm);
  int r;
  MPI_Comm_rank(comm, &r);
  if (r == 0) off = 0;
  MPI_Allreduce(&n, total, 1, MPI_LONG, MPI_SUM, comm);
  return off;
}

// Checkpoint format 3: per grain id, x, v, w, x0, f, torque, r, theta, mass weight and the
// orientation quaternion w, x, y, z (3D; 2D: 1, 0, 0, 0), and 8 state values (the last the
// format number). Format 2 (22 columns, 7 state values) lacks the orientation; format 1
// (21 columns, 6 state values) the mass weight too. A run without orientations
// (-dem_orientation false) writes theta 0 and the quaternion 0, 0, 0, 0 (not a rotation).
constexpr int CK_COLS = 26, CK_FORMAT = 3;

// Rows of an older format (cols columns) widened to CK_COLS: mass weight 1 (grains wholly
// discrete), identity orientation.
std::vector<double> widen_rows(const std::vector<double> &old, long N, int cols) {
  std::vector<double> rows((size_t)N * CK_COLS, 0.0);
  for (long g = 0; g < N; ++g) {
    double *q = &rows[(size_t)g * CK_COLS];
    std::copy_n(&old[(size_t)g * cols], cols, q);
    if (cols < 22) q[21] = 1.0;
    q[22] = 1.0;
  }
  return rows;
}

// An older checkpoint restarts its spheres unrotated: said once, on rank 0.
void note_no_orientation(MPI_Comm comm, int dim, const std::string &what, int format) {
  int r;
  MPI_Comm_rank(comm, &r);
  if (dim == 3 && r == 0)
    std::printf("dem: note: %s is a format-%d DEM checkpoint without grain orientations: the spheres restart with the identity orientation\n", what.c_str(), format);
}

// A checkpoint written with -dem_orientation false: its grains restart unrotated (collective).
void note_orientation_off(MPI_Comm comm, bool mine) {
  int any = mine, r;
  MPI_Allreduce(MPI_IN_PLACE, &any, 1, MPI_INT, MPI_MAX, comm);
  MPI_Comm_rank(comm, &r);
  if (any && r == 0)
    std::printf("dem: note: the checkpoint was written with -dem_orientation false: its grains restart with the identity orientation\n");
}

} // namespace

void Engine::pack_state(std::vector<double> &rows, std::vector<double> &hist) const {
  rows.assign((size_t)nown_ * CK_COLS, 0.0);
  for (long i = 0; i < nown_; ++i) {
    double *q = &rows[(size_t)i * CK_COLS];
    const V3 a[6] = {x_[i], v_[i], w_[i], x0_[i], f_[i], tq_[i]};
    q[0] = (double)id_[i];
    for (int b = 0; b < 6; ++b) {
      q[1 + 3 * b] = a[b].x;
      q[2 + 3 * b] = a[b].y;
      q[3 + 3 * b] = a[b].z;
    }
    q[19] = r_[i];
    q[20] = theta_.empty() ? 0.0 : theta_[i];
    q[21] = mw_.empty() ? 1.0 : mw_[i];
    const Quat o = c_.orientation ? orientation(i) : Quat{0, 0, 0, 0};
    q[22] = o.w;
    q[23] = o.x;
    q[24] = o.y;
    q[25] = o.z;
  }
  hist.clear();
  for (const HistRec &s : owned_springs(nullptr)) {
    const double rec[5] = {(double)s.a, (double)s.b, s.h.x, s.h.y, s.h.z};
    hist.insert(hist.end(), rec, rec + 5);
  }
}

std::vector<double> Engine::state_attr(long N, long H) const {
  long R;
  double RM;
  MPI_Allreduce(&removed_, &R, 1, MPI_LONG, MPI_SUM, comm_);
  MPI_Allreduce(&removed_mass_, &RM, 1, MPI_DOUBLE, MPI_SUM, comm_);
  return {t_, (double)step_, dt_, (double)N, (double)H, (double)R, RM, (double)CK_FORMAT};
}

void Engine::write_checkpoint(const std::string &path) {
  std::vector<double> rows, hist;
  pack_state(rows, hist);
  const h5::Check chk{path};
  h5::TmpFile tf(comm_, path, "-dem_checkpoint");
  const hid_t f = tf.id();
  long N, H;
  const long off = exscan(comm_, nown_, &N);
  const long hoff = exscan(comm_, (long)hist.size() / 5, &H);
  h5::write_rows(f, "grains", H5T_NATIVE_DOUBLE, rows.data(), nown_, off, N, CK_COLS, chk);
  h5::write_rows(f, "springs", H5T_NATIVE_DOUBLE, hist.data(), hist.size() / 5, hoff, H, 5, chk);
  h5::attr_doubles(f, "state", state_attr(N, H));
  if (own_bodies_) { // per body c[3], angle, v[3], omega; then the last pass's contact forces
    std::vector<double> b;
    for (const BodyMotionState &s : bst_) append_motion_state(b, s);
    b.insert(b.end(), blast_.begin(), blast_.end());
    h5::attr_doubles(f, "bodies", b);
  }
  tf.publish();
}

void Engine::write_state(CheckpointIO &io, const std::string &prefix) const {
  std::vector<double> rows, hist;
  pack_state(rows, hist);
  long N, H;
  const long off = exscan(comm_, nown_, &N);
  const long hoff = exscan(comm_, (long)hist.size() / 5, &H);
  io.write_rows(prefix + "grains", rows.data(), nown_, off, N, CK_COLS);
  io.write_rows(prefix + "springs", hist.data(), (long)hist.size() / 5, hoff, H, 5);
  io.write_attr(prefix + "state", state_attr(N, H));
  if (!bprev_.empty()) io.write_attr(prefix + "body_force", bprev_); // the bodies' last contact forces (the next step's first kick; the same on every rank)
}

void Engine::read_state(CheckpointIO &io, const std::string &prefix) {
  if (!io.has_attr(prefix + "state")) io.bad("no DEM grains in it (written by a run without -hybrid_dem?)");
  const std::vector<double> st = io.read_attr(prefix + "state");
  // Format 2 (7 state values, 22 columns: no orientations) or 3.
  const int format = st.size() == 7 ? 2 : (st.size() == 8 ? (int)st[7] : 0);
  if (format != 2 && format != CK_FORMAT) io.bad("its DEM grains are in an unknown format (written by a newer GranMPM?)");
  if (st[2] != dt_) io.bad("its DEM time step differs from this run's: use the -dem_ options of the checkpointed run");
  t_ = st[0];
  step_ = (long)st[1];
  const long N = (long)st[3], H = (long)st[4];
  removed_ = rank_ == 0 ? (long)st[5] : 0;
  removed_mass_ = rank_ == 0 ? st[6] : 0.0;
  const int cols = format == 2 ? 22 : CK_COLS;
  std::vector<double> rows((size_t)N * cols), hist((size_t)H * 5);
  io.read_all_rows(prefix + "grains", rows.data(), N, cols);
  io.read_all_rows(prefix + "springs", hist.data(), H, 5);
  if (cols != CK_COLS) {
    rows = widen_rows(rows, N, cols);
    note_no_orientation(comm_, c_.dim, "the restart file", format);
  }
  unpack_state(rows, hist);
  if (!bprev_.empty()) {
    if (!io.has_attr(prefix + "body_force")) io.bad("it has no DEM forces on rigid bodies (written by a run without bodies?)");
    const std::vector<double> g = io.read_attr(prefix + "body_force");
    if (g.size() != bprev_.size()) io.bad("its number of rigid bodies differs from this run's");
    bprev_ = g;
  }
}

Backup Engine::backup() const {
  Backup b;
  pack_state(b.rows, b.hist);
  b.t = t_;
  b.step = step_;
  b.removed = removed_;
  b.removed_mass = removed_mass_;
  b.body_prev = bprev_;
  return b;
}

namespace {
std::vector<double> allgather(MPI_Comm comm, const std::vector<double> &mine) {
  int size, n = (int)mine.size();
  MPI_Comm_size(comm, &size);
  std::vector<int> cnt(size), off(size + 1, 0);
  MPI_Allgather(&n, 1, MPI_INT, cnt.data(), 1, MPI_INT, comm);
  for (int r = 0; r < size; ++r) off[r + 1] = off[r] + cnt[r];
  std::vector<double> all(off[size]);
  MPI_Allgatherv(mine.data(), n, MPI_DOUBLE, all.data(), cnt.data(), off.data(), MPI_DOUBLE, comm);
  return all;
}
} // namespace

// The grains may have left their owner's box since the backup: every rank reads them all.
void Engine::restore(const Backup &b) {
  t_ = b.t;
  step_ = b.step;
  removed_ = b.removed;
  removed_mass_ = b.removed_mass;
  unpack_state(allgather(comm_, b.rows), allgather(comm_, b.hist));
  bprev_ = b.body_prev;
}

void Engine::read_checkpoint(const std::string &path) {
  const h5::Check chk{path};
  hid_t f = h5::open_read(comm_, path);
  if (f < 0) throw UserError("-dem_restart: cannot open '" + path + "' as an HDF5 DEM checkpoint");
  const auto st = h5::read_attr_doubles(f, "state", chk);
  // Format 1 (before the hybrid's grain mass weights): 6 state values, 21 columns per grain.
  // It lacks the removed mass, so it restarts only if no grain had left through an outlet.
  // Format 2: 7 state values, 22 columns (no orientations).
  const int format = st.size() == 6 ? 1 : (st.size() == 7 ? 2 : (st.size() == 8 ? (int)st[7] : 0));
  const bool format1 = format == 1;
  if (format < 1 || format > CK_FORMAT) {
    H5Fclose(f);
    throw UserError("-dem_restart: '" + path + "' is not a DEM checkpoint of a known format");
  }
  if (format1 && st[5] != 0) {
    H5Fclose(f);
    throw UserError("-dem_restart: '" + path + "' was written by an older GranMPM without the removed grains' mass (" + std::to_string((long)st[5]) +
                    " grains removed): restart it with the version that wrote it");
  }
  t_ = st[0];
  step_ = (long)st[1];
  if (st[2] != dt_) {
    H5Fclose(f);
    throw UserError("-dem_restart: the checkpoint's dt " + std::to_string(st[2]) + " differs from this run's " + std::to_string(dt_) +
                    ": use the options of the checkpointed run");
  }
  const long N = (long)st[3], H = (long)st[4];
  removed_ = rank_ == 0 ? (long)st[5] : 0;
  removed_mass_ = rank_ == 0 && !format1 ? st[6] : 0.0;
  std::vector<double> rows((size_t)N * CK_COLS), hist((size_t)H * 5);
  if (format < CK_FORMAT) { // widen each row (mass weight 1, identity orientation)
    const int cols = format == 1 ? 21 : 22;
    std::vector<double> old((size_t)N * cols);
    h5::read_rows(f, "grains", H5T_NATIVE_DOUBLE, old.data(), N, 0, cols, chk);
    rows = widen_rows(old, N, cols);
    note_no_orientation(comm_, c_.dim, "'" + path + "'", format);
  } else {
    h5::read_rows(f, "grains", H5T_NATIVE_DOUBLE, rows.data(), N, 0, CK_COLS, chk);
  }
  h5::read_rows(f, "springs", H5T_NATIVE_DOUBLE, hist.data(), H, 0, 5, chk);
  if (own_bodies_) { // before the lists are built: they look at the bodies' poses
    const size_t n = bst_.size();
    const std::vector<double> b = h5::has_attr(f, "bodies") ? h5::read_attr_doubles(f, "bodies", chk) : std::vector<double>();
    if (b.size() != 12 * n) {
      H5Fclose(f);
      throw UserError("-dem_restart: '" + path + "' holds " + (b.empty() ? std::string("no rigid bodies") : std::to_string(b.size() / 12) + " rigid bodies") +
                      ", this run has " + std::to_string(n) + " (-body<k>_shape): use the options of the checkpointed run");
    }
    for (size_t k = 0; k < n; ++k) read_motion_state(&b[8 * k], bst_[k]);
    blast_.assign(b.begin() + 8 * n, b.end());
    bprev_ = blast_; // the next first kick's share
    set_body_states(bst_, t_);
    blist_ = bnow_;
  } else if (h5::has_attr(f, "bodies")) {
    H5Fclose(f);
    throw UserError("-dem_restart: '" + path + "' holds rigid bodies, this run has none (-body<k>_shape): use the options of the checkpointed run");
  }
  H5Fclose(f);
  unpack_state(rows, hist);
}

// Every rank reads all rows and keeps the grains it owns (any rank count).
void Engine::unpack_state(const std::vector<double> &rows, const std::vector<double> &hist) {
  const long N = (long)(rows.size() / CK_COLS), H = (long)(hist.size() / 5);
  x_.clear();
  v_.clear();
  w_.clear();
  r_.clear();
  id_.clear();
  theta_.clear();
  q_.clear();
  mw_.clear();
  bool unrotated = false; // rows without orientations (written with -dem_orientation false)
  std::unordered_map<int64_t, long> row_of;
  for (long g = 0; g < N; ++g) {
    const double *q = &rows[(size_t)g * CK_COLS];
    const V3 x{q[1], q[2], q[3]};
    if (owner_rank(x) != rank_) continue;
    row_of[(int64_t)q[0]] = g;
    id_.push_back((int64_t)q[0]);
    x_.push_back(x);
    v_.push_back({q[4], q[5], q[6]});
    w_.push_back({q[7], q[8], q[9]});
    r_.push_back(q[19]);
    const bool none = q[22] == 0 && q[23] == 0 && q[24] == 0 && q[25] == 0;
    unrotated = unrotated || none;
    if (c_.orientation && c_.dim == 2) theta_.push_back(q[20]);
    if (c_.orientation && c_.dim == 3) q_.push_back(none ? Quat{} : Quat{q[22], q[23], q[24], q[25]});
    if (c_.mass_weight) mw_.push_back(q[21]);
  }
  if (c_.orientation) note_orientation_off(comm_, unrotated);
  nown_ = (long)id_.size();
  store_to_swarm();
  load_from_swarm();
  std::vector<HistRec> store;
  for (long k = 0; k < H; ++k) {
    const double *q = &hist[(size_t)k * 5];
    if (row_of.count((int64_t)q[0])) store.push_back({(int64_t)q[0], (int64_t)q[1], {q[2], q[3], q[4]}});
  }
  std::sort(store.begin(), store.end(), [](const HistRec &p, const HistRec &q) { return p.a != q.a ? p.a < q.a : p.b < q.b; });
  // The positions at the last rebuild give the canonical order of the uninterrupted run.
  x0_.resize(nown_);
  for (long i = 0; i < nown_; ++i) {
    const double *q = &rows[(size_t)row_of[id_[i]] * CK_COLS];
    x0_[i] = {q[10], q[11], q[12]};
  }
  set_keys();
  exchange_ghosts_full();
  build_lists(false, store);
  f_.assign(nown_, V3{});
  tq_.assign(nown_, V3{});
  for (long i = 0; i < nown_; ++i) {
    const double *q = &rows[(size_t)row_of[id_[i]] * CK_COLS];
    f_[i] = {q[13], q[14], q[15]};
    tq_[i] = {q[16], q[17], q[18]};
  }
  // Contact counts and energies of the restored state (no spring update: dt 0 would
  // still change nothing but is not needed; counts come from the next step).
  ncontact_.assign(nown_, 0);
}

void Engine::write_fields(int index) {
  const std::string base = "grains_" + std::to_string(100000 + index).substr(1);
  const std::string path = c_.output_dir + "/" + base + ".h5";
  const h5::Check chk{path};
  h5::TmpFile tf(comm_, path, "-dem_output_dir");
  const hid_t f = tf.id();
  long N;
  const long off = exscan(comm_, nown_, &N);
  std::vector<double> x(3 * nown_), v(3 * nown_), w(3 * nown_), r(nown_), nc(nown_), id(nown_), o(c_.orientation ? 4 * nown_ : 0);
  std::vector<int> conn(nown_);
  for (long i = 0; i < nown_; ++i) {
    const V3 a[3] = {x_[i], v_[i], w_[i]};
    double *d[3] = {&x[3 * i], &v[3 * i], &w[3 * i]};
    for (int b = 0; b < 3; ++b) {
      d[b][0] = a[b].x;
      d[b][1] = a[b].y;
      d[b][2] = a[b].z;
    }
    r[i] = r_[i];
    nc[i] = ncontact_.size() > (size_t)i ? ncontact_[i] : 0;
    id[i] = (double)id_[i];
    if (c_.orientation) {
      const Quat qi = orientation(i);
      o[4 * i] = qi.w;
      o[4 * i + 1] = qi.x;
      o[4 * i + 2] = qi.y;
      o[4 * i + 3] = qi.z;
    }
    conn[i] = (int)(off + i);
  }
  h5::group(f, "grains");
  h5::write_rows(f, "grains/position", H5T_NATIVE_DOUBLE, x.data(), nown_, off, N, 3, chk);
  h5::write_rows(f, "grains/velocity", H5T_NATIVE_DOUBLE, v.data(), nown_, off, N, 3, chk);
  h5::write_rows(f, "grains/omega", H5T_NATIVE_DOUBLE, w.data(), nown_, off, N, 3, chk);
  // w, x, y, z: ParaView's Glyph representation orients by it with Orientation Mode Quaternion.
  if (c_.orientation) h5::write_rows(f, "grains/orientation", H5T_NATIVE_DOUBLE, o.data(), nown_, off, N, 4, chk);
  h5::write_rows(f, "grains/radius", H5T_NATIVE_DOUBLE, r.data(), nown_, off, N, 1, chk);
  h5::write_rows(f, "grains/contacts", H5T_NATIVE_DOUBLE, nc.data(), nown_, off, N, 1, chk);
  h5::write_rows(f, "grains/id", H5T_NATIVE_DOUBLE, id.data(), nown_, off, N, 1, chk);
  if (c_.mass_weight) { // a hybrid run: the share of its mass each grain carries (1: discrete zone, < 1: band)
    std::vector<double> mw(mw_.begin(), mw_.begin() + nown_);
    h5::write_rows(f, "grains/mass_share", H5T_NATIVE_DOUBLE, mw.data(), nown_, off, N, 1, chk);
  }
  h5::write_rows(f, "grains/connectivity", H5T_NATIVE_INT, conn.data(), nown_, off, N, 1, chk);
  h5::attr_double(f, "time", t_);
  const long C = c_.force_chains ? write_chains(f, path) : 0;
  tf.publish();
  std::string err; // rank 0 writes the XDMF; every rank learns whether that failed
  if (rank_ == 0) try {
      write_xdmf(base, N);
      if (c_.force_chains) write_chain_xdmf(base, C);
    } catch (const UserError &e) {
      err = e.what();
    }
  collective_fail(comm_, !err.empty(), err);
}

// The contact network: one line per force-carrying grain pair (the contacts of the summary:
// f_n > 0 at the last force pass, re-evaluated at the velocities that pass saw, with the
// springs as they are: dt = 0), written by the rank owning the pair's lower grain id; its
// ends are the two centres (the partner's image across a periodic face: the line stays
// short). Per line: |f_n| and |f_t|.
long Engine::write_chains(hid_t f, const std::string &path) {
  const h5::Check chk{path};
  std::vector<double> ends, fn, ft;
  auto vhalf = [&](long i) { return i < nown_ ? v_[i] - (kick_ * inv_mass(i)) * f_[i] : v_[dat(i)]; }; // other ranks' ghosts hold it already
  auto half_image = [&](long i) { // an own image's grain has taken its kick: undo it as for an owned grain
    return i < nd_ ? vhalf(i) : vhalf(dat(i));
  };
  for (long p = 0, k = 0, q = 0; p < ntot_; ++p) {
    const int i = ord_[p];
    for (const long end = q + nl_[p]; q < end; ++q) {
      const int j = partner(nb_[q]);
      V3 h = nb_[q] < 0 ? pool_[k++] : V3{};
      const long di = dat(i), dj = dat(j);
      if ((id_[di] < id_[dj] ? i : j) >= nown_) continue;
      const V3 d = pair_sep(i, j);
      if (dot(d, d) >= (r_[di] + r_[dj]) * (r_[di] + r_[dj])) continue;
      const ContactResult res = contact(c_.contact, d, r_[di], r_[dj], half_image(i) - half_image(j), w_[di], w_[dj], 1.0 / (inv_mass(di) + inv_mass(dj)), 1.0 / (inv_inertia(di) + inv_inertia(dj)), h, 0.0);
      if (!(res.fn > 0)) continue;
      const V3 a = i < nown_ ? x_[i] : x_[di] + gshift(i - nown_), b = a + d;
      ends.insert(ends.end(), {a.x, a.y, a.z, b.x, b.y, b.z});
      fn.push_back(res.fn);
      const V3 t = res.force + (res.fn / norm(d)) * d; // the force less its normal part
      ft.push_back(norm(t));
    }
  }
  long C;
  const long c = (long)fn.size(), off = exscan(comm_, c, &C);
  std::vector<int> conn(2 * c);
  for (long k = 0; k < 2 * c; ++k) conn[k] = (int)(2 * off + k);
  h5::group(f, "chains");
  h5::write_rows(f, "chains/position", H5T_NATIVE_DOUBLE, ends.data(), 2 * c, 2 * off, 2 * C, 3, chk);
  h5::write_rows(f, "chains/connectivity", H5T_NATIVE_INT, conn.data(), c, off, C, 2, chk);
  h5::write_rows(f, "chains/normal_force", H5T_NATIVE_DOUBLE, fn.data(), c, off, C, 1, chk);
  h5::write_rows(f, "chains/tangential_force", H5T_NATIVE_DOUBLE, ft.data(), c, off, C, 1, chk);
  chains_ = C;
  return C;
}

void Engine::write_chain_xdmf(const std::string &base, long C) {
  auto item = [&](const std::string &ds, const std::string &dims, const char *type = "Float") {
    std::ostringstream s;
    s << "<DataItem Dimensions=\"" << dims << "\" NumberType=\"" << type << "\" Precision=\"" << (std::string(type) == "Int" ? 4 : 8) << "\" Format=\"HDF\">" << base
      << ".h5:/chains/" << ds << "</DataItem>";
    return s.str();
  };
  const std::string n = std::to_string(C);
  std::ostringstream g;
  g << "  <Grid Name=\"chains\" GridType=\"Uniform\">\n   <Time Value=\"" << t_ << "\"/>\n";
  g << "   <Topology TopologyType=\"Polyline\" NumberOfElements=\"" << n << "\" NodesPerElement=\"2\">" << item("connectivity", n + " 2", "Int") << "</Topology>\n";
  g << "   <Geometry GeometryType=\"XYZ\">" << item("position", std::to_string(2 * C) + " 3") << "</Geometry>\n";
  for (const char *s : {"normal_force", "tangential_force"})
    g << "   <Attribute Name=\"" << s << "\" AttributeType=\"Scalar\" Center=\"Cell\">" << item(s, n) << "</Attribute>\n";
  g << "  </Grid>\n";
  const std::string head = "<?xml version=\"1.0\" ?>\n<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n<Xdmf Version=\"2.0\">\n <Domain>\n";
  chain_series_ += g.str();
  const std::string cbase = "chains_" + base.substr(base.size() - 5);
  std::FILE *x = open_atomic(c_.output_dir + "/" + cbase + ".xmf", "-dem_output_dir");
  std::fputs((head + g.str() + " </Domain>\n</Xdmf>\n").c_str(), x);
  close_atomic(x);
  x = open_atomic(c_.output_dir + "/chains.xmf", "-dem_output_dir");
  std::fputs((head + " <Grid Name=\"series\" GridType=\"Collection\" CollectionType=\"Temporal\">\n" + chain_series_ + " </Grid>\n </Domain>\n</Xdmf>\n").c_str(), x);
  close_atomic(x);
}

void Engine::write_xdmf(const std::string &base, long N) {
  // XDMF: one grid per snapshot and a temporal collection of all snapshots so far.
  auto item = [&](const std::string &ds, const std::string &dims, const char *type = "Float") {
    std::ostringstream s;
    s << "<DataItem Dimensions=\"" << dims << "\" NumberType=\"" << type << "\" Precision=\"" << (std::string(type) == "Int" ? 4 : 8) << "\" Format=\"HDF\">" << base
      << ".h5:/grains/" << ds << "</DataItem>";
    return s.str();
  };
  const std::string n = std::to_string(N);
  std::ostringstream g;
  g << "  <Grid Name=\"grains\" GridType=\"Uniform\">\n   <Time Value=\"" << t_ << "\"/>\n";
  g << "   <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"" << n << "\" NodesPerElement=\"1\">" << item("connectivity", n, "Int") << "</Topology>\n";
  g << "   <Geometry GeometryType=\"XYZ\">" << item("position", n + " 3") << "</Geometry>\n";
  const char *vec[3] = {"velocity", "omega", nullptr};
  for (int b = 0; vec[b]; ++b)
    g << "   <Attribute Name=\"" << vec[b] << "\" AttributeType=\"Vector\" Center=\"Node\">" << item(vec[b], n + " 3") << "</Attribute>\n";
  if (c_.orientation) g << "   <Attribute Name=\"orientation\" AttributeType=\"Matrix\" Center=\"Node\">" << item("orientation", n + " 4") << "</Attribute>\n";
  for (const char *s : {"radius", "contacts", "id", "mass_share"})
    if (std::string(s) != "mass_share" || c_.mass_weight)
    g << "   <Attribute Name=\"" << s << "\" AttributeType=\"Scalar\" Center=\"Node\">" << item(s, n) << "</Attribute>\n";
  g << "  </Grid>\n";
  const std::string head = "<?xml version=\"1.0\" ?>\n<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n<Xdmf Version=\"2.0\">\n <Domain>\n";
  series_ += g.str();
  // Published atomically too: a viewer never reads a half-written series.
  std::FILE *x = open_atomic(c_.output_dir + "/" + base + ".xmf", "-dem_output_dir");
  std::fputs((head + g.str() + " </Domain>\n</Xdmf>\n").c_str(), x);
  close_atomic(x);
  x = open_atomic(c_.output_dir + "/grains.xmf", "-dem_output_dir");
  std::fputs((head + " <Grid Name=\"series\" GridType=\"Collection\" CollectionType=\"Temporal\">\n" + series_ + " </Grid>\n </Domain>\n</Xdmf>\n").c_str(), x);
  close_atomic(x);
}

int Engine::run() {
  if (rank_ == 0) std::filesystem::create_directories(c_.output_dir);
  MPI_Barrier(comm_);
  const long nsteps = c_.max_steps >= 0 ? c_.max_steps : (long)std::ceil((c_.t_end - t_) / dt_ - 1e-9);
  const long last = step_ + std::max(0L, nsteps);
  const long every = c_.output_every > 0 ? c_.output_every : std::max(1L, nsteps / 100);
  std::FILE *csv = nullptr;
  if (rank_ == 0) {
    csv = std::fopen((c_.output_dir + "/dem_summary.csv").c_str(), c_.restart.empty() ? "w" : "a");
    if (!csv) throw UserError("cannot write " + c_.output_dir + "/dem_summary.csv: check -dem_output_dir");
    if (c_.restart.empty()) std::fprintf(csv, "step,t,kinetic,rotational,gravity_pe,elastic_pe,contacts,wall_contacts,coordination,max_overlap,grains,removed\n");
  }
  int snap = 0;
  auto row = [&]() {
    const Summary s = summary();
    if (csv)
      std::fprintf(csv, "%ld,%.9g,%.12g,%.12g,%.12g,%.12g,%ld,%ld,%.6g,%.6g,%ld,%ld\n", s.step, s.t, s.ke, s.ke_rot, s.pe_grav, s.pe_elastic, s.contacts, s.wall_contacts,
                   s.coordination, s.max_overlap, s.grains, s.removed);
    if (rank_ == 0 && !c_.quiet)
      std::printf("dem step %ld t %.5g KE %.4g contacts %ld Z %.3g max overlap %.3g\n", s.step, s.t, s.ke + s.ke_rot, s.contacts, s.coordination, s.max_overlap);
    if (rank_ == 0 && !c_.quiet) std::fflush(stdout); // a progress line is seen when it is printed (logs, pipes)
  };
  if (rank_ == 0 && !c_.quiet) {
    std::printf("dem: dt %.4g (t_c %.4g), %ld steps\n", dt_, tc_, nsteps);
  }
  if (c_.restart.empty()) row();
  if (c_.restart.empty()) write_bodies_csv(true);
  if (c_.fields) write_fields(snap++);
  bool first = true;
  while (step_ < last) {
    step();
    if (first && after_first_step_) after_first_step_(comm_);
    first = false;
    if (step_ % every == 0 || step_ == last) row();
    write_bodies_csv(step_ == last);
    if (c_.fields && c_.fields_every > 0 && step_ % c_.fields_every == 0 && step_ != last) write_fields(snap++);
    if (!c_.checkpoint.empty() && c_.checkpoint_every > 0 && step_ % c_.checkpoint_every == 0) write_checkpoint(c_.checkpoint);
    // The handlers only set flags; the ranks agree on them here so that all of them write
    // the checkpoint and stop (or continue) together. Without -dem_checkpoint a stop still
    // keeps the state, in <output_dir>/dem_checkpoint.h5.
    int flags[2] = {(int)stop_signal, (int)checkpoint_signal}, got[2] = {0, 0};
    MPI_Allreduce(flags, got, 2, MPI_INT, MPI_MAX, comm_);
    if (got[0] || got[1]) {
      checkpoint_signal = 0;
      const std::string ck = c_.checkpoint.empty() ? c_.output_dir + "/dem_checkpoint.h5" : c_.checkpoint;
      write_checkpoint(ck);
      if (rank_ == 0)
        std::printf("dem: received signal %d at step %ld (t = %.6g): checkpoint written to %s%s\n", got[0] ? got[0] : (int)SIGUSR1, step_, t_, ck.c_str(),
                    got[0] ? "; continue with -dem_restart and the same options" : "; the run continues");
      if (got[0]) {
        if (csv) std::fclose(csv);
        return got[0];
      }
    }
  }
  if (c_.fields) write_fields(snap++);
  if (!c_.checkpoint.empty()) write_checkpoint(c_.checkpoint);
  if (csv) std::fclose(csv);
  if (rank_ == 0 && !c_.quiet) {
    const Timers &t = tm_;
    std::printf("dem: %ld steps, %ld rebuilds; time neighbour %.3g s, force %.3g s, comm %.3g s, integrate %.3g s; %zu bytes/grain\n", step_, t.rebuilds, t.neigh,
                t.force, t.comm, t.integrate, bytes_per_grain());
    std::printf("dem: footprint %s\n", footprint().c_str());
  }
  return 0;
}

namespace {
// The results an earlier run left in dir (summary, snapshots, series, checkpoint).
std::vector<std::string> earlier_results(const std::string &dir) {
  std::vector<std::string> found;
  std::error_code ec;
  for (const auto &e : std::filesystem::directory_iterator(dir, ec)) {
    const std::string n = e.path().filename().string();
    if (n == "dem_summary.csv" || n == "bodies.csv" || n == "grains.xmf" || n == "dem_checkpoint.h5" || n.rfind("grains_", 0) == 0) found.push_back(n);
  }
  std::sort(found.begin(), found.end());
  return found;
}

// A new run into a directory that holds another run's results would overwrite some of them
// and leave the rest mixed in: refused unless -dem_output_overwrite (which removes them
// first) or a restart continues that run. Rank 0 looks; every rank gets the verdict.
void check_output_dir(MPI_Comm comm, const Config &c) {
  if (!c.restart.empty()) return;
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  std::string msg;
  if (rank == 0) {
    const std::vector<std::string> old = earlier_results(c.output_dir);
    if (!old.empty() && !c.output_overwrite) {
      msg = "-dem_output_dir '" + c.output_dir + "' holds another run's results (" + old.front() +
            (old.size() > 1 ? " and " + std::to_string(old.size() - 1) + " more" : std::string()) +
            "); choose another -dem_output_dir, continue that run with -dem_restart, or add -dem_output_overwrite to replace them";
    } else {
      for (const std::string &n : old) std::filesystem::remove(std::filesystem::path(c.output_dir) / n);
    }
  }
  int len = (int)msg.size();
  MPI_Bcast(&len, 1, MPI_INT, 0, comm);
  msg.resize(len);
  MPI_Bcast(msg.data(), len, MPI_CHAR, 0, comm);
  if (len > 0) throw UserError(msg);
}
} // namespace

int run_main(MPI_Comm comm, bool help_only, void (*after_first_step)(MPI_Comm)) {
  const Config c = Config::from_options(comm, true, true); // with the -body<k>_* bodies
  if (help_only) return 0;
  check_output_dir(comm, c);
  Engine e(comm, c);
  e.set_after_first_step(after_first_step);
  e.setup();
  return e.run();
}

} // namespace granmpm::dem
