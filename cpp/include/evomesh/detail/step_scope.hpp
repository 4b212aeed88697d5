// The scope of an FRFC step (docs/distributed-step.md §2.1): which points,
// sites, triangles and spheres the step computes, and which it only reads
// because their outcome is certain. There is one outline, frfc_over_scope()
// (frfc.cpp); a scope answers the few questions where the outline's work can
// be restricted, each with the certificate that makes the restriction exact:
//
//   Whole_mesh      (frfc.cpp)              everything is computed: the paper's step;
//   Changed_region  (incremental_step.cpp)  where delta = 1 on most of the mesh, only
//                                           what can change (the same output, bit for bit).
//
// A third scope, a rank's owned part plus its halo, is the distributed step's
// (docs/distributed-step.md §3); its certificates are the same arguments.
// Internal: include from .cpp files only.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "evomesh/candidates.hpp"
#include "evomesh/detail/frfc_stages.hpp"
#include "evomesh/options.hpp"
#include "evomesh/sampling.hpp"
#include "evomesh/segment_chains.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/step.hpp"
#include "evomesh/step_context.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

// Step 1's results that the outline reads: nn_M, f at the input points (Lemma
// 3.1) and, within the domain, the points whose nn grew (step_weights).
struct Scope_spacing {
  std::vector<double> nn;
  std::vector<double> f;
  std::vector<std::uint8_t> evaluate;
};

class Step_scope {
 public:
  Step_scope() = default;
  Step_scope(const Step_scope&) = delete;
  Step_scope& operator=(const Step_scope&) = delete;
  virtual ~Step_scope() = default;

  // Step 1: nn_M, the weights, f at the input points, and whatever graph of
  // sites the scope answers later queries from (timed as "nn", "apollonius",
  // "spacing_at_points").
  virtual Scope_spacing spacing(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                const std::vector<Segment_chain>& chains, detail::Stage_timer& timer) = 0;
  // f for the adaptive grids that ask it (sampling.hpp, asks_spacing), in the
  // sample budget's estimate and the sampling; null if none asks.
  virtual const Spacing_queries* grid_queries(const Mesh_arrays& mesh, const std::vector<double>& f) = 0;
  // f at every candidate (the sphere radii's, candidate_radii_from_f), into
  // candidates.radius, one value each: the segment candidates (on_segment),
  // then the interior ones; not asked where options.radius is cheap. (f: step
  // 1's, at the input points.)
  virtual void f_at_candidates(const Mesh_arrays& mesh, const std::vector<double>& f, Candidates& candidates,
                               bool on_segment, detail::Stage_timer& timer) = 0;
  // Steps 3-5, first pass: input points and segment candidates (frfc_stages::first_packing_pass).
  virtual frfc_stages::Packing first_pass(const Mesh_arrays& mesh, const Scope_spacing& spacing,
                                          const Candidates& on_segments, const std::vector<std::uint8_t>& forced,
                                          std::size_t n_forced, const std::vector<std::uint8_t>& demoted) = 0;
  // Whether the quality pass's triangulation starts right after the first pass
  // (frfc_stages::Early_start) rather than once the scope's graphs are freed.
  virtual bool starts_triangulation_early() const = 0;
  // Triangles whose samples the packing certainly rejects (not sampled); empty: none.
  // `settled` (settled_points; empty without options.skip_settled): triangles
  // that draw no samples anyway (unsampled_triangles) the scope may call quiet
  // without a certificate.
  virtual std::vector<std::uint8_t> quiet_triangles(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                                    const frfc_stages::Packing& packing,
                                                    const std::vector<std::uint8_t>& demoted,
                                                    const std::vector<std::uint8_t>& settled,
                                                    detail::Stage_timer& timer) = 0;
  // After the interior sampling (`quiet` as quiet_triangles returned it).
  virtual void sampled(const Mesh_arrays& mesh, const std::vector<std::uint8_t>& quiet) = 0;
  // Every f query is answered: the graphs go.
  virtual void spacing_done() = 0;
  // Step 6 without the quality pass: the constrained Delaunay triangulation of
  // the selection (constrained_delaunay's array), when the scope can give it
  // for less than building it whole; nullopt: build it whole. `old_mesh`: the
  // input's walker (started, not waited for).
  virtual std::optional<std::vector<Triangle>> triangulation(const Selection& /*selection*/,
                                                             const std::vector<Constraint_piece>& /*pieces*/,
                                                             Old_mesh_start& /*old_mesh*/,
                                                             std::vector<std::pair<std::string, double>>& /*stats*/) {
    return std::nullopt;
  }
  // The second pass: deferred input points and interior candidates (frfc_stages::second_packing_pass);
  // `inside` may be emptied.
  virtual void second_pass(const Mesh_arrays& mesh, Candidates& inside, frfc_stages::Packing& packing) = 0;
  // Whether the input's triangle fans stay alive for the parent map's walker
  // (else they go after the spacing repair and the walker builds its own).
  virtual bool keeps_fans() const = 0;
  // nn_M of the input points that finish_step may reuse for the output's nn (NaN: unknown); null: none.
  virtual const std::vector<double>* reusable_nn(const Scope_spacing& spacing) = 0;
  // After triangulation(): 1 for every output point whose triangles are the
  // input's (kept, with no triangle of the change), for finish_step's nn within
  // the domain (keep_within_domain's `known`); null: not known.
  virtual const std::vector<std::uint8_t>* same_fans() const { return nullptr; }
  // Whether the outline gives free memory back to the system between stages
  // (when Step_context::release_memory allows): worth it where a stage frees
  // large blocks (the whole mesh's graphs, its candidates); where the scope's
  // stages free little, the next stage's fresh pages would cost page faults
  // for nothing.
  virtual bool releases_memory_between_stages() const = 0;
  // The scope's own counts, appended to the step's stats.
  virtual void add_counts(std::vector<std::pair<std::string, double>>& stats) const = 0;
};

// The FRFC step (Section 3.2) over `scope`. `input`: the mesh as given (the
// parent map and the unchanged-mesh test read it); `mesh`: the one the stages
// read (with curves, the curved chains' corners marked: with_curve_kinds).
Evolve_result frfc_over_scope(const Mesh_arrays& input, const Mesh_arrays& mesh, const std::vector<double>& delta,
                              const Frfc_options& options, const Step_context& context, Step_scope& scope);

}  // namespace evomesh
