// balanced_ranges: contiguous cuts of a weighted node line into equal shares.
#include <catch2/catch.hpp>

#include <numeric>

#include "granmpm/grid.hpp"

using granmpm::balanced_ranges;

namespace {
// Largest share of the total weight over the ranges l.
double max_share(const std::vector<double> &w, const std::vector<PetscInt> &l) {
  double mx = 0, total = std::accumulate(w.begin(), w.end(), 0.0);
  size_t i = 0;
  for (PetscInt n : l) {
    double s = 0;
    for (PetscInt k = 0; k < n; ++k) s += w[i++];
    mx = std::max(mx, s / total);
  }
  return mx;
}
} // namespace

TEST_CASE("balanced_ranges splits uniform weights into equal blocks", "[balance]") {
  const std::vector<double> w(12, 1.0);
  REQUIRE(balanced_ranges(w, 3, 2) == std::vector<PetscInt>{4, 4, 4});
  REQUIRE(balanced_ranges(w, 4, 2) == std::vector<PetscInt>{3, 3, 3, 3});
  // No weight at all: equal blocks too.
  REQUIRE(balanced_ranges(std::vector<double>(10, 0.0), 2, 2) == std::vector<PetscInt>{5, 5});
}

TEST_CASE("balanced_ranges follows a cluster and keeps the minimum width", "[balance]") {
  // 20 nodes, all weight on nodes 2..7 (6 units): 2 ranks cut at node 5.
  std::vector<double> w(20, 0.0);
  for (int i = 2; i < 8; ++i) w[i] = 1;
  const auto l2 = balanced_ranges(w, 2, 2);
  REQUIRE(l2 == std::vector<PetscInt>{5, 15});
  REQUIRE(max_share(w, l2) == 0.5);
  // 3 ranks: cuts at 4 and 6 (2 units each).
  REQUIRE(balanced_ranges(w, 3, 2) == std::vector<PetscInt>{4, 2, 14});
  // All weight on one node: cuts are pushed apart to the minimum width of 2 nodes.
  std::vector<double> spike(10, 0.0);
  spike[5] = 1;
  const auto ls = balanced_ranges(spike, 4, 2);
  for (PetscInt n : ls) REQUIRE(n >= 2);
  REQUIRE(std::accumulate(ls.begin(), ls.end(), (PetscInt)0) == 10);
}

TEST_CASE("balanced_ranges with 2 parts is the best single cut", "[balance]") {
  // The cut whose cumulative weight is closest to half minimises the larger share:
  // compare with trying every cut on a skewed profile.
  std::vector<double> w(30);
  for (int i = 0; i < 30; ++i) w[i] = (i * 7919) % 13 + (i < 10 ? 20 : 0);
  const auto l = balanced_ranges(w, 2, 2);
  double best = 1e300;
  for (PetscInt a = 2; a <= 28; ++a) best = std::min(best, max_share(w, {a, 30 - a}));
  REQUIRE(max_share(w, l) == best);
}
