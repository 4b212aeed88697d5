// Spacing repair after FRFC's packing (Section 6).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "evomesh/candidates.hpp"
#include "evomesh/options.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// What the spacing repair reads: the mesh being evolved, with delta, nn_M and f
// at its points, and the packing's spheres (input points first).
struct Spacing_repair_input {
  const Mesh_arrays& mesh;
  const Triangle_fans& fans;  // of `mesh`
  const std::vector<double>& delta;
  const std::vector<double>& nn;
  const std::vector<double>& f;
  const std::vector<Vec2>& centers;          // of all spheres: input points [0, n), then the candidates
  const std::vector<Index>& segment_owner;   // per segment candidate (centre n + j): the point of its ring, or -1
  const std::vector<std::uint8_t>& demoted;  // per input point: packed with the new points (packing.hpp)
};

// Spacing repair. The packing guarantees nn_M'(p) = Theta(f(p)) only up to a
// constant; where an R-point p that was kept ends up with no kept point within
// repair_ratio * delta(p) nn_M(p) (its ring blocked by larger spheres kept
// earlier), keep the ring candidate of p farthest from every kept point: first
// its candidates on segments (centres with segment_owner p, whose `kept` flag
// is set), then its interior ones (regenerated, as the sample filter may have
// dropped them; returned). That candidate lies just outside p's sphere, so
// afterwards nn_M'(p) is about 1.2 f(p). Nearest kept points come from a static
// kd-tree over the kept centres plus a Delaunay triangulation of the points
// added here (of the options: repair_ratio when ring_samples, the ring's reach
// from radius_scale, seed, threads). Then the gap repair: an input
// point p whose second nearest output point (the paper's nn_M'(p)) lies beyond
// gap_repair_ratio * delta(p) nn_M(p) (refine_gap_ratio where delta(p) < 1 and
// p was demoted or dropped)
// gets the point farthest from every output point among eight at distance
// delta(p) nn_M(p) from it, inside the old mesh and seen from p (if at least 0.6
// of that distance from them). `n_added` receives the number of points added.
std::vector<Vec2> repair_spacing(const Spacing_repair_input& input, const Frfc_options& options,
                                 std::vector<std::uint8_t>& kept, std::size_t& n_added);

// The pieces of the spacing repair's first part (repair_spacing), for the
// distributed step (python/evomesh/distributed/repair.py), which decides the
// needy points in rounds over ranks and must decide each as serial does.

// The squared target of the re-check at an R-point: (repair_ratio delta nn)^2.
double repair_target2(double repair_ratio, double delta, double nn);

// The squared distances from each query to its nearest and second nearest
// points of `kept` (the serial repair's kept-centre queries, the same values:
// exact minima, whatever subset holds the nearest ones). Infinity where none.
void kept_distances(const std::vector<Vec2>& kept, const std::vector<Vec2>& queries, std::vector<double>& nearest2,
                    std::vector<double>& second2);

// The needy points' decisions, in the order given, as repair_spacing takes
// them: point i at at[i], with target2[i], nn2[i] (its second nearest kept
// centre, squared) and its candidates xadj[i]..xadj[i + 1] (segment ring
// candidates by centre index, then its interior ring candidates in direction
// order) with kept2 their squared nearest kept-centre distances; `added`: the
// points added before (by earlier needy points). Returns per point the index
// of its chosen candidate among its own, or -1 (none added). Each point's
// choice is added before the next is decided.
std::vector<Index> decide_repairs(const std::vector<Vec2>& at, const std::vector<double>& target2,
                                  const std::vector<double>& nn2, const std::vector<Index>& xadj,
                                  const std::vector<Vec2>& candidates, const std::vector<double>& kept2,
                                  const std::vector<Vec2>& added);

// The gap repair's pieces (repair_gaps), for the distributed step likewise.
constexpr int kGapDirections = 16;

// The gap repair's squared bound at an input point: (ratio delta nn)^2, ratio
// refine_ratio where delta < 1 and the point was demoted or not kept, else
// gap_ratio; infinity where that ratio is 0.
double gap_target2(double delta, double nn, bool demoted, bool kept, double gap_ratio, double refine_ratio);

// The kGapDirections points at distance h from `at` (seeded phase from the point's global id).
void gap_directions(const Vec2& at, double h, std::uint64_t seed, std::int64_t gid, Vec2* out);

// Open points of the gap repair (their kept centres alone leave a gap), in the
// order they are served, with what their decisions read besides the added
// points: per point, delta, nn, demoted, its gap_directions and whether each
// lies inside the old mesh seen from it (kGapDirections each), and the squared
// distances to the two nearest kept centres at the point and at each direction
// (kept2: 2 (kGapDirections + 1) each: the point's, then the directions').
struct Gap_requests {
  std::vector<Vec2> at;
  std::vector<double> delta, nn;
  std::vector<std::uint8_t> demoted;
  std::vector<Vec2> directions;
  std::vector<std::uint8_t> inside;
  std::vector<double> kept2;
  double gap_ratio = 0, refine_ratio = 0;
};

// The gap repair's decisions, in order, as repair_gaps takes them: per point
// the direction it adds, or -1; `added` holds the points added before (the
// spacing repair's and earlier gaps'), each choice seen by the later points.
std::vector<Index> decide_gaps(const Gap_requests& requests, const std::vector<Vec2>& added);

}  // namespace evomesh
