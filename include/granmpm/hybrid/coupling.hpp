// Pure kernels of the hybrid continuum/discrete method (issue 18; docs/hybrid.md): the
// zone oracle (grains rasterised to a packing fraction phi, a signed distance from the
// contour phi = threshold, zones from that distance) and the velocity constraint that ties
// the two phases together at the grid nodes they share. No PETSc, no MPI: the module that
// drives them (not yet written) owns the grids and the swarms.
//
// Zones follow Yue et al. 2018 ("Hybrid grains"): s > 0 inside the dense region; the band is
// centred at s = band_distance inside it, of half-width band_half_width:
//   s > band_distance + hw   continuum (material points only, weight w_M = 1)
//   |s - band_distance| <= hw  band (both phases, w_M = band weight, w_D = 1 - w_M)
//   s < band_distance - hw   discrete (grains only, w_D = 1)
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

namespace granmpm::hybrid {

// Integral of sqrt(r^2 - X^2) dX from -r to x (x clamped to [-r, r]).
inline double half_chord_integral(double r, double x) {
  // sqrt((r - X)(r + X)) and atan2 instead of asin(X / r): asin is ill-conditioned at +-1,
  // where one ulp of X / r moves it by 1e-8 (measured: 1e-9 relative errors in disk areas).
  const double X = std::min(std::max(x, -r), r), h = std::sqrt((r - X) * (r + X));
  return 0.5 * (X * h + r * r * std::atan2(X, h)) + 0.25 * M_PI * r * r;
}

// Area of the disk of radius r at the origin with X < x and Y < y, exactly: the chord at
// abscissa X spans |Y| < h(X) = sqrt(r^2 - X^2); below y it has length min(y, h) + h,
// clipped at 0. Where |X| < a = sqrt(r^2 - y^2) the chord is cut by y (length y + h), outside
// it lies wholly below (y > 0: length 2h) or wholly above (y < 0: length 0).
inline double disk_quadrant_area(double r, double x, double y) {
  if (x <= -r || y <= -r) return 0.0;
  x = std::min(x, r);
  if (y >= r) return 2.0 * half_chord_integral(r, x);
  const double a = std::sqrt(r * r - y * y);
  auto H = [&](double lo, double hi) { return hi > lo ? half_chord_integral(r, hi) - half_chord_integral(r, lo) : 0.0; };
  const double lo_in = -a, hi_in = std::min(x, a);
  double A = 0;
  if (hi_in > lo_in) A += y * (hi_in - lo_in) + H(lo_in, hi_in); // cut chords: y + h
  if (y > 0) A += 2.0 * (H(-r, std::min(x, -a)) + H(a, x));     // whole chords below y
  return A;
}

// Area of the disk (centre c, radius r) inside the rectangle [x0, x1] x [y0, y1], exact to
// round-off (inclusion-exclusion of four quadrant areas).
inline double disk_rect_area(const double c[2], double r, double x0, double x1, double y0, double y1) {
  if (x1 <= c[0] - r || x0 >= c[0] + r || y1 <= c[1] - r || y0 >= c[1] + r) return 0.0;
  const double a = x0 - c[0], b = x1 - c[0], d = y0 - c[1], e = y1 - c[1];
  return disk_quadrant_area(r, b, e) - disk_quadrant_area(r, a, e) - disk_quadrant_area(r, b, d) + disk_quadrant_area(r, a, d);
}

// Volume of the sphere (centre c, radius r) inside the box [lo, hi]: the disk areas of its z
// slices integrated by Gauss-Legendre (5 points on each of nsub equal pieces of the z range
// the box and the sphere share). The slice area has kinks where the slice circle crosses a
// box edge, so the error falls algebraically with nsub (measured in test_hybrid_coupling.cpp).
inline double sphere_box_volume(const double c[3], double r, const double lo[3], const double hi[3], int nsub = 16) {
  const double z0 = std::max(lo[2], c[2] - r), z1 = std::min(hi[2], c[2] + r);
  if (z1 <= z0) return 0.0;
  static const double gx[5] = {-0.9061798459386640, -0.5384693101056831, 0.0, 0.5384693101056831, 0.9061798459386640};
  static const double gw[5] = {0.2369268850561891, 0.4786286704993665, 0.5688888888888889, 0.4786286704993665, 0.2369268850561891};
  const double w = (z1 - z0) / nsub;
  double V = 0;
  for (int s = 0; s < nsub; ++s)
    for (int q = 0; q < 5; ++q) {
      const double z = z0 + w * (s + 0.5 * (gx[q] + 1.0)), rz2 = r * r - (z - c[2]) * (z - c[2]);
      if (rz2 > 0) V += 0.5 * w * gw[q] * disk_rect_area(c, std::sqrt(rz2), lo[0], hi[0], lo[1], hi[1]);
    }
  return V;
}

// A uniform cell grid (the oracle's level-set grid): origin lo, spacing h, n cells per axis.
template <int dim>
struct CellGrid {
  double lo[dim];
  double h;
  int n[dim];
  bool periodic[dim] = {}; // wrapped axes: grains across the face and distances through it count
  int wrap(int c, int d) const { return periodic[d] ? ((c % n[d]) + n[d]) % n[d] : c; }
  long size() const {
    long s = 1;
    for (int d = 0; d < dim; ++d) s *= n[d];
    return s;
  }
  long index(const int c[dim]) const {
    long idx = 0, stride = 1;
    for (int d = 0; d < dim; ++d) {
      idx += c[d] * stride;
      stride *= n[d];
    }
    return idx;
  }
};

// Packing fraction of grains (centres x, dim per grain; radii r) on the cell grid: each
// grain's exact overlap with each cell it touches, over the cell volume. The sum of phi times
// the cell volume is the grains' total volume wherever they lie inside the grid, or across a
// periodic face (tested).
template <int dim>
std::vector<double> packing_fraction(const CellGrid<dim> &G, const std::vector<double> &x, const std::vector<double> &r, int nsub = 16) {
  std::vector<double> phi((size_t)G.size(), 0.0);
  const double cellvol = std::pow(G.h, dim);
  for (size_t p = 0; p < r.size(); ++p) {
    const double *c = &x[p * dim];
    int a[dim], b[dim];
    for (int d = 0; d < dim; ++d) { // periodic axes: the cells past a face are its images
      a[d] = (int)std::floor((c[d] - r[p] - G.lo[d]) / G.h);
      b[d] = (int)std::floor((c[d] + r[p] - G.lo[d]) / G.h);
      if (!G.periodic[d]) {
        a[d] = std::max(0, a[d]);
        b[d] = std::min(G.n[d] - 1, b[d]);
      }
    }
    int k[3] = {0, 0, 0};
    for (k[2] = dim == 3 ? a[dim - 1] : 0; k[2] <= (dim == 3 ? b[dim - 1] : 0); ++k[2])
      for (k[1] = a[1]; k[1] <= b[1]; ++k[1])
        for (k[0] = a[0]; k[0] <= b[0]; ++k[0]) {
          double lo[3], hi[3];
          int kw[3] = {0, 0, 0};
          for (int d = 0; d < dim; ++d) {
            lo[d] = G.lo[d] + k[d] * G.h;
            hi[d] = lo[d] + G.h;
            kw[d] = G.wrap(k[d], d);
          }
          const double v = dim == 2 ? disk_rect_area(c, r[p], lo[0], hi[0], lo[1], hi[1]) : sphere_box_volume(c, r[p], lo, hi, nsub);
          phi[(size_t)G.index(kw)] += v / cellvol;
        }
  }
  return phi;
}

// Signed distance of each cell centre to the contour between dense cells (phi >= threshold)
// and dilute ones, positive in the dense region: the distance to the nearest centre of the
// other class minus h/2 (exact for a contour along cell faces; O(h) otherwise). Searched
// within cap (cells farther than cap from the contour get +-cap): the zones only need the
// distance out to the band.
// The nearest cell q of the other class to a cell i always has a face neighbour of i's class
// (one step from q toward i along the largest offset component is closer to i, so it is of
// i's class), so only those contour cells are searched: each one lowers the squared offset
// of the cells of the other class within cap around it. The same minimum as searching every
// cell within cap of every cell, at O(contour cells (cap/h)^dim) instead of O(cells (cap/h)^dim).
template <int dim>
std::vector<double> signed_distance(const CellGrid<dim> &G, const std::vector<double> &phi, double threshold, double cap) {
  const long N = G.size();
  const int R = (int)std::ceil(cap / G.h) + 1;
  auto coords = [&G](long i, int c[3]) {
    c[0] = c[1] = c[2] = 0;
    for (int d = 0; d < dim; ++d) {
      c[d] = (int)(i % G.n[d]);
      i /= G.n[d];
    }
  };
  // The cell at c + o (wrapped through periodic faces), or -1 outside the grid.
  auto at = [&G](const int c[3], const int o[3]) {
    int q[dim];
    for (int d = 0; d < dim; ++d) {
      q[d] = G.wrap(c[d] + o[d], d);
      if (q[d] < 0 || q[d] >= G.n[d]) return -1L;
    }
    return G.index(q);
  };
  std::vector<char> dense((size_t)N);
  for (long i = 0; i < N; ++i) dense[(size_t)i] = phi[(size_t)i] >= threshold;
  std::vector<double> best2((size_t)N, 1e300);
  int c[3], o[3] = {0, 0, 0};
  for (long q = 0; q < N; ++q) {
    coords(q, c);
    bool contour = false;
    for (int d = 0; d < dim && !contour; ++d)
      for (int sgn = -1; sgn <= 1 && !contour; sgn += 2) {
        int e[3] = {0, 0, 0};
        e[d] = sgn;
        const long k = at(c, e);
        contour = k >= 0 && dense[(size_t)k] != dense[(size_t)q];
      }
    if (!contour) continue;
    for (o[2] = dim == 3 ? -R : 0; o[2] <= (dim == 3 ? R : 0); ++o[2])
      for (o[1] = -R; o[1] <= R; ++o[1])
        for (o[0] = -R; o[0] <= R; ++o[0]) {
          const long i = at(c, o);
          if (i < 0 || dense[(size_t)i] == dense[(size_t)q]) continue;
          const double d2 = (double)o[0] * o[0] + (double)o[1] * o[1] + (double)o[2] * o[2];
          if (d2 < best2[(size_t)i]) best2[(size_t)i] = d2;
        }
  }
  std::vector<double> s((size_t)N);
  for (long i = 0; i < N; ++i) {
    const double b = best2[(size_t)i], dist = b < 1e300 ? std::min(std::sqrt(b) * G.h - 0.5 * G.h, cap) : cap;
    s[(size_t)i] = dense[(size_t)i] ? dist : -dist;
  }
  return s;
}

enum class Zone : unsigned char { Continuum = 0, Band = 1, Discrete = 2 };

struct ZoneRule {
  double band_distance = 0; // centre of the band, inside the dense region (s > 0)
  double half_width = 0;    // of the band
  double band_weight = 0.5; // continuum share w_M of mass in the band
};

inline Zone zone_of(double s, const ZoneRule &z) {
  if (s > z.band_distance + z.half_width) return Zone::Continuum;
  if (s < z.band_distance - z.half_width) return Zone::Discrete;
  return Zone::Band;
}

// The cell of G holding x (clamped to the grid: a point on the far face is in the last cell).
template <int dim>
inline long cell_index(const CellGrid<dim> &G, const double *x) {
  int c[dim];
  for (int d = 0; d < dim; ++d) c[d] = std::min(std::max((int)std::floor((x[d] - G.lo[d]) / G.h), 0), G.n[d] - 1);
  return G.index(c);
}

// The oracle's zones of the cells (Yue et al. 2018): phi from the grains, phi = 1 in every
// cell that holds a material point (dense[c] != 0), the contour phi = threshold, the signed
// distance from it (searched out to just past the band: farther cells are continuum or
// discrete whatever their exact distance) and zone_of.
template <int dim>
std::vector<Zone> oracle_zones(const CellGrid<dim> &G, std::vector<double> phi, const std::vector<double> &dense, double threshold, const ZoneRule &z) {
  for (size_t c = 0; c < phi.size(); ++c)
    if (dense[c] != 0) phi[c] = 1.0;
  const double cap = std::max(std::fabs(z.band_distance) + z.half_width, 0.0) + 2 * G.h;
  const std::vector<double> s = signed_distance(G, phi, threshold, cap);
  std::vector<Zone> out(s.size());
  for (size_t c = 0; c < s.size(); ++c) out[c] = zone_of(s[c], z);
  return out;
}

// The continuum phase's share of a particle's or grain's mass in a zone (the discrete share is
// one minus it): both phases carry their full mass outside the band, split mass inside it.
inline double continuum_weight(Zone z, const ZoneRule &r) { return z == Zone::Continuum ? 1.0 : z == Zone::Discrete ? 0.0 : r.band_weight; }

// Zones pinned geometrically (-hybrid_band): the slab lo <= x[axis] <= hi is the band; the
// continuum zone lies above it (continuum_hi) or below it, the discrete zone on the other
// side. No conversions: each material point and grain keeps the share of its mass it was
// given at the start (continuum_weight at its initial position).
struct FixedBand {
  int axis = 1;
  double lo = 0, hi = 0;
  bool continuum_hi = true;
  double band_weight = 0.5; // w_M in the band
  Zone zone(const double *x) const {
    const double c = x[axis];
    if (c >= lo && c <= hi) return Zone::Band;
    return (c > hi) == continuum_hi ? Zone::Continuum : Zone::Discrete;
  }
  double continuum_weight(const double *x) const {
    const Zone z = zone(x);
    return z == Zone::Continuum ? 1.0 : z == Zone::Discrete ? 0.0 : band_weight;
  }
};

// Tent (linear) weights of a point at x on a grid of spacing h with node 0 at x0: the first
// node per direction and the two weights. Grains are rasterised with these whatever the
// MPM's shape: mass and momentum go to the nodes of the grain's cell, and the FLIP update
// reads the same nodes with the same weights, which is what conserves momentum.
template <int dim>
inline void tent(const double *x, const double *x0, double inv_h, int base[dim], double w[dim][2]) {
  for (int d = 0; d < dim; ++d) {
    const double xi = (x[d] - x0[d]) * inv_h;
    base[d] = (int)std::floor(xi);
    const double f = xi - base[d];
    w[d][0] = 1.0 - f;
    w[d][1] = f;
  }
}

// The velocity constraint at a grid node both phases share (Yue et al. 2018, eq. of the
// Lagrange multiplier): with continuum mass and momentum (mM, pM) and the grains' rasterised
// (mD, pD), the impulse lambda = (mD pM - mM pD) / (mM + mD) moved from the continuum to the
// grains makes both velocities (pM - lambda)/mM = (pD + lambda)/mD equal to the mass-weighted
// mean, and conserves pM + pD (the same lambda leaves one side and enters the other).
// A node with no mass on either side is left alone (nothing to constrain).
template <int dim>
inline void constrain_node(double mM, double *pM, double mD, double *pD, double *lambda) {
  for (int d = 0; d < dim; ++d) lambda[d] = 0;
  if (!(mM > 0 && mD > 0)) return;
  const double inv = 1.0 / (mM + mD);
  for (int d = 0; d < dim; ++d) {
    lambda[d] = (mD * pM[d] - mM * pD[d]) * inv;
    pM[d] -= lambda[d];
    pD[d] += lambda[d];
  }
}

// Enrichment of one cell (HybridModule::enrich): grains of density rho that take the mass M of
// the cell's material points, without overlapping each other or the grains already near the
// cell (centres xe, dim per grain; radii re) by more than tol of the smaller radius; periodic
// axes of G are wrapped. n grains of one radius r(n) = (M / (n rho unit))^(1/dim), unit = pi
// (2D) or 4 pi / 3 (3D), on the centres of k^dim sub-cells (k = ceil(n^(1/dim))), the first
// n sites in lattice order that are clear of the grains there, for n from floor(M / m(r0))
// (m(r0): the mean radius's mass) down to 1, the first n whose lattice fits (2 r <= h,
// 2 r - h / k <= tol r) and has n clear sites. If no n takes all of M (a packing above the
// lattice's, or grains reaching into the cell), the cell goes in part: grains of the mean
// radius r0 on the densest lattice of them that fits, on its clear sites, at most
// floor(M / m(r0)) of them (partial = true: they take n m(r0) of M). No grain is smaller than
// r_lo (the lightest mass the DEM's time step assumed). No site: x empty.
struct EnrichPlan {
  double r = 0;
  std::vector<double> x; // dim per grain
  bool partial = false;
};
template <int dim>
EnrichPlan enrich_cell(const CellGrid<dim> &G, const int cell[dim], double M, double r0, double r_lo, double rho, double tol, const std::vector<double> &xe,
                       const std::vector<double> &re, long nmax = 4096) {
  const double unit = dim == 3 ? 4.0 / 3.0 * M_PI : M_PI, m0 = rho * unit * std::pow(r0, dim);
  EnrichPlan plan;
  // The sites of a k^dim lattice clear of the grains near the cell, at most want of them.
  auto sites = [&](int k, double r, long want) {
    std::vector<double> out;
    const double sub = G.h / k;
    long total = 1;
    for (int d = 0; d < dim; ++d) total *= k;
    for (long j = 0; j < total && (long)out.size() / dim < want; ++j) {
      double s[dim];
      long rem = j;
      for (int d = 0; d < dim; ++d, rem /= k) s[d] = G.lo[d] + cell[d] * G.h + ((double)(rem % k) + 0.5) * sub;
      bool clear = true;
      for (size_t e = 0; e < re.size() && clear; ++e) {
        double d2 = 0;
        for (int d = 0; d < dim; ++d) {
          double dx = s[d] - xe[e * dim + d];
          if (G.periodic[d]) {
            const double L = G.n[d] * G.h;
            dx -= L * std::round(dx / L);
          }
          d2 += dx * dx;
        }
        const double reach = r + re[e] - tol * std::min(r, re[e]);
        clear = d2 >= reach * reach;
      }
      if (clear) out.insert(out.end(), s, s + dim);
    }
    return out;
  };
  if (!(M > 0)) return plan;
  const long n0 = std::max(1L, (long)std::floor(M / m0));
  for (long n = std::min(n0, nmax); n >= 1; --n) {
    const double r = std::pow(M / (n * rho * unit), 1.0 / dim);
    const int k = (int)std::ceil(std::pow((double)n, 1.0 / dim) - 1e-12);
    if (r < r_lo || 2 * r > G.h || 2 * r - G.h / k > tol * r) continue;
    std::vector<double> x = sites(k, r, n);
    if ((long)x.size() / dim == n) {
      plan.r = r;
      plan.x = std::move(x);
      return plan;
    }
  }
  // In part: the mean radius on its densest fitting lattice.
  const int k = (int)std::floor(G.h / ((2 - tol) * r0) + 1e-12);
  if (k < 1 || 2 * r0 > G.h || M < m0) return plan;
  plan.x = sites(k, r0, std::min(n0, nmax));
  plan.r = r0;
  plan.partial = true;
  return plan;
}

} // namespace granmpm::hybrid
