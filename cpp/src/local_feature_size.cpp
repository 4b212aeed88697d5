#include "evomesh/local_feature_size.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "evomesh/boundary_geometry.hpp"
#include "evomesh/candidates.hpp"
#include "evomesh/mesh_walk.hpp"
#include "evomesh/parallel.hpp"

namespace evomesh {

std::vector<std::uint8_t> keep_within_domain(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                                             std::vector<double>& nn, const std::vector<std::uint8_t>* known) {
  // A point changes where its shortest edge (the least std::hypot of its edges)
  // exceeds nn * (1 + kRounding). The edge of least squared length decides that
  // for almost every point with one hypot: the least hypot is at most that edge's,
  // so "unchanged" is certain when its hypot is within the bound. Only the other
  // points (about those that change) take the least hypot of all their edges, as
  // the definition says: the same bits as computing it everywhere.
  const std::size_t n = points.size();
  constexpr double kRounding = 4 * std::numeric_limits<double>::epsilon();
  constexpr std::size_t kBlock = 1 << 14;
  std::vector<double> least(n, std::numeric_limits<double>::infinity());
  std::vector<Index> other(n, -1);  // (stays -1 at the known points: nothing to decide there)
  if (known != nullptr && known->size() != n) throw std::logic_error("keep_within_domain: one known flag per point");
  if (known != nullptr) {
    // The shortest edge of every other point, in one pass in triangle order.
    for (const Triangle& t : triangles) {
      for (int k = 0; k < 3; ++k) {
        const Index a = t[k], b = t[(k + 1) % 3];
        const bool open_a = !(*known)[a], open_b = !(*known)[b];
        if (!open_a && !open_b) continue;
        const double dx = points[b][0] - points[a][0], dy = points[b][1] - points[a][1];
        const double squared = dx * dx + dy * dy;
        if (open_a && squared < least[a]) least[a] = squared, other[a] = b;
        if (open_b && squared < least[b]) least[b] = squared, other[b] = a;
      }
    }
  } else {
    // Squared edge lengths in parallel blocks (the reads of the points), the
    // shortest edge of every point in one pass.
    std::vector<std::array<double, 3>> squared_length(triangles.size());
    parallel_for((triangles.size() + kBlock - 1) / kBlock, 0, [&](std::size_t block) {
      for (std::size_t t = block * kBlock; t < std::min(triangles.size(), (block + 1) * kBlock); ++t) {
        for (int k = 0; k < 3; ++k) {
          const Index a = triangles[t][k], b = triangles[t][(k + 1) % 3];
          const double dx = points[b][0] - points[a][0], dy = points[b][1] - points[a][1];
          squared_length[t][k] = dx * dx + dy * dy;
        }
      }
    });
    // Each worker owns a range of points and scans every edge for them (ties keep
    // the first edge in triangle order, as one pass would).
    const std::size_t n_owners = std::clamp<std::size_t>(static_cast<std::size_t>(resolve_threads(0)), 1, 8);
    parallel_for(n_owners, 0, [&](std::size_t owner) {
      const Index lo = static_cast<Index>(n * owner / n_owners), hi = static_cast<Index>(n * (owner + 1) / n_owners);
      for (std::size_t t = 0; t < triangles.size(); ++t) {
        for (int k = 0; k < 3; ++k) {
          const Index a = triangles[t][k], b = triangles[t][(k + 1) % 3];
          const double squared = squared_length[t][k];
          if (a >= lo && a < hi && squared < least[a]) least[a] = squared, other[a] = b;
          if (b >= lo && b < hi && squared < least[b]) least[b] = squared, other[b] = a;
        }
      }
    });
  }
  // `least` becomes the least hypot where it is needed exactly, else stays unused.
  std::vector<std::uint8_t> exact(n, 0);
  parallel_for((n + kBlock - 1) / kBlock, 0, [&](std::size_t block) {
    for (std::size_t i = block * kBlock; i < std::min(n, (block + 1) * kBlock); ++i) {
      if (other[i] < 0) continue;  // no edge: nn stays
      const Vec2& q = points[other[i]];
      const double length = std::hypot(q[0] - points[i][0], q[1] - points[i][1]);
      if (length > nn[i] * (1 + kRounding) || std::isnan(length) || std::isnan(nn[i])) {
        exact[i] = 1;
        least[i] = std::numeric_limits<double>::infinity();
      }
    }
  });
  other = {};
  bool any = false;
  for (std::uint8_t e : exact) any = any || e;
  if (any) {
    for (const Triangle& t : triangles) {
      for (int k = 0; k < 3; ++k) {
        const Index a = t[k], b = t[(k + 1) % 3];
        if (!exact[a] && !exact[b]) continue;
        const double length = std::hypot(points[b][0] - points[a][0], points[b][1] - points[a][1]);
        if (exact[a]) least[a] = std::min(least[a], length);
        if (exact[b]) least[b] = std::min(least[b], length);
      }
    }
  }
  std::vector<std::uint8_t> changed(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    // the nearest point is no edge neighbour: in a constrained Delaunay
    // triangulation it is hidden behind a constraint (a slit, a thin wall)
    if (exact[i] && std::isfinite(least[i]) && least[i] > nn[i] * (1 + kRounding)) {
      nn[i] = least[i];
      changed[i] = 1;
    }
  }
  return changed;
}

namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// The walks of the local feature size at a point inside a chain: along the
// normal (towards the domain, both ways for an interior constraint), the
// distance to the first segment that `counts` (of a chain that neither is the
// point's own nor shares a corner with it), below `limit`. NaN when the point's
// chain neighbours coincide (no tangent). The tangent runs u -> w and the normal
// is on the left of the segment (v, w) as stored, so the result does not depend
// on the direction the chain is listed in.
template <class Counts>
double cast_feature_size(const Mesh_arrays& mesh, const Mesh_walk& walk, const Chain_point& c, double limit,
                         const Counts& counts, bool* left) {
  const Vec2& u = mesh.points[c.u];
  const Vec2& w = mesh.points[c.w];
  Vec2 tangent{w[0] - u[0], w[1] - u[1]};
  const double length = std::hypot(tangent[0], tangent[1]);
  if (!(length > 0)) return std::numeric_limits<double>::quiet_NaN();
  tangent = {tangent[0] / length, tangent[1] / length};
  Vec2 normal{-tangent[1], tangent[0]};
  if (!c.along) normal = {-normal[0], -normal[1]};
  double best = kInfinity;
  for (int side = 0; side < (c.two_sided ? 2 : 1); ++side) {
    const Vec2 d = side == 0 ? normal : Vec2{-normal[0], -normal[1]};
    const auto [segment, distance] = walk.cast(c.v, d, std::min(limit, best), left);
    if (segment >= 0 && counts(segment)) best = std::min(best, distance);
  }
  return best;
}

}  // namespace

double curve_turn_cap(const Vec2& u, const Vec2& p, const Vec2& w, double corner_angle) {
  const double a = std::hypot(p[0] - u[0], p[1] - u[1]), b = std::hypot(w[0] - p[0], w[1] - p[1]);
  const double ux = p[0] - u[0], uy = p[1] - u[1], wx = w[0] - p[0], wy = w[1] - p[1];
  const double turn = std::atan2(std::abs(ux * wy - uy * wx), ux * wx + uy * wy);
  const double allowed = corner_angle * (3.14159265358979323846 / 180.0);
  return turn > 0 ? 0.25 * (a + b) * allowed / turn : std::numeric_limits<double>::infinity();
}

std::vector<double> local_feature_size(const Mesh_arrays& mesh, const std::vector<Segment_chain>& chains,
                                       const std::vector<double>& limit) {
  const std::size_t n = mesh.points.size();
  std::vector<double> lfs(n, kInfinity);
  if (chains.empty()) return lfs;
  std::vector<Index> chain_of(mesh.segments.size(), -1);
  for (std::size_t c = 0; c < chains.size(); ++c) {
    for (Index s : chains[c].segments) chain_of[s] = static_cast<Index>(c);
  }
  auto adjacent = [&](Index c1, Index c2) {
    if (c1 == c2) return true;
    const auto& a = chains[c1].vertices;
    const auto& b = chains[c2].vertices;
    return a.front() == b.front() || a.front() == b.back() || a.back() == b.front() || a.back() == b.back();
  };
  const Triangle_fans fans(mesh);
  const Mesh_walk walk(mesh, fans);
  const Boundary_geometry* geometry = mesh.geometry.get();
  for (std::size_t c = 0; c < chains.size(); ++c) {
    const auto& chain = chains[c];
    const bool curved = geometry && geometry->is_curved(chain.tag);
    const std::size_t m = chain.segments.size();
    // the points inside the chain (a closed chain's first point is its corner)
    for (std::size_t k = 1; k < m; ++k) {
      const Index v = chain.vertices[k];
      const Vec2& p = mesh.points[v];
      const Vec2& u = mesh.points[chain.vertices[k - 1]];
      const Index w_index = chain.closed && k + 1 == chain.vertices.size() ? chain.vertices[0] : chain.vertices[k + 1];
      const Vec2& w = mesh.points[w_index];
      // segment k runs v -> next in its own orientation
      const Chain_point point{v, chain.vertices[k - 1], w_index, chain.forward[k] != 0, !chain.boundary};
      // An interior chain (an interface) also faces itself: a fold of one
      // curve (a thin filament, a wave) is as narrow as a strip between two.
      const auto counts = [&](Index segment) {
        const Index other = chain_of[segment];
        return other >= 0 && (!adjacent(static_cast<Index>(c), other) || (other == static_cast<Index>(c) && !chain.boundary));
      };
      double best = cast_feature_size(mesh, walk, point, limit[v], counts, nullptr);
      if (std::isnan(best)) continue;
      if (curved) best = std::min(best, curve_turn_cap(u, p, w, geometry->corner_angle));
      lfs[v] = best;
    }
    // Two corners are features of their own (Ruppert): a corner carries no
    // spacing beyond the other end of its chain (the tip of a slit, a short side).
    if (!chain.closed && !curved) {
      const Index a = chain.vertices.front(), b = chain.vertices.back();
      const double d = std::hypot(mesh.points[b][0] - mesh.points[a][0], mesh.points[b][1] - mesh.points[a][1]);
      lfs[a] = std::min(lfs[a], d);
      lfs[b] = std::min(lfs[b], d);
    }
  }
  return lfs;
}

std::vector<double> chain_feature_sizes(const Mesh_arrays& part, const std::vector<Chain_point>& points,
                                        const std::vector<std::int64_t>& chain_of_point,
                                        const std::vector<std::int64_t>& chain_of_segment,
                                        const std::unordered_map<std::int64_t, std::array<std::int64_t, 2>>& ends,
                                        const std::vector<double>& limit, std::vector<std::uint8_t>& certified) {
  const std::size_t n = points.size();
  if (chain_of_point.size() != n || limit.size() != n) throw Input_error("chain_feature_sizes: one chain and limit per point");
  if (chain_of_segment.size() != part.segments.size()) throw Input_error("chain_feature_sizes: one chain per segment");
  const auto end_of = [&](std::int64_t chain) -> const std::array<std::int64_t, 2>& {
    const auto found = ends.find(chain);
    if (found == ends.end()) throw Input_error("chain_feature_sizes: a chain without its ends");
    return found->second;
  };
  for (const Chain_point& c : points) {
    for (Index i : {c.v, c.u, c.w}) {
      if (i < 0 || static_cast<std::size_t>(i) >= part.points.size()) throw Input_error("chain_feature_sizes: point index out of range");
    }
  }
  const Triangle_fans fans(part);
  const Mesh_walk walk(part, fans);
  std::vector<double> lfs(n, kInfinity);
  certified.assign(n, 1);
  for (std::size_t k = 0; k < n; ++k) {
    const std::int64_t own = chain_of_point[k];
    const auto& own_ends = end_of(own);
    const auto counts = [&](Index segment) {
      const std::int64_t other = chain_of_segment[segment];
      if (other < 0) return false;
      if (other == own) return points[k].two_sided;  // (an interior chain faces itself, as local_feature_size)
      const auto& e = end_of(other);
      return !(own_ends[0] == e[0] || own_ends[0] == e[1] || own_ends[1] == e[0] || own_ends[1] == e[1]);
    };
    bool left = false;
    lfs[k] = cast_feature_size(part, walk, points[k], limit[k], counts, &left);
    certified[k] = left ? 0 : 1;
  }
  return lfs;
}

}  // namespace evomesh
