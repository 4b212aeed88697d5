#include "evomesh/refinement.hpp"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Constrained_Delaunay_triangulation_face_base_2.h>
#include <CGAL/Delaunay_mesh_face_base_2.h>
#include <CGAL/Mesh_2/Clusters.h>
#include <CGAL/Mesh_2/Face_badness.h>
#include <CGAL/Mesh_2/Refine_edges_with_clusters.h>  // before the visitor, as in Delaunay_mesher_2.h
#include <CGAL/Mesh_2/Refine_edges_visitor.h>
#include <CGAL/Mesh_2/Refine_faces.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "evomesh/detail/domain.hpp"
#include "evomesh/kernel.hpp"

namespace evomesh {

namespace {

constexpr double kPi = 3.14159265358979323846;

struct Vertex_info {
  Index index = -1;    // input point, -1 for an inserted one
  Index out = -1;      // output index (extraction)
  double f = -1;       // spacing function here; < 0: not known yet
  Index site = -1;     // Apollonius site that attains f here
  bool exact = false;  // f evaluated exactly (else from the sites of neighbours)
};

using Vb = CGAL::Triangulation_vertex_base_with_info_2<Vertex_info, Kernel>;
using Fb_info = CGAL::Triangulation_face_base_with_info_2<std::int8_t, Kernel>;  // flood-fill label
using Fb_constrained = CGAL::Constrained_triangulation_face_base_2<Kernel, Fb_info>;
using Fb_cdt = CGAL::Constrained_Delaunay_triangulation_face_base_2<Kernel, Fb_constrained>;
using Fb = CGAL::Delaunay_mesh_face_base_2<Kernel, Fb_cdt>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
// As in constrained_delaunay: constraints may pass through points, never cross.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<
    Kernel, Tds, CGAL::No_constraint_intersection_requiring_constructions_tag>;
using Vertex_handle = Cdt::Vertex_handle;
using Face_handle = Cdt::Face_handle;

// The triangulation works on the points scaled by a power of two (exact) to
// magnitude about 1: CGAL's circumcentres and the quality measures multiply three
// lengths, which would overflow for coordinates near 1e150 (or underflow near 1e-150).
struct Scaling {
  double to_unit = 1;
  double from_unit = 1;
};

Scaling unit_scaling(const std::vector<Vec2>& points) {
  double largest = 0;
  for (const auto& p : points) largest = std::max({largest, std::abs(p[0]), std::abs(p[1])});
  if (!(largest > 0) || !std::isfinite(largest)) return {};
  const int e = std::ilogb(largest);
  const Scaling s{std::ldexp(1.0, -e), std::ldexp(1.0, e)};
  // Exact unless a coordinate would become subnormal; then keep the input scale.
  for (const auto& p : points) {
    for (double x : p) {
      const double y = x * s.to_unit;
      if (y * s.from_unit != x || (y != 0 && !std::isnormal(y))) return {};
    }
  }
  return s;
}

// Spacing data for rule 4 (Section 5): sites and weights of f = min_s (w_s + |x - s|)
// in input units; f at the vertices is kept in the triangulation's units.
struct Spacing_data {
  const std::vector<Vec2>* sites = nullptr;
  const std::vector<double>* weights = nullptr;
  Scaling scaling;
};

double squared_distance(const Point_2& a, const Point_2& b) {
  const double dx = a.x() - b.x(), dy = a.y() - b.y();
  return dx * dx + dy * dy;
}

// Squared length of the shortest edge at v: the Delaunay neighbour spacing. It is
// never below the true nn spacing, so nn(v) <= f(v) follows from it.
double neighbour_spacing_squared(const Cdt& tr, Vertex_handle v) {
  double best = std::numeric_limits<double>::infinity();
  auto c = tr.incident_vertices(v), done = c;
  do {
    if (!tr.is_infinite(c)) best = std::min(best, squared_distance(v->point(), c->point()));
  } while (++c != done);
  return best;
}

// f at an inserted vertex while refining: the cones of its neighbours' sites. This
// is f over a subset of the cones, so never below f; exact values replace it after
// each pass.
double target_spacing(const Cdt& tr, Vertex_handle v, const Spacing_data& spacing) {
  auto& info = v->info();
  if (info.f >= 0) return info.f;
  double best = std::numeric_limits<double>::infinity();
  Index best_site = -1;
  const double x = v->point().x() * spacing.scaling.from_unit, y = v->point().y() * spacing.scaling.from_unit;
  auto c = tr.incident_vertices(v), done = c;
  do {
    if (tr.is_infinite(c) || c->info().site < 0) continue;
    const Index s = c->info().site;
    const Vec2& p = (*spacing.sites)[s];
    const double value = (*spacing.weights)[s] + std::hypot(x - p[0], y - p[1]);
    if (value < best) {
      best = value;
      best_site = s;
    }
  } while (++c != done);
  if (best_site < 0) return best;  // no neighbour knows a site yet: no rule 4 here
  info.f = best * spacing.scaling.to_unit;
  info.site = best_site;
  return info.f;
}

// Face criteria for CGAL's Delaunay mesher. Quality: for a triangle that breaks
// rule 4, minus (circumradius / f)^2 of its worst vertex, so the largest such
// triangles are split first; otherwise the squared sine of its smallest angle (as
// Delaunay_mesh_criteria_2), bad below sin^2(min_angle) (rule 3).
class Refinement_criteria {
 public:
  using Quality = double;

  Refinement_criteria(double min_angle_degrees, const Cdt& tr, const Spacing_data* spacing, bool off_centres)
      : bound_(std::pow(std::sin(min_angle_degrees * kPi / 180.0), 2)),
        min_angle_(min_angle_degrees),
        off_centres_(off_centres),
        tr_(&tr),
        spacing_(spacing) {}

  // Cotangent of half the angle under which an off-centre sees the short edge;
  // infinite (always the circumcentre) without off-centres. That angle is a little
  // above the target, so rounding cannot make the new triangle bad again.
  double off_centre_half_angle_cotangent() const {
    if (!off_centres_) return std::numeric_limits<double>::infinity();
    return 1.0 / std::tan(0.5 * std::min(1.02 * min_angle_, 60.0) * kPi / 180.0);
  }

  class Is_bad {
   public:
    Is_bad(double bound, const Cdt* tr, const Spacing_data* spacing) : bound_(bound), tr_(tr), spacing_(spacing) {}

    CGAL::Mesh_2::Face_badness operator()(Quality q) const {
      return q < bound_ ? CGAL::Mesh_2::BAD : CGAL::Mesh_2::NOT_BAD;
    }

    CGAL::Mesh_2::Face_badness operator()(const Face_handle& fh, Quality& q) const {
      const Point_2& pa = fh->vertex(0)->point();
      const Point_2& pb = fh->vertex(1)->point();
      const Point_2& pc = fh->vertex(2)->point();
      // Edge lengths, not their products (which could leave the range of double).
      const double a = std::sqrt(squared_distance(pb, pc)), b = std::sqrt(squared_distance(pc, pa)),
                   c = std::sqrt(squared_distance(pa, pb));
      const double twice_area = (pb.x() - pa.x()) * (pc.y() - pa.y()) - (pb.y() - pa.y()) * (pc.x() - pa.x());
      if (spacing_ != nullptr) {
        // Rule 4: a vertex whose neighbour spacing exceeds f there.
        double worst = 0;
        for (int k = 0; k < 3; ++k) {
          const Vertex_handle v = fh->vertex(k);
          const double f = target_spacing(*tr_, v, *spacing_);
          if (!(f < std::numeric_limits<double>::infinity())) continue;
          if (std::sqrt(neighbour_spacing_squared(*tr_, v)) > f) {
            const double circumradius = a / twice_area * b * c / 2;
            worst = std::max(worst, (circumradius / f) * (circumradius / f));
          }
        }
        if (worst > 0) {
          q = rounded(-worst);
          return CGAL::Mesh_2::BAD;
        }
      }
      // Squared sine of the angle opposite the shortest edge: 2 area / (product of the others).
      double sine;
      if (a < b) sine = a < c ? twice_area / b / c : twice_area / a / b;
      else sine = b < c ? twice_area / a / c : twice_area / a / b;
      q = rounded(sine * sine);
      return operator()(q);
    }

   private:
    // The queue order must not depend on rounding: the same mesh scaled by 1e-100
    // has qualities equal up to a few ulps, and near-ties would then be refined in
    // another order. Rounded to float, they tie exactly and CGAL breaks ties by the
    // points' lexicographic order, which scaling keeps.
    static double rounded(double q) { return static_cast<double>(static_cast<float>(q)); }

    double bound_;
    const Cdt* tr_;
    const Spacing_data* spacing_;
  };

  Is_bad is_bad_object() const { return Is_bad(bound_, tr_, spacing_); }

 private:
  double bound_;
  double min_angle_;
  bool off_centres_;
  const Cdt* tr_;
  const Spacing_data* spacing_;
};

using Gabriel = CGAL::Mesh_2::Is_locally_conforming_Gabriel<Cdt>;
using Edges_base_with_clusters = CGAL::Mesh_2::Refine_edges_base_with_clusters<Cdt, Gabriel>;

// Edge level that can also be told to split a given constraint edge (Section 6:
// a segment crowded by points is split instead of keeping them).
struct Edges_base : Edges_base_with_clusters {
  using Edges_base_with_clusters::Edges_base_with_clusters;
  void queue_split(Cdt::Vertex_handle a, Cdt::Vertex_handle b) { this->add_constrained_edge_to_be_conformed(a, b); }
};
using Edges_level = CGAL::Mesh_2::Refine_edges_with_clusters<Cdt, Gabriel, Edges_base>;

using Faces_base_cgal = CGAL::Mesh_2::Refine_faces_base<Cdt, Refinement_criteria, Edges_level>;

// Rule 4 is about vertices: a triangle queued as bad can become good when a point
// is inserted next to one of its vertices without destroying it. Such stale
// entries are dropped before the mesher looks at the queue.
//
// In the quality pass badly shaped triangles are split at their off-centre (Ungor,
// "Off-centers", 2004) rather than their circumcentre: the point on the bisector of
// the shortest edge pq, towards the circumcentre, from which pq is seen under the
// target angle; the circumcentre when that is nearer. Same guarantees as Ruppert's
// rule 3 with fewer points. DRFC's refinement uses circumcentres (Ruppert, Section 5).
struct Faces_base : Faces_base_cgal {
  Faces_base(Cdt& tr, Refinement_criteria& criteria, Edges_level& edges)
      : Faces_base_cgal(tr, criteria, edges),
        half_angle_cotangent_(criteria.off_centre_half_angle_cotangent()) {}

  Point_2 refinement_point_impl(const Cdt::Face_handle& f) const {
    const Point_2 c = this->triangulation_ref_impl().circumcenter(f);
    Refinement_criteria::Quality q;
    this->is_bad(f, q);
    if (q < 0) return c;  // rule 4 (size): the circumcentre
    int k = 0;  // the shortest edge is opposite vertex k
    double shortest = std::numeric_limits<double>::infinity();
    for (int i = 0; i < 3; ++i) {
      const double l = squared_distance(f->vertex(Cdt::ccw(i))->point(), f->vertex(Cdt::cw(i))->point());
      if (l < shortest) {
        shortest = l;
        k = i;
      }
    }
    const Point_2& p = f->vertex(Cdt::ccw(k))->point();
    const Point_2& r = f->vertex(Cdt::cw(k))->point();
    const double mx = 0.5 * (p.x() + r.x()), my = 0.5 * (p.y() + r.y());
    const double dx = c.x() - mx, dy = c.y() - my;
    const double to_centre = std::hypot(dx, dy);
    const double height = 0.5 * std::sqrt(shortest) * half_angle_cotangent_;
    if (!(to_centre > height)) return c;
    return Point_2(mx + dx / to_centre * height, my + dy / to_centre * height);
  }

  bool no_longer_element_to_refine_impl() {
    while (!this->bad_faces.empty()) {
      Refinement_criteria::Quality q;
      if (this->is_bad(this->bad_faces.front()->second, q) != CGAL::Mesh_2::NOT_BAD) break;
      this->bad_faces.pop_front();
    }
    return this->bad_faces.empty();
  }

 private:
  double half_angle_cotangent_;
};
using Faces_level = CGAL::Mesh_2::Refine_faces<Cdt, Refinement_criteria, Edges_level, Faces_base>;
using Visitor = CGAL::Mesh_2::Refine_edges_visitor_from_faces<Faces_level>;

// CGAL's Delaunay_mesher_2, wired with the levels above, driven one point at a
// time so the number of insertions can be bounded. The domain is marked by the
// caller (in_domain flags); the levels keep the marks up to date.
class Mesher {
 public:
  Mesher(Cdt& tr, const Refinement_criteria& criteria)
      : criteria_(criteria),
        clusters_(tr),
        edges_(tr, clusters_, null_level_),
        faces_(tr, criteria_, edges_),
        visitor_(faces_, edges_, null_visitor_) {}

  void init() {
    clusters_.create_clusters();
    edges_.scan_triangulation();
    faces_.scan_triangulation();
  }
  void queue_split(Vertex_handle a, Vertex_handle b) { edges_.queue_split(a, b); }
  void rescan_faces() { faces_.scan_triangulation(); }
  // Inserts one point; false when nothing is left to refine.
  bool insert_one_point() { return faces_.try_to_insert_one_point(visitor_); }
  bool is_done() { return faces_.is_algorithm_done(); }

 private:
  Refinement_criteria criteria_;
  CGAL::Null_mesher_level null_level_;
  CGAL::Null_mesh_visitor null_visitor_;
  CGAL::Mesh_2::Clusters<Cdt> clusters_;
  Edges_level edges_;
  Faces_level faces_;
  Visitor visitor_;
};

std::vector<Vertex_handle> insert_points(Cdt& cdt, const std::vector<Vec2>& points, const Scaling& scaling) {
  std::vector<std::pair<Point_2, Vertex_info>> input;
  input.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    Vertex_info info;
    info.index = static_cast<Index>(i);
    input.emplace_back(Point_2(points[i][0] * scaling.to_unit, points[i][1] * scaling.to_unit), info);
  }
  cdt.insert(input.begin(), input.end());
  if (cdt.number_of_vertices() != points.size()) throw Input_error("points contain duplicates");
  std::vector<Vertex_handle> handles(points.size());
  for (auto v = cdt.finite_vertices_begin(); v != cdt.finite_vertices_end(); ++v) handles[v->info().index] = v;
  return handles;
}

// The face on the left of a -> b (f, with the edge opposite vertex i), if ab is an edge.
bool left_face(const Cdt& cdt, Vertex_handle a, Vertex_handle b, Face_handle& f, int& i) {
  if (!cdt.is_edge(a, b, f, i)) return false;
  if (f->vertex(Cdt::ccw(i)) != a) {
    const Face_handle g = f->neighbor(i);
    i = g->index(f);
    f = g;
  }
  return true;
}

// in_domain marks: regions bounded by the pieces take the side labels of their
// pieces (left of a boundary piece: inside; right: outside), as in constrained_delaunay.
void mark_domain(Cdt& cdt, const std::vector<Vertex_handle>& handles, const std::vector<Constraint_piece>& pieces) {
  detail::label_domain(cdt, handles, pieces, "refinement");
  for (auto f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f) f->set_in_domain(f->info() == detail::domain_inside);
}

// Section 6: drop free points that crowd a piece (see it under more than
// crowding_angle) and return the pieces to split instead. The apex of a side of a
// constrained Delaunay edge sees it under the largest angle of all points visible
// on that side, so only apexes need testing.
std::vector<std::pair<Vertex_handle, Vertex_handle>> drop_crowding_points(
    Cdt& cdt, const std::vector<Vertex_handle>& handles, const std::vector<Constraint_piece>& pieces,
    double crowding_angle, std::vector<std::uint8_t>& removed, Refinement_report& report) {
  std::vector<std::pair<Vertex_handle, Vertex_handle>> crowded;
  const double cos_bound = std::cos(crowding_angle * kPi / 180.0);
  auto crowds = [&](const Point_2& a, const Point_2& p, const Point_2& b) {
    // A choice of which points to drop, not a combinatorial predicate: floating point.
    const double ux = a.x() - p.x(), uy = a.y() - p.y(), vx = b.x() - p.x(), vy = b.y() - p.y();
    return ux * vx + uy * vy < cos_bound * std::sqrt((ux * ux + uy * uy) * (vx * vx + vy * vy));
  };
  for (const auto& piece : pieces) {
    const Vertex_handle a = handles[piece.a], b = handles[piece.b];
    bool dropped = false;
    for (int side = 0; side < (piece.boundary ? 1 : 2); ++side) {
      const Vertex_handle from = side == 0 ? a : b, to = side == 0 ? b : a;
      while (true) {
        Face_handle f;
        int i;
        if (!left_face(cdt, from, to, f, i)) break;
        const Vertex_handle apex = f->vertex(i);
        if (cdt.is_infinite(apex) || cdt.are_there_incident_constraints(apex)) break;
        if (!crowds(a->point(), apex->point(), b->point())) break;
        removed[apex->info().index] = 1;
        cdt.remove(apex);
        ++report.n_removed;
        dropped = true;
      }
    }
    if (dropped) crowded.emplace_back(a, b);
  }
  report.n_crowded_segments = crowded.size();
  return crowded;
}

std::size_t run_mesher(Mesher& mesher, std::size_t budget, Refinement_report& report) {
  std::size_t inserted = 0;
  while (inserted < budget && mesher.insert_one_point()) ++inserted;
  if (inserted == budget && !mesher.is_done()) report.capped = true;
  report.n_inserted += inserted;
  return inserted;
}

// Input points keep their exact input coordinates; f is returned in input units.
Refined_mesh extract(Cdt& cdt, const std::vector<Vec2>& input_points, const std::vector<Point_kind>& input_kind,
                     const std::vector<std::uint8_t>& removed, const Scaling& scaling) {
  Refined_mesh result;
  Mesh_arrays& out = result.mesh;
  const std::size_t n = input_kind.size();
  std::vector<Index> input_to_out(n, -1);
  for (std::size_t i = 0; i < n; ++i) {
    if (removed[i]) continue;
    input_to_out[i] = static_cast<Index>(result.source.size());
    result.source.push_back(static_cast<Index>(i));
  }
  std::vector<Vertex_handle> inserted;
  for (auto v = cdt.finite_vertices_begin(); v != cdt.finite_vertices_end(); ++v) {
    if (v->info().index >= 0) v->info().out = input_to_out[v->info().index];
    else inserted.push_back(v);
  }
  std::sort(inserted.begin(), inserted.end(), [](Vertex_handle u, Vertex_handle w) {
    return u->point().x() < w->point().x() || (u->point().x() == w->point().x() && u->point().y() < w->point().y());
  });
  const std::size_t n_out = result.source.size() + inserted.size();
  out.points.resize(n_out);
  out.kind.resize(n_out);
  result.f.resize(n_out);
  for (auto v = cdt.finite_vertices_begin(); v != cdt.finite_vertices_end(); ++v) {
    if (v->info().index < 0) continue;
    const Index o = v->info().out;
    out.points[o] = input_points[v->info().index];
    out.kind[o] = input_kind[v->info().index];
    result.f[o] = v->info().f * scaling.from_unit;
  }
  for (std::size_t k = 0; k < inserted.size(); ++k) {
    const Index o = static_cast<Index>(result.source.size() + k);
    inserted[k]->info().out = o;
    out.points[o] = {inserted[k]->point().x() * scaling.from_unit, inserted[k]->point().y() * scaling.from_unit};
    out.kind[o] = Point_kind::sampled;
    result.f[o] = inserted[k]->info().f * scaling.from_unit;
  }
  result.source.resize(n_out, -1);
  for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
    if (f->is_in_domain()) {
      out.triangles.push_back({f->vertex(0)->info().out, f->vertex(1)->info().out, f->vertex(2)->info().out});
    }
  }
  // Constraint edges: boundary ones oriented with the domain on their left.
  std::vector<std::pair<Edge, std::uint8_t>> segments;
  for (auto e = cdt.finite_edges_begin(); e != cdt.finite_edges_end(); ++e) {
    const Face_handle f = e->first;
    const int i = e->second;
    if (!f->is_constrained(i)) continue;
    const Face_handle g = f->neighbor(i);
    const bool f_in = !cdt.is_infinite(f) && f->is_in_domain();
    const bool g_in = !cdt.is_infinite(g) && g->is_in_domain();
    const Index a = f->vertex(Cdt::ccw(i))->info().out, b = f->vertex(Cdt::cw(i))->info().out;
    if (f_in && g_in) segments.push_back({{std::min(a, b), std::max(a, b)}, 0});
    else if (f_in) segments.push_back({{a, b}, 1});
    else if (g_in) segments.push_back({{b, a}, 1});
    else throw std::runtime_error("refinement: a constraint lies outside the domain");
  }
  std::sort(segments.begin(), segments.end());
  for (const auto& s : segments) {
    out.segments.push_back(s.first);
    out.segment_is_boundary.push_back(s.second);
    for (Index v : s.first) {
      if (out.kind[v] > Point_kind::boundary) out.kind[v] = Point_kind::boundary;
      if (result.source[v] < 0) ++result.report.n_inserted_on_segments;
    }
  }
  // Each new point on a constraint was counted once per constraint edge at it (two).
  result.report.n_inserted_on_segments /= 2;
  return result;
}

}  // namespace

std::pair<double, Vec2> smallest_angle(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles) {
  double best = 180.0;
  Vec2 where{0, 0};
  for (const auto& t : triangles) {
    for (int k = 0; k < 3; ++k) {
      const Vec2& p = points[t[k]];
      const Vec2& q = points[t[(k + 1) % 3]];
      const Vec2& r = points[t[(k + 2) % 3]];
      const double ux = q[0] - p[0], uy = q[1] - p[1], vx = r[0] - p[0], vy = r[1] - p[1];
      const double angle = std::atan2(std::abs(ux * vy - uy * vx), ux * vx + uy * vy) * 180.0 / kPi;
      if (angle < best) {
        best = angle;
        where = {(p[0] + q[0] + r[0]) / 3.0, (p[1] + q[1] + r[1]) / 3.0};
      }
    }
  }
  return {best, where};
}

namespace {


// The quality pass on `cdt`, which holds all points (handles by point index).
Refined_mesh quality_pass(Cdt& cdt, const std::vector<Vertex_handle>& handles, const Scaling& scaling,
                          const std::vector<Vec2>& points, const std::vector<Point_kind>& kind,
                          const std::vector<Constraint_piece>& pieces, const Quality_options& options) {
  for (const auto& piece : pieces) cdt.insert_constraint(handles[piece.a], handles[piece.b]);
  Refinement_report report;
  std::vector<std::uint8_t> removed(points.size(), 0);
  std::vector<std::pair<Vertex_handle, Vertex_handle>> crowded;
  if (options.crowding_angle > 0) {
    crowded = drop_crowding_points(cdt, handles, pieces, options.crowding_angle, removed, report);
  }
  mark_domain(cdt, handles, pieces);
  Mesher mesher(cdt, Refinement_criteria(options.min_angle, cdt, nullptr, /*off_centres=*/true));
  mesher.init();
  for (const auto& e : crowded) mesher.queue_split(e.first, e.second);
  const double budget = options.max_inserted_fraction * static_cast<double>(points.size()) + options.max_inserted_extra;
  run_mesher(mesher, static_cast<std::size_t>(std::max(0.0, budget)), report);
  report.rounds = 1;
  Refined_mesh result = extract(cdt, points, kind, removed, scaling);
  result.f.clear();
  result.report.n_inserted = report.n_inserted;
  result.report.n_removed = report.n_removed;
  result.report.n_crowded_segments = report.n_crowded_segments;
  result.report.rounds = report.rounds;
  result.report.capped = report.capped;
  return result;
}

// Whether every point scales exactly (and stays normal) with `s`.
bool scales_exactly(const Vec2* begin, const Vec2* end, const Scaling& s) {
  for (const Vec2* p = begin; p != end; ++p) {
    for (double x : *p) {
      const double y = x * s.to_unit;
      if (y * s.from_unit != x || (y != 0 && !std::isnormal(y))) return false;
    }
  }
  return true;
}

}  // namespace

Refined_mesh quality_triangulate(const std::vector<Vec2>& points, const std::vector<Point_kind>& kind,
                                 const std::vector<Constraint_piece>& pieces, const Quality_options& options) {
  options.validate();
  Cdt cdt;
  const Scaling scaling = unit_scaling(points);
  const auto handles = insert_points(cdt, points, scaling);
  return quality_pass(cdt, handles, scaling, points, kind, pieces, options);
}

struct Early_triangulation::Impl {
  Cdt cdt;
  Scaling scaling;
  std::size_t n_first = 0;
  bool started = false;
};

Early_triangulation::Early_triangulation() : impl_(std::make_unique<Impl>()) {}
Early_triangulation::~Early_triangulation() = default;

void Early_triangulation::insert_first(const std::vector<Vec2>& first) {
  Impl& impl = *impl_;
  impl.scaling = unit_scaling(first);
  insert_points(impl.cdt, first, impl.scaling);
  impl.n_first = first.size();
  impl.started = true;
}

Refined_mesh Early_triangulation::finish(const std::vector<Vec2>& points, const std::vector<Point_kind>& kind,
                                         const std::vector<Constraint_piece>& pieces, const Quality_options& options) {
  Impl& impl = *impl_;
  options.validate();
  if (!impl.started || impl.n_first > points.size() ||
      !scales_exactly(points.data() + impl.n_first, points.data() + points.size(), impl.scaling) ||
      unit_scaling(points).to_unit != impl.scaling.to_unit) {
    return quality_triangulate(points, kind, pieces, options);
  }
  Cdt& cdt = impl.cdt;
  std::vector<std::pair<Point_2, Vertex_info>> input;
  input.reserve(points.size() - impl.n_first);
  for (std::size_t i = impl.n_first; i < points.size(); ++i) {
    Vertex_info info;
    info.index = static_cast<Index>(i);
    input.emplace_back(Point_2(points[i][0] * impl.scaling.to_unit, points[i][1] * impl.scaling.to_unit), info);
  }
  cdt.insert(input.begin(), input.end());
  if (cdt.number_of_vertices() != points.size()) throw Input_error("points contain duplicates");
  std::vector<Vertex_handle> handles(points.size());
  for (auto v = cdt.finite_vertices_begin(); v != cdt.finite_vertices_end(); ++v) handles[v->info().index] = v;
  return quality_pass(cdt, handles, impl.scaling, points, kind, pieces, options);
}

Refined_mesh spacing_refine(const Mesh_arrays& mesh, const Spacing_function& spacing,
                            const std::vector<double>& f_at_points, double min_angle,
                            std::size_t max_inserted, int threads) {
  const std::size_t n = mesh.points.size();
  if (f_at_points.size() != n) throw Input_error("spacing_refine: one f value per point");
  if (!(min_angle >= 0 && min_angle < 60)) throw Input_error("min_angle must be in [0, 60)");
  Cdt cdt;
  const Scaling scaling = unit_scaling(mesh.points);
  const auto handles = insert_points(cdt, mesh.points, scaling);
  std::vector<Constraint_piece> pieces(mesh.segments.size());
  for (std::size_t k = 0; k < pieces.size(); ++k) {
    pieces[k] = {mesh.segments[k][0], mesh.segments[k][1], mesh.segment_is_boundary[k] != 0};
    cdt.insert_constraint(handles[pieces[k].a], handles[pieces[k].b]);
  }
  // Sites of the input points: the Apollonius nearest site, or the point itself
  // where its own cone is the minimum (f(p) = delta(p) nn(p), Lemma 3.1).
  {
    std::vector<double> f_eval(n);
    std::vector<Index> site(n);
    spacing.evaluate(mesh.points.data(), n, f_eval.data(), site.data(), threads);
    const auto& weights = spacing.weights();
    for (std::size_t i = 0; i < n; ++i) {
      auto& info = handles[i]->info();
      info.f = f_at_points[i] * scaling.to_unit;
      info.site = weights[i] <= f_eval[i] ? static_cast<Index>(i) : site[i];
      info.exact = true;
    }
  }
  mark_domain(cdt, handles, pieces);
  const Spacing_data data{&spacing.sites(), &spacing.weights(), scaling};
  Mesher mesher(cdt, Refinement_criteria(min_angle, cdt, &data, /*off_centres=*/false));
  mesher.init();
  Refinement_report report;
  std::vector<Vertex_handle> estimated;
  std::vector<Vec2> queries;
  std::vector<double> values;
  std::vector<Index> sites;
  while (true) {
    ++report.rounds;
    const std::size_t inserted = run_mesher(mesher, max_inserted - report.n_inserted, report);
    // Exact f at the points inserted in this pass; a lower f can break rule 4 again.
    estimated.clear();
    for (auto v = cdt.finite_vertices_begin(); v != cdt.finite_vertices_end(); ++v) {
      if (!v->info().exact) estimated.push_back(v);
    }
    queries.resize(estimated.size());
    for (std::size_t k = 0; k < estimated.size(); ++k) {
      queries[k] = {estimated[k]->point().x() * scaling.from_unit, estimated[k]->point().y() * scaling.from_unit};
    }
    values.resize(estimated.size());
    sites.resize(estimated.size());
    spacing.evaluate(queries.data(), queries.size(), values.data(), sites.data(), threads);
    for (std::size_t k = 0; k < estimated.size(); ++k) {
      auto& info = estimated[k]->info();
      info.f = values[k] * scaling.to_unit;
      info.site = sites[k];
      info.exact = true;
    }
    if (inserted == 0 || report.capped) break;
    mesher.rescan_faces();
  }
  std::vector<std::uint8_t> removed(n, 0);
  Refined_mesh result = extract(cdt, mesh.points, mesh.kind, removed, scaling);
  result.report.n_inserted = report.n_inserted;
  result.report.rounds = report.rounds;
  result.report.capped = report.capped;
  return result;
}

}  // namespace evomesh
