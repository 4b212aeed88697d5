// Nearest-neighbour distances with a static kd-tree (detail/static_kd_tree.hpp).
// Internal: included by cpp/src only.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <limits>
#include <vector>

#include "evomesh/detail/static_kd_tree.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/types.hpp"

namespace evomesh::detail {

// All nearest neighbours with a static kd-tree (leaves of at most 16 points in
// tree order, boxes exact): nn(p) = min over q != p of the squared distance,
// computed as CGAL::squared_distance does. The minimum over all points is the
// minimum over the Delaunay neighbours (a nearest neighbour is one), without
// building the triangulation, and the queries run in parallel. The answers do
// not depend on the shape of the tree: every distance is the same expression,
// and pruning never skips a point.
class Point_tree {
 public:
  explicit Point_tree(const std::vector<Vec2>& points) : tree_(points, kLeafSize, points_) {}

  std::size_t size() const { return points_.size(); }

  // Squared distance from x to the nearest point of the tree (any point,
  // also one of the tree's own; +inf for an empty tree).
  double squared_nearest(const Vec2& x) const {
    double best = std::numeric_limits<double>::infinity();
    if (points_.empty()) return best;
    nearer_first(x, [&] { return best; }, [&](std::size_t leaf) { best = leaf_min<false>(leaf, x, 0, best); });
    return best;
  }

  // Whether some point of the tree lies within squared distance `bound` of x
  // (computed as squared_nearest computes it): the search prunes every node
  // farther than the bound, so far queries stop near the root.
  bool has_point_within(const Vec2& x, double bound) const {
    if (points_.empty()) return false;
    bool found = false;
    nearer_first(x, [&] { return found ? -1.0 : bound; }, [&](std::size_t leaf) {
      found = found || leaf_min<false>(leaf, x, 0, std::numeric_limits<double>::infinity()) <= bound;
    });
    return found;
  }

  // Squared distances from x to its nearest and second nearest points of the
  // tree (+inf where the tree has fewer).
  std::array<double, 2> squared_two_nearest(const Vec2& x) const {
    std::array<double, 2> best{std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
    if (points_.empty()) return best;
    nearer_first(x, [&] { return best[1]; }, [&](std::size_t leaf) {
      for (std::size_t k = tree_.leaf_begin(leaf); k < tree_.leaf_begin(leaf + 1); ++k) {
        const double dx = x[0] - points_[k][0];
        const double dy = x[1] - points_[k][1];
        const double d = dx * dx + dy * dy;
        if (d < best[0]) best = {d, best[0]};
        else if (d < best[1]) best[1] = d;
      }
    });
    return best;
  }

  // Squared nearest-neighbour distances, by point index.
  std::vector<double> squared_nn(int threads) const {
    const std::size_t n = points_.size();
    const auto& point_at = tree_.point_at();
    std::vector<double> nn2(n);
    constexpr std::size_t kChunk = 4096;  // in tree order: neighbouring queries
    parallel_for((n + kChunk - 1) / kChunk, threads, [&](std::size_t c) {
      for (std::size_t k = c * kChunk; k < std::min(n, (c + 1) * kChunk); ++k) {
        nn2[point_at[k]] = query(k);
        if (nn2[point_at[k]] == 0 && has_duplicate(k)) throw Input_error("points contain duplicates");
      }
    });
    return nn2;
  }

 private:
  static constexpr std::size_t kLeafSize = 16;

  // The least of `best` and the squared distances from x to the points of a
  // leaf (other than the one at position `self`, with skip_self).
  template <bool skip_self>
  double leaf_min(std::size_t leaf, const Vec2& x, std::size_t self, double best) const {
    for (std::size_t k = tree_.leaf_begin(leaf); k < tree_.leaf_begin(leaf + 1); ++k) {
      if (skip_self && k == self) continue;
      const double dx = x[0] - points_[k][0];
      const double dy = x[1] - points_[k][1];
      best = std::min(best, dx * dx + dy * dy);
    }
    return best;
  }

  // Depth-first from the root, the nearer child first; a node farther from x
  // than bound() (the current best) is pruned, a leaf goes to visit(leaf).
  template <class Bound, class Visit>
  void nearer_first(const Vec2& x, Bound&& bound, Visit&& visit) const {
    tree_.depth_first(1, [&](std::size_t m, Kd_stack& stack) {
      if (squared_distance(tree_.node(m), x[0], x[1]) > bound()) return false;
      if (tree_.is_leaf(m)) {
        visit(tree_.leaf(m));
      } else if (squared_distance(tree_.node(2 * m), x[0], x[1]) <=
                 squared_distance(tree_.node(2 * m + 1), x[0], x[1])) {  // nearer child first
        stack.push_children(m);
      } else {
        stack.push_children_right_first(m);
      }
      return false;
    });
  }

  // Whether another point has the same coordinates: a squared distance of 0 is
  // a duplicate only then (tiny distances underflow to 0 too; nn is then 0, as
  // from the Delaunay edges).
  bool has_duplicate(std::size_t self) const {
    const Vec2& p = points_[self];
    return tree_.depth_first(1, [&](std::size_t m, Kd_stack& stack) {
      const Box& b = tree_.node(m);
      if (p[0] < b.lo_x || p[0] > b.hi_x || p[1] < b.lo_y || p[1] > b.hi_y) return false;
      if (!tree_.is_leaf(m)) {
        stack.push_children(m);
        return false;
      }
      const std::size_t leaf = tree_.leaf(m);
      for (std::size_t k = tree_.leaf_begin(leaf); k < tree_.leaf_begin(leaf + 1); ++k) {
        if (k != self && points_[k] == p) return true;
      }
      return false;
    });
  }

  // Own leaf first, then the sibling subtrees up to the root, pruned by the
  // best distance so far (box distances never exceed point distances).
  double query(std::size_t self) const {
    const Vec2& p = points_[self];
    double best = std::numeric_limits<double>::infinity();
    tree_.outward(
        self,
        [&](std::size_t leaf) {
          best = leaf_min<true>(leaf, p, self, best);
          return false;
        },
        [&](std::size_t m, Kd_stack& stack) {
          if (squared_distance(tree_.node(m), p[0], p[1]) > best) return false;
          if (tree_.is_leaf(m)) best = leaf_min<true>(tree_.leaf(m), p, self, best);
          else stack.push_children(m);
          return false;
        });
    return best;
  }

  std::vector<Vec2> points_;  // in tree order (filled by tree_, declared first)
  Static_kd_tree<> tree_;
};

}  // namespace evomesh::detail
