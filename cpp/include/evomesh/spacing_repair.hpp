// Spacing repair after FRFC's packing (Section 6).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "evomesh/candidates.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// Spacing repair. The packing guarantees nn_M'(p) = Theta(f(p)) only up to a
// constant; where an R-point p that was kept ends up with no kept point within
// repair_ratio * delta(p) nn_M(p) (its ring blocked by larger spheres kept
// earlier), keep the ring candidate of p farthest from every kept point: first
// its candidates on segments (centres with segment_owner p, whose `kept` flag
// is set), then its interior ones (regenerated, as the sample filter may have
// dropped them; returned). That candidate lies just outside p's sphere, so
// afterwards nn_M'(p) is about 1.2 f(p). Nearest kept points come from a static
// kd-tree over the kept centres plus a Delaunay triangulation of the points
// added here. Then (gap_repair_ratio > 0, issue 11) a kept point p with
// delta(p) >= 1 and no kept point within gap_repair_ratio * delta(p) nn_M(p)
// gets the point farthest from every kept point among six at distance
// delta(p) nn_M(p) from it inside the old mesh (if at least 0.6 of that
// distance from them). `n_added` receives the number of points added.
std::vector<Vec2> repair_spacing(const Mesh_arrays& mesh, const Triangle_fans& fans, const std::vector<double>& delta,
                                 const std::vector<double>& nn, const std::vector<double>& f, double reach,
                                 std::uint64_t seed, const std::vector<Vec2>& centers,
                                 const std::vector<Index>& segment_owner, double repair_ratio,
                                 double gap_repair_ratio, int threads, std::vector<std::uint8_t>& kept,
                                 std::size_t& n_added);

}  // namespace evomesh
