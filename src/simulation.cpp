#include "granmpm/simulation.hpp"

#include <algorithm>
#include <cmath>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <sstream>

#include <sys/resource.h>

#include "granmpm/checkpoint.hpp"
#include "granmpm/density.hpp"
#include "granmpm/dynamic_fluidity.hpp"
#include "granmpm/fluidity.hpp"
#include "granmpm/implicit.hpp"
#include "granmpm/output.hpp"
#include "granmpm/scene.hpp"

namespace granmpm {

volatile std::sig_atomic_t stop_signal = 0;
volatile std::sig_atomic_t checkpoint_signal = 0;

namespace {
// One set of log stages per process, however many simulations (2D or 3D) it builds.
const PetscLogStage *log_stages() {
  static PetscLogStage stages[7];
  static bool registered = false;
  if (!registered) {
    const char *names[7] = {"Migrate", "P2G", "GridUpdate", "G2P", "Constitutive", "Fluidity", "Output"};
    for (int i = 0; i < 7; ++i) GM_CALL(PetscLogStageRegister(names[i], &stages[i]));
    registered = true;
  }
  return stages;
}
// G2P's reduction of {guard tripped, largest speed, kinetic energy}: max, max, sum.
void g2p_reduce(void *in, void *inout, int *len, MPI_Datatype *) {
  const double *a = static_cast<const double *>(in);
  double *b = static_cast<double *>(inout);
  for (int i = 0; i + 2 < *len; i += 3) {
    b[i] = std::max(a[i], b[i]);
    b[i + 1] = std::max(a[i + 1], b[i + 1]);
    b[i + 2] = a[i + 2] + b[i + 2];
  }
}
MPI_Op g2p_reduce_op() {
  static MPI_Op op = MPI_OP_NULL;
  if (op == MPI_OP_NULL) MPI_Op_create(&g2p_reduce, 1, &op);
  return op;
}
} // namespace

template <int dim>
Simulation<dim>::Simulation(MPI_Comm c, const Config &config) : cfg(config), comm(c) {
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
}

template <int dim>
Simulation<dim>::~Simulation() {
  if (bodies_csv_) std::fclose(bodies_csv_);
}

template <int dim>
void Simulation<dim>::setup() {
  cfg.validate();
  if (cfg.dim != dim) throw UserError("internal: Simulation<" + std::to_string(dim) + "> given -dim " + std::to_string(cfg.dim));
  const PetscLogStage *stages = log_stages();
  st_migrate_ = stages[0];
  st_p2g_ = stages[1];
  st_grid_ = stages[2];
  st_g2p_ = stages[3];
  st_const_ = stages[4];
  st_fluid_ = stages[5];
  st_out_ = stages[6];

  const ElasticModuli el = ElasticModuli::from_E_nu(cfg.E, cfg.nu);
  wave_speed = std::sqrt(el.p_wave() / cfg.rho);
  switch (cfg.material) {
  case MaterialKind::LinearElastic: material = LinearElastic{el}; break;
  case MaterialKind::Hypoelastic: material = Hypoelastic{el}; break;
  case MaterialKind::MuI: material = LocalMuI{el, cfg.gran, cfg.stress_update}; break;
  case MaterialKind::Nonlocal: material = NonlocalNGF{el, cfg.gran, cfg.stress_update}; break;
  case MaterialKind::Dynamic:
    material = DynamicNGF{DynamicNGFParams{el, cfg.gran, cfg.t0, cfg.g0, KinematicUpdate::ForwardEuler},
                          cfg.fluidity_step == FluidityStepKind::Explicit ? FluidityStep::Explicit : FluidityStep::ImplicitCoupled};
    break;
  case MaterialKind::DruckerPrager:
    material = DruckerPrager{el, cfg.friction_angle * M_PI / 180.0, cfg.cohesion, cfg.gran.rho_c, (DPMatch)cfg.dp_match};
    break;
  }
  grid.create(comm, cfg);
  if (cfg.scene == SceneKind::Silo) grid.set_plate(cfg.silo_plate_y, cfg.silo_orifice, cfg.silo_orifice_x, cfg.silo_orifice_z);
  switch (cfg.shape) {
  case ShapeKind::Linear: shape = LinearShape{}; break;
  case ShapeKind::GIMP: shape = GIMPShape{0.5 / cfg.ppc}; break;
  case ShapeKind::BSpline2: shape = BSpline2Shape{}; break;
  }

  // Decide once what this scene needs.
  ParticleFieldSet fs;
  fs.apic = cfg.transfer == TransferKind::APIC;
  fs.gdot = cfg.granular();
  fs.fluidity = cfg.material == MaterialKind::Nonlocal || cfg.material == MaterialKind::Dynamic;
  fs.hyper = cfg.material == MaterialKind::Dynamic;
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
    if (fs.hyper) init_hyperelastic_state();
  }
  // implicit_coupled solves the fluidity inside its SNES system (ImplicitSolver), not here.
  if (cfg.material == MaterialKind::Nonlocal && cfg.time_integrator != TimeIntegrator::ImplicitCoupled) fluidity = new_fluidity_solver();
  if (cfg.material == MaterialKind::Dynamic) dyn_fluidity = std::make_unique<DynamicFluidity<dim>>(grid, cfg);
  output = std::make_unique<Output<dim>>(*this);
  if (cfg.density != DensityMethod::Local) density = std::make_unique<CellDensity<dim>>(grid, cfg);
  m_min_ = 1e-12 * cfg.rho * std::pow(grid.h, dim);
  if (!cfg.restart.empty()) Checkpoint<dim>::read(*this, cfg.restart);
  if (cfg.time_integrator != TimeIntegrator::Explicit) implicit = std::make_unique<ImplicitSolver<dim>>(*this);
  if (bodies) bodies->set_time(time);

  const char *shapes[] = {"linear", "gimp", "bspline2"}, *transfers[] = {"pic", "flip", "apic"}, *orders[] = {"usl", "usf", "musl"},
             *dens[] = {"local", "elemental", "hybrid"};
  std::ostringstream s;
  s << "stages: " << dim << "D " << to_string(cfg.scene) << ", material " << to_string(cfg.material) << ", " << shapes[(int)cfg.shape] << " shape, "
    << transfers[(int)cfg.transfer] << (cfg.transfer == TransferKind::FLIP ? " (alpha " + std::to_string(cfg.flip_alpha) + ")" : std::string()) << ", "
    << orders[(int)cfg.update] << "; fluidity solve: "
    << (fluidity ? "steady (KSP, prefix -fluidity_)"
                 : cfg.time_integrator == TimeIntegrator::ImplicitCoupled ? "steady, coupled with the momentum (SNES, prefix -implicit_)"
                 : dyn_fluidity ? (cfg.fluidity_step == FluidityStepKind::Implicit ? "dynamical, implicit (KSP, prefix -fluidity_)" : "dynamical, explicit") : "no")
    << "; momentum: " << (implicit ? (cfg.time_integrator == TimeIntegrator::ImplicitCoupled ? "implicit momentum + fluidity (SNES, prefix -implicit_)" : "implicit momentum (SNES, prefix -implicit_)") : "explicit")
    << (bodies ? "; rigid bodies (" + std::to_string(bodies->size()) + ")" : std::string()) << "; APIC matrix: " << (fs.apic ? "yes" : "no") << "; F tracking: " << (fs.hyper ? "yes" : "no") << "; density: " << dens[(int)cfg.density] << "; output every " << cfg.output_interval << " steps";
  stage_summary = s.str();
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
double Simulation<dim>::gravity_factor(double t) const {
  if (cfg.gravity_ramp <= 0) return 1.0;
  return std::min(1.0, t / cfg.gravity_ramp);
}

// ---------------------------------------------------------------------------------------
// P2G

template <int dim>
template <class S>
void Simulation<dim>::p2g_impl(const S &sh, bool with_force) {
  NodeView<dim> g = grid.begin_local(true);
  ParticleView<dim> P = particles.get();
  const double h = grid.h;
  Stencil<dim, S> st;
  for (PetscInt p = 0; p < P.n; ++p) {
    st.compute(sh, P.x + p * dim, grid.x0, grid.inv_h);
    P2GInput<dim> in{P.m[p], P.vol[p], P.v + p * dim, P.C ? P.C + p * dim * dim : nullptr, with_force ? P.s + 6 * p : nullptr,
                     with_force ? body_acc_ : nullptr};
    p2g_particle(st, in, h, g);
  }
  particles.restore(P);
  grid.end_local();
  grid.local_to_global_add();
}

template <int dim>
void Simulation<dim>::p2g(bool with_force) {
  GM_CALL(PetscLogStagePush(st_p2g_));
  std::visit([&](const auto &s) { p2g_impl(s, with_force); }, shape);
  GM_CALL(PetscLogStagePop());
}

// ---------------------------------------------------------------------------------------
// Grid update: v_old = (mv)/m, v_new = v_old + dt f/m (with_force), boundary conditions on
// v_new. Stores [m, v_new, v_new - v_old] and scatters it to the ghosts.

template <int dim>
void Simulation<dim>::grid_update(double dt, bool with_force) {
  GM_CALL(PetscLogStagePush(st_grid_));
  NodeView<dim> g = grid.begin_global();
  bool bad = false;
  std::string msg;
  if (bodies && with_force) bodies->begin_forces();
  const int k0 = grid.xs[2], k1 = dim == 3 ? grid.xs[2] + grid.xm[2] : 1;
  for (int k = k0; k < k1; ++k)
    for (int j = grid.xs[1]; j < grid.xs[1] + grid.xm[1]; ++j)
      for (int i = grid.xs[0]; i < grid.xs[0] + grid.xm[0]; ++i) {
        double *n = g.at(i, j, k);
        const double m = n[0];
        if (m <= m_min_) {
          for (int c = 1; c < Grid<dim>::NDOF; ++c) n[c] = 0;
          continue;
        }
        double vold[dim], vnew[dim];
        for (int d = 0; d < dim; ++d) {
          vold[d] = n[1 + d] / m;
          vnew[d] = vold[d];
          if (with_force) vnew[d] += dt * (n[1 + dim + d] / m - cfg.damping * vold[d]);
        }
        if (bodies) {
          const double xn[3] = {grid.node_x(0, i), grid.node_x(1, j), dim == 3 ? grid.node_x(2, k) : 0.0};
          bodies->apply(xn, m, vnew, with_force ? dt : 0.0); // owned nodes: forces counted once
        }
        grid.apply_bc(i, j, k, vnew);
        for (int d = 0; d < dim; ++d) {
          n[1 + d] = vnew[d];
          n[1 + dim + d] = vnew[d] - vold[d];
          if (!std::isfinite(vnew[d]) && !bad) {
            bad = true;
            std::ostringstream o;
            o << "grid node (" << i << ", " << j << (dim == 3 ? ", " + std::to_string(k) : std::string()) << ") at x = " << grid.node_x(0, i) << ", y = " << grid.node_x(1, j)
              << " has a non-finite velocity at t = " << time << " (nodal mass " << m << "): the run is unstable; reduce -dt or -cfl" << hint_;
            msg = o.str();
          }
        }
      }
  grid.end_global();
  collective_fail(comm, bad, msg);
  if (bodies && with_force) {
    std::vector<double> &f = bodies->forces(), &mc = bodies->contact_mass();
    MPI_Allreduce(MPI_IN_PLACE, f.data(), (int)f.size(), MPI_DOUBLE, MPI_SUM, comm);
    MPI_Allreduce(MPI_IN_PLACE, mc.data(), (int)mc.size(), MPI_DOUBLE, MPI_SUM, comm);
    // Bodies supply energy: their work on the material, -(F . V + T omega) dt with the
    // velocity the contact used, raises the bound of the energy guard.
    for (size_t b = 0; b < bodies->size(); ++b) {
      double pw = -f[4 * b + 3] * bodies->omega(b);
      for (int d = 0; d < dim; ++d) pw -= f[4 * b + d] * bodies->velocity(b)[d];
      energy_bound_ += dt * std::max(0.0, pw);
    }
    // A dynamic body is updated explicitly with the impulse of its contact nodes, which
    // were set to its velocity of the step start: the next step's velocity change is about
    // -(m_contact / M) times this one's (added mass), unstable once m_contact > M (for a
    // free rotation: sum m r^2 > I). Same numbers on every rank after the reduction.
    for (size_t b = 0; b < bodies->size(); ++b) {
      if (!bodies->dynamic(b)) continue;
      const BodySpec &B = bodies->spec(b);
      const bool free_translation = !B.lock[0] || !B.lock[1] || (dim == 3 && !B.lock[2]);
      std::ostringstream m;
      if (free_translation && mc[2 * b] > B.mass)
        m << "at t = " << time << " the grid mass at the contact nodes of dynamic rigid body " << b << " (" << body_names[b] << "), " << mc[2 * b]
          << " kg, exceeds its mass -body" << B.index << "_mass " << B.mass << ": the explicit body update is unstable (added mass); raise -body" << B.index
          << "_mass, lock the axes that need not move (-body" << B.index << "_lock), or use a finer grid";
      else if (!B.lock[3] && mc[2 * b + 1] > B.inertia)
        m << "at t = " << time << " the moment of inertia of the grid mass at the contact nodes of dynamic rigid body " << b << " (" << body_names[b] << "), "
          << mc[2 * b + 1] << " kg m^2, exceeds its -body" << B.index << "_inertia " << B.inertia
          << ": the explicit body update is unstable (added mass); raise -body" << B.index << "_inertia or lock its rotation (-body" << B.index << "_lock rot)";
      if (!m.str().empty()) throw UserError(m.str()); // identical on every rank (reduced sums)
    }
  }
  grid.global_to_local();
  GM_CALL(PetscLogStagePop());
}

// ---------------------------------------------------------------------------------------
// G2P

// The message of the first guard G2P's particle loop tripped (same text as when it was
// built inside the loop): x is the position after the move.
template <int dim>
std::string Simulation<dim>::g2p_fault_text(const ParticleView<dim> &P, const G2PFault &f, double dt) const {
  const double *x = P.x + f.p * dim;
  std::ostringstream s;
  if (f.kind == G2PFault::Moved)
    s << "particle " << P.id[f.p] << " moved " << dt * std::sqrt(f.u2) / grid.h << " cells in one step at t = " << time << " (speed " << std::sqrt(f.u2) << " m/s, position";
  else
    s << "particle " << P.id[f.p] << " has a non-finite velocity at t = " << time << " (position";
  for (int d = 0; d < dim; ++d) s << " " << x[d];
  s << "): the run is unstable; reduce -dt or -cfl" << hint_;
  return s.str();
}

template <int dim>
template <class S>
void Simulation<dim>::g2p_impl(const S &sh, double dt, unsigned mode) {
  NodeView<dim> g = grid.begin_local(false);
  ParticleView<dim> P = particles.get();
  const double h = grid.h;
  const bool apic = P.C != nullptr, linear_C = std::is_same<S, LinearShape>::value;
  const double alpha = cfg.transfer == TransferKind::FLIP ? cfg.flip_alpha : 0.0;
  if (mode & kL) Lbuf_.resize((size_t)P.n * dim * dim);
  const bool cells = (mode & kL) && cfg.vol_cell_average;
  if (cells) cellbuf_.resize((size_t)P.n);
  if (mode & kStoreXv) xvel_.resize((size_t)P.n * dim);
  Stencil<dim, S> st;
  G2POutput<dim> o;
  double v2max = 0, ke = 0;
  PetscInt fastest = -1;
  // The loop only records the first particle that fails a guard (in particle order, the
  // move check before the finite check, as before); g2p_check builds the message after it.
  G2PFault fault;
  for (PetscInt p = 0; p < P.n; ++p) {
    double *x = P.x + p * dim, *v = P.v + p * dim;
    st.compute(sh, x, grid.x0, grid.inv_h);
    g2p_particle(st, h, g, o);
    if (mode & kVel)
      for (int d = 0; d < dim; ++d) v[d] = alpha * (v[d] + o.dv[d]) + (1.0 - alpha) * o.v_pic[d];
    if ((mode & kC) && apic) apic_C(o, linear_C, P.C + p * dim * dim);
    if (mode & kL)
      for (int d = 0; d < dim; ++d)
        for (int e = 0; e < dim; ++e) Lbuf_[(size_t)p * dim * dim + d * dim + e] = o.L[d][e];
    if (cells) {
      // The cell at the start of the step (owned by this rank: particles were migrated).
      long idx = 0, stride = 1;
      for (int d = 0; d < dim; ++d) {
        const int c = std::min(std::max(grid.cell_of(d, x[d]) - grid.xs[d], 0), grid.xm[d] - 1);
        idx += c * stride;
        stride *= grid.xm[d];
      }
      cellbuf_[p] = idx;
    }
    if (mode & kStoreXv)
      for (int d = 0; d < dim; ++d) xvel_[(size_t)p * dim + d] = o.v_pic[d];
    if (mode & (kMove | kApplyXv)) {
      const double *u = (mode & kMove) ? o.v_pic : &xvel_[(size_t)p * dim];
      double u2 = 0;
      for (int d = 0; d < dim; ++d) {
        x[d] += dt * u[d];
        u2 += u[d] * u[d];
      }
      if (!(dt * std::sqrt(u2) <= h) && fault.p < 0) fault = G2PFault{p, G2PFault::Moved, u2};
    }
    double s2 = 0;
    for (int d = 0; d < dim; ++d) s2 += v[d] * v[d];
    if (!std::isfinite(s2) && fault.p < 0) fault = G2PFault{p, G2PFault::NonFinite, 0};
    if (s2 > v2max) {
      v2max = s2;
      fastest = p;
    }
    ke += 0.5 * P.m[p] * s2;
  }
  std::string msg = fault.p >= 0 ? g2p_fault_text(P, fault, dt) : std::string();
  particles.restore(P);
  grid.end_local();
  // One reduction per pass for the guard, the largest speed and the kinetic energy: on
  // small scenes every collective is a synchronisation of the ranks, and they dominate the step.
  double vm = std::sqrt(v2max), red[3] = {fault.p >= 0 ? 1.0 : 0.0, vm, ke}, all[3];
  MPI_Allreduce(red, all, 3, MPI_DOUBLE, g2p_reduce_op(), comm);
  if (all[0] > 0) collective_fail(comm, fault.p >= 0, msg);
  vmax = all[1];
  if (mode & kVel) {
    // Energy guard: a physical flow cannot multiply its kinetic energy by a large factor
    // in one stable step (below the floor, growth from rest is allowed).
    const double ke_all = all[2];
    // Energy guard: kinetic energy beyond a multiple of all the energy the scene can supply
    // (initial kinetic and elastic energy, gravity's work) comes from an instability.
    if (ke_all > cfg.energy_bound_factor * energy_bound_) {
      // Name the fastest particle: the rank holding it reports.
      struct {
        double v;
        int r;
      } mine{vm, rank}, top{0, 0};
      MPI_Allreduce(&mine, &top, 1, MPI_DOUBLE_INT, MPI_MAXLOC, comm);
      std::string fastest_text;
      if (rank == top.r && fastest >= 0) {
        ParticleView<dim> Q = particles.get();
        std::ostringstream f;
        f << "; the fastest particle is " << Q.id[fastest] << " at";
        for (int d = 0; d < dim; ++d) f << " " << Q.x[fastest * dim + d];
        f << " with speed " << std::sqrt(v2max) << " m/s";
        fastest_text = f.str();
        particles.restore(Q);
      }
      std::ostringstream m;
      m << "the kinetic energy reached " << ke_all << " J at t = " << time << ", " << ke_all / energy_bound_
        << " times the energy the scene can supply (" << energy_bound_ << " J: initial kinetic + elastic energy + gravity's work" << (bodies ? " + rigid bodies' work" : "") << ")" << fastest_text
        << ": the run is unstable; reduce -dt or -cfl" << hint_ << " (or raise -energy_bound_factor if energy is supplied otherwise)";
      collective_fail(comm, rank == top.r, m.str());
    }
    ke_ = ke_all;
  }
}

template <int dim>
void Simulation<dim>::g2p(double dt, unsigned mode) {
  GM_CALL(PetscLogStagePush(st_g2p_));
  std::visit([&](const auto &s) { g2p_impl(s, dt, mode); }, shape);
  GM_CALL(PetscLogStagePop());
}

// ---------------------------------------------------------------------------------------
// Constitutive update from the stored velocity gradients. The material is chosen once
// (std::visit outside the particle loop); 2D embeds L in 3x3 with zero out-of-plane rows
// (plane strain: D_zz = 0, sigma_zz evolves through lambda tr D).

template <int dim>
void Simulation<dim>::constitutive(double dt) {
  GM_CALL(PetscLogStagePush(st_const_));
  ParticleView<dim> P = particles.get();
  // Explicit granular updates are stable for G dt dgdot/dtau < 2: track the largest rate.
  const bool explicit_plastic = cfg.stress_update == StressUpdate::Explicit && (cfg.material == MaterialKind::MuI || cfg.material == MaterialKind::Nonlocal);
  if (lapbuf_.size() < (size_t)P.n) lapbuf_.assign(P.n, 0.0);
  double rate_max = 0, dyn_limit = 1e300;
  bool bad = false;
  std::string msg;
  const ElasticModuli el = ElasticModuli::from_E_nu(cfg.E, cfg.nu);
  if (cfg.vol_cell_average && cellbuf_.size() >= (size_t)P.n) {
    // B-bar-like: tr L of each particle -> the volume-weighted mean of its cell.
    long ncell = 1;
    for (int d = 0; d < dim; ++d) ncell *= grid.xm[d];
    std::vector<double> sum(2 * ncell, 0.0);
    for (PetscInt p = 0; p < P.n; ++p) {
      double tr = 0;
      for (int d = 0; d < dim; ++d) tr += Lbuf_[(size_t)p * dim * dim + d * dim + d];
      sum[2 * cellbuf_[p]] += P.vol[p] * tr;
      sum[2 * cellbuf_[p] + 1] += P.vol[p];
    }
    for (PetscInt p = 0; p < P.n; ++p) {
      double *l = &Lbuf_[(size_t)p * dim * dim], tr = 0;
      for (int d = 0; d < dim; ++d) tr += l[d * dim + d];
      const double avg = sum[2 * cellbuf_[p]] / sum[2 * cellbuf_[p] + 1];
      for (int d = 0; d < dim; ++d) l[d * dim + d] += (avg - tr) / dim;
    }
  }
  std::visit(
      [&](const auto &mat) {
        using M = std::decay_t<decltype(mat)>;
        for (PetscInt p = 0; p < P.n; ++p) {
          if (explicit_plastic) {
            const double pn = pressure6(P.s + 6 * p);
            if (pn > 0) {
              double r = 0;
              if (tau6(P.s + 6 * p) > cfg.gran.mu_s * pn) r = 1.0 / (cfg.gran.b * cfg.gran.d * std::sqrt(cfg.gran.rho_s * pn));
              if (P.g) r = std::max(r, P.g[p] / pn);
              rate_max = std::max(rate_max, el.G * r);
            }
          }
          Mat3 L = Mat3::Zero();
          const double *l = &Lbuf_[(size_t)p * dim * dim];
          for (int d = 0; d < dim; ++d)
            for (int e = 0; e < dim; ++e) L(d, e) = l[d * dim + e];
          // Volume: consistent with F where F is tracked (det(I + dt L)), else exp(dt tr L).
          if constexpr (std::is_same_v<M, DynamicNGF>) P.vol[p] *= (Mat3::Identity() + dt * L).determinant();
          else P.vol[p] *= std::exp(dt * L.trace());
          const double rho = P.m[p] / P.vol[p];
          Mat3 s = sym6_to_mat(P.s + 6 * p);
          double gd = 0;
          if constexpr (std::is_same_v<M, LocalMuI> || std::is_same_v<M, DruckerPrager>) gd = mat.update(s, L, dt, rho);
          else if constexpr (std::is_same_v<M, NonlocalNGF>) gd = mat.update(s, L, dt, rho, P.g[p]);
          else if constexpr (std::is_same_v<M, DynamicNGF>) {
            DynamicNGFState st;
            for (int a = 0; a < 3; ++a)
              for (int b = 0; b < 3; ++b) {
                st.F(a, b) = P.F[p * 9 + 3 * a + b];
                st.Fp(a, b) = P.Fp[p * 9 + 3 * a + b];
              }
            st.g = P.g[p];
            st.p_prev = P.p_prev[p];
            st.mu_prev = P.mu_prev[p];
            if (mat.mode == FluidityStep::Explicit && st.connected())
              dyn_limit = std::min(dyn_limit, dynamic_ngf_local_dt_limit(mat.P, st.p_prev, st.mu_prev, mat.mode));
            const DynamicNGFResult r = dynamic_ngf_update(mat.P, st, L, dt, lapbuf_[p], rho, mat.mode);
            for (int a = 0; a < 3; ++a)
              for (int b = 0; b < 3; ++b) {
                P.F[p * 9 + 3 * a + b] = st.F(a, b);
                P.Fp[p * 9 + 3 * a + b] = st.Fp(a, b);
              }
            P.g[p] = st.g;
            P.p_prev[p] = st.p_prev;
            P.mu_prev[p] = st.mu_prev;
            s = r.sigma;
            gd = r.gdot_p;
          } else
            gd = mat.update(s, L, dt);
          mat_to_sym6(s, P.s + 6 * p);
          if (P.gdot) P.gdot[p] = gd;
          if (!std::isfinite(s.sum() + P.vol[p]) && !bad) {
            bad = true;
            std::ostringstream m;
            m << "particle " << P.id[p] << " has a non-finite " << (std::isfinite(P.vol[p]) ? "stress" : "volume") << " at t = " << time << " (position";
            for (int d = 0; d < dim; ++d) m << " " << P.x[p * dim + d];
            m << "): the run is unstable; reduce -dt or -cfl" << hint_;
            msg = m.str();
          }
        }
      },
      material);
  particles.restore(P);
  collective_fail(comm, bad, msg);
  if (explicit_plastic) {
    double g = 0;
    MPI_Allreduce(&rate_max, &g, 1, MPI_DOUBLE, MPI_MAX, comm);
    plastic_limit = g > 0 ? 2.0 / g : 1e300;
  }
  if (cfg.material == MaterialKind::Dynamic && cfg.fluidity_step == FluidityStepKind::Explicit) {
    // Explicit dynamical fluidity: the local relaxation limit and the diffusion limit
    // dx^2 t0 / (2 dim A^2 d^2).
    double lim = 1e300;
    MPI_Allreduce(&dyn_limit, &lim, 1, MPI_DOUBLE, MPI_MIN, comm);
    plastic_limit = std::min(lim, dynamic_ngf_explicit_dt_limit(std::get<DynamicNGF>(material).P, grid.h, dim));
  }
  GM_CALL(PetscLogStagePop());
}

template <int dim>
void Simulation<dim>::density_update() {
  // Elemental and hybrid density rules live with the fluidity/cell machinery.
  if (density) density->apply(particles);
}

template <int dim>
void Simulation<dim>::solve_fluidity() {
  GM_CALL(PetscLogStagePush(st_fluid_));
  if (fluidity) fluidity->solve(particles, cfg.fluidity_map, nsteps);
  if (dyn_fluidity) {
    // Laplacian of g at the particles from the connected particles at the start of the
    // step; the implicit step diffuses over this step's dt first (no step limit).
    ParticleView<dim> P = particles.get();
    dyn_fluidity->laplacian(P.x, P.m, P.g, P.p_prev, P.mu_prev, P.n, last_dt_, cfg.fluidity_step == FluidityStepKind::Implicit, lapbuf_);
    particles.restore(P);
  }
  GM_CALL(PetscLogStagePop());
}

template <int dim>
void Simulation<dim>::init_hyperelastic_state() {
  // The deformation state whose elastic stress is each particle's initial stress.
  const DynamicNGF &dm = std::get<DynamicNGF>(material);
  ParticleView<dim> P = particles.get();
  for (PetscInt p = 0; p < P.n; ++p) {
    const DynamicNGFState st = dynamic_ngf_state_from_stress(dm.P, sym6_to_mat(P.s + 6 * p), cfg.g0);
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        P.F[p * 9 + 3 * a + b] = st.F(a, b);
        P.Fp[p * 9 + 3 * a + b] = st.Fp(a, b);
      }
    P.g[p] = st.g;
    P.p_prev[p] = st.p_prev;
    P.mu_prev[p] = st.mu_prev;
  }
  particles.restore(P);
}

template <int dim>
void Simulation<dim>::migrate() {
  GM_CALL(PetscLogStagePush(st_migrate_));
  particles.migrate(grid);
  GM_CALL(PetscLogStagePop());
}

template <int dim>
double Simulation<dim>::step(double dt) {
  const double gf = gravity_factor(time);
  for (int d = 0; d < dim; ++d) body_acc_[d] = cfg.gravity[d] * gf;
  last_dt_ = dt;
  if (bodies) bodies->set_time(time); // body poses at the start of the step
  if (fluidity || dyn_fluidity) solve_fluidity(); // from the stress and positions at the start of the step
  if (implicit) dt = implicit->advance(dt); // backward Euler: P2G, SNES, G2P, constitutive
  else switch (cfg.update) {
  case UpdateOrder::USL:
    p2g(true);
    grid_update(dt, true);
    g2p(dt, kVel | kC | kL | kMove);
    constitutive(dt);
    break;
  case UpdateOrder::USF:
    p2g(false);
    grid_update(dt, false);
    g2p(dt, kL);
    constitutive(dt);
    p2g(true);
    grid_update(dt, true);
    g2p(dt, kVel | kC | kMove);
    break;
  case UpdateOrder::MUSL:
    p2g(true);
    grid_update(dt, true);
    g2p(dt, kVel | kC | kStoreXv);
    p2g(false); // remap the updated particle momentum (old positions)
    grid_update(dt, false);
    g2p(dt, kL | kApplyXv); // velocity gradient from the remapped velocity
    constitutive(dt);
    break;
  }
  density_update();
  if (bodies) {
    // Dynamic bodies take this step's reduced contact force (the grid updates above used
    // their start-of-step velocity); kinematic ones move to t + dt. Particles are then
    // checked against the end-of-step poses.
    bodies->advance(time, dt, body_acc_);
    body_particles();
  }
  migrate();
  time += dt;
  ++nsteps;
  return dt;
}

template <int dim>
void Simulation<dim>::body_particles() {
  // Same treatment as walls (Particles::migrate): a particle the interpolated velocity
  // carried less than a cell into a body is put back onto its surface along the normal;
  // counted and reported. Deeper
  // penetration means the body or the flow moves too far per step: the run stops.
  ParticleView<dim> P = particles.get();
  (void)P.v;
  long hits = 0;
  bool bad = false;
  std::string msg;
  for (PetscInt p = 0; p < P.n; ++p) {
    double *x = P.x + p * dim;
    for (size_t k = 0; k < bodies->size(); ++k) {
      const SdfResult s = bodies->sdf_full(k, x);
      if (!(s.d < 0)) continue;
      if (-s.d <= grid.h) {
        // Position only: the velocity came from the grid, where the contact already acted
        // (changing it here would be momentum the body forces do not account for).
        for (int d = 0; d < dim; ++d) x[d] -= s.d * s.n[d];
        ++hits;
      } else if (!bad) {
        bad = true;
        std::ostringstream m;
        m << "particle " << P.id[p] << " is " << -s.d / grid.h << " cells inside rigid body " << k << " (" << body_names[k] << ") at t = " << time << " (position";
        for (int d = 0; d < dim; ++d) m << " " << x[d];
        m << "): a body or the flow moves more than a cell per step; reduce -dt or -cfl, or the body's velocity/omega";
        msg = m.str();
      }
    }
  }
  particles.restore(P);
  collective_fail(comm, bad, msg);
  long all = 0;
  MPI_Allreduce(&hits, &all, 1, MPI_LONG, MPI_SUM, comm);
  body_corrections += all;
}

template <int dim>
void Simulation<dim>::write_bodies_row() {
  // Rank 0 writes; a failure (disk full, permission) stops every rank with the cause.
  bool bad = false;
  std::string msg;
  const std::string path = cfg.output_dir + "/bodies.csv";
  if (rank == 0 && !bodies_csv_) {
    std::filesystem::create_directories(cfg.output_dir);
    if (nsteps > 0 && !cfg.restart.empty()) {
      // A restart appends; rows after the checkpoint's time (written before the old run
      // stopped) would be doubled: keep the header and the rows up to now.
      std::FILE *in = std::fopen(path.c_str(), "r");
      std::string kept;
      if (in) {
        char line[4096];
        for (bool first = true; std::fgets(line, sizeof line, in); first = false)
          if (first || std::strtod(line, nullptr) <= time * (1 + 1e-12)) kept += line;
        std::fclose(in);
        try {
          std::FILE *out = open_atomic(path);
          std::fputs(kept.c_str(), out);
          close_atomic(out);
        } catch (const UserError &e) {
          bad = true;
          msg = e.what();
        }
      }
    }
    if (!bad) bodies_csv_ = std::fopen(path.c_str(), nsteps > 0 && !cfg.restart.empty() ? "a" : "w");
    if (!bad && !bodies_csv_) {
      bad = true;
      msg = "cannot write " + path + " (" + std::strerror(errno) + "): check -output_dir";
    }
    if (bodies_csv_ && std::ftell(bodies_csv_) == 0)
      std::fprintf(bodies_csv_, dim == 3 ? "time,body,x,y,z,vx,vy,vz,omega,fx,fy,fz,torque,angle\n" : "time,body,x,y,vx,vy,omega,fx,fy,torque,angle\n");
  }
  if (rank == 0 && bodies_csv_) {
    // Pose and velocity at the current time; forces of the last step's grid update (0 before the first).
    const RigidBodies<dim> &now = *bodies;
    for (size_t k = 0; k < now.size(); ++k) {
      const BodyPose &q = now.pose(k);
      const double *f = &now.forces()[4 * k];
      std::fprintf(bodies_csv_, "%.9e,%zu", time, k);
      for (int d = 0; d < dim; ++d) std::fprintf(bodies_csv_, ",%.9e", q.c[d]);
      for (int d = 0; d < dim; ++d) std::fprintf(bodies_csv_, ",%.9e", now.velocity(k)[d]);
      std::fprintf(bodies_csv_, ",%.9e", now.omega(k));
      for (int d = 0; d < dim; ++d) std::fprintf(bodies_csv_, ",%.9e", f[d]);
      std::fprintf(bodies_csv_, ",%.9e,%.9e\n", f[3], q.angle);
    }
    errno = 0;
    if (std::fflush(bodies_csv_) != 0 || std::ferror(bodies_csv_)) {
      bad = true;
      msg = "cannot write " + path + " (" + (errno ? std::strerror(errno) : "write failed") + "): check -output_dir";
    }
  }
  collective_fail(comm, bad, msg);
}

template <int dim>
std::vector<double> Simulation<dim>::grid_velocity_at_particles() {
  std::vector<double> out;
  std::visit(
      [&](const auto &sh) {
        using S = std::decay_t<decltype(sh)>;
        NodeView<dim> g = grid.begin_local(false);
        ParticleView<dim> P = particles.get();
        out.resize((size_t)P.n * dim);
        Stencil<dim, S> st;
        G2POutput<dim> o;
        for (PetscInt p = 0; p < P.n; ++p) {
          st.compute(sh, P.x + p * dim, grid.x0, grid.inv_h);
          g2p_particle(st, grid.h, g, o);
          for (int d = 0; d < dim; ++d) out[(size_t)p * dim + d] = o.v_pic[d];
        }
        particles.restore(P);
        grid.end_local();
      },
      shape);
  return out;
}

// ---------------------------------------------------------------------------------------

template <int dim>
Totals Simulation<dim>::totals() const {
  auto &P0 = const_cast<Particles<dim> &>(particles);
  ParticleView<dim> P = P0.get();
  double loc[3 + 2] = {0, 0, 0, 0, 0};
  double v2max = 0;
  for (PetscInt p = 0; p < P.n; ++p) {
    double v2 = 0;
    loc[0] += P.m[p];
    for (int d = 0; d < dim; ++d) {
      loc[1 + d] += P.m[p] * P.v[p * dim + d];
      v2 += P.v[p * dim + d] * P.v[p * dim + d];
    }
    loc[4] += 0.5 * P.m[p] * v2;
    v2max = std::max(v2max, v2);
  }
  P0.restore(P);
  double glob[5];
  MPI_Allreduce(loc, glob, 5, MPI_DOUBLE, MPI_SUM, comm);
  Totals t;
  t.n = particles.global_size();
  t.mass = glob[0];
  for (int d = 0; d < 3; ++d) t.momentum[d] = glob[1 + d];
  t.kinetic = glob[4];
  double vm = std::sqrt(v2max);
  MPI_Allreduce(&vm, &t.vmax, 1, MPI_DOUBLE, MPI_MAX, comm);
  const_cast<Simulation *>(this)->vmax = t.vmax;
  return t;
}

template <int dim>
std::vector<ParticleRecord> Simulation<dim>::gather(int root) const {
  auto &P0 = const_cast<Particles<dim> &>(particles);
  ParticleView<dim> P = P0.get();
  std::vector<ParticleRecord> mine(P.n);
  for (PetscInt p = 0; p < P.n; ++p) {
    ParticleRecord &r = mine[p];
    r = ParticleRecord{};
    r.id = P.id[p];
    for (int d = 0; d < dim; ++d) {
      r.x[d] = P.x[p * dim + d];
      r.v[d] = P.v[p * dim + d];
    }
    for (int c = 0; c < 6; ++c) r.s[c] = P.s[6 * p + c];
    r.m = P.m[p];
    r.vol = P.vol[p];
    r.g = P.g ? P.g[p] : 0.0;
  }
  P0.restore(P);
  int n = (int)(mine.size() * sizeof(ParticleRecord));
  std::vector<int> counts(size), displs(size);
  MPI_Gather(&n, 1, MPI_INT, counts.data(), 1, MPI_INT, root, comm);
  std::vector<ParticleRecord> all;
  if (rank == root) {
    int tot = 0;
    for (int r = 0; r < size; ++r) {
      displs[r] = tot;
      tot += counts[r];
    }
    all.resize(tot / sizeof(ParticleRecord));
  }
  MPI_Gatherv(mine.data(), n, MPI_BYTE, all.data(), counts.data(), displs.data(), MPI_BYTE, root, comm);
  std::sort(all.begin(), all.end(), [](const ParticleRecord &a, const ParticleRecord &b) { return a.id < b.id; });
  return all;
}

// ---------------------------------------------------------------------------------------

template <int dim>
void Simulation<dim>::backup_state() {
  backup_.resize(particles.field_meta().size());
  DM sw = particles.dm();
  const PetscInt n = particles.local_size();
  size_t k = 0;
  for (const FieldMeta &f : particles.field_meta()) {
    void *data = nullptr;
    const size_t bytes = (size_t)n * f.bs * (f.type == PETSC_INT64 ? 8 : f.type == PETSC_INT ? sizeof(PetscInt) : sizeof(double));
    GM_CALL(DMSwarmGetField(sw, f.name.c_str(), NULL, NULL, &data));
    backup_[k].assign((const char *)data, (const char *)data + bytes);
    GM_CALL(DMSwarmRestoreField(sw, f.name.c_str(), NULL, NULL, &data));
    ++k;
  }
  backup_scalars_ = {time, (double)nsteps, vmax, plastic_limit, ke_, (double)n, (double)particles.removed_total, particles.removed_mass_total,
                     (double)output->count()};
  backup_ranges_.clear();
  for (int d = 0; d < dim; ++d) backup_ranges_.push_back(grid.ranges(d));
  if (bodies) backup_bodies_ = bodies->state();
  // The steady solver's nodal g is part of the state a checkpoint holds (the next solve's
  // guess) and its schedule decides when the next solve happens: without them the "last
  // good" checkpoint would carry the g of a later (unstable) step.
  if (fluidity) {
    const PetscScalar *g = nullptr;
    PetscInt m = 0;
    GM_CALL(VecGetLocalSize(fluidity->solution(), &m));
    GM_CALL(VecGetArrayRead(fluidity->solution(), &g));
    backup_g_.assign(g, g + m);
    GM_CALL(VecRestoreArrayRead(fluidity->solution(), &g));
    backup_fluidity_schedule_ = fluidity->state();
  }
  ke_backup_ = ke_;
}

// Signs of an instability that the guards can see before they stop the run: a fixed step
// above the stability limit (-dt_allow_unstable), kinetic energy above all the energy the
// scene can supply (the guard stops at -energy_bound_factor times that), or kinetic energy
// multiplied by more than 10 since the last step (an explicit instability grows
// exponentially: the chute at 6x the CFL step gained 10-800x per step for 5 steps before
// the guard; a flow starting from rest gains 4x from step 1 to 2, then less). Growth from
// below 1e-6 of the available energy is not counted (start-up from rest).
template <int dim>
bool Simulation<dim>::instability_sign(double dt) const {
  if (!implicit && cfg.dt > 0 && dt > dt_limit()) return true;
  if (ke_ > energy_bound_) return true;
  return ke_backup_ > 1e-6 * energy_bound_ && ke_ > 10 * ke_backup_;
}

template <int dim>
void Simulation<dim>::restore_state() {
  // The backup may be many steps old: the particles have moved between ranks (and the grid
  // may have been repartitioned) since; each rank gets back what it held then.
  particles.set_local_size((PetscInt)backup_scalars_[5]);
  DM sw = particles.dm();
  size_t k = 0;
  for (const FieldMeta &f : particles.field_meta()) {
    void *data = nullptr;
    GM_CALL(DMSwarmGetField(sw, f.name.c_str(), NULL, NULL, &data));
    std::copy(backup_[k].begin(), backup_[k].end(), (char *)data);
    GM_CALL(DMSwarmRestoreField(sw, f.name.c_str(), NULL, NULL, &data));
    ++k;
  }
  time = backup_scalars_[0];
  nsteps = (long)backup_scalars_[1];
  vmax = backup_scalars_[2];
  plastic_limit = backup_scalars_[3];
  ke_ = backup_scalars_[4];
  particles.removed_total = (long)backup_scalars_[6];
  particles.removed_mass_total = backup_scalars_[7];
  std::vector<typename Output<dim>::Frame> fr = output->frames();
  fr.resize(std::min(fr.size(), (size_t)backup_scalars_[8])); // snapshots after the backup are not part of it
  output->set_frames(fr);
  if (bodies) bodies->set_state(backup_bodies_);
  bool same = true;
  for (int d = 0; d < dim; ++d) same = same && backup_ranges_[d] == grid.ranges(d);
  if (!same) repartition(backup_ranges_);
  if (fluidity && !backup_g_.empty()) { // after the repartition: the layout is the backup's again
    PetscScalar *g = nullptr;
    PetscInt m = 0;
    GM_CALL(VecGetLocalSize(fluidity->solution(), &m));
    if ((size_t)m != backup_g_.size()) throw std::logic_error("restore_state: the fluidity layout differs from the backup's");
    GM_CALL(VecGetArray(fluidity->solution(), &g));
    std::copy(backup_g_.begin(), backup_g_.end(), g);
    GM_CALL(VecRestoreArray(fluidity->solution(), &g));
    fluidity->set_state(backup_fluidity_schedule_);
  }
}

template <int dim>
void Simulation<dim>::write_checkpoint(const std::string &path) {
  GM_CALL(PetscLogStagePush(st_out_));
  Checkpoint<dim>::write(*this, path);
  GM_CALL(PetscLogStagePop());
}

// ---------------------------------------------------------------------------------------
// Load balance

template <int dim>
double Simulation<dim>::imbalance() const {
  const long n = particles.local_size();
  long mx = 0, sum = 0;
  MPI_Allreduce(&n, &mx, 1, MPI_LONG, MPI_MAX, comm);
  MPI_Allreduce(&n, &sum, 1, MPI_LONG, MPI_SUM, comm);
  return sum > 0 ? (double)mx * size / sum : 1.0;
}

template <int dim>
std::vector<std::vector<PetscInt>> Simulation<dim>::balanced_split() const {
  // Marginal particle counts per owner cell in each direction (one allreduce of
  // sum(M[d]) doubles), cut into equal shares.
  std::vector<double> w;
  size_t off[3] = {0, 0, 0};
  for (int d = 0; d < dim; ++d) {
    off[d] = w.size();
    w.resize(w.size() + grid.M[d], 0.0);
  }
  auto &P0 = const_cast<Particles<dim> &>(particles);
  ParticleView<dim> P = P0.get();
  for (PetscInt p = 0; p < P.n; ++p)
    for (int d = 0; d < dim; ++d) w[off[d] + grid.owner_cell(d, P.x[p * dim + d])] += 1;
  P0.restore(P);
  MPI_Allreduce(MPI_IN_PLACE, w.data(), (int)w.size(), MPI_DOUBLE, MPI_SUM, comm);
  std::vector<std::vector<PetscInt>> l(dim);
  for (int d = 0; d < dim; ++d)
    l[d] = balanced_ranges(std::vector<double>(w.begin() + off[d], w.begin() + off[d] + grid.M[d]), grid.nproc[d], 2);
  return l;
}

template <int dim>
bool Simulation<dim>::rebalance() {
  if (size == 1) return false;
  const double before = imbalance();
  if (before <= cfg.balance_threshold) return false;
  GM_CALL(PetscLogStagePush(st_migrate_));
  const std::vector<std::vector<PetscInt>> l = balanced_split();
  bool same = true;
  for (int d = 0; d < dim; ++d) same = same && l[d] == grid.ranges(d);
  // The particles per rank the new split would give (exact: every particle's new owner).
  double predicted = before;
  if (!same) {
    std::vector<int> own[dim];
    for (int d = 0; d < dim; ++d) own[d] = owner_map(l[d]);
    std::vector<long> cnt(size, 0);
    ParticleView<dim> P = particles.get();
    for (PetscInt p = 0; p < P.n; ++p) {
      int r = 0, stride = 1;
      for (int d = 0; d < dim; ++d) {
        r += own[d][grid.owner_cell(d, P.x[p * dim + d])] * stride;
        stride *= grid.nproc[d];
      }
      ++cnt[r];
    }
    particles.restore(P);
    MPI_Allreduce(MPI_IN_PLACE, cnt.data(), size, MPI_LONG, MPI_SUM, comm);
    long mx = 0, sum = 0;
    for (long c : cnt) {
      mx = std::max(mx, c);
      sum += c;
    }
    predicted = sum > 0 ? (double)mx * size / sum : 1.0;
  }
  // Repartition only when it helps: the tensor-product split may not get below the
  // threshold (a cluster smaller than the rank grid), and then nothing is gained.
  const bool go = !same && predicted < before;
  if (go) {
    repartition(l);
    ++rebalances;
    imbalance_before = before;
    imbalance_after = imbalance();
  }
  GM_CALL(PetscLogStagePop());
  if (go && rank == 0 && !cfg.quiet) {
    std::printf("GranMPM: step %ld: rebalanced, particles per rank max/mean %.3f -> %.3f; nodes per rank", nsteps, imbalance_before, imbalance_after);
    for (int d = 0; d < dim; ++d) {
      std::printf(" %c:", "xyz"[d]);
      for (size_t r = 0; r < l[d].size(); ++r) std::printf("%s%ld", r ? "," : "", (long)l[d][r]);
    }
    std::printf("\n");
    std::fflush(stdout);
  }
  return go;
}

template <int dim>
typename Simulation<dim>::Footprint Simulation<dim>::footprint() const {
  double pb = 0, nb = 0;
  for (const FieldMeta &f : particles.field_meta()) pb += (double)f.bs * (f.type == PETSC_INT64 ? 8 : f.type == PETSC_INT ? sizeof(PetscInt) : sizeof(double));
  const double n = (double)particles.local_size();
  double buffers = (double)(Lbuf_.capacity() + xvel_.capacity() + lapbuf_.capacity()) * sizeof(double) + (double)cellbuf_.capacity() * sizeof(long);
  PetscInt ng, nl;
  GM_CALL(VecGetLocalSize(grid.global, &ng));
  GM_CALL(VecGetLocalSize(grid.local, &nl));
  nb = (double)(ng + nl) * sizeof(double);
  double loc[3] = {pb * n + buffers, nb, n}, glob[3];
  MPI_Allreduce(loc, glob, 3, MPI_DOUBLE, MPI_SUM, comm);
  double nodes = 1;
  for (int d = 0; d < dim; ++d) nodes *= grid.M[d];
  Footprint f;
  f.per_particle = glob[2] > 0 ? glob[0] / glob[2] : 0;
  f.per_node = glob[1] / nodes;
  return f;
}

template <int dim>
void Simulation<dim>::sort_particles() {
  GM_CALL(PetscLogStagePush(st_migrate_));
  particles.sort_by_cell(grid);
  GM_CALL(PetscLogStagePop());
}

template <int dim>
std::unique_ptr<FluiditySolver<dim>> Simulation<dim>::new_fluidity_solver() {
  auto f = std::make_unique<FluiditySolver<dim>>(grid, cfg);
  if (bodies && cfg.body_fluidity_bc == BodyFluidityBC::Zero)
    f->set_zero_nodes([this](const double *x) { // the grid contact nodes (poses of the current step)
      for (size_t k = 0; k < bodies->size(); ++k)
        if (bodies->sdf(k, x) < bodies->layer()) return true; // layer() is in metres
      return false;
    });
  return f;
}

template <int dim>
void Simulation<dim>::repartition(const std::vector<std::vector<PetscInt>> &l) {
  grid.create(comm, cfg, l.data());
  if (fluidity) {
    // New solver on the new layout; the nodal fluidity (next solve's initial guess) is
    // carried over in PETSc's natural ordering, so it is the same field exactly.
    std::unique_ptr<FluiditySolver<dim>> fresh = new_fluidity_solver();
    copy_across_layouts(comm, fluidity->da(), fluidity->solution(), fresh->da(), fresh->solution());
    fresh->last_iterations = fluidity->last_iterations;
    fresh->solves = fluidity->solves;
    fresh->iterations_total = fluidity->iterations_total;
    fresh->pc_setups = fluidity->pc_setups;
    fresh->skipped = fluidity->skipped;
    fresh->set_state(fluidity->state());
    fluidity = std::move(fresh);
  }
  if (dyn_fluidity) {
    // Its nodal fields are rebuilt from the particles every step: nothing to carry over.
    std::unique_ptr<DynamicFluidity<dim>> fresh = std::make_unique<DynamicFluidity<dim>>(grid, cfg);
    fresh->last_iterations = dyn_fluidity->last_iterations;
    fresh->solves = dyn_fluidity->solves;
    dyn_fluidity = std::move(fresh);
  }
  if (density) density = std::make_unique<CellDensity<dim>>(grid, cfg);
  if (implicit) implicit->rebuild();
  particles.migrate(grid);
}

template <int dim>
std::map<std::string, double> Simulation<dim>::run() {
  Scene<dim> scene(*this);
  const double t0 = MPI_Wtime();
  const double sim_t0 = time;
  const long np0 = particles.global_size();
  const double imb_start = imbalance();
  if (rank == 0 && !cfg.quiet) {
    std::printf("GranMPM: %s\n", stage_summary.c_str());
    std::printf("GranMPM: %ld particles, grid %d x %d%s nodes on %d rank(s), h = %g m, wave speed %g m/s, CFL limit %g s\n", np0, grid.M[0],
                grid.M[1], dim == 3 ? (" x " + std::to_string(grid.M[2])).c_str() : "", size, grid.h, wave_speed, dt_limit());
    if (!cfg.restart.empty()) std::printf("GranMPM: restarted from %s at step %ld, t = %g s\n", cfg.restart.c_str(), nsteps, time);
    std::fflush(stdout);
  }
  const double eps = 1e-12 * cfg.t_end;
  if (!cfg.restart.empty() && time >= cfg.t_end - eps) {
    // Nothing to do: say so, write nothing (the run's results stay as they are).
    if (rank == 0)
      std::printf("GranMPM: the checkpoint is at t = %.17g s, at or past -t_end %.17g s: nothing to run (raise -t_end to continue the run)\n", time, cfg.t_end);
    scene.metrics["interrupted"] = 0.0;
    scene.metrics["nothing_to_run"] = 1.0;
    return scene.metrics;
  }
  if (cfg.output_interval > 0 && nsteps == 0) {
    GM_CALL(PetscLogStagePush(st_out_));
    output->write(scene);
    GM_CALL(PetscLogStagePop());
  }
  scene.on_step(*this);
  if (bodies && nsteps == 0) write_bodies_row();
  int interrupted = 0; // the signal that stopped the run
  while (time < cfg.t_end - eps && (cfg.max_steps < 0 || nsteps < cfg.max_steps)) {
    double dt = cfg.dt > 0 ? cfg.dt : cfl_dt();
    if (implicit) dt = implicit->next_dt(dt);
    if (!implicit && cfg.dt > 0 && !cfg.dt_allow_unstable && dt > dt_limit()) {
      std::ostringstream m;
      if (plastic_limit < dt_cfl_limit() && cfg.material == MaterialKind::Dynamic)
        m << "at t = " << time << " -dt " << cfg.dt << " exceeds the stability limit " << plastic_limit
          << " s of the explicit dynamical fluidity step (diffusion dx^2 t0/(2 dim A^2 d^2) or local relaxation); use -fluidity_step implicit, reduce -dt, or -dt 0 for automatic steps";
      else if (plastic_limit < dt_cfl_limit())
        m << "at t = " << time << " -dt " << cfg.dt << " exceeds the stability limit " << plastic_limit
          << " s of the explicit granular stress update (G dt / eta < 2); use -stress_update implicit, reduce -dt, or -dt 0 for automatic steps";
      else
        m << "at t = " << time << " the particle speed " << vmax << " m/s makes -dt " << cfg.dt << " exceed the CFL limit h/(c+|v|max) = " << dt_limit()
          << " s; reduce -dt (or use -dt 0 for automatic steps)";
      collective_fail(comm, true, m.str());
    }
    if (time + dt > cfg.t_end) dt = cfg.t_end - time;
    // Before the backup: both change the particles' ranks and order.
    if (cfg.balance_threshold > 0 && nsteps % cfg.balance_interval == 0) rebalance();
    if (cfg.sort_interval > 0 && nsteps % cfg.sort_interval == 0) sort_particles();
    if (cfg.checkpoint_on_instability) {
      sign_seen_ = sign_seen_ || (nsteps > 0 && instability_sign(dt));
      if (!sign_seen_ || backup_.empty()) backup_state();
    }
    try {
      dt = step(dt);
    } catch (const UserError &e) {
      if (!cfg.checkpoint_on_instability) throw;
      restore_state();
      const std::string path = cfg.output_dir + "/checkpoint_last_good.h5";
      write_checkpoint(path);
      std::ostringstream m;
      m << e.what() << " [the last good state (before the first sign of instability), step " << nsteps << " at t = " << time << ", was written to " << path
        << "; continue with -restart " << path << " and a smaller -dt or -cfl]";
      throw UserError(m.str());
    }
    if (nsteps == 1 && after_first_step) after_first_step();
    scene.on_step(*this);
    if (bodies && (nsteps % cfg.bodies_interval == 0 || (cfg.output_interval > 0 && nsteps % cfg.output_interval == 0) || time >= cfg.t_end - eps))
      write_bodies_row(); // every -bodies_interval steps, every output step and at t_end
    if (cfg.output_interval > 0 && nsteps % cfg.output_interval == 0) {
      GM_CALL(PetscLogStagePush(st_out_));
      output->write(scene);
      GM_CALL(PetscLogStagePop());
    }
    if (cfg.checkpoint_interval > 0 && nsteps % cfg.checkpoint_interval == 0) write_checkpoint(cfg.checkpoint_path());
    if (cfg.progress_interval > 0 && nsteps % cfg.progress_interval == 0 && !cfg.quiet) {
      const Totals tt = totals();
      const double wall = MPI_Wtime() - t0;
      const double eta = time > sim_t0 ? wall * (cfg.t_end - time) / (time - sim_t0) : 0;
      if (rank == 0) {
        std::printf("step %8ld  t %.5e  dt %.3e  KE %.6e  particles %ld  wall %.1f s  ETA %.1f s%s\n", nsteps, time, dt, tt.kinetic, tt.n, wall, eta,
                    implicit ? implicit->progress().c_str() : "");
        std::fflush(stdout);
      }
    }
    // A scheduler's SIGTERM (or Ctrl-C) on any rank: checkpoint and stop cleanly;
    // SIGUSR1: checkpoint and continue.
    int sig[2] = {(int)stop_signal, (int)checkpoint_signal}, got[2] = {0, 0};
    MPI_Allreduce(sig, got, 2, MPI_INT, MPI_MAX, comm);
    const int any = got[0];
    if (got[1] && !any) {
      checkpoint_signal = 0;
      const std::string path = cfg.checkpoint_path();
      write_checkpoint(path);
      if (rank == 0) {
        std::printf("GranMPM: received SIGUSR1 at step %ld, t = %g s; checkpoint written to %s; continuing\n", nsteps, time, path.c_str());
        std::fflush(stdout);
      }
    }
    if (any) {
      const std::string path = cfg.checkpoint_path();
      write_checkpoint(path);
      if (rank == 0)
        std::printf("GranMPM: received signal %d at step %ld, t = %g s; checkpoint written to %s (continue with -restart %s)\n", any, nsteps, time,
                    path.c_str(), path.c_str());
      interrupted = any;
      break;
    }
  }
  if (!interrupted && cfg.output_final && !(cfg.output_interval > 0 && nsteps % cfg.output_interval == 0)) {
    GM_CALL(PetscLogStagePush(st_out_));
    output->write(scene);
    GM_CALL(PetscLogStagePop());
  }
  if (!interrupted) {
    // The scene's CSV results are written on rank 0: a failure there must stop every rank.
    bool bad = false;
    std::string msg;
    try {
      scene.finalize(*this);
    } catch (const UserError &e) {
      bad = true;
      msg = e.what();
    }
    collective_fail(comm, bad, msg);
  }
  const double wall = MPI_Wtime() - t0;
  const long np1 = particles.global_size();
  struct rusage ru;
  getrusage(RUSAGE_SELF, &ru);
  double rss = ru.ru_maxrss / 1024.0, rss_sum = 0; // MiB (Linux reports KiB)
  MPI_Reduce(&rss, &rss_sum, 1, MPI_DOUBLE, MPI_SUM, 0, comm);
  const double imb_end = imbalance();
  const Footprint fp = footprint();
  if (rank == 0 && !cfg.quiet) {
    std::printf("GranMPM: %s, %ld steps to t = %g s in %.2f s wall (%.3g particle-steps/s); output in %s/\n", interrupted ? "interrupted" : "done", nsteps,
                time, wall, wall > 0 ? (double)np1 * nsteps / wall : 0.0, cfg.output_dir.c_str());
    std::printf("GranMPM: peak memory %.1f MiB over %d rank(s) (%.0f bytes per particle)\n", rss_sum, size, np1 > 0 ? rss_sum * 1048576.0 / np1 : 0.0);
    std::printf("GranMPM: particle data %.0f bytes per particle (swarm fields and step buffers), transfer grid %.0f bytes per node (global and ghosted vectors)\n",
                fp.per_particle, fp.per_node);
    if (implicit) std::printf("GranMPM: %s\n", implicit->summary().c_str());
    if (size > 1)
      std::printf("GranMPM: load balance: particles per rank max/mean %.3f at the start, %.3f at the end; %ld repartition(s) (-balance_threshold %g)\n", imb_start, imb_end,
                  rebalances, cfg.balance_threshold);
    if (particles.removed_total > 0) std::printf("GranMPM: %ld particles left through outlets\n", particles.removed_total);
    if (particles.wall_corrections > 0)
      std::printf("GranMPM: %ld times a particle was put back onto a wall it had crossed by less than a cell\n", particles.wall_corrections);
    if (body_corrections > 0)
      std::printf("GranMPM: %ld times a particle was put back onto a rigid body surface it had entered by less than a cell\n", body_corrections);
    if (bodies) std::printf("GranMPM: rigid body positions, forces and torques in %s/bodies.csv\n", cfg.output_dir.c_str());
  }
  if (bodies) scene.metrics["body_corrections"] = (double)body_corrections;
  scene.metrics["interrupted"] = (double)interrupted;
  return scene.metrics;
}

template class Simulation<2>;
template class Simulation<3>;

} // namespace granmpm
