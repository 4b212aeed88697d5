#include "evomesh/empty_scope.hpp"

#include <algorithm>
#include <cstdint>
#include <limits>
#include <utility>

#include "evomesh/candidates.hpp"
#include "evomesh/kernel.hpp"
#include "evomesh/local_feature_size.hpp"
#include "evomesh/packing.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/quality_pass.hpp"
#include "evomesh/sampling.hpp"
#include "evomesh/segment_chains.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/detail/delaunay_mesher.hpp"

namespace evomesh {

// Why the full step (frfc.cpp, the stages in its order) returns the input when
// every certificate below holds. Write M for the input, n its points.
//
// Dispatch. No curves (mesh.geometry null): the full step works on M itself,
// not on with_curve_kinds(M), and fits nothing to curves.
//
// Step 1 (step_spacing, F_at_points::lemma_3_1). The same step_weights call as
// the full step gives nn and w = delta nn (capped by the local feature size
// within the domain). No point's nn grew within the domain (`evaluate` all
// zero) and delta = 1 everywhere, so f(p) = w_p exactly (Lemma 3.1: no
// Apollonius query); f is `weight` bit for bit. (C1: delta == 1, C7: none grew.)
//
// Steps 2-5, candidates. Every point is settled (settled_points with this f;
// C8). With skip_settled (C0): segment_candidates drops every grid sample (both
// ends of every segment settled) and adds ring candidates only at ends with
// delta < 1 (none); interior_candidates skips every triangle and adds rings
// only at delta < 1 (none). No candidate at all. The sample budget check before
// sampling (check_sample_budget) passes: estimate_sample_count's fine grid
// bounds its adaptive count ("the fine grid's count bounds the adaptive
// grid's", sampling.cpp), and the fine count (adaptive = false, no queries
// needed) is within max_samples (C9).
//
// Packing. demoted_points (the same call) demotes none (C10), so the first
// pass holds the n input points alone and the second pass nothing. Spheres are
// B(p, r_p), r_p = radius_scale * f(p) / 2 (times boundary_scale <= 1 on
// segments): f(p) = w_p <= nn(p) <= |p - q| for every other q, so
// r_p + r_q <= radius_scale |p - q| and, with radius_scale <= 0.999 (C0), the
// packing's floating-point overlap test (|p - q|^2 < (r_p + r_q)^2) is false
// for every pair by a margin far above rounding: the MIS keeps every point.
//
// Spacing repair (repair_spacing). The ring repair serves kept points with
// delta < 1 only: none. The gap repair opens a kept point p only if no kept
// mesh neighbour q has |p - q|^2 (1 + 1e-9) <= (gap_repair_ratio nn(p))^2;
// settled p has an edge of length L <= f(p) / (1 - 8 eps) <= nn(p) (1 + 9 eps),
// so with gap_repair_ratio = 0 (no bound) or >= 1.001 (C0) none is open
// (refine_gap_ratio applies where delta < 1 only). No repair point.
//
// Selection. Every input point, in input order (output index = input index),
// kind kept_point_kind(kind, forced corner); the constraint pieces are the
// chains' consecutive points: one piece per segment, with its chain's boundary
// flag, which is the segment's own (C4), directed along the chain (flipped on
// a boundary chain whose first segment runs backwards, constraint_pieces).
//
// Triangulation (constrained Delaunay, or the quality pass's start). M is an
// edge-manifold disc (C3: each edge in at most two triangles, oppositely
// directed; V - E + F = 1; one boundary loop), all its triangles counter-
// clockwise (C2, exact), its boundary loop turns left or goes straight at every
// vertex (C5, exact): a locally injective map of a disc whose boundary goes
// once around a convex polygon is an embedding, so M triangulates the convex
// hull of its points. Its boundary edges are exactly its boundary segments
// (C4), each directed as its piece with M on its left (C6), and its other
// segments have triangles on both sides. Every unconstrained edge is strictly
// locally Delaunay (C11, exact incircle): M is the constrained Delaunay
// triangulation of the points and pieces, and the only one (no unconstrained
// edge could flip), so CGAL's CDT holds M's triangles, whatever the insertion
// order (early triangulation or not). label_domain: the infinite faces are
// outside, every hull edge is a boundary piece, so the outside fill stops
// there; every finite face is inside (the left side of every boundary piece is
// M's triangle, C6): the domain faces are M's triangles.
//
// Quality pass (options.quality). drop_crowding_points removes an apex only
// when it sees its piece under more than crowding_angle; every apex of a piece
// sees it under an acute angle (C12, exact), and crowding_angle is off or
// >= 91 degrees (C0: the floating-point cosine test cannot call an acute angle
// obtuse by more than rounding): no point removed, no segment queued. The edge
// level's Gabriel test (CGAL's: the apex angle ACUTE, exact) holds on both
// sides of every constraint edge (the side outside the hull is infinite, which
// conforms), whatever the domain sides and clusters say: nothing encroached.
// The face level's Is_bad (rule 3 only: FRFC passes no spacing data) is
// Refinement_criteria::angle_badness on the face's points scaled by
// unit_scaling (the scaling both triangulations use, all points being in the
// first batch), in the face's rotation, which is one of the three tested
// (C13): no bad face. The mesher inserts nothing; a CGAL failure falls back to
// the same CDT.
//
// finish_step. restore_origins: no new point, nothing restored.
// adopt_input_order: same points in order, same triangle and segment sets
// (with boundary flags): "unchanged", the input's triangles, segments, flags,
// tags and required flags. parent_map: every point kept, so every triangle -1
// and barycentric zero. Output nn: nn_spacing of the output points (the
// input's, C7 makes it step 1's nn), keep_within_domain on the input's
// triangles grows none (C7). input_nn, input_f: step 1's nn and f.
namespace {

using detail::Stage_timer;

// C0: the options under which the argument holds.
bool options_allow(const Frfc_options& options) {
  if (!options.incremental || !options.skip_settled) return false;
  if (!(options.radius_scale <= 0.999)) return false;
  if (options.gap_repair_ratio > 0 && !(options.gap_repair_ratio >= 1.001)) return false;
  if (options.quality && options.crowding_angle > 0 && !(options.crowding_angle >= 91)) return false;
  return true;
}

// Per directed triangle edge 3t + k (t[k] -> t[k+1]): the triangle across it
// (-1: none), whether a segment lies on it; and the directed edges leaving
// each vertex (compressed lists: `xadj`, `target`, `half` = 3t + k), which
// keep the neighbours of a vertex near it in memory (points in spatial order).
struct Edge_table {
  std::vector<Index> across;
  std::vector<std::uint8_t> constrained;
  std::vector<Index> xadj, target;
  std::vector<std::uint32_t> half;

  // The directed edge u -> v (3t + k), or -1.
  std::int64_t find(Index u, Index v) const {
    for (Index j = xadj[u]; j < xadj[u + 1]; ++j) {
      if (target[j] == v) return half[j];
    }
    return -1;
  }
};

// False when M is not an edge-manifold, consistently oriented triangulation
// (C3: a directed edge twice), or a segment is not an edge of it or given twice.
bool build_edge_table(const Mesh_arrays& mesh, Edge_table& table) {
  const std::size_t n = mesh.points.size(), m = mesh.triangles.size();
  table.across.assign(3 * m, -1);
  table.constrained.assign(3 * m, 0);
  table.xadj.assign(n + 1, 0);
  for (const Triangle& tri : mesh.triangles) {
    for (Index v : tri) ++table.xadj[v + 1];
  }
  for (std::size_t v = 0; v < n; ++v) table.xadj[v + 1] += table.xadj[v];
  table.target.resize(3 * m);
  table.half.resize(3 * m);
  {
    std::vector<Index> fill(table.xadj.begin(), table.xadj.end() - 1);
    for (std::size_t t = 0; t < m; ++t) {
      const Triangle& tri = mesh.triangles[t];
      for (int k = 0; k < 3; ++k) {
        const Index at = fill[tri[k]]++;
        table.target[at] = tri[(k + 1) % 3];
        table.half[at] = static_cast<std::uint32_t>(3 * t + k);
      }
    }
  }
  for (std::size_t u = 0; u < n; ++u) {
    for (Index j = table.xadj[u]; j < table.xadj[u + 1]; ++j) {
      const Index w = table.target[j];
      for (Index i = j + 1; i < table.xadj[u + 1]; ++i) {
        if (table.target[i] == w) return false;  // u -> w twice
      }
      const std::int64_t twin = table.find(w, static_cast<Index>(u));
      if (twin >= 0) table.across[table.half[j]] = static_cast<Index>(twin / 3);
    }
  }
  for (const Edge& e : mesh.segments) {
    bool any = false;
    for (const std::int64_t h : {table.find(e[0], e[1]), table.find(e[1], e[0])}) {
      if (h < 0) continue;
      if (table.constrained[h]) return false;  // the same segment twice
      table.constrained[h] = 1;
      any = true;
    }
    if (!any) return false;  // a segment that is no edge
  }
  return true;
}

// C3-C6: segments against the triangulation and the boundary loop.
bool boundary_certified(const Mesh_arrays& mesh, const std::vector<Segment_chain>& chains, const Edge_table& table) {
  const std::size_t n = mesh.points.size(), m = mesh.triangles.size();
  // C4: a segment of an interior chain has triangles on both sides, one of a
  // boundary chain on exactly one, the left of its piece (C6); segment flags
  // as their chain's.
  for (const Segment_chain& chain : chains) {
    const bool flip = chain.boundary && !chain.forward.front();
    for (std::size_t k = 0; k < chain.segments.size(); ++k) {
      const Index s = chain.segments[k];
      if ((mesh.segment_is_boundary[s] != 0) != chain.boundary) return false;
      const Edge& e = mesh.segments[s];
      Index a = chain.forward[k] ? e[0] : e[1], b = chain.forward[k] ? e[1] : e[0];
      if (flip) std::swap(a, b);
      const bool left = table.find(a, b) >= 0;
      const bool right = table.find(b, a) >= 0;
      if (chain.boundary ? !(left && !right) : !(left && right)) return false;
    }
  }
  // C4: every edge with one triangle is a segment (then a boundary one, above).
  // C5: the boundary edges (directed with M on the left) form one loop turning
  // left or going straight on at every vertex; C3: V - E + F = 1.
  std::vector<Index> next(n, -1);
  std::size_t n_boundary = 0;
  Index start = -1;
  for (std::size_t t = 0; t < m; ++t) {
    for (int k = 0; k < 3; ++k) {
      if (table.across[3 * t + k] >= 0) continue;
      if (!table.constrained[3 * t + k]) return false;
      const Index u = mesh.triangles[t][k], v = mesh.triangles[t][(k + 1) % 3];
      if (next[u] >= 0) return false;  // a vertex where the boundary pinches
      next[u] = v;
      start = u;
      ++n_boundary;
    }
  }
  if (start < 0) return false;
  const std::size_t n_edges = (3 * m + n_boundary) / 2;
  if (n + m != n_edges + 1) return false;
  std::size_t length = 0;
  Index u = start;
  do {
    const Index v = next[u];
    const Index w = next[v];
    if (w < 0) return false;
    const Point_2 a = to_cgal(mesh.points[u]), b = to_cgal(mesh.points[v]), c = to_cgal(mesh.points[w]);
    const CGAL::Orientation turn = CGAL::orientation(a, b, c);
    if (turn == CGAL::RIGHT_TURN) return false;
    if (turn == CGAL::COLLINEAR && !CGAL::collinear_are_strictly_ordered_along_line(a, b, c)) return false;
    u = v;
    if (++length > n_boundary) return false;
  } while (u != start);
  return length == n_boundary;
}

// C2, C11-C13 over the triangles: 0, or the first certificate that fails.
int triangles_certified(const Mesh_arrays& mesh, const Edge_table& table, const Frfc_options& options) {
  const auto& P = mesh.points;
  const detail::Scaling scaling = detail::unit_scaling(P);
  const double bound = detail::Refinement_criteria::angle_bound(options.quality_settings().min_angle);
  auto scaled = [&](Index i) { return Point_2(P[i][0] * scaling.to_unit, P[i][1] * scaling.to_unit); };
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Triangle& tri = mesh.triangles[t];
    const Point_2 a = to_cgal(P[tri[0]]), b = to_cgal(P[tri[1]]), c = to_cgal(P[tri[2]]);
    if (CGAL::orientation(a, b, c) != CGAL::LEFT_TURN) return 2;
    const Point_2 corner[3] = {a, b, c};
    for (int k = 0; k < 3; ++k) {
      const Index other = table.across[3 * t + k];
      const Point_2& apex = corner[(k + 2) % 3];
      if (table.constrained[3 * t + k]) {
        // C12: the apex sees its constraint edge under an acute angle.
        if (options.quality && CGAL::angle(corner[k], apex, corner[(k + 1) % 3]) != CGAL::ACUTE) return 12;
      } else if (other >= 0 && other > static_cast<Index>(t)) {
        // C11: the vertex across is strictly outside the circumcircle.
        const Triangle& o = mesh.triangles[other];
        Index d = o[0];
        for (Index v : o) {
          if (v != tri[k] && v != tri[(k + 1) % 3]) d = v;
        }
        if (CGAL::side_of_oriented_circle(a, b, c, to_cgal(P[d])) != CGAL::ON_NEGATIVE_SIDE) return 11;
      }
    }
    if (options.quality) {
      // C13: not bad for the angle rule, in each of the face's rotations.
      const Point_2 s[3] = {scaled(tri[0]), scaled(tri[1]), scaled(tri[2])};
      for (int r = 0; r < 3; ++r) {
        double q;
        if (detail::Refinement_criteria::angle_badness(s[r], s[(r + 1) % 3], s[(r + 2) % 3], bound, q) !=
            CGAL::Mesh_2::NOT_BAD) {
          return 13;
        }
      }
    }
  }
  return 0;
}

}  // namespace

std::optional<Evolve_result> empty_scope_frfc(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                              const Frfc_options& options, const Step_context& context,
                                              int* declined_by) {
  const std::size_t n = mesh.points.size();
  auto decline = [declined_by](int certificate) {
    if (declined_by != nullptr) *declined_by = certificate;
    return std::nullopt;
  };
  // C0, C1, no curves: O(1) and one pass over delta.
  if (mesh.geometry || !options_allow(options) || mesh.triangles.empty()) return decline(0);
  for (double d : delta) {
    if (d != 1) return decline(1);
  }
  Evolve_result result;
  Stage_timer timer(result.stats, context.profile);
  const Thread_limit thread_limit(context.threads);  // (step_weights' trees, as in the full step)
  // C2-C6, C11-C13: the triangulation is the step's triangulation, untouched
  // by the quality pass. O(n) over the directed edges.
  Edge_table table;
  if (!build_edge_table(mesh, table)) return decline(3);
  const auto chains = segment_chains(mesh);
  if (!boundary_certified(mesh, chains, table)) return decline(4);  // (C3-C6: reported as 4)
  const int failed = triangles_certified(mesh, table, options);
  if (failed != 0) return decline(failed);
  table = Edge_table();
  timer.lap("empty_scope_mesh");
  // Step 1 as the full step computes it (C7).
  Step_weights weights = step_weights(mesh, delta, timer, options.within_domain ? &chains : nullptr);
  for (std::uint8_t e : weights.evaluate) {
    if (e) return decline(7);
  }
  std::vector<double> output_nn;  // finish_step's: nn_spacing of the output points
  if (options.within_domain && !mesh.nn_within_domain.empty()) {
    output_nn = nn_spacing(mesh.points);
    if (!mesh.nn_grew.empty() || output_nn != weights.nn) return decline(7);
  } else {
    output_nn = weights.nn;
    if (!options.within_domain) {
      std::vector<double> within = output_nn;
      const auto grew = keep_within_domain(mesh.points, mesh.triangles, within);
      if (std::find(grew.begin(), grew.end(), 1) != grew.end()) return decline(7);
    }
  }
  const std::vector<double>& f = weights.weight;  // Lemma 3.1 at delta = 1
  // C8: every point settled.
  const auto settled = settled_points(mesh, delta, f);
  if (std::find(settled.begin(), settled.end(), 0) != settled.end()) return decline(8);
  // C9: the sample budget.
  if (!(estimate_sample_count(mesh, f, options.cell_factor, options.max_samples, /*adaptive=*/false, nullptr) <=
        options.max_samples)) {
    return decline(9);
  }
  // C10: none demoted; the forced corners give the kinds.
  std::size_t n_forced = 0;
  const auto forced = forced_corners(mesh, chains, n_forced, mesh.required);
  const auto demoted = demoted_points(mesh.triangles, weights.nn, f, forced, options.demote_ratio);
  if (std::find(demoted.begin(), demoted.end(), 1) != demoted.end()) return decline(10);
  timer.lap("empty_scope_spacing");

  // The full step's output, as finish_step's unchanged path returns it.
  Mesh_arrays& out = result.mesh;
  out.points = mesh.points;
  out.triangles = mesh.triangles;
  out.segments = mesh.segments;
  out.segment_is_boundary = mesh.segment_is_boundary;
  out.kind.resize(n);
  for (std::size_t i = 0; i < n; ++i) out.kind[i] = kept_point_kind(mesh.kind[i], forced[i] == kForcedCorner);
  out.segment_tags = mesh.segment_tags;
  out.triangle_tags = mesh.triangle_tags;
  out.required = mesh.required;
  result.origin.resize(n);
  for (std::size_t i = 0; i < n; ++i) result.origin[i] = static_cast<Index>(i);
  result.parents.triangle.assign(n, -1);
  result.parents.barycentric.assign(n, {0.0, 0.0, 0.0});
  result.output_nn = std::move(output_nn);
  result.input_f = std::move(weights.weight);
  result.input_nn = std::move(weights.nn);
  const auto angle = smallest_angle(out.points, out.triangles);
  timer.lap("empty_scope_output");
  auto& stats = result.stats;
  double seconds = 0;
  for (const auto& s : stats) {
    if (s.first.rfind("seconds_", 0) == 0) seconds += s.second;
  }
  stats.emplace_back("min_angle", angle.first);
  stats.emplace_back("min_angle_x", angle.second[0]);
  stats.emplace_back("min_angle_y", angle.second[1]);
  stats.emplace_back("restored_points", 0.0);
  stats.emplace_back("unchanged", 1.0);
  stats.emplace_back("seconds_total", seconds);
  add_step_counts(result, {{"n_input_points", n}, {"incremental_step", 0}, {"empty_scope", 1}});
  return result;
}

}  // namespace evomesh
