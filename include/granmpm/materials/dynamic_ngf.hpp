// Hyperelastic dynamical nonlocal granular fluidity (seed 004 §2-3.2, eqs. 6 and 17-31,
// Fig. 3-4; model.md §3.2). Pure per-particle kernel: no PETSc, no MPI, no heap allocation
// (fixed-size Eigen only).
//
// State per particle: B = Be - I, Be = Fe Fe^T the elastic left Cauchy-Green tensor (6 numbers;
// F = Fe Fp), the fluidity g, and p, mu of the last step. The seed stores F and Fp (18
// numbers); the model is isotropic, so the stress depends on Fe only through Be (the rotation
// R of Fe = R U is never read), and Be is all a step needs (issue 16: memory per particle).
// Be - I rather than Be: elastic strains are ~1e-4, and Be = I + O(1e-4) would lose 4 digits
// of the strain to the 1 on the diagonal (its eigenvalues are taken as 1 + mu, ln = log1p).
// One step, given L = grad v, the grid Laplacian of g (lap_g) and the density rho:
//
//   f       = I + dt L                  (or exp(dt L)): F_{n+1} = f F_n. Seed 004 eq. 18 prints
//                                        F_n (1 + dt L), which integrates F' = F L; with
//                                        L = grad_x v the kinematics (its eq. 17) is F' = L F.
//   Fe_tr   = F_{n+1} Fp_n^-1 = f Fe_n = Us diag(s) Vs^T, so
//   Be_tr   = f Be_n f^T = Us diag(s^2) Us^T (symmetric eigenproblem; Fe_tr inverted iff det f <= 0,
//             B_tr = f B_n f^T + (f f^T - I), f f^T - I = dt (L + L^T) + dt^2 L L^T,
//             since det Fe_n > 0), V = Us diag(s) Us^T, Ee = ln V = Us diag(ln s) Us^T (eq. 20,
//             in the spatial frame: R M R^T below needs only Us)
//   M_tr    = 2G dev Ee + K tr(Ee) I    (Mandel stress, eq. 21, rotated), p_M = -K ln Je
//
// The four particle states of seed 004 Fig. 3:
//   p_M <= 0, rho < rho_c, or Fe inverted  -> stress-free: sigma = 0, Be = I (Fp = F_{n+1}: the
//       elastic strain resets, so the particle re-enters stress-free at its current shape),
//       p_prev = 0 marks it. State 2 if it was connected, else state 3. g is kept frozen:
//       it is overwritten on reconnection anyway, and seed 004 (after its ref. [48]) does not
//       transfer the fluidity of open particles to the grid -- the caller must skip particles
//       with !connected() when building lap g.
//   p_prev == 0 (state 4, reconnecting) -> kinematic fluidity g = sqrt(2)|D|/mu_2 (eq. 23).
//   otherwise (state 1) -> fluidity step of eq. 6 (see FluidityStep): explicit with mu_n, p_n
//       of the last step (eq. 24, the seed's scheme), backward Euler with mu_n, p_n frozen, or
//       backward Euler coupled to this step's return (mu_{n+1}, p_{n+1}).
//   Then the closed-form return (eqs. 25-26), at fixed trial pressure:
//       tau_tr = |dev M_tr|/sqrt 2, N = dev M_tr/(sqrt 2 tau_tr),
//       tau = tau_tr p_M / (p_M + G dt g)        [tau = tau_tr - G dt gdot, gdot = g tau/p_M]
//       M = M_tr - sqrt 2 (tau_tr - tau) N, sigma = R M R^T / Je (eq. 27).
//   Plastic flow (eqs. 29-31): gdot_p = g tau/p, Lp = gdot_p N/sqrt 2,
//       Fp_{n+1} = exp(dt Lp) Fp_n, i.e. Be_{n+1} = Us diag(exp(2 (scale dev_i + tr/3))) Us^T.
//
// Choices that differ from (or pin down) the seed, and why:
//  * gdot_p = g tau_{n+1}/p also on reconnection. The seed sets mu = mu_2 there (and its
//    pseudo-code caps mu at mu_2), which would make the plastic increment in Fp differ from
//    the stress drop of the return; with gdot = g tau/p the stored Be reproduces exactly the
//    returned stress (tested), so the next trial state starts from the stress we reported.
//  * Fp uses the exponential instead of the forward Euler of eq. 31: N is diagonal in the
//    principal basis, so exp(dt Lp) = Vs diag(exp(.)) Vs^T costs three exp() calls, keeps det Fp = 1
//    to round-off (N is traceless) and makes Ee_{n+1} = Ee_tr - dt Lp exact.
//  * Cauchy stress divides the Kirchhoff stress R M R^T by Je = det Fe (the seed divides by
//    det F). They agree while det Fp = 1; after a stress-free reset Fp = F has det Fp != 1
//    and the elastic energy is per unit volume of the intermediate configuration, so Je is
//    the right Jacobian (Je = sqrt(det Be)).
//  * Be instead of F, Fp (above): the same stress and flow in exact arithmetic; the total F
//    (seed output) is not kept.
//  * mu = tau/p is the same for Mandel and Cauchy invariants. The return uses the Mandel
//    pair (tau_M, p_M), where it is exact; the rheology (sqrt(rho_s d^2/p) in eq. 6) and the
//    stored p_prev use the Cauchy pressure p = p_M/Je, the pressure of the mu(I) law
//    (model.md notation). They differ by the elastic volume change, O(1e-3).
#pragma once

#include "granmpm/materials/local_mu_i.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace granmpm {

// How the fluidity ODE (seed 004 eq. 6) is advanced per particle, given lap g (always
// explicit here; the grid-level implicit diffusion is done elsewhere):
//   Explicit        forward Euler with mu_n, p_n of the last step (seed 004 eq. 24).
//   Implicit        backward Euler in g, mu_n and p_n frozen (a quadratic in g_{n+1}).
//   ImplicitCoupled backward Euler in g with mu_{n+1} = tau_{n+1}/p taken from this step's
//                   return, tau_{n+1} = tau_tr p/(p + G dt g_{n+1}); still a quadratic.
// Explicit and Implicit both lag mu, and that lag, not the g step, limits dt in practice:
// see dynamic_ngf_local_dt_limit. ImplicitCoupled has no local step limit.
enum class FluidityStep { Explicit = 0, Implicit = 1, ImplicitCoupled = 2 };
// How F is advanced: F_{n+1} = (I + dt L) F_n (seed 004 eq. 18) or exp(dt L) F_n.
enum class KinematicUpdate { ForwardEuler = 0, Exponential = 1 };

struct DynamicNGFParams {
  ElasticModuli el;
  GranularParams gp;
  double t0 = 1e-4; // material time scale of the fluidity [s] (seed 004 Table 1)
  // Smallest fluidity of a connected particle. g = 0 is a fixed point of eq. 6, and a g that
  // decayed (mu < mu_s) into the subnormal range can no longer grow when mu later exceeds
  // mu_s: 4 ulp times (1 + dt (mu - mu_s)/t0) rounds back to 4 ulp. A positive floor keeps
  // the growth representable; the creep it allows, mu g_min, is negligible for g_min ~ 1e-8/s.
  double g_min = 0;
  KinematicUpdate f_update = KinematicUpdate::ForwardEuler;
};

struct DynamicNGFState {
  Mat3 B = Mat3::Zero(); // Be - I, Be = Fe Fe^T the elastic left Cauchy-Green tensor (symmetric)
  double g = 0;       // granular fluidity [1/s]
  double p_prev = 0;  // Cauchy pressure after the last step; 0 marks "disconnected"
  double mu_prev = 0; // tau/p after the last step
  bool connected() const { return p_prev > 0; }
};

// Seed 004 Fig. 3 numbering.
enum class NGFParticleState { Compressed = 1, Separating = 2, Free = 3, Reconnecting = 4 };

struct DynamicNGFResult {
  Mat3 sigma = Mat3::Zero(); // Cauchy stress
  double p = 0, tau = 0;     // Cauchy invariants of sigma
  double mu = 0;             // tau/p (0 when stress-free)
  double gdot_p = 0;         // equivalent plastic shear rate g tau/p
  double g = 0;              // fluidity after the step
  NGFParticleState state = NGFParticleState::Free;
};

// exp(A) for a 3x3 matrix: scaling and squaring with a Taylor series (|A/2^s| <= 1/2, so
// the truncated tail is below 1e-16 relative). Used for exp(dt L); allocation-free.
inline Mat3 expm3(const Mat3 &A) {
  const double nrm = A.cwiseAbs().rowwise().sum().maxCoeff(); // infinity norm
  int s = 0;
  if (nrm > 0.5) s = std::min(60, static_cast<int>(std::ceil(std::log2(nrm / 0.5))));
  const Mat3 B = std::ldexp(1.0, -s) * A;
  Mat3 E = Mat3::Identity(), term = Mat3::Identity();
  for (int k = 1; k <= 24; ++k) {
    term = (term * B) / static_cast<double>(k);
    E += term;
    if (!(term.cwiseAbs().maxCoeff() > 1e-17 * E.cwiseAbs().maxCoeff())) break;
  }
  for (int i = 0; i < s; ++i) E = (E * E).eval();
  return E;
}

namespace detail {
// Hencky strain of Be = I + B in its principal basis: Be = Us diag(s^2) Us^T (Us a rotation:
// the left basis of Fe), Ee = ln V = Us diag(ln s) Us^T. ok = false if Be is not positive
// definite (Fe singular) or not finite.
struct Hencky {
  Mat3 Us;
  Vec3 dev;      // deviatoric principal Hencky strains
  double tr = 0; // tr Ee = ln det Fe
  bool ok = false;
};

// Larger root of a2 g^2 + a1 g - gamma = 0 (a2 > 0), clamped at 0 (g >= 0 is a
// constraint; 0 also when the roots are complex). Written without cancellation for either
// sign of a1; both forms are the same root since (sq - a1)(sq + a1) = 4 a2 gamma.
inline double larger_root(double a2, double a1, double gamma) {
  const double disc = a1 * a1 + 4.0 * a2 * gamma;
  if (!(disc >= 0)) return 0.0;
  const double sq = std::sqrt(disc);
  const double r = (a1 > 0) ? 2.0 * gamma / (a1 + sq) : (sq - a1) / (2.0 * a2);
  return r > 0 ? r : 0.0; // also maps NaN to 0
}

// Eigenvalues mu and orthonormal eigenvectors U (columns) of a symmetric 3x3 B. Plane strain
// (2D runs) keeps B block-diagonal, B_xz = B_yz = 0 exactly: then one Jacobi rotation of the
// xy block is the exact answer, about 10x cheaper than the general solver (the profile's
// largest item), and accurate to the absolute round-off of B. Not sorted.
inline void sym_eig3(const Mat3 &B, Mat3 &U, Vec3 &mu) {
  if (B(2, 0) == 0.0 && B(2, 1) == 0.0) {
    const double a = B(0, 0), b = B(1, 0), c = B(1, 1);
    double cs = 1.0, sn = 0.0, t = 0.0;
    if (b != 0.0) { // the rotation that zeroes b (Golub & Van Loan's symmetric Schur form)
      const double tau = (c - a) / (2.0 * b);
      t = (tau >= 0 ? 1.0 : -1.0) / (std::fabs(tau) + std::sqrt(1.0 + tau * tau));
      cs = 1.0 / std::sqrt(1.0 + t * t);
      sn = t * cs;
    }
    mu = Vec3(a - t * b, c + t * b, B(2, 2));
    U << cs, sn, 0.0, -sn, cs, 0.0, 0.0, 0.0, 1.0;
    return;
  }
  const Eigen::SelfAdjointEigenSolver<Mat3> es(B); // reads the lower triangle
  mu = es.eigenvalues();
  U = es.eigenvectors();
}

inline Hencky hencky(const Mat3 &B) {
  Hencky h;
  Vec3 mu; // Be's eigenvalues are 1 + mu
  sym_eig3(B, h.Us, mu);
  if (!(mu.minCoeff() > -1.0) || !std::isfinite(mu.sum())) return h;
  const Vec3 e(0.5 * std::log1p(mu(0)), 0.5 * std::log1p(mu(1)), 0.5 * std::log1p(mu(2)));
  h.tr = e.sum();
  h.dev = e - Vec3::Constant(h.tr / 3.0);
  h.ok = true;
  return h;
}

// The general (3D) path without an eigensolver (Eigen's 3x3 solver was 21% of a 3D dynamic
// run, perf). Elastic strains are small: Be = I + B = (1 + s)(I + X) with s = tr B/3 and
// X = dev B/(1 + s), and I commutes with X, so
//   ln Be = log1p(s) I + ln(I + X),  ln(I + X) = X - X^2/2 + X^3/3 - ... (Horner),
// with as many terms as |X|_F needs for a tail below 2^-53 |X|_F (4 at |X| = 1e-4, 11 at the
// limit 0.05; beyond it, or if 1 + s <= 0, the caller takes the eigensolver). The same
// strain as Us diag(ln s) Us^T to round-off; dev Ee and tr Ee as tensors.
constexpr double kSeriesMax = 0.05;
// Symmetric 3x3 as (xx, yy, zz, xy, yz, xz), in plain scalars: with Eigen's Mat3 the Horner
// loops below stalled on store forwarding (a scalar store to the diagonal, then a vector
// load), and the products were not inlined (perf).
struct Sym {
  double xx, yy, zz, xy, yz, xz;
};
inline Sym to_sym(const Mat3 &A) { return {A(0, 0), A(1, 1), A(2, 2), A(1, 0), A(2, 1), A(2, 0)}; } // lower triangle
inline Mat3 to_mat(const Sym &a) {
  Mat3 R;
  R << a.xx, a.xy, a.xz, a.xy, a.yy, a.yz, a.xz, a.yz, a.zz;
  return R;
}
// c I + k A B for symmetric A, B that commute (polynomials in one matrix), so A B is symmetric.
inline Sym horner_step(double c, double k, const Sym &A, const Sym &B) {
  return {c + k * (A.xx * B.xx + A.xy * B.xy + A.xz * B.xz), c + k * (A.xy * B.xy + A.yy * B.yy + A.yz * B.yz),
          c + k * (A.xz * B.xz + A.yz * B.yz + A.zz * B.zz), k * (A.xx * B.xy + A.xy * B.yy + A.xz * B.yz),
          k * (A.xy * B.xz + A.yy * B.yz + A.yz * B.zz), k * (A.xx * B.xz + A.xy * B.yz + A.xz * B.zz)};
}
inline double sym_norm2(const Sym &a) { return a.xx * a.xx + a.yy * a.yy + a.zz * a.zz + 2.0 * (a.xy * a.xy + a.yz * a.yz + a.xz * a.xz); }
inline bool hencky_series(const Mat3 &Bm, Mat3 &devE, double &trE) {
  const Sym B = to_sym(Bm);
  const double s = (B.xx + B.yy + B.zz) / 3.0;
  if (!(s > -1.0)) return false;
  const double q = 1.0 / (1.0 + s);
  const Sym X{(B.xx - s) * q, (B.yy - s) * q, (B.zz - s) * q, B.xy * q, B.yz * q, B.xz * q};
  const double r = std::sqrt(sym_norm2(X));
  if (!(r <= kSeriesMax)) return false; // also NaN
  // Tail of the series after N terms: <= r^(N+1)/((N+1)(1 - r)).
  int N = 1;
  for (double t = r; N < 40 && t > 1.1e-16 * (N + 1) * (1.0 - r); t *= r) ++N;
  const double cN = (N % 2 ? 1.0 : -1.0) / N; // c_k = (-1)^(k+1)/k
  Sym P{cN, cN, cN, 0.0, 0.0, 0.0};
  for (int k = N - 1; k >= 1; --k) P = horner_step((k % 2 ? 1.0 : -1.0) / k, 1.0, X, P);
  const Sym l = horner_step(0.0, 1.0, X, P); // ln(I + X)
  const double trX = l.xx + l.yy + l.zz;
  trE = 1.5 * std::log1p(s) + 0.5 * trX;
  const Sym d{0.5 * (l.xx - trX / 3.0), 0.5 * (l.yy - trX / 3.0), 0.5 * (l.zz - trX / 3.0), 0.5 * l.xy, 0.5 * l.yz, 0.5 * l.xz};
  devE = to_mat(d);
  return std::isfinite(trE) && std::isfinite(sym_norm2(d));
}
// exp(Y) - I of a symmetric Y with |Y|_F <= kSeriesMax (Taylor series, Horner; the tail below
// 2^-53 |Y|_F).
inline Mat3 expm1_series(const Mat3 &Ym) {
  const Sym Y = to_sym(Ym);
  const double r = std::sqrt(sym_norm2(Y));
  int N = 1; // tail after N terms <= r^(N+1)/(N+1)! (1 + r): relative r^N/(N+1)! (1 + r)
  for (double t = r / 2.0; N < 30 && t * (1.0 + r) > 1.1e-16; t *= r / (N + 1)) ++N;
  Sym P{1.0, 1.0, 1.0, 0.0, 0.0, 0.0};
  for (int k = N; k >= 2; --k) P = horner_step(1.0, 1.0 / k, Y, P);
  return to_mat(horner_step(0.0, 1.0, Y, P));
}

// U diag(expm1(x)) U^T: exp(X) - I of a symmetric X = U diag(x) U^T, without cancellation.
inline Mat3 expm1_sym(const Mat3 &U, const Vec3 &x) {
  const Vec3 y(std::expm1(x(0)), std::expm1(x(1)), std::expm1(x(2)));
  return U * y.asDiagonal() * U.transpose();
}
// Plane strain (2D runs): L and B have no xz, yz entries and L_zz = 0, so f = I + D is
// block-diagonal with f_zz = 1 and B_tr_zz = B_zz. The same formulas as the general path on
// the xy block, without the 3x3 products' zero terms (about a third of the update's cost).
inline bool plane_strain(const Mat3 &D, const Mat3 &B) {
  return D(0, 2) == 0.0 && D(1, 2) == 0.0 && D(2, 0) == 0.0 && D(2, 1) == 0.0 && D(2, 2) == 0.0 && B(2, 0) == 0.0 && B(2, 1) == 0.0;
}
// f B f^T + D + D^T + D D^T, f = I + D, both plane (xy block and zz only).
inline Mat3 trial_B_plane(const Mat3 &D, const Mat3 &B) {
  const double d00 = D(0, 0), d01 = D(0, 1), d10 = D(1, 0), d11 = D(1, 1);
  const double f00 = 1.0 + d00, f11 = 1.0 + d11;
  const double b00 = B(0, 0), b01 = B(1, 0), b11 = B(1, 1);
  // f B: rows of f times the symmetric block.
  const double a00 = f00 * b00 + d01 * b01, a01 = f00 * b01 + d01 * b11;
  const double a10 = d10 * b00 + f11 * b01, a11 = d10 * b01 + f11 * b11;
  Mat3 R;
  R(0, 0) = (a00 * f00 + a01 * d01) + (2.0 * d00 + (d00 * d00 + d01 * d01));
  R(1, 1) = (a10 * d10 + a11 * f11) + (2.0 * d11 + (d10 * d10 + d11 * d11));
  R(1, 0) = R(0, 1) = (a10 * f00 + a11 * d01) + ((d10 + d01) + (d10 * d00 + d11 * d01));
  R(2, 2) = B(2, 2);
  R(2, 0) = R(0, 2) = R(2, 1) = R(1, 2) = 0.0;
  return R;
}
// U diag(v) U^T for the plane rotation U of sym_eig3 (U = [c s 0; -s c 0; 0 0 1]), which it
// returns for every B with B_xz = B_yz = 0 (so for every plane B_tr).
inline Mat3 rotate_diag_plane(const Mat3 &U, const Vec3 &v) {
  const double c = U(0, 0), s = U(0, 1);
  Mat3 R;
  R(0, 0) = c * c * v(0) + s * s * v(1);
  R(1, 1) = s * s * v(0) + c * c * v(1);
  R(1, 0) = R(0, 1) = c * s * (v(1) - v(0));
  R(2, 2) = v(2);
  R(2, 0) = R(0, 2) = R(2, 1) = R(1, 2) = 0.0;
  return R;
}
} // namespace detail

// Hyperelastic Cauchy stress of an elastic state B = Be - I (no return, no state):
// sigma = R (2G dev Ee + K tr Ee I) R^T / Je, zero if p <= 0 or Be is singular (no tension).
inline Mat3 dynamic_ngf_elastic_stress(const ElasticModuli &el, const Mat3 &B) {
  const detail::Hencky h = detail::hencky(B);
  if (!h.ok || !(-el.K * h.tr > 0)) return Mat3::Zero();
  const Vec3 m = 2.0 * el.G * h.dev + Vec3::Constant(el.K * h.tr);
  return h.Us * (m * std::exp(-h.tr)).asDiagonal() * h.Us.transpose();
}

// One step of the fluidity ODE (seed 004 eq. 6) at frozen p > 0, mu and lap_g:
//   t0 g' = A^2 d^2 lap_g - a g - c g^2,   a = mu_s - mu,   c = b sqrt(rho_s d^2 / p) mu >= 0.
// Its homogeneous fixed points are g = 0 and, for mu > mu_s, g_loc = -a/c
// = sqrt(p/(rho_s d^2)) (mu - mu_s)/(b mu), the local mu(I) law.
//
// Explicit: g1 = max(0, g + dt (A^2 d^2 lap_g - a g - c g^2)/t0)   (seed 004 eq. 24).
//   At fixed mu the per-step amplification about g is 1 - dt (a + 2 c g)/t0: stable for
//   dt < 2 t0/|a + 2 c g|, monotone for dt < t0/|a + 2 c g|. At g_loc, a + 2 c g_loc =
//   mu - mu_s, i.e. dt < 2 t0/(mu - mu_s). (In the kernel mu is not fixed: the coupled
//   limit is stricter, see dynamic_ngf_local_dt_limit.) Past it the step can overshoot to
//   exactly 0, also a fixed point, and a flowing particle locks at g = 0.
// Implicit (and ImplicitCoupled, which at frozen mu is the same step): backward Euler in g
//   with lap_g (and p, mu) explicit:
//   c g1^2 + beta g1 - gamma = 0,  beta = t0/dt + a,  gamma = t0 g/dt + A^2 d^2 lap_g.
//   Larger root (the continuation of the stable branch; the only root >= 0 when gamma > 0),
//   0 if it is negative or complex. Bounded for every dt: as dt -> inf it tends to the
//   local steady solution c g^2 + a g = A^2 d^2 lap_g.
// The reaction coefficients of the fluidity ODE, R(g) = -a g - c g^2 (also used by the
// implicit grid step, DynamicFluidity): a = mu_s - mu, c = b sqrt(rho_s d^2/p) mu, p > 0.
struct FluidityReaction {
  double a, c;
  double rate(double g) const { return -a * g - c * g * g; }
  double slope(double g) const { return -a - 2.0 * c * g; } // dR/dg
};
inline FluidityReaction fluidity_reaction(const GranularParams &gp, double p, double mu) {
  return {gp.mu_s - mu, (mu > 0) ? gp.b * mu * std::sqrt(gp.rho_s * gp.d * gp.d / p) : 0.0};
}

inline double dynamic_fluidity_step(const DynamicNGFParams &P, double g, double p, double mu,
                                    double lap_g, double dt, FluidityStep mode) {
  if (!(dt > 0)) return g;
  if (!(p > 0)) return 0.0; // no contact pressure: no fluidity (never called so by the kernel)
  const GranularParams &gp = P.gp;
  const double src = gp.A * gp.A * gp.d * gp.d * lap_g;
  const FluidityReaction R = fluidity_reaction(gp, p, mu);
  const double a = R.a, c = R.c;
  if (!std::isfinite(c)) return 0.0; // p -> 0: the g^2 sink is unbounded, g -> 0
  const auto explicit_step = [&] {
    const double g1 = g + dt * (src - a * g - c * g * g) / P.t0;
    return g1 > 0 ? g1 : 0.0; // also maps NaN to 0
  };
  if (mode == FluidityStep::Explicit) return explicit_step();
  const double beta = P.t0 / dt + a, gamma = P.t0 * g / dt + src;
  if (c > 0) return detail::larger_root(c, beta, gamma);
  if (beta > 0) {
    const double r = gamma / beta;
    return r > 0 ? r : 0.0;
  }
  // c = 0 needs b = 0 (mu <= 0 gives beta > 0): a pure linear growth past
  // dt = t0/(mu - mu_s) has no bounded backward-Euler answer; fall back to explicit.
  return explicit_step();
}

// Largest stable dt of the kernel's local (per-particle) dynamics about the flowing steady
// state g = g_loc(mu), mu > mu_s, for a fixed driving rate (lap g = 0). Linearising the step
// in (mu, g) -- the return gives mu_{n+1} = (mu_n + G dt gdot/p)/(1 + G dt g_{n+1}/p) --
// with u = dt (mu - mu_s)/t0 (fluidity rate), v = dt G g/p (Maxwell rate) and
// r = mu_s/(mu - mu_s), the Jury conditions reduce to
//   Explicit:        (1 + r) u v + 2u < 4 + 2v
//   Implicit:        (r - 1) u v     < 4 + 2u + 2v   (always met if mu >= 2 mu_s)
//   ImplicitCoupled: no limit (returns infinity).
// Each is a quadratic in dt, solved below. Usually v >> u (G g/p >> (mu - mu_s)/t0), and
// then they are dt < 2 t0/mu and dt < 2 t0/(2 mu_s - mu) up to O(1/v) (about 15 % for the
// Taylor-Couette parameters at 10/s): 5-7x below the fixed-mu limit 2 t0/(mu - mu_s) of
// the g equation alone. Beyond them the
// particle falls into a period-2 oscillation of mu and g (implicit) or locks at g = 0 with an
// elastically growing shear stress (explicit). For mu <= mu_s there is no flowing state: the
// explicit limit is the g equation's 2 t0/(mu_s - mu), which the clamp at 0 makes harmless.
inline double dynamic_ngf_local_dt_limit(const DynamicNGFParams &P, double p, double mu, FluidityStep mode) {
  const double inf = std::numeric_limits<double>::infinity();
  const GranularParams &gp = P.gp;
  const double e = mu - gp.mu_s;
  if (mode == FluidityStep::ImplicitCoupled || !(p > 0)) return inf;
  if (!(e > 0)) return (mode == FluidityStep::Explicit && e < 0) ? 2.0 * P.t0 / -e : inf;
  const double g = std::sqrt(p / (gp.rho_s * gp.d * gp.d)) * e / (gp.b * mu); // g_loc
  const double wg = e / P.t0, wm = P.el.G * g / p;                          // u/dt, v/dt
  double A, B;
  if (mode == FluidityStep::Explicit) {
    A = mu * wg / e * wm; // (1 + r)(u/dt)(v/dt) with (1 + r) e = mu
    B = 2.0 * (wg - wm);
  } else {
    if (mu >= 2.0 * gp.mu_s) return inf;
    A = (2.0 * gp.mu_s - mu) * wg / e * wm; // (r - 1) e = 2 mu_s - mu
    B = -2.0 * (wg + wm);
  }
  return (-B + std::sqrt(B * B + 16.0 * A)) / (2.0 * A); // root of A dt^2 + B dt - 4
}

// Von Neumann limit of the explicit nonlocal (diffusion) term with the (2 dim + 1)-point
// Laplacian on spacing dx: dt < dx^2 t0 / (2 dim A^2 d^2) (seed 004 §4 cites the 1D form).
inline double dynamic_ngf_explicit_dt_limit(const DynamicNGFParams &P, double dx, int dim) {
  const double D = P.gp.A * P.gp.A * P.gp.d * P.gp.d; // diffusivity times t0
  if (!(D > 0)) return std::numeric_limits<double>::infinity();
  return dx * dx * P.t0 / (2.0 * dim * D);
}

// The state whose elastic stress is the Cauchy stress sigma0 (e.g. the initial isotropic
// compression of a scene): Fe = exp(Ee) symmetric (R = I, Fp = I), Be = exp(2 Ee), connected with
// p_prev = p0, mu_prev = tau0/p0 and fluidity g0. Volumetric part: sigma = M/Je with
// Je = exp(theta), so K theta exp(-theta) = -p0 (Newton; monotone from theta = -p0/K since
// the left side is increasing and concave for theta < 1); deviator dev Ee = Je dev sigma/(2G).
// A stress-free sigma0 (p0 <= 0) gives the default, disconnected state.
inline DynamicNGFState dynamic_ngf_state_from_stress(const DynamicNGFParams &P, const Mat3 &sigma0,
                                                     double g0 = 0) {
  DynamicNGFState s;
  const double p0 = pressure(sigma0), K = P.el.K;
  if (!(p0 > 0)) return s;
  double th = -p0 / K;
  for (int it = 0; it < 50; ++it) {
    const double f = K * th * std::exp(-th) + p0, df = K * std::exp(-th) * (1.0 - th);
    const double step = f / df;
    th -= step;
    if (!(std::fabs(step) > 1e-16 * std::fabs(th))) break;
  }
  const double J = std::exp(th);
  const Mat3 Ee = (J / (2.0 * P.el.G)) * deviator(0.5 * (sigma0 + sigma0.transpose())) +
                  (th / 3.0) * Mat3::Identity();
  const Eigen::SelfAdjointEigenSolver<Mat3> es(Ee);
  s.B = detail::expm1_sym(es.eigenvectors(), 2.0 * es.eigenvalues());
  s.g = g0;
  s.p_prev = p0;
  s.mu_prev = tau_of(sigma0) / p0;
  return s;
}

// One constitutive step (see the header comment). lap_g: Laplacian of the fluidity on the
// grid at this particle (from g of connected particles at the start of the step); rho: the
// particle's current density (stress-free below gp.rho_c).
inline DynamicNGFResult dynamic_ngf_update(const DynamicNGFParams &P, DynamicNGFState &st, const Mat3 &L,
                                           double dt, double lap_g, double rho,
                                           FluidityStep mode = FluidityStep::Explicit) {
  const Mat3 I = Mat3::Identity();
  // f = I + D; f Be f^T - I = f B f^T + D + D^T + D D^T, D = dt L (or exp(dt L) - I).
  const Mat3 D = (P.f_update == KinematicUpdate::Exponential) ? Mat3(expm3(dt * L) - I) : Mat3(dt * L);
  const bool plane = detail::plane_strain(D, st.B);
  Mat3 B_tr;
  double det_f;
  if (plane) {
    B_tr = detail::trial_B_plane(D, st.B);
    det_f = (1.0 + D(0, 0)) * (1.0 + D(1, 1)) - D(0, 1) * D(1, 0);
  } else {
    const Mat3 f = I + D;
    B_tr = f * st.B * f.transpose() + (D + D.transpose() + D * D.transpose());
    det_f = f.determinant();
  }
  // det Fe_n > 0 for every stored state, so Fe_tr = f Fe_n is inverted iff det f <= 0.
  // 3D: dev Ee and tr Ee by series (hencky_series) while the deviatoric strain is small.
  Mat3 devE;
  double trE = 0;
  const bool series = !plane && det_f > 0 && detail::hencky_series(B_tr, devE, trE);
  const detail::Hencky h = (det_f > 0 && !series) ? detail::hencky(B_tr) : detail::Hencky();
  const double tr = series ? trE : h.tr;
  const double G = P.el.G;
  const double pM = -P.el.K * tr; // Mandel (Kirchhoff) pressure

  DynamicNGFResult out;
  if (!(series || h.ok) || !(pM > 0) || rho < P.gp.rho_c) {
    // States 2/3: stress-free, elastic strain reset. g is frozen (see the header comment).
    out.state = st.connected() ? NGFParticleState::Separating : NGFParticleState::Free;
    st.B.setZero();
    st.p_prev = 0;
    st.mu_prev = 0;
    out.g = st.g;
    return out;
  }

  // Principal deviatoric Mandel stress is 2G dev; tau_tr = sqrt(sum (2G dev_i)^2 / 2).
  const double tau_tr = G * std::sqrt(2.0 * (series ? devE.squaredNorm() : h.dev.squaredNorm()));
  const double Je = std::exp(tr);
  if (!st.connected()) {
    // State 4: kinematic fluidity from the stretching, seed 004 eq. 23.
    const Mat3 D = 0.5 * (L + L.transpose());
    st.g = std::sqrt(2.0) * D.norm() / P.gp.mu_2;
    out.state = NGFParticleState::Reconnecting;
  } else if (mode == FluidityStep::ImplicitCoupled && dt > 0) {
    // Backward Euler in g with mu = x_tr/(1 + m g) from this step's return (x_tr = tau_tr/p_M,
    // m = G dt/p_M) and the current pressure p = p_M/Je; times (1 + m g) > 0 it is
    //   [m (t0/dt + mu_s) + c x_tr] g^2 + [t0/dt (1 - m g_n) - m S + mu_s - x_tr] g
    //     - (t0 g_n/dt + S) = 0,   S = A^2 d^2 lap_g,  c = b sqrt(rho_s d^2/p).
    const GranularParams &gp = P.gp;
    const double S = gp.A * gp.A * gp.d * gp.d * lap_g, k = P.t0 / dt;
    const double x_tr = tau_tr / pM, m = G * dt / pM;
    const double c = gp.b * std::sqrt(gp.rho_s * gp.d * gp.d * Je / pM);
    st.g = std::isfinite(c) ? detail::larger_root(m * (k + gp.mu_s) + c * x_tr,
                                                  k * (1.0 - m * st.g) - m * S + gp.mu_s - x_tr,
                                                  k * st.g + S)
                            : 0.0;
    out.state = NGFParticleState::Compressed;
  } else {
    st.g = dynamic_fluidity_step(P, st.g, st.p_prev, st.mu_prev, lap_g, dt, mode);
    out.state = NGFParticleState::Compressed;
  }
  if (!std::isfinite(st.g)) st.g = 0; // e.g. a non-finite lap_g from an empty stencil
  if (st.g < P.g_min) st.g = P.g_min;

  // Return at fixed pressure, radial in the deviatoric plane.
  const double tau = (tau_tr > 0) ? tau_tr * pM / (pM + G * dt * st.g) : 0.0;
  const double scale = (tau_tr > 0) ? tau / tau_tr : 1.0;
  if (series) {
    out.sigma = ((2.0 * G * scale) * devE - Mat3::Identity() * pM) / Je; // R M R^T / Je
  } else {
    const Vec3 m = (2.0 * G * scale) * h.dev - Vec3::Constant(pM);
    out.sigma = plane ? detail::rotate_diag_plane(h.Us, m / Je) : Mat3(h.Us * (m / Je).asDiagonal() * h.Us.transpose()); // R M R^T / Je
  }
  out.p = pM / Je;
  out.tau = tau / Je;
  out.mu = tau / pM;
  out.gdot_p = st.g * out.mu;
  out.g = st.g;

  // Fp_{n+1} = exp(dt Lp) Fp_n, Lp = gdot N/sqrt 2 (N diagonal in the principal basis). With
  // gdot = (tau_tr - tau)/(G dt) and n_i = sqrt 2 G dev_i/tau_tr the exponent is
  // dt gdot n_i/sqrt 2 = (1 - scale) dev_i, so Ee_{n+1} = scale * dev + tr/3 exactly (same
  // basis, the volume kept) and the stored B encodes exactly the stress just returned.
  if (scale < 1.0 && series) {
    // exp(2 scale dev Ee + a I) - I = e^a expm1(2 scale dev Ee) + expm1(a) I, a = 2 tr/3.
    const double ea = std::expm1(2.0 * tr / 3.0);
    st.B = (1.0 + ea) * detail::expm1_series((2.0 * scale) * devE) + Mat3::Identity() * ea;
  } else if (scale < 1.0) {
    const Vec3 x = 2.0 * (scale * h.dev + Vec3::Constant(h.tr / 3.0));
    if (plane) st.B = detail::rotate_diag_plane(h.Us, Vec3(std::expm1(x(0)), std::expm1(x(1)), std::expm1(x(2))));
    else st.B = detail::expm1_sym(h.Us, x);
  } else {
    st.B = B_tr;
  }
  st.p_prev = out.p;
  st.mu_prev = out.mu;
  return out;
}

// The dynamical model as a material (model.hpp): its parameters t0 and g0, its particle
// state (fluidity, gdot, Be - I, p_prev, mu_prev) and how its fluidity is stepped.
struct DynamicNGF {
  DynamicNGFParams P;
  FluidityStep mode;

  static constexpr bool kVolumeFromF = true; // volume consistent with F: det(I + dt L)
  static ModelInfo info() {
    ModelInfo m{"dynamic", "hyperelastic dynamical nonlocal fluidity (seed 004)", {}, {{"fluidity", 1}, {"gdot", 1}, {"Be_minus_I", 6}, {"p_prev", 1}, {"mu_prev", 1}}, true, false};
    m.params.push_back({"-t0", "Dynamical fluidity: material time scale t0 [s]", 1e-4, 0, std::numeric_limits<double>::infinity(), true});
    m.params.push_back({"-g0", "Dynamical fluidity: initial and smallest g of connected particles [1/s]; g = 0 is a fixed point, so a jammed start needs g0 > 0 to flow", 1e-8, 0});
    return m;
  }
  static DynamicNGF make(const MaterialInputs &in) {
    return {DynamicNGFParams{in.el, *in.gran, in.param("-t0"), in.param("-g0"), KinematicUpdate::ForwardEuler},
            in.fluidity_step == 0 ? FluidityStep::Explicit : FluidityStep::ImplicitCoupled};
  }
  // The state in the declared fields (Be - I as xx yy zz xy yz xz, the stress's order).
  static DynamicNGFState load(const PointState &s) {
    DynamicNGFState st;
    st.B = sym6_to_mat(s.f[2]);
    st.g = *s.f[0];
    st.p_prev = *s.f[3];
    st.mu_prev = *s.f[4];
    return st;
  }
  static void store(const PointState &s, const DynamicNGFState &st) {
    mat_to_sym6(st.B, s.f[2]);
    *s.f[0] = st.g;
    *s.f[3] = st.p_prev;
    *s.f[4] = st.mu_prev;
  }
  double step(Mat3 &sigma, const Mat3 &L, const PointIn &in, const PointState &s) const {
    DynamicNGFState st = load(s);
    const DynamicNGFResult r = dynamic_ngf_update(P, st, L, in.dt, in.lap_g, in.rho, mode);
    store(s, st);
    sigma = r.sigma;
    return r.gdot_p;
  }
  // The deformation state whose elastic stress is the initial stress.
  void init(const Mat3 &sigma0, const PointState &s) const { store(s, dynamic_ngf_state_from_stress(P, sigma0, P.g_min)); }
  // Explicit fluidity steps: the local relaxation limit (per particle) and the diffusion
  // limit dx^2 t0 / (2 dim A^2 d^2).
  bool limits_dt() const { return mode == FluidityStep::Explicit; }
  double local_dt_limit(const PointState &s) const {
    const double p_prev = *s.f[3];
    return p_prev > 0 ? dynamic_ngf_local_dt_limit(P, p_prev, *s.f[4], mode) : 1e300;
  }
  double dt_limit(double, double local_min, double h, int dim) const { return std::min(local_min, dynamic_ngf_explicit_dt_limit(P, h, dim)); }
};

} // namespace granmpm
