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

// Of the points marked in `points`, those within `rings` edges (triangle
// sides) of a point marked in `seeds`: delta_from_size's settled clusters.
// Ring by ring, every triangle with a corner reached so far reaches its other
// corners. O(rings m). Preconditions: indices in range, both masks one per point.
std::vector<std::uint8_t> near_seeds(const std::vector<Triangle>& triangles, const std::vector<std::uint8_t>& points,
                                     const std::vector<std::uint8_t>& seeds, int rings);

}  // namespace evomesh
