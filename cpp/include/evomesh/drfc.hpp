// Delaunay-Refining-Functional-Coarsening (Section 5): one evolution step.
#pragma once

#include <vector>

#include "evomesh/frfc.hpp"
#include "evomesh/refinement.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

struct Drfc_options {
  // Step 1: Delaunay refinement with Ruppert's rules 1 and 3 for this angle
  // (degrees) and rule 4 for the spacing function f.
  double min_angle = 20.0;
  // Step 2: spheres B(p, radius_scale f(p) / 2) on the refined points. 1 is the
  // one-level coarsening of Miller, Talmor and Teng.
  double radius_scale = 1.0;
  int threads = 0;            // spacing queries (results do not depend on it)
  // Refuse a step whose refinement would need more points than this (estimated
  // from f as FRFC's sampling is), and stop refining at twice the estimate.
  double max_samples = 5e7;
  // The quality pass of Section 6 on the coarsened points (off here, on in evolve).
  bool quality = false;
  Quality_options quality_options;
};

// Step 1 alone: the refined mesh M_I (input points first, in input order, then
// new ones), with f at its points in `f` and the counts in `report`.
Refined_mesh drfc_refine(const Mesh_arrays& mesh, const std::vector<double>& delta, const Drfc_options& options);

// Runs DRFC on a validated mesh: M_I from drfc_refine, then the lexical-first
// maximal independent set of B(p, radius_scale f(p)/2) over the points of M_I
// (corners forced; boundary points, then original, Steiner and new points; smaller
// spheres first within a class) and the constrained Delaunay triangulation of the
// kept points. No new samples in step 2. delta: one positive finite factor per point.
Evolve_result drfc(const Mesh_arrays& mesh, const std::vector<double>& delta, const Drfc_options& options);

}  // namespace evomesh
