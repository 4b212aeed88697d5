// size= as delta (python/evomesh/spacing_function.py, delta_from_size, says
// what the rule does and why): how a mesh's edges compare with a requested
// edge length h, and the one function that turns h into delta and checks it,
// called by every scope (the whole mesh, a rank's part with its halo, the mesh
// cut by an interface).
#pragma once

#include <cstdint>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

// L(p) of delta_from_size, bit for bit as its numpy form computed it: each
// triangle edge's length over the request at its midpoint (h[0] when h is the
// same everywhere, else the mean of h at its ends); at p, the mean over the
// edges at p, counted once per triangle corner at p (an interior edge twice);
// then the mean of that over p and the points sharing a triangle with p
// (counted once per shared triangle). NaN at a point in no triangle. Sums in
// the order numpy's bincount and sum(axis=1) add: triangles in order, corners
// in order. O(n + m). Preconditions: indices in range, h.size() == points.size().
std::vector<double> edge_over_size_around(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                                          const std::vector<double>& h);

// The bits of edge_over_size_classes: L(p) > above, L(p) < below, L(p) >= at_least.
constexpr std::uint8_t Edge_over_size_above = 1;
constexpr std::uint8_t Edge_over_size_below = 2;
constexpr std::uint8_t Edge_over_size_at_least = 4;

// What delta_from_size asks of L, for each point: the bits above, each exactly
// as edge_over_size_around's L compares (0 where L is NaN). L is computed with
// sqrt(dx^2 + dy^2) for hypot (hypot is most of edge_over_size_around's time),
// within a bound on its relative error; where that bound leaves a comparison
// undecided, L is computed again with hypot over the triangles around the
// point, with edge_over_size_around's bits. O(n + m). Preconditions as
// edge_over_size_around's.
std::vector<std::uint8_t> edge_over_size_classes(const std::vector<Vec2>& points,
                                                 const std::vector<Triangle>& triangles, const std::vector<double>& h,
                                                 double above, double below, double at_least);

// The calibration of the size rule. Measured by benchmarks/stays_put.py on
// unit_square_mesh and on evomesh's own output: a refining step's edges are
// 1.25-1.4 times its new spacing delta nn_M for delta in [0.4, 0.9], a
// coarsening step's about 1.0 times (0.9-1.1). Refining aims at 1.35: with
// 1.3 the refined neighbourhood landed at L of about 1.08, one refined point
// in seven above 1.15, a fringe the next step refined again; 1.4 puts the
// median edge of a 0.7 times finer request on a jittered lattice at 0.89 of it.
//
// Where the request is met (delta = 1 exactly): around p, L(p) the mean
// length of its and its neighbours' edges over the request: above
// coarse_tolerance the mesh is refined where that asks for delta <
// refine_below (a step asked for less adds a point here and there, step after
// step); below 1 / fine_tolerance it is coarsened, except within
// clearance_rings edges of a point where L is at least 1 / meets: a cluster
// that the segments' Gabriel condition, small angles or required points make
// finer than the request is put back by the quality pass whenever a step
// coarsens it. The band is symmetric, [1 / 1.25, 1.25]: with 1.15 above, the
// points a refining step inserts between its refined points and the settled
// ones were refined again by the next step; at 1.25 they are not
// (benchmarks/stays_put.py, 1e4-5e4 points: 0.04-0.05 % changed at the second
// repeated step on a graded request, none at the third). refine_below 0.8,
// not 0.85: what is left above the band after a refining step is its fringe,
// asking for delta 0.6-0.82, a point here and there.
struct Size_rule {
  static constexpr double edge_over_nn_refined = 1.35;
  static constexpr double edge_over_nn_coarsened = 1.0;
  static constexpr double coarse_tolerance = 1.25;
  static constexpr double refine_below = 0.8;
  static constexpr double fine_tolerance = 1.25;
  static constexpr double meets = 1.1;
  static constexpr int clearance_rings = 3;
  // The rings of triangles around a point that its delta depends on: L reads
  // two, the clusters 2 clearance_rings + 2 more. A part of a mesh with this
  // many halo rings around its own points gives them the whole mesh's delta.
  static constexpr int rings = 2 + 2 * clearance_rings + 2;
};

// delta(p) for the request h (delta_from_size), bit for bit as its numpy form
// computed it: L(p) through edge_over_size_classes; too coarse (L > 1.25 and
// h / (1.35 nn) < 0.8): delta = h / (1.35 nn); too fine (L < 1 / 1.25, with the
// clusters' exceptions when keep_fine_clusters): max(1, h / nn); else 1.
// `nn`: nn_M at the points. On a part of a mesh (a rank's points and the
// halo), the points with Size_rule::rings halo rings around them get the
// whole mesh's delta if the points and triangles are in the whole mesh's
// order. Then check_size_delta on the points [0, n_checked) (ids: their names
// in its message; null: their indices). O(n + rings m). Preconditions as
// edge_over_size_around's, nn.size() == points.size().
std::vector<double> delta_from_size(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                                    const std::vector<double>& h, const std::vector<double>& nn,
                                    bool keep_fine_clusters, double delta_min, double delta_max,
                                    std::size_t n_checked, const std::vector<std::int64_t>* ids = nullptr);

// The check of a size request turned into delta, the same in every scope:
// Input_error naming the first of the points [0, n_checked) whose delta is
// outside [delta_min, delta_max] ("size h at point id is delta times its
// current spacing nn; one step changes the spacing by a factor in [min,
// max]"; id: ids[p], or p). Preconditions: the vectors of one length at least
// n_checked (ids too, if given).
void check_size_delta(const std::vector<double>& delta, const std::vector<double>& h, const std::vector<double>& nn,
                      double delta_min, double delta_max, std::size_t n_checked,
                      const std::vector<std::int64_t>* ids = nullptr);

// Of the points marked in `points`, those within `rings` edges (triangle
// sides) of a point marked in `seeds`: delta_from_size's settled clusters.
// Ring by ring, every triangle with a corner reached so far reaches its other
// corners; with `through`, only those marked in it (paths through marked
// points: delta_from_size's coarsening regions). O(rings m); it stops at the
// ring that has reached every marked point, or nothing new. Preconditions:
// indices in range, the masks one value per point.
std::vector<std::uint8_t> near_seeds(const std::vector<Triangle>& triangles, const std::vector<std::uint8_t>& points,
                                     const std::vector<std::uint8_t>& seeds, int rings,
                                     const std::vector<std::uint8_t>* through = nullptr);

// Of the points marked in `marked`, those that share a triangle with another
// marked point (uint8 mask): delta_from_size's too-fine points that are not
// alone. O(m). Preconditions: indices in range.
std::vector<std::uint8_t> sharing_a_triangle(const std::vector<Triangle>& triangles,
                                             const std::vector<std::uint8_t>& marked);

}  // namespace evomesh
