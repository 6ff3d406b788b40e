// The parallel DEM engine: set-up, the time step, migration (rebuild), summaries.
// Grain store on a BASIC DMSwarm: swarm.cpp; ghosts and lists: halo.cpp; forces: forces.cpp.
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

Engine::Engine(MPI_Comm comm, const Config &cfg) : comm_(comm), c_(cfg) {
  MPI_Comm_rank(comm_, &rank_);
  MPI_Comm_size(comm_, &size_);
  c_.validate();
  nrot_ = c_.dim == 3 ? 3 : 1;
}

Engine::~Engine() {
  if (bcsv_) std::fclose(bcsv_);
  int fin = 0;
  MPI_Finalized(&fin);
  if (!fin)
    for (MPI_Datatype &t : gb_rtype_)
      if (t != MPI_BYTE) MPI_Type_free(&t);
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
  if (part_.owner) {
    const double xx[3] = {x.x, x.y, x.z};
    return part_.owner(xx);
  }
  int p[3] = {0, 0, 0};
  for (int k = 0; k < c_.dim; ++k) {
    int cidx = (int)std::floor((comp(x, k) - c_.lo[k]) / h_[k]);
    cidx = std::clamp(cidx, 0, M_[k] - 1);
    const auto &s = own_start_[k];
    p[k] = (int)(std::upper_bound(s.begin(), s.end(), cidx) - s.begin()) - 1;
  }
  return p[0] + P_[0] * (p[1] + P_[1] * p[2]);
}

double Engine::cut(int k, int p) const { return part_.owner ? part_.cut[k][p] : c_.lo[k] + own_start_[k][p] * h_[k]; }

V3 Engine::box_lo(int r) const {
  const int p[3] = {r % P_[0], (r / P_[0]) % P_[1], r / (P_[0] * P_[1])};
  V3 b{0, 0, 0};
  for (int k = 0; k < c_.dim; ++k) comp(b, k) = (p[k] == 0 && !c_.periodic[k]) ? -1e300 : cut(k, p[k]);
  return b;
}
V3 Engine::box_hi(int r) const {
  const int p[3] = {r % P_[0], (r / P_[0]) % P_[1], r / (P_[0] * P_[1])};
  V3 b{0, 0, 0};
  for (int k = 0; k < c_.dim; ++k) comp(b, k) = (p[k] == P_[k] - 1 && !c_.periodic[k]) ? 1e300 : cut(k, p[k] + 1);
  return b;
}

void Engine::setup() {
  if (!c_.bodies.empty()) {
    if (!bspec_.empty()) throw std::logic_error("dem::Engine: bodies from both Config::bodies and set_bodies");
    own_bodies_setup();
  }
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
  for (int code = 0; code < 27; ++code) // the periodic shifts a ghost can carry (shift_code)
    for (int k = 0, rest = code; k < 3; ++k, rest /= 3) {
      const double L = c_.hi[k] - c_.lo[k]; // as ghost_plan computes it: the same bits
      comp(shifts_[code], k) = rest % 3 == 1 ? 0.0 : (rest % 3 == 2 ? L : -L);
    }
  for (int k = 0; k < c_.dim; ++k)
    if (c_.periodic[k] && c_.hi[k] - c_.lo[k] < 2 * halo_ + 1e-12)
      throw UserError("the periodic direction " + std::string(1, "xyz"[k]) + " is shorter than twice the interaction range (" + std::to_string(2 * halo_) +
                      "): enlarge -dem_hi - -dem_lo or lower -dem_radius/-dem_skin");
  c_.contact.finalize();
  c_.wall.finalize();
  for (int f = 0; f <= 2 * c_.dim; ++f) { // the faces' laws: the wall's with their own mu and e
    wlaw_[f] = c_.wall;
    if (!std::isnan(c_.face_mu[f])) wlaw_[f].mu = c_.face_mu[f];
    if (!std::isnan(c_.face_e[f])) {
      wlaw_[f].e = c_.face_e[f];
      wlaw_[f].finalize();
    }
  }
  // Automatic time step from the lightest contact (two lightest grains, or one on a wall).
  const double mmin = c_.mass_weight_min * grain_mass(rmin);
  c_.contact.mean_mass_value = c_.wall.mean_mass_value = grain_mass(c_.radius);
  auto tc_of = [&](const ContactParams &p, double meff, double reff) {
    double kn = p.kn;
    if (p.law == Law::Hertz) kn *= std::sqrt(0.02 * reff * reff); // stiffness at 2% overlap
    // gamma_n = damp sqrt(kn m), m the effective (or the seed's mean) mass.
    const double mm = p.mean_mass ? 0.5 * p.mean_mass_value : meff;
    return contact_duration(kn, p.damp * std::sqrt(mm / meff), meff);
  };
  double tc = std::min(tc_of(c_.contact, 0.5 * mmin, 0.5 * rmin), tc_of(c_.wall, mmin, rmin));
  for (int f = 0; f <= 2 * c_.dim; ++f) {
    wlaw_[f].mean_mass_value = c_.wall.mean_mass_value;
    if (!std::isnan(c_.face_e[f])) tc = std::min(tc, tc_of(wlaw_[f], mmin, rmin));
  }
  tc_ = tc;
  if (c_.dt > 0) {
    if (c_.dt > tc / 5)
      throw UserError("-dem_dt " + std::to_string(c_.dt) + " is above t_c/5 = " + std::to_string(tc / 5) +
                      " (t_c the contact time of the lightest contact): lower -dem_dt or leave it to -dem_steps_per_contact");
    dt_ = c_.dt;
  } else
    dt_ = tc / c_.steps_per_contact;
  hstep_ = dt_;

  create_swarm();
  if (!c_.restart.empty()) {
    read_checkpoint(c_.restart);
    return;
  }
  bodies_at(t_);
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
  if (msg.empty() && !bspec_.empty()) check_bodies(msg);
  collective_fail(comm_, !msg.empty(), msg);
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
  for (size_t i = 0; i < drop_.size() && (long)i < nown_; ++i)
    if (drop_[i]) gone[i] = 2; // removed by a host (reweight), not through an outlet
  drop_.clear();
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
      if (gone[i] == 1) {
        ++removed_;
        removed_mass_ += 1.0 / inv_mass(i);
      }
      continue;
    }
    x_[keep] = x_[i];
    v_[keep] = v_[i];
    w_[keep] = w_[i];
    r_[keep] = r_[i];
    id_[keep] = id_[i];
    if (!theta_.empty()) theta_[keep] = theta_[i];
    if (!q_.empty()) q_[keep] = q_[i];
    if (!mw_.empty()) mw_[keep] = mw_[i];
    ++keep;
  }
  nown_ = keep;
  for (const GrainRecord &g : add_) { // a host's new grains (add_grains)
    const long k = nown_++;
    if ((long)x_.size() <= k) {
      x_.resize(k + 1);
      v_.resize(k + 1);
      w_.resize(k + 1);
      r_.resize(k + 1);
      id_.resize(k + 1);
    }
    if (c_.orientation && dim == 2 && (long)theta_.size() <= k) theta_.resize(k + 1);
    if (c_.orientation && dim == 3 && (long)q_.size() <= k) q_.resize(k + 1);
    if (c_.mass_weight && (long)mw_.size() <= k) mw_.resize(k + 1); // (empty on a rank without grains)
    x_[k] = {g.x[0], g.x[1], g.x[2]};
    v_[k] = {g.v[0], g.v[1], g.v[2]};
    w_[k] = {g.w[0], g.w[1], g.w[2]};
    r_[k] = g.r;
    id_[k] = g.id;
    if (c_.orientation && dim == 2) theta_[k] = 0;
    if (c_.orientation && dim == 3) q_[k] = Quat{}; // a host's new grain starts unrotated
    if (c_.mass_weight) mw_[k] = g.m / grain_mass(g.r);
  }
  add_.clear();
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

void Engine::inverse_masses(long i0, long n, double *__restrict im, double *__restrict ii) const {
  const double *__restrict r = r_.data() + i0;
  const double *__restrict mw = mw_.empty() ? nullptr : mw_.data() + i0;
  const double kI = c_.dim == 3 ? 0.4 : 0.5;
  // grain_mass(r) term by term: the constant factor first, as it evaluates left to right.
  const double g = c_.dim == 3 ? c_.density * 4.0 / 3.0 * M_PI : c_.density * M_PI;
  for (long k = 0; k < n; ++k) {
    const double m = (mw ? mw[k] : 1.0) * (c_.dim == 3 ? g * r[k] * r[k] * r[k] : g * r[k] * r[k]);
    im[k] = 1.0 / m;
    ii[k] = 1.0 / (kI * m * r[k] * r[k]);
  }
}

void Engine::step(double dt) {
  hstep_ = dt;
  double t0 = MPI_Wtime();
  const bool verlet = c_.integrator == Integrator::Verlet;
  double disp2 = 0;
  for (size_t q = 0; q < bimp_.size(); ++q) bimp_[q] += (verlet ? 0.5 * dt : dt) * bprev_[q]; // the first kick's share
  double im[kBlock], ii[kBlock];
  for (long i0 = 0; i0 < nown_; i0 += kBlock) {
    const long n = std::min(kBlock, nown_ - i0);
    inverse_masses(i0, n, im, ii);
    for (long k = 0; k < n; ++k) {
      const long i = i0 + k;
      if (verlet) {
        v_[i] = v_[i] + (0.5 * dt * im[k]) * f_[i];
        w_[i] = w_[i] + (0.5 * dt * ii[k]) * tq_[i];
        x_[i] = x_[i] + dt * v_[i];
      } else {
        x_[i] = x_[i] + dt * v_[i];
        v_[i] = v_[i] + (dt * im[k]) * f_[i];
        w_[i] = w_[i] + (dt * ii[k]) * tq_[i];
      }
      const V3 d = x_[i] - x0_[i];
      disp2 = std::max(disp2, dot(d, d));
    }
  }
  // The orientation turns with the spin the drift used (Verlet: the half-step spin),
  // exactly for a spin held over the step.
  if (c_.orientation && c_.dim == 2)
    for (long i = 0; i < nown_; ++i) theta_[i] += dt * w_[i].z;
  if (c_.orientation && c_.dim == 3) rotate_all(q_.data(), w_.data(), nown_, dt);
  double t1 = MPI_Wtime();
  tm_.integrate += t1 - t0;
  double g;
  MPI_Allreduce(&disp2, &g, 1, MPI_DOUBLE, MPI_MAX, comm_);
  bool stale = 4 * g > c_.skin * c_.skin;
  if (!bspec_.empty()) {
    bodies_at(t_ + dt);
    stale = stale || std::sqrt(g) + body_drift() > c_.skin;
  }
  if (stale) {
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
  kick_ = verlet ? 0.5 * dt : 0.0; // the velocities the force pass saw: v - kick_ im f
  double t2 = MPI_Wtime();
  tm_.force += t2 - t1;
  if (verlet) {
    for (long i0 = 0; i0 < nown_; i0 += kBlock) {
      const long n = std::min(kBlock, nown_ - i0);
      inverse_masses(i0, n, im, ii);
      for (long k = 0; k < n; ++k) {
        v_[i0 + k] = v_[i0 + k] + (0.5 * dt * im[k]) * f_[i0 + k];
        w_[i0 + k] = w_[i0 + k] + (0.5 * dt * ii[k]) * tq_[i0 + k];
      }
    }
    for (size_t q = 0; q < bimp_.size(); ++q) bimp_[q] += 0.5 * dt * bf_[q];
  }
  tm_.integrate += MPI_Wtime() - t2;
  t_ += dt;
  ++step_;
}

// A new host decomposition: the forces and torques of the last step (the next half kick's)
// and the contact counts travel with their grains, keyed by id; the springs go with the
// rebuild's migration.
void Engine::repartition(Partition p) {
  part_ = std::move(p);
  P_ = part_.P;
  rebuild_carrying_forces(false);
}

// rebuild() migrates positions, velocities and springs, but not the last step's forces,
// torques and contact counts, which the next half kick and the summary need: send them to
// the grain's owner after the rebuild, keyed by id, and put them back. Grains added by the
// rebuild (new_grains) have none: zero until the next force pass.
void Engine::rebuild_carrying_forces(bool new_grains) {
  struct Carry {
    int64_t id;
    V3 f, tq;
    int nc;
  };
  std::vector<std::vector<Carry>> out(size_);
  for (long i = 0; i < nown_; ++i) out[owner_rank(x_[i])].push_back({id_[i], f_[i], tq_[i], ncontact_[i]});
  std::vector<Carry> sbuf, got;
  std::vector<int> scnt(size_), rcnt;
  for (int r = 0; r < size_; ++r) {
    scnt[r] = (int)out[r].size();
    sbuf.insert(sbuf.end(), out[r].begin(), out[r].end());
  }
  alltoallv(comm_, sbuf, scnt, got, rcnt);
  rebuild();
  std::unordered_map<int64_t, size_t> at;
  for (size_t q = 0; q < got.size(); ++q) at[got[q].id] = q;
  for (long i = 0; i < nown_; ++i) {
    const auto it = at.find(id_[i]);
    if (it == at.end() && !new_grains) throw std::logic_error("dem::Engine: grain " + std::to_string(id_[i]) + " lost its forces in a repartition");
    const Carry c = it == at.end() ? Carry{id_[i], V3{}, V3{}, 0} : got[it->second];
    f_[i] = c.f;
    tq_[i] = c.tq;
    ncontact_[i] = c.nc;
  }
}

Summary Engine::summary() {
  Summary s;
  s.step = step_;
  s.t = t_;
  double loc[5] = {0, 0, 0, elastic_, 0};
  const V3 g{c_.gravity[0], c_.gravity[1], c_.gravity[2]};
  for (long i = 0; i < nown_; ++i) {
    const double m = 1.0 / inv_mass(i);
    loc[0] += 0.5 * m * dot(v_[i], v_[i]);
    loc[1] += 0.5 / inv_inertia(i) * dot(w_[i], w_[i]);
    loc[2] -= m * dot(g, x_[i]);
  }
  double glob[5];
  MPI_Allreduce(loc, glob, 4, MPI_DOUBLE, MPI_SUM, comm_);
  MPI_Allreduce(&max_overlap_, &glob[4], 1, MPI_DOUBLE, MPI_MAX, comm_);
  MPI_Allreduce(&removed_mass_, &s.removed_mass, 1, MPI_DOUBLE, MPI_SUM, comm_);
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
    g.m = 1.0 / inv_mass(i);
    const Quat o = orientation(i);
    g.q[0] = o.w;
    g.q[1] = o.x;
    g.q[2] = o.y;
    g.q[3] = o.z;
  }
  // Spring sums in the force's canonical order (walls, then partners in key order).
  {
    std::vector<double> hs(ntot_, 0.0);
    for (size_t q = 0; q < wf_.size(); ++q) hs[wg_[q]] += norm(whist_[q]);
    for (long p = 0, k = 0, q = 0; p < ntot_; ++p)
      for (const long end = q + nl_[p]; q < end; ++q) {
        const double h = nb_[q] < 0 ? norm(pool_[k++]) : 0.0;
        hs[ord_[p]] += h;
        hs[partner(nb_[q])] += h;
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

// Every container the engine keeps between steps, in bytes (capacities): what it holds,
// its category, and for the per-local-grain arrays the part that belongs to ghosts.
std::vector<Engine::Container> Engine::containers() const {
  const size_t ng = (size_t)(ntot_ - nown_);
  std::vector<Container> c;
  auto local = [&](const char *name, const char *ghost_name, size_t cap, size_t elem) { // owned grains then ghosts
    const size_t used = std::min(cap, (size_t)nown_ + ng), g = used > (size_t)nown_ ? (used - nown_) * elem : 0;
    c.push_back({name, "state", cap * elem - g});
    c.push_back({ghost_name, "ghosts", g});
  };
  local("x", "x_ghost", x_.capacity(), sizeof(V3));
  local("v", "v_ghost", v_.capacity(), sizeof(V3));
  local("omega", "omega_ghost", w_.capacity(), sizeof(V3));
  local("radius", "radius_ghost", r_.capacity(), sizeof(double));
  local("mass_weight", "mass_weight_ghost", mw_.capacity(), sizeof(double));
  local("id", "id_ghost", id_.capacity(), sizeof(int64_t));
  local("order", "order_ghost", ord_.capacity(), sizeof(int));
  local("keys", "keys_ghost", ckey_.capacity(), sizeof(int));
  c.push_back({"force", "state", f_.capacity() * sizeof(V3)});
  c.push_back({"torque", "state", tq_.capacity() * sizeof(V3)});
  c.push_back({"x_rebuild", "state", x0_.capacity() * sizeof(V3)});
  c.push_back({"orientation", "state", q_.capacity() * sizeof(Quat) + theta_.capacity() * sizeof(double)});
  c.push_back({"contacts", "state", ncontact_.capacity() * sizeof(uint16_t)});
  c.push_back({"ghost_shift", "ghosts", gcode_.capacity()});
  c.push_back({"send_index", "ghosts", send_idx_.capacity() * sizeof(int)});
  c.push_back({"ghost_buffer", "ghosts", gbuf_send_.capacity() * sizeof(V3)});
  c.push_back({"list_length", "lists", nl_.capacity() * sizeof(uint16_t)});
  c.push_back({"list_partner", "lists", nb_.capacity() * sizeof(int)});
  c.push_back({"spring_queue", "springs", carry_.capacity() * sizeof(V3)});
  c.push_back({"wall_grain", "lists", wg_.capacity() * sizeof(int)});
  c.push_back({"wall_face", "lists", wf_.capacity() * sizeof(int)});
  c.push_back({"springs", "springs", pool_.capacity() * sizeof(V3)});
  c.push_back({"wall_springs", "springs", whist_.capacity() * sizeof(V3)});
  return c;
}

std::string Engine::footprint() const {
  const double n = nown_ ? (double)nown_ : 1.0;
  const std::vector<Container> all = containers();
  double tot = 0, cat[4] = {0, 0, 0, 0};
  const char *names[4] = {"state", "ghosts", "lists", "springs"};
  std::string fields;
  char buf[160];
  for (const Container &c : all) {
    tot += c.bytes;
    for (int k = 0; k < 4; ++k)
      if (c.category == names[k]) cat[k] += c.bytes;
    if (c.bytes == 0) continue;
    std::snprintf(buf, sizeof buf, "%s%s %.1f", fields.empty() ? "" : ", ", c.name, c.bytes / n);
    fields += buf;
  }
  char head[240];
  std::snprintf(head, sizeof head, "%.0f bytes/grain (grain state %.0f, lists %.0f, springs %.0f, ghosts %.0f; %.2f list entries, %.2f springs, %.2f ghosts per grain)\n", tot / n,
                cat[0] / n, cat[2] / n, cat[3] / n, cat[1] / n, nb_.size() / n, (double)pool_.size() / n, (ntot_ - nown_) / n);
  return std::string(head) + "dem: footprint per container (bytes/grain): " + fields;
}

size_t Engine::bytes_per_grain() const {
  size_t b = 0;
  for (const Container &c : containers()) b += c.bytes;
  return nown_ ? b / nown_ : 0;
}

} // namespace granmpm::dem

namespace granmpm::dem {

void Engine::reweight(const std::vector<double> &w) {
  if (!c_.mass_weight || !part_.owner || (long)w.size() != nown_)
    throw std::logic_error("dem::Engine::reweight: needs a host partition, Config::mass_weight and one weight per owned grain");
  drop_.assign(nown_, 0);
  for (long i = 0; i < nown_; ++i) {
    if (w[i] > 0) mw_[i] = w[i];
    else drop_[i] = 1;
  }
  repartition(part_); // carries f, tq, contact counts by id through the rebuild (drops, ghost masses)
}

} // namespace granmpm::dem

namespace granmpm::dem {

void Engine::add_grains(const std::vector<GrainRecord> &g) {
  if (!c_.mass_weight || !part_.owner) throw std::logic_error("dem::Engine::add_grains: needs a host partition and Config::mass_weight");
  add_ = g;
  rebuild_carrying_forces(true);
}

} // namespace granmpm::dem
