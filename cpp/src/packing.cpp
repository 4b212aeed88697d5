#include "evomesh/packing.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <utility>

#include "evomesh/detail/bits.hpp"
#include "evomesh/detail/static_kd_tree.hpp"
#include "evomesh/parallel.hpp"

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
class Kept_sphere_tree {
 public:
  // `order`: the visiting order (distinct sphere indices; the tree holds every
  // sphere), consumed: the tree keeps the position of each instead.
  Kept_sphere_tree(const std::vector<Vec2>& centers, const std::vector<double>& radii, std::vector<Index>&& order,
                   int threads)
      : tree_(centers, kLeafSize, Tree::Boxes_later{}) {
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
      slots_[k] = {centers[i][0], centers[i][1], radii[i]};
    });
    // The nodes' boxes from the slots, in order (the same boxes).
    tree_.set_boxes([this](std::size_t k) { return Vec2{slots_[k].x, slots_[k].y}; });
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
    const double cx = s.x, cy = s.y, r = s.radius;
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
        const double ex = t.x - cx;
        const double ey = t.y - cy;
        const double sum = r + t.radius;
        if (!(ex * ex + ey * ey < sum * sum)) continue;
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
    tree_.outward(position, scan, [&](std::size_t node, detail::Kd_stack& stack) {
      const Node& b = tree_.node(node);
      // Every pending sphere's radius is at most pending_radius: the pruning
      // of conflicting_kept with that radius for every node never skips a
      // pending conflict either.
      const double reach_radius = std::max(b.max_kept_radius, pending_radius);
      if (reach_radius < 0) return false;
      const double reach = r + reach_radius;
      if (detail::squared_distance(b, cx, cy) >= reach * reach) return false;
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
    double x, y, radius;
  };
  struct Node : detail::Box {
    double max_kept_radius = -1;
  };
  // Bit k: position leaf_begin + k is kept; is pending.
  struct Leaf_masks {
    std::uint64_t kept = 0, pending = 0;
  };

  std::size_t leaf_conflicts(std::size_t leaf, double cx, double cy, double r) const {
    const std::size_t begin = tree_.leaf_begin(leaf);
    const Slot* first = &slots_[begin];
    for (std::uint64_t mask = leaf_masks_[leaf].kept; mask != 0; mask &= mask - 1) {
      const Slot& s = first[detail::count_trailing_zeros(mask)];
      const double ex = s.x - cx;
      const double ey = s.y - cy;
      const double sum = r + s.radius;
      if (ex * ex + ey * ey < sum * sum) return begin + static_cast<std::size_t>(&s - first);
    }
    return kNone;
  }

  using Tree = detail::Static_kd_tree<Node>;
  Tree tree_;
  std::vector<Slot> slots_;                  // in tree order
  std::vector<std::uint32_t> visit_;         // position of each sphere of the visiting order
  std::vector<Leaf_masks> leaf_masks_;
  double pending_radius_ = -1;  // the largest radius of a pending sphere (-1: none)
};

}  // namespace

namespace {

constexpr std::size_t kNone = Kept_sphere_tree::kNone;

// The visiting loop: each sphere is kept unless a kept one conflicts (the
// first `n_forced` always).
void mis_sequential(Kept_sphere_tree& tree, std::size_t n_forced, std::vector<std::uint8_t>& kept,
                    std::vector<Index>* blocker) {
  // The loop prefetches a few spheres ahead: which sphere comes next never
  // depends on the decisions.
  constexpr std::size_t kAhead = 8;
  const std::size_t m = tree.n_visits();
  for (std::size_t k = 0; k < m; ++k) {
    if (k + kAhead < m) tree.prefetch(tree.visit(k + kAhead));
    const std::size_t position = tree.visit(k);
    const std::size_t hit = k < n_forced ? kNone : tree.conflicting_kept(position);
    if (hit == kNone) {
      kept[tree.sphere_at(position)] = 1;
      tree.keep(position);
    } else if (blocker) {
      (*blocker)[tree.sphere_at(position)] = static_cast<Index>(tree.sphere_at(hit));
    }
  }
}

// The same decisions and blockers, the queries on `threads` threads.
//
// The spheres after the forced ones go in blocks of `block` consecutive ones
// of the order. At the start of a block the tree holds S_a, the spheres kept
// before it; the block's spheres are marked pending and each is queried in
// parallel against this frozen tree (conflicting_kept_or_pending, read only):
// h_k, its first kept conflict in search order T_k, and L_k, the pending
// spheres that conflict before h_k in T_k (in T_k order). Then one pass over
// the block, in order, decides as the sequential loop would: there the query
// of sphere k sees S_a + K_k, K_k the block's spheres kept before k, and
// answers the earliest conflicting sphere of that set in T_k
// (Kept_sphere_tree). A sphere of K_k that conflicts and comes before h_k in
// T_k is pending, so it is in L_k; those after h_k do not matter. The answer
// is therefore the first sphere of L_k in K_k, else h_k. K_k is read off the
// tree's kept flags as the pass keeps spheres: a sphere of the block is
// flagged at k exactly when it comes before k and was kept. When L_k would
// exceed Met::kMaxMet (dense overlap within the block), the pass runs the
// sequential query instead, on the tree that then holds S_a + K_k. So every
// decision and every blocker equals the sequential one, for any block size
// and thread count.
void mis_in_blocks(Kept_sphere_tree& tree, std::size_t n_forced, std::vector<std::uint8_t>& kept,
                   std::vector<Index>* blocker, int threads, std::size_t block, detail::Mis_block_counts* counts) {
  const std::size_t m = tree.n_visits();
  for (std::size_t k = 0; k < n_forced; ++k) {
    kept[tree.sphere_at(tree.visit(k))] = 1;
    tree.keep(tree.visit(k));
  }
  // A block's queries go in chunks, a parallel_for item each; a chunk lists
  // its met pending spheres as (offset in the block, position) in order.
  constexpr std::size_t kChunk = 256;
  // A query's outcome: the position of its first kept conflict, or one of these.
  constexpr std::uint64_t kNoHit = ~std::uint64_t{0};  // no kept conflict
  constexpr std::uint64_t kRerun = kNoHit - 1;         // too many pending conflicts
  constexpr std::uint64_t kDone = kNoHit - 2;          // a kept conflict, no pending one: rejected, blocker written
  block = std::max<std::size_t>(block, 1);
  if (n_forced == m) return;
  // Blocks of at most `block` spheres whose radii lie within a factor
  // kRadiusSpread: the pending radius prunes a frozen query like the kept
  // spheres' radii prune the sequential one. (One radius for the whole block
  // lets a few large spheres, from the end of a class or a coarse region,
  // widen every query of the block: 16x the sequential time measured on a
  // strongly graded refinement.) Any partition gives the same decisions.
  constexpr double kRadiusSpread = 2.0;
  std::vector<std::size_t> starts{n_forced};
  {
    double lo = tree.radius(tree.visit(n_forced)), hi = lo;
    for (std::size_t k = n_forced + 1; k < m; ++k) {
      const double r = tree.radius(tree.visit(k));
      const double new_lo = std::min(lo, r), new_hi = std::max(hi, r);
      if (k - starts.back() >= block || new_hi > kRadiusSpread * new_lo) {
        starts.push_back(k);
        lo = hi = r;
      } else {
        lo = new_lo;
        hi = new_hi;
      }
    }
  }
  starts.push_back(m);
  std::size_t longest = 0;
  for (std::size_t i = 0; i + 1 < starts.size(); ++i) longest = std::max(longest, starts[i + 1] - starts[i]);
  std::vector<std::uint64_t> hit(longest);
  std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>> met((hit.size() + kChunk - 1) / kChunk);
  // Marking spheres pending (and unmarking them) goes in chunks too, in the
  // same parallel_for as the queries: a query may see the marks of the next
  // block or those of the previous one, or not. Either way it lists at most
  // spheres that are not kept when its sphere's turn comes (those of the next
  // block) or that are decided (those of the previous one: kept ones have
  // their kept flag, a hit; the others are never kept), which the pass
  // ignores: all that matters is that the block's own spheres are marked and
  // the pending radius covers them, done before its queries start.
  constexpr std::size_t kMarkChunk = 4096;
  std::vector<double> chunk_radius;
  double next_radius = -1;
  // One parallel_for: the queries of [a, b) (a < b), marks [b, c), unmarks [a0, a).
  auto run = [&](std::size_t a0, std::size_t a, std::size_t b, std::size_t c) {
    const std::size_t n_query = (b - a + kChunk - 1) / kChunk;
    const std::size_t n_mark = (c - b + kMarkChunk - 1) / kMarkChunk, n_unmark = (a - a0 + kMarkChunk - 1) / kMarkChunk;
    chunk_radius.assign(n_mark, -1);
    parallel_for(n_mark + n_unmark + n_query, threads, [&](std::size_t item) {
      if (item < n_mark) {
        double radius = -1;
        const std::size_t begin = b + item * kMarkChunk;
        for (std::size_t k = begin; k < std::min(c, begin + kMarkChunk); ++k) {
          tree.mark_pending(tree.visit(k));
          radius = std::max(radius, tree.radius(tree.visit(k)));
        }
        chunk_radius[item] = radius;
        return;
      }
      if (item < n_mark + n_unmark) {
        const std::size_t begin = a0 + (item - n_mark) * kMarkChunk;
        for (std::size_t k = begin; k < std::min(a, begin + kMarkChunk); ++k) tree.unmark_pending(tree.visit(k));
        return;
      }
      const std::size_t q = item - n_mark - n_unmark;
      constexpr std::size_t kAhead = 8;
      const std::size_t begin = a + q * kChunk, end = std::min(b, begin + kChunk);
      auto& list = met[q];
      list.clear();
      Kept_sphere_tree::Met found;
      for (std::size_t k = begin; k < end; ++k) {
        if (k + kAhead < end) tree.prefetch(tree.visit(k + kAhead));
        std::size_t h = kNone;
        const std::size_t offset = k - a;
        if (!tree.conflicting_kept_or_pending(tree.visit(k), h, found)) {
          hit[offset] = kRerun;
        } else if (h != kNone && found.size == 0) {
          // Final: no sphere of the block can come first (each k writes its own entry).
          if (blocker) (*blocker)[tree.sphere_at(tree.visit(k))] = static_cast<Index>(tree.sphere_at(h));
          hit[offset] = kDone;
        } else {
          hit[offset] = h == kNone ? kNoHit : h;
          for (std::size_t i = 0; i < found.size; ++i) list.emplace_back(offset, found.position[i]);
        }
      }
    });
    next_radius = -1;
    for (double r : chunk_radius) next_radius = std::max(next_radius, r);
  };
  run(n_forced, n_forced, n_forced, starts[1]);  // marks the first block
  std::size_t a0 = n_forced;
  for (std::size_t i = 0; i + 1 < starts.size(); ++i) {
    const std::size_t a = starts[i], b = starts[i + 1];
    tree.set_pending_radius(next_radius);
    run(a0, a, b, i + 2 < starts.size() ? starts[i + 2] : m);
    const std::size_t n_chunks = (b - a + kChunk - 1) / kChunk;
    for (std::size_t c = 0; c < n_chunks; ++c) {
      const auto& list = met[c];
      std::size_t next = 0;
      const std::size_t begin = a + c * kChunk, end = std::min(b, begin + kChunk);
      for (std::size_t k = begin; k < end; ++k) {
        const std::size_t offset = k - a;
        const std::uint64_t h = hit[offset];
        if (h == kDone) continue;
        const std::size_t position = tree.visit(k);
        std::size_t first = kNone;
        if (h == kRerun) {
          first = tree.conflicting_kept(position);
          if (counts) ++counts->reruns;
        } else {
          for (; next < list.size() && list[next].first == offset; ++next) {
            if (first == kNone && tree.is_kept(list[next].second)) first = list[next].second;
            if (counts) ++counts->met;
          }
          if (first != kNone && counts) ++(h == kNoHit ? counts->blocked_in_block : counts->blocker_in_block);
          if (first == kNone && h != kNoHit) first = static_cast<std::size_t>(h);
        }
        if (first == kNone) {
          kept[tree.sphere_at(position)] = 1;
          tree.keep(position);
        } else if (blocker) {
          (*blocker)[tree.sphere_at(position)] = static_cast<Index>(tree.sphere_at(first));
        }
      }
    }
    a0 = a;
  }
}

// The block size of mis_in_blocks, and the fewest spheres (after the forced
// ones) for which it runs instead of the sequential loop. On FRFC's second
// pass at 1e6 points (6.6e6 spheres, a third of them meeting a pending
// conflict at 16384) blocks of 16384 and 65536 took the same time and 262144
// 40% more; the larger of the first two waits on fewer parallel_for ends,
// which cost most on a loaded machine.
constexpr std::size_t kBlock = 65536;
constexpr std::size_t kMinParallel = 32768;

// The lexical-first MIS of the spheres listed in `order` (distinct indices; with
// `permutation`, all of them); spheres not listed are neither kept nor met.
// `block` > 0: mis_in_blocks with that block size whatever the size and the
// thread count (tests).
std::vector<std::uint8_t> mis_in_order(const std::vector<Vec2>& centers, const std::vector<double>& radii,
                                       std::vector<Index> order, std::size_t n_forced,
                                       std::vector<Index>* blocker, bool permutation, int threads,
                                       std::size_t block = 0, detail::Mis_block_counts* counts = nullptr) {
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
  const std::size_t m = order.size();
  Kept_sphere_tree tree(centers, radii, std::move(order), threads);
  if (blocker) {
    blocker->clear();
    detail::parallel_resize(*blocker, n, Index{-1});
  }
  const bool parallel = resolve_threads(threads) > 1 && !detail::in_parallel_region() && m - n_forced >= kMinParallel;
  if (block > 0 || parallel) {
    mis_in_blocks(tree, n_forced, kept, blocker, threads, block > 0 ? block : kBlock, counts);
  } else {
    mis_sequential(tree, n_forced, kept, blocker);
  }
  return kept;
}

}  // namespace

std::vector<std::uint8_t> lexical_first_mis(const std::vector<Vec2>& centers,
                                            const std::vector<double>& radii,
                                            const std::vector<Index>& order, std::size_t n_forced,
                                            std::vector<Index>* blocker, int threads) {
  return mis_in_order(centers, radii, order, n_forced, blocker, /*permutation=*/true, threads);
}

namespace detail {

std::vector<std::uint8_t> lexical_first_mis_in_blocks(const std::vector<Vec2>& centers,
                                                      const std::vector<double>& radii,
                                                      const std::vector<Index>& order, std::size_t n_forced,
                                                      std::vector<Index>* blocker, int threads, std::size_t block,
                                                      bool permutation, Mis_block_counts* counts) {
  if (counts) *counts = Mis_block_counts{};
  if (block == 0) return mis_in_order(centers, radii, order, n_forced, blocker, permutation, /*threads=*/1);
  return mis_in_order(centers, radii, order, n_forced, blocker, permutation, threads, block, counts);
}

}  // namespace detail

namespace {

// packing_order's sort keys: the radius's bits and (class, index).
struct Order_item {
  std::uint64_t radius_bits;
  std::uint64_t class_and_index;  // class in the top byte
};
constexpr std::size_t kOrderChunk = std::size_t{1} << 16;

template <class Body>
void for_order_chunks(std::size_t n, Body body) {
  const std::size_t n_chunks = std::max<std::size_t>(1, (n + kOrderChunk - 1) / kOrderChunk);
  parallel_for(n_chunks, 0, [&](std::size_t c) { body(c, c * kOrderChunk, std::min(n, (c + 1) * kOrderChunk)); });
}

std::vector<Order_item> order_items(const std::vector<std::uint8_t>& priority_class, const std::vector<double>& radii) {
  if (priority_class.size() != radii.size()) throw Input_error("classes and radii must have the same length");
  std::vector<Order_item> items;
  detail::parallel_resize(items, radii.size());
  for_order_chunks(radii.size(), [&](std::size_t, std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      if (!(radii[i] > 0)) throw Input_error("sphere radii must be > 0");
      std::memcpy(&items[i].radius_bits, &radii[i], sizeof(double));
      items[i].class_and_index = (std::uint64_t{priority_class[i]} << 56) | i;
    }
  });
  return items;
}

// (class, radius, index) is a strict total order. A stable least-significant-
// digit radix sort on (class, radius) of the indices in increasing order gives
// it: the bits of a positive double order like the double, so the radius is
// sorted in six 11-bit passes (passes whose digit is the same everywhere are
// skipped), then the class in one 8-bit pass. Each pass counts and moves the
// items in chunks on parallel_for's default threads, each chunk's items of a
// digit after those of the chunks before: the same stable order.
std::vector<Index> sorted_order(std::vector<Order_item> items) {
  const std::size_t n = items.size();
  const std::size_t n_chunks = std::max<std::size_t>(1, (n + kOrderChunk - 1) / kOrderChunk);
  std::vector<Order_item> next;
  detail::parallel_resize(next, n);
  std::vector<std::size_t> count(n_chunks << 11);  // chunk c, digit d: count[c * n_buckets + d]
  auto pass = [&](auto digit_of, std::size_t n_buckets) {
    for_order_chunks(n, [&](std::size_t c, std::size_t begin, std::size_t end) {
      std::size_t* chunk_count = &count[c * n_buckets];
      std::fill(chunk_count, chunk_count + n_buckets, 0);
      for (std::size_t i = begin; i < end; ++i) ++chunk_count[digit_of(items[i])];
    });
    std::size_t sum = 0;
    for (std::size_t d = 0; d < n_buckets; ++d) {
      std::size_t total = 0;
      for (std::size_t c = 0; c < n_chunks; ++c) total += count[c * n_buckets + d];
      if (total == n) return;  // one digit everywhere: the order stays
      for (std::size_t c = 0; c < n_chunks; ++c) {
        const std::size_t k = count[c * n_buckets + d];
        count[c * n_buckets + d] = sum;
        sum += k;
      }
    }
    for_order_chunks(n, [&](std::size_t c, std::size_t begin, std::size_t end) {
      std::size_t* chunk_count = &count[c * n_buckets];
      for (std::size_t i = begin; i < end; ++i) next[chunk_count[digit_of(items[i])]++] = items[i];
    });
    items.swap(next);
  };
  for (int shift = 0; shift < 64; shift += 11) {
    pass([shift](const Order_item& item) { return static_cast<std::size_t>((item.radius_bits >> shift) & 0x7ff); },
         std::size_t{1} << 11);
  }
  pass([](const Order_item& item) { return static_cast<std::size_t>(item.class_and_index >> 56); }, 256);
  next = std::vector<Order_item>();  // (before the order is made: 16 bytes a sphere)
  std::vector<Index> order;
  detail::parallel_resize(order, n);
  constexpr std::uint64_t kIndexMask = (std::uint64_t{1} << 56) - 1;
  for_order_chunks(n, [&](std::size_t, std::size_t begin, std::size_t end) {
    for (std::size_t k = begin; k < end; ++k) order[k] = static_cast<Index>(items[k].class_and_index & kIndexMask);
  });
  return order;
}

}  // namespace

std::vector<Index> packing_order(const std::vector<std::uint8_t>& priority_class,
                                 const std::vector<double>& radii) {
  return sorted_order(order_items(priority_class, radii));
}

std::vector<Index> packing_order(const std::vector<std::uint8_t>& priority_class, const std::vector<double>& radii,
                                 const std::vector<Index>& tie_order) {
  std::vector<Order_item> items = order_items(priority_class, radii);
  if (tie_order.empty()) return sorted_order(std::move(items));
  if (tie_order.size() != items.size()) throw std::invalid_argument("packing_order: one tie position per sphere");
  // The radix sort is stable: items laid out in tie order keep it among equal (class, radius).
  std::vector<Order_item> in_tie_order;
  detail::parallel_resize(in_tie_order, items.size());
  for_order_chunks(items.size(), [&](std::size_t, std::size_t begin, std::size_t end) {
    for (std::size_t r = begin; r < end; ++r) in_tie_order[r] = items[static_cast<std::size_t>(tie_order[r])];
  });
  items = std::vector<Order_item>();
  return sorted_order(std::move(in_tie_order));
}

std::vector<Index> packing_order(std::vector<std::uint8_t>&& priority_class, std::vector<double>&& radii) {
  std::vector<Order_item> items = order_items(priority_class, radii);
  priority_class = std::vector<std::uint8_t>();
  radii = std::vector<double>();
  return sorted_order(std::move(items));
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
                                         std::vector<Index> more_order, int threads) {
  std::size_t n_first = 0;
  for (Index c : first_order) n_first += kept[c] != 0;
  std::vector<Index> order;
  detail::parallel_resize(order, n_first + more_order.size());
  std::size_t k = 0;
  for (Index c : first_order) {
    if (kept[c]) order[k++] = c;
  }
  constexpr std::size_t kChunk = std::size_t{1} << 16;
  parallel_for((more_order.size() + kChunk - 1) / kChunk, threads, [&](std::size_t c) {
    for (std::size_t j = c * kChunk; j < std::min(more_order.size(), (c + 1) * kChunk); ++j) {
      order[n_first + j] = more_order[j];
    }
  });
  more_order = std::vector<Index>();
  return mis_in_order(centers, radii, std::move(order), n_first, nullptr, /*permutation=*/false, threads);
}

}  // namespace evomesh
