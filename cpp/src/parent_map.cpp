#include "evomesh/parent_map.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <queue>
#include <unordered_set>
#include <stdexcept>
#include <numeric>

#include "evomesh/kernel.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/triangulation.hpp"

namespace evomesh {

namespace {

// The old triangles of `queries` by walks from `hints` (an old triangle near
// each), a search over the old mesh for those no walk reaches.
std::vector<Index> locate_with_hints(const Old_mesh_walker& walker, const std::vector<Vec2>& queries,
                                     const std::vector<Index>& hints, std::size_t& n_searched) {
  const Mesh_arrays& old_mesh = walker.mesh();
  std::vector<Index> found(queries.size(), -1);
  std::vector<std::size_t> missed;
  std::size_t steps = 0;
  for (std::size_t k = 0; k < queries.size(); ++k) {
    found[k] = hints[k] < 0 ? -1 : walker.walk(hints[k], queries[k], k, steps);
    if (found[k] < 0) missed.push_back(k);
  }
  n_searched = missed.size();
  if (!missed.empty()) {
    std::vector<Vec2> lost(missed.size());
    for (std::size_t k = 0; k < missed.size(); ++k) lost[k] = queries[missed[k]];
    std::vector<Index> where;
    std::vector<std::array<double, 3>> unused;
    locate_points(old_mesh.points, old_mesh.triangles, lost, where, unused);
    for (std::size_t k = 0; k < missed.size(); ++k) found[missed[k]] = where[k];
  }
  return found;
}

}  // namespace

Old_mesh_walker::Old_mesh_walker(const Mesh_arrays& old_mesh, double outside)
    : Old_mesh_walker(old_mesh, Triangle_fans(old_mesh), outside) {}

Old_mesh_walker::Old_mesh_walker(const Mesh_arrays& old_mesh, Triangle_fans fans, double outside)
    : outside_(outside),
      mesh_(old_mesh),
      P_(old_mesh.points),
      T_(old_mesh.triangles),
      fans_(std::move(fans)),
      limit_(64 + 4 * static_cast<std::size_t>(std::sqrt(static_cast<double>(old_mesh.triangles.size())))) {
  if (fans_.xadj.size() != P_.size() + 1 || fans_.adj.size() != 3 * T_.size()) {
    throw std::logic_error("Old_mesh_walker: the fans are not the old mesh's");
  }
}

// The other triangle around a that has b (a mesh is an oriented manifold: at
// most one), looked up when a walk crosses the edge: the walks of a step cross
// a few triangles per new point, far fewer than the 3 m edges a table would
// cost to fill (the whole old mesh, also where nothing changed).
Index Old_mesh_walker::across(Index t, int k) const {
  const Index a = T_[t][k], b = T_[t][(k + 1) % 3];
  for (Index f = fans_.xadj[a]; f < fans_.xadj[a + 1]; ++f) {
    const Index u = fans_.adj[f];
    if (u == t) continue;
    const Triangle& other = T_[u];
    if (other[0] == b || other[1] == b || other[2] == b) return u;
  }
  return -1;
}

Index Old_mesh_walker::walk(Index t, const Vec2& q, std::size_t salt, std::size_t& steps) const {
  for (std::size_t step = 0; step < limit_; ++step) {
    const Triangle& tri = T_[t];
    Index next = -1;
    int boundary_side = -1;
    for (int j = 0; j < 3; ++j) {
      const int k = static_cast<int>((salt + step + j) % 3);
      if (orientation(P_[tri[k]], P_[tri[(k + 1) % 3]], q) < 0) {
        next = across(t, k);
        if (next >= 0) break;
        boundary_side = k;
      }
    }
    if (next >= 0) {
      t = next;
      ++steps;
      continue;
    }
    if (boundary_side < 0) return t;
    const Vec2& a = P_[tri[boundary_side]];
    const Vec2& b = P_[tri[(boundary_side + 1) % 3]];
    const double reach = std::max({std::abs(q[0]), std::abs(q[1]), std::abs(a[0]), std::abs(a[1]), std::abs(b[0]),
                                   std::abs(b[1])});
    if (distance_to_segment(q, a, b) <= std::max(outside_, boundary_rounding(reach))) return t;
    return search(t, q);  // blocked by the boundary of a non-convex domain
  }
  return search(t, q);
}

Index Old_mesh_walker::search(Index t, const Vec2& q) const {
  constexpr std::size_t kSearchBudget = 1 << 16;
  using Entry = std::pair<double, Index>;
  std::priority_queue<Entry, std::vector<Entry>, std::greater<Entry>> open;
  std::unordered_set<Index> seen{t};
  open.push({distance_to_triangle(P_, T_[t], q), t});
  for (std::size_t popped = 0; !open.empty() && popped < kSearchBudget; ++popped) {
    const auto [d, u] = open.top();
    open.pop();
    double reach = std::max(std::abs(q[0]), std::abs(q[1]));
    for (Index v : T_[u]) reach = std::max({reach, std::abs(P_[v][0]), std::abs(P_[v][1])});
    if (d <= std::max(outside_, boundary_rounding(reach))) return u;
    // across edges, and around vertices: where a domain touches itself at a
    // vertex, the triangles on either side share no edge
    for (Index v : T_[u]) {
      for (Index a = fans_.xadj[v]; a < fans_.xadj[v + 1]; ++a) {
        const Index w = fans_.adj[a];
        if (seen.insert(w).second) open.push({distance_to_triangle(P_, T_[w], q), w});
      }
    }
  }
  return -1;
}

Parent_map parent_map(const Old_mesh_walker& walker, const Mesh_arrays& new_mesh, const std::vector<Index>& origin) {
  const Mesh_arrays& old_mesh = walker.mesh();
  const auto& P = old_mesh.points;
  const auto& T = old_mesh.triangles;
  const std::size_t n_new = new_mesh.points.size();
  if (origin.size() != n_new) throw std::logic_error("parent_map: one origin per new point");
  Parent_map map;
  detail::parallel_resize(map.triangle, n_new, Index{-1});
  detail::parallel_resize(map.barycentric, n_new);
  if (T.empty()) return map;
  // Rounds of walks, each from the old triangle of a new neighbour placed in
  // an earlier round: the kept points first (a triangle at their old index),
  // then the points placed by the walks of round 1, and so on. A point walks
  // from its placed neighbour of least index (an atomic minimum over the new
  // triangles at it), so the walks of a round are independent and run in
  // parallel, and the map is the same for any thread count. O(n) walks of a few
  // triangles each, as in a breadth-first order, with no sequential pass. There
  // are as many rounds as new points lie edges away from the nearest kept one
  // (a few, more only where a step refines by a large factor); each reads only
  // the new triangles that still have a pending vertex.
  constexpr std::uint32_t kNone = ~std::uint32_t{0};
  constexpr std::size_t kChunk = std::size_t{1} << 14;
  auto chunks = [](std::size_t size) { return (size + kChunk - 1) / kChunk; };
  // value(k) for k in [0, size) with keep(k), in order (filtered in parallel chunks).
  auto collect = [&](std::size_t size, auto keep, auto value) {
    std::vector<std::vector<Index>> found(chunks(size));
    parallel_for(found.size(), 0, [&](std::size_t c) {
      for (std::size_t k = c * kChunk; k < std::min(size, (c + 1) * kChunk); ++k) {
        if (keep(k)) found[c].push_back(value(k));
      }
    });
    std::vector<Index> out;
    for (const auto& f : found) out.insert(out.end(), f.begin(), f.end());
    return out;
  };
  auto itself = [](std::size_t k) { return static_cast<Index>(k); };
  std::vector<Index> start;  // the old triangle a walk from new point u starts at (-1: u not placed)
  detail::parallel_resize(start, n_new, Index{-1});
  parallel_for(chunks(n_new), 0, [&](std::size_t c) {
    for (std::size_t i = c * kChunk; i < std::min(n_new, (c + 1) * kChunk); ++i) {
      if (origin[i] >= 0) start[i] = walker.triangle_at(origin[i]);
    }
  });
  const auto& NT = new_mesh.triangles;
  std::vector<Index> pending = collect(n_new, [&](std::size_t i) { return origin[i] < 0; }, itself);
  // The new triangles that have a vertex not placed (those a round reads).
  std::vector<Index> open_triangles = collect(
      NT.size(), [&](std::size_t t) { return origin[NT[t][0]] < 0 || origin[NT[t][1]] < 0 || origin[NT[t][2]] < 0; },
      itself);
  std::vector<std::atomic<std::uint32_t>> from(n_new);  // least placed neighbour of a pending point
  parallel_for(chunks(n_new), 0, [&](std::size_t c) {
    for (std::size_t i = c * kChunk; i < std::min(n_new, (c + 1) * kChunk); ++i) from[i].store(kNone, std::memory_order_relaxed);
  });
  std::vector<Index> unplaced;
  while (!pending.empty()) {
    // Each pending point's least placed neighbour (start >= 0 only for points
    // placed before this round: this round's walks write start afterwards).
    parallel_for(chunks(open_triangles.size()), 0, [&](std::size_t c) {
      for (std::size_t k = c * kChunk; k < std::min(open_triangles.size(), (c + 1) * kChunk); ++k) {
        const Triangle& tri = NT[open_triangles[k]];
        for (int j = 0; j < 3; ++j) {
          const Index v = tri[j];
          if (start[v] >= 0) continue;
          for (int i = 1; i < 3; ++i) {
            const Index u = tri[(j + i) % 3];
            if (start[u] < 0) continue;
            std::uint32_t seen = from[v].load(std::memory_order_relaxed);
            while (static_cast<std::uint32_t>(u) < seen &&
                   !from[v].compare_exchange_weak(seen, static_cast<std::uint32_t>(u), std::memory_order_relaxed)) {
            }
          }
        }
      }
    });
    // The walks; a point with no placed neighbour waits for the next round, one
    // whose walk fails is located by the search below.
    std::vector<std::vector<Index>> waiting(chunks(pending.size())), failed(waiting.size());
    std::vector<std::size_t> steps(waiting.size(), 0);
    std::vector<Index> placed_now;  // (start is written after the round)
    detail::parallel_resize(placed_now, pending.size(), Index{-1});
    parallel_for(waiting.size(), 0, [&](std::size_t c) {
      for (std::size_t k = c * kChunk; k < std::min(pending.size(), (c + 1) * kChunk); ++k) {
        const Index v = pending[k];
        const std::uint32_t u = from[v].load(std::memory_order_relaxed);
        if (u == kNone) {
          waiting[c].push_back(v);
          continue;
        }
        from[v].store(kNone, std::memory_order_relaxed);
        const Index t = walker.walk(start[u], new_mesh.points[v], static_cast<std::size_t>(v), steps[c]);
        if (t < 0) {
          failed[c].push_back(v);
          continue;
        }
        map.triangle[v] = t;
        map.barycentric[v] = barycentric_coordinates(P, T[t], new_mesh.points[v]);
        placed_now[k] = t;
      }
    });
    std::vector<std::size_t> n_placed(waiting.size(), 0);
    parallel_for(waiting.size(), 0, [&](std::size_t c) {
      for (std::size_t k = c * kChunk; k < std::min(pending.size(), (c + 1) * kChunk); ++k) {
        if (placed_now[k] < 0) continue;
        start[pending[k]] = placed_now[k];
        ++n_placed[c];
      }
    });
    std::size_t placed_in_round = 0;
    for (std::size_t c = 0; c < waiting.size(); ++c) {
      placed_in_round += n_placed[c];
      map.n_walk_steps += steps[c];
      unplaced.insert(unplaced.end(), failed[c].begin(), failed[c].end());
    }
    pending.clear();
    for (const auto& w : waiting) pending.insert(pending.end(), w.begin(), w.end());
    if (placed_in_round == 0 || pending.empty()) break;  // (then none has a placed neighbour)
    // The triangles with a vertex still pending, in order.
    open_triangles = collect(
        open_triangles.size(),
        [&](std::size_t k) {
          const Triangle& tri = NT[open_triangles[k]];
          return start[tri[0]] < 0 || start[tri[1]] < 0 || start[tri[2]] < 0;
        },
        [&](std::size_t k) { return open_triangles[k]; });
  }
  unplaced.insert(unplaced.end(), pending.begin(), pending.end());
  if (!unplaced.empty()) {
    std::sort(unplaced.begin(), unplaced.end());
    std::vector<Vec2> queries(unplaced.size());
    for (std::size_t k = 0; k < unplaced.size(); ++k) queries[k] = new_mesh.points[unplaced[k]];
    std::vector<Index> found;
    std::vector<std::array<double, 3>> weights;
    locate_points(P, T, queries, found, weights);
    for (std::size_t k = 0; k < unplaced.size(); ++k) {
      map.triangle[unplaced[k]] = found[k];
      map.barycentric[unplaced[k]] = weights[k];
    }
    map.n_located_globally = unplaced.size();
  }
  return map;
}

void carry_tags(const Old_mesh_walker& walker, const std::vector<Index>& origin, const Parent_map& parents,
                Mesh_arrays& new_mesh) {
  const Mesh_arrays& old_mesh = walker.mesh();
  if (!old_mesh.required.empty()) {
    new_mesh.required.assign(new_mesh.points.size(), 0);
    for (std::size_t i = 0; i < origin.size(); ++i) {
      if (origin[i] >= 0) new_mesh.required[i] = old_mesh.required[origin[i]];
    }
  }
  const bool segments_tagged = !old_mesh.segment_tags.empty();
  const bool triangles_tagged = !old_mesh.triangle_tags.empty();
  if (!segments_tagged && !triangles_tagged) return;
  // An old triangle at (or near) every new point, to start walks from.
  auto hint_at = [&](Index v) { return origin[v] >= 0 ? walker.triangle_at(origin[v]) : parents.triangle[v]; };
  std::size_t searched = 0;
  if (triangles_tagged) {
    // Region borders are constraints, so a new triangle lies in one region: the
    // one of the old triangle that contains its centroid.
    const std::size_t m = new_mesh.triangles.size();
    std::vector<Vec2> centroids(m);
    std::vector<Index> hints(m);
    for (std::size_t t = 0; t < m; ++t) {
      const Triangle& tri = new_mesh.triangles[t];
      const Vec2 &a = new_mesh.points[tri[0]], &b = new_mesh.points[tri[1]], &c = new_mesh.points[tri[2]];
      centroids[t] = {(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0};
      hints[t] = hint_at(tri[0]);
    }
    const auto found = locate_with_hints(walker, centroids, hints, searched);
    new_mesh.triangle_tags.resize(m);
    for (std::size_t t = 0; t < m; ++t) {
      if (found[t] < 0) throw std::logic_error("carry_tags: a new triangle outside the old mesh");
      new_mesh.triangle_tags[t] = old_mesh.triangle_tags[found[t]];
    }
  }
  if (segments_tagged) {
    // A new segment lies on one chain of old segments, all of one tag (a tag
    // change is a corner, which every step keeps): the tag of the old segment
    // nearest its midpoint, among those on the old triangle found there and at
    // that triangle's vertices.
    const std::size_t k = new_mesh.segments.size();
    std::vector<Vec2> midpoints(k);
    std::vector<Index> hints(k);
    for (std::size_t s = 0; s < k; ++s) {
      const Edge& e = new_mesh.segments[s];
      const Vec2 &a = new_mesh.points[e[0]], &b = new_mesh.points[e[1]];
      midpoints[s] = {0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])};
      hints[s] = hint_at(e[0]);
    }
    const auto found = locate_with_hints(walker, midpoints, hints, searched);
    const std::size_t n_old = old_mesh.points.size();
    std::vector<Index> xadj(n_old + 1, 0), adj(2 * old_mesh.segments.size());
    for (const auto& e : old_mesh.segments) {
      ++xadj[e[0] + 1];
      ++xadj[e[1] + 1];
    }
    std::partial_sum(xadj.begin(), xadj.end(), xadj.begin());
    {
      std::vector<Index> fill(xadj.begin(), xadj.end() - 1);
      for (std::size_t s = 0; s < old_mesh.segments.size(); ++s) {
        adj[fill[old_mesh.segments[s][0]]++] = static_cast<Index>(s);
        adj[fill[old_mesh.segments[s][1]]++] = static_cast<Index>(s);
      }
    }
    new_mesh.segment_tags.resize(k);
    for (std::size_t s = 0; s < k; ++s) {
      if (found[s] < 0) throw std::logic_error("carry_tags: a new segment outside the old mesh");
      Index best = -1;
      double best_distance = std::numeric_limits<double>::infinity();
      const auto consider = [&](Index segment) {
        const Edge& e = old_mesh.segments[segment];
        const double d = distance_to_segment(midpoints[s], old_mesh.points[e[0]], old_mesh.points[e[1]]);
        if (d < best_distance) {
          best_distance = d;
          best = segment;
        }
      };
      for (Index v : old_mesh.triangles[found[s]]) {
        for (Index a = xadj[v]; a < xadj[v + 1]; ++a) consider(adj[a]);
      }
      // A segment of an interior curve whose points moved onto the curve by
      // more than an old triangle (an interface folded within the spacing):
      // the old triangles at its ends, then (rarely) every old segment.
      for (const Index end : new_mesh.segments[s]) {
        if (best >= 0) break;
        const Index t = hint_at(end);
        if (t < 0) continue;
        for (Index v : old_mesh.triangles[t]) {
          for (Index a = xadj[v]; a < xadj[v + 1]; ++a) consider(adj[a]);
        }
      }
      if (best < 0) {
        for (std::size_t o = 0; o < old_mesh.segments.size(); ++o) consider(static_cast<Index>(o));
      }
      if (best < 0) throw std::logic_error("carry_tags: a new segment and no old one");
      new_mesh.segment_tags[s] = old_mesh.segment_tags[best];
    }
  }
}

}  // namespace evomesh
