// The packing's conflict test, written once.
#pragma once

#include <cstddef>

#include "evomesh/nd/kd_tree.hpp"

namespace evomesh::detail {

// Spheres B(a, r_a) and B(b, r_b) conflict (their interiors overlap) when
// |a - b| < r_a + r_b, decided in doubles as ex^2 + ey^2 < sum^2 with (ex, ey) =
// a - b (either sign) and sum = r_a + r_b. Every caller (the packing's kd-tree,
// the MIS in rounds, the candidates' drop by their parents' blockers, the
// changed region's safe points) must decide a pair alike to the last bit, which
// one expression compiled without contraction (-ffp-contract=off,
// CMakeLists.txt) guarantees on every platform.
inline bool spheres_conflict(double ex, double ey, double sum) { return ex * ex + ey * ey < sum * sum; }

// The same test in D dimensions, e = a - b: the squared length summed in axis
// order from 0 (nd::squared_distance), in 2-D the expression above to the bit.
template <std::size_t D>
inline bool spheres_conflict(const nd::Point<D>& a, const nd::Point<D>& b, double sum) {
  return nd::squared_distance<D>(a, b) < sum * sum;
}

}  // namespace evomesh::detail
