// Functional-Refining-Functional-Coarsening (Section 3.2): one evolution step.
#pragma once

#include <vector>

#include "evomesh/options.hpp"
#include "evomesh/segment_chains.hpp"
#include "evomesh/step.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// Runs FRFC on a validated mesh. delta: one positive finite factor per point.
Evolve_result frfc(const Mesh_arrays& mesh, const std::vector<double>& delta,
                   const Frfc_options& options);

}  // namespace evomesh
