// Functional-Refining-Functional-Coarsening (Section 3.2): one evolution step.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "evomesh/refinement.hpp"
#include "evomesh/sampling.hpp"
#include "evomesh/triangulation.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

struct Frfc_options {
  double cell_factor = 1.0;          // c in the cell side c f(q) / (2 sqrt 2)
  bool exact_radius = true;          // f(x)/2 from the Apollonius graph; else (f(q)+|x-q|)/2
  // Spheres are B(x, radius_scale * f(x) / 2). 1 is the paper's choice; a smaller
  // scale packs tighter (radius_scale * f is still a valid, Lipschitz spacing).
  double radius_scale = 1.0;
  // Extra factor for spheres centred on segments (corners, boundary points and
  // segment samples): the boundary is a 1-D packing, which leaves larger gaps.
  double boundary_radius_scale = 1.0;
  // Offer candidates on a ring just outside every R-point's sphere (see frfc.cpp).
  bool ring_samples = true;
  // Spacing repair: a kept R-point p with no kept point within
  // repair_ratio * delta(p) nn_M(p) gets its best ring candidate. 0 disables.
  double repair_ratio = 1.75;
  Sample_mode sample_mode = Sample_mode::random_grid;
  bool skip_coarse_triangles = false;  // no samples where all three vertices have delta > 1
  // Interior samples that certainly overlap a kept sphere at a vertex of their
  // triangle are dropped before their radius is computed (frfc.cpp). The kept
  // spheres are the same either way; on is faster and smaller.
  bool filter_samples = true;
  std::uint64_t seed = 0;
  int threads = 0;                   // 0: hardware concurrency (capped at 2 chunks per core)
  double max_samples = 5e7;          // refuse inputs whose sampling would exceed this
  // The quality pass of Section 6 (refinement.hpp). Off here, so frfc() is the paper's
  // algorithm; Python's evolve turns it on by default.
  bool quality = false;
  Quality_options quality_options;
};

struct Evolve_result {
  Mesh_arrays mesh;
  std::vector<Index> origin;   // index in the input mesh, -1 for a new point
  std::vector<double> input_f; // f at the input points
  std::vector<double> input_nn;
  std::vector<std::pair<std::string, double>> stats;  // stage timings (s) and counts
};

// Runs FRFC on a validated mesh. delta: one positive finite factor per point.
Evolve_result frfc(const Mesh_arrays& mesh, const std::vector<double>& delta,
                   const Frfc_options& options);

// Maximal chains of segments between corners, in order, for building constraint pieces.
struct Segment_chain {
  std::vector<Index> vertices;  // v0 .. vk along the chain
  std::vector<Index> segments;  // segment index of (v_i, v_{i+1})
  std::vector<std::uint8_t> forward;  // segment k is traversed a -> b
  bool closed = false;
  bool boundary = true;
};
std::vector<Segment_chain> segment_chains(const Mesh_arrays& mesh);

// Shared by FRFC and DRFC: the last stage of a step. Triangulates the selected
// points (`selected.points`, `selected.kind`, their input `origin`) with the
// constraint pieces between them (constrained Delaunay, Section 3.2 step 6), or
// runs the quality pass on them when `quality` is given (on `early`, when given,
// whose first points must be the first selected points). Fills result.mesh and
// result.origin and adds the pass's counts and the smallest angle to result.stats.
void triangulate_selection(Mesh_arrays selected, std::vector<Index> origin,
                           const std::vector<Constraint_piece>& pieces, const Quality_options* quality,
                           Evolve_result& result, Early_triangulation* early = nullptr);

namespace detail {

// Appends ("seconds_" + stage, elapsed seconds since the previous lap) to stats.
class Stage_timer {
 public:
  explicit Stage_timer(std::vector<std::pair<std::string, double>>& stats) : stats_(stats) {}
  // Adds the time since the last lap to the stage `name` (a stage may be timed in several laps).
  void lap(const std::string& name) {
    const auto now = std::chrono::steady_clock::now();
    const double seconds = std::chrono::duration<double>(now - last_).count();
    last_ = now;
    for (auto& entry : stats_) {
      if (entry.first == "seconds_" + name) {
        entry.second += seconds;
        return;
      }
    }
    stats_.emplace_back("seconds_" + name, seconds);
  }

 private:
  std::vector<std::pair<std::string, double>>& stats_;
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

}  // namespace detail

}  // namespace evomesh
