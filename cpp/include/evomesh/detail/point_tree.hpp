// A static kd-tree over points for nearest-neighbour distances. Internal:
// included by cpp/src only.
#pragma once

#include <algorithm>
#include <cstddef>
#include <limits>
#include <utility>
#include <vector>

#include "evomesh/parallel.hpp"
#include "evomesh/types.hpp"

namespace evomesh::detail {

// All nearest neighbours with a static kd-tree (leaves of at most 16 points in
// tree order, boxes exact): nn(p) = min over q != p of the squared distance,
// computed as CGAL::squared_distance does. The minimum over all points is the
// minimum over the Delaunay neighbours (a nearest neighbour is one), without
// building the triangulation, and the queries run in parallel.
class Point_tree {
 public:
  explicit Point_tree(const std::vector<Vec2>& points) {
    const std::size_t n = points.size();
    while ((n >> depth_) > kLeafSize) ++depth_;
    n_leaves_ = std::size_t{1} << depth_;
    items_.resize(n);
    for (std::size_t i = 0; i < n; ++i) items_[i] = {points[i][0], points[i][1], i};
    boxes_.resize(2 * n_leaves_);
    const int top = std::min(depth_, 2);
    for (int level = 0; level < top; ++level) {
      for (std::size_t node = std::size_t{1} << level; node < (std::size_t{2} << level); ++node) split(node, level);
    }
    const std::size_t first = std::size_t{1} << top;
    parallel_for(first, 0, [&](std::size_t k) { build(first + k, top); });
    for (std::size_t leaf = 0; leaf < n_leaves_; ++leaf) {
      Box& box = boxes_[n_leaves_ + leaf];
      box = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
             -std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};
      for (std::size_t k = leaf_begin(leaf); k < leaf_begin(leaf + 1); ++k) {
        box = {std::min(box.lo_x, items_[k].x), std::min(box.lo_y, items_[k].y), std::max(box.hi_x, items_[k].x),
               std::max(box.hi_y, items_[k].y)};
      }
    }
    for (std::size_t node = n_leaves_ - 1; node >= 1; --node) {
      const Box& l = boxes_[2 * node];
      const Box& r = boxes_[2 * node + 1];
      boxes_[node] = {std::min(l.lo_x, r.lo_x), std::min(l.lo_y, r.lo_y), std::max(l.hi_x, r.hi_x),
                      std::max(l.hi_y, r.hi_y)};
    }
  }

  std::size_t size() const { return items_.size(); }

  // Squared distance from x to the nearest point of the tree (any point,
  // also one of the tree's own; +inf for an empty tree).
  double squared_nearest(const Vec2& x) const {
    double best = std::numeric_limits<double>::infinity();
    if (items_.empty()) return best;
    std::size_t stack[128];
    int top = 0;
    stack[top++] = 1;
    while (top > 0) {
      const std::size_t m = stack[--top];
      const Box& b = boxes_[m];
      const double dx = std::max({b.lo_x - x[0], 0.0, x[0] - b.hi_x});
      const double dy = std::max({b.lo_y - x[1], 0.0, x[1] - b.hi_y});
      if (dx * dx + dy * dy > best) continue;
      if (m >= n_leaves_) {
        for (std::size_t k = leaf_begin(m - n_leaves_); k < leaf_begin(m - n_leaves_ + 1); ++k) {
          const double ex = x[0] - items_[k].x, ey = x[1] - items_[k].y;
          best = std::min(best, ex * ex + ey * ey);
        }
      } else {
        // nearer child last, so it is searched first
        const Box& l = boxes_[2 * m];
        const double lx = std::max({l.lo_x - x[0], 0.0, x[0] - l.hi_x});
        const double ly = std::max({l.lo_y - x[1], 0.0, x[1] - l.hi_y});
        const Box& r = boxes_[2 * m + 1];
        const double rx = std::max({r.lo_x - x[0], 0.0, x[0] - r.hi_x});
        const double ry = std::max({r.lo_y - x[1], 0.0, x[1] - r.hi_y});
        if (lx * lx + ly * ly <= rx * rx + ry * ry) {
          stack[top++] = 2 * m + 1;
          stack[top++] = 2 * m;
        } else {
          stack[top++] = 2 * m;
          stack[top++] = 2 * m + 1;
        }
      }
    }
    return best;
  }

  // Squared nearest-neighbour distances, by point index.
  std::vector<double> squared_nn(int threads) const {
    const std::size_t n = items_.size();
    std::vector<double> nn2(n);
    constexpr std::size_t kChunk = 4096;  // in tree order: neighbouring queries
    parallel_for((n + kChunk - 1) / kChunk, threads, [&](std::size_t c) {
      for (std::size_t k = c * kChunk; k < std::min(n, (c + 1) * kChunk); ++k) {
        nn2[items_[k].index] = query(k);
        if (nn2[items_[k].index] == 0 && has_duplicate(k)) throw Input_error("points contain duplicates");
      }
    });
    return nn2;
  }

 private:
  static constexpr std::size_t kLeafSize = 16;
  struct Item {
    double x, y;
    std::size_t index;
  };
  struct Box {
    double lo_x, lo_y, hi_x, hi_y;
  };

  std::size_t leaf_begin(std::size_t leaf) const {
    return static_cast<std::size_t>(static_cast<unsigned __int128>(leaf) * items_.size() / n_leaves_);
  }
  std::size_t leaf_of(std::size_t position) const {
    const std::size_t n = items_.size();
    return static_cast<std::size_t>((static_cast<unsigned __int128>(position + 1) * n_leaves_ + n - 1) / n - 1);
  }
  std::pair<std::size_t, std::size_t> range(std::size_t node, int level) const {
    const std::size_t j = node - (std::size_t{1} << level);
    const int shift = depth_ - level;
    return {leaf_begin(j << shift), leaf_begin((j + 1) << shift)};
  }

  void split(std::size_t node, int level) {
    if (level == depth_) return;
    const auto [begin, end] = range(node, level);
    double lo_x = std::numeric_limits<double>::infinity(), lo_y = lo_x, hi_x = -lo_x, hi_y = -lo_x;
    for (std::size_t k = begin; k < end; ++k) {
      lo_x = std::min(lo_x, items_[k].x);
      lo_y = std::min(lo_y, items_[k].y);
      hi_x = std::max(hi_x, items_[k].x);
      hi_y = std::max(hi_y, items_[k].y);
    }
    const std::size_t mid = range(2 * node + 1, level + 1).first;
    auto first = items_.begin();
    if (hi_x - lo_x >= hi_y - lo_y) {
      std::nth_element(first + begin, first + mid, first + end, [](const Item& u, const Item& v) {
        return u.x < v.x || (u.x == v.x && u.index < v.index);
      });
    } else {
      std::nth_element(first + begin, first + mid, first + end, [](const Item& u, const Item& v) {
        return u.y < v.y || (u.y == v.y && u.index < v.index);
      });
    }
  }

  void build(std::size_t node, int level) {
    split(node, level);
    if (level == depth_) return;
    build(2 * node, level + 1);
    build(2 * node + 1, level + 1);
  }

  double leaf_min(std::size_t leaf, std::size_t self, double best) const {
    const Item& p = items_[self];
    for (std::size_t k = leaf_begin(leaf); k < leaf_begin(leaf + 1); ++k) {
      if (k == self) continue;
      const double dx = p.x - items_[k].x;
      const double dy = p.y - items_[k].y;
      best = std::min(best, dx * dx + dy * dy);
    }
    return best;
  }

  // Whether another point has the same coordinates: a squared distance of 0 is
  // a duplicate only then (tiny distances underflow to 0 too; nn is then 0, as
  // from the Delaunay edges).
  bool has_duplicate(std::size_t self) const {
    const Item& p = items_[self];
    std::size_t stack[128];
    int top = 0;
    stack[top++] = 1;
    while (top > 0) {
      const std::size_t m = stack[--top];
      const Box& b = boxes_[m];
      if (p.x < b.lo_x || p.x > b.hi_x || p.y < b.lo_y || p.y > b.hi_y) continue;
      if (m >= n_leaves_) {
        for (std::size_t k = leaf_begin(m - n_leaves_); k < leaf_begin(m - n_leaves_ + 1); ++k) {
          if (k != self && items_[k].x == p.x && items_[k].y == p.y) return true;
        }
      } else {
        stack[top++] = 2 * m + 1;
        stack[top++] = 2 * m;
      }
    }
    return false;
  }

  // Own leaf first, then the sibling subtrees up to the root, pruned by the
  // best distance so far (box distances never exceed point distances).
  double query(std::size_t self) const {
    const Item& p = items_[self];
    std::size_t node = n_leaves_ + leaf_of(self);
    double best = leaf_min(node - n_leaves_, self, std::numeric_limits<double>::infinity());
    std::size_t stack[128];
    for (; node > 1; node >>= 1) {
      int top = 0;
      stack[top++] = node ^ 1;
      while (top > 0) {
        const std::size_t m = stack[--top];
        const Box& b = boxes_[m];
        const double dx = std::max({b.lo_x - p.x, 0.0, p.x - b.hi_x});
        const double dy = std::max({b.lo_y - p.y, 0.0, p.y - b.hi_y});
        if (dx * dx + dy * dy > best) continue;
        if (m >= n_leaves_) {
          best = leaf_min(m - n_leaves_, self, best);
        } else {
          stack[top++] = 2 * m + 1;
          stack[top++] = 2 * m;
        }
      }
    }
    return best;
  }

  int depth_ = 0;
  std::size_t n_leaves_ = 1;
  std::vector<Item> items_;
  std::vector<Box> boxes_;
};

}  // namespace evomesh::detail
