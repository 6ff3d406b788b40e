// The rigid bodies' options, -body<k>_* (k < Config::kMaxBodies) and -body_contact_layer,
// -bodies_interval: registered (so -help lists them), converted into Config::bodies,
// checked and put in the restart signature here, by the body component, under its prefix.
// Config::from_options calls read() inside its one options block and finish() after it.
#pragma once

#include <petscsys.h>

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "granmpm/config.hpp"

namespace granmpm {

class BodyOptions {
public:
  BodyOptions();
  ~BodyOptions();
  // Inside PetscOptionsBegin/End: registers and reads the options; failed: the option
  // PETSc could not parse; notes: the first non-finite or out-of-range value.
  PetscErrorCode read(PetscOptionItems *PetscOptionsObject, const Config &c, const char *&failed, std::string &notes);
  // After the block: the bodies given into c.bodies (and the two global body options).
  void finish(Config &c) const;
  // One-line errors naming the option (Config::validate).
  static void validate(const Config &c);
  // "-option value" lines of the bodies (Config::signature).
  static void signature(const Config &c, std::vector<std::pair<std::string, std::string>> &s);

private:
  struct Raw;
  std::unique_ptr<Raw> r_;
};

} // namespace granmpm
