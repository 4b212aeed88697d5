// A local supermesh of two tetrahedral meshes of the same domain: every pair
// (new tetrahedron t, old tetrahedron s) whose intersection has positive
// volume, with that volume. The conservative (P0) transfer of per-tetrahedron
// fields divides by these volumes (evomesh.transfer_cells).
//
// No global search, as in 2-D (supermesh.hpp): the old tetrahedra overlapping
// t are found by a flood fill over old face adjacency, seeded with an old
// tetrahedron at each vertex of t (for a kept vertex one incident to its old
// index, for a new vertex its parent tetrahedron from the step's lineage). The
// fill crosses every old tetrahedron whose bounding box overlaps t's (slightly
// enlarged) box: the old tetrahedra that meet t's interior are face-connected
// through such tetrahedra (a path inside t crosses only their faces), and the
// whole old star of a kept vertex overlaps t's box, so every one is reached.
//
// A new tetrahedron whose four kept vertices have origins forming an old
// tetrahedron is that tetrahedron (kept points keep their coordinates bit for
// bit): its one pair is written directly with its own volume, without the fill
// or the clipping. Every other pair is s clipped by the four planes of t
// (each clip splits a tetrahedron into at most three), measured by summing
// the pieces' volumes: exact up to the rounding of the cut points.
// Pure C++: no pybind11 here.
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "evomesh/tet/tet_step.hpp"
#include "evomesh/types.hpp"

namespace evomesh::tet {

struct Tet_supermesh {
  // CSR by new tetrahedron: pairs offsets[t] .. offsets[t+1] - 1 belong to t.
  std::vector<Index> offsets;
  std::vector<Index> old_tet;  // per pair
  std::vector<double> volume;  // per pair: |t n s| > 0
  std::size_t identical = 0;   // new tetrahedra that are old ones (one pair each, no clipping)
};

// Volume of the intersection of two tetrahedra (any orientation). For the tests.
double tet_intersection_volume(const std::array<Vec3, 4>& t, const std::array<Vec3, 4>& s);

// The supermesh of new_tets over old_tets. origin[v] is the old index of a kept
// new point v (-1: new), parent_tet[v] an old tetrahedron holding a new point
// (-1: unknown); kept points must have their origin's coordinates. Every new
// tetrahedron needs a vertex with a seed (Input_error otherwise). Parallel over
// fixed blocks of new tetrahedra on `threads` threads (0: the default); the
// result does not depend on the thread count.
Tet_supermesh build_tet_supermesh(const std::vector<Vec3>& old_points, const std::vector<Tet>& old_tets,
                                  const std::vector<Vec3>& new_points, const std::vector<Tet>& new_tets,
                                  const std::vector<Index>& origin, const std::vector<Index>& parent_tet,
                                  int threads = 0);

}  // namespace evomesh::tet
