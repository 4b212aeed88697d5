// The local supermesh: for random pairs of meshes of the unit square, the
// intersection areas of each new triangle sum to its area and those of each old
// triangle to its area; the mixed mass entries sum to the areas; the result does
// not depend on the thread count.
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "check.hpp"
#include "evomesh/supermesh.hpp"

using namespace evomesh;

namespace {

struct Grid {
  std::vector<Vec2> points;
  std::vector<Triangle> triangles;
};

// A k x k grid of the unit square, interior points jittered by up to `jitter`
// cells, each cell split along a random diagonal (counter-clockwise triangles).
Grid jittered_grid(int k, double jitter, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-jitter, jitter);
  Grid g;
  const double h = 1.0 / (k - 1);
  for (int j = 0; j < k; ++j)
    for (int i = 0; i < k; ++i) {
      Vec2 p{i * h, j * h};
      if (i > 0 && i < k - 1 && j > 0 && j < k - 1) p = {p[0] + u(rng) * h, p[1] + u(rng) * h};
      g.points.push_back(p);
    }
  std::bernoulli_distribution flip(0.5);
  for (int j = 0; j + 1 < k; ++j)
    for (int i = 0; i + 1 < k; ++i) {
      const Index a = i + k * j, b = a + 1, c = a + k + 1, d = a + k;
      if (flip(rng)) {
        g.triangles.push_back({a, b, c});
        g.triangles.push_back({a, c, d});
      } else {
        g.triangles.push_back({a, b, d});
        g.triangles.push_back({b, c, d});
      }
    }
  return g;
}

double area(const Grid& g, const Triangle& t) {
  const Vec2 &a = g.points[t[0]], &b = g.points[t[1]], &c = g.points[t[2]];
  return 0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]));
}

// An old triangle containing each new point (brute force: the test's own search).
std::vector<Index> brute_seeds(const Grid& old, const Grid& fresh) {
  std::vector<Index> seed(fresh.points.size(), -1);
  for (std::size_t v = 0; v < fresh.points.size(); ++v) {
    const Vec2& p = fresh.points[v];
    for (std::size_t s = 0; s < old.triangles.size() && seed[v] < 0; ++s) {
      bool inside = true;
      for (int k = 0; k < 3; ++k) {
        const Vec2& a = old.points[old.triangles[s][k]];
        const Vec2& b = old.points[old.triangles[s][(k + 1) % 3]];
        if ((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) < -1e-14) inside = false;
      }
      if (inside) seed[v] = static_cast<Index>(s);
    }
  }
  return seed;
}

void check_intersection_area() {
  const std::array<Vec2, 3> t = {Vec2{0, 0}, Vec2{1, 0}, Vec2{0, 1}};
  CHECK(std::abs(triangle_intersection_area(t, t) - 0.5) < 1e-15);
  const std::array<Vec2, 3> far = {Vec2{2, 2}, Vec2{3, 2}, Vec2{2, 3}};
  CHECK(triangle_intersection_area(t, far) == 0.0);
  // The reflected triangle (1,1),(0,1),(1,0) meets t only along the diagonal.
  const std::array<Vec2, 3> other = {Vec2{1, 1}, Vec2{0, 1}, Vec2{1, 0}};
  CHECK(std::abs(triangle_intersection_area(t, other)) < 1e-15);
  // t and its translate by (0.5, 0): overlap is a triangle of legs 0.5 -> 0.125.
  const std::array<Vec2, 3> shifted = {Vec2{0.5, 0}, Vec2{1.5, 0}, Vec2{0.5, 1}};
  CHECK(std::abs(triangle_intersection_area(t, shifted) - 0.125) < 1e-15) << triangle_intersection_area(t, shifted);
  // clockwise input gives the same area
  const std::array<Vec2, 3> cw = {Vec2{0, 0}, Vec2{0, 1}, Vec2{1, 0}};
  CHECK(std::abs(triangle_intersection_area(cw, shifted) - 0.125) < 1e-15);
}

void check_random_pairs() {
  std::mt19937_64 rng(12345);
  std::uniform_int_distribution<int> side(3, 14);
  for (int trial = 0; trial < 30; ++trial) {
    const Grid old = jittered_grid(side(rng), trial % 3 == 0 ? 0.0 : 0.25, rng);
    const Grid fresh = jittered_grid(side(rng), trial % 2 == 0 ? 0.0 : 0.25, rng);
    const auto seed = brute_seeds(old, fresh);
    for (const Index s : seed) CHECK(s >= 0) << "trial " << trial;
    const Supermesh sm = build_supermesh(old.points, old.triangles, fresh.points, fresh.triangles, seed, true, 1);
    CHECK(sm.offsets.size() == fresh.triangles.size() + 1);
    std::vector<double> old_sum(old.triangles.size(), 0.0);
    double worst_new = 0.0, worst_old = 0.0, worst_mass = 0.0;
    for (std::size_t t = 0; t < fresh.triangles.size(); ++t) {
      double sum = 0.0;
      const double a = area(fresh, fresh.triangles[t]);
      for (Index k = sm.offsets[t]; k < sm.offsets[t + 1]; ++k) {
        sum += sm.area[k];
        old_sum[sm.old_triangle[k]] += sm.area[k];
        double m = 0.0;
        for (int e = 0; e < 9; ++e) m += sm.mass[9 * k + e];
        worst_mass = std::max(worst_mass, std::abs(m - sm.area[k]) / a);  // slivers: relative to |t|
      }
      worst_new = std::max(worst_new, std::abs(sum - a) / a);
    }
    for (std::size_t s = 0; s < old.triangles.size(); ++s) {
      const double a = area(old, old.triangles[s]);
      worst_old = std::max(worst_old, std::abs(old_sum[s] - a) / a);
    }
    CHECK(worst_new < 1e-12) << "trial " << trial << ": new triangle areas off by " << worst_new;
    CHECK(worst_old < 1e-12) << "trial " << trial << ": old triangle areas off by " << worst_old;
    CHECK(worst_mass < 1e-12) << "trial " << trial << ": mass entries off by " << worst_mass;
    // the same on 2 and 3 threads, bit for bit
    for (int threads : {2, 3}) {
      const Supermesh other =
          build_supermesh(old.points, old.triangles, fresh.points, fresh.triangles, seed, true, threads);
      CHECK(other.offsets == sm.offsets && other.old_triangle == sm.old_triangle && other.area == sm.area &&
            other.mass == sm.mass)
          << "trial " << trial << ", " << threads << " threads";
    }
  }
}

void check_missing_seed() {
  std::mt19937_64 rng(7);
  const Grid g = jittered_grid(4, 0.0, rng);
  std::vector<Index> seed(g.points.size(), -1);
  bool threw = false;
  try {
    build_supermesh(g.points, g.triangles, g.points, g.triangles, seed, false, 1);
  } catch (const Input_error&) {
    threw = true;
  }
  CHECK(threw);
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    check_intersection_area();
    check_random_pairs();
    check_missing_seed();
  });
}
