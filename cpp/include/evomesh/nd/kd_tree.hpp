// The static kd-tree over points in D dimensions: one tree for the 2-D and
// 3-D steps (nearest neighbours, the packing's tree of kept spheres), the 2-D
// boundary's corner search and the 3-D cone envelope f. A complete binary tree in heap order: node 1 is the
// root, node k has children 2k and 2k + 1, the leaves are nodes n_leaves() ..
// 2 n_leaves() - 1, and leaf L holds the positions [leaf_begin(L),
// leaf_begin(L + 1)) of the points in tree order. Boxes are the exact bounding
// boxes of the points below, so the distance from a query to a box never
// exceeds the computed distance to a point in it (rounding is monotone):
// pruning on it never skips a point. Header-only.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "evomesh/detail/bits.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/types.hpp"

namespace evomesh::nd {

template <std::size_t D>
using Point = std::array<double, D>;

// The squared distance of two points, summed in axis order from 0 (0 + a is
// a, so in 2-D it is dx^2 + dy^2): every search and brute-force reference
// uses this expression.
template <std::size_t D>
inline double squared_distance(const Point<D>& a, const Point<D>& b) {
  double s = 0;
  for (std::size_t i = 0; i < D; ++i) {
    const double d = a[i] - b[i];
    s += d * d;
  }
  return s;
}

// An axis-aligned box (empty: lo = +inf, hi = -inf).
template <std::size_t D>
struct Box {
  Point<D> lo, hi;
};

// The squared distance from x to the box (0 inside or on it): at most the
// computed squared distance from x to any point in it.
template <std::size_t D>
inline double squared_distance(const Box<D>& b, const Point<D>& x) {
  double s = 0;
  for (std::size_t i = 0; i < D; ++i) {
    const double d = std::max({b.lo[i] - x[i], 0.0, x[i] - b.hi[i]});
    s += d * d;
  }
  return s;
}

// The nodes a depth-first search has yet to visit, the last pushed first.
class Kd_stack {
 public:
  bool empty() const { return top_ == 0; }
  void push(std::size_t node) { nodes_[top_++] = node; }
  std::size_t pop() { return nodes_[--top_]; }
  // Both children of an inner node, the left one to be visited first.
  void push_children(std::size_t node) {
    push(2 * node + 1);
    push(2 * node);
  }
  // Both children, the right one to be visited first.
  void push_children_right_first(std::size_t node) {
    push(2 * node);
    push(2 * node + 1);
  }

 private:
  std::size_t nodes_[128];  // a search holds at most one pending node per level
  int top_ = 0;
};

// The shape of a static kd-tree over n points (n < 2^32). Leaves hold the
// positions as evenly as integers allow (at most leaf_size + 1), and
// point_at()[position] is the input index of the point there.
//
// Each inner node splits its positions at its children's boundary (a median)
// along the longest side of their bounding box (the first such axis), ties
// broken by index. The shape only affects speed, so it is chosen on compact
// float copies of the points, normalised to their bounding box (any coordinate
// scale works). The top two levels are split first and the subtrees below
// built in parallel: the same tree whatever the number of threads. Every node
// carries a `Node`: a Box (the exact bounding box of its points) with whatever
// the user adds to it (default member initialisers give its start values).
// What a leaf holds and how a node is pruned is the user's.
template <std::size_t D, class Node = Box<D>>
class Static_kd_tree {
 public:
  // `tree_points` receives the points in tree order (for the user's leaves).
  Static_kd_tree(const std::vector<Point<D>>& points, std::size_t leaf_size, std::vector<Point<D>>& tree_points)
      : Static_kd_tree(points, leaf_size, &tree_points, true) {}
  // The same tree without the copy of the points (the user gathers its own
  // leaf records through point_at()).
  Static_kd_tree(const std::vector<Point<D>>& points, std::size_t leaf_size)
      : Static_kd_tree(points, leaf_size, nullptr, true) {}
  // The same tree without its nodes' boxes, for a user who gathers its own
  // records into tree order anyway (through point_at()): set_boxes then reads
  // the points from those, in order, instead of one more pass of reads all
  // over `points` (on 6.9e7 spheres each such pass took seconds).
  struct Boxes_later {};
  Static_kd_tree(const std::vector<Point<D>>& points, std::size_t leaf_size, Boxes_later)
      : Static_kd_tree(points, leaf_size, nullptr, false) {}
  // The boxes of a tree built with Boxes_later: tree_point(position) is the
  // point at that position (points[point_at()[position]]).
  template <class Tree_point>
  void set_boxes(Tree_point tree_point) {
    compute_boxes(tree_point);
  }

  std::size_t size() const { return n_; }
  std::size_t n_leaves() const { return n_leaves_; }
  std::size_t n_nodes() const { return 2 * n_leaves_; }
  bool is_leaf(std::size_t node) const { return node >= n_leaves_; }
  // The leaf number of a leaf node, and the leaf node of a position.
  std::size_t leaf(std::size_t node) const { return node - n_leaves_; }
  std::size_t leaf_node(std::size_t position) const { return n_leaves_ + leaf_of(position); }

  // Leaves split the positions as evenly as integers allow.
  std::size_t leaf_begin(std::size_t leaf) const {
    return static_cast<std::size_t>(static_cast<unsigned __int128>(leaf) * n_ / n_leaves_);
  }
  std::size_t leaf_of(std::size_t position) const {
    return static_cast<std::size_t>((static_cast<unsigned __int128>(position + 1) * n_leaves_ + n_ - 1) / n_ - 1);
  }
  // Positions [begin, end) of a leaf node.
  std::size_t node_begin(std::size_t node) const { return leaf_begin(leaf(node)); }
  std::size_t node_end(std::size_t node) const { return leaf_begin(leaf(node) + 1); }

  // The input index of the point at each position, and the position of each
  // input index.
  const std::vector<std::uint32_t>& point_at() const { return point_at_; }
  std::vector<std::uint32_t> positions() const {
    std::vector<std::uint32_t> out(n_);
    for (std::size_t k = 0; k < n_; ++k) out[point_at_[k]] = static_cast<std::uint32_t>(k);
    return out;
  }

  Node& node(std::size_t k) { return nodes_[k]; }
  const Node& node(std::size_t k) const { return nodes_[k]; }

  // Depth-first search of the subtree at `root`: visit(node, stack) looks at a
  // node and pushes those to visit next (for an inner node it does not prune,
  // its children); it returns true to end the search. Returns whether a visit
  // ended it. (Visits push with branches, as the searches here want: a push
  // order computed without a branch makes every step wait for the comparison.)
  template <class Visit>
  EVOMESH_ALWAYS_INLINE bool depth_first(std::size_t root, Visit&& visit) const {
    Kd_stack stack;
    stack.push(root);
    while (!stack.empty()) {
      if (visit(stack.pop(), stack)) return true;
    }
    return false;
  }

  // A search around the point at `position`: its own leaf (own_leaf(leaf) ->
  // whether to end), then the sibling subtrees from the bottom up to the root
  // (depth_first with `visit`). A query for a near point mostly ends in the
  // first leaves, and pruning only gets tighter as the search goes on.
  template <class Own_leaf, class Visit>
  EVOMESH_ALWAYS_INLINE bool outward(std::size_t position, Own_leaf&& own_leaf, Visit&& visit) const {
    std::size_t node = leaf_node(position);
    if (own_leaf(leaf(node))) return true;
    Kd_stack stack;
    for (; node > 1; node >>= 1) {
      stack.push(node ^ 1);
      while (!stack.empty()) {
        if (visit(stack.pop(), stack)) return true;
      }
    }
    return false;
  }

 private:
  struct Build_item {
    std::array<float, D> x;
    std::uint32_t index;
  };
  static constexpr std::size_t kChunk = std::size_t{1} << 16;  // points per parallel_for item

  static Box<D> empty_box() {
    Box<D> b;
    b.lo.fill(std::numeric_limits<double>::infinity());
    b.hi.fill(-std::numeric_limits<double>::infinity());
    return b;
  }
  static void extend(Box<D>& b, const Point<D>& p) {
    for (std::size_t i = 0; i < D; ++i) {
      b.lo[i] = std::min(b.lo[i], p[i]);
      b.hi[i] = std::max(b.hi[i], p[i]);
    }
  }

  Static_kd_tree(const std::vector<Point<D>>& points, std::size_t leaf_size, std::vector<Point<D>>* tree_points,
                 bool boxes)
      : n_(points.size()) {
    if (n_ >= std::numeric_limits<std::uint32_t>::max()) {
      throw Input_error("too many points for a kd-tree (at most 2^32 - 2)");
    }
    while ((n_ >> depth_) > leaf_size) ++depth_;
    n_leaves_ = std::size_t{1} << depth_;
    detail::parallel_resize(point_at_, n_);
    // The loops over points run in chunks on parallel_for's default threads
    // (min and max are exact: the same box whatever the chunks).
    const std::size_t n_chunks = (n_ + kChunk - 1) / kChunk;
    auto chunk_range = [this](std::size_t c) { return std::pair{c * kChunk, std::min(n_, (c + 1) * kChunk)}; };
    if (n_ > 0) {
      std::vector<Box<D>> chunk_box(n_chunks);
      parallel_for(n_chunks, 0, [&](std::size_t c) {
        Box<D> b = empty_box();
        const auto [begin, end] = chunk_range(c);
        for (std::size_t i = begin; i < end; ++i) extend(b, points[i]);
        chunk_box[c] = b;
      });
      Box<D> all = empty_box();
      for (const Box<D>& b : chunk_box) {
        extend(all, b.lo);
        extend(all, b.hi);
      }
      double extent = all.hi[0] - all.lo[0];
      for (std::size_t i = 1; i < D; ++i) extent = std::max(extent, all.hi[i] - all.lo[i]);
      const double scale = extent > 0 ? 1.0 / extent : 1.0;
      std::vector<Build_item> items;
      detail::parallel_resize(items, n_);
      parallel_for(n_chunks, 0, [&](std::size_t c) {
        const auto [begin, end] = chunk_range(c);
        for (std::size_t k = begin; k < end; ++k) {
          for (std::size_t i = 0; i < D; ++i) items[k].x[i] = static_cast<float>((points[k][i] - all.lo[i]) * scale);
          items[k].index = static_cast<std::uint32_t>(k);
        }
      });
      // The root is split alone, the nodes of the next level side by side.
      const int top = std::min(depth_, 2);
      for (int level = 0; level < top; ++level) {
        const std::size_t first = std::size_t{1} << level;
        parallel_for(first, 0, [&](std::size_t k) { split(items, first + k, level); });
      }
      const std::size_t first = std::size_t{1} << top;
      parallel_for(first, 0, [&](std::size_t k) { build(items, first + k, top); });
      parallel_for(n_chunks, 0, [&](std::size_t c) {
        const auto [begin, end] = chunk_range(c);
        for (std::size_t k = begin; k < end; ++k) point_at_[k] = items[k].index;
      });
    }
    if (tree_points) {
      detail::parallel_resize(*tree_points, n_);
      parallel_for(n_chunks, 0, [&](std::size_t c) {
        const auto [begin, end] = chunk_range(c);
        for (std::size_t k = begin; k < end; ++k) (*tree_points)[k] = points[point_at_[k]];
      });
    }
    if (boxes) {
      compute_boxes(
          [&](std::size_t k) -> const Point<D>& { return tree_points ? (*tree_points)[k] : points[point_at_[k]]; });
    }
  }

  // Every node's box: the leaves' from their points (tree_point(position)), in
  // parallel, then the inner nodes' from their children.
  template <class Tree_point>
  void compute_boxes(Tree_point tree_point) {
    nodes_.resize(2 * n_leaves_);
    constexpr std::size_t kLeafChunk = 1024;
    parallel_for((n_leaves_ + kLeafChunk - 1) / kLeafChunk, 0, [&](std::size_t c) {
      for (std::size_t leaf = c * kLeafChunk; leaf < std::min(n_leaves_, (c + 1) * kLeafChunk); ++leaf) {
        Box<D> b = empty_box();
        for (std::size_t k = leaf_begin(leaf); k < leaf_begin(leaf + 1); ++k) extend(b, tree_point(k));
        static_cast<Box<D>&>(nodes_[n_leaves_ + leaf]) = b;
      }
    });
    for (std::size_t node = n_leaves_ - 1; node >= 1; --node) {
      const Box<D>& l = nodes_[2 * node];
      const Box<D>& r = nodes_[2 * node + 1];
      Box<D>& b = nodes_[node];
      for (std::size_t i = 0; i < D; ++i) {
        b.lo[i] = std::min(l.lo[i], r.lo[i]);
        b.hi[i] = std::max(l.hi[i], r.hi[i]);
      }
    }
  }

  // Positions [begin, end) of a node at `level` (root: 0).
  std::pair<std::size_t, std::size_t> range(std::size_t node, int level) const {
    const std::size_t j = node - (std::size_t{1} << level);
    const int shift = depth_ - level;
    return {leaf_begin(j << shift), leaf_begin((j + 1) << shift)};
  }

  // Partitions an inner node's range at its children's boundary, along the
  // longest side of the range's (float) bounding box.
  void split(std::vector<Build_item>& items, std::size_t node, int level) const {
    if (level == depth_) return;
    const auto [begin, end] = range(node, level);
    std::array<float, D> lo, hi;
    lo.fill(std::numeric_limits<float>::infinity());
    hi.fill(-std::numeric_limits<float>::infinity());
    for (std::size_t k = begin; k < end; ++k) {
      for (std::size_t i = 0; i < D; ++i) {
        lo[i] = std::min(lo[i], items[k].x[i]);
        hi[i] = std::max(hi[i], items[k].x[i]);
      }
    }
    std::size_t axis = 0;
    for (std::size_t i = 1; i < D; ++i) {
      if (hi[i] - lo[i] > hi[axis] - lo[axis]) axis = i;
    }
    const std::size_t mid = range(2 * node + 1, level + 1).first;
    auto first = items.begin();
    std::nth_element(first + begin, first + mid, first + end, [axis](const Build_item& u, const Build_item& v) {
      return u.x[axis] < v.x[axis] || (u.x[axis] == v.x[axis] && u.index < v.index);
    });
  }

  void build(std::vector<Build_item>& items, std::size_t node, int level) const {
    split(items, node, level);
    if (level == depth_) return;
    build(items, 2 * node, level + 1);
    build(items, 2 * node + 1, level + 1);
  }

  std::size_t n_;
  int depth_ = 0;
  std::size_t n_leaves_ = 1;
  std::vector<std::uint32_t> point_at_;  // position -> input index
  std::vector<Node> nodes_;
};

// A static kd-tree that holds its points (in tree order) and answers nearest
// point queries. Every distance is squared_distance of the same two points,
// and pruning never skips a point, so the answers do not depend on the shape
// of the tree nor the visiting order.
template <std::size_t D>
class Kd_tree {
 public:
  static constexpr std::size_t kLeafSize = 8;

  explicit Kd_tree(const std::vector<Point<D>>& points, std::size_t leaf_size = kLeafSize)
      : tree_(points, leaf_size, points_) {}

  std::size_t size() const { return points_.size(); }
  std::size_t n_leaves() const { return tree_.n_leaves(); }
  std::size_t n_nodes() const { return tree_.n_nodes(); }
  bool is_leaf(std::size_t node) const { return tree_.is_leaf(node); }
  std::size_t leaf_begin(std::size_t leaf) const { return tree_.leaf_begin(leaf); }
  std::size_t leaf_of(std::size_t position) const { return tree_.leaf_of(position); }
  std::size_t node_begin(std::size_t node) const { return tree_.node_begin(node); }
  std::size_t node_end(std::size_t node) const { return tree_.node_end(node); }
  const Box<D>& box(std::size_t node) const { return tree_.node(node); }
  // Input index of the point at a position, and the point there.
  const std::vector<std::uint32_t>& point_at() const { return tree_.point_at(); }
  const Point<D>& tree_point(std::size_t position) const { return points_[position]; }
  // The position of each input index.
  std::vector<std::uint32_t> positions() const { return tree_.positions(); }

  // Squared distance from x to the nearest point of the tree (any point,
  // also one of the tree's own; +inf for an empty tree).
  double squared_nearest(const Point<D>& x) const {
    double best = std::numeric_limits<double>::infinity();
    if (points_.empty()) return best;
    nearer_first(x, [&] { return best; }, [&](std::size_t node) { best = leaf_min<false>(node, x, 0, best); });
    return best;
  }

  // Whether some point of the tree lies within squared distance `bound` of x
  // (computed as squared_nearest computes it): the search prunes every node
  // farther than the bound, so far queries stop near the root.
  bool has_point_within(const Point<D>& x, double bound) const {
    if (points_.empty()) return false;
    bool found = false;
    nearer_first(x, [&] { return found ? -1.0 : bound; }, [&](std::size_t node) {
      found = found || leaf_min<false>(node, x, 0, std::numeric_limits<double>::infinity()) <= bound;
    });
    return found;
  }

  // Squared distances from x to its nearest and second nearest points of the
  // tree (+inf where the tree has fewer).
  std::array<double, 2> squared_two_nearest(const Point<D>& x) const {
    std::array<double, 2> best{std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
    if (points_.empty()) return best;
    nearer_first(x, [&] { return best[1]; }, [&](std::size_t node) {
      for (std::size_t k = node_begin(node); k < node_end(node); ++k) {
        const double d = squared_distance<D>(x, points_[k]);
        if (d < best[0]) best = {d, best[0]};
        else if (d < best[1]) best[1] = d;
      }
    });
    return best;
  }

  // Squared nearest-neighbour distances (to the nearest other point), by input
  // index, the queries in parallel. Input_error for duplicate points; tiny
  // distances that underflow to 0 are not duplicates (nn is then 0).
  std::vector<double> squared_nn(int threads) const {
    const std::size_t n = points_.size();
    const auto& at = point_at();
    std::vector<double> nn2(n);
    constexpr std::size_t kChunk = 4096;  // in tree order: neighbouring queries
    parallel_for((n + kChunk - 1) / kChunk, threads, [&](std::size_t c) {
      for (std::size_t k = c * kChunk; k < std::min(n, (c + 1) * kChunk); ++k) {
        nn2[at[k]] = query(k);
        if (nn2[at[k]] == 0 && has_duplicate(k)) throw Input_error("points contain duplicates");
      }
    });
    return nn2;
  }

 private:
  // The least of `best` and the squared distances from x to the points of a
  // leaf node (other than the one at position `self`, with skip_self).
  template <bool skip_self>
  double leaf_min(std::size_t node, const Point<D>& x, std::size_t self, double best) const {
    for (std::size_t k = node_begin(node); k < node_end(node); ++k) {
      if (skip_self && k == self) continue;
      best = std::min(best, squared_distance<D>(x, points_[k]));
    }
    return best;
  }

  // Depth-first from the root, the nearer child first; a node farther from x
  // than bound() (the current best) is pruned, a leaf node goes to visit.
  template <class Bound, class Visit>
  void nearer_first(const Point<D>& x, Bound&& bound, Visit&& visit) const {
    tree_.depth_first(1, [&](std::size_t m, Kd_stack& stack) {
      if (squared_distance(box(m), x) > bound()) return false;
      if (is_leaf(m)) {
        visit(m);
      } else if (squared_distance(box(2 * m), x) <= squared_distance(box(2 * m + 1), x)) {  // nearer child first
        stack.push_children(m);
      } else {
        stack.push_children_right_first(m);
      }
      return false;
    });
  }

  // Whether another point has the same coordinates: a squared distance of 0 is
  // a duplicate only then.
  bool has_duplicate(std::size_t self) const {
    const Point<D>& p = points_[self];
    return tree_.depth_first(1, [&](std::size_t m, Kd_stack& stack) {
      const Box<D>& b = box(m);
      for (std::size_t i = 0; i < D; ++i) {
        if (p[i] < b.lo[i] || p[i] > b.hi[i]) return false;
      }
      if (!is_leaf(m)) {
        stack.push_children(m);
        return false;
      }
      for (std::size_t k = node_begin(m); k < node_end(m); ++k) {
        if (k != self && points_[k] == p) return true;
      }
      return false;
    });
  }

  // Own leaf first, then the sibling subtrees up to the root, pruned by the
  // best distance so far.
  double query(std::size_t self) const {
    const Point<D>& p = points_[self];
    double best = std::numeric_limits<double>::infinity();
    tree_.outward(
        self,
        [&](std::size_t leaf) {
          best = leaf_min<true>(n_leaves() + leaf, p, self, best);
          return false;
        },
        [&](std::size_t m, Kd_stack& stack) {
          if (squared_distance(box(m), p) > best) return false;
          if (is_leaf(m)) best = leaf_min<true>(m, p, self, best);
          else stack.push_children(m);
          return false;
        });
    return best;
  }

  std::vector<Point<D>> points_;  // in tree order (filled by tree_, declared first)
  Static_kd_tree<D> tree_;
};

// The tree for nearest-neighbour queries: leaves of 16 points, scanned in one
// sweep.
template <std::size_t D>
class Point_tree : public Kd_tree<D> {
 public:
  explicit Point_tree(const std::vector<Point<D>>& points) : Kd_tree<D>(points, 16) {}
};

// Nearest-neighbour distances (to the nearest other point), by input index;
// Input_error for duplicate points.
template <std::size_t D>
std::vector<double> nearest_neighbour_distances(const std::vector<Point<D>>& points, int threads) {
  std::vector<double> nn = Point_tree<D>(points).squared_nn(threads);
  for (double& d : nn) d = std::sqrt(d);
  return nn;
}

}  // namespace evomesh::nd
