// DynamicFluidity<dim>: the grid part of the dynamical nonlocal fluidity (seed 004;
// model.md section 3.2). The fluidity g lives on the particles; its Laplacian comes from
// the grid:
//
//   1. g of the connected (not stress-free) particles is transferred mass-weighted and
//      normalised to the nodes of a width-1 DMDA with the ownership of the transfer grid,
//      G_i = sum S_ip m_p g_p / sum S_ip m_p (Q1 weights; the seed's public code sums
//      S_ip g_p without normalising, which inflates the nonlocal term by about the
//      particles per cell);
//   2. explicit: lap_i = (Delta_h G)_i. Implicit (no step limit): a linearised backward-
//      Euler predictor of the new nodal fluidity,
//        ((1 + beta_i) I - theta Delta_h) Gh = (1 + beta_i) G + (dt/t0) R_i(G),
//        theta = dt A^2 d^2 / t0,  R(g) = -(mu_s - mu) g - b sqrt(rho_s d^2/p) mu g^2,
//        beta_i = max(0, -(dt/t0) R'(G_i)),
//      solved by a band LU on rank 0 on small grids (the steady solver's band criterion),
//      else with KSP (prefix -fluidity_; GMRES + block Jacobi/ILU(0)), and lap_i = (Delta_h Gh)_i. At a steady state
//      Gh = G for any beta, so the implicit step keeps the steady states of the explicit
//      one (a plain diffusion solve (I - theta Delta_h) Gh = G would not: it smooths the
//      Laplacian by (I - theta Delta_h)^-1 and biases the steady profile when
//      theta/h^2 is not small);
//   3. lap at each particle by Q1 interpolation; the particle kernel adds
//      dt A^2 d^2 lap / t0 to its fluidity step.
// Delta_h is the compact (2 dim + 1)-point or the isotropic box (9 / 27-point) finite
// difference Laplacian on active nodes; a missing (massless) neighbour is left out, which
// is the zero-flux condition at free surfaces and walls.
#pragma once

#include <petscdmda.h>
#include <petscksp.h>

#include <vector>

#include "granmpm/config.hpp"
#include "granmpm/grid.hpp"
#include "granmpm/particles.hpp"

namespace granmpm {

// Stencil weights w(offset) for the Laplacian sum_j w_j (g_j - g_i) / h^2, offsets in
// {-1,0,1}^dim (x fastest). Pure.
void laplacian_weights(int dim, LaplacianStencil st, double *w /* 3^dim */);

template <int dim>
class DynamicFluidity {
public:
  DynamicFluidity(const Grid<dim> &grid, const Config &cfg);
  ~DynamicFluidity();
  DynamicFluidity(const DynamicFluidity &) = delete;
  DynamicFluidity &operator=(const DynamicFluidity &) = delete;

  // Laplacian of g at every local particle (lap.size() == local particles). Particles with
  // p_prev <= 0 (stress-free) are left out of the transfer. implicit: the predictor above
  // for a step of size dt.
  void laplacian(const double *x, const double *m, const double *g, const double *p_prev, const double *mu_prev, PetscInt n, double dt, bool implicit,
                 std::vector<double> &lap);

  PetscInt last_iterations = 0;
  long solves = 0;

private:
  const Grid<dim> &grid_;
  GranularParams gp_;
  double t0_;
  LaplacianStencil stencil_;
  FluiditySolverKind solver_;
  double w_[27];
  DM da_ = nullptr;
  // Global (owned) and local (ghosted) vectors: G nodal fluidity, W projection weights
  // (ghosted: the active flags), lap Delta_h on the owned nodes, Gh the implicit
  // correction, rate/beta the projected reaction rate and its slope, rhs.
  Vec G_ = nullptr, Gl_ = nullptr, W_ = nullptr, Wl_ = nullptr, lap_ = nullptr, lapl_ = nullptr, Gh_ = nullptr;
  Vec beta_ = nullptr, rhs_ = nullptr;
  // The projection's sums, nv_ interleaved components per node (G, W, and for the implicit
  // step rate and beta): one ghost sum for all of them instead of one per field.
  DM dap_ = nullptr;
  Vec Pl_ = nullptr, Pg_ = nullptr;
  static constexpr int nv_ = 4;
  Mat A_ = nullptr;
  KSP ksp_ = nullptr;
  double Ad2_ = 0;                  // (A d)^2
  int lgs_[3] = {0, 0, 0}, lgm_[3] = {1, 1, 1}; // ghosted local box of the DMDA
  // The mirrored stencil of every owned node (CSR over the owned nodes in DMDA order; an
  // inactive node has no entries), built once per step from the active flags.
  std::vector<int> nb_start_;
  std::vector<long> nb_idx_;        // local (ghosted) index of the neighbour
  std::vector<double> nb_w_;
  std::vector<unsigned char> active_; // the active flags (ghosted) the stencil was built from
  // Band path (small grids): rows summed into one band array in the node order of
  // band_node_order, reduced to rank 0, LU-factored there (band_lu) and the solution
  // broadcast. Every row comes from its owner rank alone, so the reduced matrix, and with it
  // the solution, is the same on any rank count. For a few hundred nodes PETSc's assembly
  // and factorisation cost many times the band arithmetic.
  bool band_ = false;
  int bw_ = 0;
  PetscInt band_n_ = 0, stride_[3] = {0, 0, 0};
  std::vector<PetscInt> band_row_, band_col_; // per owned node / per CSR entry: band index
  std::vector<double> buf_, sol_;
  void setup_solver();
  void solve_band(double theta);
  long lidx(int i, int j, int k) const { return ((long)(k - lgs_[2]) * lgm_[1] + (j - lgs_[1])) * lgm_[0] + (i - lgs_[0]); }
  // The local index of the first node of x's Q1 cell and x's local coordinates in it (computed
  // where used, not stored: 32 B per particle in 3D, issue 16).
  long locate(const double *x, double *xi) const;
  void project(const double *x, const double *m, const double *g, const double *p_prev, const double *mu_prev, PetscInt n, double dt, bool implicit);
  void build_neighbours(const double *wl);
  void nodal_laplacian(Vec in, bool add);
  void interpolate(const double *x, PetscInt n, std::vector<double> &out);
  void assemble_implicit(double theta);
  void implicit_correction(double dt);
};

} // namespace granmpm
