// The spheres a lexical-first maximal independent set has selected so far,
// among fixed candidates, in D dimensions (the packing of Section 3.2, the
// sequential form). A static kd-tree over the candidates' centres whose nodes
// carry the largest selected radius below them (-1: none): selecting updates
// the path to the root, queries visit only nodes that can hold a conflict.
// Two spheres conflict when |p - q|^2 < (r_p + r_q)^2, computed exactly as
// conflicts() computes it; pruning is monotone under rounding (the box
// distance is at most the point distance, r_q is at most the node's largest
// radius), so a query answers as the brute force would. Header-only.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "evomesh/nd/kd_tree.hpp"

namespace evomesh::nd {

template <std::size_t D>
class Selected_spheres {
 public:
  explicit Selected_spheres(const std::vector<Point<D>>& centres)
      : tree_(centres), position_(tree_.positions()), radius_(centres.size(), -1.0), max_radius_(tree_.n_nodes(), -1.0) {}

  static bool is_conflict(double squared_distance, double r, double s) { return squared_distance < (r + s) * (r + s); }

  void select(std::size_t candidate, double radius) {
    const std::size_t k = position_[candidate];
    radius_[k] = radius;
    for (std::size_t node = tree_.n_leaves() + tree_.leaf_of(k); node >= 1; node >>= 1) {
      if (max_radius_[node] >= radius) break;
      max_radius_[node] = radius;
    }
  }

  // Whether a selected sphere conflicts with B(x, r).
  bool conflicts(const Point<D>& x, double r) const {
    return any(x, [&](double d2, double s) { return is_conflict(d2, r, s); });
  }

  // Whether x lies strictly inside a selected sphere: then B(x, r) conflicts
  // with it for every r >= 0 ((s + r)^2 >= s^2 after rounding), so a candidate
  // there can be dropped before its radius is known.
  bool covers(const Point<D>& x) const {
    return any(x, [&](double d2, double s) { return d2 < s * s; });
  }

 private:
  // Whether some selected sphere (centre at squared distance d2, radius s)
  // passes hit(d2, s); hit must be monotone: false at (d2, s) implies false at
  // every larger d2 and smaller s.
  template <class Hit>
  bool any(const Point<D>& x, Hit hit) const {
    if (radius_.empty()) return false;
    std::size_t stack[128];
    int top = 0;
    stack[top++] = 1;
    while (top > 0) {
      const std::size_t node = stack[--top];
      const double s = max_radius_[node];
      if (s < 0 || !hit(squared_distance(tree_.box(node), x), s)) continue;
      if (tree_.is_leaf(node)) {
        for (std::size_t k = tree_.node_begin(node); k < tree_.node_end(node); ++k) {
          if (radius_[k] >= 0 && hit(squared_distance<D>(tree_.tree_point(k), x), radius_[k])) return true;
        }
      } else {
        stack[top++] = 2 * node + 1;
        stack[top++] = 2 * node;
      }
    }
    return false;
  }

  Kd_tree<D> tree_;
  std::vector<std::uint32_t> position_;  // candidate -> tree position
  std::vector<double> radius_;           // by position; -1: not selected
  std::vector<double> max_radius_;       // by node
};

}  // namespace evomesh::nd
