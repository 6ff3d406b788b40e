#include "granmpm/implicit.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <type_traits>

#include "granmpm/fluidity.hpp"
#include "granmpm/materials/nonlocal_ngf.hpp"
#include "granmpm/simulation.hpp"
#include "implicit_cells.hpp"

namespace granmpm {

template <int dim>
ImplicitSolver<dim>::ImplicitSolver(State<dim> &sim, StepOps<dim> &ops)
    : sim_(sim), ops_(ops), acc_(ops.body_acceleration()), m_min_(ops.min_node_mass()) {
  // coupled: dim + 1 dofs per node, the last one g (its Q1 stencil needs only width 1).
  coupled_ = sim.cfg.time_integrator == TimeIntegrator::ImplicitCoupled;
  nd_ = coupled_ ? dim + 1 : dim;
  kf_ = nonlocal_k(sim.cfg.gran); // (A d)^2, formed by the material header
  create_objects();
}

template <int dim>
void ImplicitSolver<dim>::rebuild() {
  // The grid was re-partitioned. implicit_coupled keeps the last converged g in v_ as the
  // next solve's initial guess: carry it over, so balancing changes nothing but the layout.
  DM old_da = vda_;
  Vec old_v = v_;
  GM_CALL(PetscObjectReference((PetscObject)old_da));
  GM_CALL(PetscObjectReference((PetscObject)old_v));
  destroy_objects();
  create_objects();
  if (coupled_) copy_across_layouts(sim_.comm, old_da, old_v, vda_, v_);
  GM_CALL(VecDestroy(&old_v));
  GM_CALL(DMDestroy(&old_da));
}

template <int dim>
void ImplicitSolver<dim>::create_objects() {
  State<dim> &sim = sim_;
  // Same ownership, periodicity and BOX stencil width 2 as the transfer grid, dof = nd_.
  GM_CALL(DMDACreateCompatibleDMDA(sim.grid.da, nd_, &vda_));
  GM_CALL(DMCreateGlobalVector(vda_, &v_));
  GM_CALL(VecDuplicate(v_, &r_));
  GM_CALL(DMCreateLocalVector(vda_, &vloc_));
  GM_CALL(VecDuplicate(vloc_, &floc_));
  GM_CALL(VecDuplicate(vloc_, &fixloc_));
  GM_CALL(VecDuplicate(vloc_, &vnloc_));
  GM_CALL(DMCreateMatrix(vda_, &P_)); // full width-2 box pattern (explicit zeros), kept for the run
  GM_CALL(MatSetOption(P_, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));
  GM_CALL(SNESCreate(sim.comm, &snes_));
  GM_CALL(SNESSetOptionsPrefix(snes_, "implicit_"));
  GM_CALL(SNESSetType(snes_, SNESNEWTONLS));
  GM_CALL(SNESSetFunction(snes_, r_, form_function, this));
  GM_CALL(SNESSetJacobian(snes_, P_, P_, form_jacobian, this));
  // Default: J by finite differences (-implicit_snes_mf_operator), P assembled.
  GM_CALL(SNESSetUseMatrixFree(snes_, sim.cfg.implicit.assembled_jacobian ? PETSC_FALSE : PETSC_TRUE, PETSC_FALSE));
  // Matrix-free Krylov iterations each cost one residual: no cap on residual evaluations.
  GM_CALL(SNESSetTolerances(snes_, PETSC_DEFAULT, PETSC_DEFAULT, PETSC_DEFAULT, PETSC_DEFAULT, 100000000));
  KSP ksp;
  GM_CALL(SNESGetKSP(snes_, &ksp));
  GM_CALL(KSPSetType(ksp, KSPGMRES)); // coupled: see docs/implicit.md for GMRES against FGMRES
  GM_CALL(SNESSetFromOptions(snes_));
  PetscBool set = PETSC_FALSE;
  GM_CALL(PetscOptionsHasName(NULL, "implicit_", "-snes_atol", &set));
  user_atol_ = set;
}

template <int dim>
ImplicitSolver<dim>::~ImplicitSolver() {
  destroy_objects();
}

template <int dim>
void ImplicitSolver<dim>::destroy_objects() {
  SNESDestroy(&snes_);
  MatDestroy(&P_);
  VecDestroy(&v_);
  VecDestroy(&r_);
  VecDestroy(&vloc_);
  VecDestroy(&floc_);
  VecDestroy(&fixloc_);
  VecDestroy(&vnloc_);
  DMDestroy(&vda_);
}

template <int dim>
PetscErrorCode ImplicitSolver<dim>::form_function(SNES, Vec V, Vec R, void *ctx) {
  // Exceptions must not cross PETSc's C frames: report them as a PETSc error instead.
  try {
    static_cast<ImplicitSolver *>(ctx)->residual(V, R);
  } catch (const std::exception &e) {
    SETERRQ(PETSC_COMM_SELF, PETSC_ERR_LIB, "%s", e.what());
  }
  return 0;
}

template <int dim>
PetscErrorCode ImplicitSolver<dim>::form_jacobian(SNES, Vec X, Mat J, Mat P, void *ctx) {
  try {
    static_cast<ImplicitSolver *>(ctx)->assemble_preconditioner(X, P);
    if (J != P) {
      // The finite-difference operator: re-base it at the current iterate.
      GM_CALL(MatAssemblyBegin(J, MAT_FINAL_ASSEMBLY));
      GM_CALL(MatAssemblyEnd(J, MAT_FINAL_ASSEMBLY));
    }
  } catch (const std::exception &e) {
    SETERRQ(PETSC_COMM_SELF, PETSC_ERR_LIB, "%s", e.what());
  }
  return 0;
}

// ---------------------------------------------------------------------------------------
// Residual: particle loop for f_int (ghosted, then LocalToGlobal ADD), then the nodal terms.

template <int dim>
template <class S>
void ImplicitSolver<dim>::residual_impl(const S &sh, const double *va, double *fa, double dt_stress, bool absval) {
  const Grid<dim> &G = sim_.grid;
  ParticleView<dim> P = sim_.particles.get();
  Stencil<dim, S> st;
  NodeSet<dim, S> ns;
  Q1Cell<dim> q1;
  constexpr int NQ = Q1Cell<dim>::NN;
  double Ke[NQ * NQ], fe[NQ];
  const int nd = nd_;
  const bool fl = coupled_ && dt_stress > 0; // the fluidity rows (not for the force scale)
  auto lidx = [&](const int *n) { return ((long)(n[2] - G.gxs[2]) * G.gxm[1] + (n[1] - G.gxs[1])) * G.gxm[0] + (n[0] - G.gxs[0]); };
  if (dt_stress > 0) trial_stresses(sh, P, va, dt_stress);
  for (PetscInt p = 0; p < P.n; ++p) {
    st.compute(sh, P.x + p * dim, G.x0, G.inv_h);
    ns.fill(st);
    Mat3 sig;
    if (dt_stress > 0) {
      sig = tsig_[p];
      if (fl) {
        q1.fill(G, P.x + p * dim);
        // This particle's share of K(w) g - f(w, g_loc), w and g_loc from the trial stress.
        const FluiditySource src = fluidity_source(sim_.cfg.gran, sig);
        std::fill(Ke, Ke + NQ * NQ, 0.0);
        std::fill(fe, fe + NQ, 0.0);
        fluidity_element_contribution<dim>(q1.xi, G.h, P.vol[p], src.weight, src.g_loc, kf_, Ke, fe);
        for (int a = 0; a < NQ; ++a) {
          double r = -fe[a];
          for (int b = 0; b < NQ; ++b) r += Ke[a * NQ + b] * va[nd * lidx(q1.nid[b]) + dim];
          fa[nd * lidx(q1.nid[a]) + dim] += r;
        }
      }
    } else
      sig = sym6_to_mat(P.s + 6 * p);
    for (int a = 0; a < ns.NN; ++a) {
      double *f = fa + nd * lidx(ns.nid[a]);
      for (int d = 0; d < dim; ++d) {
        double s = 0;
        for (int e = 0; e < dim; ++e) s += absval ? std::fabs(sig(d, e) * ns.grad[a][e]) : sig(d, e) * ns.grad[a][e];
        f[d] -= P.vol[p] * s;
      }
    }
  }
  sim_.particles.restore(P);
}

// The material's stress after dt at every particle from its start-of-step stress and the
// velocity gradient of the nodal velocities va (coupled: with the fluidity of va's g dof),
// without touching the particles (Simulation::constitutive commits with the same inputs):
// the gradients of all particles first, then one call of the model's loop.
template <int dim>
template <class S>
void ImplicitSolver<dim>::trial_stresses(const S &sh, const ParticleView<dim> &P, const double *va, double dt) {
  const Grid<dim> &G = sim_.grid;
  Stencil<dim, S> st;
  NodeSet<dim, S> ns;
  Q1Cell<dim> q1;
  const int nd = nd_;
  auto lidx = [&](const int *n) { return ((long)(n[2] - G.gxs[2]) * G.gxm[1] + (n[1] - G.gxs[1])) * G.gxm[0] + (n[0] - G.gxs[0]); };
  tL_.resize(P.n);
  tsig_.resize(P.n);
  tg_.assign(P.n, 0.0);
  for (PetscInt p = 0; p < P.n; ++p) {
    st.compute(sh, P.x + p * dim, G.x0, G.inv_h);
    ns.fill(st);
    Mat3 L = Mat3::Zero();
    for (int a = 0; a < ns.NN; ++a) {
      const double *v = va + nd * lidx(ns.nid[a]);
      for (int d = 0; d < dim; ++d)
        for (int e = 0; e < dim; ++e) L(d, e) += v[d] * ns.grad[a][e];
    }
    tL_[p] = L;
    if (coupled_) {
      q1.fill(G, P.x + p * dim);
      tg_[p] = q1.value(sim_.cfg.fluidity_map, [&](int a) { return va[nd * lidx(q1.nid[a]) + dim]; });
    }
  }
  sim_.material->trial(P.n, P.s, tL_.data(), P.m, P.vol, tg_.data(), dt, tsig_.data());
}

// vloc_ = v_theta = theta V + (1 - theta) v_n, ghosted.
template <int dim>
void ImplicitSolver<dim>::theta_velocity_to_local(Vec V) {
  GM_CALL(DMGlobalToLocalBegin(vda_, V, INSERT_VALUES, vloc_));
  GM_CALL(DMGlobalToLocalEnd(vda_, V, INSERT_VALUES, vloc_));
  const double theta = sim_.cfg.implicit.theta;
  if (theta != 1.0) GM_CALL(VecAXPBY(vloc_, 1.0 - theta, theta, vnloc_));
}

template <int dim>
void ImplicitSolver<dim>::residual(Vec V, Vec R) {
  const double theta = sim_.cfg.implicit.theta;
  theta_velocity_to_local(V);
  GM_CALL(VecZeroEntries(floc_));
  const double *va;
  double *fa;
  GM_CALL(VecGetArrayRead(vloc_, &va));
  GM_CALL(VecGetArray(floc_, &fa));
  std::visit([&](const auto &s) { residual_impl(s, va, fa, theta * dt_, false); }, sim_.shape);
  GM_CALL(VecRestoreArrayRead(vloc_, &va));
  GM_CALL(VecRestoreArray(floc_, &fa));
  GM_CALL(VecZeroEntries(R));
  GM_CALL(DMLocalToGlobalBegin(vda_, floc_, ADD_VALUES, R));
  GM_CALL(DMLocalToGlobalEnd(vda_, floc_, ADD_VALUES, R));
  // R holds f_int; complete R = m (v - v_n)/dt + c m v - m b - f_int, Dirichlet rows s v.
  const double *v;
  double *r;
  GM_CALL(VecGetArrayRead(V, &v));
  GM_CALL(VecGetArray(R, &r));
  const size_t nn = mass_.size();
  const double c = sim_.cfg.damping;
  for (size_t n = 0; n < nn; ++n) {
    for (int d = 0; d < dim; ++d) {
      const size_t q = n * nd_ + d;
      if (fixed_[q]) r[q] = diag_ * v[q];
      else r[q] = mass_[n] * ((v[q] - vn_[q]) / dt_ + c * v[q] - acc_[d]) - r[q];
    }
    if (coupled_) {
      // Fluidity row: scaled Galerkin residual; inactive nodes g = 0.
      const size_t q = n * nd_ + dim;
      r[q] = fixed_[q] ? sg_ * std::pow(sim_.grid.h, dim) * v[q] : sg_ * r[q];
    }
  }
  GM_CALL(VecRestoreArrayRead(V, &v));
  GM_CALL(VecRestoreArray(R, &r));
}

// Norm of |M v_n/dt| + |M b| + sum_p V_p |sigma_n grad N| over the free dofs: the force
// scale of the step, for the absolute SNES tolerance (absolute values per particle, so that
// balanced stresses, e.g. a uniform pressure at rest, still set a scale above round-off).
// r_ = the owned sums of floc_'s ghosted contributions (particle loops add into ghosts).
template <int dim>
void ImplicitSolver<dim>::sum_ghosted_into_r() {
  GM_CALL(VecZeroEntries(r_));
  GM_CALL(DMLocalToGlobalBegin(vda_, floc_, ADD_VALUES, r_));
  GM_CALL(DMLocalToGlobalEnd(vda_, floc_, ADD_VALUES, r_));
}

template <int dim>
double ImplicitSolver<dim>::force_scale() {
  GM_CALL(VecZeroEntries(floc_));
  double *fa;
  GM_CALL(VecGetArray(floc_, &fa));
  std::visit([&](const auto &s) { residual_impl(s, nullptr, fa, 0.0, true); }, sim_.shape);
  GM_CALL(VecRestoreArray(floc_, &fa));
  sum_ghosted_into_r();
  const double *r;
  GM_CALL(VecGetArrayRead(r_, &r));
  double s2 = 0;
  for (size_t n = 0; n < mass_.size(); ++n)
    for (int d = 0; d < dim; ++d) {
      const size_t q = n * nd_ + d;
      if (fixed_[q]) continue;
      const double f = mass_[n] * (std::fabs(vn_[q]) / dt_ + std::fabs(acc_[d])) + std::fabs(r[q]);
      s2 += f * f;
    }
  GM_CALL(VecRestoreArrayRead(r_, &r));
  double all = 0;
  MPI_Allreduce(&s2, &all, 1, MPI_DOUBLE, MPI_SUM, sim_.comm);
  return std::sqrt(all);
}

// ---------------------------------------------------------------------------------------
// Preconditioning matrix P = M (1/dt + c) + theta^2 dt K.
//   K[i a][j b] = sum_p V_p (lambda_p g_i^a g_j^b + G_p (delta_ab g_i.g_j + g_i^b g_j^a))
// with the elastic moduli, or (-implicit_tangent scaled, granular materials) per particle
// G_p = alpha G, K_p = beta K: alpha = tau/tau_trial of the material's stress return at the
// current iterate (the radial return scales the deviator by alpha: the tangent of every
// deviatoric direction but the flow direction, which is softer still), beta = 0 where the
// point is stress-free and 1 otherwise.

template <int dim>
template <class S>
void ImplicitSolver<dim>::preconditioner_impl(const S &sh, Mat P, const double *va, bool scaled) {
  const Grid<dim> &G = sim_.grid;
  const ElasticModuli el = ElasticModuli::from_E_nu(sim_.cfg.E, sim_.cfg.nu);
  using NS = NodeSet<dim, S>;
  constexpr int ND = NS::NN * dim;
  std::vector<double> Ke((size_t)ND * ND);
  std::vector<MatStencil> rows(ND);
  bool fx[ND];
  NS ns;
  Stencil<dim, S> st;
  const double *fix;
  GM_CALL(VecGetArrayRead(fixloc_, &fix));
  auto lidx = [&](const int *n) { return ((long)(n[2] - G.gxs[2]) * G.gxm[1] + (n[1] - G.gxs[1])) * G.gxm[0] + (n[0] - G.gxs[0]); };
  ParticleView<dim> Pv = sim_.particles.get();
  if (va) trial_stresses(sh, Pv, va, sim_.cfg.implicit.theta * dt_);
  for (PetscInt p = 0; p < Pv.n; ++p) {
    st.compute(sh, Pv.x + p * dim, G.x0, G.inv_h);
    ns.fill(st);
    for (int a = 0; a < NS::NN; ++a) {
      const long l = lidx(ns.nid[a]);
      for (int d = 0; d < dim; ++d) {
        MatStencil &m = rows[a * dim + d];
        m.i = ns.nid[a][0];
        m.j = ns.nid[a][1];
        m.k = ns.nid[a][2];
        m.c = d;
        fx[a * dim + d] = fix[l * nd_ + d] != 0;
      }
    }
    const double theta = sim_.cfg.implicit.theta;
    const double f = theta * theta * dt_ * Pv.vol[p]; // d sigma / d v = theta^2 dt C
    double Gp = el.G, Kp = el.K;
    const Mat3 s0 = sym6_to_mat(Pv.s + 6 * p);
    const Mat3 L = va ? tL_[p] : Mat3::Zero().eval();
    const Mat3 s_new = va ? tsig_[p] : s0; // the trial state at the current iterate
    Q1Cell<dim> q1;
    if (coupled_) q1.fill(G, Pv.x + p * dim);
    if (scaled) {
      Mat3 s_el = s0;
      Hypoelastic{el}.update(s_el, L, theta * dt_);
      const double t_el = tau_of(s_el), t_new = tau_of(s_new);
      if (t_el > 0) Gp = el.G * std::min(1.0, std::max(0.0, t_new / t_el));
      if (s_new.isZero(0.0) && !s_el.isZero(0.0)) Kp = Gp = 0; // stress-free: no stiffness
    }
    const double lam = Kp - 2.0 * Gp / 3.0;
    for (int a = 0; a < NS::NN; ++a)
      for (int b = 0; b < NS::NN; ++b) {
        double gg = 0;
        for (int e = 0; e < dim; ++e) gg += ns.grad[a][e] * ns.grad[b][e];
        for (int c = 0; c < dim; ++c)
          for (int e = 0; e < dim; ++e) {
            const int r = a * dim + c, q = b * dim + e;
            double k = lam * ns.grad[a][c] * ns.grad[b][e] + Gp * ns.grad[a][e] * ns.grad[b][c];
            if (c == e) k += Gp * gg;
            Ke[(size_t)r * ND + q] = (fx[r] || fx[q]) ? 0.0 : f * k;
          }
      }
    GM_CALL(MatSetValuesStencil(P, ND, rows.data(), ND, rows.data(), Ke.data(), ADD_VALUES));
    if (coupled_) {
      // Fluidity block s_g K(w) with w from the trial stress at the current iterate
      // (the dependence of w and g_loc on g and v is left to the matrix-free operator).
      constexpr int NQ = Q1Cell<dim>::NN;
      const Mat3 &sig = s_new;
      const FluiditySource src = fluidity_source(sim_.cfg.gran, sig);
      double Kq[NQ * NQ] = {0}, fq[NQ] = {0};
      fluidity_element_contribution<dim>(q1.xi, G.h, Pv.vol[p], src.weight, 0.0, kf_, Kq, fq);
      MatStencil qr[NQ];
      for (int a = 0; a < NQ; ++a) {
        qr[a].i = q1.nid[a][0];
        qr[a].j = q1.nid[a][1];
        qr[a].k = q1.nid[a][2];
        qr[a].c = dim;
      }
      for (double &k : Kq) k *= sg_;
      GM_CALL(MatSetValuesStencil(P, NQ, qr, NQ, qr, Kq, ADD_VALUES));
    }
  }
  sim_.particles.restore(Pv);
  GM_CALL(VecRestoreArrayRead(fixloc_, &fix));
}

template <int dim>
void ImplicitSolver<dim>::assemble_preconditioner(Vec X, Mat P) {
  const Grid<dim> &G = sim_.grid;
  GM_CALL(MatZeroEntries(P));
  const bool scaled = sim_.cfg.implicit.scaled_tangent && sim_.cfg.granular();
  const double *va = nullptr;
  if (scaled || coupled_) {
    theta_velocity_to_local(X);
    GM_CALL(VecGetArrayRead(vloc_, &va));
  }
  std::visit([&](const auto &s) { preconditioner_impl(s, P, va, scaled); }, sim_.shape);
  if (va) GM_CALL(VecRestoreArrayRead(vloc_, &va));
  // Diagonal: lumped mass terms and Dirichlet rows.
  const double c = sim_.cfg.damping;
  const int k0 = G.xs[2], k1 = dim == 3 ? G.xs[2] + G.xm[2] : 1;
  size_t n = 0;
  for (int k = k0; k < k1; ++k)
    for (int j = G.xs[1]; j < G.xs[1] + G.xm[1]; ++j)
      for (int i = G.xs[0]; i < G.xs[0] + G.xm[0]; ++i, ++n)
        for (int d = 0; d < nd_; ++d) {
          MatStencil m;
          m.i = i;
          m.j = j;
          m.k = k;
          m.c = d;
          double val = fixed_[n * nd_ + d] ? diag_ : mass_[n] * (1.0 / dt_ + c);
          if (d == dim) val = fixed_[n * nd_ + d] ? sg_ * std::pow(G.h, dim) : 0.0; // fluidity: inactive rows only
          GM_CALL(MatSetValuesStencil(P, 1, &m, 1, &m, &val, ADD_VALUES));
        }
  GM_CALL(MatAssemblyBegin(P, MAT_FINAL_ASSEMBLY));
  GM_CALL(MatAssemblyEnd(P, MAT_FINAL_ASSEMBLY));
}

// ---------------------------------------------------------------------------------------

template class ImplicitSolver<2>;
template class ImplicitSolver<3>;

} // namespace granmpm
