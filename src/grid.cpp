#include "granmpm/grid.hpp"

#include <algorithm>
#include <string>

namespace granmpm {

std::vector<PetscInt> balanced_ranges(const std::vector<double> &w, int parts, int min_nodes) {
  const int n = (int)w.size();
  std::vector<double> cum(n + 1, 0.0);
  for (int i = 0; i < n; ++i) cum[i + 1] = cum[i] + w[i];
  const double total = cum[n];
  std::vector<int> b(parts + 1);
  b[0] = 0;
  b[parts] = n;
  for (int r = 1; r < parts; ++r) {
    if (!(total > 0)) {
      b[r] = (int)((long)n * r / parts); // no weight: equal blocks
      continue;
    }
    const double target = total * r / parts;
    int i = (int)(std::lower_bound(cum.begin(), cum.end(), target) - cum.begin());
    if (i > 0 && target - cum[i - 1] < cum[i] - target) --i;
    b[r] = i;
  }
  for (int r = 1; r < parts; ++r) b[r] = std::max(b[r], b[r - 1] + min_nodes);
  for (int r = parts - 1; r >= 1; --r) b[r] = std::min(b[r], b[r + 1] - min_nodes);
  std::vector<PetscInt> l(parts);
  for (int r = 0; r < parts; ++r) l[r] = b[r + 1] - b[r];
  return l;
}

std::vector<int> owner_map(const std::vector<PetscInt> &ranges) {
  std::vector<int> o;
  for (size_t r = 0; r < ranges.size(); ++r) o.insert(o.end(), (size_t)ranges[r], (int)r);
  return o;
}

template <int dim>
void Grid<dim>::create(MPI_Comm c, const Config &cfg, const std::vector<PetscInt> *l) {
  destroy();
  comm = c;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  h = (cfg.hi[0] - cfg.lo[0]) / cfg.cells[0];
  wall_friction = cfg.wall_friction;
  inv_h = 1.0 / h;
  DMBoundaryType bt[3] = {DM_BOUNDARY_NONE, DM_BOUNDARY_NONE, DM_BOUNDARY_NONE};
  for (int d = 0; d < 3; ++d) {
    lo[d] = cfg.lo[d];
    hi[d] = cfg.hi[d];
    bc[d][0] = cfg.bc[d][0];
    bc[d][1] = cfg.bc[d][1];
    if (d >= dim) continue;
    periodic[d] = cfg.is_periodic(d);
    ncell[d] = cfg.cells[d];
    if (periodic[d]) {
      pad[d] = 0;
      M[d] = ncell[d];
      x0[d] = lo[d];
      bt[d] = DM_BOUNDARY_PERIODIC;
    } else {
      pad[d] = PAD;
      M[d] = ncell[d] + 1 + 2 * PAD;
      x0[d] = lo[d] - PAD * h;
    }
  }
  // The split is decided here, not inside DMSetUp: a PETSc split failure is raised on some
  // ranks only and leaves the others waiting in a collective call.
  std::vector<PetscInt> own[3];
  if (l) {
    for (int d = 0; d < dim; ++d) own[d] = l[d];
  } else {
    const std::array<int, 3> f = choose_split(size, cfg.procs);
    if (f[0] == 0) {
      std::string grid = std::to_string(M[0]) + "x" + std::to_string(M[1]) + (dim == 3 ? "x" + std::to_string(M[2]) : std::string());
      throw UserError("cannot split the " + grid + "-node grid over " + std::to_string(size) +
                      " ranks with at least 2 nodes per rank and direction (as -da_processors_x/y/z ask); increase -cells, use fewer ranks or change -da_processors_x/y/z");
    }
    for (int d = 0; d < dim; ++d) {
      own[d].resize(f[d]);
      for (int r = 0; r < f[d]; ++r) own[d][r] = M[d] / f[d] + (r < M[d] % f[d] ? 1 : 0);
    }
  }
  if (dim == 2)
    GM_CALL(DMDACreate2d(comm, bt[0], bt[1], DMDA_STENCIL_BOX, M[0], M[1], (PetscInt)own[0].size(), (PetscInt)own[1].size(), NDOF, 2, own[0].data(),
                         own[1].data(), &da));
  else
    GM_CALL(DMDACreate3d(comm, bt[0], bt[1], bt[2], DMDA_STENCIL_BOX, M[0], M[1], M[2], (PetscInt)own[0].size(), (PetscInt)own[1].size(),
                         (PetscInt)own[2].size(), NDOF, 2, own[0].data(), own[1].data(), own[2].data(), &da));
  GM_CALL(DMSetUp(da));
  GM_CALL(DMDASetUniformCoordinates(da, x0[0], x0[0] + (M[0] - 1) * h, x0[1], x0[1] + (M[1] - 1) * h, dim == 3 ? x0[2] : 0, dim == 3 ? x0[2] + (M[2] - 1) * h : 0));
  GM_CALL(DMDAGetLocalInfo(da, &info));
  PetscInt pm, pn, pp;
  GM_CALL(DMDAGetInfo(da, NULL, NULL, NULL, NULL, &pm, &pn, &pp, NULL, NULL, NULL, NULL, NULL, NULL));
  nproc[0] = (int)pm;
  nproc[1] = (int)pn;
  nproc[2] = dim == 3 ? (int)pp : 1;
  pcoord[0] = rank % nproc[0];
  pcoord[1] = (rank / nproc[0]) % nproc[1];
  pcoord[2] = rank / (nproc[0] * nproc[1]);
  xs[0] = info.xs; xm[0] = info.xm; gxs[0] = info.gxs; gxm[0] = info.gxm;
  xs[1] = info.ys; xm[1] = info.ym; gxs[1] = info.gys; gxm[1] = info.gym;
  if (dim == 3) {
    xs[2] = info.zs; xm[2] = info.zm; gxs[2] = info.gzs; gxm[2] = info.gzm;
  } else {
    xs[2] = 0; xm[2] = 1; gxs[2] = 0; gxm[2] = 1;
  }
  for (int d = 0; d < 3; ++d) owner_[d] = d < dim ? owner_map(own[d]) : std::vector<int>(1, 0);
  GM_CALL(DMCreateGlobalVector(da, &global));
  GM_CALL(DMCreateLocalVector(da, &local));
}

template <int dim>
std::array<int, 3> Grid<dim>::choose_split(int nranks, const std::array<int, 3> &fixed) const {
  // Among all factorisations m x n (x p) = nranks that give every rank >= 2 nodes per
  // direction and honour the fixed counts, take the one with the smallest halo surface.
  std::array<int, 3> best = {0, 0, 0};
  double best_cost = 1e300;
  for (int m = 1; m <= nranks; ++m) {
    if (nranks % m) continue;
    for (int n = 1; n <= nranks / m; ++n) {
      if ((nranks / m) % n) continue;
      const int p = nranks / (m * n);
      if (dim == 2 && p != 1) continue;
      const int f[3] = {m, n, p};
      bool ok = true;
      for (int d = 0; d < dim; ++d) {
        if (fixed[d] > 0 && fixed[d] != f[d]) ok = false;
        if (M[d] / f[d] < 2) ok = false;
      }
      if (!ok) continue;
      double cost = 0;
      for (int d = 0; d < dim; ++d) {
        double face = 1;
        for (int e = 0; e < dim; ++e)
          if (e != d) face *= M[e];
        cost += (f[d] - 1) * face;
      }
      if (cost < best_cost) {
        best_cost = cost;
        best = {m, n, p};
      }
    }
  }
  return best;
}

template <int dim>
void Grid<dim>::destroy() {
  if (global) VecDestroy(&global);
  if (local) VecDestroy(&local);
  if (da) DMDestroy(&da);
  global = local = nullptr;
  da = nullptr;
}

template <int dim>
std::vector<PetscInt> Grid<dim>::ranges(int d) const {
  const PetscInt *own[3] = {nullptr, nullptr, nullptr};
  GM_CALL(DMDAGetOwnershipRanges(da, &own[0], &own[1], &own[2]));
  return std::vector<PetscInt>(own[d], own[d] + nproc[d]);
}

template <int dim>
NodeView<dim> Grid<dim>::begin_local(bool zero) {
  if (zero) GM_CALL(VecZeroEntries(local));
  GM_CALL(VecGetArray(local, &arr_));
  arr_vec_ = local;
  NodeView<dim> v;
  v.a = arr_;
  for (int d = 0; d < 3; ++d) {
    v.gs[d] = gxs[d];
    v.gm[d] = gxm[d];
  }
  return v;
}

template <int dim>
NodeView<dim> Grid<dim>::begin_global() {
  GM_CALL(VecGetArray(global, &arr_));
  arr_vec_ = global;
  NodeView<dim> v;
  v.a = arr_;
  for (int d = 0; d < 3; ++d) {
    v.gs[d] = xs[d];
    v.gm[d] = xm[d];
  }
  return v;
}

template <int dim>
void Grid<dim>::end_local() {
  GM_CALL(VecRestoreArray(arr_vec_, &arr_));
  arr_vec_ = nullptr;
}
template <int dim>
void Grid<dim>::end_global() {
  end_local();
}

template <int dim>
void Grid<dim>::local_to_global_add() {
  GM_CALL(VecZeroEntries(global));
  GM_CALL(DMLocalToGlobalBegin(da, local, ADD_VALUES, global));
  GM_CALL(DMLocalToGlobalEnd(da, local, ADD_VALUES, global));
}

template <int dim>
void Grid<dim>::global_to_local() {
  GM_CALL(DMGlobalToLocalBegin(da, global, INSERT_VALUES, local));
  GM_CALL(DMGlobalToLocalEnd(da, global, INSERT_VALUES, local));
}

template <int dim>
DM Grid<dim>::create_da(int s, int dof) const {
  DMBoundaryType bt[3];
  for (int d = 0; d < 3; ++d) bt[d] = periodic[d] ? DM_BOUNDARY_PERIODIC : DM_BOUNDARY_NONE;
  std::vector<PetscInt> l[3];
  for (int d = 0; d < dim; ++d) l[d] = ranges(d);
  DM d1;
  if (dim == 2)
    GM_CALL(DMDACreate2d(comm, bt[0], bt[1], DMDA_STENCIL_BOX, M[0], M[1], nproc[0], nproc[1], dof, s, l[0].data(), l[1].data(), &d1));
  else
    GM_CALL(DMDACreate3d(comm, bt[0], bt[1], bt[2], DMDA_STENCIL_BOX, M[0], M[1], M[2], nproc[0], nproc[1], nproc[2], dof, s, l[0].data(), l[1].data(), l[2].data(), &d1));
  GM_CALL(DMSetUp(d1));
  return d1;
}

void copy_across_layouts(MPI_Comm comm, DM from, Vec from_global, DM to, Vec to_global) {
  Vec nat_old, nat_new;
  GM_CALL(DMDACreateNaturalVector(from, &nat_old));
  GM_CALL(DMDACreateNaturalVector(to, &nat_new));
  GM_CALL(DMDAGlobalToNaturalBegin(from, from_global, INSERT_VALUES, nat_old));
  GM_CALL(DMDAGlobalToNaturalEnd(from, from_global, INSERT_VALUES, nat_old));
  // The two natural vectors are split differently among the ranks: scatter between them.
  PetscInt lo, hi;
  GM_CALL(VecGetOwnershipRange(nat_new, &lo, &hi));
  IS is;
  VecScatter sc;
  GM_CALL(ISCreateStride(comm, hi - lo, lo, 1, &is));
  GM_CALL(VecScatterCreate(nat_old, is, nat_new, is, &sc));
  GM_CALL(VecScatterBegin(sc, nat_old, nat_new, INSERT_VALUES, SCATTER_FORWARD));
  GM_CALL(VecScatterEnd(sc, nat_old, nat_new, INSERT_VALUES, SCATTER_FORWARD));
  GM_CALL(DMDANaturalToGlobalBegin(to, nat_new, INSERT_VALUES, to_global));
  GM_CALL(DMDANaturalToGlobalEnd(to, nat_new, INSERT_VALUES, to_global));
  GM_CALL(VecScatterDestroy(&sc));
  GM_CALL(ISDestroy(&is));
  GM_CALL(VecDestroy(&nat_old));
  GM_CALL(VecDestroy(&nat_new));
}

template class Grid<2>;
template class Grid<3>;

} // namespace granmpm
