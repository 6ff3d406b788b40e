// DEM contact laws as pure kernels (seed 002, chapter 2; docs/dem.md). Everything is written
// with 3-vectors: 2D disks live in the z = 0 plane and spin about z only.
//
// Sign conventions: the kernel computes the force on grain i from partner j. n points from
// i to j; delta = r_i + r_j - |x_j - x_i| is the overlap; u is the velocity of i's surface
// relative to j's at the contact point. A wall is a partner with r_j = 0, v_j = omega_j = 0.
// Written so that swapping i and j negates every result exactly (IEEE negation is exact),
// so Newton's third law holds bit for bit and each grain can compute its own forces.
#pragma once

#include <algorithm>
#include <cmath>

namespace granmpm::dem {

struct V3 {
  double x = 0, y = 0, z = 0;
};
inline V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline V3 operator-(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline V3 operator-(V3 a) { return {-a.x, -a.y, -a.z}; }
inline V3 operator*(double s, V3 a) { return {s * a.x, s * a.y, s * a.z}; }
inline double dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline V3 cross(V3 a, V3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
inline double norm(V3 a) { return std::sqrt(dot(a, a)); }

enum class Law { Linear = 0, Hertz = 1 };

// Normal damping of the linear spring-dashpot for restitution e (0 < e <= 1) and effective
// mass m_eff: the seed's gamma_n = sqrt(m k_n) (-2 ln e) / sqrt(2 (pi^2 + ln^2 e)) with its
// mean grain mass m replaced by 2 m_eff (equal for two equal grains); exact e for any pair.
inline double gamma_from_e(double e, double kn, double meff) {
  const double le = std::log(e);
  return -2.0 * le * std::sqrt(meff * kn / (M_PI * M_PI + le * le));
}

// Duration of a linear contact: t_c = pi / sqrt(k_n/m_eff - (gamma_n / (2 m_eff))^2); for
// an overdamped contact, pi sqrt(m_eff / k_n) (the undamped value, which sets the step).
inline double contact_time(double kn, double gamma, double meff) {
  const double w2 = kn / meff - 0.25 * gamma * gamma / (meff * meff);
  return w2 > 0 ? M_PI / std::sqrt(w2) : M_PI * std::sqrt(meff / kn);
}

// Duration of an elastic Hertz contact F = k_n sqrt(R_eff) delta^(3/2) at impact speed v:
// delta_max = (5 m v^2 / (4 k_n sqrt(R)))^(2/5), t_c = 2 delta_max / v * (2/5) B(2/5, 1/2).
inline double hertz_contact_time(double kn, double reff, double meff, double v) {
  const double dmax = std::pow(1.25 * meff * v * v / (kn * std::sqrt(reff)), 0.4);
  const double I = 0.4 * std::tgamma(0.4) * std::tgamma(0.5) / std::tgamma(0.9);
  return 2.0 * dmax / v * I;
}

// Restitution of the linear spring-dashpot WITHOUT attraction at damping ratio zeta
// (gamma = 2 zeta sqrt(k m)): the contact ends when k delta + gamma u_n reaches 0, before the
// overlap does, so e_c(zeta) > exp(-pi zeta / sqrt(1 - zeta^2)) (Schwager & Poeschel 2007).
// Dimensionless RK4 of x'' = -x - 2 zeta x' from x = 0, x' = 1; tstar (optional): the
// contact duration in units of sqrt(m/k).
inline double clamped_restitution(double zeta, double *tstar) {
  double h = 1e-3, x = 0, v = 1, t = 0;
  int refine = 0;
  auto acc = [&](double xx, double vv) { return -xx - 2 * zeta * vv; };
  for (int it = 0; it < 1000000; ++it) {
    const double k1x = v, k1v = acc(x, v);
    const double k2x = v + 0.5 * h * k1v, k2v = acc(x + 0.5 * h * k1x, v + 0.5 * h * k1v);
    const double k3x = v + 0.5 * h * k2v, k3v = acc(x + 0.5 * h * k2x, v + 0.5 * h * k2v);
    const double k4x = v + h * k3v, k4v = acc(x + h * k3x, v + h * k3v);
    const double xn = x + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x), vn = v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
    const double f0 = x + 2 * zeta * v, f1 = xn + 2 * zeta * vn; // -(force)
    if (t > 0 && f1 <= 0) {
      if (refine < 3) { // the end of contact lies in this step: redo it with finer steps
        h /= 50;
        ++refine;
        continue;
      }
      const double s = f0 / (f0 - f1);
      if (tstar) *tstar = t + s * h;
      return -(v + s * (vn - v));
    }
    x = xn;
    v = vn;
    t += h;
  }
  if (tstar) *tstar = t;
  return 0;
}

// Duration of the no-attraction linear contact with gamma_n = damp sqrt(k_n m_eff): the
// time until the force (not the overlap) returns to zero; sets the automatic time step.
inline double contact_duration(double kn, double damp, double meff) {
  double ts = M_PI;
  clamped_restitution(0.5 * damp, &ts);
  return ts * std::sqrt(meff / kn);
}

// How gamma_n follows from e: the seed's formula (exact only if the force may pull at the
// end of the contact), or calibrated so that the no-attraction contact restitutes exactly e.
enum class Damping { Seed = 0, Exact = 1 };

struct ContactParams {
  Law law = Law::Linear;
  double kn = 1e5;       // normal stiffness [N/m] (Hertz: N/m^1.5 per sqrt(m), as LAMMPS)
  double kt_ratio = 2.0 / 7.0; // k_t / k_n
  double e = 0.5;        // restitution
  Damping damping = Damping::Exact;
  double gt_ratio = 0.5; // gamma_t / gamma_n
  double mu = 0.5;       // Coulomb friction
  double mu_roll = 0.0;  // rolling resistance coefficient (constant torque mu_r R_eff f_n)
  bool mean_mass = false; // the seed's damping from the mean grain mass instead of m_eff
  double mean_mass_value = 0; // mean grain mass (for mean_mass)
  // gamma_n = damp * sqrt(k_n m_eff), set by finalize(): seed: damp = -2 ln e / sqrt(pi^2 +
  // ln^2 e) (= 2 zeta); exact: 2 zeta with clamped_restitution(zeta) = e (bisection).
  double damp = 0;
  void finalize() {
    const double le = std::log(e);
    damp = -2.0 * le / std::sqrt(M_PI * M_PI + le * le);
    if (damping == Damping::Exact && e < 1) {
      double a = 0, b = 50; // e_c falls monotonically from 1 (zeta = 0) towards 0
      for (int it = 0; it < 60; ++it) {
        const double m = 0.5 * (a + b);
        (clamped_restitution(m, nullptr) > e ? a : b) = m;
      }
      damp = a + b; // 2 zeta
    }
  }
};

struct ContactResult {
  V3 force;    // on grain i
  V3 torque;   // on grain i (about its centre); the torque on j is (r_j / r_i) * torque - rolling
  V3 troll;    // rolling-resistance torque on i (on j: -troll)
  V3 arm;      // n x F_t: torque = r_i arm on i, r_j arm on j (the same bits from either side)
  double fn = 0; // normal force magnitude (>= 0)
  double elastic = 0; // stored spring energy (normal + tangential) of this contact
  double overlap = 0; // delta
};

// Force of partner j on grain i. d = x_j - x_i, ri/rj radii (rj = 0: wall), u0 = v_i - v_j,
// wi/wj angular velocities, meff effective mass, Ieff = 1/(1/I_i + 1/I_j) (rolling), hist
// the tangential spring (updated in place, kept in the tangent plane), dt the step.
[[gnu::always_inline]] inline ContactResult contact(const ContactParams &p, V3 d, double ri, double rj, V3 u0, V3 wi, V3 wj, double meff, double Ieff, V3 &hist, double dt) {
  ContactResult res;
  const double dist = norm(d);
  const double delta = ri + rj - dist;
  if (delta <= 0 || dist == 0) {
    hist = V3{};
    return res;
  }
  res.overlap = delta;
  const V3 n = (1.0 / dist) * d;
  const V3 u = u0 + cross(ri * wi + rj * wj, n);
  const double un = dot(u, n);
  const V3 ut = u - un * n;
  const double reff = rj > 0 ? ri * rj / (ri + rj) : ri;
  double kn = p.kn;
  double scale = 1.0;
  if (p.law == Law::Hertz) {
    scale = std::sqrt(delta * reff);
    kn *= scale;
  }
  const double kt = p.kt_ratio * kn;
  const double gn = p.damp * std::sqrt(kn * (p.mean_mass ? 0.5 * p.mean_mass_value : meff));
  const double gt = p.gt_ratio * gn;
  double fn = kn * delta + gn * un;
  if (fn < 0) fn = 0; // no attraction
  // Tangential spring: rotate into the current tangent plane keeping its length, then
  // add this step's slip. (One square root: the length ratio as sqrt(|h_old|^2/|h|^2).)
  V3 h = hist;
  const double hmag2 = dot(hist, hist);
  if (hmag2 > 0) {
    h = hist - dot(hist, n) * n;
    const double hm2 = dot(h, h);
    if (hm2 > 0) h = std::sqrt(hmag2 / hm2) * h;
  }
  h = h + dt * ut;
  V3 ft = -kt * h - gt * ut;
  const double ft2 = dot(ft, ft), cap = p.mu * fn;
  if (ft2 > cap * cap) {
    // Coulomb: rescale the force to mu f_n and the spring to match (as the seed says).
    ft = (cap / std::sqrt(ft2)) * ft;
    h = kt > 0 ? (-1.0 / kt) * (ft + gt * ut) : V3{};
  }
  hist = h;
  res.fn = fn;
  res.force = ft - fn * n;
  res.arm = cross(n, ft);
  res.torque = ri * res.arm;
  if (p.mu_roll > 0) {
    const V3 wrel = wi - wj;
    const double wm = norm(wrel);
    // Constant torque mu_r R_eff f_n against the relative rolling, but never more than
    // stops it within the step (no chatter about omega = 0).
    if (wm > 0) res.troll = (-std::min(p.mu_roll * reff * fn, Ieff * wm / dt) / wm) * wrel;
  }
  res.elastic = 0.5 * kn * delta * delta * (p.law == Law::Hertz ? 0.8 : 1.0) + 0.5 * kt * dot(h, h);
  return res;
}

} // namespace granmpm::dem
