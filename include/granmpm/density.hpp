// Elemental and hybrid density rules of seed 000 section 3.4.
//   elemental: rho_e = (particle mass in cell e) / V_e, given to the cell's particles
//   hybrid:    Sobel edge detection on the particles-per-cell field; edge cells keep the
//              local rule (rho = m / V, V *= exp(dt tr L)), interior cells take rho_e.
// Particles of a cell all live on the rank that owns the cell, so cell sums are local;
// the Sobel stencil needs neighbour cells, exchanged through a scalar DMDA (width 1)
// whose node c stands for cell c.
#pragma once

#include <petscdmda.h>

#include <vector>

#include "granmpm/config.hpp"
#include "granmpm/grid.hpp"
#include "granmpm/particles.hpp"

namespace granmpm {

// Sobel gradient magnitude of a cell field (pure; 2D 3x3 or 3D 3x3x3 kernels) at the
// centre of a 3^dim neighbourhood given in x-fastest order.
double sobel_magnitude(int dim, const double *nb);

template <int dim>
class CellDensity {
public:
  CellDensity(const Grid<dim> &grid, const Config &cfg);
  ~CellDensity();
  // Sets particle volumes; returns the number of edge cells (hybrid), global.
  long apply(Particles<dim> &parts);

private:
  const Grid<dim> &grid_;
  DensityMethod method_;
  double threshold_, nominal_;
  DM da_ = nullptr;
  Vec gcount_ = nullptr, lcount_ = nullptr;
};

} // namespace granmpm
