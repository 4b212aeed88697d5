// The Delaunay tetrahedralisation of a step's kept points, and its
// radius-edge refinement (tet/tet_step.hpp).
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "evomesh/detail/bits.hpp"
#include "evomesh/kernel.hpp"
#include "evomesh/tet/tet_step.hpp"

namespace evomesh::tet {

namespace {

using Point_3 = Kernel::Point_3;
using Vertex_base = CGAL::Triangulation_vertex_base_with_info_3<Index, Kernel>;
using Data_structure = CGAL::Triangulation_data_structure_3<Vertex_base>;
using Delaunay_3 = CGAL::Delaunay_triangulation_3<Kernel, Data_structure>;
using Vertex_handle = Delaunay_3::Vertex_handle;

// The tetrahedron's smallest index first by an even permutation (the same
// orientation), then the other three rotated to put their smallest first.
Tet canonical(Tet t) {
  const auto first = static_cast<int>(std::min_element(t.begin(), t.end()) - t.begin());
  switch (first) {
    case 1: t = {t[1], t[0], t[3], t[2]}; break;
    case 2: t = {t[2], t[0], t[1], t[3]}; break;
    case 3: t = {t[3], t[0], t[2], t[1]}; break;
    default: break;
  }
  while (t[1] > t[2] || t[1] > t[3]) t = {t[0], t[2], t[3], t[1]};
  return t;
}

Delaunay_3 triangulate(const std::vector<Vec3>& points, std::vector<Vertex_handle>& handles) {
  std::vector<std::pair<Point_3, Index>> sites(points.size());
  for (std::size_t k = 0; k < points.size(); ++k) {
    sites[k] = {Point_3(points[k][0], points[k][1], points[k][2]), static_cast<Index>(k)};
  }
  // The range insertion sorts the points spatially (CGAL::spatial_sort) first.
  Delaunay_3 triangulation(sites.begin(), sites.end());
  if (triangulation.number_of_vertices() != points.size()) throw Input_error("duplicate points in a triangulation");
  handles.assign(points.size(), Vertex_handle());
  for (auto v = triangulation.finite_vertices_begin(); v != triangulation.finite_vertices_end(); ++v) {
    handles[static_cast<std::size_t>(v->info())] = v;
  }
  return triangulation;
}

std::vector<Tet> finite_tets(const Delaunay_3& triangulation) {
  std::vector<Tet> tets;
  tets.reserve(triangulation.number_of_finite_cells());
  for (auto cell = triangulation.finite_cells_begin(); cell != triangulation.finite_cells_end(); ++cell) {
    tets.push_back(canonical({cell->vertex(0)->info(), cell->vertex(1)->info(), cell->vertex(2)->info(),
                              cell->vertex(3)->info()}));
  }
  std::sort(tets.begin(), tets.end());
  return tets;
}

double squared(const Point_3& a, const Point_3& b) { return CGAL::to_double(CGAL::squared_distance(a, b)); }

// How far a tetrahedron's dihedral angles stay from 0 and 180 degrees:
// min(smallest, 180 - largest), in degrees (at edge (i, j) the angle between
// the normals of its two faces there). Slivers and caps both score low.
double dihedral_margin(const Point_3& a, const Point_3& b, const Point_3& c, const Point_3& d) {
  const Point_3 p[4] = {a, b, c, d};
  constexpr int kEdges[6][4] = {{0, 1, 2, 3}, {0, 2, 1, 3}, {0, 3, 1, 2}, {1, 2, 0, 3}, {1, 3, 0, 2}, {2, 3, 0, 1}};
  double margin = 90.0;
  for (const auto& e : kEdges) {
    const auto edge = p[e[1]] - p[e[0]];
    const auto n1 = CGAL::cross_product(edge, p[e[2]] - p[e[0]]);
    const auto n2 = CGAL::cross_product(edge, p[e[3]] - p[e[0]]);
    const double cosine = n1 * n2 / std::sqrt(n1.squared_length() * n2.squared_length());
    const double angle = std::acos(std::clamp(cosine, -1.0, 1.0)) * 180.0 / M_PI;
    margin = std::min({margin, angle, 180.0 - angle});
  }
  return margin;
}

double dihedral_margin(const Delaunay_3::Cell_handle& cell) {
  return dihedral_margin(cell->vertex(0)->point(), cell->vertex(1)->point(), cell->vertex(2)->point(),
                         cell->vertex(3)->point());
}

Tet cell_indices(const Delaunay_3::Cell_handle& cell) {
  return canonical({cell->vertex(0)->info(), cell->vertex(1)->info(), cell->vertex(2)->info(), cell->vertex(3)->info()});
}

// The finite cells that pass `test`, by canonical vertex indices, sorted: the
// order a round visits them in, whatever the triangulation's storage order.
template <class Test>
std::vector<Tet> cells_where(const Delaunay_3& triangulation, Test test) {
  std::vector<Tet> out;
  for (auto cell = triangulation.finite_cells_begin(); cell != triangulation.finite_cells_end(); ++cell) {
    if (test(cell)) out.push_back(cell_indices(cell));
  }
  std::sort(out.begin(), out.end());
  return out;
}

// The cell with these vertices, if an earlier change of the round left it.
bool find_cell(const Delaunay_3& triangulation, const std::vector<Vertex_handle>& handles, const Tet& t,
               Delaunay_3::Cell_handle& cell) {
  const auto h = [&](std::size_t q) { return handles[static_cast<std::size_t>(t[q])]; };
  int i, j, k, l;
  return triangulation.is_cell(h(0), h(1), h(2), h(3), cell, i, j, k, l);
}

double shortest_edge(const Delaunay_3::Cell_handle& cell) {
  double shortest = std::numeric_limits<double>::infinity();
  for (int u = 0; u < 4; ++u) {
    for (int v = u + 1; v < 4; ++v) shortest = std::min(shortest, squared(cell->vertex(u)->point(), cell->vertex(v)->point()));
  }
  return std::sqrt(shortest);
}

double radius_edge(const Delaunay_3::Cell_handle& cell) {
  const Point_3& a = cell->vertex(0)->point();
  const Point_3 centre = CGAL::circumcenter(a, cell->vertex(1)->point(), cell->vertex(2)->point(), cell->vertex(3)->point());
  return std::sqrt(squared(centre, a)) / shortest_edge(cell);
}

// The worst of the tetrahedra around v: (min dihedral, -max radius-edge) to maximise.
std::pair<double, double> star_quality(const Delaunay_3& triangulation, Vertex_handle v) {
  std::vector<Delaunay_3::Cell_handle> cells;
  triangulation.finite_incident_cells(v, std::back_inserter(cells));
  double dihedral = 180.0, ratio = 0.0;
  for (const auto& cell : cells) {
    dihedral = std::min(dihedral, dihedral_margin(cell));
    ratio = std::max(ratio, radius_edge(cell));
  }
  return {dihedral, ratio};
}

// Where a circumcentre goes (Delaunay refinement and the sliver pass): the
// centre itself when it lies inside the domain at least half the
// tetrahedron's shortest edge from every facet; else its projection onto the
// facet it is near or beyond (exactly on it) when that keeps half the
// shortest edge from the facets around; else, when the projection is near
// exactly one of them and the two meet at an edge, its projection onto that
// edge, kept as far from the facets at the edge's ends (a boundary segment
// split, as in Shewchuk's Delaunay refinement: a bad tetrahedron next to an
// edge is resolved there); else nowhere (false). A centre of a tetrahedron
// whose circumradius exceeds twice its shortest edge s moves by less than
// s, so the point keeps more than s from every point of the (empty)
// circumsphere.
enum class Placement { centre, facet, edge };
// A centre moved onto a facet or an edge keeps this fraction of the
// tetrahedron's shortest edge from every point (insert_at_circumcentre).
constexpr double kProjectedClearance = 0.4;

bool centre_placement(const Point_3& centre, double shortest, const Polyhedral_domain& domain, Vec3& x,
                      Placement& placed) {
  using Mask = Polyhedral_domain::Mask;
  x = {centre.x(), centre.y(), centre.z()};
  placed = Placement::centre;
  int near = -1;
  double near_distance = 0.5 * shortest;
  for (std::size_t f = 0; f < domain.n_facets(); ++f) {
    const double distance = domain.distance(f, x);
    const bool beyond = distance <= 0;
    if (beyond || distance < near_distance) near = static_cast<int>(f), near_distance = beyond ? -1.0 : distance;
  }
  if (near < 0) return true;
  const auto facet = static_cast<std::size_t>(near);
  if (!domain.snap_to_facet(facet, x)) return false;
  placed = Placement::facet;
  const auto too_near = [&](const Vec3& y, Mask facets) {
    Mask out = 0;
    for (std::size_t g = 0; g < domain.n_facets(); ++g) {
      if ((facets >> g & 1u) && !(domain.distance(g, y) >= 0.5 * shortest)) out |= Mask{1} << g;
    }
    return out;
  };
  const Mask around = domain.neighbours(facet) & ~(Mask{1} << facet);
  const Mask near_facets = too_near(x, around);
  if (near_facets == 0) return true;
  if (Polyhedral_domain::count(near_facets) > 1) return false;
  const int edge = domain.edge_of((Mask{1} << facet) | near_facets);
  if (edge < 0) return false;
  const auto e = static_cast<std::size_t>(edge);
  if (!domain.edge_point(e, x[static_cast<std::size_t>(domain.edge_axis(e))], x)) return false;
  placed = Placement::edge;
  const auto [f0, f1] = domain.edge_facets(e);
  const Mask ends = domain.neighbours(static_cast<std::size_t>(f0)) & domain.neighbours(static_cast<std::size_t>(f1)) &
                    ~((Mask{1} << f0) | (Mask{1} << f1));
  return too_near(x, ends) == 0;
}

using evomesh::detail::mix;

// A uniform point u of the unit ball (rejection from the cube; counter-based
// draws from `draw`).
void unit_ball_point(std::uint64_t draw, double u[3]) {
  double norm;
  do {
    norm = 0;
    for (int i = 0; i < 3; ++i) {
      draw = mix(draw);
      u[i] = 2.0 * (static_cast<double>(draw >> 11) * 0x1.0p-53) - 1.0;
      norm += u[i] * u[i];
    }
  } while (norm > 1.0);
}

// Picking regions for new points (Chew; Li and Teng): each sliver (a
// dihedral angle below the bound or above 180 degrees minus it) with a
// movable vertex (a new point: inside the domain, or on one facet, where it
// moves within the facet so that the facets stay covered; old points and the
// domain's edges and corners never move) tries that vertex at random points
// of a ball (a disc on a facet) of radius rho times its shortest edge, and keeps the position
// whose star has the largest dihedral margin (radius-edge still within
// bound), if that beats where it was. A move changes every distance from the
// point by at most rho times its shortest edge, so the spacing stays within
// that factor of the packing's. In rounds, slivers in canonical order.
void perturb_slivers(Delaunay_3& triangulation, std::vector<Vertex_handle>& handles, std::vector<Vec3>& points,
                     const Sliver_options& options, const Polyhedral_domain& domain, bool first_pass,
                     Refinement_report& report) {
  // -2: the point never moves (an old point, or on an edge or a corner of
  // the domain); -1: it moves freely (interior); f >= 0: it moves within
  // facet f (exactly on it).
  auto movable_in = [&](Index k) {
    if (static_cast<std::size_t>(k) < options.first_movable) return -2;
    const Polyhedral_domain::Mask on = domain.incidences(points[static_cast<std::size_t>(k)]);
    const int planes = Polyhedral_domain::count(on);
    return planes == 0 ? -1 : planes == 1 ? Polyhedral_domain::first(on) : -2;
  };
  std::vector<std::uint8_t> moved(points.size(), 0);
  const auto is_sliver = [&](const Delaunay_3::Cell_handle& cell) { return dihedral_margin(cell) < options.min_dihedral; };
  for (int round = 0; round < options.rounds; ++round) {
    const std::vector<Tet> slivers = cells_where(triangulation, is_sliver);
    if (round == 0 && first_pass) report.slivers_before = slivers.size();
    std::size_t improved = 0;
    for (const Tet& t : slivers) {
      const auto h = [&](int q) { return handles[static_cast<std::size_t>(t[static_cast<std::size_t>(q)])]; };
      Delaunay_3::Cell_handle cell;
      if (!find_cell(triangulation, handles, t, cell) || !is_sliver(cell)) continue;
      for (int q = 0; q < 4; ++q) {
        const Index index = t[static_cast<std::size_t>(q)];
        const int facet = movable_in(index);
        if (facet < -1) continue;
        const Vertex_handle v = h(q);
        const Point_3 home = v->point();
        std::vector<Vertex_handle> around;
        triangulation.finite_adjacent_vertices(v, std::back_inserter(around));
        double shortest = std::numeric_limits<double>::infinity();
        for (const auto& w : around) shortest = std::min(shortest, squared(w->point(), home));
        const double reach = options.rho * std::sqrt(shortest);
        auto best = star_quality(triangulation, v);
        const double start = best.first;
        Point_3 best_point = home;
        for (int attempt = 0; attempt < options.attempts; ++attempt) {
          double u[3];
          unit_ball_point(mix(mix(options.seed ^ static_cast<std::uint64_t>(index)) + static_cast<std::uint64_t>(round * 64 + attempt)), u);
          Vec3 x{home.x() + reach * u[0], home.y() + reach * u[1], home.z() + reach * u[2]};
          if (facet >= 0 && !domain.snap_to_facet(static_cast<std::size_t>(facet), x)) continue;
          if (!domain.strictly_inside(x, facet >= 0 ? Polyhedral_domain::Mask{1} << facet : 0)) continue;
          if (triangulation.move_if_no_collision(v, Point_3(x[0], x[1], x[2])) != v) continue;
          const auto quality = star_quality(triangulation, v);
          if (quality.second <= options.max_radius_edge && quality.first > best.first) {
            best = quality;
            best_point = v->point();
          }
        }
        triangulation.move_if_no_collision(v, best_point);
        if (best.first > start) {
          points[static_cast<std::size_t>(index)] = {best_point.x(), best_point.y(), best_point.z()};
          moved[static_cast<std::size_t>(index)] = 1;
          ++improved;
        }
        if (best.first >= options.min_dihedral) break;
      }
    }
    if (improved == 0) break;
  }
  report.moved.clear();
  for (std::size_t k = 0; k < points.size(); ++k) {
    if (moved[k] || report.was_moved(k)) report.moved.push_back(static_cast<Index>(k));
  }
  report.moved_mask.assign(moved.begin(), moved.end());
  for (Index k : report.moved) report.moved_mask[static_cast<std::size_t>(k)] = 1;
  report.slivers_after = cells_where(triangulation, is_sliver).size();
}

// Inserts a point for tetrahedron t (its circumcentre, or that centre's
// projection onto a facet or an edge, centre_placement) when t is still a cell; returns
// the new vertex, or a null handle when t is gone, the centre has no place or
// the point is already there. The caller keeps it (keep_point) or removes it.
// With picking > 0 the point is drawn at random (`draw`) in the ball of
// radius picking times the circumradius around the centre instead (Li's
// random off-centres).
Vertex_handle insert_at_circumcentre(Delaunay_3& triangulation, const std::vector<Vertex_handle>& handles,
                                     const Tet& t, const Polyhedral_domain& domain, Vec3& x, double picking = 0,
                                     std::uint64_t draw = 0) {
  Delaunay_3::Cell_handle cell;
  if (!find_cell(triangulation, handles, t, cell)) return Vertex_handle();  // gone this round
  Point_3 centre = CGAL::circumcenter(cell->vertex(0)->point(), cell->vertex(1)->point(),
                                      cell->vertex(2)->point(), cell->vertex(3)->point());
  if (picking > 0) {
    double u[3];
    unit_ball_point(draw, u);
    const double reach = picking * std::sqrt(squared(centre, cell->vertex(0)->point()));
    centre = Point_3(centre.x() + reach * u[0], centre.y() + reach * u[1], centre.z() + reach * u[2]);
  }
  const double shortest = shortest_edge(cell);
  Placement placed;
  if (!centre_placement(centre, shortest, domain, x, placed)) return Vertex_handle();
  // A centre moved onto a facet or an edge may land next to a point (the
  // empty circumsphere says nothing about where it moved to, say right
  // under an interior point near the facet): a placement closer than
  // kProjectedClearance times the tetrahedron's shortest edge to a point is
  // refused. Without it, splits cascaded to ever shorter edges on coarse
  // meshes of an octahedron and a tilted box (edges of 0.003, dihedrals of
  // 1.5 degrees); with the whole shortest edge as the bound, bad tetrahedra
  // next to box edges were left again. 0.4 measured best (docs/implementation.md).
  const Point_3 target(x[0], x[1], x[2]);
  if (placed != Placement::centre && squared(triangulation.nearest_vertex(target, cell)->point(), target) <
                                         kProjectedClearance * kProjectedClearance * shortest * shortest) {
    return Vertex_handle();
  }
  const std::size_t before = triangulation.number_of_vertices();
  const Vertex_handle v = triangulation.insert(Point_3(x[0], x[1], x[2]), cell);
  if (triangulation.number_of_vertices() == before) return Vertex_handle();  // an existing point
  return v;
}

// Numbers an inserted vertex as the next point (its hint: t's first vertex).
void keep_point(const Vertex_handle& v, const Vec3& x, const Tet& t, std::vector<Vec3>& points,
                std::vector<Vertex_handle>& handles, Refinement_report& report) {
  v->info() = static_cast<Index>(points.size());
  points.push_back(x);
  handles.push_back(v);
  report.hints.push_back(t[0]);
}

// The slivers the perturbation left (four kept points, or new points it
// could not move far enough): a new point inside each one's circumsphere,
// which destroys it, at its circumcentre (the sliver's empty sphere keeps it
// clear of every point by the circumradius) or, near or beyond a facet, the
// centre's projection onto it (centre_placement); the perturbation
// then moves the new points. Returns how many were inserted.
std::size_t insert_off_centres(Delaunay_3& triangulation, std::vector<Vertex_handle>& handles,
                               std::vector<Vec3>& points, const Sliver_options& options,
                               const Polyhedral_domain& domain, Refinement_report& report) {
  const std::vector<Tet> slivers = cells_where(
      triangulation, [&](const Delaunay_3::Cell_handle& cell) { return dihedral_margin(cell) < options.min_dihedral; });
  std::size_t inserted = 0;
  Delaunay_3::Cell_handle cell;
  for (const Tet& t : slivers) {
    // The centre first; where it has no place or would break the ratio,
    // random points around it (they must destroy the sliver).
    for (int attempt = 0; attempt <= options.attempts; ++attempt) {
      if (!find_cell(triangulation, handles, t, cell)) break;
      Vec3 x;
      const std::uint64_t draw = mix(mix(options.seed ^ 0x0ffcull) + static_cast<std::uint64_t>(t[0] * 131 + t[1]) * 64 +
                                     static_cast<std::uint64_t>(attempt));
      const Vertex_handle v = insert_at_circumcentre(triangulation, handles, t, domain, x, attempt ? 0.5 : 0.0, draw);
      if (v == Vertex_handle()) continue;
      // Every tetrahedron the insertion makes has v as a vertex: one whose
      // radius-edge ratio the insertion would break is not made (removing v
      // restores the Delaunay tetrahedra it replaced).
      if ((attempt > 0 && find_cell(triangulation, handles, t, cell)) ||
          star_quality(triangulation, v).second > options.max_radius_edge) {
        triangulation.remove(v);
        continue;
      }
      keep_point(v, x, t, points, handles, report);
      ++inserted;
      break;
    }
  }
  return inserted;
}

}  // namespace

std::vector<Tet> delaunay_tetrahedra(const std::vector<Vec3>& points) {
  std::vector<Vertex_handle> handles;
  return finite_tets(triangulate(points, handles));
}

std::vector<Tet> refined_delaunay(std::vector<Vec3>& points, const Polyhedral_domain& domain, double max_ratio,
                                  std::size_t budget, const Sliver_options& slivers, Refinement_report& report) {
  std::vector<Vertex_handle> handles;
  Delaunay_3 triangulation = triangulate(points, handles);
  const std::size_t n_input = points.size();
  for (report.rounds = 0; report.rounds < 64; ++report.rounds) {
    // The round's bad tetrahedra, by canonical vertex indices.
    const std::vector<Tet> bad = cells_where(
        triangulation, [&](const Delaunay_3::Cell_handle& cell) { return radius_edge(cell) > max_ratio; });
    report.unresolved = bad.size();
    if (bad.empty() || points.size() - n_input >= budget) break;
    std::size_t inserted = 0;
    for (const Tet& t : bad) {
      if (points.size() - n_input >= budget) break;
      Vec3 x;
      const Vertex_handle v = insert_at_circumcentre(triangulation, handles, t, domain, x);
      if (v == Vertex_handle()) continue;
      keep_point(v, x, t, points, handles, report);
      ++inserted;
    }
    if (inserted == 0) break;
  }
  if (slivers.min_dihedral > 0) {
    perturb_slivers(triangulation, handles, points, slivers, domain, true, report);
    for (int pass = 0; pass < slivers.insertion_passes && report.slivers_after > 0; ++pass) {
      const std::size_t inserted = insert_off_centres(triangulation, handles, points, slivers, domain, report);
      if (inserted == 0) break;
      report.off_centres += inserted;
      perturb_slivers(triangulation, handles, points, slivers, domain, false, report);
    }
    // The insertions may leave a tetrahedron above the ratio: counted.
    report.unresolved = cells_where(
        triangulation, [&](const Delaunay_3::Cell_handle& cell) { return radius_edge(cell) > max_ratio; }).size();
  }
  report.inserted = points.size() - n_input;
  return finite_tets(triangulation);
}

}  // namespace evomesh::tet
