// The spatial orders (detail/spatial_order.hpp) against the CGAL sorts they
// reproduce, the Hilbert index in 2-D and 3-D (nd/hilbert_order.hpp), and the
// nearest-point queries of the static kd-tree (nd/kd_tree.hpp) in 2-D and 3-D
// against brute force.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Spatial_sort_traits_adapter_2.h>
#include <CGAL/hilbert_sort.h>
#include <CGAL/property_map.h>
#include <CGAL/spatial_sort.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "check.hpp"
#include "evomesh/detail/spatial_order.hpp"
#include "evomesh/nd/hilbert_order.hpp"
#include "evomesh/nd/kd_tree.hpp"
#include "evomesh/parallel.hpp"

using namespace evomesh;
using detail::Spatial_order;

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;

enum class Layout { uniform, lattice, clustered, line };

// Points with many equal coordinates (lattice, line) or spread over scales (clustered).
std::vector<Vec2> make_points(std::size_t n, Layout layout, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Vec2> points(n);
  const auto side = static_cast<std::size_t>(std::ceil(std::sqrt(static_cast<double>(n))));
  for (std::size_t i = 0; i < n; ++i) {
    switch (layout) {
      case Layout::uniform: points[i] = {u(rng), u(rng)}; break;
      case Layout::lattice: points[i] = {static_cast<double>(i % side), static_cast<double>(i / side)}; break;
      case Layout::clustered: {
        const double scale = std::pow(10.0, -6.0 * u(rng));
        points[i] = {0.3 + scale * u(rng), 0.7 - scale * u(rng)};
        break;
      }
      case Layout::line: points[i] = {static_cast<double>(i % 7), 2.0}; break;
    }
  }
  return points;
}

std::vector<std::size_t> indices(const std::vector<detail::Ordered_point>& order) {
  std::vector<std::size_t> out(order.size());
  for (std::size_t k = 0; k < order.size(); ++k) out[k] = order[k].index;
  return out;
}

void check_orders(const char* name, const std::vector<Vec2>& points) {
  const std::size_t n = points.size();
  std::vector<K::Point_2> cgal_points;
  for (const auto& p : points) cgal_points.emplace_back(p[0], p[1]);
  using Traits = CGAL::Spatial_sort_traits_adapter_2<K, CGAL::Pointer_property_map<K::Point_2>::type>;
  const Traits traits(CGAL::make_property_map(cgal_points));
  std::vector<std::size_t> hilbert(n), brio(n);
  std::iota(hilbert.begin(), hilbert.end(), 0);
  std::iota(brio.begin(), brio.end(), 0);
  CGAL::hilbert_sort(hilbert.begin(), hilbert.end(), traits);
  CGAL::spatial_sort(brio.begin(), brio.end(), traits);
  for (int threads : {1, 2}) {
    const auto ours_hilbert = detail::spatial_order(points, Spatial_order::hilbert, threads);
    const auto ours_brio = detail::spatial_order(points, Spatial_order::brio, threads);
    CHECK(indices(ours_hilbert) == hilbert) << name << ": not CGAL::hilbert_sort's order, threads " << threads;
    CHECK(indices(ours_brio) == brio) << name << ": not CGAL::spatial_sort's order, threads " << threads;
    bool coordinates = true;
    for (const auto& q : ours_brio) coordinates = coordinates && q.x == points[q.index][0] && q.y == points[q.index][1];
    CHECK(coordinates) << name << ": records carry other coordinates";
    // The grid order: a permutation, the same for any thread count.
    auto grid = indices(detail::spatial_order(points, Spatial_order::hilbert_grid, threads));
    const auto grid_one = indices(detail::spatial_order(points, Spatial_order::hilbert_grid, 1));
    CHECK(grid == grid_one) << name << ": the grid order depends on the threads";
    // Equal points share a key: they come by index (the order is by key, then index).
    bool ties_by_index = true;
    for (std::size_t k = 1; k < n; ++k) {
      if (points[grid[k]] == points[grid[k - 1]]) ties_by_index = ties_by_index && grid[k - 1] < grid[k];
    }
    CHECK(ties_by_index) << name << ": equal points of the grid order are not by index";
    std::sort(grid.begin(), grid.end());
    bool permutation = true;
    for (std::size_t k = 0; k < n; ++k) permutation = permutation && grid[k] == k;
    CHECK(permutation) << name << ": the grid order is not a permutation";
  }
  std::printf("%-24s %7zu points: orders as CGAL's\n", name, n);
}

// squared_nearest and squared_nn against brute force.
void check_tree(const char* name, const std::vector<Vec2>& points, unsigned seed) {
  const nd::Point_tree<2> tree(points);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-0.2, 1.2);
  std::size_t wrong = 0;
  for (int q = 0; q < 200; ++q) {
    const Vec2 x = q % 4 == 0 && !points.empty() ? points[rng() % points.size()] : Vec2{u(rng), u(rng)};
    double best = std::numeric_limits<double>::infinity();
    for (const auto& p : points) {
      const double dx = x[0] - p[0], dy = x[1] - p[1];
      best = std::min(best, dx * dx + dy * dy);
    }
    wrong += tree.squared_nearest(x) != best;
  }
  CHECK(wrong == 0) << name << ": squared_nearest differs from brute force at " << wrong << " queries";
  if (points.size() >= 2) {
    const auto nn2 = tree.squared_nn(2);
    std::size_t nn_wrong = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
      double best = std::numeric_limits<double>::infinity();
      for (std::size_t j = 0; j < points.size(); ++j) {
        if (j == i) continue;
        const double dx = points[i][0] - points[j][0], dy = points[i][1] - points[j][1];
        best = std::min(best, dx * dx + dy * dy);
      }
      nn_wrong += nn2[i] != best;
    }
    CHECK(nn_wrong == 0) << name << ": squared_nn differs from brute force at " << nn_wrong << " points";
  }
}

// The quadrant-rotation form of the 2-D Hilbert index (the core's 2-D grid
// order before it was dimension-generic): nd::hilbert_index<2> must equal it.
std::uint32_t quadrant_hilbert_index(std::uint32_t x, std::uint32_t y) {
  std::uint32_t d = 0;
  for (std::uint32_t s = 1u << 15; s > 0; s >>= 1) {
    const std::uint32_t rx = (x & s) > 0, ry = (y & s) > 0;
    d += s * s * ((3 * rx) ^ ry);
    if (ry == 0) {
      if (rx == 1) {
        x = s - 1 - x;
        y = s - 1 - y;
      }
      std::swap(x, y);
    }
  }
  return d;
}

// A Hilbert curve starts at the origin and fills the cube of side 2^k there
// with its first 2^(D k) cells, each a unit step from the one before.
template <std::size_t D>
void check_hilbert_curve(std::uint32_t side) {
  std::size_t cells = 1;
  for (std::size_t i = 0; i < D; ++i) cells *= side;
  std::vector<std::array<std::uint32_t, D>> at(cells);
  std::vector<std::uint8_t> seen(cells, 0);
  bool inside = true;
  for (std::size_t c = 0; c < cells; ++c) {
    std::array<std::uint32_t, D> x;
    std::size_t rest = c;
    for (std::size_t i = 0; i < D; ++i) x[i] = static_cast<std::uint32_t>(rest % side), rest /= side;
    const std::uint32_t d = nd::hilbert_index<D>(x);
    if (d >= cells || seen[d]) {
      inside = false;
      continue;
    }
    seen[d] = 1;
    at[d] = x;
  }
  CHECK(inside) << D << "-D: the first cells of the curve are not the cube at the origin";
  std::size_t jumps = 0;
  for (std::size_t d = 1; inside && d < cells; ++d) {
    std::uint32_t step = 0;
    for (std::size_t i = 0; i < D; ++i) step += at[d][i] > at[d - 1][i] ? at[d][i] - at[d - 1][i] : at[d - 1][i] - at[d][i];
    jumps += step != 1;
  }
  CHECK(jumps == 0) << D << "-D: " << jumps << " consecutive cells of the curve are not neighbours";
}

void check_hilbert() {
  std::mt19937_64 rng(7);
  std::size_t wrong = 0;
  for (int k = 0; k < 100000; ++k) {
    const auto x = static_cast<std::uint32_t>(rng() & 0xffff), y = static_cast<std::uint32_t>(rng() & 0xffff);
    wrong += nd::hilbert_index<2>({x, y}) != quadrant_hilbert_index(x, y);
  }
  CHECK(wrong == 0) << "the 2-D Hilbert index differs from the quadrant form at " << wrong << " cells";
  check_hilbert_curve<2>(64);
  check_hilbert_curve<3>(16);
  // The 3-D grid order: a permutation, the same for any thread count.
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<nd::Point<3>> points(5000);
  for (auto& p : points) p = {u(rng), u(rng), u(rng)};
  auto order = nd::hilbert_grid_permutation<3>(points.data(), points.size(), 2);
  CHECK(order == nd::hilbert_grid_permutation<3>(points.data(), points.size(), 1)) << "3-D order depends on threads";
  std::sort(order.begin(), order.end());
  bool permutation = true;
  for (std::size_t k = 0; k < order.size(); ++k) permutation = permutation && order[k] == k;
  CHECK(permutation) << "the 3-D grid order is not a permutation";
  std::printf("hilbert index: 2-D as the quadrant form, 2-D and 3-D curves continuous\n");
}

// The 3-D tree's nearest-neighbour distances against brute force.
void check_tree_3(std::size_t n, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<nd::Point<3>> points(n);
  for (auto& p : points) p = {u(rng), u(rng), std::floor(4 * u(rng)) / 4};  // layers: ties along z
  const std::vector<double> nn = nd::nearest_neighbour_distances<3>(points, 2);
  std::size_t wrong = 0;
  for (std::size_t i = 0; i < n; ++i) {
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t j = 0; j < n; ++j) {
      if (j != i) best = std::min(best, nd::squared_distance<3>(points[i], points[j]));
    }
    wrong += nn[i] != std::sqrt(best);
  }
  CHECK(wrong == 0) << "3-D nearest neighbours differ from brute force at " << wrong << " points";
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    unsigned seed = 1;
    for (std::size_t n : {0, 1, 2, 3, 5, 16, 17, 100, 1000}) {
      for (Layout layout : {Layout::uniform, Layout::lattice, Layout::clustered}) {
        const auto points = make_points(n, layout, seed++);
        check_orders(("small " + std::to_string(n)).c_str(), points);
        check_tree(("tree " + std::to_string(n)).c_str(), points, seed++);
      }
    }
    check_orders("line 50 (ties)", make_points(50, Layout::line, seed++));
    // Above 2^16 points the Hilbert sort splits the top levels and sorts the
    // subranges in parallel.
    check_orders("uniform 70000", make_points(70000, Layout::uniform, seed++));
    check_orders("lattice 90000", make_points(90000, Layout::lattice, seed++));
    check_orders("clustered 300000", make_points(300000, Layout::clustered, seed++));
    check_tree("tree clustered 3000", make_points(3000, Layout::clustered, seed), seed + 1);
    check_hilbert();
    for (std::size_t n : {2, 9, 1000}) check_tree_3(n, seed++);

    bool threw = false;
    try {
      nd::Point_tree<2>(std::vector<Vec2>{{0.0, 0.0}, {1.0, 1.0}, {0.0, 0.0}}).squared_nn(1);
    } catch (const Input_error&) {
      threw = true;
    }
    CHECK(threw) << "duplicate points";
  });
}
