// The triangles around each point of a mesh, as compressed lists: used by the
// sampling (ring candidates), the spacing repair, mesh walks and the walker of
// the old mesh (parent map), which takes over the step's copy.
#pragma once

#include <cstdint>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

// The triangles around point v are adj[xadj[v]], ..., adj[xadj[v + 1] - 1], in
// increasing order of their global ids (Mesh_arrays::triangle_gids; without
// them, increasing order). (4-byte offsets and triangle numbers: 28 bytes a point
// instead of 56; the constructor refuses a mesh with 3 m >= 2^32.)
struct Triangle_fans {
  std::vector<std::uint32_t> xadj, adj;
  explicit Triangle_fans(const Mesh_arrays& mesh);
};

}  // namespace evomesh
