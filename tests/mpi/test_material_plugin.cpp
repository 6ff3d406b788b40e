// Worked example of docs/architecture.md "Add a material": a model defined in this file,
// added with one registration line, run in a small simulation and checked against an
// analytic solution.
//
// The model: a weakly compressible Newtonian fluid, sigma = -p I + 2 eta dev D with the
// pressure from the bulk modulus (dp = -K tr D dt). Its one parameter, -viscosity, is
// declared by the model; it keeps no particle state.
//
// The check: a shear wave v_x = V sin(k y) in a box periodic in x and y decays as
// exp(-nu k^2 t), nu = eta/rho (the momentum equation reduces to v_t = nu v_yy).
#include "harness.hpp"

#include "granmpm/material.hpp"

using namespace granmpm;

namespace {

struct NewtonianFluid {
  double K = 0, eta = 0;

  static ModelInfo info() {
    ModelInfo m{"newtonian_test", "weakly compressible Newtonian fluid (a test's model)", {}, {}};
    m.params.push_back({"-viscosity", "Newtonian fluid: dynamic viscosity eta [Pa s]", 1.0, 0, std::numeric_limits<double>::infinity(), true});
    return m;
  }
  static NewtonianFluid make(const MaterialInputs &in) { return {in.el.K, in.param("-viscosity")}; }
  double step(Mat3 &sigma, const Mat3 &L, const PointIn &in, const PointState &) const {
    const Mat3 D = 0.5 * (L + L.transpose());
    const double p = pressure(sigma) - K * in.dt * D.trace();
    sigma = -p * Mat3::Identity() + 2.0 * eta * deviator(D);
    return 0.0;
  }
};

// The one registration line.
const MaterialKind kNewtonian = register_material<NewtonianFluid>();

constexpr double kRho = 1.0, kEta = 0.05, kV = 0.01, kTEnd = 0.3;

// The shear wave on n cells per wavelength (domain 1 high, 4 cells wide), 2 PPC, run to
// kTEnd on `ranks` ranks; returns the amplitude ratio A(t)/A(0) of the sine mode.
double decay_ratio(int n, int ranks) {
  Config c;
  c.dim = 2;
  c.scene = SceneKind::Block;
  c.material = kNewtonian;
  c.model_params["-viscosity"] = kEta;
  c.E = 1e4;
  c.nu = 0.3;
  c.rho = kRho;
  c.p0 = 0;
  c.ppc = 2;
  const double h = 1.0 / n;
  c.lo = {0, 0, 0};
  c.hi = {4 * h, 1, 0};
  c.cells = {4, n, 1};
  c.bc = {{{BC::Periodic, BC::Periodic}, {BC::Periodic, BC::Periodic}, {BC::Periodic, BC::Periodic}}};
  c.gravity = {0, 0, 0};
  c.gravity_ramp = 0;
  c.v0 = {kV, 0, 0}; // the energy guard's budget: twice the shear wave's kinetic energy
  gmtest::quiet(c, "material_plugin");
  double ratio = 0;
  gmtest::on_ranks(ranks, [&](MPI_Comm comm) {
    Simulation<2> sim(comm, c);
    sim.setup();
    const double k = 2 * M_PI;
    auto amplitude = [&] {
      ParticleView<2> P = sim.particles.get();
      double num[2] = {0, 0}, all[2] = {0, 0};
      for (PetscInt p = 0; p < P.n; ++p) {
        const double s = std::sin(k * P.x[2 * p + 1]);
        num[0] += P.m[p] * P.v[2 * p] * s;
        num[1] += P.m[p] * s * s;
      }
      sim.particles.restore(P);
      MPI_Allreduce(num, all, 2, MPI_DOUBLE, MPI_SUM, comm);
      return all[0] / all[1];
    };
    ParticleView<2> P = sim.particles.get();
    for (PetscInt p = 0; p < P.n; ++p) {
      const double y = P.x[2 * p + 1];
      P.v[2 * p] = kV * std::sin(k * y);
      P.v[2 * p + 1] = 0;
      if (P.C) { // the affine matrix of APIC: the velocity gradient, dv_x/dy
        for (int i = 0; i < 4; ++i) P.C[4 * p + i] = 0;
        P.C[4 * p + 1] = kV * k * std::cos(k * y);
      }
    }
    sim.particles.restore(P);
    const double a0 = amplitude();
    const double dt = 0.4 * h / sim.wave_speed;
    const int steps = (int)std::ceil(kTEnd / dt);
    for (int s = 0; s < steps; ++s) sim.step(kTEnd / steps);
    ratio = amplitude() / a0;
  });
  return gmtest::bcast(ratio);
}

} // namespace

TEST_CASE("a material defined in a test, registered with one line: shear wave decays as exp(-nu k^2 t)", "[parallel][material]") {
  const MaterialEntry &e = material_entry(kNewtonian);
  REQUIRE(std::string(e.info.name) == "newtonian_test");
  REQUIRE(e.info.params.size() == 1);
  const double exact = std::exp(-kEta / kRho * 4 * M_PI * M_PI * kTEnd);
  const double r16 = decay_ratio(16, 1), r32 = decay_ratio(32, 1);
  const double e16 = std::fabs(r16 / exact - 1), e32 = std::fabs(r32 / exact - 1);
  INFO("A(t)/A(0) exact " << exact << ", 16 cells " << r16 << " (error " << e16 << "), 32 cells " << r32 << " (error " << e32 << ")");
  // Measured: errors 7.53e-3 (16 cells) and 2.03e-3 (32 cells), a ratio of 3.7 (second
  // order in h, with dt ~ h: GIMP/APIC transfer and the viscous step). Required: at least
  // 3 (order > 1.58) and the 32-cell error within 25% of the measured one.
  REQUIRE(e16 / e32 > 3.0);
  REQUIRE(e32 < 2.5e-3);
  // The same run on 2 and 3 ranks: equal to round-off.
  for (int n = 2; n <= std::min(3, gmtest::world_size()); ++n) {
    const double rn = decay_ratio(16, n);
    INFO(n << " ranks: " << rn << " against " << r16);
    REQUIRE(std::fabs(rn - r16) < 1e-12 * std::fabs(r16));
  }
}
