// A test input shared by the C++ tests: an n x n grid of the unit square,
// slightly jittered inside (deterministically), with boundary segments and
// kinds as Mesh() makes them.
#pragma once

#include <cmath>

#include "evomesh/triangulation.hpp"
#include "evomesh/types.hpp"

namespace evomesh::testing {

inline Mesh_arrays grid_mesh(int n) {
  Mesh_arrays mesh;
  const double h = 1.0 / (n - 1);
  for (int y = 0; y < n; ++y) {
    for (int x = 0; x < n; ++x) {
      const bool inside = x > 0 && y > 0 && x < n - 1 && y < n - 1;
      const double jx = inside ? 0.2 * h * std::sin(12.9898 * x + 78.233 * y) : 0.0;
      const double jy = inside ? 0.2 * h * std::cos(39.3468 * x + 11.135 * y) : 0.0;
      mesh.points.push_back({x * h + jx, y * h + jy});
    }
  }
  for (int y = 0; y + 1 < n; ++y) {
    for (int x = 0; x + 1 < n; ++x) {
      const Index a = static_cast<Index>(n) * y + x, b = a + 1, c = a + n + 1, d = a + n;
      mesh.triangles.push_back({a, b, c});
      mesh.triangles.push_back({a, c, d});
    }
  }
  build_segments(mesh, {});
  mesh.kind = classify_points(mesh);
  return mesh;
}

}  // namespace evomesh::testing
