// The per-particle node sets the implicit solver's loops use (implicit.cpp,
// implicit_step.cpp): the shape functions' stencil with gradients, and the fluidity's Q1
// cell. Internal to src/.
#pragma once

#include <algorithm>

#include "granmpm/config.hpp"
#include "granmpm/grid.hpp"
#include "granmpm/transfer.hpp"

namespace granmpm {
namespace {

// Weights and gradients of the N^dim nodes of a particle's stencil, node a = (ax, ay, az)
// flattened x fastest; node indices in nid.
template <int dim, class S>
struct NodeSet {
  static constexpr int NN = dim == 3 ? S::N * S::N * S::N : S::N * S::N;
  int nid[NN][3];
  double grad[NN][dim];
  void fill(const Stencil<dim, S> &st) {
    const int kN = dim == 3 ? S::N : 1;
    int a = 0;
    for (int c = 0; c < kN; ++c)
      for (int b = 0; b < S::N; ++b)
        for (int q = 0; q < S::N; ++q, ++a) {
          const double wz = dim == 3 ? st.w[dim - 1][c] : 1.0, dwz = dim == 3 ? st.dw[dim - 1][c] : 0.0;
          nid[a][0] = st.base[0] + q;
          nid[a][1] = st.base[1] + b;
          nid[a][2] = dim == 3 ? st.base[2] + c : 0;
          grad[a][0] = st.dw[0][q] * st.w[1][b] * wz;
          grad[a][1] = st.w[0][q] * st.dw[1][b] * wz;
          if constexpr (dim == 3) grad[a][2] = st.w[0][q] * st.w[1][b] * dwz;
        }
  }
};

// The fluidity's Q1 cell of a particle as FluiditySolver uses it: the cell's 2^dim nodes
// (global indices), the particle's local coordinates xi in [0, 1] and the hat weights S.
template <int dim>
struct Q1Cell {
  static constexpr int NN = 1 << dim;
  int nid[NN][3];
  double xi[dim], S[NN];
  void fill(const Grid<dim> &G, const double *x) {
    int c[3] = {0, 0, 0};
    for (int d = 0; d < dim; ++d) {
      c[d] = std::min(G.cell_of(d, x[d]), G.xs[d] + G.xm[d] - 1);
      xi[d] = (x[d] - G.node_x(d, c[d])) * G.inv_h;
    }
    for (int a = 0; a < NN; ++a) {
      S[a] = 1;
      for (int d = 0; d < 3; ++d) nid[a][d] = d < dim ? c[d] + ((a >> d) & 1) : 0;
      for (int d = 0; d < dim; ++d) S[a] *= ((a >> d) & 1) ? xi[d] : 1.0 - xi[d];
    }
  }
  // g at the particle from nodal values g(a) (-fluidity_map interpolate|cell_average).
  template <class F>
  double value(FluidityMap map, F g) const {
    double s = 0;
    for (int a = 0; a < NN; ++a) s += (map == FluidityMap::CellAverage ? 1.0 / NN : S[a]) * g(a);
    return s;
  }
};

} // namespace
} // namespace granmpm
