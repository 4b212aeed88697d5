#include "evomesh/segment_chains.hpp"

#include "evomesh/global_ids.hpp"

#include <stdexcept>
#include <utility>

namespace evomesh {

std::vector<Segment_chain> segment_chains(const Mesh_arrays& mesh) {
  const std::size_t n = mesh.points.size();
  const std::size_t k = mesh.segments.size();
  // Segments incident to each vertex (compressed lists: xadj/adj).
  std::vector<Index> xadj(n + 1, 0), adj(2 * k);
  for (const auto& e : mesh.segments) {
    ++xadj[e[0] + 1];
    ++xadj[e[1] + 1];
  }
  for (std::size_t v = 0; v < n; ++v) xadj[v + 1] += xadj[v];
  {
    std::vector<Index> fill(xadj.begin(), xadj.end() - 1);
    // (in the order of the segments' keys, and below the corners in the order
    // of their ids: every chain starts at the same end whatever the array order)
    const std::vector<Index> by_key = order_by_ids(mesh.segment_keys);
    for (std::size_t r = 0; r < k; ++r) {
      const std::size_t s = visit(by_key, r);
      adj[fill[mesh.segments[s][0]]++] = static_cast<Index>(s);
      adj[fill[mesh.segments[s][1]]++] = static_cast<Index>(s);
    }
  }
  // Chains end at corners: those of the geometry (classify_points, whatever the
  // kinds say) and points labelled corner. So every closed loop has a corner,
  // and a kind that calls a turning point "boundary" cannot straighten the
  // boundary through it.
  const std::vector<Point_kind> geometric = classify_points(mesh);
  std::vector<std::uint8_t> is_corner(n, 0);
  for (std::size_t v = 0; v < n; ++v) {
    is_corner[v] = geometric[v] == Point_kind::corner || (xadj[v + 1] > xadj[v] && mesh.kind[v] == Point_kind::corner);
  }
  std::vector<std::uint8_t> used(k, 0);
  std::vector<Segment_chain> chains;
  auto walk = [&](Index start, Index first_segment) {
    Segment_chain chain;
    chain.boundary = mesh.segment_is_boundary[first_segment] != 0;
    chain.tag = mesh.segment_tags.empty() ? 0 : mesh.segment_tags[first_segment];
    Index v = start, s = first_segment;
    chain.vertices.push_back(v);
    while (true) {
      used[s] = 1;
      const Edge& e = mesh.segments[s];
      const bool forward = e[0] == v;
      const Index w = forward ? e[1] : e[0];
      chain.segments.push_back(s);
      chain.forward.push_back(forward);
      if (w == start) {
        chain.closed = true;
        break;
      }
      chain.vertices.push_back(w);
      if (is_corner[w]) break;
      const Index s0 = adj[xadj[w]], s1 = adj[xadj[w] + 1];
      s = s0 == s ? s1 : s0;
      v = w;
      if (used[s]) break;
    }
    chains.push_back(std::move(chain));
  };
  const std::vector<Index> by_id = order_by_ids(mesh.point_gids);
  for (std::size_t r = 0; r < n; ++r) {
    const std::size_t v = visit(by_id, r);
    if (!is_corner[v]) continue;
    for (Index a = xadj[v]; a < xadj[v + 1]; ++a) {
      if (!used[adj[a]]) walk(static_cast<Index>(v), adj[a]);
    }
  }
  for (std::size_t s = 0; s < k; ++s) {
    if (!used[s]) throw std::logic_error("segment_chains: a loop of segments without a corner");
  }
  return chains;
}

std::vector<std::uint8_t> forced_corners(const Mesh_arrays& mesh, const std::vector<Segment_chain>& chains,
                                         std::size_t& n_forced, const std::vector<std::uint8_t>& required) {
  const std::size_t n = mesh.points.size();
  std::vector<std::uint8_t> forced(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    if (mesh.kind[i] == Point_kind::corner) forced[i] = kForcedCorner;
    else if (!required.empty() && required[i]) forced[i] = kForcedRequired;
  }
  for (const auto& chain : chains) {
    forced[chain.vertices.front()] = kForcedCorner;
    forced[chain.vertices.back()] = kForcedCorner;
  }
  n_forced = 0;
  for (std::uint8_t f : forced) n_forced += f != 0;
  return forced;
}

std::vector<Constraint_piece> constraint_pieces(const std::vector<Segment_chain>& chains,
                                                const std::vector<Index>& out_vertex,
                                                const std::vector<Index>& segment_begin,
                                                const std::vector<Index>& out_on_segment,
                                                std::vector<Piece_span>* spans) {
  std::vector<Constraint_piece> pieces;
  std::vector<Index> along;
  // Where each kept point lies along the chain: 2k at vertex k, 2k + 1 inside segment k.
  std::vector<Index> at;
  Index here = 0;
  auto add = [&](Index out) {
    if (out < 0) return;
    along.push_back(out);
    at.push_back(here);
  };
  if (spans) spans->clear();
  for (std::size_t c = 0; c < chains.size(); ++c) {
    const Segment_chain& chain = chains[c];
    along.clear();
    at.clear();
    for (std::size_t k = 0; k < chain.segments.size(); ++k) {
      here = static_cast<Index>(2 * k);
      add(out_vertex[chain.vertices[k]]);
      if (segment_begin.empty()) continue;
      here = static_cast<Index>(2 * k + 1);
      const Index s = chain.segments[k];
      const Index b = segment_begin[s], e = segment_begin[s + 1];
      if (chain.forward[k]) {
        for (Index j = b; j < e; ++j) add(out_on_segment[j]);
      } else {
        for (Index j = e; j-- > b;) add(out_on_segment[j]);
      }
    }
    here = static_cast<Index>(2 * chain.segments.size());
    if (chain.closed) {
      along.push_back(along.front());
      at.push_back(here);
    } else {
      add(out_vertex[chain.vertices.back()]);
    }
    // All segments of a boundary chain are oriented alike (domain on the left).
    const bool flip = chain.boundary && !chain.forward.front();
    for (std::size_t k = 0; k + 1 < along.size(); ++k) {
      Constraint_piece piece{along[k], along[k + 1], chain.boundary, chain.tag};
      if (flip) std::swap(piece.a, piece.b);
      pieces.push_back(piece);
      // the vertices i with at[k] < 2 i < at[k + 1]
      if (spans) spans->push_back({static_cast<Index>(c), at[k] / 2 + 1, (at[k + 1] + 1) / 2});
    }
  }
  return pieces;
}

}  // namespace evomesh
