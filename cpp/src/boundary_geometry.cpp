#include "evomesh/boundary_geometry.hpp"

#include <CGAL/exceptions.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <queue>
#include <string>
#include <unordered_map>
#include <utility>

#include "evomesh/quality_pass.hpp"
#include "evomesh/step.hpp"
#include "evomesh/triangulation.hpp"

namespace evomesh {

void Boundary_geometry::validate() const {
  if (!(corner_angle > 0 && corner_angle < 180)) {
    throw Input_error("geometry: corner_angle must be in (0, 180) degrees, got " + std::to_string(corner_angle));
  }
  if (!std::is_sorted(curved_tags.begin(), curved_tags.end()) ||
      std::adjacent_find(curved_tags.begin(), curved_tags.end()) != curved_tags.end()) {
    throw std::logic_error("Boundary_geometry: curved_tags must be sorted without repeats");
  }
  if (!project) throw Input_error("geometry: no projection");
}

namespace {

std::string where(const Vec2& x) {
  char buffer[80];
  std::snprintf(buffer, sizeof buffer, "(%.17g, %.17g)", x[0], x[1]);
  return buffer;
}

// Units of rounding of its coordinates within which a point counts as on its
// curve: a polygon's vertices computed as c + r (cos t, sin t), and the
// projection's own rounding, are within a few.
constexpr double kOnCurveUlps = 64;

double rounding_of(const Vec2& a, const Vec2& b) {
  return std::numeric_limits<double>::epsilon() *
         std::max({std::abs(a[0]), std::abs(a[1]), std::abs(b[0]), std::abs(b[1])});
}

// A polygon along curves: nodes (a point with the tag of the curve it lies on;
// a point where two curved tags meet is one node per tag) and its edges.
struct Curve_polygon {
  std::vector<std::pair<std::int64_t, Index>> keys;  // (tag, point), sorted, no repeats
  std::vector<std::array<std::size_t, 2>> edges;

  // Call with every edge's ends first (add_key), then finish_keys, then add_edge.
  void add_key(Index point, std::int64_t tag) { keys.emplace_back(tag, point); }
  void finish_keys() {
    std::sort(keys.begin(), keys.end());
    keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  }
  std::size_t node(Index point, std::int64_t tag) const {
    return static_cast<std::size_t>(std::lower_bound(keys.begin(), keys.end(), std::make_pair(tag, point)) -
                                    keys.begin());
  }
  void add_edge(Index a, Index b, std::int64_t tag) { edges.push_back({node(a, tag), node(b, tag)}); }
};

// For every node of `polygon` (coordinates from `points`), its distance along
// the polygon to the nearest node that lies on its curve (within kOnCurveUlps
// units of rounding; infinite where no node of its part does).
//
// Why this bounds a move: if w lies on the curve, a point p of the polygon is
// at most |p - w| from the curve, and |p - w| is at most the length of any path
// from p to w along the polygon (triangle inequality). A projection onto the
// nearest point of the curve moves p by no more, however coarse the polygon is
// for the curve (a 12-gon's chords stray from its circle by 3.4 % of the
// radius, far more than a fine spacing near them) and whatever points of it
// were kept off the curve in earlier steps.
std::vector<double> distance_along_to_curve(const Boundary_geometry& geometry, const Curve_polygon& polygon,
                                            const std::vector<Vec2>& points) {
  const std::size_t n = polygon.keys.size();
  std::vector<Vec2> at(n);
  std::vector<std::int64_t> tags(n);
  for (std::size_t k = 0; k < n; ++k) {
    tags[k] = polygon.keys[k].first;
    at[k] = points[polygon.keys[k].second];
  }
  std::vector<Vec2> projected = at;
  geometry.project(projected, tags);
  if (projected.size() != n) throw Input_error("geometry: the projection returned a different number of points");
  std::vector<double> distance(n, std::numeric_limits<double>::infinity());
  using Entry = std::pair<double, std::size_t>;
  std::priority_queue<Entry, std::vector<Entry>, std::greater<Entry>> queue;
  for (std::size_t k = 0; k < n; ++k) {
    const double move = std::hypot(projected[k][0] - at[k][0], projected[k][1] - at[k][1]);
    if (move <= kOnCurveUlps * rounding_of(at[k], projected[k])) {  // false for NaN
      distance[k] = 0;
      queue.emplace(0.0, k);
    }
  }
  // Dijkstra along the edges (compressed neighbour lists).
  std::vector<std::size_t> xadj(n + 1, 0), adj(2 * polygon.edges.size());
  for (const auto& e : polygon.edges) {
    ++xadj[e[0] + 1];
    ++xadj[e[1] + 1];
  }
  for (std::size_t k = 0; k < n; ++k) xadj[k + 1] += xadj[k];
  {
    std::vector<std::size_t> fill(xadj.begin(), xadj.end() - 1);
    for (const auto& e : polygon.edges) {
      adj[fill[e[0]]++] = e[1];
      adj[fill[e[1]]++] = e[0];
    }
  }
  while (!queue.empty()) {
    const auto [d, k] = queue.top();
    queue.pop();
    if (d > distance[k]) continue;
    for (std::size_t a = xadj[k]; a < xadj[k + 1]; ++a) {
      const std::size_t j = adj[a];
      const double through = d + std::hypot(at[j][0] - at[k][0], at[j][1] - at[k][1]);
      if (through < distance[j]) {
        distance[j] = through;
        queue.emplace(through, j);
      }
    }
  }
  return distance;
}

// Projects `points` (on segments tagged `tags`) onto their curves; each may move
// by at most limit[k]. A point of an interior chain (interior[k]; an interface)
// that would move farther stays where it is, on its chord: there the
// curve is not resolved at the local spacing (two level-set circles touching),
// and an interior chain does not bound the domain. Returns the largest move;
// adds the points left so to *left.
double project_points(const Boundary_geometry& geometry, std::vector<Vec2>& points,
                      const std::vector<std::int64_t>& tags, const std::vector<double>& limit,
                      const std::vector<std::uint8_t>& interior, std::size_t* left = nullptr) {
  if (points.empty()) return 0;
  const std::vector<Vec2> before = points;
  geometry.project(points, tags);
  if (points.size() != before.size()) throw Input_error("geometry: the projection returned a different number of points");
  double largest = 0;
  for (std::size_t k = 0; k < points.size(); ++k) {
    const double move = std::hypot(points[k][0] - before[k][0], points[k][1] - before[k][1]);
    if (interior[k] && std::isfinite(move) && !(move <= limit[k])) {
      points[k] = before[k];
      if (left != nullptr) ++*left;
      continue;
    }
    if (!std::isfinite(points[k][0]) || !std::isfinite(points[k][1]) || !(move <= limit[k])) {
      throw Input_error("geometry: projecting the boundary point " + where(before[k]) + " (segment tag " +
                        std::to_string(tags[k]) + ") gave " + where(points[k]) + ", a move of " + format_count(move) +
                        ", more than the local spacing or the distance along the boundary to a point on the curve "
                        "allows (" + format_count(limit[k]) +
                        "): is this the curve that the segments of that tag approximate?");
    }
    largest = std::max(largest, move);
  }
  return largest;
}

}  // namespace

Mesh_arrays with_curve_kinds(const Mesh_arrays& input) {
  Mesh_arrays mesh = input;
  mesh.geometry->validate();
  if (mesh.segment_tags.empty()) mesh.segment_tags.assign(mesh.segments.size(), 0);
  // A curve for a tag no segment has is a mistake (a wrong tag number, or a
  // geometry meant for another mesh): said, not ignored.
  std::vector<std::int64_t> used = mesh.segment_tags;
  std::sort(used.begin(), used.end());
  used.erase(std::unique(used.begin(), used.end()), used.end());
  for (const std::int64_t tag : mesh.geometry->curved_tags) {
    if (std::binary_search(used.begin(), used.end(), tag)) continue;
    std::string listed;
    for (std::size_t k = 0; k < used.size() && k < 10; ++k) listed += (k ? ", " : "") + std::to_string(used[k]);
    if (used.size() > 10) listed += ", ...";
    throw Input_error("geometry: segment tag " + std::to_string(tag) + " has a curve, but no segment of the mesh has "
                      "that tag (its segment tags: " + (listed.empty() ? std::string("none") : listed) + ")");
  }
  // A point on segments of curved tags only is a corner exactly when the geometry
  // says so (classify_points); on straight chains the given kinds stand.
  const std::vector<Point_kind> geometric = classify_points(mesh);
  std::vector<std::uint8_t> on_curve(mesh.points.size(), 0), on_straight(mesh.points.size(), 0);
  for (std::size_t s = 0; s < mesh.segments.size(); ++s) {
    auto& mark = mesh.geometry->is_curved(mesh.segment_tags[s]) ? on_curve : on_straight;
    mark[mesh.segments[s][0]] = mark[mesh.segments[s][1]] = 1;
  }
  for (std::size_t v = 0; v < mesh.points.size(); ++v) {
    if (on_curve[v] && !on_straight[v]) mesh.kind[v] = geometric[v];
  }
  return mesh;
}

double project_segment_candidates(const Mesh_arrays& mesh, const std::vector<std::uint32_t>& segment_of_candidate,
                                  std::size_t first, const std::vector<std::uint8_t>& kept,
                                  const std::vector<double>& radius, std::vector<Vec2>& centers,
                                  std::vector<std::pair<std::size_t, Vec2>>* interior_moves) {
  const Boundary_geometry& geometry = *mesh.geometry;
  std::vector<std::size_t> which;
  std::vector<Vec2> points;
  std::vector<std::int64_t> tags;
  std::vector<double> limit;
  std::vector<std::uint8_t> interior;
  for (std::size_t k = 0; k < segment_of_candidate.size(); ++k) {
    const std::size_t c = first + k;
    const std::int64_t tag = mesh.segment_tags[segment_of_candidate[k]];
    if (!kept[c] || !geometry.is_curved(tag)) continue;
    which.push_back(c);
    points.push_back(centers[c]);
    tags.push_back(tag);
    limit.push_back(radius[c]);
    interior.push_back(mesh.segment_is_boundary[segment_of_candidate[k]] == 0);
  }
  if (which.empty()) return 0;
  // A candidate on segment (a, b) may also move by its distance to a or b plus
  // that end's distance along the input's curved segments to a point on the
  // curve (distance_along_to_curve).
  Curve_polygon polygon;
  for (std::size_t s = 0; s < mesh.segments.size(); ++s) {
    if (!geometry.is_curved(mesh.segment_tags[s])) continue;
    polygon.add_key(mesh.segments[s][0], mesh.segment_tags[s]);
    polygon.add_key(mesh.segments[s][1], mesh.segment_tags[s]);
  }
  polygon.finish_keys();
  for (std::size_t s = 0; s < mesh.segments.size(); ++s) {
    if (geometry.is_curved(mesh.segment_tags[s])) polygon.add_edge(mesh.segments[s][0], mesh.segments[s][1], mesh.segment_tags[s]);
  }
  const std::vector<double> along = distance_along_to_curve(geometry, polygon, mesh.points);
  std::size_t k = 0;
  for (std::size_t j = 0; j < segment_of_candidate.size(); ++j) {
    const std::size_t c = first + j;
    if (k == which.size() || which[k] != c) continue;
    const Edge& e = mesh.segments[segment_of_candidate[j]];
    double bound = std::numeric_limits<double>::infinity();
    for (const Index end : e) {
      const Vec2& q = mesh.points[end];
      bound = std::min(bound, std::hypot(points[k][0] - q[0], points[k][1] - q[1]) + along[polygon.node(end, tags[k])]);
    }
    // (not on an interior chain: an interface's input points lie on its curve,
    // and a longer move means the curve is not resolved there)
    if (std::isfinite(bound) && !interior[k]) limit[k] = std::max(limit[k], bound);
    limit[k] += kOnCurveUlps * rounding_of(points[k], points[k]);
    ++k;
  }
  const double largest = project_points(geometry, points, tags, limit, interior);
  for (std::size_t j = 0; j < which.size(); ++j) {
    if (interior_moves != nullptr && interior[j] && points[j] != centers[which[j]]) {
      interior_moves->emplace_back(which[j], centers[which[j]]);
    }
    centers[which[j]] = points[j];
  }
  return largest;
}

namespace {

// Removes the points no triangle uses (interior points that a curved boundary
// left outside), renumbering everything.
std::size_t drop_unused_points(Evolve_result& result) {
  Mesh_arrays& mesh = result.mesh;
  const std::size_t n = mesh.points.size();
  std::vector<Index> renumber(n, -1);
  for (const auto& t : mesh.triangles) {
    for (Index v : t) renumber[v] = 0;
  }
  Index next = 0;
  for (std::size_t v = 0; v < n; ++v) {
    if (renumber[v] < 0) continue;
    renumber[v] = next;
    mesh.points[next] = mesh.points[v];
    mesh.kind[next] = mesh.kind[v];
    result.origin[next] = result.origin[v];
    if (!mesh.required.empty()) mesh.required[next] = mesh.required[v];
    ++next;
  }
  const std::size_t dropped = n - static_cast<std::size_t>(next);
  if (dropped == 0) return 0;
  for (std::size_t v = 0; v < n; ++v) {
    if (renumber[v] < 0 && !mesh.required.empty() && mesh.required[v]) {
      throw Input_error("geometry: the required point " + where(mesh.points[v]) +
                        " lies outside the curved boundary");
    }
  }
  mesh.points.resize(next);
  mesh.kind.resize(next);
  result.origin.resize(next);
  if (!mesh.required.empty()) mesh.required.resize(next);
  for (auto& t : mesh.triangles) {
    for (Index& v : t) v = renumber[v];
  }
  for (auto& e : mesh.segments) {
    for (Index& v : e) {
      if (renumber[v] < 0) throw std::logic_error("drop_unused_points: a segment end in no triangle");
      v = renumber[v];
    }
  }
  return dropped;
}

}  // namespace

Segments_at_points::Segments_at_points(const Mesh_arrays& mesh)
    : xadj(mesh.points.size() + 1, 0), adj(2 * mesh.segments.size()) {
  for (const auto& e : mesh.segments) {
    ++xadj[e[0] + 1];
    ++xadj[e[1] + 1];
  }
  for (std::size_t v = 0; v < mesh.points.size(); ++v) xadj[v + 1] += xadj[v];
  std::vector<Index> fill(xadj.begin(), xadj.end() - 1);
  for (std::size_t s = 0; s < mesh.segments.size(); ++s) {
    adj[fill[mesh.segments[s][0]]++] = static_cast<Index>(s);
    adj[fill[mesh.segments[s][1]]++] = static_cast<Index>(s);
  }
}

Index Segments_at_points::walk(const Mesh_arrays& mesh, const std::vector<Index>& selection_index, Index v, Index s,
                               std::vector<Index>& walked, std::vector<Index>* inside) const {
  auto other = [&](Index t, Index u) { return mesh.segments[t][0] == u ? mesh.segments[t][1] : mesh.segments[t][0]; };
  walked.assign(1, s);
  Index w = other(s, v);
  while (selection_index[w] < 0) {
    if (xadj[w + 1] - xadj[w] != 2) throw std::logic_error("a point inserted in a constraint piece is off it");
    if (inside) inside->push_back(w);
    const Index s0 = adj[xadj[w]], s1 = adj[xadj[w] + 1];
    s = s0 == s ? s1 : s0;
    walked.push_back(s);
    w = other(s, w);
  }
  return w;
}

std::size_t keep_pieces_apart(std::vector<Vec2>& points, const std::vector<Constraint_piece>& pieces,
                              const std::vector<std::pair<Index, Vec2>>& moved) {
  if (moved.empty()) return 0;
  std::vector<Index> move_of(points.size(), -1);
  for (std::size_t k = 0; k < moved.size(); ++k) move_of[moved[k].first] = static_cast<Index>(k);
  // The two piece neighbours of every moved point (-1: not exactly two).
  std::vector<std::array<Index, 2>> beside(moved.size(), {-1, -1});
  std::vector<int> count(moved.size(), 0);
  for (const auto& piece : pieces) {
    for (const auto& [v, w] : {std::pair{piece.a, piece.b}, std::pair{piece.b, piece.a}}) {
      if (move_of[v] < 0) continue;
      const Index k = move_of[v];
      if (count[k] < 2) beside[k][count[k]] = w;
      ++count[k];
    }
  }
  std::size_t undone = 0;
  const auto undo = [&](Index v) {
    if (move_of[v] < 0) return false;
    points[v] = moved[move_of[v]].second;
    move_of[v] = -1;
    ++undone;
    return true;
  };
  // Each round undoes at least one move, and with every move undone the pieces
  // are the input's chords again.
  for (;;) {
    bool any = false;
    for (const auto& pair : meeting_pieces(points, pieces, /*touching=*/true)) {
      for (const Index piece : pair) {
        for (const Index v : {pieces[piece].a, pieces[piece].b}) any = undo(v) || any;
      }
    }
    // A move that folds its chain back (its pieces meet at less than 90
    // degrees) followed the curve onto another branch, or a branch the input
    // does not resolve (two curves closer than the spacing): undone too.
    for (std::size_t k = 0; k < moved.size(); ++k) {
      const Index v = moved[k].first;
      if (move_of[v] < 0 || count[k] != 2) continue;
      const Vec2 &p = points[v], &u = points[beside[k][0]], &w = points[beside[k][1]];
      if ((u[0] - p[0]) * (w[0] - p[0]) + (u[1] - p[1]) * (w[1] - p[1]) > 0) any = undo(v) || any;
    }
    if (!any) return undone;
  }
}

namespace {

// One round of fit_to_curves: what it did, and the tag of every output segment.
struct Fit_round {
  double largest = 0;  // move
  double longest = 0;  // piece on a curve
  std::size_t projected = 0;
  std::size_t dropped = 0;
  std::size_t left_on_chords = 0;  // points of interior chains not moved (too far)
  bool moved = false;
  std::vector<std::int64_t> segment_tags;
};

Fit_round fit_once(const Boundary_geometry& geometry, const std::vector<Constraint_piece>& pieces,
                   const std::vector<Index>& selection_index, Evolve_result& result) {
  Fit_round round;
  Mesh_arrays& mesh = result.mesh;
  const std::size_t n = mesh.points.size();
  // The tag of every output segment: the piece (between selected points) it is part of.
  std::unordered_map<std::uint64_t, const Constraint_piece*> piece_of;
  auto key = [](Index a, Index b) {
    return (static_cast<std::uint64_t>(std::min(a, b)) << 32) ^ static_cast<std::uint64_t>(std::max(a, b));
  };
  for (const auto& piece : pieces) piece_of[key(piece.a, piece.b)] = &piece;
  const Segments_at_points at(mesh);
  const std::vector<Index>&xadj = at.xadj, &adj = at.adj;
  auto other = [&](Index s, Index v) { return mesh.segments[s][0] == v ? mesh.segments[s][1] : mesh.segments[s][0]; };
  // Points the step created: those of the selection that are new, and those the
  // quality pass inserted on segments (inside pieces, two segments each).
  std::vector<std::int64_t> tag_of(n, 0);
  std::vector<std::uint8_t> curved(n, 0), interior(n, 0);
  double& longest = round.longest;  // of the pieces on curves
  round.segment_tags.assign(mesh.segments.size(), 0);
  std::vector<std::vector<Index>> curved_pieces;  // end to end through their inserted points
  std::vector<std::int64_t> curved_piece_tag;
  for (std::size_t v = 0; v < n; ++v) {
    if (selection_index[v] < 0) continue;
    for (Index a = xadj[v]; a < xadj[v + 1]; ++a) {
      // follow the piece from v through inserted points to the next selected point
      std::vector<Index> inside, walked;
      const Index w = at.walk(mesh, selection_index, static_cast<Index>(v), adj[a], walked, &inside);
      if (selection_index[w] < static_cast<Index>(selection_index[v])) continue;  // walked from the other end
      const auto found = piece_of.find(key(selection_index[v], selection_index[w]));
      if (found == piece_of.end()) throw std::logic_error("fit_to_curves: a segment on no constraint piece");
      const Constraint_piece& piece = *found->second;
      for (Index t : walked) round.segment_tags[t] = piece.tag;
      if (!geometry.is_curved(piece.tag)) continue;
      const Vec2 &from = mesh.points[v], &to = mesh.points[w];
      longest = std::max(longest, std::hypot(to[0] - from[0], to[1] - from[1]));
      curved_pieces.push_back({static_cast<Index>(v)});
      curved_pieces.back().insert(curved_pieces.back().end(), inside.begin(), inside.end());
      curved_pieces.back().push_back(w);
      curved_piece_tag.push_back(piece.tag);
      for (Index u : inside) {
        curved[u] = 1;
        tag_of[u] = piece.tag;
        interior[u] = !piece.boundary;
      }
      // new selected points on a curve (already projected in FRFC; a projection is idempotent)
      for (Index end : {static_cast<Index>(v), w}) {
        if (result.origin[end] < 0 && mesh.kind[end] != Point_kind::corner) {
          curved[end] = 1;
          tag_of[end] = piece.tag;
          interior[end] = interior[end] || !piece.boundary;
        }
      }
    }
  }
  // A point may also move by its distance along the curved pieces to a point
  // on the curve (distance_along_to_curve): kept points that lie off the
  // curve (a coarse input polygon) are where it is needed.
  Curve_polygon polygon;
  for (std::size_t p = 0; p < curved_pieces.size(); ++p) {
    for (Index u : curved_pieces[p]) polygon.add_key(u, curved_piece_tag[p]);
  }
  polygon.finish_keys();
  for (std::size_t p = 0; p < curved_pieces.size(); ++p) {
    const auto& piece = curved_pieces[p];
    for (std::size_t k = 0; k + 1 < piece.size(); ++k) polygon.add_edge(piece[k], piece[k + 1], curved_piece_tag[p]);
  }
  const std::vector<double> along =
      polygon.keys.empty() ? std::vector<double>() : distance_along_to_curve(geometry, polygon, mesh.points);
  std::vector<Index> which;
  std::vector<Vec2> points;
  std::vector<std::int64_t> tags;
  std::vector<double> limit;
  std::vector<std::uint8_t> on_interior;
  for (std::size_t v = 0; v < n; ++v) {
    if (!curved[v]) continue;
    on_interior.push_back(interior[v]);
    double shortest = std::numeric_limits<double>::infinity();
    for (Index a = xadj[v]; a < xadj[v + 1]; ++a) {
      const Vec2& w = mesh.points[other(adj[a], static_cast<Index>(v))];
      shortest = std::min(shortest, std::hypot(w[0] - mesh.points[v][0], w[1] - mesh.points[v][1]));
    }
    which.push_back(static_cast<Index>(v));
    points.push_back(mesh.points[v]);
    tags.push_back(tag_of[v]);
    const double bound = interior[v] ? 0.0 : along[polygon.node(static_cast<Index>(v), tag_of[v])];
    limit.push_back(std::max(0.5 * shortest, std::isfinite(bound) ? bound : 0.0) +
                    kOnCurveUlps * rounding_of(mesh.points[v], mesh.points[v]));
  }
  const double largest = project_points(geometry, points, tags, limit, on_interior, &round.left_on_chords);
  bool& moved = round.moved;
  std::vector<std::pair<Index, Vec2>> interior_moves;  // (point, where it was)
  for (std::size_t k = 0; k < which.size(); ++k) {
    if (points[k] == mesh.points[which[k]]) continue;
    moved = true;
    if (on_interior[k]) interior_moves.emplace_back(which[k], mesh.points[which[k]]);
    mesh.points[which[k]] = points[k];
  }
  if (moved) {
    // The same constraints through the moved points: triangulated again.
    std::vector<Constraint_piece> constraints(mesh.segments.size());
    for (std::size_t s = 0; s < mesh.segments.size(); ++s) {
      constraints[s] = {mesh.segments[s][0], mesh.segments[s][1], mesh.segment_is_boundary[s] != 0,
                        round.segment_tags[s]};
    }
    // An interior chain's points whose moves make its segments cross or touch
    // others (a fold of the curve narrower than the spacing) stay on their chords.
    round.left_on_chords += keep_pieces_apart(mesh.points, constraints, interior_moves);
    try {
      mesh.triangles = constrained_delaunay(mesh.points, constraints);
    } catch (const CGAL::Failure_exception&) {
      throw Input_error("geometry: the boundary moved onto its curves crosses itself (the mesh is too coarse for "
                        "the curve, or the geometry is not the one its segments approximate)");
    } catch (const std::runtime_error&) {
      throw Input_error("geometry: the boundary moved onto its curves no longer bounds a domain");
    }
  }
  round.dropped = drop_unused_points(result);
  round.projected = which.size();
  round.largest = largest;
  return round;
}

}  // namespace

double fit_to_curves(const Boundary_geometry& geometry, const std::vector<Constraint_piece>& pieces,
                     const std::vector<Index>& selection_index, Evolve_result& result, const Quality_options* quality) {
  Fit_round round = fit_once(geometry, pieces, selection_index, result);
  double largest = round.largest, longest = round.longest;
  std::size_t projected = round.projected, dropped = round.dropped, left = round.left_on_chords, rounds = 0;
  // Points moved onto their curves change the angles of their triangles (by
  // about sagitta / spacing): where that leaves one below min_angle, the quality
  // pass runs again on the fitted mesh (its segments as pieces, no point
  // dropped) and its new points on curves are fitted in turn. Each round's moves
  // are sagittas of shorter chords when the chords' ends lie on the curve; two
  // rounds settle it in practice. Where they do not (kept points of
  // a coarse input polygon, which stay on its chords), a point the pass puts
  // between two of them moves by up to the polygon's sagitta, far more than its
  // new segments' length: a spike whose thin triangles the next round splits
  // again, down to degenerate ones. So a round must raise the smallest angle
  // (or keep it) and succeed, else the mesh before it stands.
  constexpr int kMaxRefits = 2;
  double smallest = smallest_angle(result.mesh.points, result.mesh.triangles).first;
  std::size_t undone = 0;
  while (quality != nullptr && round.moved && rounds < kMaxRefits && smallest < quality->min_angle) {
    Mesh_arrays before = result.mesh;
    std::vector<Index> before_origin = result.origin;
    auto undo = [&] {
      result.mesh = std::move(before);
      result.origin = std::move(before_origin);
      ++undone;
    };
    Mesh_arrays& mesh = result.mesh;
    std::vector<Constraint_piece> again(mesh.segments.size());
    for (std::size_t s = 0; s < mesh.segments.size(); ++s) {
      again[s] = {mesh.segments[s][0], mesh.segments[s][1], mesh.segment_is_boundary[s] != 0, round.segment_tags[s]};
    }
    Quality_options options = *quality;
    options.crowding_angle = 0;  // keep every point: only Ruppert's insertions
    Refined_mesh refined;
    try {
      refined = quality_triangulate(mesh.points, mesh.kind, again, options);
    } catch (const CGAL::Failure_exception&) {
      break;  // (the fitted mesh stands, as after a failed quality pass)
    }
    std::vector<Index> origin(refined.source.size());
    for (std::size_t i = 0; i < origin.size(); ++i) {
      origin[i] = refined.source[i] < 0 ? -1 : result.origin[refined.source[i]];
    }
    result.origin = std::move(origin);
    result.mesh = std::move(refined.mesh);
    Fit_round next;
    try {
      next = fit_once(geometry, again, refined.source, result);
    } catch (const Input_error&) {
      undo();  // the first round's fit stood the same checks: the geometry is the one the segments approximate
      break;
    } catch (const CGAL::Failure_exception&) {
      undo();
      break;
    }
    const double now = smallest_angle(result.mesh.points, result.mesh.triangles).first;
    if (!(now >= smallest)) {
      undo();
      break;
    }
    smallest = now;
    round = std::move(next);
    largest = std::max(largest, round.largest);
    longest = std::max(longest, round.longest);
    projected += round.projected;
    dropped += round.dropped;
    left += round.left_on_chords;
    ++rounds;
  }
  result.stats.emplace_back("curve_points_projected", static_cast<double>(projected));
  result.stats.emplace_back("curve_points_dropped_outside", static_cast<double>(dropped));
  result.stats.emplace_back("curve_largest_move", largest);
  result.stats.emplace_back("curve_refits", static_cast<double>(rounds));
  result.stats.emplace_back("curve_refits_undone", static_cast<double>(undone));
  result.stats.emplace_back("curve_points_left_on_chords", static_cast<double>(left));
  // A chord between points of a curve strays from the input's polygon by at
  // most about its sagitta, well under its length.
  return std::max(2 * largest, longest);
}

}  // namespace evomesh
