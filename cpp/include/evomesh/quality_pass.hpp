// The quality pass after FRFC and DRFC (Section 6): crowding points dropped,
// then Ruppert's rules with off-centres, on the constrained Delaunay
// triangulation of the kept points.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "evomesh/options.hpp"
#include "evomesh/refined_mesh.hpp"
#include "evomesh/triangulation.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// The quality pass: constrained Delaunay triangulation of `points` with `pieces`
// (as in constrained_delaunay), then crowding points dropped and their segments
// split (Section 6), then Ruppert's rules 1 and 3 with CGAL's Delaunay mesher
// (midpoint splits of encroached segments, off-centres (Ungor) of triangles below
// min_angle, concentric-shell splits near small input angles). There is no size
// criterion: new points only go where a triangle is badly shaped, so their spacing
// follows that of the points handed in (or the domain's features where those are
// finer). The number of insertions is bounded by options.max_inserted_fraction n +
// max_inserted_extra where constraints meet under less than 60 degrees; where none
// do, by that plus what the features need (quality_pass.cpp, feature_allowance).
// `pinned` (aligned with points; empty: none) marks points the pass never drops
// (required points), even where they crowd a segment.
Refined_mesh quality_triangulate(const std::vector<Vec2>& points, const std::vector<Point_kind>& kind,
                                 const std::vector<Constraint_piece>& pieces, const Quality_options& options,
                                 const std::vector<std::uint8_t>& pinned = {});

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

  // Inserts `more`, the points that follow those inserted so far (a second
  // batch before finish(), possibly on another thread; the scaling stays the
  // first batch's). finish() checks that every point inserted is the one the
  // final point list has at its index.
  void insert_more(const std::vector<Vec2>& more);

  // quality_triangulate(points, ...) where points starts with the `first` points.
  // Falls back to a triangulation from scratch when the rest does not scale
  // exactly with the first points' scaling.
  Refined_mesh finish(const std::vector<Vec2>& points, const std::vector<Point_kind>& kind,
                      const std::vector<Constraint_piece>& pieces, const Quality_options& options,
                      const std::vector<std::uint8_t>& pinned = {});

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Smallest interior angle (degrees) over `triangles` and the centroid of the
// triangle that has it.
std::pair<double, Vec2> smallest_angle(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles);
// Python's quality() figures in one parallel pass (mesh_quality.py's formulas:
// angles by the law of cosines from the edge lengths, clipped; radius-edge =
// circumradius / shortest edge): the smallest and largest angle, the first
// triangle with the smallest angle, the largest and the sum of the radius-edge
// ratios, and the counts of the angles in 18 bins of 10 degrees.
struct Quality_summary {
  double min_angle = 180, max_angle = 0, max_radius_edge = 0, sum_radius_edge = 0;
  Index worst = -1;
  std::array<std::int64_t, 18> histogram{};
};
Quality_summary quality_summary(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles);
// The same over triangles [begin, end) (the first smallest of them).
std::pair<double, Vec2> smallest_angle_in(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                                          std::size_t begin, std::size_t end);

}  // namespace evomesh
