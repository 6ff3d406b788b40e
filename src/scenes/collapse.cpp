#include <algorithm>
#include <cmath>
#include <cstdio>

#include "scene_util.hpp"

namespace granmpm {

using namespace scene_util;

namespace {
// ---------------------------------------------------------------------------------------
// Column collapse: a column of width L0 and height H0 = a L0 against the wall at
// x = domain_lo collapses along x. Runout L_f: the tip of the deposit (the furthest
// particle, what the experiments measure; the mass-weighted 99% front is reported too),
// against the 2D laws of Lube et al. (2005): (L_f - L0)/L0 = 1.2 a for a < 1.8 and
// 1.9 a^(2/3) for a > 2.8; in between (the transition) both are reported.

template <int dim>
class CollapseScene final : public SceneCase<dim> {
public:
  void finalize(State<dim> &sim, Metrics &metrics) override;
};

template <int dim>
void CollapseScene<dim>::finalize(State<dim> &sim, Metrics &metrics) {
  const Config &c = sim.cfg;
  const double L0 = std::min(c.body_hi[0], c.hi[0]) - c.lo[0], H0 = std::min(c.body_hi[1], c.hi[1]) - std::max(c.body_lo[1], c.lo[1]);
  const double a = H0 / L0;
  std::vector<ParticleRecord> all = sim.gather(0);
  if (sim.rank != 0) return;
  std::vector<std::pair<double, double>> xm;
  double mtot = 0, ymax = 0, xmax = 0;
  for (const auto &r : all) {
    xm.push_back({r.x[0] - c.lo[0], r.m});
    mtot += r.m;
    ymax = std::max(ymax, r.x[1] - c.lo[1]);
    xmax = std::max(xmax, r.x[0] - c.lo[0]);
  }
  std::sort(xm.begin(), xm.end());
  double acc = 0, x99 = 0;
  for (const auto &q : xm) {
    acc += q.second;
    if (acc >= 0.99 * mtot) {
      x99 = q.first;
      break;
    }
  }
  const double runout = (xmax - L0) / L0;
  const double lube_lo = 1.2 * a, lube_hi = 1.9 * std::pow(a, 2.0 / 3.0);
  const double lube = a <= 1.8 ? lube_lo : (a >= 2.8 ? lube_hi : lube_lo + (lube_hi - lube_lo) * (a - 1.8) / 1.0);
  metrics["aspect_ratio"] = a;
  metrics["runout"] = runout;
  metrics["runout_99"] = (x99 - L0) / L0;
  // Lube's laws are fits to dry granular flows: they do not apply to an elastic material.
  const bool granular = c.material != MaterialKind::LinearElastic && c.material != MaterialKind::Hypoelastic;
  if (granular) metrics["lube_runout"] = lube;
  metrics["final_height"] = ymax / L0;
  // Surface profile: highest particle per grid column.
  const int nc = sim.grid.ncell[0];
  std::vector<double> top(nc, 0.0);
  for (const auto &r : all) {
    const int col = std::min(nc - 1, std::max(0, (int)((r.x[0] - c.lo[0]) / sim.grid.h)));
    top[col] = std::max(top[col], r.x[1] - c.lo[1]);
  }
  std::FILE *f = open_csv(c.output_dir, "collapse.csv");
  std::fprintf(f, "x,height\n");
  for (int i = 0; i < nc; ++i) std::fprintf(f, "%.6e,%.6e\n", (i + 0.5) * sim.grid.h, top[i]);
  close_atomic(f);
  f = open_csv(c.output_dir, "collapse_summary.csv");
  std::fprintf(f, "aspect_ratio,runout,runout_99,lube_runout,final_height,time\n%.6e,%.6e,%.6e,%.6e,%.6e,%.6e\n", a, runout,
               metrics["runout_99"], lube, metrics["final_height"], sim.time);
  close_atomic(f);
  if (!granular) {
    std::printf("collapse: a = %.3g: runout (L_f - L0)/L0 = %.4g (deposit tip; 99%% mass front %.4g); final height H_f/L0 = %.4g (%s/collapse.csv); "
                "reference skipped: Lube et al. 2005 covers granular materials, -material mu_i|nonlocal|dynamic|drucker_prager (got %s)\n",
                a, runout, metrics["runout_99"], metrics["final_height"], c.output_dir.c_str(), to_string(c.material));
    return;
  }
  std::printf("collapse: a = %.3g: runout (L_f - L0)/L0 = %.4g (deposit tip; 99%% mass front %.4g); Lube et al. 2005: %.4g (%s); final height H_f/L0 = %.4g (%s/collapse.csv)\n",
              a, runout, metrics["runout_99"], lube, a <= 1.8 ? "1.2 a" : (a >= 2.8 ? "1.9 a^(2/3)" : "between 1.2 a and 1.9 a^(2/3), interpolated"),
              metrics["final_height"], c.output_dir.c_str());
}

} // namespace

GM_SCENE(collapse, CollapseScene)

} // namespace granmpm
