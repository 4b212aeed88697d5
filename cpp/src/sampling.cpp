#include "evomesh/sampling.hpp"

#include "evomesh/detail/bits.hpp"
#include "evomesh/global_ids.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <unordered_set>

#include "evomesh/kernel.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/step.hpp"

namespace evomesh {

namespace {

std::uint64_t splitmix64(std::uint64_t& x) {
  const std::uint64_t z = detail::mix(x);
  x += 0x9e3779b97f4a7c15ULL;
  return z;
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

// Grid cells follow f, not only its value at the triangle's smallest vertex q.
// The paper's cell side is c f(q) / (2 sqrt 2) over the whole triangle; where
// the vertices' f differ by orders of magnitude (two input points 1e-9 apart in
// a coarsening step) that draws (extent / f(q))^2 samples. f is 1-Lipschitz, so
// over a box B, f >= lower(B) = max(f(q), max_v f(v) - max_{x in B} |x - v|), and a
// box of side <= c lower(B) / (2 sqrt 2) is as dense as the rule asks. The fine
// grid of side s = c f(q) / (2 sqrt 2) is grouped into aligned dyadic blocks of
// 2^k x 2^k cells: a block is one cell when its side passes that test, else it is
// split (blocks strictly outside the triangle are dropped). Cells are taken in
// row-major order of their first fine cell, so where no block passes (the
// vertices' f within a factor 2 + |edge| / f(q)) the samples are those of the
// plain grid, draw for draw.
struct Dyadic_cell {
  std::int64_t ix, iy, size;  // first fine cell and side, in fine cells
};

double farthest_distance(const Vec2& v, double x0, double y0, double x1, double y1) {
  const double dx = std::max(std::abs(v[0] - x0), std::abs(v[0] - x1));
  const double dy = std::max(std::abs(v[1] - y0), std::abs(v[1] - y1));
  return std::hypot(dx, dy);
}

// Its four quarters, appended to `out`.
void split_block(const Dyadic_cell& block, std::vector<Dyadic_cell>& out) {
  const std::int64_t half = block.size / 2;
  out.push_back({block.ix + half, block.iy + half, half});
  out.push_back({block.ix, block.iy + half, half});
  out.push_back({block.ix + half, block.iy, half});
  out.push_back({block.ix, block.iy, half});
}

// The cells of the adaptive grid over the box [xmin, xmax] x [ymin, ymax] (nx by
// ny fine cells of side s) for the triangle `corners` with vertex values `fv`;
// stops (returns false) once more than `limit` cells were found.
bool adaptive_cells(const std::array<Vec2, 3>& corners, const std::array<double, 3>& fv, double xmin, double ymin,
                    double xmax, double ymax, double s, double cell_factor, std::int64_t nx, std::int64_t ny,
                    double limit, bool adaptive, const Spacing_queries* queries, std::vector<Dyadic_cell>& cells) {
  const double f_min = std::min({fv[0], fv[1], fv[2]});
  std::int64_t top = 1;
  while (adaptive && top < std::max(nx, ny)) top *= 2;
  if (!adaptive) {  // the fine grid itself, row by row
    for (std::int64_t iy = 0; iy < ny; ++iy) {
      for (std::int64_t ix = 0; ix < nx; ++ix) cells.push_back({ix, iy, 1});
      if (static_cast<double>(cells.size()) > limit) return false;
    }
    return true;
  }
  // A block is kept as one cell when its side is at most c lower / (2 sqrt 2),
  // lower a lower bound of f over it; else it is split in four. The bound from
  // the vertices (1-Lipschitz) and, for a triangle that asks, f at the block's
  // centre less half its diagonal (f exact there, asked level by level in one
  // batch per level). The cells are sorted at the end, so the order of the
  // visit does not matter.
  struct Box {
    double x0, y0, x1, y1;
  };
  const auto box_of = [&](const Dyadic_cell& block) {
    return Box{xmin + static_cast<double>(block.ix) * s, ymin + static_cast<double>(block.iy) * s,
               std::min(xmax, xmin + static_cast<double>(block.ix + block.size) * s),
               std::min(ymax, ymin + static_cast<double>(block.iy + block.size) * s)};
  };
  const auto passes = [&](const Dyadic_cell& block, double lower) {
    return !(static_cast<double>(block.size) * s > cell_factor * lower * kInvTwoSqrtTwo);
  };
  // -1: outside the triangle (strictly right of a side at all four corners), else
  // the vertices' lower bound of f over the block.
  const auto vertex_bound = [&](const Box& b) {
    for (int k = 0; k < 3; ++k) {
      const Vec2& p = corners[k];
      const Vec2& q = corners[(k + 1) % 3];
      if (orientation(p, q, {b.x0, b.y0}) < 0 && orientation(p, q, {b.x1, b.y0}) < 0 &&
          orientation(p, q, {b.x1, b.y1}) < 0 && orientation(p, q, {b.x0, b.y1}) < 0) {
        return -1.0;
      }
    }
    double lower = f_min;
    for (int k = 0; k < 3; ++k) lower = std::max(lower, fv[k] - farthest_distance(corners[k], b.x0, b.y0, b.x1, b.y1));
    return lower;
  };
  const bool ask = queries != nullptr && static_cast<double>(nx) * static_cast<double>(ny) > kQueryCells;
  if (!ask) {  // depth first
    std::vector<Dyadic_cell> stack{{0, 0, top}};
    while (!stack.empty()) {
      const Dyadic_cell block = stack.back();
      stack.pop_back();
      if (block.ix >= nx || block.iy >= ny) continue;
      if (block.size > 1) {
        const double lower = vertex_bound(box_of(block));
        if (lower < 0) continue;
        if (!passes(block, lower)) {
          split_block(block, stack);
          continue;
        }
      }
      cells.push_back(block);
      if (static_cast<double>(cells.size()) > limit) return false;
    }
  } else {  // level by level
    std::vector<Dyadic_cell> level{{0, 0, top}}, next, asked;
    std::vector<double> asked_lower, f_at;
    std::vector<Vec2> centres;
    while (!level.empty()) {
      next.clear();
      asked.clear();
      asked_lower.clear();
      centres.clear();
      for (const Dyadic_cell& block : level) {
        if (block.ix >= nx || block.iy >= ny) continue;
        if (block.size > 1) {
          const Box b = box_of(block);
          const double lower = vertex_bound(b);
          if (lower < 0) continue;
          if (!passes(block, lower)) {
            asked.push_back(block);
            asked_lower.push_back(lower);
            centres.push_back({0.5 * (b.x0 + b.x1), 0.5 * (b.y0 + b.y1)});
            continue;
          }
        }
        cells.push_back(block);
        if (static_cast<double>(cells.size()) > limit) return false;
      }
      if (!asked.empty()) {
        (*queries)(centres, f_at);
        for (std::size_t k = 0; k < asked.size(); ++k) {
          const Box b = box_of(asked[k]);
          if (!passes(asked[k], std::max(asked_lower[k], f_at[k] - 0.5 * std::hypot(b.x1 - b.x0, b.y1 - b.y0)))) {
            split_block(asked[k], next);
            continue;
          }
          cells.push_back(asked[k]);
          if (static_cast<double>(cells.size()) > limit) return false;
        }
      }
      level.swap(next);
    }
  }
  std::sort(cells.begin(), cells.end(), [](const Dyadic_cell& p, const Dyadic_cell& q) {
    return p.iy != q.iy ? p.iy < q.iy : p.ix < q.ix;
  });
  return true;
}

// The same for the 1-D cells of the segment a -> b of the given length (`cells`
// fine cells), with f(a) and f(b) at its ends: the blocks as [first, size) pairs,
// in order along the segment. A segment of more than kQueryCells fine cells asks
// `queries` (if any) for f at the centres of the blocks the ends' bound splits.
void adaptive_segment_cells(const Vec2& a, const Vec2& b, double length, double fa, double fb, double cell_factor,
                            std::int64_t n_cells, bool adaptive, const Spacing_queries* queries,
                            std::vector<std::array<std::int64_t, 2>>& out) {
  const double fine = length / static_cast<double>(n_cells);
  if (!adaptive) {
    for (std::int64_t j = 0; j < n_cells; ++j) out.push_back({j, 1});
    return;
  }
  std::int64_t top = 1;
  while (top < n_cells) top *= 2;
  const bool ask = queries != nullptr && static_cast<double>(n_cells) > kQueryCells;
  using Block = std::array<std::int64_t, 2>;
  std::vector<Block> level{{0, top}}, next, asked;
  std::vector<double> asked_lower, f_at;
  std::vector<Vec2> centres;
  const std::size_t first_out = out.size();
  while (!level.empty()) {
    next.clear();
    asked.clear();
    asked_lower.clear();
    centres.clear();
    for (const auto& [first, size] : level) {
      if (first >= n_cells) continue;
      const double t0 = static_cast<double>(first) * fine;
      const double t1 = std::min(length, static_cast<double>(first + size) * fine);
      const double lower = std::max({std::min(fa, fb), fa - t1, fb - (length - t0)});
      if (size > 1 && static_cast<double>(size) * fine > cell_factor * lower * kInvTwoSqrtTwo) {
        if (ask) {
          asked.push_back({first, size});
          asked_lower.push_back(lower);
          const double t = 0.5 * (t0 + t1) / length;
          centres.push_back({a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])});
        } else {
          next.push_back({first, size / 2});
          next.push_back({first + size / 2, size / 2});
        }
        continue;
      }
      out.push_back({first, std::min(size, n_cells - first)});
    }
    if (!asked.empty()) {
      (*queries)(centres, f_at);
      for (std::size_t k = 0; k < asked.size(); ++k) {
        const auto [first, size] = asked[k];
        const double t0 = static_cast<double>(first) * fine;
        const double t1 = std::min(length, static_cast<double>(first + size) * fine);
        const double lower = std::max(asked_lower[k], f_at[k] - 0.5 * (t1 - t0));
        if (static_cast<double>(size) * fine > cell_factor * lower * kInvTwoSqrtTwo) {
          next.push_back({first, size / 2});
          next.push_back({first + size / 2, size / 2});
          continue;
        }
        out.push_back({first, std::min(size, n_cells - first)});
      }
    }
    level.swap(next);
  }
  std::sort(out.begin() + static_cast<std::ptrdiff_t>(first_out), out.end(),
            [](const Block& p, const Block& q) { return p[0] < q[0]; });
}

}  // namespace

Random_stream::Random_stream(std::uint64_t seed, std::uint64_t stream) {
  std::uint64_t x = seed ^ 0x243f6a8885a308d3ULL;
  state = splitmix64(x) ^ (stream * 0xd1342543de82ef95ULL);
  splitmix64(state);
}

std::uint64_t Random_stream::next() { return splitmix64(state); }

double Random_stream::uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

bool in_cover(const Cover_discs& cover, const Triangle& t, const Vec2& x) {
  if (cover.empty()) return false;
  for (Index v : t) {
    const Vec2& c = (*cover.points)[cover.centre[v]];
    const double r = cover.reach[v];
    const double dx = x[0] - c[0], dy = x[1] - c[1];
    if (dx * dx + dy * dy < r * r) return true;
  }
  return false;
}

namespace {

// The fine grid of a triangle: cells of side s = c f(q) / (2 sqrt 2), q its
// vertex of smallest f, over its bounding box (fx by fy cells, as doubles).
struct Triangle_grid {
  double s, xmin, ymin, xmax, ymax, fx, fy;
  double cells() const { return std::max(fx, 1.0) * std::max(fy, 1.0); }
};

Triangle_grid triangle_grid(const Mesh_arrays& mesh, const std::vector<double>& vertex_f, const Triangle& t,
                            double cell_factor) {
  const Vec2 &a = mesh.points[t[0]], &b = mesh.points[t[1]], &c = mesh.points[t[2]];
  Triangle_grid g;
  g.s = cell_factor * vertex_f[smallest_f_vertex(t, vertex_f)] * kInvTwoSqrtTwo;
  g.xmin = std::min({a[0], b[0], c[0]});
  g.xmax = std::max({a[0], b[0], c[0]});
  g.ymin = std::min({a[1], b[1], c[1]});
  g.ymax = std::max({a[1], b[1], c[1]});
  g.fx = std::ceil((g.xmax - g.xmin) / g.s);
  g.fy = std::ceil((g.ymax - g.ymin) / g.s);
  return g;
}

// The cells of triangle t's adaptive grid (adaptive_cells over its fine grid g).
bool triangle_cells(const Mesh_arrays& mesh, const std::vector<double>& vertex_f, const Triangle& t,
                    const Triangle_grid& g, double cell_factor, double limit, bool adaptive,
                    const Spacing_queries* queries, std::vector<Dyadic_cell>& cells) {
  return adaptive_cells({mesh.points[t[0]], mesh.points[t[1]], mesh.points[t[2]]},
                        {vertex_f[t[0]], vertex_f[t[1]], vertex_f[t[2]]}, g.xmin, g.ymin, g.xmax, g.ymax, g.s,
                        cell_factor, std::max<std::int64_t>(static_cast<std::int64_t>(g.fx), 1),
                        std::max<std::int64_t>(static_cast<std::int64_t>(g.fy), 1), limit, adaptive, queries, cells);
}

// The 1-D fine grid of a segment: cells of side s = c min f / (2 sqrt 2) over its length.
struct Segment_grid {
  double s, length, cells;
};

Segment_grid segment_grid(const Mesh_arrays& mesh, const std::vector<double>& vertex_f, const Edge& e,
                          double cell_factor) {
  const Vec2& a = mesh.points[e[0]];
  const Vec2& b = mesh.points[e[1]];
  Segment_grid g;
  g.s = cell_factor * std::min(vertex_f[e[0]], vertex_f[e[1]]) * kInvTwoSqrtTwo;
  g.length = std::hypot(b[0] - a[0], b[1] - a[1]);
  g.cells = std::ceil(g.length / g.s);
  return g;
}

}  // namespace

bool asks_spacing(const Mesh_arrays& mesh, const std::vector<double>& vertex_f, const Edge& e, double cell_factor) {
  return !(segment_grid(mesh, vertex_f, e, cell_factor).cells <= kQueryCells);
}

bool asks_spacing(const Mesh_arrays& mesh, const std::vector<double>& vertex_f, const Triangle& t, double cell_factor) {
  return !(triangle_grid(mesh, vertex_f, t, cell_factor).cells() <= kQueryCells);
}

double estimate_sample_count(const Mesh_arrays& mesh, const std::vector<double>& vertex_f, double cell_factor,
                             double limit, bool adaptive, const Spacing_queries* queries) {
  // The fine grid's count bounds the adaptive grid's; only triangles whose fine
  // grid is large are counted cell by cell (and only up to the limit), with the
  // cells sample_triangle_blocks uses (the same queries).
  constexpr double kCountCells = kQueryCells;
  constexpr double kMaxCellsPerSide = 0x1.0p50;  // dyadic indices stay exact in int64 and double
  // The fine grids' sizes in parallel blocks (NaN: a side beyond
  // kMaxCellsPerSide), then the sum in triangle order as before, with its early
  // returns: the same estimate for any thread count.
  const std::size_t m = mesh.triangles.size();
  std::vector<double> fine_cells(m);
  constexpr std::size_t kBlock = 1 << 14;
  parallel_for((m + kBlock - 1) / kBlock, /*threads=*/0, [&](std::size_t b) {
    for (std::size_t t = b * kBlock; t < std::min(m, (b + 1) * kBlock); ++t) {
      const Triangle_grid g = triangle_grid(mesh, vertex_f, mesh.triangles[t], cell_factor);
      fine_cells[t] = g.fx <= kMaxCellsPerSide && g.fy <= kMaxCellsPerSide ? g.cells()
                                                                            : std::numeric_limits<double>::quiet_NaN();
    }
  });
  double total = 0;
  std::vector<Dyadic_cell> cells;
  for (std::size_t ti = 0; ti < m; ++ti) {
    const double fine = fine_cells[ti];
    if (std::isnan(fine)) return std::numeric_limits<double>::infinity();
    if (!adaptive || fine <= kCountCells) {
      total += fine;
    } else {
      const Triangle& t = mesh.triangles[ti];
      const Triangle_grid g = triangle_grid(mesh, vertex_f, t, cell_factor);
      cells.clear();
      const bool complete = triangle_cells(mesh, vertex_f, t, g, cell_factor, limit - total, adaptive, queries, cells);
      total += static_cast<double>(cells.size());
      if (!complete) return total;
    }
    if (total > limit) return total;
  }
  std::vector<std::array<std::int64_t, 2>> blocks;
  for (const auto& e : mesh.segments) {
    const Segment_grid g = segment_grid(mesh, vertex_f, e, cell_factor);
    const double fine = g.cells;
    if (!(fine <= kMaxCellsPerSide)) return std::numeric_limits<double>::infinity();
    if (!adaptive || fine <= kCountCells) {
      total += fine + 1;
    } else {
      blocks.clear();
      adaptive_segment_cells(mesh.points[e[0]], mesh.points[e[1]], g.length, vertex_f[e[0]], vertex_f[e[1]],
                             cell_factor, static_cast<std::int64_t>(fine), adaptive, queries, blocks);
      total += static_cast<double>(blocks.size()) + 1;
    }
    if (total > limit) return total;
  }
  return total;
}

namespace {

// The samples of one triangle, appended to `out` unless a vertex covers them.
void sample_one_triangle(const Mesh_arrays& mesh, std::size_t ti, const std::vector<double>& vertex_f,
                         double cell_factor, Sample_mode mode, std::uint64_t seed,
                         const std::unordered_set<std::uint64_t>& segment_edges, const Cover_discs& cover,
                         bool adaptive, const Spacing_queries* queries, Sample_set& out, std::size_t& n_drawn) {
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
    out.parent.push_back(static_cast<std::uint32_t>(ti));
  };
  if (mode != Sample_mode::random_grid) {
    if (mode == Sample_mode::barycentre || mode == Sample_mode::barycentre_midpoints) {
      const Vec2 g{(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0};
      if (strictly_inside(a, b, c, g)) emit(g);
    }
    if (mode == Sample_mode::midpoints || mode == Sample_mode::barycentre_midpoints) {
      // An interior edge is shared by two triangles with opposite directions;
      // emit its midpoint from the triangle that has it as (low id -> high id).
      for (int k = 0; k < 3; ++k) {
        const Index u = t[k];
        const Index v = t[(k + 1) % 3];
        if (mesh.point_gid(static_cast<std::size_t>(u)) > mesh.point_gid(static_cast<std::size_t>(v)) ||
            segment_edges.count(edge_key(u, v, n))) {
          continue;
        }
        emit({0.5 * (P[u][0] + P[v][0]), 0.5 * (P[u][1] + P[v][1])});
      }
    }
    return;
  }
  Random_stream rng(seed, static_cast<std::uint64_t>(mesh.triangle_gid(ti)));  // (keyed by id, not position)
  const Triangle_grid g = triangle_grid(mesh, vertex_f, t, cell_factor);
  const double s = g.s, xmin = g.xmin, xmax = g.xmax, ymin = g.ymin, ymax = g.ymax;
  std::vector<Dyadic_cell> cells;
  triangle_cells(mesh, vertex_f, t, g, cell_factor, std::numeric_limits<double>::infinity(), adaptive, queries, cells);
  Polygon poly, clipped;
  std::array<double, 8> cumulative{};
  for (const Dyadic_cell& cell : cells) {
    const double y0 = ymin + static_cast<double>(cell.iy) * s;
    const double y1 = std::min(ymax, ymin + static_cast<double>(cell.iy + cell.size) * s);
    const double x0 = xmin + static_cast<double>(cell.ix) * s;
    const double x1 = std::min(xmax, xmin + static_cast<double>(cell.ix + cell.size) * s);
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

}  // namespace

std::vector<Sample_set> sample_triangle_blocks(const Mesh_arrays& mesh, const std::vector<double>& vertex_f,
                                               double cell_factor, Sample_mode mode, std::uint64_t seed,
                                               const std::vector<std::uint8_t>& skip, const Cover_discs& cover,
                                               int threads, std::size_t* n_drawn, bool adaptive,
                                               const Spacing_queries* queries) {
  check_fits_4_bytes(mesh.triangles.size(), "triangles");
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
  // Triangles in the order of their global ids (positions without them), so
  // that the samples come in the same order whatever array order holds them.
  const std::vector<Index> by_id = order_by_ids(mesh.triangle_gids);
  parallel_for(n_blocks, threads, [&](std::size_t k) {
    for (std::size_t r = k * kBlock; r < std::min(n_triangles, (k + 1) * kBlock); ++r) {
      const std::size_t ti = visit(by_id, r);
      if (!skip.empty() && skip[ti]) continue;
      sample_one_triangle(mesh, ti, vertex_f, cell_factor, mode, seed, segment_edges, cover, adaptive, queries,
                          blocks[k], drawn[k]);
    }
  });
  if (n_drawn) {
    *n_drawn = 0;
    for (std::size_t d : drawn) *n_drawn += d;
  }
  return blocks;
}

Sample_set join_samples(std::vector<Sample_set>& blocks) {
  std::size_t total = 0;
  for (const Sample_set& block : blocks) total += block.points.size();
  Sample_set out;
  out.points.reserve(total);  // (pages are touched group by group, not before)
  out.parent.reserve(total);
  // Groups of blocks holding kRelease bytes or more: each group's range of the
  // output is touched and filled on parallel_for's threads, then its blocks
  // are freed and what they held goes back to the system (a trim walks the
  // free lists of every arena: a few per step, not one per block).
  constexpr std::size_t kRelease = std::size_t{32} << 20;
  constexpr std::size_t kBytesPerSample = sizeof(Vec2) + sizeof(std::uint32_t);
  for (std::size_t first = 0; first < blocks.size();) {
    std::size_t last = first, bytes = 0;
    while (last < blocks.size() && bytes < kRelease) bytes += blocks[last++].points.size() * kBytesPerSample;
    const std::size_t at = out.points.size();
    std::vector<std::size_t> offset(last - first + 1, at);
    for (std::size_t k = first; k < last; ++k) offset[k - first + 1] = offset[k - first] + blocks[k].points.size();
    detail::parallel_resize(out.points, offset.back());
    detail::parallel_resize(out.parent, offset.back());
    parallel_for(last - first, 0, [&](std::size_t k) {
      Sample_set& block = blocks[first + k];
      std::copy(block.points.begin(), block.points.end(), out.points.begin() + static_cast<std::ptrdiff_t>(offset[k]));
      std::copy(block.parent.begin(), block.parent.end(), out.parent.begin() + static_cast<std::ptrdiff_t>(offset[k]));
      block = Sample_set();
    });
    if (bytes >= kRelease) detail::release_free_memory();
    first = last;
  }
  blocks = std::vector<Sample_set>();
  return out;
}

Sample_set sample_segments(const Mesh_arrays& mesh, const std::vector<double>& vertex_f,
                           double cell_factor, Sample_mode mode, std::uint64_t seed, bool adaptive,
                           const Spacing_queries* queries) {
  check_fits_4_bytes(mesh.segments.size(), "segments");
  Sample_set out;
  std::vector<std::array<std::int64_t, 2>> blocks;
  const std::vector<Index> by_key = order_by_ids(mesh.segment_keys);  // (as the triangles')
  for (std::size_t r = 0; r < mesh.segments.size(); ++r) {
    const std::size_t k = visit(by_key, r);
    const Edge& e = mesh.segments[k];
    const Vec2& a = mesh.points[e[0]];
    const Vec2& b = mesh.points[e[1]];
    if (mode != Sample_mode::random_grid) {
      out.points.push_back({0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])});
      out.parent.push_back(static_cast<std::uint32_t>(k));
      continue;
    }
    const Segment_grid g = segment_grid(mesh, vertex_f, e, cell_factor);
    const auto cells = static_cast<std::int64_t>(g.cells);
    if (cells < 2) continue;
    // Stream ids for segments follow the triangles' so the two never share one.
    Random_stream rng(seed, (std::uint64_t{1} << 62) + static_cast<std::uint64_t>(mesh.segment_key(k)));
    blocks.clear();
    adaptive_segment_cells(a, b, g.length, vertex_f[e[0]], vertex_f[e[1]], cell_factor, cells, adaptive, queries, blocks);
    for (const auto& [first, size] : blocks) {
      const double t = (static_cast<double>(first) + static_cast<double>(size) * rng.uniform()) / static_cast<double>(cells);
      if (!(t > 0 && t < 1)) continue;
      const Vec2 x{a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])};
      if ((x[0] == a[0] && x[1] == a[1]) || (x[0] == b[0] && x[1] == b[1])) continue;
      out.points.push_back(x);
      out.parent.push_back(static_cast<std::uint32_t>(k));
    }
  }
  return out;
}

}  // namespace evomesh
