// Particle <-> grid transfers: pure per-particle kernels on a plain node array (no PETSc).
//
// Node layout (NDOF doubles per node: 1 + 2 dim, and in 3D one more that stays 0):
//   during P2G:            [ m, m v (dim), f (dim) (, 0) ]
//   after the grid update: [ m, v_new (dim), v_new - v_old (dim) (, 0) ]
// The 8th double in 3D makes [m, m v] and [f, 0] two aligned 4-wide vectors (NodeLanes).
// The Grid class owns the storage; these kernels only see a strided view of the local
// (ghosted) array, indexed with global node indices.
#pragma once

#include <cmath>
#include <cstring>
#include <type_traits>

#include "granmpm/shape.hpp"
#include "granmpm/tensor.hpp"

// P2G updates a row of N nodes as one run of N NDOF doubles, so consecutive particles of a
// cell (same rows) store and reload the same vectors, which store forwarding handles. (The
// earlier per-node form, packed by GCC's straight-line vectoriser into mixed-width loads and
// stores of a node's dofs, stalled on every node and was compiled without it.)

namespace granmpm {

enum class TransferKind { PIC = 0, FLIP = 1, APIC = 2 };

template <int dim>
struct NodeView {
  static constexpr int NDOF = dim == 3 ? 8 : 1 + 2 * dim;
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

// Short vectors over a node's components (GCC vector extensions; without -march=native they
// lower to SSE2 pairs). 3D: the 4-wide vector at the node's start holds [m, v0, v1, v2]
// (component d in lane d + 1, lane 0 the mass), the one at +4 [f0, f1, f2, 0] (lanes 0-2),
// and the one at +3 [v2, dv0, dv1, dv2] (lanes 1-3, aligned with the first). 2D: 2-wide
// vectors at +1 (m v or v) and +3 (f or dv), components in lanes 0, 1; the mass is a scalar.
template <int dim>
struct NodeLanes;
template <>
struct NodeLanes<3> {
  typedef double V __attribute__((vector_size(32)));
  static constexpr int v_at = 0, dv_at = 3, lane = 1, f_at = 4;
};
template <>
struct NodeLanes<2> {
  typedef double V __attribute__((vector_size(16)));
  static constexpr int v_at = 1, dv_at = 3, lane = 0, f_at = 3;
};
template <class V>
inline V load_lanes(const double *p) {
  V x;
  std::memcpy(&x, p, sizeof(V)); // an unaligned vector load
  return x;
}
template <class V>
inline void store_lanes(double *p, const V &x) {
  std::memcpy(p, &x, sizeof(V));
}

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
//
// Node i gets m w_i, w_i (m v + m C dx_i) and -V sigma grad w_i + m w_i b, with
// w_i = wx wy wz and grad w_i = (dwx wy wz, wx dwy wz, wx wy dwz). Both are factored by rows
// (fixed y and z; the N nodes of a row are consecutive in memory): every term is an x factor
// of its node (wx, wx fx h or dwx) times a scalar of the row (wyz, dwy wz, wy dwz, wyz fy h,
// wyz fz h) times a coefficient of the particle (equal to the term-by-term formula to
// round-off, tests/unit/test_transfer.cpp).
//
// 3D, on the node's two 4-wide vectors (NodeLanes): [m, m v] += wyz P_a + wx_a Rm and
// [f, 0] += wyz G_a + wx_a Rf, with P_a, G_a (x factor times particle coefficients) formed
// once per particle and Rm, Rf once per row: 4 vector fused multiply-adds per node, every
// operand in a register. 2D: every entry of a row (N NDOF doubles) is updated from tables
// of those products (U below), one vectorisable run per row.
template <int dim, class Shape>
inline void p2g_particle(const Stencil<dim, Shape> &st, const P2GInput<dim> &in, double h, const NodeView<dim> &g) {
  constexpr int N = Shape::N, NDOF = NodeView<dim>::NDOF;
  const double m = in.m;
  double A[dim][dim] = {}, S[dim][dim] = {}, mb[dim] = {}; // m C, -V sigma, m b
  if (in.C)
    for (int d = 0; d < dim; ++d)
      for (int e = 0; e < dim; ++e) A[d][e] = m * in.C[d * dim + e];
  if (in.s6) {
    const double V = in.vol;
    S[0][0] = -V * in.s6[0];
    S[1][1] = -V * in.s6[1];
    S[0][1] = S[1][0] = -V * in.s6[3];
    if constexpr (dim == 3) {
      S[2][2] = -V * in.s6[2];
      S[1][2] = S[2][1] = -V * in.s6[4];
      S[0][2] = S[2][0] = -V * in.s6[5];
    }
  }
  if (in.bacc)
    for (int d = 0; d < dim; ++d) mb[d] = m * in.bacc[d];
  if constexpr (dim == 3) {
    using V = NodeLanes<3>::V;
    const bool force = in.s6 || in.bacc; // without, the force entries stay 0
    const V Q = {m, m * in.v[0], m * in.v[1], m * in.v[2]}, MB = {mb[0], mb[1], mb[2], 0.0};
    const V Ac[3] = {{0.0, A[0][0], A[1][0], A[2][0]}, {0.0, A[0][1], A[1][1], A[2][1]}, {0.0, A[0][2], A[1][2], A[2][2]}};
    const V Sc[3] = {{S[0][0], S[1][0], S[2][0], 0.0}, {S[0][1], S[1][1], S[2][1], 0.0}, {S[0][2], S[1][2], S[2][2], 0.0}};
    V P[N], G[N];
    for (int a = 0; a < N; ++a) {
      P[a] = st.w[0][a] * Q + (st.w[0][a] * st.frac[0][a] * h) * Ac[0];
      G[a] = st.w[0][a] * MB + st.dw[0][a] * Sc[0];
    }
    for (int c = 0; c < N; ++c) {
      const double wz = st.w[2][c], dwz = st.dw[2][c], fz = st.frac[2][c] * h;
      for (int b = 0; b < N; ++b) {
        const double wyz = st.w[1][b] * wz, gy = st.dw[1][b] * wz, gz = st.w[1][b] * dwz;
        const V Rm = (wyz * st.frac[1][b] * h) * Ac[1] + (wyz * fz) * Ac[2];
        const V Rf = gy * Sc[1] + gz * Sc[2];
        double *n = g.at(st.base[0], st.base[1] + b, st.base[2] + c);
        for (int a = 0; a < N; ++a, n += NDOF) {
          store_lanes(n, load_lanes<V>(n) + st.w[0][a] * Rm + wyz * P[a]);
          if (force) store_lanes(n + NodeLanes<3>::f_at, load_lanes<V>(n + NodeLanes<3>::f_at) + st.w[0][a] * Rf + wyz * G[a]);
        }
      }
    }
  } else {
    constexpr int R = N * NDOF;
    // Per-particle tables over the R entries of a row. Row update:
    //   row += wyz (U0 + fy U4) + gy U2
    // U0: wx m | wx m v + wfx m C_d0 | wx m b + dwx (-V sigma_d0)      (mass | momentum | force)
    // U2: wx (-V sigma_d1) in the force dofs; U4: wx m C_d1 in the momentum dofs.
    double U0[R], U2[R], U4[R];
    for (int a = 0; a < N; ++a) {
      const double wx = st.w[0][a], wfx = st.w[0][a] * st.frac[0][a] * h, dwx = st.dw[0][a];
      double *u0 = U0 + a * NDOF, *u2 = U2 + a * NDOF, *u4 = U4 + a * NDOF;
      u0[0] = wx * m;
      u2[0] = u4[0] = 0;
      for (int d = 0; d < dim; ++d) {
        u0[1 + d] = wx * (m * in.v[d]) + wfx * A[d][0];
        u2[1 + d] = 0;
        u4[1 + d] = wx * A[d][1];
        u0[1 + dim + d] = wx * mb[d] + dwx * S[d][0];
        u2[1 + dim + d] = wx * S[d][1];
        u4[1 + dim + d] = 0;
      }
    }
    for (int b = 0; b < N; ++b) {
      const double wyz = st.w[1][b], gy = st.dw[1][b], wy4 = wyz * st.frac[1][b] * h;
      double *n = g.at(st.base[0], st.base[1] + b, 0);
      // Explicit fused multiply-adds: the vectorised body and a scalar prologue or epilogue
      // (which entries fall in which depends on the array's alignment, i.e. on the rank's
      // layout) round alike, so the result does not depend on the decomposition.
      for (int t = 0; t < R; ++t) n[t] = std::fma(wyz, U0[t], std::fma(wy4, U4[t], std::fma(gy, U2[t], n[t])));
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
  double Dinv[dim];    // 1 / D, formed before the gathers so that the divisions overlap them
};

// Gathers of one particle, factored like p2g_particle: along each row of N nodes the sums
// over the x factor (wx v, dwx v, wx fx h v, wx dv) are formed first, then weighted by the
// row's y and z factors, all on vectors of the node's components (NodeLanes): a node costs
// three vector fused multiply-adds instead of 3 dim scalar ones. The x factors are read from
// the stencil one scalar at a time (copying them as vectors from the stencil's scalar stores
// stalls store forwarding). with_dv = false skips the FLIP increment (o.dv is then 0): PIC
// and APIC never read it, and it is a third of the loads.
template <int dim, class Shape, bool with_dv = true>
inline void g2p_particle(const Stencil<dim, Shape> &st, double h, const NodeView<dim> &g, G2POutput<dim> &o) {
  constexpr int N = Shape::N, NDOF = NodeView<dim>::NDOF;
  using Ln = NodeLanes<dim>;
  using V = typename Ln::V;
  // D is diagonal for tensor-product kernels because sum_k w_k (x_k - x_p) = 0 in 1D.
  for (int d = 0; d < dim; ++d) {
    double s = 0;
    for (int a = 0; a < N; ++a) s += st.w[d][a] * st.frac[d][a] * st.frac[d][a];
    o.D[d] = s * h * h;
    // (The linear tent's D vanishes at nodes; apic_C uses the gradient form there.)
    o.Dinv[d] = std::is_same<Shape, LinearShape>::value ? 0.0 : 1.0 / o.D[d];
  }
  double wfx[N];
  for (int a = 0; a < N; ++a) wfx[a] = st.w[0][a] * st.frac[0][a] * h;
  V vp = {}, dv = {}, L[dim] = {}, B[dim] = {}; // L[e], B[e]: column e over the components
  const int kN = (dim == 3) ? N : 1;
  for (int c = 0; c < kN; ++c) {
    const double wz = (dim == 3) ? st.w[dim - 1][c] : 1.0;
    const double dwz = (dim == 3) ? st.dw[dim - 1][c] : 0.0;
    const double fz = (dim == 3) ? st.frac[dim - 1][c] * h : 0.0;
    const int k = (dim == 3) ? st.base[2] + c : 0;
    for (int b = 0; b < N; ++b) {
      const double wyz = st.w[1][b] * wz, gy = st.dw[1][b] * wz, gz = st.w[1][b] * dwz, fy = st.frac[1][b] * h;
      const double *n = g.at(st.base[0], st.base[1] + b, k);
      V s0 = {}, s1 = {}, s2 = {}, sd = {};
      for (int a = 0; a < N; ++a, n += NDOF) {
        const V vn = load_lanes<V>(n + Ln::v_at);
        s0 += st.w[0][a] * vn;
        s1 += st.dw[0][a] * vn;
        s2 += wfx[a] * vn;
        if constexpr (with_dv) sd += st.w[0][a] * load_lanes<V>(n + Ln::dv_at);
      }
      vp += wyz * s0;
      if constexpr (with_dv) dv += wyz * sd;
      L[0] += wyz * s1;
      L[1] += gy * s0;
      B[0] += wyz * s2;
      B[1] += (wyz * fy) * s0;
      if constexpr (dim == 3) {
        L[2] += gz * s0;
        B[2] += (wyz * fz) * s0;
      }
    }
  }
  for (int d = 0; d < dim; ++d) {
    o.v_pic[d] = vp[Ln::lane + d];
    o.dv[d] = dv[Ln::lane + d];
    for (int e = 0; e < dim; ++e) {
      o.L[d][e] = L[e][Ln::lane + d];
      o.B[d][e] = B[e][Ln::lane + d];
    }
  }
}

// APIC affine matrix C = B D^-1. For the linear tent D is singular at nodes; there
// C = sum v_i (x) grad w_i (= B D^-1 wherever D is invertible, Jiang et al. 2015).
template <int dim>
inline void apic_C(const G2POutput<dim> &o, bool use_gradient, double *C) {
  if (use_gradient) {
    for (int d = 0; d < dim; ++d)
      for (int e = 0; e < dim; ++e) C[d * dim + e] = o.L[d][e];
    return;
  }
  for (int d = 0; d < dim; ++d)
    for (int e = 0; e < dim; ++e) C[d * dim + e] = o.B[d][e] * o.Dinv[e];
}

} // namespace granmpm
