// Sobel edge detector of the hybrid density rule.
#include <catch2/catch.hpp>

#include "granmpm/density.hpp"

using namespace granmpm;

TEST_CASE("Sobel magnitude: zero on uniform fields, 4 per unit step across an edge", "[density]") {
  double full[27], step2[27], step3[27];
  for (int q = 0; q < 27; ++q) {
    full[q] = 1.0;
    const int i = q % 3;
    step2[q] = i == 0 ? 1.0 : (i == 1 ? 1.0 : 0.0); // filled | filled | empty along x
    step3[q] = step2[q];
  }
  REQUIRE(sobel_magnitude(2, full) == 0.0);
  REQUIRE(sobel_magnitude(3, full) == 0.0);
  REQUIRE(sobel_magnitude(2, step2) == Approx(4.0)); // (1 + 2 + 1) * 1
  REQUIRE(sobel_magnitude(3, step3) == Approx(16.0)); // (1+2+1)^2 in 3D
  // A linear ramp along y, 2 per cell: central difference 4, times the smoothing weight 4.
  double ramp[27];
  for (int q = 0; q < 27; ++q) ramp[q] = 2.0 * ((q / 3) % 3);
  REQUIRE(sobel_magnitude(2, ramp) == Approx(16.0));
}
