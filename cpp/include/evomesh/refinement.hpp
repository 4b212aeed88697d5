// Delaunay refinement (Ruppert's rules) on a constrained triangulation of a domain:
// the quality pass after FRFC/DRFC (Section 6) and DRFC's refinement stage (Section 5).
#pragma once

#include <cstddef>
#include <memory>
#include <utility>
#include <vector>

#include "evomesh/spacing.hpp"
#include "evomesh/triangulation.hpp"
#include "evomesh/options.hpp"
#include "evomesh/types.hpp"

namespace evomesh {


struct Refinement_report {
  std::size_t n_inserted = 0;              // points inserted (inside and on segments)
  std::size_t n_inserted_on_segments = 0;
  std::size_t n_removed = 0;               // points dropped for crowding a segment
  std::size_t n_crowded_segments = 0;      // pieces split because points crowded them
  std::size_t rounds = 0;                  // spacing_refine: passes with exact f
  bool capped = false;                     // stopped by the bound on inserted points
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

// The quality pass: constrained Delaunay triangulation of `points` with `pieces`
// (as in constrained_delaunay), then crowding points dropped and their segments
// split (Section 6), then Ruppert's rules 1 and 3 with CGAL's Delaunay mesher
// (midpoint splits of encroached segments, off-centres (Ungor) of triangles below
// min_angle, concentric-shell splits near small input angles). There is no size
// criterion: new points only go where a triangle is badly shaped, so their spacing
// follows that of the points handed in.
Refined_mesh quality_triangulate(const std::vector<Vec2>& points, const std::vector<Point_kind>& kind,
                                 const std::vector<Constraint_piece>& pieces, const Quality_options& options);

// The triangulation of quality_triangulate started early: the first points
// (those known before the rest, e.g. the kept input points of FRFC) are inserted
// now, possibly on another thread, and the rest by finish(). Inserting in two
// batches gives the same triangulation whatever thread does the work.
class Early_triangulation {
 public:
  Early_triangulation();
  ~Early_triangulation();
  Early_triangulation(const Early_triangulation&) = delete;
  Early_triangulation& operator=(const Early_triangulation&) = delete;

  // Inserts `first` (they become points 0 .. first.size() - 1), scaled as
  // unit_scaling scales them (the corners span the domain, so all points
  // usually scale alike; finish() checks).
  void insert_first(const std::vector<Vec2>& first);

  // quality_triangulate(points, ...) where points starts with the `first` points.
  // Falls back to a triangulation from scratch when the rest does not scale
  // exactly with the first points' scaling.
  Refined_mesh finish(const std::vector<Vec2>& points, const std::vector<Point_kind>& kind,
                      const std::vector<Constraint_piece>& pieces, const Quality_options& options);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

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

// Smallest interior angle (degrees) over `triangles` and the centroid of the
// triangle that has it.
std::pair<double, Vec2> smallest_angle(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles);

}  // namespace evomesh
