// Geometry-aware spacing: the spacing of a mesh measured within its
// domain, and the spacing its domain can carry.
//
// nn_M(p) of the paper is the distance to the nearest other mesh point, which
// may lie across a slit or a thin wall, outside the domain: a wall point of a
// slit 1e-4 wide then asks for spacing 1e-4 along the whole slit. Within the
// domain, the nearest point is the nearest one visible from p without crossing
// a constraint; for a constrained Delaunay triangulation (every mesh a step
// makes) it is an edge neighbour of p, so domain_nn_spacing is p's shortest
// edge. Conversely, a thin channel carries no spacing wider than itself:
// local_feature_size caps the spacing at the distance across the domain to a
// facing, non-adjacent chain of segments.
#pragma once

#include <array>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "evomesh/segment_chains.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// nn (the Euclidean nearest-neighbour distances) made nn within the domain: where
// a point's shortest edge is longer than nn beyond rounding, its nearest point is
// not an edge neighbour (in a constrained Delaunay triangulation: hidden behind
// a constraint) and nn becomes that edge's length. Returns which points changed.
// O(m). `known` (optional, one flag per point): points whose answer is known to
// be "unchanged" (a changed-region step's kept points whose fan and nn are the
// input's, where nn did not grow): left as they are, and only the edges at the
// others are measured (the same arithmetic and edge order, so the same bits).
std::vector<std::uint8_t> keep_within_domain(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                                             std::vector<double>& nn,
                                             const std::vector<std::uint8_t>* known = nullptr);

// An upper bound on the spacing the domain carries at every point, +infinity
// where nothing is found below `limit[v]` (the spacing asked for there):
// - at a point inside a chain of segments, the distance along its normal,
//   through the triangles (towards the domain, both ways for an interior
//   constraint), to the first segment of a chain that neither is its own chain
//   nor shares a corner with it (Ruppert's local feature size, measured through
//   the domain: a channel's walls face each other, a slit's do not); an interior
//   chain (an interface) also counts its own segments, so a fold of one curve
//   (a thin filament) is as narrow as a strip between two;
// - at a corner, the length of its shortest straight chain (two corners are
//   features of their own: the tip of a slit is as wide as the slit);
// - with a boundary geometry, at a point of a curved chain, the spacing at which
//   a piece turns by corner_angle (the polygon's turn and edge lengths there), so
//   a curve never loses the points it needs to stay a curve.
// Walks stop beyond limit[v], so the cost is O(sum of limit / local edge length)
// over the points on segments.
std::vector<double> local_feature_size(const Mesh_arrays& mesh, const std::vector<Segment_chain>& chains,
                                       const std::vector<double>& limit);

// A point inside a chain of segments, as the walks of local_feature_size see it.
// On a chain of a curved tag (boundary_geometry.hpp), the spacing at which a
// piece through u, p, w turns by the geometry's corner angle: a piece of length
// L turns by about L turn / (edge length) here; half of it, as a packing of
// spacing f leaves gaps up to about 2 f. +inf where the chain runs straight.
double curve_turn_cap(const Vec2& u, const Vec2& p, const Vec2& w, double corner_angle);

struct Chain_point {
  Index v = 0, u = 0, w = 0;  // the point, and its neighbours along the chain
  bool along = true;          // the segment (v, w) is stored v -> w
  bool two_sided = false;     // an interior constraint: walk both ways
};

// The walks of local_feature_size on a part of a mesh (a rank's triangles plus
// those its walks may cross; docs/distributed-step.md 3.1). Chains are named by
// global ids: `chain_of_segment` per segment of `part` (-1: none), `chain_of_point`
// per query; two chains are adjacent when equal or when they share an end corner
// (`ends`: chain id -> the global ids of its two end corners). Returns, per query,
// the distance local_feature_size finds by its walks (an interior chain counts
// its own segments, as there) (+inf: nothing below
// limit[k]; NaN: the chain neighbours coincide, no tangent), and clears
// certified[k] where a walk reached the part's border, where the whole mesh's
// answer needs more triangles. Not included: the curved term and the corners'
// rule, which read the chain only. Triangle_fans order by part.triangle_gids, so
// with the whole mesh's triangle ids the walks are the whole mesh's.
std::vector<double> chain_feature_sizes(const Mesh_arrays& part, const std::vector<Chain_point>& points,
                                        const std::vector<std::int64_t>& chain_of_point,
                                        const std::vector<std::int64_t>& chain_of_segment,
                                        const std::unordered_map<std::int64_t, std::array<std::int64_t, 2>>& ends,
                                        const std::vector<double>& limit, std::vector<std::uint8_t>& certified);

}  // namespace evomesh
