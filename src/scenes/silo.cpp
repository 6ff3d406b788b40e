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
  void add_modules(State<dim> &sim, std::vector<std::unique_ptr<Module<dim>>> &modules) const override {
    const Config &c = sim.cfg;
    modules.push_back(std::make_unique<SiloPlate<dim>>(sim.grid, c.silo_plate_y, c.silo_orifice, c.silo_orifice_x, c.silo_orifice_z));
  }
  void validate(const Config &c) const override {
    if (!(c.silo_plate_y > c.lo[1] && c.silo_plate_y < c.hi[1])) bad("-silo_plate_y must lie inside the domain in y (got " + fmt(c.silo_plate_y) + ")");
    if (!(c.silo_orifice > 0)) bad("-silo_orifice must be > 0 (got " + fmt(c.silo_orifice) + ")");
    if (c.bc[1][0] != BC::Outlet) bad("-scene silo: particles leave below the plate, set -bc_ylo outlet");
  }
  void signature(const Config &c, Signature &s) const override {
    s.push_back({"-silo_plate_y", exact(c.silo_plate_y)});
    s.push_back({"-silo_orifice", exact(c.silo_orifice)});
    s.push_back({"-silo_orifice_x", exact(c.silo_orifice_x)});
    if (c.dim == 3) s.push_back({"-silo_orifice_z", exact(c.silo_orifice_z)});
  }
  void on_step(State<dim> &sim) override { silo_.push_back({sim.time, sim.particles.removed_mass_total, (double)sim.particles.removed_total}); }
  void finalize(State<dim> &sim, Metrics &metrics) override;

private:
  std::vector<std::array<double, 3>> silo_; // t, discharged mass, discharged particles
};

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
  std::fprintf(f, "orifice,orifice_effective,discharge_rate,discharged_mass,discharged_particles,time\n%.6e,%.6e,%.6e,%.6e,%ld,%.6e\n", c.silo_orifice,
               metrics["orifice_effective"], rate,
               sim.particles.removed_mass_total, sim.particles.removed_total, sim.time);
  close_atomic(f);
  std::printf("silo: orifice D = %g m (on the grid: %g m between the innermost sticky plate nodes): %ld particles (%.6g kg%s) discharged; discharge rate %.6g kg/s%s (fit over the middle 60%% of the discharge; %s/silo.csv)\n",
              c.silo_orifice, metrics["orifice_effective"], sim.particles.removed_total, sim.particles.removed_mass_total, dim == 2 ? " per m depth" : "", rate,
              dim == 2 ? " per m depth" : "", c.output_dir.c_str());
}

} // namespace

GM_SCENE(silo, SiloScene)

} // namespace granmpm
