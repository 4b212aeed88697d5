// FRFC's candidate centres (Section 3.2, step 2): the grid samples of
// sampling.hpp plus the ring candidates around R-points, their sphere radii,
// and the filter that drops interior candidates the packing would reject anyway.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "evomesh/options.hpp"
#include "evomesh/sampling.hpp"
#include "evomesh/segment_chains.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/triangle_fans.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// Candidate centres of one kind (on segments, or inside triangles), with what
// the packing needs of each.
struct Candidates {
  Sample_set samples;              // centres and their parent segment or triangle
  std::vector<std::int8_t> round;  // ring round (packing class), -1: not a ring candidate
  std::vector<Index> owner;        // on segments: the R-point of a ring candidate, else -1
  std::vector<double> radius;      // sphere radius, once candidate_radii ran
  std::size_t size() const { return samples.points.size(); }
  // Packing classes (new_point_class).
  std::vector<std::uint8_t> classes(bool on_segment) const;
};

// Ring candidates. Around every R-point p (delta < 1) f is a cone of slope 1
// with its tip f(p) = delta nn_M(p) (Lemma 3.1). A sphere B(y, k f(y)/2) with
// f(y) = f(p) + |y - p| misses B(p, k f(p)/2) once |y - p| >= k f(p) / (1 - k/2).
// Candidates just beyond that distance (ring_reach(k) f(p)) are the smallest
// spheres that can be p's neighbours; offering them keeps nn_M'(p) close to f(p)
// instead of leaving the ring around p to spheres centred further away (the grid
// samples land there only up to a cell size).
//
// Ring candidates are packed in rounds: first one candidate per R-point (in
// radius order), then a second one, and so on, so that the rings of neighbouring
// R-points cannot take every place around p before p's own ring is offered.
constexpr int kRingDirections = 6;
double ring_reach(double radius_scale);

struct Ring_candidate {
  Vec2 x;
  Index triangle;
  int round;
};

// The interior ring candidates of the R-point p, in round order: the
// kRingDirections points at distance reach f(p) (random phase from the seed)
// that lie strictly inside a triangle around p. Returns their number.
int ring_candidates_of(const Mesh_arrays& mesh, const Triangle_fans& fans, const std::vector<double>& f, double reach,
                       std::uint64_t seed, std::size_t p, std::array<Ring_candidate, kRingDirections>& out);

// Settled points: delta(p) = 1 and f(p) = the length of p's
// shortest mesh edge. Always f(p) <= w_p = delta(p) nn_M(p) <= nn_M(p) <= that
// length (Lemma 3.1, Eq. 3), so equality says that the request at p is the
// spacing the mesh already has there: not lowered by the local feature size or
// by another point's cone, and met by an edge of p. (Lengths are compared up to
// a few units of rounding: nn_M and the edge may be computed by sqrt or hypot.)
std::vector<std::uint8_t> settled_points(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                         const std::vector<double>& f);

// Triangles that draw no grid samples whatever the packing does: with
// options.skip_coarse those whose three vertices coarsen (delta > 1), with
// options.skip_settled those whose three vertices are settled (`settled`:
// settled_points, or a rank's flags); empty when neither option is on.
std::vector<std::uint8_t> unsampled_triangles(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                              const std::vector<std::uint8_t>& settled, const Frfc_options& options);

// Candidates on segments: grid samples, then (options.ring_samples) one ring
// candidate each way from every R-point, merged in so that each segment's list
// stays sorted along it, then snapped to straight chains. Radii not yet set.
// With options.skip_settled, no grid samples on a segment whose two ends are
// settled (settled_points).
// `queries` (optional): f for the grids of segments far longer than f at their
// ends (sample_segments).
// `settled` (optional, one flag per point): the settled flags to use instead of
// settled_points on `mesh` (a rank's part of a distributed step, whose segment
// end points come without their triangles: their owners decide).
Candidates segment_candidates(const Mesh_arrays& mesh, const std::vector<double>& delta, const std::vector<double>& f,
                              const std::vector<Segment_chain>& chains, const Frfc_options& options,
                              const Spacing_queries* queries = nullptr,
                              const std::vector<std::uint8_t>* settled = nullptr);

// Candidates inside triangles: grid samples and (options.ring_samples) the ring
// candidates of every R-point, except those in a cover disc of their triangle
// (cover empty: none dropped). With options.skip_settled, none in a triangle
// whose three vertices are settled (settled_points). `n_drawn` receives the
// number of grid samples drawn.
// `quiet` (optional, one flag per triangle): triangles whose grid samples all lie
// in a cover disc (incremental_step.cpp); they are not sampled, the result is the same.
// `queries` (optional): f for the adaptive grids of strongly graded triangles
// (sample_triangle_blocks).
// For a rank's part of a distributed step (distributed/step.py), whose halo
// points come without their whole fans: `settled` (optional, one flag per
// point) replaces settled_points on `mesh`; `ring_from` (optional, one flag per
// point) limits the ring candidates to the R-points flagged (the part's owned
// points); `ring_point` (optional) receives the R-point of every ring candidate
// (one entry per ring candidate, in their order after the grid samples).
Candidates interior_candidates(const Mesh_arrays& mesh, const Triangle_fans& fans, const std::vector<double>& delta,
                               const std::vector<double>& f, const std::vector<std::uint8_t>& demoted,
                               const Cover_discs& cover,
                               const Frfc_options& options, std::size_t& n_drawn,
                               const std::vector<std::uint8_t>* quiet = nullptr,
                               const Spacing_queries* queries = nullptr,
                               const std::vector<std::uint8_t>* settled = nullptr,
                               const std::vector<std::uint8_t>* ring_from = nullptr,
                               std::vector<Index>* ring_point = nullptr);

// Sphere radii of the input points: radius_scale f(p) / 2 (times boundary_scale on segments).
std::vector<double> input_point_radii(const Mesh_arrays& mesh, const std::vector<double>& f,
                                      const Frfc_options& options);

// Sphere radii of candidates: radius_scale f(x) / 2 (times boundary_scale on
// segments), f(x) exact from the Apollonius graph or (f(q) + |x - q|) with q the
// vertex of smallest f (Section 3.2, step 2).
void candidate_radii(const Mesh_arrays& mesh, const Spacing_function& spacing, const std::vector<double>& f,
                     const std::vector<std::uint8_t>& demoted, const Frfc_options& options, bool on_segment,
                     Candidates& candidates);

// candidate_radii from f at the candidates, which candidates.radius holds on
// entry (size() values; unread when options.radius is cheap): where the step
// evaluates f at them another way than one graph (Step_scope::f_at_candidates).
void candidate_radii_from_f(const Mesh_arrays& mesh, const std::vector<double>& f,
                            const std::vector<std::uint8_t>& demoted, const Frfc_options& options, bool on_segment,
                            Candidates& candidates);

// The sample filter, part 1: one cover disc per input point (see candidates.cpp).
// kept/blocker: the first packing pass over the input points (indices < n) and
// segment candidates; radius: the radii of its spheres.
Cover_discs cover_discs(const Mesh_arrays& mesh, const std::vector<double>& f,
                              const std::vector<double>& radius, const std::vector<std::uint8_t>& kept,
                              const std::vector<Index>& blocker, double radius_scale, bool interpolated);

// The sample filter, part 2: drops the interior candidates whose sphere overlaps
// the kept sphere of a vertex of their triangle (or of the kept sphere that
// rejected that vertex) in the first pass over centers/radius.
void drop_blocked_candidates(const Mesh_arrays& mesh, const std::vector<Vec2>& centers,
                             const std::vector<double>& radius, const std::vector<std::uint8_t>& kept,
                             const std::vector<Index>& blocker, int threads, Candidates& inside);

}  // namespace evomesh
