// The machinery of Delaunay refinement with CGAL shared by the quality pass
// (quality_pass.cpp, Section 6) and DRFC's refinement (drfc_refinement.cpp,
// Section 5): a constrained Delaunay triangulation whose vertices carry f, the
// face criteria (Ruppert's rule 3, and rule 4 in terms of f), the mesher levels,
// and the extraction of the result. Internal: include from .cpp files only.
#pragma once

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
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <stdexcept>
#include <unordered_set>
#include <utility>
#include <vector>

#include "evomesh/detail/insert_points.hpp"
#include "evomesh/detail/parallel_sweep.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/kernel.hpp"
#include "evomesh/refined_mesh.hpp"
#include "evomesh/triangulation.hpp"
#include "evomesh/types.hpp"

namespace evomesh::detail {

inline constexpr double kPi = 3.14159265358979323846;

struct Vertex_info {
  Index index = -1;    // input point, -1 for an inserted one
  Index out = -1;      // output index (extraction)
  double f = -1;       // spacing function here; < 0: not known yet
  Index site = -1;     // Apollonius site that attains f here
  bool exact = false;  // f evaluated exactly (else from the sites of neighbours)
};
// The input point of a vertex (for detail::insert_points).
inline Index& vertex_index(Vertex_info& info) { return info.index; }

using Vb = CGAL::Triangulation_vertex_base_with_info_2<Vertex_info, Kernel>;
using Fb_info = CGAL::Triangulation_face_base_with_info_2<std::int8_t, Kernel>;  // flood-fill label
using Fb_constrained = CGAL::Constrained_triangulation_face_base_2<Kernel, Fb_info>;
using Fb_cdt = CGAL::Constrained_Delaunay_triangulation_face_base_2<Kernel, Fb_constrained>;
using Fb_mesh = CGAL::Delaunay_mesh_face_base_2<Kernel, Fb_cdt>;

// A face base with the number of the face's entry in the mesher's queue of bad
// faces (Bad_face_queue), 0 when it has none. A face the triangulation creates
// starts with 0.
//
// The default constructor must be user-provided: CGAL's container creates faces
// by value-initialisation (`T()`), which zero-fills a class whose default
// constructor is not, and Delaunay_mesh_face_base_2's time stamp must keep the
// "unset" value the container wrote there (its constructors leave it alone):
// zeroed, every such face had time stamp 0, and CGAL's handle comparisons
// (ordered by time stamp) failed their assertion.
template <class Gt, class Base>
class Queued_face_base_2 : public Base {
 public:
  template <class Tds2>
  struct Rebind_TDS {
    using Base2 = typename Base::template Rebind_TDS<Tds2>::Other;
    using Other = Queued_face_base_2<Gt, Base2>;
  };
  Queued_face_base_2() : Base() {}  // NOLINT(modernize-use-equals-default): see above
  using Base::Base;
  std::uint64_t queue_entry = 0;
};
using Fb = Queued_face_base_2<Kernel, Fb_mesh>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
// As in constrained_delaunay: constraints may pass through points, never cross.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<
    Kernel, Tds, CGAL::No_constraint_intersection_requiring_constructions_tag>;
using Vertex_handle = Cdt::Vertex_handle;
using Face_handle = Cdt::Face_handle;

}  // namespace evomesh::detail

// CGAL's Clusters::create_clusters (a triangulation without a constraint
// hierarchy) circulates the edges of every vertex for constrained ones: a
// quarter of the quality pass's set-up on a 1e6-point mesh. Only the vertices
// of constraint edges can have clusters, and the clusters of a vertex are built
// from its own edges alone (the map is keyed by the vertex), so visiting those
// vertices, found by one sweep over the faces (in parallel: parallel_sweep.hpp),
// builds the same map.
template <>
template <>
inline void CGAL::Mesh_2::Clusters<evomesh::detail::Cdt>::create_clusters<CGAL::Tag_false>(CGAL::Tag_false) {
  cluster_map.clear();
  if (tr.dimension() < 2) return;  // (no constraint edges in a face)
  auto& faces = tr.tds().faces();
  std::vector<std::vector<Vertex_handle>> in_chunk(evomesh::detail::sweep_chunks(faces));
  evomesh::detail::parallel_sweep(faces, [&](std::size_t c, evomesh::detail::Face_handle f) {
    if (tr.is_infinite(f)) return;
    for (int i = 0; i < 3; ++i) {
      if (!f->is_constrained(i)) continue;
      in_chunk[c].push_back(f->vertex(evomesh::detail::Cdt::ccw(i)));
      in_chunk[c].push_back(f->vertex(evomesh::detail::Cdt::cw(i)));
    }
  });
  std::vector<Vertex_handle> ends = evomesh::detail::joined(in_chunk);
  std::sort(ends.begin(), ends.end());
  ends.erase(std::unique(ends.begin(), ends.end()), ends.end());
  for (const Vertex_handle& v : ends) create_clusters_of_vertex(v);
}

// CGAL's test of a small angle between consecutive constraint edges (acute, a
// left turn, 4 cos^2 > 1: below 60 degrees), with a margin: an angle within
// rounding of 60 degrees is not small. The corners of a regular triangle
// computed in floating point fell on either side of 60 degrees, and a corner
// taken for a cluster keeps its triangles unrefined (measured: 16-19 degrees
// left at a 60 degree corner of an equilateral domain with min_angle 20).
// Ruppert's refinement ends for input angles of 60 degrees, so nothing is lost.
template <>
inline bool CGAL::Mesh_2::Clusters<evomesh::detail::Cdt>::is_small_angle(const Point& pleft, const Point& pmiddle,
                                                                       const Point& pright) const {
  if (tr.geom_traits().angle_2_object()(pleft, pmiddle, pright) == OBTUSE) return false;
  if (tr.geom_traits().orientation_2_object()(pmiddle, pleft, pright) == RIGHT_TURN) return false;
  // 4 cos^2 drops by 8 cos sin = 3.46 per radian at 60 degrees: the margin is
  // 3e-10 radians.
  return squared_cosine_of_angle_times_4(pleft, pmiddle, pright) > 1 + 1e-9;
}

namespace evomesh::detail {

// The triangulation works on the points scaled by a power of two (exact) to
// magnitude about 1: CGAL's circumcentres and the quality measures multiply three
// lengths, which would overflow for coordinates near 1e150 (or underflow near 1e-150).
struct Scaling {
  double to_unit = 1;
  double from_unit = 1;
};

inline Scaling unit_scaling(const std::vector<Vec2>& points) {
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

inline double squared_distance(const Point_2& a, const Point_2& b) {
  const double dx = a.x() - b.x(), dy = a.y() - b.y();
  return dx * dx + dy * dy;
}

// Squared length of the shortest edge at v: the Delaunay neighbour spacing. It is
// never below the true nn spacing, so nn(v) <= f(v) follows from it.
inline double neighbour_spacing_squared(const Cdt& tr, Vertex_handle v) {
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
inline double target_spacing(const Cdt& tr, Vertex_handle v, const Spacing_data& spacing) {
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

// A face's three points in its canonical rotation: counter-clockwise as given,
// starting at the lexicographically least (x, then y). In the quality pass's
// rounds (quality_rounds.cpp) every floating-point quantity derived from a face
// (its quality, its off-centre) is computed in this rotation, so it does not
// depend on the rotation the triangulation's history gave the face, and
// the pass is a function of its input sets. The serial pass keeps the face's
// stored rotation (its pinned outputs).
inline std::array<Point_2, 3> canonical_rotation(const Point_2& a, const Point_2& b, const Point_2& c) {
  if (b < a && b < c) return {b, c, a};
  if (c < a && c < b) return {c, a, b};
  return {a, b, c};
}
inline std::array<Point_2, 3> canonical_rotation(const Face_handle& f) {
  return canonical_rotation(f->vertex(0)->point(), f->vertex(1)->point(), f->vertex(2)->point());
}

// Face criteria for CGAL's Delaunay mesher. Quality: for a triangle that breaks
// rule 4, minus (circumradius / f)^2 of its worst vertex, so the largest such
// triangles are split first; otherwise the squared sine of its smallest angle (as
// Delaunay_mesh_criteria_2), bad below sin^2(min_angle) (rule 3).
class Refinement_criteria {
 public:
  // Heights (twice the area over the longest edge) below this many units of
  // rounding of the triangle's largest coordinate are not refined for their
  // angles: 16 times Mesh()'s flatness limit, so the triangles a last split
  // makes stay above it. (The triangulation's coordinates are the input's
  // times a power of two: the same units of rounding.)
  static constexpr double kAngleRuleFloorUlps = 16 * 1024;

  using Quality = double;

  // canonical: qualities and refinement points computed in each face's
  // canonical rotation (the rounds of quality_rounds.cpp); false: in the face's
  // stored rotation (the serial pass, as its pinned outputs were made).
  Refinement_criteria(double min_angle_degrees, const Cdt& tr, const Spacing_data* spacing, bool off_centres,
                      bool canonical = false)
      : bound_(angle_bound(min_angle_degrees)),
        min_angle_(min_angle_degrees),
        off_centres_(off_centres),
        canonical_(canonical),
        tr_(&tr),
        spacing_(spacing) {}

  bool is_canonical() const { return canonical_; }

  // The bound of rule 3 on the squared sine of the smallest angle.
  static double angle_bound(double min_angle_degrees) { return std::pow(std::sin(min_angle_degrees * kPi / 180.0), 2); }

  // Rule 3 alone (a mesh without rule 4, as FRFC's quality pass) on a face's
  // points in the face's order: what Is_bad answers for that face, bit for bit
  // (the same operations; empty_scope.cpp certifies a mesh with it).
  static CGAL::Mesh_2::Face_badness angle_badness(const Point_2& pa, const Point_2& pb, const Point_2& pc,
                                                  double bound, Quality& q) {
    const double a = std::sqrt(squared_distance(pb, pc)), b = std::sqrt(squared_distance(pc, pa)),
                 c = std::sqrt(squared_distance(pa, pb));
    const double twice_area = (pb.x() - pa.x()) * (pc.y() - pa.y()) - (pb.y() - pa.y()) * (pc.x() - pa.x());
    // Below the resolution floor the angle rule stops: the triangle is left as
    // it is. Only a cascade can get there (at a small input angle whose cluster
    // CGAL does not reduce, concentric shells halving without end: measured on a
    // 12-point mesh, points 1e-12 from the apex and triangles below Mesh()'s
    // limit of 1024 units of rounding); rule 4 and the edges' Gabriel test are
    // untouched.
    const double longest = std::max({a, b, c});
    const double reach = std::max({std::abs(pa.x()), std::abs(pa.y()), std::abs(pb.x()), std::abs(pb.y()),
                                   std::abs(pc.x()), std::abs(pc.y())});
    if (twice_area < kAngleRuleFloorUlps * std::numeric_limits<double>::epsilon() * reach * longest) {
      q = 1;
      return CGAL::Mesh_2::NOT_BAD;
    }
    // Squared sine of the angle opposite the shortest edge: 2 area / (product of the others).
    double sine;
    if (a < b) sine = a < c ? twice_area / b / c : twice_area / a / b;
    else sine = b < c ? twice_area / a / c : twice_area / a / b;
    q = rounded(sine * sine);
    return q < bound ? CGAL::Mesh_2::BAD : CGAL::Mesh_2::NOT_BAD;
  }

  // The queue order must not depend on rounding: the same mesh scaled by 1e-100
  // has qualities equal up to a few ulps, and near-ties would then be refined in
  // another order. Rounded to float, they tie exactly, and the queue
  // (Bad_face_queue) breaks ties by the points' lexicographic order, which
  // scaling keeps.
  static double rounded(double q) { return static_cast<double>(static_cast<float>(q)); }

  // Whether rule 4 (sizes from the spacing function) is on.
  bool has_spacing() const { return spacing_ != nullptr; }

  // Cotangent of half the angle under which an off-centre sees the short edge;
  // infinite (always the circumcentre) without off-centres. That angle is a little
  // above the target, so rounding cannot make the new triangle bad again.
  double off_centre_half_angle_cotangent() const {
    if (!off_centres_) return std::numeric_limits<double>::infinity();
    return 1.0 / std::tan(0.5 * std::min(1.02 * min_angle_, 60.0) * kPi / 180.0);
  }

  class Is_bad {
   public:
    Is_bad(double bound, const Cdt* tr, const Spacing_data* spacing, bool canonical)
        : bound_(bound), tr_(tr), spacing_(spacing), canonical_(canonical) {}

    CGAL::Mesh_2::Face_badness operator()(Quality q) const {
      return q < bound_ ? CGAL::Mesh_2::BAD : CGAL::Mesh_2::NOT_BAD;
    }

    CGAL::Mesh_2::Face_badness operator()(const Face_handle& fh, Quality& q) const {
      if (canonical_) {
        const std::array<Point_2, 3> p = canonical_rotation(fh);
        return badness(fh, p[0], p[1], p[2], q);
      }
      return badness(fh, fh->vertex(0)->point(), fh->vertex(1)->point(), fh->vertex(2)->point(), q);
    }

   private:
    CGAL::Mesh_2::Face_badness badness(const Face_handle& fh, const Point_2& pa, const Point_2& pb,
                                       const Point_2& pc, Quality& q) const {
      if (spacing_ != nullptr) {
        // Rule 4: a vertex whose neighbour spacing exceeds f there.
        double worst = 0;
        for (int k = 0; k < 3; ++k) {
          const Vertex_handle v = fh->vertex(k);
          const double f = target_spacing(*tr_, v, *spacing_);
          if (!(f < std::numeric_limits<double>::infinity())) continue;
          if (std::sqrt(neighbour_spacing_squared(*tr_, v)) > f) {
            // Edge lengths, not their products (which could leave the range of double).
            const double a = std::sqrt(squared_distance(pb, pc)), b = std::sqrt(squared_distance(pc, pa)),
                         c = std::sqrt(squared_distance(pa, pb));
            const double twice_area = (pb.x() - pa.x()) * (pc.y() - pa.y()) - (pb.y() - pa.y()) * (pc.x() - pa.x());
            const double circumradius = a / twice_area * b * c / 2;
            worst = std::max(worst, (circumradius / f) * (circumradius / f));
          }
        }
        if (worst > 0) {
          q = rounded(-worst);
          return CGAL::Mesh_2::BAD;
        }
      }
      return angle_badness(pa, pb, pc, bound_, q);
    }

    double bound_;
    const Cdt* tr_;
    const Spacing_data* spacing_;
    bool canonical_;
  };

  Is_bad is_bad_object() const { return Is_bad(bound_, tr_, spacing_, canonical_); }

 private:
  double bound_;
  double min_angle_;
  bool off_centres_;
  bool canonical_;
  const Cdt* tr_;
  const Spacing_data* spacing_;
};

// The side of the domain at each boundary sub-segment (a constraint edge with the
// domain on one side only), kept as the set of such edges directed with the domain
// on their left. Recorded from the in_domain marks before refinement starts and
// updated when the edge level splits a sub-segment a -> b at v (a -> v and v -> b
// keep the parent's side), it never depends on the marks CGAL changes while it
// inserts a point. Lookups only: the order of the set is never used.
class Domain_sides {
 public:
  // Domain on the left of every boundary constraint edge, as the marks say now.
  // Every constraint edge is seen from its finite faces (a face sweep, in
  // parallel, is much cheaper than CGAL's edge iterator); from either side it
  // gives the same key.
  void record(Cdt& tr) {
    left_.clear();
    if (tr.dimension() < 2) return;
    auto& faces = tr.tds().faces();
    std::vector<std::vector<Key>> in_chunk(sweep_chunks(faces));
    parallel_sweep(faces, [&](std::size_t c, Face_handle f) {
      if (tr.is_infinite(f)) return;
      for (int i = 0; i < 3; ++i) {
        if (!f->is_constrained(i)) continue;
        const Face_handle g = f->neighbor(i);
        const bool f_in = f->is_in_domain();
        const bool g_in = !tr.is_infinite(g) && g->is_in_domain();
        // f lies on the left of vertex(ccw(i)) -> vertex(cw(i)).
        const Vertex_handle a = f->vertex(Cdt::ccw(i)), b = f->vertex(Cdt::cw(i));
        if (f_in && !g_in) in_chunk[c].push_back(key(a, b));
        else if (g_in && !f_in) in_chunk[c].push_back(key(b, a));
      }
    });
    for (const auto& keys : in_chunk) left_.insert(keys.begin(), keys.end());
  }
  // +1: the domain is on the left of a -> b only; -1: on its right only; 0: both
  // sides (an interior constraint) or not a boundary edge.
  int side(Vertex_handle a, Vertex_handle b) const {
    if (left_.empty()) return 0;
    if (left_.count(key(a, b)) != 0) return 1;
    if (left_.count(key(b, a)) != 0) return -1;
    return 0;
  }
  // The edge level split a -> b (either direction) at v.
  void split(Vertex_handle a, Vertex_handle b, Vertex_handle v) {
    const int s = side(a, b);
    if (s == 0) return;
    if (s < 0) std::swap(a, b);
    left_.erase(key(a, b));
    left_.insert(key(a, v));
    left_.insert(key(v, b));
  }

 private:
  using Key = std::pair<const void*, const void*>;
  struct Hash {
    std::size_t operator()(const Key& k) const {
      const auto x = reinterpret_cast<std::uintptr_t>(k.first), y = reinterpret_cast<std::uintptr_t>(k.second);
      return std::hash<std::uintptr_t>()(x * 0x9E3779B97F4A7C15ull ^ y);
    }
  };
  static Key key(Vertex_handle a, Vertex_handle b) { return {&*a, &*b}; }
  std::unordered_set<Key, Hash> left_;
};

// Gabriel conformity of a constraint edge as seen from the domain: CGAL's test
// (no vertex sees the edge under an obtuse or right angle) applied to the apex on
// each side of the edge where the domain is. A boundary sub-segment is encroached
// only from its domain side: the points across a slit, behind a thin wall or in a
// hole are hidden from the domain by the constraint itself and never refine it.
// The test of a point p to be inserted (four arguments, used on the boundary of a
// conflict zone) stays CGAL's: p encroaches whichever side it lies on, so a point
// that would land behind a constraint splits the constraint instead (Ruppert).
//
// Except at a small angle of the domain: the edges of a cluster (CGAL's,
// Mesh_2/Clusters.h: constraint edges at a vertex consecutive under less than 60
// degrees, whatever lies between them) are split on common concentric shells
// until the cluster is reduced, which is what ends the refinement at a small
// angle in the domain. That needs the edges of such a cluster to encroach each
// other across the wedges between them, also across a wedge outside the domain
// (a hole touching the vertex): every constraint edge at the apex of a cluster
// with a wedge of the domain keeps CGAL's two-sided test (also one outside the
// cluster: with it one-sided, a 12.5 degree wedge between two holes meeting at
// its apex was refined into the apex at midpoints, 120 points down to 1e-11,
// never reduced). A cluster whose wedges are all outside the domain
// (a thin notch, holes meeting at a vertex) has no small angle to end, and its
// edges see only the domain: across a notch of angle theta, a point at radius r
// from its apex is r theta from the other side, sees the other side's piece at
// that radius under a right angle up to rounding, and the shells would go on
// until the two sides met (measured: a notch of 2e-10 radians, points 3e-7 from
// the apex rounded to the same point).
struct Gabriel : CGAL::Mesh_2::Is_locally_conforming_Gabriel<Cdt> {
  using Base = CGAL::Mesh_2::Is_locally_conforming_Gabriel<Cdt>;
  using Base::operator();
  const Domain_sides* sides = nullptr;
  const CGAL::Mesh_2::Clusters<Cdt>* clusters = nullptr;

  // Whether v is the apex of a cluster with a wedge of the domain: two of the
  // cluster's edges consecutive around v with the domain between them (or an
  // edge with the domain on both sides). The cluster's edges in counter-clockwise
  // order of direction (a split keeps an edge's direction, so this never looks at
  // the triangulation, which is mid-insertion when CGAL asks); the wedge from
  // v -> u to the next edge is on the left of v -> u. The widest gap between
  // consecutive directions is no wedge of the cluster unless all are below 60
  // degrees (a cluster all around v).
  bool apex_of_domain_cluster(Vertex_handle v) const {
    const unsigned n = clusters->number_of_clusters_at_vertex(v);
    for (unsigned k = 0; k < n; ++k) {
      const auto range = clusters->vertices_in_cluster_sequence(v, k);
      std::vector<std::pair<double, Vertex_handle>> around;
      for (auto it = range.first; it != range.second; ++it) {
        const Vertex_handle u = *it;
        around.emplace_back(std::atan2(u->point().y() - v->point().y(), u->point().x() - v->point().x()), u);
      }
      std::sort(around.begin(), around.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
      const std::size_t m = around.size();
      std::size_t widest = 0;
      double widest_gap = -1;
      for (std::size_t j = 0; j < m; ++j) {
        const double gap = j + 1 < m ? around[j + 1].first - around[j].first : around[0].first + 2 * kPi - around[j].first;
        if (gap > widest_gap) {
          widest_gap = gap;
          widest = j;
        }
      }
      for (std::size_t j = 0; j < m; ++j) {
        if (j == widest && widest_gap >= kPi / 3) continue;
        if (sides->side(v, around[j].second) >= 0) return true;
      }
    }
    return false;
  }

  bool operator()(const Cdt& tr, const Face_handle& fh, const int i) const {
    const Vertex_handle va = fh->vertex(Cdt::cw(i)), vb = fh->vertex(Cdt::ccw(i));
    int side = sides == nullptr ? 0 : sides->side(vb, va);  // fh is on the left of vb -> va
    if (side != 0 && clusters != nullptr &&
        (apex_of_domain_cluster(va) || apex_of_domain_cluster(vb))) {
      side = 0;
    }
    const Vertex_handle vi = fh->vertex(i);
    const Vertex_handle mvi = tr.tds().mirror_vertex(fh, i);
    return (side < 0 || tr.is_infinite(vi) || Base::operator()(tr, va, vb, vi->point())) &&
           (side > 0 || tr.is_infinite(mvi) || Base::operator()(tr, va, vb, mvi->point()));
  }

  bool operator()(const Cdt& tr, const Vertex_handle& va, const Vertex_handle& vb) const {
    Face_handle fh;
    int i;
    if (!tr.is_edge(va, vb, fh, i)) throw std::logic_error("Gabriel: not an edge");
    return operator()(tr, fh, i);
  }
};
using Edges_base_with_clusters = CGAL::Mesh_2::Refine_edges_base_with_clusters<Cdt, Gabriel>;

// Edge level with the domain-side Gabriel test, that can also be told to split a
// given constraint edge (Section 6: a segment crowded by points is split instead
// of keeping them).
struct Edges_base : Edges_base_with_clusters {
  Edges_base(Cdt& tr, CGAL::Mesh_2::Clusters<Cdt>& clusters) : Edges_base_with_clusters(tr, clusters) {
    this->is_locally_conform.sides = &sides_;
    this->is_locally_conform.clusters = &clusters;
  }
  Edges_base(const Edges_base&) = delete;
  Edges_base& operator=(const Edges_base&) = delete;

  // Call once the in_domain marks are set, before scanning.
  void record_domain_sides() { sides_.record(this->tr); }

  // CGAL's scan (every constraint edge in edge order; the encroached ones
  // queued), with the Gabriel tests computed in parallel blocks first (they
  // only read the triangulation, the sides and the clusters): the same queue.
  // The constraint edges in CGAL's edge order, from a (parallel) sweep over the faces:
  // its edge iterator visits the faces in container order and reports edge i
  // of face f when f < f->neighbor(i) (Triangulation_ds_edge_iterator_2), and
  // the finite-edge filter never drops a constraint edge (its ends are finite).
  // Visiting every edge through that iterator took 0.1 s on a 1e6-point mesh.
  void scan_triangulation_impl() {
    this->clear();
    if (this->tr.dimension() < 2) return;
    auto& faces = this->tr.tds().faces();
    std::vector<std::vector<Cdt::Edge>> in_chunk(sweep_chunks(faces));
    parallel_sweep(faces, [&](std::size_t c, Cdt::Face_handle f) {
      for (int i = 0; i < 3; ++i) {
        if (f->is_constrained(i) && f < f->neighbor(i)) in_chunk[c].emplace_back(f, i);
      }
    });
    const std::vector<Cdt::Edge> edges = joined(in_chunk);
    std::vector<std::uint8_t> conform(edges.size());
    constexpr std::size_t kChunk = std::size_t{1} << 12;
    parallel_for((edges.size() + kChunk - 1) / kChunk, 0, [&](std::size_t c) {
      for (std::size_t k = c * kChunk; k < std::min(edges.size(), (c + 1) * kChunk); ++k) {
        conform[k] = this->is_locally_conform(this->tr, edges[k].first, edges[k].second);
      }
    });
    for (std::size_t k = 0; k < edges.size(); ++k) {
      if (!conform[k]) this->add_constrained_edge_to_be_conformed(edges[k]);
    }
  }
  void queue_split(Cdt::Vertex_handle a, Cdt::Vertex_handle b) { this->add_constrained_edge_to_be_conformed(a, b); }

  // The sub-segments take their parent's side before CGAL's after_insertion_impl
  // tests them (and the edges around the new point).
  void after_insertion_impl(const detail::Vertex_handle& v) {
    sides_.split(this->va, this->vb, v);
    Edges_base_with_clusters::after_insertion_impl(v);
  }

 private:
  Domain_sides sides_;
};
using Edges_level = CGAL::Mesh_2::Refine_edges_with_clusters<Cdt, Gabriel, Edges_base>;

using Faces_base_cgal = CGAL::Mesh_2::Refine_faces_base<Cdt, Refinement_criteria, Edges_level>;

// The faces the mesher will split, worst first: by quality, then by their
// points (CGAL's Face_compare: the three vertices' points in order,
// lexicographically), a total order. CGAL's own queue (a Double_map: two
// balanced trees, one of them keyed by the points) cost about a microsecond per
// insertion or removal, with the points of both faces read at every comparison,
// and broke ties of quality by where its hinted insertion landed. This is a
// binary heap whose entries carry their key and leave lazily: an entry is
// current while its face's queue_entry holds its number. A face leaves the queue
// by setting that to 0; a face the triangulation creates or reuses starts at 0;
// clear() makes every number issued so far stale. Every operation is O(log n)
// on a contiguous array; entries left behind are compacted away when they
// outnumber the current ones.
class Bad_face_queue {
 public:
  using Quality = Refinement_criteria::Quality;

  // The face's entry, if current (the face is queued).
  bool contains(const Face_handle& f) const { return f->queue_entry >= first_current_; }

  // Queues f with quality q unless it is queued already (as CGAL's map, which
  // keeps one entry per face).
  void push(const Face_handle& f, Quality q) {
    if (contains(f)) return;
    f->queue_entry = next_;
    heap_.push_back({q, next_++, f, {f->vertex(0), f->vertex(1), f->vertex(2)}});
    std::push_heap(heap_.begin(), heap_.end(), Later());
    ++n_current_;
  }
  void erase(const Face_handle& f) {
    if (!contains(f)) return;
    f->queue_entry = 0;
    --n_current_;
    if (heap_.size() > 2 * n_current_ + 4096) compact();
  }
  bool empty() {
    settle();
    return heap_.empty();
  }
  // The worst face and its quality (the queue must not be empty).
  Face_handle front_face() {
    settle();
    return heap_.front().face;
  }
  Quality front_quality() {
    settle();
    return heap_.front().quality;
  }
  void pop_front() {
    settle();
    erase(heap_.front().face);  // (its entry leaves at the next settle)
  }
  void clear() {
    heap_.clear();
    first_current_ = next_;
    n_current_ = 0;
  }
  // Calls visit(face, quality) for every queued face, in no particular order.
  template <class Visit>
  void for_each_queued(Visit&& visit) const {
    for (const Entry& e : heap_) {
      if (current(e)) visit(e.face, e.quality);
    }
  }

 private:
  struct Entry {
    Quality quality;
    std::uint64_t number;
    Face_handle face;
    std::array<Vertex_handle, 3> vertices;  // the key's points (vertices outlive the mesher's run)
  };
  // Heap order: the entry that comes later in the queue is "less".
  struct Later {
    bool operator()(const Entry& a, const Entry& b) const {
      if (a.quality != b.quality) return b.quality < a.quality;
      for (int k = 0; k < 3; ++k) {
        const Point_2& p = a.vertices[k]->point();
        const Point_2& q = b.vertices[k]->point();
        if (q < p) return true;
        if (p < q) return false;
      }
      return false;
    }
  };
  bool current(const Entry& e) const { return e.number >= first_current_ && e.face->queue_entry == e.number; }
  void settle() {
    while (!heap_.empty() && !current(heap_.front())) {
      std::pop_heap(heap_.begin(), heap_.end(), Later());
      heap_.pop_back();
    }
  }
  void compact() {
    heap_.erase(std::remove_if(heap_.begin(), heap_.end(), [this](const Entry& e) { return !current(e); }),
                heap_.end());
    std::make_heap(heap_.begin(), heap_.end(), Later());
  }

  std::vector<Entry> heap_;
  std::uint64_t next_ = 1;           // the next entry's number
  std::uint64_t first_current_ = 1;  // entries numbered below were cleared
  std::size_t n_current_ = 0;
};

// In the quality pass badly shaped triangles are split at their off-centre (Ungor,
// "Off-centers", 2004) rather than their circumcentre: the point on the bisector of
// the shortest edge pq, towards the circumcentre, from which pq is seen under the
// target angle; the circumcentre when that is nearer. Same guarantees as Ruppert's
// rule 3 with fewer points. DRFC's refinement uses circumcentres (Ruppert, Section 5).
struct Faces_base : Faces_base_cgal {
  Faces_base(Cdt& tr, Refinement_criteria& criteria, Edges_level& edges)
      : Faces_base_cgal(tr, criteria, edges),
        half_angle_cotangent_(criteria.off_centre_half_angle_cotangent()),
        parallel_scan_(!criteria.has_spacing()),
        canonical_(criteria.is_canonical()) {}

  Point_2 refinement_point_impl(const Cdt::Face_handle& f) const {
    // (With canonical_, in the face's canonical rotation: the same point
    // whatever rotation the triangulation gave the face.)
    const std::array<Point_2, 3> v =
        canonical_ ? canonical_rotation(f)
                   : std::array<Point_2, 3>{f->vertex(0)->point(), f->vertex(1)->point(), f->vertex(2)->point()};
    const Point_2 c = canonical_ ? CGAL::circumcenter(v[0], v[1], v[2]) : this->triangulation_ref_impl().circumcenter(f);
    Refinement_criteria::Quality q;
    this->is_bad(f, q);
    if (q < 0) return c;  // rule 4 (size): the circumcentre
    int k = 0;  // the shortest edge is opposite point k (the first of equal ones)
    double shortest = std::numeric_limits<double>::infinity();
    for (int i = 0; i < 3; ++i) {
      const double l = squared_distance(v[Cdt::ccw(i)], v[Cdt::cw(i)]);
      if (l < shortest) {
        shortest = l;
        k = i;
      }
    }
    const Point_2& p = v[Cdt::ccw(k)];
    const Point_2& r = v[Cdt::cw(k)];
    const double mx = 0.5 * (p.x() + r.x()), my = 0.5 * (p.y() + r.y());
    const double dx = c.x() - mx, dy = c.y() - my;
    const double to_centre = std::hypot(dx, dy);
    const double height = 0.5 * std::sqrt(shortest) * half_angle_cotangent_;
    if (!(to_centre > height)) return c;
    return Point_2(mx + dx / to_centre * height, my + dy / to_centre * height);
  }

  // The face level's queue (CGAL's Refine_faces_base, with Bad_face_queue for
  // its Double_map): every function of it that reads or changes the queue.

  // CGAL's scan (every face of the domain in container order; the bad ones
  // queued), with the badness of the faces computed in a parallel sweep
  // (parallel_sweep.hpp) when rule 4 is off (its target_spacing caches f in the
  // vertices: not thread-safe), the bad ones then queued in container order.
  void scan_triangulation_impl() {
    queue_.clear();
    Cdt& tr = this->triangulation_ref_impl();
    if (tr.dimension() < 2) return;
    auto& faces = tr.tds().faces();
    std::vector<std::vector<std::pair<Cdt::Face_handle, Refinement_criteria::Quality>>> bad(sweep_chunks(faces));
    parallel_sweep(
        faces,
        [&](std::size_t c, Cdt::Face_handle f) {
          if (tr.is_infinite(f) || !f->is_in_domain()) return;
          Refinement_criteria::Quality q;
          if (this->is_bad(f, q) != CGAL::Mesh_2::NOT_BAD) bad[c].emplace_back(f, q);
        },
        parallel_scan_ ? 0 : 1);
    for (const auto& in_chunk : bad) {
      for (const auto& [f, q] : in_chunk) queue_.push(f, q);
    }
  }

  // Rule 4 is about vertices: a triangle queued as bad can become good when a
  // point is inserted next to one of its vertices without destroying it. Such
  // stale entries are dropped before the mesher looks at the queue.
  bool no_longer_element_to_refine_impl() {
    while (!queue_.empty()) {
      Refinement_criteria::Quality q;
      if (this->is_bad(queue_.front_face(), q) != CGAL::Mesh_2::NOT_BAD) break;
      queue_.pop_front();
    }
    return queue_.empty();
  }
  Cdt::Face_handle get_next_element_impl() {
    this->current_badness = this->is_bad(queue_.front_quality());
    return queue_.front_face();
  }
  void pop_next_element_impl() { queue_.pop_front(); }

  // The faces in conflict with a new point leave the queue (and the domain
  // until after_insertion marks the new ones); called by both levels.
  void before_insertion_impl(const Cdt::Face_handle&, const Point_2&,
                             CGAL::Triangulation_mesher_level_traits_2<Cdt>::Zone& zone) {
    for (const Cdt::Face_handle& f : zone.faces) {
      queue_.erase(f);
      f->set_in_domain(false);
    }
  }
  void after_insertion_impl(const detail::Vertex_handle& v) {
    auto f = this->triangulation_ref_impl().incident_faces(v), done = f;
    do {
      f->set_in_domain(true);
    } while (++f != done);
    compute_new_bad_faces(v);
  }
  // The bad faces around a new point join the queue (also called by the edge
  // level's visitor).
  void compute_new_bad_faces(const detail::Vertex_handle& v) {
    Cdt& tr = this->triangulation_ref_impl();
    auto f = tr.incident_faces(v), done = f;
    do {
      if (!tr.is_infinite(f) && f->is_in_domain()) {
        Refinement_criteria::Quality q;
        if (this->is_bad(f, q) != CGAL::Mesh_2::NOT_BAD) queue_.push(f, q);
      }
    } while (++f != done);
  }
  // (CGAL's public counterpart would work on its own, unused map.)
  void remove_bad_face(const Cdt::Face_handle& f) { queue_.erase(f); }

  // For the rounds (quality_rounds.cpp): the queued faces, whether a face is
  // queued, and the badness CGAL's face level reads when a face is refined
  // outside its queue order (get_next_element_impl sets it otherwise).
  template <class Visit>
  void for_each_bad_face(Visit&& visit) const {
    queue_.for_each_queued(visit);
  }
  bool is_queued(const Cdt::Face_handle& f) const { return queue_.contains(f); }
  void refine_outside_queue_order() { this->current_badness = CGAL::Mesh_2::BAD; }

 private:
  double half_angle_cotangent_;
  bool parallel_scan_;
  bool canonical_;
  Bad_face_queue queue_;
};
using Faces_level = CGAL::Mesh_2::Refine_faces<Cdt, Refinement_criteria, Edges_level, Faces_base>;
using Visitor = CGAL::Mesh_2::Refine_edges_visitor_from_faces<Faces_level>;

// What run_in_rounds did.
struct Rounds_report {
  std::size_t n_inserted = 0;
  std::size_t rounds = 0;          // rounds that inserted at least one point
  std::size_t largest_round = 0;   // the most points one round inserted
  bool capped = false;             // stopped by the budget with work left
  bool stalled = false;            // a round inserted nothing while bad faces or encroached edges remained
  bool round_limit = false;        // stopped by max_rounds with work left
};

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
    edges_.record_domain_sides();
    clusters_.create_clusters();
    edges_.scan_triangulation();
    faces_.scan_triangulation();
  }
  void queue_split(Vertex_handle a, Vertex_handle b) { edges_.queue_split(a, b); }
  void rescan_faces() { faces_.scan_triangulation(); }
  // Inserts one point; false when nothing is left to refine.
  bool insert_one_point() { return faces_.try_to_insert_one_point(visitor_); }
  bool is_done() { return faces_.is_algorithm_done(); }
  // After init(): whether two constraint edges meet under less than 60 degrees
  // (CGAL's clusters, Clusters::is_small_angle above), either side of the domain.
  bool has_small_angles() const { return clusters_.size() > 0; }

  // Refinement in rounds of independent insertions (quality_rounds.cpp, design
  // in docs/distributed-step.md section 3.6), instead of one point at a time
  // from the worst face. Requires criteria built with canonical = true.
  Rounds_report run_in_rounds(std::size_t budget, std::size_t max_rounds);

 private:
  Refinement_criteria criteria_;
  CGAL::Null_mesher_level null_level_;
  CGAL::Null_mesh_visitor null_visitor_;
  CGAL::Mesh_2::Clusters<Cdt> clusters_;
  Edges_level edges_;
  Faces_level faces_;
  Visitor visitor_;
};

// The face on the left of a -> b (f, with the edge opposite vertex i), if ab is an edge.
bool left_face(const Cdt& cdt, Vertex_handle a, Vertex_handle b, Face_handle& f, int& i);

// in_domain marks: regions bounded by the pieces take the side labels of their
// pieces (left of a boundary piece: inside; right: outside), as in constrained_delaunay.
void mark_domain(Cdt& cdt, const std::vector<Vertex_handle>& handles, const std::vector<Constraint_piece>& pieces);

// Runs the mesher until it is done or `budget` points were inserted; returns the number inserted.
std::size_t run_mesher(Mesher& mesher, std::size_t budget, Refinement_report& report);

// The refined mesh: the input points not removed, in input order (handles: the
// vertex of each), then the points the mesher inserted, sorted. Input points keep
// their exact input coordinates; f is returned in input units.
Refined_mesh extract(Cdt& cdt, const std::vector<Vertex_handle>& handles, const std::vector<Vec2>& input_points,
                     const std::vector<Point_kind>& input_kind, const std::vector<std::uint8_t>& removed,
                     const Scaling& scaling);

}  // namespace evomesh::detail
