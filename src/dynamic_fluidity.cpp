#include "granmpm/dynamic_fluidity.hpp"

#include "granmpm/fluidity.hpp"
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
  for (Vec *v : {&W_, &lap_, &Gh_, &beta_, &rhs_}) GM_CALL(VecDuplicate(G_, v));
  GM_CALL(DMCreateLocalVector(da_, &Gl_));
  for (Vec *v : {&Wl_, &lapl_}) GM_CALL(VecDuplicate(Gl_, v));
  dap_ = grid.create_da(1, nv_);
  GM_CALL(DMCreateLocalVector(dap_, &Pl_));
  GM_CALL(DMCreateGlobalVector(dap_, &Pg_));
  Ad2_ = nonlocal_k(gp_); // (A d)^2 as the material forms it (local_mu_i.hpp)
  DMDALocalInfo li;
  GM_CALL(DMDAGetLocalInfo(da_, &li));
  lgs_[0] = li.gxs, lgs_[1] = li.gys, lgs_[2] = li.gzs;
  lgm_[0] = li.gxm, lgm_[1] = li.gym, lgm_[2] = li.gzm;
  if (cfg.fluidity_step == FluidityStepKind::Implicit) setup_solver();
}

template <int dim>
void DynamicFluidity<dim>::setup_solver() {
  // I - theta Delta_h is a strictly row diagonally dominant M-matrix, not symmetric next to
  // free surfaces (mirrored neighbours). Small grids (-fluidity_solver auto, with the steady
  // solver's band criterion, or direct): the band LU of solve_band. Measured on the 40-cell
  // dynamic chute (164 nodes, half-bandwidth 4) it replaces a PETSc LU whose numeric factor,
  // assembly and KSP set-up were redone every step. Otherwise GMRES + block Jacobi with
  // ILU(0) blocks (one block per rank): on the 360^2 periodic block at theta/h^2 = 17, 25
  // iterations per solve against 125 with Jacobi, 2.7x less solve time; use
  // -fluidity_pc_type hypre for very large steps. (The iterates then depend on the rank
  // count at the level of the 1e-10 tolerance.)
  const Grid<dim> &G = grid_;
  band_n_ = (PetscInt)G.M[0] * G.M[1] * G.M[2];
  band_node_order(G.M, G.periodic, stride_);
  // The half-bandwidth of this stencil in that order (band_node_order's bound is for the
  // full 3^dim neighbourhood): the compact stencil couples along one axis at a time, so on
  // the chute (45 x 4 nodes, periodic across) it is 4 instead of 7, a 3x cheaper factor.
  // A mirrored neighbour i - o is as far away as i + o; a periodic wrap is M - 1 strides.
  PetscInt bw = 0;
  for (int q = 0; q < (dim == 3 ? 27 : 9); ++q) {
    if (w_[q] == 0) continue;
    const int o[3] = {q % 3 - 1, (q / 3) % 3 - 1, dim == 3 ? q / 9 - 1 : 0};
    PetscInt dist = 0;
    for (int d = 0; d < 3; ++d)
      if (o[d] != 0 && G.M[d] > 1) dist += (G.periodic[d] ? std::max(1, G.M[d] - 1) : 1) * stride_[d];
    bw = std::max(bw, dist);
  }
  bw_ = (int)std::min<PetscInt>(bw, band_n_ - 1);
  const double n = (double)band_n_, cost = n * bw_ * bw_, storage = n * (2.0 * bw_ + 2);
  band_ = (solver_ == FluiditySolverKind::Direct && storage <= FluiditySolver<dim>::kBandStorageMax) ||
          (solver_ == FluiditySolverKind::Auto && cost <= FluiditySolver<dim>::kDirectCostMax && storage <= FluiditySolver<dim>::kBandStorageAuto);
  if (band_) return;
  // -fluidity_solver direct beyond the band's storage limit: PETSc's sparse LU.
  const bool direct = solver_ == FluiditySolverKind::Direct;
  GM_CALL(DMCreateMatrix(da_, &A_));
  GM_CALL(MatSetOption(A_, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));
  GM_CALL(KSPCreate(grid_.comm, &ksp_));
  GM_CALL(KSPSetOptionsPrefix(ksp_, "fluidity_"));
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
    // Reverse Cuthill-McKee: on long thin grids it numbers across first and the factor is
    // a narrow band (2.8x fewer factor flops than nested dissection on the 40-cell chute).
    // The symbolic factor is computed once (the DMDA pattern is fixed); the numeric factor
    // is redone each step because beta and theta change.
    // -fluidity_pc_factor_mat_ordering_type overrides it.
    GM_CALL(PCFactorSetMatOrderingType(fpc, MATORDERINGRCM));
  } else {
    GM_CALL(KSPSetType(ksp_, KSPGMRES));
    GM_CALL(PCSetType(pc, PCBJACOBI));
    GM_CALL(KSPSetTolerances(ksp_, 1e-10, PETSC_DEFAULT, 1e50, PETSC_DEFAULT));
  }
  GM_CALL(KSPSetFromOptions(ksp_));
}

template <int dim>
DynamicFluidity<dim>::~DynamicFluidity() {
  if (ksp_) KSPDestroy(&ksp_);
  if (A_) MatDestroy(&A_);
  Vec *vs[] = {&G_, &Gl_, &W_, &Wl_, &lap_, &lapl_, &Gh_, &beta_, &rhs_, &Pl_, &Pg_};
  for (Vec *v : vs)
    if (*v) VecDestroy(v);
  DMDestroy(&dap_);
  DMDestroy(&da_);
}

template <int dim>
long DynamicFluidity<dim>::locate(const double *x, double *xi) const {
  const Grid<dim> &Gd = grid_;
  int c[3] = {0, 0, 0};
  for (int d = 0; d < dim; ++d) {
    c[d] = std::min(Gd.cell_of(d, x[d]), Gd.xs[d] + Gd.xm[d] - 1);
    xi[d] = (x[d] - Gd.node_x(d, c[d])) * Gd.inv_h;
  }
  return lidx(c[0], c[1], dim == 3 ? c[2] : 0);
}

namespace {
// Local-index offsets of the 2^dim corners of a Q1 cell (corner q: bit d set = +1 in d) and
// their weights at local coordinates xi.
template <int dim>
struct Q1 {
  static constexpr int nn = 1 << dim;
  long off[nn];
  Q1(const int *lgm) {
    for (int q = 0; q < nn; ++q) off[q] = (q & 1) + ((q >> 1) & 1) * (long)lgm[0] + (dim == 3 ? ((q >> 2) & 1) * (long)lgm[0] * lgm[1] : 0);
  }
  static void weights(const double *xi, double scale, double *S) {
    for (int q = 0; q < nn; ++q) {
      double s = scale;
      for (int d = 0; d < dim; ++d) s *= ((q >> d) & 1) ? xi[d] : 1.0 - xi[d];
      S[q] = s;
    }
  }
};
} // namespace

template <int dim>
void DynamicFluidity<dim>::project(const double *x, const double *m, const double *g, const double *p_prev, const double *mu_prev, PetscInt n, double dt, bool implicit) {
  // One pass over the connected particles (p_prev > 0) for the mass-weighted, normalised
  // transfers to the owned nodes: G = P[g] (global G_), the weights S m (W_, and their
  // ghosted copy Wl_: the neighbours' active flags) and, for the implicit step, the
  // reaction rate (dt/t0) R(g) (rhs_) and beta = |(dt/t0) dR/dg| (beta_).
  const Q1<dim> q1(lgm_);
  const int nv = implicit ? 4 : 2, st = nv_; // the explicit step needs only G and W
  double *a;
  GM_CALL(VecZeroEntries(Pl_));
  GM_CALL(VecGetArray(Pl_, &a));
  const double k = dt / t0_;
  for (PetscInt p = 0; p < n; ++p) {
    if (!(p_prev[p] > 0)) continue;
    double S[Q1<dim>::nn], rate = 0, beta = 0, xi[dim];
    const long cell = locate(x + p * dim, xi);
    Q1<dim>::weights(xi, m[p], S);
    if (implicit) {
      const FluidityReaction R = fluidity_reaction(gp_, p_prev[p], mu_prev[p]);
      rate = k * R.rate(g[p]);
      beta = k * std::fabs(R.slope(g[p])); // damps growth too
    }
    for (int q = 0; q < Q1<dim>::nn; ++q) {
      double *al = a + (cell + q1.off[q]) * st;
      al[0] += S[q] * g[p];
      al[1] += S[q];
      if (implicit) {
        al[2] += S[q] * rate;
        al[3] += S[q] * beta;
      }
    }
  }
  GM_CALL(VecRestoreArray(Pl_, &a));
  GM_CALL(VecZeroEntries(Pg_));
  GM_CALL(DMLocalToGlobalBegin(dap_, Pl_, ADD_VALUES, Pg_));
  GM_CALL(DMLocalToGlobalEnd(dap_, Pl_, ADD_VALUES, Pg_));
  // Split into the scalar vectors, normalised by the weights (inactive nodes: 0).
  PetscInt nl;
  GM_CALL(VecGetLocalSize(G_, &nl));
  const double *pg;
  double *o[4] = {nullptr, nullptr, nullptr, nullptr};
  Vec glob[4] = {G_, W_, rhs_, beta_};
  GM_CALL(VecGetArrayRead(Pg_, &pg));
  for (int v = 0; v < nv; ++v) GM_CALL(VecGetArray(glob[v], &o[v]));
  for (PetscInt i = 0; i < nl; ++i) {
    const double *pi = pg + i * st, ww = pi[1];
    o[1][i] = ww;
    for (int v = 0; v < nv; ++v)
      if (v != 1) o[v][i] = ww > 0 ? pi[v] / ww : 0.0;
  }
  for (int v = 0; v < nv; ++v) GM_CALL(VecRestoreArray(glob[v], &o[v]));
  GM_CALL(VecRestoreArrayRead(Pg_, &pg));
  GM_CALL(DMGlobalToLocalBegin(da_, W_, INSERT_VALUES, Wl_));
  GM_CALL(DMGlobalToLocalEnd(da_, W_, INSERT_VALUES, Wl_));
}

template <int dim>
void DynamicFluidity<dim>::build_neighbours(const double *wl) {
  // Stencil neighbours of every active owned node. A missing (massless or outside)
  // neighbour i + o is replaced by its mirror image i - o when that one is active: the
  // ghost-point form of the zero-flux condition at walls and free surfaces (skipping it
  // instead would halve the normal flux term there and bias the solution next to every
  // boundary). Both missing: no term.
  const Grid<dim> &Gd = grid_;
  auto exists = [&](int d, int v) { return Gd.periodic[d] || (v >= 0 && v < Gd.M[d]); };
  auto active = [&](int a, int b, int c) { return exists(0, a) && exists(1, b) && (dim == 2 || exists(2, c)) && wl[lidx(a, b, c)] > 0; };
  nb_start_.assign(1, 0);
  nb_idx_.clear();
  nb_w_.clear();
  band_row_.clear();
  band_col_.clear();
  const int k0 = Gd.xs[2], k1 = dim == 3 ? Gd.xs[2] + Gd.xm[2] : 1, kn = dim == 3 ? 3 : 1;
  for (int k = k0; k < k1; ++k)
    for (int j = Gd.xs[1]; j < Gd.xs[1] + Gd.xm[1]; ++j)
      for (int i = Gd.xs[0]; i < Gd.xs[0] + Gd.xm[0]; ++i) {
        if (wl[lidx(i, j, k)] > 0)
          for (int c = 0; c < kn; ++c)
            for (int b = 0; b < 3; ++b)
              for (int a = 0; a < 3; ++a) {
                const double w = w_[(c * 3 + b) * 3 + a];
                if (w == 0) continue;
                const int o[3] = {a - 1, b - 1, dim == 3 ? c - 1 : 0};
                int s = 0;
                if (active(i + o[0], j + o[1], k + o[2])) s = 1;
                else if (active(i - o[0], j - o[1], k - o[2])) s = -1;
                if (!s) continue;
                nb_idx_.push_back(lidx(i + s * o[0], j + s * o[1], k + s * o[2]));
                nb_w_.push_back(w);
                if (band_) band_col_.push_back(band_node_index(Gd.M, stride_, i + s * o[0], j + s * o[1], k + s * o[2]));
              }
        nb_start_.push_back((int)nb_idx_.size());
        if (band_) band_row_.push_back(band_node_index(Gd.M, stride_, i, j, k));
      }
}

template <int dim>
void DynamicFluidity<dim>::nodal_laplacian(Vec in, bool add) {
  // lap_ (owned nodes) = (or +=) Delta_h of the global nodal vector in.
  const Grid<dim> &Gd = grid_;
  GM_CALL(DMGlobalToLocalBegin(da_, in, INSERT_VALUES, Gl_));
  GM_CALL(DMGlobalToLocalEnd(da_, in, INSERT_VALUES, Gl_));
  const double *gl;
  double *L;
  GM_CALL(VecGetArrayRead(Gl_, &gl));
  GM_CALL(VecGetArray(lap_, &L));
  const double inv_h2 = Gd.inv_h * Gd.inv_h;
  const int k0 = Gd.xs[2], k1 = dim == 3 ? Gd.xs[2] + Gd.xm[2] : 1;
  long q = 0;
  for (int k = k0; k < k1; ++k)
    for (int j = Gd.xs[1]; j < Gd.xs[1] + Gd.xm[1]; ++j)
      for (int i = Gd.xs[0]; i < Gd.xs[0] + Gd.xm[0]; ++i, ++q) {
        const double me = gl[lidx(i, j, k)];
        double s = 0;
        for (int e = nb_start_[q]; e < nb_start_[q + 1]; ++e) s += nb_w_[e] * (gl[nb_idx_[e]] - me);
        L[q] = add ? L[q] + s * inv_h2 : s * inv_h2;
      }
  GM_CALL(VecRestoreArrayRead(Gl_, &gl));
  GM_CALL(VecRestoreArray(lap_, &L));
}

template <int dim>
void DynamicFluidity<dim>::interpolate(const double *x, PetscInt n, std::vector<double> &out) {
  // lap_ Q1-interpolated to every local particle.
  GM_CALL(DMGlobalToLocalBegin(da_, lap_, INSERT_VALUES, lapl_));
  GM_CALL(DMGlobalToLocalEnd(da_, lap_, INSERT_VALUES, lapl_));
  const Q1<dim> q1(lgm_);
  const double *ll;
  GM_CALL(VecGetArrayRead(lapl_, &ll));
  out.resize(n);
  for (PetscInt p = 0; p < n; ++p) {
    double S[Q1<dim>::nn], s = 0, xi[dim];
    const long cell = locate(x + p * dim, xi);
    Q1<dim>::weights(xi, 1.0, S);
    for (int q = 0; q < Q1<dim>::nn; ++q) s += S[q] * ll[cell + q1.off[q]];
    out[p] = s;
  }
  GM_CALL(VecRestoreArrayRead(lapl_, &ll));
}

template <int dim>
void DynamicFluidity<dim>::laplacian(const double *x, const double *m, const double *g, const double *p_prev, const double *mu_prev, PetscInt n,
                                     double dt, bool implicit, std::vector<double> &lap) {
  // 1.-3. Explicit Laplacian of the projected fluidity; the implicit correction on top
  // (Delta_h is linear: the particles get I Delta_h (G + Gh), one interpolation).
  if (!(Ad2_ > 0)) {
    // A = 0: the particle kernel multiplies lap by A^2 d^2 = 0, the nonlocal term is off
    // and the grid has nothing to compute (the same particles wherever lap was finite).
    lap.assign(n, 0.0);
    return;
  }
  project(x, m, g, p_prev, mu_prev, n, dt, implicit);
  const double *wl;
  GM_CALL(VecGetArrayRead(Wl_, &wl));
  // The stencil depends only on the active flags: rebuilt when they change (on the chute
  // every node stays active and the rebuild was 4.7% of the step, perf).
  const long nl = (long)lgm_[0] * lgm_[1] * lgm_[2];
  bool changed = (long)active_.size() != nl;
  active_.resize(nl);
  for (long i = 0; i < nl; ++i) {
    const unsigned char a = wl[i] > 0;
    changed |= a != active_[i];
    active_[i] = a;
  }
  if (changed) build_neighbours(wl);
  GM_CALL(VecRestoreArrayRead(Wl_, &wl));
  nodal_laplacian(G_, false);
  if (implicit) implicit_correction(dt);
  interpolate(x, n, lap);
}

template <int dim>
void DynamicFluidity<dim>::implicit_correction(double dt) {
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
  // On entry rhs_ = P[(dt/t0) R], beta_ = P[beta], lap_ = Delta_h G; on exit lap_ = Delta_h (G + delta).
  const double theta = dt * Ad2_ / t0_;
  GM_CALL(VecAXPY(rhs_, theta, lap_));
  if (band_) {
    solve_band(theta);
  } else {
    if (!ksp_) setup_solver();
    assemble_implicit(theta);
    GM_CALL(KSPSetOperators(ksp_, A_, A_));
    GM_CALL(VecZeroEntries(Gh_)); // delta: zero initial guess (it vanishes at steady state)
    GM_CALL(KSPSolve(ksp_, rhs_, Gh_));
    KSPConvergedReason reason;
    GM_CALL(KSPGetConvergedReason(ksp_, &reason));
    GM_CALL(KSPGetIterationNumber(ksp_, &last_iterations));
    if (reason < 0)
      collective_fail(grid_.comm, true,
                      std::string("the implicit fluidity solve did not converge (KSP reason ") + KSPConvergedReasons[reason] +
                          "); tune -fluidity_ksp_type, -fluidity_pc_type or -fluidity_ksp_max_it");
  }
  ++solves;
  nodal_laplacian(Gh_, true);
}

template <int dim>
void DynamicFluidity<dim>::solve_band(double theta) {
  // The rows of assemble_implicit, by band index, and the right-hand side after them;
  // summed on rank 0 (each entry is nonzero on one rank only: the sum is exact).
  const Grid<dim> &Gd = grid_;
  const double inv_h2 = Gd.inv_h * Gd.inv_h;
  const PetscInt n = band_n_, w = 2 * bw_ + 1;
  buf_.assign(n * w + n, 0.0);
  double *K = buf_.data(), *f = K + n * w;
  const double *beta, *wl, *rhs;
  GM_CALL(VecGetArrayRead(beta_, &beta));
  GM_CALL(VecGetArrayRead(Wl_, &wl));
  GM_CALL(VecGetArrayRead(rhs_, &rhs));
  long own = 0;
  const int k0 = Gd.xs[2], k1 = dim == 3 ? Gd.xs[2] + Gd.xm[2] : 1;
  for (int k = k0; k < k1; ++k)
    for (int j = Gd.xs[1]; j < Gd.xs[1] + Gd.xm[1]; ++j)
      for (int i = Gd.xs[0]; i < Gd.xs[0] + Gd.xm[0]; ++i, ++own) {
        const PetscInt r = band_row_[own];
        double *row = K + r * w + bw_ - r; // row[c] = entry (r, c)
        double diag = 1.0;
        if (wl[lidx(i, j, k)] > 0) diag += beta[own];
        for (int e = nb_start_[own]; e < nb_start_[own + 1]; ++e) {
          row[band_col_[e]] -= theta * nb_w_[e] * inv_h2;
          diag += theta * nb_w_[e] * inv_h2;
        }
        row[r] += diag;
        f[r] = rhs[own];
      }
  GM_CALL(VecRestoreArrayRead(beta_, &beta));
  GM_CALL(VecRestoreArrayRead(Wl_, &wl));
  GM_CALL(VecRestoreArrayRead(rhs_, &rhs));
  sol_.resize(n + 1);
  if (Gd.size > 1) {
    if (Gd.rank == 0) MPI_Reduce(MPI_IN_PLACE, buf_.data(), (int)buf_.size(), MPI_DOUBLE, MPI_SUM, 0, Gd.comm);
    else MPI_Reduce(buf_.data(), nullptr, (int)buf_.size(), MPI_DOUBLE, MPI_SUM, 0, Gd.comm);
  }
  if (Gd.rank == 0) {
    const bool ok = band_lu(n, bw_, K);
    std::copy(f, f + n, sol_.data());
    if (ok) band_lu_solve(n, bw_, K, sol_.data());
    sol_[n] = ok ? 1.0 : 0.0;
  }
  if (Gd.size > 1) MPI_Bcast(sol_.data(), (int)(n + 1), MPI_DOUBLE, 0, Gd.comm);
  if (!(sol_[n] > 0))
    collective_fail(Gd.comm, true, "the implicit fluidity step's band LU met a zero or non-finite pivot (a non-finite fluidity or beta?); try -fluidity_solver iterative");
  last_iterations = 1;
  double *gh;
  GM_CALL(VecGetArray(Gh_, &gh));
  for (PetscInt q = 0; q < (PetscInt)band_row_.size(); ++q) gh[q] = sol_[band_row_[q]];
  GM_CALL(VecRestoreArray(Gh_, &gh));
}

template <int dim>
void DynamicFluidity<dim>::assemble_implicit(double theta) {
  // (1 + beta) I - theta Delta_h on the active nodes (the mirrored stencil of
  // build_neighbours), identity rows on inactive ones (right-hand side 0 there). Rows and
  // columns by local (ghosted) index: DMCreateMatrix set the local-to-global map.
  const Grid<dim> &Gd = grid_;
  const double inv_h2 = Gd.inv_h * Gd.inv_h;
  GM_CALL(MatZeroEntries(A_));
  const double *beta, *wl;
  GM_CALL(VecGetArrayRead(beta_, &beta));
  GM_CALL(VecGetArrayRead(Wl_, &wl));
  PetscInt cols[28];
  double vals[28];
  long own = 0;
  const int k0 = Gd.xs[2], k1 = dim == 3 ? Gd.xs[2] + Gd.xm[2] : 1;
  for (int k = k0; k < k1; ++k)
    for (int j = Gd.xs[1]; j < Gd.xs[1] + Gd.xm[1]; ++j)
      for (int i = Gd.xs[0]; i < Gd.xs[0] + Gd.xm[0]; ++i, ++own) {
        const PetscInt row = (PetscInt)lidx(i, j, k);
        int nc = 0;
        double diag = 1.0;
        if (wl[row] > 0) diag += beta[own];
        for (int e = nb_start_[own]; e < nb_start_[own + 1]; ++e) {
          cols[nc] = (PetscInt)nb_idx_[e];
          vals[nc++] = -theta * nb_w_[e] * inv_h2;
          diag += theta * nb_w_[e] * inv_h2;
        }
        cols[nc] = row;
        vals[nc++] = diag;
        GM_CALL(MatSetValuesLocal(A_, 1, &row, nc, cols, vals, ADD_VALUES));
      }
  GM_CALL(VecRestoreArrayRead(beta_, &beta));
  GM_CALL(VecRestoreArrayRead(Wl_, &wl));
  GM_CALL(MatAssemblyBegin(A_, MAT_FINAL_ASSEMBLY));
  GM_CALL(MatAssemblyEnd(A_, MAT_FINAL_ASSEMBLY));
}

template class DynamicFluidity<2>;
template class DynamicFluidity<3>;

} // namespace granmpm
