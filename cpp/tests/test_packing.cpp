// lexical_first_mis and packing_order against O(n^2) / std::sort references.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <random>
#include <tuple>
#include <vector>

#include "check.hpp"
#include "evomesh/detail/sphere_conflict.hpp"
#include "evomesh/packing.hpp"
#include "sphere_systems.hpp"

using namespace evomesh;
using test::System;

namespace {

// The conflict test of packing.hpp: interiors overlap.
bool conflict(const Vec2& a, double ra, const Vec2& b, double rb) {
  return evomesh::detail::spheres_conflict(a[0] - b[0], a[1] - b[1], ra + rb);
}

// The reference: visit in order, keep unless a kept sphere conflicts.
std::vector<std::uint8_t> brute_mis(const System& s, const std::vector<Index>& order, std::size_t n_forced) {
  std::vector<std::uint8_t> kept(s.centers.size(), 0);
  std::vector<Index> kept_list;
  for (std::size_t k = 0; k < order.size(); ++k) {
    const Index i = order[k];
    bool free = true;
    if (k >= n_forced) {
      for (Index j : kept_list) {
        if (conflict(s.centers[i], s.radii[i], s.centers[j], s.radii[j])) {
          free = false;
          break;
        }
      }
    }
    if (free) {
      kept[i] = 1;
      kept_list.push_back(i);
    }
  }
  return kept;
}

void check_case(std::size_t n, bool clustered, std::size_t n_forced, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const System s = test::make_system(n, clustered ? test::Layout::clustered : test::Layout::uniform, 1.0, 2.0, rng, 5);

  // packing_order: (class, radius, index) ascending.
  const std::vector<Index> order = packing_order(s.priority, s.radii);
  CHECK(order == test::reference_order(s)) << "packing_order, n = " << n;

  std::vector<Index> blocker;
  const std::vector<std::uint8_t> kept = lexical_first_mis(s.centers, s.radii, order, n_forced, &blocker);
  CHECK(kept == brute_mis(s, order, n_forced)) << "lexical_first_mis differs from the reference, n = " << n;

  std::vector<std::size_t> position(n);
  for (std::size_t k = 0; k < n; ++k) position[order[k]] = k;
  std::size_t overlaps = 0, unblocked = 0, bad_blocker = 0, n_kept = 0;
  for (std::size_t i = 0; i < n; ++i) {
    n_kept += kept[i];
    if (kept[i]) {
      // Independence: forced spheres are kept whatever they overlap; no other pair overlaps.
      for (std::size_t j = i + 1; j < n; ++j) {
        const bool both_forced = position[i] < n_forced && position[j] < n_forced;
        if (kept[j] && !both_forced && conflict(s.centers[i], s.radii[i], s.centers[j], s.radii[j])) ++overlaps;
      }
      if (blocker[i] != -1) ++bad_blocker;
      continue;
    }
    // Lexical-first maximality: a kept sphere earlier in the order overlaps it.
    bool blocked = false;
    for (std::size_t j = 0; j < n && !blocked; ++j) {
      blocked = kept[j] && position[j] < position[i] && conflict(s.centers[i], s.radii[i], s.centers[j], s.radii[j]);
    }
    if (!blocked) ++unblocked;
    const Index b = blocker[i];
    if (b < 0 || b >= static_cast<Index>(n) || !kept[b] || position[b] > position[i] ||
        !conflict(s.centers[i], s.radii[i], s.centers[b], s.radii[b])) {
      ++bad_blocker;
    }
  }
  CHECK(overlaps == 0) << overlaps << " overlapping kept pairs, n = " << n;
  CHECK(unblocked == 0) << unblocked << " rejected spheres without an earlier kept conflict, n = " << n;
  CHECK(bad_blocker == 0) << bad_blocker << " wrong blocker entries, n = " << n;
  CHECK(n_kept > 0 && (n < 10 || n_kept < n)) << "degenerate case, n = " << n << ", kept " << n_kept;

  // The order alone decides: a random permutation, no blocker output.
  std::vector<Index> shuffled(n);
  std::iota(shuffled.begin(), shuffled.end(), 0);
  std::shuffle(shuffled.begin(), shuffled.end(), rng);
  CHECK(lexical_first_mis(s.centers, s.radii, shuffled) == brute_mis(s, shuffled, 0))
      << "random order, n = " << n;
  std::printf("%6zu spheres (%s, %zu forced): %zu kept\n", n, clustered ? "clustered" : "uniform", n_forced, n_kept);
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    check_case(1, false, 0, 1);
    check_case(2, false, 1, 2);
    check_case(50, false, 0, 3);
    check_case(1000, true, 0, 4);
    check_case(3000, false, 40, 5);
    check_case(6000, true, 100, 6);
    check_case(20000, false, 0, 7);

    bool threw = false;
    try {
      lexical_first_mis({{0.0, 0.0}, {1.0, 0.0}}, {1.0, 1.0}, {0, 0});
    } catch (const Input_error&) {
      threw = true;
    }
    CHECK(threw) << "an order that is not a permutation";
    threw = false;
    try {
      packing_order({0}, {0.0});
    } catch (const Input_error&) {
      threw = true;
    }
    CHECK(threw) << "a zero radius";
  });
}
