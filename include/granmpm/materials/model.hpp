// The material interface: what a constitutive model declares about itself, and the one
// per-particle call every model answers. Pure (standard library and Eigen only), like the
// models. A model M is a struct in materials/<name>.hpp with
//
//   static ModelInfo info();                      // name, -help line, parameters, state fields
//   static M make(const MaterialInputs &in);      // from the options, derived constants once
//   double step(Mat3 &sigma, const Mat3 &L, const PointIn &in, const PointState &st) const;
//                                                 // one stress update; returns gdot (output)
// and optionally
//   static constexpr bool kVolumeFromF = true;    // volume *= det(I + dt L) (F tracked), else exp(dt tr L)
//   void init(const Mat3 &sigma0, const PointState &st) const;  // state from the initial stress
//   bool limits_dt() const; double stable_rate(const Mat3 &sigma_n, const PointIn &in) const;
//   double local_dt_limit(const PointState &st) const; double dt_limit(double rate_max,
//       double local_min, double h, int dim) const;            // explicit step limits
// It is registered with one line (register_material<M>(), material.hpp; the built-in ones
// in src/materials.cpp), which gives it its -material name, its options (-help, parsing,
// validation, the restart signature), its particle fields (swarm, checkpoint, output) and
// the particle loops (explicit update and the implicit trial stress), instantiated for M:
// the model is chosen once per run and its step() is inlined in the loop.
#pragma once

#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "granmpm/materials/moduli.hpp"

namespace granmpm {

struct GranularParams;    // materials/local_mu_i.hpp
enum class StressUpdate;  // materials/local_mu_i.hpp

// A real parameter the model owns: "-option", its -help text, its default and the range it
// must lie in (lo_open: lo itself excluded; the same for hi). choices: "a|b|c" for an
// option given by name (the value is then the index of the name).
struct ParamDecl {
  const char *option;
  const char *help;
  double def;
  double lo = -std::numeric_limits<double>::infinity();
  double hi = std::numeric_limits<double>::infinity();
  bool lo_open = false, hi_open = false;
  const char *unit = "";    // appended to the range in messages ("degrees")
  std::string choices = ""; // non-empty: a named option
  bool valid(double v) const {
    if (!std::isfinite(v) && choices.empty()) return false;
    return (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
  }
};

// A per-particle field the model keeps (double values, bs per particle). "fluidity",
// "gdot", "F", "Fp", "p_prev", "mu_prev" are known by name to the fluidity solvers and
// the output; any other name is written to checkpoints and output as it is.
struct FieldDecl {
  const char *name;
  int bs;
};

struct ModelInfo {
  const char *name; // the -material value
  const char *help; // one line for -help
  std::vector<ParamDecl> params;
  std::vector<FieldDecl> fields;
  bool granular = false; // reads the granular parameters (-mu_s, -b, -d, -rho_s, -A, -rho_c)
  bool implicit = true;  // supported by -time_integrator implicit (its step has no state)
};

// What make() reads: the elastic moduli, the granular family's parameters, the options that
// select a scheme, and the model's own parameters by option name (param("-t0")).
struct MaterialInputs {
  ElasticModuli el;
  double rho = 0;
  const GranularParams *gran = nullptr;
  StressUpdate stress_update{};
  int fluidity_step = 1; // -fluidity_step: 0 explicit, 1 implicit
  std::function<double(const std::string &)> param;
};

// The per-particle inputs of one step besides sigma and L.
struct PointIn {
  double dt = 0;
  double rho = 0;   // current density (volume already updated)
  double g = 0;     // the fluidity field at the particle (0 if the model has none)
  double lap_g = 0; // the grid Laplacian of g at the particle (dynamical fluidity)
};

// The model's declared fields at one particle: f[i] points at its bs_i values of field i.
struct PointState {
  static constexpr int kMax = 8;
  double *f[kMax] = {};
};

} // namespace granmpm
