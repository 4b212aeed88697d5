// Functional-Refining-Functional-Coarsening (Section 3.2): one evolution step.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "evomesh/options.hpp"
#include "evomesh/parent_map.hpp"
#include "evomesh/refinement.hpp"
#include "evomesh/sampling.hpp"
#include "evomesh/triangulation.hpp"
#include "evomesh/types.hpp"

namespace evomesh {


struct Evolve_result {
  Mesh_arrays mesh;
  std::vector<Index> origin;   // index in the input mesh, -1 for a new point
  std::vector<double> input_f; // f at the input points
  std::vector<double> input_nn;
  Parent_map parents;          // where every new point lies in the input mesh
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

class Stage_timer;

}  // namespace detail

// Shared by FRFC and DRFC, after triangulate_selection: the parent map of the new
// mesh in `input` (timed as "parent_map") and the step's total time.
void finish_step(const Mesh_arrays& input, Evolve_result& result, detail::Stage_timer& timer);

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
