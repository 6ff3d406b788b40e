// FluiditySolver<dim>: the node order of the banded direct path, its boundary rows and the
// map of the solution back to the particles of the last assembly. Split from fluidity.cpp.
#include "granmpm/fluidity.hpp"

#include <algorithm>
#include <cmath>

namespace granmpm {

template <int dim>
PetscInt FluiditySolver<dim>::row_of(int i, int j, int k) const {
  const int *xs = grid_.xs, *xm = grid_.xm;
  return rstart_ + (i - xs[0]) + xm[0] * ((j - xs[1]) + (PetscInt)xm[1] * (dim == 3 ? (k - xs[2]) : 0));
}

int band_node_order(const int *M, const bool *periodic, PetscInt *stride) {
  // Node numbering i st[0] + j st[1] + k st[2] with the strides of the axis order that
  // gives the smallest half-bandwidth: the longest non-periodic axis slowest. In a periodic
  // axis of M nodes the wrap couples nodes M - 1 apart.
  const PetscInt n = (PetscInt)M[0] * M[1] * M[2];
  int perm[3] = {0, 1, 2};
  PetscInt best = -1;
  do {
    PetscInt st[3], s = 1, b = 0;
    for (int q = 0; q < 3; ++q) {
      st[perm[q]] = s;
      s *= M[perm[q]];
    }
    for (int d = 0; d < 3; ++d) b += (M[d] == 1 ? 0 : (periodic[d] ? M[d] - 1 : 1)) * st[d];
    if (best < 0 || b < best) {
      best = b;
      std::copy(st, st + 3, stride);
    }
  } while (std::next_permutation(perm, perm + 3));
  return (int)std::min<PetscInt>(best, n - 1);
}

PetscInt band_node_index(const int *M, const PetscInt *stride, int i, int j, int k) {
  const int ijk[3] = {i, j, k};
  PetscInt q = 0;
  for (int d = 0; d < 3; ++d) {
    // Callers pass nodes at most one period out of range (cell corners, stencil neighbours).
    const int m = M[d], v = ijk[d];
    q += (v >= m ? v - m : (v < 0 ? v + m : v)) * stride[d];
  }
  return q;
}

template <int dim>
void FluiditySolver<dim>::choose_band_order() {
  nb_ = (PetscInt)grid_.M[0] * grid_.M[1] * grid_.M[2];
  bw_ = band_node_order(grid_.M, grid_.periodic, stride_);
}

template <int dim>
PetscInt FluiditySolver<dim>::band_index(int i, int j, int k) const {
  return band_node_index(grid_.M, stride_, i, j, k);
}

template <int dim>
void FluiditySolver<dim>::band_boundary_rows(double *K, double *f, const double *act, const double *zero, const double *sv, const double *proj) const {
  // Inactive nodes and zero-g nodes: g = 0; Dirichlet wall nodes: g = g_loc (nodal
  // projection). Each fixed node's column moves to the right-hand side, its row and column
  // become the identity: the matrix stays symmetric.
  const Grid<dim> &G = grid_;
  const PetscInt wd = bw_ + 1;
  auto entry = [&](PetscInt r, PetscInt c) -> double & { return r >= c ? K[r * wd + bw_ - (r - c)] : K[c * wd + bw_ - (c - r)]; };
  for (int k = 0; k < G.M[2]; ++k)
    for (int j = 0; j < G.M[1]; ++j)
      for (int i = 0; i < G.M[0]; ++i) {
        const PetscInt q = band_index(i, j, k);
        double v = 0;
        bool fix = act[q] == 0 || zero[q] > 0;
        if (!fix && dirichlet_ && sv[q] > 0) {
          const int ijk[3] = {i, j, k};
          for (int d = 0; d < dim; ++d) {
            if (G.periodic[d]) continue;
            if ((ijk[d] == G.pad[d] && G.bc[d][0] != BC::Free && G.bc[d][0] != BC::Outlet) ||
                (ijk[d] == G.pad[d] + G.ncell[d] && G.bc[d][1] != BC::Free && G.bc[d][1] != BC::Outlet))
              fix = true;
          }
          if (fix) v = proj[q] / sv[q];
        }
        if (!fix) continue;
        for (PetscInt r = std::max<PetscInt>(0, q - bw_); r <= std::min<PetscInt>(nb_ - 1, q + bw_); ++r) {
          if (r == q) continue;
          f[r] -= entry(r, q) * v;
          entry(r, q) = 0;
        }
        entry(q, q) = 1;
        f[q] = v;
      }
}

template <int dim>
void FluiditySolver<dim>::map_band_sorted(const double *x, FluidityMap map, double *g) const {
  // map_to_particles for the particles of the last assembly, cell by cell: the nodal values
  // of a cell are looked up once for all its particles.
  const Grid<dim> &G = grid_;
  constexpr int nn = 1 << dim;
  for_each_occupied_cell([&](int c, const int *ci) {
        double v[nn], mean = 0;
        for (int a = 0; a < nn; ++a) {
          v[a] = sol_[band_index(ci[0] + (a & 1), ci[1] + ((a >> 1) & 1), dim == 3 ? ci[2] + ((a >> 2) & 1) : 0)];
          mean += v[a] / nn;
        }
        for (int q = cell_start_[c]; q < cell_start_[c + 1]; ++q) {
          const int p = order_[q];
          if (map == FluidityMap::CellAverage) {
            g[p] = mean;
            continue;
          }
          double xi[dim], s = 0;
          for (int d = 0; d < dim; ++d) xi[d] = (x[p * dim + d] - G.node_x(d, ci[d])) * G.inv_h;
          for (int a = 0; a < nn; ++a) {
            double S = 1;
            for (int d = 0; d < dim; ++d) S *= ((a >> d) & 1) ? xi[d] : 1.0 - xi[d];
            s += S * v[a];
          }
          g[p] = s;
        }
      });
}

template PetscInt FluiditySolver<2>::row_of(int, int, int) const;
template void FluiditySolver<2>::choose_band_order();
template PetscInt FluiditySolver<2>::band_index(int, int, int) const;
template void FluiditySolver<2>::band_boundary_rows(double *, double *, const double *, const double *, const double *, const double *) const;
template void FluiditySolver<2>::map_band_sorted(const double *, FluidityMap, double *) const;
template PetscInt FluiditySolver<3>::row_of(int, int, int) const;
template void FluiditySolver<3>::choose_band_order();
template PetscInt FluiditySolver<3>::band_index(int, int, int) const;
template void FluiditySolver<3>::band_boundary_rows(double *, double *, const double *, const double *, const double *, const double *) const;
template void FluiditySolver<3>::map_band_sorted(const double *, FluidityMap, double *) const;

} // namespace granmpm
