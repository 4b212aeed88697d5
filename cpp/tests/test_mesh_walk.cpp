// Mesh_walk::locate_from (the gap repair's point location, mesh_walk.hpp)
// against brute force with exact predicates, on a lattice (lines through
// vertices and points on edges happen there) and a jittered one, with a wall of
// interior segments; Point_tree::squared_two_nearest against brute force; and
// the old mesh's walker (parent map) built with its own fans or a step's.
#include <algorithm>
#include <cstdio>
#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "check.hpp"
#include "evomesh/candidates.hpp"
#include "evomesh/nd/kd_tree.hpp"
#include "evomesh/kernel.hpp"
#include "evomesh/mesh_walk.hpp"
#include "evomesh/parent_map.hpp"

using namespace evomesh;

namespace {

// A k x k grid of the unit square, two triangles per cell (counter-clockwise),
// the boundary as segments, and a wall of interior segments along x = 1/2 for
// y in [1/4, 3/4] (k - 1 divisible by 4).
Mesh_arrays grid(int k, double jitter, unsigned seed) {
  Mesh_arrays m;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-jitter, jitter);
  const double h = 1.0 / (k - 1);
  for (int j = 0; j < k; ++j) {
    for (int i = 0; i < k; ++i) {
      const bool inner = i > 0 && j > 0 && i < k - 1 && j < k - 1 && 2 * i != k - 1;
      m.points.push_back({i * h + (inner ? u(rng) * h : 0.0), j * h + (inner ? u(rng) * h : 0.0)});
    }
  }
  auto id = [k](int i, int j) { return static_cast<Index>(j * k + i); };
  for (int j = 0; j + 1 < k; ++j) {
    for (int i = 0; i + 1 < k; ++i) {
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  }
  for (int i = 0; i + 1 < k; ++i) {
    m.segments.push_back({id(i, 0), id(i + 1, 0)});
    m.segments.push_back({id(k - 1, i), id(k - 1, i + 1)});
    m.segments.push_back({id(i + 1, k - 1), id(i, k - 1)});
    m.segments.push_back({id(0, i + 1), id(0, i)});
  }
  m.segment_is_boundary.assign(m.segments.size(), 1);
  for (int j = (k - 1) / 4; j < 3 * (k - 1) / 4; ++j) {
    m.segments.push_back({id((k - 1) / 2, j), id((k - 1) / 2, j + 1)});
    m.segment_is_boundary.push_back(0);
  }
  m.kind.assign(m.points.size(), Point_kind::original);
  return m;
}

// Whether the closed segments ab and cd share a point (exact).
bool intersect(const Vec2& a, const Vec2& b, const Vec2& c, const Vec2& d) {
  const int o1 = orientation(a, b, c), o2 = orientation(a, b, d);
  const int o3 = orientation(c, d, a), o4 = orientation(c, d, b);
  if (o1 * o2 < 0 && o3 * o4 < 0) return true;
  auto on = [](const Vec2& p, const Vec2& q, const Vec2& r) {  // r on the closed segment pq, collinear
    return std::min(p[0], q[0]) <= r[0] && r[0] <= std::max(p[0], q[0]) && std::min(p[1], q[1]) <= r[1] &&
           r[1] <= std::max(p[1], q[1]);
  };
  return (o1 == 0 && on(a, b, c)) || (o2 == 0 && on(a, b, d)) || (o3 == 0 && on(c, d, a)) ||
         (o4 == 0 && on(c, d, b));
}

// What locate_from(v, x) must answer: the triangle containing x strictly, when
// the open segment v -> x passes through no vertex and meets no segment that
// does not end at v... and x is inside the domain; -1 otherwise.
Index expected(const Mesh_arrays& m, Index v, const Vec2& x) {
  const Vec2& p = m.points[v];
  for (std::size_t w = 0; w < m.points.size(); ++w) {
    if (static_cast<Index>(w) == v) continue;
    const Vec2& q = m.points[w];
    if (orientation(p, x, q) == 0 && intersect(p, x, q, q)) return -1;  // through a vertex (or x on it)
  }
  for (const Edge& s : m.segments) {
    if (s[0] == v || s[1] == v) continue;
    if (intersect(p, x, m.points[s[0]], m.points[s[1]])) return -1;
  }
  for (std::size_t t = 0; t < m.triangles.size(); ++t) {
    const Triangle& tri = m.triangles[t];
    const auto& P = m.points;
    if (orientation(P[tri[0]], P[tri[1]], x) > 0 && orientation(P[tri[1]], P[tri[2]], x) > 0 &&
        orientation(P[tri[2]], P[tri[0]], x) > 0) {
      return static_cast<Index>(t);
    }
  }
  return -1;
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    for (double jitter : {0.0, 0.25}) {
      const Mesh_arrays m = grid(17, jitter, 7);
      const Triangle_fans fans(m);
      const Mesh_walk walk(m, fans);
      std::mt19937 rng(11);
      std::uniform_int_distribution<Index> pick(0, static_cast<Index>(m.points.size() - 1));
      std::uniform_real_distribution<double> angle(0, 6.283185307179586), reach(0.0, 3.5 / 16);
      std::uniform_int_distribution<int> lattice(-3, 3);
      int wrong = 0, located = 0, refused = 0;
      for (int q = 0; q < 4000; ++q) {
        const Index v = pick(rng);
        Vec2 x;
        if (q % 2 == 0) {  // along the lattice: through vertices, onto edges
          x = {m.points[v][0] + lattice(rng) / 32.0, m.points[v][1] + lattice(rng) / 32.0};
        } else {
          const double a = angle(rng), r = reach(rng);
          x = {m.points[v][0] + r * std::cos(a), m.points[v][1] + r * std::sin(a)};
        }
        if (x == m.points[v]) continue;
        const Index got = walk.locate_from(v, x);
        const Index want = expected(m, v, x);
        if (got != want && wrong < 5) {
          std::fprintf(stderr, "v %ld (%.17g %.17g) x (%.17g %.17g): got %ld, brute force %ld\n", static_cast<long>(v),
                       m.points[v][0], m.points[v][1], x[0], x[1], static_cast<long>(got), static_cast<long>(want));
        }
        wrong += got != want;
        (got >= 0 ? located : refused) += 1;
      }
      CHECK(wrong == 0) << "jitter " << jitter << ": " << wrong << " answers differ from brute force";
      CHECK(located > 500 && refused > 200) << "jitter " << jitter << ": located " << located << ", refused "
                                            << refused;
    }
    // Old_mesh_walker::triangle_at: the last (largest) triangle around a point,
    // -1 for a point of no triangle, whether the walker builds its fans or takes
    // a step's; and a walk from there finds the triangle brute force finds.
    for (double jitter : {0.0, 0.25}) {
      Mesh_arrays m = grid(17, jitter, 5);
      m.points.push_back({2.0, 2.0});  // in no triangle
      std::vector<Index> last(m.points.size(), -1);
      for (std::size_t t = 0; t < m.triangles.size(); ++t) {
        for (Index v : m.triangles[t]) last[v] = static_cast<Index>(t);
      }
      const Old_mesh_walker own(m);
      const Old_mesh_walker taken(m, Triangle_fans(m));
      int wrong = 0, walked_wrong = 0;
      for (std::size_t v = 0; v < m.points.size(); ++v) {
        const Index i = static_cast<Index>(v);
        wrong += own.triangle_at(i) != last[v] || taken.triangle_at(i) != last[v];
      }
      CHECK(wrong == 0) << "jitter " << jitter << ": " << wrong << " points with another triangle_at";
      std::mt19937 rng(13);
      std::uniform_real_distribution<double> u(0.01, 0.99);
      for (int q = 0; q < 500; ++q) {
        const Vec2 x{u(rng), u(rng)};
        std::size_t steps = 0;
        const Index got = taken.walk(taken.triangle_at(0), x, static_cast<std::size_t>(q), steps);
        const Triangle& t = m.triangles[got < 0 ? 0 : got];
        const bool inside = got >= 0 && orientation(m.points[t[0]], m.points[t[1]], x) >= 0 &&
                            orientation(m.points[t[1]], m.points[t[2]], x) >= 0 &&
                            orientation(m.points[t[2]], m.points[t[0]], x) >= 0;
        walked_wrong += !inside;
      }
      CHECK(walked_wrong == 0) << "jitter " << jitter << ": " << walked_wrong << " walks ended outside their point";
    }
    // squared_two_nearest against brute force
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(0, 1);
    for (std::size_t n : {0, 1, 2, 3, 17, 500}) {
      std::vector<Vec2> points(n);
      for (auto& p : points) p = {u(rng), u(rng)};
      const nd::Point_tree<2> tree(points);
      int wrong = 0;
      for (int q = 0; q < 300; ++q) {
        const Vec2 x = q % 3 == 0 && n > 0 ? points[q % n] : Vec2{u(rng), u(rng)};
        std::array<double, 2> best{std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
        for (const Vec2& p : points) {
          const double dx = x[0] - p[0], dy = x[1] - p[1], d = dx * dx + dy * dy;
          if (d < best[0]) best = {d, best[0]};
          else if (d < best[1]) best[1] = d;
        }
        wrong += tree.squared_two_nearest(x) != best;
      }
      CHECK(wrong == 0) << "n " << n << ": squared_two_nearest differs from brute force at " << wrong << " queries";
    }
  });
}
