// The material registry: the built-in models, one line each, in the order of MaterialKind;
// register_material<M>() appends further ones (a test's model). Config's material
// queries (its name, whether it is granular, its own parameters) read the registry.
#include "granmpm/material.hpp"

#include "granmpm/materials/drucker_prager.hpp"
#include "granmpm/materials/dynamic_ngf.hpp"
#include "granmpm/materials/elastic.hpp"
#include "granmpm/materials/local_mu_i.hpp"
#include "granmpm/materials/nonlocal_ngf.hpp"

namespace granmpm {

namespace {
std::vector<MaterialEntry> &registry() {
  static std::vector<MaterialEntry> r = [] {
    std::vector<MaterialEntry> v;
    v.push_back(material_entry_of<LinearElastic>()); // MaterialKind::LinearElastic
    v.push_back(material_entry_of<Hypoelastic>());   // MaterialKind::Hypoelastic
    v.push_back(material_entry_of<LocalMuI>());      // MaterialKind::MuI
    v.push_back(material_entry_of<NonlocalNGF>());   // MaterialKind::Nonlocal
    v.push_back(material_entry_of<DynamicNGF>());    // MaterialKind::Dynamic
    v.push_back(material_entry_of<DruckerPrager>()); // MaterialKind::DruckerPrager
    return v;
  }();
  return r;
}
} // namespace

const std::vector<MaterialEntry> &material_registry() { return registry(); }

MaterialKind add_material(MaterialEntry e) {
  for (const MaterialEntry &m : registry())
    if (std::string(m.info.name) == e.info.name) throw UserError(std::string("internal: material '") + e.info.name + "' registered twice");
  registry().push_back(std::move(e));
  return (MaterialKind)(registry().size() - 1);
}

const MaterialEntry &material_entry(MaterialKind k) {
  const int i = (int)k;
  if (i < 0 || i >= (int)registry().size()) throw UserError("internal: material " + std::to_string(i) + " is not registered");
  return registry()[i];
}

MaterialInputs material_inputs(const Config &c) {
  MaterialInputs in;
  in.el = ElasticModuli::from_E_nu(c.E, c.nu);
  in.rho = c.rho;
  in.gran = &c.gran;
  in.stress_update = c.stress_update;
  in.fluidity_step = (int)c.fluidity_step;
  in.param = [&c](const std::string &opt) { return c.param(opt); };
  return in;
}

const char *to_string(MaterialKind m) {
  const int i = (int)m;
  return i >= 0 && i < (int)registry().size() ? registry()[i].info.name : "?";
}

bool Config::granular() const { return material_entry(material).info.granular; }

double *Config::param_slot(const std::string &opt) {
  if (opt == "-t0") return &t0;
  if (opt == "-g0") return &g0;
  return &model_params[opt];
}

double Config::param(const std::string &opt) const {
  if (opt == "-t0") return t0;
  if (opt == "-g0") return g0;
  const auto it = model_params.find(opt);
  if (it != model_params.end()) return it->second;
  for (const ParamDecl &p : material_entry(material).info.params)
    if (opt == p.option) return p.def;
  throw UserError("internal: -material " + std::string(to_string(material)) + " has no parameter " + opt);
}

} // namespace granmpm
