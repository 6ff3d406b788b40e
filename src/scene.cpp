// The scene registry and the parts every scene shares (the initial lattice, -geostatic,
// the rigid bodies of the -body<k>_ options). Each scene is in src/scenes/<name>.cpp.
#include "granmpm/scene.hpp"

#include <algorithm>
#include <cmath>

#include "granmpm/option_names.hpp"
#include "options_util.hpp"

namespace granmpm {

// The built-in scenes, one line each, in the order of SceneKind (config.hpp). A new scene:
// its file src/scenes/<name>.cpp (ending with GM_SCENE) and one line X(<name>) here.
#define GM_SCENES(X)                                                                                                                                 \
  X(block)                                                                                                                                           \
  X(bar)                                                                                                                                             \
  X(column)                                                                                                                                          \
  X(chute)                                                                                                                                           \
  X(collapse)                                                                                                                                        \
  X(silo)                                                                                                                                            \
  X(annulus)

#define GM_SCENE_DECLARE(name) SceneEntry scene_entry_##name();
#define GM_SCENE_ENTRY(name) scene_entry_##name(),
GM_SCENES(GM_SCENE_DECLARE)

namespace {
std::vector<SceneEntry> &registry() {
  static std::vector<SceneEntry> v = {GM_SCENES(GM_SCENE_ENTRY)};
  return v;
}
} // namespace

const std::vector<SceneEntry> &scene_registry() { return registry(); }

SceneKind add_scene(SceneEntry e) {
  for (const SceneEntry &s : registry())
    if (std::string(s.name) == e.name) throw UserError(std::string("internal: scene '") + e.name + "' registered twice");
  registry().push_back(std::move(e));
  return (SceneKind)(registry().size() - 1);
}

const SceneEntry &scene_entry(SceneKind k) {
  const int i = (int)k;
  if (i < 0 || i >= (int)scene_registry().size()) throw UserError("internal: scene " + std::to_string(i) + " is not registered");
  return scene_registry()[i];
}

const char *to_string(SceneKind k) { return scene_entry(k).name; }

SceneKind parse_scene(const std::string &opt, const std::string &val) {
  for (size_t i = 0; i < scene_registry().size(); ++i)
    if (val == scene_registry()[i].name) return (SceneKind)i;
  throw UserError(opt + ": unknown value '" + val + "' (choose " + scene_names() + ")");
}

std::string scene_names() {
  std::string s;
  for (const SceneEntry &e : scene_registry()) s += std::string(s.empty() ? "" : "|") + e.name;
  return s;
}

template <int dim>
std::unique_ptr<SceneCase<dim>> make_scene(SceneKind k) {
  if constexpr (dim == 2) return scene_entry(k).make2();
  else return scene_entry(k).make3();
}
template std::unique_ptr<SceneCase<2>> make_scene<2>(SceneKind);
template std::unique_ptr<SceneCase<3>> make_scene<3>(SceneKind);

bool scene_has_reference(const Config &c) {
  return c.material == MaterialKind::MuI || c.material == MaterialKind::Nonlocal || c.material == MaterialKind::Dynamic;
}

const SceneRules &scene_rules(SceneKind k) {
  static std::vector<std::unique_ptr<SceneCase<2>>> made; // one per registered scene, made on first use
  const SceneEntry &e = scene_entry(k);
  if (made.size() <= (size_t)k) made.resize((size_t)k + 1);
  if (!made[(size_t)k]) made[(size_t)k] = e.make2();
  return *made[(size_t)k];
}

const std::vector<SceneOption> &SceneRules::options() const {
  static const std::vector<SceneOption> none;
  return none;
}

void SceneRules::signature(const Config &c, Signature &s) const {
  for (const SceneOption &o : options()) {
    const double v = c.scene_param(o.option);
    s.push_back({o.option, o.flag ? std::string(v != 0 ? "true" : "false") : opt::exact(v)});
  }
}

void SceneRules::validate_options(const Config &c) const {
  for (const SceneOption &o : options())
    if (!o.flag && !o.valid(c.scene_param(o.option))) opt::bad(std::string(o.option) + " must be " + opt::range_text(o) + " (got " + opt::fmt(c.scene_param(o.option)) + ")");
}

namespace {
// The declaration of a scene option: the run's scene's first, then any registered scene's.
const SceneOption *find_scene_option(SceneKind run, const std::string &name) {
  for (const SceneOption &o : scene_rules(run).options())
    if (name == o.option) return &o;
  for (size_t k = 0; k < scene_registry().size(); ++k)
    for (const SceneOption &o : scene_rules((SceneKind)k).options())
      if (name == o.option) return &o;
  return nullptr;
}
} // namespace

double Config::scene_param(const std::string &option) const {
  const auto it = scene_params.find(option);
  if (it != scene_params.end()) return it->second;
  const SceneOption *o = find_scene_option(scene, option);
  if (!o) throw UserError("internal: no scene declares the option " + option);
  return o->def;
}

void Config::set_scene_param(const std::string &option, double value) {
  if (!find_scene_option(scene, option)) throw UserError("internal: no scene declares the option " + option);
  scene_params[option] = value;
}

// (GM_OPT, options_util.hpp, needs notes_ and failed in scope.)
PetscErrorCode read_scene_options(PetscOptionItems *PetscOptionsObject, Config &c, const char *&failed, std::string &notes_) {
  PetscFunctionBeginUser;
  for (size_t k = 0; k < scene_registry().size(); ++k) {
    const SceneRules &rules = scene_rules((SceneKind)k);
    if (rules.options().empty()) continue;
    const std::string name = scene_registry()[k].name;
    PetscOptionsHeadBegin(PetscOptionsObject, ("Scene " + name + " (-scene " + name + "):").c_str());
    for (const SceneOption &o : rules.options()) {
      PetscBool set = PETSC_FALSE;
      if (o.flag) {
        PetscBool b = o.def != 0 ? PETSC_TRUE : PETSC_FALSE;
        GM_OPT(o.option, PetscOptionsBool(o.option, o.help, NULL, b, &b, &set));
        if (set) c.scene_params[o.option] = b ? 1 : 0;
      } else {
        double v = o.def;
        GM_OPT(o.option, PetscOptionsReal(o.option, o.help, NULL, v, &v, &set));
        if (set) c.scene_params[o.option] = v;
      }
    }
    PetscOptionsHeadEnd();
  }
  PetscFunctionReturn(0);
}

std::vector<BodySpec> SceneRules::bodies(const Config &c, std::vector<std::string> &names) const {
  names.clear();
  for (size_t k = 0; k < c.bodies.size(); ++k) names.push_back("-body" + std::to_string(c.bodies[k].index) + "_shape " + name_of(c.bodies[k].shape));
  return c.bodies;
}

std::vector<BodySpec> scene_bodies(const Config &c, std::vector<std::string> &names) { return scene_rules(c.scene).bodies(c, names); }
bool scene_has_bodies(const Config &c) {
  std::vector<std::string> names;
  return !scene_bodies(c, names).empty();
}

template <int dim>
Scene<dim>::Scene(State<dim> &sim) : case_(make_scene<dim>(sim.cfg.scene)) {}

template <int dim>
void Scene<dim>::lattice_position(const Config &cfg, const Grid<dim> &grid, int64_t id, double *X) {
  for (int d = 0; d < dim; ++d) {
    const int64_t n = (int64_t)grid.ncell[d] * cfg.ppc;
    const int64_t q = id % n;
    id /= n;
    X[d] = grid.lo[d] + (q + 0.5) / cfg.ppc * grid.h;
  }
}

template <int dim>
void Scene<dim>::initialize(State<dim> &sim) {
  const Config &c = sim.cfg;
  ParticleView<dim> P = sim.particles.get();
  double centre[3] = {0, 0, 0};
  for (int d = 0; d < dim; ++d) centre[d] = 0.5 * (std::max(c.body_lo[d], c.lo[d]) + std::min(c.body_hi[d], c.hi[d]));
  const std::unique_ptr<SceneCase<dim>> sc = make_scene<dim>(c.scene);
  for (PetscInt p = 0; p < P.n; ++p) {
    const double *x = P.x + p * dim;
    double *v = P.v + p * dim, *s = P.s + 6 * p;
    for (int q = 0; q < 6; ++q) s[q] = 0;
    for (int d = 0; d < dim; ++d) v[d] = 0;
    sc->init_particle(c, centre, x, v, s);
  }
  if (c.geostatic) {
    // sigma_yy = -rho |g| (top - y), lateral K0 = nu/(1 - nu) of it (uniaxial strain).
    const double top = std::min(c.body_hi[1], c.hi[1]), gy = std::fabs(c.gravity[1]), K0 = c.nu / (1 - c.nu);
    for (PetscInt p = 0; p < P.n; ++p) {
      double *s = P.s + 6 * p;
      const double syy = -c.rho * gy * (top - P.x[p * dim + 1]);
      s[1] += syy;
      s[0] += K0 * syy;
      s[2] += K0 * syy;
    }
  }
  sim.particles.restore(P);
}

template class Scene<2>;
template class Scene<3>;

} // namespace granmpm
