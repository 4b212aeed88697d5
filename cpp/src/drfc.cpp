#include "evomesh/drfc.hpp"

#include <cmath>
#include <memory>
#include <string>

#include "evomesh/packing.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/sampling.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/triangulation.hpp"

namespace evomesh {

namespace {

using detail::Stage_timer;

// Packing priority classes of step 2 (Section 6's order): corners, boundary points
// of M, boundary points added by the refinement, original, Steiner, new interior.
enum Priority : std::uint8_t {
  prio_corner = 0,
  prio_boundary = 1,
  prio_boundary_new = 2,
  prio_original = 3,
  prio_steiner = 4,
  prio_new = 5,
};

struct Refinement_stage {
  std::vector<double> nn;  // nn_M at the input points
  std::vector<double> f;   // f at the input points
  std::unique_ptr<Spacing_function> spacing;
  Refined_mesh refined;    // M_I
};

void check_options(const Mesh_arrays& mesh, const std::vector<double>& delta, const Drfc_options& options) {
  if (delta.size() != mesh.points.size()) throw Input_error("delta must have one value per mesh point");
  for (double d : delta) {
    if (!std::isfinite(d) || !(d > 0)) throw Input_error("delta must be finite and > 0");
  }
  options.validate();
}

Refinement_stage refinement_stage(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                  const Drfc_options& options, Stage_timer& timer) {
  check_options(mesh, delta, options);
  const std::size_t n = mesh.points.size();
  Refinement_stage stage;
  // f of Section 3.1, as in FRFC.
  stage.nn = nn_spacing(mesh.points);
  std::vector<double> weight(n);
  for (std::size_t i = 0; i < n; ++i) weight[i] = delta[i] * stage.nn[i];
  timer.lap("nn");
  stage.spacing = std::make_unique<Spacing_function>(mesh.points, weight);
  timer.lap("apollonius");
  stage.f.resize(n);
  stage.spacing->evaluate(mesh.points.data(), n, stage.f.data(), nullptr, options.threads);
  for (std::size_t i = 0; i < n; ++i) stage.f[i] = std::min(stage.f[i], weight[i]);
  timer.lap("spacing_at_points");
  // FRFC's sampling count bounds the points a packing for f needs (Lemma 3.5).
  const double estimate = estimate_sample_count(mesh, stage.f, 1.0, options.max_samples);
  if (estimate > options.max_samples) {
    throw Input_error("delta asks for too much refinement in one step: refinement would create about " +
                      format_count(estimate) + " points (max_samples is " +
                      format_count(options.max_samples) +
                      "); delta is relative (the new spacing is delta times the current one): raise it, refine over "
                      "several steps, or raise max_samples");
  }
  const auto cap = static_cast<std::size_t>(2 * estimate + 1000);
  stage.refined = spacing_refine(mesh, *stage.spacing, stage.f, options.min_angle, cap, options.threads);
  timer.lap("refine");
  return stage;
}

}  // namespace

Refined_mesh drfc_refine(const Mesh_arrays& mesh, const std::vector<double>& delta, const Drfc_options& options) {
  std::vector<std::pair<std::string, double>> unused;
  Stage_timer timer(unused);
  const Thread_limit thread_limit(options.threads);
  return std::move(refinement_stage(mesh, delta, options, timer).refined);
}

Evolve_result drfc(const Mesh_arrays& mesh, const std::vector<double>& delta, const Drfc_options& options) {
  Evolve_result result;
  auto& stats = result.stats;
  Stage_timer timer(stats);
  const Thread_limit thread_limit(options.threads);
  // Step 1: Delaunay refinement with rules 1-4 (Section 5).
  Refinement_stage stage = refinement_stage(mesh, delta, options, timer);
  const Mesh_arrays& refined = stage.refined.mesh;
  const std::vector<Index>& source = stage.refined.source;
  const std::size_t m = refined.points.size();

  // Step 2: one-level coarsening of Miller, Talmor and Teng: the lexical-first MIS
  // of B(p, f(p)/2) over the refined points, boundary first; no new samples.
  std::vector<double> radius(m);
  for (std::size_t i = 0; i < m; ++i) radius[i] = 0.5 * options.radius_scale * stage.refined.f[i];
  const auto chains = segment_chains(refined);
  std::vector<std::uint8_t> forced_corner(m, 0);
  for (std::size_t i = 0; i < m; ++i) forced_corner[i] = refined.kind[i] == Point_kind::corner;
  for (const auto& chain : chains) {
    forced_corner[chain.vertices.front()] = 1;
    forced_corner[chain.vertices.back()] = 1;
  }
  std::vector<std::uint8_t> priority(m);
  std::size_t n_forced = 0;
  for (std::size_t i = 0; i < m; ++i) {
    const bool on_segment = refined.kind[i] <= Point_kind::boundary;
    if (forced_corner[i]) {
      priority[i] = prio_corner;
      ++n_forced;
    } else if (source[i] < 0) {
      priority[i] = on_segment ? prio_boundary_new : prio_new;
    } else if (on_segment) {
      priority[i] = prio_boundary;
    } else {
      priority[i] = refined.kind[i] == Point_kind::original ? prio_original : prio_steiner;
    }
  }
  const auto order = packing_order(priority, radius);
  const auto kept = lexical_first_mis(refined.points, radius, order, n_forced);
  timer.lap("lfmis");

  // Output points: kept input points in input order, then kept new points.
  Mesh_arrays out;
  std::vector<Index> origin;
  std::vector<Index> out_index(m, -1);
  for (std::size_t i = 0; i < m; ++i) {
    if (!kept[i]) continue;
    out_index[i] = static_cast<Index>(out.points.size());
    out.points.push_back(refined.points[i]);
    origin.push_back(source[i]);
    Point_kind k = refined.kind[i];
    if (forced_corner[i]) k = Point_kind::corner;
    else if (source[i] >= 0 && k == Point_kind::sampled) k = Point_kind::steiner;
    out.kind.push_back(k);
  }
  // Constraint pieces between consecutive kept points along every chain of M_I.
  std::vector<Constraint_piece> pieces;
  std::vector<Index> along;
  for (const auto& chain : chains) {
    along.clear();
    for (std::size_t k = 0; k < chain.segments.size(); ++k) {
      if (kept[chain.vertices[k]]) along.push_back(out_index[chain.vertices[k]]);
    }
    if (chain.closed) along.push_back(along.front());
    else if (kept[chain.vertices.back()]) along.push_back(out_index[chain.vertices.back()]);
    const bool flip = chain.boundary && !chain.forward.front();
    for (std::size_t k = 0; k + 1 < along.size(); ++k) {
      Constraint_piece piece{along[k], along[k + 1], chain.boundary};
      if (flip) std::swap(piece.a, piece.b);
      pieces.push_back(piece);
    }
  }
  const Quality_options quality = options.quality_settings();
  triangulate_selection(std::move(out), std::move(origin), pieces, options.quality ? &quality : nullptr, result);
  timer.lap(options.quality ? "quality" : "cdt");
  finish_step(mesh, result, timer);
  const auto& report = stage.refined.report;
  stats.emplace_back("n_input_points", static_cast<double>(mesh.points.size()));
  stats.emplace_back("n_refined_points", static_cast<double>(m));
  stats.emplace_back("refine_points_added", static_cast<double>(report.n_inserted));
  stats.emplace_back("refine_rounds", static_cast<double>(report.rounds));
  stats.emplace_back("refine_capped", report.capped ? 1.0 : 0.0);
  stats.emplace_back("n_output_points", static_cast<double>(result.mesh.points.size()));
  stats.emplace_back("n_output_triangles", static_cast<double>(result.mesh.triangles.size()));
  result.input_f = std::move(stage.f);
  result.input_nn = std::move(stage.nn);
  return result;
}

}  // namespace evomesh
