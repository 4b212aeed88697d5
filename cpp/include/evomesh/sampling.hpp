// Sample points S2 of FRFC (Section 3.2, step 2) and the practical variations of Section 5.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <vector>

#include "evomesh/options.hpp"
#include "evomesh/types.hpp"

namespace evomesh {


// The sample filter's discs, one per input point v (candidates.cpp,
// cover_discs): centre (*points)[centre[v]], radius reach[v] (0: no disc).
// Empty (no reach): no filter. (12 bytes a point; the centres are input points)
struct Cover_discs {
  const std::vector<Vec2>* points = nullptr;
  std::vector<std::uint32_t> centre;
  std::vector<double> reach;
  bool empty() const { return reach.empty(); }
};

struct Sample_set {
  std::vector<Vec2> points;
  // triangle index (interior samples) or segment index (segment samples); 4
  // bytes (the samplers refuse a mesh of 2^32 triangles or segments)
  std::vector<std::uint32_t> parent;
};

// f at a batch of points (exactly, e.g. Spacing_function::evaluate): lets the
// adaptive grid of a strongly graded triangle size its blocks by f itself, not
// only by the bound from the triangle's vertices. Called from the sampling
// threads: it must be safe to call concurrently.
using Spacing_queries = std::function<void(const std::vector<Vec2>& at, std::vector<double>& f)>;

// Whether the adaptive grid of triangle t asks `Spacing_queries` (its fine grid
// has more than kQueryCells cells: a triangle far larger than f at its smallest
// vertex, where the vertices' bound alone leaves fine cells over all of it).
constexpr double kQueryCells = 4096;
bool asks_spacing(const Mesh_arrays& mesh, const std::vector<double>& vertex_f, const Triangle& t, double cell_factor);
// The same for the 1-D grid of a segment (sample_segments).
bool asks_spacing(const Mesh_arrays& mesh, const std::vector<double>& vertex_f, const Edge& e, double cell_factor);

// Interior samples. Cell side = cell_factor * f(q) / (2 sqrt 2), q the vertex of the
// triangle with the smallest f, or larger where f's Lipschitz bound from the
// vertices allows (sampling.cpp: adaptive cells; `adaptive` false: the paper's
// uniform cells). Every interior sample is strictly inside its triangle
// (checked with exact orientation predicates). Triangles with skip[t] != 0 get none.
// Edges that are segments are never sampled here (see sample_segments).
// A sample strictly inside the cover disc of a vertex v of its triangle is
// drawn but not returned (cover empty: all are returned); `n_drawn` receives
// the number drawn.
// Triangles are sampled in parallel in fixed blocks, one set each, in order
// (join_samples makes them one set): the result never depends on `threads`
// (0: hardware concurrency). A caller may add blocks of its own before the one
// join. `queries` (optional): f for the adaptive grid of the triangles
// asks_spacing() names.
std::vector<Sample_set> sample_triangle_blocks(const Mesh_arrays& mesh, const std::vector<double>& vertex_f,
                                               double cell_factor, Sample_mode mode, std::uint64_t seed,
                                               const std::vector<std::uint8_t>& skip, const Cover_discs& cover,
                                               int threads, std::size_t* n_drawn, bool adaptive,
                                               const Spacing_queries* queries);

// The blocks joined in order into one set of exact size; `blocks` is emptied.
// Groups of blocks (32 MiB or more) are copied in parallel, then freed, and
// what they held goes back to the system (detail::release_free_memory), so the
// join holds little more than its output. (Appending blocks to a growing set
// held the old and the new copy of it at once: that was the refining front's
// peak at 1e6.)
Sample_set join_samples(std::vector<Sample_set>& blocks);

// Samples on the segments, strictly between their endpoints, sorted along each
// segment from a to b: one random point per 1-D cell of side cell_factor * min f / (2 sqrt 2),
// or, in every deterministic mode (barycentre and/or midpoints), the midpoint.
Sample_set sample_segments(const Mesh_arrays& mesh, const std::vector<double>& vertex_f,
                           double cell_factor, Sample_mode mode, std::uint64_t seed, bool adaptive = true,
                           const Spacing_queries* queries = nullptr);

// Whether x lies strictly inside the cover disc of a vertex of t (cover empty: no).
bool in_cover(const Cover_discs& cover, const Triangle& t, const Vec2& x);

// Upper bound on the number of samples sample_triangle_blocks/sample_segments would
// produce, so callers can refuse inputs that would exhaust memory: O(n) plus the
// cells of the triangles whose grid adapts, and it stops as soon as the count
// passes `limit` (infinite when a triangle would need more than 2^50 cells a side).
// With the same `queries` as sample_triangle_blocks, the same cells.
double estimate_sample_count(const Mesh_arrays& mesh, const std::vector<double>& vertex_f, double cell_factor,
                             double limit = std::numeric_limits<double>::infinity(), bool adaptive = true,
                             const Spacing_queries* queries = nullptr);

// Counter-based random numbers: the same (seed, stream) always gives the same sequence.
struct Random_stream {
  std::uint64_t state;
  Random_stream(std::uint64_t seed, std::uint64_t stream);
  std::uint64_t next();
  double uniform();  // in [0, 1)
};

}  // namespace evomesh
