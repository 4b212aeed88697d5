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
//     concentric-shell point at a small input angle) and its cavity; so does
//     every piece of a run of equal input pieces that such splits have been
//     seen to march along (Marching_runs: without it the rounds grow with the
//     run's length over the pieces' length);
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
// the same sequence. The runs queued for splitting are read from the rounds'
// meshes, by walks whose union does not depend on the seeds' order.
// Independence makes the points of a round far apart (cavities that do not
// touch), which is what keeps the rounds from creating short edges between
// points that did not know of each other.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <set>
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

// The other end of the constrained edge at v that continues the chain from
// `from` through v: v must be on exactly two constrained edges.
bool next_in_chain(const Cdt& tr, Vertex_handle from, Vertex_handle v, Vertex_handle& next) {
  int n = 0;
  auto e = tr.incident_edges(v), done = e;
  do {
    if (tr.is_infinite(*e) || !e->first->is_constrained(e->second)) continue;
    const Vertex_handle a = e->first->vertex(Cdt::cw(e->second)), b = e->first->vertex(Cdt::ccw(e->second));
    const Vertex_handle other = a == v ? b : a;
    if (other == from) continue;
    next = other;
    ++n;
  } while (++e != done);
  return n == 1;
}

// Whether c -> d points the way of a -> b (within 6 degrees).
bool same_direction(const Point_2& a, const Point_2& b, const Point_2& c, const Point_2& d) {
  const double ax = b.x() - a.x(), ay = b.y() - a.y(), bx = d.x() - c.x(), by = d.y() - c.y();
  const double dot = ax * bx + ay * by, cross = ax * by - ay * bx;
  return dot > 0 && std::abs(cross) <= 0.1 * dot;
}
// Whether v -> w continues u -> v straight (turning by less than 6 degrees).
bool goes_straight(const Point_2& u, const Point_2& v, const Point_2& w) { return same_direction(u, v, v, w); }

// Whether a -> b and c -> d are equally long to rounding (1024 units of
// rounding of their largest coordinate: the pieces of a structured mesh's
// side, whose ends were each rounded once). A choice of which pieces to split,
// not a combinatorial predicate: floating point.
bool same_length(const Point_2& a, const Point_2& b, const Point_2& c, const Point_2& d) {
  const double reach = std::max({std::abs(a.x()), std::abs(a.y()), std::abs(b.x()), std::abs(b.y()), std::abs(c.x()),
                                 std::abs(c.y()), std::abs(d.x()), std::abs(d.y())});
  const double first = std::sqrt(squared_distance(a, b)), second = std::sqrt(squared_distance(c, d));
  return std::abs(first - second) <= 1024 * std::numeric_limits<double>::epsilon() * reach;
}

bool is_input(const Vertex_handle& v) { return v->info().index >= 0; }

// The input pieces of the length of from -> at that continue it straight
// beyond `at` and were split (a sub-segment of them has an inserted end),
// among the next `reach` such pieces: the chain of sub-segments is walked
// piece by piece (input point to input point), stopping at a turn, at a
// piece of another length or at a vertex on more than two constraints.
int split_pieces_beyond(const Cdt& tr, Vertex_handle from, Vertex_handle at, int reach) {
  const Point_2 seed_from = from->point(), seed_to = at->point();
  int split = 0;
  for (int k = 0; k < reach; ++k) {
    const Vertex_handle start = at;
    bool inserted = false;
    Vertex_handle next;
    do {
      if (!next_in_chain(tr, from, at, next) || !goes_straight(seed_from, start->point(), next->point())) {
        return split;
      }
      from = at;
      at = next;
      inserted = inserted || !is_input(at);
    } while (!is_input(at));
    if (!same_length(seed_from, seed_to, start->point(), at->point())) return split;
    split += inserted ? 1 : 0;
  }
  return split;
}

// A sub-segment by its sorted end points, with its ends.
using Sub_segment = std::pair<std::array<Point_2, 2>, std::array<Vertex_handle, 2>>;

Sub_segment sub_segment(Vertex_handle a, Vertex_handle b) {
  if (b->point() < a->point()) std::swap(a, b);
  return {{a->point(), b->point()}, {a, b}};
}

// Splits that march along a run of input pieces of one length (a side of a
// structured mesh; a run turns by less than 6 degrees where two pieces meet)
// are finished in one go. There a split makes bad
// triangles whose points encroach the next piece or the one after, the next
// split does the same, and the splits march along the run one piece every
// few rounds (measured: 158 rounds at 1e5 points, four such marches along
// two sides of the square, every other piece split). When a piece is to be
// split with at least two split pieces of its run among the four beyond one
// of its ends, the rest of the run the other way is queued for splitting
// too: its pieces are split in the next rounds (as independent candidates,
// sub-segments first), whether or not the march would have reached them.
// Only input pieces are queued, each once, so the extra points are at most
// one per input piece. Which pieces are queued is a function of the round's
// mesh: a walk from a seed in one direction follows the run to its end, and
// a walk that meets a piece another walk of the round took the same way
// stops there (it would go on alike).
class Marching_runs {
 public:
  // Queues the runs that the splits of `seeds` march along.
  void add_marching_runs(const Cdt& tr, const std::vector<Sub_segment>& seeds) {
    walked_.clear();
    for (const auto& [ends, v] : seeds) {
      Edge e;
      if (!is_input(v[0]) || !is_input(v[1]) || !constrained_edge(tr, v[0], v[1], e)) continue;
      for (int dir = 0; dir < 2; ++dir) {
        if (split_pieces_beyond(tr, v[1 - dir], v[dir], kReach) < kMarch) continue;
        Vertex_handle from = v[dir], at = v[1 - dir], next;
        // (straight piece to piece and against the seed's piece: a polygon of many
        // equal sides, a circular hole, turns little at each corner but is no run)
        while (next_in_chain(tr, from, at, next) && is_input(next) &&
               goes_straight(from->point(), at->point(), next->point()) &&
               same_direction(v[dir]->point(), v[1 - dir]->point(), at->point(), next->point()) &&
               same_length(from->point(), at->point(), at->point(), next->point())) {
          if (!walked_.insert({at->point(), next->point()}).second) break;
          Sub_segment s = sub_segment(at, next);
          if (queued_.insert(s.first).second) pending_.push_back(s);
          from = at;
          at = next;
        }
      }
    }
  }
  // Appends the queued pieces not split yet to `edges` (and forgets the others).
  void append_pending(const Cdt& tr, std::vector<Sub_segment>& edges) {
    Edge e;
    pending_.erase(std::remove_if(pending_.begin(), pending_.end(),
                                  [&](const Sub_segment& s) { return !constrained_edge(tr, s.second[0], s.second[1], e); }),
                   pending_.end());
    edges.insert(edges.end(), pending_.begin(), pending_.end());
  }

 private:
  static constexpr int kReach = 4;  // pieces looked at beyond a seed
  static constexpr int kMarch = 2;  // split pieces among them that make a march

  std::set<std::array<Point_2, 2>> walked_;  // this round's walks: pieces, directed as walked
  std::set<std::array<Point_2, 2>> queued_;  // every piece queued so far, by sorted ends
  std::vector<Sub_segment> pending_;         // queued pieces, until split
};

}  // namespace

Rounds_report Mesher::run_in_rounds(std::size_t budget, std::size_t max_rounds) {
  Rounds_report report;
  Cdt& tr = faces_.triangulation();
  auto& edge_visitor = visitor_.previous_level();
  std::vector<Candidate> candidates;
  std::unordered_set<const void*> blocked;  // faces of chosen cavities and their neighbours
  Marching_runs runs;
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
    std::vector<Sub_segment> edges;
    while (!edges_.no_longer_element_to_refine()) {
      const Edge e = edges_.get_next_element();
      edges_.pop_next_element();
      edges.push_back(sub_segment(e.first->vertex(Cdt::cw(e.second)), e.first->vertex(Cdt::ccw(e.second))));
    }
    runs.add_marching_runs(tr, edges);
    runs.append_pending(tr, edges);
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
