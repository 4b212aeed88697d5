// The result of Delaunay refinement: the quality pass (Section 6) and DRFC's refinement (Section 5).
#pragma once

#include <cstddef>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

struct Refinement_report {
  std::size_t n_inserted = 0;              // points inserted (inside and on segments)
  std::size_t n_inserted_on_segments = 0;
  std::size_t n_inserted_outside = 0;      // new points with no triangle of the domain at them (never, by design)
  std::size_t n_removed = 0;               // points dropped for crowding a segment
  std::size_t n_crowded_segments = 0;      // pieces split because points crowded them
  std::size_t rounds = 0;                  // spacing_refine: passes with exact f
  bool capped = false;                     // stopped by the bound on inserted points
  bool stalled = false;                    // quality_rounds: a round inserted nothing with work left
  bool round_limit = false;                // quality_rounds: stopped by the cap on rounds with work left
  // The quality pass: seconds of its insertions into the triangulation (the
  // constraint pieces, then the refinement's points), which follow the
  // triangulation's history; not the set-up scans or the extraction.
  double insert_seconds = 0;
};

// Points of a refined triangulation: the input points that remain, in input order,
// then the new points (sorted by coordinates). Kinds of input points are kept (a
// point that ends up on a constraint is at most `boundary`); new points are
// `boundary` on a constraint and `sampled` elsewhere. Segments: every constraint
// edge; boundary ones have the domain on their left.
struct Refined_mesh {
  Mesh_arrays mesh;
  std::vector<Index> source;  // input point index, -1 for a new point
  std::vector<double> f;      // spacing_refine only: the spacing function at every point
  Refinement_report report;
};

}  // namespace evomesh
