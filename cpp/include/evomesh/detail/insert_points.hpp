// Inserting the input points into a CGAL triangulation, shared by the
// constrained triangulations of triangulation.cpp and the Delaunay mesher
// (delaunay_mesher.hpp). Internal: included by cpp/src only.
#pragma once

#include <cstddef>
#include <utility>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh::detail {

// The point index a vertex's info holds: the info itself when it is an Index.
// Other info types give theirs by an overload in their own namespace (found by
// argument-dependent lookup).
inline Index& vertex_index(Index& info) { return info; }

// Inserts `points`, scaled by `scale` (a power of two, so exactly), with CGAL's
// range insertion (its spatial sort, each point located from the last); each
// vertex's info holds the index of its point (vertex_index), the rest of the
// info is value-initialised. Returns the vertex of every point; throws
// Input_error when points coincide.
template <class Tr>
std::vector<typename Tr::Vertex_handle> insert_points(Tr& tr, const std::vector<Vec2>& points, double scale = 1) {
  using Info = typename Tr::Vertex::Info;
  std::vector<std::pair<typename Tr::Point, Info>> input;
  input.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    Info info{};
    vertex_index(info) = static_cast<Index>(i);
    input.emplace_back(typename Tr::Point(points[i][0] * scale, points[i][1] * scale), info);
  }
  tr.insert(input.begin(), input.end());
  if (tr.number_of_vertices() != points.size()) throw Input_error("points contain duplicates");
  std::vector<typename Tr::Vertex_handle> handles(points.size());
  for (auto v = tr.finite_vertices_begin(); v != tr.finite_vertices_end(); ++v) handles[vertex_index(v->info())] = v;
  return handles;
}

}  // namespace evomesh::detail
