#include <algorithm>
#include <cmath>
#include <cstdio>

#include "granmpm/chute_reference.hpp"
#include "scene_util.hpp"

namespace granmpm {

using namespace scene_util;

namespace {
// ---------------------------------------------------------------------------------------
// Chute: vy averaged over the particles of each grid column, against the local analytic
// profile and the nonlocal 1D finite-difference reference for the run's parameters.
// The particle velocity used is the grid velocity interpolated to the particle (what it
// moves with): with FLIP, particle velocities next to a sticky wall keep a spurious
// offset that P2G does not see (the wall node's increment -v acts on them every step).

template <int dim>
class ChuteScene final : public SceneCase<dim> {
public:
  const std::vector<SceneOption> &options() const override {
    static const std::vector<SceneOption> o = {{{"-chute_prestress", "Start from the steady shear stress (use with -gravity_ramp 0)", 0}, true}};
    return o;
  }
  void init_particle(const Config &c, const double *, const double *x, double *, double *s) const override {
    s[0] = s[1] = s[2] = -c.p0;
    // Optionally start from the steady shear stress sigma_xy = -rho g_y (x - x_centre),
    // as the seed's public code does (with -gravity_ramp 0 the flow then starts at once).
    if (c.scene_param("-chute_prestress") != 0) s[3] = -c.rho * c.gravity[1] * (x[0] - 0.5 * (c.lo[0] + c.hi[0]));
  }
  void validate(const Config &c) const override {
    if (!c.is_periodic(1)) bad("-scene chute: the chute is periodic in y (set -bc_ylo periodic -bc_yhi periodic)");
  }
  void checks(const Config &c, std::vector<Finding> &out) const override {
    check_initial_pressure(c, out);
    if (c.p0 == 0)
      out.push_back({true, "-scene chute with -p0 0: the chute has no confining pressure, so no frictional strength, and its reference mu = tau/p is undefined (NaN); set -p0 > 0"});
  }
  void finalize(State<dim> &sim, Metrics &metrics) override;
};

// (84 lines: the column binning, the reduction and the comparison against the three
// references write one CSV row per column in one loop; splitting it would pass the bins
// and all references between functions.)
template <int dim>
void ChuteScene<dim>::finalize(State<dim> &sim, Metrics &metrics) {
  const Config &c = sim.cfg;
  const Grid<dim> &G = sim.grid;
  const int nc = G.ncell[0];
  std::vector<double> loc(3 * nc, 0.0), glob(3 * nc, 0.0);
  const std::vector<double> vg = sim.grid_velocity_at_particles();
  ParticleView<dim> P = sim.particles.get();
  for (PetscInt p = 0; p < P.n; ++p) {
    const double x = P.x[p * dim];
    const int col = std::min(nc - 1, std::max(0, (int)std::floor((x - c.lo[0]) / G.h)));
    loc[3 * col] += 1;
    loc[3 * col + 1] += x;
    loc[3 * col + 2] += vg[(size_t)p * dim + 1];
  }
  sim.particles.restore(P);
  MPI_Allreduce(loc.data(), glob.data(), 3 * nc, MPI_DOUBLE, MPI_SUM, sim.comm);
  // The references are mu(I)'s, the steady nonlocal model's and the dynamical model's steady
  // state; for elastic, hypoelastic and Drucker-Prager materials none applies.
  if (!scene_has_reference(c)) {
    if (sim.rank == 0) {
      std::FILE *f = open_csv(c.output_dir, "profile.csv");
      std::fprintf(f, "x,vy\n");
      for (int i = 0; i < nc; ++i)
        if (glob[3 * i] > 0) std::fprintf(f, "%.9e,%.9e\n", glob[3 * i + 1] / glob[3 * i] - c.lo[0], glob[3 * i + 2] / glob[3 * i]);
      close_atomic(f);
      std::printf("chute: reference skipped: the 1D references cover -material mu_i|nonlocal|dynamic (got %s); vy(x) in %s/profile.csv\n", to_string(c.material),
                  c.output_dir.c_str());
    }
    return;
  }
  ChuteParams cp;
  cp.gp = c.gran;
  cp.L = c.hi[0] - c.lo[0];
  cp.rho = c.rho;
  cp.g = std::fabs(c.gravity[1]);
  cp.p0 = c.p0;
  const double sign = c.gravity[1] < 0 ? -1.0 : 1.0;
  const NonlocalChuteReference nl(cp, 5001);
  const DynamicChuteReference dy(cp, 5001);
  const bool local = c.material == MaterialKind::MuI;
  const bool dynamic = c.material == MaterialKind::Dynamic;
  double e2 = 0, r2 = 0;
  std::FILE *f = sim.rank == 0 ? open_csv(c.output_dir, "profile.csv") : nullptr;
  if (f) std::fprintf(f, "x,vy,vy_ref,vy_ref_local,vy_ref_nonlocal,vy_ref_dynamic,vy_ref_column_mean\n");
  double e2s = 0, r2s = 0; // dynamical model against the steady nonlocal reference
  double e2c = 0, r2c = 0; // against the column mean of the reference (issue 15)
  auto ref_at = [&](double s) { return sign * (dynamic ? dy.speed(s) : (local ? chute_local_speed(cp, s) : nl.speed(s))); };
  for (int i = 0; i < nc; ++i) {
    if (glob[3 * i] == 0) continue;
    const double x = glob[3 * i + 1] / glob[3 * i], vy = glob[3 * i + 2] / glob[3 * i];
    const double s = x - 0.5 * (c.lo[0] + c.hi[0]);
    const double vl = sign * chute_local_speed(cp, s), vn = sign * nl.speed(s), vd = sign * dy.speed(s);
    const double ref = dynamic ? vd : (local ? vl : vn);
    // The particles' column mean estimates the mean of the velocity field over the column,
    // so the like-for-like reference is the mean of the reference over the column (composite
    // Simpson, 64 intervals), not its value at the particles' mean x (which differs by
    // h^2 v''/24 + O(h^4) at the column centre).
    const double s0 = c.lo[0] + i * G.h - 0.5 * (c.lo[0] + c.hi[0]);
    double cm = 0;
    for (int q = 0; q <= 64; ++q) cm += (q == 0 || q == 64 ? 1.0 : (q % 2 ? 4.0 : 2.0)) * ref_at(s0 + G.h * q / 64.0);
    cm /= 3.0 * 64.0;
    e2 += (vy - ref) * (vy - ref);
    r2 += ref * ref;
    e2c += (vy - cm) * (vy - cm);
    r2c += cm * cm;
    e2s += (vy - vn) * (vy - vn);
    r2s += vn * vn;
    if (f) std::fprintf(f, "%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.9e\n", x - c.lo[0], vy, ref, vl, vn, vd, cm);
  }
  if (f) close_atomic(f);
  metrics["l2_abs"] = std::sqrt(e2);
  metrics["l2_rel"] = r2 > 0 ? std::sqrt(e2 / r2) : 0;
  metrics["l2_abs_column_mean"] = std::sqrt(e2c);
  metrics["l2_rel_column_mean"] = r2c > 0 ? std::sqrt(e2c / r2c) : 0;
  metrics["l2_rel_steady_nonlocal"] = r2s > 0 ? std::sqrt(e2s / r2s) : 0;
  if (sim.rank == 0) {
    std::printf("chute: vy against the %s reference at t = %g s: L2 error absolute %.4e m/s, relative %.4e (%s/profile.csv)\n",
                dynamic ? "dynamical-model steady 1D finite-difference (5001 points, Newton)"
                        : (local ? "local analytic" : "nonlocal 1D finite-difference (5001 points)"),
                sim.time, metrics["l2_abs"], metrics["l2_rel"], c.output_dir.c_str());
    std::printf("chute: against the column means of the reference (like the particles' column means): L2 error absolute %.4e m/s, relative %.4e\n",
                metrics["l2_abs_column_mean"], metrics["l2_rel_column_mean"]);
    if (dynamic) std::printf("chute: against the steady nonlocal reference the relative L2 difference is %.4e\n", metrics["l2_rel_steady_nonlocal"]);
  }
}

} // namespace

GM_SCENE(chute, ChuteScene)

} // namespace granmpm
