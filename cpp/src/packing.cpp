#include "evomesh/packing.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace evomesh {

namespace {

// Static kd-tree over sphere centres. Each node keeps its bounding box and the
// largest radius among the *kept* spheres below it (-1: none kept yet).
class Kept_sphere_tree {
 public:
  Kept_sphere_tree(const std::vector<Vec2>& centers, const std::vector<double>& radii)
      : centers_(centers), radii_(radii), items_(centers.size()), leaf_of_(centers.size(), -1) {
    std::iota(items_.begin(), items_.end(), Index{0});
    nodes_.reserve(2 * centers.size() / kLeafSize + 2);
    if (!centers.empty()) build(0, static_cast<Index>(centers.size()), -1);
  }

  bool conflicts_with_kept(Index i) const {
    const Vec2& c = centers_[i];
    const double r = radii_[i];
    Index stack[128];
    int top = 0;
    if (!nodes_.empty()) stack[top++] = 0;
    while (top > 0) {
      const Node& node = nodes_[stack[--top]];
      if (node.max_kept_radius < 0) continue;
      const double dx = std::max({node.lo[0] - c[0], 0.0, c[0] - node.hi[0]});
      const double dy = std::max({node.lo[1] - c[1], 0.0, c[1] - node.hi[1]});
      const double reach = r + node.max_kept_radius;
      if (dx * dx + dy * dy >= reach * reach) continue;
      if (node.left < 0) {
        for (Index k = node.begin; k < node.end; ++k) {
          const Index j = items_[k];
          if (!kept_flag(j)) continue;
          const double ex = centers_[j][0] - c[0];
          const double ey = centers_[j][1] - c[1];
          const double sum = r + radii_[j];
          if (ex * ex + ey * ey < sum * sum) return true;
        }
      } else {
        stack[top++] = node.left;
        stack[top++] = node.right;
      }
    }
    return false;
  }

  void keep(Index i) {
    kept_.push_back(i);
    if (kept_mask_.empty()) kept_mask_.assign(centers_.size(), 0);
    kept_mask_[i] = 1;
    for (Index k = leaf_of_[i]; k >= 0; k = nodes_[k].parent) {
      if (nodes_[k].max_kept_radius >= radii_[i]) break;  // ancestors are at least as large
      nodes_[k].max_kept_radius = radii_[i];
    }
  }

 private:
  static constexpr Index kLeafSize = 8;
  struct Node {
    Vec2 lo, hi;
    double max_kept_radius = -1;
    Index begin, end;
    Index left = -1, right = -1, parent = -1;
  };

  bool kept_flag(Index j) const { return !kept_mask_.empty() && kept_mask_[j]; }

  Index build(Index begin, Index end, Index parent) {
    const Index id = static_cast<Index>(nodes_.size());
    nodes_.push_back(Node{});
    Node node;
    node.begin = begin;
    node.end = end;
    node.parent = parent;
    node.lo = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
    node.hi = {-node.lo[0], -node.lo[1]};
    for (Index k = begin; k < end; ++k) {
      const Vec2& p = centers_[items_[k]];
      node.lo = {std::min(node.lo[0], p[0]), std::min(node.lo[1], p[1])};
      node.hi = {std::max(node.hi[0], p[0]), std::max(node.hi[1], p[1])};
    }
    if (end - begin <= kLeafSize) {
      for (Index k = begin; k < end; ++k) leaf_of_[items_[k]] = id;
      nodes_[id] = node;
      return id;
    }
    const int axis = (node.hi[0] - node.lo[0]) >= (node.hi[1] - node.lo[1]) ? 0 : 1;
    const Index mid = begin + (end - begin) / 2;
    std::nth_element(items_.begin() + begin, items_.begin() + mid, items_.begin() + end,
                     [&](Index u, Index v) {
                       const double a = centers_[u][axis];
                       const double b = centers_[v][axis];
                       return a < b || (a == b && u < v);
                     });
    nodes_[id] = node;
    const Index left = build(begin, mid, id);
    const Index right = build(mid, end, id);
    nodes_[id].left = left;
    nodes_[id].right = right;
    return id;
  }

  const std::vector<Vec2>& centers_;
  const std::vector<double>& radii_;
  std::vector<Index> items_;
  std::vector<Index> leaf_of_;
  std::vector<Node> nodes_;
  std::vector<Index> kept_;
  std::vector<std::uint8_t> kept_mask_;
};

}  // namespace

std::vector<std::uint8_t> lexical_first_mis(const std::vector<Vec2>& centers,
                                            const std::vector<double>& radii,
                                            const std::vector<Index>& order, std::size_t n_forced) {
  const std::size_t n = centers.size();
  if (radii.size() != n || order.size() != n) throw Input_error("centers, radii and order must have the same length");
  if (n_forced > n) throw Input_error("more forced spheres than spheres");
  std::vector<std::uint8_t> seen(n, 0);
  for (Index i : order) {
    if (i < 0 || static_cast<std::size_t>(i) >= n || seen[i]) throw Input_error("order must be a permutation of 0..n-1");
    seen[i] = 1;
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(centers[i][0]) || !std::isfinite(centers[i][1])) throw Input_error("sphere centres must be finite");
    if (!std::isfinite(radii[i]) || !(radii[i] > 0)) throw Input_error("sphere radii must be finite and > 0");
  }
  std::vector<std::uint8_t> kept(n, 0);
  Kept_sphere_tree tree(centers, radii);
  for (std::size_t k = 0; k < n; ++k) {
    const Index i = order[k];
    if (k < n_forced || !tree.conflicts_with_kept(i)) {
      kept[i] = 1;
      tree.keep(i);
    }
  }
  return kept;
}

std::vector<Index> packing_order(const std::vector<std::uint8_t>& priority_class,
                                 const std::vector<double>& radii) {
  if (priority_class.size() != radii.size()) throw Input_error("classes and radii must have the same length");
  std::vector<Index> order(radii.size());
  std::iota(order.begin(), order.end(), Index{0});
  std::sort(order.begin(), order.end(), [&](Index a, Index b) {
    if (priority_class[a] != priority_class[b]) return priority_class[a] < priority_class[b];
    if (radii[a] != radii[b]) return radii[a] < radii[b];
    return a < b;
  });
  return order;
}

}  // namespace evomesh
