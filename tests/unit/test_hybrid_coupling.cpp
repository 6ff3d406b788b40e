// The hybrid method's pure kernels (include/granmpm/hybrid/coupling.hpp) against exact
// geometry and the conservation laws they must keep.
#include <catch2/catch.hpp>

#include <cmath>
#include <random>

#include "granmpm/hybrid/coupling.hpp"

using namespace granmpm::hybrid;

TEST_CASE("disk-rectangle area: exact pieces of a disk", "[hybrid]") {
  const double c[2] = {0.3, -0.2}, r = 0.7;
  // Whole disk, half disks, a quadrant, nothing.
  CHECK(disk_rect_area(c, r, -5, 5, -5, 5) == Approx(M_PI * r * r).epsilon(1e-14));
  CHECK(disk_rect_area(c, r, c[0], 5, -5, 5) == Approx(0.5 * M_PI * r * r).epsilon(1e-14));
  CHECK(disk_rect_area(c, r, -5, 5, -5, c[1]) == Approx(0.5 * M_PI * r * r).epsilon(1e-14));
  CHECK(disk_rect_area(c, r, c[0], 5, c[1], 5) == Approx(0.25 * M_PI * r * r).epsilon(1e-14));
  CHECK(disk_rect_area(c, r, c[0] + r, 5, -5, 5) == 0.0);
  // A circular segment cut at distance t from the centre: r^2 acos(t/r) - t sqrt(r^2 - t^2).
  for (double t : {-0.6, -0.1, 0.0, 0.35, 0.69}) {
    const double seg = r * r * std::acos(t / r) - t * std::sqrt(r * r - t * t);
    CHECK(disk_rect_area(c, r, c[0] + t, 5, -5, 5) == Approx(seg).epsilon(1e-13));
    CHECK(disk_rect_area(c, r, -5, 5, c[1] + t, 5) == Approx(seg).epsilon(1e-13));
  }
  // A square inside the disk is its own area.
  CHECK(disk_rect_area(c, r, c[0] - 0.3, c[0] + 0.2, c[1] - 0.1, c[1] + 0.4) == Approx(0.5 * 0.5).epsilon(1e-13));
}

TEST_CASE("disk-rectangle area: the cells of any grid add up to the disk", "[hybrid]") {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0, 1);
  for (int trial = 0; trial < 20; ++trial) {
    const double c[2] = {u(rng), u(rng)}, r = 0.05 + 0.4 * u(rng), h = 0.03 + 0.2 * u(rng);
    double sum = 0;
    for (int i = -30; i < 40; ++i)
      for (int j = -30; j < 40; ++j) sum += disk_rect_area(c, r, i * h, (i + 1) * h, j * h, (j + 1) * h);
    CHECK(sum == Approx(M_PI * r * r).epsilon(1e-12));
  }
}

TEST_CASE("sphere-box volume: converges to the exact pieces of a sphere", "[hybrid]") {
  const double c[3] = {0.1, 0.2, 0.3}, r = 0.5;
  const double big_lo[3] = {-5, -5, -5}, big_hi[3] = {5, 5, 5};
  CHECK(sphere_box_volume(c, r, big_lo, big_hi) == Approx(4.0 / 3.0 * M_PI * r * r * r).epsilon(1e-12));
  // An octant: one eighth (kinks of the slice area at the box edges: none inside the range).
  const double oct_lo[3] = {c[0], c[1], c[2]};
  CHECK(sphere_box_volume(c, r, oct_lo, big_hi) == Approx(M_PI * r * r * r / 6.0).epsilon(1e-12));
  // A spherical cap of height k = r - t: pi k^2 (3r - k) / 3, cut across z (smooth integrand).
  const double t = 0.2, k = r - t;
  const double cap_lo[3] = {-5, -5, c[2] + t};
  CHECK(sphere_box_volume(c, r, cap_lo, big_hi) == Approx(M_PI * k * k * (3 * r - k) / 3.0).epsilon(1e-12));
  // A cap cut across x: the slice area has a square-root kink where the slice circle first
  // touches the plane; the error falls with nsub (measured: 5.6e-4 relative at nsub = 4,
  // 1.9e-5 at 16, 4.5e-7 at 64, that is ~ nsub^-2.6). Bounds: twice the measured value.
  const double capx_lo[3] = {c[0] + t, -5, -5};
  const double exact = M_PI * k * k * (3 * r - k) / 3.0;
  const double e4 = std::abs(sphere_box_volume(c, r, capx_lo, big_hi, 4) / exact - 1);
  const double e16 = std::abs(sphere_box_volume(c, r, capx_lo, big_hi, 16) / exact - 1);
  const double e64 = std::abs(sphere_box_volume(c, r, capx_lo, big_hi, 64) / exact - 1);
  INFO("relative errors " << e4 << " " << e16 << " " << e64);
  CHECK(e16 < 4e-5);
  CHECK(e64 < e16 / 10);
}

TEST_CASE("packing fraction: grain volume is conserved and a regular packing has its density", "[hybrid]") {
  // A hexagonal packing of touching disks: phi = pi / (2 sqrt 3) in the bulk.
  const double r = 0.01, dx = 2 * r, dy = std::sqrt(3.0) * r;
  std::vector<double> x, rad;
  for (int j = 0; j < 40; ++j)
    for (int i = 0; i < 35; ++i) {
      x.push_back(0.1 + i * dx + (j % 2) * r);
      x.push_back(0.1 + j * dy);
      rad.push_back(r);
    }
  CellGrid<2> G{{0, 0}, 0.05, {20, 20}};
  std::vector<double> phi = packing_fraction<2>(G, x, rad);
  double vol = 0;
  for (double p : phi) vol += p * G.h * G.h;
  CHECK(vol == Approx(rad.size() * M_PI * r * r).epsilon(1e-12));
  // Bulk cells (well inside the packing) average to the hexagonal density; a cell of
  // 0.05 m holds a few grains, so one cell deviates by the cut grains, the mean does not.
  double mean = 0;
  int cnt = 0;
  for (int j = 4; j < 10; ++j)
    for (int i = 4; i < 12; ++i) {
      const int c[2] = {i, j};
      mean += phi[(size_t)G.index(c)];
      ++cnt;
    }
  CHECK(mean / cnt == Approx(M_PI / (2 * std::sqrt(3.0))).epsilon(0.02));
  // 3D: random non-overlapping spheres inside the grid keep their total volume.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.2, 0.8);
  std::vector<double> x3, r3;
  for (int p = 0; p < 30; ++p) {
    for (int d = 0; d < 3; ++d) x3.push_back(u(rng));
    r3.push_back(0.04 + 0.03 * (p % 3));
  }
  CellGrid<3> G3{{0, 0, 0}, 0.1, {10, 10, 10}};
  std::vector<double> phi3 = packing_fraction<3>(G3, x3, r3, 32);
  double v3 = 0, exact3 = 0;
  for (double p : phi3) v3 += p * 1e-3;
  for (double rr : r3) exact3 += 4.0 / 3.0 * M_PI * rr * rr * rr;
  CHECK(v3 == Approx(exact3).epsilon(1e-6));
}

TEST_CASE("signed distance and zones: exact for a contour along cell faces", "[hybrid]") {
  // Dense (phi = 0.6) for x < 0.5, dilute (0.1) beyond; h = 0.05, 20 x 6 cells.
  CellGrid<2> G{{0, 0}, 0.05, {20, 6}};
  std::vector<double> phi((size_t)G.size());
  for (int j = 0; j < 6; ++j)
    for (int i = 0; i < 20; ++i) {
      const int c[2] = {i, j};
      phi[(size_t)G.index(c)] = i < 10 ? 0.6 : 0.1;
    }
  const double cap = 0.3;
  std::vector<double> s = signed_distance<2>(G, phi, 0.3, cap);
  for (int j = 0; j < 6; ++j)
    for (int i = 0; i < 20; ++i) {
      const int c[2] = {i, j};
      const double xc = (i + 0.5) * G.h, exact = std::max(-cap, std::min(cap, 0.5 - xc));
      CHECK(s[(size_t)G.index(c)] == Approx(exact).margin(1e-14));
    }
  ZoneRule z;
  z.band_distance = 0.1;
  z.half_width = 0.05;
  // s = 0.225 (cell 5): continuum; s = 0.125 and 0.075 (cells 7, 8): band; s = 0.025, < 0: discrete.
  const int c5[2] = {5, 0}, c7[2] = {7, 0}, c8[2] = {8, 0}, c9[2] = {9, 0}, c12[2] = {12, 0};
  CHECK(zone_of(s[(size_t)G.index(c5)], z) == Zone::Continuum);
  CHECK(zone_of(s[(size_t)G.index(c7)], z) == Zone::Band);
  CHECK(zone_of(s[(size_t)G.index(c8)], z) == Zone::Band);
  CHECK(zone_of(s[(size_t)G.index(c9)], z) == Zone::Discrete);
  CHECK(zone_of(s[(size_t)G.index(c12)], z) == Zone::Discrete);
  CHECK(continuum_weight(Zone::Band, z) + (1 - continuum_weight(Zone::Band, z)) == 1.0);
  CHECK(continuum_weight(Zone::Continuum, z) == 1.0);
  CHECK(continuum_weight(Zone::Discrete, z) == 0.0);
}

TEST_CASE("signed distance of a disk-shaped dense region: first order in h", "[hybrid]") {
  // The contour is a circle of radius R; at each centre within the cap the distance must be
  // R - |x - c| to O(h): the error at h/2 is about half the error at h.
  auto max_error = [](double h) {
    const int n = (int)std::lround(1.0 / h);
    CellGrid<2> G{{0, 0}, h, {n, n}};
    std::vector<double> phi((size_t)G.size());
    const double R = 0.3;
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const int c[2] = {i, j};
        phi[(size_t)G.index(c)] = std::hypot((i + 0.5) * h - 0.5, (j + 0.5) * h - 0.5) < R ? 1.0 : 0.0;
      }
    std::vector<double> s = signed_distance<2>(G, phi, 0.5, 0.15);
    double e = 0;
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const int c[2] = {i, j};
        const double exact = R - std::hypot((i + 0.5) * h - 0.5, (j + 0.5) * h - 0.5);
        if (std::abs(exact) < 0.1) e = std::max(e, std::abs(s[(size_t)G.index(c)] - exact));
      }
    return e;
  };
  const double e1 = max_error(0.02), e2 = max_error(0.01);
  INFO("max errors " << e1 << " " << e2);
  CHECK(e1 < 0.02);
  CHECK(e2 < 0.7 * e1);
}

// The search from the contour cells only against the plain definition: every cell's nearest
// centre of the other class within cap, by trying every cell (with periodic images).
template <int dim>
static double distance_vs_brute_force(const CellGrid<dim> &G, const std::vector<double> &phi, double thr, double cap) {
  const std::vector<double> s = signed_distance<dim>(G, phi, thr, cap);
  auto coords = [&G](long i, int c[3]) {
    for (int d = 0; d < dim; ++d) {
      c[d] = (int)(i % G.n[d]);
      i /= G.n[d];
    }
  };
  double worst = 0;
  for (long i = 0; i < G.size(); ++i) {
    int a[3] = {0, 0, 0}, b[3] = {0, 0, 0};
    coords(i, a);
    double best = cap;
    for (long j = 0; j < G.size(); ++j) {
      coords(j, b);
      if ((phi[(size_t)j] >= thr) == (phi[(size_t)i] >= thr)) continue;
      double d2 = 0;
      for (int d = 0; d < dim; ++d) {
        double o = std::abs(a[d] - b[d]);
        if (G.periodic[d]) o = std::min(o, G.n[d] - o);
        d2 += o * o;
      }
      // the search box is (ceil(cap/h) + 1) cells each way; beyond it the distance is capped anyway
      best = std::min(best, std::sqrt(d2) * G.h - 0.5 * G.h);
    }
    const double exact = phi[(size_t)i] >= thr ? best : -best;
    worst = std::max(worst, std::abs(s[(size_t)i] - exact));
  }
  return worst;
}

TEST_CASE("signed distance: the contour-cell search equals the brute-force nearest cell, 2D and 3D, periodic or not", "[hybrid]") {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  int runs = 0;
  for (int per = 0; per < 2; ++per)
    for (double fill : {0.1, 0.5, 0.9}) {
      CellGrid<2> G{{0, 0}, 0.01, {23, 17}};
      G.periodic[0] = per;
      std::vector<double> phi((size_t)G.size());
      for (double &p : phi) p = u(rng) < fill ? 0.6 : 0.1;
      for (double cap : {0.015, 0.04, 0.2}) {
        INFO("2D periodic " << per << " fill " << fill << " cap " << cap);
        CHECK(distance_vs_brute_force<2>(G, phi, 0.3, cap) < 1e-15);
        ++runs;
      }
      CellGrid<3> G3{{0, 0, 0}, 0.02, {9, 7, 6}};
      G3.periodic[2] = per;
      std::vector<double> phi3((size_t)G3.size());
      for (double &p : phi3) p = u(rng) < fill ? 0.6 : 0.1;
      INFO("3D periodic " << per << " fill " << fill);
      CHECK(distance_vs_brute_force<3>(G3, phi3, 0.3, 0.05) < 1e-15);
    }
  CHECK(runs == 18);
}

TEST_CASE("node constraint: equal velocities, momentum conserved to round-off", "[hybrid]") {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1, 1), m(1e-6, 1);
  for (int t = 0; t < 1000; ++t) {
    double mM = m(rng), mD = m(rng), pM[3] = {u(rng), u(rng), u(rng)}, pD[3] = {u(rng), u(rng), u(rng)}, lam[3];
    const double before[3] = {pM[0] + pD[0], pM[1] + pD[1], pM[2] + pD[2]};
    constrain_node<3>(mM, pM, mD, pD, lam);
    for (int d = 0; d < 3; ++d) {
      CHECK(pM[d] / mM == Approx(pD[d] / mD).epsilon(1e-12).margin(1e-12));
      CHECK(pM[d] + pD[d] == Approx(before[d]).epsilon(1e-15).margin(4e-16));
      CHECK(pM[d] / mM == Approx(before[d] / (mM + mD)).epsilon(1e-12).margin(1e-12));
    }
  }
  // Only one phase at the node: nothing to constrain.
  double pM[2] = {1, 2}, pD[2] = {0, 0}, lam[2];
  constrain_node<2>(1.0, pM, 0.0, pD, lam);
  CHECK(pM[0] == 1.0);
  CHECK(pM[1] == 2.0);
  CHECK(lam[0] == 0.0);
}

TEST_CASE("fixed band: zones and mass shares on either side of the slab", "[hybrid]") {
  FixedBand b;
  b.axis = 1;
  b.lo = 0.2;
  b.hi = 0.3;
  b.band_weight = 0.25;
  const double above[2] = {5, 0.31}, in[2] = {5, 0.25}, edge[2] = {5, 0.2}, below[2] = {5, 0.19};
  CHECK(b.zone(above) == Zone::Continuum);
  CHECK(b.zone(in) == Zone::Band);
  CHECK(b.zone(edge) == Zone::Band);
  CHECK(b.zone(below) == Zone::Discrete);
  CHECK(b.continuum_weight(above) == 1.0);
  CHECK(b.continuum_weight(in) == 0.25);
  CHECK(b.continuum_weight(below) == 0.0);
  b.continuum_hi = false; // the continuum below the band
  CHECK(b.zone(above) == Zone::Discrete);
  CHECK(b.zone(below) == Zone::Continuum);
}

// The tent weights the grains are rasterised with: a partition of unity that reproduces
// the position (first moments), so mass and momentum land on the grain's cell exactly.
TEST_CASE("tent weights: partition of unity and exact first moments", "[hybrid]") {
  std::mt19937_64 gen(7);
  std::uniform_real_distribution<double> U(-1.0, 3.0);
  const double x0[3] = {-0.05, 0.1, -0.3}, h = 0.025;
  for (int t = 0; t < 200; ++t) {
    const double x[3] = {U(gen), U(gen), U(gen)};
    int b[3];
    double w[3][2];
    tent<3>(x, x0, 1.0 / h, b, w);
    double sum = 0, mom[3] = {0, 0, 0};
    for (int c = 0; c < 8; ++c) {
      const int o[3] = {c & 1, (c >> 1) & 1, (c >> 2) & 1};
      const double wt = w[0][o[0]] * w[1][o[1]] * w[2][o[2]];
      CHECK(wt >= 0);
      sum += wt;
      for (int d = 0; d < 3; ++d) mom[d] += wt * (x0[d] + (b[d] + o[d]) * h);
    }
    CHECK(sum == Approx(1.0).epsilon(1e-14));
    for (int d = 0; d < 3; ++d) CHECK(mom[d] == Approx(x[d]).margin(1e-13));
  }
}

TEST_CASE("oracle zones: material points are dense, grains by their phi, band by the distance", "[hybrid]") {
  // 12 x 10 cells of h = 1. Rows 0-2: a square packing of disks of radius h/2 centred in
  // their cells (phi = pi/4 exactly in each); rows 3-5: one small disk per cell (phi 0.03);
  // rows 6-9: material points (phi = 1). Threshold 0.3: rows 0-2 and 6-9 are dense, the
  // contours lie along the faces y = 3 and y = 6.
  CellGrid<2> G;
  G.lo[0] = G.lo[1] = 0;
  G.h = 1;
  G.n[0] = 12;
  G.n[1] = 10;
  std::vector<double> x, r, dense((size_t)G.size(), 0.0);
  for (int j = 0; j < 6; ++j)
    for (int i = 0; i < 12; ++i) {
      x.push_back(i + 0.5);
      x.push_back(j + 0.5);
      r.push_back(j < 3 ? 0.5 : 0.1);
    }
  for (int j = 6; j < 10; ++j)
    for (int i = 0; i < 12; ++i) {
      const double p[2] = {i + 0.3, j + 0.7};
      dense[(size_t)cell_index<2>(G, p)] = 1;
    }
  const std::vector<double> phi = packing_fraction<2>(G, x, r);
  CHECK(phi[(size_t)(1 * 12 + 4)] == Approx(M_PI / 4).epsilon(1e-14));
  CHECK(phi[(size_t)(4 * 12 + 4)] == Approx(M_PI * 0.01).epsilon(1e-13));
  // Band centred 1.5 cells inside the dense region, half-width 0.5: cell centres at
  // distance 0.5, 1.5, 2.5 ... from a face; s = 1.5 is the band, s = 0.5 discrete, s >= 2.5
  // continuum; the dilute rows (s < 0) are discrete.
  ZoneRule rule;
  rule.band_distance = 1.5;
  rule.half_width = 0.5;
  const std::vector<Zone> z = oracle_zones<2>(G, phi, dense, 0.3, rule);
  // Row 0 lies on the grid's edge, not a contour: 2.5 from the face y = 3, continuum.
  const Zone want[10] = {Zone::Continuum, Zone::Band, Zone::Discrete, Zone::Discrete, Zone::Discrete, Zone::Discrete,
                         Zone::Discrete, Zone::Band, Zone::Continuum, Zone::Continuum};
  for (int j = 0; j < 10; ++j)
    for (int i = 0; i < 12; ++i) {
      INFO("cell " << i << ", " << j);
      CHECK((int)z[(size_t)(j * 12 + i)] == (int)want[j]);
    }
  // A lower threshold makes the sparse rows dense too: one dense slab, no contour inside.
  const std::vector<Zone> all = oracle_zones<2>(G, phi, dense, 0.02, rule);
  for (Zone q : all) CHECK(q == Zone::Continuum);
}

TEST_CASE("periodic faces: grains across a face keep their volume, distances wrap", "[hybrid]") {
  // The same dense strip (x < 0.5 of a 1 m box, h = 0.05) with x periodic: the contour is at
  // x = 0.5 and, through the face, at x = 0 (= 1), so the distance is to the nearer of them.
  CellGrid<2> G{{0, 0}, 0.05, {20, 6}};
  G.periodic[0] = true;
  std::vector<double> phi((size_t)G.size());
  for (int j = 0; j < 6; ++j)
    for (int i = 0; i < 20; ++i) {
      const int c[2] = {i, j};
      phi[(size_t)G.index(c)] = i < 10 ? 0.6 : 0.1;
    }
  const double cap = 0.3;
  std::vector<double> s = signed_distance<2>(G, phi, 0.3, cap);
  for (int j = 0; j < 6; ++j)
    for (int i = 0; i < 20; ++i) {
      const int c[2] = {i, j};
      const double xc = (i + 0.5) * G.h, exact = i < 10 ? std::min(0.5 - xc, xc) : -std::min(xc - 0.5, 1.0 - xc);
      CHECK(s[(size_t)G.index(c)] == Approx(std::max(-cap, std::min(cap, exact))).margin(1e-14));
    }
  // A disk centred on the periodic face: its whole area lands in the cells on both sides
  // (without the wrap only the half inside the box would).
  const std::vector<double> x = {0.002, 0.13}, r = {0.03};
  const std::vector<double> pw = packing_fraction<2>(G, x, r);
  G.periodic[0] = false;
  const std::vector<double> pn = packing_fraction<2>(G, x, r);
  double aw = 0, an = 0;
  for (size_t c = 0; c < pw.size(); ++c) {
    aw += pw[c] * G.h * G.h;
    an += pn[c] * G.h * G.h;
  }
  CHECK(aw == Approx(M_PI * 0.03 * 0.03).epsilon(1e-13));
  CHECK(an < 0.6 * M_PI * 0.03 * 0.03);
  const int last[2] = {19, 2};
  CHECK(pw[(size_t)G.index(last)] > 0); // the part across the face
}

// Enrichment of one cell: grains that take the cell's mass without overlapping each other or
// the grains already near it. References: the grains' mass against M (n m(r) = M to
// round-off, or the part n m(r0)), pairwise distances against the sum of radii, and the
// cell's bounds, on the collapse's numbers (h = 1 cm, r0 = 2 mm, 2D; 3D h = 1 cm, r0 = 2.5 mm);
// the counts are worked by hand in the comments.
template <int dim>
static void check_plan(const CellGrid<dim> &G, const int ci[dim], double M, double r0, double rho, double tol, const std::vector<double> &xe,
                       const std::vector<double> &re, const EnrichPlan &plan, bool want_partial) {
  const double unit = dim == 3 ? 4.0 / 3.0 * M_PI : M_PI;
  const long n = (long)plan.x.size() / dim;
  REQUIRE(n > 0);
  REQUIRE(plan.partial == want_partial);
  const double mg = rho * unit * std::pow(plan.r, dim);
  if (!plan.partial)
    REQUIRE(std::fabs(n * mg - M) <= 1e-14 * M);
  else {
    REQUIRE(plan.r == r0);
    REQUIRE(n * mg <= M * (1 + 1e-14));
  }
  REQUIRE(2 * plan.r <= G.h);
  for (long a = 0; a < n; ++a) {
    for (int d = 0; d < dim; ++d) { // inside the cell, and at least r (1 - tol/2) from its faces
      const double lo = G.lo[d] + ci[d] * G.h, hi = lo + G.h, xa = plan.x[(size_t)(a * dim + d)];
      REQUIRE(xa - lo >= plan.r * (1 - tol / 2) - 1e-15);
      REQUIRE(hi - xa >= plan.r * (1 - tol / 2) - 1e-15);
    }
    for (long b = a + 1; b < n; ++b) {
      double d2 = 0;
      for (int d = 0; d < dim; ++d) d2 += std::pow(plan.x[(size_t)(a * dim + d)] - plan.x[(size_t)(b * dim + d)], 2);
      REQUIRE((2 * plan.r - std::sqrt(d2)) / plan.r <= tol + 1e-12);
    }
    for (size_t e = 0; e < re.size(); ++e) {
      double d2 = 0;
      for (int d = 0; d < dim; ++d) d2 += std::pow(plan.x[(size_t)(a * dim + d)] - xe[e * dim + d], 2);
      REQUIRE((plan.r + re[e] - std::sqrt(d2)) / std::min(plan.r, re[e]) <= tol + 1e-12);
    }
  }
}

TEST_CASE("enrichment of a cell: grains take its mass, clear of each other and of the grains near it", "[hybrid]") {
  const double rho = 2500, tol = 0.05;
  {
    CellGrid<2> G{{0, 0}, 0.01, {10, 10}};
    const int ci[2] = {3, 4};
    const double r0 = 0.002, full = 2050 * G.h * G.h; // a cell of the collapse's points (phi 0.82)
    // Alone: floor(M / m(r0)) = 6 grains do not fit a 3x3 lattice (2 r > h / 3); 4 of 2.55 mm fit the 2x2 one.
    const EnrichPlan a = enrich_cell<2>(G, ci, full, r0, 0.0016, rho, tol, {}, {});
    check_plan<2>(G, ci, full, r0, rho, tol, {}, {}, a, false);
    REQUIRE(a.x.size() == 8);
    // Half full: 3 grains of r(3) on the 2x2 lattice (one site spare), then a grain of the
    // neighbour cell reaching in over a corner site takes that site.
    const EnrichPlan b = enrich_cell<2>(G, ci, 0.5 * full, r0, 0.0016, rho, tol, {}, {});
    check_plan<2>(G, ci, 0.5 * full, r0, rho, tol, {}, {}, b, false);
    REQUIRE(b.x.size() == 6);
    const std::vector<double> xe = {0.0298, 0.0398}, re = {0.0022}; // near the cell's lower left corner (0.03, 0.04)
    const EnrichPlan c = enrich_cell<2>(G, ci, 0.5 * full, r0, 0.0016, rho, tol, xe, re);
    check_plan<2>(G, ci, 0.5 * full, r0, rho, tol, xe, re, c, false);
    REQUIRE(c.x.size() == 6);
    REQUIRE(c.x[0] > 0.0325); // the corner site is not used
    // Full, with that grain: no count of one radius takes all of M; the mean radius takes part.
    const EnrichPlan d = enrich_cell<2>(G, ci, full, r0, 0.0016, rho, tol, xe, re);
    check_plan<2>(G, ci, full, r0, rho, tol, xe, re, d, true);
    REQUIRE(d.x.size() == 6); // 3 of the 4 sites
    // Grains in the middle of the cell: no site clear; too little mass for a grain the DEM's
    // step allows: nothing.
    REQUIRE(enrich_cell<2>(G, ci, full, r0, 0.0016, rho, tol, {0.035, 0.045}, {0.0045}).x.empty());
    REQUIRE(enrich_cell<2>(G, ci, 0.01 * full, r0, 0.0016, rho, tol, {}, {}).x.empty());
    // Through a periodic face: a grain just past the upper x face reaches the cell at the lower one.
    CellGrid<2> P{{0, 0}, 0.01, {10, 10}, {true, false}};
    const int c0[2] = {0, 4};
    const std::vector<double> xp = {0.0995, 0.0405}, rp = {0.0022};
    const EnrichPlan e = enrich_cell<2>(P, c0, 0.5 * full, r0, 0.0016, rho, tol, xp, rp);
    std::vector<double> xw = {-0.0005, 0.0405}; // its image
    check_plan<2>(P, c0, 0.5 * full, r0, rho, tol, xw, rp, e, false);
    REQUIRE(e.x[0] > 0.0025);
  }
  {
    CellGrid<3> G{{0, 0, 0}, 0.01, {4, 4, 4}};
    const int ci[3] = {1, 2, 1};
    const double r0 = 0.0025, full = 0.48 * rho * 1e-6; // 7 grains of 2.54 mm on the 2x2x2 lattice
    const std::vector<double> xe = {0.015, 0.0295, 0.0195}, re = {0.0028}; // over two of the 8 sites: 6 of r0 take part
    for (int k = 0; k < 2; ++k) {
      const EnrichPlan a = enrich_cell<3>(G, ci, full, r0, 0.002, rho, tol, k ? xe : std::vector<double>{}, k ? re : std::vector<double>{});
      check_plan<3>(G, ci, full, r0, rho, tol, k ? xe : std::vector<double>{}, k ? re : std::vector<double>{}, a, k == 1);
    }
  }
}
