// The parallel DEM engine: grain store on a BASIC DMSwarm, own owner-rank migration, ghost
// halo, Verlet lists on cell lists, contact histories keyed by grain ids, time integration.
#include "granmpm/dem/dem.hpp"

#include <algorithm>
#include <cstring>
#include <unordered_map>

#include "granmpm/config.hpp"

namespace granmpm::dem {

namespace {

const char *F_X = "DMSwarmPIC_coor";
const char *F_CELL = "DMSwarm_cellid";
const char *F_V = "dem_v";
const char *F_W = "dem_omega";
const char *F_R = "dem_radius";
const char *F_TH = "dem_theta";
const char *F_ID = "DMSwarm_pid";
const char *F_RANK = "DMSwarm_rank";

// known: rcnt already holds the receive counts (the ghost plan between rebuilds).
template <class T>
void alltoallv(MPI_Comm comm, const std::vector<T> &send, const std::vector<int> &scnt, std::vector<T> &recv, std::vector<int> &rcnt, bool known = false) {
  const int P = (int)scnt.size();
  if (!known) {
    rcnt.assign(P, 0);
    MPI_Alltoall(scnt.data(), 1, MPI_INT, rcnt.data(), 1, MPI_INT, comm);
  }
  std::vector<int> sb(P), rb(P), sd(P), rd(P);
  int ts = 0, tr = 0;
  for (int p = 0; p < P; ++p) {
    sb[p] = scnt[p] * (int)sizeof(T);
    rb[p] = rcnt[p] * (int)sizeof(T);
    sd[p] = ts;
    rd[p] = tr;
    ts += sb[p];
    tr += rb[p];
  }
  recv.resize(tr / sizeof(T));
  MPI_Alltoallv(send.data(), sb.data(), sd.data(), MPI_BYTE, recv.data(), rb.data(), rd.data(), MPI_BYTE, comm);
}

inline double comp(const V3 &a, int k) { return k == 0 ? a.x : (k == 1 ? a.y : a.z); }
inline double &comp(V3 &a, int k) { return k == 0 ? a.x : (k == 1 ? a.y : a.z); }

} // namespace

// splitmix64: a grain's random numbers depend on its id only, so any rank count creates
// the same grains.
static inline uint64_t mix(uint64_t z) {
  z += 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}
static inline double urand(uint64_t seed, int64_t id, int k) { // in [0, 1)
  return (mix(mix(seed * 0x632be59bd9b4e019ULL + (uint64_t)id) + (uint64_t)k) >> 11) * 0x1.0p-53;
}

Engine::Engine(MPI_Comm comm, const Config &cfg) : comm_(comm), c_(cfg) {
  MPI_Comm_rank(comm_, &rank_);
  MPI_Comm_size(comm_, &size_);
  c_.validate();
  nrot_ = c_.dim == 3 ? 3 : 1;
}

Engine::~Engine() {
  if (sw_) DMDestroy(&sw_);
  if (da_) DMDestroy(&da_);
}

double Engine::grain_radius(int64_t id) const {
  const double r = c_.radius, s = c_.spread;
  switch (c_.dist) {
  case RadiusDist::Mono: return r;
  case RadiusDist::Uniform: return r * (1 + s * (2 * urand(c_.seed, id, 7) - 1));
  case RadiusDist::Normal: {
    // Box-Muller, redrawn until within +-2 sigma.
    for (int k = 0;; k += 2) {
      const double u1 = 1 - urand(c_.seed, id, 8 + k), u2 = urand(c_.seed, id, 9 + k);
      const double g = std::sqrt(-2 * std::log(u1)) * std::cos(2 * M_PI * u2);
      if (std::fabs(g) <= 2) return r * (1 + s * g);
    }
  }
  }
  return r;
}

int Engine::owner_rank(const V3 &x) const {
  int p[3] = {0, 0, 0};
  for (int k = 0; k < c_.dim; ++k) {
    int cidx = (int)std::floor((comp(x, k) - c_.lo[k]) / h_[k]);
    cidx = std::clamp(cidx, 0, M_[k] - 1);
    const auto &s = own_start_[k];
    p[k] = (int)(std::upper_bound(s.begin(), s.end(), cidx) - s.begin()) - 1;
  }
  return p[0] + P_[0] * (p[1] + P_[1] * p[2]);
}

V3 Engine::box_lo(int r) const {
  const int p[3] = {r % P_[0], (r / P_[0]) % P_[1], r / (P_[0] * P_[1])};
  V3 b{0, 0, 0};
  for (int k = 0; k < c_.dim; ++k)
    comp(b, k) = (p[k] == 0 && !c_.periodic[k]) ? -1e300 : c_.lo[k] + own_start_[k][p[k]] * h_[k];
  return b;
}
V3 Engine::box_hi(int r) const {
  const int p[3] = {r % P_[0], (r / P_[0]) % P_[1], r / (P_[0] * P_[1])};
  V3 b{0, 0, 0};
  for (int k = 0; k < c_.dim; ++k)
    comp(b, k) = (p[k] == P_[k] - 1 && !c_.periodic[k]) ? 1e300 : c_.lo[k] + own_start_[k][p[k] + 1] * h_[k];
  return b;
}

void Engine::create_swarm() {
  const int dim = c_.dim;
  // Broad-phase cells: at least one largest diameter plus the skin (Config checks -dem_cell).
  for (int k = 0; k < 3; ++k) {
    if (k >= dim) {
      M_[k] = 1;
      h_[k] = 1;
      continue;
    }
    const double L = c_.hi[k] - c_.lo[k];
    M_[k] = std::max(1, (int)std::floor(L / c_.cell));
    h_[k] = L / M_[k];
  }
  if ((double)(M_[0] + 2) * (M_[1] + 2) * (M_[2] + 2) > 2e9)
    throw UserError("the DEM box has more than 2e9 broad-phase cells: raise -dem_cell or shrink -dem_hi - -dem_lo");
  DMBoundaryType bt[3];
  for (int k = 0; k < 3; ++k) bt[k] = c_.periodic[k] ? DM_BOUNDARY_PERIODIC : DM_BOUNDARY_NONE;
  PetscErrorPrintf = PetscErrorPrintfNone;
  PetscPushErrorHandler(PetscReturnErrorHandler, NULL);
  PetscErrorCode ierr;
  if (dim == 2)
    ierr = DMDACreate2d(comm_, bt[0], bt[1], DMDA_STENCIL_BOX, M_[0], M_[1], PETSC_DECIDE, PETSC_DECIDE, 1, 0, NULL, NULL, &da_);
  else
    ierr = DMDACreate3d(comm_, bt[0], bt[1], bt[2], DMDA_STENCIL_BOX, M_[0], M_[1], M_[2], PETSC_DECIDE, PETSC_DECIDE, PETSC_DECIDE, 1, 0, NULL, NULL, NULL, &da_);
  if (!ierr) ierr = DMSetUp(da_);
  PetscPopErrorHandler();
  PetscErrorPrintf = PetscErrorPrintfDefault;
  if (ierr)
    throw UserError("the DEM box has " + std::to_string(M_[0]) + "x" + std::to_string(M_[1]) + (dim == 3 ? "x" + std::to_string(M_[2]) : std::string()) +
                    " broad-phase cells, too few for " + std::to_string(size_) + " ranks: enlarge -dem_hi - -dem_lo, lower -dem_cell or use fewer ranks");
  PetscInt px, py, pz;
  GM_CALL(DMDAGetInfo(da_, NULL, NULL, NULL, NULL, &px, &py, &pz, NULL, NULL, NULL, NULL, NULL, NULL));
  P_ = {(int)px, (int)py, dim == 3 ? (int)pz : 1};
  const PetscInt *l[3];
  GM_CALL(DMDAGetOwnershipRanges(da_, &l[0], &l[1], &l[2]));
  for (int k = 0; k < 3; ++k) {
    own_start_[k].assign(1, 0);
    for (int p = 0; p < P_[k]; ++p) own_start_[k].push_back(own_start_[k].back() + (k < dim ? (int)l[k][p] : 1));
  }
}

// The grain swarm is only the vehicle of migration: created for it, emptied into the
// working arrays and destroyed right after (its copy would cost ~100 bytes per grain).
void Engine::new_swarm() {
  const int dim = c_.dim;
  GM_CALL(DMCreate(comm_, &sw_));
  GM_CALL(DMSetType(sw_, DMSWARM));
  GM_CALL(DMSetDimension(sw_, dim));
  GM_CALL(DMSwarmSetType(sw_, DMSWARM_BASIC));
  GM_CALL(DMSwarmSetCellDM(sw_, da_));
  GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_X, dim, PETSC_REAL));
  GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_CELL, 1, PETSC_INT));
  GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_V, dim, PETSC_REAL));
  GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_W, nrot_, PETSC_REAL));
  GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_R, 1, PETSC_REAL));
  if (dim == 2) GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_TH, 1, PETSC_REAL));
  GM_CALL(DMSwarmFinalizeFieldRegister(sw_));
  GM_CALL(DMSwarmSetLocalSizes(sw_, 0, 16));
}

// Owned working arrays -> swarm (same order; the swarm holds exactly the owned grains).
void Engine::store_to_swarm() {
  const int dim = c_.dim;
  if (!sw_) new_swarm();
  GM_CALL(DMSwarmSetLocalSizes(sw_, (PetscInt)nown_, 16));
  double *x, *v, *w, *r, *th = nullptr;
  int64_t *id;
  PetscInt *cell;
  int *rank;
  GM_CALL(DMSwarmGetField(sw_, F_X, NULL, NULL, (void **)&x));
  GM_CALL(DMSwarmGetField(sw_, F_CELL, NULL, NULL, (void **)&cell));
  GM_CALL(DMSwarmGetField(sw_, F_V, NULL, NULL, (void **)&v));
  GM_CALL(DMSwarmGetField(sw_, F_W, NULL, NULL, (void **)&w));
  GM_CALL(DMSwarmGetField(sw_, F_R, NULL, NULL, (void **)&r));
  GM_CALL(DMSwarmGetField(sw_, F_ID, NULL, NULL, (void **)&id));
  GM_CALL(DMSwarmGetField(sw_, F_RANK, NULL, NULL, (void **)&rank));
  if (dim == 2) GM_CALL(DMSwarmGetField(sw_, F_TH, NULL, NULL, (void **)&th));
  for (long i = 0; i < nown_; ++i) {
    for (int k = 0; k < dim; ++k) {
      x[i * dim + k] = comp(x_[i], k);
      v[i * dim + k] = comp(v_[i], k);
    }
    if (dim == 3) {
      w[3 * i] = w_[i].x;
      w[3 * i + 1] = w_[i].y;
      w[3 * i + 2] = w_[i].z;
    } else {
      w[i] = w_[i].z;
      th[i] = theta_[i];
    }
    r[i] = r_[i];
    id[i] = id_[i];
    rank[i] = owner_rank(x_[i]);
    // Cell id in DMDAGetElements-like global numbering of broad-phase cells.
    int ci[3] = {0, 0, 0};
    for (int k = 0; k < dim; ++k) ci[k] = std::clamp((int)std::floor((comp(x_[i], k) - c_.lo[k]) / h_[k]), 0, M_[k] - 1);
    cell[i] = ci[0] + M_[0] * (ci[1] + M_[1] * ci[2]);
  }
  if (dim == 2) GM_CALL(DMSwarmRestoreField(sw_, F_TH, NULL, NULL, (void **)&th));
  GM_CALL(DMSwarmRestoreField(sw_, F_RANK, NULL, NULL, (void **)&rank));
  GM_CALL(DMSwarmRestoreField(sw_, F_ID, NULL, NULL, (void **)&id));
  GM_CALL(DMSwarmRestoreField(sw_, F_R, NULL, NULL, (void **)&r));
  GM_CALL(DMSwarmRestoreField(sw_, F_W, NULL, NULL, (void **)&w));
  GM_CALL(DMSwarmRestoreField(sw_, F_V, NULL, NULL, (void **)&v));
  GM_CALL(DMSwarmRestoreField(sw_, F_CELL, NULL, NULL, (void **)&cell));
  GM_CALL(DMSwarmRestoreField(sw_, F_X, NULL, NULL, (void **)&x));
}

// Swarm -> owned working arrays, in id order (a canonical layout, so that the ghost plan and
// everything after it are the same on every run with this rank count).
void Engine::load_from_swarm() {
  const int dim = c_.dim;
  PetscInt n;
  GM_CALL(DMSwarmGetLocalSize(sw_, &n));
  double *x, *v, *w, *r, *th = nullptr;
  int64_t *id;
  GM_CALL(DMSwarmGetField(sw_, F_X, NULL, NULL, (void **)&x));
  GM_CALL(DMSwarmGetField(sw_, F_V, NULL, NULL, (void **)&v));
  GM_CALL(DMSwarmGetField(sw_, F_W, NULL, NULL, (void **)&w));
  GM_CALL(DMSwarmGetField(sw_, F_R, NULL, NULL, (void **)&r));
  GM_CALL(DMSwarmGetField(sw_, F_ID, NULL, NULL, (void **)&id));
  if (dim == 2) GM_CALL(DMSwarmGetField(sw_, F_TH, NULL, NULL, (void **)&th));
  // Spatial order (cell, then id) for cache locality; deterministic.
  std::vector<std::pair<int64_t, int64_t>> key(n);
  for (PetscInt i = 0; i < n; ++i) {
    V3 xi{};
    for (int k = 0; k < dim; ++k) comp(xi, k) = x[i * dim + k];
    key[i] = {cell_key(xi), i};
  }
  std::sort(key.begin(), key.end(), [&](const auto &a, const auto &b) { return a.first != b.first ? a.first < b.first : id[a.second] < id[b.second]; });
  nown_ = n;
  x_.resize(n);
  v_.resize(n);
  w_.resize(n);
  r_.resize(n);
  id_.resize(n);
  theta_.assign(dim == 2 ? n : 0, 0.0); // the rotation angle of disks (3D: none kept)
  for (PetscInt q = 0; q < n; ++q) {
    const PetscInt i = (PetscInt)key[q].second;
    V3 xi{}, vi{}, wi{};
    for (int k = 0; k < dim; ++k) {
      comp(xi, k) = x[i * dim + k];
      comp(vi, k) = v[i * dim + k];
    }
    if (dim == 3) wi = {w[3 * i], w[3 * i + 1], w[3 * i + 2]};
    else {
      wi.z = w[i];
      theta_[q] = th[i];
    }
    x_[q] = xi;
    v_[q] = vi;
    w_[q] = wi;
    r_[q] = r[i];
    id_[q] = id[i];
  }
  if (dim == 2) GM_CALL(DMSwarmRestoreField(sw_, F_TH, NULL, NULL, (void **)&th));
  GM_CALL(DMSwarmRestoreField(sw_, F_ID, NULL, NULL, (void **)&id));
  GM_CALL(DMSwarmRestoreField(sw_, F_R, NULL, NULL, (void **)&r));
  GM_CALL(DMSwarmRestoreField(sw_, F_W, NULL, NULL, (void **)&w));
  GM_CALL(DMSwarmRestoreField(sw_, F_V, NULL, NULL, (void **)&v));
  GM_CALL(DMSwarmRestoreField(sw_, F_X, NULL, NULL, (void **)&x));
  GM_CALL(DMDestroy(&sw_));
}

// The broad-phase cell of x as one number (cells just outside the box included): with the
// grain id it orders the grains the same way on every rank.
int Engine::cell_key(const V3 &x) const {
  int64_t ci = 0;
  for (int k = c_.dim - 1; k >= 0; --k) ci = ci * (M_[k] + 2) + std::clamp((int)std::floor((comp(x, k) - c_.lo[k]) / h_[k]), -1, M_[k]) + 1;
  return (int)ci;
}

void Engine::set_keys() {
  ckey_.resize(nown_);
  for (long i = 0; i < nown_; ++i) ckey_[i] = cell_key(x0_[i]);
}

V3 Engine::pair_sep(long i, long j) const {
  V3 d = x_[j] - x_[i];
  if (j >= nown_) d = d + gshift_[j - nown_];
  else if (i >= nown_) d = d + (-gshift_[i - nown_]); // -s is the partner rank's shift of j
  return d;
}

void Engine::create_grains() {
  const int dim = c_.dim;
  std::vector<V3> xs, vs;
  std::vector<double> rs;
  std::vector<int64_t> ids;
  auto add = [&](int64_t id, V3 x, V3 v, double r) {
    if (owner_rank(x) != rank_) return;
    ids.push_back(id);
    xs.push_back(x);
    vs.push_back(v);
    rs.push_back(r);
  };
  if (c_.scene == Scene::List) {
    const int per = 2 * dim + 1;
    for (size_t g = 0; g * per < c_.grains.size(); ++g) {
      const double *q = &c_.grains[g * per];
      V3 x{}, v{};
      for (int k = 0; k < dim; ++k) {
        comp(x, k) = q[k];
        comp(v, k) = q[dim + 1 + k];
      }
      add((int64_t)g, x, v, q[dim]);
    }
  } else {
    // A lattice filling the block (simple cubic, or fcc / hexagonal with nearest-neighbour
    // distance a); each site jittered by a fraction of the free gap.
    const double a = c_.spacing > 0 ? c_.spacing : 2.02 * rmax_;
    const bool dense = c_.lattice == Lattice::Dense;
    double cell[3] = {a, a, a};
    std::vector<V3> basis{{0.5, 0.5, 0.5}};
    if (dense && dim == 3) {
      cell[0] = cell[1] = cell[2] = a * std::sqrt(2.0);
      basis = {{0.25, 0.25, 0.25}, {0.75, 0.75, 0.25}, {0.75, 0.25, 0.75}, {0.25, 0.75, 0.75}};
    } else if (dense) {
      cell[1] = a * std::sqrt(3.0);
      basis = {{0.25, 0.25, 0}, {0.75, 0.75, 0}};
    }
    int n[3] = {1, 1, 1};
    for (int k = 0; k < dim; ++k) n[k] = std::max(0, (int)std::floor((c_.block_hi[k] - c_.block_lo[k]) / cell[k] + 1e-9));
    const int nb = (int)basis.size();
    for (int kz = 0; kz < n[2]; ++kz)
      for (int ky = 0; ky < n[1]; ++ky)
        for (int kx = 0; kx < n[0]; ++kx)
          for (int b = 0; b < nb; ++b) {
            const int64_t id = b + nb * (kx + (int64_t)n[0] * (ky + (int64_t)n[1] * kz));
            const double r = grain_radius(id);
            const int kk[3] = {kx, ky, kz};
            V3 x{}, v{};
            for (int k = 0; k < dim; ++k) {
              comp(x, k) = c_.block_lo[k] + (kk[k] + comp(basis[b], k)) * cell[k] + c_.jitter * (a - 2 * r) * (urand(c_.seed, id, k) - 0.5);
              comp(v, k) = c_.v0[k] + c_.vrand * (2 * urand(c_.seed, id, 3 + k) - 1);
            }
            add(id, x, v, r);
          }
  }
  nown_ = (long)ids.size();
  x_ = xs;
  v_ = vs;
  w_.assign(nown_, V3{});
  r_ = rs;
  id_ = ids;
  theta_.assign(dim == 2 ? nown_ : 0, 0.0);
  // Through the swarm once, so the working layout is the canonical one.
  store_to_swarm();
  load_from_swarm();
}

double Engine::grain_mass(double r) const {
  return c_.dim == 3 ? c_.density * 4.0 / 3.0 * M_PI * r * r * r : c_.density * M_PI * r * r;
}

void Engine::setup() {
  // Largest radius of the distribution (the halo and the cells are sized from it).
  rmax_ = c_.radius * (c_.dist == RadiusDist::Mono ? 1.0 : (c_.dist == RadiusDist::Uniform ? 1 + c_.spread : 1 + 2 * c_.spread));
  double rmin = c_.radius * (c_.dist == RadiusDist::Mono ? 1.0 : (c_.dist == RadiusDist::Uniform ? 1 - c_.spread : 1 - 2 * c_.spread));
  if (c_.scene == Scene::List) {
    const int per = 2 * c_.dim + 1;
    rmax_ = 0;
    rmin = 1e300;
    for (size_t g = 0; g * per < c_.grains.size(); ++g) {
      rmax_ = std::max(rmax_, c_.grains[g * per + c_.dim]);
      rmin = std::min(rmin, c_.grains[g * per + c_.dim]);
    }
  }
  if (c_.skin <= 0) c_.skin = 0.3 * rmax_;
  const double need = 2 * rmax_ + c_.skin;
  if (c_.cell <= 0) c_.cell = need;
  else if (c_.cell < need)
    throw UserError("-dem_cell " + std::to_string(c_.cell) + " is smaller than the largest grain diameter plus the skin (" + std::to_string(need) +
                    "): raise -dem_cell or lower -dem_radius/-dem_radius_spread/-dem_skin");
  halo_ = need;
  for (int k = 0; k < c_.dim; ++k)
    if (c_.periodic[k] && c_.hi[k] - c_.lo[k] < 2 * halo_ + 1e-12)
      throw UserError("the periodic direction " + std::string(1, "xyz"[k]) + " is shorter than twice the interaction range (" + std::to_string(2 * halo_) +
                      "): enlarge -dem_hi - -dem_lo or lower -dem_radius/-dem_skin");
  c_.contact.finalize();
  c_.wall.finalize();
  // Automatic time step from the lightest contact (two lightest grains, or one on a wall).
  const double mmin = grain_mass(rmin);
  c_.contact.mean_mass_value = c_.wall.mean_mass_value = grain_mass(c_.radius);
  auto tc_of = [&](const ContactParams &p, double meff, double reff) {
    double kn = p.kn;
    if (p.law == Law::Hertz) kn *= std::sqrt(0.02 * reff * reff); // stiffness at 2% overlap
    // gamma_n = damp sqrt(kn m), m the effective (or the seed's mean) mass.
    const double mm = p.mean_mass ? 0.5 * p.mean_mass_value : meff;
    return contact_duration(kn, p.damp * std::sqrt(mm / meff), meff);
  };
  const double tc = std::min(tc_of(c_.contact, 0.5 * mmin, 0.5 * rmin), tc_of(c_.wall, mmin, rmin));
  tc_ = tc;
  if (c_.dt > 0) {
    if (c_.dt > tc / 5)
      throw UserError("-dem_dt " + std::to_string(c_.dt) + " is above t_c/5 = " + std::to_string(tc / 5) +
                      " (t_c the contact time of the lightest contact): lower -dem_dt or leave it to -dem_steps_per_contact");
    dt_ = c_.dt;
  } else
    dt_ = tc / c_.steps_per_contact;

  create_swarm();
  if (!c_.restart.empty()) {
    read_checkpoint(c_.restart);
    return;
  }
  create_grains();
  long n = nown_, N;
  MPI_Allreduce(&n, &N, 1, MPI_LONG, MPI_SUM, comm_);
  if (N == 0) throw UserError("the DEM scene has no grains: check -dem_block_lo/-dem_block_hi against -dem_radius (or -dem_grains)");
  check_walls();
  x0_.assign(x_.begin(), x_.begin() + nown_);
  set_keys();
  exchange_ghosts_full();
  build_lists(true, {});
  compute_forces();
}

// A grain whose centre is past a non-periodic face has left the domain: stop.
void Engine::check_walls() {
  std::string msg;
  for (long i = 0; i < nown_ && msg.empty(); ++i)
    for (int k = 0; k < c_.dim; ++k) {
      const double xk = comp(x_[i], k);
      if (!c_.periodic[k] && ((xk < c_.lo[k] && !c_.outlet[k][0]) || (xk > c_.hi[k] && !c_.outlet[k][1]))) {
        msg = "grain " + std::to_string(id_[i]) + " left the domain through the " + (xk < c_.lo[k] ? "lower " : "upper ") + std::string(1, "xyz"[k]) +
              " face at t = " + std::to_string(t_) + ": stiffen the walls (-dem_wall_kn), lower -dem_dt, or make the face periodic (-dem_periodic)";
        break;
      }
    }
  collective_fail(comm_, !msg.empty(), msg);
}

// The ghost plan: every owned grain within the interaction range of another rank's box
// (or of this rank's own box through a periodic face) is sent there, with its shift.
void Engine::exchange_ghosts_full() {
  const int dim = c_.dim;
  std::vector<std::vector<std::pair<int, V3>>> out(size_);
  std::vector<V3> blo(size_), bhi(size_);
  for (int r = 0; r < size_; ++r) {
    blo[r] = box_lo(r);
    bhi[r] = box_hi(r);
  }
  const V3 mlo = blo[rank_], mhi = bhi[rank_];
  for (long i = 0; i < nown_; ++i) {
    const V3 x = x_[i];
    // Interior grains (farther than the halo from every face of this box) stay home.
    bool interior = true;
    for (int k = 0; k < dim; ++k)
      if (comp(x, k) - comp(mlo, k) < halo_ || comp(mhi, k) - comp(x, k) < halo_) interior = false;
    if (interior) continue;
    double sh[3][3];
    int ns[3] = {1, 1, 1};
    for (int k = 0; k < 3; ++k) {
      sh[k][0] = 0;
      if (k >= dim || !c_.periodic[k]) continue;
      const double L = c_.hi[k] - c_.lo[k];
      if (comp(x, k) - c_.lo[k] < halo_) sh[k][ns[k]++] = L;
      if (c_.hi[k] - comp(x, k) < halo_) sh[k][ns[k]++] = -L;
    }
    for (int a = 0; a < ns[0]; ++a)
      for (int b = 0; b < ns[1]; ++b)
        for (int cc = 0; cc < ns[2]; ++cc) {
          const V3 s{sh[0][a], sh[1][b], sh[2][cc]};
          const V3 xs = x + s;
          const bool zero = a == 0 && b == 0 && cc == 0;
          for (int r = 0; r < size_; ++r) {
            if (r == rank_ && zero) continue;
            double d2 = 0;
            for (int k = 0; k < dim; ++k) {
              const double q = std::max({comp(blo[r], k) - comp(xs, k), 0.0, comp(xs, k) - comp(bhi[r], k)});
              d2 += q * q;
            }
            if (d2 < halo_ * halo_) out[r].push_back({(int)i, s});
          }
        }
  }
  send_cnt_.assign(size_, 0);
  send_idx_.clear();
  send_shift_.clear();
  for (int r = 0; r < size_; ++r) {
    send_cnt_[r] = (int)out[r].size();
    for (auto &q : out[r]) {
      send_idx_.push_back(q.first);
      send_shift_.push_back(q.second);
    }
  }
  struct GhostFull {
    int64_t id, key;
    double r;
    V3 x, s, v, w; // raw position and its periodic shift (applied after differences)
  };
  std::vector<GhostFull> sbuf(send_idx_.size()), rbuf;
  for (size_t q = 0; q < send_idx_.size(); ++q) {
    const int i = send_idx_[q];
    sbuf[q] = {id_[i], ckey_[i], r_[i], x_[i], send_shift_[q], v_[i], w_[i]};
  }
  alltoallv(comm_, sbuf, send_cnt_, rbuf, recv_cnt_);
  ntot_ = nown_ + (long)rbuf.size();
  // Exact sizes (a plain resize may double the capacity): the memory follows the grains.
  auto fit = [](auto &vec, size_t n) {
    vec.resize(n);
    vec.shrink_to_fit();
  };
  fit(x_, ntot_);
  fit(v_, ntot_);
  fit(w_, ntot_);
  fit(r_, ntot_);
  fit(id_, ntot_);
  fit(ckey_, ntot_);
  fit(f_, ntot_);
  fit(tq_, ntot_);
  fit(ncontact_, ntot_);
  fit(gshift_, rbuf.size());
  fit(theta_, theta_.size());
  fit(x0_, nown_);
  fit(send_idx_, send_idx_.size());
  fit(send_shift_, send_shift_.size());
  for (size_t q = 0; q < rbuf.size(); ++q) {
    const long j = nown_ + (long)q;
    id_[j] = rbuf[q].id;
    ckey_[j] = (int)rbuf[q].key;
    r_[j] = rbuf[q].r;
    x_[j] = rbuf[q].x;
    gshift_[q] = rbuf[q].s;
    v_[j] = rbuf[q].v;
    w_[j] = rbuf[q].w;
  }
  fit(im_, ntot_);
  fit(iI_, ntot_);
  for (long i = 0; i < ntot_; ++i) {
    const double m = grain_mass(r_[i]);
    im_[i] = 1.0 / m;
    iI_[i] = 1.0 / ((c_.dim == 3 ? 0.4 : 0.5) * m * r_[i] * r_[i]);
  }
}

// Each step: ghosts get the new positions (with their shifts), velocities, spins.
void Engine::update_ghosts() {
  struct GhostState {
    V3 x, v, w;
  };
  std::vector<GhostState> sbuf(send_idx_.size()), rbuf;
  for (size_t q = 0; q < send_idx_.size(); ++q) {
    const int i = send_idx_[q];
    sbuf[q] = {x_[i], v_[i], w_[i]};
  }
  alltoallv(comm_, sbuf, send_cnt_, rbuf, recv_cnt_, true);
  for (size_t q = 0; q < rbuf.size(); ++q) {
    const long j = nown_ + (long)q;
    x_[j] = rbuf[q].x;
    v_[j] = rbuf[q].v;
    w_[j] = rbuf[q].w;
  }
}

// Neighbour lists from cell lists over owned + ghost grains: every partner within
// r_i + r_j + skin, and every non-periodic face within r_i + skin; sorted by partner key
// (faces first), the tangential springs carried over from `store` by key.
void Engine::build_lists(bool first, const std::vector<HistRec> &store) {
  const int dim = c_.dim;
  // Ghost images sit at their raw position plus their periodic shift.
  std::vector<V3> xb(x_.begin(), x_.begin() + ntot_);
  for (long j = nown_; j < ntot_; ++j) xb[j] = x_[j] + gshift_[j - nown_];
  V3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (long i = 0; i < ntot_; ++i)
    for (int k = 0; k < dim; ++k) {
      comp(lo, k) = std::min(comp(lo, k), comp(xb[i], k));
      comp(hi, k) = std::max(comp(hi, k), comp(xb[i], k));
    }
  int nc[3] = {1, 1, 1};
  for (int k = 0; k < dim; ++k) nc[k] = ntot_ ? std::max(1, (int)((comp(hi, k) - comp(lo, k)) / c_.cell) + 1) : 1;
  const long ncell = (long)nc[0] * nc[1] * nc[2];
  std::vector<int> cstart(ncell + 1, 0), cidx(ntot_), order(ntot_);
  auto cell_of = [&](const V3 &x, int *ci) {
    for (int k = 0; k < 3; ++k) ci[k] = k < dim ? std::min(nc[k] - 1, (int)((comp(x, k) - comp(lo, k)) / c_.cell)) : 0;
    return ci[0] + (long)nc[0] * (ci[1] + (long)nc[1] * ci[2]);
  };
  for (long i = 0; i < ntot_; ++i) {
    int ci[3];
    cidx[i] = (int)cell_of(xb[i], ci);
    cstart[cidx[i] + 1]++;
  }
  for (long c = 0; c < ncell; ++c) cstart[c + 1] += cstart[c];
  {
    std::vector<int> fill(cstart.begin(), cstart.end() - 1);
    for (long i = 0; i < ntot_; ++i) order[fill[cidx[i]]++] = (int)i;
  }
  // The canonical order of the local grains.
  ord_.resize(ntot_);
  ord_.shrink_to_fit();
  for (long i = 0; i < ntot_; ++i) ord_[i] = (int)i;
  auto before = [&](int a, int b) { return ckey_[a] != ckey_[b] ? ckey_[a] < ckey_[b] : (id_[a] != id_[b] ? id_[a] < id_[b] : a < b); };
  std::sort(ord_.begin(), ord_.end(), before);
  std::vector<int> pos(ntot_);
  for (long p = 0; p < ntot_; ++p) pos[ord_[p]] = (int)p;
  // A spring of the previous lists, as seen from owned grain a (store is sorted by a, b).
  auto find = [&](int64_t a, int64_t b, V3 &h) {
    auto it = std::lower_bound(store.begin(), store.end(), std::make_pair(a, b), [](const HistRec &r, const std::pair<int64_t, int64_t> &k) {
      return r.a != k.first ? r.a < k.first : r.b < k.second;
    });
    if (it != store.end() && it->a == a && it->b == b) {
      h = it->h;
      return true;
    }
    return false;
  };
  // Walls and the plate (owned grains), in key order.
  ws_.assign(nown_ + 1, 0);
  wf_.clear();
  whist_.clear();
  double max_ov = 0;
  std::vector<int> faces;
  for (long i = 0; i < nown_; ++i) {
    faces.clear();
    const V3 xi = x_[i];
    for (int k = 0; k < dim; ++k) {
      if (c_.periodic[k]) continue;
      if (!c_.outlet[k][0] && comp(xi, k) - c_.lo[k] < r_[i] + c_.skin) faces.push_back(-(2 * k + 1));
      if (!c_.outlet[k][1] && c_.hi[k] - comp(xi, k) < r_[i] + c_.skin) faces.push_back(-(2 * k + 2));
      if (first && !c_.outlet[k][0] && !c_.outlet[k][1]) {
        max_ov = std::max(max_ov, (r_[i] - (comp(xi, k) - c_.lo[k])) / r_[i]);
        max_ov = std::max(max_ov, (r_[i] - (c_.hi[k] - comp(xi, k))) / r_[i]);
      }
    }
    if (c_.plate && std::fabs(xi.y - c_.plate_y) < r_[i] + c_.skin) {
      faces.push_back(-(2 * dim + 1));
      if (first) max_ov = std::max(max_ov, (r_[i] - norm(plate_point(xi) - xi)) / r_[i]);
    }
    std::sort(faces.begin(), faces.end());
    for (int f : faces) {
      V3 h{};
      find(id_[i], f, h);
      wf_.push_back(f);
      whist_.push_back(h);
    }
    ws_[i + 1] = (int)wf_.size();
  }
  // Half lists in canonical order: partners later in the order within r_i + r_j + skin, at
  // least one of the two owned; sorted by their position in the order.
  ls_.assign(ntot_ + 1, 0);
  nb_.clear();
  sp_.clear();
  std::vector<V3> pool;
  std::vector<int> cand;
  for (long p = 0; p < ntot_; ++p) {
    const int i = ord_[p];
    cand.clear();
    int ci[3];
    cell_of(xb[i], ci);
    for (int dz = (dim == 3 ? -1 : 0); dz <= (dim == 3 ? 1 : 0); ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int a = ci[0] + dx, b = ci[1] + dy, cz = ci[2] + dz;
          if (a < 0 || b < 0 || cz < 0 || a >= nc[0] || b >= nc[1] || cz >= nc[2]) continue;
          const long c = a + (long)nc[0] * (b + (long)nc[1] * cz);
          for (int q = cstart[c]; q < cstart[c + 1]; ++q) {
            const int j = order[q];
            if (pos[j] <= p || (i >= nown_ && j >= nown_)) continue;
            const V3 d = pair_sep(i, j);
            const double cut = r_[i] + r_[j] + c_.skin;
            const double d2 = dot(d, d);
            if (d2 < cut * cut) {
              cand.push_back(pos[j]);
              if (first) max_ov = std::max(max_ov, (r_[i] + r_[j] - std::sqrt(d2)) / std::min(r_[i], r_[j]));
            }
          }
        }
    std::sort(cand.begin(), cand.end());
    for (int pj : cand) {
      const int j = ord_[pj];
      V3 h{};
      if (i < nown_) find(id_[i], id_[j], h);
      else if (find(id_[j], id_[i], h)) h = -h;
      nb_.push_back(j);
      sp_.push_back(h.x != 0 || h.y != 0 || h.z != 0 ? (int)pool.size() : -1);
      if (sp_.back() >= 0) pool.push_back(h);
    }
    ls_[p + 1] = (int)nb_.size();
  }
  // Exact capacities: the lists' memory follows the grains, not the largest list so far.
  nb_.shrink_to_fit();
  sp_.shrink_to_fit();
  wf_.shrink_to_fit();
  whist_.shrink_to_fit();
  pool_.swap(pool);
  free_.clear();
  if (first) {
    double g;
    MPI_Allreduce(&max_ov, &g, 1, MPI_DOUBLE, MPI_MAX, comm_);
    if (g > c_.overlap_tol)
      throw UserError("initial grain overlap " + std::to_string(g) + " (of the smaller radius) is above -dem_overlap_tol " + std::to_string(c_.overlap_tol) +
                      ": space the grains (-dem_spacing, -dem_jitter, -dem_radius_spread) or raise -dem_overlap_tol");
  }
}

std::vector<HistRec> Engine::owned_springs(std::vector<long> *who) const {
  std::vector<HistRec> out;
  auto add = [&](long i, HistRec r) {
    out.push_back(r);
    if (who) who->push_back(i);
  };
  auto nonzero = [](const V3 &h) { return h.x != 0 || h.y != 0 || h.z != 0; };
  for (long i = 0; i < nown_; ++i)
    for (int q = ws_[i]; q < ws_[i + 1]; ++q)
      if (nonzero(whist_[q])) add(i, {id_[i], (int64_t)wf_[q], whist_[q]});
  for (long p = 0; p < ntot_; ++p) {
    const int i = ord_[p];
    for (int q = ls_[p]; q < ls_[p + 1]; ++q) {
      const V3 h = spring(q);
      if (!nonzero(h)) continue;
      const int j = nb_[q];
      if (i < nown_) add(i, {id_[i], id_[j], h});
      if (j < nown_) add(j, {id_[j], id_[i], -h});
    }
  }
  return out;
}

void Engine::compute_forces() {
  const double dt = dt_;
  f_.resize(ntot_);
  tq_.resize(ntot_);
  ncontact_.resize(ntot_);
  const V3 g{c_.gravity[0], c_.gravity[1], c_.gravity[2]};
  const ContactParams cp = c_.contact; // a local copy: no reloads through this
  const bool roll = cp.mu_roll > 0;
  const V3 *__restrict x = x_.data();
  const V3 *__restrict v = v_.data();
  const V3 *__restrict w = w_.data();
  const double *__restrict rad = r_.data();
  const double *__restrict im = im_.data();
  const double *__restrict iI = iI_.data();
  const int *__restrict nb = nb_.data();
  int *__restrict sp = sp_.data();
  V3 *__restrict f = f_.data();
  V3 *__restrict tq = tq_.data();
  int *__restrict ncon = ncontact_.data();
  const long nown = nown_;
  double elastic = 0, max_ov = 0;
  long contacts = 0, wall_contacts = 0;
  // Walls first (the first partners of every grain in key order).
  for (long i = 0; i < ntot_; ++i) {
    f[i] = V3{};
    tq[i] = V3{};
    ncon[i] = 0;
  }
  for (long i = 0; i < nown; ++i)
    for (int q = ws_[i]; q < ws_[i + 1]; ++q) {
      const V3 xi = x[i];
      const double ri = rad[i];
      const int face = -wf_[q] - 1, k = face / 2;
      V3 d{};
      if (face < 2 * c_.dim) comp(d, k) = (face % 2 == 0 ? c_.lo[k] : c_.hi[k]) - comp(xi, k);
      else d = plate_point(xi) - xi;
      const double dd = dot(d, d);
      if (dd >= ri * ri) {
        whist_[q] = V3{};
        continue;
      }
      const ContactResult res = contact(c_.wall, d, ri, 0.0, v[i], w[i], V3{}, 1.0 / im[i], 1.0 / iI[i], whist_[q], dt);
      f[i] = f[i] + res.force;
      tq[i] = tq[i] + res.torque + res.troll;
      elastic += res.elastic;
      max_ov = std::max(max_ov, ri - std::sqrt(dd));
      if (res.fn > 0) {
        ++ncon[i];
        ++wall_contacts;
      }
    }
  // Pairs, each once, in canonical order; the partner takes the negated force.
  const int *__restrict ls = ls_.data();
  for (long p = 0; p < ntot_; ++p) {
    const int i = ord_[p];
    if (ls[p] == ls[p + 1]) continue;
    const V3 xi = x[i], vi = v[i], wi = w[i];
    const double ri = rad[i];
    const bool iown = i < nown;
    const V3 si = iown ? V3{} : -gshift_[i - nown];
    for (int q = ls[p]; q < ls[p + 1]; ++q) {
      const int j = nb[q];
      V3 d = x[j] - xi;
      if (j >= nown) d = d + gshift_[j - nown];
      else if (!iown) d = d + si;
      const double s = ri + rad[j];
      if (dot(d, d) >= s * s) {
        if (sp[q] >= 0) { // the contact ended: its spring slot is free
          free_.push_back(sp[q]);
          sp[q] = -1;
        }
        continue;
      }
      if (sp[q] < 0) { // a new contact: a zero spring (the pool grows only past its peak)
        if (free_.empty()) {
          sp[q] = (int)pool_.size();
          pool_.push_back(V3{});
        } else {
          sp[q] = free_.back();
          free_.pop_back();
          pool_[sp[q]] = V3{};
        }
      }
      const double meff = 1.0 / (im[i] + im[j]);
      const double Ieff = roll ? 1.0 / (iI[i] + iI[j]) : 0.0; // (only rolling resistance needs it)
      const ContactResult res = contact(cp, d, ri, rad[j], vi - v[j], wi, w[j], meff, Ieff, pool_[sp[q]], dt);
      f[i] = f[i] + res.force;
      tq[i] = tq[i] + res.torque + res.troll;
      f[j] = f[j] + (-res.force);
      tq[j] = tq[j] + rad[j] * res.arm + (-res.troll);
      const int owners = (int)iown + (int)(j < nown);
      elastic += 0.5 * owners * res.elastic;
      max_ov = std::max(max_ov, res.overlap);
      if (res.fn > 0) { // a force-carrying contact (an overlap may outlive its force)
        ++ncon[i];
        ++ncon[j];
        contacts += owners;
      }
    }
  }
  for (long i = 0; i < nown; ++i) f[i] = f[i] + (1.0 / im[i]) * g;
  elastic_ = elastic;
  max_overlap_ = max_ov;
  pair_entries_ = contacts;
  wall_contacts_ = wall_contacts;
}

V3 Engine::plate_point(const V3 &x) const {
  const double h = 0.5 * c_.orifice;
  V3 q = x;
  q.y = c_.plate_y;
  if (c_.dim == 2) {
    const double dx = x.x - c_.orifice_x;
    if (std::fabs(dx) < h) q.x = c_.orifice_x + (dx >= 0 ? h : -h);
  } else {
    const double dx = x.x - c_.orifice_x, dz = x.z - c_.orifice_z, rho = std::sqrt(dx * dx + dz * dz);
    if (rho < h) {
      q.x = c_.orifice_x + (rho > 0 ? h * dx / rho : h);
      q.z = c_.orifice_z + (rho > 0 ? h * dz / rho : 0.0);
    }
  }
  return q;
}

void Engine::rebuild() {
  check_walls();
  const int dim = c_.dim;
  for (long i = 0; i < nown_; ++i)
    for (int k = 0; k < dim; ++k)
      if (c_.periodic[k]) {
        const double L = c_.hi[k] - c_.lo[k];
        double &xk = comp(x_[i], k);
        if (xk >= c_.hi[k]) xk -= L;
        else if (xk < c_.lo[k]) xk += L;
      }
  // Grains past an open face leave the run; the springs of every other touching contact
  // travel to the owner's new rank.
  std::vector<char> gone(nown_, 0);
  for (long i = 0; i < nown_; ++i)
    for (int k = 0; k < dim; ++k)
      if ((c_.outlet[k][0] && comp(x_[i], k) < c_.lo[k]) || (c_.outlet[k][1] && comp(x_[i], k) > c_.hi[k])) gone[i] = 1;
  std::vector<std::vector<HistRec>> out(size_);
  {
    std::vector<long> who;
    const std::vector<HistRec> sp = owned_springs(&who);
    for (size_t k = 0; k < sp.size(); ++k)
      if (!gone[who[k]]) out[owner_rank(x_[who[k]])].push_back(sp[k]);
  }
  long keep = 0;
  for (long i = 0; i < nown_; ++i) {
    if (gone[i]) {
      ++removed_;
      continue;
    }
    x_[keep] = x_[i];
    v_[keep] = v_[i];
    w_[keep] = w_[i];
    r_[keep] = r_[i];
    id_[keep] = id_[i];
    if (dim == 2) theta_[keep] = theta_[i];
    ++keep;
  }
  nown_ = keep;
  std::vector<HistRec> sbuf, store;
  std::vector<int> scnt(size_), rcnt;
  for (int r = 0; r < size_; ++r) {
    scnt[r] = (int)out[r].size();
    sbuf.insert(sbuf.end(), out[r].begin(), out[r].end());
  }
  alltoallv(comm_, sbuf, scnt, store, rcnt);
  std::sort(store.begin(), store.end(), [](const HistRec &p, const HistRec &q) { return p.a != q.a ? p.a < q.a : p.b < q.b; });
  store_to_swarm();
  GM_CALL(DMSwarmMigrate(sw_, PETSC_TRUE));
  load_from_swarm();
  x0_.assign(x_.begin(), x_.begin() + nown_);
  set_keys();
  exchange_ghosts_full();
  build_lists(false, store);
  ++tm_.rebuilds;
}

void Engine::step() {
  const double dt = dt_;
  double t0 = MPI_Wtime();
  const bool verlet = c_.integrator == Integrator::Verlet;
  double disp2 = 0;
  for (long i = 0; i < nown_; ++i) {
    if (verlet) {
      v_[i] = v_[i] + (0.5 * dt * im_[i]) * f_[i];
      w_[i] = w_[i] + (0.5 * dt * iI_[i]) * tq_[i];
      x_[i] = x_[i] + dt * v_[i];
    } else {
      x_[i] = x_[i] + dt * v_[i];
      v_[i] = v_[i] + (dt * im_[i]) * f_[i];
      w_[i] = w_[i] + (dt * iI_[i]) * tq_[i];
    }
    if (c_.dim == 2) theta_[i] += dt * w_[i].z;
    const V3 d = x_[i] - x0_[i];
    disp2 = std::max(disp2, dot(d, d));
  }
  double t1 = MPI_Wtime();
  tm_.integrate += t1 - t0;
  double g;
  MPI_Allreduce(&disp2, &g, 1, MPI_DOUBLE, MPI_MAX, comm_);
  if (4 * g > c_.skin * c_.skin) {
    rebuild();
    double t2 = MPI_Wtime();
    tm_.neigh += t2 - t1;
    t1 = t2;
  } else {
    update_ghosts();
    double t2 = MPI_Wtime();
    tm_.comm += t2 - t1;
    t1 = t2;
  }
  compute_forces();
  double t2 = MPI_Wtime();
  tm_.force += t2 - t1;
  if (verlet)
    for (long i = 0; i < nown_; ++i) {
      v_[i] = v_[i] + (0.5 * dt * im_[i]) * f_[i];
      w_[i] = w_[i] + (0.5 * dt * iI_[i]) * tq_[i];
    }
  tm_.integrate += MPI_Wtime() - t2;
  t_ += dt;
  ++step_;
}

Summary Engine::summary() {
  Summary s;
  s.step = step_;
  s.t = t_;
  double loc[5] = {0, 0, 0, elastic_, 0};
  const V3 g{c_.gravity[0], c_.gravity[1], c_.gravity[2]};
  for (long i = 0; i < nown_; ++i) {
    const double m = 1.0 / im_[i];
    loc[0] += 0.5 * m * dot(v_[i], v_[i]);
    loc[1] += 0.5 / iI_[i] * dot(w_[i], w_[i]);
    loc[2] -= m * dot(g, x_[i]);
  }
  double glob[5];
  MPI_Allreduce(loc, glob, 4, MPI_DOUBLE, MPI_SUM, comm_);
  MPI_Allreduce(&max_overlap_, &glob[4], 1, MPI_DOUBLE, MPI_MAX, comm_);
  long cl[4] = {pair_entries_, wall_contacts_, nown_, removed_}, cg[4];
  MPI_Allreduce(cl, cg, 4, MPI_LONG, MPI_SUM, comm_);
  s.removed = cg[3];
  s.ke = glob[0];
  s.ke_rot = glob[1];
  s.pe_grav = glob[2];
  s.pe_elastic = glob[3];
  s.max_overlap = glob[4];
  s.contacts = cg[0] / 2;
  s.wall_contacts = cg[1];
  s.grains = cg[2];
  s.coordination = cg[2] ? (double)cg[0] / cg[2] : 0;
  return s;
}

std::vector<GrainRecord> Engine::gather() {
  std::vector<GrainRecord> mine(nown_), all;
  for (long i = 0; i < nown_; ++i) {
    GrainRecord &g = mine[i];
    g.id = id_[i];
    g.r = r_[i];
    const V3 a[3] = {x_[i], v_[i], w_[i]};
    for (int k = 0; k < 3; ++k) {
      g.x[k] = comp(a[0], k);
      g.v[k] = comp(a[1], k);
      g.w[k] = comp(a[2], k);
    }
    g.contacts = ncontact_[i];
  }
  // Spring sums in the force's canonical order (walls, then partners in key order).
  {
    std::vector<double> hs(ntot_, 0.0);
    for (long i = 0; i < nown_; ++i)
      for (int q = ws_[i]; q < ws_[i + 1]; ++q) hs[i] += norm(whist_[q]);
    for (long p = 0; p < ntot_; ++p)
      for (int q = ls_[p]; q < ls_[p + 1]; ++q) {
        const double h = norm(spring(q));
        hs[ord_[p]] += h;
        hs[nb_[q]] += h;
      }
    for (long i = 0; i < nown_; ++i) mine[i].hist_sum = hs[i];
  }
  int n = (int)mine.size() * (int)sizeof(GrainRecord);
  std::vector<int> cnt(size_), off(size_);
  MPI_Gather(&n, 1, MPI_INT, cnt.data(), 1, MPI_INT, 0, comm_);
  int tot = 0;
  for (int r = 0; r < size_; ++r) {
    off[r] = tot;
    tot += cnt[r];
  }
  if (rank_ == 0) all.resize(tot / sizeof(GrainRecord));
  MPI_Gatherv(mine.data(), n, MPI_BYTE, all.data(), cnt.data(), off.data(), MPI_BYTE, 0, comm_);
  std::sort(all.begin(), all.end(), [](const GrainRecord &a, const GrainRecord &b) { return a.id < b.id; });
  return all;
}

// Sum over owned grains with centre height x_k in [lo, hi) of the grain stress moment
// -sum_c (x_c - x_i)_k f_k (compression positive), from the forces of the last step
// (springs not advanced). Collective.
double Engine::stress_moment(int k, double lo, double hi) {
  double s = 0;
  auto in = [&](long i) { return i < nown_ && comp(x_[i], k) >= lo && comp(x_[i], k) < hi; };
  // The spring as stored already includes this step's slip: re-evaluate at dt = 0.
  for (long i = 0; i < nown_; ++i) {
    if (!in(i)) continue;
    for (int q = ws_[i]; q < ws_[i + 1]; ++q) {
      const int face = -wf_[q] - 1, kk = face / 2;
      V3 d{};
      if (face < 2 * c_.dim) comp(d, kk) = (face % 2 == 0 ? c_.lo[kk] : c_.hi[kk]) - comp(x_[i], kk);
      else d = plate_point(x_[i]) - x_[i];
      const double dist = norm(d);
      if (dist >= r_[i]) continue;
      V3 h = whist_[q];
      const ContactResult res = contact(c_.wall, d, r_[i], 0.0, v_[i], w_[i], V3{}, 1.0 / im_[i], 1.0 / iI_[i], h, 0.0);
      s -= (r_[i] / dist) * comp(d, k) * comp(res.force, k);
    }
  }
  for (long p = 0; p < ntot_; ++p) {
    const int i = ord_[p];
    for (int q = ls_[p]; q < ls_[p + 1]; ++q) {
      const int j = nb_[q];
      if (!in(i) && !in(j)) continue;
      const V3 d = pair_sep(i, j);
      const double dist = norm(d);
      if (dist >= r_[i] + r_[j]) continue;
      V3 h = spring(q);
      const ContactResult res = contact(c_.contact, d, r_[i], r_[j], v_[i] - v_[j], w_[i], w_[j], 1.0 / (im_[i] + im_[j]), 1.0 / (iI_[i] + iI_[j]), h, 0.0);
      // Grain j sees -d and -F: its moment -(r_j/dist) d_k F_k has the same sign.
      if (in(i)) s -= (r_[i] / dist) * comp(d, k) * comp(res.force, k);
      if (in(j)) s -= (r_[j] / dist) * comp(d, k) * comp(res.force, k);
    }
  }
  double g;
  MPI_Allreduce(&s, &g, 1, MPI_DOUBLE, MPI_SUM, comm_);
  return g;
}

std::string Engine::footprint() const {
  const double n = nown_ ? (double)nown_ : 1.0;
  const size_t grain = (x_.capacity() + v_.capacity() + w_.capacity() + x0_.capacity() + f_.capacity() + tq_.capacity() + gshift_.capacity()) * sizeof(V3) +
                       (r_.capacity() + im_.capacity() + iI_.capacity() + theta_.capacity()) * sizeof(double) + id_.capacity() * sizeof(int64_t) +
                       (ckey_.capacity() + ord_.capacity() + ncontact_.capacity() + send_idx_.capacity()) * sizeof(int) + send_shift_.capacity() * sizeof(V3);
  const size_t lists = (ls_.capacity() + nb_.capacity() + sp_.capacity() + ws_.capacity() + wf_.capacity() + free_.capacity()) * sizeof(int);
  const size_t springs = (pool_.capacity() + whist_.capacity()) * sizeof(V3);
  char buf[200];
  std::snprintf(buf, sizeof buf, "%.0f bytes/grain (grain state %.0f, lists %.0f, springs %.0f; %.2f list entries, %.2f ghosts per grain)", (grain + lists + springs) / n,
                grain / n, lists / n, springs / n, nb_.size() / n, (ntot_ - nown_) / n);
  return buf;
}

size_t Engine::bytes_per_grain() const {
  size_t b = 0;
  b += (x_.capacity() + v_.capacity() + w_.capacity() + x0_.capacity() + f_.capacity() + tq_.capacity() + gshift_.capacity()) * sizeof(V3);
  b += (r_.capacity() + im_.capacity() + iI_.capacity() + theta_.capacity()) * sizeof(double) + id_.capacity() * sizeof(int64_t);
  b += (ckey_.capacity() + ord_.capacity() + ls_.capacity() + nb_.capacity() + sp_.capacity() + free_.capacity() + ws_.capacity() + wf_.capacity() + ncontact_.capacity() +
        send_idx_.capacity()) * sizeof(int);
  b += (pool_.capacity() + whist_.capacity() + send_shift_.capacity()) * sizeof(V3);
  return nown_ ? b / nown_ : 0;
}

} // namespace granmpm::dem
