// The DEM grains on their BASIC DMSwarm: the decomposition, the swarm as the vehicle of
// migration, the canonical layout, the initial grains.
#include "granmpm/dem/dem.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <unordered_map>

#include "granmpm/config.hpp"
#include "internal.hpp"

namespace granmpm::dem {

using namespace detail;

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
  if (part_.owner) { // a host's decomposition (DemModule): no DMDA of its own
    P_ = part_.P;
    return;
  }
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
  GM_CALL(DMSwarmSetCellDM(sw_, part_.owner ? part_.cell_dm : da_));
  GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_X, dim, PETSC_REAL));
  GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_CELL, 1, PETSC_INT));
  GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_V, dim, PETSC_REAL));
  GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_W, nrot_, PETSC_REAL));
  GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_R, 1, PETSC_REAL));
  if (c_.orientation) GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_TH, dim == 2 ? 1 : 4, PETSC_REAL)); // theta, or the quaternion
  if (c_.mass_weight) GM_CALL(DMSwarmRegisterPetscDatatypeField(sw_, F_MW, 1, PETSC_REAL));
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
  if (c_.orientation) GM_CALL(DMSwarmGetField(sw_, F_TH, NULL, NULL, (void **)&th));
  double *mw = nullptr;
  if (c_.mass_weight) GM_CALL(DMSwarmGetField(sw_, F_MW, NULL, NULL, (void **)&mw));
  for (long i = 0; i < nown_; ++i) {
    for (int k = 0; k < dim; ++k) {
      x[i * dim + k] = comp(x_[i], k);
      v[i * dim + k] = comp(v_[i], k);
    }
    if (dim == 3) {
      w[3 * i] = w_[i].x;
      w[3 * i + 1] = w_[i].y;
      w[3 * i + 2] = w_[i].z;
      if (th) {
        th[4 * i] = q_[i].w;
        th[4 * i + 1] = q_[i].x;
        th[4 * i + 2] = q_[i].y;
        th[4 * i + 3] = q_[i].z;
      }
    } else {
      w[i] = w_[i].z;
      if (th) th[i] = theta_[i];
    }
    r[i] = r_[i];
    if (mw) mw[i] = mw_[i];
    id[i] = id_[i];
    rank[i] = owner_rank(x_[i]);
    // Cell id in DMDAGetElements-like global numbering of broad-phase cells.
    int ci[3] = {0, 0, 0};
    for (int k = 0; k < dim; ++k) ci[k] = std::clamp((int)std::floor((comp(x_[i], k) - c_.lo[k]) / h_[k]), 0, M_[k] - 1);
    cell[i] = ci[0] + M_[0] * (ci[1] + M_[1] * ci[2]);
  }
  if (mw) GM_CALL(DMSwarmRestoreField(sw_, F_MW, NULL, NULL, (void **)&mw));
  if (th) GM_CALL(DMSwarmRestoreField(sw_, F_TH, NULL, NULL, (void **)&th));
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
  if (c_.orientation) GM_CALL(DMSwarmGetField(sw_, F_TH, NULL, NULL, (void **)&th));
  double *mw = nullptr;
  if (c_.mass_weight) GM_CALL(DMSwarmGetField(sw_, F_MW, NULL, NULL, (void **)&mw));
  mw_.resize(mw ? n : 0);
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
  theta_.assign(th && dim == 2 ? n : 0, 0.0); // the rotation angle of disks
  q_.assign(th && dim == 3 ? n : 0, Quat{});   // the orientation of spheres
  for (PetscInt q = 0; q < n; ++q) {
    const PetscInt i = (PetscInt)key[q].second;
    V3 xi{}, vi{}, wi{};
    for (int k = 0; k < dim; ++k) {
      comp(xi, k) = x[i * dim + k];
      comp(vi, k) = v[i * dim + k];
    }
    if (dim == 3) {
      wi = {w[3 * i], w[3 * i + 1], w[3 * i + 2]};
      if (th) q_[q] = {th[4 * i], th[4 * i + 1], th[4 * i + 2], th[4 * i + 3]};
    } else {
      wi.z = w[i];
      if (th) theta_[q] = th[i];
    }
    x_[q] = xi;
    v_[q] = vi;
    w_[q] = wi;
    r_[q] = r[i];
    if (mw) mw_[q] = mw[i];
    id_[q] = id[i];
  }
  if (mw) GM_CALL(DMSwarmRestoreField(sw_, F_MW, NULL, NULL, (void **)&mw));
  if (th) GM_CALL(DMSwarmRestoreField(sw_, F_TH, NULL, NULL, (void **)&th));
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
  V3 d = x_[dat(j)] - x_[dat(i)];
  if (j >= nown_) d = d + gshift(j - nown_);
  else if (i >= nown_) d = d + (-gshift(i - nown_)); // -s is the partner rank's shift of j
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
  w_.assign(nown_, V3{c_.w0[0], c_.w0[1], c_.w0[2]});
  r_ = rs;
  id_ = ids;
  mw_.clear();
  for (long i = 0; c_.mass_weight && i < nown_; ++i) {
    const double xx[3] = {x_[i].x, x_[i].y, x_[i].z};
    mw_.push_back(c_.mass_weight(xx));
  }
  theta_.assign(c_.orientation && dim == 2 ? nown_ : 0, 0.0);
  q_.assign(c_.orientation && dim == 3 ? nown_ : 0, Quat{}); // every grain starts unrotated
  // Through the swarm once, so the working layout is the canonical one.
  store_to_swarm();
  load_from_swarm();
}

} // namespace granmpm::dem
