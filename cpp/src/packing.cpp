#include "evomesh/packing.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

#include "evomesh/detail/bits.hpp"
#include "evomesh/parallel.hpp"

namespace evomesh {

namespace {

// Static kd-tree over sphere centres, stored as a complete binary tree in heap
// order (node 1 is the root, node k has children 2k and 2k + 1, leaves are
// n_leaves .. 2 n_leaves - 1). Leaf L holds the positions [leaf_begin(L),
// leaf_begin(L + 1)) of `slots_`: the spheres in tree order, centre and radius
// copied, so a leaf is scanned in one contiguous sweep. Each node keeps its
// bounding box and the largest radius among the *kept* spheres below it (-1:
// none kept yet).
//
// A query starts at the sphere's own leaf and climbs to the root, searching the
// sibling subtree at each level: a sphere that conflicts with a kept one (most
// candidates of FRFC) usually finds it in the first leaves visited and stops.
// The result does not depend on the shape of the tree or the search order, only
// on the conflict test, which is the same expression for every pair.
class Kept_sphere_tree {
 public:
  // `order`: the visiting order (a permutation of the sphere indices).
  // `keep_indices`: remember which sphere sits at each position (for sphere_at).
  Kept_sphere_tree(const std::vector<Vec2>& centers, const std::vector<double>& radii, const std::vector<Index>& order,
                   bool keep_indices = false)
      : n_(centers.size()) {
    if (n_ == 0) return;
    while ((n_ >> depth_) > kLeafSize) ++depth_;
    n_leaves_ = std::size_t{1} << depth_;
    nodes_.resize(2 * n_leaves_);
    std::vector<std::uint32_t> index_at(n_);  // sphere at each position
    {
      // The shape of the tree only affects speed, so it is chosen on compact
      // float copies of the centres (normalised to the bounding box, so any
      // coordinate scale works); the boxes are then computed exactly.
      double lo_x = std::numeric_limits<double>::infinity(), lo_y = lo_x, hi_x = -lo_x, hi_y = -lo_x;
      for (const auto& c : centers) {
        lo_x = std::min(lo_x, c[0]);
        lo_y = std::min(lo_y, c[1]);
        hi_x = std::max(hi_x, c[0]);
        hi_y = std::max(hi_y, c[1]);
      }
      const double extent = std::max(hi_x - lo_x, hi_y - lo_y);
      const double scale = extent > 0 ? 1.0 / extent : 1.0;
      std::vector<Build_item> items(n_);
      for (std::size_t i = 0; i < n_; ++i) {
        items[i] = {static_cast<float>((centers[i][0] - lo_x) * scale), static_cast<float>((centers[i][1] - lo_y) * scale),
                    static_cast<std::uint32_t>(i)};
      }
      // The top levels are split first; the subtrees below them are independent
      // and built in parallel. The tree is the same whatever the number of threads.
      const int top = std::min(depth_, 2);
      for (int level = 0; level < top; ++level) {
        for (std::size_t node = std::size_t{1} << level; node < (std::size_t{2} << level); ++node) {
          split(items, node, level);
        }
      }
      const std::size_t first = std::size_t{1} << top;
      parallel_for(first, 0, [&](std::size_t k) { build(items, first + k, top); });
      for (std::size_t k = 0; k < n_; ++k) index_at[k] = items[k].index;
    }
    slots_.resize(n_);
    for (std::size_t k = 0; k < n_; ++k) slots_[k] = {centers[index_at[k]][0], centers[index_at[k]][1], radii[index_at[k]]};
    {
      std::vector<std::uint32_t> position_of(n_);
      for (std::size_t k = 0; k < n_; ++k) position_of[index_at[k]] = static_cast<std::uint32_t>(k);
      if (keep_indices) index_at_ = std::move(index_at);
      index_at = std::vector<std::uint32_t>();
      visit_.resize(n_);
      for (std::size_t k = 0; k < n_; ++k) visit_[k] = position_of[order[k]];
    }
    for (std::size_t leaf = 0; leaf < n_leaves_; ++leaf) {
      Node& box = nodes_[n_leaves_ + leaf];
      box.lo_x = box.lo_y = std::numeric_limits<double>::infinity();
      box.hi_x = box.hi_y = -std::numeric_limits<double>::infinity();
      for (std::size_t k = leaf_begin(leaf); k < leaf_begin(leaf + 1); ++k) {
        box.lo_x = std::min(box.lo_x, slots_[k].x);
        box.lo_y = std::min(box.lo_y, slots_[k].y);
        box.hi_x = std::max(box.hi_x, slots_[k].x);
        box.hi_y = std::max(box.hi_y, slots_[k].y);
      }
    }
    for (std::size_t node = n_leaves_ - 1; node >= 1; --node) {
      const Node& l = nodes_[2 * node];
      const Node& r = nodes_[2 * node + 1];
      nodes_[node] = {std::min(l.lo_x, r.lo_x), std::min(l.lo_y, r.lo_y), std::max(l.hi_x, r.hi_x),
                      std::max(l.hi_y, r.hi_y), -1.0};
    }
    kept_in_leaf_.assign(n_leaves_, 0);
  }

  // Position of the k-th sphere of the visiting order.
  std::size_t visit(std::size_t k) const { return visit_[k]; }

  // Fetches what a query at `position` reads first, ahead of time.
  void prefetch(std::size_t position) const {
    detail::prefetch(&slots_[position]);
    const std::size_t node = n_leaves_ + leaf_of(position);
    detail::prefetch(&kept_in_leaf_[node - n_leaves_]);
    detail::prefetch(&nodes_[node ^ 1]);
  }

  static constexpr std::size_t kNone = ~std::size_t{0};

  // The position of a kept sphere that conflicts with the one at `position`
  // (the first found), or kNone.
  std::size_t conflicting_kept(std::size_t position) const {
    const Slot& s = slots_[position];
    const double cx = s.x, cy = s.y, r = s.radius;
    std::size_t node = n_leaves_ + leaf_of(position);
    std::size_t hit = leaf_conflicts(node - n_leaves_, cx, cy, r);
    if (hit != kNone) return hit;
    for (; node > 1; node >>= 1) {
      hit = subtree_conflicts(node ^ 1, cx, cy, r);
      if (hit != kNone) return hit;
    }
    return kNone;
  }

  // The sphere at a position (only with keep_indices).
  std::size_t sphere_at(std::size_t position) const { return index_at_[position]; }

  void keep(std::size_t position) {
    const double r = slots_[position].radius;
    const std::size_t leaf = leaf_of(position);
    kept_in_leaf_[leaf] |= std::uint64_t{1} << (position - leaf_begin(leaf));
    for (std::size_t node = n_leaves_ + leaf; node >= 1; node >>= 1) {
      if (nodes_[node].max_kept_radius >= r) break;  // ancestors are at least as large
      nodes_[node].max_kept_radius = r;
    }
  }

 private:
  static constexpr std::size_t kLeafSize = 48;
  // Leaves hold at most kLeafSize + 1 spheres: one bit each in kept_in_leaf_.
  static_assert(kLeafSize < 64, "leaf masks are 64 bits");
  struct Slot {
    double x, y, radius;
  };
  struct Build_item {
    float x, y;
    std::uint32_t index;
  };
  struct Node {
    double lo_x, lo_y, hi_x, hi_y;
    double max_kept_radius = -1;
  };

  // Leaves split the positions as evenly as integers allow.
  std::size_t leaf_begin(std::size_t leaf) const {
    return static_cast<std::size_t>(static_cast<unsigned __int128>(leaf) * n_ / n_leaves_);
  }
  std::size_t leaf_of(std::size_t position) const {
    return static_cast<std::size_t>((static_cast<unsigned __int128>(position + 1) * n_leaves_ + n_ - 1) / n_ - 1);
  }
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

  std::size_t leaf_conflicts(std::size_t leaf, double cx, double cy, double r) const {
    const std::size_t begin = leaf_begin(leaf);
    const Slot* first = &slots_[begin];
    for (std::uint64_t mask = kept_in_leaf_[leaf]; mask != 0; mask &= mask - 1) {
      const Slot& s = first[detail::count_trailing_zeros(mask)];
      const double ex = s.x - cx;
      const double ey = s.y - cy;
      const double sum = r + s.radius;
      if (ex * ex + ey * ey < sum * sum) return begin + static_cast<std::size_t>(&s - first);
    }
    return kNone;
  }

  std::size_t subtree_conflicts(std::size_t root, double cx, double cy, double r) const {
    std::size_t stack[128];
    int top = 0;
    stack[top++] = root;
    while (top > 0) {
      const std::size_t node = stack[--top];
      const Node& b = nodes_[node];
      if (b.max_kept_radius < 0) continue;
      // Rounding is monotone, so this distance never exceeds the computed
      // distance to any centre in the box: pruning never skips a conflict.
      const double dx = std::max({b.lo_x - cx, 0.0, cx - b.hi_x});
      const double dy = std::max({b.lo_y - cy, 0.0, cy - b.hi_y});
      const double reach = r + b.max_kept_radius;
      if (dx * dx + dy * dy >= reach * reach) continue;
      if (node >= n_leaves_) {
        const std::size_t hit = leaf_conflicts(node - n_leaves_, cx, cy, r);
        if (hit != kNone) return hit;
      } else {
        stack[top++] = 2 * node + 1;
        stack[top++] = 2 * node;
      }
    }
    return kNone;
  }

  std::size_t n_;
  int depth_ = 0;
  std::size_t n_leaves_ = 1;
  std::vector<Slot> slots_;
  std::vector<std::uint32_t> visit_;
  std::vector<Node> nodes_;
  std::vector<std::uint64_t> kept_in_leaf_;  // bit k: position leaf_begin + k is kept
  std::vector<std::uint32_t> index_at_;      // sphere at each position (keep_indices only)
};

}  // namespace

std::vector<std::uint8_t> lexical_first_mis(const std::vector<Vec2>& centers,
                                            const std::vector<double>& radii,
                                            const std::vector<Index>& order, std::size_t n_forced,
                                            std::vector<Index>* blocker) {
  const std::size_t n = centers.size();
  if (radii.size() != n || order.size() != n) throw Input_error("centers, radii and order must have the same length");
  if (n_forced > n) throw Input_error("more forced spheres than spheres");
  if (n >= std::numeric_limits<std::uint32_t>::max()) throw Input_error("too many spheres (at most 2^32 - 2)");
  std::vector<std::uint8_t> kept(n, 0);
  for (Index i : order) {
    if (i < 0 || static_cast<std::size_t>(i) >= n || kept[i]) throw Input_error("order must be a permutation of 0..n-1");
    kept[i] = 1;
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(centers[i][0]) || !std::isfinite(centers[i][1])) throw Input_error("sphere centres must be finite");
    if (!std::isfinite(radii[i]) || !(radii[i] > 0)) throw Input_error("sphere radii must be finite and > 0");
  }
  std::fill(kept.begin(), kept.end(), 0);
  Kept_sphere_tree tree(centers, radii, order, blocker != nullptr);
  if (blocker) blocker->assign(n, -1);
  // The loop prefetches a few spheres ahead: which sphere comes next never
  // depends on the decisions.
  constexpr std::size_t kAhead = 8;
  for (std::size_t k = 0; k < n; ++k) {
    if (k + kAhead < n) tree.prefetch(tree.visit(k + kAhead));
    const std::size_t hit = k < n_forced ? Kept_sphere_tree::kNone : tree.conflicting_kept(tree.visit(k));
    if (hit == Kept_sphere_tree::kNone) {
      kept[order[k]] = 1;
      tree.keep(tree.visit(k));
    } else if (blocker) {
      (*blocker)[order[k]] = static_cast<Index>(tree.sphere_at(hit));
    }
  }
  return kept;
}

std::vector<Index> packing_order(const std::vector<std::uint8_t>& priority_class,
                                 const std::vector<double>& radii) {
  if (priority_class.size() != radii.size()) throw Input_error("classes and radii must have the same length");
  // (class, radius, index) is a strict total order. A stable least-significant-
  // digit radix sort on (class, radius) of the indices in increasing order gives
  // it: the bits of a positive double order like the double, so the radius is
  // sorted in six 11-bit passes (passes whose digit is the same everywhere are
  // skipped), then the class in one 8-bit pass.
  const std::size_t n = radii.size();
  struct Item {
    std::uint64_t radius_bits;
    std::uint64_t class_and_index;  // class in the top byte
  };
  std::vector<Item> items(n), next(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (!(radii[i] > 0)) throw Input_error("sphere radii must be > 0");
    std::memcpy(&items[i].radius_bits, &radii[i], sizeof(double));
    items[i].class_and_index = (std::uint64_t{priority_class[i]} << 56) | i;
  }
  std::vector<std::size_t> count(std::size_t{1} << 11);
  auto pass = [&](auto digit_of, std::size_t n_buckets) {
    std::fill(count.begin(), count.begin() + static_cast<std::ptrdiff_t>(n_buckets), 0);
    for (const Item& item : items) ++count[digit_of(item)];
    for (std::size_t d = 0; d < n_buckets; ++d) {
      if (count[d] == n) return;  // one digit everywhere: the order stays
    }
    std::size_t sum = 0;
    for (std::size_t d = 0; d < n_buckets; ++d) {
      const std::size_t c = count[d];
      count[d] = sum;
      sum += c;
    }
    for (const Item& item : items) next[count[digit_of(item)]++] = item;
    items.swap(next);
  };
  for (int shift = 0; shift < 64; shift += 11) {
    pass([shift](const Item& item) { return static_cast<std::size_t>((item.radius_bits >> shift) & 0x7ff); },
         std::size_t{1} << 11);
  }
  pass([](const Item& item) { return static_cast<std::size_t>(item.class_and_index >> 56); }, 256);
  std::vector<Index> order(n);
  constexpr std::uint64_t kIndexMask = (std::uint64_t{1} << 56) - 1;
  for (std::size_t k = 0; k < n; ++k) order[k] = static_cast<Index>(items[k].class_and_index & kIndexMask);
  return order;
}

Packing_class old_point_class(Point_kind kind, bool forced, bool demoted) {
  if (forced) return class_corner;
  if (demoted) return kind == Point_kind::corner || kind == Point_kind::boundary ? class_boundary_new : class_new;
  switch (kind) {
    case Point_kind::corner:
    case Point_kind::boundary: return class_boundary;
    case Point_kind::original: return class_original;
    default: return class_steiner;
  }
}

std::vector<std::uint8_t> demoted_points(const std::vector<Triangle>& triangles, const std::vector<double>& nn,
                                         const std::vector<double>& f, const std::vector<std::uint8_t>& forced,
                                         double demote_ratio) {
  const std::size_t n = nn.size();
  std::vector<std::uint8_t> demoted(n, 0);
  if (!(demote_ratio > 0)) return demoted;
  std::vector<std::uint8_t> refined(n);
  for (std::size_t p = 0; p < n; ++p) refined[p] = nn[p] > demote_ratio * f[p];
  for (std::size_t p = 0; p < n; ++p) demoted[p] = refined[p] && !forced[p];
  for (const Triangle& t : triangles) {
    if (refined[t[0]] && refined[t[1]] && refined[t[2]]) continue;
    for (Index v : t) demoted[v] = 0;  // a neighbour conforms
  }
  return demoted;
}

Packing_class new_point_class(bool on_segment, int round) {
  if (round < 0) return on_segment ? class_boundary_new : class_new;
  return static_cast<Packing_class>((on_segment ? class_boundary_ring : class_ring) + round);
}

void extend_packing(const std::vector<Vec2>& centers, const std::vector<double>& radii,
                    const std::vector<Index>& first_order, const std::vector<Vec2>& more_centers,
                    const std::vector<double>& more_radii, const std::vector<Index>& more_order,
                    std::vector<std::uint8_t>& kept) {
  std::vector<Index> order;
  std::vector<Vec2> all_centers;
  std::vector<double> all_radii;
  for (Index c : first_order) {
    if (!kept[c]) continue;
    order.push_back(static_cast<Index>(all_centers.size()));
    all_centers.push_back(centers[c]);
    all_radii.push_back(radii[c]);
  }
  const std::size_t n_first = order.size();
  for (Index j : more_order) order.push_back(static_cast<Index>(n_first + j));
  all_centers.insert(all_centers.end(), more_centers.begin(), more_centers.end());
  all_radii.insert(all_radii.end(), more_radii.begin(), more_radii.end());
  const auto more_kept = lexical_first_mis(all_centers, all_radii, order, n_first);
  kept.insert(kept.end(), more_kept.begin() + static_cast<std::ptrdiff_t>(n_first), more_kept.end());
}

}  // namespace evomesh
