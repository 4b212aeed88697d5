// Local supermesh of two tetrahedral meshes of one domain: see evomesh/tet/tet_supermesh.hpp.
#include "evomesh/tet/tet_supermesh.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include "evomesh/detail/cell_stars.hpp"
#include "evomesh/parallel.hpp"

namespace evomesh::tet {

namespace {

using detail::facet_adjacency;
using detail::has_vertex;
using detail::vertex_stars;
using detail::Vertex_stars;
using detail::Visit_marks;

using Corners = std::array<Vec3, 4>;

inline Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
inline double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
inline double abs_volume(const Corners& c) {
  return std::abs(dot(sub(c[1], c[0]), cross(sub(c[2], c[0]), sub(c[3], c[0])))) / 6.0;
}

// The half-space of one face of t that holds t: d(x) = normal . (x - face[0]) >= 0.
struct Half_space {
  Vec3 normal;
  std::array<Vec3, 3> face;
  // Exactly 0 at the face's own vertices (a kept point shared by t and s is
  // on the plane, not a rounding error off it).
  double distance(const Vec3& x) const {
    if (x == face[0] || x == face[1] || x == face[2]) return 0.0;
    return dot(normal, sub(x, face[0]));
  }
};

std::array<Half_space, 4> half_spaces(const Corners& t) {
  std::array<Half_space, 4> h;
  for (int k = 0; k < 4; ++k) {
    const Vec3& a = t[(k + 1) % 4];
    const Vec3& b = t[(k + 2) % 4];
    const Vec3& c = t[(k + 3) % 4];
    Vec3 n = cross(sub(b, a), sub(c, a));
    if (dot(n, sub(t[k], a)) < 0) n = {-n[0], -n[1], -n[2]};
    h[k] = {n, {a, b, c}};
  }
  return h;
}

// The prism with triangles a and b (a[i] joined to b[i]) as three tetrahedra.
void push_prism(const std::array<Vec3, 3>& a, const std::array<Vec3, 3>& b, std::vector<Corners>& out) {
  out.push_back({a[0], a[1], a[2], b[0]});
  out.push_back({a[1], a[2], b[0], b[1]});
  out.push_back({a[2], b[0], b[1], b[2]});
}

// Appends the part of c where h.distance > 0 (a convex piece: a tetrahedron
// or a prism) as at most three tetrahedra.
void clip(const Corners& c, const Half_space& h, std::vector<Corners>& out) {
  double d[4];
  int in[4], out_[4], n_in = 0, n_out = 0;
  for (int k = 0; k < 4; ++k) {
    d[k] = h.distance(c[k]);
    if (d[k] > 0) in[n_in++] = k;
    else out_[n_out++] = k;
  }
  if (n_in == 0) return;
  if (n_in == 4) {
    out.push_back(c);
    return;
  }
  auto cut = [&](int i, int o) {  // the point of edge (i, o) where d = 0
    const double s = d[i] / (d[i] - d[o]);
    return Vec3{c[i][0] + s * (c[o][0] - c[i][0]), c[i][1] + s * (c[o][1] - c[i][1]),
                c[i][2] + s * (c[o][2] - c[i][2])};
  };
  if (n_in == 1) {
    const int i = in[0];
    out.push_back({c[i], cut(i, out_[0]), cut(i, out_[1]), cut(i, out_[2])});
  } else if (n_in == 2) {
    const int i = in[0], j = in[1];
    push_prism({c[i], cut(i, out_[0]), cut(i, out_[1])}, {c[j], cut(j, out_[0]), cut(j, out_[1])}, out);
  } else {
    const int o = out_[0];
    push_prism({c[in[0]], c[in[1]], c[in[2]]}, {cut(in[0], o), cut(in[1], o), cut(in[2], o)}, out);
  }
}

// Scratch lists of the clipping, one per worker thread.
struct Clip_buffers {
  std::vector<Corners> a, b;
};

// Whether every corner of c lies in every half-space (on a plane counts as in).
bool holds(const std::array<Half_space, 4>& planes, const Corners& c) {
  for (const Half_space& h : planes)
    for (const Vec3& x : c)
      if (h.distance(x) < 0) return false;
  return true;
}

// |t n s| for t given by its corners and half-spaces. Before any clipping: s
// outside one plane of t (all its corners on or beyond it) is disjoint from t,
// s inside t is s, t inside s is t (most pairs where one mesh is much finer).
double intersection_volume(const std::array<Half_space, 4>& t, const Corners& t_corners, const Corners& s,
                           Clip_buffers& buffers) {
  bool s_in_t = true;
  for (const Half_space& h : t) {
    bool any_in = false;
    for (const Vec3& x : s) {
      const double d = h.distance(x);
      any_in = any_in || d > 0;
      s_in_t = s_in_t && d >= 0;
    }
    if (!any_in) return 0.0;
  }
  if (s_in_t) return abs_volume(s);
  if (holds(half_spaces(s), t_corners)) return abs_volume(t_corners);
  buffers.a.assign(1, s);
  for (const Half_space& h : t) {
    buffers.b.clear();
    for (const Corners& c : buffers.a) clip(c, h, buffers.b);
    std::swap(buffers.a, buffers.b);
    if (buffers.a.empty()) return 0.0;
  }
  double volume = 0.0;
  for (const Corners& c : buffers.a) volume += abs_volume(c);
  return volume;
}

constexpr std::size_t block_size = 512;

// The old tetrahedron with the four (kept) vertices' origins, else -1.
Index identical_old(const Vertex_stars& stars, const std::vector<Tet>& old_tets, const Tet& t,
                    const std::vector<Index>& origin) {
  Tet o;
  for (int k = 0; k < 4; ++k) {
    o[k] = origin[t[k]];
    if (o[k] < 0) return -1;
  }
  for (Index i = stars.start[o[0]]; i < stars.start[o[0] + 1]; ++i) {
    const Tet& s = old_tets[stars.star[i]];
    if (has_vertex(s, o[1]) && has_vertex(s, o[2]) && has_vertex(s, o[3])) return stars.star[i];
  }
  return -1;
}

struct Block_result {
  std::vector<Index> count;  // pairs per new tetrahedron of the block
  std::vector<Index> old_tet;
  std::vector<double> volume;
  std::size_t identical = 0;
  Index orphan = -1;  // a new tetrahedron without any seed
};

}  // namespace

double tet_intersection_volume(const std::array<Vec3, 4>& t, const std::array<Vec3, 4>& s) {
  Clip_buffers buffers;
  return intersection_volume(half_spaces(t), t, s, buffers);
}

Tet_supermesh build_tet_supermesh(const std::vector<Vec3>& old_points, const std::vector<Tet>& old_tets,
                                  const std::vector<Vec3>& new_points, const std::vector<Tet>& new_tets,
                                  const std::vector<Index>& origin, const std::vector<Index>& parent_tet,
                                  int threads) {
  const std::size_t n_old = old_points.size(), n_new = new_points.size();
  const auto m_old = static_cast<Index>(old_tets.size());
  if (origin.size() != n_new || parent_tet.size() != n_new)
    throw Input_error("origin and parent_tet need one entry per new point");
  for (const Tet& t : old_tets)
    for (const Index v : t)
      if (v < 0 || static_cast<std::size_t>(v) >= n_old) throw Input_error("old tetrahedra: index out of range");
  for (const Tet& t : new_tets)
    for (const Index v : t)
      if (v < 0 || static_cast<std::size_t>(v) >= n_new) throw Input_error("new tetrahedra: index out of range");
  for (std::size_t v = 0; v < n_new; ++v) {
    if (origin[v] >= static_cast<Index>(n_old)) throw Input_error("origin out of range of the old mesh");
    if (parent_tet[v] >= m_old) throw Input_error("parent_tet out of range of the old mesh");
    if (origin[v] >= 0 && new_points[v] != old_points[origin[v]])
      throw Input_error("kept point " + std::to_string(v) + " moved: it is not at its origin's coordinates");
  }
  const Vertex_stars stars = vertex_stars(n_old, old_tets);
  // neighbour[4 s + k]: the old tetrahedron across the face of s without s[(k + 3) % 4].
  const std::vector<Index> neighbour = facet_adjacency(stars, old_tets, threads);
  // Seeds: an old tetrahedron at each new point (the first of a kept point's old star).
  std::vector<Index> seed(n_new, -1);
  for (std::size_t v = 0; v < n_new; ++v) {
    if (origin[v] >= 0 && stars.start[origin[v]] < stars.start[origin[v] + 1]) {
      seed[v] = stars.star[stars.start[origin[v]]];
    } else if (origin[v] < 0) {
      seed[v] = parent_tet[v];
    }
  }
  std::vector<std::array<double, 6>> box(old_tets.size());
  parallel_for((old_tets.size() + block_size - 1) / block_size, threads, [&](std::size_t block) {
    for (std::size_t s = block * block_size, end = std::min(old_tets.size(), s + block_size); s < end; ++s) {
      auto& b = box[s];
      for (int d = 0; d < 3; ++d) {
        b[d] = b[d + 3] = old_points[old_tets[s][0]][d];
        for (int k = 1; k < 4; ++k) {
          b[d] = std::min(b[d], old_points[old_tets[s][k]][d]);
          b[d + 3] = std::max(b[d + 3], old_points[old_tets[s][k]][d]);
        }
      }
    }
  });
  const std::size_t m = new_tets.size();
  const std::size_t n_blocks = (m + block_size - 1) / block_size;
  std::vector<Block_result> blocks(n_blocks);
  parallel_for(n_blocks, threads, [&](std::size_t block) {
    thread_local Visit_marks marks;
    thread_local Clip_buffers buffers;
    Block_result& out = blocks[block];
    const std::size_t begin = block * block_size, end = std::min(m, begin + block_size);
    out.count.assign(end - begin, 0);
    std::vector<Index> queue;
    for (std::size_t t = begin; t < end; ++t) {
      const Tet& tet = new_tets[t];
      const Vec3 origin_point = new_points[tet[0]];
      // Local coordinates (relative to the first vertex of t): less cancellation far from 0.
      Corners tv;
      for (int k = 0; k < 4; ++k) tv[k] = sub(new_points[tet[k]], origin_point);
      const Index same = identical_old(stars, old_tets, tet, origin);
      if (same >= 0) {
        ++out.identical;
        ++out.count[t - begin];
        out.old_tet.push_back(same);
        out.volume.push_back(abs_volume(tv));
        continue;
      }
      const std::array<Half_space, 4> planes = half_spaces(tv);
      double lo[3], hi[3];
      for (int d = 0; d < 3; ++d) {
        lo[d] = std::min({tv[0][d], tv[1][d], tv[2][d], tv[3][d]}) + origin_point[d];
        hi[d] = std::max({tv[0][d], tv[1][d], tv[2][d], tv[3][d]}) + origin_point[d];
        const double margin = 1e-9 * (hi[d] - lo[d]) + 64 * std::numeric_limits<double>::epsilon() *
                                                           std::max(std::abs(lo[d]), std::abs(hi[d]));
        lo[d] -= margin;
        hi[d] += margin;
      }
      const std::uint32_t mark = marks.next(old_tets.size());
      queue.clear();
      for (const Index v : tet)
        if (seed[v] >= 0 && marks.stamp[seed[v]] != mark) {
          marks.stamp[seed[v]] = mark;
          queue.push_back(seed[v]);
        }
      if (queue.empty() && out.orphan < 0) out.orphan = static_cast<Index>(t);
      for (std::size_t head = 0; head < queue.size(); ++head) {
        const Index s = queue[head];
        const auto& b = box[s];
        if (b[0] > hi[0] || b[3] < lo[0] || b[1] > hi[1] || b[4] < lo[1] || b[2] > hi[2] || b[5] < lo[2]) continue;
        for (int k = 0; k < 4; ++k) {
          const Index u = neighbour[4 * s + k];
          if (u >= 0 && marks.stamp[u] != mark) {
            marks.stamp[u] = mark;
            queue.push_back(u);
          }
        }
        Corners sv;
        for (int k = 0; k < 4; ++k) sv[k] = sub(old_points[old_tets[s][k]], origin_point);
        const double volume = intersection_volume(planes, tv, sv, buffers);
        if (!(volume > 0)) continue;
        ++out.count[t - begin];
        out.old_tet.push_back(s);
        out.volume.push_back(volume);
      }
    }
  });
  for (const Block_result& b : blocks)
    if (b.orphan >= 0)
      throw Input_error("new tetrahedron " + std::to_string(b.orphan) +
                        " has no vertex located in the old mesh: the supermesh needs new = evolve(old, ...)");
  Tet_supermesh result;
  result.offsets.assign(m + 1, 0);
  std::size_t total = 0;
  for (const Block_result& b : blocks) total += b.old_tet.size();
  result.old_tet.reserve(total);
  result.volume.reserve(total);
  std::size_t t = 0;
  for (const Block_result& b : blocks) {
    for (const Index c : b.count) {
      result.offsets[t + 1] = result.offsets[t] + c;
      ++t;
    }
    result.old_tet.insert(result.old_tet.end(), b.old_tet.begin(), b.old_tet.end());
    result.volume.insert(result.volume.end(), b.volume.begin(), b.volume.end());
    result.identical += b.identical;
  }
  return result;
}

}  // namespace evomesh::tet
