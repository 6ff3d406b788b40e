// ImplicitSolver<dim>: the backward-Euler (implicit) momentum step, created only for
// -time_integrator implicit (and implicit_coupled, below). Updated-Lagrangian in the style of Guilkey & Weiss (2003):
// the unknowns are the grid velocities v = v^{n+1} (dof dim per node, on a DMDA with the
// transfer grid's ownership and BOX stencil width 2), and the residual is
//
//   R_i(v) = m_i (v_i - v_i^n)/dt + c m_i v_i - f_int,i(sigma(v)) - m_i b
//
// where v^n, m_i come from the normal P2G of mass and momentum, c is -damping, b the body
// acceleration, and f_int,i = -sum_p V_p sigma_p(v) grad N_i(x_p) at the start-of-step
// positions and volumes. sigma_p(v) is the material's own stress update from the start-of-
// step stress with L_p = sum_i v_theta,i (x) grad N_i(x_p) over theta dt, v_theta =
// theta v + (1 - theta) v^n (-implicit_theta: 1 backward Euler, 0.5 implicit midpoint),
// evaluated without committing: the particles are only read during the solve. Wall nodes (sticky: all components, slip:
// the normal one, as Grid::apply_bc decides) and nodes without mass are Dirichlet rows
// R = s v (s a typical m/dt), so their velocity is 0.
//
// SNES (prefix -implicit_, default Newton with line search, KSP GMRES) solves R(v) = 0 with
// the Jacobian applied matrix-free by finite differences and the preconditioning matrix
// P = M (1/dt + c) + theta^2 dt K_el, K_el the linear-elastic stiffness from grad N at the
// particles and the material's elastic moduli (-implicit_tangent scaled: per particle,
// moduli scaled by the granular stress return at the current iterate). Wall/empty-node rows and columns of K_el are dropped,
// so P is symmetric positive definite. For -material elastic, R is linear and P is exactly
// its Jacobian (-implicit_jacobian assembled). P is created once with DMCreateMatrix (the
// full width-2 box pattern) and only refilled, so there are no mallocs after the first
// assembly.
//
// After convergence the converged velocities go through the normal G2P (the -transfer
// scheme) and the particles move with the interpolated grid velocity; the stress and
// volume are committed by the normal constitutive update with the same L. A failed solve
// (any negative SNESConvergedReason) never continues: with -implicit_dt_adapt the step is
// retried with dt/2 (nothing was committed), otherwise the run stops with an error.
//
// -time_integrator implicit_coupled (-material nonlocal only): the same DMDA carries dim + 1
// dofs per node, the velocities and the steady fluidity g^{n+1}, and one SNES solves
//
//   R_v(v, g) = the momentum residual above, sigma_p = NonlocalNGF update with g_p(g)
//   R_g(v, g) = s_g [ K(w(sigma(v, g))) g - f(w, g_loc(sigma(v, g))) ]
//
// K and f are FluiditySolver's Galerkin system (Q1 hat functions, integrated at the
// particles with the start-of-step volumes; fluidity_element_contribution), built from the
// trial stress instead of the start-of-step stress; g_p is g interpolated (or cell-averaged,
// -fluidity_map) to the particle. Nodes touched by no particle-holding cell have g = 0
// (rows s_g h^dim g). s_g = (m_avg/dt) h / h^dim makes a fluidity error dg weigh in the
// SNES norm like a velocity error of about h dg / 2. The preconditioning matrix is block
// diagonal: the elastic momentum block above and s_g K at the current iterate (the
// momentum-fluidity coupling is left to the matrix-free operator). docs/implicit.md.
#pragma once

#include <petscdmda.h>
#include <petscsnes.h>

#include <string>
#include <vector>
#include "granmpm/particles.hpp"
#include "granmpm/tensor.hpp"

namespace granmpm {

template <int dim>
struct State;

// What the implicit solver calls back into: the transfers and the stress update of the
// explicit step, on the shared State (Simulation implements them). The solver evaluates
// the stress at trial velocities itself (trial_stress, on copies of the particle stress).
template <int dim>
class StepOps {
public:
  enum G2PMode : unsigned { kVel = 1, kL = 2, kMove = 4, kStoreXv = 8, kApplyXv = 16, kC = 32 };
  virtual ~StepOps() = default;
  virtual void p2g(bool with_force) = 0;             // mass, momentum [, force] -> global grid
  virtual void g2p(double dt, unsigned mode) = 0;    // grid -> particles, as mode says
  virtual void constitutive(double dt) = 0;          // stress update from the stored L
  virtual double min_node_mass() const = 0;          // nodes at or below it are empty
  virtual const double *body_acceleration() const = 0; // gravity of this step (dim values)
};

template <int dim>
class ImplicitSolver {
public:
  ImplicitSolver(State<dim> &state, StepOps<dim> &ops);
  ~ImplicitSolver();
  ImplicitSolver(const ImplicitSolver &) = delete;
  ImplicitSolver &operator=(const ImplicitSolver &) = delete;

  // One implicit step from the current state trying dt first (halving on failure when
  // adaptive); commits the particles and returns the dt actually taken. Collective.
  double advance(double dt);
  // The step to try next: the first step (dt0), then as adapted.
  double next_dt(double dt0) const;
  // " SNES its N (KSP M)..." for the progress line.
  std::string progress() const;
  std::string summary() const;

  // Re-creates every object built on the transfer grid's DMDA (after Simulation::
  // repartition); the step-size state and counters are kept.
  void rebuild();
  SNES snes() const { return snes_; }
  Mat preconditioner() const { return P_; }
  PetscInt last_snes_its = 0, last_ksp_its = 0;
  int last_retries = 0;
  long steps = 0, failures = 0, snes_its_total = 0, ksp_its_total = 0;

private:
  void create_objects();
  void sum_ghosted_into_r();
  void destroy_objects();
  bool solve(double dt);
  void commit(double dt);
  void residual(Vec V, Vec R);
  void assemble_preconditioner(Vec X, Mat P);
  void fluidity_to_particles();
  void theta_velocity_to_local(Vec V);
  double force_scale();
  static PetscErrorCode form_function(SNES, Vec, Vec, void *);
  static PetscErrorCode form_jacobian(SNES, Vec, Mat, Mat, void *);
  template <class S>
  void residual_impl(const S &sh, const double *va, double *fa, double dt_stress, bool absval);
  template <class S>
  void preconditioner_impl(const S &sh, Mat P, const double *va, bool scaled);
  template <class S>
  void trial_stresses(const S &sh, const ParticleView<dim> &P, const double *va, double dt);
  double prepare_nodes();
  void prepare_fluidity_nodes(const std::vector<double> &gprev);
  void owned_to_local(Vec local, bool fixed_mask);
  std::vector<Mat3> tL_, tsig_; // per particle: trial velocity gradient and stress
  std::vector<double> tg_;      // coupled: trial fluidity at the particle

  State<dim> &sim_;
  StepOps<dim> &ops_;
  const double *acc_; // ops_.body_acceleration(): fixed storage, updated by the step
  double m_min_;      // ops_.min_node_mass(), fixed at set-up
  bool coupled_ = false; // -time_integrator implicit_coupled: dof dim + 1 (velocity, g)
  int nd_ = dim;         // dofs per node
  double kf_ = 0, sg_ = 0; // (A d)^2; the fluidity rows' scale
  DM vda_ = nullptr;
  Vec v_ = nullptr, r_ = nullptr, vloc_ = nullptr, floc_ = nullptr, fixloc_ = nullptr, vnloc_ = nullptr;
  Mat P_ = nullptr;
  SNES snes_ = nullptr;
  bool user_atol_ = false;
  std::vector<double> mass_, vn_; // owned nodes (mass), owned dofs (v^n; coupled: previous g as the guess)
  std::vector<char> fixed_;       // owned dofs: Dirichlet (coupled: g of inactive nodes)
  double dt_ = 0, diag_ = 1, next_dt_ = 0, dt_min_ = 0;
  std::string last_failure_;
};

} // namespace granmpm
