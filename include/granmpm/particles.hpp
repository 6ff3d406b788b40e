// Particles<dim>: the material points, held in a PETSc DMSwarm of type BASIC.
//
// Why BASIC and not PIC: PETSc 3.18's PIC migration loses particles in periodic and 3D
// cases and cannot hop past neighbour ranks (../shared/notes). Here every particle's owner
// rank is computed by Grid::owner_rank from the DMDA ownership ranges, written into
// DMSwarm_rank, and DMSwarmMigrate(BASIC) sends it there, however far.
//
// Fields are structure-of-arrays doubles (so HDF5 output and shared Vecs work); which
// optional fields exist is decided once at set-up from the scene's needs.
#pragma once

#include <functional>

#include <petscdmswarm.h>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "granmpm/config.hpp"
#include "granmpm/grid.hpp"

namespace granmpm {

// The optional fields of a swarm. Set-up lists the material model's declared fields
// (materials/model.hpp) in `model`; the flags name the known ones directly (tests) and
// are set from the names after Particles::create.
struct ParticleFieldSet {
  bool apic = false;     // affine matrix C (dim x dim)
  bool fluidity = false; // g (steady or dynamical fluidity)
  bool gdot = false;     // equivalent plastic shear rate, for output
  bool hyper = false;    // Be, p_prev, mu_prev (hyperelastic dynamical fluidity)
  bool fluidity_split = false; // g - g_loc, g_loc of the last steady fluidity solve, g_loc ahead
  std::vector<std::pair<std::string, int>> model; // the material's fields: name, doubles per particle
};

template <int dim>
struct ParticleView {
  PetscInt n = 0;
  double *x = nullptr;     // dim
  double *v = nullptr;     // dim
  double *m = nullptr;     // 1
  double *vol = nullptr;   // 1
  double *s = nullptr;     // 6: xx yy zz xy yz xz
  double *C = nullptr;     // dim*dim (APIC only)
  double *g = nullptr;     // 1 (fluidity models only)
  double *gdot = nullptr;  // 1 (granular models only)
  double *Be = nullptr;    // 6: Be - I, Be = Fe Fe^T the elastic left Cauchy-Green tensor, xx yy zz xy yz xz (hyperelastic models only)
  double *p_prev = nullptr;  // 1: pressure of the last step, 0 = stress-free (disconnected)
  double *mu_prev = nullptr; // 1
  double *gsplit = nullptr;  // 3: g - g_loc and g_loc at the last steady fluidity solve, g_loc of the next step (change_ahead)
  int64_t *id = nullptr;   // global particle id
  // Every optional field by its index (Particles::field_index), the named ones included.
  static constexpr int kMaxOptional = 12;
  double *opt[kMaxOptional] = {};
  double *field(int i) const { return i >= 0 && i < kMaxOptional ? opt[i] : nullptr; }
};

// A registered swarm field, for generic I/O (checkpoints).
struct FieldMeta {
  std::string name;
  int bs;
  PetscDataType type; // PETSC_REAL, PETSC_INT64 or PETSC_INT
};

struct MigrateStats {
  long sent = 0;      // particles sent to another rank (global)
  long removed = 0;   // particles removed through outlets this call (global)
  double removed_mass = 0;
  bool migrated = false;
};

template <int dim>
class Particles {
public:
  Particles() = default;
  Particles(const Particles &) = delete;
  Particles &operator=(const Particles &) = delete;
  ~Particles() { destroy(); }

  void create(MPI_Comm comm, Grid<dim> &grid, const ParticleFieldSet &fields);
  void destroy();

  // Seeds ppc^dim particles per cell on a regular lattice in every owned cell whose
  // lattice points fall inside [body_lo, body_hi). Ids are lattice indices, so they do not
  // depend on the number of ranks.
  // keep (optional): a lattice point is seeded only if keep(x) (rigid bodies are not filled).
  void seed(const Config &cfg, const Grid<dim> &grid, const std::function<bool(const double *)> &keep = nullptr);

  PetscInt local_size() const;
  long global_size() const;
  // The fields of every local particle. They are checked out of the swarm at the first get()
  // and stay checked out (restore() only clears the view) until an operation that changes the
  // swarm's size or layout: migration that moves or removes particles, sort_by_cell,
  // set_local_size, seed, destroy, and dm() (any direct swarm call). DMSwarmGetField finds a
  // field by a string search over all fields; the dozens of look-ups per step were 6.6% of
  // the step of the 40-cell dynamic chute (perf: strcmp). A view must not be used after one
  // of those operations (as before: they may move the arrays).
  ParticleView<dim> get();
  void restore(ParticleView<dim> &v);

  // Wraps periodic coordinates, removes particles that left through an outlet (counted),
  // stops with a message naming the particle and the face if one left through any other
  // non-periodic face, then sends every particle to its owner rank. flags (optional,
  // nflags values): this rank's, replaced by their max over the ranks, reduced with the
  // counts (Simulation::migrate: the signals and the modules' reduce_ahead).
  MigrateStats migrate(const Grid<dim> &grid, double *flags = nullptr, int nflags = 0);

  // Reorders the local particles by the index of their owner cell (x fastest, as the
  // grid's node arrays), keeping the order within a cell: P2G and G2P then sweep the
  // node array nearly sequentially. Every field is permuted. Local, no communication.
  void sort_by_cell(const Grid<dim> &grid);

  DM dm() const {
    release(); // the caller may get fields or resize the swarm
    return sw_;
  }
  const ParticleFieldSet &fields() const { return fields_; }
  // The index of an optional field in ParticleView::opt, -1 if the swarm has none.
  int field_index(const std::string &name) const;
  // The optional fields (name, doubles per particle), in ParticleView::opt order.
  const std::vector<std::pair<std::string, int>> &optional_fields() const { return opt_; }
  // Every field of the swarm (physics fields, DMSwarm_pid, DMSwarm_rank).
  const std::vector<FieldMeta> &field_meta() const { return meta_; }
  // Resizes the local swarm to n points (restart); contents are then written by the caller.
  void set_local_size(PetscInt n);
  long removed_total = 0;
  double removed_mass_total = 0;
  long wall_corrections = 0; // particles put back onto a wall they had crossed by < 1 cell

private:
  DM sw_ = nullptr;
  MPI_Comm comm_ = MPI_COMM_NULL;
  ParticleFieldSet fields_;
  std::vector<FieldMeta> meta_;
  std::vector<std::pair<std::string, int>> opt_;
  std::vector<double *ParticleView<dim>::*> named_; // per optional field: the named view member it fills, or null
  mutable bool held_ = false;         // the fields of cache_ (and rank_) are checked out
  mutable ParticleView<dim> cache_;
  mutable int *rank_ = nullptr;       // DMSwarm_rank (migrate)
  void hold() const;
  void release() const;
};

} // namespace granmpm
