// Comparison of gathered grain records shared by the DEM body tests.
#pragma once
#include <algorithm>
#include <cmath>
#include <vector>

#include "granmpm/dem/dem.hpp"

namespace gmtest {
// Largest absolute difference of positions, velocities and spins; -1 if counts or ids differ.
inline double grain_diff(const std::vector<granmpm::dem::GrainRecord> &a, const std::vector<granmpm::dem::GrainRecord> &b) {
  if (a.size() != b.size()) return -1;
  double e = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].id != b[i].id) return -1;
    for (int k = 0; k < 3; ++k) e = std::max({e, std::fabs(a[i].x[k] - b[i].x[k]), std::fabs(a[i].v[k] - b[i].v[k]), std::fabs(a[i].w[k] - b[i].w[k])});
  }
  return e;
}
} // namespace gmtest
