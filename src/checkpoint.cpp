#include "granmpm/checkpoint.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <sstream>

#include "granmpm/module.hpp"
#include "granmpm/output.hpp"
#include "h5util.hpp"

namespace granmpm {

namespace {

hid_t h5type(PetscDataType t) {
  if (t == PETSC_INT64) return H5T_NATIVE_INT64;
  if (t == PETSC_INT) return H5T_NATIVE_INT;
  return H5T_NATIVE_DOUBLE;
}

std::string signature_text(const Config &c) {
  std::string s;
  for (const auto &kv : c.signature()) s += kv.first + " " + kv.second + "\n";
  return s;
}

// All options of the run as "-name value" lines, rank 0's view broadcast to all.
std::string all_options(MPI_Comm comm) {
  char *copts = nullptr;
  PetscOptionsGetAll(NULL, &copts);
  std::string s = copts ? copts : "";
  PetscFree(copts);
  int len = (int)s.size();
  MPI_Bcast(&len, 1, MPI_INT, 0, comm);
  s.resize(len);
  MPI_Bcast(s.data(), len, MPI_CHAR, 0, comm);
  return s;
}

// 2: per-dataset checksums, the output directory relative to the checkpoint's.
const int kVersion = 2;

// Every particle field of a restart, checked before the particles are used: a NaN or a
// position outside the domain would read outside the grid in P2G. Collective; the
// message names the dataset, the row and the value. base: global row of local particle 0.
template <int dim>
void validate_particles(State<dim> &S, const std::string &path, long base, long id_limit) {
  bool bad = false;
  std::ostringstream m;
  m.precision(17);
  auto fail = [&](const std::string &field, long p, const std::string &why) {
    if (bad) return;
    bad = true;
    m << "-restart " << path << ": dataset /particles/" << field << " row " << base + p << " " << why
      << " (a corrupt or edited checkpoint; restart from an intact one)";
  };
  DM sw = S.particles.dm();
  const PetscInt n = S.particles.local_size();
  for (const FieldMeta &f : S.particles.field_meta()) {
    if (f.type != PETSC_REAL) continue;
    double *a = nullptr;
    GM_CALL(DMSwarmGetField(sw, f.name.c_str(), NULL, NULL, (void **)&a));
    for (PetscInt p = 0; p < n && !bad; ++p)
      for (int c = 0; c < f.bs; ++c)
        if (!std::isfinite(a[p * f.bs + c])) {
          std::ostringstream v;
          v << "holds a non-finite value (" << a[p * f.bs + c] << ", component " << c << ")";
          fail(f.name, p, v.str());
          break;
        }
    GM_CALL(DMSwarmRestoreField(sw, f.name.c_str(), NULL, NULL, (void **)&a));
  }
  ParticleView<dim> P = S.particles.get();
  const Config &c = S.cfg;
  for (PetscInt p = 0; p < P.n && !bad; ++p) {
    for (int d = 0; d < dim; ++d) {
      const double x = P.x[p * dim + d];
      const bool in = c.is_periodic(d) ? (x >= c.lo[d] && x < c.hi[d]) : (x >= c.lo[d] && x <= c.hi[d]);
      if (!in) {
        std::ostringstream v;
        v.precision(17);
        v << "is a position outside the domain (" << "xyz"[d] << " = " << x << ", domain " << c.lo[d] << " .. " << c.hi[d] << ")";
        fail(S.particles.field_meta()[0].name, p, v.str()); // field 0 is the coordinates
        break;
      }
    }
    if (!bad && !(P.m[p] > 0)) fail("mass", p, "is a mass that is not positive (" + std::to_string(P.m[p]) + ")");
    if (!bad && !(P.vol[p] > 0)) fail("volume", p, "is a volume that is not positive (" + std::to_string(P.vol[p]) + ")");
    if (!bad && (P.id[p] < 0 || (P.id[p] >= id_limit && P.id[p] < kConvertedParticleIds)))
      fail("DMSwarm_pid", p, "is an id outside 0 .. " + std::to_string(id_limit - 1) + " (" + std::to_string((long)P.id[p]) + ")");
  }
  // Unique ids: each id goes to rank id % size, which sorts what it gets.
  std::vector<int> scount(S.size, 0), rcount(S.size, 0), sdisp(S.size, 0), rdisp(S.size, 0);
  for (PetscInt p = 0; p < P.n; ++p) ++scount[(size_t)(std::max<int64_t>(P.id[p], 0) % S.size)];
  MPI_Alltoall(scount.data(), 1, MPI_INT, rcount.data(), 1, MPI_INT, S.comm);
  for (int r = 1; r < S.size; ++r) {
    sdisp[r] = sdisp[r - 1] + scount[r - 1];
    rdisp[r] = rdisp[r - 1] + rcount[r - 1];
  }
  std::vector<int64_t> send(P.n), recv((size_t)rdisp[S.size - 1] + rcount[S.size - 1]);
  std::vector<int> fill = sdisp;
  for (PetscInt p = 0; p < P.n; ++p) send[fill[(size_t)(std::max<int64_t>(P.id[p], 0) % S.size)]++] = P.id[p];
  S.particles.restore(P);
  MPI_Alltoallv(send.data(), scount.data(), sdisp.data(), MPI_INT64_T, recv.data(), rcount.data(), rdisp.data(), MPI_INT64_T, S.comm);
  std::sort(recv.begin(), recv.end());
  auto dup = std::adjacent_find(recv.begin(), recv.end());
  if (!bad && dup != recv.end()) {
    bad = true;
    m << "-restart " << path << ": dataset /particles/DMSwarm_pid holds particle id " << (long)*dup
      << " twice (a corrupt or edited checkpoint; restart from an intact one)";
  }
  collective_fail(S.comm, bad, m.str());
}

} // namespace

void CheckpointIO::write_attr(const std::string &name, const std::vector<double> &v) { h5::attr_doubles(file_, name, v); }
bool CheckpointIO::has_attr(const std::string &name) const { return h5::has_attr(file_, name); }
std::vector<double> CheckpointIO::read_attr(const std::string &name) const { return h5::read_attr_doubles(file_, name, *(const h5::Check *)chk_); }
bool CheckpointIO::has_dataset(const std::string &name) const { return !h5::shape(file_, name).empty(); }
void CheckpointIO::write_box(const std::string &name, const double *owned, const int *M, const int *xs, const int *xm, int comps) {
  h5::write_box(file_, name, owned, M, xs, xm, comps, *(const h5::Check *)chk_);
}
void CheckpointIO::read_box(const std::string &name, double *owned, const int *xs, const int *xm, int comps) {
  h5::read_box(file_, name, owned, xs, xm, comps, *(const h5::Check *)chk_);
}
void CheckpointIO::write_rows(const std::string &name, const double *rows, long n, long off, long N, int cols) {
  h5::write_rows(file_, name, H5T_NATIVE_DOUBLE, rows, n, off, N, cols, *(const h5::Check *)chk_);
}
void CheckpointIO::read_all_rows(const std::string &name, double *rows, long N, int cols) {
  h5::read_rows(file_, name, H5T_NATIVE_DOUBLE, rows, N, 0, cols, *(const h5::Check *)chk_, true);
}
void CheckpointIO::bad(const std::string &why) const { throw UserError("-restart " + path_ + ": " + why); }

template <int dim>
void Checkpoint<dim>::write(const State<dim> &S, const std::string &path) {
  h5::TmpFile tf(S.comm, path, "-checkpoint_file / -output_dir");
  const hid_t file = tf.id();
  h5::Check chk{tf.tmp(), S.comm};

  // Particles in rank order, every field, and the per-rank counts.
  const PetscInt n = S.particles.local_size();
  std::vector<long> counts(S.size);
  long nl = n;
  MPI_Allgather(&nl, 1, MPI_LONG, counts.data(), 1, MPI_LONG, S.comm);
  long off = 0, tot = 0;
  for (int r = 0; r < S.size; ++r) {
    if (r < S.rank) off += counts[r];
    tot += counts[r];
  }
  h5::group(file, "particles");
  DM sw = S.particles.dm();
  for (const FieldMeta &f : S.particles.field_meta()) {
    void *data = nullptr;
    GM_CALL(DMSwarmGetField(sw, f.name.c_str(), NULL, NULL, &data));
    h5::write_rows(file, "/particles/" + f.name, h5type(f.type), data, n, off, tot, f.bs, chk);
    GM_CALL(DMSwarmRestoreField(sw, f.name.c_str(), NULL, NULL, &data));
  }
  h5::write_rows(file, "/particles/counts", H5T_NATIVE_LONG, &nl, 1, S.rank, S.size, 1, chk);

  // The modules' own fields (nodal fluidity, rigid-body state, ...).
  CheckpointIO io(file, &chk, path);
  for (const auto &m : S.modules) m->write_checkpoint(S, io);

  // Run state and provenance.
  h5::attr_double(file, "version", kVersion);
  h5::attr_double(file, "dim", dim);
  h5::attr_double(file, "time", S.time);
  h5::attr_double(file, "nsteps", (double)S.nsteps);
  h5::attr_double(file, "vmax", S.vmax);
  h5::attr_double(file, "plastic_limit", S.plastic_limit);
  h5::attr_double(file, "removed_total", (double)S.particles.removed_total);
  h5::attr_double(file, "removed_mass_total", S.particles.removed_mass_total);
  h5::attr_double(file, "nranks", S.size);
  // The grid's ownership ranges (changed by load balancing): a restart on as many ranks
  // re-creates them, so every rank's particles are again its own.
  for (int d = 0; d < dim; ++d) {
    const std::vector<PetscInt> l = S.grid.ranges(d);
    h5::attr_doubles(file, std::string("ranges_") + "xyz"[d], std::vector<double>(l.begin(), l.end()));
  }
  h5::attr_string(file, "signature", signature_text(S.cfg));
  h5::attr_string(file, "options", all_options(S.comm));
  std::vector<double> ft, fn;
  std::string files;
  for (const auto &fr : S.output->frames()) {
    ft.push_back(fr.t);
    fn.push_back((double)fr.np);
    files += fr.file + "\n";
  }
  h5::attr_doubles(file, "frame_times", ft);
  h5::attr_doubles(file, "frame_particles", fn);
  h5::attr_string(file, "frame_files", files);
  // The frames' files are named relative to the output directory; record where that is
  // from the checkpoint's own directory, so that a moved run still finds its snapshots.
  {
    namespace fs = std::filesystem;
    const fs::path ckdir = fs::absolute(fs::path(path)).parent_path().lexically_normal();
    h5::attr_string(file, "output_dir", fs::absolute(S.cfg.output_dir).lexically_normal().lexically_relative(ckdir).string());
  }
  tf.publish();
}

namespace {

// The options of the stored signature ("-option value" lines) that differ from this run's,
// as the message of a refused restart ("" if none differ).
std::string signature_diff(const std::string &stored, const Config &cfg) {
  std::istringstream there(stored);
  std::map<std::string, std::string> old;
  for (std::string line; std::getline(there, line);) {
    const size_t sp = line.find(' ');
    if (sp != std::string::npos) old[line.substr(0, sp)] = line.substr(sp + 1);
  }
  std::string diff;
  int ndiff = 0;
  for (const auto &kv : cfg.signature()) {
    auto it = old.find(kv.first);
    if (it == old.end() || it->second != kv.second)
      diff += std::string(ndiff++ ? "; " : "") + kv.first + " is '" + (it == old.end() ? std::string("unset") : it->second) + "' there but '" + kv.second + "' here";
  }
  if (!ndiff) return "";
  return "it is from another scene: " + diff + " (" + std::to_string(ndiff) + " scene or physics option(s) differ; restart with the options of the checkpointed run: only time, output and solver options may change)";
}

// This rank's rows of the particle datasets: its own slab when the rank count is the
// checkpoint's (a bitwise continuation), else an even share.
void slab(const std::vector<long> &counts, int rank, int size, long &off, long &n) {
  long tot = 0;
  for (long c : counts) tot += c;
  off = 0;
  if ((int)counts.size() == size) {
    for (int r = 0; r < rank; ++r) off += counts[r];
    n = counts[rank];
  } else {
    off = tot * rank / size;
    n = tot * (rank + 1) / size - off;
  }
}

// The checkpoint's grid ownership ranges into l; false if they do not fit this run's
// layout of ranks per direction (the particles are then migrated after reading); differ:
// they fit but are not the current ranges.
template <int dim, class Bad>
bool stored_ranges(hid_t file, const h5::Check &chk, const Grid<dim> &G, Ranges &l, bool &differ, Bad &&bad) {
  bool fits = true;
  for (int d = 0; d < dim; ++d) {
    const std::vector<double> r = h5::read_attr_doubles(file, std::string("ranges_") + "xyz"[d], chk);
    long sum = 0;
    for (double x : r) {
      if (!(x >= 2)) bad("inconsistent grid ownership ranges");
      l[d].push_back((PetscInt)x);
      sum += (long)x;
    }
    if (sum != G.M[d]) bad("grid ownership ranges do not fit this run's grid");
    fits = fits && (int)l[d].size() == G.nproc[d];
    differ = differ || !fits || l[d] != G.ranges(d);
  }
  return fits;
}

// Every swarm field, checked against the file's sizes first: this rank's n rows from off.
template <int dim, class Bad>
void read_particle_fields(hid_t file, const h5::Check &chk, State<dim> &S, long tot, long off, long n, Bad &&bad) {
  for (const FieldMeta &f : S.particles.field_meta()) {
    const std::vector<hsize_t> sh = h5::shape(file, "/particles/" + f.name);
    const hsize_t bs = sh.size() > 1 ? sh[1] : 1;
    // The dynamical model stored F and Fp (9 + 9) before it stored Be - I (6): name that layout.
    if (sh.empty() && f.name == "Be_minus_I" && !h5::shape(file, "/particles/Fp").empty())
      bad("written with the dynamical model's old state F, Fp (this GranMPM stores Be - I only); rerun from the start");
    if (sh.empty() || (long)sh[0] != tot || (int)bs != f.bs) bad("particle field '" + f.name + "' is missing or has another size (another scene or model)");
  }
  S.particles.set_local_size((PetscInt)n);
  DM sw = S.particles.dm();
  for (const FieldMeta &f : S.particles.field_meta()) {
    void *data = nullptr;
    GM_CALL(DMSwarmGetField(sw, f.name.c_str(), NULL, NULL, &data));
    h5::read_rows(file, "/particles/" + f.name, h5type(f.type), data, n, off, f.bs, chk);
    GM_CALL(DMSwarmRestoreField(sw, f.name.c_str(), NULL, NULL, &data));
  }
}

// The run state (time, steps, speeds, removed particles) and the output frames so far.
template <int dim, class Bad>
void read_run_state(hid_t file, const h5::Check &chk, State<dim> &S, const std::string &path, Bad &&bad) {
  S.time = h5::read_attr_double(file, "time", chk);
  S.nsteps = (long)h5::read_attr_double(file, "nsteps", chk);
  S.vmax = h5::read_attr_double(file, "vmax", chk);
  S.plastic_limit = h5::read_attr_double(file, "plastic_limit", chk);
  if (!(std::isfinite(S.time) && S.time >= 0) || S.nsteps < 0 || !(std::isfinite(S.vmax) && S.vmax >= 0) || std::isnan(S.plastic_limit))
    bad("the run state (time, step count, speed) is not valid");
  S.particles.removed_total = (long)h5::read_attr_double(file, "removed_total", chk);
  S.particles.removed_mass_total = h5::read_attr_double(file, "removed_mass_total", chk);
  const std::vector<double> ft = h5::read_attr_doubles(file, "frame_times", chk), fn = h5::read_attr_doubles(file, "frame_particles", chk);
  std::istringstream files(h5::read_attr_string(file, "frame_files", chk));
  std::vector<typename Output<dim>::Frame> frames;
  std::string name;
  for (size_t i = 0; i < ft.size() && std::getline(files, name); ++i) frames.push_back({ft[i], name, (long)fn[i]});
  const std::string ckdir = std::filesystem::path(path).parent_path().string();
  S.output->set_frames(frames, (std::filesystem::path(ckdir.empty() ? "." : ckdir) / h5::read_attr_string(file, "output_dir", chk)).string());
}

} // namespace

// (The file is read in the order it was written -- signature, counts,
// ranges, fields, run state, modules -- and each failure closes it with its own message;
// the independent parts are the helpers above.)
template <int dim>
void Checkpoint<dim>::read(State<dim> &S, const std::string &path, const std::function<void(const Ranges &)> &repartition) {
  const hid_t file = h5::open_read(S.comm, path);
  if (file < 0) throw UserError("-restart: cannot read '" + path + "' (missing, unreadable or not an HDF5 checkpoint)");
  h5::Check chk{path, S.comm};
  auto bad = [&](const std::string &why) {
    H5Fclose(file);
    throw UserError("-restart " + path + ": " + why);
  };
  if (!h5::has_attr(file, "signature") || !h5::has_attr(file, "version")) bad("not a GranMPM checkpoint");
  if ((int)h5::read_attr_double(file, "version", chk) != kVersion) bad("checkpoint format version differs from this build's");
  // The scene must match: compare option by option and name every difference.
  const std::string diff = signature_diff(h5::read_attr_string(file, "signature", chk), S.cfg);
  if (!diff.empty()) bad(diff);
  // Particles: same rank count -> each rank its own slab in the same order (bitwise
  // continuation); otherwise even slabs, then migration to the owners.
  const int nranks_file = (int)h5::read_attr_double(file, "nranks", chk);
  const std::vector<hsize_t> cshape = h5::shape(file, "/particles/counts");
  if (cshape.size() != 1 || (int)cshape[0] != nranks_file) bad("particle counts are missing or inconsistent");
  std::vector<long> counts(nranks_file);
  h5::read_rows(file, "/particles/counts", H5T_NATIVE_LONG, counts.data(), nranks_file, 0, 1, chk, true);
  long tot = 0;
  for (long c : counts) {
    if (c < 0) bad("dataset /particles/counts holds a negative particle count");
    tot += c;
  }
  long off = 0, n = 0;
  slab(counts, S.rank, S.size, off, n);
  // Same rank count: each rank's slab holds the particles it owned; they stay put if the
  // grid gets the checkpoint's ownership ranges back (a checkpoint without them had the
  // default ranges); otherwise (another rank count or -da_processors_x/y/z layout) they
  // are migrated to their owners after reading.
  bool in_place = nranks_file == S.size;
  if (in_place && h5::has_attr(file, "ranges_x")) {
    Ranges l(dim);
    bool differ = false;
    if (!stored_ranges(file, chk, S.grid, l, differ, bad)) in_place = false;
    else if (differ) repartition(l); // no particles yet: only the grid and its solvers
  }
  read_particle_fields(file, chk, S, tot, off, n, bad);
  {
    // Lattice ids of the seeding: 0 .. prod(cells * ppc) - 1.
    long id_limit = 1;
    for (int d = 0; d < dim; ++d) id_limit *= (long)S.cfg.cells[d] * S.cfg.ppc;
    const double removed = h5::read_attr_double(file, "removed_total", chk);
    long converted = 0; // points made from grains (hybrid) are not on the lattice
    {
      ParticleView<dim> P = S.particles.get();
      for (PetscInt p = 0; p < P.n; ++p) converted += P.id[p] >= kConvertedParticleIds;
      S.particles.restore(P);
      MPI_Allreduce(MPI_IN_PLACE, &converted, 1, MPI_LONG, MPI_SUM, S.comm);
    }
    if (!(removed >= 0) || tot - converted + removed > (double)id_limit) bad("inconsistent particle counts (particles plus removed exceed the seeded lattice)");
    try {
      validate_particles(S, path, off, id_limit);
    } catch (const UserError &) {
      H5Fclose(file);
      throw;
    }
  }
  {
    CheckpointIO io(file, &chk, path);
    try {
      for (const auto &m : S.modules) m->read_checkpoint(S, io);
    } catch (const UserError &) {
      H5Fclose(file);
      throw;
    }
  }
  read_run_state(file, chk, S, path, bad);
  chk(H5Fclose(file), "close the checkpoint");
  if (!in_place) S.particles.migrate(S.grid);
}

template struct Checkpoint<2>;
template struct Checkpoint<3>;

} // namespace granmpm
