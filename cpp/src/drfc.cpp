#include "evomesh/drfc.hpp"

#include <CGAL/exceptions.h>

#include <string>

#include <utility>

#include "evomesh/packing.hpp"
#include "evomesh/parent_map.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/sampling.hpp"
#include "evomesh/segment_chains.hpp"

namespace evomesh {

namespace {

using detail::Stage_timer;

struct Refinement_stage {
  Step_spacing spacing;
  Refined_mesh refined;  // M_I
};

// Step 1: f of Section 3.1, as in FRFC, then Delaunay refinement with rules 1-4 (Section 5).
Refinement_stage refinement_stage(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                  const Drfc_options& options, const Step_context& context, Stage_timer& timer) {
  check_delta(mesh, delta);
  if (mesh.geometry) throw Input_error("a boundary geometry (curved boundaries) is supported by method 'frfc' only");
  options.validate();
  Refinement_stage stage;
  const auto chains = options.within_domain ? segment_chains(mesh) : std::vector<Segment_chain>{};
  stage.spacing = step_spacing(mesh, delta, F_at_points::evaluate_all, /*threads=*/0, timer,
                               options.within_domain ? &chains : nullptr, context.filter_sites);
  // FRFC's sampling count bounds the points a packing for f needs (Lemma 3.5).
  const double estimate = estimate_sample_count(mesh, stage.spacing.f, 1.0, options.max_samples);
  check_sample_budget(estimate, options.max_samples, "refinement");
  const auto cap = static_cast<std::size_t>(2 * estimate + 1000);
  try {
    stage.refined =
        spacing_refine(mesh, *stage.spacing.function, stage.spacing.f, options.min_angle, cap, /*threads=*/0);
  } catch (const CGAL::Failure_exception& error) {
    // CGAL's mesher broke an invariant on near-degenerate input (see CMakeLists.txt).
    throw Input_error(std::string("DRFC's Delaunay refinement failed on this mesh (") + error.what() +
                      "); its geometry is too close to degenerate for it: try method='frfc'");
  }
  timer.lap("refine");
  return stage;
}

// Step 2: one-level coarsening of Miller, Talmor and Teng: the lexical-first MIS
// of B(p, radius_scale f(p)/2) over the refined points, corners forced, boundary
// first; no new samples.
std::vector<std::uint8_t> coarsen(const Refined_mesh& refined, const std::vector<std::uint8_t>& forced,
                                  std::size_t n_forced, double radius_scale) {
  const std::size_t m = refined.mesh.points.size();
  std::vector<double> radius(m);
  for (std::size_t i = 0; i < m; ++i) radius[i] = 0.5 * radius_scale * refined.f[i];
  std::vector<std::uint8_t> classes(m);
  for (std::size_t i = 0; i < m; ++i) {
    const Point_kind kind = refined.mesh.kind[i];
    classes[i] = refined.source[i] >= 0 || forced[i] ? old_point_class(kind, forced[i])
                                                     : new_point_class(kind <= Point_kind::boundary);
  }
  return lexical_first_mis(refined.mesh.points, radius, packing_order(classes, radius), n_forced);
}

// Output points: the kept points of M_I in its order (input points first).
// `out_index` receives the output index of every point of M_I (-1: not kept).
Selection select_output(const Refined_mesh& refined, const std::vector<std::uint8_t>& forced,
                        const std::vector<std::uint8_t>& kept, std::vector<Index>& out_index) {
  const std::size_t m = refined.mesh.points.size();
  Selection out;
  out_index.assign(m, -1);
  for (std::size_t i = 0; i < m; ++i) {
    if (!kept[i]) continue;
    out_index[i] = static_cast<Index>(out.mesh.points.size());
    const Index source = refined.source[i];
    out.add(refined.mesh.points[i], kept_point_kind(refined.mesh.kind[i], forced[i] == kForcedCorner, source >= 0), source);
  }
  return out;
}

}  // namespace

Refined_mesh drfc_refine(const Mesh_arrays& mesh, const std::vector<double>& delta, const Drfc_options& options,
                         const Step_context& context) {
  std::vector<std::pair<std::string, double>> unused;
  Stage_timer timer(unused);
  const Thread_limit thread_limit(context.threads);  // (the stages' loops run under it)
  Refined_mesh refined = std::move(refinement_stage(mesh, delta, options, context, timer).refined);
  canonical_triangle_order(refined.mesh.points.size(), refined.mesh.triangles);
  // The input's labels, as a step carries them (finish_step): refinement only
  // adds points, so every input point is kept (its `required` flag with it), a
  // new segment lies on the input segment it split and a new triangle in the
  // input triangle's region.
  if (!mesh.segment_tags.empty() || !mesh.triangle_tags.empty() || !mesh.required.empty()) {
    const Old_mesh_walker walker(mesh);
    const Parent_map parents = parent_map(walker, refined.mesh, refined.source);
    carry_tags(walker, refined.source, parents, refined.mesh);
  }
  return refined;
}

Evolve_result drfc(const Mesh_arrays& mesh, const std::vector<double>& delta, const Drfc_options& options,
                   const Step_context& context) {
  Evolve_result result;
  Stage_timer timer(result.stats, context.profile);
  const Thread_limit thread_limit(context.threads);  // (the stages' loops run under it)
  Refinement_stage stage = refinement_stage(mesh, delta, options, context, timer);
  const Refined_mesh& refined = stage.refined;

  const auto chains = segment_chains(refined.mesh);
  std::size_t n_forced = 0;
  std::vector<std::uint8_t> required;  // the input's required points, on M_I
  if (!mesh.required.empty()) {
    required.assign(refined.mesh.points.size(), 0);
    for (std::size_t i = 0; i < required.size(); ++i) {
      if (refined.source[i] >= 0) required[i] = mesh.required[refined.source[i]];
    }
  }
  const auto forced = forced_corners(refined.mesh, chains, n_forced, required);
  const auto kept = coarsen(refined, forced, n_forced, options.radius_scale);
  timer.lap("lfmis");

  // The kept points, the constraint pieces between them along every chain of
  // M_I, their triangulation.
  std::vector<Index> out_index;
  Selection selection = select_output(refined, forced, kept, out_index);
  selection.pin(mesh.required);
  const auto pieces = constraint_pieces(chains, out_index);
  const Quality_options quality = options.quality_settings();
  triangulate_selection(std::move(selection), pieces, options.quality ? &quality : nullptr, result);
  timer.lap(options.quality ? "quality" : "cdt");
  finish_step(mesh, result, timer);
  const auto& report = refined.report;
  add_step_counts(result, {{"n_input_points", mesh.points.size()},
                           {"n_refined_points", refined.mesh.points.size()},
                           {"refine_points_added", report.n_inserted},
                           {"refine_rounds", report.rounds},
                           {"refine_capped", report.capped ? 1.0 : 0.0},
                           {"refine_points_outside", report.n_inserted_outside}});
  result.input_f = std::move(stage.spacing.f);
  result.input_nn = std::move(stage.spacing.nn);
  return result;
}

}  // namespace evomesh
