#include "evomesh/empty_scope.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <utility>

#include "evomesh/boundary_geometry.hpp"
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
#include "evomesh/detail/domain.hpp"
#include "evomesh/detail/insert_points.hpp"

namespace evomesh {

// Why the full step (frfc.cpp, the stages in its order) returns the input when
// every certificate below holds. Write M for the input, n its points.
//
// Dispatch. Without curves the full step works on M itself; with curves
// (mesh.geometry) on with_curve_kinds(M): the same points, triangles and
// segments, the kinds of curved chains from the geometry, zero tags where M
// has none. The certificates below read what the stages read (that mesh); the
// output takes the points, triangles, segments and tags of M, the kinds of
// that mesh (what the full step's selection gives them).
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
// Triangulation (constrained Delaunay, or the quality pass's start). M may
// have holes and need not be convex. Its triangles are counter-clockwise (C2,
// exact); each directed edge lies in at most one triangle and every point in
// one (C3); the edges with a triangle on one side only are exactly the
// boundary segments, each directed as its piece with M on its left, and one
// such edge enters and one leaves each boundary vertex (C4). Write dM for
// these directed boundary edges.
//
// M is embedded and D, the union of its triangles, is bounded by dM alone.
// For x on no edge, the number of triangles of M holding x is the winding
// number w(x) of dM around x: each counter-clockwise triangle contributes the
// winding number of its own boundary, and an interior edge's two directions
// cancel (C3). B, the constrained Delaunay triangulation of the boundary
// vertices and dM alone (boundary_certified), has every edge of dM as an edge
// (C5: no two boundary edges cross, no boundary vertex lies on another
// boundary edge or at another's coordinates), and label_domain, the full
// step's own labelling, succeeds on B (C5): every region of the plane between
// the loops of dM lies on the left of every edge of dM around it, or on the
// right of all of them, and the unbounded region on the right. Across an edge
// of dM, w grows by 1 from its right to its left; starting from the unbounded
// region (w = 0) and crossing one loop at a time, w is 1 on the regions
// labelled inside and 0 on the others. So no two triangles overlap, and a
// vertex never lies inside another triangle or edge, nor at another vertex's
// coordinates (near it its own triangles would overlap that triangle or the
// outside region next to that boundary edge, where w = 0): D is the inside of
// B's labelling, M a triangulation of D whose boundary edges are its boundary
// pieces. The rest of the plane (within the convex hull of the points, which
// is the hull of the boundary vertices) is the hidden regions H: no point lies
// inside them, and their boundaries are constraint edges of dM and hull edges.
//
// The full step's CDT T contains every piece (no crossing, no point on one:
// pieces are whole edges of T), so T is a triangulation of D and one of H side
// by side, each with all its unconstrained edges locally Delaunay (CGAL's
// CDT). Every unconstrained edge of M is strictly locally Delaunay (C11, exact
// incircle); by the constrained Delaunay lemma (Shewchuk, "General-dimensional
// constrained Delaunay and constrained regular triangulations", 2008) a
// triangulation of the domain D whose unconstrained edges are locally
// Delaunay is a constrained Delaunay triangulation of D, and with strict
// inequalities every triangle is strictly so: the only one. T restricted to D
// is M, whatever the insertion order (early triangulation or not). Likewise T
// and B restricted to H are CDTs of the same region with the same vertices and
// constraints: they may differ only within the cocircular cells of its unique
// constrained Delaunay subdivision, so the face of T across a boundary edge
// ab has its apex on the same circle and on the same side of ab as B's: the
// same angle at the apex (inscribed angles over one chord).
// label_domain on T: infinite faces and the right sides of boundary pieces
// outside, both sides of interior pieces and the left sides of boundary
// pieces inside; each region of T between constraints is a region of D (only
// inside seeds: M's triangles) or of H (only outside seeds: the right side of
// dM, as in B, and the infinite faces): no conflict, and the domain faces are
// M's triangles.
//
// Quality pass (options.quality). drop_crowding_points removes an apex on the
// domain side of a piece only (the left of a boundary piece, both sides of an
// interior one) when it sees its piece under more than crowding_angle; every
// apex of a piece in M sees it under an acute angle (C12, exact), and
// crowding_angle is off or >= 91 degrees (C0: the floating-point cosine test
// cannot call an acute angle obtuse by more than rounding): no point removed,
// no segment queued. The edge level's Gabriel test (CGAL's: the apex angle
// ACUTE, exact) looks at the domain side of a boundary edge, and also at the
// hidden side when an end of the edge is the apex of a cluster (CGAL's,
// Mesh_2/Clusters.h) with a wedge of the domain (Gabriel in
// delaunay_mesher.hpp). It holds on every side of every constraint edge in M
// (C12). Across an edge of dM the face of T is infinite (a hull edge, which
// conforms) or has the apex of B's face there; where that apex is not acute,
// neither end of the edge may be such a cluster apex (C6): an end with an
// interior segment is taken for one; else its only constraint edges are its two
// boundary edges u -> v -> w, whose one wedge below 180 degrees is the only one
// that can be small (CGAL: acute, 4 cos^2 > 1 + 1e-9); it is the domain's when
// u, v, w turn left, and it is taken for small unless exactly obtuse or right,
// or 4 cos^2 <= 1 - 1e-6 in floating point (far beyond the rounding of both
// tests). A wedge outside the domain (a notch, a spike of a hole) keeps the
// test one-sided. Nothing is encroached. The face level's
// Is_bad (rule 3 only: FRFC passes no spacing data; domain faces only) is
// Refinement_criteria::angle_badness on the face's points scaled by
// unit_scaling (the scaling both triangulations use, all points being in the
// first batch), in the face's rotation, which is one of the three tested
// (C13): no bad face. The mesher inserts nothing; a CGAL failure falls back to
// the same CDT.
//
// Curves (fit_to_curves, after the triangulation). project_segment_candidates
// has no candidate on a segment, so nothing to project. fit_once projects the
// points the step created on curved pieces (inserted by the quality pass or
// new in the selection): none, every output point being an input point. It
// also projects every point of a curved piece to find those on their curves,
// for the moves' limits (distance_along_to_curve): the same call succeeds
// (C14) and its answer bounds moves that do not happen. No point moves, so
// no new triangulation and no refit (they need a move); drop_unused_points
// finds every point in a triangle (C3). curve_reach (max(2 largest move,
// longest curved piece)) only tells the old mesh's walker how far outside new
// points may lie: every point is kept, so no point is walked to.
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

// C3, C4: segments against the triangulation; the boundary edges (directed
// with M on their left) into `next` (-1: no boundary edge leaves the vertex).
bool segments_certified(const Mesh_arrays& mesh, const std::vector<Segment_chain>& chains, const Edge_table& table,
                        std::vector<Index>& next) {
  const std::size_t n = mesh.points.size(), m = mesh.triangles.size();
  // C4: a segment of an interior chain has triangles on both sides, one of a
  // boundary chain on exactly one, the left of its piece; segment flags as
  // their chain's.
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
  // C3: every point is a corner of a triangle. C4: every edge with one
  // triangle is a segment (then a boundary one, above); one boundary edge
  // enters and one leaves each boundary vertex (no pinch).
  for (std::size_t v = 0; v < n; ++v) {
    if (table.xadj[v] == table.xadj[v + 1]) return false;
  }
  next.assign(n, -1);
  std::vector<std::uint8_t> entered(n, 0);
  for (std::size_t t = 0; t < m; ++t) {
    for (int k = 0; k < 3; ++k) {
      if (table.across[3 * t + k] >= 0) continue;
      if (!table.constrained[3 * t + k]) return false;
      const Index u = mesh.triangles[t][k], v = mesh.triangles[t][(k + 1) % 3];
      if (next[u] >= 0 || entered[v]) return false;
      next[u] = v;
      entered[v] = 1;
    }
  }
  for (std::size_t v = 0; v < n; ++v) {
    if ((next[v] >= 0) != (entered[v] != 0)) return false;
  }
  return true;
}

// C5, C6 on the constrained Delaunay triangulation B of the boundary vertices
// and edges alone (the comment at the top: why B says what the full step's
// triangulation does outside M): 0, or the certificate that fails.
int boundary_certified(const Mesh_arrays& mesh, const std::vector<Index>& next, const Frfc_options& options) {
  using detail::Cdt;
  const std::size_t n = mesh.points.size();
  std::vector<Index> local(n, -1);
  std::vector<Vec2> at;
  for (std::size_t v = 0; v < n; ++v) {
    if (next[v] < 0) continue;
    local[v] = static_cast<Index>(at.size());
    at.push_back(mesh.points[v]);
  }
  std::vector<Constraint_piece> pieces;  // pieces[k]: the boundary edge leaving local vertex k
  pieces.reserve(at.size());
  for (std::size_t v = 0; v < n; ++v) {
    if (next[v] >= 0) pieces.push_back(Constraint_piece{local[v], local[next[v]], true, 0});
  }
  Cdt cdt;
  std::vector<Cdt::Vertex_handle> handles;
  try {
    handles = detail::insert_points(cdt, at);  // throws Input_error on coinciding points
    for (const auto& piece : pieces) cdt.insert_constraint(handles[piece.a], handles[piece.b]);
  } catch (const Input_error&) {
    return 5;
  } catch (const Cdt::Intersection_of_constraints_exception&) {
    return 5;  // two boundary edges cross
  }
  if (cdt.dimension() != 2) return 5;
  // C5: no boundary vertex on another boundary edge (CGAL would split it).
  for (const auto& piece : pieces) {
    if (!cdt.is_edge(handles[piece.a], handles[piece.b])) return 5;
  }
  // C5: the regions of the plane between the loops are labelled consistently
  // (each on the left of every loop edge around it, or on the right of all).
  try {
    detail::label_domain(cdt, handles, pieces, "empty_scope");
  } catch (const std::runtime_error&) {
    return 5;
  }
  // C6: the apex across each boundary edge (if finite) sees it under an acute
  // angle, or the full step's quality pass does not look at it: neither end
  // is the apex of a cluster with a wedge of the domain (see the top).
  if (options.quality) {
    std::vector<std::uint8_t> has_interior_segment(at.size(), 0);
    for (std::size_t s = 0; s < mesh.segments.size(); ++s) {
      if (mesh.segment_is_boundary[s]) continue;
      for (Index v : mesh.segments[s]) {
        if (local[v] >= 0) has_interior_segment[local[v]] = 1;
      }
    }
    std::vector<Index> previous(at.size(), -1);
    for (const auto& piece : pieces) previous[piece.b] = piece.a;
    auto may_be_domain_cluster_apex = [&](Index v) {
      if (has_interior_segment[v]) return true;
      const Point_2 u = to_cgal(at[previous[v]]), p = to_cgal(at[v]), w = to_cgal(at[pieces[v].b]);
      if (CGAL::orientation(u, p, w) != CGAL::LEFT_TURN || CGAL::angle(u, p, w) != CGAL::ACUTE) return false;
      const double ax = u.x() - p.x(), ay = u.y() - p.y(), bx = w.x() - p.x(), by = w.y() - p.y();
      const double dot = ax * bx + ay * by;
      return 4 * dot * dot > (1 - 1e-6) * (ax * ax + ay * ay) * (bx * bx + by * by);
    };
    for (const auto& piece : pieces) {
      Cdt::Face_handle f;
      int i = 0;
      if (!cdt.is_edge(handles[piece.a], handles[piece.b], f, i)) return 5;  // (not reached: C5 above)
      if (f->vertex(Cdt::ccw(i)) == handles[piece.a]) {  // f on the left: take the face across
        const Cdt::Face_handle g = f->neighbor(i);
        i = g->index(f);
        f = g;
      }
      const Cdt::Vertex_handle apex = f->vertex(i);
      if (cdt.is_infinite(apex)) continue;
      if (CGAL::angle(handles[piece.a]->point(), apex->point(), handles[piece.b]->point()) == CGAL::ACUTE) continue;
      if (may_be_domain_cluster_apex(piece.a) || may_be_domain_cluster_apex(piece.b)) return 6;
    }
  }
  return 0;
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
      // The rotations share the three lengths (the same operations on the same
      // pairs) and differ in the rounding of twice the area (relative error a
      // few units of rounding over the sine of the angle at the first corner,
      // below 1e-13 for a triangle whose smallest angle is above 0.57 degrees,
      // sin^2 >= 1e-4) and in the order of two divisions: by far less than
      // 1e-6 of q, which is rounded to float (6e-8). So, at such a bound, the
      // first rotation decides when its q clears the bound by 1e-6 and its
      // area the resolution floor by a factor 2; else all three are evaluated.
      const Point_2 s[3] = {scaled(tri[0]), scaled(tri[1]), scaled(tri[2])};
      double q;
      if (detail::Refinement_criteria::angle_badness(s[0], s[1], s[2], bound, q) != CGAL::Mesh_2::NOT_BAD) return 13;
      const double twice_area =
          (s[1].x() - s[0].x()) * (s[2].y() - s[0].y()) - (s[1].y() - s[0].y()) * (s[2].x() - s[0].x());
      const double longest = std::sqrt(std::max({detail::squared_distance(s[1], s[2]),
                                                 detail::squared_distance(s[2], s[0]),
                                                 detail::squared_distance(s[0], s[1])}));
      const double reach = std::max({std::abs(s[0].x()), std::abs(s[0].y()), std::abs(s[1].x()),
                                     std::abs(s[1].y()), std::abs(s[2].x()), std::abs(s[2].y())});
      const double floor = detail::Refinement_criteria::kAngleRuleFloorUlps *
                           std::numeric_limits<double>::epsilon() * reach * longest;
      if (bound >= 1e-4 && q >= bound * (1 + 1e-6) && twice_area >= 2 * floor) continue;
      for (int r = 1; r < 3; ++r) {
        if (detail::Refinement_criteria::angle_badness(s[r], s[(r + 1) % 3], s[(r + 2) % 3], bound, q) !=
            CGAL::Mesh_2::NOT_BAD) {
          return 13;
        }
      }
    }
  }
  return 0;
}

// C14: the geometry's projection of every point of a curved segment (once
// per point and tag, as fit_to_curves' polygon keys) returns one point each
// and throws nothing. Its result is not needed (no point moves).
bool curves_project(const Mesh_arrays& mesh) {
  const Boundary_geometry& geometry = *mesh.geometry;
  std::vector<std::pair<std::int64_t, Index>> keys;
  for (std::size_t s = 0; s < mesh.segments.size(); ++s) {
    if (!geometry.is_curved(mesh.segment_tags[s])) continue;
    for (Index v : mesh.segments[s]) keys.emplace_back(mesh.segment_tags[s], v);
  }
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  if (keys.empty()) return true;
  std::vector<Vec2> points(keys.size());
  std::vector<std::int64_t> tags(keys.size());
  for (std::size_t k = 0; k < keys.size(); ++k) {
    tags[k] = keys[k].first;
    points[k] = mesh.points[keys[k].second];
  }
  try {
    geometry.project(points, tags);
  } catch (const std::exception&) {
    return false;
  }
  return points.size() == keys.size();
}

}  // namespace

std::optional<Evolve_result> empty_scope_frfc(const Mesh_arrays& input, const std::vector<double>& delta,
                                              const Frfc_options& options, const Step_context& context,
                                              int* declined_by) {
  const std::size_t n = input.points.size();
  auto decline = [declined_by](int certificate) {
    if (declined_by != nullptr) *declined_by = certificate;
    return std::nullopt;
  };
  // C0, C1: O(1) and one pass over delta.
  if (!options_allow(options) || input.triangles.empty()) return decline(0);
  for (double d : delta) {
    if (d != 1) return decline(1);
  }
  Evolve_result result;
  Stage_timer timer(result.stats, context.profile);
  const Thread_limit thread_limit(context.threads);  // (step_weights' trees, as in the full step)
  // Curves: the full step's stages work on with_curve_kinds(input) (C14: a
  // geometry it refuses is left to the full step, which says why).
  std::optional<Mesh_arrays> with_curves;
  if (input.geometry) {
    try {
      with_curves = with_curve_kinds(input);
    } catch (const Input_error&) {
      return decline(14);
    }
  }
  const Mesh_arrays& mesh = with_curves ? *with_curves : input;
  // C2-C6, C11-C13: the triangulation is the step's triangulation, untouched
  // by the quality pass. O(n) over the directed edges, and O(b log b) for the
  // b boundary vertices (C5, C6).
  Edge_table table;
  if (!build_edge_table(mesh, table)) return decline(3);
  const auto chains = segment_chains(mesh);
  std::vector<Index> next;
  if (!segments_certified(mesh, chains, table, next)) return decline(4);  // (C3, C4: reported as 4)
  timer.lap("empty_scope_edges");
  int failed = triangles_certified(mesh, table, options);
  if (failed != 0) return decline(failed);
  timer.lap("empty_scope_triangles");
  failed = boundary_certified(mesh, next, options);
  if (failed != 0) return decline(failed);
  table = Edge_table();
  timer.lap("empty_scope_boundary");
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
  timer.lap("empty_scope_weights");
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
  // C14: fit_to_curves projects the points of its curved pieces (to find
  // those on their curves); whatever that projection does not accept is left
  // to the full step.
  if (input.geometry && !curves_project(mesh)) return decline(14);
  timer.lap("empty_scope_spacing");

  // The full step's output, as finish_step's unchanged path returns it.
  Mesh_arrays& out = result.mesh;
  out.points = input.points;
  out.triangles = input.triangles;
  out.segments = input.segments;
  out.segment_is_boundary = input.segment_is_boundary;
  out.kind.resize(n);
  for (std::size_t i = 0; i < n; ++i) out.kind[i] = kept_point_kind(mesh.kind[i], forced[i] == kForcedCorner);
  out.segment_tags = input.segment_tags;
  out.triangle_tags = input.triangle_tags;
  out.required = input.required;
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
  result.unchanged = true;
  stats.emplace_back("unchanged", 1.0);
  stats.emplace_back("seconds_total", seconds);
  add_step_counts(result, {{"n_input_points", n}, {"incremental_step", 0}, {"empty_scope", 1}});
  return result;
}

}  // namespace evomesh
