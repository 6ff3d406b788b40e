#include "granmpm/scene.hpp"

#include <cmath>
#include <cstdio>
#include <algorithm>
#include <filesystem>

#include "granmpm/annulus_reference.hpp"
#include "granmpm/chute_reference.hpp"
#include "granmpm/modules.hpp"
#include "granmpm/option_names.hpp"
#include "granmpm/output.hpp"

namespace granmpm {

namespace {
const double kPi = 3.14159265358979323846;

// Strain energy density sigma : C^-1 : sigma / 2 for isotropic elasticity.
double strain_energy_density(const ElasticModuli &el, const double *s6) {
  const double p = pressure6(s6), tau = tau6(s6);
  // dev:dev = 2 tau^2 ; tr^2 = 9 p^2
  return 0.5 * (2.0 * tau * tau / (2.0 * el.G) + 9.0 * p * p / (9.0 * el.K));
}

// CSV results are written under a temporary name and published by close_atomic (fsync,
// rename), so that a failed write never leaves a partial file (output.hpp).
std::FILE *open_csv(const std::string &dir, const std::string &name) { return open_atomic(dir + "/" + name); }
} // namespace

bool scene_has_reference(const Config &c) {
  return c.material == MaterialKind::MuI || c.material == MaterialKind::Nonlocal || c.material == MaterialKind::Dynamic;
}

std::vector<BodySpec> scene_bodies(const Config &c, std::vector<std::string> &names) {
  names.clear();
  if (c.scene != SceneKind::Annulus) {
    for (size_t k = 0; k < c.bodies.size(); ++k) names.push_back("-body" + std::to_string(c.bodies[k].index) + "_shape " + name_of(c.bodies[k].shape));
    return c.bodies;
  }
  // Annulus: centred in the domain; inner disk rotating, outer ring fixed, both sticky.
  BodySpec in, out;
  for (int d = 0; d < 2; ++d) in.center[d] = out.center[d] = 0.5 * (c.lo[d] + c.hi[d]);
  in.shape = BodyShape::Disk;
  in.radius = c.annulus_ri;
  in.omega = c.annulus_omega;
  out.shape = BodyShape::Ring;
  out.radius = c.annulus_ro;
  names = {"the annulus inner disk, -annulus_ri/-annulus_omega", "the annulus outer ring, -annulus_ro"};
  return {in, out};
}

template <int dim>
Scene<dim>::Scene(State<dim> &sim) {
  (void)sim;
}

template <int dim>
void Scene<dim>::lattice_position(const Config &cfg, const Grid<dim> &grid, int64_t id, double *X) {
  for (int d = 0; d < dim; ++d) {
    const int64_t n = (int64_t)grid.ncell[d] * cfg.ppc;
    const int64_t q = id % n;
    id /= n;
    X[d] = grid.lo[d] + (q + 0.5) / cfg.ppc * grid.h;
  }
}

template <int dim>
void Scene<dim>::initialize(State<dim> &sim) {
  const Config &c = sim.cfg;
  ParticleView<dim> P = sim.particles.get();
  double centre[3] = {0, 0, 0};
  for (int d = 0; d < dim; ++d) centre[d] = 0.5 * (std::max(c.body_lo[d], c.lo[d]) + std::min(c.body_hi[d], c.hi[d]));
  const ElasticModuli el = ElasticModuli::from_E_nu(c.E, c.nu);
  for (PetscInt p = 0; p < P.n; ++p) {
    const double *x = P.x + p * dim;
    double *v = P.v + p * dim, *s = P.s + 6 * p;
    for (int q = 0; q < 6; ++q) s[q] = 0;
    for (int d = 0; d < dim; ++d) v[d] = 0;
    switch (c.scene) {
    case SceneKind::Block:
      for (int d = 0; d < dim; ++d) v[d] = c.v0[d];
      v[0] += -c.spin * (x[1] - centre[1]);
      v[1] += c.spin * (x[0] - centre[0]);
      s[0] = s[1] = s[2] = -c.p0;
      break;
    case SceneKind::Bar: {
      const double L = std::min(c.body_hi[0], c.hi[0]) - c.lo[0];
      v[0] = c.bar_amplitude * std::sin(kPi * (x[0] - c.lo[0]) / (2 * L));
      break;
    }
    case SceneKind::Column:
    case SceneKind::Collapse:
    case SceneKind::Silo: break;
    case SceneKind::Annulus: // at rest, isotropic pressure
      s[0] = s[1] = s[2] = -c.p0;
      if (dim == 3) { // Taylor-Couette: plus the lithostatic stress under gravity along -z (uniaxial strain, K0)
        const double top = std::min(c.body_hi[2], c.hi[2]), szz = -c.rho * std::fabs(c.gravity[2]) * (top - x[dim - 1]);
        s[2] += szz;
        s[0] += c.nu / (1 - c.nu) * szz;
        s[1] += c.nu / (1 - c.nu) * szz;
      }
      break;
    case SceneKind::Chute:
      s[0] = s[1] = s[2] = -c.p0;
      // Optionally start from the steady shear stress sigma_xy = -rho g_y (x - x_centre),
      // as the seed's public code does (with -gravity_ramp 0 the flow then starts at once).
      if (c.chute_prestress) s[3] = -c.rho * c.gravity[1] * (x[0] - 0.5 * (c.lo[0] + c.hi[0]));
      break;
    }
  }
  if (c.geostatic) {
    // sigma_yy = -rho |g| (top - y), lateral K0 = nu/(1 - nu) of it (uniaxial strain).
    const double top = std::min(c.body_hi[1], c.hi[1]), gy = std::fabs(c.gravity[1]), K0 = c.nu / (1 - c.nu);
    for (PetscInt p = 0; p < P.n; ++p) {
      double *s = P.s + 6 * p;
      const double syy = -c.rho * gy * (top - P.x[p * dim + 1]);
      s[1] += syy;
      s[0] += K0 * syy;
      s[2] += K0 * syy;
    }
  }
  (void)el;
  sim.particles.restore(P);
}

// ---------------------------------------------------------------------------------------
// Bar: first axial mode of a bar fixed at X = 0 and free at X = L, laterally constrained
// (periodic sides, plane strain), so its wave speed is c = sqrt(M/rho), M = K + 4G/3
// (= E for nu = 0): v(X,t) = A sin(pi X / 2L) cos(omega t), omega = pi c / (2L).

template <int dim>
void Scene<dim>::bar_sample(State<dim> &sim) {
  const Config &c = sim.cfg;
  const ElasticModuli el = ElasticModuli::from_E_nu(c.E, c.nu);
  const double L = std::min(c.body_hi[0], c.hi[0]) - c.lo[0]; // bar length (the domain may be longer)
  const double cw = std::sqrt(el.p_wave() / c.rho), omega = kPi * cw / (2 * L);
  ParticleView<dim> P = sim.particles.get();
  double loc[6] = {0, 0, 0, 0, 0, 0}; // KE, SE, sum m (v-ve)^2, sum m, sum m v, KE exact
  for (PetscInt p = 0; p < P.n; ++p) {
    double X[3];
    lattice_position(c, sim.grid, P.id[p], X);
    const double ve = c.bar_amplitude * std::sin(kPi * (X[0] - c.lo[0]) / (2 * L)) * std::cos(omega * sim.time);
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
  const double vcm_exact = c.bar_amplitude * (2.0 / kPi) * std::cos(omega * sim.time);
  series_.push_back({sim.time, g[0], g[1], g[5], g[0] + g[1], g[4] / g[3], vcm_exact, std::sqrt(g[2] / g[3])});
}

template <int dim>
void Scene<dim>::bar_finalize(State<dim> &sim) {
  if (series_.empty()) return;
  const double A = sim.cfg.bar_amplitude;
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

// ---------------------------------------------------------------------------------------
// Column: at equilibrium sigma_yy(Y) = -rho g (Y_top - Y) in the reference configuration
// (the weight of the material above, whatever the elastic compression).

template <int dim>
void Scene<dim>::column_finalize(State<dim> &sim) {
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
    lattice_position(c, sim.grid, r.id, X);
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

// ---------------------------------------------------------------------------------------
// Chute: vy averaged over the particles of each grid column, against the local analytic
// profile and the nonlocal 1D finite-difference reference for the run's parameters.
// The particle velocity used is the grid velocity interpolated to the particle (what it
// moves with): with FLIP, particle velocities next to a sticky wall keep a spurious
// offset that P2G does not see (the wall node's increment -v acts on them every step).

template <int dim>
void Scene<dim>::chute_finalize(State<dim> &sim) {
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

// ---------------------------------------------------------------------------------------
// Column collapse: a column of width L0 and height H0 = a L0 against the wall at
// x = domain_lo collapses along x. Runout L_f: the tip of the deposit (the furthest
// particle, what the experiments measure; the mass-weighted 99% front is reported too),
// against the 2D laws of Lube et al. (2005): (L_f - L0)/L0 = 1.2 a for a < 1.8 and
// 1.9 a^(2/3) for a > 2.8; in between (the transition) both are reported.

template <int dim>
void Scene<dim>::collapse_finalize(State<dim> &sim) {
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
  metrics["lube_runout"] = lube;
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
  std::printf("collapse: a = %.3g: runout (L_f - L0)/L0 = %.4g (deposit tip; 99%% mass front %.4g); Lube et al. 2005: %.4g (%s); final height H_f/L0 = %.4g (%s/collapse.csv)\n",
              a, runout, metrics["runout_99"], lube, a <= 1.8 ? "1.2 a" : (a >= 2.8 ? "1.9 a^(2/3)" : "between 1.2 a and 1.9 a^(2/3), interpolated"),
              metrics["final_height"], c.output_dir.c_str());
}

// ---------------------------------------------------------------------------------------
// Silo: particles leaving through the outlet below the plate are counted; the discharge
// rate is the slope of the discharged mass against time, fitted over the middle of the
// discharge (from 20% to 80% of the time after the first particle left).

template <int dim>
void Scene<dim>::silo_finalize(State<dim> &sim) {
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

// ---------------------------------------------------------------------------------------
// Annulus: v_theta = e_theta . v (about the disk centre) averaged over the particles of
// radial bins one cell wide from Ri, against the local or nonlocal 1D reference at the
// bins' mean radius. Like the chute, the velocity used is the grid velocity interpolated
// to the particle. Also reports the mean pressure and the torque on the inner disk
// (from bodies.csv's force sums) against the reference's 2 pi T per unit depth.

template <int dim>
void Scene<dim>::annulus_finalize(State<dim> &sim) {
  const Config &c = sim.cfg;
  if (dim == 3) return taylor_couette_finalize(sim);
  const double cx = 0.5 * (c.lo[0] + c.hi[0]), cy = 0.5 * (c.lo[1] + c.hi[1]);
  const double h = sim.grid.h, Ri = c.annulus_ri, Ro = c.annulus_ro;
  const int nb = std::max(1, (int)std::ceil((Ro - Ri) / h));
  const int W = 9; // per bin: count, r, v_theta, p, v_r, s_rr, s_tt, s_zz, s_rt
  std::vector<double> loc(W * nb + 2, 0.0), glob(W * nb + 2, 0.0);
  const std::vector<double> vg = sim.grid_velocity_at_particles();
  ParticleView<dim> P = sim.particles.get();
  for (PetscInt p = 0; p < P.n; ++p) {
    const double dx = P.x[p * dim] - cx, dy = P.x[p * dim + 1] - cy, r = std::hypot(dx, dy);
    const int b = std::min(nb - 1, std::max(0, (int)std::floor((r - Ri) / h)));
    const double vt = r > 0 ? (-dy * vg[(size_t)p * dim] + dx * vg[(size_t)p * dim + 1]) / r : 0.0;
    const double vr = r > 0 ? (dx * vg[(size_t)p * dim] + dy * vg[(size_t)p * dim + 1]) / r : 0.0;
    // Polar components of the stress: e_r = (c, s), e_theta = (-s, c).
    const double *S = P.s + 6 * p, cs = r > 0 ? dx / r : 1.0, sn = r > 0 ? dy / r : 0.0;
    const double srr = cs * cs * S[0] + sn * sn * S[1] + 2 * cs * sn * S[3];
    const double stt = sn * sn * S[0] + cs * cs * S[1] - 2 * cs * sn * S[3];
    const double srt = cs * sn * (S[1] - S[0]) + (cs * cs - sn * sn) * S[3];
    double *L = &loc[(size_t)W * b];
    L[0] += 1;
    L[1] += r;
    L[2] += vt;
    L[3] += pressure6(S);
    L[4] += vr;
    L[5] += srr;
    L[6] += stt;
    L[7] += S[2];
    L[8] += srt;
    loc[W * nb] += P.vol[p] * pressure6(S);
    loc[W * nb + 1] += P.vol[p];
  }
  sim.particles.restore(P);
  MPI_Allreduce(loc.data(), glob.data(), W * nb + 2, MPI_DOUBLE, MPI_SUM, sim.comm);
  AnnulusParams ap;
  ap.gp = c.gran;
  ap.Ri = Ri;
  ap.Ro = Ro;
  ap.Omega = c.annulus_omega;
  ap.p = c.p0;
  ap.zero_g_walls = c.body_fluidity_bc == BodyFluidityBC::Zero;
  if (!scene_has_reference(c) || c.material == MaterialKind::Dynamic) { // the 1D references: mu(I) and the steady nonlocal model only
    if (sim.rank == 0) {
      std::FILE *f = open_csv(c.output_dir, "profile.csv");
      std::fprintf(f, "r,v_theta,p,v_r,s_rr,s_tt,s_zz,s_rt\n");
      for (int b = 0; b < nb; ++b) {
        const double *G = &glob[(size_t)W * b], n = G[0];
        if (n > 0) std::fprintf(f, "%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.9e\n", G[1] / n, G[2] / n, G[3] / n, G[4] / n, G[5] / n, G[6] / n, G[7] / n, G[8] / n);
      }
      close_atomic(f);
    }
    metrics["mean_pressure"] = glob[W * nb + 1] > 0 ? glob[W * nb] / glob[W * nb + 1] : 0;
    if (sim.bodies) metrics["inner_torque"] = sim.bodies->forces()[3];
    if (sim.rank == 0)
      std::printf("annulus: reference skipped: the 1D references cover -material mu_i|nonlocal (got %s); v_theta(r) in %s/profile.csv; mean pressure %.6g Pa, torque on the inner disk %.6g N m/m\n",
                  to_string(c.material), c.output_dir.c_str(), metrics["mean_pressure"], metrics["inner_torque"]);
    return;
  }
  const bool local = c.material == MaterialKind::MuI;
  const AnnulusReference lr(ap, true), nr(ap, false, 4001);
  const AnnulusReference &ref = local ? lr : nr;
  double e2 = 0, r2 = 0;
  std::FILE *f = sim.rank == 0 ? open_csv(c.output_dir, "profile.csv") : nullptr;
  if (f) std::fprintf(f, "r,v_theta,v_ref,v_ref_local,v_ref_nonlocal,p,v_r,s_rr,s_tt,s_zz,s_rt,s_rt_r2\n");
  for (int b = 0; b < nb; ++b) {
    const double *G = &glob[(size_t)W * b], n = G[0];
    if (n == 0) continue;
    const double r = G[1] / n, vt = G[2] / n, v = ref.v_theta(r);
    e2 += (vt - v) * (vt - v);
    r2 += v * v;
    if (f)
      std::fprintf(f, "%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.9e\n", r, vt, v, lr.v_theta(r), nr.v_theta(r), G[3] / n, G[4] / n, G[5] / n,
                   G[6] / n, G[7] / n, G[8] / n, G[8] / n * r * r);
  }
  if (f) close_atomic(f);
  if (sim.rank == 0) { // the references on a fine radial grid, for plots
    std::FILE *g = open_csv(c.output_dir, "reference.csv");
    std::fprintf(g, "r,v_local,v_nonlocal\n");
    for (int i = 0; i <= 400; ++i) {
      const double r = Ri + (Ro - Ri) * i / 400.0;
      std::fprintf(g, "%.9e,%.9e,%.9e\n", r, lr.v_theta(r), nr.v_theta(r));
    }
    close_atomic(g);
  }
  metrics["l2_abs"] = std::sqrt(e2);
  metrics["l2_rel"] = r2 > 0 ? std::sqrt(e2 / r2) : 0;
  metrics["mean_pressure"] = glob[W * nb + 1] > 0 ? glob[W * nb] / glob[W * nb + 1] : 0;
  metrics["reference_torque"] = 2 * kPi * ref.T(); // per unit depth: tau(Ri) Ri * 2 pi Ri
  if (sim.bodies) metrics["inner_torque"] = sim.bodies->forces()[3];
  metrics["yield_radius_local"] = lr.yield_radius();
  if (sim.rank == 0) {
    std::printf("annulus: v_theta against the %s reference at t = %g s: L2 error absolute %.4e m/s, relative %.4e (%s/profile.csv)\n",
                local ? "local mu(I) (closed form, T by bisection)"
                      : ap.zero_g_walls ? "nonlocal 1D finite-difference (4001 points, g = 0 at the walls, T by bisection)"
                                        : "nonlocal 1D finite-difference (4001 points, zero flux at the walls, T by bisection)",
                sim.time,
                metrics["l2_abs"], metrics["l2_rel"], c.output_dir.c_str());
    std::printf("annulus: mean pressure %.6g Pa (reference assumes p0 = %g Pa); torque on the inner disk %.6g N m/m, reference 2 pi T = %.6g N m/m\n",
                metrics["mean_pressure"], c.p0, metrics["inner_torque"], metrics["reference_torque"]);
  }
}

// ---------------------------------------------------------------------------------------
// 3D Taylor-Couette (seed 004 section 4.1): the normalised angular velocity omega(r)/Omega
// at the top surface, as the seed plots it. The surface is free and may deform, so the
// top layer is taken per radial bin (one cell wide from Ri): the particles within one cell
// of the highest particle of their bin. No reference in 3D: the seed compares with
// experiment and FEM. Also written: the mean over the whole depth, the top layer's
// pressure (for the inertial number) and the torque on the inner cylinder.

template <int dim>
void Scene<dim>::taylor_couette_finalize(State<dim> &sim) {
  const Config &c = sim.cfg;
  const double cx = 0.5 * (c.lo[0] + c.hi[0]), cy = 0.5 * (c.lo[1] + c.hi[1]);
  const double h = sim.grid.h, Ri = c.annulus_ri, Ro = c.annulus_ro, d = c.gran.d, Om = c.annulus_omega;
  const int nb = std::max(1, (int)std::ceil((Ro - Ri) / h));
  const std::vector<double> vg = sim.grid_velocity_at_particles();
  ParticleView<dim> P = sim.particles.get();
  std::vector<double> r(P.n), vt(P.n);
  std::vector<int> bin(P.n);
  std::vector<double> zloc(nb, -1e300), ztop(nb);
  for (PetscInt p = 0; p < P.n; ++p) {
    const double dx = P.x[p * dim] - cx, dy = P.x[p * dim + 1] - cy;
    r[p] = std::hypot(dx, dy);
    vt[p] = r[p] > 0 ? (-dy * vg[(size_t)p * dim] + dx * vg[(size_t)p * dim + 1]) / r[p] : 0.0;
    bin[p] = std::min(nb - 1, std::max(0, (int)std::floor((r[p] - Ri) / h)));
    zloc[bin[p]] = std::max(zloc[bin[p]], P.x[p * dim + dim - 1]);
  }
  MPI_Allreduce(zloc.data(), ztop.data(), nb, MPI_DOUBLE, MPI_MAX, sim.comm);
  const int W = 7; // per bin: top count, r, v_theta, p, z; all count, v_theta
  std::vector<double> loc(W * nb, 0.0), glob(W * nb, 0.0);
  for (PetscInt p = 0; p < P.n; ++p) {
    double *L = &loc[(size_t)W * bin[p]];
    const double z = P.x[p * dim + dim - 1];
    if (z >= ztop[bin[p]] - h) {
      L[0] += 1;
      L[1] += r[p];
      L[2] += vt[p];
      L[3] += pressure6(P.s + 6 * p);
      L[4] += z;
    }
    L[5] += 1;
    L[6] += r[p] > 0 ? vt[p] / r[p] : 0.0;
  }
  sim.particles.restore(P);
  MPI_Allreduce(loc.data(), glob.data(), W * nb, MPI_DOUBLE, MPI_SUM, sim.comm);
  std::FILE *f = sim.rank == 0 ? open_csv(c.output_dir, "profile.csv") : nullptr;
  if (f) std::fprintf(f, "r,xi_d,xi_gap,omega_over_Omega,v_theta,p,z_top,n_top,omega_over_Omega_all_depth\n");
  double wmin = 1e300;
  for (int b = 0; b < nb; ++b) {
    const double *G = &glob[(size_t)W * b], n = G[0];
    if (n == 0) continue;
    const double rb = G[1] / n, w = G[2] / n / rb / Om;
    wmin = std::min(wmin, w);
    if (f)
      std::fprintf(f, "%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.9e,%.0f,%.9e\n", rb, (rb - Ri) / d, (rb - Ri) / (Ro - Ri), w, G[2] / n, G[3] / n, G[4] / n, n,
                   G[6] / G[5] / Om);
  }
  if (f) close_atomic(f);
  if (sim.bodies) metrics["inner_torque"] = sim.bodies->forces()[3]; // fx, fy, fz, torque about z
  metrics["omega_min_top"] = wmin;
  if (sim.rank == 0)
    std::printf("taylor-couette: omega/Omega at the top surface in %d radial bins of h = %g m = %g d at t = %g s (%s/profile.csv); smallest %.4e; torque on the inner cylinder %.6g N m\n",
                nb, h, h / d, sim.time, c.output_dir.c_str(), wmin, metrics["inner_torque"]);
}

template <int dim>
void Scene<dim>::on_step(State<dim> &sim) {
  if (sim.cfg.scene == SceneKind::Bar) bar_sample(sim);
  if (sim.cfg.scene == SceneKind::Silo) silo_.push_back({sim.time, sim.particles.removed_mass_total, (double)sim.particles.removed_total});
}

template <int dim>
void Scene<dim>::finalize(State<dim> &sim) {
  switch (sim.cfg.scene) {
  case SceneKind::Bar: bar_finalize(sim); break;
  case SceneKind::Column: column_finalize(sim); break;
  case SceneKind::Chute: chute_finalize(sim); break;
  case SceneKind::Collapse: collapse_finalize(sim); break;
  case SceneKind::Silo: silo_finalize(sim); break;
  case SceneKind::Annulus: annulus_finalize(sim); break;
  case SceneKind::Block: {
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
    break;
  }
  }
}

template class Scene<2>;
template class Scene<3>;

} // namespace granmpm
