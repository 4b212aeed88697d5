// Where every point of an evolved mesh lies in the mesh it was evolved from (the
// step's parent map), so fields move from the old mesh to the new one without a
// global point location, and an intersection of the two meshes stays local.
#pragma once

#include <array>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

struct Parent_map {
  // Per new point: the old triangle containing it, -1 for a kept point (its old
  // index is the step's origin) and for a point that no old triangle contains.
  std::vector<Index> triangle;
  // The barycentric coordinates of the point in that triangle (with respect to its
  // vertices in order; they sum to 1, and reproduce linear functions exactly).
  // A point outside the old domain by rounding gets its boundary triangle, with a
  // coordinate negative by rounding.
  std::vector<std::array<double, 3>> barycentric;
  std::size_t n_walk_steps = 0;        // triangles crossed by all walks
  std::size_t n_located_globally = 0;  // points a walk did not reach (located by a search)
};

// The parent map of `new_mesh` in `old_mesh`; origin[i] is the old index of new
// point i or -1. Points are located in breadth-first order over the new mesh's
// edges, from the kept points: each walk starts in the old triangle of a new
// neighbour already placed, a few triangles away (a visibility walk with exact
// orientation tests). Points a walk cannot reach (across a hole, or a walk longer
// than its bound) are located by a search over the whole old mesh. O(n) walks.
// `outside`: a step that moved boundary points onto curves (boundary_geometry.hpp)
// may put new points outside the old domain by up to this much; they are
// located in the nearest boundary triangle (with a negative coordinate). 0: by
// rounding only.
Parent_map parent_map(const Mesh_arrays& old_mesh, const Mesh_arrays& new_mesh, const std::vector<Index>& origin,
                      double outside = 0);

// The input's labels on the new mesh, through the parent map (no global search):
// every new triangle gets the tag of the input triangle containing its centroid
// (region borders are constraints, so it lies in one region), every new segment
// the tag of the input segment it lies on (a tag change is a corner, kept by every
// step, so a chain of segments has one tag), every kept point its `required` flag.
// Labels the input does not have stay empty.
void carry_tags(const Mesh_arrays& old_mesh, const std::vector<Index>& origin, const Parent_map& parents,
                Mesh_arrays& new_mesh, double outside = 0);

}  // namespace evomesh
