// Checks of a Config that need more than one option at a time: physical consistency of
// the parameters the models combine, the placement of the material, the rank layout and
// the memory a run needs. Pure functions on Config (unit-tested in
// tests/unit/test_config_checks.cpp); Config::from_options calls them after validate(),
// so that configurations built in code by tests are not second-guessed.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "granmpm/config.hpp"

namespace granmpm {

// One finding: an error (the run is refused) or a warning (printed, the run goes on).
struct Finding {
  bool error = false;
  std::string msg;
};

// Physics and placement: chute confinement, densities, moduli against the time step and
// the range of doubles, grain size against cell and domain, silo orifice against the
// grid, the material box (-body_lo/-body_hi) against the domain and the particle spacing.
std::vector<Finding> physics_checks(const Config &c);

// Shared by the scenes' own checks (SceneRules::checks, scene.hpp): the elastic P-wave
// speed sqrt(M/rho); a prescribed speed s (option opt) at or beyond the speed of light is
// refused; -p0 against the bulk modulus (scenes that start from an isotropic pressure).
double wave_speed(const Config &c);
void check_speed(std::vector<Finding> &out, const std::string &opt, double s);
void check_initial_pressure(const Config &c, std::vector<Finding> &out);

// Particle lattice of the material box along direction d: positions lo + (i + 1/2) h/ppc
// as Particles::seed computes them. in_domain: lattice points inside the domain and the
// box; outside: points of the box's lattice that lie outside the domain (0 when the box
// is unbounded there, i.e. left at its default).
struct LatticeCount {
  double in_domain = 0, outside = 0;
};
LatticeCount lattice_count(const Config &c, int d);
// Particles the material box would hold (product over directions; rigid bodies and
// scene-specific cut-outs ignored: an upper bound), and those clipped off by the domain.
double seeded_particles_bound(const Config &c);
double clipped_particles(const Config &c);

// -da_processors_x/y/z against the number of ranks: "" when consistent, else the cause.
std::string check_procs(const Config &c, int nranks);

// Memory a run needs, from the bytes counted per grid node and per particle of the data
// structures GranMPM allocates (grid vectors, particle fields, solver vectors/matrices).
struct MemoryEstimate {
  double nodes = 0, particles = 0;                           // counts
  double grid_bytes = 0, particle_bytes = 0, solver_bytes = 0; // totals over all ranks
  double total() const { return grid_bytes + particle_bytes + solver_bytes; }
};
MemoryEstimate estimate_memory(const Config &c);
// "" if the estimate fits in `available` bytes, else the one-line refusal; `where`
// describes what `available` is (e.g. "MemAvailable summed over 1 node").
std::string check_memory(const MemoryEstimate &m, double available, const std::string &where);

// A real option's text as given ("1e8", "inf,0", "nan"): the index of the first
// component that parses to a non-finite number, or -1. Components that do not parse as
// numbers are left to PETSc's parser.
int nonfinite_component(const std::string &text);
// An integer option's text: the index of the first component that is an integer beyond
// [-max - 1, max] (PETSc would wrap it silently: 4294967297 -> 1), or -1.
int int_overflow_component(const std::string &text, long long max);

} // namespace granmpm
