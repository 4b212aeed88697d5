// The parallel lexical-first MIS (packing.cpp, mis_in_blocks) against the
// sequential loop: the same kept flags and the same blockers for every thread
// count and block size, down to blocks of one sphere, with forced prefixes and
// extend_packing's partial orders. The fix-up paths of the pass over a block
// (a sphere rejected by one kept earlier in its block, a blocker kept earlier
// in the block that comes first in the search order, too many pending
// conflicts) are counted, and each must have run.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "check.hpp"
#include "evomesh/packing.hpp"
#include "sphere_systems.hpp"

using namespace evomesh;
using test::Layout;
using test::make_system;
using test::System;

namespace {

detail::Mis_block_counts g_total;

void add(const detail::Mis_block_counts& c) {
  g_total.met += c.met;
  g_total.blocked_in_block += c.blocked_in_block;
  g_total.blocker_in_block += c.blocker_in_block;
  g_total.reruns += c.reruns;
}

// Every thread count and block size against the sequential loop, on one order
// (`permutation`: it lists every sphere).
void compare(const System& s, const std::vector<Index>& order, std::size_t n_forced, bool permutation,
             const std::string& what) {
  std::vector<Index> blocker_ref;
  const auto kept_ref = detail::lexical_first_mis_in_blocks(s.centers, s.radii, order, n_forced, &blocker_ref, 1,
                                                            /*block=*/0, permutation);
  if (permutation) {
    std::vector<Index> blocker_public;
    CHECK(lexical_first_mis(s.centers, s.radii, order, n_forced, &blocker_public, 1) == kept_ref &&
          blocker_public == blocker_ref)
        << what << ": the hook's sequential loop differs from lexical_first_mis";
  }
  std::size_t n_kept = 0;
  for (auto k : kept_ref) n_kept += k;
  const std::size_t m = order.size();
  // (a parallel_for per block: blocks of 1 and 3 spheres on the small systems only)
  for (std::size_t block : {std::size_t{1}, std::size_t{3}, std::size_t{17}, std::size_t{64}, std::size_t{500},
                            m / 2 + 1, m + 5}) {
    if (block < 10 && m > 400) continue;
    for (int threads : {1, 2, 3, 8}) {
      std::vector<Index> blocker;
      detail::Mis_block_counts counts;
      const auto kept = detail::lexical_first_mis_in_blocks(s.centers, s.radii, order, n_forced, &blocker, threads,
                                                            block, permutation, &counts);
      add(counts);
      CHECK(kept == kept_ref) << what << ": kept flags differ, block " << block << ", threads " << threads;
      CHECK(blocker == blocker_ref) << what << ": blockers differ, block " << block << ", threads " << threads;
      // Without the blocker output the decisions are the same.
      const auto kept_only = detail::lexical_first_mis_in_blocks(s.centers, s.radii, order, n_forced, nullptr,
                                                                 threads, block, permutation);
      CHECK(kept_only == kept_ref) << what << ": kept flags differ without blockers, block " << block;
    }
  }
  std::printf("%-48s %7zu spheres, %zu forced: %zu kept\n", what.c_str(), m, n_forced, n_kept);
}

void check_system(std::size_t n, Layout layout, double scale, double decades, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const System s = make_system(n, layout, scale, decades, rng);
  const std::string name = std::string(layout == Layout::uniform ? "uniform" : layout == Layout::clustered ? "clustered"
                                                                                                             : "grid") +
                           " n=" + std::to_string(n) + " scale=" + std::to_string(scale);
  // The packing order (by class, radius, index), with and without a forced prefix.
  const std::vector<Index> order = packing_order(s.priority, s.radii);
  compare(s, order, 0, true, name + " packing order");
  compare(s, order, std::min<std::size_t>(n, n / 10 + 1), true, name + " packing order, forced");
  // A random order, and an order along x (consecutive spheres near each other:
  // many conflicts inside a block).
  std::vector<Index> shuffled(n);
  std::iota(shuffled.begin(), shuffled.end(), 0);
  std::shuffle(shuffled.begin(), shuffled.end(), rng);
  compare(s, shuffled, n / 7, true, name + " random order");
  std::vector<Index> along_x = shuffled;
  std::stable_sort(along_x.begin(), along_x.end(),
                   [&](Index a, Index b) { return s.centers[a][0] < s.centers[b][0]; });
  compare(s, along_x, 0, true, name + " order along x");

  // extend_packing's second pass: the first pass over a part of the spheres,
  // then its kept spheres forced and the rest; spheres the first pass rejected
  // take no part (a partial order).
  std::vector<Index> first, more;
  for (Index i : order) (i % 3 == 0 ? more : first).push_back(i);
  std::vector<std::uint8_t> mask(n, 0);
  for (Index i : first) mask[i] = 1;
  // The first pass on its own spheres: a sub-system.
  System sub;
  std::vector<Index> sub_of(n, -1), sub_order;
  for (Index i : first) {
    sub_of[i] = static_cast<Index>(sub.centers.size());
    sub.centers.push_back(s.centers[i]);
    sub.radii.push_back(s.radii[i]);
  }
  for (Index i : first) sub_order.push_back(sub_of[i]);
  const auto sub_kept = lexical_first_mis(sub.centers, sub.radii, sub_order, 0, nullptr, 1);
  std::vector<std::uint8_t> kept_first(n, 0);
  for (Index i : first) kept_first[i] = sub_kept[sub_of[i]];
  std::vector<Index> second;
  for (Index i : first) {
    if (kept_first[i]) second.push_back(i);
  }
  const std::size_t n_first = second.size();
  second.insert(second.end(), more.begin(), more.end());
  compare(s, second, n_first, false, name + " extend_packing's order");
  const auto extended = extend_packing(s.centers, s.radii, first, kept_first, more, 1);
  for (int threads : {2, 3}) {
    CHECK(extend_packing(s.centers, s.radii, first, kept_first, more, threads) == extended)
        << name << ": extend_packing differs with " << threads << " threads";
  }
  CHECK(detail::lexical_first_mis_in_blocks(s.centers, s.radii, second, n_first, nullptr, 2, 9, false) == extended)
      << name << ": extend_packing differs from its order through the parallel path";
}

// Large enough for the parallel path without the test hook (2 threads, default block size).
void check_public_path(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const System s = make_system(n, Layout::clustered, 1.0, 2.0, rng);
  const std::vector<Index> order = packing_order(s.priority, s.radii);
  // packing_order sorts in chunks of 2^16 on several threads: the order of (class, radius, index).
  CHECK(order == test::reference_order(s)) << "packing_order, n = " << n;
  std::vector<Index> blocker_1, blocker_2;
  const auto kept_1 = lexical_first_mis(s.centers, s.radii, order, 5, &blocker_1, 1);
  const auto kept_2 = lexical_first_mis(s.centers, s.radii, order, 5, &blocker_2, 2);
  CHECK(kept_1 == kept_2 && blocker_1 == blocker_2) << "lexical_first_mis, 1 and 2 threads, n = " << n;
  const auto kept_0 = lexical_first_mis(s.centers, s.radii, order, 5, nullptr);  // the default thread count
  CHECK(kept_0 == kept_1) << "lexical_first_mis, default threads, n = " << n;
  std::printf("public path: %zu spheres\n", n);
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    check_system(1, Layout::uniform, 1.0, 2.0, 1);
    check_system(2, Layout::uniform, 1.0, 2.0, 2);
    check_system(300, Layout::uniform, 1.0, 2.0, 3);
    check_system(400, Layout::clustered, 2.0, 2.0, 11);
    check_system(1500, Layout::clustered, 1.0, 2.0, 4);
    check_system(1500, Layout::uniform, 4.0, 3.0, 5);   // dense: many conflicts per sphere
    check_system(1200, Layout::uniform, 30.0, 1.0, 6);  // every sphere overlaps very many: reruns
    check_system(1600, Layout::grid, 1.0, 0.0, 7);      // equal radii on a lattice: ties everywhere
    check_system(4000, Layout::uniform, 0.5, 4.0, 8);   // sparse, radii over four decades
    check_public_path(70000, 9);
    check_public_path(300000, 10);
    std::printf("pass counts: %zu met, %zu blocked in block, %zu blockers in block, %zu reruns\n", g_total.met,
                g_total.blocked_in_block, g_total.blocker_in_block, g_total.reruns);
    CHECK(g_total.blocked_in_block > 0) << "no sphere was rejected by one kept earlier in its block";
    CHECK(g_total.blocker_in_block > 0) << "no blocker kept earlier in the block came before the frozen one";
    CHECK(g_total.reruns > 0) << "the sequential query never ran in the pass";
  });
}
