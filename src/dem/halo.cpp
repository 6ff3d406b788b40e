// The DEM ghost halo (the plan at each rebuild, the per-step update) and the neighbour
// lists with their carried-over tangential springs.
#include "granmpm/dem/dem.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <unordered_map>

#include "granmpm/config.hpp"
#include "internal.hpp"

namespace granmpm::dem {

using namespace detail;

// The ghost plan: every owned grain within the interaction range of another rank's box
// (or of this rank's own box through a periodic face) is sent there, with its shift
// (per destination rank: owned index, shift).
std::vector<std::vector<std::pair<int, V3>>> Engine::ghost_plan() const {
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
  return out;
}

uint8_t Engine::shift_code(const V3 &s) const {
  int code = 0;
  for (int k = 2; k >= 0; --k) {
    const double v = comp(s, k);
    code = 3 * code + (v > 0 ? 2 : (v < 0 ? 0 : 1));
  }
  const V3 t = shifts_[code];
  if (!(t.x == s.x && t.y == s.y && t.z == s.z)) throw std::logic_error("dem::Engine: a ghost shift outside the table");
  return (uint8_t)code;
}

// The ghosts of the plan arrive with their state; the working arrays are sized to them.
void Engine::exchange_ghosts_full() {
  const std::vector<std::vector<std::pair<int, V3>>> out = ghost_plan();
  send_cnt_.assign(size_, 0);
  send_idx_.clear();
  std::vector<V3> send_shift; // (only this exchange needs them: ghosts keep their own shift)
  for (int r = 0; r < size_; ++r) {
    send_cnt_[r] = (int)out[r].size();
    for (auto &q : out[r]) {
      send_idx_.push_back(q.first);
      send_shift.push_back(q.second);
    }
  }
  struct GhostFull {
    int64_t id, key;
    double r, mw;
    V3 x, s, v, w; // raw position and its periodic shift (applied after differences)
  };
  std::vector<GhostFull> sbuf(send_idx_.size()), rbuf;
  for (size_t q = 0; q < send_idx_.size(); ++q) {
    const int i = send_idx_[q];
    sbuf[q] = {id_[i], ckey_[i], r_[i], mw_.empty() ? 1.0 : mw_[i], x_[i], send_shift[q], v_[i], w_[i]};
  }
  alltoallv(comm_, sbuf, send_cnt_, rbuf, recv_cnt_);
  // This rank's own images are not copied: they read their grain's slot (dat).
  const long nself = recv_cnt_[rank_];
  self0_ = 0;
  for (int r = 0; r < rank_; ++r) self0_ += send_cnt_[r];
  ntot_ = nown_ + (long)rbuf.size();
  nd_ = ntot_ - nself;
  gb_scnt_.clear(); // the per-step ghost buffers follow the new plan
  // Exact sizes (a plain resize may double the capacity): the memory follows the grains.
  auto fit = [](auto &vec, size_t n) {
    vec.resize(n);
    vec.shrink_to_fit();
  };
  fit(x_, nd_);
  fit(v_, nd_);
  fit(w_, nd_);
  fit(r_, nd_);
  fit(mw_, c_.mass_weight ? nd_ : 0);
  fit(id_, nd_);
  fit(ckey_, nd_);
  fit(f_, nown_);
  fit(tq_, nown_);
  fit(ncontact_, nown_);
  fit(gcode_, rbuf.size());
  fit(theta_, theta_.size());
  fit(q_, q_.size());
  fit(x0_, nown_);
  fit(send_idx_, send_idx_.size());
  // Ghosts keep their arrival order (rank order), other ranks' first, then the own images.
  long from = 0, rem = nown_, img = nd_;
  for (int r = 0; r < size_; ++r)
    for (int k = 0; k < recv_cnt_[r]; ++k, ++from) {
      const GhostFull &g = rbuf[from];
      const long j = r == rank_ ? img++ : rem++;
      gcode_[j - nown_] = shift_code(g.s);
      if (r == rank_) continue;
      id_[j] = g.id;
      ckey_[j] = (int)g.key;
      r_[j] = g.r;
      if (c_.mass_weight) mw_[j] = g.mw;
      x_[j] = g.x;
      v_[j] = g.v;
      w_[j] = g.w;
    }
}

// Each step: ghosts get the new positions (with their shifts), velocities and spins in one
// MPI_Alltoallw: packed per destination rank as all x, then all v, then all omega of its
// grains (one send buffer, 72 B per sent ghost), received straight into the ghosts' slots of
// x_, v_, w_ (they arrive in rank order) through one three-block datatype per source rank
// (no receive buffer). Plan and types are kept from the last rebuild (no allocation per
// step); the types hold the arrays' addresses, so they are remade after every reallocation
// (exchange_ghosts_full clears gb_scnt_).
void Engine::update_ghosts() {
  const size_t ns = send_idx_.size();
  if (gb_scnt_.size() != (size_t)size_ || gb_x_ != x_.data() || gb_v_ != v_.data() || gb_w_ != w_.data()) {
    gbuf_send_.assign(3 * (ns - send_cnt_[rank_]), V3{}); // (images of own grains are copied directly)
    gbuf_send_.shrink_to_fit();
    for (MPI_Datatype &t : gb_rtype_)
      if (t != MPI_BYTE) MPI_Type_free(&t);
    gb_scnt_.assign(size_, 0);
    gb_sdsp_.assign(size_, 0);
    gb_rcnt_.assign(size_, 0);
    gb_rdsp_.assign(size_, 0);
    gb_stype_.assign(size_, MPI_BYTE);
    gb_rtype_.assign(size_, MPI_BYTE);
    int so = 0;
    long ro = nown_;
    for (int p = 0; p < size_; ++p) {
      if (p == rank_) continue; // (its images read their grains' slots)
      gb_scnt_[p] = send_cnt_[p] * 3 * (int)sizeof(V3);
      gb_sdsp_[p] = so;
      so += gb_scnt_[p];
      if (recv_cnt_[p] > 0) {
        const int len = recv_cnt_[p] * (int)sizeof(V3);
        int lens[3] = {len, len, len};
        MPI_Aint at[3];
        MPI_Get_address(x_.data() + ro, &at[0]);
        MPI_Get_address(v_.data() + ro, &at[1]);
        MPI_Get_address(w_.data() + ro, &at[2]);
        MPI_Datatype bytes[3] = {MPI_BYTE, MPI_BYTE, MPI_BYTE};
        MPI_Type_create_struct(3, lens, at, bytes, &gb_rtype_[p]);
        MPI_Type_commit(&gb_rtype_[p]);
        gb_rcnt_[p] = 1;
      }
      ro += recv_cnt_[p];
    }
    gb_x_ = x_.data();
    gb_v_ = v_.data();
    gb_w_ = w_.data();
  }
  for (int p = 0, q0 = 0, b0 = 0; p < size_; q0 += send_cnt_[p], ++p) {
    const int c = send_cnt_[p];
    if (p == rank_) continue;
    V3 *b = gbuf_send_.data() + 3 * b0;
    b0 += c;
    for (int k = 0; k < c; ++k) {
      const int i = send_idx_[q0 + k];
      b[k] = x_[i];
      b[c + k] = v_[i];
      b[2 * c + k] = w_[i];
    }
  }
  MPI_Alltoallw(gbuf_send_.data(), gb_scnt_.data(), gb_sdsp_.data(), gb_stype_.data(), MPI_BOTTOM, gb_rcnt_.data(), gb_rdsp_.data(), gb_rtype_.data(), comm_);
}

namespace {

// A spring of the previous lists, as seen from owned grain a (store is sorted by a, b).
bool find_spring(const std::vector<HistRec> &store, int64_t a, int64_t b, V3 &h) {
  auto it = std::lower_bound(store.begin(), store.end(), std::make_pair(a, b), [](const HistRec &r, const std::pair<int64_t, int64_t> &k) {
    return r.a != k.first ? r.a < k.first : r.b < k.second;
  });
  if (it != store.end() && it->a == a && it->b == b) {
    h = it->h;
    return true;
  }
  return false;
}

} // namespace

// The grains binned into cells of the broad phase over their bounding box.
CellBins::CellBins(const std::vector<V3> &xb, long n, double cell_size, int dim_) : cell(cell_size), dim(dim_) {
  V3 hi{-1e300, -1e300, -1e300};
  lo = {1e300, 1e300, 1e300};
  for (long i = 0; i < n; ++i)
    for (int k = 0; k < dim; ++k) {
      comp(lo, k) = std::min(comp(lo, k), comp(xb[i], k));
      comp(hi, k) = std::max(comp(hi, k), comp(xb[i], k));
    }
  for (int k = 0; k < dim; ++k) nc[k] = n ? std::max(1, (int)((comp(hi, k) - comp(lo, k)) / cell) + 1) : 1;
  const long ncell = (long)nc[0] * nc[1] * nc[2];
  std::vector<int> cidx(n);
  start.assign(ncell + 1, 0);
  order.resize(n);
  for (long i = 0; i < n; ++i) {
    int ci[3];
    cidx[i] = (int)of(xb[i], ci);
    start[cidx[i] + 1]++;
  }
  for (long c = 0; c < ncell; ++c) start[c + 1] += start[c];
  std::vector<int> fill(start.begin(), start.end() - 1);
  for (long i = 0; i < n; ++i) order[fill[cidx[i]]++] = (int)i;
}

// Neighbour lists from cell lists over owned + ghost grains: every partner within
// r_i + r_j + skin, and every non-periodic face within r_i + skin; sorted by partner key
// (faces first), the tangential springs carried over from `store` by key.
void Engine::build_lists(bool first, const std::vector<HistRec> &store) {
  // Ghost images sit at their raw position plus their periodic shift.
  std::vector<V3> xb(ntot_);
  for (long j = 0; j < ntot_; ++j) xb[j] = j < nown_ ? x_[j] : x_[dat(j)] + gshift(j - nown_);
  const CellBins bins(xb, ntot_, c_.cell, c_.dim);
  // The canonical order of the local grains.
  ord_.resize(ntot_);
  ord_.shrink_to_fit();
  for (long i = 0; i < ntot_; ++i) ord_[i] = (int)i;
  auto before = [&](int a, int b) {
    const long da = dat(a), db = dat(b);
    return ckey_[da] != ckey_[db] ? ckey_[da] < ckey_[db] : (id_[da] != id_[db] ? id_[da] < id_[db] : a < b);
  };
  std::sort(ord_.begin(), ord_.end(), before);
  const double max_ov = std::max(wall_lists(first, store), pair_lists(first, store, xb, bins));
  // Exact capacities: the lists' memory follows the grains, not the largest list so far.
  nb_.shrink_to_fit();
  nl_.shrink_to_fit();
  wf_.shrink_to_fit();
  wg_.shrink_to_fit();
  whist_.shrink_to_fit();
  carry_.clear();
  carry_.shrink_to_fit(); // (it had grown to the most contacts begun ahead of ended ones in a pass)
  // The keys served the canonical order; the next rebuild recomputes them (set_keys).
  ckey_.clear();
  ckey_.shrink_to_fit();
  if (first) {
    double g;
    MPI_Allreduce(&max_ov, &g, 1, MPI_DOUBLE, MPI_MAX, comm_);
    if (g > c_.overlap_tol)
      throw UserError("initial grain overlap " + std::to_string(g) + " (of the smaller radius) is above -dem_overlap_tol " + std::to_string(c_.overlap_tol) +
                      ": space the grains (-dem_spacing, -dem_jitter, -dem_radius_spread) or raise -dem_overlap_tol");
  }
}

// Walls and the plate (owned grains), in key order; returns the largest initial overlap
// (first build only).
double Engine::wall_lists(bool first, const std::vector<HistRec> &store) {
  const int dim = c_.dim;
  wg_.clear();
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
    body_lists(i, faces, max_ov, first);
    std::sort(faces.begin(), faces.end());
    for (int f : faces) {
      V3 h{};
      find_spring(store, id_[i], f, h);
      wf_.push_back(f);
      wg_.push_back((int)i);
      whist_.push_back(h);
    }
  }
  blist_ = bnow_;
  return max_ov;
}

// Half lists in canonical order: partners later in the order within r_i + r_j + skin, at
// least one of the two owned; sorted by their position in the order. Returns the largest
// initial overlap (first build only).
double Engine::pair_lists(bool first, const std::vector<HistRec> &store, const std::vector<V3> &xb, const CellBins &bins) {
  const int dim = c_.dim;
  std::vector<int> pos(ntot_);
  for (long p = 0; p < ntot_; ++p) pos[ord_[p]] = (int)p;
  nl_.assign(ntot_, 0);
  nb_.clear();
  if (ntot_ >= (1L << 30)) throw std::length_error("dem::Engine: more than 2^30 local grains on a rank");
  std::vector<V3> pool;
  std::vector<int> cand;
  double max_ov = 0;
  for (long p = 0; p < ntot_; ++p) {
    const int i = ord_[p];
    cand.clear();
    int ci[3];
    bins.of(xb[i], ci);
    for (int dz = (dim == 3 ? -1 : 0); dz <= (dim == 3 ? 1 : 0); ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int a = ci[0] + dx, b = ci[1] + dy, cz = ci[2] + dz;
          if (a < 0 || b < 0 || cz < 0 || a >= bins.nc[0] || b >= bins.nc[1] || cz >= bins.nc[2]) continue;
          const long c = a + (long)bins.nc[0] * (b + (long)bins.nc[1] * cz);
          for (int q = bins.start[c]; q < bins.start[c + 1]; ++q) {
            const int j = bins.order[q];
            if (pos[j] <= p || (i >= nown_ && j >= nown_)) continue;
            const V3 d = pair_sep(i, j);
            const double ri = r_[dat(i)], rj = r_[dat(j)], cut = ri + rj + c_.skin;
            const double d2 = dot(d, d);
            if (d2 < cut * cut) {
              cand.push_back(pos[j]);
              if (first) max_ov = std::max(max_ov, (ri + rj - std::sqrt(d2)) / std::min(ri, rj));
            }
          }
        }
    std::sort(cand.begin(), cand.end());
    if (cand.size() > 65535) throw std::length_error("dem::Engine: a grain with more than 65535 neighbours (-dem_skin, -dem_radius_spread)");
    nl_[p] = (uint16_t)cand.size();
    for (int pj : cand) {
      const int j = ord_[pj];
      V3 h{};
      if (i < nown_) find_spring(store, id_[i], id_[dat(j)], h);
      else if (find_spring(store, id_[j], id_[dat(i)], h)) h = -h;
      const bool has = h.x != 0 || h.y != 0 || h.z != 0;
      nb_.push_back(has ? ~j : j);
      if (has) pool.push_back(h);
    }
  }
  // The springs with 1/8 headroom for new contacts (not the doubling of push_back).
  pool_.clear();
  pool_.shrink_to_fit();
  pool_.reserve(pool.size() + pool.size() / 8 + 16);
  pool_.assign(pool.begin(), pool.end());
  return max_ov;
}

std::vector<HistRec> Engine::owned_springs(std::vector<long> *who) const {
  std::vector<HistRec> out;
  auto add = [&](long i, HistRec r) {
    out.push_back(r);
    if (who) who->push_back(i);
  };
  auto nonzero = [](const V3 &h) { return h.x != 0 || h.y != 0 || h.z != 0; };
  for (size_t q = 0; q < wf_.size(); ++q)
    if (nonzero(whist_[q])) add(wg_[q], {id_[wg_[q]], (int64_t)wf_[q], whist_[q]});
  for (long p = 0, k = 0, q = 0; p < ntot_; ++p) {
    const int i = ord_[p];
    for (const long end = q + nl_[p]; q < end; ++q) {
      const V3 h = nb_[q] < 0 ? pool_[k++] : V3{};
      if (!nonzero(h)) continue;
      const int j = partner(nb_[q]);
      if (i < nown_) add(i, {id_[i], id_[dat(j)], h});
      if (j < nown_) add(j, {id_[j], id_[dat(i)], -h});
    }
  }
  return out;
}

} // namespace granmpm::dem
