// Simulation<dim>::run: the time loop (step sizes, load balance, output, checkpoints,
// signals, progress lines) and the end-of-run summary.
#include <cstdio>
#include <sstream>

#include <sys/resource.h>

#include "granmpm/implicit.hpp"
#include "granmpm/output.hpp"
#include "granmpm/scene.hpp"
#include "granmpm/simulation.hpp"

namespace granmpm {

// The step to try: -dt or the CFL step (implicit: as adapted); a fixed -dt above the
// stability limit stops the run naming the limit that binds.
template <int dim>
double Simulation<dim>::next_dt() const {
  double dt = cfg.dt > 0 ? cfg.dt : cfl_dt();
  if (implicit) dt = implicit->next_dt(dt);
  if (!implicit && cfg.dt > 0 && !cfg.dt_allow_unstable && dt > dt_limit()) {
    std::ostringstream m;
    if (plastic_limit < dt_cfl_limit() && cfg.material == MaterialKind::Dynamic)
      m << "at t = " << time << " -dt " << cfg.dt << " exceeds the stability limit " << plastic_limit
        << " s of the explicit dynamical fluidity step (diffusion dx^2 t0/(2 dim A^2 d^2) or local relaxation); use -fluidity_step implicit, reduce -dt, or -dt 0 for automatic steps";
    else if (plastic_limit < dt_cfl_limit())
      m << "at t = " << time << " -dt " << cfg.dt << " exceeds the stability limit " << plastic_limit
        << " s of the explicit granular stress update (G dt / eta < 2); use -stress_update implicit, reduce -dt, or -dt 0 for automatic steps";
    else
      m << "at t = " << time << " the particle speed " << vmax << " m/s makes -dt " << cfg.dt << " exceed the CFL limit h/(c+|v|max) = " << dt_limit()
        << " s; reduce -dt (or use -dt 0 for automatic steps)";
    collective_fail(comm, true, m.str());
  }
  return dt;
}

// SIGTERM/SIGINT on any rank: checkpoint, return the signal (the run stops). SIGUSR1:
// checkpoint and continue (returns 0). Collective.
template <int dim>
int Simulation<dim>::handle_signals() {
  // Every step ends with migrate(), which has reduced the flags already (a signal that came
  // after it is seen at the next step).
  int sig[2] = {(int)stop_signal, (int)checkpoint_signal}, got[2] = {0, 0};
  if (signals_reduced_) got[0] = (int)signals_[0], got[1] = (int)signals_[1];
  else MPI_Allreduce(sig, got, 2, MPI_INT, MPI_MAX, comm);
  signals_reduced_ = false;
  const int any = got[0];
  if (got[1] && !any) {
    checkpoint_signal = 0;
    const std::string path = cfg.checkpoint_path();
    write_checkpoint(path);
    if (rank == 0) {
      std::printf("GranMPM: received SIGUSR1 at step %ld, t = %g s; checkpoint written to %s; continuing\n", nsteps, time, path.c_str());
      std::fflush(stdout);
    }
  }
  if (any) {
    const std::string path = cfg.checkpoint_path();
    write_checkpoint(path);
    if (rank == 0)
      std::printf("GranMPM: received signal %d at step %ld, t = %g s; checkpoint written to %s (continue with -restart %s)\n", any, nsteps, time,
                  path.c_str(), path.c_str());
    return any;
  }
  return 0;
}

template <int dim>
void Simulation<dim>::print_summary(int interrupted, double wall, long np1, double rss_sum, double imb_start, double imb_end, const Footprint &fp) const {
  if (rank != 0 || cfg.quiet) return;
  std::printf("GranMPM: %s, %ld steps to t = %g s in %.2f s wall (%.3g particle-steps/s); output in %s/\n", interrupted ? "interrupted" : "done", nsteps,
              time, wall, wall > 0 ? (double)np1 * nsteps / wall : 0.0, cfg.output_dir.c_str());
  std::printf("GranMPM: peak memory %.1f MiB over %d rank(s) (%.0f bytes per particle)\n", rss_sum, size, np1 > 0 ? rss_sum * 1048576.0 / np1 : 0.0);
  std::printf("GranMPM: particle data %.0f bytes per particle (swarm fields and step buffers), transfer grid %.0f bytes per node (global and ghosted vectors)\n",
              fp.per_particle, fp.per_node);
  if (implicit) std::printf("GranMPM: %s\n", implicit->summary().c_str());
  for (Module<dim> *m : modules_view())
    if (!m->summary().empty()) std::printf("GranMPM: %s\n", m->summary().c_str());
  if (size > 1)
    std::printf("GranMPM: load balance: particles per rank max/mean %.3f at the start, %.3f at the end; %ld repartition(s) (-balance_threshold %g)\n", imb_start, imb_end,
                rebalances, cfg.balance_threshold);
  if (particles.removed_total > 0) std::printf("GranMPM: %ld particles left through outlets\n", particles.removed_total);
  if (particles.wall_corrections > 0)
    std::printf("GranMPM: %ld times a particle was put back onto a wall it had crossed by less than a cell\n", particles.wall_corrections);
  if (body_corrections > 0)
    std::printf("GranMPM: %ld times a particle was put back onto a rigid body surface it had entered by less than a cell\n", body_corrections);
  if (bodies) std::printf("GranMPM: rigid body positions, forces and torques in %s/bodies.csv\n", cfg.output_dir.c_str());
}

// step(dt); with -on_instability checkpoint_and_abort, a guard's stop first restores the
// last good state and writes it as a checkpoint, named in the message.
template <int dim>
double Simulation<dim>::step_or_restore(double dt) {
  try {
    return step(dt);
  } catch (const UserError &e) {
    if (!cfg.checkpoint_on_instability) throw;
    restore_state();
    const std::string path = cfg.output_dir + "/checkpoint_last_good.h5";
    write_checkpoint(path);
    std::ostringstream m;
    m << e.what() << " [the last good state (before the first sign of instability), step " << nsteps << " at t = " << time << ", was written to " << path
      << "; continue with -restart " << path << " and a smaller -dt or -cfl]";
    throw UserError(m.str());
  }
}

// One progress line (collective: the totals are reduced).
template <int dim>
void Simulation<dim>::progress_line(double dt, double wall, double sim_t0) {
  const Totals tt = totals();
  const double eta = time > sim_t0 ? wall * (cfg.t_end - time) / (time - sim_t0) : 0;
  if (rank == 0) {
    std::printf("step %8ld  t %.5e  dt %.3e  KE %.6e  particles %ld  wall %.1f s  ETA %.1f s%s\n", nsteps, time, dt, tt.kinetic, tt.n, wall, eta,
                implicit ? implicit->progress().c_str() : "");
    std::fflush(stdout);
  }
}

// (86 lines: the time loop reads top to bottom as the run does -- rebalance and sort,
// backup, step, the bodies' record, output, checkpoint, progress, signals, then the final
// output and summary; each part is one call.)
template <int dim>
std::map<std::string, double> Simulation<dim>::run() {
  Scene<dim> scene(*this);
  const double t0 = MPI_Wtime();
  const double sim_t0 = time;
  const long np0 = particles.global_size();
  const double imb_start = imbalance();
  if (rank == 0 && !cfg.quiet) {
    std::printf("GranMPM: %s\n", stage_summary.c_str());
    std::printf("GranMPM: %ld particles, grid %d x %d%s nodes on %d rank(s), h = %g m, wave speed %g m/s, CFL limit %g s\n", np0, grid.M[0],
                grid.M[1], dim == 3 ? (" x " + std::to_string(grid.M[2])).c_str() : "", size, grid.h, wave_speed, dt_limit());
    if (!cfg.restart.empty()) std::printf("GranMPM: restarted from %s at step %ld, t = %g s\n", cfg.restart.c_str(), nsteps, time);
    std::fflush(stdout);
  }
  const double eps = 1e-12 * cfg.t_end;
  if (!cfg.restart.empty() && time >= cfg.t_end - eps) {
    // Nothing to do: say so, write nothing (the run's results stay as they are).
    if (rank == 0)
      std::printf("GranMPM: the checkpoint is at t = %.17g s, at or past -t_end %.17g s: nothing to run (raise -t_end to continue the run)\n", time, cfg.t_end);
    scene.metrics["interrupted"] = 0.0;
    scene.metrics["nothing_to_run"] = 1.0;
    return scene.metrics;
  }
  if (cfg.output_interval > 0 && nsteps == 0) {
    GM_CALL(PetscLogStagePush(st_out_));
    output->write(scene);
    GM_CALL(PetscLogStagePop());
  }
  scene.on_step(*this);
  if (body_module_) body_module_->record(*this, true);
  int interrupted = 0; // the signal that stopped the run
  while (time < cfg.t_end - eps && (cfg.max_steps < 0 || nsteps < cfg.max_steps)) {
    double dt = next_dt();
    if (time + dt > cfg.t_end) dt = cfg.t_end - time;
    // Before the backup: both change the particles' ranks and order.
    if (cfg.balance_threshold > 0 && nsteps % cfg.balance_interval == 0) rebalance();
    if (cfg.sort_interval > 0 && nsteps % cfg.sort_interval == 0) sort_particles();
    if (cfg.checkpoint_on_instability) {
      sign_seen_ = sign_seen_ || (nsteps > 0 && instability_sign(dt));
      if (!sign_seen_ || backup_.empty()) backup_state();
    }
    dt = step_or_restore(dt);
    if (nsteps == 1 && after_first_step) after_first_step();
    scene.on_step(*this);
    if (body_module_) body_module_->record(*this, false); // every -bodies_interval steps, every output step and at t_end
    if (cfg.output_interval > 0 && nsteps % cfg.output_interval == 0) {
      GM_CALL(PetscLogStagePush(st_out_));
      output->write(scene);
      GM_CALL(PetscLogStagePop());
    }
    if (cfg.checkpoint_interval > 0 && nsteps % cfg.checkpoint_interval == 0) write_checkpoint(cfg.checkpoint_path());
    if (cfg.progress_interval > 0 && nsteps % cfg.progress_interval == 0 && !cfg.quiet) progress_line(dt, MPI_Wtime() - t0, sim_t0);
    // A scheduler's SIGTERM (or Ctrl-C) on any rank: checkpoint and stop cleanly;
    // SIGUSR1: checkpoint and continue.
    interrupted = handle_signals();
    if (interrupted) break;
  }
  if (!interrupted && cfg.output_final && !(cfg.output_interval > 0 && nsteps % cfg.output_interval == 0)) {
    GM_CALL(PetscLogStagePush(st_out_));
    output->write(scene);
    GM_CALL(PetscLogStagePop());
  }
  if (!interrupted) {
    // The scene's CSV results are written on rank 0: a failure there must stop every rank.
    bool bad = false;
    std::string msg;
    try {
      scene.finalize(*this);
    } catch (const UserError &e) {
      bad = true;
      msg = e.what();
    }
    collective_fail(comm, bad, msg);
  }
  const double wall = MPI_Wtime() - t0;
  const long np1 = particles.global_size();
  struct rusage ru;
  getrusage(RUSAGE_SELF, &ru);
  double rss = ru.ru_maxrss / 1024.0, rss_sum = 0; // MiB (Linux reports KiB)
  MPI_Reduce(&rss, &rss_sum, 1, MPI_DOUBLE, MPI_SUM, 0, comm);
  const double imb_end = imbalance();
  const Footprint fp = footprint();
  print_summary(interrupted, wall, np1, rss_sum, imb_start, imb_end, fp);
  if (bodies) scene.metrics["body_corrections"] = (double)body_corrections;
  scene.metrics["interrupted"] = (double)interrupted;
  return scene.metrics;
}

// Explicit instantiations of the members defined in this file.
#define GM_INSTANTIATE(d) \
  template std::map<std::string, double> Simulation<d>::run(); \
  template double Simulation<d>::next_dt() const; \
  template int Simulation<d>::handle_signals(); \
  template double Simulation<d>::step_or_restore(double); \
  template void Simulation<d>::progress_line(double, double, double); \
  template void Simulation<d>::print_summary(int, double, long, double, double, double, const Footprint &) const;
GM_INSTANTIATE(2)
GM_INSTANTIATE(3)
#undef GM_INSTANTIATE

} // namespace granmpm
