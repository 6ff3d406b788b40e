// Grid<dim>: the distributed Cartesian background grid. Owns the PETSc DMDA used for
// particle transfers (BOX stencil, width 2, dof 1 + 2 dim) and its vectors, the node
// geometry, the owner-rank lookup used by particle migration, and the boundary
// conditions on nodal velocities.
//
// Geometry: square (cubic) cells of size h. In a non-periodic direction the grid extends
// `pad` = 2 cells beyond each wall, so that no GIMP or B-spline support of a particle inside
// the domain reaches past the last node (a GHOSTED DMDA boundary would drop those
// contributions: see ../shared/notes). In a periodic direction node 0 sits at the lower
// face and there are exactly `cells` nodes.
//
// Particle ownership: a particle in cell c (c = floor((x - x0)/h)) belongs to the rank that
// owns node c. Its support then spans nodes c-1 .. c+2, inside the width-2 ghost region.
#pragma once

#include <petscdmda.h>

#include <array>
#include <cmath>
#include <vector>

#include "granmpm/config.hpp"
#include "granmpm/transfer.hpp"

namespace granmpm {

// Splits nodes 0..n-1, node i carrying weight w[i], into `parts` contiguous ranges of at
// least min_nodes nodes each, with weight sums as equal as contiguous cuts allow: cut r
// goes to the node index whose cumulative weight is closest to r/parts of the total, then
// is moved as little as needed to keep every range at least min_nodes long. Returns the
// node count of each range (DMDA ownership ranges). Pure; requires n >= parts * min_nodes.
std::vector<PetscInt> balanced_ranges(const std::vector<double> &w, int parts, int min_nodes);

// Rank coordinate owning each node, from ownership ranges (node counts per rank).
std::vector<int> owner_map(const std::vector<PetscInt> &ranges);

template <int dim>
class Grid {
public:
  static constexpr int NDOF = NodeView<dim>::NDOF; // 1 + 2 dim, 8 in 3D (transfer.hpp)
  static constexpr int PAD = 2;

  Grid() = default;
  Grid(const Grid &) = delete;
  Grid &operator=(const Grid &) = delete;
  ~Grid() { destroy(); }

  // Creates the DMDA. l[0..dim-1] (nodes per rank per direction) may be given to impose
  // an ownership layout (rebalancing, restart); otherwise equal blocks. Only
  // Simulation::repartition re-creates a grid in a run: it also rebuilds what depends on it.
  void create(MPI_Comm comm, const Config &cfg, const std::vector<PetscInt> *l = nullptr);
  void destroy();

  // Geometry.
  MPI_Comm comm = MPI_COMM_NULL;
  int rank = 0, size = 1;
  double h = 0, inv_h = 0;
  double x0[3] = {0, 0, 0}; // coordinate of node 0
  double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
  int M[3] = {1, 1, 1};      // global nodes
  int ncell[3] = {1, 1, 1};  // physical cells
  int pad[3] = {0, 0, 0};
  bool periodic[3] = {false, false, false};
  BC bc[3][2];
  double wall_friction = 0; // Coulomb friction coefficient of slip faces
  int nproc[3] = {1, 1, 1}, pcoord[3] = {0, 0, 0};
  DMDALocalInfo info;
  // first owned node and count per direction, and the ghosted box
  int xs[3] = {0, 0, 0}, xm[3] = {1, 1, 1}, gxs[3] = {0, 0, 0}, gxm[3] = {1, 1, 1};

  DM da = nullptr;
  Vec global = nullptr, local = nullptr;

  double node_x(int d, int i) const { return x0[d] + i * h; }
  int cell_of(int d, double x) const { return (int)std::floor((x - x0[d]) * inv_h); }
  // Cell (index of its lower node) of coordinate x in direction d, wrapped in periodic
  // directions and clamped to the node range otherwise: what decides ownership.
  int owner_cell(int d, double x) const {
    const int c = cell_of(d, x);
    return periodic[d] ? ((c % M[d]) + M[d]) % M[d] : std::min(std::max(c, 0), M[d] - 1);
  }
  // Rank owning the particle at x (x already inside the domain / wrapped).
  int owner_rank(const double *x) const {
    int r = 0, stride = 1;
    for (int d = 0; d < dim; ++d) {
      r += owner_[d][owner_cell(d, x[d])] * stride;
      stride *= nproc[d];
    }
    return r;
  }
  // owner_rank(x), with a shortcut for the common case of a particle in an owned cell (the
  // rank itself, DMDA ranks being numbered x fastest like owner_rank): migration asks for
  // every particle every step, and owner_cell's wrap costs two integer divisions per direction.
  int owner_rank_or_self(const double *x) const {
    for (int d = 0; d < dim; ++d) {
      const int c = cell_of(d, x[d]);
      if (c < xs[d] || c >= xs[d] + xm[d]) return owner_rank(x);
    }
    return rank;
  }
  // Is cell c (index of its lower node) owned by this rank in direction d?
  bool owns_cell(int d, int c) const { return c >= xs[d] && c < xs[d] + xm[d]; }

  // Ownership ranges (nodes per rank) per direction, as DMDAGetOwnershipRanges gives them.
  std::vector<PetscInt> ranges(int d) const;

  // P2G/G2P: zero the local (ghosted) vector and view its array.
  NodeView<dim> begin_local(bool zero);
  void end_local();
  // Sum ghost contributions into owners (LocalToGlobal ADD); global is zeroed first.
  void local_to_global_add();
  // Owners' values into ghosts (GlobalToLocal INSERT).
  void global_to_local();
  // View of the owned part of the global vector (indices are global node indices).
  NodeView<dim> begin_global();
  void end_global();

  // Boundary conditions on a nodal velocity of node (i,j,k): sticky -> 0, slip -> zero
  // normal component, applied to every node at or beyond a wall (the wall node and the
  // padding nodes).
  inline void apply_bc(int i, int j, int k, double *v) const {
    const int idx[3] = {i, j, k};
    for (int d = 0; d < dim; ++d) {
      if (periodic[d]) continue;
      for (int s = 0; s < 2; ++s) {
        const bool at = (s == 0) ? (idx[d] <= pad[d]) : (idx[d] >= M[d] - 1 - pad[d]);
        if (!at) continue;
        if (bc[d][s] == BC::Sticky) {
          for (int e = 0; e < dim; ++e) v[e] = 0;
        } else if (bc[d][s] == BC::Slip) {
          // Zero normal velocity; Coulomb friction takes wall_friction times the removed
          // normal velocity off the tangential velocity, never reversing it.
          const double vn = std::fabs(v[d]);
          v[d] = 0;
          if (wall_friction > 0 && vn > 0) {
            double vt2 = 0;
            for (int e = 0; e < dim; ++e) vt2 += v[e] * v[e];
            const double vt = std::sqrt(vt2);
            const double f = vt > 0 ? std::max(0.0, 1.0 - wall_friction * vn / vt) : 0.0;
            for (int e = 0; e < dim; ++e) v[e] *= f;
          }
        }
      }
    }
  }

  // Ranks per direction for nranks: the factorisation with the smallest halo that gives
  // every rank >= 2 nodes per direction and matches the nonzero entries of fixed;
  // {0,0,0} if there is none.
  std::array<int, 3> choose_split(int nranks, const std::array<int, 3> &fixed) const;

  // A scalar DMDA (dof 1) with the same ownership and periodicity and stencil width s.
  DM create_scalar_da(int s) const { return create_da(s, 1); }
  // The same with dof interleaved components per node.
  DM create_da(int s, int dof) const;

private:
  std::vector<int> owner_[3];
  double *arr_ = nullptr;
  Vec arr_vec_ = nullptr;
};

// Copy a field between two DMDAs of the same global size and dof but different ownership
// ranges (load balancing): through PETSc's natural ordering, so the copy is exact.
void copy_across_layouts(MPI_Comm comm, DM from, Vec from_global, DM to, Vec to_global);

} // namespace granmpm
