// DRFC's Delaunay refinement (Section 5): Ruppert's rules 1 and 3 and rule 4 in
// terms of the spacing function.
#pragma once

#include <cstddef>
#include <vector>

#include "evomesh/refined_mesh.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// DRFC, step 1 (Section 5): Delaunay refinement of `mesh` with rules 1 and 3 for
// min_angle (circumcentres) and rule 4 in terms of the spacing function: a triangle is split while
// one of its vertices v has a Delaunay neighbour spacing above f(v), where
// f(p) = min(f from `spacing`, delta(p) nn_M(p)) at input points. (For an input
// point this is nn > delta(p) nn_M(p) when delta(p) <= 1 (Lemma 3.1) and never
// triggers when delta(p) >= 1.) New points get f from the Apollonius sites of their
// neighbours while refining; after every pass f is evaluated exactly at them and
// the pass repeats until no vertex violates rule 4, or max_inserted points were
// inserted. Preconditions: `mesh` valid (segments, kinds), f_at_points.size() == n.
Refined_mesh spacing_refine(const Mesh_arrays& mesh, const Spacing_function& spacing,
                            const std::vector<double>& f_at_points, double min_angle,
                            std::size_t max_inserted, int threads);

}  // namespace evomesh
