// Local supermesh of two meshes of one domain: see evomesh/supermesh.hpp.
#include "evomesh/supermesh.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>

#include "evomesh/detail/cell_stars.hpp"
#include "evomesh/parallel.hpp"

namespace evomesh {

namespace {

using detail::facet_adjacency;
using detail::vertex_stars;
using detail::Vertex_stars;
using detail::Visit_marks;

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

// int_poly phi^t_a phi^s_b for a, b in 0..2 (written to mass[3 a + b]): the
// polygon is cut into a fan from its first vertex, and on each piece P the
// product of two affine functions integrates exactly as
// |P| / 12 (sum_v f(v) g(v) + sum_v f(v) sum_v g(v)) over its three vertices v.
void polygon_mass(const Polygon& poly, const std::array<Vec2, 3>& tv, double t_twice, const std::array<Vec2, 3>& sv,
                  double s_twice, double* mass) {
  std::array<std::array<double, 3>, 9> lt, ls;  // barycentric coordinates at the polygon's vertices
  for (int v = 0; v < poly.n; ++v) {
    lt[v] = barycentric(tv, t_twice, poly.p[v]);
    ls[v] = barycentric(sv, s_twice, poly.p[v]);
  }
  std::array<double, 9> sum{};
  for (int i = 1; i + 1 < poly.n; ++i) {
    const double w = std::abs(cross(sub(poly.p[i], poly.p[0]), sub(poly.p[i + 1], poly.p[0]))) / 24.0;  // |P| / 12
    double st[3], ss[3];
    for (int a = 0; a < 3; ++a) {
      st[a] = lt[0][a] + lt[i][a] + lt[i + 1][a];
      ss[a] = ls[0][a] + ls[i][a] + ls[i + 1][a];
    }
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        sum[3 * a + b] +=
            w * (lt[0][a] * ls[0][b] + lt[i][a] * ls[i][b] + lt[i + 1][a] * ls[i + 1][b] + st[a] * ss[b]);
  }
  for (int k = 0; k < 9; ++k) mass[k] = sum[k];
}

constexpr std::size_t block_size = 1024;

struct Block_result {
  std::vector<Index> count;  // pairs per triangle of the block
  std::vector<Index> old_triangle;
  std::vector<double> area;
  std::vector<double> mass;
};

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
                          const std::vector<Index>& seed, bool with_mass, int threads,
                          const std::vector<Index>& identical) {
  if (seed.size() != new_points.size()) throw Input_error("seed must have one entry per new point");
  const auto n_old_tri = static_cast<Index>(old_triangles.size());
  for (const Index s : seed)
    if (s < -1 || s >= n_old_tri) throw Input_error("seed refers to an old triangle out of range");
  if (!identical.empty() && identical.size() != new_triangles.size())
    throw Input_error("identical must have one entry per new triangle");
  for (const Index s : identical)
    if (s < -1 || s >= n_old_tri) throw Input_error("identical refers to an old triangle out of range");
  // neighbour[3 s + k]: the old triangle across the edge (s[k], s[k+1]), -1 on the boundary.
  const std::vector<Index> neighbour =
      facet_adjacency(vertex_stars(old_points.size(), old_triangles), old_triangles, threads);
  // Bounding boxes of the old triangles.
  std::vector<std::array<double, 4>> box(old_triangles.size());
  parallel_for((old_triangles.size() + block_size - 1) / block_size, threads, [&](std::size_t block) {
    for (std::size_t s = block * block_size, end = std::min(old_triangles.size(), s + block_size); s < end; ++s) {
      const Vec2& a = old_points[old_triangles[s][0]];
      const Vec2& b = old_points[old_triangles[s][1]];
      const Vec2& c = old_points[old_triangles[s][2]];
      box[s] = {std::min({a[0], b[0], c[0]}), std::min({a[1], b[1], c[1]}), std::max({a[0], b[0], c[0]}),
                std::max({a[1], b[1], c[1]})};
    }
  });
  const std::size_t m = new_triangles.size();
  const std::size_t n_blocks = (m + block_size - 1) / block_size;
  std::vector<Block_result> blocks(n_blocks);
  std::vector<Index> orphan(n_blocks, -1);     // a new triangle without any seed
  std::vector<Index> mismatch(n_blocks, -1);   // a new triangle whose identical old triangle is not
  parallel_for(n_blocks, threads, [&](std::size_t block) {
    thread_local Visit_marks marks;
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
      if (!identical.empty() && identical[t] >= 0) {
        // t is the old triangle s: one pair, |t| and the element mass matrix
        // |t| / 12 (1 + [same point]); vertices matched by their coordinates.
        const Index s = identical[t];
        int same[3];
        for (int a = 0; a < 3; ++a) {
          same[a] = -1;
          for (int b = 0; b < 3; ++b)
            if (new_points[tri[a]] == old_points[old_triangles[s][b]]) same[a] = b;
        }
        if (same[0] < 0 || same[1] < 0 || same[2] < 0 || same[0] == same[1] || same[1] == same[2] ||
            same[0] == same[2]) {
          if (mismatch[block] < 0) mismatch[block] = static_cast<Index>(t);
          continue;
        }
        const double area = 0.5 * std::abs(t_twice);
        ++out.count[t - begin];
        out.old_triangle.push_back(s);
        out.area.push_back(area);
        if (with_mass)
          for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) out.mass.push_back(same[a] == b ? area / 6.0 : area / 12.0);
        continue;
      }
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
        out.mass.resize(out.mass.size() + 9);
        polygon_mass(poly, tv, t_twice, sv, s_twice, &out.mass[out.mass.size() - 9]);
      }
    }
  });
  for (const Index t : mismatch)
    if (t >= 0)
      throw Input_error("new triangle " + std::to_string(t) +
                        " is not the old triangle given as identical to it (its points differ)");
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

std::vector<Index> identical_old_triangles(std::size_t n_old_points, const std::vector<Triangle>& old_triangles,
                                           const std::vector<Triangle>& new_triangles,
                                           const std::vector<Index>& origin, int threads) {
  for (const Index o : origin)
    if (o >= 0 && static_cast<std::size_t>(o) >= n_old_points) throw Input_error("origin out of range of the old mesh");
  for (const Triangle& t : new_triangles)
    for (const Index v : t)
      if (v < 0 || static_cast<std::size_t>(v) >= origin.size()) throw Input_error("new triangle out of range of origin");
  const Vertex_stars stars = vertex_stars(n_old_points, old_triangles);
  std::vector<Index> identical(new_triangles.size(), -1);
  const std::size_t m = new_triangles.size();
  parallel_for((m + block_size - 1) / block_size, threads, [&](std::size_t block) {
    for (std::size_t t = block * block_size, end = std::min(m, t + block_size); t < end; ++t) {
      const Index a = origin[new_triangles[t][0]], b = origin[new_triangles[t][1]], c = origin[new_triangles[t][2]];
      if (a < 0 || b < 0 || c < 0) continue;
      for (Index k = stars.start[a]; k < stars.start[a + 1]; ++k) {
        const Triangle& s = old_triangles[stars.star[k]];
        const bool has_b = s[0] == b || s[1] == b || s[2] == b;
        const bool has_c = s[0] == c || s[1] == c || s[2] == c;
        if (has_b && has_c && b != c) {
          identical[t] = stars.star[k];
          break;
        }
      }
    }
  });
  return identical;
}

Csr_matrix p1_mass_matrix(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles, int threads) {
  const std::size_t n = points.size();
  const Vertex_stars stars = vertex_stars(n, triangles);
  std::vector<double> area(triangles.size());
  for (std::size_t k = 0; k < triangles.size(); ++k) {
    const Vec2& a = points[triangles[k][0]];
    area[k] = 0.5 * std::abs(cross(sub(points[triangles[k][1]], a), sub(points[triangles[k][2]], a)));
  }
  // Rows in fixed blocks; a row's entries are summed over its star in
  // increasing triangle order, then sorted by column.
  struct Rows {
    std::vector<Index> length, indices;
    std::vector<double> data;
  };
  const std::size_t n_blocks = (n + block_size - 1) / block_size;
  std::vector<Rows> blocks(n_blocks);
  parallel_for(n_blocks, threads, [&](std::size_t block) {
    Rows& out = blocks[block];
    std::vector<std::pair<Index, double>> row;
    for (std::size_t i = block * block_size, end = std::min(n, i + block_size); i < end; ++i) {
      row.clear();
      for (Index k = stars.start[i]; k < stars.start[i + 1]; ++k) {
        const Index s = stars.star[k];
        for (const Index j : triangles[s]) {
          const double value = static_cast<std::size_t>(j) == i ? area[s] / 6.0 : area[s] / 12.0;
          std::size_t r = 0;
          while (r < row.size() && row[r].first != j) ++r;  // a star has a handful of points
          if (r == row.size()) row.push_back({j, value});
          else row[r].second += value;
        }
      }
      std::sort(row.begin(), row.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
      out.length.push_back(static_cast<Index>(row.size()));
      for (const auto& [j, value] : row) {
        out.indices.push_back(j);
        out.data.push_back(value);
      }
    }
  });
  Csr_matrix out;
  out.indptr.assign(n + 1, 0);
  std::size_t i = 0;
  for (const Rows& b : blocks) {
    for (const Index length : b.length) {
      out.indptr[i + 1] = out.indptr[i] + length;
      ++i;
    }
    out.indices.insert(out.indices.end(), b.indices.begin(), b.indices.end());
    out.data.insert(out.data.end(), b.data.begin(), b.data.end());
  }
  return out;
}

void mixed_mass_times(std::size_t n_new_triangles, const Index* offsets, const Index* old_triangle,
                      const double* mass, const Triangle* old_triangles, const Triangle* new_triangles,
                      const double* values, std::size_t columns, std::size_t n_new_points, double* rhs) {
  std::fill(rhs, rhs + n_new_points * columns, 0.0);
  for (std::size_t t = 0; t < n_new_triangles; ++t)
    for (Index k = offsets[t]; k < offsets[t + 1]; ++k) {
      const Triangle& s = old_triangles[old_triangle[k]];
      const double* m = mass + 9 * k;
      for (int a = 0; a < 3; ++a) {
        double* out = rhs + new_triangles[t][a] * columns;
        for (std::size_t c = 0; c < columns; ++c)
          out[c] += m[3 * a] * values[s[0] * columns + c] + m[3 * a + 1] * values[s[1] * columns + c] +
                    m[3 * a + 2] * values[s[2] * columns + c];
      }
    }
}

namespace {

// Dot products and updates over fixed blocks of rows: partial sums per block,
// added in block order (independent of the thread count).
constexpr std::size_t solve_block = 4096;

template <class Row>
double blocked_sum(std::size_t n, int threads, std::vector<double>& partial, Row row) {
  const std::size_t blocks = (n + solve_block - 1) / solve_block;
  partial.assign(blocks, 0.0);
  parallel_for(blocks, threads, [&](std::size_t b) {
    double sum = 0.0;
    for (std::size_t i = b * solve_block, end = std::min(n, i + solve_block); i < end; ++i) sum += row(i);
    partial[b] = sum;
  });
  double total = 0.0;
  for (const double x : partial) total += x;
  return total;
}

}  // namespace

std::vector<double> solve_p1_mass(const Csr_matrix& mass, const std::vector<double>& rhs, std::size_t columns,
                                  int threads, int* iterations) {
  const std::size_t n = mass.indptr.empty() ? 0 : mass.indptr.size() - 1;
  if (rhs.size() != n * columns) throw Input_error("rhs must have one row per point");
  std::vector<double> diagonal(n, 0.0), row_sum(n, 0.0);
  for (std::size_t i = 0; i < n; ++i)
    for (Index k = mass.indptr[i]; k < mass.indptr[i + 1]; ++k) {
      if (static_cast<std::size_t>(mass.indices[k]) == i) diagonal[i] = mass.data[k];
      row_sum[i] += mass.data[k];
    }
  for (const double d : diagonal)
    if (!(d > 0)) throw Input_error("the mass matrix needs a positive diagonal (every point in a triangle)");
  const auto times = [&](const std::vector<double>& x, std::size_t i) {
    double y = 0.0;
    for (Index k = mass.indptr[i]; k < mass.indptr[i + 1]; ++k) y += mass.data[k] * x[mass.indices[k]];
    return y;
  };
  std::vector<double> out(n * columns);
  std::vector<double> b(n), u(n), r(n), z(n), p(n), q(n), partial;
  int most = 0;
  const double eps = std::numeric_limits<double>::epsilon();
  for (std::size_t c = 0; c < columns; ++c) {
    for (std::size_t i = 0; i < n; ++i) b[i] = rhs[i * columns + c];
    const double scale = std::sqrt(blocked_sum(n, threads, partial, [&](std::size_t i) { return b[i] * b[i] / diagonal[i]; }));
    const double tiny = eps * std::max(scale, std::numeric_limits<double>::min());
    for (std::size_t i = 0; i < n; ++i) u[i] = b[i] / diagonal[i];
    double rz = blocked_sum(n, threads, partial, [&](std::size_t i) {
      r[i] = b[i] - times(u, i);
      z[i] = r[i] / diagonal[i];
      p[i] = z[i];
      return r[i] * z[i];
    });
    int iteration = 0;
    for (; iteration < 200 && !(std::sqrt(std::abs(rz)) <= tiny); ++iteration) {
      const double pq = blocked_sum(n, threads, partial, [&](std::size_t i) {
        q[i] = times(p, i);
        return p[i] * q[i];
      });
      const double alpha = pq != 0 ? rz / pq : 0.0;
      const double rz_new = blocked_sum(n, threads, partial, [&](std::size_t i) {
        u[i] += alpha * p[i];
        r[i] -= alpha * q[i];
        z[i] = r[i] / diagonal[i];
        return r[i] * z[i];
      });
      const double beta = rz != 0 ? rz_new / rz : 0.0;
      parallel_for((n + solve_block - 1) / solve_block, threads, [&](std::size_t blk) {
        for (std::size_t i = blk * solve_block, end = std::min(n, i + solve_block); i < end; ++i) p[i] = z[i] + beta * p[i];
      });
      rz = rz_new;
    }
    most = std::max(most, iteration);
    // The integral: 1^T M u = 1^T rhs up to rounding, whatever the iteration left over.
    const double defect = blocked_sum(n, threads, partial, [&](std::size_t i) { return b[i] - times(u, i); });
    const double total = blocked_sum(n, threads, partial, [&](std::size_t i) { return row_sum[i]; });
    const double shift = defect / total;
    for (std::size_t i = 0; i < n; ++i) out[i * columns + c] = u[i] + shift;
  }
  if (iterations) *iterations = most;
  return out;
}

}  // namespace evomesh
