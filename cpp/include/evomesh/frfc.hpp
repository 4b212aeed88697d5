// Functional-Refining-Functional-Coarsening (Section 3.2): one evolution step.
#pragma once

#include <vector>

#include "evomesh/options.hpp"
#include "evomesh/segment_chains.hpp"
#include "evomesh/step.hpp"
#include "evomesh/step_context.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// Runs FRFC on a validated mesh. delta: one positive finite factor per point.
// `context`: how the step runs (step_context.hpp); the output does not depend on it.
Evolve_result frfc(const Mesh_arrays& mesh, const std::vector<double>& delta, const Frfc_options& options,
                   const Step_context& context);
// The same with Step_context::from_threads(options.threads).
inline Evolve_result frfc(const Mesh_arrays& mesh, const std::vector<double>& delta, const Frfc_options& options) {
  return frfc(mesh, delta, options, Step_context::from_threads(options.threads));
}

}  // namespace evomesh
