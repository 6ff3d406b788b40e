// granmpm: the GranMPM executable. Reads the options, builds the simulation for -dim 2 or
// 3, runs it, and turns every failure into a one-line message and a non-zero exit.
#include <petscsys.h>

#include <cctype>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "granmpm/config.hpp"
#include "granmpm/config_checks.hpp"
#include "granmpm/dem/dem.hpp"
#include "granmpm/output.hpp"
#include "granmpm/simulation.hpp"

static const char help[] =
    "GranMPM: distributed-memory material point method for dense granular flow (PETSc).\n"
    "With no options it runs the built-in default scene: the nonlocal granular-fluidity vertical chute\n"
    "of seed 000 (width 1 m, 20 cells across, periodic in y, rough walls, gravity ramped to 0.8 m/s^2 over\n"
    "0.5 s, read at t = 1.25 s) and writes output/profile.csv with vy(x) against its reference.\n"
    "Scenes are options files: granmpm -options_file examples/<scene>.opts (YAML: -options_file_yaml).\n"
    "The discrete element solver: granmpm -dem -dem_... (examples/dem_*.opts, docs/dem.md).\n\n";

namespace {

extern "C" void on_stop_signal(int sig) { granmpm::stop_signal = sig; }
extern "C" void on_checkpoint_signal(int) { granmpm::checkpoint_signal = 1; }

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

// PETSc 3.18 reads options files on rank 0 only and raises format errors there before
// broadcasting, leaving the other ranks waiting forever. Check the files here first, with
// PETSc's rules (one '-key [value]' or 'alias' per line, '#' comments), on rank 0.
bool valid_key(const std::string &k) {
  if (k.size() < 2 || k[0] != '-') return false;
  size_t i = (k[1] == '-') ? 2 : 1;
  if (i >= k.size() || !std::isalpha((unsigned char)k[i])) return false;
  return true;
}

// One options file and, recursively, the files it includes with -options_file lines
// (PETSc resolves their paths from the working directory). `chain` holds the files being
// read; an include of one of them is a cycle, which PETSc would follow until the stack
// overflows.
std::string check_options_file(const std::string &opt, const std::string &file, std::vector<std::string> &chain) {
  std::ifstream f(file);
  if (!f || std::filesystem::is_directory(file)) return opt + ": cannot read '" + file + "'" + (chain.empty() ? std::string() : " (included from " + chain.back() + ")");
  std::error_code ec;
  const std::string id = std::filesystem::weakly_canonical(file, ec).string();
  for (size_t i = 0; i < chain.size(); ++i)
    if (std::filesystem::weakly_canonical(chain[i], ec).string() == id) {
      std::string loop;
      for (size_t j = i; j < chain.size(); ++j) loop += chain[j] + " -> ";
      return opt + ": " + chain[i] + " includes itself (" + loop + file + "); remove the -options_file line that closes the loop";
    }
  const bool yaml = opt == "-options_file_yaml" || (file.size() > 5 && (file.substr(file.size() - 5) == ".yaml" || file.substr(file.size() - 4) == ".yml"));
  if (yaml) return ""; // read on rank 0 but parsed on every rank: errors stay collective
  chain.push_back(file);
  std::string line;
  for (int n = 1; std::getline(f, line); ++n) {
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream ss(line);
    std::vector<std::string> tok;
    for (std::string t; ss >> t;) tok.push_back(t);
    if (tok.empty()) continue;
    const std::string where = opt + " " + file + " line " + std::to_string(n) + ": ";
    if (tok[0] == "alias" || tok[0] == "ALIAS") {
      if (tok.size() != 3) return where + "'alias' needs exactly two options";
      continue;
    }
    if (!valid_key(tok[0])) return where + "expected '-option [value]', found '" + tok[0] + "'";
    if (tok.size() > 1 && valid_key(tok[1])) return where + "one option per line (found " + tok[0] + " and " + tok[1] + ")";
    if (tok.size() > 2) return where + "extra token '" + tok[2] + "' (values with commas take no spaces: -cells 20,4)";
    if ((tok[0] == "-options_file" || tok[0] == "-options_file_yaml") && tok.size() == 2) {
      const std::string m = check_options_file(tok[0], tok[1], chain);
      if (!m.empty()) return m;
    }
  }
  chain.pop_back();
  return "";
}

std::string check_options_files(int argc, char **argv) {
  for (int i = 1; i + 1 < argc; ++i) {
    const std::string opt = argv[i];
    if (opt != "-options_file" && opt != "-options_file_yaml") continue;
    std::vector<std::string> chain;
    const std::string m = check_options_file(opt, argv[i + 1], chain);
    if (!m.empty()) return m;
  }
  return "";
}

// The DEM solver reads its -dem_* options itself (src/dem/config.cpp); as for the MPM
// options (Config::from_options), a non-finite number in any of them (inf, nan, 1e400,
// in any component) stops here, naming the option, instead of running to NaN.
std::string dem_nonfinite_option() {
  char *all = nullptr;
  if (PetscOptionsGetAll(NULL, &all) || !all) return "";
  std::istringstream in(all);
  PetscFree(all);
  std::string name, tok;
  while (in >> tok) {
    char *end = nullptr;
    std::strtod(tok.c_str(), &end);
    const bool number = end != tok.c_str() && *end == 0;
    if (!number && valid_key(tok)) {
      name = tok;
      continue;
    }
    if (name.rfind("-dem_", 0) == 0 && granmpm::nonfinite_component(tok) >= 0)
      return name + ": '" + tok + "' is not a finite number" + (tok.find(',') != std::string::npos ? " (component " + std::to_string(granmpm::nonfinite_component(tok) + 1) + ")" : std::string()) +
             "; give a finite value (values beyond +-1.8e308 overflow to inf)";
  }
  return "";
}

// Returns the signal that interrupted the run (0: it ran to the end).
template <int dim>
int run(MPI_Comm comm, const granmpm::Config &cfg, bool help_only) {
  if (!help_only) granmpm::check_output_dir(comm, cfg);
  granmpm::Simulation<dim> sim(comm, cfg);
  sim.setup();
  if (help_only) return 0;
  sim.after_first_step = [comm]() { check_unused_options(comm); };
  return (int)sim.run()["interrupted"];
}

} // namespace

int main(int argc, char **argv) {
  // MPI first, so that a failure while PETSc reads the options is reported once.
  MPI_Init(&argc, &argv);
  int rank = 0, size = 1, code = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  {
    std::string msg = rank == 0 ? check_options_files(argc, argv) : std::string();
    int len = (int)msg.size();
    MPI_Bcast(&len, 1, MPI_INT, 0, MPI_COMM_WORLD);
    if (len > 0) {
      if (rank == 0) std::fprintf(stderr, "granmpm: error: %s\n", msg.c_str());
      MPI_Finalize();
      return 1;
    }
  }
  // While PETSc reads the options: no trace (it would bury the cause), and return the
  // error on every rank (PETSc's default handler exits ranks > 0 on collective errors,
  // which Open MPI reports as an improper exit).
  PetscErrorPrintf = PetscErrorPrintfNone;
  PetscPushErrorHandler(PetscReturnErrorHandler, NULL);
  PetscErrorCode ierr = PetscInitialize(&argc, &argv, NULL, help);
  PetscPopErrorHandler();
  PetscErrorPrintf = PetscErrorPrintfDefault;
  if (ierr) {
    const char *text = nullptr;
    char *specific = nullptr;
    PetscErrorMessage(ierr, &text, &specific);
    if (rank == 0)
      std::fprintf(stderr, "granmpm: error: cannot read the options (command line, -options_file or -options_file_yaml): %s\n",
                   specific && *specific ? specific : (text ? text : "unknown PETSc error"));
    MPI_Finalize();
    return 1;
  }
  // After PetscInitialize, replacing PETSc's handler: a scheduler's SIGTERM (or Ctrl-C)
  // makes the run loop write a checkpoint and stop, with status 128 + the signal (what a
  // shell reports for a process killed by it) on every rank; SIGUSR1 writes a checkpoint
  // and the run continues.
  std::signal(SIGTERM, on_stop_signal);
  std::signal(SIGINT, on_stop_signal);
  std::signal(SIGUSR1, on_checkpoint_signal);
  MPI_Comm comm = PETSC_COMM_WORLD;
  try {
    PetscBool dem = PETSC_FALSE, help = PETSC_FALSE;
    PetscOptionsGetBool(NULL, NULL, "-dem", &dem, NULL);
    PetscOptionsHasName(NULL, NULL, "-help", &help);
    if (dem) {
      const std::string bad = dem_nonfinite_option();
      if (!bad.empty()) throw granmpm::UserError(bad);
      const int sig = granmpm::dem::run_main(comm, help, check_unused_options);
      if (sig > 0) code = 128 + sig;
    } else {
      const granmpm::Config cfg = granmpm::Config::from_options(comm);
      const int sig = cfg.dim == 2 ? run<2>(comm, cfg, help) : run<3>(comm, cfg, help);
      if (sig > 0) code = 128 + sig;
    }
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
  MPI_Finalize();
  return code;
}
