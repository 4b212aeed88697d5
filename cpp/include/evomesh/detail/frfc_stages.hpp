// FRFC's stages (frfc.cpp) that the incremental step (incremental_step.cpp)
// shares with the full one. Internal: include from .cpp files only.
#pragma once

#include <chrono>
#include <cstdint>
#include <vector>

#include "evomesh/candidates.hpp"
#include "evomesh/options.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/quality_pass.hpp"
#include "evomesh/segment_chains.hpp"
#include "evomesh/step.hpp"
#include "evomesh/step_context.hpp"
#include "evomesh/types.hpp"

namespace evomesh::frfc_stages {

// detail::release_free_memory() between stages, as the context's memory policy says.
inline void release_free_memory(const Step_context& context) {
  if (context.release_memory) detail::release_free_memory();
}

// The spheres of the packing in candidate order: input points [0, n), segment
// candidates [n, n + n_seg), then interior candidates (after both passes, the
// kept ones only: frfc.cpp, drop_rejected_candidates).
struct Packing {
  std::vector<Vec2> centers;
  std::vector<double> radius;            // of the first pass's spheres
  std::vector<Index> first_order;        // the first pass's order
  std::vector<Index> blocker;            // first pass: a kept sphere that rejected the sphere, -1 if kept
  std::vector<std::uint8_t> kept_first;  // kept by the first pass
  std::vector<std::uint8_t> kept;        // kept by either pass or the spacing repair
  std::vector<Index> deferred;           // demoted interior input points: packed in the second pass
  std::size_t n_demoted = 0;             // demoted input points (deferred or on segments)
};

// The points the first packing pass keeps are final: the quality pass's
// triangulation of them can start on a second thread while the interior
// candidates are packed (members destroyed in reverse: the thread is joined
// before the points it reads go). The full step starts it once the Apollonius
// graph is freed (alive with the graph during sampling it set the step's peak
// memory): beside the second pass, or after it when that pass packs more
// candidates than there are input points (frfc.cpp); the incremental step at once.
//
// After the second pass, the points it keeps (the interior candidates and the
// deferred input points) are final too and come next in the output order
// (select_output): insert_late adds them on the second thread while the
// spacing repair runs. What the repair adds comes last (the segment candidates
// it keeps, then its own points): insert_rest adds those while the output is
// selected; finish() inserts whatever is still missing.
struct Early_start {
  std::vector<Vec2> points, late_points, rest_points;
  Early_triangulation triangulation;
  // late_work waits for work (joins it), then inserts the late points;
  // rest_work waits for late_work, then inserts the rest.
  Background work, late_work, rest_work;
  bool started = false;
  bool on_thread = false;
  // Seconds the three batches took (on the second thread; written by the
  // batches, read after wait()): the part of the step that follows the
  // triangulation's insertion history (docs/distributed-step.md 2.5).
  double insert_seconds = 0;
  Early_start(const Early_start&) = delete;  // the background work holds `this`
  Early_start& operator=(const Early_start&) = delete;
  Early_start(const Packing& packing, const Frfc_options& options, bool curved) {
    // (with curved boundaries, kept segment candidates move before the triangulation)
    if (!options.quality || curved) return;
    for (std::size_t c = 0; c < packing.kept_first.size(); ++c) {
      if (packing.kept_first[c]) points.push_back(packing.centers[c]);
    }
    started = true;
    on_thread = resolve_threads(0) > 1;  // (under the outline's Thread_limit)
    work.start([this]() { timed([&] { triangulation.insert_first(points); }); }, on_thread);
  }
  // `n_first_range`: input points and segment candidates (n + n_seg), whose
  // kept ones after the first pass (the deferred input points) follow the
  // interior candidates in the output order.
  void insert_late(const Packing& packing, std::size_t n_points, std::size_t n_first_range) {
    if (!started) return;
    for (std::size_t c = n_first_range; c < packing.kept.size(); ++c) {
      if (packing.kept[c]) late_points.push_back(packing.centers[c]);
    }
    for (std::size_t c = 0; c < n_points; ++c) {
      if (packing.kept[c] && !packing.kept_first[c]) late_points.push_back(packing.centers[c]);
    }
    late_work.start(
        [this]() {
          work.wait();  // the first batch (rethrows its error here, then from late_work)
          timed([&] { triangulation.insert_more(late_points); });
        },
        on_thread);
  }
  // After the spacing repair: the segment candidates it kept ([n_points,
  // n_first_range), kept and not kept_first; those before n_points that are
  // kept later went with the late points: select_output lists the former after
  // the latter) and its points, the tail of the output order. (Were the order
  // not the final one, finish() would find a point at the wrong index and throw.)
  void insert_rest(const Packing& packing, std::size_t n_points, std::size_t n_first_range,
                   const std::vector<Vec2>& repair_points) {
    if (!started) return;
    for (std::size_t c = n_points; c < n_first_range; ++c) {
      if (packing.kept[c] && !packing.kept_first[c]) rest_points.push_back(packing.centers[c]);
    }
    rest_points.insert(rest_points.end(), repair_points.begin(), repair_points.end());
    rest_work.start(
        [this]() {
          late_work.wait();
          timed([&] { triangulation.insert_more(rest_points); });
        },
        on_thread);
  }
  // Every batch inserted; their copies of the points freed.
  void wait() {
    rest_work.wait();
    late_work.wait();
    work.wait();
    points = std::vector<Vec2>();
    late_points = std::vector<Vec2>();
    rest_points = std::vector<Vec2>();
  }

 private:
  template <class Insert>
  void timed(Insert insert) {
    const auto begin = std::chrono::steady_clock::now();
    insert();
    insert_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
  }
};

// Steps 3-5, first pass: input points and segment candidates (frfc.cpp).
Packing first_packing_pass(const Mesh_arrays& mesh, const std::vector<double>& f, const Candidates& on_segments,
                           const std::vector<std::uint8_t>& forced, std::size_t n_forced,
                           const std::vector<std::uint8_t>& demoted, const Frfc_options& options);

// After the first pass's MIS: demoted interior input points (packing class
// class_new, classes[i] of input point i) leave it for the second pass
// (Packing::deferred); a blocker that is one of them is forgotten (only a
// deferred point comes after a deferred point). Sets kept_first.
void defer_demoted_points(const std::vector<std::uint8_t>& classes, std::size_t n_points, Packing& packing);

// The second pass: deferred input points and interior candidates.
void second_packing_pass(Candidates& inside, Packing& packing);

// The output points in output order; `out_index` receives the output index of
// every input point and segment candidate.
Selection select_output(const Mesh_arrays& mesh, const std::vector<std::uint8_t>& forced, const Packing& packing,
                        std::size_t n_seg, const std::vector<Vec2>& repair_points, std::vector<Index>& out_index);

// Constraint pieces between consecutive kept points along every chain (and,
// if asked, the chain vertices between their ends: constraint_pieces).
std::vector<Constraint_piece> pieces_along_chains(const Mesh_arrays& mesh, const std::vector<Segment_chain>& chains,
                                                  const Candidates& on_segments, const std::vector<Index>& out_index,
                                                  std::vector<Piece_span>* spans = nullptr);

// With a geometry, after the moves of segment candidates onto their curves:
// undoes the moves of interior chains that make pieces cross or touch
// (keep_pieces_apart, counted in `undone`; `moves` as there), and a piece that
// still crosses another (a chord between kept chain points across a bulge or
// fold of a curve that the spacing does not resolve) gets back the dropped
// chain vertex farthest from it, kept again at the end of the selection, its
// pieces rebuilt; until no pieces cross, or no crossing piece has a dropped
// vertex. That ends at the latest when the crossing pieces lie on the input's
// segments, which do not cross. Returns the number of vertices kept again.
std::size_t keep_crossed_chain_vertices(const Mesh_arrays& mesh, const std::vector<Segment_chain>& chains,
                                        const Candidates& on_segments, std::vector<Index>& out_index,
                                        Selection& selection, std::vector<Constraint_piece>& pieces,
                                        std::vector<std::pair<Index, Vec2>>& moves, std::size_t& undone);

}  // namespace evomesh::frfc_stages
