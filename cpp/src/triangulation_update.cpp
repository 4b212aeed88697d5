#include "evomesh/triangulation_update.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <unordered_map>
#include <unordered_set>
#include <utility>

#include "evomesh/kernel.hpp"
#include "evomesh/nd/hilbert_order.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/triangulation.hpp"

namespace evomesh {

namespace {

enum Declined : int { kUpdated = 0, kOrigins = 1, kNotLocated = 2, kTooLarge = 3, kFlood = 4, kMissing = 5, kNotDelaunay = 6 };

std::uint64_t edge_key(Index a, Index b) {
  const auto lo = static_cast<std::uint64_t>(std::min(a, b)), hi = static_cast<std::uint64_t>(std::max(a, b));
  return (lo << 32) | hi;
}

// > 0: d strictly inside the circle through the counter-clockwise a, b, c; 0 on it; < 0 outside (exact).
int in_circle(const Vec2& a, const Vec2& b, const Vec2& c, const Vec2& d) {
  return static_cast<int>(CGAL::side_of_oriented_circle(to_cgal(a), to_cgal(b), to_cgal(c), to_cgal(d)));
}

}  // namespace

std::optional<std::vector<Triangle>> updated_constrained_delaunay(const Old_mesh_walker& old_mesh,
                                                                  const std::vector<Vec2>& points,
                                                                  const std::vector<Constraint_piece>& pieces,
                                                                  const std::vector<Index>& origin,
                                                                  double max_cavity_share,
                                                                  Triangulation_update_report& report,
                                                                  std::vector<std::uint8_t>* same_fan) {
  const Mesh_arrays& input = old_mesh.mesh();
  const std::vector<Vec2>& P = input.points;
  const std::vector<Triangle>& T = input.triangles;
  const std::size_t n_in = P.size(), m_in = T.size(), n = points.size();
  using Clock = std::chrono::steady_clock;
  auto lap = [last = Clock::now()](double& seconds) mutable {
    const auto now = Clock::now();
    seconds += std::chrono::duration<double>(now - last).count();
    last = now;
  };
  auto decline = [&report](int why) -> std::optional<std::vector<Triangle>> {
    report.declined = why;
    return std::nullopt;
  };
  if (origin.size() != n || m_in == 0 || n < 3) return decline(kOrigins);

  // 1. Output index of every input point (-1: dropped); kept points unmoved.
  std::vector<Index> new_of(n_in, -1);
  std::vector<Index> fresh;  // output indices of the new points
  for (std::size_t j = 0; j < n; ++j) {
    const Index o = origin[j];
    if (o < 0) {
      fresh.push_back(static_cast<Index>(j));
      continue;
    }
    if (static_cast<std::size_t>(o) >= n_in || new_of[o] >= 0 || points[j] != P[o]) return decline(kOrigins);
    new_of[o] = static_cast<Index>(j);
  }

  // 2. The cavity: input triangles with a dropped vertex, and every triangle
  // whose closed circumdisc holds a new point, found by a search from the new
  // point's triangle across edges that are not input segments (the conflict
  // zone of an insertion into a constrained Delaunay triangulation is connected
  // that way) and across an edge the point lies on (a segment it splits).
  std::vector<std::uint8_t> cavity(m_in, 0);
  for (std::size_t t = 0; t < m_in; ++t) {
    for (Index v : T[t]) cavity[t] |= new_of[v] < 0;
  }
  // Input segments as a mask per triangle (bit k: its edge t[k] -> t[k + 1] is one).
  std::vector<std::uint8_t> segment_mask(m_in, 0);
  for (const Edge& e : input.segments) {
    old_mesh.for_each_triangle_at(e[0], [&](Index u) {
      for (int k = 0; k < 3; ++k) {
        const Index a = T[u][k], b = T[u][(k + 1) % 3];
        if ((a == e[0] && b == e[1]) || (a == e[1] && b == e[0])) segment_mask[u] |= static_cast<std::uint8_t>(1u << k);
      }
    });
  }
  std::vector<Vec2> fresh_points(fresh.size());
  for (std::size_t k = 0; k < fresh.size(); ++k) fresh_points[k] = points[fresh[k]];
  const std::vector<std::uint32_t> order = nd::hilbert_grid_permutation<2>(fresh_points.data(), fresh_points.size());
  std::vector<Index> stack;
  std::vector<Index> seen_at(m_in, -1);  // the new point (position in `order`) that last visited a triangle
  Index at = old_mesh.triangle_at(T[0][0]);
  for (std::size_t r = 0; r < order.size(); ++r) {
    const Vec2& x = fresh_points[order[r]];
    std::size_t steps = 0;
    const Index start = old_mesh.walk(at, x, r, steps);
    if (start < 0) return decline(kNotLocated);
    at = start;
    stack.assign(1, start);
    seen_at[start] = static_cast<Index>(r);
    while (!stack.empty()) {
      const Index t = stack.back();
      stack.pop_back();
      cavity[t] = 1;
      const Triangle& tri = T[t];
      for (int k = 0; k < 3; ++k) {
        const Index u = old_mesh.across(t, k);
        if (u < 0 || seen_at[u] == static_cast<Index>(r)) continue;
        const Index a = tri[k], b = tri[(k + 1) % 3];
        const bool on_edge = orientation(P[a], P[b], x) == 0 && t == start;
        if (!on_edge && (segment_mask[t] >> k & 1)) continue;
        const Triangle& other = T[u];
        if (!on_edge && in_circle(P[other[0]], P[other[1]], P[other[2]], x) < 0) continue;
        seen_at[u] = static_cast<Index>(r);
        stack.push_back(u);
      }
    }
  }
  seen_at = std::vector<Index>();
  std::size_t n_cavity = 0;
  for (std::uint8_t c : cavity) n_cavity += c;
  report.n_cavity_triangles = n_cavity;
  lap(report.locate_seconds);
  if (static_cast<double>(n_cavity) > max_cavity_share * static_cast<double>(m_in)) return decline(kTooLarge);

  // 3. The cavity's points (local indices) and constraints: its boundary edges
  // (a kept triangle on the right, the cavity on the left), and the pieces
  // between cavity points that are not an edge of a kept triangle.
  std::vector<Index> local_of(n, -1);
  std::vector<Index> global_of;  // output index of every local point
  auto local = [&](Index j) {
    if (local_of[j] < 0) {
      local_of[j] = static_cast<Index>(global_of.size());
      global_of.push_back(j);
    }
    return local_of[j];
  };
  for (Index j : fresh) local(j);
  struct Boundary_edge {
    Index kept;  // the kept input triangle on its right
    int side;    // its edge there: T[kept][side] -> T[kept][side + 1]
  };
  std::vector<Boundary_edge> rim;
  for (std::size_t t = 0; t < m_in; ++t) {
    if (!cavity[t]) continue;
    for (int k = 0; k < 3; ++k) {
      const Index v = T[t][k];
      if (new_of[v] >= 0) local(new_of[v]);
      const Index u = old_mesh.across(static_cast<Index>(t), k);
      if (u < 0 || cavity[u]) continue;
      // (the kept side's edge runs the other way)
      const Index a = T[t][k], b = T[t][(k + 1) % 3];
      const Triangle& other = T[u];
      const int side = other[0] == b ? 0 : other[1] == b ? 1 : 2;
      if (other[(side + 1) % 3] != a) return decline(kFlood);
      rim.push_back({u, side});
    }
  }
  std::vector<Vec2> local_points(global_of.size());
  for (std::size_t l = 0; l < global_of.size(); ++l) local_points[l] = points[global_of[l]];
  report.n_cavity_points = local_points.size();
  // The output's pieces, as edges.
  std::unordered_set<std::uint64_t> piece_keys;
  piece_keys.reserve(2 * pieces.size());
  for (const auto& piece : pieces) piece_keys.insert(edge_key(piece.a, piece.b));
  std::vector<Constraint_piece> local_pieces;
  std::unordered_set<std::uint64_t> stops;  // local keys the flood does not cross: the cavity's and domain's borders
  for (const Boundary_edge& e : rim) {
    const Triangle& tri = T[e.kept];
    const Index a = local_of[new_of[tri[(e.side + 1) % 3]]], b = local_of[new_of[tri[e.side]]];
    local_pieces.push_back({a, b, true});
    stops.insert(edge_key(a, b));
  }
  std::vector<std::uint64_t> cavity_pieces;  // local keys of the pieces in the cavity
  // Whether input points ia and ib are the ends of an edge of a kept input triangle.
  const auto kept_edge_between = [&](Index ia, Index ib) {
    bool found = false;
    old_mesh.for_each_triangle_at(ia, [&](Index u) {
      const Triangle& tri = T[u];
      found = found || (!cavity[u] && (tri[0] == ib || tri[1] == ib || tri[2] == ib));
    });
    return found;
  };
  // The same for output points a and b.
  const auto kept_input_edge = [&](Index a, Index b) {
    return origin[a] >= 0 && origin[b] >= 0 && kept_edge_between(origin[a], origin[b]);
  };
  for (const auto& piece : pieces) {
    const Index a = local_of[piece.a], b = local_of[piece.b];
    if (a < 0 || b < 0) {
      // (away from the cavity a piece must be a kept triangle's edge already)
      if (!kept_input_edge(piece.a, piece.b)) return decline(kMissing);
      continue;
    }
    // An edge of a kept triangle: on the rim (a constraint already), or away
    // from the cavity (a segment between two cavity points that stayed).
    if (kept_input_edge(piece.a, piece.b)) continue;
    local_pieces.push_back({a, b, piece.boundary});
    cavity_pieces.push_back(edge_key(a, b));
    if (piece.boundary) stops.insert(edge_key(a, b));
  }

  // 4. The local triangulation; the cavity is what the rim's and the domain
  // boundary's inner sides reach without crossing them.
  const Local_triangulation lt = local_constrained_delaunay(local_points, local_pieces);
  const std::size_t n_faces = lt.triangles.size();
  // Whether edge k of face f (opposite corner k) is on the rim or the domain's boundary.
  const auto stop_edge = [&](std::size_t f, int k) {
    const Triangle& tri = lt.triangles[f];
    return (lt.constrained[f] >> k & 1) && stops.count(edge_key(tri[(k + 1) % 3], tri[(k + 2) % 3])) != 0;
  };
  std::vector<std::uint8_t> inside(n_faces, 0);
  std::vector<Index> flood;
  for (std::size_t f = 0; f < n_faces; ++f) {
    if (lt.seed[f] & 2) continue;
    if (lt.seed[f] & 1) {
      // (an interior piece seeds both of its sides: only the rim and the domain
      // boundary's left sides are the cavity's for sure)
      if (stop_edge(f, 0) || stop_edge(f, 1) || stop_edge(f, 2)) {
        inside[f] = 1;
        flood.push_back(static_cast<Index>(f));
      }
    }
  }
  while (!flood.empty()) {
    const Index f = flood.back();
    flood.pop_back();
    for (int k = 0; k < 3; ++k) {
      if (stop_edge(static_cast<std::size_t>(f), k)) continue;
      const Index g = lt.neighbour[f][k];
      if (g < 0 || (lt.seed[g] & 2)) return decline(kFlood);  // out of the hull, or out of the domain
      if (inside[g]) continue;
      inside[g] = 1;
      flood.push_back(g);
    }
  }

  lap(report.local_seconds);
  // 5. Certificates. Every rim edge and piece in the cavity is an edge of an
  // inside face, on the right side for the rim; faces inside that meet across
  // an edge that is not a piece are strictly Delaunay.
  std::unordered_map<std::uint64_t, std::pair<Index, int>> inside_edges;  // constrained: local key -> (face, k)
  std::size_t n_inside = 0;
  for (std::size_t f = 0; f < n_faces; ++f) {
    if (!inside[f]) continue;
    ++n_inside;
    const Triangle& tri = lt.triangles[f];
    for (int k = 0; k < 3; ++k) {
      const Index a = tri[(k + 1) % 3], b = tri[(k + 2) % 3];
      if (lt.constrained[f] >> k & 1) {  // (the rim and the domain boundary are constraints too)
        inside_edges[edge_key(a, b)] = {static_cast<Index>(f), k};
        continue;
      }
      const Index g = lt.neighbour[f][k];
      if (g < static_cast<Index>(f)) continue;  // each edge once (g inside: see the flood)
      const Triangle& o = lt.triangles[g];
      const Index d = o[0] != a && o[0] != b ? o[0] : o[1] != a && o[1] != b ? o[1] : o[2];
      if (in_circle(local_points[tri[0]], local_points[tri[1]], local_points[tri[2]], local_points[d]) >= 0) {
        return decline(kNotDelaunay);
      }
    }
  }
  for (const Boundary_edge& e : rim) {
    const Triangle& tri = T[e.kept];
    const Index ga = new_of[tri[(e.side + 1) % 3]], gb = new_of[tri[e.side]];
    const auto found = inside_edges.find(edge_key(local_of[ga], local_of[gb]));
    if (found == inside_edges.end()) return decline(kMissing);
    const auto [f, k] = found->second;
    const Triangle& face = lt.triangles[f];
    // the face must have it as (ga -> gb) (the cavity on its left), and its
    // third point outside the kept triangle's circle unless the edge is a piece
    if (global_of[face[(k + 1) % 3]] != ga || global_of[face[(k + 2) % 3]] != gb) return decline(kMissing);
    if (piece_keys.count(edge_key(ga, gb)) != 0) continue;
    if (in_circle(P[tri[0]], P[tri[1]], P[tri[2]], local_points[face[k]]) >= 0) return decline(kNotDelaunay);
  }
  for (std::uint64_t key : cavity_pieces) {
    if (inside_edges.count(key) == 0) return decline(kMissing);
  }
  // The kept triangles among themselves: strictly Delaunay across every edge
  // that is not an input segment (a kept segment is a piece of the output: its
  // chain points stayed and no new point lies on it). Point by point, in
  // parallel blocks: at point a, the fan's triangle t with edge a -> b meets
  // the s with edge b -> a, whose third point is the one after a in s; each
  // edge is checked at its smaller end.
  // (An input certified strictly Delaunay has them so already: the same four
  // points make each such edge's test.)
  std::atomic<bool> delaunay{true};
  constexpr std::size_t kBlock = 1 << 13;
  report.checked_kept_edges = !input.strictly_delaunay;
  parallel_for(input.strictly_delaunay ? 0 : (n_in + kBlock - 1) / kBlock, /*threads=*/0, [&](std::size_t blk) {
    struct Corner {
      Index t;
      int k;  // a = T[t][k]
      Index next, prev;
    };
    std::vector<Corner> fan;
    for (std::size_t v = blk * kBlock; v < std::min(n_in, (blk + 1) * kBlock) && delaunay.load(std::memory_order_relaxed);
         ++v) {
      const Index a = static_cast<Index>(v);
      fan.clear();
      old_mesh.for_each_triangle_at(a, [&](Index u) {
        const Triangle& tri = T[u];
        const int k = tri[0] == a ? 0 : tri[1] == a ? 1 : 2;
        fan.push_back({u, k, tri[(k + 1) % 3], tri[(k + 2) % 3]});
      });
      for (const Corner& c : fan) {
        if (c.next < a || cavity[c.t] || (segment_mask[c.t] >> c.k & 1)) continue;
        for (const Corner& o : fan) {
          if (o.prev != c.next) continue;
          const Triangle& tri = T[c.t];
          if (!cavity[o.t] && in_circle(P[tri[0]], P[tri[1]], P[tri[2]], P[o.next]) >= 0) delaunay = false;
          break;
        }
      }
    }
  });
  if (!delaunay) return decline(kNotDelaunay);
  // (and those segments are pieces indeed)
  for (const Edge& e : input.segments) {
    if (kept_edge_between(e[0], e[1]) && piece_keys.count(edge_key(new_of[e[0]], new_of[e[1]])) == 0) {
      return decline(kMissing);
    }
  }

  // 6. The kept triangles (renumbered) and the cavity's, in canonical order.
  // The kept ones come in the input's order, canonical when the input is a
  // step's output, and a step keeps its points' relative order but for a few
  // (demoted points go after the others): one pass keeps the increasing run of
  // them in place and sets aside what does not fit (detail::extend_increasing_run);
  // the set-aside and the cavity's are sorted and merged in from the back. Many set aside (an input in another order): the
  // counting sort of canonical_triangle_order.
  std::vector<Triangle> triangles;
  triangles.reserve(m_in - n_cavity + n_inside);
  std::vector<Triangle> rest;
  rest.reserve(n_inside);
  for (std::size_t f = 0; f < n_faces; ++f) {
    if (!inside[f]) continue;
    const Triangle& tri = lt.triangles[f];
    rest.push_back(least_index_first({global_of[tri[0]], global_of[tri[1]], global_of[tri[2]]}));
  }
  for (std::size_t t = 0; t < m_in; ++t) {
    if (cavity[t]) continue;
    const Triangle x = least_index_first({new_of[T[t][0]], new_of[T[t][1]], new_of[T[t][2]]});
    detail::extend_increasing_run(triangles, rest, x, std::less<Triangle>());
  }
  if (rest.size() > n_inside + (m_in - n_cavity) / 16) {
    triangles.insert(triangles.end(), rest.begin(), rest.end());
    canonical_triangle_order(n, triangles);
  } else {
    std::sort(rest.begin(), rest.end());
    std::size_t i = triangles.size(), j = rest.size(), k = i + j;
    triangles.resize(k);
    while (j > 0) triangles[--k] = i > 0 && rest[j - 1] < triangles[i - 1] ? triangles[--i] : rest[--j];
  }
  if (same_fan != nullptr) {
    same_fan->assign(n, 0);
    for (std::size_t j = 0; j < n; ++j) (*same_fan)[j] = origin[j] >= 0;
    for (std::size_t f = 0; f < n_faces; ++f) {
      if (!inside[f]) continue;
      for (Index v : lt.triangles[f]) (*same_fan)[static_cast<std::size_t>(global_of[v])] = 0;
    }
  }
  lap(report.certify_seconds);
  return triangles;
}

}  // namespace evomesh
