// The spacing function f(x) = min_p (w_p + |x - p|) over weighted sites, in D
// dimensions, by an exact branch and bound on a kd-tree whose nodes carry the
// least weight below them (the paper's f, Section 3.1, with w_p = delta(p)
// nn(p); in 3-D there is no Apollonius graph to answer it). Header-only,
// dimension-generic.
//
// Exactness: a node is pruned when sqrt(d(x, box)^2) + w_min(node) >= best.
// Each term of the box distance is at most the corresponding term of the
// distance to any point in the box (the box is the points' exact bounding
// box, rounding is monotone), so the bound never exceeds a computed value
// w_p + sqrt(|x - p|^2) below it: a pruned node holds no value below best.
// The answer is therefore the minimum of the same set of computed values as
// the brute force (brute_force()), bit for bit, whatever the visiting order.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <vector>

#include "evomesh/nd/kd_tree.hpp"

namespace evomesh::nd {

template <std::size_t D>
class Cone_envelope {
 public:
  Cone_envelope(const std::vector<Point<D>>& sites, const std::vector<double>& weights)
      : tree_(sites), weight_(sites.size()), min_weight_(tree_.n_nodes(), std::numeric_limits<double>::infinity()) {
    if (weights.size() != sites.size()) throw Input_error("one weight per site");
    for (std::size_t k = 0; k < sites.size(); ++k) weight_[k] = weights[tree_.point_at()[k]];
    const std::size_t first_leaf = tree_.n_leaves();
    for (std::size_t node = first_leaf; node < 2 * first_leaf; ++node) {
      for (std::size_t k = tree_.node_begin(node); k < tree_.node_end(node); ++k) {
        min_weight_[node] = std::min(min_weight_[node], weight_[k]);
      }
    }
    for (std::size_t node = first_leaf - 1; node >= 1; --node) {
      min_weight_[node] = std::min(min_weight_[2 * node], min_weight_[2 * node + 1]);
    }
  }

  std::size_t size() const { return weight_.size(); }

  // One computed value of the minimum: every caller uses this expression.
  static double value(double weight, const Point<D>& site, const Point<D>& x) {
    return weight + std::sqrt(squared_distance<D>(site, x));
  }

  // f(x), starting from `best` (an upper bound that is itself a value of the
  // minimum, or +inf); `evaluations` counts the sites evaluated.
  double operator()(const Point<D>& x, double best, std::size_t& evaluations) const {
    if (weight_.empty()) return best;
    std::size_t stack[128];
    double bound[128];
    int top = 0;
    stack[top] = 1;
    bound[top++] = lower_bound(1, x);
    while (top > 0) {
      --top;
      const std::size_t node = stack[top];
      if (bound[top] >= best) continue;
      if (tree_.is_leaf(node)) {
        for (std::size_t k = tree_.node_begin(node); k < tree_.node_end(node); ++k) {
          best = std::min(best, value(weight_[k], tree_.tree_point(k), x));
        }
        evaluations += tree_.node_end(node) - tree_.node_begin(node);
        continue;
      }
      // The nearer child (smaller bound) is visited first.
      const double left = lower_bound(2 * node, x);
      const double right = lower_bound(2 * node + 1, x);
      if (left <= right) {
        stack[top] = 2 * node + 1, bound[top++] = right;
        stack[top] = 2 * node, bound[top++] = left;
      } else {
        stack[top] = 2 * node, bound[top++] = left;
        stack[top] = 2 * node + 1, bound[top++] = right;
      }
    }
    return best;
  }

  double operator()(const Point<D>& x) const {
    std::size_t evaluations = 0;
    return (*this)(x, std::numeric_limits<double>::infinity(), evaluations);
  }

  // The reference: every site, in input order.
  static double brute_force(const std::vector<Point<D>>& sites, const std::vector<double>& weights,
                            const Point<D>& x) {
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t p = 0; p < sites.size(); ++p) best = std::min(best, value(weights[p], sites[p], x));
    return best;
  }

 private:
  double lower_bound(std::size_t node, const Point<D>& x) const {
    return min_weight_[node] + std::sqrt(squared_distance(tree_.box(node), x));
  }

  Kd_tree<D> tree_;
  std::vector<double> weight_;      // by position
  std::vector<double> min_weight_;  // by node
};

}  // namespace evomesh::nd
