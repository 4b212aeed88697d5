// Lexical-first maximal independent set of a sphere system (Section 3.2, steps 4-5).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

// Two spheres conflict when their interiors overlap: |c1 - c2| < r1 + r2.
//
// Visits spheres in the order given by `order` (a permutation of 0..n-1) and keeps
// a sphere unless it conflicts with a sphere kept before it. The first `n_forced`
// spheres of the order are kept unconditionally (mesh corners). Uses a static
// kd-tree over all centres whose nodes carry the largest radius kept below them,
// so a query visits only nodes that can hold a conflicting kept sphere:
// O(n log n) for systems of bounded ply (Lemma 3.6).
// `blocker` (optional) receives, for every rejected sphere, a kept sphere it
// conflicts with (the first one the search meets), and -1 for kept spheres.
// Preconditions: radii finite and > 0, centres finite.
std::vector<std::uint8_t> lexical_first_mis(const std::vector<Vec2>& centers,
                                            const std::vector<double>& radii,
                                            const std::vector<Index>& order,
                                            std::size_t n_forced = 0,
                                            std::vector<Index>* blocker = nullptr);

// Packing order: by increasing priority class, then increasing radius, then index.
std::vector<Index> packing_order(const std::vector<std::uint8_t>& priority_class,
                                 const std::vector<double>& radii);

}  // namespace evomesh
