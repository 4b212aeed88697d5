// What FRFC and DRFC share: the result of a step, its input check, the
// selection of output points, their triangulation (or quality pass), the parent
// map and the stage timings.
#pragma once

#include <algorithm>
#include <chrono>
#include <initializer_list>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "evomesh/boundary_geometry.hpp"
#include "evomesh/options.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/parent_map.hpp"
#include "evomesh/quality_pass.hpp"
#include "evomesh/segment_chains.hpp"
#include "evomesh/sampling.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/triangulation.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

namespace detail {

// Appends ("seconds_" + stage, elapsed seconds since the previous lap) to stats.
class Stage_timer {
 public:
  // `profile` (Step_context::profile): also the memory and CPU figures below.
  explicit Stage_timer(std::vector<std::pair<std::string, double>>& stats, bool profile = false)
      : memory_(profile), stats_(stats) {}
  // Adds the time since the last lap to the stage `name` (a stage may be timed in several laps).
  void lap(const std::string& name) {
    const auto now = std::chrono::steady_clock::now();
    const double seconds = std::chrono::duration<double>(now - last_).count();
    last_ = now;
    add("seconds_" + name, seconds, false);
    if (memory_) record_memory(name);
  }

 private:
  void add(const std::string& key, double value, bool max) {
    for (auto& entry : stats_) {
      if (entry.first == key) {
        entry.second = max ? std::max(entry.second, value) : entry.second + value;
        return;
      }
    }
    stats_.emplace_back(key, value);
  }
  // With `profile` (diagnostics, Linux): "memory_peak_mib_" + stage,
  // the process's peak RSS during the stage (VmHWM, reset after every lap),
  // "memory_heap_mib_" + stage, the malloc heap in use at its end (largest over
  // its laps), "cpu_seconds_" + stage, the process's CPU time (all threads),
  // "page_faults_" + stage and "system_seconds_" + stage, its page faults and
  // the CPU time the kernel spent for it (first touches of fresh memory cost
  // about 1.5 µs a page on a virtual machine).
  void record_memory(const std::string& name);
  static double process_cpu_seconds();
  struct Kernel_usage {
    double page_faults = 0;
    double system_seconds = 0;
  };
  static Kernel_usage kernel_usage();
  bool memory_;
  double last_cpu_ = memory_ ? process_cpu_seconds() : 0.0;
  Kernel_usage last_usage_ = memory_ ? kernel_usage() : Kernel_usage{};


  std::vector<std::pair<std::string, double>>& stats_;
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

// Gives the free memory of every malloc arena back to the system (glibc's
// malloc_trim; elsewhere nothing). The step's blocks are allocated on worker
// threads, in their arenas, and freed later on the main thread: without this
// the process keeps that memory resident while the next stage allocates anew.
void release_free_memory();

}  // namespace detail

struct Evolve_result {
  Mesh_arrays mesh;
  std::vector<Index> origin;   // index in the input mesh, -1 for a new point
  std::vector<double> input_f; // f at the input points
  std::vector<double> input_nn;
  Parent_map parents;          // where every new point lies in the input mesh
  double curve_reach = 0;      // how far outside the input's domain curved boundaries put new points
  // nn_M of the output points (finish_step, beside the parent map): Euclidean,
  // and where nn within the domain exceeds it (keep_within_domain) its value
  // there. Empty if it could not be computed (the caller checks the output).
  std::vector<double> output_nn;
  std::vector<Index> output_nn_grew;
  std::vector<double> output_nn_grown;
  // The step's two contracts with its caller (also reported in stats):
  // `unchanged`: the output is the input, the same points in the same order
  // with its triangles and segments (finish_step's adopt_input_order);
  // `triangulation_certified`: every edge of the output's triangulation is
  // strictly locally Delaunay, so the next step's update checks only what it changes.
  bool unchanged = false;
  bool triangulation_certified = false;
  std::vector<std::pair<std::string, double>> stats;  // stage timings (s) and counts
};

// Throws Input_error unless delta has one positive finite value per point.
void check_delta(const Mesh_arrays& mesh, const std::vector<double>& delta);

// The first part of step 1: nn_M at the input points and the weights w_p =
// delta(p) nn_M(p) (within the domain, capped by the local feature size, see
// step_spacing), timed as "nn". `evaluate` flags the points whose nn grew
// (empty without within_domain): f there comes from the Apollonius graph.
struct Step_weights {
  std::vector<double> nn;
  std::vector<double> weight;
  std::vector<std::uint8_t> evaluate;
};
Step_weights step_weights(const Mesh_arrays& mesh, const std::vector<double>& delta, detail::Stage_timer& timer,
                          const std::vector<Segment_chain>* within_domain);

// Step 1 of both methods (Section 3.1): nn_M at the input points, the weights
// w_p = delta(p) nn_M(p), the spacing function f = min_p (w_p + |x - p|) and f
// at the input points (timed as "nn", "apollonius", "spacing_at_points").
struct Step_spacing {
  std::vector<double> nn;  // nn_M at the input points
  std::vector<double> f;   // f at the input points
  std::unique_ptr<Spacing_function> function;
};
// How f is found at the input points: `lemma_3_1` takes f(p) = w_p where
// delta(p) <= 1 and asks the Apollonius graph only at the others (FRFC);
// `evaluate_all` asks it everywhere and takes the minimum with w_p (DRFC).
enum class F_at_points { lemma_3_1, evaluate_all };
// `within_domain` (the mesh's chains; null: the paper's nn and weights): nn
// within the domain and weights capped by the local feature size
// (local_feature_size.hpp).
// `filter_sites` (Step_context::filter_sites): sites hidden by a mesh neighbour
// are left out of the Apollonius graph (f is the same).
Step_spacing step_spacing(const Mesh_arrays& mesh, const std::vector<double>& delta, F_at_points how, int threads,
                          detail::Stage_timer& timer, const std::vector<Segment_chain>* within_domain = nullptr,
                          bool filter_sites = true);

// Spacing_queries (sampling.hpp) answered by `function` (certified: CGAL's
// exact nearest site), one thread per call (the sampling threads call it).
Spacing_queries spacing_queries(const Spacing_function& function);

// Throws Input_error when `estimate` (the points `what` would create) is above max_samples.
void check_sample_budget(double estimate, double max_samples, const char* what);

// The points a step keeps, in output order: mesh.points and mesh.kind, and the
// input index of every point (-1 for a new one).
struct Selection {
  Mesh_arrays mesh;
  std::vector<Index> origin;
  void add(const Vec2& x, Point_kind kind, Index from) {
    mesh.points.push_back(x);
    mesh.kind.push_back(kind);
    origin.push_back(from);
  }
  // Marks the points that are required in the input (`input_required`, empty:
  // none), so that the quality pass keeps them.
  void pin(const std::vector<std::uint8_t>& input_required) {
    if (input_required.empty()) return;
    mesh.required.assign(origin.size(), 0);
    for (std::size_t i = 0; i < origin.size(); ++i) {
      if (origin[i] >= 0) mesh.required[i] = input_required[origin[i]];
    }
  }
};

// The output kind of a kept point of the mesh being coarsened: a forced corner
// is a corner, and an input point sampled in an earlier step (`from_input`) is a
// Steiner point now.
inline Point_kind kept_point_kind(Point_kind kind, bool forced_corner, bool from_input = true) {
  if (forced_corner) return Point_kind::corner;
  return from_input && kind == Point_kind::sampled ? Point_kind::steiner : kind;
}

// The last stage of a step. Triangulates the selected points with the
// constraint pieces between them (constrained Delaunay, Section 3.2 step 6), or
// runs the quality pass on them when `quality` is given (on `early`, when given,
// whose first points must be the first selected points). Fills result.mesh and
// result.origin and adds the pass's counts and the smallest angle to result.stats.
// With a `geometry`, new points on curved pieces are then moved onto their
// curves (fit_to_curves); result.curve_reach says how far outside the input's
// domain that may put them. `triangles` (without `quality`): the constrained
// Delaunay triangulation of the points and pieces, when the caller has it
// already (updated_constrained_delaunay).
void triangulate_selection(Selection selected, const std::vector<Constraint_piece>& pieces,
                           const Quality_options* quality, Evolve_result& result,
                           Early_triangulation* early = nullptr, const Boundary_geometry* geometry = nullptr,
                           std::vector<Triangle>* triangles = nullptr);

// For every segment of `mesh` (triangulate_selection's result), the index in
// `pieces` of the constraint piece it is part of: the quality pass and the
// curve fit split pieces at the points they insert, which have
// selection_index -1 (the others: their index in the selection the pieces
// refer to). std::logic_error if a segment is on no piece (a bug).
std::vector<Index> segment_pieces(const Mesh_arrays& mesh, const std::vector<Constraint_piece>& pieces,
                                  const std::vector<Index>& selection_index);


// The old mesh's walker for finish_step, built on the other thread while the
// step triangulates (it reads only the input mesh; the quality pass is CGAL's
// sequential mesher): started before triangulate_selection. `fans`, the input's
// if the step has them: the walker takes them over instead of building its own.
struct Old_mesh_start {
  std::unique_ptr<Old_mesh_walker> walker;
  std::optional<Triangle_fans> fans;  // (before `work`: joined before they go)
  Background work;
  Old_mesh_start(const Old_mesh_start&) = delete;  // the background work holds `this`
  Old_mesh_start& operator=(const Old_mesh_start&) = delete;
  Old_mesh_start(const Mesh_arrays& input, int threads, std::optional<Triangle_fans> input_fans = std::nullopt)
      : fans(std::move(input_fans)) {
    work.start(
        [this, &input]() {
          walker = fans ? std::make_unique<Old_mesh_walker>(input, std::move(*fans))
                        : std::make_unique<Old_mesh_walker>(input);
          fans.reset();
        },
        resolve_threads(threads) > 1);
  }
};

// After triangulate_selection: an output point at exactly the coordinates of an
// input point the selection dropped gets that point's origin and kept kind
// (stat "restored_points"); an output with the input's points, triangles and
// segments (as sets) takes the input's arrays, in their order (stat
// "unchanged"); then the parent map of the new mesh in `input` (timed
// as "parent_map") and the step's total time; the walker from `start` if given.
// `input_nn`, if given: nn_spacing of the input points (NaN where unknown), for
// the output's nn from what the step changed (nn_spacing_after_change; kept
// points must not have moved). `same_fans`, if given with `input_nn`: the
// output points whose triangles are the input's (Step_scope::same_fans); where
// also their nn is the input's (and did not grow), nn within the domain is the
// input's too, and keep_within_domain measures only the others.
void finish_step(const Mesh_arrays& input, Evolve_result& result, detail::Stage_timer& timer,
                 Old_mesh_start* start = nullptr, const std::vector<double>* input_nn = nullptr,
                 const std::vector<std::uint8_t>* same_fans = nullptr);

// Appends the counts (name, value) to result.stats, then the output's point and
// triangle counts.
void add_step_counts(Evolve_result& result, std::initializer_list<std::pair<const char*, double>> counts);

}  // namespace evomesh
