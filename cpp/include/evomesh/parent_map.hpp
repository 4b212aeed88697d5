// Where every point of an evolved mesh lies in the mesh it was evolved from (the
// step's parent map), so fields move from the old mesh to the new one without a
// global point location, and an intersection of the two meshes stays local.
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "evomesh/triangle_fans.hpp"
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

// Point location in the mesh a step starts from (the old mesh), by visibility
// walks over its triangles: built once per step (finish_step) for the parent
// map and carry_tags. Keeps a reference to the mesh.
class Old_mesh_walker {
 public:
  // `outside`: a step that moved boundary points onto curves (boundary_geometry.hpp)
  // may put new points outside the old domain by up to this much; they are
  // located in the nearest boundary triangle (with a negative coordinate). 0: by
  // rounding only.
  explicit Old_mesh_walker(const Mesh_arrays& old_mesh, double outside = 0);
  // With the fans of old_mesh already built (a step's, which it no longer needs).
  Old_mesh_walker(const Mesh_arrays& old_mesh, Triangle_fans fans, double outside = 0);

  const Mesh_arrays& mesh() const { return mesh_; }
  // The `outside` of the constructor, when known only after construction.
  void set_outside(double outside) { outside_ = outside; }

  // One old triangle at old point v (the last around it; -1 for a point of no triangle).
  Index triangle_at(Index v) const {
    return fans_.xadj[v] == fans_.xadj[v + 1] ? -1 : static_cast<Index>(fans_.adj[fans_.xadj[v + 1] - 1]);
  }

  // Visibility walk from triangle t towards q: cross an edge that has q strictly
  // on its outer side (the first in a rotating order, so that walks do not
  // cycle); stop in a triangle that has q on no outer side (q inside or on it),
  // or at a boundary edge with q beyond it by rounding (q outside the old domain
  // as far as a step that kept the domain can put it). Blocked by the boundary
  // of a non-convex domain, or longer than a bound, it searches instead (-1 when
  // that fails too). `steps` counts the triangles crossed.
  Index walk(Index t, const Vec2& q, std::size_t salt, std::size_t& steps) const;

  // Best-first search over the old triangles from t, nearest to q first: the
  // first within rounding of q, or -1 after a budget of triangles. Finds q
  // around holes and re-entrant corners, where a walk is blocked.
  Index search(Index t, const Vec2& q) const;

  // The triangle across edge k (t[k] -> t[k + 1]) of t, -1 on the boundary.
  Index across(Index t, int k) const;
  // Calls visit(t) for every old triangle t at old point v.
  template <class Visit>
  void for_each_triangle_at(Index v, Visit visit) const {
    for (auto f = fans_.xadj[v]; f < fans_.xadj[v + 1]; ++f) visit(static_cast<Index>(fans_.adj[f]));
  }

 private:
  double outside_;
  const Mesh_arrays& mesh_;
  const std::vector<Vec2>& P_;
  const std::vector<Triangle>& T_;
  Triangle_fans fans_;                                   // the triangles around each old point
  std::size_t limit_;                                    // of a walk's steps
};

// The parent map of `new_mesh` in the old mesh; origin[i] is the old index of new
// point i or -1. Points are located in rounds over the new mesh's edges, from
// the kept points: each walk starts in the old triangle of a new neighbour
// placed in an earlier round (the one of least index), a few triangles away (a
// visibility walk with exact orientation tests); the walks of a round run in
// parallel, and the map does not depend on the thread count. Points a walk
// cannot reach (across a hole, or a walk longer than its bound) are located by
// a search over the whole old mesh. O(n) walks. (A point strictly inside an old
// triangle gets that triangle from any walk; one on an old edge or vertex gets
// one of the triangles there.)
Parent_map parent_map(const Old_mesh_walker& old_mesh, const Mesh_arrays& new_mesh, const std::vector<Index>& origin);

// The input's labels on the new mesh, through the parent map (no global search):
// every new triangle gets the tag of the input triangle containing its centroid
// (region borders are constraints, so it lies in one region), every new segment
// the tag of the input segment it lies on (a tag change is a corner, kept by every
// step, so a chain of segments has one tag), every kept point its `required` flag.
// Labels the input does not have stay empty.
void carry_tags(const Old_mesh_walker& old_mesh, const std::vector<Index>& origin, const Parent_map& parents,
                Mesh_arrays& new_mesh);

}  // namespace evomesh
