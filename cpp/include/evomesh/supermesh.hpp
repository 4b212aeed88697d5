// A local supermesh of two meshes of the same domain (issue 12): every pair
// (new triangle t, old triangle s) whose intersection has positive area, with
// that area and the exact mixed mass entries  int_{t n s} phi_a^new phi_b^old.
//
// No global search: the old triangles overlapping t are found by a flood fill
// over old edge adjacency, seeded with an old triangle at each vertex of t (for
// a kept vertex one incident to its old index, for a new vertex its parent
// triangle from the step's lineage). The fill crosses every old triangle whose
// bounding box overlaps t's (slightly enlarged) box, so it reaches every old
// triangle that intersects t even across zero-area contacts.
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

struct Supermesh {
  // CSR by new triangle: pairs offsets[t] .. offsets[t+1] - 1 belong to new triangle t.
  std::vector<Index> offsets;
  std::vector<Index> old_triangle;  // per pair
  std::vector<double> area;         // per pair: |t n s| (shoelace of the clipped polygon)
  // per pair (only when mass was requested): mass[9 k + 3 a + b] =
  // int_{t n s} phi^new_{t[a]} phi^old_{s[b]} (vertex order of the input triangles).
  std::vector<double> mass;
};

// Area of the intersection of two triangles (any orientation), by
// Sutherland-Hodgman clipping of s against the three edges of t and the
// shoelace formula. Exposed for the tests.
double triangle_intersection_area(const std::array<Vec2, 3>& t, const std::array<Vec2, 3>& s);

// The supermesh of new_triangles over old_triangles. seed[v] is an old triangle
// touching new point v, or -1 when unknown; every new triangle needs at least
// one vertex with a seed (Input_error otherwise). Triangles must be
// counter-clockwise. Parallel over fixed blocks of new triangles on `threads`
// threads (0: the default); the result does not depend on the thread count.
Supermesh build_supermesh(const std::vector<Vec2>& old_points, const std::vector<Triangle>& old_triangles,
                          const std::vector<Vec2>& new_points, const std::vector<Triangle>& new_triangles,
                          const std::vector<Index>& seed, bool with_mass, int threads = 0);

// seed for build_supermesh from an evolve step: origin[v] >= 0 (kept point) gives
// an old triangle incident to old point origin[v]; otherwise parent_triangle[v].
std::vector<Index> supermesh_seeds(std::size_t n_old_points, const std::vector<Triangle>& old_triangles,
                                   const std::vector<Index>& origin, const std::vector<Index>& parent_triangle);

}  // namespace evomesh
