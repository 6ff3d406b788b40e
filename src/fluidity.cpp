// FluiditySolver<dim> (fluidity.hpp): set-up, assembly, the iterative path, the per-step
// source and the solve schedule. The band path's node order and map: fluidity_band.cpp;
// the pure kernels: fluidity_kernels.cpp.
#include "granmpm/fluidity.hpp"

#include <petscdmswarm.h>
#include <petscpc.h>

#include <cmath>
#include <algorithm>
#include <cstring>
#include <mpi.h>
#include <string>

#include "granmpm/materials/nonlocal_ngf.hpp"

namespace granmpm {

namespace {
// -log_view events of the steady fluidity (inside the Fluidity stage).
PetscLogEvent ev_source = 0, ev_assemble = 0, ev_solve = 0, ev_map = 0;
void register_events() {
  static bool done = false;
  if (done) return;
  done = true;
  PetscClassId cid;
  GM_CALL(PetscClassIdRegister("GranMPM fluidity", &cid));
  GM_CALL(PetscLogEventRegister("FluiditySource", cid, &ev_source));
  GM_CALL(PetscLogEventRegister("FluidityAssemble", cid, &ev_assemble));
  GM_CALL(PetscLogEventRegister("FluiditySolve", cid, &ev_solve));
  GM_CALL(PetscLogEventRegister("FluidityMap", cid, &ev_map));
}
} // namespace

template <int dim>
FluiditySolver<dim>::FluiditySolver(const Grid<dim> &grid, const Config &cfg) : grid_(grid), gp_(cfg.gran) {
  register_events();
  k_ = nonlocal_k(cfg.gran); // (A d)^2 as the material forms it (local_mu_i.hpp)
  dirichlet_ = cfg.fluidity_bc == FluidityBC::Dirichlet;
  local_only_ = (cfg.gran.A == 0);
  pc_interval_ = cfg.fluidity_pc_interval;
  resolve_max_ = cfg.fluidity_resolve_max;
  cell_quad_ = cfg.fluidity_quadrature == FluidityQuadrature::Cell;
  resolve_tol_ = cfg.fluidity_resolve_tol;
  da_ = grid.create_scalar_da(1);
  GM_CALL(DMCreateGlobalVector(da_, &g_));
  GM_CALL(VecDuplicate(g_, &f_));
  GM_CALL(VecDuplicate(g_, &work_g_));
  GM_CALL(VecDuplicate(g_, &work2_g_));
  GM_CALL(DMCreateLocalVector(da_, &gl_));
  GM_CALL(VecDuplicate(gl_, &work_l_));
  GM_CALL(VecDuplicate(gl_, &work2_l_));
  GM_CALL(VecGetOwnershipRange(g_, &rstart_, NULL));
  choose_band_order();
  // The system is SPD. Its Cholesky factor in band form costs n b^2 / 2 flops: for the
  // 2D chutes (b <= 10) a few microseconds, far below one AMG set-up (seed 000's 80-cell
  // chute: 200 us per BoomerAMG set-up + solve). Large grids keep CG + BoomerAMG.
  const double nodes = (double)nb_, b = bw_, storage = nodes * (b + 1);
  if (cfg.fluidity_solver == FluiditySolverKind::Direct && storage > kBandStorageMax)
    throw UserError("-fluidity_solver direct: the band factor of the fluidity system would hold " + std::to_string((long)storage) + " entries (" +
                    std::to_string(nb_) + " nodes, half-bandwidth " + std::to_string(bw_) + "), above " + std::to_string((long)kBandStorageMax) +
                    "; use -fluidity_solver iterative or auto");
  banded_ = cfg.fluidity_solver == FluiditySolverKind::Direct ||
            (cfg.fluidity_solver == FluiditySolverKind::Auto && nodes * b * b <= kDirectCostMax && storage <= kBandStorageAuto);
  if (banded_) {
    // The band solve's stopping test is the KSP's relative tolerance option.
    PetscReal rt;
    PetscBool set;
    GM_CALL(PetscOptionsGetReal(NULL, "fluidity_", "-ksp_rtol", &rt, &set));
    if (set) rtol_ = rt;
    return;
  }
  GM_CALL(DMCreateMatrix(da_, &K_)); // full 9/27-point pattern, kept for the whole run
  GM_CALL(MatSetOption(K_, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));
  GM_CALL(KSPCreate(grid.comm, &ksp_));
  GM_CALL(KSPSetOptionsPrefix(ksp_, "fluidity_"));
  PC pc;
  GM_CALL(KSPGetPC(ksp_, &pc));
  GM_CALL(KSPSetType(ksp_, KSPCG));
  GM_CALL(PCSetType(pc, PCHYPRE));
  GM_CALL(PCHYPRESetType(pc, "boomeramg"));
  // No divergence test against ||b||: the previous step's g is the initial guess, and when
  // the flow stops ||b|| can drop by orders of magnitude in one step while the guess is
  // still good (PETSc's default dtol 1e4 then reports DIVERGED_DTOL at iteration 0).
  GM_CALL(KSPSetTolerances(ksp_, 1e-8, PETSC_DEFAULT, 1e50, PETSC_DEFAULT));
  GM_CALL(KSPSetInitialGuessNonzero(ksp_, PETSC_TRUE));
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
  if (ksp_) KSPDestroy(&ksp_);
  if (K_) MatDestroy(&K_);
  Vec *vs[] = {&g_, &f_, &gl_, &work_l_, &work_g_, &work2_l_, &work2_g_};
  for (Vec *v : vs)
    if (*v) VecDestroy(v);
  DMDestroy(&da_);
}

template <int dim>
void FluiditySolver<dim>::sort_by_cell(const double *x, PetscInt n) {
  // Counting sort of the particles by local cell: each cell's element matrix is then
  // accumulated once and added in one go.
  const Grid<dim> &G = grid_;
  const int nx = G.xm[0], ny = G.xm[1], nz = dim == 3 ? G.xm[2] : 1;
  const int ncells = nx * ny * nz;
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
  std::vector<int> fill(cell_start_.begin(), cell_start_.end() - 1);
  for (PetscInt p = 0; p < n; ++p) order_[fill[cell[p]]++] = (int)p;
}

template <int dim>
template <class Sink>
void FluiditySolver<dim>::for_each_cell(const double *x, const double *vol, const double *w, const double *gloc, Sink sink) {
  // Element matrix and vector of every particle-holding owned cell (after sort_by_cell),
  // with the nodal projection sums S V and S V g_loc for the Dirichlet wall values.
  const Grid<dim> &G = grid_;
  constexpr int nn = 1 << dim;
  const double hd = std::pow(G.h, dim);
  double Ke[nn * nn], fe[nn], wsum[nn], wg[nn];
  for_each_occupied_cell([&](int c, const int *ci) {
        std::fill(Ke, Ke + nn * nn, 0.0);
        std::fill(fe, fe + nn, 0.0);
        std::fill(wsum, wsum + nn, 0.0);
        std::fill(wg, wg + nn, 0.0);
        double cV = 0, cW = 0, cF = 0;
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
          if (dirichlet_)
            for (int a = 0; a < nn; ++a) {
              double S = 1;
              for (int d = 0; d < dim; ++d) S *= ((a >> d) & 1) ? xi[d] : 1.0 - xi[d];
              wsum[a] += S * vol[p];
              wg[a] += S * vol[p] * gloc[p];
            }
        }
        if (cell_quad_) fluidity_cell_contribution<dim>(G.h, cV / hd, cW / hd, cF, k_, Ke, fe);
        sink(ci, Ke, fe, wsum, wg);
      });
}

template <int dim>
void FluiditySolver<dim>::assemble(const double *x, const double *vol, const double *w, const double *gloc, PetscInt n) {
  GM_CALL(PetscLogEventBegin(ev_assemble, 0, 0, 0, 0));
  sort_by_cell(x, n);
  if (banded_) {
    assemble_band(x, vol, w, gloc);
  } else {
    assemble_mat(x, vol, w, gloc);
    finish_mat();
  }
  GM_CALL(PetscLogEventEnd(ev_assemble, 0, 0, 0, 0));
}

template <int dim>
void FluiditySolver<dim>::assemble_band(const double *x, const double *vol, const double *w, const double *gloc) {
  // Straight into the band array; with the right-hand side, the active-node counts, the
  // zero-g marks and (Dirichlet) the projection sums, in one buffer that is summed on
  // rank 0.
  const Grid<dim> &G = grid_;
  constexpr int nn = 1 << dim;
  const PetscInt n = nb_, wd = bw_ + 1, nK = n * wd;
  buf_.assign(nK + (dirichlet_ ? 5 : 3) * n, 0.0);
  double *K = buf_.data(), *f = K + nK, *act = f + n, *zero = act + n, *sv = zero + n, *proj = sv + n;
  for_each_cell(x, vol, w, gloc, [&](const int *ci, const double *Ke, const double *fe, const double *wsum, const double *wg) {
    PetscInt q[nn];
    for (int a = 0; a < nn; ++a) q[a] = band_index(ci[0] + (a & 1), ci[1] + ((a >> 1) & 1), dim == 3 ? ci[2] + ((a >> 2) & 1) : 0);
    for (int a = 0; a < nn; ++a) {
      f[q[a]] += fe[a];
      act[q[a]] += 1;
      if (dirichlet_) {
        sv[q[a]] += wsum[a];
        proj[q[a]] += wg[a];
      }
      double *row = K + q[a] * wd + bw_ - q[a];
      for (int b = 0; b < nn; ++b)
        if (q[b] <= q[a]) row[q[b]] += Ke[a * nn + b];
    }
  });
  if (zero_at_) {
    const int k0 = G.xs[2], k1 = dim == 3 ? G.xs[2] + G.xm[2] : 1;
    for (int k = k0; k < k1; ++k)
      for (int j = G.xs[1]; j < G.xs[1] + G.xm[1]; ++j)
        for (int i = G.xs[0]; i < G.xs[0] + G.xm[0]; ++i) {
          const int ijk[3] = {i, j, k};
          double xn[3] = {0, 0, 0};
          for (int d = 0; d < dim; ++d) xn[d] = G.node_x(d, ijk[d]);
          if (zero_at_(xn)) zero[band_index(i, j, k)] = 1;
        }
  }
  if (G.size > 1) {
    if (G.rank == 0) MPI_Reduce(MPI_IN_PLACE, buf_.data(), (int)buf_.size(), MPI_DOUBLE, MPI_SUM, 0, G.comm);
    else MPI_Reduce(buf_.data(), nullptr, (int)buf_.size(), MPI_DOUBLE, MPI_SUM, 0, G.comm);
  }
}

template <int dim>
void FluiditySolver<dim>::solve_band() {
  const Grid<dim> &G = grid_;
  const PetscInt n = nb_, nK = n * (bw_ + 1);
  sol_.resize(n + 1);
  if (G.rank == 0) {
    double *K = buf_.data(), *f = K + nK, *act = f + n, *zero = act + n;
    band_boundary_rows(K, f, act, zero, zero + n, zero + 2 * n);
    fac_.assign(K, K + nK);
    const int replaced = band_cholesky(n, bw_, fac_.data());
    replaced_pivots += replaced;
    if (replaced == 0) {
      // An exact factor: the solve is exact to round-off (CG would stop after 1 iteration).
      std::copy(f, f + n, sol_.data());
      band_solve(n, bw_, fac_.data(), sol_.data());
      sol_[n] = 1;
    } else {
      work_.resize(4 * n);
      sol_[n] = band_pcg(n, bw_, K, fac_.data(), f, sol_.data(), rtol_, 50, work_.data());
    }
  }
  if (G.size > 1) MPI_Bcast(sol_.data(), (int)(n + 1), MPI_DOUBLE, 0, G.comm);
  last_iterations = (PetscInt)sol_[n];
  if (last_iterations < 0)
    collective_fail(G.comm, true,
                    "the banded fluidity solve did not reach -fluidity_ksp_rtol " + std::to_string(rtol_) +
                        " in 50 preconditioned CG iterations (a singular system?); try -fluidity_solver iterative");
  // The owned part into the DMDA vector (checkpoints, output, the iterative path's guess).
  double *gv;
  GM_CALL(VecGetArray(g_, &gv));
  long idx = 0;
  const int k0 = G.xs[2], k1 = dim == 3 ? G.xs[2] + G.xm[2] : 1;
  for (int k = k0; k < k1; ++k)
    for (int j = G.xs[1]; j < G.xs[1] + G.xm[1]; ++j)
      for (int i = G.xs[0]; i < G.xs[0] + G.xm[0]; ++i) gv[idx++] = sol_[band_index(i, j, k)];
  GM_CALL(VecRestoreArray(g_, &gv));
}

template <int dim>
void FluiditySolver<dim>::assemble_mat(const double *x, const double *vol, const double *w, const double *gloc) {
  constexpr int nn = 1 << dim;
  GM_CALL(MatZeroEntries(K_));
  GM_CALL(VecZeroEntries(work_l_));  // active-node marks
  GM_CALL(VecZeroEntries(work2_l_)); // sum S V (nodal projection weight)
  GM_CALL(VecZeroEntries(gl_));      // local f
  double *fa, *act, *sv;
  GM_CALL(VecGetArray(gl_, &fa));
  GM_CALL(VecGetArray(work_l_, &act));
  GM_CALL(VecGetArray(work2_l_, &sv));
  DMDALocalInfo li;
  GM_CALL(DMDAGetLocalInfo(da_, &li));
  const int lgs[3] = {li.gxs, li.gys, li.gzs}, lgm[3] = {li.gxm, li.gym, li.gzm};
  auto lidx = [&](int i, int j, int k) { return ((long)(k - lgs[2]) * lgm[1] + (j - lgs[1])) * lgm[0] + (i - lgs[0]); };
  std::vector<double> fproj(dirichlet_ ? (size_t)lgm[0] * lgm[1] * lgm[2] : 0, 0.0);
  MatStencil st[nn];
  for_each_cell(x, vol, w, gloc, [&](const int *ci, const double *Ke, const double *fe, const double *wsum, const double *wg) {
    for (int a = 0; a < nn; ++a) {
      st[a].i = ci[0] + (a & 1);
      st[a].j = ci[1] + ((a >> 1) & 1);
      st[a].k = dim == 3 ? ci[2] + ((a >> 2) & 1) : 0;
      st[a].c = 0;
      const long l = lidx(st[a].i, st[a].j, st[a].k);
      fa[l] += fe[a];
      act[l] += 1.0;
      if (dirichlet_) {
        sv[l] += wsum[a];
        fproj[l] += wg[a];
      }
    }
    GM_CALL(MatSetValuesStencil(K_, nn, st, nn, st, Ke, ADD_VALUES));
  });
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
  if (dirichlet_) {
    GM_CALL(VecZeroEntries(work2_g_));
    GM_CALL(DMLocalToGlobalBegin(da_, work2_l_, ADD_VALUES, work2_g_));
    GM_CALL(DMLocalToGlobalEnd(da_, work2_l_, ADD_VALUES, work2_g_));
    // The local f is summed already: reuse gl_ for the sum S V gloc.
    double *pl;
    GM_CALL(VecGetArray(gl_, &pl));
    std::copy(fproj.begin(), fproj.end(), pl);
    GM_CALL(VecRestoreArray(gl_, &pl));
  }
  GM_CALL(MatAssemblyEnd(K_, MAT_FINAL_ASSEMBLY));
}

template <int dim>
void FluiditySolver<dim>::finish_mat() {
  // Inactive nodes -> identity rows with g = 0; wall nodes -> g = g_loc when Dirichlet.
  const Grid<dim> &G = grid_;
  Vec proj_g = nullptr;
  if (dirichlet_) {
    GM_CALL(VecDuplicate(f_, &proj_g));
    GM_CALL(VecZeroEntries(proj_g));
    GM_CALL(DMLocalToGlobalBegin(da_, gl_, ADD_VALUES, proj_g));
    GM_CALL(DMLocalToGlobalEnd(da_, gl_, ADD_VALUES, proj_g));
  }
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
        const int ijk[3] = {i, j, k};
        double xn[3] = {0, 0, 0};
        for (int d = 0; d < dim; ++d) xn[d] = G.node_x(d, ijk[d]);
        if (a[idx] == 0 || (zero_at_ && zero_at_(xn))) {
          rows.push_back(row_of(i, j, k));
          gv[idx] = 0;
          continue;
        }
        if (!dirichlet_ || !(wsv[idx] > 0)) continue;
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
  GM_CALL(PetscLogEventBegin(ev_solve, 0, 0, 0, 0));
  if (banded_) {
    solve_band();
    ++solves;
    iterations_total += last_iterations;
    GM_CALL(PetscLogEventEnd(ev_solve, 0, 0, 0, 0));
    return;
  }
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
    if (reason == KSP_DIVERGED_INDEFINITE_MAT && consistent_residual()) reason = KSP_CONVERGED_ATOL;
    if (reason >= 0 || rebuild) break;
    rebuild = true; // a stale preconditioner failed: rebuild and solve again
  }
  ++solves;
  iterations_total += last_iterations;
  GM_CALL(PetscLogEventEnd(ev_solve, 0, 0, 0, 0));
  if (reason < 0)
    collective_fail(grid_.comm, true,
                    std::string("the fluidity solve did not converge (KSP reason ") + KSPConvergedReasons[reason] + " after " + std::to_string(last_iterations) +
                        " iterations); tune -fluidity_ksp_type, -fluidity_pc_type, -fluidity_ksp_max_it or -fluidity_ksp_rtol");
}

template <int dim>
void FluiditySolver<dim>::map_to_particles(const double *x, PetscInt n, FluidityMap map, double *g) const {
  // Nodal values: the broadcast band solution on every rank, or the ghosted DMDA vector.
  const Grid<dim> &G = grid_;
  const bool band = banded_ && (PetscInt)sol_.size() == nb_ + 1;
  const double *a = nullptr;
  int lgs[3] = {0, 0, 0}, lgm[3] = {1, 1, 1};
  if (band) {
    a = sol_.data();
  } else {
    GM_CALL(DMGlobalToLocalBegin(da_, g_, INSERT_VALUES, gl_));
    GM_CALL(DMGlobalToLocalEnd(da_, g_, INSERT_VALUES, gl_));
    DMDALocalInfo li;
    GM_CALL(DMDAGetLocalInfo(da_, &li));
    lgs[0] = li.gxs, lgs[1] = li.gys, lgs[2] = li.gzs, lgm[0] = li.gxm, lgm[1] = li.gym, lgm[2] = li.gzm;
    GM_CALL(VecGetArrayRead(gl_, &a));
  }
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
      const double v = band ? a[band_index(ni, nj, nk)] : a[((long)(nk - lgs[2]) * lgm[1] + (nj - lgs[1])) * lgm[0] + (ni - lgs[0])];
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
  if (!band) GM_CALL(VecRestoreArrayRead(gl_, &a));
}

template <int dim>
void FluiditySolver<dim>::source_terms(const ParticleView<dim> &P, double *change) {
  // w = |mu - mu_s| and g_loc of every particle from its stress; with the split field also
  // the largest change of g_loc since the last solve and the largest |g| (resolve_due).
  w_.resize(P.n);
  gloc_.resize(P.n);
  change[0] = change[1] = 0;
  double *w = w_.data(), *gl = gloc_.data();
  for (PetscInt p = 0; p < P.n; ++p) { // branch-free: vectorised (-fno-math-errno)
    const FluiditySource src = fluidity_source6(gp_, P.s + 6 * p);
    w[p] = src.weight;
    gl[p] = src.g_loc;
  }
  double c0 = 0, c1 = 0;
  if (P.gsplit)
    for (PetscInt p = 0; p < P.n; ++p) {
      c0 = std::max(c0, std::fabs(gl[p] - P.gsplit[3 * p + 1]));
      c1 = std::max(c1, std::max(std::fabs(P.g[p]), gl[p]));
    }
  change[0] = c0;
  change[1] = c1;
}

template <int dim>
bool FluiditySolver<dim>::change_ahead(const ParticleView<dim> &P, long next_step, double *change) {
  // A planned solve needs no maxima (resolve_due is true without them) and recomputes
  // everything itself, so nothing is done for it.
  if (grid_.size == 1 || local_only_ || !P.gsplit || next_step >= next_solve_) return false;
  double c0 = 0, c1 = 0;
  for (PetscInt p = 0; p < P.n; ++p) {
    const double gl = fluidity_source6(gp_, P.s + 6 * p).g_loc; // the same value source_terms computes
    P.gsplit[3 * p + 2] = gl;
    c0 = std::max(c0, std::fabs(gl - P.gsplit[3 * p + 1]));
    c1 = std::max(c1, std::max(std::fabs(P.g[p]), gl));
  }
  change[0] = c0;
  change[1] = c1;
  return true;
}

template <int dim>
void FluiditySolver<dim>::solve(Particles<dim> &parts, FluidityMap map, long step, const double *change_all) {
  GM_CALL(PetscLogEventBegin(ev_source, 0, 0, 0, 0));
  // Particles::get keeps the fields checked out across steps: no per-step look-up by name.
  ParticleView<dim> P = parts.get();
  if (change_all && !resolve_due(step, nullptr, change_all)) {
    // Skipped, decided from change_ahead's maxima: its g_loc travelled with the particles.
    for (PetscInt p = 0; p < P.n; ++p) P.g[p] = P.gsplit[3 * p + 2] + P.gsplit[3 * p];
    ++skipped;
    parts.restore(P);
    GM_CALL(PetscLogEventEnd(ev_source, 0, 0, 0, 0));
    return;
  }
  double change[2];
  source_terms(P, change);
  const bool skip = !change_all && !local_only_ && P.gsplit && !resolve_due(step, change, change_all);
  if (local_only_ || skip) {
    // A = 0: no cooperativity, the fluidity is the local one. Between solves the local part
    // follows the stress every step; the nonlocal part g - g_loc of each particle is the one
    // of the last solve. (Freezing all of g instead is unstable: 24% error on the 80-cell
    // chute with a solve every 20 steps.)
    for (PetscInt p = 0; p < P.n; ++p) P.g[p] = gloc_[p] + (skip ? P.gsplit[3 * p] : 0.0);
    if (skip) ++skipped;
    parts.restore(P);
    GM_CALL(PetscLogEventEnd(ev_source, 0, 0, 0, 0));
    return;
  }
  GM_CALL(PetscLogEventEnd(ev_source, 0, 0, 0, 0));
  assemble(P.x, P.vol, w_.data(), gloc_.data(), P.n);
  solve_system();
  GM_CALL(PetscLogEventBegin(ev_map, 0, 0, 0, 0));
  if (banded_) map_band_sorted(P.x, map, P.g);
  else map_to_particles(P.x, P.n, map, P.g);
  if (P.gsplit) {
    // Step-size control on the solve interval: the error the skipped steps made is the
    // distance between the solved g and the split prediction; it grows about linearly with
    // the interval, and a too long interval lets a lagged-feedback instability grow (the
    // 80-cell chute with a fixed interval of 40 steps: 5e-3 error against 7.8e-4).
    double loc[2] = {0, 0}, glob[2];
    for (PetscInt p = 0; p < P.n; ++p) {
      loc[0] = std::max(loc[0], std::fabs(P.g[p] - gloc_[p] - P.gsplit[3 * p]));
      loc[1] = std::max(loc[1], std::fabs(P.g[p]));
      P.gsplit[3 * p] = P.g[p] - gloc_[p];
      P.gsplit[3 * p + 1] = gloc_[p];
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
  GM_CALL(PetscLogEventEnd(ev_map, 0, 0, 0, 0));
}

template <int dim>
bool FluiditySolver<dim>::resolve_due(long step, const double *change, const double *change_all) const {
  // A function of the particle fields and of (interval_, next_solve_), which go into the
  // checkpoint, so a restart takes the same decisions as the uninterrupted run. Besides
  // the planned step, a sudden change of g_loc (an impact) triggers a solve at once.
  if (step >= next_solve_) return true;
  if (change_all) return change_all[0] > kChangeFactor * resolve_tol_ * change_all[1];
  double glob[2] = {change[0], change[1]};
  if (grid_.size > 1) MPI_Allreduce(change, glob, 2, MPI_DOUBLE, MPI_MAX, grid_.comm);
  return glob[0] > kChangeFactor * resolve_tol_ * glob[1];
}

template class FluiditySolver<2>;
template class FluiditySolver<3>;

} // namespace granmpm
