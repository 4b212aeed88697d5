// The packing's conflict test, written once.
#pragma once

namespace evomesh::detail {

// Spheres B(a, r_a) and B(b, r_b) conflict (their interiors overlap) when
// |a - b| < r_a + r_b, decided in doubles as ex^2 + ey^2 < sum^2 with (ex, ey) =
// a - b (either sign) and sum = r_a + r_b. Every caller (the packing's kd-tree,
// the MIS in rounds, the candidates' drop by their parents' blockers, the
// changed region's safe points) must decide a pair alike to the last bit, which
// one expression compiled without contraction (-ffp-contract=off,
// CMakeLists.txt) guarantees on every platform.
inline bool spheres_conflict(double ex, double ey, double sum) { return ex * ex + ey * ey < sum * sum; }

}  // namespace evomesh::detail
