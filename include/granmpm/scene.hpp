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
//
// A scene is one class template deriving from SceneCase<dim>. A built-in scene is its own
// file src/scenes/<name>.cpp ending with GM_SCENE(<name>, <Class>) and ONE line X(<name>)
// in GM_SCENES (src/scene.cpp): its position there is its SceneKind value. A scene defined
// outside the library (a test's) is added with ONE line,
// `const SceneKind kMine = register_scene<Mine>("mine");`. -scene's parsing, -help and
// messages read the names from the registry (scene_registry()).
//
// A scene's own options (-spin, -silo_orifice, ...) are declared by the scene (options():
// name, help, default, range); Config::from_options registers them under the heading
// "Scene <name>" of -help and stores the values given in Config::scene_params; the scene
// reads them with Config::scene_param("-option"), which falls back to the default. So a
// scene with options touches only its file and its GM_SCENES line.
#pragma once

#include <array>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "granmpm/config_checks.hpp"
#include "granmpm/materials/model.hpp"
#include "granmpm/module.hpp"
#include "granmpm/state.hpp"

namespace granmpm {

using Metrics = std::map<std::string, double>;
using Signature = std::vector<std::pair<std::string, std::string>>; // "-option", value

// One of a scene's own options: name, -help text, default and range as a model's
// parameter (ParamDecl, materials/model.hpp; a value outside the range stops the run with
// "<option> must be <range> (got v)"); flag: a boolean option, stored as 0 or 1.
struct SceneOption : ParamDecl {
  bool flag = false;
};

// A scene's part that does not depend on the dimension: its options, its rules on them and
// its rigid bodies. Every hook has a default, so a scene overrides what it needs.
class SceneRules {
public:
  virtual ~SceneRules() = default;
  // Its own options (read for every run, whatever the scene, so that -help lists them all).
  virtual const std::vector<SceneOption> &options() const;
  // Its own rules (Config::validate, after its options' ranges): a one-line error naming
  // the option to change.
  virtual void validate(const Config &) const {}
  // Its physics findings (physics_checks, config_checks.hpp): errors refuse the run,
  // warnings are printed and the run goes on.
  virtual void checks(const Config &, std::vector<Finding> &) const {}
  // Its own options in the restart signature (Config::signature); default: every option
  // of options() at full precision (flags as true/false).
  virtual void signature(const Config &, Signature &) const;
  // The ranges of options() (called by Config::validate before validate()).
  void validate_options(const Config &) const;
  // The rigid bodies of the run (default: the -body<k>_ options); names[k] says how
  // messages name body k.
  virtual std::vector<BodySpec> bodies(const Config &c, std::vector<std::string> &names) const;
};

// What a scene does, at the points of the run where the solver calls it.
template <int dim>
class SceneCase : public SceneRules {
public:
  // Velocity v and stress s (both zero on entry) of a freshly seeded particle at x; centre
  // is the centre of the material box clipped to the domain. (-geostatic is added after.)
  virtual void init_particle(const Config &, const double *centre, const double *x, double *v, double *s) const {
    (void)centre, (void)x, (void)v, (void)s;
  }
  // Modules the scene needs (the silo's plate), added once at set-up.
  virtual void add_modules(State<dim> &, std::vector<std::unique_ptr<Module<dim>>> &) const {}
  // After every step (time series).
  virtual void on_step(State<dim> &) {}
  // At the end of the run: diagnostics against the scene's reference, CSV files, metrics.
  virtual void finalize(State<dim> &, Metrics &) {}
};

struct SceneEntry {
  const char *name; // a literal: to_string(SceneKind) returns it
  std::unique_ptr<SceneCase<2>> (*make2)();
  std::unique_ptr<SceneCase<3>> (*make3)();
};

// The registered scenes; the index is the SceneKind value.
const std::vector<SceneEntry> &scene_registry();
const SceneEntry &scene_entry(SceneKind k);
const SceneRules &scene_rules(SceneKind k); // (the 2D form of the scene, made once)
template <int dim>
std::unique_ptr<SceneCase<dim>> make_scene(SceneKind k);

template <template <int> class S>
SceneEntry scene_entry_of(const char *name) {
  return {name, [] { return std::unique_ptr<SceneCase<2>>(new S<2>); }, [] { return std::unique_ptr<SceneCase<3>>(new S<3>); }};
}
SceneKind add_scene(SceneEntry e);
template <template <int> class S>
SceneKind register_scene(const char *name) {
  return add_scene(scene_entry_of<S>(name));
}
// Ends a scene's file: defines the entry that GM_SCENES lists.
#define GM_SCENE(name, Class)                                                                                                                        \
  SceneEntry scene_entry_##name() { return scene_entry_of<Class>(#name); }

// Inside Config::from_options' options block: every registered scene's options, each
// scene's under its heading; the values given go to c.scene_params. failed: the option
// PETSc could not parse; notes: the first non-finite value.
PetscErrorCode read_scene_options(PetscOptionItems *PetscOptionsObject, Config &c, const char *&failed, std::string &notes);

// The rigid bodies of a run: the scene's (the annulus scene's inner disk and outer ring) or
// the -body<k>_ options. names[k] says how messages name body k.
std::vector<BodySpec> scene_bodies(const Config &cfg, std::vector<std::string> &names);
bool scene_has_bodies(const Config &cfg);

// Whether the granular references of the chute and annulus scenes (mu(I), steady nonlocal,
// dynamical steady state) can apply to the run's material; the scenes accept every
// material and skip their reference with a one-line note where it does not apply.
bool scene_has_reference(const Config &cfg);

// The run's scene: made from the registry for cfg.scene.
template <int dim>
class Scene {
public:
  explicit Scene(State<dim> &sim);
  // Sets velocity and stress of freshly seeded particles.
  static void initialize(State<dim> &sim);
  void on_step(State<dim> &sim) { case_->on_step(sim); }
  void finalize(State<dim> &sim) { case_->finalize(sim, metrics); }
  // Numbers a scene measured (errors, energies), printed at the end and read by tests.
  Metrics metrics;
  // Particle initial (lattice) position from its id.
  static void lattice_position(const Config &cfg, const Grid<dim> &grid, int64_t id, double *X);

private:
  std::unique_ptr<SceneCase<dim>> case_;
};

} // namespace granmpm
