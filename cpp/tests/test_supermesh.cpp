// The local supermesh: for random pairs of meshes of the unit square, the
// intersection areas of each new triangle sum to its area and those of each old
// triangle to its area; the mixed mass entries sum to the areas; the result does
// not depend on the thread count. A new triangle that is an old one (three kept
// points) takes the shortcut and gets the pair the clipping gives; the P1 mass
// matrix, the mixed mass product and the mass solve against brute force.
#include <algorithm>
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

// The same points as g, each cell split along a diagonal drawn again.
Grid redrawn_diagonals(const Grid& g, int k, std::mt19937_64& rng) {
  Grid out;
  out.points = g.points;
  std::bernoulli_distribution flip(0.5);
  for (int j = 0; j + 1 < k; ++j)
    for (int i = 0; i + 1 < k; ++i) {
      const Index a = i + k * j, b = a + 1, c = a + k + 1, d = a + k;
      if (flip(rng)) {
        out.triangles.push_back({a, b, c});
        out.triangles.push_back({a, c, d});
      } else {
        out.triangles.push_back({a, b, d});
        out.triangles.push_back({b, c, d});
      }
    }
  return out;
}

void check_identical_shortcut() {
  std::mt19937_64 rng(99);
  for (int trial = 0; trial < 10; ++trial) {
    const int k = 5 + trial;
    const Grid old = jittered_grid(k, 0.25, rng);
    const Grid fresh = redrawn_diagonals(old, k, rng);
    std::vector<Index> origin(fresh.points.size());
    for (std::size_t v = 0; v < origin.size(); ++v) origin[v] = static_cast<Index>(v);
    const auto seed = supermesh_seeds(old.points.size(), old.triangles, origin, std::vector<Index>(origin.size(), -1));
    const auto identical = identical_old_triangles(old.points.size(), old.triangles, fresh.triangles, origin, 1);
    std::size_t n_identical = 0;
    for (std::size_t t = 0; t < identical.size(); ++t) {
      if (identical[t] < 0) continue;
      ++n_identical;
      Triangle a = fresh.triangles[t], b = old.triangles[identical[t]];
      std::sort(a.begin(), a.end());
      std::sort(b.begin(), b.end());
      CHECK(a == b) << "trial " << trial << ", triangle " << t;
    }
    CHECK(n_identical > 0 && n_identical < identical.size()) << "trial " << trial << ": " << n_identical;
    const Supermesh full = build_supermesh(old.points, old.triangles, fresh.points, fresh.triangles, seed, true, 1);
    const Supermesh fast =
        build_supermesh(old.points, old.triangles, fresh.points, fresh.triangles, seed, true, 1, identical);
    CHECK(full.offsets == fast.offsets && full.old_triangle == fast.old_triangle) << "trial " << trial;
    if (full.old_triangle != fast.old_triangle) continue;
    double worst = 0.0;
    for (std::size_t t = 0; t < fresh.triangles.size(); ++t) {
      const double a = area(fresh, fresh.triangles[t]);
      for (Index p = full.offsets[t]; p < full.offsets[t + 1]; ++p) {
        worst = std::max(worst, std::abs(full.area[p] - fast.area[p]) / a);
        for (int e = 0; e < 9; ++e) worst = std::max(worst, std::abs(full.mass[9 * p + e] - fast.mass[9 * p + e]) / a);
      }
    }
    CHECK(worst < 1e-14) << "trial " << trial << ": shortcut off the clipping by " << worst;
    for (int threads : {2, 3}) {
      const Supermesh other =
          build_supermesh(old.points, old.triangles, fresh.points, fresh.triangles, seed, true, threads, identical);
      CHECK(other.offsets == fast.offsets && other.old_triangle == fast.old_triangle && other.area == fast.area &&
            other.mass == fast.mass)
          << "trial " << trial << ", " << threads << " threads";
      CHECK(identical_old_triangles(old.points.size(), old.triangles, fresh.triangles, origin, threads) == identical);
    }
  }
  // A wrong identical entry (a triangle with other points) is refused.
  const Grid g = jittered_grid(4, 0.0, rng);
  std::vector<Index> origin(g.points.size());
  for (std::size_t v = 0; v < origin.size(); ++v) origin[v] = static_cast<Index>(v);
  const auto seed = supermesh_seeds(g.points.size(), g.triangles, origin, std::vector<Index>(origin.size(), -1));
  std::vector<Index> wrong(g.triangles.size(), -1);
  wrong[0] = static_cast<Index>(g.triangles.size() - 1);
  bool threw = false;
  try {
    build_supermesh(g.points, g.triangles, g.points, g.triangles, seed, true, 1, wrong);
  } catch (const Input_error&) {
    threw = true;
  }
  CHECK(threw);
}

void check_mass_matrix_and_solve() {
  std::mt19937_64 rng(5);
  for (int trial = 0; trial < 6; ++trial) {
    const int k = 4 + 3 * trial;
    const Grid g = jittered_grid(k, 0.3, rng);
    const std::size_t n = g.points.size();
    // brute force: dense accumulation per triangle
    std::vector<double> dense(n * n, 0.0);
    for (const Triangle& t : g.triangles) {
      const double a = area(g, t);
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) dense[t[i] * n + t[j]] += (i == j ? 2.0 : 1.0) * a / 12.0;
    }
    const Csr_matrix m = p1_mass_matrix(g.points, g.triangles, 1);
    CHECK(m.indptr.size() == n + 1);
    double worst = 0.0;
    std::size_t nonzero = 0;
    for (std::size_t i = 0; i < n; ++i) {
      for (Index p = m.indptr[i]; p < m.indptr[i + 1]; ++p) {
        if (p > m.indptr[i]) CHECK(m.indices[p - 1] < m.indices[p]) << "columns sorted";
        worst = std::max(worst, std::abs(m.data[p] - dense[i * n + m.indices[p]]));
      }
      nonzero += static_cast<std::size_t>(m.indptr[i + 1] - m.indptr[i]);
    }
    CHECK(nonzero == static_cast<std::size_t>(std::count_if(dense.begin(), dense.end(), [](double x) { return x != 0; })));
    CHECK(worst < 1e-16) << "trial " << trial << ": " << worst;
    for (int threads : {2, 3}) {
      const Csr_matrix other = p1_mass_matrix(g.points, g.triangles, threads);
      CHECK(other.indptr == m.indptr && other.indices == m.indices && other.data == m.data);
    }
    // solve: two columns, a constant and a random one
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    std::vector<double> x(2 * n);
    for (std::size_t i = 0; i < n; ++i) x[2 * i] = 0.7, x[2 * i + 1] = u(rng);
    std::vector<double> rhs(2 * n, 0.0);
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = 0; j < n; ++j)
        for (int c = 0; c < 2; ++c) rhs[2 * i + c] += dense[i * n + j] * x[2 * j + c];
    int iterations = 0;
    const std::vector<double> solved = solve_p1_mass(m, rhs, 2, 1, &iterations);
    double error = 0.0;
    for (std::size_t i = 0; i < 2 * n; ++i) error = std::max(error, std::abs(solved[i] - x[i]));
    CHECK(error < 1e-12) << "trial " << trial << ": solve off by " << error;
    CHECK(iterations > 0 && iterations < 60) << iterations;
    for (int threads : {2, 3}) CHECK(solve_p1_mass(m, rhs, 2, threads) == solved) << threads << " threads";
  }
}

void check_mixed_mass_times() {
  std::mt19937_64 rng(11);
  const Grid old = jittered_grid(7, 0.25, rng);
  const Grid fresh = jittered_grid(9, 0.25, rng);
  const auto seed = brute_seeds(old, fresh);
  const Supermesh sm = build_supermesh(old.points, old.triangles, fresh.points, fresh.triangles, seed, true, 1);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const std::size_t columns = 3;
  std::vector<double> values(old.points.size() * columns);
  for (double& v : values) v = u(rng);
  std::vector<double> expected(fresh.points.size() * columns, 0.0);
  for (std::size_t t = 0; t < fresh.triangles.size(); ++t)
    for (Index p = sm.offsets[t]; p < sm.offsets[t + 1]; ++p)
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
          for (std::size_t c = 0; c < columns; ++c)
            expected[fresh.triangles[t][a] * columns + c] +=
                sm.mass[9 * p + 3 * a + b] * values[old.triangles[sm.old_triangle[p]][b] * columns + c];
  std::vector<double> rhs(expected.size(), 1.0);
  mixed_mass_times(fresh.triangles.size(), sm.offsets.data(), sm.old_triangle.data(), sm.mass.data(),
                   old.triangles.data(), fresh.triangles.data(), values.data(), columns, fresh.points.size(),
                   rhs.data());
  double worst = 0.0;
  for (std::size_t i = 0; i < rhs.size(); ++i) worst = std::max(worst, std::abs(rhs[i] - expected[i]));
  CHECK(worst < 1e-15) << worst;
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    check_intersection_area();
    check_random_pairs();
    check_missing_seed();
    check_identical_shortcut();
    check_mass_matrix_and_solve();
    check_mixed_mass_times();
  });
}
