// Catch2 runner for the MPI tests: PETSc is initialised once; every rank runs every test
// case (they are collective) and only rank 0 reports. Run with mpiexec -n 1, 2 or 3.
#define CATCH_CONFIG_RUNNER
#include <catch2/catch.hpp>
#include <petscsys.h>

#include <string>
#include <vector>

int main(int argc, char **argv) {
  // Catch parses its own arguments; keep PETSc away from them.
  int pargc = 1;
  char **pargv = argv;
  PetscInitialize(&pargc, &pargv, NULL, NULL);
  int rank = 0;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  std::vector<char *> args(argv, argv + argc);
  std::string out = "--out", null = "/dev/null";
  if (rank != 0) {
    args.push_back(out.data());
    args.push_back(null.data());
  }
  Catch::Session session;
  int rc = session.applyCommandLine((int)args.size(), args.data());
  if (rc == 0) rc = session.run();
  int all = 0;
  MPI_Allreduce(&rc, &all, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  PetscFinalize();
  return all;
}
