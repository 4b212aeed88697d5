#include "evomesh/parent_map.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <limits>
#include <stdexcept>
#include <numeric>

#include "evomesh/kernel.hpp"
#include "evomesh/triangulation.hpp"

namespace evomesh {

namespace {

// Neighbour across edge k (t[k] -> t[k+1]) of every triangle, -1 on the boundary.
std::vector<std::array<Index, 3>> triangle_neighbours(const std::vector<Triangle>& triangles) {
  struct Half {
    Index lo, hi, triangle;
    int side;
  };
  std::vector<Half> halves;
  halves.reserve(3 * triangles.size());
  for (std::size_t t = 0; t < triangles.size(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const Index a = triangles[t][k], b = triangles[t][(k + 1) % 3];
      halves.push_back({std::min(a, b), std::max(a, b), static_cast<Index>(t), k});
    }
  }
  std::sort(halves.begin(), halves.end(), [](const Half& x, const Half& y) {
    return x.lo != y.lo ? x.lo < y.lo : (x.hi != y.hi ? x.hi < y.hi : x.triangle < y.triangle);
  });
  std::vector<std::array<Index, 3>> neighbour(triangles.size(), {-1, -1, -1});
  for (std::size_t i = 0; i + 1 < halves.size(); ++i) {
    const Half& x = halves[i];
    const Half& y = halves[i + 1];
    if (x.lo == y.lo && x.hi == y.hi) {
      neighbour[x.triangle][x.side] = y.triangle;
      neighbour[y.triangle][y.side] = x.triangle;
      ++i;
    }
  }
  return neighbour;
}

std::array<double, 3> barycentric_in(const std::vector<Vec2>& points, const Triangle& t, const Vec2& q) {
  const Vec2& a = points[t[0]];
  const Vec2& b = points[t[1]];
  const Vec2& c = points[t[2]];
  const double det = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
  const double l1 = ((q[0] - a[0]) * (c[1] - a[1]) - (q[1] - a[1]) * (c[0] - a[0])) / det;
  const double l2 = ((b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0])) / det;
  return {1.0 - l1 - l2, l1, l2};
}

}  // namespace

Parent_map parent_map(const Mesh_arrays& old_mesh, const Mesh_arrays& new_mesh, const std::vector<Index>& origin) {
  const auto& P = old_mesh.points;
  const auto& T = old_mesh.triangles;
  const std::size_t n_new = new_mesh.points.size();
  if (origin.size() != n_new) throw std::logic_error("parent_map: one origin per new point");
  Parent_map map;
  map.triangle.assign(n_new, -1);
  map.barycentric.assign(n_new, {0.0, 0.0, 0.0});
  if (T.empty()) return map;
  const auto neighbour = triangle_neighbours(T);
  std::vector<Index> triangle_at(P.size(), -1);  // one old triangle at every old point
  for (std::size_t t = 0; t < T.size(); ++t) {
    for (Index v : T[t]) triangle_at[v] = static_cast<Index>(t);
  }
  // New points around each new point (compressed lists).
  std::vector<Index> xadj(n_new + 1, 0), adj;
  for (const auto& t : new_mesh.triangles) {
    for (Index v : t) xadj[v + 1] += 2;
  }
  std::partial_sum(xadj.begin(), xadj.end(), xadj.begin());
  adj.resize(static_cast<std::size_t>(xadj.back()));
  {
    std::vector<Index> fill(xadj.begin(), xadj.end() - 1);
    for (const auto& t : new_mesh.triangles) {
      for (int k = 0; k < 3; ++k) {
        adj[fill[t[k]]++] = t[(k + 1) % 3];
        adj[fill[t[k]]++] = t[(k + 2) % 3];
      }
    }
  }
  // Visibility walk from triangle t towards q: cross an edge that has q strictly on
  // its outer side (the first in a rotating order, so that walks do not cycle);
  // stop in a triangle that has q on no outer side (q inside or on it), or at a
  // boundary edge with q beyond it (q outside the old domain, by rounding when the
  // step kept the domain). Gives up after `limit` steps.
  const std::size_t limit = 64 + 4 * static_cast<std::size_t>(std::sqrt(static_cast<double>(T.size())));
  auto walk = [&](Index t, const Vec2& q, std::size_t salt) -> Index {
    for (std::size_t step = 0; step < limit; ++step) {
      const Triangle& tri = T[t];
      Index next = -1;
      int boundary_side = -1;
      for (int j = 0; j < 3; ++j) {
        const int k = static_cast<int>((salt + step + j) % 3);
        if (orientation(P[tri[k]], P[tri[(k + 1) % 3]], q) < 0) {
          if (neighbour[t][k] >= 0) {
            next = neighbour[t][k];
            break;
          }
          boundary_side = k;
        }
      }
      if (next >= 0) {
        t = next;
        ++map.n_walk_steps;
        continue;
      }
      if (boundary_side < 0) return t;
      // Beyond a boundary edge: rounding if q is that close to it (else a
      // non-convex domain blocks the walk, and the search decides).
      const Vec2& a = P[tri[boundary_side]];
      const Vec2& b = P[tri[(boundary_side + 1) % 3]];
      const double dx = b[0] - a[0], dy = b[1] - a[1];
      const double along = std::clamp(((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / (dx * dx + dy * dy), 0.0, 1.0);
      const double gap = std::hypot(q[0] - a[0] - along * dx, q[1] - a[1] - along * dy);
      const double reach = std::max({std::abs(q[0]), std::abs(q[1]), std::abs(a[0]), std::abs(a[1]), std::abs(b[0]),
                                     std::abs(b[1])});
      return gap <= (16 + kStraightUlps) * std::numeric_limits<double>::epsilon() * reach ? t : -1;
    }
    return -1;
  };
  std::vector<std::uint8_t> placed(n_new, 0);
  std::deque<Index> queue;
  for (std::size_t i = 0; i < n_new; ++i) {
    if (origin[i] >= 0) {
      placed[i] = 1;
      queue.push_back(static_cast<Index>(i));
    }
  }
  std::vector<Index> unplaced;
  while (!queue.empty()) {
    const Index u = queue.front();
    queue.pop_front();
    const Index start = origin[u] >= 0 ? triangle_at[origin[u]] : map.triangle[u];
    for (Index a = xadj[u]; a < xadj[u + 1]; ++a) {
      const Index v = adj[a];
      if (placed[v]) continue;
      placed[v] = 1;
      const Index t = start < 0 ? -1 : walk(start, new_mesh.points[v], static_cast<std::size_t>(v));
      if (t < 0) {
        unplaced.push_back(v);
        continue;
      }
      map.triangle[v] = t;
      map.barycentric[v] = barycentric_in(P, T[t], new_mesh.points[v]);
      queue.push_back(v);
    }
  }
  for (std::size_t i = 0; i < n_new; ++i) {
    if (!placed[i]) unplaced.push_back(static_cast<Index>(i));
  }
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

}  // namespace evomesh
