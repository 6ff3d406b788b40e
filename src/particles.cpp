#include "granmpm/particles.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>

namespace granmpm {

namespace {
const char *F_X = "DMSwarmPIC_coor";
const char *F_V = "velocity";
const char *F_M = "mass";
const char *F_VOL = "volume";
const char *F_S = "stress";
const char *F_C = "apic_C";
const char *F_G = "fluidity";
const char *F_GDOT = "gdot";
const char *F_BE = "Be_minus_I";
const char *F_PPREV = "p_prev";
const char *F_MUPREV = "mu_prev";
const char *F_GSPLIT = "fluidity_split";
const char *F_ID = "DMSwarm_pid";
const char *F_RANK = "DMSwarm_rank";
// Migration's reduction of {movers, outlet removals, wall hits, guard} (sums; doubles hold
// the counts exactly) and the caller's flags (the entries after them, maxima).
void migrate_reduce(void *in, void *inout, int *len, MPI_Datatype *) {
  const double *a = static_cast<const double *>(in);
  double *b = static_cast<double *>(inout);
  for (int i = 0; i < *len; ++i) b[i] = i < 4 ? a[i] + b[i] : std::max(a[i], b[i]);
}
MPI_Op migrate_reduce_op() {
  static MPI_Op op = MPI_OP_NULL;
  if (op == MPI_OP_NULL) MPI_Op_create(&migrate_reduce, 1, &op);
  return op;
}
} // namespace

template <int dim>
void Particles<dim>::create(MPI_Comm comm, Grid<dim> &grid, const ParticleFieldSet &fields) {
  (void)grid;
  destroy();
  comm_ = comm;
  fields_ = fields;
  GM_CALL(DMCreate(comm, &sw_));
  GM_CALL(DMSetType(sw_, DMSWARM));
  GM_CALL(DMSetDimension(sw_, dim));
  GM_CALL(DMSwarmSetType(sw_, DMSWARM_BASIC));
  meta_.clear();
  auto reg = [&](const char *name, int bs) {
    GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, name, bs, PETSC_REAL));
    meta_.push_back({name, bs, PETSC_REAL});
  };
  reg(F_X, dim);
  reg(F_V, dim);
  reg(F_M, 1);
  reg(F_VOL, 1);
  reg(F_S, 6);
  // The optional fields: APIC's C, the material's declared fields (or those the flags
  // name), the steady fluidity's split; their order is the order of ParticleView::opt.
  opt_.clear();
  auto add = [&](const std::string &name, int bs) {
    for (const auto &f : opt_)
      if (f.first == name) return;
    opt_.push_back({name, bs});
  };
  if (fields.apic) add(F_C, dim * dim);
  for (const auto &f : fields.model) add(f.first, f.second);
  if (fields.fluidity) add(F_G, 1);
  if (fields.gdot) add(F_GDOT, 1);
  if (fields.hyper) {
    add(F_BE, 6);
    add(F_PPREV, 1);
    add(F_MUPREV, 1);
  }
  if (fields.fluidity_split) add(F_GSPLIT, 3);
  if ((int)opt_.size() > ParticleView<dim>::kMaxOptional) throw UserError("internal: more than " + std::to_string(ParticleView<dim>::kMaxOptional) + " optional particle fields");
  for (const auto &f : opt_) reg(f.first.c_str(), f.second);
  // Which named ParticleView member each optional field fills, resolved once here: get()
  // runs many times a step and comparing names there cost 3-7% of a small run (profile).
  named_.assign(opt_.size(), nullptr);
  const std::pair<const char *, double *ParticleView<dim>::*> named[] = {
      {F_C, &ParticleView<dim>::C},       {F_G, &ParticleView<dim>::g},           {F_GDOT, &ParticleView<dim>::gdot},
      {F_BE, &ParticleView<dim>::Be},     {F_PPREV, &ParticleView<dim>::p_prev},
      {F_MUPREV, &ParticleView<dim>::mu_prev}, {F_GSPLIT, &ParticleView<dim>::gsplit}};
  for (size_t i = 0; i < opt_.size(); ++i)
    for (const auto &nm : named)
      if (opt_[i].first == nm.first) named_[i] = nm.second;
  fields_.fluidity = field_index(F_G) >= 0;
  fields_.gdot = field_index(F_GDOT) >= 0;
  fields_.hyper = field_index(F_BE) >= 0;
  fields_.fluidity_split = field_index(F_GSPLIT) >= 0;
  meta_.push_back({F_ID, 1, PETSC_INT64});
  meta_.push_back({F_RANK, 1, PETSC_INT});
  GM_CALL(DMSwarmFinalizeFieldRegister(sw_));
  // A small buffer: PETSc 3.18 zero-fills the whole spare buffer on every point removal.
  GM_CALL(DMSwarmSetLocalSizes(sw_, 0, 16));
}

template <int dim>
int Particles<dim>::field_index(const std::string &name) const {
  for (size_t i = 0; i < opt_.size(); ++i)
    if (opt_[i].first == name) return (int)i;
  return -1;
}

namespace {
// Returns the fields of a held view to the swarm. quiet (destroy, from the destructor):
// errors are ignored, nothing is thrown.
template <int dim>
void restore_fields(DM sw, ParticleView<dim> &v, int *&rank, const std::vector<std::pair<std::string, int>> &opt, bool quiet) {
  auto put = [&](const char *name, void *a) {
    const PetscErrorCode e = DMSwarmRestoreField(sw, name, NULL, NULL, (void **)a);
    if (e && !quiet) throw PetscFailure(e);
  };
  put(F_X, &v.x);
  put(F_V, &v.v);
  put(F_M, &v.m);
  put(F_VOL, &v.vol);
  put(F_S, &v.s);
  for (size_t i = 0; i < opt.size(); ++i) put(opt[i].first.c_str(), &v.opt[i]);
  put(F_ID, &v.id);
  put(F_RANK, &rank);
  v = ParticleView<dim>();
}
} // namespace

template <int dim>
void Particles<dim>::destroy() {
  if (sw_ && held_) restore_fields(sw_, cache_, rank_, opt_, true); // no exceptions from the destructor
  held_ = false;
  if (sw_) DMDestroy(&sw_);
  sw_ = nullptr;
}

template <int dim>
void Particles<dim>::set_local_size(PetscInt n) {
  release();
  GM_CALL(DMSwarmSetLocalSizes(sw_, n, 16));
}

template <int dim>
PetscInt Particles<dim>::local_size() const {
  PetscInt n;
  GM_CALL(DMSwarmGetLocalSize(sw_, &n));
  return n;
}

template <int dim>
long Particles<dim>::global_size() const {
  long n = local_size(), tot = 0;
  MPI_Allreduce(&n, &tot, 1, MPI_LONG, MPI_SUM, comm_);
  return tot;
}

template <int dim>
void Particles<dim>::hold() const {
  if (held_) return;
  ParticleView<dim> &v = cache_;
  v = ParticleView<dim>();
  v.n = local_size();
  GM_CALL(DMSwarmGetField(sw_, F_X, NULL, NULL, (void **)&v.x));
  GM_CALL(DMSwarmGetField(sw_, F_V, NULL, NULL, (void **)&v.v));
  GM_CALL(DMSwarmGetField(sw_, F_M, NULL, NULL, (void **)&v.m));
  GM_CALL(DMSwarmGetField(sw_, F_VOL, NULL, NULL, (void **)&v.vol));
  GM_CALL(DMSwarmGetField(sw_, F_S, NULL, NULL, (void **)&v.s));
  for (size_t i = 0; i < opt_.size(); ++i) {
    double *f = nullptr;
    GM_CALL(DMSwarmGetField(sw_, opt_[i].first.c_str(), NULL, NULL, (void **)&f));
    v.opt[i] = f;
    if (named_[i]) v.*named_[i] = f;
  }
  GM_CALL(DMSwarmGetField(sw_, F_ID, NULL, NULL, (void **)&v.id));
  GM_CALL(DMSwarmGetField(sw_, F_RANK, NULL, NULL, (void **)&rank_));
  held_ = true;
}

template <int dim>
void Particles<dim>::release() const {
  if (!held_) return;
  held_ = false; // first: a failing call below must not leave it set
  restore_fields(sw_, cache_, rank_, opt_, false);
}

template <int dim>
ParticleView<dim> Particles<dim>::get() {
  hold();
  return cache_;
}

template <int dim>
void Particles<dim>::restore(ParticleView<dim> &v) {
  v = ParticleView<dim>(); // the fields stay checked out (hold)
}

template <int dim>
void Particles<dim>::seed(const Config &cfg, const Grid<dim> &grid, const std::function<bool(const double *)> &keep) {
  const int ppc = cfg.ppc;
  // Owned physical cells per direction: [c0, c1).
  int c0[3] = {0, 0, 0}, c1[3] = {1, 1, 1}, nlat[3] = {1, 1, 1};
  for (int d = 0; d < dim; ++d) {
    const int phys0 = grid.pad[d], phys1 = grid.pad[d] + grid.ncell[d];
    c0[d] = std::max(grid.xs[d], phys0);
    c1[d] = std::min(grid.xs[d] + grid.xm[d], phys1);
    nlat[d] = grid.ncell[d] * ppc;
  }
  // Two passes over the lattice (count, then fill the fields): no temporary copy of the
  // positions and ids beside the swarm at the peak of set-up.
  const int kc0 = dim == 3 ? c0[2] : 0, kc1 = dim == 3 ? c1[2] : 1, ks1 = dim == 3 ? ppc : 1;
  auto lattice = [&](auto &&emit) {
    int q[3] = {0, 0, 0};
    for (int k = kc0; k < kc1; ++k)
      for (int sk = 0; sk < ks1; ++sk)
        for (int j = c0[1]; j < c1[1]; ++j)
          for (int sj = 0; sj < ppc; ++sj)
            for (int i = c0[0]; i < c1[0]; ++i)
              for (int si = 0; si < ppc; ++si) {
                const int c[3] = {i, j, k}, s[3] = {si, sj, sk};
                double x[3];
                bool inside = true;
                for (int d = 0; d < dim; ++d) {
                  x[d] = grid.x0[d] + (c[d] + (s[d] + 0.5) / ppc) * grid.h;
                  q[d] = (c[d] - grid.pad[d]) * ppc + s[d];
                  if (x[d] < cfg.body_lo[d] || x[d] >= cfg.body_hi[d]) inside = false;
                }
                if (!inside || (keep && !keep(x))) continue;
                int64_t id = q[dim - 1];
                for (int d = dim - 2; d >= 0; --d) id = id * nlat[d] + q[d];
                emit(x, id);
              }
  };
  PetscInt n = 0;
  lattice([&](const double *, int64_t) { ++n; });
  release();
  GM_CALL(DMSwarmSetLocalSizes(sw_, n, 16));
  const double vol = std::pow(grid.h / ppc, dim);
  ParticleView<dim> v = get();
  PetscInt p = 0;
  lattice([&](const double *x, int64_t id) {
    for (int d = 0; d < dim; ++d) {
      v.x[p * dim + d] = x[d];
      v.v[p * dim + d] = 0;
    }
    v.m[p] = cfg.rho * vol;
    v.vol[p] = vol;
    for (int c = 0; c < 6; ++c) v.s[p * 6 + c] = 0;
    if (v.C)
      for (int c = 0; c < dim * dim; ++c) v.C[p * dim * dim + c] = 0;
    if (v.g) v.g[p] = 0;
    if (v.gdot) v.gdot[p] = 0;
    if (v.Be)
      for (int c = 0; c < 6; ++c) v.Be[p * 6 + c] = 0.0; // Be = I
    if (v.p_prev) v.p_prev[p] = v.mu_prev[p] = 0;
    if (v.gsplit) v.gsplit[3 * p] = v.gsplit[3 * p + 1] = v.gsplit[3 * p + 2] = 0;
    v.id[p] = id;
    ++p;
  });
  restore(v);
}

// (82 lines: one pass over the particles that wraps, counts outlet removals and finds the
// owner rank, so that each particle is read once; the stop message is built in place.)
template <int dim>
MigrateStats Particles<dim>::migrate(const Grid<dim> &grid, double *flags, int nflags) {
  MigrateStats st;
  PetscInt n = local_size();
  ParticleView<dim> v = get();
  int *rank = rank_;
  long movers = 0, wall_hits = 0;
  std::vector<PetscInt> outlet;
  bool bad = false;
  std::string msg;
  const char *axes = "xyz";
  for (PetscInt p = 0; p < n; ++p) {
    double *x = v.x + p * dim;
    bool remove = false;
    for (int d = 0; d < dim; ++d) {
      if (grid.periodic[d]) {
        const double L = grid.hi[d] - grid.lo[d];
        if (x[d] < grid.lo[d] || x[d] >= grid.hi[d]) {
          x[d] = grid.lo[d] + std::fmod(x[d] - grid.lo[d], L);
          if (x[d] < grid.lo[d]) x[d] += L;
          if (x[d] >= grid.hi[d]) x[d] = grid.lo[d]; // fmod rounding at exactly L
        }
      } else if (!(x[d] >= grid.lo[d] && x[d] <= grid.hi[d])) {
        const int side = (x[d] > grid.hi[d]) ? 1 : 0;
        const double depth = side ? x[d] - grid.hi[d] : grid.lo[d] - x[d];
        const bool wall = grid.bc[d][side] == BC::Sticky || grid.bc[d][side] == BC::Slip;
        if (grid.bc[d][side] == BC::Outlet && std::isfinite(x[d])) {
          remove = true;
        } else if (wall && depth <= grid.h) {
          // Walls are impenetrable: a particle that the interpolated velocity carried
          // slightly past one (less than a cell) is put back on it; counted and reported.
          x[d] = side ? grid.hi[d] : grid.lo[d];
          double &vd = v.v[p * dim + d];
          if (side ? vd > 0 : vd < 0) vd = 0;
          ++wall_hits;
        } else if (!bad) {
          bad = true;
          std::ostringstream s;
          s << "particle " << v.id[p] << " left the domain through the " << axes[d] << (side ? "hi" : "lo") << " face (-bc_" << axes[d]
            << (side ? "hi " : "lo ") << to_string(grid.bc[d][side]) << ") at " << axes[d] << " = " << x[d] << ", domain " << grid.lo[d] << " .. "
            << grid.hi[d] << ". ";
          if (!std::isfinite(x[d])) s << "Its position is not finite: the run became unstable; reduce -dt or -cfl.";
          else s << "Enlarge -domain_lo/-domain_hi, make the face a wall (sticky|slip) or an outlet, or reduce -dt.";
          msg = s.str();
        }
      }
    }
    if (remove) {
      outlet.push_back(p);
      rank[p] = grid.rank;
      continue;
    }
    if (bad) continue;
    rank[p] = grid.owner_rank_or_self(x);
    movers += (rank[p] != grid.rank);
  }
  double mass_out = 0;
  for (PetscInt q : outlet) mass_out += v.m[q];
  restore(v);
  // One reduction for the counts and the guard (each collective synchronises the ranks);
  // the message is exchanged only when some rank failed.
  std::vector<double> red = {(double)movers, (double)outlet.size(), (double)wall_hits, bad ? 1.0 : 0.0}, all(4 + nflags);
  if (nflags > 0) red.insert(red.end(), flags, flags + nflags);
  MPI_Allreduce(red.data(), all.data(), 4 + nflags, MPI_DOUBLE, migrate_reduce_op(), grid.comm);
  if (nflags > 0) std::copy(all.begin() + 4, all.end(), flags);
  const long glob[4] = {(long)all[0], (long)all[1], (long)all[2], (long)all[3]};
  if (glob[3] > 0) collective_fail(grid.comm, bad, msg);
  if (!outlet.empty() || glob[0] > 0) release(); // the swarm changes: the fields go back
  // Outlet removals: highest index first, because removal moves the last point into the hole.
  for (auto it = outlet.rbegin(); it != outlet.rend(); ++it) GM_CALL(DMSwarmRemovePointAtIndex(sw_, *it));
  wall_corrections += glob[2];
  st.sent = glob[0];
  st.removed = glob[1];
  removed_total += glob[1];
  if (glob[1] > 0) {
    MPI_Allreduce(&mass_out, &st.removed_mass, 1, MPI_DOUBLE, MPI_SUM, grid.comm);
    removed_mass_total += st.removed_mass;
  }
  // Skip the collective migration (and its topology set-up) when nobody moves.
  if (glob[0] > 0) {
    GM_CALL(DMSwarmMigrate(sw_, PETSC_TRUE));
    st.migrated = true;
  }
  return st;
}

template <int dim>
void Particles<dim>::sort_by_cell(const Grid<dim> &grid) {
  const PetscInt n = local_size();
  if (n == 0) return; // an empty rank (memcpy must not see the empty buffers' null pointers)
  // Counting sort on the cell index within the box of occupied cells (x fastest, so the
  // order is that of the global cell index, stable within a cell), then every field
  // permuted in place along the cycles of the permutation: the transient memory is two
  // ints and a bit per particle (issue 16: the peak RSS, not only the fields, per particle).
  std::vector<int> cell(n);
  std::vector<PetscInt> order(n);
  {
    ParticleView<dim> v = get();
    int lo[dim], hi[dim];
    for (int d = 0; d < dim; ++d) lo[d] = grid.M[d], hi[d] = -1;
    for (PetscInt p = 0; p < n; ++p)
      for (int d = 0; d < dim; ++d) {
        const int c = grid.owner_cell(d, v.x[p * dim + d]);
        lo[d] = std::min(lo[d], c);
        hi[d] = std::max(hi[d], c);
      }
    for (PetscInt p = 0; p < n; ++p) {
      long k = 0;
      for (int d = dim - 1; d >= 0; --d) k = k * (hi[d] - lo[d] + 1) + grid.owner_cell(d, v.x[p * dim + d]) - lo[d];
      cell[p] = (int)k;
    }
    restore(v);
    long ncell = 1;
    for (int d = 0; d < dim; ++d) ncell *= hi[d] - lo[d] + 1;
    std::vector<PetscInt> start(ncell + 1, 0);
    for (PetscInt p = 0; p < n; ++p) ++start[cell[p] + 1];
    for (long c = 0; c < ncell; ++c) start[c + 1] += start[c];
    for (PetscInt p = 0; p < n; ++p) order[start[cell[p]]++] = p; // new position -> old index
  }
  std::vector<int>().swap(cell);
  release(); // every field is fetched below
  std::vector<bool> done(n);
  std::vector<char> tmp;
  for (const FieldMeta &f : meta_) {
    const size_t esz = (size_t)f.bs * (f.type == PETSC_INT64 ? 8 : f.type == PETSC_INT ? sizeof(PetscInt) : sizeof(double));
    char *data = nullptr;
    GM_CALL(DMSwarmGetField(sw_, f.name.c_str(), NULL, NULL, (void **)&data));
    tmp.resize(esz);
    done.assign(n, false);
    for (PetscInt i = 0; i < n; ++i) {
      if (done[i] || order[i] == i) continue;
      // Cycle i <- order[i] <- order[order[i]] ... back to i: data[j] = old data[order[j]].
      std::memcpy(tmp.data(), data + (size_t)i * esz, esz);
      PetscInt j = i;
      while (order[j] != i) {
        std::memcpy(data + (size_t)j * esz, data + (size_t)order[j] * esz, esz);
        done[j] = true;
        j = order[j];
      }
      std::memcpy(data + (size_t)j * esz, tmp.data(), esz);
      done[j] = true;
    }
    GM_CALL(DMSwarmRestoreField(sw_, f.name.c_str(), NULL, NULL, (void **)&data));
  }
}

template class Particles<2>;
template class Particles<3>;

} // namespace granmpm
