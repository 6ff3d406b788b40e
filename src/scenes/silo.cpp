#include <algorithm>
#include <cmath>
#include <cstdio>

#include "granmpm/modules.hpp"
#include "scene_util.hpp"

namespace granmpm {

using namespace scene_util;

namespace {
// ---------------------------------------------------------------------------------------
// Silo: particles leaving through the outlet below the plate are counted; the discharge
// rate is the slope of the discharged mass against time, fitted over the middle of the
// discharge (from 20% to 80% of the time after the first particle left).

template <int dim>
class SiloScene final : public SceneCase<dim> {
public:
  const std::vector<SceneOption> &options() const override {
    static const std::vector<SceneOption> o = {
        {{"-silo_plate_y", "Height of the bottom plate (its nodes are sticky outside the orifice) [m]", 0}},
        {{"-silo_orifice", "Orifice width D [m]", 0, 0, kInf, true}},
        {{"-silo_orifice_x", "x of the orifice centre [m]", 0}},
        {{"-silo_orifice_z", "(3D) z of the orifice centre [m]", 0}}};
    return o;
  }
  void add_modules(State<dim> &sim, std::vector<std::unique_ptr<Module<dim>>> &modules) const override {
    const Config &c = sim.cfg;
    modules.push_back(std::make_unique<SiloPlate<dim>>(sim.grid, c.scene_param("-silo_plate_y"), c.scene_param("-silo_orifice"), c.scene_param("-silo_orifice_x"),
                                                       c.scene_param("-silo_orifice_z")));
  }
  void validate(const Config &c) const override {
    const double y = c.scene_param("-silo_plate_y");
    if (!(y > c.lo[1] && y < c.hi[1])) bad("-silo_plate_y must lie inside the domain in y (got " + fmt(y) + ")");
    if (c.bc[1][0] != BC::Outlet) bad("-scene silo: particles leave below the plate, set -bc_ylo outlet");
  }
  void checks(const Config &c, std::vector<Finding> &out) const override;
  void signature(const Config &c, Signature &s) const override { // (-silo_orifice_z in 3D only)
    SceneRules::signature(c, s);
    if (c.dim == 2) s.pop_back();
  }
  void on_step(State<dim> &sim) override { silo_.push_back({sim.time, sim.particles.removed_mass_total, (double)sim.particles.removed_total}); }
  void finalize(State<dim> &sim, Metrics &metrics) override;

private:
  std::vector<std::array<double, 3>> silo_; // t, discharged mass, discharged particles
};

// The orifice must open at least one node of the plate.
template <int dim>
void SiloScene<dim>::checks(const Config &c, std::vector<Finding> &out) const {
  const double D = c.scene_param("-silo_orifice"), xc = c.scene_param("-silo_orifice_x"), zc = c.scene_param("-silo_orifice_z");
  if (!(D > 0)) return; // refused by its range
  const double h = (c.hi[0] - c.lo[0]) / c.cells[0], r2 = 0.25 * D * D * (1 - 1e-9);
  long open = 0;
  for (int i = 0; i <= c.cells[0]; ++i) {
    const double dx = c.lo[0] + i * h - xc;
    if (c.dim == 2) open += dx * dx < r2;
    else
      for (int k = 0; k <= c.cells[2]; ++k) {
        const double dz = c.lo[2] + k * h - zc;
        open += dx * dx + dz * dz < r2;
      }
  }
  if (open == 0)
    out.push_back({true, "-silo_orifice " + fmt(D) + " m centred at -silo_orifice_x " + fmt(xc) + (c.dim == 3 ? ", -silo_orifice_z " + fmt(zc) : std::string()) +
                             " opens no node of the plate (cell size " + fmt(h) + " m): nothing could flow out; widen the orifice, move it into the domain, or refine -cells"});
  else if (scene_has_reference(c) && D < 5 * c.gran.d)
    out.push_back({false, "-silo_orifice " + fmt(D) + " m is narrower than 5 grain diameters (-d " + fmt(c.gran.d) + "): a real silo would jam (arching); the continuum model does not"});
}

template <int dim>
void SiloScene<dim>::finalize(State<dim> &sim, Metrics &metrics) {
  const Config &c = sim.cfg;
  double rate = 0;
  size_t first = 0;
  while (first < silo_.size() && silo_[first][1] <= 0) ++first;
  if (first + 3 < silo_.size()) {
    const double t0 = silo_[first][0], t1 = silo_.back()[0];
    double st = 0, sm = 0, stt = 0, stm = 0, n = 0;
    for (size_t i = first; i < silo_.size(); ++i) {
      const double t = silo_[i][0];
      if (t < t0 + 0.2 * (t1 - t0) || t > t0 + 0.8 * (t1 - t0)) continue;
      st += t;
      sm += silo_[i][1];
      stt += t * t;
      stm += t * silo_[i][1];
      n += 1;
    }
    if (n > 2) rate = (n * stm - st * sm) / (n * stt - st * st);
  }
  metrics["discharge_rate"] = rate;
  metrics["orifice_effective"] = sim.template find<SiloPlate<dim>>()->effective_width(sim.grid);
  metrics["discharged_mass"] = sim.particles.removed_mass_total;
  metrics["discharged_particles"] = (double)sim.particles.removed_total;
  if (sim.rank != 0) return;
  std::FILE *f = open_csv(c.output_dir, "silo.csv");
  std::fprintf(f, "t,discharged_mass,discharged_particles\n");
  const size_t stride = std::max<size_t>(1, silo_.size() / 2000);
  for (size_t i = 0; i < silo_.size(); i += stride) std::fprintf(f, "%.6e,%.6e,%.0f\n", silo_[i][0], silo_[i][1], silo_[i][2]);
  close_atomic(f);
  f = open_csv(c.output_dir, "silo_summary.csv");
  std::fprintf(f, "orifice,orifice_effective,discharge_rate,discharged_mass,discharged_particles,time\n%.6e,%.6e,%.6e,%.6e,%ld,%.6e\n", c.scene_param("-silo_orifice"),
               metrics["orifice_effective"], rate,
               sim.particles.removed_mass_total, sim.particles.removed_total, sim.time);
  close_atomic(f);
  std::printf("silo: orifice D = %g m (on the grid: %g m between the innermost sticky plate nodes): %ld particles (%.6g kg%s) discharged; discharge rate %.6g kg/s%s (fit over the middle 60%% of the discharge; %s/silo.csv)\n",
              c.scene_param("-silo_orifice"), metrics["orifice_effective"], sim.particles.removed_total, sim.particles.removed_mass_total, dim == 2 ? " per m depth" : "", rate,
              dim == 2 ? " per m depth" : "", c.output_dir.c_str());
}

} // namespace

GM_SCENE(silo, SiloScene)

} // namespace granmpm
