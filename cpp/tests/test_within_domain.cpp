// keep_within_domain against its definition (the least std::hypot of every
// point's edges, compared with nn beyond rounding), bit for bit: lattices (every
// edge a tie), jittered grids with slits (points whose nearest point hides behind
// a constraint), points without triangles, and coordinates scaled to 1e-150 and
// 1e200 (squares out of the normal range).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "check.hpp"
#include "evomesh/local_feature_size.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/triangulation.hpp"

using namespace evomesh;

namespace {

std::vector<std::uint8_t> reference(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                                    std::vector<double>& nn) {
  std::vector<double> shortest(points.size(), std::numeric_limits<double>::infinity());
  for (const Triangle& t : triangles) {
    for (int k = 0; k < 3; ++k) {
      const Index a = t[k], b = t[(k + 1) % 3];
      const double length = std::hypot(points[b][0] - points[a][0], points[b][1] - points[a][1]);
      shortest[a] = std::min(shortest[a], length);
      shortest[b] = std::min(shortest[b], length);
    }
  }
  std::vector<std::uint8_t> changed(points.size(), 0);
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (std::isfinite(shortest[i]) && shortest[i] > nn[i] * (1 + 4 * std::numeric_limits<double>::epsilon())) {
      nn[i] = shortest[i];
      changed[i] = 1;
    }
  }
  return changed;
}

// A grid of nx x ny points (jittered), triangulated with `slits` interior
// constraints, each with pairs of points `gap` (in grid spacings) apart across
// it: their nearest point hides behind the constraint.
struct Case {
  std::vector<Vec2> points;
  std::vector<Triangle> triangles;
};

Case grid_case(int nx, int ny, double jitter, int slits, double gap, double scale, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  Case c;
  std::vector<Constraint_piece> pieces;
  const double h = 1.0 / (nx - 1);
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const bool inner = i > 0 && i + 1 < nx && j > 0 && j + 1 < ny;
      c.points.push_back({scale * (i * h + (inner ? jitter * h * u(rng) : 0.0)),
                          scale * (j * h + (inner ? jitter * h * u(rng) : 0.0))});
    }
  }
  for (int s = 0; s < slits; ++s) {  // a horizontal constraint with points a gap apart across it
    const double y = (s + 1.37) * h;
    const double x0 = 1.3 * h, x1 = 1 - 1.3 * h;
    const Index first = static_cast<Index>(c.points.size());
    c.points.push_back({scale * x0, scale * y});
    c.points.push_back({scale * x1, scale * y});
    pieces.push_back({first, first + 1, false});
    for (int k = 0; k < 5; ++k) {
      const double x = x0 + (k + 0.5) / 5 * (x1 - x0);
      c.points.push_back({scale * x, scale * (y - 0.5 * gap * h)});
      c.points.push_back({scale * x, scale * (y + 0.5 * gap * h)});
    }
  }
  // The boundary of the square.
  auto at = [&](int i, int j) { return static_cast<Index>(j * nx + i); };
  for (int i = 0; i + 1 < nx; ++i) pieces.push_back({at(i, 0), at(i + 1, 0), true});
  for (int j = 0; j + 1 < ny; ++j) pieces.push_back({at(nx - 1, j), at(nx - 1, j + 1), true});
  for (int i = nx - 1; i > 0; --i) pieces.push_back({at(i, ny - 1), at(i - 1, ny - 1), true});
  for (int j = ny - 1; j > 0; --j) pieces.push_back({at(0, j), at(0, j - 1), true});
  c.triangles = constrained_delaunay(c.points, pieces);
  return c;
}

void check_same(const char* name, const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                std::size_t& n_changed) {
  std::vector<double> nn = nn_spacing(points);
  std::vector<double> expected = nn;
  const auto expected_changed = reference(points, triangles, expected);
  const auto changed = keep_within_domain(points, triangles, nn);
  CHECK(changed == expected_changed) << name << ": which points changed";
  CHECK(std::memcmp(nn.data(), expected.data(), nn.size() * sizeof(double)) == 0) << name << ": the values";
  for (std::uint8_t c : changed) n_changed += c;
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    std::mt19937_64 rng(7);
    std::size_t n_changed = 0;
    for (double scale : {1.0, 1e-150, 1e200, 3.7e-9}) {
      for (double jitter : {0.0, 0.3}) {
        for (int slits : {0, 1, 3}) {
          for (double gap : {1e-3, 0.3}) {
            const Case c = grid_case(23, 19, jitter, slits, gap, scale, rng);
            char name[96];
            std::snprintf(name, sizeof name, "scale %g jitter %g slits %d gap %g", scale, jitter, slits, gap);
            check_same(name, c.points, c.triangles, n_changed);
          }
        }
      }
    }
    CHECK(n_changed > 0) << "the cases have points whose nn grows";
    // The same bits on any number of threads.
    {
      const Case c = grid_case(61, 57, 0.3, 3, 1e-3, 1.0, rng);
      std::vector<double> one = nn_spacing(c.points);
      std::vector<double> many = one;
      std::vector<std::uint8_t> changed_one, changed_many;
      {
        const Thread_limit limit(1);
        changed_one = keep_within_domain(c.points, c.triangles, one);
      }
      for (int threads : {2, 3, 5}) {
        std::vector<double> nn = many;
        const Thread_limit limit(threads);
        changed_many = keep_within_domain(c.points, c.triangles, nn);
        CHECK(changed_many == changed_one && nn == one) << threads << " threads";
      }
    }
    // A point no triangle uses keeps its nn; nn of NaN stays NaN (as the definition).
    const Case c = grid_case(9, 9, 0.2, 1, 1e-3, 1.0, rng);
    std::vector<Vec2> points = c.points;
    points.push_back({0.5 + 1e-9, 0.5});
    std::vector<Triangle> triangles = c.triangles;
    check_same("orphan point", points, triangles, n_changed);
    std::printf("keep_within_domain: %zu changed points over all cases, the definition's bits\n", n_changed);
  });
}
