#include "evomesh/packing.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <utility>

#include "evomesh/detail/bits.hpp"
#include "evomesh/detail/kept_sphere_tree.hpp"
#include "evomesh/parallel.hpp"

namespace evomesh {

using detail::Kept_sphere_tree;

namespace {

constexpr std::size_t kNone = Kept_sphere_tree<2>::kNone;

// The visiting loop: each sphere is kept unless a kept one conflicts (the
// first `n_forced` always).
template <std::size_t D>
void mis_sequential(Kept_sphere_tree<D>& tree, std::size_t n_forced, std::vector<std::uint8_t>& kept,
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
template <std::size_t D>
void mis_in_blocks(Kept_sphere_tree<D>& tree, std::size_t n_forced, std::vector<std::uint8_t>& kept,
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
      typename Kept_sphere_tree<D>::Met found;
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
template <std::size_t D>
std::vector<std::uint8_t> mis_in_order(const std::vector<nd::Point<D>>& centers, const std::vector<double>& radii,
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
    for (double x : centers[i])
      if (!std::isfinite(x)) throw Input_error("sphere centres must be finite");
    if (!std::isfinite(radii[i]) || !(radii[i] > 0)) throw Input_error("sphere radii must be finite and > 0");
  }
  std::fill(kept.begin(), kept.end(), 0);
  const std::size_t m = order.size();
  Kept_sphere_tree<D> tree(centers, radii, std::move(order), threads);
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

namespace {

template <std::size_t D>
std::vector<std::uint8_t> extend_packing_in(const std::vector<nd::Point<D>>& centers, const std::vector<double>& radii,
                                            const std::vector<Index>& first_order,
                                            const std::vector<std::uint8_t>& kept, std::vector<Index> more_order,
                                            int threads) {
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

}  // namespace

std::vector<std::uint8_t> extend_packing(const std::vector<Vec2>& centers, const std::vector<double>& radii,
                                         const std::vector<Index>& first_order, const std::vector<std::uint8_t>& kept,
                                         std::vector<Index> more_order, int threads) {
  return extend_packing_in(centers, radii, first_order, kept, std::move(more_order), threads);
}

std::vector<std::uint8_t> lexical_first_mis_3(const std::vector<std::array<double, 3>>& centers,
                                              const std::vector<double>& radii, const std::vector<Index>& order,
                                              std::size_t n_forced, int threads) {
  return mis_in_order(centers, radii, order, n_forced, nullptr, /*permutation=*/false, threads);
}

std::vector<std::uint8_t> extend_packing_3(const std::vector<std::array<double, 3>>& centers,
                                           const std::vector<double>& radii, const std::vector<Index>& first_order,
                                           const std::vector<std::uint8_t>& kept, std::vector<Index> more_order,
                                           int threads) {
  return extend_packing_in(centers, radii, first_order, kept, std::move(more_order), threads);
}

}  // namespace evomesh
