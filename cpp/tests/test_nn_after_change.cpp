// nn_spacing_after_change against nn_spacing of the output, bit for bit: outputs
// that lose and gain points in a band, in clusters and everywhere (the fallback),
// input nn partly unknown, lattices (ties everywhere), coordinates at 1e-150 and
// 1e150, and a new point on top of a kept one (both throw the same error).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "check.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/triangulation.hpp"

using namespace evomesh;

namespace {

struct Output {
  std::vector<Vec2> points;
  std::vector<Index> origin;
  std::vector<Triangle> triangles;
};

// Keeps the input points except those `drop` says, adds `added`, triangulates
// (inside a square boundary of four extra kept points).
Output make_output(const std::vector<Vec2>& input, const std::vector<std::uint8_t>& drop,
                   const std::vector<Vec2>& added) {
  Output out;
  for (std::size_t o = 0; o < input.size(); ++o) {
    if (drop[o]) continue;
    out.points.push_back(input[o]);
    out.origin.push_back(static_cast<Index>(o));
  }
  for (const Vec2& p : added) {
    out.points.push_back(p);
    out.origin.push_back(-1);
  }
  const Index m = static_cast<Index>(input.size());  // the last four input points are the square's corners
  std::vector<Constraint_piece> pieces;
  std::vector<Index> corner;
  for (Index c = m - 4; c < m; ++c) {
    corner.push_back(static_cast<Index>(std::find(out.origin.begin(), out.origin.end(), c) - out.origin.begin()));
  }
  for (int k = 0; k < 4; ++k) pieces.push_back({corner[k], corner[(k + 1) % 4], true});
  out.triangles = constrained_delaunay(out.points, pieces);
  return out;
}

void check_case(const char* name, const std::vector<Vec2>& input, const std::vector<double>& input_nn,
                const Output& out) {
  const std::vector<double> expected = nn_spacing(out.points);
  const std::vector<double> got = nn_spacing_after_change(input, input_nn, out.points, out.triangles, out.origin);
  CHECK(got.size() == expected.size() &&
        std::memcmp(got.data(), expected.data(), got.size() * sizeof(double)) == 0)
      << name;
}

std::vector<Vec2> square_points(std::size_t n, bool lattice, double scale, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.01, 0.99);
  std::vector<Vec2> p;
  if (lattice) {
    const int side = static_cast<int>(std::sqrt(static_cast<double>(n)));
    for (int j = 0; j < side; ++j) {
      for (int i = 0; i < side; ++i) {
        p.push_back({scale * (0.01 + 0.98 * i / (side - 1)), scale * (0.01 + 0.98 * j / (side - 1))});
      }
    }
  } else {
    for (std::size_t i = 0; i < n; ++i) p.push_back({scale * u(rng), scale * u(rng)});
  }
  for (const Vec2& c : {Vec2{-0.05, -0.05}, Vec2{1.05, -0.05}, Vec2{1.05, 1.05}, Vec2{-0.05, 1.05}}) {
    p.push_back({scale * c[0], scale * c[1]});
  }
  return p;
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> u(0, 1);
    for (double scale : {1.0, 1e-150, 1e150}) {
      for (bool lattice : {false, true}) {
        const std::vector<Vec2> input = square_points(6000, lattice, scale, rng);
        const std::size_t n = input.size();
        const std::vector<double> input_nn = nn_spacing(input);
        // A band that loses every third point and gains new ones (a front step).
        std::vector<std::uint8_t> drop(n, 0);
        std::vector<Vec2> added;
        for (std::size_t o = 0; o + 4 < n; ++o) {
          const double x = input[o][0] / scale;
          if (x > 0.3 && x < 0.36 && o % 3 == 0) drop[o] = 1;
        }
        for (int k = 0; k < 150; ++k) added.push_back({scale * (0.3 + 0.06 * u(rng)), scale * (0.01 + 0.98 * u(rng))});
        check_case(lattice ? "band, lattice" : "band", input, input_nn, make_output(input, drop, added));
        // Lattice points added exactly between old ones (ties with the old nn).
        if (lattice) {
          std::vector<Vec2> between;
          for (std::size_t o = 0; o + 4 < n && between.size() < 40; o += 97) {
            between.push_back({input[o][0], input[o][1] + 0.5 * input_nn[o]});
          }
          check_case("lattice, points between", input, input_nn,
                     make_output(input, std::vector<std::uint8_t>(n, 0), between));
        }
        // Unknown input nn at some points, a few scattered removals.
        std::vector<double> partly = input_nn;
        for (std::size_t o = 0; o < n; o += 7) partly[o] = std::numeric_limits<double>::quiet_NaN();
        std::vector<std::uint8_t> scattered(n, 0);
        for (std::size_t o = 5; o + 4 < n; o += 211) scattered[o] = 1;
        check_case("unknown nn, scattered removals", input, partly, make_output(input, scattered, {}));
        // Nothing changed; and a change too large for the shortcut (half of the points).
        check_case("unchanged", input, input_nn, make_output(input, std::vector<std::uint8_t>(n, 0), {}));
        std::vector<std::uint8_t> half(n, 0);
        for (std::size_t o = 0; o + 4 < n; o += 2) half[o] = 1;
        check_case("half removed", input, input_nn, make_output(input, half, {}));
      }
    }
    // A new point on top of a kept one: both refuse the duplicate.
    const std::vector<Vec2> input = square_points(500, false, 1.0, rng);
    const std::vector<double> input_nn = nn_spacing(input);
    std::vector<Vec2> points = input;
    std::vector<Index> origin(input.size());
    for (std::size_t o = 0; o < input.size(); ++o) origin[o] = static_cast<Index>(o);
    points.push_back(input[17]);
    origin.push_back(-1);
    bool threw = false;
    try {
      nn_spacing_after_change(input, input_nn, points, {}, origin);
    } catch (const Input_error&) {
      threw = true;
    }
    CHECK(threw) << "duplicate point";
    // The same bits on 1 and 3 threads.
    std::vector<std::uint8_t> drop(input.size(), 0);
    drop[40] = drop[41] = 1;
    const Output out = make_output(input, drop, {{0.5, 0.5}, {0.25, 0.75}});
    std::vector<double> one, three;
    {
      const Thread_limit limit(1);
      one = nn_spacing_after_change(input, input_nn, out.points, out.triangles, out.origin);
    }
    {
      const Thread_limit limit(3);
      three = nn_spacing_after_change(input, input_nn, out.points, out.triangles, out.origin);
    }
    CHECK(one == three) << "1 and 3 threads";
  });
}
