// Local supermesh of two meshes of one domain: see evomesh/supermesh.hpp.
#include "evomesh/supermesh.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include "evomesh/parallel.hpp"

namespace evomesh {

namespace {

inline double cross(const Vec2& a, const Vec2& b) { return a[0] * b[1] - a[1] * b[0]; }
inline Vec2 sub(const Vec2& a, const Vec2& b) { return {a[0] - b[0], a[1] - b[1]}; }

// A convex polygon of at most 9 vertices (a triangle clipped by 3 half-planes has at most 6).
struct Polygon {
  std::array<Vec2, 9> p;
  int n = 0;
};

// Keeps the part of `in` where cross(b - a, x - a) >= 0 (left of a -> b).
void clip(const Polygon& in, const Vec2& a, const Vec2& b, Polygon& out) {
  out.n = 0;
  if (in.n == 0) return;
  const Vec2 e = sub(b, a);
  std::array<double, 9> d;
  for (int i = 0; i < in.n; ++i) d[i] = cross(e, sub(in.p[i], a));
  for (int i = 0; i < in.n; ++i) {
    const int j = (i + 1) % in.n;
    const Vec2& x = in.p[i];
    const Vec2& y = in.p[j];
    if (d[i] >= 0) out.p[out.n++] = x;
    if ((d[i] > 0 && d[j] < 0) || (d[i] < 0 && d[j] > 0)) {  // the edge crosses the line
      const double t = d[i] / (d[i] - d[j]);
      out.p[out.n++] = {x[0] + t * (y[0] - x[0]), x[1] + t * (y[1] - x[1])};
    }
  }
}

// The intersection polygon of s with the counter-clockwise triangle t.
void intersect(const std::array<Vec2, 3>& t, const std::array<Vec2, 3>& s, Polygon& result) {
  Polygon a, b;
  a.n = 3;
  for (int k = 0; k < 3; ++k) a.p[k] = s[k];
  clip(a, t[0], t[1], b);
  clip(b, t[1], t[2], a);
  clip(a, t[2], t[0], result);
}

double shoelace(const Polygon& poly) {
  double twice = 0.0;
  for (int i = 0; i < poly.n; ++i) twice += cross(poly.p[i], poly.p[(i + 1) % poly.n]);
  return 0.5 * twice;
}

// Barycentric coordinates of x in the triangle v (twice_area its signed doubled area).
inline std::array<double, 3> barycentric(const std::array<Vec2, 3>& v, double twice_area, const Vec2& x) {
  std::array<double, 3> l;
  for (int i = 0; i < 3; ++i) l[i] = cross(sub(v[(i + 1) % 3], x), sub(v[(i + 2) % 3], x)) / twice_area;
  return l;
}

// Old triangle adjacency: neighbour[3 s + k] across the edge (s[k], s[k+1]), -1 on the boundary.
std::vector<Index> adjacency(const std::vector<Triangle>& tris) {
  struct Half {
    Index lo, hi, slot;
  };
  std::vector<Half> halves(3 * tris.size());
  for (std::size_t s = 0; s < tris.size(); ++s)
    for (int k = 0; k < 3; ++k) {
      const Index a = tris[s][k], b = tris[s][(k + 1) % 3];
      halves[3 * s + k] = {std::min(a, b), std::max(a, b), static_cast<Index>(3 * s + k)};
    }
  std::sort(halves.begin(), halves.end(), [](const Half& x, const Half& y) {
    return x.lo != y.lo ? x.lo < y.lo : (x.hi != y.hi ? x.hi < y.hi : x.slot < y.slot);
  });
  std::vector<Index> neighbour(3 * tris.size(), -1);
  for (std::size_t i = 0; i + 1 < halves.size(); ++i)
    if (halves[i].lo == halves[i + 1].lo && halves[i].hi == halves[i + 1].hi) {
      neighbour[halves[i].slot] = halves[i + 1].slot / 3;
      neighbour[halves[i + 1].slot] = halves[i].slot / 3;
      ++i;
    }
  return neighbour;
}

struct Block_result {
  std::vector<Index> count;  // pairs per triangle of the block
  std::vector<Index> old_triangle;
  std::vector<double> area;
  std::vector<double> mass;
};

// Visited marks of old triangles, one array per worker thread (a generation
// counter avoids clearing it between new triangles).
struct Marks {
  std::vector<std::uint32_t> stamp;
  std::uint32_t generation = 0;
  std::uint32_t next(std::size_t n) {
    if (stamp.size() != n || generation == std::numeric_limits<std::uint32_t>::max()) {
      stamp.assign(n, 0);
      generation = 0;
    }
    return ++generation;
  }
};

constexpr std::size_t block_size = 1024;

}  // namespace

double triangle_intersection_area(const std::array<Vec2, 3>& t, const std::array<Vec2, 3>& s) {
  std::array<Vec2, 3> tt = t;
  if (cross(sub(t[1], t[0]), sub(t[2], t[0])) < 0) std::swap(tt[1], tt[2]);
  Polygon poly;
  intersect(tt, s, poly);
  return std::abs(shoelace(poly));
}

std::vector<Index> supermesh_seeds(std::size_t n_old_points, const std::vector<Triangle>& old_triangles,
                                   const std::vector<Index>& origin, const std::vector<Index>& parent_triangle) {
  if (origin.size() != parent_triangle.size()) throw Input_error("origin and parent_triangle differ in length");
  std::vector<Index> incident(n_old_points, -1);
  for (std::size_t s = old_triangles.size(); s-- > 0;)
    for (const Index v : old_triangles[s])
      if (v >= 0 && static_cast<std::size_t>(v) < n_old_points) incident[v] = static_cast<Index>(s);
  std::vector<Index> seed(origin.size(), -1);
  const auto m = static_cast<Index>(old_triangles.size());
  for (std::size_t v = 0; v < origin.size(); ++v) {
    if (origin[v] >= 0) {
      if (static_cast<std::size_t>(origin[v]) >= n_old_points) throw Input_error("origin out of range of the old mesh");
      seed[v] = incident[origin[v]];
    } else if (parent_triangle[v] >= 0 && parent_triangle[v] < m) {
      seed[v] = parent_triangle[v];
    }
  }
  return seed;
}

Supermesh build_supermesh(const std::vector<Vec2>& old_points, const std::vector<Triangle>& old_triangles,
                          const std::vector<Vec2>& new_points, const std::vector<Triangle>& new_triangles,
                          const std::vector<Index>& seed, bool with_mass, int threads) {
  if (seed.size() != new_points.size()) throw Input_error("seed must have one entry per new point");
  const auto n_old_tri = static_cast<Index>(old_triangles.size());
  for (const Index s : seed)
    if (s < -1 || s >= n_old_tri) throw Input_error("seed refers to an old triangle out of range");
  const std::vector<Index> neighbour = adjacency(old_triangles);
  // Bounding boxes of the old triangles.
  std::vector<std::array<double, 4>> box(old_triangles.size());
  for (std::size_t s = 0; s < old_triangles.size(); ++s) {
    const Vec2& a = old_points[old_triangles[s][0]];
    const Vec2& b = old_points[old_triangles[s][1]];
    const Vec2& c = old_points[old_triangles[s][2]];
    box[s] = {std::min({a[0], b[0], c[0]}), std::min({a[1], b[1], c[1]}), std::max({a[0], b[0], c[0]}),
              std::max({a[1], b[1], c[1]})};
  }
  const std::size_t m = new_triangles.size();
  const std::size_t n_blocks = (m + block_size - 1) / block_size;
  std::vector<Block_result> blocks(n_blocks);
  std::vector<Index> orphan(n_blocks, -1);  // a new triangle without any seed
  parallel_for(n_blocks, threads, [&](std::size_t block) {
    thread_local Marks marks;
    Block_result& out = blocks[block];
    const std::size_t begin = block * block_size, end = std::min(m, begin + block_size);
    out.count.assign(end - begin, 0);
    std::vector<Index> queue;
    for (std::size_t t = begin; t < end; ++t) {
      const Triangle& tri = new_triangles[t];
      const Vec2 origin = new_points[tri[0]];
      // Local coordinates (relative to the first vertex of t): less cancellation far from 0.
      std::array<Vec2, 3> tv = {Vec2{0.0, 0.0}, sub(new_points[tri[1]], origin), sub(new_points[tri[2]], origin)};
      const double t_twice = cross(tv[1], tv[2]);
      std::array<Vec2, 3> tc = tv;  // counter-clockwise copy for the clipping
      if (t_twice < 0) std::swap(tc[1], tc[2]);
      double lo[2], hi[2];
      for (int d = 0; d < 2; ++d) {
        lo[d] = std::min({tv[0][d], tv[1][d], tv[2][d]}) + origin[d];
        hi[d] = std::max({tv[0][d], tv[1][d], tv[2][d]}) + origin[d];
        const double margin = 1e-9 * (hi[d] - lo[d]) +
                              64 * std::numeric_limits<double>::epsilon() *
                                  std::max(std::abs(lo[d]), std::abs(hi[d]));
        lo[d] -= margin;
        hi[d] += margin;
      }
      const std::uint32_t mark = marks.next(old_triangles.size());
      queue.clear();
      for (const Index v : tri)
        if (seed[v] >= 0 && marks.stamp[seed[v]] != mark) {
          marks.stamp[seed[v]] = mark;
          queue.push_back(seed[v]);
        }
      if (queue.empty() && orphan[block] < 0) orphan[block] = static_cast<Index>(t);
      for (std::size_t head = 0; head < queue.size(); ++head) {
        const Index s = queue[head];
        const auto& b = box[s];
        if (b[0] > hi[0] || b[2] < lo[0] || b[1] > hi[1] || b[3] < lo[1]) continue;  // not near t
        for (int k = 0; k < 3; ++k) {
          const Index u = neighbour[3 * s + k];
          if (u >= 0 && marks.stamp[u] != mark) {
            marks.stamp[u] = mark;
            queue.push_back(u);
          }
        }
        const std::array<Vec2, 3> sv = {sub(old_points[old_triangles[s][0]], origin),
                                        sub(old_points[old_triangles[s][1]], origin),
                                        sub(old_points[old_triangles[s][2]], origin)};
        Polygon poly;
        intersect(tc, sv, poly);
        if (poly.n < 3) continue;
        const double area = std::abs(shoelace(poly));
        if (!(area > 0)) continue;
        ++out.count[t - begin];
        out.old_triangle.push_back(s);
        out.area.push_back(area);
        if (!with_mass) continue;
        const double s_twice = cross(sub(sv[1], sv[0]), sub(sv[2], sv[0]));
        std::array<double, 9> mass{};
        // Fan from the first vertex; the edge-midpoint rule is exact for the
        // quadratic phi^new * phi^old on each piece.
        for (int i = 1; i + 1 < poly.n; ++i) {
          const Vec2& p0 = poly.p[0];
          const Vec2& p1 = poly.p[i];
          const Vec2& p2 = poly.p[i + 1];
          const double w = std::abs(cross(sub(p1, p0), sub(p2, p0))) / 6.0;  // |piece| / 3
          const Vec2 mids[3] = {{0.5 * (p0[0] + p1[0]), 0.5 * (p0[1] + p1[1])},
                                {0.5 * (p1[0] + p2[0]), 0.5 * (p1[1] + p2[1])},
                                {0.5 * (p2[0] + p0[0]), 0.5 * (p2[1] + p0[1])}};
          for (const Vec2& q : mids) {
            const auto lt = barycentric(tv, t_twice, q);
            const auto ls = barycentric(sv, s_twice, q);
            for (int a = 0; a < 3; ++a)
              for (int c = 0; c < 3; ++c) mass[3 * a + c] += w * lt[a] * ls[c];
          }
        }
        out.mass.insert(out.mass.end(), mass.begin(), mass.end());
      }
    }
  });
  for (const Index t : orphan)
    if (t >= 0)
      throw Input_error("new triangle " + std::to_string(t) +
                        " has no vertex located in the old mesh: the supermesh needs new = evolve(old, ...)");
  Supermesh result;
  result.offsets.assign(m + 1, 0);
  std::size_t total = 0;
  for (const auto& b : blocks) total += b.old_triangle.size();
  result.old_triangle.reserve(total);
  result.area.reserve(total);
  if (with_mass) result.mass.reserve(9 * total);
  std::size_t t = 0;
  for (const auto& b : blocks) {
    for (const Index c : b.count) {
      result.offsets[t + 1] = result.offsets[t] + c;
      ++t;
    }
    result.old_triangle.insert(result.old_triangle.end(), b.old_triangle.begin(), b.old_triangle.end());
    result.area.insert(result.area.end(), b.area.begin(), b.area.end());
    result.mass.insert(result.mass.end(), b.mass.begin(), b.mass.end());
  }
  return result;
}

}  // namespace evomesh
