#include "granmpm/state.hpp"

#include <algorithm>
#include <cmath>

#include "granmpm/module.hpp"
#include "granmpm/output.hpp"
#include "granmpm/transfer.hpp"

namespace granmpm {

PetscLogStage log_stage(LogStage s) {
  // One set of log stages per process, however many simulations (2D or 3D) it builds.
  static PetscLogStage stages[7];
  static bool registered = false;
  if (!registered) {
    const char *names[7] = {"Migrate", "P2G", "GridUpdate", "G2P", "Constitutive", "Fluidity", "Output"};
    for (int i = 0; i < 7; ++i) GM_CALL(PetscLogStageRegister(names[i], &stages[i]));
    registered = true;
  }
  return stages[(int)s];
}

template <int dim>
void State<dim>::constrain(const NodeAt &n, double *v) const {
  for (const Module<dim> *m : constraint_modules) m->constrain(n, v);
}

template <int dim>
State<dim>::State(MPI_Comm c, const Config &config) : cfg(config), comm(c) {
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
}

template <int dim>
State<dim>::~State() = default;

template <int dim>
double State<dim>::gravity_factor(double t) const {
  if (cfg.gravity_ramp <= 0) return 1.0;
  return std::min(1.0, t / cfg.gravity_ramp);
}

template <int dim>
Totals State<dim>::totals() const {
  auto &P0 = const_cast<Particles<dim> &>(particles);
  ParticleView<dim> P = P0.get();
  double loc[3 + 2] = {0, 0, 0, 0, 0};
  double v2max = 0;
  for (PetscInt p = 0; p < P.n; ++p) {
    double v2 = 0;
    loc[0] += P.m[p];
    for (int d = 0; d < dim; ++d) {
      loc[1 + d] += P.m[p] * P.v[p * dim + d];
      v2 += P.v[p * dim + d] * P.v[p * dim + d];
    }
    loc[4] += 0.5 * P.m[p] * v2;
    v2max = std::max(v2max, v2);
  }
  P0.restore(P);
  double glob[5];
  MPI_Allreduce(loc, glob, 5, MPI_DOUBLE, MPI_SUM, comm);
  Totals t;
  t.n = particles.global_size();
  t.mass = glob[0];
  for (int d = 0; d < 3; ++d) t.momentum[d] = glob[1 + d];
  t.kinetic = glob[4];
  double vm = std::sqrt(v2max);
  MPI_Allreduce(&vm, &t.vmax, 1, MPI_DOUBLE, MPI_MAX, comm);
  const_cast<State *>(this)->vmax = t.vmax;
  return t;
}

template <int dim>
std::vector<ParticleRecord> State<dim>::gather(int root) const {
  auto &P0 = const_cast<Particles<dim> &>(particles);
  ParticleView<dim> P = P0.get();
  std::vector<ParticleRecord> mine(P.n);
  for (PetscInt p = 0; p < P.n; ++p) {
    ParticleRecord &r = mine[p];
    r = ParticleRecord{};
    r.id = P.id[p];
    for (int d = 0; d < dim; ++d) {
      r.x[d] = P.x[p * dim + d];
      r.v[d] = P.v[p * dim + d];
    }
    for (int c = 0; c < 6; ++c) r.s[c] = P.s[6 * p + c];
    r.m = P.m[p];
    r.vol = P.vol[p];
    r.g = P.g ? P.g[p] : 0.0;
  }
  P0.restore(P);
  int n = (int)(mine.size() * sizeof(ParticleRecord));
  std::vector<int> counts(size), displs(size);
  MPI_Gather(&n, 1, MPI_INT, counts.data(), 1, MPI_INT, root, comm);
  std::vector<ParticleRecord> all;
  if (rank == root) {
    int tot = 0;
    for (int r = 0; r < size; ++r) {
      displs[r] = tot;
      tot += counts[r];
    }
    all.resize(tot / sizeof(ParticleRecord));
  }
  MPI_Gatherv(mine.data(), n, MPI_BYTE, all.data(), counts.data(), displs.data(), MPI_BYTE, root, comm);
  std::sort(all.begin(), all.end(), [](const ParticleRecord &a, const ParticleRecord &b) { return a.id < b.id; });
  return all;
}

template <int dim>
std::vector<double> State<dim>::grid_velocity_at_particles() {
  std::vector<double> out;
  std::visit(
      [&](const auto &sh) {
        using S = std::decay_t<decltype(sh)>;
        NodeView<dim> g = grid.begin_local(false);
        ParticleView<dim> P = particles.get();
        out.resize((size_t)P.n * dim);
        Stencil<dim, S> st;
        G2POutput<dim> o;
        for (PetscInt p = 0; p < P.n; ++p) {
          st.compute(sh, P.x + p * dim, grid.x0, grid.inv_h);
          g2p_particle(st, grid.h, g, o);
          for (int d = 0; d < dim; ++d) out[(size_t)p * dim + d] = o.v_pic[d];
        }
        particles.restore(P);
        grid.end_local();
      },
      shape);
  return out;
}

template struct State<2>;
template struct State<3>;

} // namespace granmpm
