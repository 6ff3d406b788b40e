// State<dim>: what every part of a run reads. The grid, the particles, the material and
// shape function (chosen once), the clock, the rigid bodies' description, the output
// record and the list of modules. Scene, Output and Checkpoint read a State (never the
// Simulation that steps it); modules (module.hpp) get it in each of their hooks.
//
// Ownership: the State owns its members; a module owns its own solver objects (built on
// grid's DMDA) and rebuilds them after a repartition. Members are declared so that the
// modules are destroyed first, the particles before the grid.
#pragma once

#include <memory>
#include <string>
#include <variant>
#include <vector>

#include "granmpm/config.hpp"
#include "granmpm/grid.hpp"
#include "granmpm/material.hpp"
#include "granmpm/materials/drucker_prager.hpp"
#include "granmpm/materials/dynamic_ngf.hpp"
#include "granmpm/materials/elastic.hpp"
#include "granmpm/materials/local_mu_i.hpp"
#include "granmpm/materials/nonlocal_ngf.hpp"
#include "granmpm/particles.hpp"
#include "granmpm/rigid_body.hpp"
#include "granmpm/shape.hpp"

namespace granmpm {

template <int dim>
class Output;
struct NodeAt;
template <int dim>
class Module;

using Shape = std::variant<LinearShape, GIMPShape, BSpline2Shape>;
// The PETSc log stages of a step (-log_view), registered once per process.
enum class LogStage { Migrate, P2G, GridUpdate, G2P, Constitutive, Fluidity, Output };
PetscLogStage log_stage(LogStage s);

// Grid ownership ranges: nodes per rank, per direction.
using Ranges = std::vector<std::vector<PetscInt>>;

// One particle's state, gathered for comparisons and diagnostics.
// Ids of material points made from DEM grains (hybrid homogenisation): this + the grain's id,
// apart from the seeding lattice's ids 0 .. prod(cells * ppc) - 1.
inline constexpr int64_t kConvertedParticleIds = int64_t(1) << 40;

struct ParticleRecord {
  int64_t id;
  double x[3], v[3], s[6], m, vol, g;
};

struct Totals {
  long n = 0;
  double mass = 0, momentum[3] = {0, 0, 0}, kinetic = 0, vmax = 0;
};

template <int dim>
struct State {
  State(MPI_Comm comm, const Config &cfg);
  ~State();
  State(const State &) = delete;
  State &operator=(const State &) = delete;

  const Config cfg;
  MPI_Comm comm;
  int rank = 0, size = 1;
  double time = 0;
  long nsteps = 0;
  double wave_speed = 0;          // elastic P-wave speed
  double vmax = 0;                // max particle speed after the last step
  double plastic_limit = 1e300;   // explicit stress updates only (Simulation::dt_limit)
  // What the energy guard allows: initial kinetic + elastic energy + gravity's work,
  // raised by modules that supply energy (rigid bodies' work).
  double energy_bound = 0;
  Grid<dim> grid;
  Particles<dim> particles;
  // The material model (material.hpp), made once at set-up from -material.
  std::unique_ptr<MaterialModel<dim>> material;
  Shape shape;
  // Rigid bodies (-body<k>_*, or the annulus scene's two); null without bodies. Their
  // coupling to the grid is the BodyModule's; their description is read by the output,
  // the scenes and the fluidity solver's body condition.
  std::unique_ptr<RigidBodies<dim>> bodies;
  std::vector<std::string> body_names; // how messages name body k (its options)
  long body_corrections = 0; // particles put back onto a body surface they entered by < 1 cell
  std::unique_ptr<Output<dim>> output;
  // The modules of this run, chosen once in Simulation::setup from the scene, called in
  // this order at each hook. Last member: destroyed before the grid their objects use.
  std::vector<std::unique_ptr<Module<dim>>> modules;
  // The modules with a node pass / a velocity constraint (Simulation::setup fills them).
  std::vector<Module<dim> *> node_modules, constraint_modules;
  // The velocity constraints of the modules on node n (before the walls' Grid::apply_bc).
  void constrain(const NodeAt &n, double *v) const;

  // The module of type M, or null (a scene or test asks for what it reads).
  template <class M>
  M *find() const {
    for (const auto &m : modules)
      if (auto *p = dynamic_cast<M *>(m.get())) return p;
    return nullptr;
  }

  Totals totals() const;                                  // collective; also sets vmax
  std::vector<ParticleRecord> gather(int root = 0) const; // collective; sorted by id on root
  double gravity_factor(double t) const;
  // Velocity of the last grid update interpolated to each local particle (dim per
  // particle): the velocity the particles move with, free of FLIP's particle-level noise.
  std::vector<double> grid_velocity_at_particles();
};

} // namespace granmpm
