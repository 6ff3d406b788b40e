#include <algorithm>
#include <cmath>
#include <cstdio>

#include "granmpm/annulus_reference.hpp"
#include "scene_util.hpp"

namespace granmpm {

using namespace scene_util;

namespace {
// ---------------------------------------------------------------------------------------
// Annulus: v_theta = e_theta . v (about the disk centre) averaged over the particles of
// radial bins one cell wide from Ri, against the local or nonlocal 1D reference at the
// bins' mean radius. Like the chute, the velocity used is the grid velocity interpolated
// to the particle. Also reports the mean pressure and the torque on the inner disk
// (from bodies.csv's force sums) against the reference's 2 pi T per unit depth.

template <int dim>
class AnnulusScene final : public SceneCase<dim> {
public:
  void init_particle(const Config &c, const double *, const double *x, double *, double *s) const override { // at rest, isotropic pressure
    s[0] = s[1] = s[2] = -c.p0;
    if (dim == 3) { // Taylor-Couette: plus the lithostatic stress under gravity along -z (uniaxial strain, K0)
      const double top = std::min(c.body_hi[2], c.hi[2]), szz = -c.rho * std::fabs(c.gravity[2]) * (top - x[dim - 1]);
      s[2] += szz;
      s[0] += c.nu / (1 - c.nu) * szz;
      s[1] += c.nu / (1 - c.nu) * szz;
    }
  }
  const std::vector<SceneOption> &options() const override {
    static const std::vector<SceneOption> o = {{{"-annulus_ri", "Radius of the inner rotating disk Ri [m]", 0.2, 0, kInf, true}},
                                               {{"-annulus_ro", "Radius of the fixed outer ring Ro [m] (> Ri)", 0.4}},
                                               {{"-annulus_omega", "Angular velocity of the inner disk [rad/s] (counter-clockwise > 0)", 0.1}}};
    return o;
  }
  // Centred in the domain; inner disk rotating, outer ring fixed, both sticky.
  std::vector<BodySpec> bodies(const Config &c, std::vector<std::string> &names) const override {
    BodySpec in, out;
    for (int d = 0; d < 2; ++d) in.center[d] = out.center[d] = 0.5 * (c.lo[d] + c.hi[d]);
    in.shape = BodyShape::Disk;
    in.radius = c.scene_param("-annulus_ri");
    in.omega = c.scene_param("-annulus_omega");
    out.shape = BodyShape::Ring;
    out.radius = c.scene_param("-annulus_ro");
    names = {"the annulus inner disk, -annulus_ri/-annulus_omega", "the annulus outer ring, -annulus_ro"};
    return {in, out};
  }
  void validate(const Config &c) const override;
  void checks(const Config &c, std::vector<Finding> &out) const override {
    const double ri = c.scene_param("-annulus_ri"), ro = c.scene_param("-annulus_ro"), h = (c.hi[0] - c.lo[0]) / c.cells[0];
    check_initial_pressure(c, out);
    check_speed(out, "-annulus_omega (times -annulus_ri)", std::fabs(c.scene_param("-annulus_omega")) * ri);
    if (ro - ri < 4 * h)
      out.push_back({false, "-scene annulus: the gap -annulus_ro - -annulus_ri = " + fmt(ro - ri) + " m spans fewer than 4 cells (" + fmt(h) + " m): the shear band is not resolved"});
  }
  void finalize(State<dim> &sim, Metrics &metrics) override;

private:
  void taylor_couette_finalize(State<dim> &sim, Metrics &metrics);
};

template <int dim>
void AnnulusScene<dim>::validate(const Config &c) const {
  const char *axes = "xyz";
  const double ri = c.scene_param("-annulus_ri"), ro = c.scene_param("-annulus_ro"); // (ri > 0: its range)
  if (!(ro > ri)) bad("-annulus_ri must be < -annulus_ro (got Ri = " + fmt(ri) + ", Ro = " + fmt(ro) + ")");
  for (int d = 0; d < 2; ++d)
    if (!(0.5 * (c.hi[d] - c.lo[d]) > ro))
      bad("-scene annulus: the domain must contain the outer ring's circle (half width " + fmt(0.5 * (c.hi[d] - c.lo[d])) + " m in " + std::string(1, axes[d]) +
          " <= -annulus_ro " + fmt(ro) + "); enlarge -domain_lo/-domain_hi");
  if (c.is_periodic(0) || c.is_periodic(1)) bad("-scene annulus: the domain faces must not be periodic (set -bc_xlo/-bc_xhi/-bc_ylo/-bc_yhi sticky)");
  if (c.dim == 2 && (c.gravity[0] != 0 || c.gravity[1] != 0)) bad("-scene annulus has no gravity in 2D (its reference assumes uniform pressure): set -gravity 0,0");
  // 3D (Taylor-Couette): the cylinders' axis is z, so gravity may only act along z.
  if (c.dim == 3 && (c.gravity[0] != 0 || c.gravity[1] != 0)) bad("-scene annulus in 3D: gravity must be along the cylinders' axis z (set -gravity 0,0,gz)");
  if (!c.bodies.empty()) bad("-scene annulus builds its own two bodies from -annulus_ri/-annulus_ro/-annulus_omega: remove the -body<k>_ options");
  // Every material is accepted: the scene skips its 1D reference where it does not apply.
}

// (About 100 lines: one pass bins the particles, one reduction, then either the profile
// alone (no reference for the material) or the profile against the references; the CSV
// columns and the printed lines follow the bins' layout, so they stay together.)
template <int dim>
void AnnulusScene<dim>::finalize(State<dim> &sim, Metrics &metrics) {
  const Config &c = sim.cfg;
  if (dim == 3) return taylor_couette_finalize(sim, metrics);
  const double cx = 0.5 * (c.lo[0] + c.hi[0]), cy = 0.5 * (c.lo[1] + c.hi[1]);
  const double h = sim.grid.h, Ri = c.scene_param("-annulus_ri"), Ro = c.scene_param("-annulus_ro");
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
  ap.Omega = c.scene_param("-annulus_omega");
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
void AnnulusScene<dim>::taylor_couette_finalize(State<dim> &sim, Metrics &metrics) {
  const Config &c = sim.cfg;
  const double cx = 0.5 * (c.lo[0] + c.hi[0]), cy = 0.5 * (c.lo[1] + c.hi[1]);
  const double h = sim.grid.h, Ri = c.scene_param("-annulus_ri"), Ro = c.scene_param("-annulus_ro"), d = c.gran.d, Om = c.scene_param("-annulus_omega");
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

// 3D soil bins with a tool (excavation, wheel): the particles in the layer one cell deep
// along the side wall z = domain_lo (the bin's glass wall, where seed 004 films the soil's
// failure surface), with their velocities: side_wall.csv.
} // namespace

GM_SCENE(annulus, AnnulusScene)

} // namespace granmpm
