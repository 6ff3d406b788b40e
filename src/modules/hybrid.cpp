// HybridModule: the continuum/discrete coupling with a fixed band (hybrid/module.hpp).
#include "granmpm/hybrid/module.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "granmpm/checkpoint.hpp"

namespace granmpm {

namespace {
const char *const kWeight = "hybrid_weight"; // a material point's continuum share w_M
const char *const kZone = "hybrid_zone";     // its zone at the last update (0 C, 1 band, 2 D)
} // namespace

template <int dim>
HybridModule<dim>::HybridModule(State<dim> &S, DemModule<dim> &grains, const hybrid::FixedBand &band) : grains_(grains), band_(band) {
  // Every grain carries a share of its mass: none may start in the continuum zone.
  dem::Engine &e = grains_.engine();
  const dem::V3 *x = e.positions();
  std::string msg;
  for (long i = 0; i < e.owned() && msg.empty(); ++i)
    if (!(e.mass(i) > 0))
      msg = "a DEM grain starts at x = " + std::to_string(x[i].x) + ", y = " + std::to_string(x[i].y) +
            " in the continuum zone of -hybrid_band (no share of its mass): keep -dem_block_lo/-dem_block_hi in the band and the discrete zone";
  collective_fail(S.comm, !msg.empty(), msg);
  make_vectors(S.grid);
}

template <int dim>
HybridModule<dim>::~HybridModule() {
  destroy_vectors();
}

template <int dim>
void HybridModule<dim>::split_particles(State<dim> &S, const hybrid::FixedBand &band) {
  ParticleView<dim> P = S.particles.get();
  double *W = P.field(S.particles.field_index(kWeight)), *Z = P.field(S.particles.field_index(kZone));
  std::string msg;
  for (PetscInt p = 0; p < P.n; ++p) {
    const double w = band.continuum_weight(P.x + p * dim);
    if (W) W[p] = w;
    if (Z) Z[p] = (double)(int)band.zone(P.x + p * dim);
    if (!(w > 0) && msg.empty())
      msg = "a material point starts at " + std::string("xyz").substr(band.axis, 1) + " = " + std::to_string(P.x[p * dim + band.axis]) +
            " in the discrete zone of -hybrid_band (no share of its mass): keep -body_lo/-body_hi in the band and the continuum zone";
    P.m[p] *= w;
    P.vol[p] *= w;
  }
  S.particles.restore(P);
  collective_fail(S.comm, !msg.empty(), msg);
}

template <int dim>
void HybridModule<dim>::make_vectors(const Grid<dim> &g) {
  grid_ = &g;
  GM_CALL(DMCreateGlobalVector(g.da, &glob_));
  GM_CALL(DMCreateLocalVector(g.da, &loc_));
}

template <int dim>
void HybridModule<dim>::destroy_vectors() {
  if (glob_) VecDestroy(&glob_);
  if (loc_) VecDestroy(&loc_);
}

template <int dim>
void HybridModule<dim>::rebuild(State<dim> &S) {
  destroy_vectors();
  make_vectors(S.grid);
}

// The owned grains' weighted mass and momentum to the nodes of their cells.
template <int dim>
void HybridModule<dim>::begin_grid(State<dim> &S, double, bool with_force) {
  active_ = with_force;
  if (!active_) return;
  const Grid<dim> &g = S.grid;
  constexpr int NDOF = Grid<dim>::NDOF;
  GM_CALL(VecZeroEntries(loc_));
  PetscScalar *a;
  GM_CALL(VecGetArray(loc_, &a));
  NodeView<dim> L;
  L.a = a;
  for (int d = 0; d < 3; ++d) {
    L.gs[d] = g.gxs[d];
    L.gm[d] = g.gxm[d];
  }
  dem::Engine &e = grains_.engine();
  const dem::V3 *x = e.positions();
  const dem::V3 *v = e.velocities();
  std::string msg;
  for (long q = 0; q < e.owned(); ++q) {
    const double xq[3] = {x[q].x, x[q].y, x[q].z}, vq[3] = {v[q].x, v[q].y, v[q].z}, m = e.mass(q);
    int b[dim];
    double w[dim][2];
    hybrid::tent<dim>(xq, g.x0, g.inv_h, b, w);
    if (!L.contains(b[0], b[1], dim == 3 ? b[2] : 0) || !L.contains(b[0] + 1, b[1] + 1, dim == 3 ? b[2] + 1 : 0)) {
      msg = "a DEM grain at x = " + std::to_string(xq[0]) + " lies outside its rank's ghosted grid: lower -dem_skin";
      break;
    }
    for (int c = 0; c < (dim == 3 ? 8 : 4); ++c) {
      const int o[3] = {c & 1, (c >> 1) & 1, (c >> 2) & 1};
      double wt = 1;
      for (int d = 0; d < dim; ++d) wt *= w[d][o[d]];
      double *n = L.at(b[0] + o[0], b[1] + o[1], dim == 3 ? b[2] + o[2] : 0);
      n[0] += wt * m;
      for (int d = 0; d < dim; ++d) n[1 + d] += wt * m * vq[d];
    }
  }
  GM_CALL(VecRestoreArray(loc_, &a));
  collective_fail(S.comm, !msg.empty(), msg);
  (void)NDOF;
  GM_CALL(VecZeroEntries(glob_));
  GM_CALL(DMLocalToGlobalBegin(g.da, loc_, ADD_VALUES, glob_));
  GM_CALL(DMLocalToGlobalEnd(g.da, loc_, ADD_VALUES, glob_));
  GM_CALL(VecGetArray(glob_, &ga_));
}

template <int dim>
void HybridModule<dim>::node(const NodeAt &n, double *v, double, bool) {
  if (!active_) return;
  const Grid<dim> &g = *grid_;
  const size_t idx = (size_t)Grid<dim>::NDOF * ((size_t)(n.k - g.xs[2]) * g.xm[1] * g.xm[0] + (size_t)(n.j - g.xs[1]) * g.xm[0] + (n.i - g.xs[0]));
  double *a = ga_ + idx;
  const double mD = a[0];
  if (!(mD > 0)) return;
  double pM[dim], lam[dim];
  for (int d = 0; d < dim; ++d) pM[d] = n.m * v[d];
  hybrid::constrain_node<dim>(n.m, pM, mD, a + 1, lam);
  for (int d = 0; d < dim; ++d) {
    v[d] = pM[d] / n.m;
    a[1 + dim + d] = lam[d];
    transferred_ += std::fabs(lam[d]);
  }
  ++constrained_;
}

template <int dim>
void HybridModule<dim>::end_grid(State<dim> &S, double, bool) {
  if (!active_) return;
  GM_CALL(VecRestoreArray(glob_, &ga_));
  ga_ = nullptr;
  GM_CALL(DMGlobalToLocalBegin(S.grid.da, glob_, INSERT_VALUES, loc_));
  GM_CALL(DMGlobalToLocalEnd(S.grid.da, glob_, INSERT_VALUES, loc_));
}

// The grains take the constraint's impulses: v_q += sum_i w_iq lambda_i / m_D,i.
template <int dim>
void HybridModule<dim>::end_step(State<dim> &S, double) {
  const Grid<dim> &g = S.grid;
  const PetscScalar *a;
  GM_CALL(VecGetArrayRead(loc_, &a));
  NodeView<dim> L;
  L.a = const_cast<PetscScalar *>(a);
  for (int d = 0; d < 3; ++d) {
    L.gs[d] = g.gxs[d];
    L.gm[d] = g.gxm[d];
  }
  dem::Engine &e = grains_.engine();
  const dem::V3 *x = e.positions();
  dem::V3 *v = e.velocities();
  for (long q = 0; q < e.owned(); ++q) {
    const double xq[3] = {x[q].x, x[q].y, x[q].z};
    int b[dim];
    double w[dim][2], dv[3] = {0, 0, 0};
    hybrid::tent<dim>(xq, g.x0, g.inv_h, b, w);
    for (int c = 0; c < (dim == 3 ? 8 : 4); ++c) {
      const int o[3] = {c & 1, (c >> 1) & 1, (c >> 2) & 1};
      double wt = 1;
      for (int d = 0; d < dim; ++d) wt *= w[d][o[d]];
      const double *n = L.at(b[0] + o[0], b[1] + o[1], dim == 3 ? b[2] + o[2] : 0);
      if (n[0] > 0)
        for (int d = 0; d < dim; ++d) dv[d] += wt * n[1 + dim + d] / n[0];
    }
    v[q].x += dv[0];
    v[q].y += dv[1];
    if (dim == 3) v[q].z += dv[2];
  }
  GM_CALL(VecRestoreArrayRead(loc_, &a));
  long nodes = constrained_;
  double lam = transferred_;
  MPI_Allreduce(MPI_IN_PLACE, &nodes, 1, MPI_LONG, MPI_SUM, S.comm);
  MPI_Allreduce(MPI_IN_PLACE, &lam, 1, MPI_DOUBLE, MPI_SUM, S.comm);
  char buf[200];
  std::snprintf(buf, sizeof buf, "hybrid coupling: band %c in [%g, %g] (w_M %g), %ld node constraints, sum |lambda| %.6g kg m/s", "xyz"[band_.axis], band_.lo, band_.hi,
                band_.band_weight, nodes, lam);
  summary_ = buf;
  ++steps_;
  if (oracle_.every > 0 && steps_ % oracle_.every == 0) update_zones(S);
}

template <int dim>
std::string HybridModule<dim>::summary() const {
  if (oracle_.every <= 0) return summary_;
  char buf[240];
  std::snprintf(buf, sizeof buf, "; zones (phi %g, band at %g +- %g m): %ld updates, material points C/B/D %ld/%ld/%ld, grains C/B/D %ld/%ld/%ld", oracle_.threshold,
                oracle_.rule.band_distance, oracle_.rule.half_width, zupdates_, zcount_[0], zcount_[1], zcount_[2], zcount_[3], zcount_[4], zcount_[5]);
  std::string out = summary_ + buf;
  if (oracle_.drive) {
    std::snprintf(buf, sizeof buf, "; shares from the zones: material points %ld changed, %ld removed (%+.6g kg), grains %ld changed, %ld removed (%+.6g kg)", shares_[0], shares_[1],
                  share_mass_[0], shares_[2], shares_[3], share_mass_[1]);
    out += buf;
  }
  return out;
}

template <int dim>
void HybridModule<dim>::set_oracle(State<dim> &S, const Oracle &o) {
  oracle_ = o;
  if (o.every <= 0) return;
  const Grid<dim> &g = S.grid;
  for (int d = 0; d < dim; ++d) {
    zgrid_.lo[d] = g.lo[d];
    zgrid_.n[d] = g.ncell[d];
  }
  zgrid_.h = g.h;
  if (o.drive && (S.particles.field_index(kWeight) < 0 || S.particles.field_index(kZone) < 0))
    throw std::logic_error("HybridModule: zone-driven shares need the hybrid_weight and hybrid_zone particle fields (hybrid_particle_fields)");
  if (S.cfg.restart.empty()) update_zones(S); // a restart reads them (read_checkpoint)
}

// Each rank rasterises its owned grains and marks the cells of its owned material points
// on the whole (replicated) cell grid; the sums over the ranks give every rank the same phi
// up to the order of the sums, and the same zones (2D: the cells of a few hundred thousand
// cells are cheap; the distance search is O(cells (band/h)^dim)).
template <int dim>
void HybridModule<dim>::update_zones(State<dim> &S) {
  const hybrid::CellGrid<dim> &G = zgrid_;
  dem::Engine &e = grains_.engine();
  std::vector<double> x((size_t)e.owned() * dim), r((size_t)e.owned());
  for (long q = 0; q < e.owned(); ++q) {
    const dem::V3 p = e.positions()[q];
    const double c[3] = {p.x, p.y, p.z};
    for (int d = 0; d < dim; ++d) x[(size_t)q * dim + d] = c[d];
    r[(size_t)q] = e.radius(q);
  }
  std::vector<double> phi = hybrid::packing_fraction<dim>(G, x, r), dense(phi.size(), 0.0), grain(phi.size(), 0.0);
  ParticleView<dim> P = S.particles.get();
  for (PetscInt p = 0; p < P.n; ++p) dense[(size_t)hybrid::cell_index<dim>(G, P.x + p * dim)] = 1.0;
  for (long q = 0; q < e.owned(); ++q) grain[(size_t)hybrid::cell_index<dim>(G, &x[(size_t)q * dim])] = 1.0;
  MPI_Allreduce(MPI_IN_PLACE, phi.data(), (int)phi.size(), MPI_DOUBLE, MPI_SUM, S.comm);
  MPI_Allreduce(MPI_IN_PLACE, dense.data(), (int)dense.size(), MPI_DOUBLE, MPI_MAX, S.comm);
  MPI_Allreduce(MPI_IN_PLACE, grain.data(), (int)grain.size(), MPI_DOUBLE, MPI_MAX, S.comm);
  zones_ = hybrid::oracle_zones<dim>(G, std::move(phi), dense, oracle_.threshold, oracle_.rule);
  for (long &c : zcount_) c = 0;
  for (PetscInt p = 0; p < P.n; ++p) ++zcount_[(int)zones_[(size_t)hybrid::cell_index<dim>(G, P.x + p * dim)]];
  S.particles.restore(P);
  for (long q = 0; q < e.owned(); ++q) ++zcount_[3 + (int)zones_[(size_t)hybrid::cell_index<dim>(G, &x[(size_t)q * dim])]];
  MPI_Allreduce(MPI_IN_PLACE, zcount_, 6, MPI_LONG, MPI_SUM, S.comm);
  ++zupdates_;
  has_mp_ = std::move(dense);
  has_grain_ = std::move(grain);
  if (oracle_.drive) apply_shares(S);
}

template <int dim>
hybrid::Zone HybridModule<dim>::zone_at(const double *x) const {
  return zones_[(size_t)hybrid::cell_index<dim>(zgrid_, x)];
}

// The shares follow the zones: w_M = 1 / band weight / 0 in C / band / D for a material
// point, w_D = 1 - w_M for a grain, except where the other species is absent from the cell
// (then the one present keeps all of its mass: nothing would carry the rest until a
// conversion creates it). A share of 0 means the other species carries all the mass there:
// the point or grain is removed. Mass and volume (grains: mass and inertia) scale with the
// share, velocities are kept. Deterministic: every rank has the same zones and presence
// maps, and each particle's share depends on its own cell only.
template <int dim>
void HybridModule<dim>::apply_shares(State<dim> &S) {
  const hybrid::CellGrid<dim> &G = zgrid_;
  long cnt[4] = {0, 0, 0, 0};
  double dm[2] = {0, 0};
  std::vector<PetscInt> gone;
  {
    ParticleView<dim> P = S.particles.get();
    double *W = P.field(S.particles.field_index(kWeight)), *Z = P.field(S.particles.field_index(kZone));
    for (PetscInt p = 0; p < P.n; ++p) {
      const double *x = P.x + p * dim;
      const hybrid::Zone z = zone_at(x);
      double w = hybrid::continuum_weight(z, oracle_.rule);
      if (w < 1 && !(has_grain_[(size_t)hybrid::cell_index<dim>(G, x)] > 0)) w = 1;
      Z[p] = (double)(int)z;
      if (w == W[p]) continue;
      const double m0 = P.m[p];
      if (!(w > 0)) {
        gone.push_back(p);
        dm[0] -= m0;
        ++cnt[1];
        continue;
      }
      const double f = w / W[p];
      P.m[p] *= f;
      P.vol[p] *= f;
      W[p] = w;
      dm[0] += P.m[p] - m0;
      ++cnt[0];
    }
    S.particles.restore(P);
  }
  for (auto it = gone.rbegin(); it != gone.rend(); ++it) GM_CALL(DMSwarmRemovePointAtIndex(S.particles.dm(), *it)); // the last point moves in: descending order
  dem::Engine &e = grains_.engine();
  std::vector<double> wq((size_t)e.owned());
  for (long q = 0; q < e.owned(); ++q) {
    const dem::V3 p = e.positions()[q];
    const double x[3] = {p.x, p.y, p.z};
    double w = 1.0 - hybrid::continuum_weight(zone_at(x), oracle_.rule);
    if (w < 1 && !(has_mp_[(size_t)hybrid::cell_index<dim>(G, x)] > 0)) w = 1;
    const double cur = e.mass_weight(q), full = e.mass(q) / cur;
    wq[(size_t)q] = w;
    if (w == cur) continue;
    dm[1] += (w - cur) * full;
    ++cnt[w > 0 ? 2 : 3];
  }
  MPI_Allreduce(MPI_IN_PLACE, cnt, 4, MPI_LONG, MPI_SUM, S.comm);
  MPI_Allreduce(MPI_IN_PLACE, dm, 2, MPI_DOUBLE, MPI_SUM, S.comm);
  if (cnt[2] + cnt[3] > 0) e.reweight(wq);
  for (int k = 0; k < 4; ++k) shares_[k] += cnt[k];
  share_mass_[0] += dm[0];
  share_mass_[1] += dm[1];
}

template <int dim>
void HybridModule<dim>::write_checkpoint(const State<dim> &S, CheckpointIO &io) const {
  if (oracle_.every <= 0) return;
  std::vector<double> a = {(double)zupdates_, (double)steps_};
  for (long c : zcount_) a.push_back((double)c);
  for (long c : shares_) a.push_back((double)c);
  a.push_back(share_mass_[0]);
  a.push_back(share_mass_[1]);
  io.write_attr("hybrid_oracle", a);
  // The zone map and presence maps of the last update (the same on every rank): rank 0 writes them.
  const long N = (long)zones_.size();
  std::vector<double> rows;
  for (long c = 0; c < N; ++c) {
    rows.push_back((double)(int)zones_[(size_t)c]);
    rows.push_back(has_mp_.empty() ? 0.0 : has_mp_[(size_t)c]);
    rows.push_back(has_grain_.empty() ? 0.0 : has_grain_[(size_t)c]);
  }
  const bool r0 = S.rank == 0;
  io.write_rows("hybrid_zones", rows.data(), r0 ? N : 0, r0 ? 0 : N, N, 3);
}

template <int dim>
void HybridModule<dim>::read_checkpoint(State<dim> &, CheckpointIO &io) {
  if (oracle_.every <= 0) return;
  if (!io.has_attr("hybrid_oracle")) io.bad("it has no zones of the hybrid oracle (written without -hybrid_zone_every): drop -hybrid_zone_every or restart from a run with it");
  const std::vector<double> a = io.read_attr("hybrid_oracle");
  if (a.size() != 14) io.bad("its hybrid_oracle attribute has " + std::to_string(a.size()) + " values instead of 14");
  zupdates_ = (long)a[0];
  steps_ = (long)a[1];
  for (int k = 0; k < 6; ++k) zcount_[k] = (long)a[2 + k];
  for (int k = 0; k < 4; ++k) shares_[k] = (long)a[8 + k];
  share_mass_[0] = a[12];
  share_mass_[1] = a[13];
  const long N = zgrid_.size();
  std::vector<double> rows((size_t)N * 3);
  io.read_all_rows("hybrid_zones", rows.data(), N, 3);
  zones_.resize((size_t)N);
  has_mp_.resize((size_t)N);
  has_grain_.resize((size_t)N);
  for (long c = 0; c < N; ++c) {
    zones_[(size_t)c] = (hybrid::Zone)(int)rows[(size_t)c * 3];
    has_mp_[(size_t)c] = rows[(size_t)c * 3 + 1];
    has_grain_[(size_t)c] = rows[(size_t)c * 3 + 2];
  }
}

namespace {

struct HybridOptions {
  PetscBool dem = PETSC_FALSE, band_set = PETSC_FALSE;
  PetscReal band[2] = {0, 0}, weight = 0.5;
  char axis[8] = "y", side[8] = "hi";
  PetscInt zone_every = 0;
  PetscReal phi = 0.3, band_distance = 0, half_width = 0;
  PetscBool hw_set = PETSC_FALSE; // without it: one MPM cell
};

PetscErrorCode read_hybrid_options(MPI_Comm comm, HybridOptions &o) {
  PetscFunctionBeginUser;
  PetscInt n = 2;
  PetscOptionsBegin(comm, NULL, "Hybrid continuum/discrete coupling (docs/hybrid.md)", NULL);
  PetscCall(PetscOptionsBool("-hybrid_dem", "Add the DEM grains of the -dem_* options (docs/dem.md) to this MPM run as a second species (docs/hybrid.md)", NULL, o.dem, &o.dem, NULL));
  PetscCall(PetscOptionsRealArray("-hybrid_band", "Couple the grains and the material points in a fixed band lo,hi along -hybrid_band_axis (needs -hybrid_dem)", NULL, o.band, &n, &o.band_set));
  PetscCall(PetscOptionsString("-hybrid_band_axis", "Axis across the fixed band (x|y|z)", NULL, o.axis, o.axis, sizeof o.axis, NULL));
  PetscCall(PetscOptionsString("-hybrid_continuum", "Side of the band with the continuum zone (lo|hi); the discrete zone is the other", NULL, o.side, o.side, sizeof o.side, NULL));
  PetscCall(PetscOptionsReal("-hybrid_band_weight", "Continuum share w_M of the mass in the band, in [0, 1] (grains: 1 - w_M)", NULL, o.weight, &o.weight, NULL));
  PetscCall(PetscOptionsInt("-hybrid_zone_every", "Recompute the oracle's zones every N MPM steps (0: off; needs -hybrid_band; reported in the summary)", NULL, o.zone_every, &o.zone_every, NULL));
  PetscCall(PetscOptionsReal("-hybrid_phi", "Oracle: packing fraction of the dense contour, in (0, 1]", NULL, o.phi, &o.phi, NULL));
  PetscCall(PetscOptionsReal("-hybrid_band_distance", "Oracle: distance of the band's centre inside the dense contour (m)", NULL, o.band_distance, &o.band_distance, NULL));
  PetscCall(PetscOptionsReal("-hybrid_band_halfwidth", "Oracle: half-width of the band (m; default one MPM cell)", NULL, o.half_width, &o.half_width, &o.hw_set));
  PetscOptionsEnd();
  if (o.band_set && n != 2) o.band[0] = o.band[1] = NAN; // band_of reports it
  PetscFunctionReturn(0);
}

hybrid::FixedBand band_of(const HybridOptions &o, const Config &c, int dim) {
  hybrid::FixedBand b;
  if (!(std::strlen(o.axis) == 1 && o.axis[0] >= 'x' && o.axis[0] < 'x' + dim))
    throw UserError(std::string("-hybrid_band_axis '") + o.axis + "': use one of " + (dim == 3 ? "x, y, z" : "x, y"));
  b.axis = o.axis[0] - 'x';
  if (std::strcmp(o.side, "lo") && std::strcmp(o.side, "hi")) throw UserError(std::string("-hybrid_continuum '") + o.side + "': use lo or hi");
  b.continuum_hi = !std::strcmp(o.side, "hi");
  b.lo = o.band[0];
  b.hi = o.band[1];
  b.band_weight = o.weight;
  if (!(b.band_weight >= 0 && b.band_weight <= 1)) throw UserError("-hybrid_band_weight must be in [0, 1] (got " + std::to_string(b.band_weight) + ")");
  const double L0 = c.lo[b.axis], L1 = c.hi[b.axis];
  if (!(b.hi > b.lo)) throw UserError("-hybrid_band needs two values lo,hi with lo < hi");
  if (!(b.lo > L0 && b.hi < L1))
    throw UserError("-hybrid_band [" + std::to_string(b.lo) + ", " + std::to_string(b.hi) + "] must lie strictly inside the domain along " + o.axis + " (" +
                    std::to_string(L0) + ", " + std::to_string(L1) + "): narrow the band or move it");
  return b;
}

} // namespace

template <int dim>
std::vector<std::unique_ptr<Module<dim>>> grain_modules(State<dim> &S) {
  std::vector<std::unique_ptr<Module<dim>>> out;
  HybridOptions o;
  GM_CALL(read_hybrid_options(S.comm, o));
  if (o.zone_every < 0) throw UserError("-hybrid_zone_every must be >= 0 (got " + std::to_string((long)o.zone_every) + ")");
  if (!(o.phi > 0 && o.phi <= 1)) throw UserError("-hybrid_phi must be in (0, 1] (got " + std::to_string(o.phi) + ")");
  if (!std::isfinite(o.band_distance)) throw UserError("-hybrid_band_distance must be a finite distance in m");
  if (!(o.half_width >= 0 && std::isfinite(o.half_width)))
    throw UserError("-hybrid_band_halfwidth must be >= 0 (got " + std::to_string(o.half_width) + ")");
  if (o.zone_every > 0 && !o.band_set) throw UserError("-hybrid_zone_every computes zones for the coupling: add -hybrid_dem and -hybrid_band");
  if (!o.dem) {
    if (o.band_set) throw UserError("-hybrid_band couples the DEM grains: add -hybrid_dem (and the -dem_* options)");
    return out;
  }
  dem::Config dc = dem_module_config<dim>(S);
  if (!o.band_set) {
    out.push_back(std::make_unique<DemModule<dim>>(S, dc));
    return out;
  }
  auto out2 = hybrid_modules<dim>(S, dc, band_of(o, S.cfg, dim));
  typename HybridModule<dim>::Oracle z;
  z.every = (int)o.zone_every;
  z.threshold = o.phi;
  z.rule.band_distance = o.band_distance;
  z.rule.half_width = o.hw_set ? o.half_width : S.grid.h;
  z.rule.band_weight = o.weight;
  z.drive = true;
  static_cast<HybridModule<dim> &>(*out2.back()).set_oracle(S, z);
  return out2;
}

template <int dim>
std::vector<std::unique_ptr<Module<dim>>> hybrid_modules(State<dim> &S, dem::Config dc, const hybrid::FixedBand &band) {
  std::vector<std::unique_ptr<Module<dim>>> out;
  const double rmax = dc.radius * (dc.dist == dem::RadiusDist::Mono ? 1.0 : dc.dist == dem::RadiusDist::Uniform ? 1 + dc.spread : 1 + 2 * dc.spread);
  if (2 * rmax > S.grid.h)
    throw UserError("-dem_radius: the largest grain diameter " + std::to_string(2 * rmax) + " exceeds the MPM cell h = " + std::to_string(S.grid.h) +
                    " (the coupling rasterises grains to the grid): use smaller grains or coarser -cells");
  if (S.cfg.restart.empty()) HybridModule<dim>::split_particles(S, band);
  dc.mass_weight = [band](const double *x) { return 1.0 - band.continuum_weight(x); };
  dc.mass_weight_min = band.band_weight < 1 ? 1.0 - band.band_weight : 1.0; // band grains are the lightest
  auto d = std::make_unique<DemModule<dim>>(S, dc);
  auto h = std::make_unique<HybridModule<dim>>(S, *d, band);
  out.push_back(std::move(d));
  out.push_back(std::move(h));
  return out;
}

std::vector<std::pair<std::string, int>> hybrid_particle_fields(MPI_Comm comm) {
  (void)comm; // the options are read (and registered for -help) by grain_modules
  PetscBool dem = PETSC_FALSE, band = PETSC_FALSE;
  GM_CALL(PetscOptionsGetBool(NULL, NULL, "-hybrid_dem", &dem, NULL));
  GM_CALL(PetscOptionsHasName(NULL, NULL, "-hybrid_band", &band));
  if (!dem || !band) return {};
  return {{kWeight, 1}, {kZone, 1}};
}

template class HybridModule<2>;
template class HybridModule<3>;
template std::vector<std::unique_ptr<Module<2>>> grain_modules(State<2> &);
template std::vector<std::unique_ptr<Module<3>>> grain_modules(State<3> &);
template std::vector<std::unique_ptr<Module<2>>> hybrid_modules(State<2> &, dem::Config, const hybrid::FixedBand &);
template std::vector<std::unique_ptr<Module<3>>> hybrid_modules(State<3> &, dem::Config, const hybrid::FixedBand &);

} // namespace granmpm
