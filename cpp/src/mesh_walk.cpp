#include "evomesh/mesh_walk.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "evomesh/kernel.hpp"

namespace evomesh {

namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

double cross(const Vec2& u, const Vec2& v) { return u[0] * v[1] - u[1] * v[0]; }

int index_in(const Triangle& t, Index v) { return t[0] == v ? 0 : t[1] == v ? 1 : 2; }

}  // namespace

Mesh_walk::Mesh_walk(const Mesh_arrays& mesh, const Triangle_fans& fans) : mesh_(mesh), fans_(fans) {
  segment_of_edge_.reserve(2 * mesh.segments.size());
  for (std::size_t s = 0; s < mesh.segments.size(); ++s) {
    segment_of_edge_[key(mesh.segments[s][0], mesh.segments[s][1])] = static_cast<Index>(s);
  }
}

Index Mesh_walk::across(Index t, Index a, Index b) const {
  for (Index k = fans_.xadj[a]; k < fans_.xadj[a + 1]; ++k) {
    const Index u = fans_.adj[k];
    if (u == t) continue;
    const Triangle& tri = mesh_.triangles[u];
    if (tri[0] == b || tri[1] == b || tri[2] == b) return u;
  }
  return -1;
}

std::pair<Index, double> Mesh_walk::cast(Index v, const Vec2& d, double limit, bool* left) const {
  const Vec2& p = mesh_.points[v];
  // the triangle at v whose angle contains d
  Index t = -1;
  int k = 0;  // t's vertex v
  for (Index a = fans_.xadj[v]; a < fans_.xadj[v + 1] && t < 0; ++a) {
    const Triangle& tri = mesh_.triangles[fans_.adj[a]];
    const int i = index_in(tri, v);
    const Vec2& b = mesh_.points[tri[(i + 1) % 3]];
    const Vec2& c = mesh_.points[tri[(i + 2) % 3]];
    if (cross({b[0] - p[0], b[1] - p[1]}, d) >= 0 && cross(d, {c[0] - p[0], c[1] - p[1]}) >= 0) {
      t = fans_.adj[a];
      k = i;
    }
  }
  if (t < 0) return {-1, kInfinity};  // d points out of the domain
  int exit_edge = (k + 1) % 3;  // the edge opposite v
  for (int step = 0; step < 1000; ++step) {
    const Triangle& tri = mesh_.triangles[t];
    const Index a = tri[exit_edge], b = tri[(exit_edge + 1) % 3];
    const Vec2& pa = mesh_.points[a];
    const Vec2& pb = mesh_.points[b];
    // where the ray p + s d crosses the line ab
    const Vec2 ab{pb[0] - pa[0], pb[1] - pa[1]};
    const double denominator = cross(d, ab);
    if (denominator == 0) return {-1, kInfinity};
    const double s = cross({pa[0] - p[0], pa[1] - p[1]}, ab) / denominator;
    if (!(s <= limit)) return {-1, kInfinity};
    const auto found = segment_of_edge_.find(key(a, b));
    if (found != segment_of_edge_.end()) return {found->second, std::max(s, 0.0)};
    const Index next = across(t, a, b);
    if (next < 0) {
      if (left != nullptr) *left = true;
      return {-1, kInfinity};
    }
    // the edge of `next` other than (a, b) that the ray leaves through
    const Triangle& ntri = mesh_.triangles[next];
    int m = 0;
    while (!((ntri[m] == b && ntri[(m + 1) % 3] == a))) ++m;
    const Index c = ntri[(m + 2) % 3];
    const Vec2& pc = mesh_.points[c];
    const double side = cross(d, {pc[0] - p[0], pc[1] - p[1]});
    // the ray passes c on its left: it leaves through (c, b)... by orientation of the pieces
    exit_edge = side > 0 ? (m + 1) % 3 : (m + 2) % 3;
    t = next;
  }
  return {-1, kInfinity};
}

Index Mesh_walk::locate_from(Index v, const Vec2& x, int max_steps, bool* left) const {
  if (left != nullptr) *left = false;
  const auto& P = mesh_.points;
  const Vec2& p = P[v];
  // the triangle (v, b, c) at v (counter-clockwise) whose open angle contains x
  Index t = -1;
  Index a = -1, b = -1;  // the edge (a, b) of t that the line v -> x leaves through
  for (Index k = fans_.xadj[v]; k < fans_.xadj[v + 1] && t < 0; ++k) {
    const Triangle& tri = mesh_.triangles[fans_.adj[k]];
    const int i = index_in(tri, v);
    const Index tb = tri[(i + 1) % 3], tc = tri[(i + 2) % 3];
    if (orientation(p, P[tb], x) > 0 && orientation(p, P[tc], x) < 0) {
      t = fans_.adj[k];
      a = tb;
      b = tc;
    }
  }
  for (int step = 0; t >= 0 && step < max_steps; ++step) {
    const int side = orientation(P[a], P[b], x);  // > 0: x on t's side of (a, b)
    if (side > 0) return t;
    if (side == 0 || is_segment(a, b)) return -1;
    const Index next = across(t, a, b);
    if (next < 0) {  // (boundary edges are segments: the border of a part)
      if (left != nullptr) *left = true;
      return -1;
    }
    const Triangle& tri = mesh_.triangles[next];
    const Index c = tri[(index_in(tri, a) + 1) % 3];  // next = (b, a, c) counter-clockwise
    const int at_c = orientation(p, x, P[c]);
    if (at_c == 0) {  // the line passes through c: beyond x (x inside `next`) or not
      return orientation(P[a], P[c], x) > 0 && orientation(P[c], P[b], x) > 0 ? next : -1;
    }
    // c left of v -> x (as b is): the line leaves through (a, c), else through (c, b)
    if (at_c > 0) b = c;
    else a = c;
    t = next;
  }
  return -1;
}

}  // namespace evomesh
