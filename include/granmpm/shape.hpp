// Shape functions of the background grid: pure, header-only kernels (no PETSc, no MPI).
//
// Every kernel is a tensor product of a 1D function. A 1D kernel maps a particle position
// given in grid units (xi = (x - x0)/h, x0 the coordinate of node 0) to the index of the
// first node of its support and the weights and derivatives (with respect to xi, so the
// caller multiplies by 1/h) of the N consecutive nodes starting there.
#pragma once

#include <array>
#include <cmath>

namespace granmpm {

enum class ShapeKind { Linear = 0, GIMP = 1, BSpline2 = 2 };

// Linear tent: support two nodes, the classic MPM kernel.
struct LinearShape {
  static constexpr int N = 2;
  static constexpr const char *name = "linear";
  double lp = 0; // unused; keeps the interface uniform
  inline int eval(double xi, double w[N], double dw[N]) const {
    const int base = (int)std::floor(xi);
    const double r = xi - base; // in [0,1)
    w[0] = 1.0 - r;
    w[1] = r;
    dw[0] = -1.0;
    dw[1] = 1.0;
    return base;
  }
};

// Uniform GIMP (Bardenhagen & Kober 2004): the tent integrated against a particle
// characteristic function of half-width lp (in grid units, 0 < lp <= 1/2, usually
// 1/(2 ppc)). Its support is |r| < 1 + lp <= 1.5, so three nodes always suffice:
// base = round(xi) - 1.
struct GIMPShape {
  static constexpr int N = 3;
  static constexpr const char *name = "gimp";
  double lp = 0.25;
  static inline void one(double r, double a, double &w, double &dw) {
    const double ar = std::fabs(r);
    const double s = (r < 0) ? -1.0 : 1.0;
    if (ar < a) {
      w = 1.0 - (r * r + a * a) / (2.0 * a);
      dw = -r / a;
    } else if (ar < 1.0 - a) {
      w = 1.0 - ar;
      dw = -s;
    } else if (ar < 1.0 + a) {
      const double t = 1.0 + a - ar;
      w = t * t / (4.0 * a);
      dw = -s * t / (2.0 * a);
    } else {
      w = 0.0;
      dw = 0.0;
    }
  }
  inline int eval(double xi, double w[N], double dw[N]) const {
    const int base = (int)std::floor(xi + 0.5) - 1;
    for (int k = 0; k < N; ++k) one(xi - (base + k), lp, w[k], dw[k]);
    return base;
  }
};

// Quadratic B-spline: support three nodes, C1, used with APIC/MLS (seed 004).
struct BSpline2Shape {
  static constexpr int N = 3;
  static constexpr const char *name = "bspline2";
  double lp = 0;
  inline int eval(double xi, double w[N], double dw[N]) const {
    const int base = (int)std::floor(xi - 0.5);
    const double r = xi - base; // in [0.5, 1.5)
    const double a = 1.5 - r, b = r - 1.0, c = r - 0.5;
    w[0] = 0.5 * a * a;
    w[1] = 0.75 - b * b;
    w[2] = 0.5 * c * c;
    dw[0] = -a;
    dw[1] = -2.0 * b;
    dw[2] = c;
    return base;
  }
};

// Tensor-product weights of one particle in dim dimensions. Stores the 1D factors only;
// the caller forms products in its loops (cheaper than storing N^dim products when the
// loop also needs gradients).
template <int dim, class Shape>
struct Stencil {
  static constexpr int N = Shape::N;
  int base[dim];
  double w[dim][N];
  double dw[dim][N]; // derivative with respect to x (already divided by h)
  double frac[dim][N]; // (x_i - x_p)/h for each 1D node, for APIC

  inline void compute(const Shape &s, const double *xp, const double *x0, double inv_h) {
    for (int d = 0; d < dim; ++d) {
      const double xi = (xp[d] - x0[d]) * inv_h;
      base[d] = s.eval(xi, w[d], dw[d]);
      for (int k = 0; k < N; ++k) {
        dw[d][k] *= inv_h;
        frac[d][k] = (base[d] + k) - xi;
      }
    }
  }
};

} // namespace granmpm
