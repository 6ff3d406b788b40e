// Helpers the scene files share (internal to src/scenes/).
#pragma once

#include <algorithm>
#include <cstdio>
#include <limits>
#include <string>

#include "granmpm/materials/moduli.hpp"
#include "granmpm/output.hpp"
#include "granmpm/scene.hpp"
#include "../options_util.hpp"

namespace granmpm::scene_util {

using opt::bad;
using opt::exact;
using opt::fmt;

constexpr double kPi = 3.14159265358979323846;
constexpr double kInf = std::numeric_limits<double>::infinity();

// Strain energy density sigma : C^-1 : sigma / 2 for isotropic elasticity.
inline double strain_energy_density(const ElasticModuli &el, const double *s6) {
  const double p = pressure6(s6), tau = tau6(s6);
  // dev:dev = 2 tau^2 ; tr^2 = 9 p^2
  return 0.5 * (2.0 * tau * tau / (2.0 * el.G) + 9.0 * p * p / (9.0 * el.K));
}

// CSV results are written under a temporary name and published by close_atomic (fsync,
// rename), so that a failed write never leaves a partial file (output.hpp).
inline std::FILE *open_csv(const std::string &dir, const std::string &name) { return open_atomic(dir + "/" + name); }

// The largest extent of the domain (a rotation rate times it is a speed).
inline double domain_size(const Config &c) {
  double size = 0;
  for (int d = 0; d < c.dim; ++d) size = std::max(size, c.hi[d] - c.lo[d]);
  return size;
}

} // namespace granmpm::scene_util
