// size_request.hpp: edge_over_size_classes compares as edge_over_size_around's
// exact L does, also at thresholds on the L values themselves (where its close
// L cannot tell and it computes L again with hypot), on a jittered grid and an
// unjittered one (where many points share an L), with a uniform request and a
// graded one; sharing_a_triangle and near_seeds on small cases worked by hand.
#include <cmath>
#include <cstdint>
#include <vector>

#include "check.hpp"
#include "evomesh/size_request.hpp"
#include "grid_mesh.hpp"

namespace {

using namespace evomesh;

std::uint8_t exact_classes(double value, double above, double below, double at_least) {
  return static_cast<std::uint8_t>((value > above ? Edge_over_size_above : 0) |
                                   (value < below ? Edge_over_size_below : 0) |
                                   (value >= at_least ? Edge_over_size_at_least : 0));
}

// Checks every point at the thresholds; returns the points whose L equals one
// of them (where the close L cannot decide).
int check_classes(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                  const std::vector<double>& h, double above, double below, double at_least) {
  const std::vector<double> exact = edge_over_size_around(points, triangles, h);
  const std::vector<std::uint8_t> classes = edge_over_size_classes(points, triangles, h, above, below, at_least);
  CHECK(classes.size() == points.size());
  int ties = 0;
  for (std::size_t p = 0; p < points.size(); ++p) {
    CHECK(classes[p] == exact_classes(exact[p], above, below, at_least))
        << "point " << p << " L " << exact[p] << " classes " << int(classes[p]);
    ties += exact[p] == above || exact[p] == below || exact[p] == at_least;
  }
  return ties;
}

void check_grid(const Mesh_arrays& mesh, const std::vector<double>& h) {
  check_classes(mesh.points, mesh.triangles, h, 1.25, 1 / 1.25, 1 / 1.1);
  const std::vector<double> exact = edge_over_size_around(mesh.points, mesh.triangles, h);
  int ties = 0;
  for (std::size_t p = 0; p < exact.size(); p += 37) {
    const double at = exact[p];
    ties += check_classes(mesh.points, mesh.triangles, h, at, std::nextafter(at, 2 * at), std::nextafter(at, 0.0));
    ties += check_classes(mesh.points, mesh.triangles, h, std::nextafter(at, 0.0), at, at);
  }
  CHECK(ties > 0);
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    const Mesh_arrays jittered = testing::grid_mesh(40);
    // Unjittered: every interior point of the grid has one L.
    Mesh_arrays regular = testing::grid_mesh(40);
    const double step = 1.0 / 39;
    for (std::size_t p = 0; p < regular.points.size(); ++p)
      regular.points[p] = {static_cast<double>(p % 40) * step, static_cast<double>(p / 40) * step};
    for (const Mesh_arrays* mesh : {&jittered, static_cast<const Mesh_arrays*>(&regular)}) {
      const std::size_t n = mesh->points.size();
      check_grid(*mesh, std::vector<double>(n, 1.1 * step));
      std::vector<double> graded(n);
      for (std::size_t p = 0; p < n; ++p) graded[p] = step * (0.5 + mesh->points[p][0]);
      check_grid(*mesh, graded);
    }
    // A point in no triangle: L is NaN, no class.
    const std::vector<Vec2> points{{0, 0}, {1, 0}, {0, 1}, {5, 5}};
    const std::vector<Triangle> one{{0, 1, 2}};
    CHECK(edge_over_size_classes(points, one, {1, 1, 1, 1}, 0.5, 2, 1)[3] == 0);
    // Two triangles 0 1 2 and 1 3 2, a third 3 4 5 apart: 1 and 2 share a
    // triangle with another marked point, 4 does not (its neighbours are not marked).
    const std::vector<Triangle> three{{0, 1, 2}, {1, 3, 2}, {3, 4, 5}};
    const std::vector<std::uint8_t> marked{0, 1, 1, 0, 1, 0};
    CHECK((sharing_a_triangle(three, marked) == std::vector<std::uint8_t>{0, 1, 1, 0, 0, 0}));
    // From seed 0: 1 and 2 within one ring, 3 within two, 4 and 5 within three.
    const std::vector<std::uint8_t> all(6, 1), seed{1, 0, 0, 0, 0, 0};
    CHECK((near_seeds(three, all, seed, 1) == std::vector<std::uint8_t>{1, 1, 1, 0, 0, 0}));
    CHECK((near_seeds(three, all, seed, 2) == std::vector<std::uint8_t>{1, 1, 1, 1, 0, 0}));
    CHECK((near_seeds(three, all, seed, 3) == std::vector<std::uint8_t>{1, 1, 1, 1, 1, 1}));
    CHECK((near_seeds(three, marked, seed, 9) == marked));
    // Through every point but 2: 2 is never reached, 3 comes from 1 a ring
    // later, and 4 and 5 from 3.
    const std::vector<std::uint8_t> through{1, 1, 0, 1, 1, 1};
    CHECK((near_seeds(three, all, seed, 1, &through) == std::vector<std::uint8_t>{1, 1, 0, 0, 0, 0}));
    CHECK((near_seeds(three, all, seed, 2, &through) == std::vector<std::uint8_t>{1, 1, 0, 1, 0, 0}));
    CHECK((near_seeds(three, all, seed, 3, &through) == std::vector<std::uint8_t>{1, 1, 0, 1, 1, 1}));
  });
}
