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

// Options given by name whose Config field is a flag (Config::implicit, checkpoint_on_instability).
enum class ImplicitJacobian { MfOperator = 0, Assembled = 1 };
enum class ImplicitTangent { Elastic = 0, Scaled = 1 };
enum class OnInstability { Abort = 0, CheckpointAndAbort = 1 };

GM_NAMES(BC, "sticky", "slip", "periodic", "free", "outlet")
GM_NAMES(ShapeKind, "linear", "gimp", "bspline2")
GM_NAMES(TransferKind, "pic", "flip", "apic")
GM_NAMES(UpdateOrder, "usl", "usf", "musl")
GM_NAMES(DensityMethod, "local", "elemental", "hybrid")
GM_NAMES(FluidityMap, "interpolate", "cell_average")
GM_NAMES(FluidityStepKind, "explicit", "implicit")
GM_NAMES(LaplacianStencil, "compact", "box")
GM_NAMES(TimeIntegrator, "explicit", "implicit", "implicit_coupled")
GM_NAMES(StressUpdate, "implicit", "explicit")
GM_NAMES(FluidityBC, "zero_flux", "dirichlet")
GM_NAMES(FluidityQuadrature, "particle", "cell")
GM_NAMES(FluiditySolverKind, "auto", "direct", "iterative")
GM_NAMES(BodyFluidityBC, "zero_flux", "zero")
GM_NAMES(ImplicitJacobian, "mf_operator", "assembled")
GM_NAMES(ImplicitTangent, "elastic", "scaled")
GM_NAMES(OnInstability, "abort", "checkpoint_and_abort")
#undef GM_NAMES

// The value named val, or UserError "<opt>: unknown value 'val' (choose a|b|c)".
template <class E>
E parse_name(const std::string &opt, const std::string &val) {
  for (int i = 0; i < Names<E>::n; ++i)
    if (val == Names<E>::v[i]) return (E)i;
  throw UserError(opt + ": unknown value '" + val + "' (choose " + names_list<E>() + ")");
}

} // namespace granmpm
