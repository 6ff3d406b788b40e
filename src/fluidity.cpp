#include "granmpm/fluidity.hpp"

#include <petscpc.h>

#include <cmath>
#include <algorithm>
#include <cstring>
#include <string>

#include "granmpm/materials/nonlocal_ngf.hpp"

namespace granmpm {

template <int dim>
void fluidity_element_contribution(const double *xi, double h, double vol, double w, double gloc, double k, double *Ke, double *fe) {
  constexpr int nn = 1 << dim;
  double S[nn], dS[nn][dim];
  for (int n = 0; n < nn; ++n) {
    S[n] = 1;
    for (int d = 0; d < dim; ++d) {
      const int bit = (n >> d) & 1;
      S[n] *= bit ? xi[d] : 1.0 - xi[d];
    }
    for (int d = 0; d < dim; ++d) {
      double g = 1;
      for (int e = 0; e < dim; ++e) {
        const int bit = (n >> e) & 1;
        if (e == d) g *= (bit ? 1.0 : -1.0) / h;
        else g *= bit ? xi[e] : 1.0 - xi[e];
      }
      dS[n][d] = g;
    }
  }
  for (int a = 0; a < nn; ++a) {
    fe[a] += vol * w * gloc * S[a];
    for (int b = 0; b < nn; ++b) {
      double gg = 0;
      for (int d = 0; d < dim; ++d) gg += dS[a][d] * dS[b][d];
      Ke[a * nn + b] += vol * (w * S[a] * S[b] + k * gg);
    }
  }
}

template <int dim>
void fluidity_cell_contribution(double h, double phi, double Wm, double F, double k, double *Ke, double *fe) {
  // Exact integrals of the Q1 products over the cell, times the cell averages of the
  // coefficients: 1D mass h/3 (same node) or h/6, 1D stiffness +-1/h.
  constexpr int nn = 1 << dim;
  const double hd = std::pow(h, dim);
  for (int a = 0; a < nn; ++a) {
    fe[a] += F / nn;
    for (int b = 0; b < nn; ++b) {
      double m[dim], mass = 1;
      for (int d = 0; d < dim; ++d) {
        m[d] = (((a >> d) & 1) == ((b >> d) & 1)) ? 1.0 / 3 : 1.0 / 6;
        mass *= m[d];
      }
      double stiff = 0;
      for (int d = 0; d < dim; ++d) {
        double t = (((a >> d) & 1) == ((b >> d) & 1)) ? 1.0 : -1.0;
        for (int e = 0; e < dim; ++e)
          if (e != d) t *= m[e];
        stiff += t;
      }
      Ke[a * nn + b] += Wm * hd * mass + phi * k * std::pow(h, dim - 2) * stiff;
    }
  }
}

template <int dim>
FluiditySolver<dim>::FluiditySolver(const Grid<dim> &grid, const Config &cfg) : grid_(grid), gp_(cfg.gran) {
  k_ = std::pow(cfg.gran.A * cfg.gran.d, 2);
  dirichlet_ = cfg.fluidity_bc == FluidityBC::Dirichlet;
  local_only_ = (cfg.gran.A == 0);
  pc_interval_ = cfg.fluidity_pc_interval;
  da_ = grid.create_scalar_da(1);
  GM_CALL(DMCreateGlobalVector(da_, &g_));
  GM_CALL(VecDuplicate(g_, &f_));
  GM_CALL(VecDuplicate(g_, &work_g_));
  GM_CALL(VecDuplicate(g_, &work2_g_));
  GM_CALL(DMCreateLocalVector(da_, &gl_));
  GM_CALL(VecDuplicate(gl_, &work_l_));
  GM_CALL(VecDuplicate(gl_, &work2_l_));
  GM_CALL(VecGetOwnershipRange(g_, &rstart_, NULL));
  GM_CALL(DMCreateMatrix(da_, &K_)); // full 9/27-point pattern, kept for the whole run
  GM_CALL(MatSetOption(K_, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));
  resolve_max_ = cfg.fluidity_resolve_max;
  cell_quad_ = cfg.fluidity_quadrature == FluidityQuadrature::Cell;
  resolve_tol_ = cfg.fluidity_resolve_tol;
  GM_CALL(KSPCreate(grid.comm, &ksp_));
  GM_CALL(KSPSetOptionsPrefix(ksp_, "fluidity_"));
  PC pc;
  GM_CALL(KSPGetPC(ksp_, &pc));
  // The system is SPD with a fixed pattern. A Cholesky factorisation in RCM order costs
  // about n b^2 with the bandwidth b ~ n / (longest extent); for the 2D chutes (b <= 10)
  // that is a few microseconds, far below one AMG set-up (seed 000's 80-cell chute:
  // 200 us per BoomerAMG set-up + solve). Large grids keep CG + BoomerAMG.
  const double nodes = (double)grid.M[0] * grid.M[1] * grid.M[2];
  const double extent = std::max({grid.M[0], grid.M[1], grid.M[2]});
  const double band = nodes / extent;
  direct_ = cfg.fluidity_solver == FluiditySolverKind::Direct ||
            (cfg.fluidity_solver == FluiditySolverKind::Auto && nodes * band * band <= kDirectCostMax);
  if (direct_) {
    // CG preconditioned by the Cholesky factor: one or two iterations. Not preonly: with
    // one particle at the centre of each cell the point quadrature has the hourglass
    // (checkerboard) mode in its null space, so the matrix can be singular (consistent
    // right-hand side) and the factorisation needs the positive-definite shift.
    GM_CALL(KSPSetType(ksp_, KSPCG));
    PC fpc = pc;
    if (grid.size > 1) {
      // Every rank factors the whole (small) system: a gather instead of a parallel
      // factorisation, and the same result on any rank count to round-off.
      GM_CALL(PCSetType(pc, PCREDUNDANT));
      KSP inner;
      GM_CALL(PCRedundantGetKSP(pc, &inner));
      GM_CALL(KSPSetType(inner, KSPPREONLY));
      GM_CALL(KSPGetPC(inner, &fpc));
    }
    GM_CALL(PCSetType(fpc, PCCHOLESKY));
    GM_CALL(PCFactorSetMatOrderingType(fpc, MATORDERINGRCM));
    GM_CALL(PCFactorSetShiftType(fpc, MAT_SHIFT_POSITIVE_DEFINITE));
    GM_CALL(KSPSetTolerances(ksp_, 1e-8, PETSC_DEFAULT, 1e50, PETSC_DEFAULT));
    GM_CALL(KSPSetInitialGuessNonzero(ksp_, PETSC_TRUE));
  } else {
    GM_CALL(KSPSetType(ksp_, KSPCG));
    GM_CALL(PCSetType(pc, PCHYPRE));
    GM_CALL(PCHYPRESetType(pc, "boomeramg"));
    // No divergence test against ||b||: the previous step's g is the initial guess, and when
    // the flow stops ||b|| can drop by orders of magnitude in one step while the guess is
    // still good (PETSc's default dtol 1e4 then reports DIVERGED_DTOL at iteration 0).
    GM_CALL(KSPSetTolerances(ksp_, 1e-8, PETSC_DEFAULT, 1e50, PETSC_DEFAULT));
    GM_CALL(KSPSetInitialGuessNonzero(ksp_, PETSC_TRUE));
  }
  GM_CALL(KSPSetFromOptions(ksp_));
  {
    KSPType kt;
    GM_CALL(KSPGetType(ksp_, &kt));
    // preonly refuses a nonzero initial guess (a user may switch to it by options).
    if (std::string(kt) == KSPPREONLY) GM_CALL(KSPSetInitialGuessNonzero(ksp_, PETSC_FALSE));
  }
  // GAMG reuses its interpolation by default in 3.18; the active set changes every step,
  // which then doubles the iterations or breaks CG (../shared/notes section 3.2).
  PetscBool isgamg, user_set;
  GM_CALL(PetscObjectTypeCompare((PetscObject)pc, PCGAMG, &isgamg));
  GM_CALL(PetscOptionsHasName(NULL, "fluidity_", "-pc_gamg_reuse_interpolation", &user_set));
  if (isgamg && !user_set) GM_CALL(PCGAMGSetReuseInterpolation(pc, PETSC_FALSE));
}

template <int dim>
FluiditySolver<dim>::~FluiditySolver() {
  KSPDestroy(&ksp_);
  MatDestroy(&K_);
  Vec *vs[] = {&g_, &f_, &gl_, &work_l_, &work_g_, &work2_l_, &work2_g_};
  for (Vec *v : vs)
    if (*v) VecDestroy(v);
  DMDestroy(&da_);
}

template <int dim>
PetscInt FluiditySolver<dim>::row_of(int i, int j, int k) const {
  const int *xs = grid_.xs, *xm = grid_.xm;
  return rstart_ + (i - xs[0]) + xm[0] * ((j - xs[1]) + (PetscInt)xm[1] * (dim == 3 ? (k - xs[2]) : 0));
}

template <int dim>
void FluiditySolver<dim>::assemble(const double *x, const double *vol, const double *w, const double *gloc, PetscInt n) {
  const Grid<dim> &G = grid_;
  constexpr int nn = 1 << dim;
  const int nx = G.xm[0], ny = G.xm[1], nz = dim == 3 ? G.xm[2] : 1;
  const int ncells = nx * ny * nz;
  // Counting sort of the particles by local cell: each cell's element matrix is then
  // accumulated once and inserted with a single MatSetValuesStencil.
  cell_start_.assign(ncells + 1, 0);
  order_.resize(n);
  std::vector<int> cell(n);
  for (PetscInt p = 0; p < n; ++p) {
    int c[3] = {0, 0, 0};
    for (int d = 0; d < dim; ++d) c[d] = std::min(G.cell_of(d, x[p * dim + d]) - G.xs[d], G.xm[d] - 1);
    cell[p] = (c[2] * ny + c[1]) * nx + c[0];
    cell_start_[cell[p] + 1]++;
  }
  for (int c = 0; c < ncells; ++c) cell_start_[c + 1] += cell_start_[c];
  {
    std::vector<int> fill(cell_start_.begin(), cell_start_.end() - 1);
    for (PetscInt p = 0; p < n; ++p) order_[fill[cell[p]]++] = (int)p;
  }

  GM_CALL(MatZeroEntries(K_));
  GM_CALL(VecZeroEntries(work_l_));  // active-node marks
  GM_CALL(VecZeroEntries(work2_l_)); // sum S V (nodal projection weight)
  GM_CALL(VecZeroEntries(gl_));      // local f, then sum S V gloc
  double *fa, *act, *sv;
  GM_CALL(VecGetArray(gl_, &fa));
  GM_CALL(VecGetArray(work_l_, &act));
  GM_CALL(VecGetArray(work2_l_, &sv));
  std::vector<double> gsum(dirichlet_ ? 0 : 0);
  const int *gs = G.xs; // ghost start of the width-1 DMDA = owned start - 1 (or wrap)
  DMDALocalInfo li;
  GM_CALL(DMDAGetLocalInfo(da_, &li));
  const int lgs[3] = {li.gxs, li.gys, li.gzs}, lgm[3] = {li.gxm, li.gym, li.gzm};
  (void)gs;
  auto lidx = [&](int i, int j, int k) { return ((long)(k - lgs[2]) * lgm[1] + (j - lgs[1])) * lgm[0] + (i - lgs[0]); };
  std::vector<double> fproj(dirichlet_ ? (size_t)lgm[0] * lgm[1] * lgm[2] : 0, 0.0);
  double Ke[nn * nn], fe[nn];
  MatStencil st[nn];
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const int c = (k * ny + j) * nx + i;
        if (cell_start_[c] == cell_start_[c + 1]) continue;
        const int ci[3] = {G.xs[0] + i, G.xs[1] + j, dim == 3 ? G.xs[2] + k : 0};
        std::memset(Ke, 0, sizeof Ke);
        std::memset(fe, 0, sizeof fe);
        double wsum[nn] = {0}, wg[nn] = {0}, cV = 0, cW = 0, cF = 0;
        for (int q = cell_start_[c]; q < cell_start_[c + 1]; ++q) {
          const int p = order_[q];
          double xi[dim];
          for (int d = 0; d < dim; ++d) xi[d] = (x[p * dim + d] - G.node_x(d, ci[d])) * G.inv_h;
          if (cell_quad_) {
            cV += vol[p];
            cW += vol[p] * w[p];
            cF += vol[p] * w[p] * gloc[p];
          } else {
            fluidity_element_contribution<dim>(xi, G.h, vol[p], w[p], gloc[p], k_, Ke, fe);
          }
          if (dirichlet_) {
            for (int a = 0; a < nn; ++a) {
              double S = 1;
              for (int d = 0; d < dim; ++d) S *= ((a >> d) & 1) ? xi[d] : 1.0 - xi[d];
              wsum[a] += S * vol[p];
              wg[a] += S * vol[p] * gloc[p];
            }
          }
        }
        if (cell_quad_) fluidity_cell_contribution<dim>(G.h, cV / std::pow(G.h, dim), cW / std::pow(G.h, dim), cF, k_, Ke, fe);
        for (int a = 0; a < nn; ++a) {
          const int ni = ci[0] + (a & 1), nj = ci[1] + ((a >> 1) & 1), nk = dim == 3 ? ci[2] + ((a >> 2) & 1) : 0;
          st[a].i = ni;
          st[a].j = nj;
          st[a].k = nk;
          st[a].c = 0;
          const long l = lidx(ni, nj, nk);
          fa[l] += fe[a];
          act[l] += 1.0;
          if (dirichlet_) {
            sv[l] += wsum[a];
            fproj[l] += wg[a];
          }
        }
        GM_CALL(MatSetValuesStencil(K_, nn, st, nn, st, Ke, ADD_VALUES));
      }
  GM_CALL(VecRestoreArray(gl_, &fa));
  GM_CALL(VecRestoreArray(work_l_, &act));
  GM_CALL(VecRestoreArray(work2_l_, &sv));
  GM_CALL(MatAssemblyBegin(K_, MAT_FINAL_ASSEMBLY));
  GM_CALL(VecZeroEntries(f_));
  GM_CALL(DMLocalToGlobalBegin(da_, gl_, ADD_VALUES, f_));
  GM_CALL(DMLocalToGlobalEnd(da_, gl_, ADD_VALUES, f_));
  GM_CALL(VecZeroEntries(work_g_));
  GM_CALL(DMLocalToGlobalBegin(da_, work_l_, ADD_VALUES, work_g_));
  GM_CALL(DMLocalToGlobalEnd(da_, work_l_, ADD_VALUES, work_g_));
  Vec proj_g = nullptr;
  if (dirichlet_) {
    GM_CALL(VecZeroEntries(work2_g_));
    GM_CALL(DMLocalToGlobalBegin(da_, work2_l_, ADD_VALUES, work2_g_));
    GM_CALL(DMLocalToGlobalEnd(da_, work2_l_, ADD_VALUES, work2_g_));
    // Reuse the local work vector for the sum S V gloc.
    double *pl;
    GM_CALL(VecGetArray(work2_l_, &pl));
    std::copy(fproj.begin(), fproj.end(), pl);
    GM_CALL(VecRestoreArray(work2_l_, &pl));
    GM_CALL(VecDuplicate(f_, &proj_g));
    GM_CALL(VecZeroEntries(proj_g));
    GM_CALL(DMLocalToGlobalBegin(da_, work2_l_, ADD_VALUES, proj_g));
    GM_CALL(DMLocalToGlobalEnd(da_, work2_l_, ADD_VALUES, proj_g));
  }
  GM_CALL(MatAssemblyEnd(K_, MAT_FINAL_ASSEMBLY));

  // Inactive nodes -> identity rows with g = 0; wall nodes -> g = g_loc when Dirichlet.
  std::vector<PetscInt> rows;
  const double *a, *wsv = nullptr, *pg = nullptr;
  double *gv;
  GM_CALL(VecGetArrayRead(work_g_, &a));
  GM_CALL(VecGetArray(g_, &gv));
  if (dirichlet_) {
    GM_CALL(VecGetArrayRead(work2_g_, &wsv));
    GM_CALL(VecGetArrayRead(proj_g, &pg));
  }
  long idx = 0;
  const int k0 = G.xs[2], k1 = dim == 3 ? G.xs[2] + G.xm[2] : 1;
  for (int k = k0; k < k1; ++k)
    for (int j = G.xs[1]; j < G.xs[1] + G.xm[1]; ++j)
      for (int i = G.xs[0]; i < G.xs[0] + G.xm[0]; ++i, ++idx) {
        if (a[idx] == 0) {
          rows.push_back(row_of(i, j, k));
          gv[idx] = 0;
          continue;
        }
        if (zero_at_) {
          const int ijk[3] = {i, j, k};
          double xn[3] = {0, 0, 0};
          for (int d = 0; d < dim; ++d) xn[d] = G.node_x(d, ijk[d]);
          if (zero_at_(xn)) {
            rows.push_back(row_of(i, j, k));
            gv[idx] = 0;
            continue;
          }
        }
        if (dirichlet_ && wsv[idx] > 0) {
          const int ijk[3] = {i, j, k};
          bool wall = false;
          for (int d = 0; d < dim; ++d) {
            if (G.periodic[d]) continue;
            if ((ijk[d] == G.pad[d] && G.bc[d][0] != BC::Free && G.bc[d][0] != BC::Outlet) ||
                (ijk[d] == G.pad[d] + G.ncell[d] && G.bc[d][1] != BC::Free && G.bc[d][1] != BC::Outlet))
              wall = true;
          }
          if (wall) {
            rows.push_back(row_of(i, j, k));
            gv[idx] = pg[idx] / wsv[idx];
          }
        }
      }
  GM_CALL(VecRestoreArrayRead(work_g_, &a));
  GM_CALL(VecRestoreArray(g_, &gv));
  if (dirichlet_) {
    GM_CALL(VecRestoreArrayRead(work2_g_, &wsv));
    GM_CALL(VecRestoreArrayRead(proj_g, &pg));
    GM_CALL(VecDestroy(&proj_g));
  }
  GM_CALL(MatZeroRowsColumns(K_, (PetscInt)rows.size(), rows.data(), 1.0, g_, f_));
  if (pc_interval_ > 1) {
    // Only a reused preconditioner needs to know whether the active set changed (one
    // reduction per step); with the default interval 1 it is rebuilt every solve anyway.
    int changed = rows != prev_rows_, any = 0;
    MPI_Allreduce(&changed, &any, 1, MPI_INT, MPI_MAX, grid_.comm);
    rows_changed_ = any != 0;
    if (rows_changed_) prev_rows_.swap(rows);
  }
}

template <int dim>
bool FluiditySolver<dim>::consistent_residual() {
  // The point quadrature can make the matrix singular (a lone particle: rank 1 + dim of
  // 2^dim per cell; one particle at each cell centre: the checkerboard mode), with a
  // consistent right-hand side. CG then meets p^T K p = 0 once the residual is round-off:
  // the iterate is a solution if its residual is at the tolerance.
  PetscReal rn, bn, rtol;
  GM_CALL(MatMult(K_, g_, work_g_));
  GM_CALL(VecAYPX(work_g_, -1.0, f_));
  GM_CALL(VecNorm(work_g_, NORM_2, &rn));
  GM_CALL(VecNorm(f_, NORM_2, &bn));
  GM_CALL(KSPGetTolerances(ksp_, &rtol, NULL, NULL, NULL));
  if (bn == 0) {
    // No source anywhere (stress-free particles only): the solution is g = 0.
    GM_CALL(VecZeroEntries(g_));
    return true;
  }
  return rn <= rtol * bn;
}

template <int dim>
void FluiditySolver<dim>::solve_system() {
  // The matrix changes a little every step (mu follows the stress); building the AMG
  // hierarchy costs several solves, so it is kept for -fluidity_pc_interval solves while
  // the active set is unchanged. The solution is the same to the KSP tolerance.
  bool rebuild = rows_changed_ || since_setup_ + 1 >= pc_interval_ || pc_setups == 0;
  KSPConvergedReason reason;
  for (int attempt = 0; attempt < 2; ++attempt) {
    GM_CALL(KSPSetOperators(ksp_, K_, K_));
    GM_CALL(KSPSetReusePreconditioner(ksp_, rebuild ? PETSC_FALSE : PETSC_TRUE));
    if (rebuild) {
      ++pc_setups;
      since_setup_ = 0;
    } else {
      ++since_setup_;
    }
    GM_CALL(KSPSolve(ksp_, f_, g_));
    GM_CALL(KSPGetConvergedReason(ksp_, &reason));
    GM_CALL(KSPGetIterationNumber(ksp_, &last_iterations));
    if (reason == KSP_DIVERGED_INDEFINITE_MAT && direct_ && consistent_residual()) reason = KSP_CONVERGED_ATOL;
    if (reason >= 0 || rebuild) break;
    rebuild = true; // a stale preconditioner failed: rebuild and solve again
  }
  ++solves;
  iterations_total += last_iterations;
  if (reason < 0)
    collective_fail(grid_.comm, true,
                    std::string("the fluidity solve did not converge (KSP reason ") + KSPConvergedReasons[reason] + " after " + std::to_string(last_iterations) +
                        " iterations); tune -fluidity_ksp_type, -fluidity_pc_type, -fluidity_ksp_max_it or -fluidity_ksp_rtol");
}

template <int dim>
void FluiditySolver<dim>::map_to_particles(const double *x, PetscInt n, FluidityMap map, double *g) const {
  const Grid<dim> &G = grid_;
  GM_CALL(DMGlobalToLocalBegin(da_, g_, INSERT_VALUES, gl_));
  GM_CALL(DMGlobalToLocalEnd(da_, g_, INSERT_VALUES, gl_));
  DMDALocalInfo li;
  GM_CALL(DMDAGetLocalInfo(da_, &li));
  const int lgs[3] = {li.gxs, li.gys, li.gzs}, lgm[3] = {li.gxm, li.gym, li.gzm};
  const double *a;
  GM_CALL(VecGetArrayRead(gl_, &a));
  constexpr int nn = 1 << dim;
  for (PetscInt p = 0; p < n; ++p) {
    int c[3] = {0, 0, 0};
    double xi[3] = {0, 0, 0};
    for (int d = 0; d < dim; ++d) {
      c[d] = std::min(G.cell_of(d, x[p * dim + d]), G.xs[d] + G.xm[d] - 1);
      xi[d] = (x[p * dim + d] - G.node_x(d, c[d])) * G.inv_h;
    }
    double s = 0;
    for (int q = 0; q < nn; ++q) {
      const int ni = c[0] + (q & 1), nj = c[1] + ((q >> 1) & 1), nk = dim == 3 ? c[2] + ((q >> 2) & 1) : 0;
      const double v = a[((long)(nk - lgs[2]) * lgm[1] + (nj - lgs[1])) * lgm[0] + (ni - lgs[0])];
      if (map == FluidityMap::CellAverage) {
        s += v / nn;
      } else {
        double S = 1;
        for (int d = 0; d < dim; ++d) S *= ((q >> d) & 1) ? xi[d] : 1.0 - xi[d];
        s += S * v;
      }
    }
    g[p] = s;
  }
  GM_CALL(VecRestoreArrayRead(gl_, &a));
}

template <int dim>
void FluiditySolver<dim>::solve(Particles<dim> &parts, FluidityMap map, long step) {
  ParticleView<dim> P = parts.get();
  w_.resize(P.n);
  gloc_.resize(P.n);
  for (PetscInt p = 0; p < P.n; ++p) {
    const FluiditySource src = fluidity_source(gp_, sym6_to_mat(P.s + 6 * p));
    w_[p] = src.weight;
    gloc_[p] = src.g_loc;
  }
  if (local_only_) {
    // A = 0: no cooperativity, the fluidity is the local one.
    for (PetscInt p = 0; p < P.n; ++p) P.g[p] = gloc_[p];
    parts.restore(P);
    return;
  }
  if (P.gsplit && !resolve_due(P, step)) {
    // Between solves the local part follows the stress every step; the nonlocal part
    // g - g_loc of each particle is the one of the last solve. (Freezing all of g instead
    // is unstable: 24% error on the 80-cell chute with a solve every 20 steps.)
    for (PetscInt p = 0; p < P.n; ++p) P.g[p] = gloc_[p] + P.gsplit[2 * p];
    ++skipped;
    parts.restore(P);
    return;
  }
  assemble(P.x, P.vol, w_.data(), gloc_.data(), P.n);
  solve_system();
  map_to_particles(P.x, P.n, map, P.g);
  if (P.gsplit) {
    // Step-size control on the solve interval: the error the skipped steps made is the
    // distance between the solved g and the split prediction; it grows about linearly with
    // the interval, and a too long interval lets a lagged-feedback instability grow (the
    // 80-cell chute with a fixed interval of 40 steps: 5e-3 error against 7.8e-4).
    double loc[2] = {0, 0}, glob[2];
    for (PetscInt p = 0; p < P.n; ++p) {
      loc[0] = std::max(loc[0], std::fabs(P.g[p] - gloc_[p] - P.gsplit[2 * p]));
      loc[1] = std::max(loc[1], std::fabs(P.g[p]));
      P.gsplit[2 * p] = P.g[p] - gloc_[p];
      P.gsplit[2 * p + 1] = gloc_[p];
    }
    MPI_Allreduce(loc, glob, 2, MPI_DOUBLE, MPI_MAX, grid_.comm);
    last_prediction_error = glob[1] > 0 ? glob[0] / glob[1] : 0.0;
    const double e = last_prediction_error, tol = resolve_tol_;
    double factor = 2;
    if (e > 0) factor = std::min(2.0, std::max(0.5, 0.7 * tol / e));
    if (e > tol) factor = std::min(factor, 0.5);
    interval_ = std::max(1, std::min(resolve_max_, (int)std::floor(interval_ * factor)));
    if (interval_ == 1 && factor > 1) interval_ = 2;
    interval_ = std::min(interval_, resolve_max_);
    next_solve_ = step + interval_;
  }
  parts.restore(P);
}

template <int dim>
bool FluiditySolver<dim>::resolve_due(const ParticleView<dim> &P, long step) const {
  // A function of the particle fields and of (interval_, next_solve_), which go into the
  // checkpoint, so a restart takes the same decisions as the uninterrupted run. Besides
  // the planned step, a sudden change of g_loc (an impact) triggers a solve at once.
  if (step >= next_solve_) return true;
  double loc[2] = {0, 0}, glob[2]; // max |g_loc - g_loc at the last solve|, max |g|
  for (PetscInt p = 0; p < P.n; ++p) {
    loc[0] = std::max(loc[0], std::fabs(gloc_[p] - P.gsplit[2 * p + 1]));
    loc[1] = std::max(loc[1], std::max(std::fabs(P.g[p]), gloc_[p]));
  }
  MPI_Allreduce(loc, glob, 2, MPI_DOUBLE, MPI_MAX, grid_.comm);
  return glob[0] > kChangeFactor * resolve_tol_ * glob[1];
}

template class FluiditySolver<2>;
template class FluiditySolver<3>;
template void fluidity_element_contribution<2>(const double *, double, double, double, double, double, double *, double *);
template void fluidity_element_contribution<3>(const double *, double, double, double, double, double, double *, double *);
template void fluidity_cell_contribution<2>(double, double, double, double, double, double *, double *);
template void fluidity_cell_contribution<3>(double, double, double, double, double, double *, double *);

} // namespace granmpm
