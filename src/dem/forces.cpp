// The DEM contact forces in the canonical order, the silo plate, the contact stress.
#include "granmpm/dem/dem.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <unordered_map>

#include "granmpm/config.hpp"
#include "internal.hpp"

namespace granmpm::dem {

using namespace detail;

// Walls first (the first partners of every grain in key order), then the pairs, then
// gravity: every grain sums its forces in the same order on every decomposition.
void Engine::compute_forces() {
  // Owned grains only: a ghost's forces belong to its owner, which computes them itself.
  f_.resize(nown_);
  tq_.resize(nown_);
  ncontact_.resize(nown_);
  for (long i = 0; i < nown_; ++i) {
    f_[i] = V3{};
    tq_[i] = V3{};
    ncontact_[i] = 0;
  }
  std::fill(bf_.begin(), bf_.end(), 0.0);
  Tally t;
  wall_forces(t);
  if (!bspec_.empty()) sum_body_hits();
  pair_forces(t);
  bprev_ = bf_;
  const V3 g{c_.gravity[0], c_.gravity[1], c_.gravity[2]};
  double im[kBlock], ii[kBlock];
  for (long i0 = 0; i0 < nown_; i0 += kBlock) {
    const long n = std::min(kBlock, nown_ - i0);
    inverse_masses(i0, n, im, ii);
    for (long k = 0; k < n; ++k) f_[i0 + k] = f_[i0 + k] + (1.0 / im[k]) * g;
  }
  elastic_ = t.elastic;
  max_overlap_ = t.max_ov;
  pair_entries_ = t.contacts;
  wall_contacts_ = t.wall_contacts;
}

void Engine::wall_forces(Tally &t) {
  const double dt = hstep_;
  const V3 *__restrict x = x_.data();
  const V3 *__restrict v = v_.data();
  const V3 *__restrict w = w_.data();
  const double *__restrict rad = r_.data();
  V3 *__restrict f = f_.data();
  V3 *__restrict tq = tq_.data();
  uint16_t *__restrict ncon = ncontact_.data();
  double elastic = t.elastic, max_ov = t.max_ov;
  long wall_contacts = t.wall_contacts;
  for (int q = 0; q < (int)wf_.size(); ++q) {
    const long i = wg_[q];
    const V3 xi = x[i];
    const double ri = rad[i];
    const int face = -wf_[q] - 1, k = face / 2;
    V3 d{}, vw{};
    if (face < 2 * c_.dim) comp(d, k) = (face % 2 == 0 ? c_.lo[k] : c_.hi[k]) - comp(xi, k);
    else d = wall_sep(face, xi, vw);
    const double dd = dot(d, d);
    const bool body = face > 2 * c_.dim;
    if (dd >= ri * ri || (body && dd == 0)) {
      if (body && dd == 0 && body_msg_.empty()) check_bodies(body_msg_); // a centre inside a body
      whist_[q] = V3{};
      continue;
    }
    const ContactResult res = contact(wall_law(face), d, ri, 0.0, body ? v[i] - vw : v[i], w[i], V3{}, 1.0 / inv_mass(i), 1.0 / inv_inertia(i), whist_[q], dt);
    if (body) body_reaction(id_[i], face - 2 * c_.dim - 1, xi, ri, d, res);
    f[i] = f[i] + res.force;
    tq[i] = tq[i] + res.torque + res.troll;
    elastic += res.elastic;
    max_ov = std::max(max_ov, ri - std::sqrt(dd));
    if (res.fn > 0) {
      ++ncon[i];
      ++wall_contacts;
    }
  }
  t.elastic = elastic;
  t.max_ov = max_ov;
  t.wall_contacts = wall_contacts;
}

// Pairs, each once, in canonical order; the partner takes the negated force.
void Engine::pair_forces(Tally &t) {
  const double dt = hstep_;
  const ContactParams cp = c_.contact; // a local copy: no reloads through this
  const bool roll = cp.mu_roll > 0;
  const V3 *__restrict x = x_.data();
  const V3 *__restrict v = v_.data();
  const V3 *__restrict w = w_.data();
  const double *__restrict rad = r_.data();
  int *__restrict nb = nb_.data();
  V3 *__restrict f = f_.data();
  V3 *__restrict tq = tq_.data();
  uint16_t *__restrict ncon = ncontact_.data();
  const long nown = nown_;
  double elastic = t.elastic, max_ov = t.max_ov;
  long contacts = t.contacts;
  const uint16_t *__restrict nl = nl_.data();
  // The springs are rewritten in place in list order: entries read from rd on (after those
  // read ahead into carry_), written at wr <= rd. A new contact before an ended one would
  // overwrite a spring not read yet: that one is read ahead first (carry_ is a queue; it
  // holds at most the net number of new contacts so far). The values are those the
  // contact law computes, so the order of storage changes no result.
  // (carry_ is a ring buffer of power-of-two size: its first entry at ch, cn entries.)
  size_t rd = 0, wr = 0, ch = 0, cn = 0;
  const size_t nold = pool_.size();
  auto take = [&]() -> V3 {
    if (cn == 0) return pool_[rd++];
    const V3 h = carry_[ch];
    ch = (ch + 1) & (carry_.size() - 1);
    --cn;
    return h;
  };
  auto put = [&](const V3 &h) {
    if (wr == rd && rd < nold) { // the slot is still unread: queue its spring
      if (cn == carry_.size()) { // full: double, unrolled to start at 0
        std::vector<V3> grown(std::max<size_t>(16, 2 * cn));
        for (size_t k = 0; k < cn; ++k) grown[k] = carry_[(ch + k) & (cn - 1)];
        carry_.swap(grown);
        ch = 0;
      }
      carry_[(ch + cn++) & (carry_.size() - 1)] = pool_[rd++];
    }
    if (wr == pool_.size()) {
      if (pool_.size() == pool_.capacity()) pool_.reserve(pool_.size() + pool_.size() / 8 + 16); // grow by 1/8
      pool_.push_back(h);
    } else
      pool_[wr] = h;
    ++wr;
  };
  const long nd = nd_;
  for (long p = 0, q0 = 0; p < ntot_; ++p) {
    const int i = ord_[p];
    if (nl[p] == 0) continue;
    const long q1 = q0 + nl[p];
    const long di = i < nd ? i : dat(i); // (an own image's state is its grain's)
    const V3 xi = x[di], vi = v[di], wi = w[di];
    const double ri = rad[di], imi = inv_mass(di);
    const bool iown = i < nown;
    const V3 si = iown ? V3{} : -gshift(i - nown);
    // i's sums in registers, in the same order as in memory (a ghost's are dropped).
    V3 fi = iown ? f[i] : V3{}, ti = iown ? tq[i] : V3{};
    int ni = iown ? ncon[i] : 0;
    for (long q = q0; q < q1; ++q) {
      const int e = nb[q], j = partner(e);
      const long dj = j < nd ? j : dat(j);
      V3 d = x[dj] - xi;
      if (j >= nown) d = d + gshift(j - nown);
      else if (!iown) d = d + si;
      const double s = ri + rad[dj];
      if (dot(d, d) >= s * s) {
        if (e < 0) { // the contact ended: its spring goes
          take();
          nb[q] = j;
        }
        continue;
      }
      V3 h{}; // a new contact starts with a zero spring
      if (e < 0) h = take();
      else nb[q] = ~j;
      const double meff = 1.0 / (imi + inv_mass(dj));
      const double Ieff = roll ? 1.0 / (inv_inertia(di) + inv_inertia(dj)) : 0.0; // (only rolling resistance needs it)
      const ContactResult res = contact(cp, d, ri, rad[dj], vi - v[dj], wi, w[dj], meff, Ieff, h, dt);
      put(h);
      fi = fi + res.force;
      ti = ti + res.torque + res.troll;
      const bool jown = j < nown;
      if (jown) {
        f[j] = f[j] + (-res.force);
        tq[j] = tq[j] + rad[j] * res.arm + (-res.troll);
      }
      const int owners = (int)iown + (int)jown;
      elastic += 0.5 * owners * res.elastic;
      max_ov = std::max(max_ov, res.overlap);
      if (res.fn > 0) { // a force-carrying contact (an overlap may outlive its force)
        ++ni;
        if (jown) ++ncon[j];
        contacts += owners;
      }
    }
    if (iown) {
      f[i] = fi;
      tq[i] = ti;
      ncon[i] = ni;
    }
    q0 = q1;
  }
  pool_.resize(wr);
  t.elastic = elastic;
  t.max_ov = max_ov;
  t.contacts = contacts;
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

// Every contact of the last step re-evaluated at dt = 0 (the springs as stored already
// include this step's slip), for the diagnostics below: fn(i, j, F, d, dist) with F the force
// on grain i, d the separation vector and j = -1 for a wall, for the contacts want(i, j) selects.
template <class Want, class Fn>
void Engine::contacts_at_rest(Want want, Fn fn) {
  for (int q = 0; q < (int)wf_.size(); ++q) {
    const long i = wg_[q];
    if (!want(i, -1)) continue;
    const int face = -wf_[q] - 1;
    V3 vw{};
    const V3 d = wall_sep(face, x_[i], vw);
    const double dist = norm(d);
    if (dist >= r_[i] || dist == 0) continue;
    V3 h = whist_[q];
    const ContactResult res = contact(wall_law(face), d, r_[i], 0.0, v_[i] - vw, w_[i], V3{}, 1.0 / inv_mass(i), 1.0 / inv_inertia(i), h, 0.0);
    fn(i, -1L, res.force, d, dist);
  }
  for (long p = 0, k = 0, q = 0; p < ntot_; ++p) {
    const long i = ord_[p];
    for (const long end = q + nl_[p]; q < end; ++q) {
      const long j = partner(nb_[q]);
      V3 h = nb_[q] < 0 ? pool_[k++] : V3{};
      if (!want(i, j)) continue;
      const V3 d = pair_sep(i, j);
      const double dist = norm(d);
      const long di = dat(i), dj = dat(j);
      if (dist >= r_[di] + r_[dj]) continue;
      const ContactResult res = contact(c_.contact, d, r_[di], r_[dj], v_[di] - v_[dj], w_[di], w_[dj], 1.0 / (inv_mass(di) + inv_mass(dj)), 1.0 / (inv_inertia(di) + inv_inertia(dj)), h, 0.0);
      fn(i, j, res.force, d, dist);
    }
  }
}

// Sum over owned grains with centre height x_k in [lo, hi) of the grain stress moment
// -sum_c (x_c - x_i)_k f_k (compression positive), from the forces of the last step
// (springs not advanced). Collective.
double Engine::stress_moment(int k, double lo, double hi) {
  double s = 0;
  auto in = [&](long i) { return i >= 0 && i < nown_ && comp(x_[i], k) >= lo && comp(x_[i], k) < hi; };
  contacts_at_rest([&](long i, long j) { return in(i) || in(j); },
                   [&](long i, long j, const V3 &F, const V3 &d, double dist) {
                     // Grain j sees -d and -F: its moment -(r_j/dist) d_k F_k has the same sign.
                     if (in(i)) s -= (r_[i] / dist) * comp(d, k) * comp(F, k);
                     if (in(j)) s -= (r_[j] / dist) * comp(d, k) * comp(F, k);
                   });
  double g;
  MPI_Allreduce(&s, &g, 1, MPI_DOUBLE, MPI_SUM, comm_);
  return g;
}

// As stress_moment, per owned grain and for every component: the force F on the grain at the
// branch vector l from its centre to the contact, sum F (x) l symmetrised (xx yy zz xy yz xz).
// Local, no communication.
std::vector<std::array<double, 6>> Engine::dipoles() {
  std::vector<std::array<double, 6>> D((size_t)nown_, std::array<double, 6>{0, 0, 0, 0, 0, 0});
  auto add = [&](long i, const V3 &F, const V3 &l) {
    std::array<double, 6> &a = D[(size_t)i];
    a[0] += F.x * l.x;
    a[1] += F.y * l.y;
    a[2] += F.z * l.z;
    a[3] += 0.5 * (F.x * l.y + F.y * l.x);
    a[4] += 0.5 * (F.y * l.z + F.z * l.y);
    a[5] += 0.5 * (F.x * l.z + F.z * l.x);
  };
  auto own = [&](long i) { return i >= 0 && i < nown_; };
  contacts_at_rest([&](long i, long j) { return own(i) || own(j); },
                   [&](long i, long j, const V3 &F, const V3 &d, double dist) {
                     // j: force -F at branch -(r_j / dist) d, the same product (r_j / dist) F (x) d.
                     if (own(i)) add(i, F, (r_[i] / dist) * d);
                     if (own(j)) add(j, F, (r_[j] / dist) * d);
                   });
  return D;
}

} // namespace granmpm::dem
