// Random systems of spheres for the packing tests (test_packing.cpp,
// test_packing_parallel.cpp).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <random>
#include <tuple>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh::test {

struct System {
  std::vector<Vec2> centers;
  std::vector<double> radii;
  std::vector<std::uint8_t> priority;
};

enum class Layout { uniform, clustered, grid };

// n spheres in the unit square; radii `scale / sqrt(n)` times a factor spread
// over `decades` decades (log-uniform), some ties, some exactly touching pairs
// (|c1 - c2| = r1 + r2, on a grid of 1/8 units: no conflict); `clustered`: two
// of three centres near (0.3, 0.6); `grid`: centres on a lattice (many equal
// distances and coordinates). Priorities (classes) 0 .. n_classes - 1.
inline System make_system(std::size_t n, Layout layout, double scale, double decades, std::mt19937_64& rng,
                          int n_classes = 4) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> g(0.0, 1.0);
  System s;
  const double unit = scale / std::sqrt(static_cast<double>(n));
  const auto side = static_cast<std::size_t>(std::ceil(std::sqrt(static_cast<double>(n))));
  for (std::size_t i = 0; i < n; ++i) {
    Vec2 c{u(rng), u(rng)};
    if (layout == Layout::clustered && i % 3 != 0) c = {0.3 + 0.03 * g(rng), 0.6 + 0.03 * g(rng)};
    if (layout == Layout::grid) c = {static_cast<double>(i % side) / side, static_cast<double>(i / side) / side};
    double r = unit * std::pow(10.0, decades * (u(rng) - 0.5));
    if (i % 11 == 3) r = unit;  // ties in radius
    if (i % 13 == 7 && i > 0 && layout != Layout::grid) {  // touching the previous sphere (1/8 units apart)
      c = {s.centers[i - 1][0] + 0.125, s.centers[i - 1][1]};
      s.radii[i - 1] = 0.0625;
      r = 0.0625;
    }
    s.centers.push_back(c);
    s.radii.push_back(r);
    s.priority.push_back(static_cast<std::uint8_t>(u(rng) * n_classes));
  }
  return s;
}

// The order packing_order must give, by std::sort: (class, radius, index) ascending.
inline std::vector<Index> reference_order(const System& s) {
  std::vector<Index> expected(s.centers.size());
  std::iota(expected.begin(), expected.end(), 0);
  std::sort(expected.begin(), expected.end(), [&](Index a, Index b) {
    return std::make_tuple(s.priority[a], s.radii[a], a) < std::make_tuple(s.priority[b], s.radii[b], b);
  });
  return expected;
}

}  // namespace evomesh::test
