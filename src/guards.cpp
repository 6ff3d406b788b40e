// Simulation<dim>: -on_instability checkpoint_and_abort (the backup of the last good
// step, the signs of an instability) and checkpoint writing.
#include <algorithm>

#include "granmpm/checkpoint.hpp"
#include "granmpm/output.hpp"
#include "granmpm/simulation.hpp"

namespace granmpm {

// ---------------------------------------------------------------------------------------

template <int dim>
void Simulation<dim>::backup_state() {
  backup_.resize(particles.field_meta().size());
  DM sw = particles.dm();
  const PetscInt n = particles.local_size();
  size_t k = 0;
  for (const FieldMeta &f : particles.field_meta()) {
    void *data = nullptr;
    const size_t bytes = (size_t)n * f.bs * (f.type == PETSC_INT64 ? 8 : f.type == PETSC_INT ? sizeof(PetscInt) : sizeof(double));
    GM_CALL(DMSwarmGetField(sw, f.name.c_str(), NULL, NULL, &data));
    backup_[k].assign((const char *)data, (const char *)data + bytes);
    GM_CALL(DMSwarmRestoreField(sw, f.name.c_str(), NULL, NULL, &data));
    ++k;
  }
  backup_scalars_ = {time, (double)nsteps, vmax, plastic_limit, ke_, (double)n, (double)particles.removed_total, particles.removed_mass_total,
                     (double)output->count()};
  backup_ranges_.clear();
  for (int d = 0; d < dim; ++d) backup_ranges_.push_back(grid.ranges(d));
  for (Module<dim> *m : modules_view()) m->backup(*this); // body state, nodal fluidity
  ke_backup_ = ke_;
}

// Signs of an instability that the guards can see before they stop the run: a fixed step
// above the stability limit (-dt_allow_unstable), kinetic energy above all the energy the
// scene can supply (the guard stops at -energy_bound_factor times that), or kinetic energy
// multiplied by more than 10 since the last step (an explicit instability grows
// exponentially: the chute at 6x the CFL step gained 10-800x per step for 5 steps before
// the guard; a flow starting from rest gains 4x from step 1 to 2, then less). Growth from
// below 1e-6 of the available energy is not counted (start-up from rest).
template <int dim>
bool Simulation<dim>::instability_sign(double dt) const {
  if (!implicit && cfg.dt > 0 && dt > dt_limit()) return true;
  if (ke_ > energy_bound_) return true;
  return ke_backup_ > 1e-6 * energy_bound_ && ke_ > 10 * ke_backup_;
}

template <int dim>
void Simulation<dim>::restore_state() {
  // The backup may be many steps old: the particles have moved between ranks (and the grid
  // may have been repartitioned) since; each rank gets back what it held then.
  particles.set_local_size((PetscInt)backup_scalars_[5]);
  DM sw = particles.dm();
  size_t k = 0;
  for (const FieldMeta &f : particles.field_meta()) {
    void *data = nullptr;
    GM_CALL(DMSwarmGetField(sw, f.name.c_str(), NULL, NULL, &data));
    std::copy(backup_[k].begin(), backup_[k].end(), (char *)data);
    GM_CALL(DMSwarmRestoreField(sw, f.name.c_str(), NULL, NULL, &data));
    ++k;
  }
  time = backup_scalars_[0];
  nsteps = (long)backup_scalars_[1];
  vmax = backup_scalars_[2];
  plastic_limit = backup_scalars_[3];
  ke_ = backup_scalars_[4];
  particles.removed_total = (long)backup_scalars_[6];
  particles.removed_mass_total = backup_scalars_[7];
  std::vector<typename Output<dim>::Frame> fr = output->frames();
  fr.resize(std::min(fr.size(), (size_t)backup_scalars_[8])); // snapshots after the backup are not part of it
  output->set_frames(fr);
  bool same = true;
  for (int d = 0; d < dim; ++d) same = same && backup_ranges_[d] == grid.ranges(d);
  if (!same) repartition(backup_ranges_);
  for (Module<dim> *m : modules_view()) m->restore(*this); // after the repartition: the layout is the backup's again
}

template <int dim>
void Simulation<dim>::write_checkpoint(const std::string &path) {
  GM_CALL(PetscLogStagePush(st_out_));
  Checkpoint<dim>::write(*this, path);
  GM_CALL(PetscLogStagePop());
}

template void Simulation<2>::backup_state();
template bool Simulation<2>::instability_sign(double) const;
template void Simulation<2>::restore_state();
template void Simulation<2>::write_checkpoint(const std::string &);
template void Simulation<3>::backup_state();
template bool Simulation<3>::instability_sign(double) const;
template void Simulation<3>::restore_state();
template void Simulation<3>::write_checkpoint(const std::string &);

} // namespace granmpm
