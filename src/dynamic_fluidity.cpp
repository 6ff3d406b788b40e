#include "granmpm/dynamic_fluidity.hpp"

#include "granmpm/materials/dynamic_ngf.hpp"

#include <petscpc.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace granmpm {

void laplacian_weights(int dim, LaplacianStencil st, double *w) {
  const int n = dim == 3 ? 27 : 9;
  for (int q = 0; q < n; ++q) {
    const int o[3] = {q % 3 - 1, (q / 3) % 3 - 1, dim == 3 ? q / 9 - 1 : 0};
    const int dist = std::abs(o[0]) + std::abs(o[1]) + std::abs(o[2]); // 1 face, 2 edge, 3 corner
    double v = 0;
    if (st == LaplacianStencil::Compact) v = dist == 1 ? 1.0 : 0.0;
    else if (dim == 2) v = dist == 1 ? 4.0 / 6.0 : (dist == 2 ? 1.0 / 6.0 : 0.0); // isotropic 9-point
    else v = dist == 1 ? 14.0 / 30.0 : (dist == 2 ? 3.0 / 30.0 : (dist == 3 ? 1.0 / 30.0 : 0.0)); // isotropic 27-point
    w[q] = v;
  }
}

template <int dim>
DynamicFluidity<dim>::DynamicFluidity(const Grid<dim> &grid, const Config &cfg)
    : grid_(grid), gp_(cfg.gran), t0_(cfg.t0), stencil_(cfg.fluidity_laplacian), solver_(cfg.fluidity_solver) {
  laplacian_weights(dim, stencil_, w_);
  da_ = grid.create_scalar_da(1);
  GM_CALL(DMCreateGlobalVector(da_, &G_));
  GM_CALL(VecDuplicate(G_, &W_));
  GM_CALL(VecDuplicate(G_, &lap_));
  GM_CALL(VecDuplicate(G_, &Gh_));
  GM_CALL(VecDuplicate(G_, &A_g_));
  GM_CALL(VecDuplicate(G_, &C_g_));
  GM_CALL(VecDuplicate(G_, &rhs_));
  GM_CALL(DMCreateLocalVector(da_, &Gl_));
  GM_CALL(VecDuplicate(Gl_, &Wl_));
  GM_CALL(VecDuplicate(Gl_, &lapl_));
  GM_CALL(VecDuplicate(Gl_, &Al_));
  GM_CALL(VecDuplicate(Gl_, &Cl_));
  GM_CALL(VecGetOwnershipRange(G_, &rstart_, NULL));
  Ad2_ = nonlocal_k(gp_); // (A d)^2 as the material forms it (local_mu_i.hpp)
  DMDALocalInfo li;
  GM_CALL(DMDAGetLocalInfo(da_, &li));
  lgs_[0] = li.gxs, lgs_[1] = li.gys, lgs_[2] = li.gzs;
  lgm_[0] = li.gxm, lgm_[1] = li.gym, lgm_[2] = li.gzm;
  nbs_.reserve(27);
  if (cfg.fluidity_step == FluidityStepKind::Implicit) setup_solver();
}

template <int dim>
void DynamicFluidity<dim>::setup_solver() {
  GM_CALL(DMCreateMatrix(da_, &A_));
  GM_CALL(MatSetOption(A_, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));
  GM_CALL(KSPCreate(grid_.comm, &ksp_));
  GM_CALL(KSPSetOptionsPrefix(ksp_, "fluidity_"));
  // I - theta Delta_h is a diagonally dominant M-matrix, not symmetric next to free
  // surfaces (mirrored neighbours). Small grids (-fluidity_solver auto, the criterion of the
  // steady solver's band factor, or direct): an LU factor, redundant on several ranks (the
  // 40-cell chute: 17 GMRES iterations per step cost twice the factor). Otherwise GMRES +
  // Jacobi, a few iterations for moderate theta; use -fluidity_pc_type hypre for very large
  // steps.
  const Grid<dim> &G = grid_;
  const double nodes = (double)G.M[0] * G.M[1] * G.M[2], band = nodes / std::max({G.M[0], G.M[1], G.M[2]});
  const bool direct = solver_ == FluiditySolverKind::Direct || (solver_ == FluiditySolverKind::Auto && nodes * band * band <= 2e7);
  PC pc;
  GM_CALL(KSPGetPC(ksp_, &pc));
  if (direct) {
    GM_CALL(KSPSetType(ksp_, KSPPREONLY));
    PC fpc = pc;
    if (G.size > 1) {
      GM_CALL(PCSetType(pc, PCREDUNDANT));
      KSP inner;
      GM_CALL(PCRedundantGetKSP(pc, &inner));
      GM_CALL(KSPSetType(inner, KSPPREONLY));
      GM_CALL(KSPGetPC(inner, &fpc));
    }
    GM_CALL(PCSetType(fpc, PCLU));
  } else {
    GM_CALL(KSPSetType(ksp_, KSPGMRES));
    GM_CALL(PCSetType(pc, PCJACOBI));
    GM_CALL(KSPSetTolerances(ksp_, 1e-10, PETSC_DEFAULT, 1e50, PETSC_DEFAULT));
  }
  GM_CALL(KSPSetFromOptions(ksp_));
}

template <int dim>
DynamicFluidity<dim>::~DynamicFluidity() {
  if (ksp_) KSPDestroy(&ksp_);
  if (A_) MatDestroy(&A_);
  Vec *vs[] = {&G_, &Gl_, &W_, &Wl_, &lap_, &lapl_, &Gh_, &Al_, &A_g_, &Cl_, &C_g_, &rhs_};
  for (Vec *v : vs)
    if (*v) VecDestroy(v);
  DMDestroy(&da_);
}

template <int dim>
void DynamicFluidity<dim>::locate(const double *x, PetscInt n) {
  // Q1 cell and local coordinates of each particle, computed once per step.
  const Grid<dim> &Gd = grid_;
  cell_.resize((size_t)n * 3);
  xis_.resize((size_t)n * 3);
  for (PetscInt p = 0; p < n; ++p)
    for (int d = 0; d < 3; ++d) {
      cell_[p * 3 + d] = d < dim ? std::min(Gd.cell_of(d, x[p * dim + d]), Gd.xs[d] + Gd.xm[d] - 1) : 0;
      xis_[p * 3 + d] = d < dim ? (x[p * dim + d] - Gd.node_x(d, cell_[p * 3 + d])) * Gd.inv_h : 0.0;
    }
}

template <int dim>
void DynamicFluidity<dim>::project(const double *m, const double *p_prev, PetscInt n, Vec out, bool weights) {
  // Mass-weighted, normalised transfer of vals_ (per particle) to the owned nodes (global
  // vec out); connected particles only (p_prev > 0). weights: the sums S m go to W_ and
  // their ghosted copy to Wl_ (the neighbours' active flags), once per step.
  constexpr int nn = 1 << dim;
  GM_CALL(VecZeroEntries(Gl_));
  if (weights) GM_CALL(VecZeroEntries(Wl_));
  double *a, *w = nullptr;
  GM_CALL(VecGetArray(Gl_, &a));
  if (weights) GM_CALL(VecGetArray(Wl_, &w));
  for (PetscInt p = 0; p < n; ++p) {
    if (!(p_prev[p] > 0)) continue;
    const int *c = &cell_[p * 3];
    const double *xi = &xis_[p * 3];
    for (int q = 0; q < nn; ++q) {
      double S = m[p];
      for (int d = 0; d < dim; ++d) S *= ((q >> d) & 1) ? xi[d] : 1.0 - xi[d];
      const long l = lidx(c[0] + (q & 1), c[1] + ((q >> 1) & 1), dim == 3 ? c[2] + ((q >> 2) & 1) : 0);
      a[l] += S * vals_[p];
      if (weights) w[l] += S;
    }
  }
  GM_CALL(VecRestoreArray(Gl_, &a));
  if (weights) GM_CALL(VecRestoreArray(Wl_, &w));
  GM_CALL(VecZeroEntries(out));
  GM_CALL(DMLocalToGlobalBegin(da_, Gl_, ADD_VALUES, out));
  GM_CALL(DMLocalToGlobalEnd(da_, Gl_, ADD_VALUES, out));
  if (weights) {
    GM_CALL(VecZeroEntries(W_));
    GM_CALL(DMLocalToGlobalBegin(da_, Wl_, ADD_VALUES, W_));
    GM_CALL(DMLocalToGlobalEnd(da_, Wl_, ADD_VALUES, W_));
    GM_CALL(DMGlobalToLocalBegin(da_, W_, INSERT_VALUES, Wl_));
    GM_CALL(DMGlobalToLocalEnd(da_, W_, INSERT_VALUES, Wl_));
  }
  double *o;
  const double *ww;
  PetscInt nl;
  GM_CALL(VecGetLocalSize(out, &nl));
  GM_CALL(VecGetArray(out, &o));
  GM_CALL(VecGetArrayRead(W_, &ww));
  for (PetscInt i = 0; i < nl; ++i) o[i] = ww[i] > 0 ? o[i] / ww[i] : 0.0; // inactive nodes: 0
  GM_CALL(VecRestoreArray(out, &o));
  GM_CALL(VecRestoreArrayRead(W_, &ww));
}

template <int dim>
const std::vector<typename DynamicFluidity<dim>::Nb> &DynamicFluidity<dim>::neighbours(int i, int j, int k, const double *wl) {
  // Stencil neighbours of an active node. A missing (massless or outside) neighbour i + o is
  // replaced by its mirror image i - o when that one is active: the ghost-point form of the
  // zero-flux condition at walls and free surfaces (skipping it instead would halve the
  // normal flux term there and bias the solution next to every boundary). Both missing: no
  // term.
  const Grid<dim> &Gd = grid_;
  auto exists = [&](int d, int v) { return Gd.periodic[d] || (v >= 0 && v < Gd.M[d]); };
  auto active = [&](int a, int b, int c) { return exists(0, a) && exists(1, b) && (dim == 2 || exists(2, c)) && wl[lidx(a, b, c)] > 0; };
  nbs_.clear();
  const int kn = dim == 3 ? 3 : 1;
  for (int c = 0; c < kn; ++c)
    for (int b = 0; b < 3; ++b)
      for (int a = 0; a < 3; ++a) {
        const double w = w_[(c * 3 + b) * 3 + a];
        if (w == 0) continue;
        const int o[3] = {a - 1, b - 1, dim == 3 ? c - 1 : 0};
        if (active(i + o[0], j + o[1], k + o[2])) nbs_.push_back({i + o[0], j + o[1], k + o[2], w});
        else if (active(i - o[0], j - o[1], k - o[2])) nbs_.push_back({i - o[0], j - o[1], k - o[2], w});
      }
  return nbs_;
}

template <int dim>
void DynamicFluidity<dim>::nodal_laplacian_at_particles(Vec in, PetscInt n, std::vector<double> &out) {
  // Delta_h of a global nodal vector into lap_ (owned nodes), then Q1-interpolated to the
  // particles.
  const Grid<dim> &Gd = grid_;
  constexpr int nn = 1 << dim;
  GM_CALL(DMGlobalToLocalBegin(da_, in, INSERT_VALUES, Gl_));
  GM_CALL(DMGlobalToLocalEnd(da_, in, INSERT_VALUES, Gl_));
  const double *gl, *wl;
  double *L;
  GM_CALL(VecGetArrayRead(Gl_, &gl));
  GM_CALL(VecGetArrayRead(Wl_, &wl));
  GM_CALL(VecGetArray(lap_, &L));
  const double inv_h2 = Gd.inv_h * Gd.inv_h;
  const int k0 = Gd.xs[2], k1 = dim == 3 ? Gd.xs[2] + Gd.xm[2] : 1;
  long q = 0;
  for (int k = k0; k < k1; ++k)
    for (int j = Gd.xs[1]; j < Gd.xs[1] + Gd.xm[1]; ++j)
      for (int i = Gd.xs[0]; i < Gd.xs[0] + Gd.xm[0]; ++i, ++q) {
        const long me = lidx(i, j, k);
        double s = 0;
        if (wl[me] > 0)
          for (const Nb &nb : neighbours(i, j, k, wl)) s += nb.w * (gl[lidx(nb.i, nb.j, nb.k)] - gl[me]);
        L[q] = s * inv_h2;
      }
  GM_CALL(VecRestoreArrayRead(Gl_, &gl));
  GM_CALL(VecRestoreArrayRead(Wl_, &wl));
  GM_CALL(VecRestoreArray(lap_, &L));
  GM_CALL(DMGlobalToLocalBegin(da_, lap_, INSERT_VALUES, lapl_));
  GM_CALL(DMGlobalToLocalEnd(da_, lap_, INSERT_VALUES, lapl_));
  const double *ll;
  GM_CALL(VecGetArrayRead(lapl_, &ll));
  out.assign(n, 0.0);
  for (PetscInt p = 0; p < n; ++p) {
    const int *c = &cell_[p * 3];
    const double *xi = &xis_[p * 3];
    double s = 0;
    for (int qq = 0; qq < nn; ++qq) {
      double S = 1;
      for (int d = 0; d < dim; ++d) S *= ((qq >> d) & 1) ? xi[d] : 1.0 - xi[d];
      s += S * ll[lidx(c[0] + (qq & 1), c[1] + ((qq >> 1) & 1), dim == 3 ? c[2] + ((qq >> 2) & 1) : 0)];
    }
    out[p] = s;
  }
  GM_CALL(VecRestoreArrayRead(lapl_, &ll));
}

template <int dim>
void DynamicFluidity<dim>::laplacian(const double *x, const double *m, const double *g, const double *p_prev, const double *mu_prev, PetscInt n,
                                     double dt, bool implicit, std::vector<double> &lap) {
  // 1.-3. Explicit Laplacian of the projected fluidity; the implicit correction on top.
  locate(x, n);
  vals_.assign(g, g + n);
  project(m, p_prev, n, G_, true);
  nodal_laplacian_at_particles(G_, n, lap);
  if (implicit) implicit_correction(m, g, p_prev, mu_prev, n, dt, lap);
}

template <int dim>
void DynamicFluidity<dim>::implicit_correction(const double *m, const double *g, const double *p_prev, const double *mu_prev, PetscInt n, double dt,
                                               std::vector<double> &lap) {
  // Implicit correction (linearised backward Euler on the grid):
  //   ((1 + beta) I - theta Delta_h) delta = theta Delta_h G + (dt/t0) P[R_p(g_p)],
  //   R(g) = -(mu_s - mu) g - b sqrt(rho_s d^2/p) mu g^2, beta = |(dt/t0) dR/dg|,
  // and the particles see the Laplacian of G + delta. Without reaction G + delta =
  // (I - theta Delta_h)^-1 G: backward Euler for the diffusion, stable for any dt (the
  // particle amplification factor is 1 - c^2 x/(1 + x), x = theta |Delta_h| symbol, c the
  // projection/interpolation symbol). At a steady state of the particles the right-hand side
  // is theta (Delta_h G - P I Delta_h G) = O(h^2), so the implicit steady state differs
  // from the explicit one by a second-order term. (Driving the correction by the projected
  // particle rate P[A^2 d^2 I Delta_h G + R] instead keeps the steady states exactly but
  // multiplies the diffusion by c^2 and is unstable for theta/h^2 > 3.4.)
  const double theta = dt * Ad2_ / t0_;
  std::vector<double> beta(n);
  for (PetscInt p = 0; p < n; ++p) {
    if (!(p_prev[p] > 0)) continue; // not projected
    const FluidityReaction R = fluidity_reaction(gp_, p_prev[p], mu_prev[p]);
    vals_[p] = (dt / t0_) * R.rate(g[p]);
    beta[p] = dt / t0_ * std::fabs(R.slope(g[p])); // beta = |(dt/t0) dR/dg|: damps growth too
  }
  project(m, p_prev, n, rhs_, false);
  GM_CALL(VecAXPY(rhs_, theta, lap_)); // lap_ still holds Delta_h G on the owned nodes
  vals_.swap(beta);
  project(m, p_prev, n, A_g_, false);
  if (!ksp_) setup_solver();
  assemble_implicit(theta);
  GM_CALL(KSPSetOperators(ksp_, A_, A_));
  GM_CALL(VecZeroEntries(Gh_)); // delta: zero initial guess (it vanishes at steady state)
  GM_CALL(KSPSolve(ksp_, rhs_, Gh_));
  KSPConvergedReason reason;
  GM_CALL(KSPGetConvergedReason(ksp_, &reason));
  GM_CALL(KSPGetIterationNumber(ksp_, &last_iterations));
  ++solves;
  if (reason < 0)
    collective_fail(grid_.comm, true,
                    std::string("the implicit fluidity solve did not converge (KSP reason ") + KSPConvergedReasons[reason] +
                        "); tune -fluidity_ksp_type, -fluidity_pc_type or -fluidity_ksp_max_it");
  std::vector<double> corr;
  nodal_laplacian_at_particles(Gh_, n, corr);
  for (PetscInt p = 0; p < n; ++p) lap[p] += corr[p];
}

template <int dim>
void DynamicFluidity<dim>::assemble_implicit(double theta) {
  // (1 + beta) I - theta Delta_h on the active nodes (the mirrored stencil of neighbours()),
  // identity rows on inactive ones (right-hand side 0 there). beta: nodal, in A_g_.
  const Grid<dim> &Gd = grid_;
  const double inv_h2 = Gd.inv_h * Gd.inv_h;
  GM_CALL(MatZeroEntries(A_));
  const double *wl, *beta;
  GM_CALL(VecGetArrayRead(Wl_, &wl));
  GM_CALL(VecGetArrayRead(A_g_, &beta));
  MatStencil row, cols[28];
  double vals[28];
  long own = 0;
  const int k0 = Gd.xs[2], k1 = dim == 3 ? Gd.xs[2] + Gd.xm[2] : 1;
  for (int k = k0; k < k1; ++k)
    for (int j = Gd.xs[1]; j < Gd.xs[1] + Gd.xm[1]; ++j)
      for (int i = Gd.xs[0]; i < Gd.xs[0] + Gd.xm[0]; ++i, ++own) {
        row.i = i;
        row.j = j;
        row.k = k;
        row.c = 0;
        int nc = 0;
        double diag = 1.0;
        if (wl[lidx(i, j, k)] > 0) {
          diag += beta[own];
          for (const Nb &nb : neighbours(i, j, k, wl)) {
            cols[nc].i = nb.i;
            cols[nc].j = nb.j;
            cols[nc].k = nb.k;
            cols[nc].c = 0;
            vals[nc++] = -theta * nb.w * inv_h2;
            diag += theta * nb.w * inv_h2;
          }
        }
        cols[nc] = row;
        vals[nc++] = diag;
        GM_CALL(MatSetValuesStencil(A_, 1, &row, nc, cols, vals, ADD_VALUES));
      }
  GM_CALL(VecRestoreArrayRead(Wl_, &wl));
  GM_CALL(VecRestoreArrayRead(A_g_, &beta));
  GM_CALL(MatAssemblyBegin(A_, MAT_FINAL_ASSEMBLY));
  GM_CALL(MatAssemblyEnd(A_, MAT_FINAL_ASSEMBLY));
}

template class DynamicFluidity<2>;
template class DynamicFluidity<3>;

} // namespace granmpm
