// Chains of segments between corners (Section 3.2): the corners a step always
// keeps, and the constraint pieces between the points it keeps along them.
// Shared by FRFC and DRFC.
#pragma once

#include <cstdint>
#include <vector>

#include "evomesh/triangulation.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// Maximal chains of segments between corners, in order, for building constraint pieces.
struct Segment_chain {
  std::vector<Index> vertices;  // v0 .. vk along the chain
  std::vector<Index> segments;  // segment index of (v_i, v_{i+1})
  std::vector<std::uint8_t> forward;  // segment k is traversed a -> b
  bool closed = false;
  bool boundary = true;
  std::int64_t tag = 0;  // the tag of its segments (a tag change ends a chain)
};
std::vector<Segment_chain> segment_chains(const Mesh_arrays& mesh);

// Points always kept (forced in the packing): corners and both ends of every chain
// (kForcedCorner), and required points off the segments (kForcedRequired, they
// keep their kind). `required` is aligned with mesh.points (empty: none).
// `n_forced` receives their number.
constexpr std::uint8_t kForcedCorner = 1;
constexpr std::uint8_t kForcedRequired = 2;
std::vector<std::uint8_t> forced_corners(const Mesh_arrays& mesh, const std::vector<Segment_chain>& chains,
                                         std::size_t& n_forced, const std::vector<std::uint8_t>& required = {});

// Constraint pieces between consecutive kept points along every chain. A chain
// vertex v is kept when out_vertex[v] >= 0 (its output index). New points
// strictly inside segment s, sorted from its first to its second end, are
// out_on_segment[segment_begin[s] .. segment_begin[s + 1]) (-1: not kept);
// segment_begin empty: none. Boundary pieces have the domain on their left.
// `spans` (if given) receives, for every piece, the chain vertices strictly
// between its ends (all of them not kept).
struct Piece_span {
  Index chain;
  Index first;  // chains[chain].vertices[first .. last)
  Index last;
};
std::vector<Constraint_piece> constraint_pieces(const std::vector<Segment_chain>& chains,
                                                const std::vector<Index>& out_vertex,
                                                const std::vector<Index>& segment_begin = {},
                                                const std::vector<Index>& out_on_segment = {},
                                                std::vector<Piece_span>* spans = nullptr);

}  // namespace evomesh
