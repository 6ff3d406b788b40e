#include <algorithm>
#include <cmath>
#include <cstdio>

#include "scene_util.hpp"

namespace granmpm {

using namespace scene_util;

namespace {
// ---------------------------------------------------------------------------------------
// Bar: first axial mode of a bar fixed at X = 0 and free at X = L, laterally constrained
// (periodic sides, plane strain), so its wave speed is c = sqrt(M/rho), M = K + 4G/3
// (= E for nu = 0): v(X,t) = A sin(pi X / 2L) cos(omega t), omega = pi c / (2L).

template <int dim>
class BarScene final : public SceneCase<dim> {
public:
  const std::vector<SceneOption> &options() const override {
    static const std::vector<SceneOption> o = {{{"-bar_amplitude", "First-mode velocity amplitude [m/s]", 0.1}}};
    return o;
  }
  void init_particle(const Config &c, const double *, const double *x, double *v, double *) const override {
    const double L = std::min(c.body_hi[0], c.hi[0]) - c.lo[0];
    v[0] = c.scene_param("-bar_amplitude") * std::sin(kPi * (x[0] - c.lo[0]) / (2 * L));
  }
  void validate(const Config &c) const override {
    if (c.bc[0][0] != BC::Sticky) bad("-scene bar: the bar is fixed at x = domain_lo (set -bc_xlo sticky)");
  }
  void checks(const Config &c, std::vector<Finding> &out) const override;
  void on_step(State<dim> &sim) override;
  void finalize(State<dim> &sim, Metrics &metrics) override;

private:
  std::vector<std::array<double, 8>> series_;
};

// The first-mode strain amplitude is A / c (c the wave speed): the analytic reference is a
// small-strain one; A >= c would invert the bar.
template <int dim>
void BarScene<dim>::checks(const Config &c, std::vector<Finding> &out) const {
  const double a = c.scene_param("-bar_amplitude"), A = std::fabs(a), c_wave = wave_speed(c);
  double vmax = 0;
  for (int d = 0; d < c.dim; ++d) vmax = std::max(vmax, std::fabs(c.v0[d]));
  if (std::isfinite(c_wave) && c_wave > 0 && vmax < 2.99792458e8) { // else refused by physics_checks
    if (A >= c_wave)
      out.push_back({true, "-bar_amplitude " + fmt(a) + " m/s reaches the wave speed " + fmt(c_wave) + " m/s: a strain amplitude v/c >= 1 inverts the bar; lower it below " + fmt(0.1 * c_wave)});
    else if (A > 0.1 * c_wave)
      out.push_back({false, "-bar_amplitude " + fmt(a) + " m/s: strain amplitude v/c = " + fmt(A / c_wave) + " is beyond small strains; the analytic reference of the bar does not apply"});
  }
  check_speed(out, "-bar_amplitude", A);
}

template <int dim>
void BarScene<dim>::on_step(State<dim> &sim) {
  const Config &c = sim.cfg;
  const ElasticModuli el = ElasticModuli::from_E_nu(c.E, c.nu);
  const double L = std::min(c.body_hi[0], c.hi[0]) - c.lo[0]; // bar length (the domain may be longer)
  const double cw = std::sqrt(el.p_wave() / c.rho), omega = kPi * cw / (2 * L), A = c.scene_param("-bar_amplitude");
  ParticleView<dim> P = sim.particles.get();
  double loc[6] = {0, 0, 0, 0, 0, 0}; // KE, SE, sum m (v-ve)^2, sum m, sum m v, KE exact
  for (PetscInt p = 0; p < P.n; ++p) {
    double X[3];
    Scene<dim>::lattice_position(c, sim.grid, P.id[p], X);
    const double ve = A * std::sin(kPi * (X[0] - c.lo[0]) / (2 * L)) * std::cos(omega * sim.time);
    double v2 = 0;
    for (int d = 0; d < dim; ++d) v2 += P.v[p * dim + d] * P.v[p * dim + d];
    const double dv = P.v[p * dim] - ve;
    double e2 = dv * dv;
    for (int d = 1; d < dim; ++d) e2 += P.v[p * dim + d] * P.v[p * dim + d];
    loc[0] += 0.5 * P.m[p] * v2;
    loc[1] += P.vol[p] * strain_energy_density(el, P.s + 6 * p);
    loc[2] += P.m[p] * e2;
    loc[3] += P.m[p];
    loc[4] += P.m[p] * P.v[p * dim];
    loc[5] += 0.5 * P.m[p] * ve * ve;
  }
  sim.particles.restore(P);
  double g[6];
  MPI_Allreduce(loc, g, 6, MPI_DOUBLE, MPI_SUM, sim.comm);
  const double vcm_exact = A * (2.0 / kPi) * std::cos(omega * sim.time);
  series_.push_back({sim.time, g[0], g[1], g[5], g[0] + g[1], g[4] / g[3], vcm_exact, std::sqrt(g[2] / g[3])});
}

template <int dim>
void BarScene<dim>::finalize(State<dim> &sim, Metrics &metrics) {
  if (series_.empty()) return;
  const double A = sim.cfg.scene_param("-bar_amplitude");
  const double E0 = series_.front()[4];
  double err_max = 0, err_end = series_.back()[7] / A, drift = 0, vcm_err = 0;
  for (const auto &r : series_) {
    err_max = std::max(err_max, r[7] / A);
    drift = std::max(drift, std::fabs(r[4] - E0) / E0);
    vcm_err = std::max(vcm_err, std::fabs(r[5] - r[6]) / A);
  }
  metrics["velocity_error_max"] = err_max;   // max over time of rms |v - v_exact| / A
  metrics["velocity_error_end"] = err_end;
  metrics["energy_drift_max"] = drift;       // max |E(t) - E(0)| / E(0)
  metrics["vcm_error_max"] = vcm_err;        // centre-of-mass velocity error / A
  if (sim.rank == 0) {
    std::FILE *f = open_csv(sim.cfg.output_dir, "bar.csv");
    std::fprintf(f, "t,kinetic,strain,kinetic_exact,total,v_cm,v_cm_exact,v_err_rms\n");
    for (const auto &r : series_) std::fprintf(f, "%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.9e\n", r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7]);
    close_atomic(f);
    std::printf("bar: rms velocity error / amplitude: max %.4e, at end %.4e; centre-of-mass velocity error %.4e; energy drift %.4e (%s/bar.csv)\n", err_max,
                err_end, vcm_err, drift, sim.cfg.output_dir.c_str());
  }
}

} // namespace

GM_SCENE(bar, BarScene)

} // namespace granmpm
