// compute_loop: the machine's capacity for several simultaneous processes, without GranMPM.
//
// Every rank owns its own array of n "particles" of W doubles each (W = 24, 192 bytes: about the
// state a GranMPM particle streams per step) and sweeps it `iters` times with a fixed mix of
// floating-point work and memory streaming (a read-modify-write of the whole record, a few dozen
// flops per particle). No communication inside the timed loop: the ranks only meet at a barrier
// before and after it. Run it as 1 process and as P simultaneous processes with the same n; if the
// machine had P independent cores and memory paths, the wall time would not change.
//
// Usage: compute_loop [n_particles] [iters]     (mpiexec -n P compute_loop ... for P processes)
// Prints: "compute_loop: ranks P, particles per rank n, iters k, wall X s (max over ranks), checksum C"
#include <mpi.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  const long n = argc > 1 ? std::atol(argv[1]) : 500000;
  const int iters = argc > 2 ? std::atoi(argv[2]) : 20;
  constexpr int W = 24;
  std::vector<double> a(static_cast<size_t>(n) * W);
  for (long i = 0; i < n; ++i)
    for (int k = 0; k < W; ++k) a[i * W + k] = 1e-3 * ((i * 7 + k * 13 + rank) % 1000);
  MPI_Barrier(MPI_COMM_WORLD);
  const double t0 = MPI_Wtime();
  const double dt = 1e-4;
  for (int it = 0; it < iters; ++it) {
    for (long i = 0; i < n; ++i) {
      double* p = &a[i * W];
      // "position" 0-2, "velocity" 3-5, "stress" 6-11, "deformation gradient" 12-20, scalars 21-23
      double s = 0.0;
      for (int k = 6; k < 12; ++k) s += p[k] * p[k];
      const double q = std::sqrt(s + 1e-12);
      for (int k = 0; k < 3; ++k) {
        p[3 + k] = 0.999 * p[3 + k] - dt * q * p[k];
        p[k] += dt * p[3 + k];
      }
      for (int k = 6; k < 12; ++k) p[k] = 0.9995 * p[k] + dt * (p[12 + k - 6] - p[15 + (k - 6) % 6 / 2]);
      for (int k = 12; k < 21; ++k) p[k] = p[k] * (1.0 + dt * p[3 + k % 3]) - dt * 1e-3 * p[6 + k % 6];
      p[21] = 0.5 * p[21] + 0.5 * q;
      p[22] += dt * p[21];
      p[23] = std::fma(p[22], 1e-6, p[23]);
    }
  }
  const double local = MPI_Wtime() - t0;
  double wall = 0.0, sum = 0.0, gsum = 0.0;
  MPI_Reduce(&local, &wall, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
  for (long i = 0; i < n; i += 97) sum += a[i * W + 23] + a[i * W + 0];
  MPI_Reduce(&sum, &gsum, 1, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
  if (rank == 0)
    std::printf("compute_loop: ranks %d, particles per rank %ld, iters %d, wall %.6f s (max over ranks), checksum %.10g\n", size, n,
                iters, wall, gsum);
  MPI_Finalize();
  return 0;
}
