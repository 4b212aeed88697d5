// The quality pass in rounds of independent insertions (design in
// docs/distributed-step.md section 3.6, option 1): Spielman, Teng and Ungor's
// parallel Delaunay refinement (IJCGA 2007) with off-centres, run serially.
//
// Each round reads the mesh as it stands at the round's start:
//  1. every queued bad face gets its refinement point (off-centre or
//     circumcentre, in the face's canonical rotation) and its cavity (the faces
//     whose circumdisc holds the point, within the constraints); a point that
//     encroaches a sub-segment on its cavity's boundary is not a candidate, the
//     sub-segment is (Ruppert's rule; CGAL's cluster rule may drop the face);
//  2. every encroached sub-segment (found by the scan, by the last round's
//     insertions or by step 1) gets its split point (midpoint, or the
//     concentric-shell point at a small input angle) and its cavity;
//  3. the candidates are ordered (sub-segments first, Ruppert's priority, by
//     their sorted end points; then faces worst first, ties by their sorted
//     points: no order of the triangulation's history) and the lexical-first
//     maximal independent set under that order is chosen, two candidates
//     conflicting when their cavities share a face or an edge;
//  4. the chosen are inserted in that order (cut by the same order when the
//     budget runs out), each by CGAL's mesher level, which recomputes its zone.
//
// Why the result is a function of the input sets: the constrained Delaunay
// triangulation is a function of its points and constraints (section 2.4),
// so the faces, cavities and encroachments of a round's start are; the
// candidates are read as a set and ordered by keys of points; the insertions
// follow that order, so CGAL's per-insertion state (clusters, edge sides) sees
// the same sequence. Independence makes the points of a round far apart
// (cavities that do not touch), which is what keeps the rounds from creating
// short edges between points that did not know of each other.
#include <algorithm>
#include <array>
#include <unordered_set>
#include <utility>
#include <vector>

#include "evomesh/detail/delaunay_mesher.hpp"

namespace evomesh::detail {

namespace {

using Edge = Cdt::Edge;

std::array<Point_2, 3> sorted_points(const Point_2& a, const Point_2& b, const Point_2& c) {
  std::array<Point_2, 3> p{a, b, c};
  std::sort(p.begin(), p.end());
  return p;
}

// A Steiner point proposed in a round.
struct Candidate {
  bool is_edge = false;
  Refinement_criteria::Quality quality = 0;  // faces: smaller is worse
  std::array<Point_2, 3> key;                // sorted points (an edge: its two ends, the last repeated)
  Face_handle face;                          // a face: itself; an edge: none
  std::array<Vertex_handle, 3> vertices;     // a face's vertices; an edge's two ends
  std::vector<Face_handle> cavity;
};

// The order of a round: sub-segments before faces, faces worst first, ties by
// the sorted points (distinct candidates have distinct keys).
bool precedes(const Candidate& a, const Candidate& b) {
  if (a.is_edge != b.is_edge) return a.is_edge;
  if (!a.is_edge && a.quality != b.quality) return a.quality < b.quality;
  return a.key < b.key;
}

// The constrained edge between a and b, if it still is one.
bool constrained_edge(const Cdt& tr, Vertex_handle a, Vertex_handle b, Edge& e) {
  Face_handle f;
  int i;
  if (!tr.is_edge(a, b, f, i) || !f->is_constrained(i)) return false;
  e = Edge(f, i);
  return true;
}

// Whether the face located for a point (fh; on edge i of it when an EDGE) is
// one of its cavity's faces: then the point is inside the cavity.
template <class Faces>
bool inside_cavity(const Faces& cavity, const Face_handle& fh, Cdt::Locate_type type, int i) {
  const bool in = std::find(cavity.begin(), cavity.end(), fh) != cavity.end();
  if (in || type != Cdt::EDGE) return in;
  return std::find(cavity.begin(), cavity.end(), fh->neighbor(i)) != cavity.end();
}

bool same_face(const Face_handle& f, const std::array<Vertex_handle, 3>& v) {
  return f->has_vertex(v[0]) && f->has_vertex(v[1]) && f->has_vertex(v[2]);
}

}  // namespace

Rounds_report Mesher::run_in_rounds(std::size_t budget, std::size_t max_rounds) {
  Rounds_report report;
  Cdt& tr = faces_.triangulation();
  auto& edge_visitor = visitor_.previous_level();
  std::vector<Candidate> candidates;
  std::unordered_set<const void*> blocked;  // faces of chosen cavities and their neighbours
  while (true) {
    candidates.clear();
    std::size_t dropped = 0;
    std::size_t waiting = 0;  // bad faces whose point cannot go in now (behind a constraint)
    // 1. The bad faces (Bad_face_queue holds exactly the bad faces of the
    // domain not dropped by the cluster rule: the scan's, and those around
    // every new point), in no particular order: what this step does for one
    // face (its candidate, the edges it queues, its drop) does not depend on
    // the others. (Each round recomputes the candidates it did not choose;
    // keeping them while their cavity and its ring stay untouched saves
    // nearly nothing: a candidate is left out because its cavity touches a
    // chosen one, whose insertion then destroys that ring.)
    std::vector<std::pair<Face_handle, Refinement_criteria::Quality>> bad;
    faces_.for_each_bad_face([&](const Face_handle& f, Refinement_criteria::Quality q) { bad.emplace_back(f, q); });
    for (const auto& [f, q] : bad) {
      const Point_2 p = faces_.refinement_point(f);
      auto zone = faces_.conflicts_zone(p, f);
      if (zone.locate_type == Cdt::VERTEX) {  // (never: the point of a bad face is inside its empty disc)
        ++waiting;
        continue;
      }
      edges_.set_imperative_refinement(false);
      const auto status = edges_.test_point_conflict_from_superior(p, zone);  // queues the edges p encroaches
      if (status == CGAL::CONFLICT_AND_ELEMENT_SHOULD_BE_DROPPED) {
        faces_.remove_bad_face(f);
        ++dropped;
        continue;
      }
      if (status != CGAL::NO_CONFLICT) continue;
      // Ruppert's lemma puts the point in the domain once no sub-segment is
      // encroached; the serial pass refines faces only then. A round refines
      // faces while sub-segments elsewhere wait, so a point must show it is
      // inside its own cavity (not behind a constraint the cavity stops at)
      // and in the domain; otherwise the face waits for the splits.
      if (!inside_cavity(zone.faces, zone.fh, zone.locate_type, zone.i) || !zone.fh->is_in_domain()) {
        ++waiting;
        continue;
      }
      Candidate c;
      c.quality = q;
      c.face = f;
      c.vertices = {f->vertex(0), f->vertex(1), f->vertex(2)};
      c.key = sorted_points(f->vertex(0)->point(), f->vertex(1)->point(), f->vertex(2)->point());
      c.cavity.assign(zone.faces.begin(), zone.faces.end());
      candidates.push_back(std::move(c));
    }
    // 2. The encroached sub-segments: CGAL's edge queue, read as a set.
    std::vector<std::pair<std::array<Point_2, 2>, std::array<Vertex_handle, 2>>> edges;
    while (!edges_.no_longer_element_to_refine()) {
      const Edge e = edges_.get_next_element();
      edges_.pop_next_element();
      Vertex_handle a = e.first->vertex(Cdt::cw(e.second)), b = e.first->vertex(Cdt::ccw(e.second));
      if (b->point() < a->point()) std::swap(a, b);
      edges.push_back({{a->point(), b->point()}, {a, b}});
    }
    std::sort(edges.begin(), edges.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
    edges.erase(std::unique(edges.begin(), edges.end(), [](const auto& x, const auto& y) { return x.first == y.first; }),
                edges.end());
    for (const auto& [ends, v] : edges) {
      Edge e;
      if (!constrained_edge(tr, v[0], v[1], e)) continue;
      const Point_2 p = edges_.refinement_point(e);
      auto zone = edges_.conflicts_zone(p, e);
      Candidate c;
      c.is_edge = true;
      c.vertices = {v[0], v[1], v[1]};
      c.key = {ends[0], ends[1], ends[1]};
      c.cavity.assign(zone.faces.begin(), zone.faces.end());
      candidates.push_back(std::move(c));
    }
    if (candidates.empty()) {
      if (dropped > 0) continue;  // (faces left the queue: look again)
      report.stalled = waiting > 0;
      break;  // nothing bad is left, or only faces no split will free
    }
    const std::size_t left = budget - report.n_inserted;
    if (left == 0) {
      report.capped = true;
      break;
    }
    if (report.rounds >= max_rounds) {
      report.round_limit = true;
      break;
    }
    // 3. The lexical-first maximal independent set under the order.
    std::sort(candidates.begin(), candidates.end(), precedes);
    blocked.clear();
    blocked.reserve(8 * candidates.size());
    std::vector<const Candidate*> chosen;
    for (const Candidate& c : candidates) {
      const bool free = std::none_of(c.cavity.begin(), c.cavity.end(),
                                     [&](const Face_handle& f) { return blocked.count(&*f) != 0; });
      if (!free) continue;
      chosen.push_back(&c);
      for (const Face_handle& f : c.cavity) {
        blocked.insert(&*f);
        for (int i = 0; i < 3; ++i) blocked.insert(&*f->neighbor(i));
      }
    }
    // 4. Insert (cut by the order at the budget).
    if (chosen.size() > left) {
      chosen.resize(left);
      report.capped = true;
    }
    std::size_t inserted = 0;
    for (const Candidate* c : chosen) {
      CGAL::Mesher_level_conflict_status status;
      if (c->is_edge) {
        Edge e;
        if (!constrained_edge(tr, c->vertices[0], c->vertices[1], e)) continue;
        status = edges_.try_to_refine_element(e, edge_visitor);
      } else {
        // The face is still there unless an earlier insertion of this round
        // reached it (a queued face's entry ends when it is destroyed).
        if (!faces_.is_queued(c->face) || !same_face(c->face, c->vertices)) continue;
        faces_.refine_outside_queue_order();
        status = faces_.try_to_refine_element(c->face, visitor_);
        if (status == CGAL::CONFLICT_AND_ELEMENT_SHOULD_BE_DROPPED) faces_.remove_bad_face(c->face);
      }
      if (status == CGAL::NO_CONFLICT) ++inserted;
    }
    ++report.rounds;
    report.n_inserted += inserted;
    report.largest_round = std::max(report.largest_round, inserted);
    if (report.capped) break;
    if (inserted == 0 && dropped == 0) {
      // Every chosen point met an encroachment at its insertion (its edges
      // are queued: the next round splits them) or nothing could be inserted.
      if (edges_.no_longer_element_to_refine()) {
        report.stalled = true;
        break;
      }
    }
  }
  return report;
}

}  // namespace evomesh::detail
