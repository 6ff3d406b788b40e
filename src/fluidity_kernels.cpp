// Pure kernels of the steady fluidity solver: element and cell contributions, symmetric band
// Cholesky, solve, product and preconditioned CG (declared in fluidity.hpp). Split from
// fluidity.cpp.
#include "granmpm/fluidity.hpp"

#include <algorithm>
#include <cmath>

namespace granmpm {

template <int dim>
void fluidity_element_contribution(const double *xi, double h, double vol, double w, double gloc, double k, double *Ke, double *fe) {
  constexpr int nn = 1 << dim;
  double S[nn], dS[nn][dim];
  for (int n = 0; n < nn; ++n) {
    S[n] = 1;
    for (int d = 0; d < dim; ++d) {
      const int bit = (n >> d) & 1;
      S[n] *= bit ? xi[d] : 1.0 - xi[d];
    }
    for (int d = 0; d < dim; ++d) {
      double g = 1;
      for (int e = 0; e < dim; ++e) {
        const int bit = (n >> e) & 1;
        if (e == d) g *= (bit ? 1.0 : -1.0) / h;
        else g *= bit ? xi[e] : 1.0 - xi[e];
      }
      dS[n][d] = g;
    }
  }
  const double vw = vol * w, vk = vol * k;
  for (int a = 0; a < nn; ++a) {
    fe[a] += vw * gloc * S[a];
    for (int b = a; b < nn; ++b) { // symmetric: the upper half, mirrored
      double gg = 0;
      for (int d = 0; d < dim; ++d) gg += dS[a][d] * dS[b][d];
      const double v = vw * S[a] * S[b] + vk * gg;
      Ke[a * nn + b] += v;
      if (b != a) Ke[b * nn + a] += v;
    }
  }
}

template <int dim>
void fluidity_cell_contribution(double h, double phi, double Wm, double F, double k, double *Ke, double *fe) {
  // Exact integrals of the Q1 products over the cell, times the cell averages of the
  // coefficients: 1D mass h/3 (same node) or h/6, 1D stiffness +-1/h.
  constexpr int nn = 1 << dim;
  const double hd = std::pow(h, dim);
  for (int a = 0; a < nn; ++a) {
    fe[a] += F / nn;
    for (int b = 0; b < nn; ++b) {
      double m[dim], mass = 1;
      for (int d = 0; d < dim; ++d) {
        m[d] = (((a >> d) & 1) == ((b >> d) & 1)) ? 1.0 / 3 : 1.0 / 6;
        mass *= m[d];
      }
      double stiff = 0;
      for (int d = 0; d < dim; ++d) {
        double t = (((a >> d) & 1) == ((b >> d) & 1)) ? 1.0 : -1.0;
        for (int e = 0; e < dim; ++e)
          if (e != d) t *= m[e];
        stiff += t;
      }
      Ke[a * nn + b] += Wm * hd * mass + phi * k * std::pow(h, dim - 2) * stiff;
    }
  }
}

int band_cholesky(PetscInt n, int bw, double *a) {
  // Right-looking: column k of L, then the rank-1 update of the (bw x bw) triangle below
  // it. The updates of one column are independent, so the loop runs at FMA throughput
  // instead of the latency of a dot-product chain per entry.
  const PetscInt w = bw + 1;
  int replaced = 0;
  std::vector<double> d0(n), col(bw + 1);
  for (PetscInt k = 0; k < n; ++k) d0[k] = a[k * w + bw];
  for (PetscInt k = 0; k < n; ++k) {
    double s = a[k * w + bw];
    if (!(s > kPivotTol * d0[k])) {
      s = d0[k] > 0 ? d0[k] : 1.0;
      ++replaced;
    }
    const double inv = 1.0 / std::sqrt(s);
    a[k * w + bw] = inv;
    const PetscInt m = std::min<PetscInt>(bw, n - 1 - k); // rows k+1 .. k+m below the pivot
    for (PetscInt r = 1; r <= m; ++r) {
      double &l = a[(k + r) * w + bw - r];
      l *= inv;
      col[r] = l;
    }
    for (PetscInt r = 1; r <= m; ++r) {
      double *row = a + (k + r) * w + bw - (k + r); // row[j] = entry (k + r, j)
      const double lr = col[r];
      for (PetscInt q = 1; q <= r; ++q) row[k + q] -= lr * col[q];
    }
  }
  return replaced;
}

void band_solve(PetscInt n, int bw, const double *L, double *x) {
  // Both sweeps column by column (independent updates); L's diagonal holds 1 / L_kk.
  const PetscInt w = bw + 1;
  for (PetscInt k = 0; k < n; ++k) {
    const double xk = (x[k] *= L[k * w + bw]);
    const PetscInt m = std::min<PetscInt>(bw, n - 1 - k);
    for (PetscInt r = 1; r <= m; ++r) x[k + r] -= L[(k + r) * w + bw - r] * xk;
  }
  for (PetscInt k = n - 1; k >= 0; --k) {
    const double xk = (x[k] *= L[k * w + bw]);
    const double *rk = L + k * w + bw - k;
    for (PetscInt i = std::max<PetscInt>(0, k - bw); i < k; ++i) x[i] -= rk[i] * xk;
  }
}

void band_matvec(PetscInt n, int bw, const double *a, const double *x, double *y) {
  const int w = bw + 1;
  for (PetscInt k = 0; k < n; ++k) y[k] = 0;
  for (PetscInt k = 0; k < n; ++k) {
    const double *rk = a + k * w + bw - k;
    double s = rk[k] * x[k];
    for (PetscInt j = std::max<PetscInt>(0, k - bw); j < k; ++j) {
      s += rk[j] * x[j];
      y[j] += rk[j] * x[k];
    }
    y[k] += s;
  }
}

int band_pcg(PetscInt n, int bw, const double *a, const double *L, const double *f, double *x, double rtol, int maxit, double *work) {
  double *r = work, *z = work + n, *p = work + 2 * n, *q = work + 3 * n;
  double fn = 0;
  for (PetscInt i = 0; i < n; ++i) {
    x[i] = 0;
    r[i] = f[i];
    fn += f[i] * f[i];
  }
  const double stop = rtol * rtol * fn;
  if (fn == 0) return 0;
  std::copy(r, r + n, z);
  band_solve(n, bw, L, z);
  std::copy(z, z + n, p);
  double rz = 0;
  for (PetscInt i = 0; i < n; ++i) rz += r[i] * z[i];
  for (int it = 1; it <= maxit; ++it) {
    band_matvec(n, bw, a, p, q);
    double pq = 0;
    for (PetscInt i = 0; i < n; ++i) pq += p[i] * q[i];
    if (!(pq > 0)) return -1; // breakdown before convergence (the residual is checked below)
    const double alpha = rz / pq;
    double rr = 0;
    for (PetscInt i = 0; i < n; ++i) {
      x[i] += alpha * p[i];
      r[i] -= alpha * q[i];
      rr += r[i] * r[i];
    }
    if (rr <= stop) return it;
    std::copy(r, r + n, z);
    band_solve(n, bw, L, z);
    double rz1 = 0;
    for (PetscInt i = 0; i < n; ++i) rz1 += r[i] * z[i];
    const double beta = rz1 / rz;
    rz = rz1;
    for (PetscInt i = 0; i < n; ++i) p[i] = z[i] + beta * p[i];
  }
  return -1;
}

namespace {
// band_lu and band_lu_solve for a half-bandwidth BW known at compile time (BW = 0: the
// run-time bw). The chute's g systems have bw 4 or 7: with a fixed BW the row updates
// unroll and vectorise (the pivot row is copied out first, so the compiler need not assume
// that it aliases the rows it updates). The same operations in the same order as the
// generic loops, so the factor and the solution are the same to the bit.
template <int BW>
bool band_lu_t(PetscInt n, int bw_rt, double *a) {
  const int bw = BW > 0 ? BW : bw_rt;
  const PetscInt w = 2 * bw + 1;
  for (PetscInt k = 0; k < n; ++k) {
    double *pk = a + k * w + bw - k; // pk[c] = entry (k, c)
    const double piv = pk[k];
    if (!(std::fabs(piv) > 0) || !std::isfinite(piv)) return false;
    const double inv = 1.0 / piv;
    pk[k] = inv; // the solve multiplies: no division on its critical path
    const PetscInt m = std::min<PetscInt>(bw, n - 1 - k);
    if (BW > 0 && m == BW) {
      double u[BW > 0 ? BW : 1];
      for (int c = 0; c < BW; ++c) u[c] = pk[k + 1 + c];
      for (int r = 1; r <= BW; ++r) {
        double *row = a + (k + r) * w + bw - (k + r);
        const double l = (row[k] *= inv);
        for (int c = 0; c < BW; ++c) row[k + 1 + c] -= l * u[c];
      }
      continue;
    }
    for (PetscInt r = 1; r <= m; ++r) {
      double *row = a + (k + r) * w + bw - (k + r); // row[c] = entry (k + r, c)
      const double l = (row[k] *= inv);
      for (PetscInt c = k + 1; c <= k + m; ++c) row[c] -= l * pk[c];
    }
  }
  return true;
}

template <int BW>
void band_lu_solve_t(PetscInt n, int bw_rt, const double *lu, double *x) {
  const int bw = BW > 0 ? BW : bw_rt;
  const PetscInt w = 2 * bw + 1;
  for (PetscInt k = 0; k < n; ++k) { // L y = x, column by column (unit diagonal)
    const double xk = x[k];
    const PetscInt m = std::min<PetscInt>(bw, n - 1 - k);
    if (BW > 0 && m == BW) {
      for (int r = 1; r <= BW; ++r) x[k + r] -= lu[(k + r) * w + bw - r] * xk;
      continue;
    }
    for (PetscInt r = 1; r <= m; ++r) x[k + r] -= lu[(k + r) * w + bw - r] * xk;
  }
  // U x = y, column by column: x_k is final once scaled by 1 / U_kk (stored by band_lu), and
  // goes into the rows above it at once. (Row by row, each row's sum starts from the x just
  // divided: a division plus bw dependent multiply-adds per row on the critical path.)
  for (PetscInt k = n - 1; k >= 0; --k) {
    const double xk = (x[k] *= lu[k * w + bw]);
    if (BW > 0 && k >= BW) {
      for (int q = BW; q >= 1; --q) x[k - q] -= lu[(k - q) * w + bw + q] * xk;
      continue;
    }
    for (PetscInt i = std::max<PetscInt>(0, k - bw); i < k; ++i) x[i] -= lu[i * w + bw + (k - i)] * xk;
  }
}
} // namespace

bool band_lu(PetscInt n, int bw, double *a) {
  // Right-looking Doolittle: the multipliers of column k, then the (bw x bw) update below
  // and right of the pivot (independent updates, as in band_cholesky).
  switch (bw) {
  case 1: return band_lu_t<1>(n, bw, a);
  case 2: return band_lu_t<2>(n, bw, a);
  case 3: return band_lu_t<3>(n, bw, a);
  case 4: return band_lu_t<4>(n, bw, a);
  case 5: return band_lu_t<5>(n, bw, a);
  case 6: return band_lu_t<6>(n, bw, a);
  case 7: return band_lu_t<7>(n, bw, a);
  case 8: return band_lu_t<8>(n, bw, a);
  default: return band_lu_t<0>(n, bw, a);
  }
}

void band_lu_solve(PetscInt n, int bw, const double *lu, double *x) {
  switch (bw) {
  case 1: return band_lu_solve_t<1>(n, bw, lu, x);
  case 2: return band_lu_solve_t<2>(n, bw, lu, x);
  case 3: return band_lu_solve_t<3>(n, bw, lu, x);
  case 4: return band_lu_solve_t<4>(n, bw, lu, x);
  case 5: return band_lu_solve_t<5>(n, bw, lu, x);
  case 6: return band_lu_solve_t<6>(n, bw, lu, x);
  case 7: return band_lu_solve_t<7>(n, bw, lu, x);
  case 8: return band_lu_solve_t<8>(n, bw, lu, x);
  default: return band_lu_solve_t<0>(n, bw, lu, x);
  }
}

template void fluidity_element_contribution<2>(const double *, double, double, double, double, double, double *, double *);
template void fluidity_element_contribution<3>(const double *, double, double, double, double, double, double *, double *);
template void fluidity_cell_contribution<2>(double, double, double, double, double, double *, double *);
template void fluidity_cell_contribution<3>(double, double, double, double, double, double *, double *);

} // namespace granmpm
