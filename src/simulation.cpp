// Simulation<dim>: the parts of one step (P2G, grid update, G2P, constitutive update,
// migration) and step() itself. Set-up: setup.cpp; guards and backups: guards.cpp; load
// balance: balance.cpp; the run loop: run.cpp.
#include "granmpm/simulation.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "granmpm/implicit.hpp"

namespace granmpm {

namespace {
// G2P's reduction of {guard tripped, largest speed, kinetic energy} and, when the
// constitutive update ran inside G2P, {update failed, largest plastic rate, -smallest local
// limit}: the kinetic energy (entry 2) is summed, every other entry is a max.
void g2p_reduce(void *in, void *inout, int *len, MPI_Datatype *) {
  const double *a = static_cast<const double *>(in);
  double *b = static_cast<double *>(inout);
  for (int i = 0; i < *len; ++i) b[i] = i == 2 ? a[i] + b[i] : std::max(a[i], b[i]);
}
MPI_Op g2p_reduce_op() {
  static MPI_Op op = MPI_OP_NULL;
  if (op == MPI_OP_NULL) MPI_Op_create(&g2p_reduce, 1, &op);
  return op;
}
// The owned cell holding x, by local cell index (x fastest); clamped into the owned range
// (G2P runs after migration, so a particle is in an owned cell up to round-off).
template <int dim>
long owned_cell_index(const Grid<dim> &grid, const double *x) {
  long idx = 0, stride = 1;
  for (int d = 0; d < dim; ++d) {
    const int c = std::min(std::max(grid.cell_of(d, x[d]) - grid.xs[d], 0), grid.xm[d] - 1);
    idx += c * stride;
    stride *= grid.xm[d];
  }
  return idx;
}
} // namespace

// ---------------------------------------------------------------------------------------
// P2G

template <int dim>
template <class S>
void Simulation<dim>::p2g_impl(const S &sh, bool with_force) {
  NodeView<dim> g = grid.begin_local(true);
  ParticleView<dim> P = particles.get();
  const double h = grid.h;
  Stencil<dim, S> st;
  for (PetscInt p = 0; p < P.n; ++p) {
    st.compute(sh, P.x + p * dim, grid.x0, grid.inv_h);
    P2GInput<dim> in{P.m[p], P.vol[p], P.v + p * dim, P.C ? P.C + p * dim * dim : nullptr, with_force ? P.s + 6 * p : nullptr,
                     with_force ? body_acc_ : nullptr};
    p2g_particle(st, in, h, g);
  }
  particles.restore(P);
  grid.end_local();
  grid.local_to_global_add();
}

template <int dim>
void Simulation<dim>::p2g(bool with_force) {
  GM_CALL(PetscLogStagePush(st_p2g_));
  std::visit([&](const auto &s) { p2g_impl(s, with_force); }, shape);
  GM_CALL(PetscLogStagePop());
}

// ---------------------------------------------------------------------------------------
// Grid update: v_old = (mv)/m, v_new = v_old + dt f/m (with_force), boundary conditions on
// v_new. Stores [m, v_new, v_new - v_old] and scatters it to the ghosts.

template <int dim>
void Simulation<dim>::grid_update(double dt, bool with_force) {
  GM_CALL(PetscLogStagePush(st_grid_));
  NodeView<dim> g = grid.begin_global();
  bool bad = false;
  std::string msg;
  for (Module<dim> *m : modules_view()) m->begin_grid(*this, dt, with_force);
  const bool node_hooks = !this->node_modules.empty() || !this->constraint_modules.empty();
  const int k0 = grid.xs[2], k1 = dim == 3 ? grid.xs[2] + grid.xm[2] : 1;
  for (int k = k0; k < k1; ++k)
    for (int j = grid.xs[1]; j < grid.xs[1] + grid.xm[1]; ++j)
      for (int i = grid.xs[0]; i < grid.xs[0] + grid.xm[0]; ++i) {
        double *n = g.at(i, j, k);
        const double m = n[0];
        if (m <= m_min_) {
          for (int c = 1; c < Grid<dim>::NDOF; ++c) n[c] = 0;
          continue;
        }
        double vold[dim], vnew[dim];
        for (int d = 0; d < dim; ++d) {
          vold[d] = n[1 + d] / m;
          vnew[d] = vold[d];
          if (with_force) vnew[d] += dt * (n[1 + dim + d] / m - cfg.damping * vold[d]);
        }
        if (node_hooks) {
          const NodeAt a{i, j, k, {grid.node_x(0, i), grid.node_x(1, j), dim == 3 ? grid.node_x(2, k) : 0.0}, m};
          for (Module<dim> *mod : this->node_modules) mod->node(a, vnew, dt, with_force);
          this->constrain(a, vnew);
        }
        grid.apply_bc(i, j, k, vnew);
        for (int d = 0; d < dim; ++d) {
          n[1 + d] = vnew[d];
          n[1 + dim + d] = vnew[d] - vold[d];
          if (!std::isfinite(vnew[d]) && !bad) {
            bad = true;
            std::ostringstream o;
            o << "grid node (" << i << ", " << j << (dim == 3 ? ", " + std::to_string(k) : std::string()) << ") at x = " << grid.node_x(0, i) << ", y = " << grid.node_x(1, j)
              << " has a non-finite velocity at t = " << time << " (nodal mass " << m << "): the run is unstable; reduce -dt or -cfl" << hint_;
            msg = o.str();
          }
        }
      }
  grid.end_global();
  collective_fail(comm, bad, msg);
  for (Module<dim> *m : modules_view()) m->end_grid(*this, dt, with_force);
  grid.global_to_local();
  GM_CALL(PetscLogStagePop());
}

// ---------------------------------------------------------------------------------------
// G2P

// The message of the first guard G2P's particle loop tripped (same text as when it was
// built inside the loop): x is the position after the move.
template <int dim>
std::string Simulation<dim>::g2p_fault_text(const ParticleView<dim> &P, const G2PFault &f, double dt) const {
  const double *x = P.x + f.p * dim;
  std::ostringstream s;
  if (f.kind == G2PFault::Moved)
    s << "particle " << P.id[f.p] << " moved " << dt * std::sqrt(f.u2) / grid.h << " cells in one step at t = " << time << " (speed " << std::sqrt(f.u2) << " m/s, position";
  else
    s << "particle " << P.id[f.p] << " has a non-finite velocity at t = " << time << " (position";
  for (int d = 0; d < dim; ++d) s << " " << x[d];
  s << "): the run is unstable; reduce -dt or -cfl" << hint_;
  return s.str();
}

template <int dim>
template <class S>
void Simulation<dim>::g2p_impl(const S &sh, double dt, unsigned mode) {
  NodeView<dim> g = grid.begin_local(false);
  ParticleView<dim> P = particles.get();
  const double h = grid.h;
  const bool apic = P.C != nullptr, linear_C = std::is_same<S, LinearShape>::value;
  const double alpha = cfg.transfer == TransferKind::FLIP ? cfg.flip_alpha : 0.0;
  const bool cells = (mode & kL) && cfg.vol_cell_average;
  // Without the cell average, each chunk of particles is updated as soon as its L is known:
  // no n x dim^2 buffer of velocity gradients (issue 16: memory), and L still in cache.
  fused_ = (mode & kL) && !cells;
  fused_st_ = UpdateStats();
  if (mode & kL) Lbuf_.resize((size_t)(fused_ ? std::min<PetscInt>(P.n, kChunk) : P.n) * dim * dim);
  if (cells) cellbuf_.resize((size_t)P.n);
  if (mode & kStoreXv) xvel_.resize((size_t)P.n * dim);
  Stencil<dim, S> st;
  G2POutput<dim> o;
  double v2max = 0, ke = 0;
  PetscInt fastest = -1;
  // The loop only records the first particle that fails a guard (in particle order, the
  // move check before the finite check, as before); g2p_fault_text builds the message after it.
  G2PFault fault;
  for (PetscInt p = 0; p < P.n; ++p) {
    double *x = P.x + p * dim, *v = P.v + p * dim;
    st.compute(sh, x, grid.x0, grid.inv_h);
    // PIC and APIC (alpha = 0) need no FLIP increment; v = v_pic is what the FLIP blend gives
    // for alpha = 0 (bit for bit, finite values).
    if (alpha != 0) g2p_particle<dim, S, true>(st, h, g, o);
    else g2p_particle<dim, S, false>(st, h, g, o);
    if (mode & kVel)
      for (int d = 0; d < dim; ++d) v[d] = alpha != 0 ? alpha * (v[d] + o.dv[d]) + (1.0 - alpha) * o.v_pic[d] : o.v_pic[d];
    if ((mode & kC) && apic) apic_C(o, linear_C, P.C + p * dim * dim);
    if (mode & kL) {
      const size_t q = fused_ ? (size_t)(p % kChunk) : (size_t)p;
      for (int d = 0; d < dim; ++d)
        for (int e = 0; e < dim; ++e) Lbuf_[q * dim * dim + d * dim + e] = o.L[d][e];
    }
    if (cells) cellbuf_[p] = owned_cell_index(grid, x);
    if (mode & kStoreXv)
      for (int d = 0; d < dim; ++d) xvel_[(size_t)p * dim + d] = o.v_pic[d];
    if (mode & (kMove | kApplyXv)) {
      const double *u = (mode & kMove) ? o.v_pic : &xvel_[(size_t)p * dim];
      double u2 = 0;
      for (int d = 0; d < dim; ++d) {
        x[d] += dt * u[d];
        u2 += u[d] * u[d];
      }
      if (!(dt * dt * u2 <= h * h) && fault.p < 0) fault = G2PFault{p, G2PFault::Moved, u2}; // dt |u| <= h, no root
    }
    double s2 = 0;
    for (int d = 0; d < dim; ++d) s2 += v[d] * v[d];
    if (!std::isfinite(s2) && fault.p < 0) fault = G2PFault{p, G2PFault::NonFinite, 0};
    if (s2 > v2max) {
      v2max = s2;
      fastest = p;
    }
    ke += 0.5 * P.m[p] * s2;
    if (fused_ && (p % kChunk == kChunk - 1 || p == P.n - 1)) {
      GM_CALL(PetscLogStagePush(st_const_)); // its time still counts as Constitutive in -log_view
      update_chunk(P, p - p % kChunk, p + 1, dt, fused_st_);
      GM_CALL(PetscLogStagePop());
    }
  }
  std::string msg = fault.p >= 0 ? g2p_fault_text(P, fault, dt) : std::string();
  particles.restore(P);
  grid.end_local();
  // One reduction per pass for the guard, the largest speed and the kinetic energy: on
  // small scenes every collective is a synchronisation of the ranks, and they dominate the step.
  // The fused constitutive update's guard and step limits ride along (finish_constitutive).
  double vm = std::sqrt(v2max), all[6];
  double red[6] = {fault.p >= 0 ? 1.0 : 0.0, vm, ke, fused_st_.bad >= 0 ? 1.0 : 0.0, fused_st_.rate_max, -fused_st_.local_dt_min};
  MPI_Allreduce(red, all, fused_ ? 6 : 3, MPI_DOUBLE, g2p_reduce_op(), comm);
  if (fused_) std::copy(all + 3, all + 6, fused_all_);
  if (all[0] > 0) collective_fail(comm, fault.p >= 0, msg);
  vmax = all[1];
  if (mode & kVel) {
    energy_guard(all[2], vm, fastest);
    ke_ = all[2];
  }
}

template <int dim>
void Simulation<dim>::energy_guard(double ke_all, double vm, PetscInt fastest) {
  // Energy guard: kinetic energy beyond a multiple of all the energy the scene can supply
  // (initial kinetic and elastic energy, gravity's work) comes from an instability. (A
  // physical flow cannot multiply its kinetic energy by a large factor in one stable step;
  // below the floor, growth from rest is allowed.) vm: this rank's largest speed, at its
  // particle `fastest`.
  if (!(ke_all > cfg.energy_bound_factor * energy_bound_)) return;
  // Name the fastest particle: the rank holding it reports.
  struct {
    double v;
    int r;
  } mine{vm, rank}, top{0, 0};
  MPI_Allreduce(&mine, &top, 1, MPI_DOUBLE_INT, MPI_MAXLOC, comm);
  std::string fastest_text;
  if (rank == top.r && fastest >= 0) {
    ParticleView<dim> Q = particles.get();
    std::ostringstream f;
    f << "; the fastest particle is " << Q.id[fastest] << " at";
    for (int d = 0; d < dim; ++d) f << " " << Q.x[fastest * dim + d];
    f << " with speed " << vm << " m/s";
    fastest_text = f.str();
    particles.restore(Q);
  }
  std::ostringstream m;
  m << "the kinetic energy reached " << ke_all << " J at t = " << time << ", " << ke_all / energy_bound_
    << " times the energy the scene can supply (" << energy_bound_ << " J: initial kinetic + elastic energy + gravity's work" << (bodies ? " + rigid bodies' work" : "") << ")" << fastest_text
    << ": the run is unstable; reduce -dt or -cfl" << hint_ << " (or raise -energy_bound_factor if energy is supplied otherwise)";
  collective_fail(comm, rank == top.r, m.str());
}

template <int dim>
void Simulation<dim>::g2p(double dt, unsigned mode) {
  GM_CALL(PetscLogStagePush(st_g2p_));
  std::visit([&](const auto &s) { g2p_impl(s, dt, mode); }, shape);
  GM_CALL(PetscLogStagePop());
}

// ---------------------------------------------------------------------------------------
// Constitutive update from the velocity gradients of G2P: particles [begin, end), their L in
// Lbuf_ from its start. The material is chosen once (one virtual call per chunk); 2D embeds L
// in 3x3 with zero out-of-plane rows (plane strain: D_zz = 0, sigma_zz evolves through
// lambda tr D). G2P calls it per chunk of kChunk particles (fused_); constitutive() calls it
// once for all particles when -volumetric_average has to see every L first.

template <int dim>
void Simulation<dim>::update_chunk(ParticleView<dim> &P, PetscInt begin, PetscInt end, double dt, UpdateStats &st) {
  UpdateInputs in;
  in.L = Lbuf_.data();
  // Filled by the dynamical fluidity module for this step's particles; none: lap g = 0.
  in.lap_g = lapbuf_.size() >= (size_t)P.n ? lapbuf_.data() : nullptr;
  in.dt = dt;
  in.begin = begin;
  in.end = end;
  material->update(P, particles, in, st); // the model's particle loop (material.hpp)
}

template <int dim>
void Simulation<dim>::constitutive(double dt) {
  GM_CALL(PetscLogStagePush(st_const_));
  ParticleView<dim> P = particles.get();
  if (fused_) { // G2P has updated every particle (fused_st_); only the reports are left
    fused_ = false;
    finish_constitutive(P, fused_st_, fused_all_);
    GM_CALL(PetscLogStagePop());
    return;
  }
  if (cfg.vol_cell_average && cellbuf_.size() >= (size_t)P.n) {
    // B-bar-like: tr L of each particle -> the volume-weighted mean of its cell.
    long ncell = 1;
    for (int d = 0; d < dim; ++d) ncell *= grid.xm[d];
    std::vector<double> sum(2 * ncell, 0.0);
    for (PetscInt p = 0; p < P.n; ++p) {
      double tr = 0;
      for (int d = 0; d < dim; ++d) tr += Lbuf_[(size_t)p * dim * dim + d * dim + d];
      sum[2 * cellbuf_[p]] += P.vol[p] * tr;
      sum[2 * cellbuf_[p] + 1] += P.vol[p];
    }
    for (PetscInt p = 0; p < P.n; ++p) {
      double *l = &Lbuf_[(size_t)p * dim * dim], tr = 0;
      for (int d = 0; d < dim; ++d) tr += l[d * dim + d];
      const double avg = sum[2 * cellbuf_[p]] / sum[2 * cellbuf_[p] + 1];
      for (int d = 0; d < dim; ++d) l[d * dim + d] += (avg - tr) / dim;
    }
  }
  UpdateStats st;
  update_chunk(P, 0, P.n, dt, st);
  finish_constitutive(P, st);
  GM_CALL(PetscLogStagePop());
}

// The non-finite guard and the explicit schemes' step limit of one update pass (collective).
// reduced: {any rank failed, largest rate, -smallest local limit} already reduced with G2P's
// sums (fused update), or null: reduce here.
template <int dim>
void Simulation<dim>::finish_constitutive(ParticleView<dim> &P, const UpdateStats &st, const double *reduced) {
  std::string msg;
  if (st.bad >= 0) {
    const PetscInt p = st.bad;
    std::ostringstream m;
    m << "particle " << P.id[p] << " has a non-finite " << (std::isfinite(P.vol[p]) ? "stress" : "volume") << " at t = " << time << " (position";
    for (int d = 0; d < dim; ++d) m << " " << P.x[p * dim + d];
    m << "): the run is unstable; reduce -dt or -cfl" << hint_;
    msg = m.str();
  }
  particles.restore(P);
  if (!reduced || reduced[0] > 0) collective_fail(comm, st.bad >= 0, msg); // every rank knows whether to enter
  if (material->limits_dt()) {
    // Explicit schemes: the largest plastic rate and the smallest local limit, reduced.
    double mine[2] = {st.rate_max, -st.local_dt_min}, all[2] = {0, 0};
    if (reduced) std::copy(reduced + 1, reduced + 3, all);
    else MPI_Allreduce(mine, all, 2, MPI_DOUBLE, MPI_MAX, comm);
    plastic_limit = material->dt_limit(all[0], -all[1], grid.h);
  }
}

template <int dim>
void Simulation<dim>::migrate() {
  GM_CALL(PetscLogStagePush(st_migrate_));
  // The run loop's signal flags (handle_signals) and the modules' values for the next step
  // travel with the migration counts.
  std::vector<double> f = {(double)stop_signal, (double)checkpoint_signal};
  std::vector<int> cnt;
  for (Module<dim> *m : modules_view()) {
    double loc[Module<dim>::kAheadMax];
    cnt.push_back(m->reduce_ahead(*this, loc));
    f.insert(f.end(), loc, loc + cnt.back());
  }
  particles.migrate(grid, f.data(), (int)f.size());
  signals_[0] = (long)f[0], signals_[1] = (long)f[1];
  signals_reduced_ = true;
  size_t at = 2;
  for (size_t i = 0; i < cnt.size(); at += cnt[i++])
    if (cnt[i] > 0) modules_view()[i]->reduced_ahead(f.data() + at);
  GM_CALL(PetscLogStagePop());
}

template <int dim>
double Simulation<dim>::step(double dt) {
  const double gf = gravity_factor(time);
  for (int d = 0; d < dim; ++d) body_acc_[d] = cfg.gravity[d] * gf;
  for (Module<dim> *m : modules_view()) m->begin_step(*this, dt); // body poses, fluidity solves
  if (implicit) dt = implicit->advance(dt); // backward Euler: P2G, SNES, G2P, constitutive
  else switch (cfg.update) {
  case UpdateOrder::USL:
    p2g(true);
    grid_update(dt, true);
    g2p(dt, kVel | kC | kL | kMove);
    constitutive(dt);
    break;
  case UpdateOrder::USF:
    p2g(false);
    grid_update(dt, false);
    g2p(dt, kL);
    constitutive(dt);
    p2g(true);
    grid_update(dt, true);
    g2p(dt, kVel | kC | kMove);
    break;
  case UpdateOrder::MUSL:
    p2g(true);
    grid_update(dt, true);
    g2p(dt, kVel | kC | kStoreXv);
    p2g(false); // remap the updated particle momentum (old positions)
    grid_update(dt, false);
    g2p(dt, kL | kApplyXv); // velocity gradient from the remapped velocity
    constitutive(dt);
    break;
  }
  for (Module<dim> *m : modules_view()) m->end_step(*this, dt); // density rule, body motion
  migrate();
  time += dt;
  ++nsteps;
  return dt;
}

template class Simulation<2>;
template class Simulation<3>;

} // namespace granmpm
