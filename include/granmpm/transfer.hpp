// Particle <-> grid transfers: pure per-particle kernels on a plain node array (no PETSc).
//
// Node layout (NDOF = 1 + 2 dim doubles per node):
//   during P2G:            [ m, m v (dim), f (dim) ]
//   after the grid update: [ m, v_new (dim), v_new - v_old (dim) ]
// The Grid class owns the storage; these kernels only see a strided view of the local
// (ghosted) array, indexed with global node indices.
#pragma once

#include "granmpm/shape.hpp"
#include "granmpm/tensor.hpp"

namespace granmpm {

enum class TransferKind { PIC = 0, FLIP = 1, APIC = 2 };

template <int dim>
struct NodeView {
  static constexpr int NDOF = 1 + 2 * dim;
  double *a = nullptr;
  int gs[3] = {0, 0, 0}; // first ghosted global index per direction
  int gm[3] = {1, 1, 1}; // ghosted widths
  inline double *at(int i, int j, int k) const {
    return a + (size_t)NDOF * ((size_t)(k - gs[2]) * gm[1] * gm[0] + (size_t)(j - gs[1]) * gm[0] + (i - gs[0]));
  }
  inline bool contains(int i, int j, int k) const {
    return i >= gs[0] && i < gs[0] + gm[0] && j >= gs[1] && j < gs[1] + gm[1] && k >= gs[2] && k < gs[2] + gm[2];
  }
};

// Inputs of one particle to P2G.
template <int dim>
struct P2GInput {
  double m;
  double vol;
  const double *v;     // dim
  const double *C;     // dim*dim row-major affine velocity (APIC), or nullptr
  const double *s6;    // stress (xx,yy,zz,xy,yz,xz), or nullptr (no internal force)
  const double *bacc;  // body acceleration (dim), or nullptr
};

// Scatter mass, momentum and (optionally) force of one particle. h is the grid spacing
// (for the APIC offset x_i - x_p = h * frac).
template <int dim, class Shape>
inline void p2g_particle(const Stencil<dim, Shape> &st, const P2GInput<dim> &in, double h, const NodeView<dim> &g) {
  constexpr int N = Shape::N;
  double sig[dim][dim] = {};
  if (in.s6) {
    sig[0][0] = in.s6[0];
    sig[1][1] = in.s6[1];
    sig[0][1] = sig[1][0] = in.s6[3];
    if constexpr (dim == 3) {
      sig[2][2] = in.s6[2];
      sig[1][2] = sig[2][1] = in.s6[4];
      sig[0][2] = sig[2][0] = in.s6[5];
    }
  }
  const int kN = (dim == 3) ? N : 1;
  for (int c = 0; c < kN; ++c) {
    const double wz = (dim == 3) ? st.w[dim - 1][c] : 1.0;
    const double dwz = (dim == 3) ? st.dw[dim - 1][c] : 0.0;
    const double fz = (dim == 3) ? st.frac[dim - 1][c] * h : 0.0;
    const int k = (dim == 3) ? st.base[2] + c : 0;
    for (int b = 0; b < N; ++b) {
      const int j = st.base[1] + b;
      const double wy = st.w[1][b], dwy = st.dw[1][b], fy = st.frac[1][b] * h;
      double *row = g.at(st.base[0], j, k);
      for (int a = 0; a < N; ++a) {
        const double wx = st.w[0][a], dwx = st.dw[0][a], fx = st.frac[0][a] * h;
        const double w = wx * wy * wz;
        double grad[dim];
        grad[0] = dwx * wy * wz;
        grad[1] = wx * dwy * wz;
        if constexpr (dim == 3) grad[2] = wx * wy * dwz;
        double dx[dim];
        dx[0] = fx;
        dx[1] = fy;
        if constexpr (dim == 3) dx[2] = fz;
        double *n = row + (size_t)a * NodeView<dim>::NDOF;
        const double mw = in.m * w;
        n[0] += mw;
        for (int d = 0; d < dim; ++d) {
          double vd = in.v[d];
          if (in.C)
            for (int e = 0; e < dim; ++e) vd += in.C[d * dim + e] * dx[e];
          n[1 + d] += mw * vd;
        }
        if (in.s6) {
          for (int d = 0; d < dim; ++d) {
            double f = 0;
            for (int e = 0; e < dim; ++e) f -= sig[d][e] * grad[e];
            n[1 + dim + d] += in.vol * f;
          }
        }
        if (in.bacc)
          for (int d = 0; d < dim; ++d) n[1 + dim + d] += mw * in.bacc[d];
      }
    }
  }
}

// Outputs of G2P for one particle.
template <int dim>
struct G2POutput {
  double v_pic[dim]; // sum w v_i
  double dv[dim];    // sum w (v_new - v_old)_i  (FLIP increment)
  double L[dim][dim];  // velocity gradient sum v_i (x) grad w
  double B[dim][dim];  // sum w v_i (x_i - x_p)  (APIC, before D^-1)
  double D[dim];       // diagonal of sum w (x_i - x_p)(x_i - x_p)^T (tensor-product kernels)
};

template <int dim, class Shape>
inline void g2p_particle(const Stencil<dim, Shape> &st, double h, const NodeView<dim> &g, G2POutput<dim> &o) {
  constexpr int N = Shape::N;
  for (int d = 0; d < dim; ++d) {
    o.v_pic[d] = o.dv[d] = 0;
    for (int e = 0; e < dim; ++e) o.L[d][e] = o.B[d][e] = 0;
  }
  // D is diagonal for tensor-product kernels because sum_k w_k (x_k - x_p) = 0 in 1D.
  for (int d = 0; d < dim; ++d) {
    double s = 0;
    for (int a = 0; a < N; ++a) s += st.w[d][a] * st.frac[d][a] * st.frac[d][a];
    o.D[d] = s * h * h;
  }
  const int kN = (dim == 3) ? N : 1;
  for (int c = 0; c < kN; ++c) {
    const double wz = (dim == 3) ? st.w[dim - 1][c] : 1.0;
    const double dwz = (dim == 3) ? st.dw[dim - 1][c] : 0.0;
    const double fz = (dim == 3) ? st.frac[dim - 1][c] * h : 0.0;
    const int k = (dim == 3) ? st.base[2] + c : 0;
    for (int b = 0; b < N; ++b) {
      const int j = st.base[1] + b;
      const double wy = st.w[1][b], dwy = st.dw[1][b], fy = st.frac[1][b] * h;
      const double *row = g.at(st.base[0], j, k);
      for (int a = 0; a < N; ++a) {
        const double wx = st.w[0][a], dwx = st.dw[0][a], fx = st.frac[0][a] * h;
        const double w = wx * wy * wz;
        double grad[dim], dx[dim];
        grad[0] = dwx * wy * wz;
        grad[1] = wx * dwy * wz;
        dx[0] = fx;
        dx[1] = fy;
        if constexpr (dim == 3) {
          grad[2] = wx * wy * dwz;
          dx[2] = fz;
        }
        const double *n = row + (size_t)a * NodeView<dim>::NDOF;
        for (int d = 0; d < dim; ++d) {
          const double vd = n[1 + d];
          o.v_pic[d] += w * vd;
          o.dv[d] += w * n[1 + dim + d];
          for (int e = 0; e < dim; ++e) {
            o.L[d][e] += vd * grad[e];
            o.B[d][e] += w * vd * dx[e];
          }
        }
      }
    }
  }
}

// APIC affine matrix C = B D^-1. For the linear tent D is singular at nodes; there
// C = sum v_i (x) grad w_i (= B D^-1 wherever D is invertible, Jiang et al. 2015).
template <int dim>
inline void apic_C(const G2POutput<dim> &o, bool use_gradient, double *C) {
  for (int d = 0; d < dim; ++d)
    for (int e = 0; e < dim; ++e) C[d * dim + e] = use_gradient ? o.L[d][e] : o.B[d][e] / o.D[e];
}

} // namespace granmpm
