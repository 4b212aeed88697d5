#include "evomesh/sampling.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <unordered_set>

#include "evomesh/kernel.hpp"
#include "evomesh/parallel.hpp"

namespace evomesh {

namespace {

std::uint64_t splitmix64(std::uint64_t& x) {
  std::uint64_t z = (x += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

constexpr double kInvTwoSqrtTwo = 0.35355339059327373;  // 1 / (2 sqrt 2)

std::uint64_t edge_key(Index a, Index b, std::size_t n) {
  if (a > b) std::swap(a, b);
  return static_cast<std::uint64_t>(a) * static_cast<std::uint64_t>(n) + static_cast<std::uint64_t>(b);
}

// A convex polygon of at most 8 vertices: a grid cell clipped by the three
// sides of a triangle has at most 4 + 3 vertices.
struct Polygon {
  std::array<Vec2, 8> v;
  std::size_t size = 0;
  void push(const Vec2& p) { v[size++] = p; }
};

// Clips a convex polygon by the half-plane left of a -> b (Sutherland-Hodgman).
// Floating point is fine here: the result only guides where a sample is drawn;
// the sample itself is accepted by an exact predicate.
void clip_left_of(const Polygon& poly, const Vec2& a, const Vec2& b, Polygon& out) {
  out.size = 0;
  const std::size_t n = poly.size;
  auto side = [&](const Vec2& p) {
    return (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
  };
  for (std::size_t i = 0; i < n; ++i) {
    const Vec2& p = poly.v[i];
    const Vec2& q = poly.v[i + 1 == n ? 0 : i + 1];
    const double sp = side(p);
    const double sq = side(q);
    if (sp >= 0 && out.size < out.v.size()) out.push(p);
    if (((sp > 0 && sq < 0) || (sp < 0 && sq > 0)) && out.size < out.v.size()) {
      const double t = sp / (sp - sq);
      out.push({p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])});
    }
  }
}

// Area of the fan from vertex 0; cumulative[i] is the area of triangles 0..i.
double polygon_fan_area(const Polygon& poly, std::array<double, 8>& cumulative) {
  double total = 0;
  for (std::size_t i = 1; i + 1 < poly.size; ++i) {
    const Vec2& a = poly.v[0];
    const Vec2& b = poly.v[i];
    const Vec2& c = poly.v[i + 1];
    const double area = 0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]));
    total += std::max(area, 0.0);
    cumulative[i - 1] = total;
  }
  return total;
}

Vec2 uniform_in_triangle(const Vec2& a, const Vec2& b, const Vec2& c, Random_stream& rng) {
  double u = rng.uniform();
  double v = rng.uniform();
  if (u + v > 1) {
    u = 1 - u;
    v = 1 - v;
  }
  return {a[0] + u * (b[0] - a[0]) + v * (c[0] - a[0]), a[1] + u * (b[1] - a[1]) + v * (c[1] - a[1])};
}

bool strictly_inside(const Vec2& a, const Vec2& b, const Vec2& c, const Vec2& x) {
  return orientation(a, b, x) > 0 && orientation(b, c, x) > 0 && orientation(c, a, x) > 0;
}

Index smallest_f_vertex(const Triangle& t, const std::vector<double>& f) {
  Index q = t[0];
  if (f[t[1]] < f[q]) q = t[1];
  if (f[t[2]] < f[q]) q = t[2];
  return q;
}

}  // namespace

Random_stream::Random_stream(std::uint64_t seed, std::uint64_t stream) {
  std::uint64_t x = seed ^ 0x243f6a8885a308d3ULL;
  state = splitmix64(x) ^ (stream * 0xd1342543de82ef95ULL);
  splitmix64(state);
}

std::uint64_t Random_stream::next() { return splitmix64(state); }

double Random_stream::uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

bool in_cover(const std::vector<Disc>& cover, const Triangle& t, const Vec2& x) {
  if (cover.empty()) return false;
  for (Index v : t) {
    const Disc& d = cover[v];
    const double dx = x[0] - d.center[0], dy = x[1] - d.center[1];
    if (dx * dx + dy * dy < d.radius * d.radius) return true;
  }
  return false;
}

double estimate_sample_count(const Mesh_arrays& mesh, const std::vector<double>& vertex_f,
                             double cell_factor) {
  double total = 0;
  for (const auto& t : mesh.triangles) {
    const double s = cell_factor * vertex_f[smallest_f_vertex(t, vertex_f)] * kInvTwoSqrtTwo;
    double xmin = mesh.points[t[0]][0], xmax = xmin, ymin = mesh.points[t[0]][1], ymax = ymin;
    for (int k = 1; k < 3; ++k) {
      xmin = std::min(xmin, mesh.points[t[k]][0]);
      xmax = std::max(xmax, mesh.points[t[k]][0]);
      ymin = std::min(ymin, mesh.points[t[k]][1]);
      ymax = std::max(ymax, mesh.points[t[k]][1]);
    }
    total += (std::floor((xmax - xmin) / s) + 1) * (std::floor((ymax - ymin) / s) + 1);
  }
  for (const auto& e : mesh.segments) {
    const double s = cell_factor * std::min(vertex_f[e[0]], vertex_f[e[1]]) * kInvTwoSqrtTwo;
    const Vec2& a = mesh.points[e[0]];
    const Vec2& b = mesh.points[e[1]];
    total += std::hypot(b[0] - a[0], b[1] - a[1]) / s + 1;
  }
  return total;
}

namespace {

// The samples of one triangle, appended to `out` unless a vertex covers them.
void sample_one_triangle(const Mesh_arrays& mesh, std::size_t ti, const std::vector<double>& vertex_f,
                         double cell_factor, Sample_mode mode, std::uint64_t seed,
                         const std::unordered_set<std::uint64_t>& segment_edges, const std::vector<Disc>& cover,
                         Sample_set& out, std::size_t& n_drawn) {
  const auto& P = mesh.points;
  const std::size_t n = P.size();
  const Triangle& t = mesh.triangles[ti];
  const Vec2& a = P[t[0]];
  const Vec2& b = P[t[1]];
  const Vec2& c = P[t[2]];
  auto emit = [&](const Vec2& x) {
    ++n_drawn;
    if (in_cover(cover, t, x)) return;
    out.points.push_back(x);
    out.parent.push_back(static_cast<Index>(ti));
  };
  if (mode != Sample_mode::random_grid) {
    if (mode == Sample_mode::barycentre || mode == Sample_mode::barycentre_midpoints) {
      const Vec2 g{(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0};
      if (strictly_inside(a, b, c, g)) emit(g);
    }
    if (mode == Sample_mode::midpoints || mode == Sample_mode::barycentre_midpoints) {
      // An interior edge is shared by two triangles with opposite directions;
      // emit its midpoint from the triangle that has it as (low -> high).
      for (int k = 0; k < 3; ++k) {
        const Index u = t[k];
        const Index v = t[(k + 1) % 3];
        if (u > v || segment_edges.count(edge_key(u, v, n))) continue;
        emit({0.5 * (P[u][0] + P[v][0]), 0.5 * (P[u][1] + P[v][1])});
      }
    }
    return;
  }
  Random_stream rng(seed, ti);
  const double s = cell_factor * vertex_f[smallest_f_vertex(t, vertex_f)] * kInvTwoSqrtTwo;
  const double xmin = std::min({a[0], b[0], c[0]});
  const double xmax = std::max({a[0], b[0], c[0]});
  const double ymin = std::min({a[1], b[1], c[1]});
  const double ymax = std::max({a[1], b[1], c[1]});
  const auto nx = static_cast<std::int64_t>(std::ceil((xmax - xmin) / s));
  const auto ny = static_cast<std::int64_t>(std::ceil((ymax - ymin) / s));
  Polygon poly, clipped;
  std::array<double, 8> cumulative{};
  for (std::int64_t iy = 0; iy < std::max<std::int64_t>(ny, 1); ++iy) {
    const double y0 = ymin + static_cast<double>(iy) * s;
    const double y1 = std::min(ymax, y0 + s);
    for (std::int64_t ix = 0; ix < std::max<std::int64_t>(nx, 1); ++ix) {
      const double x0 = xmin + static_cast<double>(ix) * s;
      const double x1 = std::min(xmax, x0 + s);
      poly.size = 0;
      poly.push({x0, y0});
      poly.push({x1, y0});
      poly.push({x1, y1});
      poly.push({x0, y1});
      clip_left_of(poly, a, b, clipped);
      clip_left_of(clipped, b, c, poly);
      clip_left_of(poly, c, a, clipped);
      if (clipped.size < 3) continue;
      const double area = polygon_fan_area(clipped, cumulative);
      if (!(area > 0)) continue;
      const std::size_t n_fan = clipped.size - 2;
      // A sample strictly inside the triangle (exact test); a few retries cover
      // the rare draw that rounding puts on an edge.
      for (int attempt = 0; attempt < 8; ++attempt) {
        const double pick = rng.uniform() * area;
        std::size_t k = std::lower_bound(cumulative.begin(), cumulative.begin() + n_fan, pick) - cumulative.begin();
        k = std::min(k, n_fan - 1);
        const Vec2 x = uniform_in_triangle(clipped.v[0], clipped.v[k + 1], clipped.v[k + 2], rng);
        if (strictly_inside(a, b, c, x)) {
          emit(x);
          break;
        }
      }
    }
  }
}

}  // namespace

Sample_set sample_triangles(const Mesh_arrays& mesh, const std::vector<double>& vertex_f,
                            double cell_factor, Sample_mode mode, std::uint64_t seed,
                            const std::vector<std::uint8_t>& skip, const std::vector<Disc>& cover, int threads,
                            std::size_t* n_drawn) {
  std::unordered_set<std::uint64_t> segment_edges;
  if (mode == Sample_mode::midpoints || mode == Sample_mode::barycentre_midpoints) {
    segment_edges.reserve(mesh.segments.size() * 2);
    for (const auto& e : mesh.segments) segment_edges.insert(edge_key(e[0], e[1], mesh.points.size()));
  }
  // Fixed blocks of triangles, each with its own output, joined in block order:
  // the samples never depend on the number of threads.
  constexpr std::size_t kBlock = 2048;
  const std::size_t n_triangles = mesh.triangles.size();
  const std::size_t n_blocks = (n_triangles + kBlock - 1) / kBlock;
  std::vector<Sample_set> blocks(n_blocks);
  std::vector<std::size_t> drawn(n_blocks, 0);
  parallel_for(n_blocks, threads, [&](std::size_t k) {
    for (std::size_t ti = k * kBlock; ti < std::min(n_triangles, (k + 1) * kBlock); ++ti) {
      if (!skip.empty() && skip[ti]) continue;
      sample_one_triangle(mesh, ti, vertex_f, cell_factor, mode, seed, segment_edges, cover, blocks[k], drawn[k]);
    }
  });
  Sample_set out;
  std::size_t total = 0, total_drawn = 0;
  for (std::size_t k = 0; k < n_blocks; ++k) {
    total += blocks[k].points.size();
    total_drawn += drawn[k];
  }
  out.points.reserve(total);
  out.parent.reserve(total);
  for (auto& block : blocks) {
    out.points.insert(out.points.end(), block.points.begin(), block.points.end());
    out.parent.insert(out.parent.end(), block.parent.begin(), block.parent.end());
    block = Sample_set();
  }
  if (n_drawn) *n_drawn = total_drawn;
  return out;
}

Sample_set sample_segments(const Mesh_arrays& mesh, const std::vector<double>& vertex_f,
                           double cell_factor, Sample_mode mode, std::uint64_t seed) {
  Sample_set out;
  for (std::size_t k = 0; k < mesh.segments.size(); ++k) {
    const Edge& e = mesh.segments[k];
    const Vec2& a = mesh.points[e[0]];
    const Vec2& b = mesh.points[e[1]];
    const double length = std::hypot(b[0] - a[0], b[1] - a[1]);
    if (mode != Sample_mode::random_grid) {
      out.points.push_back({0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])});
      out.parent.push_back(static_cast<Index>(k));
      continue;
    }
    const double s = cell_factor * std::min(vertex_f[e[0]], vertex_f[e[1]]) * kInvTwoSqrtTwo;
    const auto cells = static_cast<std::int64_t>(std::ceil(length / s));
    if (cells < 2) continue;
    // Stream ids for segments follow the triangles' so the two never share one.
    Random_stream rng(seed, (std::uint64_t{1} << 62) + k);
    for (std::int64_t j = 0; j < cells; ++j) {
      const double t = (static_cast<double>(j) + rng.uniform()) / static_cast<double>(cells);
      if (!(t > 0 && t < 1)) continue;
      const Vec2 x{a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])};
      if ((x[0] == a[0] && x[1] == a[1]) || (x[0] == b[0] && x[1] == b[1])) continue;
      out.points.push_back(x);
      out.parent.push_back(static_cast<Index>(k));
    }
  }
  return out;
}

}  // namespace evomesh
