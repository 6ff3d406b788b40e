#include "granmpm/output.hpp"

#include <hdf5.h>

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <map>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <algorithm>
#include <functional>
#include <numeric>
#include <sstream>

#include "granmpm/scene.hpp"
#include "granmpm/state.hpp"
#include "h5util.hpp"

namespace granmpm {

using h5::write_box;
using h5::write_rows;
using H5Check = h5::Check;

namespace {

// Named stress components written as scalars (index into the stored xx yy zz xy yz xz);
// in 2D (plane strain) yz and xz are zero and left out.
struct Component {
  const char *name;
  int index;
};
constexpr Component kStress[6] = {{"stress_xx", 0}, {"stress_yy", 1}, {"stress_zz", 2}, {"stress_xy", 3}, {"stress_yz", 4}, {"stress_xz", 5}};
template <int dim>
constexpr int n_stress_components() {
  return dim == 3 ? 6 : 4;
}
// Full 3x3 tensor from the stored xx yy zz xy yz xz (symmetric: row- and column-major agree).
constexpr int kFull[9] = {0, 3, 5, 3, 1, 4, 5, 4, 2};

// Every rigid body's outline: kOutlinePoints points, one polyline cell each. The XDMF
// "Mixed" connectivity of a body is {2 (polyline), count, point ids...}, with the first id
// repeated at the end when the outline is closed.
template <int dim>
long body_connectivity_size(const RigidBodies<dim> &B) {
  long n = 0;
  for (size_t k = 0; k < B.size(); ++k) n += 2 + Output<dim>::kOutlinePoints + (body_outline_closed(B.spec(k)) ? 1 : 0);
  return n;
}

// A particle field written as it is (a model's own field): not one of the fields above
// or the solver's internal ones.
bool generic_field(const std::string &n) {
  for (const char *k : {"apic_C", "fluidity", "gdot", "Be_minus_I", "p_prev", "mu_prev", "fluidity_split"})
    if (n == k) return false;
  return true;
}

template <int dim>
long write_particles(const State<dim> &S, hid_t file, const H5Check &chk) {
  auto &parts = const_cast<Particles<dim> &>(S.particles); // the field access needs the handle; nothing is changed
  ParticleView<dim> P = parts.get();
  long n = P.n, off = 0, tot = 0;
  MPI_Exscan(&n, &off, 1, MPI_LONG, MPI_SUM, S.comm);
  if (S.rank == 0) off = 0;
  MPI_Allreduce(&n, &tot, 1, MPI_LONG, MPI_SUM, S.comm);
  h5::group(file, "particles");
  auto rows = [&](const std::string &name, hid_t type, const void *buf, int cols) { write_rows(file, "/particles/" + name, type, buf, n, off, tot, cols, chk); };
  std::vector<double> b((size_t)n * 9);
  auto vec3 = [&](const double *src) {
    for (long p = 0; p < n; ++p)
      for (int d = 0; d < 3; ++d) b[p * 3 + d] = d < dim ? src[p * dim + d] : 0.0;
    return b.data();
  };
  // Vertex cell p is particle p of the file: global row numbers.
  std::vector<int64_t> conn(n);
  std::iota(conn.begin(), conn.end(), (int64_t)off);
  rows("connectivity", H5T_NATIVE_INT64, conn.data(), 1);
  rows("id", H5T_NATIVE_INT64, P.id, 1);
  rows("position", H5T_NATIVE_DOUBLE, vec3(P.x), 3);
  rows("velocity", H5T_NATIVE_DOUBLE, vec3(P.v), 3);
  rows("mass", H5T_NATIVE_DOUBLE, P.m, 1);
  rows("volume", H5T_NATIVE_DOUBLE, P.vol, 1);
  for (long p = 0; p < n; ++p) b[p] = P.m[p] / P.vol[p];
  rows("density", H5T_NATIVE_DOUBLE, b.data(), 1);
  for (long p = 0; p < n; ++p)
    for (int c = 0; c < 9; ++c) b[p * 9 + c] = P.s[6 * p + kFull[c]];
  rows("stress", H5T_NATIVE_DOUBLE, b.data(), 9);
  for (int c = 0; c < n_stress_components<dim>(); ++c) {
    for (long p = 0; p < n; ++p) b[p] = P.s[6 * p + kStress[c].index];
    rows(kStress[c].name, H5T_NATIVE_DOUBLE, b.data(), 1);
  }
  for (long p = 0; p < n; ++p) b[p] = pressure6(P.s + 6 * p);
  rows("pressure", H5T_NATIVE_DOUBLE, b.data(), 1);
  for (long p = 0; p < n; ++p) b[p] = tau6(P.s + 6 * p);
  rows("tau", H5T_NATIVE_DOUBLE, b.data(), 1);
  if (P.g) rows("fluidity", H5T_NATIVE_DOUBLE, P.g, 1);
  if (P.gdot) rows("gdot", H5T_NATIVE_DOUBLE, P.gdot, 1);
  if (P.Be) { // the symmetric elastic left Cauchy-Green tensor (stored as Be - I), all 9 components
    for (long p = 0; p < n; ++p)
      for (int c = 0; c < 9; ++c) b[p * 9 + c] = P.Be[6 * p + kFull[c]] + (c % 4 == 0 ? 1.0 : 0.0);
    rows("Be", H5T_NATIVE_DOUBLE, b.data(), 9);
  }
  // The fields a material model declares beyond the known ones, as they are.
  const auto &opt = parts.optional_fields();
  for (size_t i = 0; i < opt.size(); ++i)
    if (generic_field(opt[i].first)) rows(opt[i].first, H5T_NATIVE_DOUBLE, P.opt[i], opt[i].second);
  parts.restore(P);
  return tot;
}

// Grid: nodal mass, velocity (the state after the last grid update) where the node has
// real mass, and the mask of those nodes; periodic axes get their wrapped layer.
template <int dim>
void write_grid(const State<dim> &S, hid_t file, const H5Check &chk) {
  const Grid<dim> &G = S.grid;
  const long nodes = (long)G.xm[0] * G.xm[1] * G.xm[2];
  const double m_real = Output<dim>::kGridMassFraction * S.cfg.rho * std::pow(G.h, dim);
  std::vector<double> gm(nodes), gv(nodes * 3), act(nodes);
  const double *a;
  GM_CALL(VecGetArrayRead(G.global, &a));
  constexpr int ND = Grid<dim>::NDOF;
  for (long q = 0; q < nodes; ++q) {
    gm[q] = a[q * ND];
    act[q] = gm[q] >= m_real ? 1.0 : 0.0;
    for (int d = 0; d < 3; ++d) gv[q * 3 + d] = d < dim && act[q] > 0 ? a[q * ND + 1 + d] : 0.0;
  }
  GM_CALL(VecRestoreArrayRead(G.global, &a));
  h5::group(file, "grid");
  write_box(file, "/grid/mass", gm.data(), G.M, G.xs, G.xm, 1, chk, G.periodic);
  write_box(file, "/grid/velocity", gv.data(), G.M, G.xs, G.xm, 3, chk, G.periodic);
  write_box(file, "/grid/active", act.data(), G.M, G.xs, G.xm, 1, chk, G.periodic);
  hid_t grp = H5Gopen2(file, "grid", H5P_DEFAULT);
  h5::attr_double(grp, "mass_threshold", m_real);
  h5::attr_doubles(grp, "wrapped", {(double)G.periodic[0], (double)G.periodic[1], (double)G.periodic[2]});
  H5Gclose(grp);
}

// Rigid bodies: kOutlinePoints points on each outline with the body's rigid velocity
// there and its index, and the polyline connectivity (rank 0 writes; every rank holds
// the same body state).
template <int dim>
void write_bodies(const State<dim> &S, hid_t file, const H5Check &chk) {
  const RigidBodies<dim> &B = *S.bodies;
  std::vector<double> pos, vel, idx;
  std::vector<int64_t> conn;
  double mid[3] = {0, 0, 0}, L = 0;
  for (int d = 0; d < dim; ++d) {
    mid[d] = 0.5 * (S.cfg.lo[d] + S.cfg.hi[d]);
    L += 0.25 * (S.cfg.hi[d] - S.cfg.lo[d]) * (S.cfg.hi[d] - S.cfg.lo[d]);
  }
  constexpr int n = Output<dim>::kOutlinePoints;
  for (size_t k = 0; k < B.size(); ++k) {
    const BodyPose &q = B.pose(k);
    const double z = dim == 3 ? (B.spec(k).shape == BodyShape::Plane ? mid[2] : q.c[2]) : 0.0;
    const int64_t first = (int64_t)idx.size();
    conn.insert(conn.end(), {2, n + (body_outline_closed(B.spec(k)) ? 1 : 0)});
    for (const auto &x : body_outline(B.spec(k), q, mid, std::sqrt(L), z, n)) {
      double v[3] = {0, 0, 0};
      body_velocity_at<dim>(B.velocity(k), B.omega(k), q, x.data(), v);
      conn.push_back((int64_t)idx.size());
      pos.insert(pos.end(), x.begin(), x.end());
      vel.insert(vel.end(), v, v + 3);
      idx.push_back((double)k);
    }
    if (body_outline_closed(B.spec(k))) conn.push_back(first);
  }
  const long nb = (long)idx.size(), mine = S.rank == 0 ? nb : 0, nc = (long)conn.size();
  h5::group(file, "bodies");
  write_rows(file, "/bodies/outline", H5T_NATIVE_DOUBLE, pos.data(), mine, 0, nb, 3, chk);
  write_rows(file, "/bodies/velocity", H5T_NATIVE_DOUBLE, vel.data(), mine, 0, nb, 3, chk);
  write_rows(file, "/bodies/body", H5T_NATIVE_DOUBLE, idx.data(), mine, 0, nb, 1, chk);
  write_rows(file, "/bodies/connectivity", H5T_NATIVE_INT64, conn.data(), S.rank == 0 ? nc : 0, 0, nc, 1, chk);
}

} // namespace

std::string sync_and_rename(const std::string &tmp, const std::string &path) {
  const int fd = ::open(tmp.c_str(), O_RDONLY);
  if (fd < 0) return std::string("cannot reopen the temporary: ") + std::strerror(errno);
  const int e = ::fsync(fd) != 0 ? errno : 0;
  ::close(fd);
  if (e) return std::string("fsync failed: ") + std::strerror(e);
  if (std::rename(tmp.c_str(), path.c_str()) != 0) return std::string("cannot rename the temporary over it: ") + std::strerror(errno);
  // The rename itself is durable once the directory is synced.
  std::string dir = std::filesystem::path(path).parent_path().string();
  const int dfd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
  return "";
}

namespace {
struct OpenText {
  std::string path, option;
};
std::map<std::FILE *, OpenText> &open_texts() {
  static std::map<std::FILE *, OpenText> m;
  return m;
}
} // namespace

std::FILE *open_atomic(const std::string &path, const std::string &option) {
  std::error_code ec;
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  if (!dir.empty()) std::filesystem::create_directories(dir, ec);
  const std::string tmp = path + ".tmp";
  errno = 0;
  std::FILE *f = std::fopen(tmp.c_str(), "w");
  if (!f) throw UserError("cannot write " + tmp + " (" + (ec ? ec.message() : std::string(std::strerror(errno))) + "): check " + option);
  open_texts()[f] = {path, option};
  return f;
}

void close_atomic(std::FILE *f) {
  auto it = open_texts().find(f);
  if (it == open_texts().end()) throw std::logic_error("close_atomic: not a file of open_atomic");
  const OpenText t = it->second;
  open_texts().erase(it);
  const std::string tmp = t.path + ".tmp";
  errno = 0;
  const bool werr = std::ferror(f) || std::fflush(f) != 0;
  const int e = errno;
  const bool cerr = std::fclose(f) != 0;
  std::string why;
  if (werr || cerr) why = e ? std::strerror(e) : (errno ? std::strerror(errno) : "write failed");
  else why = sync_and_rename(tmp, t.path);
  if (!why.empty()) {
    std::remove(tmp.c_str());
    throw UserError("cannot write " + t.path + " (" + why + "): check " + t.option);
  }
}

namespace {
// Files of a GranMPM run in a directory: snapshots and checkpoints (.h5), XDMF (.xmf), CSV.
std::vector<std::string> run_files(const std::string &dir) {
  std::vector<std::string> out;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (!it->is_regular_file(ec)) continue;
    const std::string ext = it->path().extension().string();
    if (ext == ".h5" || ext == ".xmf" || ext == ".csv") out.push_back(it->path().filename().string());
  }
  std::sort(out.begin(), out.end());
  return out;
}
bool same_dir(const std::string &a, const std::string &b) {
  std::error_code ec;
  const bool eq = std::filesystem::equivalent(a.empty() ? "." : a, b.empty() ? "." : b, ec);
  return !ec && eq;
}
} // namespace

void check_output_dir(MPI_Comm comm, const Config &cfg) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  std::string msg;
  if (rank == 0) {
    const std::vector<std::string> found = run_files(cfg.output_dir);
    const bool restart_here = !cfg.restart.empty() && same_dir(std::filesystem::path(cfg.restart).parent_path().string(), cfg.output_dir);
    if (!found.empty() && !restart_here) {
      if (!cfg.output_overwrite) {
        msg = "-output_dir '" + cfg.output_dir + "' holds another run's results (" + found[0] + (found.size() > 1 ? " and " + std::to_string(found.size() - 1) + " more" : "") +
              "); choose another -output_dir, continue that run with -restart " + cfg.output_dir + "/checkpoint.h5, or add -output_overwrite to replace them";
      } else {
        // Replace, do not mix: the old run's snapshots and XDMF go (other files are rewritten).
        for (const std::string &n : found)
          if ((n.rfind("snap_", 0) == 0 && n.size() > 3 && n.substr(n.size() - 3) == ".h5") || n.substr(n.size() - 4) == ".xmf")
            std::filesystem::remove(std::filesystem::path(cfg.output_dir) / n);
      }
    }
  }
  collective_fail(comm, !msg.empty(), msg);
}

template <int dim>
void Output<dim>::set_frames(const std::vector<Frame> &f, const std::string &from_dir) {
  namespace fs = std::filesystem;
  const State<dim> &S = sim_;
  frames_ = f;
  if (from_dir.empty() || same_dir(from_dir, S.cfg.output_dir)) return;
  // Another directory: link the old snapshots that exist (rank 0 looks, all ranks agree).
  std::vector<int> keep(f.size(), 0);
  const fs::path here = fs::absolute(S.cfg.output_dir).lexically_normal();
  std::vector<std::string> rel(f.size());
  for (size_t i = 0; i < f.size(); ++i) { // lexical: the same on every rank
    const fs::path old = fs::absolute(fs::path(from_dir) / f[i].file).lexically_normal();
    std::error_code ec;
    if (S.rank == 0) keep[i] = fs::is_regular_file(old, ec);
    rel[i] = old.lexically_relative(here).string();
  }
  MPI_Bcast(keep.data(), (int)keep.size(), MPI_INT, 0, S.comm);
  frames_.clear();
  long missing = 0;
  for (size_t i = 0; i < f.size(); ++i)
    if (keep[i]) frames_.push_back({f[i].t, rel[i], f[i].np});
    else ++missing;
  if (S.rank == 0 && !S.cfg.quiet) {
    std::printf("GranMPM: restart into another -output_dir: its XDMF links the %zu earlier snapshot(s) of %s by relative path", frames_.size(), from_dir.c_str());
    if (missing) std::printf("; %ld snapshot(s) no longer there are left out", missing);
    std::printf("\n");
    std::fflush(stdout);
  }
}

template <int dim>
Output<dim>::Output(const State<dim> &sim) : sim_(sim) {
  // -help sets up a run only to list its options: it must leave no directory behind.
  PetscBool help = PETSC_FALSE;
  GM_CALL(PetscOptionsHasName(NULL, NULL, "-help", &help));
  if (help) return;
  // Fail at start-up, not hours later, if the output directory cannot be written.
  bool bad = false;
  std::string msg;
  if (sim.rank == 0) {
    std::error_code ec;
    std::filesystem::create_directories(sim.cfg.output_dir, ec);
    const std::string probe = sim.cfg.output_dir + "/.granmpm_write_test";
    std::FILE *f = std::fopen(probe.c_str(), "w");
    if (ec || !f) {
      bad = true;
      msg = "output directory '" + sim.cfg.output_dir + "' is not writable" + (ec ? " (" + ec.message() + ")" : std::string()) + "; change -output_dir";
    }
    if (f) {
      std::fclose(f);
      std::remove(probe.c_str());
    }
    // The checkpoint's directory too (-checkpoint_file may point elsewhere).
    const std::filesystem::path ckdir = std::filesystem::path(sim.cfg.checkpoint_path()).parent_path();
    if (!bad && !ckdir.empty() && !std::filesystem::is_directory(ckdir, ec)) {
      bad = true;
      msg = "cannot create " + sim.cfg.checkpoint_path() + ".tmp (directory " + ckdir.string() + " does not exist): check -checkpoint_file";
    }
  }
  collective_fail(sim.comm, bad, msg);
}

template <int dim>
void Output<dim>::write(Scene<dim> &scene) {
  (void)scene;
  const State<dim> &S = sim_;
  char name[64];
  std::snprintf(name, sizeof name, "snap_%06d.h5", (int)frames_.size());
  const std::string path = S.cfg.output_dir + "/" + name;
  h5::TmpFile tf(S.comm, path, "-output_dir");
  const hid_t file = tf.id();
  H5Check chk{path, S.comm};
  const long tot = write_particles(S, file, chk);
  write_grid(S, file, chk);
  if (S.bodies) write_bodies(S, file, chk);
  h5::attr_double(file, "time", S.time);
  h5::attr_double(file, "step", (double)S.nsteps);
  // The physical domain (the grid extends past non-periodic walls), for viewers and scripts.
  h5::attr_double(file, "dim", dim);
  h5::attr_doubles(file, "domain_lo", {S.cfg.lo[0], S.cfg.lo[1], dim == 3 ? S.cfg.lo[2] : 0.0});
  h5::attr_doubles(file, "domain_hi", {S.cfg.hi[0], S.cfg.hi[1], dim == 3 ? S.cfg.hi[2] : 0.0});
  tf.publish();
  frames_.push_back({S.time, name, tot});
  last_file = path;
  bool bad = false;
  std::string msg;
  if (S.rank == 0) {
    try {
      write_xdmf();
    } catch (const UserError &e) {
      bad = true;
      msg = e.what();
    }
  }
  collective_fail(S.comm, bad, msg);
}

namespace {

// One XDMF <DataItem> of dataset ds in file.
std::string item(const std::string &file, const std::string &dims, const std::string &ds, const char *type = "Float") {
  std::ostringstream s;
  s << "<DataItem Dimensions=\"" << dims << "\" NumberType=\"" << type << "\" Precision=\"8\" Format=\"HDF\">" << file << ":" << ds << "</DataItem>";
  return s.str();
}
std::string attribute(const std::string &name, const char *kind, const std::string &data) {
  return "    <Attribute Name=\"" + name + "\" AttributeType=\"" + kind + "\" Center=\"Node\">" + data + "</Attribute>\n";
}

} // namespace

template <int dim>
void Output<dim>::write_xdmf() const {
  const State<dim> &S = sim_;
  const Grid<dim> &G = S.grid;
  const long nbody = S.bodies ? (long)S.bodies->size() * kOutlinePoints : 0;
  const long nconn = S.bodies ? body_connectivity_size(*S.bodies) : 0;
  std::ostringstream gdims; // z y x, with the wrapped layer on periodic axes
  gdims << G.M[2] + G.periodic[2] << " " << G.M[1] + G.periodic[1] << " " << G.M[0] + G.periodic[0];
  const ParticleFieldSet &pf = S.particles.fields();
  auto particles = [&](std::ostream &f, const Frame &fr) {
    const std::string N = std::to_string(fr.np), &h = fr.file;
    f << "    <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"" << N << "\" NodesPerElement=\"1\">" << item(h, N, "/particles/connectivity", "Int")
      << "</Topology>\n";
    f << "    <Geometry GeometryType=\"XYZ\">" << item(h, N + " 3", "/particles/position") << "</Geometry>\n";
    f << attribute("id", "Scalar", item(h, N, "/particles/id", "Int"));
    f << attribute("velocity", "Vector", item(h, N + " 3", "/particles/velocity"));
    f << attribute("stress", "Tensor", item(h, N + " 9", "/particles/stress"));
    for (int c = 0; c < n_stress_components<dim>(); ++c) f << attribute(kStress[c].name, "Scalar", item(h, N, std::string("/particles/") + kStress[c].name));
    std::vector<std::string> scalars = {"mass", "volume", "density", "pressure", "tau"};
    if (pf.fluidity) scalars.push_back("fluidity");
    if (pf.gdot) scalars.push_back("gdot");
    for (const auto &o : S.particles.optional_fields())
      if (generic_field(o.first) && o.second == 1) scalars.push_back(o.first);
    for (const std::string &sc : scalars) f << attribute(sc, "Scalar", item(h, N, "/particles/" + sc));
    if (pf.hyper) f << attribute("Be", "Tensor", item(h, N + " 9", "/particles/Be"));
  };
  auto grid = [&](std::ostream &f, const Frame &fr) {
    f << "    <Topology TopologyType=\"3DCoRectMesh\" Dimensions=\"" << gdims.str() << "\"/>\n";
    f << "    <Geometry GeometryType=\"ORIGIN_DXDYDZ\">\n     <DataItem Dimensions=\"3\" NumberType=\"Float\" Precision=\"8\" Format=\"XML\">"
      << (dim == 3 ? G.x0[2] : 0.0) << " " << G.x0[1] << " " << G.x0[0] << "</DataItem>\n"
      << "     <DataItem Dimensions=\"3\" NumberType=\"Float\" Precision=\"8\" Format=\"XML\">" << G.h << " " << G.h << " " << G.h << "</DataItem>\n    </Geometry>\n";
    f << attribute("mass", "Scalar", item(fr.file, gdims.str(), "/grid/mass"));
    f << attribute("velocity", "Vector", item(fr.file, gdims.str() + " 3", "/grid/velocity"));
    f << attribute("active", "Scalar", item(fr.file, gdims.str(), "/grid/active"));
  };
  auto bodies = [&](std::ostream &f, const Frame &fr) {
    const std::string N = std::to_string(nbody);
    f << "    <Topology TopologyType=\"Mixed\" NumberOfElements=\"" << S.bodies->size() << "\">" << item(fr.file, std::to_string(nconn), "/bodies/connectivity", "Int")
      << "</Topology>\n";
    f << "    <Geometry GeometryType=\"XYZ\">" << item(fr.file, N + " 3", "/bodies/outline") << "</Geometry>\n";
    f << attribute("velocity", "Vector", item(fr.file, N + " 3", "/bodies/velocity"));
    f << attribute("body", "Scalar", item(fr.file, N, "/bodies/body"));
  };
  auto emit = [&](const std::string &kind, const std::function<void(std::ostream &, const Frame &)> &body) {
    const std::string path = S.cfg.output_dir + "/" + kind + ".xmf", tmp = path + ".tmp";
    std::ofstream f(tmp);
    f.precision(17); // times and geometry exactly as in the HDF5 files
    f << "<?xml version=\"1.0\" ?>\n<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n<Xdmf Version=\"2.0\">\n <Domain>\n";
    f << "  <Grid Name=\"" << kind << "\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
    for (size_t i = 0; i < frames_.size(); ++i) {
      const Frame &fr = frames_[i];
      f << "   <Grid Name=\"" << kind << "_" << i << "\" GridType=\"Uniform\">\n    <Time Value=\"" << fr.t << "\"/>\n";
      body(f, fr);
      f << "   </Grid>\n";
    }
    f << "  </Grid>\n </Domain>\n</Xdmf>\n";
    f.close();
    const std::string why = !f ? std::string(errno ? std::strerror(errno) : "write failed") : sync_and_rename(tmp, path);
    if (!why.empty()) {
      std::remove(tmp.c_str());
      throw UserError("cannot write " + path + " (" + why + "): check -output_dir");
    }
  };
  emit("particles", particles);
  emit("grid", grid);
  if (S.bodies) emit("bodies", bodies);
}

template class Output<2>;
template class Output<3>;

} // namespace granmpm
