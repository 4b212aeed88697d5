// The triangulation of a mesh's points after a Lagrangian motion.
//
// A displacement moves every point of a mesh, boundary and interface points
// included. Where the moved triangles fold (a triangle turned over or flat),
// the folded region is remeshed: the constrained Delaunay triangulation of the
// moved points with the moved constraint segments (boundary, interfaces, region
// borders) as constraints. Each segment knows the region tag on either side of
// it in the old mesh; the regions of the new triangulation are flood-filled
// from those sides, so a region keeps its tag when its border moves.
//
// The function reports what keeps the result from being a mesh (a point left
// outside the moved domain, a point lying on a segment, two segments crossing,
// a region reached from sides of different tags) instead of throwing, so the
// caller (python/evomesh/motion.py) can drop the points it may drop and name
// the others in its message.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

// A constraint segment a -> b of the moved mesh. `left` is the region tag on
// its left in the old mesh, `right` the tag on its right (ignored for a
// boundary piece: the outside is there).
struct Moved_piece {
  Index a;
  Index b;
  bool boundary;
  std::int64_t left = 0;
  std::int64_t right = 0;
};

struct Moved_triangulation {
  // Counter-clockwise triangles inside the domain the pieces bound, and the
  // region tag of each (empty when `crossing` >= 0).
  std::vector<Triangle> triangles;
  std::vector<std::int64_t> triangle_tags;
  // Points in no triangle of the domain (outside the moved domain), increasing.
  std::vector<Index> unused;
  // (point, piece): the point lies in the interior of the piece, which the
  // triangulation splits there.
  std::vector<std::array<Index, 2>> on_piece;
  // The first piece whose side the region fill reached with another label
  // (another region's tag, or the outside), -1 for none.
  Index conflict = -1;
  // The piece whose insertion crossed an earlier piece, -1 for none.
  Index crossing = -1;
};

// Constrained Delaunay triangulation of `points` (distinct; Input_error
// otherwise) with `pieces` as constraints, its domain and regions labelled from
// the pieces' sides. Exact predicates throughout (CGAL); O(n log n).
Moved_triangulation triangulate_moved(const std::vector<Vec2>& points, const std::vector<Moved_piece>& pieces);

}  // namespace evomesh
