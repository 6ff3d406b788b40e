#include <algorithm>
#include <cmath>
#include <cstdio>

#include "scene_util.hpp"

namespace granmpm {

using namespace scene_util;

namespace {
// ---------------------------------------------------------------------------------------
// Block: a box of material with uniform velocity -velocity, rotation -spin about z through
// the body centre and isotropic pressure -p0; reports its totals (conservation tests).

template <int dim>
class BlockScene final : public SceneCase<dim> {
public:
  const std::vector<SceneOption> &options() const override {
    static const std::vector<SceneOption> o = {{{"-spin", "Initial rigid rotation rate about the z axis through the body centre [rad/s]", 0}}};
    return o;
  }
  void init_particle(const Config &c, const double *centre, const double *x, double *v, double *s) const override {
    const double spin = c.scene_param("-spin");
    for (int d = 0; d < dim; ++d) v[d] = c.v0[d];
    v[0] += -spin * (x[1] - centre[1]);
    v[1] += spin * (x[0] - centre[0]);
    s[0] = s[1] = s[2] = -c.p0;
  }
  void checks(const Config &c, std::vector<Finding> &out) const override {
    check_initial_pressure(c, out);
    check_speed(out, "-spin", std::fabs(c.scene_param("-spin")) * domain_size(c));
  }
  void finalize(State<dim> &sim, Metrics &metrics) override;

private:
  void side_wall(State<dim> &sim);
};

template <int dim>
void BlockScene<dim>::finalize(State<dim> &sim, Metrics &metrics) {
  const Totals t = sim.totals();
  metrics["mass"] = t.mass;
  metrics["kinetic"] = t.kinetic;
  for (int d = 0; d < dim; ++d) metrics[std::string("momentum_") + "xyz"[d]] = t.momentum[d];
  double pv[2] = {0, 0}, pg[2] = {0, 0};
  ParticleView<dim> P = sim.particles.get();
  for (PetscInt p = 0; p < P.n; ++p) {
    pv[0] += P.vol[p] * pressure6(P.s + 6 * p);
    pv[1] += P.vol[p];
  }
  sim.particles.restore(P);
  MPI_Allreduce(pv, pg, 2, MPI_DOUBLE, MPI_SUM, sim.comm);
  metrics["mean_pressure"] = pg[1] > 0 ? pg[0] / pg[1] : 0;
  if (sim.rank == 0)
    std::printf("block: %ld particles, mass %.9e, kinetic energy %.9e, volume-mean pressure %.6g Pa\n", t.n, t.mass, t.kinetic, metrics["mean_pressure"]);
  if (dim == 3 && !sim.cfg.bodies.empty()) side_wall(sim);
}

// 3D soil bins with a tool (excavation, wheel): the particles in the layer one cell deep
// along the side wall z = domain_lo (the bin's glass wall, where seed 004 films the soil's
// failure surface), with their velocities: side_wall.csv.
template <int dim>
void BlockScene<dim>::side_wall(State<dim> &sim) {
  const Config &c = sim.cfg;
  std::vector<ParticleRecord> all = sim.gather(0);
  if (sim.rank != 0) return;
  std::FILE *f = open_csv(c.output_dir, "side_wall.csv");
  std::fprintf(f, "x,y,z,vx,vy,vz,speed\n");
  long n = 0;
  for (const auto &r : all) {
    if (!(r.x[2] < c.lo[2] + sim.grid.h)) continue;
    std::fprintf(f, "%.6e,%.6e,%.6e,%.6e,%.6e,%.6e,%.6e\n", r.x[0], r.x[1], r.x[2], r.v[0], r.v[1], r.v[2], std::sqrt(r.v[0] * r.v[0] + r.v[1] * r.v[1] + r.v[2] * r.v[2]));
    ++n;
  }
  close_atomic(f);
  std::printf("block: %ld particles within one cell of the side wall z = %g m at t = %g s (%s/side_wall.csv)\n", n, c.lo[2], sim.time, c.output_dir.c_str());
}
} // namespace

GM_SCENE(block, BlockScene)

} // namespace granmpm
