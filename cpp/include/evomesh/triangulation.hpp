// Constrained Delaunay triangulation and mesh checks (CGAL).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

// A constraint between two output points. For a boundary piece the domain lies
// to the left of a -> b; an interior piece has the domain on both sides.
// The canonical order of triangles: each rotated to start at its
// least point index (orientation kept), then sorted by its three indices.
// Every path that makes triangles ends with it (a step's finish_step,
// constrained_delaunay, drfc_refine, the motion's remesh): a triangulation is
// a function of its points and constraints (CGAL decides cocircular points by
// a symbolic perturbation in (x, y) order; the quality pass reads no insertion
// history, cpp/tests/test_quality_history.cpp), and with this order so are the
// arrays, whichever path or thread count built them; where a rank of a
// partitioned step owns a contiguous range of point ids, the triangles whose
// least point it owns are a contiguous range too.
// O(n + m). Returns the order applied (new position -> old), for arrays
// aligned with the triangles.
std::vector<Index> canonical_triangle_order(std::size_t n_points, std::vector<Triangle>& triangles);
namespace detail {

// One step of sorting a sequence that is almost in order (a few items displaced
// forward or backward, also in short runs): x joins the increasing `run`, and
// what does not fit goes to `aside` (to be sorted and merged back). An x below
// the run's last takes off the few (at most kLookBack) larger items before it,
// which were displaced forward, or goes aside itself when more are larger (it
// was displaced backward). Amortised O(1); the run stays strictly increasing.
template <class T, class Less>
void extend_increasing_run(std::vector<T>& run, std::vector<T>& aside, const T& x, Less less) {
  constexpr std::size_t kLookBack = 16;
  std::size_t larger = 0;
  while (larger < run.size() && larger <= kLookBack && less(x, run[run.size() - 1 - larger])) ++larger;
  if (larger > kLookBack) {
    aside.push_back(x);
    return;
  }
  for (; larger > 0; --larger) {
    aside.push_back(run.back());
    run.pop_back();
  }
  run.push_back(x);
}

}  // namespace detail

// A triangle rotated to start at its least point index (orientation kept).
inline Triangle least_index_first(Triangle t) {
  while (t[0] > t[1] || t[0] > t[2]) t = {t[1], t[2], t[0]};
  return t;
}

struct Constraint_piece {
  Index a;
  Index b;
  bool boundary;
  std::int64_t tag = 0;  // the segment tag of the chain it lies on
};

// What a step says when two of its constraint pieces cross (CGAL's
// Intersection_of_constraints_exception while inserting them): a ValueError in
// Python, never CGAL's bare RuntimeError, naming the two pieces and where they
// cross (first_crossing_pieces), and whether the cause is rounding or geometry.
Input_error crossing_pieces_error(const std::vector<Vec2>& points, const std::vector<Constraint_piece>& pieces);

// The pairs (i < j, sorted) of pieces that cross: their interiors meet at one
// point, or they overlap along a line (exact predicates); with `touching`, also
// those where an end of one lies inside the other (which a constrained
// triangulation splits there). A grid of cells about the mean piece length:
// O(m) for pieces of similar length.
std::vector<std::array<Index, 2>> meeting_pieces(const std::vector<Vec2>& points,
                                                 const std::vector<Constraint_piece>& pieces, bool touching);
// The first pair of meeting_pieces without touching, {-1, -1} for none.
std::array<Index, 2> first_crossing_pieces(const std::vector<Vec2>& points,
                                           const std::vector<Constraint_piece>& pieces);

// Constrained Delaunay triangulation of `points` with `pieces` as constraints;
// returns the counter-clockwise triangles inside the domain the pieces bound
// (regions are flood-filled from the sides of the pieces, so holes stay holes).
// Throws crossing_pieces_error() when two pieces cross.
std::vector<Triangle> constrained_delaunay(const std::vector<Vec2>& points,
                                           const std::vector<Constraint_piece>& pieces);

// The constrained Delaunay triangulation of one MPI rank's points, for the
// distributed triangulation (python/evomesh/distributed/triangulation.py;
// docs/distributed-step.md 3.5): every finite face, unlabelled, with what the
// caller needs to certify faces and label the domain across ranks.
// neighbour[t][k]: the face across the edge opposite corner k (-1: infinite);
// constrained[t] bit k: that edge is a piece; seed[t]: the labels the pieces
// give the face (bit 0 inside: the left of a boundary piece, either side of an
// interior one; bit 1 outside: the right of a boundary piece). The faces come
// in canonical order (canonical_triangle_order). crossing_pieces_error() when
// two pieces cross.
struct Local_triangulation {
  std::vector<Triangle> triangles;
  std::vector<std::array<Index, 3>> neighbour;
  std::vector<std::uint8_t> constrained;
  std::vector<std::uint8_t> seed;
};
Local_triangulation local_constrained_delaunay(const std::vector<Vec2>& points,
                                               const std::vector<Constraint_piece>& pieces);

// The extreme points of `points` (vertices of their convex hull, collinear
// points left out), counter-clockwise; exact predicates. O(n log n).
std::vector<Index> convex_hull_vertices(const std::vector<Vec2>& points);
// For each edge (a[k], b[k]): whether no point of `points` lies strictly to its
// right (exact), i.e. whether the line supports them all on its left. O(#edges x #points).
std::vector<std::uint8_t> supports_on_left(const std::vector<Vec2>& a, const std::vector<Vec2>& b,
                                           const std::vector<Vec2>& points);

// Checks that a mesh is planar: its triangles cover no point of the plane twice
// and touch only in shared edges and points; throws Input_error naming the
// problem. Preconditions: `triangles` counter-clockwise (orient_triangles), edge
// manifold with consistent orientation and `boundary` its boundary edges with
// the domain on their left (build_segments checks and builds both). Exact and
// O(n) plus a constrained Delaunay triangulation of the boundary points and edges
// only: the number of triangles over a point is the winding number of the
// boundary around it, flood-filled over that triangulation (the argument is in
// triangulation.cpp). Also refuses orphan points (used by no triangle) and
// duplicate boundary points. For such meshes it accepts exactly what
// check_planar_mesh_cdt accepts.
void check_planar_mesh(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                       const std::vector<Edge>& boundary);

// The reference check (Mesh()'s older check; kept for tests and
// benchmarks): inserts all points and every edge into a constrained Delaunay
// triangulation that throws on crossing constraints, then asks that every
// triangle be a face of it. Throws Input_error for duplicate points, crossing
// edges, a point inside a triangle or on an edge.
void check_planar_mesh_cdt(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles);

// Mesh()'s flatness limits (python/evomesh/mesh.py, _check_not_flat), computed as
// numpy does there: for each triangle the height (twice its area over its
// longest edge) against min_relative_height times the longest edge ("thin") and
// against min_height_ulps units of rounding of its largest coordinate
// ("coarse"). Returns the first thin and the first coarse triangle, -1 for none.
// On the caller's arrays (n points, m triangles; no copy), in parallel blocks;
// Input_error for a point index out of range.
std::array<Index, 2> first_flat_triangles(const Vec2* points, std::size_t n, const Triangle* triangles,
                                          std::size_t m, double min_relative_height, double min_height_ulps);

// Where the domain nearly touches itself across its outside: the first boundary
// edge (index into `boundary`) and the corner (a point with corner[v] != 0 on
// the boundary) closest to it among those not at its ends that lie closer to it
// than min_ulps units of rounding of the largest coordinate of the three
// points; {-1, -1} for none. Mesh()'s flatness limit asks this much of every
// triangle, but no triangle witnesses a gap outside the domain, and there
// CGAL's mesher splits an edge at a rounded midpoint that can land on or across
// the near point (crossing constraints, duplicates). Corners suffice: two
// straight chains of boundary edges come closest at an end of one of them (or
// cross), and a step keeps every corner and every chain's line, so a step's
// output passes when its input does (points a step adds on the sides of a small
// outer angle come close to the other side, which is no pinch). Boundary
// corners in a static kd-tree, each edge a query pruned by the distance of a
// node's box to the edge's line and box: O(n log n) on boundaries of realistic
// shape.
std::array<Index, 2> first_pinched_boundary(const std::vector<Vec2>& points, const std::vector<Edge>& boundary,
                                            const std::vector<char>& corner, double min_ulps);

// The first triangle whose signed area (floating point, as Mesh's check in
// Python) is not positive, -1 for none. As first_flat_triangles: the caller's
// arrays, parallel blocks, Input_error for an index out of range.
Index first_inverted_triangle(const Vec2* points, std::size_t n, const Triangle* triangles, std::size_t m);

// Orients every triangle counter-clockwise (exact predicate); throws Input_error
// for a zero-area triangle. Returns the number of triangles flipped.
std::size_t orient_triangles(const std::vector<Vec2>& points, std::vector<Triangle>& triangles);

// Fills mesh.segments/segment_is_boundary from user segments (or the boundary
// edges when `segments` is empty): every boundary edge becomes a segment, boundary
// segments are oriented with the domain on the left, and a segment that is not an
// edge of the mesh throws Input_error. Also checks edge manifoldness (an edge of
// more than two triangles, or inconsistently oriented neighbours, throw).
void build_segments(Mesh_arrays& mesh, const std::vector<Edge>& segments);

// The tag of every segment of `segments` (either direction): the tag of the same
// edge among `tagged` (with `tags`), 0 where it is not among them.
std::vector<std::int64_t> tags_of_segments(const std::vector<Edge>& segments, const std::vector<Edge>& tagged,
                                           const std::vector<std::int64_t>& tags);

// Whether a chain of segments u - p - w runs straight through p: u and w lie on
// opposite sides of p and p is on the line uw up to rounding, kStraightUlps units
// in the last place of the largest coordinate (points placed on a segment as
// a + t (b - a) are off its line by an ulp or two; exact collinearity would make
// every such point a corner). Decides which points are corners, in Mesh() and in
// every step alike.
constexpr double kStraightUlps = 32;
bool runs_straight_through(const Vec2& u, const Vec2& p, const Vec2& w);

// Kinds for a user mesh: corner (a segment end, a vertex where segments meet
// other than two, where an interior constraint meets the boundary, where the
// segment tag changes, a required point on segments, or where the chain does not
// run straight through: runs_straight_through), boundary (other points on
// segments), original (interior).
std::vector<Point_kind> classify_points(const Mesh_arrays& mesh);

// Small geometric helpers shared by point location (here and parent_map.cpp).
// Distance from q to the segment ab.
double distance_to_segment(const Vec2& q, const Vec2& a, const Vec2& b);
// Distance from q to the counter-clockwise triangle t of `points` (0 inside or on
// it; which sides q is beyond is decided by exact orientation tests).
double distance_to_triangle(const std::vector<Vec2>& points, const Triangle& t, const Vec2& q);
// Barycentric coordinates of q in triangle t (they sum to 1; negative outside).
std::array<double, 3> barycentric_coordinates(const std::vector<Vec2>& points, const Triangle& t, const Vec2& q);
// How far rounding can put a point from the boundary it lies on: a few units of
// rounding, plus a straight chain's tolerance (kStraightUlps), of `reach`, the
// largest coordinate involved.
double boundary_rounding(double reach);

// Point location: for each query, the index of a triangle containing it (or -1)
// and its barycentric coordinates in that triangle.
void locate_points(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                   const std::vector<Vec2>& queries, std::vector<Index>& triangle_out,
                   std::vector<std::array<double, 3>>& barycentric_out);

}  // namespace evomesh
