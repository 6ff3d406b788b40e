// granmpm: the GranMPM executable. Reads the options, builds the simulation for -dim 2 or
// 3, runs it, and turns every failure into a one-line message and a non-zero exit.
#include <petscsys.h>

#include <cstdio>
#include <cstring>
#include <string>

#include "granmpm/config.hpp"
#include "granmpm/simulation.hpp"

static const char help[] =
    "GranMPM: distributed-memory material point method for dense granular flow (PETSc).\n"
    "With no options it runs the built-in default scene: the nonlocal granular-fluidity vertical chute\n"
    "of seed 000 (width 1 m, 20 cells across, periodic in y, rough walls, gravity ramped to 0.8 m/s^2 over\n"
    "0.5 s, read at t = 1.25 s) and writes output/profile.csv with vy(x) against its reference.\n"
    "Scenes are options files: granmpm -options_file examples/<scene>.opts (YAML: -options_file_yaml).\n\n";

namespace {

// Options nobody asked for are typos or options of another scene: stop rather than
// silently ignore them. PETSc's own run-time options are left to PETSc.
void check_unused_options(MPI_Comm comm) {
  PetscInt n;
  char **names, **values;
  GM_CALL(PetscOptionsLeftGet(NULL, &n, &names, &values));
  std::string bad;
  const char *petsc_prefixes[] = {"log", "malloc", "options_", "on_error", "info", "help", "version", "fp_trap", "memory_view", "objects_dump", "check_pointer_intensity",
                                  "no_signal_handler", "debugger", "start_in_debugger", "stop_for_debugger", "viewer_", "saws", "nox", "display", "use_gpu_aware_mpi",
                                  "mpi_", "history", "skip_petscrc", "checkstack", "quiet", "options_left"};
  for (PetscInt i = 0; i < n; ++i) {
    bool petsc = false;
    for (const char *p : petsc_prefixes)
      if (std::strncmp(names[i], p, std::strlen(p)) == 0) petsc = true;
    if (!petsc && bad.empty()) bad = names[i];
  }
  GM_CALL(PetscOptionsLeftRestore(NULL, &n, &names, &values));
  if (!bad.empty())
    throw granmpm::UserError("unknown option -" + bad + " (misspelled, or not used by this scene/material); see granmpm -help");
  (void)comm;
}

template <int dim>
void run(MPI_Comm comm, const granmpm::Config &cfg, bool help_only) {
  granmpm::Simulation<dim> sim(comm, cfg);
  sim.setup();
  check_unused_options(comm);
  if (help_only) return;
  sim.run();
}

} // namespace

int main(int argc, char **argv) {
  PetscErrorCode ierr = PetscInitialize(&argc, &argv, NULL, help);
  if (ierr) {
    std::fprintf(stderr, "granmpm: error: PETSc initialisation failed (malformed options file or option?)\n");
    return 1;
  }
  MPI_Comm comm = PETSC_COMM_WORLD;
  int rank = 0, size = 1, code = 0;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  try {
    const granmpm::Config cfg = granmpm::Config::from_options(comm);
    PetscBool help = PETSC_FALSE;
    PetscOptionsHasName(NULL, NULL, "-help", &help);
    if (cfg.dim == 2) run<2>(comm, cfg, help);
    else run<3>(comm, cfg, help);
  } catch (const granmpm::UserError &e) {
    if (rank == 0) std::fprintf(stderr, "granmpm: error: %s\n", e.what());
    code = 1;
  } catch (const granmpm::PetscFailure &e) {
    // PETSc printed the details where the error arose. Other ranks may be inside a
    // collective call, so a multi-rank run cannot finalize cleanly.
    std::fprintf(stderr, "granmpm: error: PETSc error %d (details above)\n", (int)e.code);
    std::fflush(stderr);
    if (size > 1) MPI_Abort(comm, 1);
    code = 1;
  } catch (const std::exception &e) {
    std::fprintf(stderr, "granmpm: error: %s\n", e.what());
    std::fflush(stderr);
    if (size > 1) MPI_Abort(comm, 1);
    code = 1;
  }
  PetscFinalize();
  return code;
}
