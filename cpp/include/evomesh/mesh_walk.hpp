// Walks through the triangles of a mesh along straight lines, from one of its
// points: local queries (a ray's first constraint, the triangle a nearby point
// lies in as seen from a vertex) with no global point location.
#pragma once

#include <cstdint>
#include <unordered_map>
#include <utility>

#include "evomesh/candidates.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// The triangles around each point (Triangle_fans, borrowed) and the segments by
// their end points: enough to cross edges, with no global sort of half-edges.
class Mesh_walk {
 public:
  Mesh_walk(const Mesh_arrays& mesh, const Triangle_fans& fans);

  // The triangle other than t on edge (a, b), -1 if none.
  Index across(Index t, Index a, Index b) const;

  // From point v along direction d (unit), through the triangles: the first
  // segment crossed and the distance to it, or (-1, inf) beyond `limit`
  // (floating point: an estimate, for feature sizes). `left` (optional) is set
  // when the walk ends at an edge with one triangle that is no segment: on a
  // whole mesh that edge does not exist (boundary edges are segments); on a part
  // of a mesh it is the part's border, and the answer is not the whole mesh's.
  std::pair<Index, double> cast(Index v, const Vec2& d, double limit, bool* left = nullptr) const;

  // The triangle that contains x strictly inside, reached from point v along
  // the straight line v -> x without crossing a segment or the boundary, or -1
  // (x outside the domain, behind a constraint, on an edge or a vertex seen from
  // v, or more than `max_steps` triangles away). Exact orientation predicates.
  // `left` (optional) is set when the walk ends at an edge with one triangle
  // that is no segment: the border of a part of a mesh (see cast).
  Index locate_from(Index v, const Vec2& x, int max_steps = 64, bool* left = nullptr) const;

 private:
  static std::uint64_t key(Index a, Index b) {
    return (static_cast<std::uint64_t>(std::min(a, b)) << 32) ^ static_cast<std::uint64_t>(std::max(a, b));
  }
  bool is_segment(Index a, Index b) const { return segment_of_edge_.count(key(a, b)) > 0; }

  const Mesh_arrays& mesh_;
  const Triangle_fans& fans_;
  std::unordered_map<std::uint64_t, Index> segment_of_edge_;
};

}  // namespace evomesh
