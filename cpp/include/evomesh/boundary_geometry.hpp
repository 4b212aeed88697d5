// Curved boundaries: the true curve behind a polygonal boundary,
// given per segment tag as a projection onto it. With a geometry, a boundary
// vertex of a curved tag where the boundary turns by less than `corner_angle`
// is not a corner (a step may remove it), and every boundary point a step
// creates on a curved tag is moved onto the curve. Without one, the polygon is
// the domain, exactly (classify_points).
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

// The default of Boundary_geometry::corner_angle (degrees).
constexpr double kDefaultCornerAngle = 30.0;

struct Boundary_geometry {
  // Segment tags whose segments approximate a curve (sorted, no repeats).
  std::vector<std::int64_t> curved_tags;
  // A vertex where the boundary turns by more than this (degrees, in (0, 180))
  // stays a corner, even between two segments of one curved tag.
  double corner_angle = kDefaultCornerAngle;
  // Moves points[i] onto the curve of tag tags[i] (in place); may throw.
  std::function<void(std::vector<Vec2>& points, const std::vector<std::int64_t>& tags)> project;

  bool is_curved(std::int64_t tag) const {
    return std::binary_search(curved_tags.begin(), curved_tags.end(), tag);
  }
  // Throws Input_error naming the first field out of range.
  void validate() const;
};

struct Mesh_arrays;
struct Evolve_result;
struct Constraint_piece;
struct Quality_options;

// The segments at every point of a mesh (the segments at v are adj[xadj[v]] ..
// adj[xadj[v + 1] - 1]), for walks along constraint pieces.
struct Segments_at_points {
  std::vector<Index> xadj, adj;
  explicit Segments_at_points(const Mesh_arrays& mesh);
  // From point v along segment s, through the points with selection_index -1
  // (inserted inside a piece: two segments each, else std::logic_error), to
  // the next selected point, which is returned; `walked` gets the segments
  // passed and `inside` (if given) the inserted points.
  Index walk(const Mesh_arrays& mesh, const std::vector<Index>& selection_index, Index v, Index s,
             std::vector<Index>& walked, std::vector<Index>* inside = nullptr) const;
};

// The step's input with the kinds of points on curved chains taken from the
// geometry (corners only where it turns by more than corner_angle, at tag
// changes and at required points), and a zero tag on every segment when it had
// none. mesh.geometry must be set; Input_error for a curved tag no segment has.
Mesh_arrays with_curve_kinds(const Mesh_arrays& mesh);

// FRFC, before triangulating: moves the kept segment candidates of curved tags
// onto their curves. Candidate k is centers[first + k], on segment
// segment_of_candidate[k]; each may move by at most its sphere's radius, or by
// its distance along the curved segments to a vertex on the curve (else
// Input_error: the curve is not the one the segments approximate); a candidate
// of an interior chain (an interface) by its radius only, else it stays on its
// chord (an interface's input points lie on its curve: a longer move means the
// curve is not resolved there). Returns the
// largest move; `interior_moves` (if given) gets (candidate, position before)
// of every candidate of an interior chain that moved.
double project_segment_candidates(const Mesh_arrays& mesh, const std::vector<std::uint32_t>& segment_of_candidate,
                                  std::size_t first, const std::vector<std::uint8_t>& kept,
                                  const std::vector<double>& radius, std::vector<Vec2>& centers,
                                  std::vector<std::pair<std::size_t, Vec2>>* interior_moves = nullptr);

// Undoes the moves (point, position before) of points whose pieces cross or
// touch other pieces (meeting_pieces), until none do or every such move is
// undone; returns the number undone. For the points of interior chains (an
// interface): where a fold of the curve is narrower than the spacing, the move
// onto the curve would make its pieces cross; the point stays on its chord
// (the pieces between unmoved points are chords of the input's, which do not cross).
std::size_t keep_pieces_apart(std::vector<Vec2>& points, const std::vector<Constraint_piece>& pieces,
                              const std::vector<std::pair<Index, Vec2>>& moved);

// After triangulating the selection with `pieces`: every new point on a curved
// piece (a new selected point, or one the quality pass inserted; by at most half
// its shortest segment, or, off interior chains, its distance along the pieces
// to a point on the curve; a point of an interior chain whose move would make
// pieces cross, touch or fold stays on its chord: keep_pieces_apart) is moved
// onto its curve and the constraints are
// triangulated again through the moved points; points that end up outside the
// domain are dropped (stats "curve_points_projected", "curve_points_dropped_outside",
// "curve_largest_move"). selection_index: of every output point, -1 for one the
// quality pass inserted. With `quality` (the step's quality pass), where the
// moves leave an angle below its min_angle the pass runs again on the fitted
// mesh, and its new points on curves are fitted too (at most twice; stats
// "curve_refits"); a round that fails or lowers the smallest angle is undone and
// ends the refits ("curve_refits_undone"). Returns how far outside the input's domain the new boundary
// may lie (at most the longest piece on a curve, or twice the largest move).
double fit_to_curves(const Boundary_geometry& geometry, const std::vector<Constraint_piece>& pieces,
                     const std::vector<Index>& selection_index, Evolve_result& result,
                     const Quality_options* quality = nullptr);

}  // namespace evomesh
