#include "evomesh/triangulation.hpp"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Convex_hull_traits_adapter_2.h>
#include <CGAL/convex_hull_2.h>
#include <CGAL/property_map.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>

#include "evomesh/boundary_geometry.hpp"
#include "evomesh/detail/domain.hpp"
#include "evomesh/detail/insert_points.hpp"
#include "evomesh/detail/spatial_order.hpp"
#include "evomesh/kernel.hpp"
#include "evomesh/nd/kd_tree.hpp"
#include "evomesh/parallel.hpp"

namespace evomesh {

namespace {

using Vb = CGAL::Triangulation_vertex_base_with_info_2<Index, Kernel>;
using Fb_info = CGAL::Triangulation_face_base_with_info_2<Index, Kernel>;
using Fb = CGAL::Constrained_triangulation_face_base_2<Kernel, Fb_info>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
// Constraints may pass through input points (split there) but never need a
// constructed intersection point: output coordinates are never invented here.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<
    Kernel, Tds, CGAL::No_constraint_intersection_requiring_constructions_tag>;
// For validation: any crossing or overlap of two constraints throws.
using Cdt_strict = CGAL::Constrained_Delaunay_triangulation_2<Kernel, Tds, CGAL::No_constraint_intersection_tag>;

using detail::insert_points;

std::string edge_name(Index a, Index b) {
  return "(" + std::to_string(a) + ", " + std::to_string(b) + ")";
}

// The edges of all triangles grouped by their lower point: bucket lo holds
// (hi, 2 * triangle + whether the triangle runs hi -> lo) for every triangle
// edge {lo, hi}, sorted by (hi, triangle). A counting sort on lo (O(n)), then
// each bucket's few entries: the same order as one comparison sort by (lo, hi,
// triangle), several times faster on millions of edges, and half the memory.
struct Edge_buckets {
  struct Entry {
    Index hi;
    Index tagged;  // 2 * triangle + (1 if the edge runs hi -> lo in it)
    Index triangle() const { return tagged >> 1; }
    bool reversed() const { return (tagged & 1) != 0; }
  };
  std::vector<std::size_t> start;  // bucket lo is entries[start[lo], start[lo + 1])
  std::vector<Entry> entries;
  std::size_t n_buckets() const { return start.size() - 1; }
};

Edge_buckets edge_buckets(const std::vector<Triangle>& triangles) {
  Index n = 0;
  for (const auto& t : triangles) n = std::max({n, t[0] + 1, t[1] + 1, t[2] + 1});
  Edge_buckets buckets;
  auto& start = buckets.start;
  start.assign(static_cast<std::size_t>(n) + 1, 0);
  for (const auto& t : triangles) {
    for (int k = 0; k < 3; ++k) ++start[static_cast<std::size_t>(std::min(t[k], t[(k + 1) % 3])) + 1];
  }
  for (std::size_t v = 0; v < static_cast<std::size_t>(n); ++v) start[v + 1] += start[v];
  auto& entries = buckets.entries;
  entries.resize(3 * triangles.size());
  {
    std::vector<std::size_t> next(start.begin(), start.end() - 1);
    for (std::size_t t = 0; t < triangles.size(); ++t) {
      for (int k = 0; k < 3; ++k) {
        const Index a = triangles[t][k];
        const Index b = triangles[t][(k + 1) % 3];
        const bool reversed = b < a;
        entries[next[static_cast<std::size_t>(reversed ? b : a)]++] = {reversed ? a : b,
                                                                       2 * static_cast<Index>(t) + reversed};
      }
    }
  }
  // Within a bucket the triangles already increase: a stable sort on hi keeps that.
  using Entry = Edge_buckets::Entry;
  for (std::size_t v = 0; v < static_cast<std::size_t>(n); ++v) {
    Entry* first = entries.data() + start[v];
    Entry* last = entries.data() + start[v + 1];
    if (last - first <= 32) {
      for (Entry* i = first + 1; i < last; ++i) {  // insertion sort: stable
        const Entry e = *i;
        Entry* j = i;
        for (; j > first && e.hi < (j - 1)->hi; --j) *j = *(j - 1);
        *j = e;
      }
    } else {
      std::stable_sort(first, last, [](const Entry& x, const Entry& y) { return x.hi < y.hi; });
    }
  }
  return buckets;
}

// Directed edges of all triangles, sorted by undirected key (then triangle).
struct Directed_edge {
  Index lo, hi;   // undirected key
  Index from;     // direction: from -> other
  Index triangle;
};

std::vector<Directed_edge> sorted_edges(const std::vector<Triangle>& triangles) {
  const Edge_buckets buckets = edge_buckets(triangles);
  std::vector<Directed_edge> edges;
  edges.reserve(buckets.entries.size());
  for (std::size_t v = 0; v < buckets.n_buckets(); ++v) {
    const Index lo = static_cast<Index>(v);
    for (std::size_t k = buckets.start[v]; k < buckets.start[v + 1]; ++k) {
      const auto& e = buckets.entries[k];
      edges.push_back({lo, e.hi, e.reversed() ? e.hi : lo, e.triangle()});
    }
  }
  return edges;
}

}  // namespace

std::size_t orient_triangles(const std::vector<Vec2>& points, std::vector<Triangle>& triangles) {
  std::size_t flipped = 0;
  for (std::size_t t = 0; t < triangles.size(); ++t) {
    auto& tri = triangles[t];
    const int o = orientation(points[tri[0]], points[tri[1]], points[tri[2]]);
    if (o == 0) throw Input_error("triangle " + std::to_string(t) + " has zero area (collinear vertices)");
    if (o < 0) {
      std::swap(tri[1], tri[2]);
      ++flipped;
    }
  }
  return flipped;
}

void build_segments(Mesh_arrays& mesh, const std::vector<Edge>& user_segments) {
  const Edge_buckets buckets = edge_buckets(mesh.triangles);
  const auto& entries = buckets.entries;
  std::vector<Edge> boundary;
  for (std::size_t v = 0; v < buckets.n_buckets(); ++v) {
    const Index lo = static_cast<Index>(v);
    for (std::size_t i = buckets.start[v], end = buckets.start[v + 1]; i < end;) {
      std::size_t j = i;
      while (j < end && entries[j].hi == entries[i].hi) ++j;
      const std::size_t count = j - i;
      const Index hi = entries[i].hi;
      if (count > 2) {
        throw Input_error("edge " + edge_name(lo, hi) + " is shared by " + std::to_string(count) +
                          " triangles (non-manifold)");
      }
      if (count == 2) {
        if (entries[i].reversed() == entries[i + 1].reversed()) {
          throw Input_error("triangles " + std::to_string(entries[i].triangle()) + " and " +
                            std::to_string(entries[i + 1].triangle()) +
                            " overlap: they lie on the same side of edge " + edge_name(lo, hi));
        }
      } else {
        boundary.push_back(entries[i].reversed() ? Edge{hi, lo} : Edge{lo, hi});
      }
      i = j;
    }
  }
  mesh.segments = boundary;
  mesh.segment_is_boundary.assign(boundary.size(), 1);
  // How many triangles have the edge {a, b}: 0 (not an edge), 1 or 2.
  const auto triangles_at = [&](const Edge& key) -> std::size_t {
    if (key[0] < 0 || static_cast<std::size_t>(key[0]) >= buckets.n_buckets()) return 0;
    const auto* first = entries.data() + buckets.start[key[0]];
    const auto* last = entries.data() + buckets.start[key[0] + 1];
    const auto range = std::equal_range(first, last, Edge_buckets::Entry{key[1], 0},
                                        [](const auto& x, const auto& y) { return x.hi < y.hi; });
    return static_cast<std::size_t>(range.second - range.first);
  };
  std::vector<Edge> extra;
  for (std::size_t k = 0; k < user_segments.size(); ++k) {
    const Edge& s = user_segments[k];
    if (s[0] == s[1]) throw Input_error("segment " + std::to_string(k) + " joins a point to itself");
    const Edge key{std::min(s[0], s[1]), std::max(s[0], s[1])};
    const std::size_t count = triangles_at(key);
    if (count == 2) {
      extra.push_back(key);
      continue;
    }
    // Boundary edges are already segments; anything else is not an edge at all.
    if (count == 0) {
      throw Input_error("segment " + std::to_string(k) + " " + edge_name(s[0], s[1]) + " is not an edge of the mesh");
    }
  }
  std::sort(extra.begin(), extra.end());
  extra.erase(std::unique(extra.begin(), extra.end()), extra.end());
  for (const auto& e : extra) {
    mesh.segments.push_back(e);
    mesh.segment_is_boundary.push_back(0);
  }
}

std::vector<std::int64_t> tags_of_segments(const std::vector<Edge>& segments, const std::vector<Edge>& tagged,
                                           const std::vector<std::int64_t>& tags) {
  std::vector<std::pair<Edge, std::int64_t>> keyed(tagged.size());
  for (std::size_t k = 0; k < tagged.size(); ++k) {
    keyed[k] = {{std::min(tagged[k][0], tagged[k][1]), std::max(tagged[k][0], tagged[k][1])}, tags[k]};
  }
  std::sort(keyed.begin(), keyed.end());
  std::vector<std::int64_t> out(segments.size(), 0);
  for (std::size_t k = 0; k < segments.size(); ++k) {
    const Edge key{std::min(segments[k][0], segments[k][1]), std::max(segments[k][0], segments[k][1])};
    auto it = std::lower_bound(keyed.begin(), keyed.end(), key,
                               [](const std::pair<Edge, std::int64_t>& a, const Edge& b) { return a.first < b; });
    if (it != keyed.end() && it->first == key) out[k] = it->second;
  }
  return out;
}

bool runs_straight_through(const Vec2& u, const Vec2& p, const Vec2& w) {
  const double ux = u[0] - p[0], uy = u[1] - p[1], wx = w[0] - p[0], wy = w[1] - p[1];
  if (!(ux * wx + uy * wy < 0)) return false;  // u and w must lie on opposite sides of p
  if (orientation(u, p, w) == 0) return true;
  // Within rounding of the line uw: |cross| / |w - u| is p's distance from it.
  const double reach = std::max({std::abs(u[0]), std::abs(u[1]), std::abs(p[0]), std::abs(p[1]), std::abs(w[0]),
                                 std::abs(w[1])});
  const double tolerance = kStraightUlps * std::numeric_limits<double>::epsilon() * reach;
  return std::abs(ux * wy - uy * wx) <= tolerance * std::hypot(w[0] - u[0], w[1] - u[1]);
}

std::vector<Point_kind> classify_points(const Mesh_arrays& mesh) {
  const std::size_t n = mesh.points.size();
  std::vector<Point_kind> kind(n, Point_kind::original);
  std::vector<int> degree(n, 0);
  std::vector<std::array<Index, 2>> neighbour(n, {-1, -1});
  std::vector<std::array<int, 2>> flavour(n, {-1, -1});
  std::vector<std::array<std::int64_t, 2>> tag(n, {0, 0});
  std::vector<std::uint8_t> curved(n, 0);  // a vertex inside a chain of a curved tag
  for (std::size_t k = 0; k < mesh.segments.size(); ++k) {
    const Edge& e = mesh.segments[k];
    for (int s = 0; s < 2; ++s) {
      const Index v = e[s];
      if (degree[v] < 2) {
        neighbour[v][degree[v]] = e[1 - s];
        flavour[v][degree[v]] = mesh.segment_is_boundary[k];
        tag[v][degree[v]] = mesh.segment_tags.empty() ? 0 : mesh.segment_tags[k];
      }
      ++degree[v];
    }
  }
  for (std::size_t v = 0; v < n; ++v) {
    if (degree[v] == 0) continue;
    const bool required = !mesh.required.empty() && mesh.required[v];
    if (degree[v] != 2 || flavour[v][0] != flavour[v][1] || tag[v][0] != tag[v][1] || required) {
      kind[v] = Point_kind::corner;
      continue;
    }
    if (mesh.geometry && mesh.geometry->is_curved(tag[v][0])) {
      // On a curve: a corner only where the polygon turns by more than the corner angle.
      curved[v] = 1;
      const Vec2 &u = mesh.points[neighbour[v][0]], &p = mesh.points[v], &w = mesh.points[neighbour[v][1]];
      const double ax = p[0] - u[0], ay = p[1] - u[1], bx = w[0] - p[0], by = w[1] - p[1];
      const double turn = std::atan2(std::abs(ax * by - ay * bx), ax * bx + ay * by) * 57.295779513082320876;  // degrees
      kind[v] = turn > mesh.geometry->corner_angle ? Point_kind::corner : Point_kind::boundary;
      continue;
    }
    kind[v] = runs_straight_through(mesh.points[neighbour[v][0]], mesh.points[v], mesh.points[neighbour[v][1]])
                  ? Point_kind::boundary
                  : Point_kind::corner;
  }
  // Straight vertex by vertex is not enough: a chain of many such vertices can
  // bend slowly (a finely sampled hull or arc), and a step may replace all of it
  // by one piece. So every chain between corners must be straight as a whole:
  // the vertex farthest from the line through the chain's ends becomes a corner
  // while it is farther than the tolerance (Douglas-Peucker). A step then moves
  // the boundary by at most the tolerance, however long the chain.
  std::vector<std::uint8_t> visited(n, 0);
  std::vector<Index> chain, side;
  std::vector<std::pair<std::size_t, std::size_t>> pending;
  for (std::size_t v0 = 0; v0 < n; ++v0) {
    if (kind[v0] != Point_kind::boundary || visited[v0]) continue;
    // the chain through v0, from corner to corner (or a loop without one)
    auto walk = [&](Index from, Index to, std::vector<Index>& out) {
      out.clear();
      while (kind[to] == Point_kind::boundary && to != static_cast<Index>(v0)) {
        out.push_back(to);
        const Index next = neighbour[to][0] == from ? neighbour[to][1] : neighbour[to][0];
        from = to;
        to = next;
      }
      out.push_back(to);
    };
    walk(static_cast<Index>(v0), neighbour[v0][0], side);
    const bool loop = side.back() == static_cast<Index>(v0);
    if (loop) {  // v0 .. around .. v0: v0 becomes a corner
      chain.assign(1, static_cast<Index>(v0));
      chain.insert(chain.end(), side.begin(), side.end());
      kind[v0] = Point_kind::corner;
    } else {  // corner .. neighbour of v0, v0, other neighbour .. corner
      chain.assign(side.rbegin(), side.rend());
      chain.push_back(static_cast<Index>(v0));
      walk(static_cast<Index>(v0), neighbour[v0][1], side);
      chain.insert(chain.end(), side.begin(), side.end());
    }
    for (Index v : chain) visited[v] = 1;
    if (curved[v0]) continue;  // a curve: its geometry, not straightness, decides
    double reach = 0;
    for (Index v : chain) reach = std::max({reach, std::abs(mesh.points[v][0]), std::abs(mesh.points[v][1])});
    const double tolerance = kStraightUlps * std::numeric_limits<double>::epsilon() * reach;
    pending.assign(1, {0, chain.size() - 1});
    while (!pending.empty()) {
      const auto [lo, hi] = pending.back();
      pending.pop_back();
      if (hi <= lo + 1) continue;
      const Vec2& a = mesh.points[chain[lo]];
      const Vec2& b = mesh.points[chain[hi]];
      const double dx = b[0] - a[0], dy = b[1] - a[1];
      const double length = std::hypot(dx, dy);
      std::size_t far = lo;
      double far_distance = 0;
      for (std::size_t k = lo + 1; k < hi; ++k) {
        const Vec2& q = mesh.points[chain[k]];
        const double d = length > 0 ? std::abs(dx * (q[1] - a[1]) - dy * (q[0] - a[0])) / length
                                    : std::hypot(q[0] - a[0], q[1] - a[1]);
        if (d > far_distance) {
          far_distance = d;
          far = k;
        }
      }
      if (far_distance <= tolerance && length > 0) continue;
      kind[chain[far]] = Point_kind::corner;
      pending.push_back({lo, far});
      pending.push_back({far, hi});
    }
  }
  return kind;
}

void check_planar_mesh_cdt(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles) {
  Cdt_strict cdt;
  auto handles = insert_points(cdt, points);
  const auto edges = sorted_edges(triangles);
  try {
    for (std::size_t i = 0; i < edges.size(); ++i) {
      if (i > 0 && edges[i].lo == edges[i - 1].lo && edges[i].hi == edges[i - 1].hi) continue;
      cdt.insert_constraint(handles[edges[i].lo], handles[edges[i].hi]);
    }
  } catch (const Cdt_strict::Intersection_of_constraints_exception&) {
    throw Input_error("mesh edges cross each other (overlapping or inverted triangles)");
  }
  for (std::size_t t = 0; t < triangles.size(); ++t) {
    const auto& tri = triangles[t];
    if (!cdt.is_face(handles[tri[0]], handles[tri[1]], handles[tri[2]])) {
      throw Input_error("triangle " + std::to_string(t) +
                        " overlaps other triangles or contains a point (not a planar triangulation)");
    }
  }
}

void check_planar_mesh(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                       const std::vector<Edge>& boundary) {
  // Why this decides what check_planar_mesh_cdt decides (for meshes without
  // orphan points), given its preconditions: every triangle counter-clockwise,
  // every edge in at most two triangles, an interior edge in opposite directions
  // in its two triangles, and `boundary` the edges of one triangle each, in that
  // triangle's direction.
  //  * The number of triangles covering a point y off the edges, deg(y), is the
  //    winding number of the boundary edges around y: it changes by exactly one
  //    across a boundary edge (its triangle on the left) and not at all across an
  //    interior edge (one triangle on each side), and is 0 far away. It is
  //    constant on each face of a triangulation of the boundary alone, so a flood
  //    fill of that triangulation gives it everywhere, exactly.
  //  * deg <= 1 everywhere means no two triangles share interior points. Then no
  //    vertex w lies inside a triangle T, or on the interior of an interior edge
  //    of T, or at another vertex's place unless both lie on the boundary: w's
  //    own triangles (it has some: no orphans) would overlap T or the vertex's
  //    triangles near w. What is left, a boundary vertex on a boundary edge or
  //    at another boundary vertex, and boundary edges crossing each other, is
  //    caught by the constrained triangulation of the boundary (split edge,
  //    duplicate, intersection exception). So every triangle is a face of the
  //    constrained triangulation of all edges: the full check passes.
  //  * Conversely a planar mesh passes each step here (deg is 0 or 1, boundary
  //    edges meet only at shared ends).
  // Everything is exact: CGAL's exact orientation predicates, and deg is integer.
  const std::size_t n = points.size();
  std::vector<Index> local(n, -1);
  for (const auto& t : triangles) {
    for (Index v : t) local[static_cast<std::size_t>(v)] = 0;
  }
  for (std::size_t v = 0; v < n; ++v) {
    if (local[v] < 0) throw Input_error("point " + std::to_string(v) + " is not used by any triangle (orphan point)");
  }
  std::fill(local.begin(), local.end(), -1);
  std::vector<std::pair<Point_2, Index>> input;
  for (const auto& e : boundary) {
    for (Index v : e) {
      if (local[static_cast<std::size_t>(v)] >= 0) continue;
      local[static_cast<std::size_t>(v)] = static_cast<Index>(input.size());
      input.emplace_back(to_cgal(points[static_cast<std::size_t>(v)]), static_cast<Index>(input.size()));
    }
  }
  // A closed oriented mesh of positive triangles cannot exist (deg would be 0
  // everywhere), nor can one with all boundary points on a line.
  const auto not_planar = []() {
    return Input_error("triangles overlap: the mesh covers part of the plane more than once (not a planar triangulation)");
  };
  Cdt_strict cdt;
  cdt.insert(input.begin(), input.end());
  if (cdt.number_of_vertices() != input.size()) throw Input_error("points contain duplicates");
  if (cdt.dimension() < 2) throw not_planar();
  std::vector<Cdt_strict::Vertex_handle> handle(input.size());
  for (auto v = cdt.finite_vertices_begin(); v != cdt.finite_vertices_end(); ++v) handle[v->info()] = v;
  try {
    for (const auto& e : boundary) {
      cdt.insert_constraint(handle[local[e[0]]], handle[local[e[1]]]);
    }
  } catch (const Cdt_strict::Intersection_of_constraints_exception&) {
    throw Input_error("mesh edges cross each other (overlapping or inverted triangles)");
  }
  // Boundary edges by their first point (local indices), to tell a constrained
  // edge's direction.
  std::vector<std::size_t> out_start(input.size() + 1, 0);
  for (const auto& e : boundary) ++out_start[local[e[0]] + 1];
  for (std::size_t v = 0; v < input.size(); ++v) out_start[v + 1] += out_start[v];
  std::vector<Index> out_target(boundary.size());
  {
    std::vector<std::size_t> next(out_start.begin(), out_start.end() - 1);
    for (const auto& e : boundary) out_target[next[local[e[0]]]++] = local[e[1]];
  }
  const auto is_boundary_edge = [&](Index a, Index b) {
    for (std::size_t k = out_start[a]; k < out_start[a + 1]; ++k) {
      if (out_target[k] == b) return true;
    }
    return false;
  };
  for (const auto& e : boundary) {
    if (!cdt.is_edge(handle[local[e[0]]], handle[local[e[1]]])) {
      throw Input_error("a point lies on boundary edge " + edge_name(e[0], e[1]) +
                        " (overlapping or touching triangles: not a planar triangulation)");
    }
  }
  // deg of every face, flood-filled from the infinite faces (deg 0).
  constexpr Index unknown = std::numeric_limits<Index>::min();
  for (auto f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f) f->info() = unknown;
  std::vector<Cdt_strict::Face_handle> stack{cdt.infinite_face()};
  cdt.infinite_face()->info() = 0;
  while (!stack.empty()) {
    const auto f = stack.back();
    stack.pop_back();
    for (int i = 0; i < 3; ++i) {
      const auto g = f->neighbor(i);
      Index expected = f->info();
      if (f->is_constrained(i)) {
        // f lies on the left of a -> b.
        const Index a = f->vertex(Cdt_strict::ccw(i))->info();
        const Index b = f->vertex(Cdt_strict::cw(i))->info();
        expected += is_boundary_edge(a, b) ? -1 : 1;
      }
      if (cdt.is_infinite(g) && expected != 0) throw not_planar();
      if (g->info() == unknown) {
        if (expected < 0) throw not_planar();
        if (expected > 1) {
          const auto c = CGAL::centroid(g->vertex(0)->point(), g->vertex(1)->point(), g->vertex(2)->point());
          throw Input_error("triangles overlap: the mesh covers the plane " + std::to_string(expected) +
                            " times near (" + std::to_string(c.x()) + ", " + std::to_string(c.y()) +
                            ") (not a planar triangulation)");
        }
        g->info() = expected;
        stack.push_back(g);
      } else if (g->info() != expected) {
        throw not_planar();
      }
    }
  }
}

namespace {

// The checks below run over blocks of triangles in parallel; each block keeps
// its first hit of every kind, and the least over blocks is the first overall
// (the same for any thread count). Indices are checked as they are read.
constexpr std::size_t kLimitBlock = std::size_t{1} << 15;

template <std::size_t K, class Hit>
std::array<Index, K> first_triangles_where(const Vec2* points, std::size_t n, const Triangle* triangles, std::size_t m,
                                           Hit hit) {
  const std::size_t blocks = (m + kLimitBlock - 1) / kLimitBlock;
  std::vector<std::array<Index, K>> first(blocks);
  std::vector<char> out_of_range(blocks, 0);
  parallel_for(blocks, /*threads=*/0, [&](std::size_t b) {
    std::array<Index, K> mine;
    mine.fill(-1);
    for (std::size_t t = b * kLimitBlock; t < std::min(m, (b + 1) * kLimitBlock); ++t) {
      const Triangle& tri = triangles[t];
      if (static_cast<std::uint64_t>(tri[0]) >= n || static_cast<std::uint64_t>(tri[1]) >= n ||
          static_cast<std::uint64_t>(tri[2]) >= n) {
        out_of_range[b] = 1;
        break;
      }
      const std::array<bool, K> is = hit(points[tri[0]], points[tri[1]], points[tri[2]]);
      for (std::size_t k = 0; k < K; ++k) {
        if (is[k] && mine[k] < 0) mine[k] = static_cast<Index>(t);
      }
    }
    first[b] = mine;
  });
  for (char bad : out_of_range) {
    if (bad) throw Input_error("triangles has a point index out of range [0, " + std::to_string(n) + ")");
  }
  std::array<Index, K> out;
  out.fill(-1);
  for (const auto& f : first) {
    for (std::size_t k = 0; k < K; ++k) {
      if (out[k] < 0) out[k] = f[k];
    }
  }
  return out;
}

}  // namespace

std::array<Index, 2> first_flat_triangles(const Vec2* points, std::size_t n, const Triangle* triangles, std::size_t m,
                                          double min_relative_height, double min_height_ulps) {
  // The arithmetic of Python's _check_not_flat, operation for operation (no
  // fused multiply-add on the default x86-64 target), so both decide alike.
  const double eps = std::numeric_limits<double>::epsilon();
  return first_triangles_where<2>(points, n, triangles, m, [&](const Vec2& p0, const Vec2& p1, const Vec2& p2) {
    const double e0x = p1[0] - p0[0], e0y = p1[1] - p0[1];
    const double e1x = p2[0] - p1[0], e1y = p2[1] - p1[1];
    const double e2x = p0[0] - p2[0], e2y = p0[1] - p2[1];
    const double l0 = e0x * e0x + e0y * e0y, l1 = e1x * e1x + e1y * e1y, l2 = e2x * e2x + e2y * e2y;
    // numpy's max: NaN wins (cannot occur for finite points)
    const double longest = std::sqrt(std::max(std::max(l0, l1), l2));
    const double twice_area = e0x * e2y - e0y * e2x;
    const double height = std::abs(twice_area) / longest;
    const double reach = std::max({std::abs(p0[0]), std::abs(p0[1]), std::abs(p1[0]), std::abs(p1[1]),
                                   std::abs(p2[0]), std::abs(p2[1])});
    const double rounding = eps * reach;
    return std::array<bool, 2>{height < min_relative_height * longest, height < min_height_ulps * rounding};
  });
}

std::array<Index, 2> first_pinched_boundary(const std::vector<Vec2>& points, const std::vector<Edge>& boundary,
                                            const std::vector<char>& corner, double min_ulps) {
  constexpr double eps = std::numeric_limits<double>::epsilon();
  std::vector<Index> vertex;  // the boundary corners, each once
  {
    std::vector<char> seen(points.size(), 0);
    for (const auto& e : boundary) {
      for (Index v : e) {
        if (!seen[static_cast<std::size_t>(v)] && corner[static_cast<std::size_t>(v)]) vertex.push_back(v);
        seen[static_cast<std::size_t>(v)] = 1;
      }
    }
  }
  std::vector<Vec2> local(vertex.size());
  for (std::size_t k = 0; k < vertex.size(); ++k) local[k] = points[static_cast<std::size_t>(vertex[k])];
  if (local.empty()) return {-1, -1};
  std::vector<Vec2> tree_points;
  const nd::Static_kd_tree<2> tree(local, 8, tree_points);
  const auto& point_at = tree.point_at();
  const auto reach_of = [](const Vec2& p) { return std::max(std::abs(p[0]), std::abs(p[1])); };
  for (std::size_t s = 0; s < boundary.size(); ++s) {
    const Vec2& a = points[static_cast<std::size_t>(boundary[s][0])];
    const Vec2& b = points[static_cast<std::size_t>(boundary[s][1])];
    const double dx = b[0] - a[0], dy = b[1] - a[1];
    const double length = std::hypot(dx, dy);
    const double reach_ab = std::max(reach_of(a), reach_of(b));
    Index best = -1;
    double best_ratio = min_ulps;
    tree.depth_first(1, [&](std::size_t m, nd::Kd_stack& stack) {
      const nd::Box<2>& box = tree.node(m);
      // Generous pruning (twice the tolerance at the box's largest coordinate):
      // it must never skip a point that the exact test below would report.
      const double reach = std::max({reach_ab, std::abs(box.lo[0]), std::abs(box.hi[0]), std::abs(box.lo[1]),
                                     std::abs(box.hi[1])});
      const double slack = 2 * min_ulps * eps * reach;
      if (box.lo[0] > std::max(a[0], b[0]) + slack || box.hi[0] < std::min(a[0], b[0]) - slack ||
          box.lo[1] > std::max(a[1], b[1]) + slack || box.hi[1] < std::min(a[1], b[1]) - slack) {
        return false;
      }
      if (length > 0) {  // the box's corners against the edge's line
        double lo = std::numeric_limits<double>::infinity(), hi = -lo;
        for (double x : {box.lo[0], box.hi[0]}) {
          for (double y : {box.lo[1], box.hi[1]}) {
            const double side = (dx * (y - a[1]) - dy * (x - a[0])) / length;
            lo = std::min(lo, side);
            hi = std::max(hi, side);
          }
        }
        if (lo > slack || hi < -slack) return false;
      }
      if (!tree.is_leaf(m)) {
        stack.push_children(m);
        return false;
      }
      const std::size_t leaf = tree.leaf(m);
      for (std::size_t k = tree.leaf_begin(leaf); k < tree.leaf_begin(leaf + 1); ++k) {
        const Index v = vertex[point_at[k]];
        if (v == boundary[s][0] || v == boundary[s][1]) continue;
        const Vec2& q = tree_points[k];
        const double rounding = eps * std::max(reach_ab, reach_of(q));
        const double ratio = distance_to_segment(q, a, b) / rounding;
        if (ratio < best_ratio || (ratio == best_ratio && best >= 0 && v < best)) {
          best_ratio = ratio;
          best = v;
        }
      }
      return false;
    });
    if (best >= 0) return {static_cast<Index>(s), best};
  }
  return {-1, -1};
}

Index first_inverted_triangle(const Vec2* points, std::size_t n, const Triangle* triangles, std::size_t m) {
  // Python's check_mesh_limits, operation for operation (as first_flat_triangles).
  return first_triangles_where<1>(points, n, triangles, m, [](const Vec2& p0, const Vec2& p1, const Vec2& p2) {
    const double d1x = p1[0] - p0[0], d1y = p1[1] - p0[1];
    const double d2x = p2[0] - p0[0], d2y = p2[1] - p0[1];
    return std::array<bool, 1>{!(d1x * d2y - d1y * d2x > 0)};
  })[0];
}

namespace {

// Whether the pieces (a, b) and (c, d) cross: their interiors meet at one point
// (all four orientations non-zero), or they overlap along a line beyond a shared
// end. Exact predicates; a piece through an end of the other is no crossing
// (CGAL's triangulation splits it there).
bool pieces_cross(const std::vector<Vec2>& points, const Constraint_piece& p, const Constraint_piece& q) {
  const Vec2 &a = points[p.a], &b = points[p.b], &c = points[q.a], &d = points[q.b];
  const int c_side = orientation(a, b, c), d_side = orientation(a, b, d);
  const int a_side = orientation(c, d, a), b_side = orientation(c, d, b);
  if (c_side != 0 || d_side != 0) return c_side * d_side < 0 && a_side * b_side < 0;
  // collinear: an overlap of positive length (a shared end alone is none)
  const auto along = [&](const Vec2& x) {
    return (x[0] - a[0]) * (b[0] - a[0]) + (x[1] - a[1]) * (b[1] - a[1]);
  };
  const double length2 = along(b);
  const double lo = std::max(0.0, std::min(along(c), along(d))), hi = std::min(length2, std::max(along(c), along(d)));
  return hi > lo;
}

// Whether an end of q that is no end of p lies inside p (exact): a piece
// through a point of another, which a constrained triangulation splits there.
bool end_inside(const std::vector<Vec2>& points, const Constraint_piece& p, const Constraint_piece& q) {
  const Vec2 &a = points[p.a], &b = points[p.b];
  for (const Index e : {q.a, q.b}) {
    if (e == p.a || e == p.b) continue;
    const Vec2& c = points[e];
    if (orientation(a, b, c) != 0 || c == a || c == b) continue;
    const bool within_x = std::min(a[0], b[0]) <= c[0] && c[0] <= std::max(a[0], b[0]);
    const bool within_y = std::min(a[1], b[1]) <= c[1] && c[1] <= std::max(a[1], b[1]);
    if (within_x && within_y) return true;
  }
  return false;
}

double distance_to_piece(const Vec2& q, const Vec2& a, const Vec2& b) {
  const double dx = b[0] - a[0], dy = b[1] - a[1];
  const double length2 = dx * dx + dy * dy;
  const double t = length2 > 0 ? std::clamp(((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / length2, 0.0, 1.0) : 0.0;
  return std::hypot(q[0] - a[0] - t * dx, q[1] - a[1] - t * dy);
}

std::string at_point(const Vec2& x) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "(%.6g, %.6g)", x[0], x[1]);
  return buffer;
}

}  // namespace

std::vector<std::array<Index, 2>> meeting_pieces(const std::vector<Vec2>& points,
                                                 const std::vector<Constraint_piece>& pieces, bool touching) {
  const std::size_t m = pieces.size();
  std::vector<std::array<Index, 2>> pairs;
  if (m < 2) return pairs;
  // A uniform grid of cells about the mean piece length (at most about 4 m
  // cells): each piece is tested against the pieces sharing a cell with its box.
  double lo_x = std::numeric_limits<double>::infinity(), lo_y = lo_x, hi_x = -lo_x, hi_y = -lo_x, total = 0;
  for (const auto& piece : pieces) {
    const Vec2 &a = points[piece.a], &b = points[piece.b];
    lo_x = std::min({lo_x, a[0], b[0]});
    hi_x = std::max({hi_x, a[0], b[0]});
    lo_y = std::min({lo_y, a[1], b[1]});
    hi_y = std::max({hi_y, a[1], b[1]});
    total += std::hypot(b[0] - a[0], b[1] - a[1]);
  }
  const double extent = std::max(hi_x - lo_x, hi_y - lo_y);
  const double limit = 2 * std::sqrt(static_cast<double>(m)) + 1;
  const double cell = std::max({total / static_cast<double>(m), extent / limit, std::numeric_limits<double>::min()});
  const auto column = [&](double x, double lo) {
    return static_cast<std::size_t>(std::min(limit, std::max(0.0, std::floor((x - lo) / cell))));
  };
  const std::size_t nx = column(hi_x, lo_x) + 1, ny = column(hi_y, lo_y) + 1;
  std::vector<std::vector<Index>> in_cell(nx * ny);
  for (std::size_t k = 0; k < m; ++k) {
    const Vec2 &a = points[pieces[k].a], &b = points[pieces[k].b];
    for (std::size_t i = column(std::min(a[0], b[0]), lo_x); i <= column(std::max(a[0], b[0]), lo_x); ++i) {
      for (std::size_t j = column(std::min(a[1], b[1]), lo_y); j <= column(std::max(a[1], b[1]), lo_y); ++j) {
        in_cell[i * ny + j].push_back(static_cast<Index>(k));
      }
    }
  }
  for (const auto& here : in_cell) {
    for (std::size_t x = 0; x < here.size(); ++x) {
      for (std::size_t y = x + 1; y < here.size(); ++y) {
        const std::array<Index, 2> pair{std::min(here[x], here[y]), std::max(here[x], here[y])};
        const Constraint_piece &p = pieces[pair[0]], &q = pieces[pair[1]];
        if (pieces_cross(points, p, q) || (touching && (end_inside(points, p, q) || end_inside(points, q, p)))) {
          pairs.push_back(pair);
        }
      }
    }
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  return pairs;
}

std::array<Index, 2> first_crossing_pieces(const std::vector<Vec2>& points, const std::vector<Constraint_piece>& pieces) {
  const auto pairs = meeting_pieces(points, pieces, /*touching=*/false);
  return pairs.empty() ? std::array<Index, 2>{-1, -1} : pairs.front();
}

Input_error crossing_pieces_error(const std::vector<Vec2>& points, const std::vector<Constraint_piece>& pieces) {
  const auto pair = first_crossing_pieces(points, pieces);
  if (pair[0] < 0) {
    return Input_error("two constraint pieces of the step's mesh cross (CGAL found it; the exact search for the pair "
                       "did not): its boundary or interior segments are nearly degenerate here");
  }
  const Constraint_piece &p = pieces[pair[0]], &q = pieces[pair[1]];
  const Vec2 &a = points[p.a], &b = points[p.b], &c = points[q.a], &d = points[q.b];
  // How deep they cross: the least distance of an end to the other piece (an
  // end within rounding of the other piece: a float64 limit; else geometry).
  const double depth = std::min({distance_to_piece(a, c, d), distance_to_piece(b, c, d), distance_to_piece(c, a, b),
                                 distance_to_piece(d, a, b)});
  const double reach = std::max({std::abs(a[0]), std::abs(a[1]), std::abs(b[0]), std::abs(b[1]), std::abs(c[0]),
                                 std::abs(c[1]), std::abs(d[0]), std::abs(d[1])});
  const double longest = std::max(std::hypot(b[0] - a[0], b[1] - a[1]), std::hypot(d[0] - c[0], d[1] - c[1]));
  const std::string pieces_named = "the piece " + at_point(a) + " - " + at_point(b) + " (segment tag " +
                                   std::to_string(p.tag) + ") and the piece " + at_point(c) + " - " + at_point(d) +
                                   " (segment tag " + std::to_string(q.tag) + ")";
  if (depth <= 64 * std::numeric_limits<double>::epsilon() * reach) {
    return Input_error("two constraint pieces of the step's mesh cross within rounding: " + pieces_named +
                       "; the boundary or interior segments are closer to degenerate than float64 resolves here (a "
                       "corner within rounding of a segment, or segments meeting at an angle of a few units of "
                       "rounding)");
  }
  return Input_error("two constraint pieces of the step's mesh cross: " + pieces_named + ", pieces of length up to " +
                     format_count(longest) + " whose ends come within " + format_count(depth) +
                     " of the other piece: the constraints there are closer together than the step's spacing "
                     "resolves (a strip between two constraints, or a fold of one, narrower than the spacing); ask "
                     "for a spacing below " + format_count(depth) + " there");
}

// The canonical order (triangulation.hpp): a counting sort on the first
// index, O(n + m), then each bucket's few triangles. An array already in that
// order (a triangulation's output that a step passes on) costs one scan, and one
// with a few triangles out of place (a step's kept triangles, renumbered where a
// few points moved in the point order) two scans and a merge: the triangles out
// of place are set aside, sorted and merged back; else the counting sort.
std::vector<Index> canonical_triangle_order(std::size_t n_points, std::vector<Triangle>& triangles) {
  const std::size_t m = triangles.size();
  std::size_t descents = 0;
  for (std::size_t k = 0; k < m; ++k) {
    triangles[k] = least_index_first(triangles[k]);
    descents += k > 0 && !(triangles[k - 1] < triangles[k]);
  }
  std::vector<Index> order(m);
  if (descents == 0) {
    for (std::size_t k = 0; k < m; ++k) order[k] = static_cast<Index>(k);
    return order;
  }
  auto apply = [&triangles](const std::vector<Index>& by) {
    std::vector<Triangle> sorted(by.size());
    for (std::size_t k = 0; k < by.size(); ++k) sorted[k] = triangles[by[k]];
    triangles = std::move(sorted);
  };
  if (descents <= m / 256) {
    // One pass keeps an increasing run in place and sets aside what does not fit.
    const auto less = [&triangles](Index a, Index b) { return triangles[a] < triangles[b]; };
    std::vector<Index> in_place, out_of_place;
    in_place.reserve(m);
    for (std::size_t k = 0; k < m; ++k) detail::extend_increasing_run(in_place, out_of_place, static_cast<Index>(k), less);
    if (out_of_place.size() <= m / 64) {
      std::sort(out_of_place.begin(), out_of_place.end(), less);
      std::merge(in_place.begin(), in_place.end(), out_of_place.begin(), out_of_place.end(), order.begin(), less);
      apply(order);
      return order;
    }
  }
  std::vector<std::size_t> start(n_points + 1, 0);
  for (const Triangle& t : triangles) ++start[static_cast<std::size_t>(t[0]) + 1];
  for (std::size_t v = 0; v < n_points; ++v) start[v + 1] += start[v];
  std::vector<std::size_t> next(start.begin(), start.end() - 1);
  for (std::size_t k = 0; k < m; ++k) order[next[static_cast<std::size_t>(triangles[k][0])]++] = static_cast<Index>(k);
  for (std::size_t v = 0; v < n_points; ++v) {
    if (start[v + 1] - start[v] < 2) continue;
    std::sort(order.begin() + static_cast<std::ptrdiff_t>(start[v]), order.begin() + static_cast<std::ptrdiff_t>(start[v + 1]),
              [&](Index a, Index b) { return triangles[a] < triangles[b]; });
  }
  apply(order);
  return order;
}

namespace {

// The points, then the pieces as constraints (crossing_pieces_error() when two cross); the vertex of every point.
std::vector<Cdt::Vertex_handle> insert_points_and_pieces(Cdt& cdt, const std::vector<Vec2>& points,
                                                         const std::vector<Constraint_piece>& pieces) {
  auto handles = insert_points(cdt, points);
  try {
    for (const auto& piece : pieces) cdt.insert_constraint(handles[piece.a], handles[piece.b]);
  } catch (const Cdt::Intersection_of_constraints_exception&) {
    throw crossing_pieces_error(points, pieces);
  }
  return handles;
}

}  // namespace

std::vector<Triangle> constrained_delaunay(const std::vector<Vec2>& points,
                                           const std::vector<Constraint_piece>& pieces) {
  Cdt cdt;
  const auto handles = insert_points_and_pieces(cdt, points, pieces);
  detail::label_domain(cdt, handles, pieces, "constrained_delaunay");
  std::vector<Triangle> triangles;
  triangles.reserve(cdt.number_of_faces());
  for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
    if (f->info() == detail::domain_inside) triangles.push_back({f->vertex(0)->info(), f->vertex(1)->info(), f->vertex(2)->info()});
  }
  canonical_triangle_order(points.size(), triangles);
  return triangles;
}

Local_triangulation local_constrained_delaunay(const std::vector<Vec2>& points,
                                               const std::vector<Constraint_piece>& pieces) {
  Cdt cdt;
  const auto handles = insert_points_and_pieces(cdt, points, pieces);
  Local_triangulation out;
  if (cdt.dimension() < 2) return out;
  Index m = 0;
  for (auto f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f) f->info() = -1;
  for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
    f->info() = m++;
    out.triangles.push_back({f->vertex(0)->info(), f->vertex(1)->info(), f->vertex(2)->info()});
  }
  out.neighbour.resize(out.triangles.size());
  out.constrained.assign(out.triangles.size(), 0);
  out.seed.assign(out.triangles.size(), 0);
  for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
    for (int k = 0; k < 3; ++k) {
      out.neighbour[f->info()][k] = f->neighbor(k)->info();
      if (f->is_constrained(k)) out.constrained[f->info()] |= static_cast<std::uint8_t>(1u << k);
    }
  }
  // (label_domain's seeds, detail/domain.hpp; a piece through a point on it is skipped there too)
  for (const auto& piece : pieces) {
    Cdt::Face_handle f;
    int i;
    if (!cdt.is_edge(handles[piece.a], handles[piece.b], f, i)) continue;
    Cdt::Face_handle left = f, right = f->neighbor(i);
    if (f->vertex(Cdt::ccw(i)) != handles[piece.a]) std::swap(left, right);
    if (left->info() >= 0) out.seed[left->info()] |= 1;
    if (right->info() >= 0) out.seed[right->info()] |= piece.boundary ? 2 : 1;
  }
  // Canonical order: each face rotated to its least index (its per-corner
  // arrays with it), then canonical_triangle_order's sort.
  const std::size_t n_faces = out.triangles.size();
  for (std::size_t t = 0; t < n_faces; ++t) {
    const Triangle tri = out.triangles[t];
    const int r = tri[1] < tri[0] && tri[1] < tri[2] ? 1 : (tri[2] < tri[0] && tri[2] < tri[1] ? 2 : 0);
    const std::array<Index, 3> nb = out.neighbour[t];
    const std::uint8_t bits = out.constrained[t];
    out.constrained[t] = 0;
    for (int k = 0; k < 3; ++k) {
      out.triangles[t][k] = tri[(k + r) % 3];
      out.neighbour[t][k] = nb[(k + r) % 3];
      out.constrained[t] |= static_cast<std::uint8_t>(((bits >> ((k + r) % 3)) & 1u) << k);
    }
  }
  const std::vector<Index> order = canonical_triangle_order(points.size(), out.triangles);
  std::vector<Index> position(n_faces);
  for (std::size_t k = 0; k < n_faces; ++k) position[order[k]] = static_cast<Index>(k);
  Local_triangulation sorted;
  sorted.triangles = std::move(out.triangles);
  sorted.neighbour.resize(n_faces);
  sorted.constrained.resize(n_faces);
  sorted.seed.resize(n_faces);
  for (std::size_t k = 0; k < n_faces; ++k) {
    const Index t = order[k];
    sorted.constrained[k] = out.constrained[t];
    sorted.seed[k] = out.seed[t];
    for (int c = 0; c < 3; ++c) {
      const Index g = out.neighbour[t][c];
      sorted.neighbour[k][c] = g < 0 ? -1 : position[g];
    }
  }
  return sorted;
}

std::vector<Index> convex_hull_vertices(const std::vector<Vec2>& points) {
  std::vector<Index> all(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) all[i] = static_cast<Index>(i);
  // (CGAL's traits adapted to indices: the points compared through the exact kernel)
  using Traits = CGAL::Convex_hull_traits_adapter_2<Kernel, CGAL::Pointer_property_map<Kernel::Point_2>::type>;
  std::vector<Kernel::Point_2> cgal(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) cgal[i] = to_cgal(points[i]);
  std::vector<std::size_t> in(points.size()), out;
  for (std::size_t i = 0; i < points.size(); ++i) in[i] = i;
  CGAL::convex_hull_2(in.begin(), in.end(), std::back_inserter(out), Traits(CGAL::make_property_map(cgal)));
  std::vector<Index> hull(out.begin(), out.end());
  return hull;
}

std::vector<std::uint8_t> supports_on_left(const std::vector<Vec2>& a, const std::vector<Vec2>& b,
                                           const std::vector<Vec2>& points) {
  std::vector<std::uint8_t> ok(a.size(), 1);
  for (std::size_t k = 0; k < a.size(); ++k) {
    for (const Vec2& q : points) {
      if (orientation(a[k], b[k], q) < 0) {
        ok[k] = 0;
        break;
      }
    }
  }
  return ok;
}

double distance_to_segment(const Vec2& q, const Vec2& a, const Vec2& b) {
  const double dx = b[0] - a[0], dy = b[1] - a[1];
  const double along = std::clamp(((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / (dx * dx + dy * dy), 0.0, 1.0);
  return std::hypot(q[0] - a[0] - along * dx, q[1] - a[1] - along * dy);
}

double distance_to_triangle(const std::vector<Vec2>& points, const Triangle& t, const Vec2& q) {
  double gap = 0;
  for (int e = 0; e < 3; ++e) {
    const Vec2& a = points[t[e]];
    const Vec2& b = points[t[(e + 1) % 3]];
    if (orientation(a, b, q) < 0) gap = std::max(gap, distance_to_segment(q, a, b));
  }
  return gap;
}

std::array<double, 3> barycentric_coordinates(const std::vector<Vec2>& points, const Triangle& t, const Vec2& q) {
  const Vec2& a = points[t[0]];
  const Vec2& b = points[t[1]];
  const Vec2& c = points[t[2]];
  const double det = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
  const double l1 = ((q[0] - a[0]) * (c[1] - a[1]) - (q[1] - a[1]) * (c[0] - a[0])) / det;
  const double l2 = ((b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0])) / det;
  return {1.0 - l1 - l2, l1, l2};
}

double boundary_rounding(double reach) {
  return (16 + kStraightUlps) * std::numeric_limits<double>::epsilon() * reach;
}

void locate_points(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                   const std::vector<Vec2>& queries, std::vector<Index>& triangle_out,
                   std::vector<std::array<double, 3>>& barycentric_out) {
  Cdt cdt;
  auto handles = insert_points(cdt, points);
  {
    // Every edge once, in (lo, hi) order, straight from the buckets (sorted_edges'
    // order without its 16-byte records: the same constraints in the same order).
    const Edge_buckets buckets = edge_buckets(triangles);
    for (std::size_t v = 0; v < buckets.n_buckets(); ++v) {
      for (std::size_t k = buckets.start[v]; k < buckets.start[v + 1]; ++k) {
        if (k > buckets.start[v] && buckets.entries[k].hi == buckets.entries[k - 1].hi) continue;
        cdt.insert_constraint(handles[v], handles[buckets.entries[k].hi]);
      }
    }
  }
  for (auto f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f) f->info() = -1;
  for (std::size_t t = 0; t < triangles.size(); ++t) {
    Cdt::Face_handle f;
    if (!cdt.is_face(handles[triangles[t][0]], handles[triangles[t][1]], handles[triangles[t][2]], f)) {
      throw Input_error("triangle " + std::to_string(t) + " is not a face of the mesh's triangulation");
    }
    f->info() = static_cast<Index>(t);
  }
  // Of candidate faces, the mesh triangle nearest q (q inside it: distance 0).
  // Distances, not barycentric coordinates, which are scale-free: in a sliver a
  // point on an edge has coordinates off by far more than the point is.
  auto best_of = [&](const std::vector<Cdt::Face_handle>& faces, const Vec2& q, double& best_gap) {
    Index best = -1;
    best_gap = std::numeric_limits<double>::infinity();
    for (auto f : faces) {
      if (f->info() < 0) continue;
      const double gap = distance_to_triangle(points, triangles[f->info()], q);
      if (gap < best_gap) {
        best_gap = gap;
        best = f->info();
      }
    }
    return best;
  };
  const std::size_t k = queries.size();
  triangle_out.assign(k, -1);
  barycentric_out.assign(k, {0, 0, 0});
  Cdt::Face_handle hint;
  std::vector<Cdt::Face_handle> candidates;
  for (const auto& q : detail::spatial_order(queries, detail::Spatial_order::hilbert)) {
    const std::size_t idx = q.index;
    const Point_2 point(q.x, q.y);
    Cdt::Locate_type lt;
    int li;
    Cdt::Face_handle f = hint == Cdt::Face_handle() ? cdt.locate(point, lt, li) : cdt.locate(point, lt, li, hint);
    hint = f;
    candidates.clear();
    candidates.push_back(f);
    if (lt == Cdt::EDGE) candidates.push_back(f->neighbor(li));
    if (lt == Cdt::VERTEX || f->info() < 0) {
      // On a vertex, or just outside the mesh (a point on a boundary edge up to
      // rounding): consider the triangles around the face's vertices.
      for (int i = 0; i < 3; ++i) {
        if (cdt.is_infinite(f->vertex(i))) continue;
        auto c = cdt.incident_faces(f->vertex(i)), done = c;
        do {
          candidates.push_back(c);
        } while (++c != done);
      }
    }
    double gap = 0;
    Index t = best_of(candidates, queries[idx], gap);
    // Farther outside every nearby triangle than rounding (in units of the
    // coordinates, as for straight chains): outside the mesh.
    if (t >= 0) {
      double reach = std::max(std::abs(queries[idx][0]), std::abs(queries[idx][1]));
      for (Index v : triangles[t]) reach = std::max({reach, std::abs(points[v][0]), std::abs(points[v][1])});
      if (gap > boundary_rounding(reach)) t = -1;
    }
    std::array<double, 3> bary =
        t >= 0 ? barycentric_coordinates(points, triangles[t], queries[idx]) : std::array<double, 3>{0, 0, 0};
    triangle_out[idx] = t;
    if (t >= 0) {
      for (auto& l : bary) l = std::max(l, 0.0);
      const double s = bary[0] + bary[1] + bary[2];
      for (auto& l : bary) l /= s;
      barycentric_out[idx] = bary;
    }
  }
}

}  // namespace evomesh
