// Delaunay-Refining-Functional-Coarsening (Section 5): one evolution step.
#pragma once

#include <vector>

#include "evomesh/drfc_refinement.hpp"
#include "evomesh/options.hpp"
#include "evomesh/step.hpp"
#include "evomesh/step_context.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// Step 1 alone: the refined mesh M_I (input points first, in input order, then
// new ones), with f at its points in `f` and the counts in `report`.
Refined_mesh drfc_refine(const Mesh_arrays& mesh, const std::vector<double>& delta, const Drfc_options& options,
                         const Step_context& context);
inline Refined_mesh drfc_refine(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                const Drfc_options& options) {
  return drfc_refine(mesh, delta, options, Step_context::from_threads(options.threads));
}

// Runs DRFC on a validated mesh: M_I from drfc_refine, then the lexical-first
// maximal independent set of B(p, radius_scale f(p)/2) over the points of M_I
// (corners forced; boundary points, then original, Steiner and new points; smaller
// spheres first within a class) and the constrained Delaunay triangulation of the
// kept points. No new samples in step 2. delta: one positive finite factor per point.
// `context`: how the step runs (step_context.hpp); the output does not depend on it.
Evolve_result drfc(const Mesh_arrays& mesh, const std::vector<double>& delta, const Drfc_options& options,
                   const Step_context& context);
inline Evolve_result drfc(const Mesh_arrays& mesh, const std::vector<double>& delta, const Drfc_options& options) {
  return drfc(mesh, delta, options, Step_context::from_threads(options.threads));
}

}  // namespace evomesh
