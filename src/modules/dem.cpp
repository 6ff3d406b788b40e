// DemModule: the DEM grains as a species of the MPM simulation (dem/module.hpp).
#include "granmpm/dem/module.hpp"

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "granmpm/checkpoint.hpp"
#include "granmpm/cpu_time.hpp"

namespace granmpm {

namespace {

// The MPM grid's decomposition as the engine sees it: rank columns cut at the first node
// of each ownership range, the grid's own owner-rank rule, its DMDA for the swarm.
template <int dim>
dem::Partition partition_of(const Grid<dim> &g) {
  dem::Partition p;
  for (int k = 0; k < 3; ++k) {
    p.P[k] = k < dim ? g.nproc[k] : 1;
    p.cut[k].assign(1, k < dim ? g.x0[k] : 0.0);
    if (k >= dim) {
      p.cut[k].push_back(1.0);
      continue;
    }
    long start = 0;
    for (PetscInt n : g.ranges(k)) {
      start += n;
      p.cut[k].push_back(g.x0[k] + start * g.h);
    }
  }
  p.owner = [&g](const double *x) { return g.owner_rank(x); };
  p.cell_dm = g.da;
  return p;
}

// Options of the standalone DEM that the host decides with -hybrid_dem.
const char *const kHostOwned[][2] = {
    {"-dem_lo", "-domain_lo"},  {"-dem_hi", "-domain_hi"},    {"-dem_periodic", "-bc_xlo..-bc_zhi"}, {"-dem_outlet", "-bc_xlo..-bc_zhi outlet"},
    {"-dem_gravity", "-gravity"}, {"-dem_t_end", "-t_end"},   {"-dem_max_steps", "-max_steps"},     {"-dem_restart", "-restart"},
    {"-dem_checkpoint", "-checkpoint_file"}, {"-dem_checkpoint_every", "-checkpoint_interval"}, {"-dem_output_dir", "-output_dir"},
    {"-dem_output_every", "-output_interval"}, {"-dem_fields_every", "-output_interval"}, {"-dem_output_overwrite", "-output_overwrite"}};

// The host's rigid bodies at the current time (poses and velocities, as the grid sees them).
template <int dim>
std::vector<BodyMotionState> body_states(const State<dim> &S) {
  std::vector<BodyMotionState> out(S.bodies ? S.bodies->size() : 0);
  for (size_t k = 0; k < out.size(); ++k) {
    out[k].pose = S.bodies->pose(k);
    for (int d = 0; d < 3; ++d) out[k].v[d] = S.bodies->velocity(k)[d];
    out[k].omega = S.bodies->omega(k);
  }
  return out;
}

} // namespace

template <int dim>
dem::Config DemModule<dim>::hosted(const Config &host, dem::Config c) {
  if (c.dim != dim)
    throw UserError("-dem_dim " + std::to_string(c.dim) + " differs from the MPM's -dim " + std::to_string(dim) + " (-hybrid_dem): set -dem_dim " + std::to_string(dim));
  if (host.time_integrator != TimeIntegrator::Explicit)
    throw UserError("-hybrid_dem runs the grains inside explicit MPM steps: use -time_integrator explicit");
  for (int k = 0; k < 3; ++k) {
    c.lo[k] = k < dim ? host.lo[k] : 0.0;
    c.hi[k] = k < dim ? host.hi[k] : 1.0;
    c.periodic[k] = k < dim && host.is_periodic(k);
    for (int s = 0; s < 2; ++s) c.outlet[k][s] = k < dim && host.bc[k][s] == BC::Outlet;
    c.gravity[k] = k < dim ? host.gravity[k] : 0.0;
  }
  c.output_dir = host.output_dir;
  c.quiet = true;
  c.fields = false;
  c.restart.clear();
  c.checkpoint.clear();
  return c;
}

template <int dim>
DemModule<dim>::DemModule(State<dim> &S, dem::Config c, bool host_snapshots) : host_snapshots_(host_snapshots) {
  engine_ = std::make_unique<dem::Engine>(S.comm, hosted(S.cfg, std::move(c)));
  engine_->set_partition(partition_of(S.grid));
  if (S.bodies) { // the rigid bodies are contact partners of the grains too
    std::vector<BodySpec> specs;
    for (size_t k = 0; k < S.bodies->size(); ++k) specs.push_back(S.bodies->spec(k));
    engine_->set_bodies(specs, body_states(S), S.time);
  }
  engine_->setup();
  if (S.rank == 0) {
    std::filesystem::create_directories(S.cfg.output_dir);
    const std::string path = S.cfg.output_dir + "/dem_summary.csv";
    csv_ = std::fopen(path.c_str(), S.cfg.restart.empty() ? "w" : "a");
    if (csv_ && S.cfg.restart.empty()) std::fprintf(csv_, "mpm_step,t,grains,removed,removed_mass,kinetic,contacts\n");
  }
  int ok = S.rank != 0 || csv_;
  MPI_Bcast(&ok, 1, MPI_INT, 0, S.comm);
  if (!ok) throw UserError("cannot write " + S.cfg.output_dir + "/dem_summary.csv: check -output_dir");
  if (S.cfg.restart.empty() && S.cfg.output_final) {
    if (host_snapshots_) first_due_ = true;
    else engine_->write_fields(snap_++);
  }
}

// Snapshots on the MPM's output steps and at its last step (t_end or -max_steps).
template <int dim>
void DemModule<dim>::end_step(State<dim> &S, double dt) {
  if (!host_snapshots_) snapshot_if_due(S, dt);
}

template <int dim>
void DemModule<dim>::snapshot_if_due(const State<dim> &S, double dt) {
  const long n = S.nsteps + 1;
  const bool last = S.time + dt >= S.cfg.t_end * (1 - 1e-12) || (S.cfg.max_steps >= 0 && n >= S.cfg.max_steps);
  if ((S.cfg.output_interval > 0 && n % S.cfg.output_interval == 0) || (last && S.cfg.output_final)) engine_->write_fields(snap_++);
}

template <int dim>
DemModule<dim>::~DemModule() {
  if (csv_) std::fclose(csv_);
}

// The sub-steps of one MPM step, under the host's gravity at the step start.
template <int dim>
void DemModule<dim>::begin_step(State<dim> &S, double dt) {
  if (first_due_) { // the t = 0 snapshot, after the host's set-up changed the grains
    engine_->write_fields(snap_++);
    first_due_ = false;
  }
  const double gf = S.gravity_factor(S.time);
  std::array<double, 3> g{0, 0, 0};
  for (int k = 0; k < dim; ++k) g[k] = S.cfg.gravity[k] * gf;
  engine_->set_gravity(g);
  if (S.bodies) engine_->set_body_states(body_states(S), S.time); // BodyModule set them to S.time
  const long n = std::max(1L, (long)std::ceil(dt / engine_->dt() * (1 - 1e-12)));
  const double h = dt / n;
  const double c0 = process_cpu_seconds();
  for (long s = 0; s < n; ++s) engine_->step(h);
  substeps_ += n;
  const double c1 = process_cpu_seconds();
  const dem::Summary m = engine_->summary(); // collective: the summary line is rank 0's
  cpu_steps_ += c1 - c0;
  cpu_summary_ += process_cpu_seconds() - c1;
  char buf[256];
  std::snprintf(buf, sizeof buf, "DEM grains: %ld grains (%ld removed), %ld contacts, %ld sub-steps (dt_DEM %.4g s, t_c %.4g s), %ld list rebuilds, kinetic energy %.6g J",
                m.grains, m.removed, m.contacts, substeps_, engine_->dt(), engine_->contact_time_estimate(), engine_->timers().rebuilds, m.ke + m.ke_rot);
  summary_ = buf;
  if (csv_ && S.nsteps % 10 == 0) {
    std::fprintf(csv_, "%ld,%.9g,%ld,%ld,%.9g,%.9g,%ld\n", S.nsteps, engine_->time(), m.grains, m.removed, m.removed_mass, m.ke + m.ke_rot, m.contacts);
    std::fflush(csv_);
  }
}

// The grains' push on the bodies over this step joins the grid's in the bodies' force sums
// (reduced by BodyModule::end_grid just before): bodies.csv reports both, and dynamic
// bodies move with both at end_step (two-way coupling).
template <int dim>
void DemModule<dim>::end_grid(State<dim> &S, double dt, bool with_force) {
  if (!with_force || !S.bodies) return;
  const std::vector<double> imp = engine_->take_body_impulse();
  std::vector<double> &f = S.bodies->forces();
  for (size_t q = 0; q < imp.size(); ++q) f[q] += imp[q] / dt;
}

template <int dim>
void DemModule<dim>::rebuild(State<dim> &S) {
  engine_->repartition(partition_of(S.grid));
}

template <int dim>
void DemModule<dim>::write_checkpoint(const State<dim> &, CheckpointIO &io) const {
  engine_->write_state(io, "dem_");
  io.write_attr("dem_substeps", {(double)substeps_, (double)snap_});
}

template <int dim>
void DemModule<dim>::read_checkpoint(State<dim> &S, CheckpointIO &io) {
  if (S.bodies) engine_->set_body_states(body_states(S), S.time); // restored by BodyModule
  engine_->read_state(io, "dem_");
  const std::vector<double> a = io.read_attr("dem_substeps");
  substeps_ = (long)a.at(0);
  snap_ = (int)a.at(1);
}

template <int dim>
void DemModule<dim>::backup(const State<dim> &) {
  backup_ = engine_->backup();
  backup_substeps_ = substeps_;
}

template <int dim>
void DemModule<dim>::restore(State<dim> &S) {
  if (S.bodies) engine_->set_body_states(body_states(S), S.time);
  engine_->restore(backup_);
  substeps_ = backup_substeps_;
}

template <int dim>
std::string DemModule<dim>::summary() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "; CPU of rank 0's process: %.3g s in the DEM sub-steps, %.3g s in their per-step summaries", cpu_steps_, cpu_summary_);
  return summary_ + buf;
}

template <int dim>
dem::Config dem_module_config(const State<dim> &S) {
  for (const auto &o : kHostOwned) {
    PetscBool set = PETSC_FALSE;
    GM_CALL(PetscOptionsHasName(NULL, NULL, o[0], &set));
    if (set) throw UserError(std::string(o[0]) + " is the standalone DEM's (granmpm -dem); with -hybrid_dem the grains follow the MPM's " + o[1] + ": drop " + o[0]);
  }
  return dem::Config::from_options(S.comm, false);
}

template class DemModule<2>;
template class DemModule<3>;
template dem::Config dem_module_config(const State<2> &);
template dem::Config dem_module_config(const State<3> &);

} // namespace granmpm
