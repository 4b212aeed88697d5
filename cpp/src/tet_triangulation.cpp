// The Delaunay tetrahedralisation of a step's kept points, and its
// radius-edge refinement (tet/tet_step.hpp).
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

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

}  // namespace

std::vector<Tet> delaunay_tetrahedra(const std::vector<Vec3>& points) {
  std::vector<Vertex_handle> handles;
  return finite_tets(triangulate(points, handles));
}

std::vector<Tet> refined_delaunay(std::vector<Vec3>& points, const Vec3& lo, const Vec3& hi, double max_ratio,
                                  std::size_t budget, Refinement_report& report) {
  std::vector<Vertex_handle> handles;
  Delaunay_3 triangulation = triangulate(points, handles);
  const std::size_t n_input = points.size();
  auto inside = [&](const Vec3& x) {
    for (int i = 0; i < 3; ++i) {
      if (!(x[i] > lo[i] && x[i] < hi[i])) return false;
    }
    return true;
  };
  for (report.rounds = 0; report.rounds < 64; ++report.rounds) {
    // The round's bad tetrahedra, by canonical vertex indices.
    std::vector<Tet> bad;
    for (auto cell = triangulation.finite_cells_begin(); cell != triangulation.finite_cells_end(); ++cell) {
      const Point_3& a = cell->vertex(0)->point();
      const Point_3& b = cell->vertex(1)->point();
      const Point_3& c = cell->vertex(2)->point();
      const Point_3& d = cell->vertex(3)->point();
      const double shortest = std::min({squared(a, b), squared(a, c), squared(a, d), squared(b, c), squared(b, d),
                                        squared(c, d)});
      const double radius = squared(CGAL::circumcenter(a, b, c, d), a);
      if (radius > max_ratio * max_ratio * shortest) {
        bad.push_back(canonical({cell->vertex(0)->info(), cell->vertex(1)->info(), cell->vertex(2)->info(),
                                 cell->vertex(3)->info()}));
      }
    }
    report.unresolved = bad.size();
    if (bad.empty() || points.size() - n_input >= budget) break;
    std::sort(bad.begin(), bad.end());
    std::size_t inserted = 0;
    for (const Tet& t : bad) {
      if (points.size() - n_input >= budget) break;
      Delaunay_3::Cell_handle cell;
      int i, j, k, l;
      const auto h = [&](int q) { return handles[static_cast<std::size_t>(t[static_cast<std::size_t>(q)])]; };
      if (!triangulation.is_cell(h(0), h(1), h(2), h(3), cell, i, j, k, l)) continue;  // gone this round
      const Point_3 centre = CGAL::circumcenter(h(0)->point(), h(1)->point(), h(2)->point(), h(3)->point());
      double shortest = std::numeric_limits<double>::infinity();
      for (int u = 0; u < 4; ++u) {
        for (int v = u + 1; v < 4; ++v) shortest = std::min(shortest, squared(h(u)->point(), h(v)->point()));
      }
      shortest = std::sqrt(shortest);
      Vec3 x{centre.x(), centre.y(), centre.z()};
      // A centre near or beyond a box face goes onto that face (the face's
      // coordinate exact), away from its edges; none near an edge.
      int near_axis = -1;
      double near_distance = 0.5 * shortest;
      for (int a = 0; a < 3; ++a) {
        for (const double bound : {lo[a], hi[a]}) {
          const double distance = std::abs(x[a] - bound);
          const bool beyond = bound == lo[a] ? x[a] <= lo[a] : x[a] >= hi[a];
          if (beyond || distance < near_distance) near_axis = a, near_distance = beyond ? -1.0 : distance;
        }
      }
      if (near_axis >= 0) {
        x[near_axis] = std::abs(x[near_axis] - lo[near_axis]) < std::abs(x[near_axis] - hi[near_axis]) ? lo[near_axis]
                                                                                                        : hi[near_axis];
        bool clear = true;
        for (int a = 0; a < 3; ++a) {
          if (a != near_axis && !(x[a] - lo[a] >= 0.5 * shortest && hi[a] - x[a] >= 0.5 * shortest)) clear = false;
        }
        if (!clear) continue;
      } else if (!inside(x)) {
        continue;
      }
      const std::size_t before = triangulation.number_of_vertices();
      const Vertex_handle v = triangulation.insert(Point_3(x[0], x[1], x[2]), cell);
      if (triangulation.number_of_vertices() == before) continue;  // an existing point
      v->info() = static_cast<Index>(points.size());
      points.push_back(x);
      handles.push_back(v);
      report.hints.push_back(t[0]);
      ++inserted;
    }
    if (inserted == 0) break;
  }
  report.inserted = points.size() - n_input;
  return finite_tets(triangulation);
}

}  // namespace evomesh::tet
