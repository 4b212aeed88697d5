// size= (python/evomesh/spacing_function.py, delta_from_size): how a mesh's
// edges compare with a requested edge length h. The per-point means run here;
// the decision from them (the hysteresis, the settled clusters) stays in Python.
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
