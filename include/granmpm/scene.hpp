// Scenes: the initial state of the particles and the diagnostics each scene computes
// against its reference (analytic or GranMPM-computed), written as CSV to -output_dir.
//
//   block  : a box of material with uniform velocity -velocity, rotation -spin and
//            isotropic pressure -p0 (parallel and conservation tests)
//   bar    : axial vibration of an elastic bar fixed at x = domain_lo, first mode; velocity
//            and energy against the analytic solution (bar.csv)
//   column : elastic column settling under gravity; sigma_yy against -rho g (H - y)
//            (column.csv)
//   chute  : vertical chute of seed 000; vy(x) against the local analytic and nonlocal
//            1D references (profile.csv)
//   annulus: 2D annular shear between a rotating inner disk and a fixed outer ring (rigid
//            bodies), no gravity, isotropic pressure -p0; v_theta(r) against the local and
//            nonlocal 1D references of annulus_reference.hpp (profile.csv). In 3D:
//            Taylor-Couette cell (cylinders along z, gravity along -z, free top surface):
//            omega(r)/Omega in the top layer of particles (profile.csv), no reference.
//            Every scene accepts every -material; where a scene's reference does not apply
//            to it (chute: elastic, hypoelastic, Drucker-Prager; 2D annulus: those and the
//            dynamical model) the run says so in one line and writes the profile alone.
#pragma once

#include <array>
#include <map>
#include <string>
#include <vector>

#include "granmpm/state.hpp"

namespace granmpm {

// The rigid bodies of a run: the annulus scene's inner disk and outer ring, or the
// -body<k>_ options. names[k] says how messages name body k.
std::vector<BodySpec> scene_bodies(const Config &cfg, std::vector<std::string> &names);

// Whether the granular references of the chute and annulus scenes (mu(I), steady nonlocal,
// dynamical steady state) can apply to the run's material; the scenes accept every
// material and skip their reference with a one-line note where it does not apply.
bool scene_has_reference(const Config &cfg);

template <int dim>
class Scene {
public:
  explicit Scene(State<dim> &sim);
  // Sets velocity and stress of freshly seeded particles.
  static void initialize(State<dim> &sim);
  void on_step(State<dim> &sim);
  void finalize(State<dim> &sim);
  // Numbers a scene measured (errors, energies), printed at the end and read by tests.
  std::map<std::string, double> metrics;
  // Particle initial (lattice) position from its id.
  static void lattice_position(const Config &cfg, const Grid<dim> &grid, int64_t id, double *X);

private:
  long sample_every_ = 1;
  std::vector<std::array<double, 8>> series_;
  void bar_sample(State<dim> &sim);
  void bar_finalize(State<dim> &sim);
  void column_finalize(State<dim> &sim);
  void chute_finalize(State<dim> &sim);
  void collapse_finalize(State<dim> &sim);
  void silo_finalize(State<dim> &sim);
  void annulus_finalize(State<dim> &sim);
  void taylor_couette_finalize(State<dim> &sim);
  std::vector<std::array<double, 3>> silo_; // t, discharged mass, discharged particles
};

} // namespace granmpm
