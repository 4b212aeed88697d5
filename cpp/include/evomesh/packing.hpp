// Lexical-first maximal independent set of a sphere system (Section 3.2, steps 4-5).
#pragma once

#include <array>
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
// The queries run on up to `threads` threads (0: parallel_for's default,
// parallel.hpp); the result (kept flags and blockers) is the same for any count.
std::vector<std::uint8_t> lexical_first_mis(const std::vector<Vec2>& centers,
                                            const std::vector<double>& radii,
                                            const std::vector<Index>& order,
                                            std::size_t n_forced = 0,
                                            std::vector<Index>* blocker = nullptr,
                                            int threads = 0);

namespace detail {
// How often the parallel path's pass over a block took each way (packing.cpp, mis_in_blocks).
struct Mis_block_counts {
  std::size_t met = 0;               // pending conflicts listed by the frozen queries
  std::size_t blocked_in_block = 0;  // frozen query free, rejected by a sphere kept earlier in the block
  std::size_t blocker_in_block = 0;  // frozen query blocked, the blocker kept earlier in the block
  std::size_t reruns = 0;            // too many pending conflicts: the sequential query
};
// For tests: lexical_first_mis (permutation: `order` lists every sphere) or
// extend_packing's pass (otherwise: distinct spheres, the first n_forced of
// them forced) through the parallel path with blocks of `block` spheres,
// whatever the size and the thread count; block = 0: the sequential loop.
std::vector<std::uint8_t> lexical_first_mis_in_blocks(const std::vector<Vec2>& centers,
                                                      const std::vector<double>& radii,
                                                      const std::vector<Index>& order, std::size_t n_forced,
                                                      std::vector<Index>* blocker, int threads, std::size_t block,
                                                      bool permutation = true, Mis_block_counts* counts = nullptr);
}  // namespace detail

// Packing order: by increasing priority class, then increasing radius, then index
// (a radix sort on parallel_for's default threads).
std::vector<Index> packing_order(const std::vector<std::uint8_t>& priority_class,
                                 const std::vector<double>& radii);
// The same with ties in (class, radius) broken by the position in `tie_order`
// (a permutation of the spheres; empty: by index), e.g. the spheres by global id.
std::vector<Index> packing_order(const std::vector<std::uint8_t>& priority_class, const std::vector<double>& radii,
                                 const std::vector<Index>& tie_order);
// The same, freeing the classes and radii once read (the peak of a large sort).
std::vector<Index> packing_order(std::vector<std::uint8_t>&& priority_class, std::vector<double>&& radii);

// Priority classes of the packing (Section 6's order), shared by FRFC and DRFC:
// corners, boundary points (existing, then ring candidates by round, then other
// new points on segments), original, Steiner (sampled in an earlier step), then
// the new interior points: ring candidates by round, then the others. DRFC has
// no ring candidates; the order of the classes it uses is the same.
enum Packing_class : std::uint8_t {
  class_corner = 0,
  class_boundary = 1,
  class_boundary_ring = 2,  // + round (0, 1)
  class_boundary_new = 4,
  class_original = 5,
  class_steiner = 6,
  class_ring = 7,  // + round (0 .. 5)
  class_new = 7 + 6,
};

// The class of a point of the mesh being coarsened (`forced`: a forced corner).
// A `demoted` point has lost its priority (demoted_points): it is packed with
// the new points of its kind, by size (class_boundary_new on segments, else class_new).
Packing_class old_point_class(Point_kind kind, bool forced, bool demoted = false);

// Old points whose neighbourhood does not conform to the request:
// p is demoted when nn_M(q) > demote_ratio * f(q) at p and at every point q
// that shares a triangle with p, that is where the request refines the whole
// neighbourhood by more than demote_ratio (delta < 1/demote_ratio at R-points;
// a single point with a far nearest neighbour in a conforming mesh keeps its
// place). Keeping such a point first would fix the packing around it to the
// old lattice (in a lattice of spacing nn with delta = 0.8 every candidate
// lies too close to a kept old point); packed by size with the new points, it
// is kept only where it fits a fresh packing. Forced points are never demoted;
// demote_ratio = 0 demotes none (the paper: old points always first).
std::vector<std::uint8_t> demoted_points(const std::vector<Triangle>& triangles, const std::vector<double>& nn,
                                         const std::vector<double>& f, const std::vector<std::uint8_t>& forced,
                                         double demote_ratio);

// The class of a new point (on a segment or inside); `round` >= 0 for a ring candidate.
Packing_class new_point_class(bool on_segment, int round = -1);

// The second pass of a packing whose first pass (over the spheres `first_order`
// of centers/radii, kept flags `kept`) is final: the kept spheres of the first
// pass, in their order and forced, then the spheres more_order (distinct, none
// of them kept; centers/radii hold the spheres of both passes, the first
// pass's rejected spheres take no part). Returns the kept flags of all
// spheres: the lexical-first MIS over both sets in the order first_order, more_order.
// `threads` as for lexical_first_mis.
std::vector<std::uint8_t> extend_packing(const std::vector<Vec2>& centers, const std::vector<double>& radii,
                                         const std::vector<Index>& first_order, const std::vector<std::uint8_t>& kept,
                                         std::vector<Index> more_order, int threads = 0);

// The same MIS in 3-D (the tetrahedral step; the kd-tree of kept spheres is
// one template in D): lexical_first_mis_3 over the spheres listed in `order`
// (distinct; one not listed is neither kept nor met), the first n_forced kept
// unconditionally; extend_packing_3 as extend_packing.
std::vector<std::uint8_t> lexical_first_mis_3(const std::vector<std::array<double, 3>>& centers,
                                              const std::vector<double>& radii, const std::vector<Index>& order,
                                              std::size_t n_forced = 0, int threads = 0);
std::vector<std::uint8_t> extend_packing_3(const std::vector<std::array<double, 3>>& centers,
                                           const std::vector<double>& radii, const std::vector<Index>& first_order,
                                           const std::vector<std::uint8_t>& kept, std::vector<Index> more_order,
                                           int threads = 0);

}  // namespace evomesh
