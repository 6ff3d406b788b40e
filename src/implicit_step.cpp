// ImplicitSolver<dim>: one implicit step (advance: the nodes of the start of the step, the
// SNES solve with dt halvings, the commit through StepOps) and its reports. The residual,
// the trial stresses and the preconditioner are in implicit.cpp.
#include "granmpm/implicit.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "granmpm/fluidity.hpp"
#include "granmpm/simulation.hpp"
#include "implicit_cells.hpp"

namespace granmpm {

template <int dim>
bool ImplicitSolver<dim>::solve(double dt) {
  dt_ = dt;
  if (!user_atol_) {
    const double scale = force_scale();
    GM_CALL(SNESSetTolerances(snes_, sim_.cfg.implicit.force_tol * (scale > 0 ? scale : 1.0), PETSC_DEFAULT, PETSC_DEFAULT, PETSC_DEFAULT, PETSC_DEFAULT));
  }
  // Initial guess: the P2G velocity (zero on Dirichlet dofs).
  double *v;
  GM_CALL(VecGetArray(v_, &v));
  for (size_t q = 0; q < vn_.size(); ++q) v[q] = fixed_[q] ? 0.0 : vn_[q];
  GM_CALL(VecRestoreArray(v_, &v));
  GM_CALL(SNESSolve(snes_, NULL, v_));
  SNESConvergedReason reason;
  GM_CALL(SNESGetConvergedReason(snes_, &reason));
  GM_CALL(SNESGetIterationNumber(snes_, &last_snes_its));
  GM_CALL(SNESGetLinearSolveIterations(snes_, &last_ksp_its));
  snes_its_total += last_snes_its;
  ksp_its_total += last_ksp_its;
  if (reason < 0) {
    ++failures;
    std::ostringstream m;
    m << SNESConvergedReasons[reason];
    if (reason == SNES_DIVERGED_LINEAR_SOLVE) {
      KSP ksp;
      KSPConvergedReason kr;
      GM_CALL(SNESGetKSP(snes_, &ksp));
      GM_CALL(KSPGetConvergedReason(ksp, &kr));
      m << " (KSP " << KSPConvergedReasons[kr] << ")";
    }
    m << " after " << last_snes_its << " Newton iterations with dt = " << dt;
    last_failure_ = m.str();
  }
  return reason > 0;
}

template <int dim>
void ImplicitSolver<dim>::commit(double dt) {
  Grid<dim> &G = sim_.grid;
  const double *v;
  GM_CALL(VecGetArrayRead(v_, &v));
  NodeView<dim> g = G.begin_global();
  const int k0 = G.xs[2], k1 = dim == 3 ? G.xs[2] + G.xm[2] : 1;
  size_t n = 0;
  for (int k = k0; k < k1; ++k)
    for (int j = G.xs[1]; j < G.xs[1] + G.xm[1]; ++j)
      for (int i = G.xs[0]; i < G.xs[0] + G.xm[0]; ++i, ++n) {
        double *a = g.at(i, j, k);
        for (int d = 0; d < dim; ++d) {
          const bool empty = a[0] <= m_min_;
          a[1 + d] = empty ? 0.0 : v[n * nd_ + d];
          a[1 + dim + d] = empty ? 0.0 : v[n * nd_ + d] - vn_[n * nd_ + d];
        }
      }
  G.end_global();
  G.global_to_local();
  // The converged g to the particles at their start-of-step positions (as in the residual),
  // where the constitutive update below reads it.
  if (coupled_) fluidity_to_particles();
  using S = StepOps<dim>;
  const double theta = sim_.cfg.implicit.theta;
  if (theta == 1.0) {
    ops_.g2p(dt, S::kVel | S::kC | S::kL | S::kMove);
  } else {
    // Velocity (and APIC matrix) from v_{n+1}; L and the motion from v_theta.
    ops_.g2p(dt, S::kVel | S::kC);
    g = G.begin_global();
    n = 0;
    for (int k = k0; k < k1; ++k)
      for (int j = G.xs[1]; j < G.xs[1] + G.xm[1]; ++j)
        for (int i = G.xs[0]; i < G.xs[0] + G.xm[0]; ++i, ++n) {
          double *a = g.at(i, j, k);
          for (int d = 0; d < dim; ++d) {
            const size_t q = n * nd_ + d;
            a[1 + d] = a[0] <= m_min_ ? 0.0 : theta * v[q] + (1.0 - theta) * (fixed_[q] ? 0.0 : vn_[q]);
          }
        }
    G.end_global();
    G.global_to_local();
    ops_.g2p(dt, S::kL | S::kMove);
  }
  GM_CALL(VecRestoreArrayRead(v_, &v));
  ops_.constitutive(dt);
}

template <int dim>
void ImplicitSolver<dim>::fluidity_to_particles() {
  const Grid<dim> &G = sim_.grid;
  GM_CALL(DMGlobalToLocalBegin(vda_, v_, INSERT_VALUES, vloc_));
  GM_CALL(DMGlobalToLocalEnd(vda_, v_, INSERT_VALUES, vloc_));
  const double *va;
  GM_CALL(VecGetArrayRead(vloc_, &va));
  auto lidx = [&](const int *n) { return ((long)(n[2] - G.gxs[2]) * G.gxm[1] + (n[1] - G.gxs[1])) * G.gxm[0] + (n[0] - G.gxs[0]); };
  ParticleView<dim> P = sim_.particles.get();
  Q1Cell<dim> q1;
  for (PetscInt p = 0; p < P.n; ++p) {
    q1.fill(G, P.x + p * dim);
    P.g[p] = q1.value(sim_.cfg.fluidity_map, [&](int a) { return va[nd_ * lidx(q1.nid[a]) + dim]; });
  }
  sim_.particles.restore(P);
  GM_CALL(VecRestoreArrayRead(vloc_, &va));
}

// The start of a step on the owned nodes: mass, v_n from the P2G momentum, the Dirichlet
// dofs (empty nodes, the modules' constraints, the walls); returns the mean nodal mass.
template <int dim>
double ImplicitSolver<dim>::prepare_nodes() {
  Grid<dim> &G = sim_.grid;
  const size_t nn = (size_t)G.xm[0] * G.xm[1] * G.xm[2];
  mass_.assign(nn, 0.0);
  vn_.assign(nn * nd_, 0.0);
  fixed_.assign(nn * nd_, 0);
  double msum = 0, mcount = 0;
  NodeView<dim> g = G.begin_global();
  const int k0 = G.xs[2], k1 = dim == 3 ? G.xs[2] + G.xm[2] : 1;
  size_t n = 0;
  for (int k = k0; k < k1; ++k)
    for (int j = G.xs[1]; j < G.xs[1] + G.xm[1]; ++j)
      for (int i = G.xs[0]; i < G.xs[0] + G.xm[0]; ++i, ++n) {
        const double *a = g.at(i, j, k);
        if (a[0] <= m_min_) {
          for (int d = 0; d < dim; ++d) fixed_[n * nd_ + d] = 1;
          continue;
        }
        mass_[n] = a[0];
        msum += a[0];
        mcount += 1;
        double t[3] = {1, 1, 1};
        const NodeAt at{i, j, k, {G.node_x(0, i), G.node_x(1, j), dim == 3 ? G.node_x(2, k) : 0.0}, a[0]};
        sim_.constrain(at, t); // the modules' constraints (silo plate), then the walls
        G.apply_bc(i, j, k, t); // frictionless walls: a projection; zeroed components are fixed
        for (int d = 0; d < dim; ++d) {
          vn_[n * nd_ + d] = a[1 + d] / a[0];
          fixed_[n * nd_ + d] = t[d] == 0.0;
        }
      }
  G.end_global();
  double loc[2] = {msum, mcount}, glob[2];
  MPI_Allreduce(loc, glob, 2, MPI_DOUBLE, MPI_SUM, sim_.comm);
  return glob[1] > 0 ? glob[0] / glob[1] : 1.0;
}

// Coupled: the active fluidity nodes, corners of the cells that hold particles (as
// FluiditySolver), with the last converged g (gprev) as this step's guess.
template <int dim>
void ImplicitSolver<dim>::prepare_fluidity_nodes(const std::vector<double> &gprev) {
  Grid<dim> &G = sim_.grid;
  GM_CALL(VecZeroEntries(floc_));
  double *fa;
  GM_CALL(VecGetArray(floc_, &fa));
  ParticleView<dim> P = sim_.particles.get();
  Q1Cell<dim> q1;
  for (PetscInt p = 0; p < P.n; ++p) {
    q1.fill(G, P.x + p * dim);
    for (int a = 0; a < Q1Cell<dim>::NN; ++a) {
      const int *c = q1.nid[a];
      fa[nd_ * (((long)(c[2] - G.gxs[2]) * G.gxm[1] + (c[1] - G.gxs[1])) * G.gxm[0] + (c[0] - G.gxs[0])) + dim] = 1.0;
    }
  }
  sim_.particles.restore(P);
  GM_CALL(VecRestoreArray(floc_, &fa));
  sum_ghosted_into_r();
  const double *act;
  GM_CALL(VecGetArrayRead(r_, &act));
  for (size_t n = 0; n < gprev.size(); ++n) {
    const size_t q = n * nd_ + dim;
    fixed_[q] = act[q] == 0.0;
    vn_[q] = fixed_[q] ? 0.0 : gprev[n];
  }
  GM_CALL(VecRestoreArrayRead(r_, &act));
}

// values[q] (or 0 where fixed, if zero_fixed) of every owned dof, ghosted into `local`.
template <int dim>
void ImplicitSolver<dim>::owned_to_local(Vec local, bool fixed_mask) {
  double *f;
  GM_CALL(VecGetArray(r_, &f));
  for (size_t q = 0; q < fixed_.size(); ++q) f[q] = fixed_mask ? (double)fixed_[q] : (fixed_[q] ? 0.0 : vn_[q]);
  GM_CALL(VecRestoreArray(r_, &f));
  GM_CALL(DMGlobalToLocalBegin(vda_, r_, INSERT_VALUES, local));
  GM_CALL(DMGlobalToLocalEnd(vda_, r_, INSERT_VALUES, local));
}

template <int dim>
double ImplicitSolver<dim>::advance(double dt) {
  Grid<dim> &G = sim_.grid;
  const ImplicitParams &ip = sim_.cfg.implicit;
  if (steps == 0 && dt_min_ == 0) dt_min_ = ip.dt_min > 0 ? ip.dt_min : 1e-4 * dt;
  // Mass and momentum of the start of the step, v_n and the Dirichlet dofs.
  ops_.p2g(false);
  const size_t nn = (size_t)G.xm[0] * G.xm[1] * G.xm[2];
  std::vector<double> gprev;
  if (coupled_) {
    // The last converged g (zero at the start) is the initial guess of this step's.
    const double *v;
    GM_CALL(VecGetArrayRead(v_, &v));
    gprev.resize(nn);
    for (size_t n = 0; n < nn; ++n) gprev[n] = v[n * nd_ + dim];
    GM_CALL(VecRestoreArrayRead(v_, &v));
  }
  const double mavg = prepare_nodes();
  if (coupled_) prepare_fluidity_nodes(gprev);
  owned_to_local(fixloc_, true);
  if (ip.theta != 1.0) owned_to_local(vnloc_, false); // v_n with the boundary conditions, for v_theta
  last_retries = 0;
  for (;;) {
    diag_ = mavg / dt; // Dirichlet rows scaled like the mass rows
    sg_ = diag_ * G.h / std::pow(G.h, dim); // fluidity rows: dg weighs like a velocity error h dg / 2
    if (solve(dt)) break;
    std::ostringstream m;
    m << "the implicit step at t = " << sim_.time << " did not converge (" << last_failure_ << ")";
    if (!ip.dt_adapt)
      throw UserError(m.str() + "; reduce -dt, enable -implicit_dt_adapt, or tune the solver (-implicit_snes_*, -implicit_ksp_*, -implicit_pc_type)");
    if (last_retries >= ip.max_retries)
      throw UserError(m.str() + " after " + std::to_string(last_retries) +
                      " halvings of dt; raise -implicit_max_retries, reduce -dt, or tune the solver (-implicit_snes_*, -implicit_ksp_*, -implicit_pc_type)");
    if (0.5 * dt < dt_min_) {
      std::ostringstream s;
      s << m.str() << "; halving dt would go below -implicit_dt_min = " << dt_min_ << " s: reduce -implicit_dt_min, or tune the solver (-implicit_snes_*, -implicit_ksp_*, -implicit_pc_type)";
      throw UserError(s.str());
    }
    dt *= 0.5; // nothing was committed: the particles still hold the start of the step
    ++last_retries;
  }
  commit(dt);
  ++steps;
  next_dt_ = dt;
  if (ip.dt_adapt && last_retries == 0 && last_snes_its <= ip.grow_its) next_dt_ = dt * ip.grow_factor;
  if (ip.dt_adapt && ip.dt_max > 0) next_dt_ = std::min(next_dt_, ip.dt_max);
  return dt;
}

template <int dim>
double ImplicitSolver<dim>::next_dt(double dt0) const {
  if (!sim_.cfg.implicit.dt_adapt || next_dt_ <= 0) return dt0;
  return next_dt_;
}

template <int dim>
std::string ImplicitSolver<dim>::progress() const {
  std::ostringstream s;
  s << "  SNES " << last_snes_its << " its (KSP " << last_ksp_its << ")";
  if (last_retries) s << ", " << last_retries << " retries";
  return s.str();
}

template <int dim>
std::string ImplicitSolver<dim>::summary() const {
  std::ostringstream s;
  s << (coupled_ ? "implicit_coupled: " : "implicit: ") << steps << " steps, " << snes_its_total << " Newton and " << ksp_its_total << " Krylov iterations in all ("
    << (steps ? (double)snes_its_total / steps : 0.0) << " and " << (steps ? (double)ksp_its_total / steps : 0.0) << " per step), " << failures
    << " failed solves retried";
  return s.str();
}

#define GM_INSTANTIATE(d) \
  template bool ImplicitSolver<d>::solve(double); \
  template void ImplicitSolver<d>::commit(double); \
  template void ImplicitSolver<d>::fluidity_to_particles(); \
  template double ImplicitSolver<d>::prepare_nodes(); \
  template void ImplicitSolver<d>::prepare_fluidity_nodes(const std::vector<double> &); \
  template void ImplicitSolver<d>::owned_to_local(Vec, bool); \
  template double ImplicitSolver<d>::advance(double); \
  template double ImplicitSolver<d>::next_dt(double) const; \
  template std::string ImplicitSolver<d>::progress() const; \
  template std::string ImplicitSolver<d>::summary() const;
GM_INSTANTIATE(2)
GM_INSTANTIATE(3)
#undef GM_INSTANTIATE

} // namespace granmpm
