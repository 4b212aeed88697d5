// Inserting the input points into a CGAL triangulation, shared by the
// constrained triangulations of triangulation.cpp and the Delaunay mesher
// (delaunay_mesher.hpp). Internal: included by cpp/src only.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <utility>
#include <vector>

#include "evomesh/detail/parallel_sweep.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/types.hpp"

namespace evomesh::detail {

// The point index a vertex's info holds: the info itself when it is an Index.
// Other info types give theirs by an overload in their own namespace (found by
// argument-dependent lookup).
inline Index& vertex_index(Index& info) { return info; }

// The vertex of every point index (vertex_index of each finite vertex's info),
// placed by a parallel sweep over the vertices (parallel_sweep.hpp; the writes
// land all over `handles`: on a large triangulation that is the cost).
// `check(v)`, also in parallel, returns false for a vertex that is not where
// the caller expects; then std::logic_error(what) is thrown.
template <class Tr, class Check>
std::vector<typename Tr::Vertex_handle> vertex_handles(Tr& tr, std::size_t n_points, Check check, const char* what) {
  using Vertex_handle = typename Tr::Vertex_handle;
  std::vector<Vertex_handle> handles(n_points);
  auto& vertices = tr.tds().vertices();
  std::vector<std::uint8_t> wrong(sweep_chunks(vertices), 0);
  parallel_sweep(vertices, [&](std::size_t c, Vertex_handle v) {
    if (tr.is_infinite(v)) return;
    const Index i = vertex_index(v->info());
    if (i < 0 || static_cast<std::size_t>(i) >= n_points || !check(v)) {
      wrong[c] = 1;
      return;
    }
    handles[i] = v;
  });
  for (std::uint8_t w : wrong) {
    if (w) throw std::logic_error(what);
  }
  return handles;
}

// Inserts `points`, scaled by `scale` (a power of two, so exactly), with CGAL's
// range insertion (its spatial sort, each point located from the last); each
// vertex's info holds the index of its point (vertex_index), the rest of the
// info is value-initialised. Throws Input_error when points coincide.
template <class Tr>
void insert_points_only(Tr& tr, const std::vector<Vec2>& points, double scale = 1) {
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
}

// insert_points_only, and the vertex of every point.
template <class Tr>
std::vector<typename Tr::Vertex_handle> insert_points(Tr& tr, const std::vector<Vec2>& points, double scale = 1) {
  insert_points_only(tr, points, scale);
  return vertex_handles(
      tr, points.size(), [](const typename Tr::Vertex_handle&) { return true; }, "insert_points: a vertex without its point");
}

}  // namespace evomesh::detail
