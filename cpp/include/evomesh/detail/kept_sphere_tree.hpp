// The kd-tree of spheres that the lexical-first MIS queries for a kept (or
// pending) sphere in conflict, in D dimensions: the serial packing
// (packing.cpp; the 2-D and the 3-D step) and one rank's share of the MIS in
// rounds (mis_rounds.cpp).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "evomesh/detail/bits.hpp"
#include "evomesh/detail/sphere_conflict.hpp"
#include "evomesh/nd/kd_tree.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/types.hpp"

namespace evomesh::detail {

// The kd-tree over sphere centres (nd::Static_kd_tree, leaves of at most 48
// spheres) with the centre and radius of every sphere copied in tree order, so
// a leaf is scanned in one contiguous sweep. Each node keeps, besides its
// bounding box, the largest radius among the *kept* spheres below it (-1: none
// kept yet), and each leaf a mask of its kept spheres.
//
// A query starts at the sphere's own leaf and climbs to the root, searching the
// sibling subtree at each level: a sphere that conflicts with a kept one (most
// candidates of FRFC) usually finds it in the first leaves visited and stops.
// Whether a sphere conflicts does not depend on the shape of the tree or the
// search order, only on the conflict test, which is the same expression for
// every pair; which kept sphere it meets first (the blocker) does.
//
// The search order. Without pruning, a query at position p would scan every
// position in one fixed order T_p (its own leaf, then the sibling subtrees from
// the bottom up, each depth first, left child first; a leaf in position order).
// Pruning only drops subtrees (contiguous stretches of T_p) none of whose
// spheres can conflict, and it never drops a conflict (see below). So a query
// returns the first kept sphere in T_p that conflicts, whatever else is kept:
// the answer over a kept set S is min_T {s in S: s conflicts}, and the answer
// over a union is the earlier (in T_p) of the answers over its parts.
//
// The parallel packing (mis_in_blocks) also marks a block of spheres
// "pending" (the next ones of the visiting order, not decided yet): a frozen
// query then reports the first kept conflict and, before it in T_p, every
// pending sphere that conflicts.
template <std::size_t D>
class Kept_sphere_tree {
 public:
  // `order`: the visiting order (distinct sphere indices; the tree holds every
  // sphere), consumed: the tree keeps the position of each instead.
  Kept_sphere_tree(const std::vector<nd::Point<D>>& centers, const std::vector<double>& radii,
                   std::vector<Index>&& order, int threads)
      : tree_(centers, kLeafSize, typename Tree::Boxes_later{}) {
    const std::size_t n = centers.size();
    const auto& sphere_at = tree_.point_at();
    // Gathers and a scatter over all spheres, in chunks on `threads` threads.
    constexpr std::size_t kChunk = std::size_t{1} << 16;
    auto chunks = [&](std::size_t size, auto body) {
      parallel_for((size + kChunk - 1) / kChunk, threads, [&](std::size_t c) {
        for (std::size_t k = c * kChunk; k < std::min(size, (c + 1) * kChunk); ++k) body(k);
      });
    };
    // (memory: the visiting positions first, so that the order, 8 bytes a
    // sphere, is gone before the slots, 24, are filled)
    {
      std::vector<std::uint32_t> position_of;
      detail::parallel_resize(position_of, n);
      chunks(n, [&](std::size_t k) { position_of[sphere_at[k]] = static_cast<std::uint32_t>(k); });
      detail::parallel_resize(visit_, order.size());
      chunks(order.size(), [&](std::size_t k) { visit_[k] = position_of[order[k]]; });
    }
    order = std::vector<Index>();
    detail::parallel_resize(slots_, n);
    chunks(n, [&](std::size_t k) {
      const std::size_t i = sphere_at[k];
      slots_[k] = {centers[i], radii[i]};
    });
    // The nodes' boxes from the slots, in order (the same boxes).
    tree_.set_boxes([this](std::size_t k) -> const nd::Point<D>& { return slots_[k].centre; });
    leaf_masks_.assign(tree_.n_leaves(), Leaf_masks{});
  }

  // Position of the k-th sphere of the visiting order.
  std::size_t visit(std::size_t k) const { return visit_[k]; }
  std::size_t n_visits() const { return visit_.size(); }

  // Fetches what a query at `position` reads first, ahead of time.
  void prefetch(std::size_t position) const {
    detail::prefetch(&slots_[position]);
    const std::size_t node = tree_.leaf_node(position);
    detail::prefetch(&leaf_masks_[tree_.leaf(node)]);
    detail::prefetch(&tree_.node(node ^ 1));
  }

  static constexpr std::size_t kNone = ~std::size_t{0};

  // The position of a kept sphere that conflicts with the one at `position`
  // (the first found), or kNone.
  std::size_t conflicting_kept(std::size_t position) const {
    const Slot& s = slots_[position];
    const nd::Point<D>& c = s.centre;
    const double r = s.radius;
    std::size_t hit = kNone;
    tree_.outward(
        position, [&](std::size_t leaf) { return (hit = leaf_conflicts(leaf, c, r)) != kNone; },
        [&](std::size_t node, nd::Kd_stack& stack) {
          const Node& b = tree_.node(node);
          if (b.max_kept_radius < 0) return false;
          // Pruning never skips a conflict (nd::squared_distance of a box).
          const double reach = r + b.max_kept_radius;
          if (nd::squared_distance<D>(b, c) >= reach * reach) return false;
          if (!tree_.is_leaf(node)) {
            stack.push_children(node);
            return false;
          }
          hit = leaf_conflicts(tree_.leaf(node), c, r);
          return hit != kNone;
        });
    return hit;
  }

  // The pending spheres met by a frozen query, in search order.
  static constexpr std::size_t kMaxMet = 32;
  struct Met {
    std::uint32_t position[kMaxMet];
    std::size_t size = 0;
  };

  // The query of conflicting_kept against the kept spheres and the pending
  // ones: `hit` receives the first kept sphere in T_p that conflicts (kNone:
  // none) and `met` every pending sphere other than the query's own that
  // conflicts and comes before `hit` in T_p (all of them when none), in T_p
  // order. False when there are more than kMaxMet of them (`met` and `hit`
  // are then meaningless). Reads the tree only.
  bool conflicting_kept_or_pending(std::size_t position, std::size_t& hit, Met& met) const {
    const Slot& s = slots_[position];
    const nd::Point<D>& c = s.centre;
    const double r = s.radius;
    const double pending_radius = pending_radius_;
    hit = kNone;
    met.size = 0;
    bool overflow = false;
    auto scan = [&](std::size_t leaf) {
      const std::size_t begin = tree_.leaf_begin(leaf);
      const Slot* first = &slots_[begin];
      const Leaf_masks& masks = leaf_masks_[leaf];
      const std::uint64_t kept = masks.kept;
      // (threads may mark and unmark spheres pending meanwhile: an atomic read)
      for (std::uint64_t mask = kept | __atomic_load_n(&masks.pending, __ATOMIC_RELAXED); mask != 0;
           mask &= mask - 1) {
        const int bit = detail::count_trailing_zeros(mask);
        const Slot& t = first[bit];
        if (!spheres_conflict<D>(t.centre, c, r + t.radius)) continue;
        const std::size_t at = begin + static_cast<std::size_t>(bit);
        if ((kept >> bit) & 1) {
          hit = at;
          return true;
        }
        if (at == position) continue;
        if (met.size == kMaxMet) {
          overflow = true;
          return true;
        }
        met.position[met.size++] = static_cast<std::uint32_t>(at);
      }
      return false;
    };
    tree_.outward(position, scan, [&](std::size_t node, nd::Kd_stack& stack) {
      const Node& b = tree_.node(node);
      // Every pending sphere's radius is at most pending_radius: the pruning
      // of conflicting_kept with that radius for every node never skips a
      // pending conflict either.
      const double reach_radius = std::max(b.max_kept_radius, pending_radius);
      if (reach_radius < 0) return false;
      const double reach = r + reach_radius;
      if (nd::squared_distance<D>(b, c) >= reach * reach) return false;
      if (!tree_.is_leaf(node)) {
        stack.push_children(node);
        return false;
      }
      return scan(tree_.leaf(node));
    });
    return !overflow;
  }

  // Marks the sphere at `position` pending (with no sphere kept there), or
  // no longer. Atomic on the leaf's mask: threads may mark and unmark spheres
  // of the same leaf at once (the order does not matter).
  void mark_pending(std::size_t position) {
    const std::size_t leaf = tree_.leaf_of(position);
    __atomic_fetch_or(&leaf_masks_[leaf].pending, std::uint64_t{1} << (position - tree_.leaf_begin(leaf)),
                      __ATOMIC_RELAXED);
  }
  void unmark_pending(std::size_t position) {
    const std::size_t leaf = tree_.leaf_of(position);
    __atomic_fetch_and(&leaf_masks_[leaf].pending, ~(std::uint64_t{1} << (position - tree_.leaf_begin(leaf))),
                       __ATOMIC_RELAXED);
  }
  // At least the radius of every pending sphere (-1: none pending).
  void set_pending_radius(double radius) { pending_radius_ = radius; }
  double radius(std::size_t position) const { return slots_[position].radius; }
  bool is_kept(std::size_t position) const {
    const std::size_t leaf = tree_.leaf_of(position);
    return (leaf_masks_[leaf].kept >> (position - tree_.leaf_begin(leaf))) & 1;
  }

  // The sphere at a position.
  std::size_t sphere_at(std::size_t position) const { return tree_.point_at()[position]; }

  // No sphere kept or pending (the tree and the visiting order stay).
  void reset() {
    for (std::size_t node = 1; node < 2 * tree_.n_leaves(); ++node) tree_.node(node).max_kept_radius = -1;
    std::fill(leaf_masks_.begin(), leaf_masks_.end(), Leaf_masks{});
    pending_radius_ = -1;
  }

  // Whether x lies strictly inside a kept sphere: then B(x, r) conflicts with
  // it for every r >= 0 ((s + r)^2 >= s^2 after rounding), so a candidate
  // there can be dropped before its radius is known.
  bool covers(const nd::Point<D>& x) const {
    return tree_.depth_first(1, [&](std::size_t node, nd::Kd_stack& stack) {
      const Node& b = tree_.node(node);
      if (b.max_kept_radius < 0 || !(nd::squared_distance<D>(b, x) < b.max_kept_radius * b.max_kept_radius)) {
        return false;
      }
      if (!tree_.is_leaf(node)) {
        stack.push_children(node);
        return false;
      }
      const std::size_t leaf = tree_.leaf(node);
      const Slot* first = &slots_[tree_.leaf_begin(leaf)];
      for (std::uint64_t mask = leaf_masks_[leaf].kept; mask != 0; mask &= mask - 1) {
        const Slot& t = first[detail::count_trailing_zeros(mask)];
        if (nd::squared_distance<D>(t.centre, x) < t.radius * t.radius) return true;
      }
      return false;
    });
  }

  void keep(std::size_t position) {
    const double r = slots_[position].radius;
    const std::size_t leaf = tree_.leaf_of(position);
    leaf_masks_[leaf].kept |= std::uint64_t{1} << (position - tree_.leaf_begin(leaf));
    for (std::size_t node = tree_.n_leaves() + leaf; node >= 1; node >>= 1) {
      if (tree_.node(node).max_kept_radius >= r) break;  // ancestors are at least as large
      tree_.node(node).max_kept_radius = r;
    }
  }

 private:
  static constexpr std::size_t kLeafSize = 48;
  // Leaves hold at most kLeafSize + 1 spheres: one bit each in the leaf masks.
  static_assert(kLeafSize < 64, "leaf masks are 64 bits");
  struct Slot {
    nd::Point<D> centre;
    double radius;
  };
  struct Node : nd::Box<D> {
    double max_kept_radius = -1;
  };
  // Bit k: position leaf_begin + k is kept; is pending.
  struct Leaf_masks {
    std::uint64_t kept = 0, pending = 0;
  };

  std::size_t leaf_conflicts(std::size_t leaf, const nd::Point<D>& c, double r) const {
    const std::size_t begin = tree_.leaf_begin(leaf);
    const Slot* first = &slots_[begin];
    for (std::uint64_t mask = leaf_masks_[leaf].kept; mask != 0; mask &= mask - 1) {
      const Slot& s = first[detail::count_trailing_zeros(mask)];
      if (spheres_conflict<D>(s.centre, c, r + s.radius)) return begin + static_cast<std::size_t>(&s - first);
    }
    return kNone;
  }

  using Tree = nd::Static_kd_tree<D, Node>;
  Tree tree_;
  std::vector<Slot> slots_;                  // in tree order
  std::vector<std::uint32_t> visit_;         // position of each sphere of the visiting order
  std::vector<Leaf_masks> leaf_masks_;
  double pending_radius_ = -1;  // the largest radius of a pending sphere (-1: none)
};

}  // namespace evomesh::detail
