// Helpers shared by the components that register and check their own options inside the
// one PetscOptionsBegin/End block of Config::from_options (src/config.cpp: the core
// options and the material models' declared ones; src/modules/body_options.cpp: the rigid
// bodies, -body<k>_*). Internal to src/.
#pragma once

#include <petscsys.h>

#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <sstream>
#include <string>

#include "granmpm/config.hpp"
#include "granmpm/config_checks.hpp"
#include "granmpm/materials/model.hpp"
#include "granmpm/names.hpp"

namespace granmpm {
namespace opt {

inline std::string fmt(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// Full precision, so that a restart does not accept a changed value that prints alike.
inline std::string exact(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.17g", v);
  return std::string(b);
}
inline std::string vec(const std::array<double, 3> &a, int dim) {
  std::string r;
  for (int d = 0; d < dim; ++d) r += (d ? "," : "") + exact(a[d]);
  return r;
}

[[noreturn]] inline void bad(const std::string &msg) { throw UserError(msg); }

// A declared parameter's range as a message says it: "> 0", ">= 0", "in (0, 90) degrees".
inline std::string range_text(const ParamDecl &p) {
  std::string r;
  if (std::isfinite(p.lo) && std::isfinite(p.hi)) r = std::string("in ") + (p.lo_open ? "(" : "[") + fmt(p.lo) + ", " + fmt(p.hi) + (p.hi_open ? ")" : "]");
  else if (std::isfinite(p.lo)) r = std::string(p.lo_open ? "> " : ">= ") + fmt(p.lo);
  else if (std::isfinite(p.hi)) r = std::string(p.hi_open ? "< " : "<= ") + fmt(p.hi);
  else r = "finite";
  return r + p.unit;
}

// Option names built at run time (-body<k>_*) that must outlive the call that failed.
inline const char *keep(const std::string &s) {
  static std::string buf;
  buf = s;
  return buf.c_str();
}

// The first option whose text is not a finite number or beyond PetscInt, noted during the
// block and reported after it (PETSc parses inf/nan as reals and wraps large integers).
inline void note_int_range(std::string &notes, const char *name) {
  if (!notes.empty()) return;
  char val[4096] = "";
  PetscBool set = PETSC_FALSE;
  if (PetscOptionsGetString(NULL, NULL, name, val, sizeof val, &set) || !set) return;
  const int i = int_overflow_component(val, (long long)PETSC_MAX_INT);
  if (i < 0) return;
  const bool vec = std::strchr(val, ',') != nullptr;
  notes = std::string(name) + ": '" + val + "' is beyond the integer range of this build (" + std::to_string((long long)PETSC_MAX_INT) + ")" +
          (vec ? " (component " + std::to_string(i + 1) + ")" : std::string()) + "; give a smaller value";
}
inline void note_nonfinite(std::string &notes, const char *name) {
  if (!notes.empty()) return;
  char val[4096] = "";
  PetscBool set = PETSC_FALSE;
  if (PetscOptionsGetString(NULL, NULL, name, val, sizeof val, &set) || !set) return;
  const int i = nonfinite_component(val);
  if (i < 0) return;
  const bool vec = std::strchr(val, ',') != nullptr;
  notes = std::string(name) + ": '" + val + "' is not a finite number" + (vec ? " (component " + std::to_string(i + 1) + ")" : std::string()) +
          "; give a finite value (values beyond +-1.8e308 overflow to inf)";
}

// Stops reading at the first option whose value PETSc cannot parse, remembering its name
// in `failed`; notes non-finite reals and out-of-range integers in `notes_`. Both must be
// in scope (as PetscOptionsObject, which PetscOptionsReal & co. use).
#define GM_OPT(name, ...)                                                                           \
  do {                                                                                              \
    PetscErrorCode e_ = (__VA_ARGS__);                                                              \
    if (e_) {                                                                                       \
      failed = name;                                                                                \
      return e_;                                                                                    \
    }                                                                                               \
    if (std::strncmp(#__VA_ARGS__, "PetscOptionsReal", 16) == 0) ::granmpm::opt::note_nonfinite(notes_, name); \
    if (std::strncmp(#__VA_ARGS__, "PetscOptionsInt", 15) == 0) ::granmpm::opt::note_int_range(notes_, name);  \
  } while (0)

// An option whose value is one of the names of E (Names<E>, option_names.hpp): registered
// with the current value's name as default and help + ": a|b|c"; its text is kept in
// `texts` and parsed after the block (parse_name), so that bad names stop with the
// message of parse_name after every option was read.
template <class E>
PetscErrorCode name_option(PetscOptionItems *PetscOptionsObject, std::map<std::string, std::string> &texts, const char *name, const std::string &help, E value,
                           const char *&failed, const std::string &more = "") {
  char buf[256] = "";
  std::snprintf(buf, sizeof buf, "%s", name_of(value));
  PetscBool set = PETSC_FALSE;
  const PetscErrorCode e = PetscOptionsString(name, (help + ": " + names_list<E>() + more).c_str(), NULL, buf, buf, sizeof buf, &set);
  if (e) {
    failed = name;
    return e;
  }
  texts[name] = buf;
  return 0;
}

// dim comma-separated reals of an array option (n given) into dst.
inline void read_vec(const char *opt, int n, const PetscReal *src, int dim, std::array<double, 3> &dst) {
  if (n == 0) return;
  if (n != dim) bad(std::string(opt) + ": expected " + std::to_string(dim) + " comma-separated values for -dim " + std::to_string(dim) + ", got " + std::to_string(n));
  for (int d = 0; d < dim; ++d) dst[d] = src[d];
}

} // namespace opt
} // namespace granmpm
