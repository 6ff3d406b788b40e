// Simulation<dim>: set-up (material, grid, particles, modules, restart, stability check).
#include <cmath>
#include <sstream>

#include "granmpm/checkpoint.hpp"
#include "granmpm/hybrid/module.hpp"
#include "granmpm/implicit.hpp"
#include "granmpm/option_names.hpp"
#include "granmpm/output.hpp"
#include "granmpm/scene.hpp"
#include "granmpm/simulation.hpp"

namespace granmpm {

volatile std::sig_atomic_t stop_signal = 0;
volatile std::sig_atomic_t checkpoint_signal = 0;

template <int dim>
Simulation<dim>::Simulation(MPI_Comm c, const Config &config) : State<dim>(c, config) {}


template <int dim>
void Simulation<dim>::setup() {
  cfg.validate();
  if (cfg.dim != dim) throw UserError("internal: Simulation<" + std::to_string(dim) + "> given -dim " + std::to_string(cfg.dim));
  st_migrate_ = log_stage(LogStage::Migrate);
  st_p2g_ = log_stage(LogStage::P2G);
  st_grid_ = log_stage(LogStage::GridUpdate);
  st_g2p_ = log_stage(LogStage::G2P);
  st_const_ = log_stage(LogStage::Constitutive);
  st_out_ = log_stage(LogStage::Output);

  const ElasticModuli el = ElasticModuli::from_E_nu(cfg.E, cfg.nu);
  wave_speed = std::sqrt(el.p_wave() / cfg.rho);
  material = make_material<dim>(cfg);
  grid.create(comm, cfg);
  switch (cfg.shape) {
  case ShapeKind::Linear: shape = LinearShape{}; break;
  case ShapeKind::GIMP: shape = GIMPShape{0.5 / cfg.ppc}; break;
  case ShapeKind::BSpline2: shape = BSpline2Shape{}; break;
  }

  // Decide once what this scene needs.
  ParticleFieldSet fs;
  fs.apic = cfg.transfer == TransferKind::APIC;
  for (const FieldDecl &f : material->info().fields) fs.model.push_back({f.name, f.bs});
  for (const auto &f : hybrid_particle_fields(comm)) fs.model.push_back(f); // -hybrid_dem -hybrid_band
  for (const auto &f : extra_fields) fs.model.push_back(f);
  fs.fluidity_split = cfg.material == MaterialKind::Nonlocal && cfg.fluidity_resolve_max > 1;
  particles.create(comm, grid, fs);
  {
    const std::vector<BodySpec> specs = scene_bodies(cfg, body_names);
    if (!specs.empty()) bodies = std::make_unique<RigidBodies<dim>>(specs, grid.h, cfg.body_contact_layer);
  }
  if (cfg.restart.empty()) {
    // No particle is seeded inside a body.
    auto outside = [this](const double *x) {
      for (size_t k = 0; k < bodies->size(); ++k)
        if (bodies->sdf(k, x) < 0) return false;
      return true;
    };
    if (bodies) particles.seed(cfg, grid, outside);
    else particles.seed(cfg, grid);
    if (particles.global_size() == 0) throw UserError("no particles were seeded: the material box -body_lo/-body_hi does not overlap the domain");
    Scene<dim>::initialize(*this);
    init_material_state();
  }
  add_modules();
  output = std::make_unique<Output<dim>>(*this);
  m_min_ = 1e-12 * cfg.rho * std::pow(grid.h, dim);
  if (!cfg.restart.empty()) Checkpoint<dim>::read(*this, cfg.restart, [this](const Ranges &l) { repartition(l); });
  if (cfg.time_integrator != TimeIntegrator::Explicit) implicit = std::make_unique<ImplicitSolver<dim>>(*this, *this);
  if (bodies) bodies->set_time(time);

  stage_summary = describe(particles.fields());
  // Thinly spreading granular flows blow up at nearly empty nodes unless dilated material is
  // stress-free: say so in every instability message when that rule is off.
  if (cfg.granular() && cfg.gran.rho_c <= 0)
    hint_ = "; a granular flow that spreads or separates also needs -rho_c (e.g. 0.9 times -rho) so that dilated material is stress-free";

  // Stability of a fixed step is checked here and again every step as velocities grow.
  const double vmax_checkpoint = vmax;
  const Totals t0 = totals(); // sets vmax (a restart continues with the checkpointed value)
  if (!cfg.restart.empty()) vmax = vmax_checkpoint;
  ke_ = t0.kinetic;
  energy_bound_ = energy_available(t0);
  const double lim = dt_limit();
  if (!implicit && cfg.dt > 0 && cfg.dt > lim && !cfg.dt_allow_unstable) {
    std::ostringstream m;
    m << "-dt " << cfg.dt << " exceeds the CFL stability limit h/(c+|v|max) = " << lim << " s (h = " << grid.h << " m, elastic wave speed c = " << wave_speed
      << " m/s); use -dt <= " << lim << ", -dt 0 for automatic steps, or -dt_allow_unstable to run anyway";
    throw UserError(m.str());
  }
}

// The "stages:" line: what setup decided to build.
template <int dim>
std::string Simulation<dim>::describe(const ParticleFieldSet &fs) const {
  std::ostringstream s;
  s << "stages: " << dim << "D " << to_string(cfg.scene) << ", material " << to_string(cfg.material) << ", " << name_of(cfg.shape) << " shape, "
    << name_of(cfg.transfer) << (cfg.transfer == TransferKind::FLIP ? " (alpha " + std::to_string(cfg.flip_alpha) + ")" : std::string()) << ", "
    << name_of(cfg.update) << "; fluidity solve: "
    << (fluidity ? "steady (KSP, prefix -fluidity_)"
                 : cfg.time_integrator == TimeIntegrator::ImplicitCoupled ? "steady, coupled with the momentum (SNES, prefix -implicit_)"
                 : dyn_fluidity ? (cfg.fluidity_step == FluidityStepKind::Implicit ? "dynamical, implicit (KSP, prefix -fluidity_)" : "dynamical, explicit") : "no")
    << "; momentum: " << (implicit ? (cfg.time_integrator == TimeIntegrator::ImplicitCoupled ? "implicit momentum + fluidity (SNES, prefix -implicit_)" : "implicit momentum (SNES, prefix -implicit_)") : "explicit")
    << (bodies ? "; rigid bodies (" + std::to_string(bodies->size()) + ")" : std::string()) << "; APIC matrix: " << (fs.apic ? "yes" : "no") << "; F tracking: " << (fs.hyper ? "yes" : "no") << "; density: " << name_of(cfg.density) << "; output every " << cfg.output_interval << " steps";
  return s.str();
}

// The modules this scene needs, in the order their hooks run: the density rule acts
// before the bodies move (end_step), the bodies take their poses before the fluidity
// solve reads them (begin_step).
template <int dim>
void Simulation<dim>::add_modules() {
  if (cfg.density != DensityMethod::Local) {
    auto m = std::make_unique<DensityModule<dim>>(*this);
    density.bind(&m->density);
    modules.push_back(std::move(m));
  }
  if (bodies) {
    auto m = std::make_unique<BodyModule<dim>>();
    body_module_ = m.get();
    modules.push_back(std::move(m));
  }
  // implicit_coupled solves the fluidity inside its SNES system (ImplicitSolver), not here.
  if (cfg.material == MaterialKind::Nonlocal && cfg.time_integrator != TimeIntegrator::ImplicitCoupled) {
    auto m = std::make_unique<SteadyFluidityModule<dim>>(*this);
    fluidity.bind(&m->solver);
    modules.push_back(std::move(m));
  }
  if (cfg.material == MaterialKind::Dynamic) {
    auto m = std::make_unique<DynamicFluidityModule<dim>>(*this, lapbuf_);
    dyn_fluidity.bind(&m->solver);
    modules.push_back(std::move(m));
  }
  make_scene<dim>(cfg.scene)->add_modules(*this, modules); // the silo scene: its plate
  for (auto &m : grain_modules<dim>(*this)) modules.push_back(std::move(m)); // -hybrid_dem, -hybrid_band
  if (extra_modules) extra_modules(*this);
  for (const auto &m : modules) {
    module_ptrs_.push_back(m.get());
    if (m->has_node_pass()) this->node_modules.push_back(m.get());
    if (m->has_constraint()) this->constraint_modules.push_back(m.get());
  }
}

template <int dim>
double Simulation<dim>::energy_available(const Totals &t) {
  // Initial elastic energy sum V sigma:C^-1:sigma / 2, plus kinetic energy, plus the work
  // gravity can do over the domain (or over a free fall to t_end along a periodic axis).
  const ElasticModuli el = ElasticModuli::from_E_nu(cfg.E, cfg.nu);
  ParticleView<dim> P = particles.get();
  double se = 0;
  for (PetscInt p = 0; p < P.n; ++p) {
    const double pr = pressure6(P.s + 6 * p), tau = tau6(P.s + 6 * p);
    se += P.vol[p] * 0.5 * (tau * tau / el.G + pr * pr / el.K);
  }
  particles.restore(P);
  double se_all = 0;
  MPI_Allreduce(&se, &se_all, 1, MPI_DOUBLE, MPI_SUM, comm);
  double g = 0, len = 0;
  for (int d = 0; d < dim; ++d) {
    g += cfg.gravity[d] * cfg.gravity[d];
    len += (cfg.hi[d] - cfg.lo[d]) * (cfg.hi[d] - cfg.lo[d]);
  }
  g = std::sqrt(g);
  len = std::max(std::sqrt(len), 0.5 * g * cfg.t_end * cfg.t_end);
  // A floor for scenes at rest without gravity (any motion then comes from round-off).
  const double floor = 1e-12 * t.mass * wave_speed * wave_speed;
  return std::max(t.kinetic + se_all + t.mass * g * len, floor);
}

template <int dim>
double Simulation<dim>::dt_cfl_limit() const {
  return grid.h / (wave_speed + vmax);
}

template <int dim>
void Simulation<dim>::init_material_state() {
  // The model's state from each particle's initial stress (the dynamical model: F, Fp).
  ParticleView<dim> P = particles.get();
  material->init_state(P, particles);
  particles.restore(P);
}

// Explicit instantiations of the members defined in this file.
#define GM_INSTANTIATE(d) \
  template Simulation<d>::Simulation(MPI_Comm, const Config &); \
  template void Simulation<d>::setup(); \
  template void Simulation<d>::add_modules(); \
  template std::string Simulation<d>::describe(const ParticleFieldSet &) const; \
  template double Simulation<d>::energy_available(const Totals &); \
  template double Simulation<d>::dt_cfl_limit() const; \
  template void Simulation<d>::init_material_state();
GM_INSTANTIATE(2)
GM_INSTANTIATE(3)
#undef GM_INSTANTIATE

} // namespace granmpm
