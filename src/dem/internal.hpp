// Shared by the DEM engine's source files (not installed): swarm field names, the byte
// all-to-all, component access and the id-keyed random numbers.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "granmpm/dem/dem.hpp"

namespace granmpm::dem::detail {

inline const char *F_X = "DMSwarmPIC_coor";
inline const char *F_CELL = "DMSwarm_cellid";
inline const char *F_V = "dem_v";
inline const char *F_W = "dem_omega";
inline const char *F_R = "dem_radius";
inline const char *F_TH = "dem_orientation"; // 2D: the angle theta; 3D: the quaternion w, x, y, z
inline const char *F_MW = "dem_mass_weight";
inline const char *F_ID = "DMSwarm_pid";
inline const char *F_RANK = "DMSwarm_rank";

// known: rcnt already holds the receive counts (the ghost plan between rebuilds).
template <class T>
inline void alltoallv(MPI_Comm comm, const std::vector<T> &send, const std::vector<int> &scnt, std::vector<T> &recv, std::vector<int> &rcnt, bool known = false) {
  const int P = (int)scnt.size();
  if (!known) {
    rcnt.assign(P, 0);
    MPI_Alltoall(scnt.data(), 1, MPI_INT, rcnt.data(), 1, MPI_INT, comm);
  }
  std::vector<int> sb(P), rb(P), sd(P), rd(P);
  int ts = 0, tr = 0;
  for (int p = 0; p < P; ++p) {
    sb[p] = scnt[p] * (int)sizeof(T);
    rb[p] = rcnt[p] * (int)sizeof(T);
    sd[p] = ts;
    rd[p] = tr;
    ts += sb[p];
    tr += rb[p];
  }
  recv.resize(tr / sizeof(T));
  MPI_Alltoallv(send.data(), sb.data(), sd.data(), MPI_BYTE, recv.data(), rb.data(), rd.data(), MPI_BYTE, comm);
}

inline double comp(const V3 &a, int k) { return k == 0 ? a.x : (k == 1 ? a.y : a.z); }
inline double &comp(V3 &a, int k) { return k == 0 ? a.x : (k == 1 ? a.y : a.z); }

// splitmix64: a grain's random numbers depend on its id only, so any rank count creates
// the same grains.
inline uint64_t mix(uint64_t z) {
  z += 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}
inline double urand(uint64_t seed, int64_t id, int k) { // in [0, 1)
  return (mix(mix(seed * 0x632be59bd9b4e019ULL + (uint64_t)id) + (uint64_t)k) >> 11) * 0x1.0p-53;
}

inline double comp_of(const V3 &a, int k) { return k == 0 ? a.x : (k == 1 ? a.y : a.z); }

} // namespace granmpm::dem::detail

namespace granmpm::dem {

// The broad phase: grains binned into cubic cells of side `cell` over their bounding box
// (CSR: the grains of cell c are order[start[c] .. start[c+1])).
struct CellBins {
  CellBins(const std::vector<V3> &xb, long n, double cell, int dim);
  V3 lo{};
  int nc[3] = {1, 1, 1};
  double cell;
  int dim;
  std::vector<int> start, order;
  long of(const V3 &x, int *ci) const { // the cell of x (and its index triple)
    for (int k = 0; k < 3; ++k) ci[k] = k < dim ? std::min(nc[k] - 1, (int)((detail::comp_of(x, k) - detail::comp_of(lo, k)) / cell)) : 0;
    return ci[0] + (long)nc[0] * (ci[1] + (long)nc[1] * ci[2]);
  }
};

} // namespace granmpm::dem
