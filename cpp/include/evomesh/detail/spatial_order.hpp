// Spatial orders of points: the orders the core visits points in, so that
// consecutive points are near each other (Apollonius graph construction and
// queries, point location). Internal: included by cpp/src only.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh::detail {

// A point with its index in the input, as the orders return them: contiguous
// records, so a caller walks the points in order without gathering them.
struct Ordered_point {
  double x, y;
  std::size_t index;
};

enum class Spatial_order {
  // CGAL::hilbert_sort (median policy): exactly the permutation it gives
  // (the same random shuffle, the same median splits with the same
  // comparisons), the subranges below the top levels sorted in parallel.
  hilbert,
  // CGAL::spatial_sort: exactly its permutation (the same shuffle, then that
  // Hilbert sort on the rounds of a biased randomised insertion order).
  brio,
  // The Hilbert curve on a 2^16 x 2^16 grid over the bounding box, ties in
  // input order: O(n), and walks about as short. Its permutation alone (4
  // bytes a point instead of an Ordered_point's 24):
  // nd::hilbert_grid_permutation (nd/hilbert_order.hpp).
  hilbert_grid,
};

// The n points in the order `how`. The order never depends on `threads`
// (0: the default, see parallel.hpp).
std::vector<Ordered_point> spatial_order(const Vec2* points, std::size_t n, Spatial_order how, int threads = 0);

inline std::vector<Ordered_point> spatial_order(const std::vector<Vec2>& points, Spatial_order how, int threads = 0) {
  return spatial_order(points.data(), points.size(), how, threads);
}

}  // namespace evomesh::detail
