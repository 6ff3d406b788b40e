// The names of the option enums (names.hpp): the solver's; the rigid bodies' are in
// rigid_body.hpp. parse_name reads an option value with them.
#pragma once

#include <stdexcept>
#include <string>

#include "granmpm/config.hpp"
#include "granmpm/names.hpp"
#include "granmpm/materials/drucker_prager.hpp"
#include "granmpm/materials/local_mu_i.hpp"
#include "granmpm/rigid_body.hpp"
#include "granmpm/shape.hpp"
#include "granmpm/transfer.hpp"

namespace granmpm {

GM_NAMES(BC, "sticky", "slip", "periodic", "free", "outlet")
GM_NAMES(SceneKind, "block", "bar", "column", "chute", "collapse", "silo",
         "annulus")
GM_NAMES(ShapeKind, "linear", "gimp", "bspline2")
GM_NAMES(TransferKind, "pic", "flip", "apic")
GM_NAMES(UpdateOrder, "usl", "usf", "musl")
GM_NAMES(DensityMethod, "local", "elemental", "hybrid")
GM_NAMES(FluidityMap, "interpolate", "cell_average")
#undef GM_NAMES

// The value named val, or UserError "<opt>: unknown value 'val' (choose a|b|c)".
template <class E>
E parse_name(const std::string &opt, const std::string &val) {
  for (int i = 0; i < Names<E>::n; ++i)
    if (val == Names<E>::v[i]) return (E)i;
  throw UserError(opt + ": unknown value '" + val + "' (choose " + names_list<E>() + ")");
}

} // namespace granmpm
