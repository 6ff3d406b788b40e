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
// nodes. Solved with KSP, prefix -fluidity_ (default CG + hypre BoomerAMG, rtol 1e-8,
// previous g as initial guess). The matrix is created once with the full 9/27-point
// pattern and only refilled, so there are no mallocs after the first assembly.
#pragma once

#include <petscdmda.h>
#include <petscksp.h>

#include <functional>
#include <vector>

#include "granmpm/config.hpp"
#include "granmpm/grid.hpp"
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
  void solve(Particles<dim> &parts, FluidityMap map, long step = 0);

  // Lower-level pieces, also used by the manufactured-solution test: assemble from given
  // per-particle weight |mu - mu_s| and local fluidity, solve, read nodal values.
  void assemble(const double *x, const double *vol, const double *w, const double *gloc, PetscInt n);
  void solve_system();
  void map_to_particles(const double *x, PetscInt n, FluidityMap map, double *g) const;

  // Nodes where g = 0 (Dirichlet rows), e.g. rigid-body contact nodes with
  // -body_fluidity_bc zero; evaluated at each assembly (the bodies move). Empty: none.
  void set_zero_nodes(std::function<bool(const double *x)> f) { zero_at_ = std::move(f); }

  DM da() const { return da_; }
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
  std::vector<double> w_, gloc_;
  std::function<bool(const double *)> zero_at_;
  bool local_only_ = false; // A = 0: g = g_loc, no solve
  // Preconditioner reuse: rebuilt every pc_interval_ solves, whenever the set of inactive
  // rows changes, and after a failed solve with a reused one.
  int pc_interval_ = 1, since_setup_ = 0;
  bool rows_changed_ = true;
  std::vector<PetscInt> prev_rows_;
  bool direct_ = false;
  bool cell_quad_ = false;
  int resolve_max_ = 1;
  double resolve_tol_ = 0;
  int interval_ = 1;    // steps between solves, adapted at each solve
  long next_solve_ = 0; // step of the next planned solve
  bool resolve_due(const ParticleView<dim> &P, long step) const;
  bool consistent_residual();
public:
  long pc_setups = 0;
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
  bool direct() const { return direct_; }
  // Direct when n b^2 (Cholesky flops, n nodes, bandwidth b) is below this: ~10 ms.
  static constexpr double kDirectCostMax = 2e7;
  PetscInt row_of(int i, int j, int k) const;
};

} // namespace granmpm
