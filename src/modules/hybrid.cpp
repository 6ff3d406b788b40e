// HybridModule: the continuum/discrete coupling with a fixed band (hybrid/module.hpp).
#include "granmpm/hybrid/module.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "granmpm/checkpoint.hpp"
#include "granmpm/cpu_time.hpp"

#include <array>

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
  const double c0 = process_cpu_seconds();
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
  cpu_couple_ += process_cpu_seconds() - c0;
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
  const double c0 = process_cpu_seconds();
  GM_CALL(VecRestoreArray(glob_, &ga_));
  ga_ = nullptr;
  GM_CALL(DMGlobalToLocalBegin(S.grid.da, glob_, INSERT_VALUES, loc_));
  GM_CALL(DMGlobalToLocalEnd(S.grid.da, glob_, INSERT_VALUES, loc_));
  cpu_couple_ += process_cpu_seconds() - c0;
}

// The grains take the constraint's impulses: v_q += sum_i w_iq lambda_i / m_D,i.
template <int dim>
void HybridModule<dim>::end_step(State<dim> &S, double dt) {
  const double c0 = process_cpu_seconds();
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
  const double c1 = process_cpu_seconds();
  cpu_couple_ += c1 - c0;
  if (oracle_.every > 0 && steps_ % oracle_.every == 0) {
    update_zones(S);
    cpu_zones_ += process_cpu_seconds() - c1;
  }
  // The grains' snapshot after their FLIP update and the zone update: the state the material
  // points' snapshot of this step shows.
  grains_.snapshot_if_due(S, dt);
}

template <int dim>
std::string HybridModule<dim>::summary() const {
  char cpu[160];
  std::snprintf(cpu, sizeof cpu, "; CPU of rank 0's process: %.3g s in the coupling (grains to the grid, ghosts, FLIP update), %.3g s in the zone updates", cpu_couple_, cpu_zones_);
  if (oracle_.every <= 0) return summary_ + cpu;
  char buf[400];
  std::snprintf(buf, sizeof buf, "; zones (phi %g, band at %g +- %g m): %ld updates, material points C/B/D %ld/%ld/%ld, grains C/B/D %ld/%ld/%ld", oracle_.threshold,
                oracle_.rule.band_distance, oracle_.rule.half_width, zupdates_, zcount_[0], zcount_[1], zcount_[2], zcount_[3], zcount_[4], zcount_[5]);
  std::string out = summary_ + buf;
  if (oracle_.drive) {
    std::snprintf(buf, sizeof buf,
                  "; shares from the zones (mass handed over): %.6g kg material points -> grains, %.6g kg grains -> material points; %ld material points and %ld grains changed, %ld "
                  "and %ld gave all their mass and were removed; mass balance of the zone updates %+.3g kg",
                  share_mass_[0], share_mass_[1], shares_[0], shares_[2], shares_[1], shares_[3], balance_);
    out += buf;
  }
  if (oracle_.drive && oracle_.homogenise) {
    std::snprintf(buf, sizeof buf, "; homogenised %ld grains (%.6g kg) into material points", homog_, homog_m_);
    out += buf;
  }
  if (oracle_.drive && oracle_.enrich) {
    std::snprintf(buf, sizeof buf, "; enriched %ld material points (%.6g kg) into %ld grains (%ld cells next to grains; %ld cells in part, %ld points kept the rest), %ld cells skipped",
                  enr_[1], enr_m_, enr_[0], enr_[5], enr_[4], enr_[3], enr_[2]);
    out += buf;
  }
  return out + cpu;
}

template <int dim>
void HybridModule<dim>::set_oracle(State<dim> &S, const Oracle &o) {
  oracle_ = o;
  if (o.every <= 0) return;
  const Grid<dim> &g = S.grid;
  for (int d = 0; d < dim; ++d) {
    zgrid_.lo[d] = g.lo[d];
    zgrid_.n[d] = g.ncell[d];
    zgrid_.periodic[d] = g.periodic[d];
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
  prev_ = std::move(zones_);
  phi_ = phi;
  zones_ = hybrid::oracle_zones<dim>(G, std::move(phi), dense, oracle_.threshold, oracle_.rule);
  for (long &c : zcount_) c = 0;
  for (PetscInt p = 0; p < P.n; ++p) ++zcount_[(int)zones_[(size_t)hybrid::cell_index<dim>(G, P.x + p * dim)]];
  S.particles.restore(P);
  for (long q = 0; q < e.owned(); ++q) ++zcount_[3 + (int)zones_[(size_t)hybrid::cell_index<dim>(G, &x[(size_t)q * dim])]];
  MPI_Allreduce(MPI_IN_PLACE, zcount_, 6, MPI_LONG, MPI_SUM, S.comm);
  ++zupdates_;
  has_mp_ = std::move(dense);
  has_grain_ = std::move(grain);
  if (!oracle_.drive) return;
  // Every change below hands mass from one species to the other: the total before and
  // after must agree to round-off, or a conversion lost (or made) mass, which is a bug.
  const double m0 = total_mass(S);
  apply_shares(S);
  if (oracle_.homogenise) homogenise(S);
  if (oracle_.enrich) enrich(S);
  const double m1 = total_mass(S), dm = m1 - m0;
  balance_ += dm;
  if (std::fabs(dm) > 1e-11 * std::fabs(m0))
    throw std::logic_error("HybridModule: the zone update at step " + std::to_string(steps_) + " changed the total mass from " + std::to_string(m0) + " to " +
                           std::to_string(m1) + " kg (conversions must hand mass over, not remove it)");
}

// Material points and grains, each with its carried mass, over all ranks, plus the mass of
// the grains that left through outlets: the grains' rebuild after reweight removes those
// that crossed an outlet face since the last one (a silo's jet), which is outflow, not a
// conversion's loss.
template <int dim>
double HybridModule<dim>::total_mass(State<dim> &S) {
  double m = 0;
  ParticleView<dim> P = S.particles.get();
  for (PetscInt p = 0; p < P.n; ++p) m += P.m[p];
  S.particles.restore(P);
  dem::Engine &e = grains_.engine();
  for (long q = 0; q < e.owned(); ++q) m += e.mass(q);
  MPI_Allreduce(MPI_IN_PLACE, &m, 1, MPI_DOUBLE, MPI_SUM, S.comm);
  return m + e.summary().removed_mass;
}

template <int dim>
void HybridModule<dim>::enrich(State<dim> &S) {
  const hybrid::CellGrid<dim> &G = zgrid_;
  if (prev_.size() != zones_.size()) return;
  const int nnb = dim == 3 ? 27 : 9;
  auto coords = [&](long c, int ci[dim]) {
    for (int d = 0; d < dim; ++d) {
      ci[d] = (int)(c % G.n[d]);
      c /= G.n[d];
    }
  };
  // The o-th of the 3^dim cells around ci (itself included); -1 outside the grid.
  auto neighbour = [&](const int ci[dim], int o) {
    int q[dim];
    for (int d = 0, oo = o; d < dim; ++d, oo /= 3) {
      q[d] = G.wrap(ci[d] + oo % 3 - 1, d);
      if (q[d] < 0 || q[d] >= G.n[d]) return -1L;
    }
    return G.index(q);
  };
  // The cells to convert: discrete at this update and the one before, with material points.
  std::vector<long> slot((size_t)G.size(), -1), cells;
  std::vector<char> near((size_t)G.size(), 0); // cells whose grains may reach into a converted cell
  bool any_near = false;
  for (long c = 0; c < G.size(); ++c)
    if (zones_[(size_t)c] == hybrid::Zone::Discrete && prev_[(size_t)c] == hybrid::Zone::Discrete && has_mp_[(size_t)c] > 0) {
      slot[(size_t)c] = (long)cells.size();
      cells.push_back(c);
      int ci[dim];
      coords(c, ci);
      for (int o = 0; o < nnb; ++o) {
        const long q = neighbour(ci, o);
        if (q >= 0 && has_grain_[(size_t)q] > 0) near[(size_t)q] = 1, any_near = true;
      }
    }
  if (cells.empty()) return;
  // The grains in those cells (a grain centred farther away is at least h from the cell and
  // r_old + r_new <= h: it cannot overlap a new one), from every rank: (x, r) per grain.
  dem::Engine &e = grains_.engine();
  std::vector<double> gx, gr;
  std::vector<long> gcell;
  if (any_near) {
    std::vector<double> mine;
    const dem::V3 *X = e.positions();
    for (long q = 0; q < e.owned(); ++q) {
      const double xq[3] = {X[q].x, X[q].y, X[q].z};
      const long c = hybrid::cell_index<dim>(G, xq);
      if (!near[(size_t)c]) continue;
      for (int d = 0; d < dim; ++d) mine.push_back(xq[d]);
      mine.push_back(e.radius(q));
    }
    int cnt = (int)mine.size(), nr = 1;
    MPI_Comm_size(S.comm, &nr);
    std::vector<int> counts((size_t)nr), offs((size_t)nr, 0);
    MPI_Allgather(&cnt, 1, MPI_INT, counts.data(), 1, MPI_INT, S.comm);
    for (int k = 1; k < nr; ++k) offs[(size_t)k] = offs[(size_t)k - 1] + counts[(size_t)k - 1];
    std::vector<double> all((size_t)(offs.back() + counts.back()));
    MPI_Allgatherv(mine.data(), cnt, MPI_DOUBLE, all.data(), counts.data(), offs.data(), MPI_DOUBLE, S.comm);
    for (size_t i = 0; i < all.size(); i += dim + 1) {
      gx.insert(gx.end(), &all[i], &all[i] + dim);
      gr.push_back(all[i + dim]);
      gcell.push_back(hybrid::cell_index<dim>(G, &all[i]));
    }
  }
  std::vector<std::vector<long>> by_cell(any_near ? (size_t)G.size() : 0);
  for (size_t i = 0; i < gr.size(); ++i) by_cell[(size_t)gcell[i]].push_back((long)i);
  const size_t nc = cells.size(), stride = 1 + dim;
  std::vector<double> mp(nc * stride, 0.0); // per cell: M, P
  std::vector<PetscInt> mine;               // local points in the cells
  {
    ParticleView<dim> P = S.particles.get();
    for (PetscInt p = 0; p < P.n; ++p) {
      const long sl = slot[(size_t)hybrid::cell_index<dim>(G, P.x + p * dim)];
      if (sl < 0) continue;
      mine.push_back(p);
      mp[(size_t)sl * stride] += P.m[p];
      for (int d = 0; d < dim; ++d) mp[(size_t)sl * stride + 1 + d] += P.m[p] * P.v[p * dim + d];
    }
    S.particles.restore(P);
  }
  MPI_Allreduce(MPI_IN_PLACE, mp.data(), (int)mp.size(), MPI_DOUBLE, MPI_SUM, S.comm);
  const dem::Config &dc = e.config();
  const double rho = dc.density;
  // The lightest grain the DEM's time step assumed: the distribution's smallest radius at the
  // lightest share.
  const double spread = dc.dist == dem::RadiusDist::Uniform ? dc.spread : dc.dist == dem::RadiusDist::Normal ? 2 * dc.spread : 0.0;
  const double r_lo = dc.radius * (1 - spread) * std::pow(dc.mass_weight_min, 1.0 / dim);
  std::vector<double> keep(nc, 1.0); // per cell: the share of its points' mass they keep (0: all converted, the points go)
  std::vector<dem::GrainRecord> add;
  long made = 0, skipped = 0, partial = 0, beside = 0;
  double mass = 0;
  for (size_t k = 0; k < nc; ++k) {
    const double M = mp[k * stride];
    int ci[dim];
    coords(cells[k], ci);
    std::vector<double> xe, re;
    if (any_near)
      for (int o = 0; o < nnb; ++o) {
        const long q = neighbour(ci, o);
        if (q >= 0)
          for (long i : by_cell[(size_t)q]) {
            xe.insert(xe.end(), &gx[(size_t)i * dim], &gx[(size_t)i * dim] + dim);
            re.push_back(gr[(size_t)i]);
          }
      }
    const hybrid::EnrichPlan plan = hybrid::enrich_cell<dim>(G, ci, M, dc.radius, r_lo, rho, dc.overlap_tol, xe, re);
    const long n = (long)plan.x.size() / dim;
    if (n == 0) {
      ++skipped;
      continue;
    }
    const double r = plan.r, mg = dim == 3 ? rho * 4.0 / 3.0 * M_PI * r * r * r : rho * M_PI * r * r; // the engine's own expression (share exactly 1)
    // All of M (n grains of M / n to round-off) or, in part, n m(r0) of it.
    keep[k] = plan.partial ? 1.0 - n * mg / M : 0.0;
    partial += plan.partial;
    beside += !re.empty();
    made += n;
    mass += plan.partial ? n * mg : M;
    double centre[3] = {0, 0, 0};
    for (int d = 0; d < dim; ++d) centre[d] = G.lo[d] + (ci[d] + 0.5) * G.h;
    if (S.grid.owner_rank(centre) != S.rank) continue; // the cell's owner creates its grains
    for (long j = 0; j < n; ++j) {
      dem::GrainRecord g{};
      g.id = kEnrichedId + (zupdates_ * G.size() + cells[k]) * 4096 + j;
      for (int d = 0; d < dim; ++d) {
        g.x[d] = plan.x[(size_t)j * dim + d];
        g.v[d] = mp[k * stride + 1 + d] / M;
      }
      g.r = r;
      g.m = mg;
      add.push_back(g);
    }
  }
  // The points of the converted cells go (descending: the last point moves in), those of the
  // cells converted in part keep the rest of their mass (and volume, share) with their velocity:
  // the grains took the cell's mean velocity with their mass, so the momentum is conserved.
  {
    std::vector<PetscInt> gone;
    long cut = 0;
    ParticleView<dim> P = S.particles.get();
    double *W = P.field(S.particles.field_index(kWeight));
    for (PetscInt p : mine) {
      const double f = keep[(size_t)slot[(size_t)hybrid::cell_index<dim>(G, P.x + p * dim)]];
      if (f == 0.0) {
        gone.push_back(p);
      } else if (f < 1.0) {
        P.m[p] *= f;
        P.vol[p] *= f;
        if (W) W[p] *= f;
        ++cut;
      }
    }
    S.particles.restore(P);
    long ng[2] = {(long)gone.size(), cut};
    for (auto it = gone.rbegin(); it != gone.rend(); ++it) GM_CALL(DMSwarmRemovePointAtIndex(S.particles.dm(), *it));
    MPI_Allreduce(MPI_IN_PLACE, ng, 2, MPI_LONG, MPI_SUM, S.comm);
    enr_[1] += ng[0];
    enr_[3] += ng[1];
  }
  if (made > 0) e.add_grains(add);
  enr_[0] += made;
  enr_[2] += skipped;
  enr_[4] += partial;
  enr_[5] += beside;
  enr_m_ += mass;
}

template <int dim>
void HybridModule<dim>::homogenise(State<dim> &S) {
  const hybrid::CellGrid<dim> &G = zgrid_;
  if (prev_.size() != zones_.size()) return; // the first update: no region has been continuum for a whole update yet
  // The cells to convert (the same list on every rank: the maps are replicated).
  std::vector<long> slot((size_t)G.size(), -1);
  long nc = 0;
  for (long c = 0; c < G.size(); ++c)
    if (zones_[(size_t)c] == hybrid::Zone::Continuum && prev_[(size_t)c] == hybrid::Zone::Continuum && !(has_mp_[(size_t)c] > 0) && has_grain_[(size_t)c] > 0) slot[(size_t)c] = nc++;
  if (nc == 0) return;
  dem::Engine &e = grains_.engine();
  std::vector<long> conv; // owned grains to convert
  std::vector<long> cell;
  for (long q = 0; q < e.owned(); ++q) {
    const dem::V3 p = e.positions()[q];
    const double x[3] = {p.x, p.y, p.z};
    const long c = hybrid::cell_index<dim>(G, x);
    if (slot[(size_t)c] < 0) continue;
    conv.push_back(q);
    cell.push_back(c);
  }
  // Each cell's stress: the contact dipoles of its grains (on whichever rank) over its volume.
  std::vector<double> sig((size_t)nc * 6, 0.0);
  const std::vector<std::array<double, 6>> D = e.dipoles();
  for (size_t k = 0; k < conv.size(); ++k)
    for (int a = 0; a < 6; ++a) sig[(size_t)slot[(size_t)cell[k]] * 6 + a] += D[(size_t)conv[k]][a];
  MPI_Allreduce(MPI_IN_PLACE, sig.data(), (int)sig.size(), MPI_DOUBLE, MPI_SUM, S.comm);
  const double Vc = std::pow(G.h, dim), rho_g = e.config().density;
  // New material points at the end of this rank's swarm, then the grains go.
  PetscInt n0;
  GM_CALL(DMSwarmGetLocalSize(S.particles.dm(), &n0));
  if (!conv.empty()) GM_CALL(DMSwarmAddNPoints(S.particles.dm(), (PetscInt)conv.size()));
  double m_loc = 0;
  {
    ParticleView<dim> P = S.particles.get();
    const auto &opt = S.particles.optional_fields();
    const int fw = S.particles.field_index(kWeight);
    for (size_t k = 0; k < conv.size(); ++k) {
      const long q = conv[k];
      const PetscInt p = n0 + (PetscInt)k;
      const dem::V3 xq = e.positions()[q], J = e.pending_impulse(q), vq = e.velocities()[q] + (1.0 / e.mass(q)) * J; // with its pending half kick (apply_shares)
      const double xs[3] = {xq.x, xq.y, xq.z}, vs[3] = {vq.x, vq.y, vq.z}, m = e.mass(q);
      for (int d = 0; d < dim; ++d) {
        P.x[p * dim + d] = xs[d];
        P.v[p * dim + d] = vs[d];
      }
      P.m[p] = m;
      P.vol[p] = m / (e.mass_weight(q) * rho_g * phi_[(size_t)cell[k]]); // the grain's volume over phi
      const double *sc = &sig[(size_t)slot[(size_t)cell[k]] * 6];
      for (int a = 0; a < 6; ++a) P.s[6 * p + a] = sc[a] / Vc;
      if (dim == 2) P.s[6 * p + 2] = 0.5 * (sc[0] + sc[1]) / Vc; // out of plane: the in-plane mean (plane strain)
      P.id[p] = kConvertedId + e.id(q);
      for (size_t i = 0; i < opt.size(); ++i) { // a fresh material state: zero, F = Fp = identity
        double *f = P.opt[i] + (size_t)p * opt[i].second;
        for (int a = 0; a < opt[i].second; ++a) f[a] = 0;
        if ((opt[i].first == "F" || opt[i].first == "Fp") && opt[i].second == 9) f[0] = f[4] = f[8] = 1;
      }
      P.opt[fw][p] = 1; // hybrid_weight; hybrid_zone stays 0 (continuum)
      m_loc += m;
    }
    S.particles.restore(P);
  }
  if (!conv.empty()) {
    PetscInt *rank;
    GM_CALL(DMSwarmGetField(S.particles.dm(), "DMSwarm_rank", NULL, NULL, (void **)&rank));
    for (size_t k = 0; k < conv.size(); ++k) rank[n0 + (PetscInt)k] = S.rank;
    GM_CALL(DMSwarmRestoreField(S.particles.dm(), "DMSwarm_rank", NULL, NULL, (void **)&rank));
  }
  std::vector<double> w((size_t)e.owned());
  for (long q = 0; q < e.owned(); ++q) w[(size_t)q] = e.mass_weight(q);
  for (long q : conv) w[(size_t)q] = 0;
  long n = (long)conv.size();
  MPI_Allreduce(MPI_IN_PLACE, &n, 1, MPI_LONG, MPI_SUM, S.comm);
  MPI_Allreduce(MPI_IN_PLACE, &m_loc, 1, MPI_DOUBLE, MPI_SUM, S.comm);
  if (n > 0) e.reweight(w);
  homog_ += n;
  homog_m_ += m_loc;
}

template <int dim>
hybrid::Zone HybridModule<dim>::zone_at(const double *x) const {
  return zones_[(size_t)hybrid::cell_index<dim>(zgrid_, x)];
}

// The shares follow the zones by handing mass over, never by creating or deleting it: a
// cell's target shares are w_M = 1 / band weight / 0 in C / band / D for its material
// points and w_D = 1 - w_M for its grains. Per cell, the particles above their target
// (donors) give mass to those of the other species below theirs (receivers), with the
// linear momentum it carries (the donors keep their velocity; each receiver's velocity
// becomes the mass-weighted mean of its own and the handed mass's), so the cell's mass and
// momentum are unchanged to round-off. Where the other species is absent nothing changes
// (the earlier rule raised the share to 1 there and created mass, and removed points at
// share 0 whose mass no grain took: 58% of a zoned collapse's mass was lost that way).
//  - material points -> grains: min(what the points give, what the grains can take up to
//    their target share, at most 1: a grain never carries more than its solid mass); a
//    point whose share reaches 0 having given all of it is removed (its mass is in the
//    grains); otherwise the points keep the rest (enrichment or a later update takes it);
//  - grains -> material points (only in cells where no point gives): the grains go to their
//    target share exactly (a grain's share stays 0 or >= -hybrid's lightest weight, which
//    the DEM time step assumed; share 0: removed), the points take it up to their target
//    share and, beyond it, in proportion to their mass (a point's volume grows with its
//    mass: the continuum's density is kept).
// Deterministic: the per-cell sums are reduced over the ranks and each particle's change
// depends on its own values and its cell's sums only.
template <int dim>
void HybridModule<dim>::apply_shares(State<dim> &S) {
  const hybrid::CellGrid<dim> &G = zgrid_;
  const size_t N = (size_t)G.size();
  dem::Engine &e = grains_.engine();
  const long ng = e.owned();
  // Pass 1, per cell: [0] points' give, [1] points' room (to target), [2] grains' give,
  // [3] grains' room, [4] the points' mass.
  std::vector<double> c1(N * 5, 0.0);
  std::vector<long> pcell, gcell((size_t)ng);
  std::vector<double> pgive, grecv((size_t)ng, 0.0), ggive((size_t)ng, 0.0), gtarget((size_t)ng);
  {
    ParticleView<dim> P = S.particles.get();
    double *W = P.field(S.particles.field_index(kWeight)), *Z = P.field(S.particles.field_index(kZone));
    pcell.resize((size_t)P.n);
    pgive.assign((size_t)P.n, 0.0); // > 0: gives; < 0: room
    for (PetscInt p = 0; p < P.n; ++p) {
      const double *x = P.x + p * dim;
      const long c = hybrid::cell_index<dim>(G, x);
      const hybrid::Zone z = zones_[(size_t)c];
      const double w = hybrid::continuum_weight(z, oracle_.rule);
      Z[p] = (double)(int)z;
      pcell[(size_t)p] = c;
      // m - w (m / W): the mass above (> 0) or below (< 0) the target share; exactly m at w = 0.
      const double d = w == 0 ? P.m[p] : P.m[p] - w * (P.m[p] / W[p]);
      pgive[(size_t)p] = d;
      if (d > 0) c1[(size_t)c * 5] += d;
      else c1[(size_t)c * 5 + 1] -= d;
      c1[(size_t)c * 5 + 4] += P.m[p];
    }
    S.particles.restore(P);
  }
  for (long q = 0; q < ng; ++q) {
    const dem::V3 p = e.positions()[q];
    const double x[3] = {p.x, p.y, p.z};
    const long c = hybrid::cell_index<dim>(G, x);
    gcell[(size_t)q] = c;
    const double w = 1.0 - hybrid::continuum_weight(zones_[(size_t)c], oracle_.rule), cur = e.mass_weight(q), m = e.mass(q);
    gtarget[(size_t)q] = w;
    if (cur > w) {
      ggive[(size_t)q] = w == 0 ? m : m - w * (m / cur);
      c1[(size_t)c * 5 + 2] += ggive[(size_t)q];
    } else if (cur < w) {
      grecv[(size_t)q] = w * (m / cur) - m;
      c1[(size_t)c * 5 + 3] += grecv[(size_t)q];
    }
  }
  MPI_Allreduce(MPI_IN_PLACE, c1.data(), (int)c1.size(), MPI_DOUBLE, MPI_SUM, S.comm);
  // Which way each cell hands over (the same on every rank): the points' fraction given,
  // and whether the grains give.
  std::vector<double> fM(N, 0.0);
  std::vector<char> dgive(N, 0);
  for (size_t c = 0; c < N; ++c) {
    const double *a = &c1[c * 5];
    if (a[0] > 0 && a[3] > 0) fM[c] = a[0] <= a[3] ? 1.0 : a[3] / a[0];
    else if (a[2] > 0 && a[4] > 0) dgive[c] = 1;
  }
  // Pass 2: the donors give; per cell the handed mass and momentum, [0..dim] points -> grains,
  // [1+dim..2+2dim) grains -> points.
  const size_t st = 2 + 2 * dim;
  std::vector<double> c2(N * st, 0.0);
  long cnt[4] = {0, 0, 0, 0};
  std::vector<PetscInt> gone;
  {
    ParticleView<dim> P = S.particles.get();
    double *W = P.field(S.particles.field_index(kWeight));
    for (PetscInt p = 0; p < P.n; ++p) {
      const size_t c = (size_t)pcell[(size_t)p];
      const double d = pgive[(size_t)p];
      if (!(d > 0) || !(fM[c] > 0)) continue;
      const double give = fM[c] == 1.0 ? d : d * fM[c];
      double *a = &c2[c * st];
      a[0] += give;
      for (int k = 0; k < dim; ++k) a[1 + k] += give * P.v[p * dim + k];
      if (fM[c] == 1.0 && give == P.m[p]) { // all of it (share 0): the point goes
        gone.push_back(p);
        ++cnt[1];
        continue;
      }
      const double f = (P.m[p] - give) / P.m[p];
      P.m[p] -= give;
      P.vol[p] *= f;
      W[p] *= f;
      ++cnt[0];
    }
    S.particles.restore(P);
  }
  dem::V3 *gv = e.velocities();
  std::vector<double> wq((size_t)ng);
  for (long q = 0; q < ng; ++q) {
    wq[(size_t)q] = e.mass_weight(q);
    const size_t c = (size_t)gcell[(size_t)q];
    if (!dgive[c] || !(ggive[(size_t)q] > 0)) continue;
    const double give = ggive[(size_t)q], v[3] = {gv[q].x, gv[q].y, gv[q].z};
    // A grain that goes takes the impulse of its pending half kick along (its partners take the opposite one).
    const dem::V3 J = gtarget[(size_t)q] > 0 ? dem::V3{0, 0, 0} : e.pending_impulse(q);
    const double j[3] = {J.x, J.y, J.z};
    double *a = &c2[c * st + 1 + dim];
    a[0] += give;
    for (int k = 0; k < dim; ++k) a[1 + k] += give * v[k] + j[k];
    wq[(size_t)q] = gtarget[(size_t)q];
    ++cnt[gtarget[(size_t)q] > 0 ? 2 : 3];
  }
  MPI_Allreduce(MPI_IN_PLACE, c2.data(), (int)c2.size(), MPI_DOUBLE, MPI_SUM, S.comm);
  // Pass 3: the receivers take the handed mass and momentum of their cell.
  double moved[2] = {0, 0}; // the handed mass over all cells (c2 is reduced): points -> grains, grains -> points
  for (size_t c = 0; c < N; ++c) {
    moved[0] += c2[c * st];
    moved[1] += c2[c * st + 1 + dim];
  }
  for (long q = 0; q < ng; ++q) {
    const size_t c = (size_t)gcell[(size_t)q];
    const double *a = &c2[c * st];
    if (!(fM[c] > 0) || !(grecv[(size_t)q] > 0) || !(a[0] > 0)) continue;
    const double take = grecv[(size_t)q] * (a[0] / c1[c * 5 + 3]), m = e.mass(q), cur = e.mass_weight(q);
    const double mn = m + take, v[3] = {gv[q].x, gv[q].y, gv[q].z};
    double vn[3] = {0, 0, 0};
    for (int k = 0; k < dim; ++k) vn[k] = (m * v[k] + take * (a[1 + k] / a[0])) / mn;
    gv[q].x = vn[0];
    gv[q].y = vn[1];
    if (dim == 3) gv[q].z = vn[2];
    wq[(size_t)q] = cur * (mn / m);
    ++cnt[2];
  }
  {
    ParticleView<dim> P = S.particles.get();
    double *W = P.field(S.particles.field_index(kWeight));
    for (PetscInt p = 0; p < P.n; ++p) {
      const size_t c = (size_t)pcell[(size_t)p];
      const double *a = &c2[c * st + 1 + dim], *b = &c1[c * 5];
      if (!dgive[c] || !(a[0] > 0)) continue;
      const double room = pgive[(size_t)p] < 0 ? -pgive[(size_t)p] : 0.0;
      // Up to the target share, in proportion to the room; beyond it, in proportion to the mass.
      const double take = a[0] <= b[1] ? room * (a[0] / b[1]) : room + (a[0] - b[1]) * (P.m[p] / b[4]);
      if (!(take > 0)) continue;
      const double m = P.m[p], mn = m + take, f = mn / m;
      for (int k = 0; k < dim; ++k) P.v[p * dim + k] = (m * P.v[p * dim + k] + take * (a[1 + k] / a[0])) / mn;
      P.m[p] = mn;
      P.vol[p] *= f;
      W[p] *= f;
      ++cnt[0];
    }
    S.particles.restore(P);
  }
  for (auto it = gone.rbegin(); it != gone.rend(); ++it) GM_CALL(DMSwarmRemovePointAtIndex(S.particles.dm(), *it)); // the last point moves in: descending order
  MPI_Allreduce(MPI_IN_PLACE, cnt, 4, MPI_LONG, MPI_SUM, S.comm);
  if (cnt[2] + cnt[3] > 0) e.reweight(wq);
  for (int k = 0; k < 4; ++k) shares_[k] += cnt[k];
  share_mass_[0] += moved[0];
  share_mass_[1] += moved[1];
}

template <int dim>
void HybridModule<dim>::write_checkpoint(const State<dim> &S, CheckpointIO &io) const {
  if (oracle_.every <= 0) return;
  std::vector<double> a = {(double)zupdates_, (double)steps_};
  for (long c : zcount_) a.push_back((double)c);
  for (long c : shares_) a.push_back((double)c);
  a.push_back(share_mass_[0]);
  a.push_back(share_mass_[1]);
  a.push_back((double)homog_);
  a.push_back(homog_m_);
  for (long c : enr_) a.push_back((double)c);
  a.push_back(enr_m_);
  a.push_back(balance_);
  io.write_attr("hybrid_oracle", a);
  // The zone map and presence maps of the last update (the same on every rank): rank 0 writes them.
  const long N = (long)zones_.size();
  std::vector<double> rows;
  for (long c = 0; c < N; ++c) {
    rows.push_back((double)(int)zones_[(size_t)c]);
    rows.push_back(has_mp_.empty() ? 0.0 : has_mp_[(size_t)c]);
    rows.push_back(has_grain_.empty() ? 0.0 : has_grain_[(size_t)c]);
    rows.push_back(prev_.size() == zones_.size() ? (double)(int)prev_[(size_t)c] : -1.0);
    rows.push_back(phi_.empty() ? 0.0 : phi_[(size_t)c]);
  }
  const bool r0 = S.rank == 0;
  io.write_rows("hybrid_zones", rows.data(), r0 ? N : 0, r0 ? 0 : N, N, 5);
}

template <int dim>
void HybridModule<dim>::read_checkpoint(State<dim> &, CheckpointIO &io) {
  if (oracle_.every <= 0) return;
  if (!io.has_attr("hybrid_oracle")) io.bad("it has no zones of the hybrid oracle (written without -hybrid_zone_every): drop -hybrid_zone_every or restart from a run with it");
  const std::vector<double> a = io.read_attr("hybrid_oracle");
  if (a.size() != 24) io.bad("its hybrid_oracle attribute has " + std::to_string(a.size()) + " values instead of 24 (written by an older granmpm?)");
  zupdates_ = (long)a[0];
  steps_ = (long)a[1];
  for (int k = 0; k < 6; ++k) zcount_[k] = (long)a[2 + k];
  for (int k = 0; k < 4; ++k) shares_[k] = (long)a[8 + k];
  share_mass_[0] = a[12];
  share_mass_[1] = a[13];
  homog_ = (long)a[14];
  homog_m_ = a[15];
  for (int k = 0; k < 6; ++k) enr_[k] = (long)a[16 + k];
  enr_m_ = a[22];
  balance_ = a[23];
  const long N = zgrid_.size();
  std::vector<double> rows((size_t)N * 5);
  io.read_all_rows("hybrid_zones", rows.data(), N, 5);
  zones_.resize((size_t)N);
  has_mp_.resize((size_t)N);
  has_grain_.resize((size_t)N);
  phi_.resize((size_t)N);
  prev_.clear();
  for (long c = 0; c < N; ++c) {
    const double *r = &rows[(size_t)c * 5];
    zones_[(size_t)c] = (hybrid::Zone)(int)r[0];
    has_mp_[(size_t)c] = r[1];
    has_grain_[(size_t)c] = r[2];
    if (r[3] >= 0) prev_.push_back((hybrid::Zone)(int)r[3]);
    phi_[(size_t)c] = r[4];
  }
}

namespace {

struct HybridOptions {
  PetscBool dem = PETSC_FALSE, band_set = PETSC_FALSE;
  PetscReal band[3] = {0, 0, 0}, weight = 0.5; // room for a third value: PETSc drops the ones beyond the array
  char axis[8] = "y", side[8] = "hi";
  PetscInt zone_every = 0;
  PetscReal phi = 0.3, band_distance = 0, half_width = 0;
  PetscBool hw_set = PETSC_FALSE; // without it: one MPM cell
  PetscBool axis_set = PETSC_FALSE, side_set = PETSC_FALSE, weight_set = PETSC_FALSE, phi_set = PETSC_FALSE, bd_set = PETSC_FALSE;
  PetscBool homogenise = PETSC_TRUE, homogenise_set = PETSC_FALSE, enrich = PETSC_TRUE, enrich_set = PETSC_FALSE;
};

// Every -hybrid_ option in one PetscOptionsBegin/End block (-help lists them); failed names
// the option PETSc could not parse.
#define HYB_OPT(name, ...)                                                                 \
  do {                                                                                     \
    failed = name;                                                                         \
    PetscCall(__VA_ARGS__);                                                                \
  } while (0)

PetscErrorCode read_hybrid_options(MPI_Comm comm, HybridOptions &o, const char *&failed) {
  PetscFunctionBeginUser;
  PetscInt n = 3;
  PetscOptionsBegin(comm, NULL, "Hybrid continuum/discrete coupling (docs/hybrid.md)", NULL);
  HYB_OPT("-hybrid_dem", PetscOptionsBool("-hybrid_dem", "Add the DEM grains of the -dem_* options (docs/dem.md) to this MPM run as a second species (docs/hybrid.md)", NULL, o.dem, &o.dem, NULL));
  HYB_OPT("-hybrid_band", PetscOptionsRealArray("-hybrid_band", "Couple the grains and the material points in a fixed band lo,hi along -hybrid_band_axis (needs -hybrid_dem)", NULL, o.band, &n, &o.band_set));
  HYB_OPT("-hybrid_band_axis", PetscOptionsString("-hybrid_band_axis", "Axis across the fixed band (x|y|z)", NULL, o.axis, o.axis, sizeof o.axis, &o.axis_set));
  HYB_OPT("-hybrid_continuum", PetscOptionsString("-hybrid_continuum", "Side of the band with the continuum zone (lo|hi); the discrete zone is the other", NULL, o.side, o.side, sizeof o.side, &o.side_set));
  HYB_OPT("-hybrid_band_weight", PetscOptionsReal("-hybrid_band_weight", "Continuum share w_M of the mass in the band, in [0, 1] (grains: 1 - w_M)", NULL, o.weight, &o.weight, &o.weight_set));
  HYB_OPT("-hybrid_zone_every", PetscOptionsInt("-hybrid_zone_every", "Recompute the oracle's zones every N MPM steps; they set the mass shares (0: off, the fixed band holds; needs -hybrid_band; docs/hybrid.md)", NULL, o.zone_every, &o.zone_every, NULL));
  HYB_OPT("-hybrid_phi", PetscOptionsReal("-hybrid_phi", "Oracle: packing fraction of the dense contour, in (0, 1]", NULL, o.phi, &o.phi, &o.phi_set));
  HYB_OPT("-hybrid_band_distance", PetscOptionsReal("-hybrid_band_distance", "Oracle: distance of the band's centre inside the dense contour (m)", NULL, o.band_distance, &o.band_distance, &o.bd_set));
  HYB_OPT("-hybrid_band_halfwidth", PetscOptionsReal("-hybrid_band_halfwidth", "Oracle: half-width of the band (m; default one MPM cell)", NULL, o.half_width, &o.half_width, &o.hw_set));
  HYB_OPT("-hybrid_homogenise", PetscOptionsBool("-hybrid_homogenise", "With -hybrid_zone_every: grains in cells continuum at two zone updates in a row, without material points, become material points",
                             NULL, o.homogenise, &o.homogenise, &o.homogenise_set));
  HYB_OPT("-hybrid_enrich", PetscOptionsBool("-hybrid_enrich", "With -hybrid_zone_every: material points in cells discrete at two zone updates in a row, without grains, become grains", NULL,
                             o.enrich, &o.enrich, &o.enrich_set));
  failed = nullptr;
  PetscOptionsEnd();
  if (o.band_set && n != 2) o.band[0] = o.band[1] = NAN; // band_of reports it
  PetscFunctionReturn(0);
}
#undef HYB_OPT

// PETSc's parse errors (a non-numeric value, an integer out of range...) as one line naming
// the option, on every rank (the options are the same everywhere), without PETSc's trace.
void read_hybrid_options(MPI_Comm comm, HybridOptions &o) {
  const char *failed = nullptr;
  PetscErrorPrintf = PetscErrorPrintfNone;
  PetscPushErrorHandler(PetscReturnErrorHandler, NULL);
  const PetscErrorCode ierr = read_hybrid_options(comm, o, failed);
  PetscPopErrorHandler();
  PetscErrorPrintf = PetscErrorPrintfDefault;
  char val[256] = "";
  PetscBool set = PETSC_FALSE;
  if (ierr) {
    if (failed) PetscOptionsGetString(NULL, NULL, failed, val, sizeof val, &set);
    throw UserError(std::string(failed ? failed : "-hybrid_ options") + ": invalid value '" + val + "'; see granmpm -help");
  }
  // PETSc wraps an integer beyond PetscInt's range instead of refusing it.
  PetscOptionsGetString(NULL, NULL, "-hybrid_zone_every", val, sizeof val, &set);
  if (set) {
    errno = 0;
    char *end = nullptr;
    const long long v = std::strtoll(val, &end, 10);
    if (errno == ERANGE || v != (long long)o.zone_every)
      throw UserError(std::string("-hybrid_zone_every: invalid value '") + val + "' (beyond the integer range); see granmpm -help");
  }
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
  read_hybrid_options(S.comm, o);
  if (o.zone_every < 0) throw UserError("-hybrid_zone_every must be >= 0 (got " + std::to_string((long)o.zone_every) + ")");
  if (!(o.phi > 0 && o.phi <= 1)) throw UserError("-hybrid_phi must be in (0, 1] (got " + std::to_string(o.phi) + ")");
  if (!std::isfinite(o.band_distance)) throw UserError("-hybrid_band_distance must be a finite distance in m");
  if (!(o.half_width >= 0 && std::isfinite(o.half_width)))
    throw UserError("-hybrid_band_halfwidth must be >= 0 (got " + std::to_string(o.half_width) + ")");
  if (o.homogenise_set && o.zone_every == 0) throw UserError("-hybrid_homogenise converts grains where the oracle's zones say so: add -hybrid_zone_every N (or drop -hybrid_homogenise)");
  if (o.enrich_set && o.zone_every == 0) throw UserError("-hybrid_enrich converts material points where the oracle's zones say so: add -hybrid_zone_every N (or drop -hybrid_enrich)");
  // An option without the one that uses it would be silently ignored: refuse it.
  using Given = std::pair<PetscBool, const char *>;
  for (const Given &g : std::vector<Given>{{o.phi_set, "-hybrid_phi"}, {o.bd_set, "-hybrid_band_distance"}, {o.hw_set, "-hybrid_band_halfwidth"}})
    if (const char *name = g.second; g.first && o.zone_every == 0) throw UserError(std::string(name) + " sets the zone oracle: add -hybrid_zone_every N (or drop " + name + ")");
  for (const Given &g : std::vector<Given>{{o.axis_set, "-hybrid_band_axis"}, {o.side_set, "-hybrid_continuum"}, {o.weight_set, "-hybrid_band_weight"}})
    if (const char *name = g.second; g.first && !o.band_set) throw UserError(std::string(name) + " shapes the band of -hybrid_band: add -hybrid_band lo,hi (or drop " + name + ")");
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
  z.homogenise = o.homogenise;
  z.enrich = o.enrich;
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
  auto d = std::make_unique<DemModule<dim>>(S, dc, true); // its snapshots after the coupling's changes (end_step)
  auto h = std::make_unique<HybridModule<dim>>(S, *d, band);
  out.push_back(std::move(d));
  out.push_back(std::move(h));
  return out;
}

std::vector<std::pair<std::string, int>> hybrid_particle_fields(MPI_Comm comm) {
  (void)comm; // the options are read (and registered for -help) by grain_modules
  // Quietly: a bad -hybrid_dem value is one line naming it, not PETSc's trace (grain_modules,
  // which registers the options for -help, runs later).
  PetscBool dem = PETSC_FALSE, band = PETSC_FALSE;
  PetscErrorPrintf = PetscErrorPrintfNone;
  PetscPushErrorHandler(PetscReturnErrorHandler, NULL);
  const PetscErrorCode ierr = PetscOptionsGetBool(NULL, NULL, "-hybrid_dem", &dem, NULL);
  PetscPopErrorHandler();
  PetscErrorPrintf = PetscErrorPrintfDefault;
  if (ierr) {
    char val[256] = "";
    PetscOptionsGetString(NULL, NULL, "-hybrid_dem", val, sizeof val, NULL);
    throw UserError(std::string("-hybrid_dem: invalid value '") + val + "'; see granmpm -help");
  }
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
