// The material of a run: one registered model (materials/model.hpp), chosen once at set-up.
// MaterialModel<dim> is what the step sees: one virtual call per step (the explicit update
// of every particle, the implicit step's trial stresses), each a particle loop instantiated
// for the model M with M::step inlined, so no call per particle is virtual.
//
// Registration: register_material<M>() (one line) adds M to the registry; the built-in
// models are registered in src/materials.cpp, in the order of MaterialKind. The registry
// gives -material its names, the options their declarations (Config::from_options), the
// particles their fields (Simulation::setup) and set-up the factory.
#pragma once

#include <algorithm>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "granmpm/config.hpp"
#include "granmpm/materials/model.hpp"
#include "granmpm/particles.hpp"

namespace granmpm {

// What one explicit constitutive update needs besides the particles.
struct UpdateInputs {
  const double *L = nullptr;     // dim x dim per particle of [begin, end) (from G2P), L[0] is particle begin's
  const double *lap_g = nullptr; // per particle (dynamical fluidity, indexed from 0), or null
  double dt = 0;
  PetscInt begin = 0, end = -1;  // the particles to update; end < 0: to the last
};
// What it reports: the stability rates of explicit schemes and the first non-finite particle.
struct UpdateStats {
  double rate_max = 0;        // largest G d(gdot)/d(tau) (explicit granular updates)
  double local_dt_min = 1e300; // smallest per-particle limit (explicit dynamical fluidity)
  PetscInt bad = -1;           // first particle with a non-finite stress or volume
};

template <int dim>
class MaterialModel {
public:
  virtual ~MaterialModel() = default;
  virtual const ModelInfo &info() const = 0;
  // Volume, stress, state and gdot of every local particle from its velocity gradient.
  virtual void update(ParticleView<dim> &P, const Particles<dim> &parts, const UpdateInputs &in, UpdateStats &st) const = 0;
  // The stress after dt from s0 (6 per point) with gradients L at n points, without state
  // (the implicit step's trial state; m, vol: the particles' mass and volume, g: fluidity).
  virtual void trial(PetscInt n, const double *s0, const Mat3 *L, const double *m, const double *vol, const double *g, double dt, Mat3 *out) const = 0;
  // The model's state from each particle's initial stress (models with init()).
  virtual void init_state(ParticleView<dim> &P, const Particles<dim> &parts) const = 0;
  // Explicit schemes: whether the step is limited, and the limit from the reduced stats.
  virtual bool limits_dt() const = 0;
  virtual double dt_limit(double rate_max, double local_dt_min, double h) const = 0;
};

namespace detail {
template <class M, class = void>
struct has_init : std::false_type {};
template <class M>
struct has_init<M, std::void_t<decltype(std::declval<const M &>().init(Mat3(), PointState()))>> : std::true_type {};
template <class M, class = void>
struct has_limits : std::false_type {};
template <class M>
struct has_limits<M, std::void_t<decltype(std::declval<const M &>().limits_dt())>> : std::true_type {};
template <class M, class = void>
struct has_rate : std::false_type {};
template <class M>
struct has_rate<M, std::void_t<decltype(std::declval<const M &>().stable_rate(Mat3(), PointIn()))>> : std::true_type {};
template <class M, class = void>
struct has_local_limit : std::false_type {};
template <class M>
struct has_local_limit<M, std::void_t<decltype(std::declval<const M &>().local_dt_limit(PointState()))>> : std::true_type {};
template <class M, class = void>
struct volume_from_F : std::false_type {};
template <class M>
struct volume_from_F<M, std::void_t<decltype(M::kVolumeFromF)>> : std::integral_constant<bool, M::kVolumeFromF> {};
} // namespace detail

template <int dim, class M>
class Model final : public MaterialModel<dim> {
public:
  Model(const M &m, const ModelInfo &info) : m_(m), info_(info) {}
  const ModelInfo &info() const override { return info_; }

  void update(ParticleView<dim> &P, const Particles<dim> &parts, const UpdateInputs &in, UpdateStats &st) const override {
    double *base[PointState::kMax] = {};
    const int nf = fields(P, parts, base);
    const bool rates = limits_dt();
    const PetscInt end = in.end < 0 ? P.n : in.end;
    for (PetscInt p = in.begin; p < end; ++p) {
      PointState ps;
      for (int i = 0; i < nf; ++i) ps.f[i] = base[i] + (size_t)p * info_.fields[i].bs;
      PointIn pi;
      pi.dt = in.dt;
      pi.g = P.g ? P.g[p] : 0.0;
      Mat3 s = sym6_to_mat(P.s + 6 * p);
      if constexpr (detail::has_rate<M>::value)
        if (rates) st.rate_max = std::max(st.rate_max, m_.stable_rate(s, pi));
      if constexpr (detail::has_local_limit<M>::value)
        if (rates) st.local_dt_min = std::min(st.local_dt_min, m_.local_dt_limit(ps));
      Mat3 L = Mat3::Zero();
      const double *l = in.L + (size_t)(p - in.begin) * dim * dim;
      for (int d = 0; d < dim; ++d)
        for (int e = 0; e < dim; ++e) L(d, e) = l[d * dim + e];
      // Volume: consistent with F where F is tracked (det(I + dt L)), else exp(dt tr L).
      if constexpr (detail::volume_from_F<M>::value) P.vol[p] *= (Mat3::Identity() + in.dt * L).determinant();
      else P.vol[p] *= std::exp(in.dt * L.trace());
      pi.rho = P.m[p] / P.vol[p];
      pi.lap_g = in.lap_g ? in.lap_g[p] : 0.0;
      const double gd = m_.step(s, L, pi, ps);
      double *s6 = P.s + 6 * p;
      mat_to_sym6(s, s6);
      if (P.gdot) P.gdot[p] = gd;
      if (!std::isfinite(s6[0] + s6[1] + s6[2] + s6[3] + s6[4] + s6[5] + P.vol[p]) && st.bad < 0) st.bad = p;
    }
  }

  void trial(PetscInt n, const double *s0, const Mat3 *L, const double *m, const double *vol, const double *g, double dt, Mat3 *out) const override {
    double scratch[32] = {}; // a stateless model's step touches no state
    PointState ps;
    for (int i = 0; i < (int)info_.fields.size() && i < PointState::kMax; ++i) ps.f[i] = scratch;
    for (PetscInt p = 0; p < n; ++p) {
      PointIn pi;
      pi.dt = dt;
      pi.rho = m[p] / (vol[p] * std::exp(dt * L[p].trace()));
      pi.g = g ? g[p] : 0.0;
      Mat3 s = sym6_to_mat(s0 + 6 * p);
      m_.step(s, L[p], pi, ps);
      out[p] = s;
    }
  }

  void init_state(ParticleView<dim> &P, const Particles<dim> &parts) const override {
    if constexpr (detail::has_init<M>::value) {
      double *base[PointState::kMax] = {};
      const int nf = fields(P, parts, base);
      for (PetscInt p = 0; p < P.n; ++p) {
        PointState ps;
        for (int i = 0; i < nf; ++i) ps.f[i] = base[i] + (size_t)p * info_.fields[i].bs;
        m_.init(sym6_to_mat(P.s + 6 * p), ps);
      }
    } else {
      (void)P;
      (void)parts;
    }
  }

  bool limits_dt() const override {
    if constexpr (detail::has_limits<M>::value) return m_.limits_dt();
    else return false;
  }
  double dt_limit(double rate_max, double local_min, double h) const override {
    if constexpr (detail::has_limits<M>::value) return m_.dt_limit(rate_max, local_min, h, dim);
    else return 1e300;
  }
  const M &model() const { return m_; }

private:
  // The particles' arrays of the model's declared fields, in its order.
  int fields(const ParticleView<dim> &P, const Particles<dim> &parts, double **base) const {
    const int nf = (int)info_.fields.size();
    for (int i = 0; i < nf; ++i) base[i] = P.field(parts.field_index(info_.fields[i].name));
    return nf;
  }
  M m_;
  ModelInfo info_;
};

// A registered model: its declaration and its factories.
struct MaterialEntry {
  ModelInfo info;
  std::unique_ptr<MaterialModel<2>> (*make2)(const Config &) = nullptr;
  std::unique_ptr<MaterialModel<3>> (*make3)(const Config &) = nullptr;
};

// The inputs of M::make from the options.
MaterialInputs material_inputs(const Config &c);

// All registered models; the index is the MaterialKind value.
const std::vector<MaterialEntry> &material_registry();
MaterialKind add_material(MaterialEntry e);
const MaterialEntry &material_entry(MaterialKind k);

template <class M>
MaterialEntry material_entry_of() {
  MaterialEntry e;
  e.info = M::info();
  e.make2 = [](const Config &c) -> std::unique_ptr<MaterialModel<2>> { return std::make_unique<Model<2, M>>(M::make(material_inputs(c)), M::info()); };
  e.make3 = [](const Config &c) -> std::unique_ptr<MaterialModel<3>> { return std::make_unique<Model<3, M>>(M::make(material_inputs(c)), M::info()); };
  return e;
}

// One registration line for a new model: `const MaterialKind kMine = register_material<Mine>();`
template <class M>
MaterialKind register_material() {
  return add_material(material_entry_of<M>());
}

template <int dim>
std::unique_ptr<MaterialModel<dim>> make_material(const Config &c) {
  const MaterialEntry &e = material_entry(c.material);
  if constexpr (dim == 2) return e.make2(c);
  else return e.make3(c);
}

} // namespace granmpm
