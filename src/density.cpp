#include "granmpm/density.hpp"

#include <cmath>

namespace granmpm {

double sobel_magnitude(int dim, const double *nb) {
  // Derivative [-1 0 1] along the axis, smoothing [1 2 1] along the others.
  const double sm[3] = {1, 2, 1}, df[3] = {-1, 0, 1};
  double g2 = 0;
  for (int ax = 0; ax < dim; ++ax) {
    double g = 0;
    const int kn = dim == 3 ? 3 : 1;
    for (int k = 0; k < kn; ++k)
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) {
          const int idx[3] = {i, j, k};
          double w = 1;
          for (int d = 0; d < dim; ++d) w *= (d == ax) ? df[idx[d]] : sm[idx[d]];
          g += w * nb[(k * 3 + j) * 3 + i];
        }
    g2 += g * g;
  }
  return std::sqrt(g2);
}

template <int dim>
CellDensity<dim>::CellDensity(const Grid<dim> &grid, const Config &cfg) : grid_(grid), method_(cfg.density), threshold_(cfg.sobel_threshold) {
  nominal_ = std::pow((double)cfg.ppc, dim);
  if (method_ == DensityMethod::Hybrid) {
    da_ = grid.create_scalar_da(1);
    GM_CALL(DMCreateGlobalVector(da_, &gcount_));
    GM_CALL(DMCreateLocalVector(da_, &lcount_));
  }
}

template <int dim>
CellDensity<dim>::~CellDensity() {
  if (gcount_) VecDestroy(&gcount_);
  if (lcount_) VecDestroy(&lcount_);
  if (da_) DMDestroy(&da_);
}

template <int dim>
long CellDensity<dim>::apply(Particles<dim> &parts) {
  const Grid<dim> &g = grid_;
  const int nx = g.xm[0], ny = g.xm[1], nz = dim == 3 ? g.xm[2] : 1;
  std::vector<double> mass((size_t)nx * ny * nz, 0.0), count((size_t)nx * ny * nz, 0.0);
  std::vector<int> cell;
  ParticleView<dim> P = parts.get();
  cell.resize(P.n);
  for (PetscInt p = 0; p < P.n; ++p) {
    int c[3] = {0, 0, 0};
    for (int d = 0; d < dim; ++d) c[d] = g.cell_of(d, P.x[p * dim + d]) - g.xs[d];
    // A particle sits in an owned cell after migration; one exactly on the upper wall belongs to the last cell.
    for (int d = 0; d < dim; ++d) c[d] = std::min(c[d], g.xm[d] - 1);
    const int idx = (c[2] * ny + c[1]) * nx + c[0];
    cell[p] = idx;
    mass[idx] += P.m[p];
    count[idx] += 1;
  }
  std::vector<char> edge((size_t)nx * ny * nz, 0);
  long nedge = 0;
  if (method_ == DensityMethod::Hybrid) {
    double *a;
    GM_CALL(VecGetArray(gcount_, &a));
    for (size_t i = 0; i < count.size(); ++i) a[i] = count[i] / nominal_;
    GM_CALL(VecRestoreArray(gcount_, &a));
    GM_CALL(DMGlobalToLocalBegin(da_, gcount_, INSERT_VALUES, lcount_));
    GM_CALL(DMGlobalToLocalEnd(da_, gcount_, INSERT_VALUES, lcount_));
    DMDALocalInfo li;
    GM_CALL(DMDAGetLocalInfo(da_, &li));
    const double *la;
    GM_CALL(VecGetArrayRead(lcount_, &la));
    const int gs[3] = {li.gxs, li.gys, li.gzs}, gm[3] = {li.gxm, li.gym, li.gzm};
    for (int k = 0; k < nz; ++k)
      for (int j = 0; j < ny; ++j)
        for (int i = 0; i < nx; ++i) {
          const int own[3] = {g.xs[0] + i, g.xs[1] + j, g.xs[2] + k};
          double nb[27] = {0};
          const int kn = dim == 3 ? 3 : 1;
          for (int c = 0; c < kn; ++c)
            for (int b = 0; b < 3; ++b)
              for (int a2 = 0; a2 < 3; ++a2) {
                int q[3] = {own[0] + a2 - 1, own[1] + b - 1, dim == 3 ? own[2] + c - 1 : 0};
                // Walls: replicate the nearest physical cell so a wall is not an edge.
                for (int d = 0; d < dim; ++d)
                  if (!g.periodic[d]) q[d] = std::min(std::max(q[d], g.pad[d]), g.pad[d] + g.ncell[d] - 1);
                const long off = ((long)(q[2] - gs[2]) * gm[1] + (q[1] - gs[1])) * gm[0] + (q[0] - gs[0]);
                nb[(c * 3 + b) * 3 + a2] = la[off];
              }
          if (sobel_magnitude(dim, nb) > threshold_) {
            edge[(k * ny + j) * nx + i] = 1;
            ++nedge;
          }
        }
    GM_CALL(VecRestoreArrayRead(lcount_, &la));
  }
  const double Ve = std::pow(g.h, dim);
  for (PetscInt p = 0; p < P.n; ++p) {
    if (edge[cell[p]]) continue;
    const double rho_e = mass[cell[p]] / Ve;
    P.vol[p] = P.m[p] / rho_e;
  }
  parts.restore(P);
  long tot = 0;
  MPI_Allreduce(&nedge, &tot, 1, MPI_LONG, MPI_SUM, g.comm);
  return tot;
}

template class CellDensity<2>;
template class CellDensity<3>;

} // namespace granmpm
