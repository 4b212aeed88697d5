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
Packing_class old_point_class(Point_kind kind, bool forced);

// The class of a new point (on a segment or inside); `round` >= 0 for a ring candidate.
Packing_class new_point_class(bool on_segment, int round = -1);

// The second pass of a packing whose first pass (over the spheres `first_order`
// of centers/radii, kept flags `kept`) is final: the kept spheres of the first
// pass, in their order and forced, then the spheres `more_centers`/`more_radii`
// in the order `more_order`. Appends their kept flags to `kept`. Equals the
// lexical-first MIS over both sets in the order first_order, more_order.
void extend_packing(const std::vector<Vec2>& centers, const std::vector<double>& radii,
                    const std::vector<Index>& first_order, const std::vector<Vec2>& more_centers,
                    const std::vector<double>& more_radii, const std::vector<Index>& more_order,
                    std::vector<std::uint8_t>& kept);

}  // namespace evomesh
