// FluiditySolver<dim>: the steady nonlocal granular fluidity of seed 000 (Algorithm 2),
// solved on the grid every step:
//
//   -(A d)^2 lap g + |mu - mu_s| g = |mu - mu_s| g_loc
//
// Galerkin with the Q1 (linear) shape functions of a width-1 DMDA that has the same
// ownership as the transfer grid, integrated at the particles:
//   K_ij = sum_p V_p ( |mu_p - mu_s| S_i S_j + (A d)^2 grad S_i . grad S_j )
//   f_i  = sum_p V_p |mu_p - mu_s| S_i g_loc,p
// Nodes touched by no particle-holding cell are inactive (identity rows through
// MatZeroRowsColumns, which keeps the pattern and the symmetry). Zero flux is the natural
// boundary condition; -fluidity_bc dirichlet sets g = g_loc (nodal projection) on wall
// nodes.
// Two solvers (-fluidity_solver):
//  - banded (direct; auto picks it for small bandwidths, e.g. every 2D chute): the system
//    is summed straight into a symmetric band array in a fixed node order (the longest
//    direction slowest), reduced to rank 0, factored by a band Cholesky and solved by CG
//    preconditioned with that factor (1 iteration unless a pivot had to be replaced), and
//    the nodal g is broadcast. No PETSc Mat: for a few hundred nodes the PETSc assembly and
//    KSP overheads cost 10x the arithmetic. The result does not depend on the previous g
//    (zero initial guess), so a restart repeats the solve bitwise.
//  - iterative: KSP, prefix -fluidity_ (default CG + hypre BoomerAMG, rtol 1e-8, previous g
//    as initial guess). The matrix is created once with the full 9/27-point pattern and
//    only refilled, so there are no mallocs after the first assembly.
#pragma once

#include <petscdmda.h>
#include <petscksp.h>

#include <functional>
#include <vector>

#include "granmpm/config.hpp"
#include "granmpm/grid.hpp"
#include "granmpm/materials/nonlocal_ngf.hpp"
#include "granmpm/particles.hpp"

namespace granmpm {

// One particle's contribution to the system, for tests: the particle at xi (grid units,
// relative to node 0 of its cell) adds vol * (w S S^T + k grad S grad S^T) to Ke and
// vol * w * gloc * S to fe. Pure.
template <int dim>
void fluidity_element_contribution(const double *xi, double h, double vol, double w, double gloc, double k, double *Ke, double *fe);

// One cell's contribution with the cell-wise mean coefficients integrated exactly
// (-fluidity_quadrature cell): with phi = (particle volume in the cell) / h^dim,
// Wm = (sum V_p w_p) / h^dim and F = sum V_p w_p g_loc,p it adds
// Wm int S_i S_j + phi k int grad S_i . grad S_j to Ke and F / 2^dim to fe. Unlike the
// point quadrature at one particle (rank 1 + dim) the element matrix is positive definite.
// Pure.
template <int dim>
void fluidity_cell_contribution(double h, double phi, double Wm, double F, double k, double *Ke, double *fe);

// Per-particle inputs of the system from the stress in sym6 form (xx, yy, zz, xy, yz, xz):
// fluidity_source(gp, sym6_to_mat(s)) to round-off, without building the matrix and
// without branches (selects), so that a loop over particles vectorises. Pure.
inline FluiditySource fluidity_source6(const GranularParams &gp, const double *s6) {
  const double p = pressure6(s6), tau = tau6(s6);
  const bool pos = p > 0;
  const double pp = pos ? p : 1.0, mu = tau / pp, excess = tau - gp.mu_s * pp;
  // g_loc = gdot_loc / mu = excess p / (b d sqrt(rho_s p) tau); tau > 0 where excess > 0.
  const double gl = excess * pp / (gp.b * gp.d * std::sqrt(gp.rho_s * pp) * tau);
  return {pos ? std::fabs(mu - gp.mu_s) : gp.mu_s, (pos && excess > 0) ? gl : 0.0};
}

// Symmetric band matrices, lower band stored row by row: entry (k, j), k - bw <= j <= k,
// at a[k * (bw + 1) + bw - (k - j)]. Pure kernels.
// In-place Cholesky factor L (A = L L^T), with 1 / L_kk stored on the diagonal; a pivot
// below kPivotTol times its diagonal entry (a singular or nearly singular direction) is
// replaced by that entry, so that L L^T stays an SPD preconditioner. Returns the number
// of replaced pivots.
int band_cholesky(PetscInt n, int bw, double *a);
// x <- (L L^T)^-1 x.
void band_solve(PetscInt n, int bw, const double *L, double *x);
// y = A x.
void band_matvec(PetscInt n, int bw, const double *a, const double *x, double *y);
// CG on A x = f preconditioned by the factor L, from x = 0; stops when |r| <= rtol |f|.
// Returns the iterations, or -1 when maxit is reached first. work: 4 n doubles.
int band_pcg(PetscInt n, int bw, const double *a, const double *L, const double *f, double *x, double rtol, int maxit, double *work);
constexpr double kPivotTol = 1e-12;

// General (non-symmetric) band matrices, half-bandwidth bw: entry (r, c), |r - c| <= bw, at
// a[r * (2 bw + 1) + bw + (c - r)]. In-place LU without pivoting (unit lower L below the
// diagonal, U above it, 1 / U_kk on the diagonal): enough for strictly row diagonally dominant matrices, whose
// Schur complements stay so (no pivot growth), e.g. the dynamical fluidity's implicit step.
// Returns false (a stays partly factored) at the first pivot that is zero or not finite.
bool band_lu(PetscInt n, int bw, double *a);
// x <- (L U)^-1 x with the factor of band_lu.
void band_lu_solve(PetscInt n, int bw, const double *lu, double *x);

// The node order of the band solvers: strides (node (i, j, k) -> i s0 + j s1 + k s2) of the
// axis order with the smallest half-bandwidth (wraps of periodic axes included), which it
// returns. M: global nodes per direction (1 for a missing third). Pure.
int band_node_order(const int *M, const bool *periodic, PetscInt *stride);
// The band index of node (i, j, k), wrapping indices at most one period out of range. Pure.
PetscInt band_node_index(const int *M, const PetscInt *stride, int i, int j, int k);

template <int dim>
class FluiditySolver {
public:
  FluiditySolver(const Grid<dim> &grid, const Config &cfg);
  ~FluiditySolver();
  FluiditySolver(const FluiditySolver &) = delete;
  FluiditySolver &operator=(const FluiditySolver &) = delete;

  // Assembles from each particle's stress and volume (start of step), solves, and writes
  // g back to the particles by interpolation or cell average. With the particles' split
  // field (-fluidity_resolve_max > 1) the solve is skipped unless resolve_due(step), and
  // g = g_loc + (g - g_loc of the last solve) instead.
  // change_all: the maxima of change_ahead over the ranks, reduced since (null: reduce here).
  void solve(Particles<dim> &parts, FluidityMap map, long step = 0, const double *change_all = nullptr);
  // This rank's {largest change of g_loc since the last solve, largest |g|} that the next
  // solve's resolve_due would reduce (the stress is that of the next step's start); false
  // when that solve reduces nothing (one rank, no split field, a planned solve at next_step).
  // Each particle's g_loc goes into its split field, so that a skipped solve after the
  // migration (which reorders the particles) does not evaluate the local fluidity again.
  bool change_ahead(const ParticleView<dim> &P, long next_step, double *change);

  // Lower-level pieces, also used by the manufactured-solution test: assemble from given
  // per-particle weight |mu - mu_s| and local fluidity, solve, read nodal values.
  void assemble(const double *x, const double *vol, const double *w, const double *gloc, PetscInt n);
  void solve_system();
  void map_to_particles(const double *x, PetscInt n, FluidityMap map, double *g) const;

  // Nodes where g = 0 (Dirichlet rows), e.g. rigid-body contact nodes with
  // -body_fluidity_bc zero; evaluated at each assembly (the bodies move). Empty: none.
  void set_zero_nodes(std::function<bool(const double *x)> f) { zero_at_ = std::move(f); }

  DM da() const { return da_; }
  bool banded() const { return banded_; }
  int bandwidth() const { return bw_; }
  Vec solution() const { return g_; }
  KSP ksp() const { return ksp_; }
  PetscInt last_iterations = 0;
  long solves = 0;
  long iterations_total = 0;

private:
  const Grid<dim> &grid_;
  double k_; // (A d)^2
  bool dirichlet_;
  GranularParams gp_;
  DM da_ = nullptr;
  Mat K_ = nullptr;
  Vec g_ = nullptr, f_ = nullptr, gl_ = nullptr, work_l_ = nullptr, work_g_ = nullptr, work2_l_ = nullptr, work2_g_ = nullptr;
  KSP ksp_ = nullptr;
  PetscInt rstart_ = 0;
  std::vector<int> cell_start_, order_;
  // f(c, ci) for every owned cell that holds particles of the last sort_by_cell, in cell
  // order: c its local index, ci its global lower-corner node (assembly and map share it).
  template <class F>
  void for_each_occupied_cell(F &&f) const {
    const int nx = grid_.xm[0], ny = grid_.xm[1], nz = dim == 3 ? grid_.xm[2] : 1;
    for (int k = 0; k < nz; ++k)
      for (int j = 0; j < ny; ++j)
        for (int i = 0; i < nx; ++i) {
          const int c = (k * ny + j) * nx + i;
          if (cell_start_[c] == cell_start_[c + 1]) continue;
          const int ci[3] = {grid_.xs[0] + i, grid_.xs[1] + j, dim == 3 ? grid_.xs[2] + k : 0};
          f(c, ci);
        }
  }
  std::vector<double> w_, gloc_;
  std::function<bool(const double *)> zero_at_;
  bool local_only_ = false; // A = 0: g = g_loc, no solve
  // Preconditioner reuse: rebuilt every pc_interval_ solves, whenever the set of inactive
  // rows changes, and after a failed solve with a reused one.
  int pc_interval_ = 1, since_setup_ = 0;
  bool rows_changed_ = true;
  std::vector<PetscInt> prev_rows_;
  bool cell_quad_ = false;
  int resolve_max_ = 1;
  double resolve_tol_ = 0;
  int interval_ = 1;    // steps between solves, adapted at each solve
  long next_solve_ = 0; // step of the next planned solve
  bool resolve_due(long step, const double *change, const double *change_all) const;
  bool consistent_residual();
public:
  long pc_setups = 0;
  long replaced_pivots = 0; // banded: pivots of (nearly) singular directions replaced (rank 0)
  long skipped = 0; // steps that used the split instead of a solve
  double last_prediction_error = 0; // max|g - split prediction| / max|g| at the last solve
  // The solve schedule, for checkpoints: {current interval, step of the next solve}.
  std::vector<double> state() const { return {(double)interval_, (double)next_solve_}; }
  bool set_state(const std::vector<double> &s) {
    if (s.size() != 2) return false;
    interval_ = (int)s[0];
    next_solve_ = (long)s[1];
    return true;
  }
  // A change of g_loc by more than this times -fluidity_resolve_tol (relative to max|g|)
  // since the last solve forces a solve before the planned step.
  static constexpr double kChangeFactor = 10;
  // auto: banded when n b^2 (Cholesky flops, n nodes, half-bandwidth b) is below
  // kDirectCostMax (~10 ms) and the band has at most kBandStorageAuto entries (the
  // reduction to rank 0 moves it every solve); -fluidity_solver direct up to kBandStorageMax.
  static constexpr double kDirectCostMax = 2e7;
  static constexpr double kBandStorageAuto = 2e6, kBandStorageMax = 1e8;
  PetscInt row_of(int i, int j, int k) const;

private:
  // Banded path: node order and band, root-side arrays.
  bool banded_ = false;
  int bw_ = 0;
  PetscInt nb_ = 0, stride_[3] = {0, 0, 0};
  std::vector<double> buf_, fac_, sol_, work_;
  double rtol_ = 1e-8;
  PetscInt band_index(int i, int j, int k) const;
  void choose_band_order();
  template <class Sink>
  void for_each_cell(const double *x, const double *vol, const double *w, const double *gloc, Sink sink);
  void sort_by_cell(const double *x, PetscInt n);
  void assemble_band(const double *x, const double *vol, const double *w, const double *gloc);
  void band_boundary_rows(double *K, double *f, const double *act, const double *zero, const double *sv, const double *proj) const;
  void solve_band();
  void map_band_sorted(const double *x, FluidityMap map, double *g) const;
  void assemble_mat(const double *x, const double *vol, const double *w, const double *gloc);
  void finish_mat();
  void source_terms(const ParticleView<dim> &P, double *change);
};

} // namespace granmpm
