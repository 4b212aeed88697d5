// A static kd-tree over points in the plane: the shape, the node boxes and the
// two search loops shared by the nearest-neighbour tree (point_tree.hpp) and the
// packing's tree of kept spheres (packing.cpp). What a leaf holds and how a node
// is pruned is the user's. Internal: included by cpp/src only.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "evomesh/detail/bits.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/types.hpp"

namespace evomesh::detail {

// An axis-aligned box (empty: lo = +inf, hi = -inf).
struct Box {
  double lo_x, lo_y, hi_x, hi_y;
};

// The squared distance from (x, y) to the box b (0 inside or on it). Rounding is
// monotone, so it never exceeds the computed squared distance from (x, y) to a
// point in the box: pruning on it never skips a point.
inline double squared_distance(const Box& b, double x, double y) {
  const double dx = std::max({b.lo_x - x, 0.0, x - b.hi_x});
  const double dy = std::max({b.lo_y - y, 0.0, y - b.hi_y});
  return dx * dx + dy * dy;
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

// The shape of a static kd-tree over n points (n < 2^32), stored as a complete
// binary tree in heap order: node 1 is the root, node k has children 2k and
// 2k + 1, the leaves are nodes n_leaves() .. 2 n_leaves() - 1. The points are
// placed in tree order: leaf L holds the positions [leaf_begin(L),
// leaf_begin(L + 1)), as evenly as integers allow (at most leaf_size + 1), and
// point_at()[position] is the input index of the point there.
//
// Each inner node splits its positions at its children's boundary (a median)
// along the longer side of their bounding box, ties broken by index. The shape
// only affects speed, so it is chosen on compact float copies of the points,
// normalised to their bounding box (any coordinate scale works). The top two
// levels are split first and the subtrees below built in parallel: the same
// tree whatever the number of threads. Every node carries a `Node`: a Box (the
// exact bounding box of its points) with whatever the user adds to it (default
// member initialisers give its start values).
template <class Node = Box>
class Static_kd_tree {
 public:
  // `tree_points` receives the points in tree order (for the user's leaves).
  Static_kd_tree(const std::vector<Vec2>& points, std::size_t leaf_size, std::vector<Vec2>& tree_points)
      : Static_kd_tree(points, leaf_size, &tree_points) {}
  // The same tree without the copy of the points (the user gathers its own
  // leaf records through point_at()).
  Static_kd_tree(const std::vector<Vec2>& points, std::size_t leaf_size)
      : Static_kd_tree(points, leaf_size, nullptr, true) {}
  // The same tree without its nodes' boxes, for a user who gathers its own
  // records into tree order anyway (through point_at()): set_boxes then reads
  // the points from those, in order, instead of one more pass of reads all
  // over `points` (on 6.9e7 spheres each such pass took seconds).
  struct Boxes_later {};
  Static_kd_tree(const std::vector<Vec2>& points, std::size_t leaf_size, Boxes_later)
      : Static_kd_tree(points, leaf_size, nullptr, false) {}
  // The boxes of a tree built with Boxes_later: tree_point(position) is the
  // point at that position (points[point_at()[position]]).
  template <class Tree_point>
  void set_boxes(Tree_point tree_point) {
    compute_boxes(tree_point);
  }

 private:
  Static_kd_tree(const std::vector<Vec2>& points, std::size_t leaf_size, std::vector<Vec2>* tree_points)
      : Static_kd_tree(points, leaf_size, tree_points, true) {}
  Static_kd_tree(const std::vector<Vec2>& points, std::size_t leaf_size, std::vector<Vec2>* tree_points,
                 bool boxes)
      : n_(points.size()) {
    if (n_ >= std::numeric_limits<std::uint32_t>::max()) {
      throw Input_error("too many points for a kd-tree (at most 2^32 - 2)");
    }
    while ((n_ >> depth_) > leaf_size) ++depth_;
    n_leaves_ = std::size_t{1} << depth_;
    parallel_resize(point_at_, n_);
    // The loops over points run in chunks on parallel_for's default threads
    // (min and max are exact: the same box whatever the chunks).
    const std::size_t n_chunks = (n_ + kChunk - 1) / kChunk;
    auto chunk_range = [this](std::size_t c) { return std::pair{c * kChunk, std::min(n_, (c + 1) * kChunk)}; };
    if (n_ > 0) {
      std::vector<Box> chunk_box(n_chunks);
      parallel_for(n_chunks, 0, [&](std::size_t c) {
        double lo_x = std::numeric_limits<double>::infinity(), lo_y = lo_x, hi_x = -lo_x, hi_y = -lo_x;
        const auto [begin, end] = chunk_range(c);
        for (std::size_t i = begin; i < end; ++i) {
          const auto& p = points[i];
          lo_x = std::min(lo_x, p[0]);
          lo_y = std::min(lo_y, p[1]);
          hi_x = std::max(hi_x, p[0]);
          hi_y = std::max(hi_y, p[1]);
        }
        chunk_box[c] = {lo_x, lo_y, hi_x, hi_y};
      });
      double lo_x = std::numeric_limits<double>::infinity(), lo_y = lo_x, hi_x = -lo_x, hi_y = -lo_x;
      for (const Box& b : chunk_box) {
        lo_x = std::min(lo_x, b.lo_x);
        lo_y = std::min(lo_y, b.lo_y);
        hi_x = std::max(hi_x, b.hi_x);
        hi_y = std::max(hi_y, b.hi_y);
      }
      const double extent = std::max(hi_x - lo_x, hi_y - lo_y);
      const double scale = extent > 0 ? 1.0 / extent : 1.0;
      std::vector<Build_item> items;
      parallel_resize(items, n_);
      parallel_for(n_chunks, 0, [&](std::size_t c) {
        const auto [begin, end] = chunk_range(c);
        for (std::size_t i = begin; i < end; ++i) {
          items[i] = {static_cast<float>((points[i][0] - lo_x) * scale),
                      static_cast<float>((points[i][1] - lo_y) * scale), static_cast<std::uint32_t>(i)};
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
      parallel_resize(*tree_points, n_);
      parallel_for(n_chunks, 0, [&](std::size_t c) {
        const auto [begin, end] = chunk_range(c);
        for (std::size_t k = begin; k < end; ++k) (*tree_points)[k] = points[point_at_[k]];
      });
    }
    if (boxes) {
      compute_boxes([&](std::size_t k) -> const Vec2& { return tree_points ? (*tree_points)[k] : points[point_at_[k]]; });
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
        Box& box = nodes_[n_leaves_ + leaf];
        box.lo_x = box.lo_y = std::numeric_limits<double>::infinity();
        box.hi_x = box.hi_y = -std::numeric_limits<double>::infinity();
        for (std::size_t k = leaf_begin(leaf); k < leaf_begin(leaf + 1); ++k) {
          const Vec2 p = tree_point(k);
          box.lo_x = std::min(box.lo_x, p[0]);
          box.lo_y = std::min(box.lo_y, p[1]);
          box.hi_x = std::max(box.hi_x, p[0]);
          box.hi_y = std::max(box.hi_y, p[1]);
        }
      }
    });
    for (std::size_t node = n_leaves_ - 1; node >= 1; --node) {
      const Box& l = nodes_[2 * node];
      const Box& r = nodes_[2 * node + 1];
      static_cast<Box&>(nodes_[node]) = {std::min(l.lo_x, r.lo_x), std::min(l.lo_y, r.lo_y), std::max(l.hi_x, r.hi_x),
                                         std::max(l.hi_y, r.hi_y)};
    }
  }

 public:
  std::size_t size() const { return n_; }
  std::size_t n_leaves() const { return n_leaves_; }
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

  // The input index of the point at each position.
  const std::vector<std::uint32_t>& point_at() const { return point_at_; }

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
    float x, y;
    std::uint32_t index;
  };
  static constexpr std::size_t kChunk = std::size_t{1} << 16;  // points per parallel_for item

  // Positions [begin, end) of a node at `level` (root: 0).
  std::pair<std::size_t, std::size_t> range(std::size_t node, int level) const {
    const std::size_t j = node - (std::size_t{1} << level);
    const int shift = depth_ - level;
    return {leaf_begin(j << shift), leaf_begin((j + 1) << shift)};
  }

  // Partitions an inner node's range at its children's boundary, along the
  // longer side of the range's (float) bounding box.
  void split(std::vector<Build_item>& items, std::size_t node, int level) const {
    if (level == depth_) return;
    const auto [begin, end] = range(node, level);
    float lo_x = std::numeric_limits<float>::infinity(), lo_y = lo_x, hi_x = -lo_x, hi_y = -lo_x;
    for (std::size_t k = begin; k < end; ++k) {
      lo_x = std::min(lo_x, items[k].x);
      lo_y = std::min(lo_y, items[k].y);
      hi_x = std::max(hi_x, items[k].x);
      hi_y = std::max(hi_y, items[k].y);
    }
    const std::size_t mid = range(2 * node + 1, level + 1).first;
    auto first = items.begin();
    if (hi_x - lo_x >= hi_y - lo_y) {
      std::nth_element(first + begin, first + mid, first + end, [](const Build_item& u, const Build_item& v) {
        return u.x < v.x || (u.x == v.x && u.index < v.index);
      });
    } else {
      std::nth_element(first + begin, first + mid, first + end, [](const Build_item& u, const Build_item& v) {
        return u.y < v.y || (u.y == v.y && u.index < v.index);
      });
    }
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

}  // namespace evomesh::detail
