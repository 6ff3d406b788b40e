// Simulation<dim>: load balance (imbalance, the balanced split, repartition), the memory
// footprint and the sort by cell.
#include <algorithm>
#include <cstdio>

#include "granmpm/implicit.hpp"
#include "granmpm/simulation.hpp"

namespace granmpm {

// ---------------------------------------------------------------------------------------
// Load balance

template <int dim>
double Simulation<dim>::imbalance() const {
  const long n = particles.local_size();
  long mx = 0, sum = 0;
  MPI_Allreduce(&n, &mx, 1, MPI_LONG, MPI_MAX, comm);
  MPI_Allreduce(&n, &sum, 1, MPI_LONG, MPI_SUM, comm);
  return sum > 0 ? (double)mx * size / sum : 1.0;
}

template <int dim>
std::vector<std::vector<PetscInt>> Simulation<dim>::balanced_split() const {
  // Marginal particle counts per owner cell in each direction (one allreduce of
  // sum(M[d]) doubles), cut into equal shares.
  std::vector<double> w;
  size_t off[3] = {0, 0, 0};
  for (int d = 0; d < dim; ++d) {
    off[d] = w.size();
    w.resize(w.size() + grid.M[d], 0.0);
  }
  auto &P0 = const_cast<Particles<dim> &>(particles);
  ParticleView<dim> P = P0.get();
  for (PetscInt p = 0; p < P.n; ++p)
    for (int d = 0; d < dim; ++d) w[off[d] + grid.owner_cell(d, P.x[p * dim + d])] += 1;
  P0.restore(P);
  MPI_Allreduce(MPI_IN_PLACE, w.data(), (int)w.size(), MPI_DOUBLE, MPI_SUM, comm);
  std::vector<std::vector<PetscInt>> l(dim);
  for (int d = 0; d < dim; ++d)
    l[d] = balanced_ranges(std::vector<double>(w.begin() + off[d], w.begin() + off[d] + grid.M[d]), grid.nproc[d], 2);
  return l;
}

template <int dim>
bool Simulation<dim>::rebalance() {
  if (size == 1) return false;
  const double before = imbalance();
  if (before <= cfg.balance_threshold) return false;
  GM_CALL(PetscLogStagePush(st_migrate_));
  const std::vector<std::vector<PetscInt>> l = balanced_split();
  bool same = true;
  for (int d = 0; d < dim; ++d) same = same && l[d] == grid.ranges(d);
  // The particles per rank the new split would give (exact: every particle's new owner).
  double predicted = before;
  if (!same) {
    std::vector<int> own[dim];
    for (int d = 0; d < dim; ++d) own[d] = owner_map(l[d]);
    std::vector<long> cnt(size, 0);
    ParticleView<dim> P = particles.get();
    for (PetscInt p = 0; p < P.n; ++p) {
      int r = 0, stride = 1;
      for (int d = 0; d < dim; ++d) {
        r += own[d][grid.owner_cell(d, P.x[p * dim + d])] * stride;
        stride *= grid.nproc[d];
      }
      ++cnt[r];
    }
    particles.restore(P);
    MPI_Allreduce(MPI_IN_PLACE, cnt.data(), size, MPI_LONG, MPI_SUM, comm);
    long mx = 0, sum = 0;
    for (long c : cnt) {
      mx = std::max(mx, c);
      sum += c;
    }
    predicted = sum > 0 ? (double)mx * size / sum : 1.0;
  }
  // Repartition only when it helps: the tensor-product split may not get below the
  // threshold (a cluster smaller than the rank grid), and then nothing is gained.
  const bool go = !same && predicted < before;
  if (go) {
    repartition(l);
    ++rebalances;
    imbalance_before = before;
    imbalance_after = imbalance();
  }
  GM_CALL(PetscLogStagePop());
  if (go && rank == 0 && !cfg.quiet) {
    std::printf("GranMPM: step %ld: rebalanced, particles per rank max/mean %.3f -> %.3f; nodes per rank", nsteps, imbalance_before, imbalance_after);
    for (int d = 0; d < dim; ++d) {
      std::printf(" %c:", "xyz"[d]);
      for (size_t r = 0; r < l[d].size(); ++r) std::printf("%s%ld", r ? "," : "", (long)l[d][r]);
    }
    std::printf("\n");
    std::fflush(stdout);
  }
  return go;
}

template <int dim>
typename Simulation<dim>::Footprint Simulation<dim>::footprint() const {
  double pb = 0, nb = 0;
  for (const FieldMeta &f : particles.field_meta()) pb += (double)f.bs * (f.type == PETSC_INT64 ? 8 : f.type == PETSC_INT ? sizeof(PetscInt) : sizeof(double));
  const double n = (double)particles.local_size();
  double buffers = (double)(Lbuf_.capacity() + xvel_.capacity() + lapbuf_.capacity()) * sizeof(double) + (double)cellbuf_.capacity() * sizeof(long);
  PetscInt ng, nl;
  GM_CALL(VecGetLocalSize(grid.global, &ng));
  GM_CALL(VecGetLocalSize(grid.local, &nl));
  nb = (double)(ng + nl) * sizeof(double);
  double loc[3] = {pb * n + buffers, nb, n}, glob[3];
  MPI_Allreduce(loc, glob, 3, MPI_DOUBLE, MPI_SUM, comm);
  double nodes = 1;
  for (int d = 0; d < dim; ++d) nodes *= grid.M[d];
  Footprint f;
  f.per_particle = glob[2] > 0 ? glob[0] / glob[2] : 0;
  f.per_node = glob[1] / nodes;
  return f;
}

template <int dim>
void Simulation<dim>::sort_particles() {
  GM_CALL(PetscLogStagePush(st_migrate_));
  particles.sort_by_cell(grid);
  GM_CALL(PetscLogStagePop());
}

template <int dim>
void Simulation<dim>::repartition(const std::vector<std::vector<PetscInt>> &l) {
  grid.create(comm, cfg, l.data());
  for (Module<dim> *m : modules_view()) m->rebuild(*this); // every object built on the DMDA
  if (implicit) implicit->rebuild();
  particles.migrate(grid);
}

template double Simulation<2>::imbalance() const;
template std::vector<std::vector<PetscInt>> Simulation<2>::balanced_split() const;
template bool Simulation<2>::rebalance();
template typename Simulation<2>::Footprint Simulation<2>::footprint() const;
template void Simulation<2>::sort_particles();
template void Simulation<2>::repartition(const std::vector<std::vector<PetscInt>> &);
template double Simulation<3>::imbalance() const;
template std::vector<std::vector<PetscInt>> Simulation<3>::balanced_split() const;
template bool Simulation<3>::rebalance();
template typename Simulation<3>::Footprint Simulation<3>::footprint() const;
template void Simulation<3>::sort_particles();
template void Simulation<3>::repartition(const std::vector<std::vector<PetscInt>> &);

} // namespace granmpm
