// The empty-scope step (empty_scope.hpp) on meshes the Python Mesh would
// refuse: its certificate must not take the embedding for granted. A mesh
// whose boundary loops cross, or whose parts cover the plane twice without a
// crossing, is declined at C5 (the boundary's own triangulation), after the
// per-triangle certificates have passed; the settled mesh with a hole they are
// made of is certified, with frfc's bits.
#include <utility>
#include <vector>

#include "check.hpp"
#include "evomesh/empty_scope.hpp"
#include "evomesh/frfc.hpp"
#include "evomesh/triangulation.hpp"
#include "grid_mesh.hpp"

namespace {

using namespace evomesh;

// A grid of the unit square without the triangles in its middle square (a
// hole), then frfc at delta = 1 until it returns its input.
Mesh_arrays settled_mesh_with_hole() {
  Mesh_arrays grid = testing::grid_mesh(24);
  Mesh_arrays mesh;
  mesh.points = grid.points;
  for (const Triangle& t : grid.triangles) {
    const double x = (grid.points[t[0]][0] + grid.points[t[1]][0] + grid.points[t[2]][0]) / 3;
    const double y = (grid.points[t[0]][1] + grid.points[t[1]][1] + grid.points[t[2]][1]) / 3;
    if (x > 0.35 && x < 0.65 && y > 0.35 && y < 0.65) continue;
    mesh.triangles.push_back(t);
  }
  // (the points of the hole's inside, in no triangle, are dropped)
  std::vector<Index> old2new(mesh.points.size(), -1);
  std::vector<Vec2> used;
  for (Triangle& t : mesh.triangles) {
    for (Index& v : t) {
      if (old2new[v] < 0) {
        old2new[v] = static_cast<Index>(used.size());
        used.push_back(mesh.points[v]);
      }
      v = old2new[v];
    }
  }
  mesh.points = used;
  build_segments(mesh, {});
  mesh.kind = classify_points(mesh);
  for (int step = 0; step < 6; ++step) {
    Evolve_result r = frfc(mesh, std::vector<double>(mesh.points.size(), 1.0), Frfc_options{});
    mesh = std::move(r.mesh);
  }
  return mesh;
}

// a and a copy of b mapped by x -> scale x + shift, side by side in one mesh.
Mesh_arrays with_copy(const Mesh_arrays& a, const Mesh_arrays& b, double scale, Vec2 shift) {
  Mesh_arrays out = a;
  const Index n = static_cast<Index>(a.points.size());
  for (const Vec2& p : b.points) out.points.push_back({scale * p[0] + shift[0], scale * p[1] + shift[1]});
  for (const Triangle& t : b.triangles) out.triangles.push_back({t[0] + n, t[1] + n, t[2] + n});
  for (const Edge& e : b.segments) out.segments.push_back({e[0] + n, e[1] + n});
  out.segment_is_boundary.insert(out.segment_is_boundary.end(), b.segment_is_boundary.begin(),
                                 b.segment_is_boundary.end());
  out.kind.insert(out.kind.end(), b.kind.begin(), b.kind.end());
  return out;
}

bool same_step(const Evolve_result& a, const Evolve_result& b) {
  return a.mesh.points == b.mesh.points && a.mesh.triangles == b.mesh.triangles &&
         a.mesh.segments == b.mesh.segments && a.mesh.segment_is_boundary == b.mesh.segment_is_boundary &&
         a.mesh.kind == b.mesh.kind && a.origin == b.origin && a.output_nn == b.output_nn &&
         a.input_f == b.input_f && a.parents.triangle == b.parents.triangle;
}

int declined_by(const Mesh_arrays& mesh) {
  int certificate = -1;
  const auto result = empty_scope_frfc(mesh, std::vector<double>(mesh.points.size(), 1.0), Frfc_options{}, Step_context{}, &certificate);
  return result ? -1 : certificate;
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    const Mesh_arrays mesh = settled_mesh_with_hole();
    const std::vector<double> ones(mesh.points.size(), 1.0);
    // The settled mesh with a hole: certified, frfc's full step bit for bit.
    int certificate = -1;
    const auto fast = empty_scope_frfc(mesh, ones, Frfc_options{}, Step_context{}, &certificate);
    CHECK(fast.has_value()) << "declined by " << certificate;
    Frfc_options full_options;
    full_options.incremental = false;
    const Evolve_result full = frfc(mesh, ones, full_options);
    if (fast) CHECK(same_step(*fast, full));
    // One segment given backwards (Mesh() would orient it), on the hole or
    // the outer boundary: whenever the empty scope answers, with frfc's bits.
    int answered = 0;
    for (std::size_t s = 0; s < mesh.segments.size(); s += 7) {
      Mesh_arrays flipped = mesh;
      std::swap(flipped.segments[s][0], flipped.segments[s][1]);
      const auto quick = empty_scope_frfc(flipped, ones, Frfc_options{}, Step_context{});
      if (!quick) continue;
      ++answered;
      CHECK(same_step(*quick, frfc(flipped, ones, full_options))) << "segment " << s;
    }
    CHECK(answered > 0);
    // Each part passes the per-triangle certificates; together they do not
    // bound a domain: two boundaries crossing, a copy inside the domain (the
    // plane covered twice, no crossing), a copy over the hole's edge.
    CHECK(declined_by(with_copy(mesh, mesh, 1.0, {0.5, 0.25})) == 5);
    CHECK(declined_by(with_copy(mesh, mesh, 0.1, {0.1, 0.1})) == 5);
    CHECK(declined_by(with_copy(mesh, mesh, 0.1, {0.3, 0.45})) == 5);
    // The same copy inside the hole, touching nothing: an island, certified as
    // far as the boundary goes (declined, if at all, by the spacing, C7 on).
    const int island = declined_by(with_copy(mesh, mesh, 0.1, {0.45, 0.45}));
    CHECK(island == -1 || island >= 7) << island;
  });
}
