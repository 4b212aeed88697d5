#include "evomesh/packing.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

#include "evomesh/detail/bits.hpp"
#include "evomesh/detail/static_kd_tree.hpp"

namespace evomesh {

namespace {

// The kd-tree over sphere centres (detail/static_kd_tree.hpp, leaves of at most
// 48 spheres) with the centre and radius of every sphere copied in tree order,
// so a leaf is scanned in one contiguous sweep. Each node keeps, besides its
// bounding box, the largest radius among the *kept* spheres below it (-1: none
// kept yet), and each leaf a mask of its kept spheres.
//
// A query starts at the sphere's own leaf and climbs to the root, searching the
// sibling subtree at each level: a sphere that conflicts with a kept one (most
// candidates of FRFC) usually finds it in the first leaves visited and stops.
// Whether a sphere conflicts does not depend on the shape of the tree or the
// search order, only on the conflict test, which is the same expression for
// every pair; which kept sphere it meets first (the blocker) does.
class Kept_sphere_tree {
 public:
  // `order`: the visiting order (distinct sphere indices; the tree holds every sphere).
  Kept_sphere_tree(const std::vector<Vec2>& centers, const std::vector<double>& radii, const std::vector<Index>& order)
      : tree_(centers, kLeafSize) {
    const std::size_t n = centers.size();
    const auto& sphere_at = tree_.point_at();
    slots_.resize(n);
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t i = sphere_at[k];
      slots_[k] = {centers[i][0], centers[i][1], radii[i]};
    }
    {
      std::vector<std::uint32_t> position_of(n);
      for (std::size_t k = 0; k < n; ++k) position_of[sphere_at[k]] = static_cast<std::uint32_t>(k);
      visit_.resize(order.size());
      for (std::size_t k = 0; k < order.size(); ++k) visit_[k] = position_of[order[k]];
    }
    kept_in_leaf_.assign(tree_.n_leaves(), 0);
  }

  // Position of the k-th sphere of the visiting order.
  std::size_t visit(std::size_t k) const { return visit_[k]; }

  // Fetches what a query at `position` reads first, ahead of time.
  void prefetch(std::size_t position) const {
    detail::prefetch(&slots_[position]);
    const std::size_t node = tree_.leaf_node(position);
    detail::prefetch(&kept_in_leaf_[tree_.leaf(node)]);
    detail::prefetch(&tree_.node(node ^ 1));
  }

  static constexpr std::size_t kNone = ~std::size_t{0};

  // The position of a kept sphere that conflicts with the one at `position`
  // (the first found), or kNone.
  std::size_t conflicting_kept(std::size_t position) const {
    const Slot& s = slots_[position];
    const double cx = s.x, cy = s.y, r = s.radius;
    std::size_t hit = kNone;
    tree_.outward(
        position, [&](std::size_t leaf) { return (hit = leaf_conflicts(leaf, cx, cy, r)) != kNone; },
        [&](std::size_t node, detail::Kd_stack& stack) {
          const Node& b = tree_.node(node);
          if (b.max_kept_radius < 0) return false;
          // Pruning never skips a conflict (detail::squared_distance).
          const double reach = r + b.max_kept_radius;
          if (detail::squared_distance(b, cx, cy) >= reach * reach) return false;
          if (!tree_.is_leaf(node)) {
            stack.push_children(node);
            return false;
          }
          hit = leaf_conflicts(tree_.leaf(node), cx, cy, r);
          return hit != kNone;
        });
    return hit;
  }

  // The sphere at a position.
  std::size_t sphere_at(std::size_t position) const { return tree_.point_at()[position]; }

  void keep(std::size_t position) {
    const double r = slots_[position].radius;
    const std::size_t leaf = tree_.leaf_of(position);
    kept_in_leaf_[leaf] |= std::uint64_t{1} << (position - tree_.leaf_begin(leaf));
    for (std::size_t node = tree_.n_leaves() + leaf; node >= 1; node >>= 1) {
      if (tree_.node(node).max_kept_radius >= r) break;  // ancestors are at least as large
      tree_.node(node).max_kept_radius = r;
    }
  }

 private:
  static constexpr std::size_t kLeafSize = 48;
  // Leaves hold at most kLeafSize + 1 spheres: one bit each in kept_in_leaf_.
  static_assert(kLeafSize < 64, "leaf masks are 64 bits");
  struct Slot {
    double x, y, radius;
  };
  struct Node : detail::Box {
    double max_kept_radius = -1;
  };

  std::size_t leaf_conflicts(std::size_t leaf, double cx, double cy, double r) const {
    const std::size_t begin = tree_.leaf_begin(leaf);
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

  detail::Static_kd_tree<Node> tree_;
  std::vector<Slot> slots_;                  // in tree order
  std::vector<std::uint32_t> visit_;         // position of each sphere of the visiting order
  std::vector<std::uint64_t> kept_in_leaf_;  // bit k: position leaf_begin + k is kept
};

}  // namespace

namespace {

// The lexical-first MIS of the spheres listed in `order` (distinct indices; with
// `permutation`, all of them); spheres not listed are neither kept nor met.
std::vector<std::uint8_t> mis_in_order(const std::vector<Vec2>& centers, const std::vector<double>& radii,
                                       const std::vector<Index>& order, std::size_t n_forced,
                                       std::vector<Index>* blocker, bool permutation) {
  const std::size_t n = centers.size();
  if (radii.size() != n || (permutation && order.size() != n)) {
    throw Input_error("centers, radii and order must have the same length");
  }
  if (n_forced > order.size()) throw Input_error("more forced spheres than spheres");
  if (n >= std::numeric_limits<std::uint32_t>::max()) throw Input_error("too many spheres (at most 2^32 - 2)");
  std::vector<std::uint8_t> kept(n, 0);
  for (Index i : order) {
    if (i < 0 || static_cast<std::size_t>(i) >= n || kept[i]) {
      throw Input_error(permutation ? "order must be a permutation of 0..n-1" : "order must list distinct spheres");
    }
    kept[i] = 1;
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(centers[i][0]) || !std::isfinite(centers[i][1])) throw Input_error("sphere centres must be finite");
    if (!std::isfinite(radii[i]) || !(radii[i] > 0)) throw Input_error("sphere radii must be finite and > 0");
  }
  std::fill(kept.begin(), kept.end(), 0);
  Kept_sphere_tree tree(centers, radii, order);
  if (blocker) blocker->assign(n, -1);
  // The loop prefetches a few spheres ahead: which sphere comes next never
  // depends on the decisions.
  constexpr std::size_t kAhead = 8;
  const std::size_t m = order.size();
  for (std::size_t k = 0; k < m; ++k) {
    if (k + kAhead < m) tree.prefetch(tree.visit(k + kAhead));
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

}  // namespace

std::vector<std::uint8_t> lexical_first_mis(const std::vector<Vec2>& centers,
                                            const std::vector<double>& radii,
                                            const std::vector<Index>& order, std::size_t n_forced,
                                            std::vector<Index>* blocker) {
  return mis_in_order(centers, radii, order, n_forced, blocker, /*permutation=*/true);
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

std::vector<std::uint8_t> extend_packing(const std::vector<Vec2>& centers, const std::vector<double>& radii,
                                         const std::vector<Index>& first_order, const std::vector<std::uint8_t>& kept,
                                         std::vector<Index> more_order) {
  std::vector<Index> order;
  for (Index c : first_order) {
    if (kept[c]) order.push_back(c);
  }
  const std::size_t n_first = order.size();
  order.reserve(n_first + more_order.size());
  order.insert(order.end(), more_order.begin(), more_order.end());
  more_order = std::vector<Index>();
  return mis_in_order(centers, radii, order, n_first, nullptr, /*permutation=*/false);
}

}  // namespace evomesh
