// Config::validate: every rule on the options that needs no communicator, one line naming
// the option to change. The material models' own parameters are range-checked from their
// declarations (materials/model.hpp), the rigid bodies by their component (BodyOptions).
#include <cmath>
#include <string>

#include "granmpm/body_options.hpp"
#include "granmpm/config.hpp"
#include "granmpm/material.hpp"
#include "granmpm/option_names.hpp"
#include "granmpm/scene.hpp"
#include "options_util.hpp"

namespace granmpm {

using opt::bad;
using opt::fmt;
using opt::range_text;

// The grid, the domain, the material box and the plain numbers.
void Config::validate_domain() const {
  const char *axes = "xyz";
  if (dim != 2 && dim != 3) bad("-dim must be 2 or 3 (got " + std::to_string(dim) + ")");
  double h = 0;
  for (int d = 0; d < dim; ++d) {
    const std::string ax(1, axes[d]);
    if (!(hi[d] > lo[d])) bad("-domain_hi must exceed -domain_lo in " + ax + " (got " + fmt(lo[d]) + " .. " + fmt(hi[d]) + ")");
    if (cells[d] < 1) bad("-cells must be >= 1 in every direction (got " + std::to_string(cells[d]) + " in " + ax + ")");
    const double hd = (hi[d] - lo[d]) / cells[d];
    if (d == 0) h = hd;
    else if (std::fabs(hd - h) > 1e-9 * h)
      bad("-cells: cells must be square (spacing " + fmt(h) + " in x but " + fmt(hd) + " in " + ax + "); adjust -cells or -domain_lo/-domain_hi");
    if ((bc[d][0] == BC::Periodic) != (bc[d][1] == BC::Periodic))
      bad("-bc_" + ax + "lo/-bc_" + ax + "hi: periodic must be set on both faces of a direction");
    if (bc[d][0] == BC::Periodic && cells[d] < 4) bad("-cells: a periodic direction needs at least 4 cells (got " + std::to_string(cells[d]) + " in " + ax + ")");
  }
  if (ppc < 1 || ppc > 8) bad("-ppc must be in 1..8 (got " + std::to_string(ppc) + ")");
  if (!(E > 0)) bad("-E must be > 0 (got " + fmt(E) + ")");
  if (!(nu > -1.0 && nu < 0.5)) bad("-nu must satisfy -1 < nu < 0.5 (got " + fmt(nu) + ")");
  if (!(rho > 0)) bad("-rho must be > 0 (got " + fmt(rho) + ")");
  if (!(cfl > 0 && cfl <= 1)) bad("-cfl must be in (0, 1] (got " + fmt(cfl) + ")");
  if (!(dt >= 0)) bad("-dt must be >= 0 (0 = automatic; got " + fmt(dt) + ")");
  if (!(t_end > 0)) bad("-t_end must be > 0 (got " + fmt(t_end) + ")");
  if (!(flip_alpha >= 0 && flip_alpha <= 1)) bad("-flip_alpha must be in [0, 1] (got " + fmt(flip_alpha) + ")");
  if (!(gravity_ramp >= 0)) bad("-gravity_ramp must be >= 0 (got " + fmt(gravity_ramp) + ")");
  if (!(wall_friction >= 0)) bad("-wall_friction must be >= 0 (got " + fmt(wall_friction) + ")");
  if (!(damping >= 0)) bad("-damping must be >= 0 (got " + fmt(damping) + ")");
  if (!(p0 >= 0)) bad("-p0 must be >= 0 (got " + fmt(p0) + ")");
  if (output_interval < 0) bad("-output_interval must be >= 0 (got " + std::to_string(output_interval) + ")");
  if (fluidity_pc_interval < 1) bad("-fluidity_pc_interval must be >= 1 (got " + std::to_string(fluidity_pc_interval) + ")");
  if (fluidity_resolve_max < 1) bad("-fluidity_resolve_max must be >= 1 (got " + std::to_string(fluidity_resolve_max) + ")");
  if (!(fluidity_resolve_tol >= 0)) bad("-fluidity_resolve_tol must be >= 0 (got " + fmt(fluidity_resolve_tol) + ")");
  if (progress_interval < 0) bad("-progress_interval must be >= 0 (got " + std::to_string(progress_interval) + ")");
  if (output_dir.empty()) bad("-output_dir must not be empty");
  if (checkpoint_interval < 0) bad("-checkpoint_interval must be >= 0 (got " + std::to_string(checkpoint_interval) + ")");
  if (!(energy_bound_factor > 1)) bad("-energy_bound_factor must be > 1 (got " + fmt(energy_bound_factor) + ")");
  for (int d = 0; d < 3; ++d)
    if (procs[d] < 0) bad(std::string("-da_processors_") + "xyz"[d] + " must be >= 0 (got " + std::to_string(procs[d]) + ")");
}

// The material's parameters and the rules that tie it to other options.
void Config::validate_material() const {
  for (const ParamDecl &p : material_entry(material).info.params)
    if (p.choices.empty() && !p.valid(param(p.option))) bad(std::string(p.option) + " must be " + range_text(p) + " (got " + fmt(param(p.option)) + ")");
  if (material == MaterialKind::DruckerPrager && !(gran.rho_c >= 0)) bad("-rho_c must be >= 0 (got " + fmt(gran.rho_c) + ")");
  if (material == MaterialKind::MuI || material == MaterialKind::Nonlocal || material == MaterialKind::Dynamic) {
    const std::string e = granular_error(gran); // the family's rules (materials/local_mu_i.hpp)
    if (!e.empty()) bad(e);
  }
}

// The implicit momentum step.
void Config::validate_implicit() const {
  if (time_integrator == TimeIntegrator::ImplicitCoupled) {
    if (material != MaterialKind::Nonlocal)
      bad(std::string("-time_integrator implicit_coupled solves the steady nonlocal fluidity with the momentum and needs -material nonlocal (got ") + to_string(material) +
          "); use -time_integrator implicit for elastic|hypoelastic|mu_i|drucker_prager");
    if (gran.A == 0) bad("-time_integrator implicit_coupled: -A 0 has no fluidity equation (g = g_loc); use -material mu_i with -time_integrator implicit");
    if (fluidity_bc != FluidityBC::ZeroFlux) bad("-fluidity_bc dirichlet is not supported with -time_integrator implicit_coupled; use -fluidity_bc zero_flux");
    if (stress_update != StressUpdate::Implicit)
      bad("-stress_update explicit is not supported with -time_integrator implicit_coupled (its plastic flow is stable only for G dt / eta < 2); use -stress_update implicit");
    if (implicit.theta != 1.0) bad("-implicit_theta must be 1 with -time_integrator implicit_coupled (the fluidity equation holds at the end of the step; got " + fmt(implicit.theta) + ")");
  }
  if (time_integrator == TimeIntegrator::Implicit || time_integrator == TimeIntegrator::ImplicitCoupled) {
    if (time_integrator == TimeIntegrator::Implicit && (material == MaterialKind::Nonlocal || material == MaterialKind::Dynamic))
      bad(std::string("-time_integrator implicit does not support -material ") + to_string(material) +
          " (the fluidity is not part of the implicit solve); use -material elastic|hypoelastic|mu_i|drucker_prager, -time_integrator implicit_coupled (nonlocal) or -time_integrator explicit");
    if (!material_entry(material).info.implicit)
      bad(std::string("-time_integrator implicit does not support -material ") + to_string(material) + " (its particle state is not part of the implicit solve); use -time_integrator explicit");
    if (update != UpdateOrder::USL) bad("-update usf|musl order the explicit step only; the implicit step has its own order (omit -update or use usl)");
    if (wall_friction > 0) bad("-wall_friction: Coulomb wall friction is not supported with -time_integrator implicit (slip faces are frictionless there)");
    if (scene_has_bodies(*this))
      bad("-time_integrator implicit does not support rigid bodies (-body<k>_shape, -scene annulus): their contact acts in the explicit grid update; use -time_integrator explicit");
    if (vol_cell_average) bad("-volumetric_average is not supported with -time_integrator implicit; use -time_integrator explicit");
    if (implicit.assembled_jacobian && material != MaterialKind::LinearElastic)
      bad("-implicit_jacobian assembled is the exact Jacobian only for -material elastic; use -implicit_jacobian mf_operator");
    if (!(implicit.theta >= 0.5 && implicit.theta <= 1)) bad("-implicit_theta must be in [0.5, 1] (got " + fmt(implicit.theta) + ")");
    if (implicit.grow_its < 0) bad("-implicit_grow_its must be >= 0 (got " + std::to_string(implicit.grow_its) + ")");
    if (!(implicit.grow_factor >= 1)) bad("-implicit_grow_factor must be >= 1 (got " + fmt(implicit.grow_factor) + ")");
    if (!(implicit.dt_max >= 0)) bad("-implicit_dt_max must be >= 0 (got " + fmt(implicit.dt_max) + ")");
    if (!(implicit.dt_min >= 0)) bad("-implicit_dt_min must be >= 0 (got " + fmt(implicit.dt_min) + ")");
    if (implicit.max_retries < 0) bad("-implicit_max_retries must be >= 0 (got " + std::to_string(implicit.max_retries) + ")");
    if (!(implicit.force_tol > 0)) bad("-implicit_force_tol must be > 0 (got " + fmt(implicit.force_tol) + ")");
  }
}

// The scenes' own rules and the rigid bodies.
void Config::validate_scene() const {
  if (body_fluidity_bc == BodyFluidityBC::Zero && material != MaterialKind::Nonlocal)
    bad("-body_fluidity_bc zero acts on the steady fluidity solve: it needs -material nonlocal (got " + std::string(to_string(material)) + ")");
  if (body_fluidity_bc == BodyFluidityBC::Zero && !scene_has_bodies(*this))
    bad("-body_fluidity_bc zero needs rigid bodies (-body<k>_shape or -scene annulus)");
  if (!(balance_threshold == 0 || balance_threshold > 1))
    bad("-balance_threshold must be > 1 (max/mean particles per rank) or 0 to never rebalance (got " + fmt(balance_threshold) + ")");
  if (balance_interval < 1) bad("-balance_interval must be >= 1 (got " + std::to_string(balance_interval) + ")");
  if (sort_interval < 0) bad("-sort_interval must be >= 0 (0: never; got " + std::to_string(sort_interval) + ")");
  BodyOptions::validate(*this);
  scene_rules(scene).validate_options(*this);
  scene_rules(scene).validate(*this);
}

void Config::validate() const {
  validate_domain();
  validate_material();
  validate_implicit();
  validate_scene();
}

} // namespace granmpm
