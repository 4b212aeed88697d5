// Cost follows the change: FRFC where delta = 1 on most of
// the mesh, with the output of the full algorithm (frfc.hpp), bit for bit.
//
// The step is the one outline, frfc_over_scope (frfc.cpp), over the scope
// Changed_region (incremental_step.cpp; detail/step_scope.hpp): work that
// certainly changes nothing is not done, each restriction with its certificate:
//
// - the Apollonius graphs hold only the sites that can attain f at a point where
//   f is asked (Eq. 3: a site c matters at x only if |x - c| <= f(x));
// - a triangle whose every grid sample lies in a cover disc of a kept vertex is
//   not sampled (those samples are dropped by the sample filter anyway);
// - the packing passes run on the spheres that can overlap a sphere whose fate
//   is not certain; the others are old points with radius <= nn / 2, which no
//   earlier sphere can reject (Lemma 3.1: f(p) = delta(p) nn(p) = nn(p) at
//   delta = 1, and two such spheres are disjoint).
//
// What stays global: the quality pass of all selected points (without it the
// triangulation is updated locally, docs/distributed-step.md 2.5), the parent
// map, nn_M (returned in the lineage; measured again only where it can change),
// the spacing repair (its gap repair visits every input point), and O(n) loops.
#pragma once

#include <vector>

#include "evomesh/options.hpp"
#include "evomesh/step.hpp"
#include "evomesh/step_context.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// Whether the incremental step runs: no curved boundaries, the sample filter
// on, and delta != 1 at no more than half of the points (beyond that the full
// step is as fast). O(n) counts, decided before any work; frfc() asks it (with
// options.incremental). No other input is declined: what made the step give up
// late (a triangle or segment whose adaptive grid asks f itself, asks_spacing)
// is answered by a graph of the sites near it (incremental_step.cpp).
// Preconditions: those of frfc (check_delta).
bool incremental_applies(const Mesh_arrays& mesh, const std::vector<double>& delta, const Frfc_options& options);

// frfc(mesh, delta, options), bit for bit, where incremental_applies(mesh,
// delta, options) (else throws std::invalid_argument). Preconditions: those of
// frfc, checked by it (check_delta, options.validate()). What fails inside
// throws, as in the full step: a refused sample budget (max_samples) is the
// same Input_error with the same message (the same estimate).
// Adds the stats "incremental_step" (1; the full step's is 0),
// "incremental_region_points" (points of triangles sampled or of spheres
// packed), "incremental_quiet_triangles" (triangles not sampled: settled or
// certified quiet) and "incremental_sites" (sites of the Apollonius graphs).
// Without the quality pass the triangulation is the input's, updated
// (updated_constrained_delaunay, triangulation_update.hpp): stats
// "triangulation_update_declined" (0: updated; else why it was built whole)
// and "triangulation_update_cavity_triangles".
Evolve_result incremental_frfc(const Mesh_arrays& mesh, const std::vector<double>& delta,
                               const Frfc_options& options, const Step_context& context);
inline Evolve_result incremental_frfc(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                      const Frfc_options& options) {
  return incremental_frfc(mesh, delta, options, Step_context::from_threads(options.threads));
}

}  // namespace evomesh
