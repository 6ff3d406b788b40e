#include <algorithm>
#include <cmath>
#include <cstdio>

#include "scene_util.hpp"

namespace granmpm {

using namespace scene_util;

namespace {
// ---------------------------------------------------------------------------------------
// Column: at equilibrium sigma_yy(Y) = -rho g (Y_top - Y) in the reference configuration
// (the weight of the material above, whatever the elastic compression).

template <int dim>
class ColumnScene final : public SceneCase<dim> {
public:
  void finalize(State<dim> &sim, Metrics &metrics) override;
};

template <int dim>
void ColumnScene<dim>::finalize(State<dim> &sim, Metrics &metrics) {
  const Config &c = sim.cfg;
  const double ytop = std::min(c.body_hi[1], c.hi[1]), ybot = std::max(c.body_lo[1], c.lo[1]);
  const double g = std::fabs(c.gravity[1]) * sim.gravity_factor(sim.time), H = ytop - ybot;
  std::vector<ParticleRecord> all = sim.gather(0);
  if (sim.rank != 0) return;
  std::FILE *f = open_csv(c.output_dir, "column.csv");
  std::fprintf(f, "Y,y,syy,syy_exact\n");
  double e2 = 0, emax = 0;
  for (const auto &r : all) {
    double X[3];
    Scene<dim>::lattice_position(c, sim.grid, r.id, X);
    const double exact = -c.rho * g * (ytop - X[1]);
    const double e = (r.s[1] - exact) / (c.rho * g * H);
    e2 += e * e;
    emax = std::max(emax, std::fabs(e));
    std::fprintf(f, "%.9e,%.9e,%.9e,%.9e\n", X[1], r.x[1], r.s[1], exact);
  }
  close_atomic(f);
  metrics["stress_error_rms"] = std::sqrt(e2 / all.size());
  metrics["stress_error_max"] = emax;
  std::printf("column: sigma_yy error / (rho g H): rms %.4e, max %.4e (%s/column.csv)\n", metrics["stress_error_rms"], emax, c.output_dir.c_str());
}

} // namespace

GM_SCENE(column, ColumnScene)

} // namespace granmpm
