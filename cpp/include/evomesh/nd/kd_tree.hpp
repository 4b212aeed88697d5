// A static kd-tree over points in D dimensions (the dimension-generic sibling
// of detail/static_kd_tree.hpp, which keeps the 2-D core's exact shape and
// bits; the 3-D step uses this one). A complete binary tree in heap order:
// node 1 is the root, node k has children 2k and 2k + 1, the leaves are nodes
// n_leaves() .. 2 n_leaves() - 1 and leaf L holds the positions
// [leaf_begin(L), leaf_begin(L + 1)) of the points in tree order. Each inner
// node splits its range at the median along the longer side of its points'
// box, ties by index: the shape depends on the points only, never on threads.
// Boxes are the exact bounding boxes of the points below, so the distance
// from a query to a box never exceeds the computed distance to a point in it
// (rounding is monotone): pruning on it never skips a point. Header-only.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <numeric>
#include <vector>

#include "evomesh/parallel.hpp"
#include "evomesh/types.hpp"

namespace evomesh::nd {

template <std::size_t D>
using Point = std::array<double, D>;

// The squared distance of two points, summed in axis order: every caller
// (the tree's searches and the brute-force references) uses this expression.
template <std::size_t D>
inline double squared_distance(const Point<D>& a, const Point<D>& b) {
  double s = 0;
  for (std::size_t i = 0; i < D; ++i) {
    const double d = a[i] - b[i];
    s += d * d;
  }
  return s;
}

template <std::size_t D>
struct Box {
  Point<D> lo, hi;
};

// The squared distance from x to the box (0 inside): at most the computed
// squared distance from x to any point in it.
template <std::size_t D>
inline double squared_distance(const Box<D>& b, const Point<D>& x) {
  double s = 0;
  for (std::size_t i = 0; i < D; ++i) {
    const double d = std::max({b.lo[i] - x[i], 0.0, x[i] - b.hi[i]});
    s += d * d;
  }
  return s;
}

template <std::size_t D>
class Kd_tree {
 public:
  static constexpr std::size_t kLeafSize = 8;

  explicit Kd_tree(const std::vector<Point<D>>& points) : n_(points.size()) {
    if (n_ >= std::numeric_limits<std::uint32_t>::max()) throw Input_error("too many points for a kd-tree");
    while ((n_ >> depth_) > kLeafSize) ++depth_;
    n_leaves_ = std::size_t{1} << depth_;
    point_at_.resize(n_);
    std::iota(point_at_.begin(), point_at_.end(), std::uint32_t{0});
    if (n_ > 0) build(points, 1, 0);
    tree_points_.resize(n_);
    for (std::size_t k = 0; k < n_; ++k) tree_points_[k] = points[point_at_[k]];
    boxes_.resize(2 * n_leaves_);
    for (std::size_t leaf = 0; leaf < n_leaves_; ++leaf) {
      Box<D>& b = boxes_[n_leaves_ + leaf];
      b.lo.fill(std::numeric_limits<double>::infinity());
      b.hi.fill(-std::numeric_limits<double>::infinity());
      for (std::size_t k = leaf_begin(leaf); k < leaf_begin(leaf + 1); ++k) {
        for (std::size_t i = 0; i < D; ++i) {
          b.lo[i] = std::min(b.lo[i], tree_points_[k][i]);
          b.hi[i] = std::max(b.hi[i], tree_points_[k][i]);
        }
      }
    }
    for (std::size_t node = n_leaves_ - 1; node >= 1; --node) {
      for (std::size_t i = 0; i < D; ++i) {
        boxes_[node].lo[i] = std::min(boxes_[2 * node].lo[i], boxes_[2 * node + 1].lo[i]);
        boxes_[node].hi[i] = std::max(boxes_[2 * node].hi[i], boxes_[2 * node + 1].hi[i]);
      }
    }
  }

  std::size_t size() const { return n_; }
  std::size_t n_leaves() const { return n_leaves_; }
  std::size_t n_nodes() const { return 2 * n_leaves_; }
  bool is_leaf(std::size_t node) const { return node >= n_leaves_; }
  std::size_t leaf_begin(std::size_t leaf) const {
    return static_cast<std::size_t>(static_cast<unsigned __int128>(leaf) * n_ / n_leaves_);
  }
  std::size_t leaf_of(std::size_t position) const {
    return static_cast<std::size_t>((static_cast<unsigned __int128>(position + 1) * n_leaves_ + n_ - 1) / n_ - 1);
  }
  // Positions [begin, end) of a leaf node.
  std::size_t node_begin(std::size_t node) const { return leaf_begin(node - n_leaves_); }
  std::size_t node_end(std::size_t node) const { return leaf_begin(node - n_leaves_ + 1); }
  const Box<D>& box(std::size_t node) const { return boxes_[node]; }
  // Input index of the point at a position, and the point there.
  const std::vector<std::uint32_t>& point_at() const { return point_at_; }
  const Point<D>& tree_point(std::size_t position) const { return tree_points_[position]; }
  // The position of each input index.
  std::vector<std::uint32_t> positions() const {
    std::vector<std::uint32_t> out(n_);
    for (std::size_t k = 0; k < n_; ++k) out[point_at_[k]] = static_cast<std::uint32_t>(k);
    return out;
  }

 private:
  std::pair<std::size_t, std::size_t> range(std::size_t node, int level) const {
    const std::size_t j = node - (std::size_t{1} << level);
    const int shift = depth_ - level;
    return {leaf_begin(j << shift), leaf_begin((j + 1) << shift)};
  }

  void build(const std::vector<Point<D>>& points, std::size_t node, int level) {
    if (level == depth_) return;
    const auto [begin, end] = range(node, level);
    Point<D> lo, hi;
    lo.fill(std::numeric_limits<double>::infinity());
    hi.fill(-std::numeric_limits<double>::infinity());
    for (std::size_t k = begin; k < end; ++k) {
      for (std::size_t i = 0; i < D; ++i) {
        lo[i] = std::min(lo[i], points[point_at_[k]][i]);
        hi[i] = std::max(hi[i], points[point_at_[k]][i]);
      }
    }
    std::size_t axis = 0;
    for (std::size_t i = 1; i < D; ++i) {
      if (hi[i] - lo[i] > hi[axis] - lo[axis]) axis = i;
    }
    const std::size_t mid = range(2 * node + 1, level + 1).first;
    auto first = point_at_.begin();
    std::nth_element(first + begin, first + mid, first + end, [&](std::uint32_t u, std::uint32_t v) {
      return points[u][axis] < points[v][axis] || (points[u][axis] == points[v][axis] && u < v);
    });
    build(points, 2 * node, level + 1);
    build(points, 2 * node + 1, level + 1);
  }

  std::size_t n_;
  int depth_ = 0;
  std::size_t n_leaves_ = 1;
  std::vector<std::uint32_t> point_at_;
  std::vector<Point<D>> tree_points_;
  std::vector<Box<D>> boxes_;
};

// Nearest-neighbour distances (to the nearest other point), by input index;
// Input_error for duplicate points. Queries run in parallel; the answer is the
// minimum of the same expressions whatever the visiting order.
template <std::size_t D>
std::vector<double> nearest_neighbour_distances(const std::vector<Point<D>>& points, int threads) {
  const Kd_tree<D> tree(points);
  const std::size_t n = points.size();
  std::vector<double> nn(n, std::numeric_limits<double>::infinity());
  constexpr std::size_t kChunk = 2048;
  parallel_for((n + kChunk - 1) / kChunk, threads, [&](std::size_t c) {
    std::size_t stack[128];
    for (std::size_t k = c * kChunk; k < std::min(n, (c + 1) * kChunk); ++k) {
      const Point<D>& x = tree.tree_point(k);
      double best = std::numeric_limits<double>::infinity();
      int top = 0;
      stack[top++] = 1;
      while (top > 0) {
        const std::size_t node = stack[--top];
        if (squared_distance(tree.box(node), x) >= best) continue;
        if (tree.is_leaf(node)) {
          for (std::size_t j = tree.node_begin(node); j < tree.node_end(node); ++j) {
            if (j == k) continue;
            const double d = squared_distance<D>(tree.tree_point(j), x);
            if (d == 0) throw Input_error("points contain duplicates");
            best = std::min(best, d);
          }
        } else {
          stack[top++] = 2 * node + 1;
          stack[top++] = 2 * node;
        }
      }
      nn[tree.point_at()[k]] = std::sqrt(best);
    }
  });
  return nn;
}

}  // namespace evomesh::nd
