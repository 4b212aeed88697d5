#include "evomesh/frfc.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "evomesh/candidates.hpp"
#include "evomesh/empty_scope.hpp"
#include "evomesh/global_ids.hpp"
#include "evomesh/packing.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/sampling.hpp"
#include "evomesh/spacing_repair.hpp"
#include "evomesh/incremental_step.hpp"
#include "evomesh/detail/frfc_stages.hpp"
#include "evomesh/detail/step_scope.hpp"

namespace evomesh {

namespace frfc_stages {

using detail::Stage_timer;


// Steps 3-5: order the spheres, lexical-first MIS; corners are always kept.
// Every interior candidate comes after every input point and segment candidate
// in the order (its classes are last), so the MIS is computed in two passes:
// this first one over input points and segment candidates decides them for
// good; the second goes on with the interior candidates, the spheres kept so
// far forced. Demoted interior input points (demoted_points) belong to the
// interior candidates' last class: they come last here, so taking them out
// after the pass changes nothing else, and go to the second pass.
Packing first_packing_pass(const Mesh_arrays& mesh, const std::vector<double>& f, const Candidates& on_segments,
                           const std::vector<std::uint8_t>& forced, std::size_t n_forced,
                           const std::vector<std::uint8_t>& demoted, const Frfc_options& options) {
  Packing packing;
  // (exact capacities: growing by insert would double them, 24 bytes a point for nothing)
  packing.centers.reserve(mesh.points.size() + on_segments.size());
  packing.centers.insert(packing.centers.end(), mesh.points.begin(), mesh.points.end());
  packing.centers.insert(packing.centers.end(), on_segments.samples.points.begin(), on_segments.samples.points.end());
  packing.radius = input_point_radii(mesh, f, options);
  packing.radius.reserve(mesh.points.size() + on_segments.size());
  packing.radius.insert(packing.radius.end(), on_segments.radius.begin(), on_segments.radius.end());
  std::vector<std::uint8_t> classes(mesh.points.size());
  for (std::size_t i = 0; i < classes.size(); ++i) {
    classes[i] = old_point_class(mesh.kind[i], forced[i], demoted[i]);
    packing.n_demoted += demoted[i];
  }
  const auto segment_classes = on_segments.classes(/*on_segment=*/true);
  classes.insert(classes.end(), segment_classes.begin(), segment_classes.end());
  // Ties in (class, radius): input points by global id, then the segment
  // candidates, which come in the order of their segments' keys (sample_segments).
  std::vector<Index> tie_order = order_by_ids(mesh.point_gids);
  if (!tie_order.empty()) {
    tie_order.reserve(packing.centers.size());
    for (std::size_t j = mesh.points.size(); j < packing.centers.size(); ++j) tie_order.push_back(static_cast<Index>(j));
  }
  packing.first_order = packing_order(classes, packing.radius, tie_order);
  packing.kept = lexical_first_mis(packing.centers, packing.radius, packing.first_order, n_forced, &packing.blocker,
                                    /*threads=*/0);
  defer_demoted_points(classes, mesh.points.size(), packing);
  if (!mesh.point_gids.empty()) {
    // (the second pass breaks their ties by position in this list)
    std::sort(packing.deferred.begin(), packing.deferred.end(),
              [&](Index a, Index b) { return mesh.point_gids[a] < mesh.point_gids[b]; });
  }
  return packing;
}

void defer_demoted_points(const std::vector<std::uint8_t>& classes, std::size_t n_points, Packing& packing) {
  std::vector<std::uint8_t> deferred(packing.blocker.size(), 0);
  for (std::size_t i = 0; i < n_points; ++i) {
    if (classes[i] != class_new) continue;
    deferred[i] = 1;
    packing.deferred.push_back(static_cast<Index>(i));
    packing.kept[i] = 0;
    packing.blocker[i] = -1;
  }
  // Only a deferred point comes after a deferred point: a blocker that is one is forgotten.
  for (Index& b : packing.blocker) {
    if (b >= 0 && deferred[b]) b = -1;
  }
  packing.kept_first = packing.kept;
}

// The second pass: the kept spheres of the first (in their order, forced), then
// the deferred input points and the interior candidates by class, radius and
// index. The interior candidates' centres and radii move to the end of the
// packing's arrays (candidates n + n_seg, ...); `inside` is emptied.
void second_packing_pass(Candidates& inside, Packing& packing) {
  const std::size_t n_first = packing.centers.size();
  const std::size_t n_deferred = packing.deferred.size();
  std::vector<std::uint8_t> classes(n_deferred, class_new);
  {
    const auto inside_classes = inside.classes(/*on_segment=*/false);
    classes.insert(classes.end(), inside_classes.begin(), inside_classes.end());
  }
  // (the arrays grow with their fresh pages touched on both threads: detail::parallel_resize)
  const std::size_t n_inside = inside.size();
  std::vector<double> radii;
  detail::parallel_resize(radii, n_deferred + n_inside);
  for (std::size_t k = 0; k < n_deferred; ++k) radii[k] = packing.radius[packing.deferred[k]];
  detail::parallel_resize(packing.radius, n_first + n_inside);
  detail::parallel_resize(packing.centers, n_first + n_inside);
  constexpr std::size_t kChunk = std::size_t{1} << 16;
  parallel_for((n_inside + kChunk - 1) / kChunk, 0, [&](std::size_t c) {
    for (std::size_t j = c * kChunk; j < std::min(n_inside, (c + 1) * kChunk); ++j) {
      radii[n_deferred + j] = inside.radius[j];
      packing.radius[n_first + j] = inside.radius[j];
      packing.centers[n_first + j] = inside.samples.points[j];
    }
  });
  inside = Candidates();
  // Positions in (deferred, interior candidates) -> candidate indices.
  std::vector<Index> order = packing_order(std::move(classes), std::move(radii));
  for (Index& k : order) {
    k = static_cast<std::size_t>(k) < n_deferred ? packing.deferred[k]
                                                 : static_cast<Index>(n_first + (static_cast<std::size_t>(k) - n_deferred));
  }
  packing.kept = extend_packing(packing.centers, packing.radius, packing.first_order, packing.kept, std::move(order));
}

// After both passes the interior candidates nobody kept are read no more (the
// spacing repair and the selection read the kept centres and the segment
// candidates): they leave the packing's arrays, the kept ones keep their order
// (n_first_range: input points and segment candidates, which stay in place).
// On a refining front that is ~5 of every 6 candidates, 25 bytes each.
void drop_rejected_candidates(std::size_t n_first_range, Packing& packing) {
  std::size_t k = n_first_range;
  for (std::size_t c = n_first_range; c < packing.centers.size(); ++c) {
    if (!packing.kept[c]) continue;
    packing.centers[k] = packing.centers[c];
    packing.radius[k] = packing.radius[c];
    packing.kept[k] = 1;
    ++k;
  }
  packing.centers.resize(k);
  packing.centers.shrink_to_fit();
  packing.radius.resize(k);
  packing.radius.shrink_to_fit();
  packing.kept.resize(k);
  packing.kept.shrink_to_fit();
}

// Output points: kept input points in input order and kept segment candidates
// (the first points of the early triangulation), kept interior candidates, then
// the points of the spacing repair (on segments, then inside). `out_index`
// receives the output index of every input point and segment candidate (-1:
// not kept), what the constraint pieces need; not of the interior candidates
// (8 bytes each: several per input point on a refining front).
Selection select_output(const Mesh_arrays& mesh, const std::vector<std::uint8_t>& forced, const Packing& packing,
                        std::size_t n_seg, const std::vector<Vec2>& repair_points, std::vector<Index>& out_index) {
  const std::size_t n = mesh.points.size();
  const std::size_t total = packing.centers.size();
  std::vector<std::size_t> out_order;
  out_order.reserve(total);
  for (std::size_t c = 0; c < n + n_seg; ++c) {
    if (packing.kept_first[c]) out_order.push_back(c);
  }
  for (std::size_t c = n + n_seg; c < total; ++c) {
    if (packing.kept[c]) out_order.push_back(c);
  }
  for (std::size_t c = 0; c < n + n_seg; ++c) {
    if (packing.kept[c] && !packing.kept_first[c]) out_order.push_back(c);
  }
  Selection out;
  out_index.assign(n + n_seg, -1);
  for (std::size_t c : out_order) {
    if (c < n + n_seg) out_index[c] = static_cast<Index>(out.mesh.points.size());
    if (c < n) out.add(packing.centers[c], kept_point_kind(mesh.kind[c], forced[c] == kForcedCorner), static_cast<Index>(c));
    else out.add(packing.centers[c], c < n + n_seg ? Point_kind::boundary : Point_kind::sampled, -1);
  }
  for (const Vec2& x : repair_points) out.add(x, Point_kind::sampled, -1);
  return out;
}

// Constraint pieces between consecutive kept points (input points and segment
// candidates) along every chain.
std::vector<Constraint_piece> pieces_along_chains(const Mesh_arrays& mesh, const std::vector<Segment_chain>& chains,
                                                  const Candidates& on_segments, const std::vector<Index>& out_index,
                                                  std::vector<Piece_span>* spans) {
  // The candidates on segment s are n + [begin[s], begin[s + 1]), sorted along it.
  std::vector<Index> begin(mesh.segments.size() + 1, 0);
  for (Index parent : on_segments.samples.parent) ++begin[parent + 1];
  for (std::size_t s = 0; s < mesh.segments.size(); ++s) begin[s + 1] += begin[s];
  if (!mesh.segment_keys.empty()) {
    // The segments' runs of candidates come in key order (sample_segments): laid out by position here.
    const std::size_t n = mesh.points.size();
    std::vector<Index> by_position(on_segments.size());
    std::vector<Index> next(begin.begin(), begin.end() - 1);
    for (std::size_t j = 0; j < on_segments.size(); ++j) by_position[next[on_segments.samples.parent[j]]++] = out_index[n + j];
    return constraint_pieces(chains, out_index, begin, by_position, spans);
  }
  for (Index& b : begin) b += static_cast<Index>(mesh.points.size());
  return constraint_pieces(chains, out_index, begin, out_index, spans);
}

std::size_t keep_crossed_chain_vertices(const Mesh_arrays& mesh, const std::vector<Segment_chain>& chains,
                                        const Candidates& on_segments, std::vector<Index>& out_index,
                                        Selection& selection, std::vector<Constraint_piece>& pieces,
                                        std::vector<std::pair<Index, Vec2>>& moves, std::size_t& undone) {
  std::vector<Vec2>& points = selection.mesh.points;
  std::size_t kept = 0;
  std::vector<Piece_span> spans;
  std::vector<Index> again;
  for (;;) {
    // (moves undone already leave the list: keep_pieces_apart counts each once)
    moves.erase(std::remove_if(moves.begin(), moves.end(), [&](const auto& m) { return points[m.first] == m.second; }),
                moves.end());
    undone += keep_pieces_apart(points, pieces, moves);
    const auto pairs = meeting_pieces(points, pieces, /*touching=*/false);
    if (pairs.empty()) return kept;
    if (spans.empty()) pieces_along_chains(mesh, chains, on_segments, out_index, &spans);
    again.clear();
    for (const auto& pair : pairs) {
      for (const Index p : pair) {
        const Piece_span& span = spans[p];
        const Vec2 &a = points[pieces[p].a], &b = points[pieces[p].b];
        const double dx = b[0] - a[0], dy = b[1] - a[1];
        Index farthest = -1;
        double largest = -1;
        for (Index i = span.first; i < span.last; ++i) {
          const Vec2& x = mesh.points[chains[span.chain].vertices[i]];
          const double away = std::abs(dx * (x[1] - a[1]) - dy * (x[0] - a[0]));  // (times the chord's length)
          if (away > largest) {
            largest = away;
            farthest = chains[span.chain].vertices[i];
          }
        }
        if (farthest >= 0) again.push_back(farthest);
      }
    }
    if (again.empty()) return kept;  // (the triangulation names the pair)
    std::sort(again.begin(), again.end());
    again.erase(std::unique(again.begin(), again.end()), again.end());
    for (const Index v : again) {
      out_index[v] = static_cast<Index>(points.size());
      selection.add(mesh.points[v], kept_point_kind(mesh.kind[v], /*forced_corner=*/false), v);
    }
    kept += again.size();
    pieces = pieces_along_chains(mesh, chains, on_segments, out_index, &spans);
  }
}

}  // namespace frfc_stages


namespace {

using detail::Stage_timer;
using frfc_stages::Packing;

// The paper's step: every stage on the whole mesh, f from one Apollonius graph
// of all sites (step_spacing).
class Whole_mesh final : public Step_scope {
 public:
  Whole_mesh(const Frfc_options& options, const Step_context& context) : options_(options), context_(context) {}

  Scope_spacing spacing(const Mesh_arrays& mesh, const std::vector<double>& delta,
                        const std::vector<Segment_chain>& chains, Stage_timer& timer) override {
    Step_spacing spacing = step_spacing(mesh, delta, F_at_points::lemma_3_1, /*threads=*/0, timer,
                                        options_.within_domain ? &chains : nullptr, context_.filter_sites);
    function_ = std::move(spacing.function);
    queries_ = spacing_queries(*function_);
    frfc_stages::release_free_memory(context_);  // what building the Apollonius graphs in parallel freed
    return {std::move(spacing.nn), std::move(spacing.f), {}};
  }
  const Spacing_queries* grid_queries(const Mesh_arrays&, const std::vector<double>&) override { return &queries_; }
  void f_at_candidates(const Mesh_arrays&, const std::vector<double>&, Candidates& candidates, bool,
                       Stage_timer&) override {
    // (a floating-point walk to the site the exact settle step starts from: the same answers, faster)
    detail::parallel_resize(candidates.radius, candidates.size());
    function_->evaluate(candidates.samples.points.data(), candidates.size(), candidates.radius.data(), nullptr,
                        /*threads=*/0, /*certified=*/false);
  }
  Packing first_pass(const Mesh_arrays& mesh, const Scope_spacing& spacing, const Candidates& on_segments,
                     const std::vector<std::uint8_t>& forced, std::size_t n_forced,
                     const std::vector<std::uint8_t>& demoted) override {
    return frfc_stages::first_packing_pass(mesh, spacing.f, on_segments, forced, n_forced, demoted, options_);
  }
  // (alive with the Apollonius graph during the sampling, the triangulation set the step's peak memory)
  bool starts_triangulation_early() const override { return false; }
  std::vector<std::uint8_t> quiet_triangles(const Mesh_arrays&, const std::vector<double>&, const Packing&,
                                            const std::vector<std::uint8_t>&, const std::vector<std::uint8_t>&,
                                            Stage_timer&) override {
    return {};
  }
  void sampled(const Mesh_arrays&, const std::vector<std::uint8_t>&) override {}
  void spacing_done() override {
    n_hidden_ = function_->n_hidden();
    n_filtered_ = function_->n_filtered();
    queries_ = nullptr;
    function_.reset();
  }
  void second_pass(const Mesh_arrays&, Candidates& inside, Packing& packing) override {
    frfc_stages::second_packing_pass(inside, packing);
  }
  // (alive with the packing after the repair, they would add to the peak)
  bool keeps_fans() const override { return false; }
  const std::vector<double>* reusable_nn(const Scope_spacing&) override { return nullptr; }
  // (the graph of every site, the candidates of the whole mesh: hundreds of MiB at 1e6)
  bool releases_memory_between_stages() const override { return true; }
  void add_counts(std::vector<std::pair<std::string, double>>& stats) const override {
    stats.emplace_back("n_hidden_sites", static_cast<double>(n_hidden_));
    stats.emplace_back("n_filtered_sites", static_cast<double>(n_filtered_));
    stats.emplace_back("incremental_step", 0);
  }

 private:
  const Frfc_options& options_;
  const Step_context& context_;
  std::unique_ptr<Spacing_function> function_;
  Spacing_queries queries_;
  std::size_t n_hidden_ = 0, n_filtered_ = 0;
};

}  // namespace

// The outline of one step (Section 3.2), the same for every scope; the numbers
// are the paper's steps.
Evolve_result frfc_over_scope(const Mesh_arrays& input, const Mesh_arrays& mesh, const std::vector<double>& delta,
                              const Frfc_options& options, const Step_context& context, Step_scope& scope) {
  using namespace frfc_stages;
  const std::size_t n = mesh.points.size();
  Evolve_result result;
  Stage_timer timer(result.stats, context.profile);
  // Every stage runs its loops under this limit (parallel_for(..., 0, ...)).
  const Thread_limit thread_limit(context.threads);
  // The context's memory policy, where the scope's stages free enough for it to pay.
  const auto release_free_memory = [&context, &scope] {
    if (scope.releases_memory_between_stages()) frfc_stages::release_free_memory(context);
  };
  // Memory: what a stage leaves behind goes as soon as nothing reads it.

  // Step 1: nn_M and the spacing function f (Section 3.1), within the domain.
  const auto chains = segment_chains(mesh);
  Scope_spacing spacing = scope.spacing(mesh, delta, chains, timer);
  const std::vector<double>& f = spacing.f;

  // Steps 2-5: candidates on segments, first packing pass; interior candidates, second pass.
  // Old points whose neighbourhood the request refines lose their priority.
  std::size_t n_forced = 0;
  const auto forced = forced_corners(mesh, chains, n_forced, mesh.required);
  auto demoted = demoted_points(mesh.triangles, spacing.nn, f, forced, options.demote_ratio);
  // Step 2a: candidates on segments (grid samples and ring candidates, snapped
  // to straight chains) and their spheres.
  const Spacing_queries* queries = scope.grid_queries(mesh, f);
  try {
    check_sample_budget(
        estimate_sample_count(mesh, f, options.cell_factor, options.max_samples, options.adaptive_cells, queries),
        options.max_samples, "sampling");
  } catch (const Input_error& error) {
    // The place where the request is finest (a feature the spacing follows there: an interface's pieces close together).
    const std::size_t n = std::min(f.size(), mesh.points.size());
    if (n == 0) throw;
    const std::size_t k = static_cast<std::size_t>(std::min_element(f.begin(), f.begin() + n) - f.begin());
    char place[200];
    std::snprintf(place, sizeof place, "; the finest spacing asked is %.4g, at (%.9g, %.9g)", f[k], mesh.points[k][0],
                  mesh.points[k][1]);
    throw Input_error(error.what() + std::string(place));
  }
  // Points whose request is the spacing they have (candidates.hpp): no grid
  // samples on a segment or in a triangle with every vertex settled.
  const std::vector<std::uint8_t> settled =
      options.skip_settled ? settled_points(mesh, delta, f) : std::vector<std::uint8_t>();
  const std::vector<std::uint8_t>* settled_flags = options.skip_settled ? &settled : nullptr;
  // The candidates' sphere radii (candidates.hpp) from f at them, as the scope evaluates it.
  const auto sphere_radii = [&](Candidates& candidates, bool on_segment) {
    if (options.radius != Radius_rule::cheap) scope.f_at_candidates(mesh, f, candidates, on_segment, timer);
    candidate_radii_from_f(mesh, f, demoted, options, on_segment, candidates);
  };
  Candidates on_segments = segment_candidates(mesh, delta, f, chains, options, queries, settled_flags);
  const std::size_t n_seg = on_segments.size();
  timer.lap("sampling");
  sphere_radii(on_segments, /*on_segment=*/true);
  timer.lap("sample_radii");
  Packing packing = scope.first_pass(mesh, spacing, on_segments, forced, n_forced, demoted);
  std::optional<Early_start> early;
  if (scope.starts_triangulation_early()) early.emplace(packing, options, mesh.geometry != nullptr);
  timer.lap("lfmis");

  // Step 2b: interior candidates (grid samples and ring candidates, less those
  // the first pass certainly blocks) and their spheres.
  std::optional<Triangle_fans> fans(mesh);
  std::size_t n_drawn = 0;
  Candidates inside;
  {
    Cover_discs cover;
    if (options.filter_samples) {
      cover = cover_discs(mesh, f, packing.radius, packing.kept, packing.blocker, options.radius_scale,
                          options.radius == Radius_rule::interpolated);
    }
    const std::vector<std::uint8_t> quiet = scope.quiet_triangles(mesh, delta, packing, demoted, settled, timer);
    inside = interior_candidates(mesh, *fans, delta, f, demoted, cover, options, n_drawn,
                                 quiet.empty() ? nullptr : &quiet, queries, settled_flags);
    scope.sampled(mesh, quiet);
  }
  release_free_memory();  // the sampling threads' blocks
  timer.lap("sampling");
  sphere_radii(inside, /*on_segment=*/false);
  timer.lap("sample_radii");
  if (options.filter_samples) {
    drop_blocked_candidates(mesh, packing.centers, packing.radius, packing.kept, packing.blocker, /*threads=*/0,
                            inside);
  }
  const std::size_t n_interior = inside.size();
  scope.spacing_done();  // the candidates' radii were the graphs' last use
  release_free_memory();
  // The quality pass's triangulation of the first pass's points starts on the
  // second thread (unless the scope started it already) beside the second pass
  // when that is small, else after it: its tree of every candidate (about 36
  // bytes each) is the peak of a step with several candidates per input point.
  if (!early && inside.size() + packing.deferred.size() <= n) early.emplace(packing, options, mesh.geometry != nullptr);
  scope.second_pass(mesh, inside, packing);
  inside = Candidates();
  release_free_memory();
  if (!early) early.emplace(packing, options, mesh.geometry != nullptr);
  early->insert_late(packing, n, n + n_seg);
  const std::size_t n_candidates = packing.centers.size();
  drop_rejected_candidates(n + n_seg, packing);
  release_free_memory();
  timer.lap("lfmis");

  // The spacing repair (spacing_repair.hpp), when asked for and ring candidates were offered.
  std::size_t n_repairs = 0;
  std::vector<Vec2> repair_points;
  if ((options.repair_ratio > 0 && options.ring_samples) || options.gap_repair_ratio > 0 ||
      options.refine_gap_ratio > 0) {
    const Spacing_repair_input repair{mesh, *fans, delta, spacing.nn, f, packing.centers, on_segments.owner, demoted};
    repair_points = repair_spacing(repair, options, packing.kept, n_repairs);
  }
  demoted = std::vector<std::uint8_t>();
  early->insert_rest(packing, n, n + n_seg, repair_points);
  timer.lap("spacing_repair");
  if (!scope.keeps_fans()) fans.reset();

  // Step 6: the kept points (on curves, moved onto them), the constraint pieces
  // between them, their triangulation.
  std::vector<std::pair<std::size_t, Vec2>> interior_moves;  // (candidate, where it was)
  if (mesh.geometry) {
    project_segment_candidates(mesh, on_segments.samples.parent, n, packing.kept, packing.radius, packing.centers,
                               &interior_moves);
  }
  std::vector<Index> out_index;
  Selection selection = select_output(mesh, forced, packing, n_seg, repair_points, out_index);
  auto pieces = pieces_along_chains(mesh, chains, on_segments, out_index);
  if (mesh.geometry) {
    // Candidates of interior chains whose moves onto the curve make pieces
    // cross or touch (a fold narrower than the spacing) stay on their chords;
    // pieces that still cross get chain vertices back.
    std::vector<std::pair<Index, Vec2>> at_output;
    for (const auto& [c, before] : interior_moves) {
      if (out_index[c] >= 0) at_output.emplace_back(out_index[c], before);
    }
    std::size_t undone = 0;
    const std::size_t kept_again =
        keep_crossed_chain_vertices(mesh, chains, on_segments, out_index, selection, pieces, at_output, undone);
    result.stats.emplace_back("curve_samples_left_on_chords", static_cast<double>(undone));
    result.stats.emplace_back("chain_points_kept_across_crossings", static_cast<double>(kept_again));
  }
  selection.pin(mesh.required);
  const std::size_t n_demoted = packing.n_demoted;
  packing = Packing();
  out_index = std::vector<Index>();
  const Quality_options quality = options.quality_settings();
  // The old mesh's walker (parent map) is built on another thread while the
  // early triangulation takes the repair's points: both before the quality
  // pass, which runs on this thread.
  std::optional<Old_mesh_start> old_mesh;
  if (fans) old_mesh.emplace(input, /*threads=*/0, std::move(fans));
  else old_mesh.emplace(input, /*threads=*/0);
  const auto waited = std::chrono::steady_clock::now();
  early->wait();
  const double wait_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - waited).count();
  release_free_memory();
  const bool early_started = options.quality && !mesh.geometry;
  std::optional<std::vector<Triangle>> triangles;
  if (!options.quality && !mesh.geometry) triangles = scope.triangulation(selection, pieces, *old_mesh, result.stats);
  // An updated triangulation is certified strictly Delaunay (the next step's
  // update then checks only what it changes); one built whole is not checked.
  const bool certified = triangles.has_value();
  triangulate_selection(std::move(selection), pieces, options.quality ? &quality : nullptr, result,
                        early_started ? &early->triangulation : nullptr, mesh.geometry.get(),
                        triangles ? &*triangles : nullptr);
  release_free_memory();
  timer.lap(options.quality ? "quality" : "cdt");
  finish_step(input, result, timer, &*old_mesh, scope.reusable_nn(spacing), scope.same_fans());
  scope.add_counts(result.stats);
  result.triangulation_certified = certified;
  result.stats.emplace_back("triangulation_certified", certified ? 1.0 : 0.0);
  // (not "seconds_" stages: the batches run beside the others; the quality
  // stage includes the wait for them)
  result.stats.emplace_back("early_triangulation_insert_seconds", early->insert_seconds);
  result.stats.emplace_back("early_triangulation_wait_seconds", wait_seconds);
  add_step_counts(result, {{"n_input_points", n},
                           {"n_segment_samples", n_seg},
                           {"n_interior_samples", n_interior},
                           {"n_interior_samples_drawn", n_drawn},
                           {"n_candidates", n_candidates},
                           {"n_demoted_points", n_demoted},
                           {"n_spacing_repairs", n_repairs}});
  result.input_nn = std::move(spacing.nn);
  result.input_f = std::move(spacing.f);
  return result;
}

Evolve_result frfc(const Mesh_arrays& input, const std::vector<double>& delta, const Frfc_options& options,
                   const Step_context& context) {
  check_delta(input, delta);
  options.validate();
  // The scope is chosen here, before any work, from O(n) counts; what a scope
  // throws propagates (a bug there must show, not cost a second step).
  // First, with delta = 1 everywhere: a step that certainly returns its input
  // (empty_scope.hpp; the certificate, O(n), in empty_scope.cpp) returns it.
  int declined_by = 0;
  if (auto unchanged = empty_scope_frfc(input, delta, options, context, &declined_by)) return std::move(*unchanged);
  Evolve_result result;
  if (options.incremental && incremental_applies(input, delta, options)) {
    // Where delta = 1 on most of the mesh: the same step at the cost of the change (incremental_step.hpp).
    result = incremental_frfc(input, delta, options, context);
  } else {
    // With curved boundaries, the corners of curved chains come from the geometry.
    const Mesh_arrays with_curves = input.geometry ? with_curve_kinds(input) : Mesh_arrays{};
    const Mesh_arrays& mesh = input.geometry ? with_curves : input;
    Whole_mesh scope(options, context);
    result = frfc_over_scope(input, mesh, delta, options, context, scope);
  }
  result.stats.emplace_back("empty_scope", 0.0);
  result.stats.emplace_back("empty_scope_declined_by", declined_by);
  return result;
}

}  // namespace evomesh
