// A step that certainly changes nothing costs a few
// percent of a full step. frfc() asks empty_scope_frfc first; it answers only
// when O(n) certificates (empty_scope.cpp, stage by stage) prove that the full
// step would return its input as the "unchanged" path of finish_step returns
// it: the same points, triangles and segments in the input's order, the
// input's tags, every point kept (origin = its index, no parent triangle), the
// input's nn and f as the lineage. Otherwise it returns nothing and the step
// runs as before (no work of the step is repeated but nn and the local feature
// size, which the certificate needs).
#pragma once

#include <optional>
#include <vector>

#include "evomesh/options.hpp"
#include "evomesh/step.hpp"
#include "evomesh/step_context.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// frfc(mesh, delta, options) bit for bit (but the stats: "empty_scope" = 1),
// or nullopt when the certificate does not hold; then `declined_by` (optional)
// receives the number of the first certificate that failed (C0-C14 in
// empty_scope.cpp; 0: the options; 1: delta != 1 somewhere; 4: the segments
// against the triangles; 5: the boundary loops do not bound M alone; 6: a
// hidden side of a boundary edge encroaches it; 14: the geometry (curves)
// refused). Meshes with holes, non-convex domains and curved boundaries are
// certified as convex uncurved ones are.
// Preconditions: those of frfc (check_delta, options.validate()).
std::optional<Evolve_result> empty_scope_frfc(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                              const Frfc_options& options, const Step_context& context,
                                              int* declined_by = nullptr);

}  // namespace evomesh
