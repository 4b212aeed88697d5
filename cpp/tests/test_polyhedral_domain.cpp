// Polyhedral_domain on a regular octahedron: every point it puts on a facet
// (snap_to_facet) or an edge (edge_point) lies there exactly (CGAL's exact
// orientation and collinearity), its incidences and clearance agree with the
// geometry, strictly_inside is exact on the facets, and a facet whose corners
// hold no float64 lattice is refused with Input_error.
#include <array>
#include <cmath>
#include <random>
#include <vector>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include "check.hpp"
#include "evomesh/tet/polyhedral_domain.hpp"

using namespace evomesh;
using namespace evomesh::tet;
using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point_3 = Kernel::Point_3;

namespace {

Point_3 point(const Vec3& p) { return Point_3(p[0], p[1], p[2]); }

// The octahedron |x| + |y| + |z| <= 1: facet (sx, sy, sz) through sx e_x,
// sy e_y, sz e_z, outward; edges between facets differing in one sign.
Polyhedral_domain octahedron(std::vector<std::array<Vec3, 3>>& facets) {
  facets.clear();
  std::vector<std::array<int, 3>> signs;
  for (int sx : {1, -1}) {
    for (int sy : {1, -1}) {
      for (int sz : {1, -1}) {
        std::array<Vec3, 3> f{Vec3{double(sx), 0, 0}, Vec3{0, double(sy), 0}, Vec3{0, 0, double(sz)}};
        // outward: the origin (inside) sees them clockwise
        if (CGAL::orientation(point(f[0]), point(f[1]), point(f[2]), Point_3(0, 0, 0)) == CGAL::POSITIVE) {
          std::swap(f[1], f[2]);
        }
        facets.push_back(f);
        signs.push_back({sx, sy, sz});
      }
    }
  }
  std::vector<std::array<int, 2>> edge_facets;
  std::vector<std::array<Vec3, 2>> edge_ends;
  for (int f = 0; f < 8; ++f) {
    for (int g = f + 1; g < 8; ++g) {
      int differ = -1, count = 0;
      for (int i = 0; i < 3; ++i) {
        if (signs[f][i] != signs[g][i]) differ = i, ++count;
      }
      if (count != 1) continue;
      Vec3 p{0, 0, 0}, q{0, 0, 0};
      p[(differ + 1) % 3] = signs[f][(differ + 1) % 3];
      q[(differ + 2) % 3] = signs[f][(differ + 2) % 3];
      edge_facets.push_back({f, g});
      edge_ends.push_back({p, q});
    }
  }
  return Polyhedral_domain(facets, edge_facets, edge_ends, std::vector<Polyhedral_domain::Mask>(8, 0xff));
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    std::vector<std::array<Vec3, 3>> facets;
    const Polyhedral_domain domain = octahedron(facets);
    CHECK(domain.n_facets() == 8 && domain.n_edges() == 12) << domain.n_edges();
    std::mt19937_64 random(7);
    std::uniform_real_distribution<double> uniform(-1.2, 1.2);
    int on_facets = 0, on_edges = 0;
    for (int k = 0; k < 4000; ++k) {
      const Vec3 x{uniform(random), uniform(random), uniform(random)};
      const std::size_t f = static_cast<std::size_t>(k % 8);
      Vec3 y = x;
      if (domain.snap_to_facet(f, y)) {
        ++on_facets;
        CHECK(CGAL::orientation(point(facets[f][0]), point(facets[f][1]), point(facets[f][2]), point(y)) ==
              CGAL::COPLANAR) << k;
        CHECK(domain.incidences(y) >> f & 1u) << k;
        CHECK(std::abs(domain.distance(f, y)) < 1e-15) << domain.distance(f, y);
        CHECK(!domain.strictly_inside(y, 0)) << k;  // on facet f: not strictly inside it
      }
      const std::size_t e = static_cast<std::size_t>(k % 12);
      Vec3 z;
      if (domain.edge_point(e, x[static_cast<std::size_t>(domain.edge_axis(e))], z)) {
        ++on_edges;
        const auto [f0, f1] = domain.edge_facets(e);
        const Polyhedral_domain::Mask both = (Polyhedral_domain::Mask{1} << f0) | (Polyhedral_domain::Mask{1} << f1);
        CHECK((domain.incidences(z) & both) == both) << k;
      }
      // inside strictly iff |x| + |y| + |z| < 1, exactly for these dyadic-free tests away from the surface
      const double l1 = std::abs(x[0]) + std::abs(x[1]) + std::abs(x[2]);
      if (std::abs(l1 - 1) > 1e-9) CHECK(domain.strictly_inside(x, 0) == (l1 < 1)) << l1;
      if (l1 < 1 - 1e-9) CHECK(domain.clearance(x, 0) > 0 && std::abs(domain.clearance(x, 0) - (1 - l1) / std::sqrt(3.0)) < 1e-12);
    }
    CHECK(on_facets > 3900) << on_facets;  // the lattice is exact nearly everywhere
    CHECK(on_edges > 3900) << on_edges;
    // A facet through corners with full-precision coordinates holds no lattice.
    const double a = 0.1, b = 0.7, c = std::sqrt(0.3);
    bool refused = false;
    try {
      Polyhedral_domain({{Vec3{a, 0, 0}, Vec3{0, b, 0}, Vec3{0, 0, c}}}, {}, {}, {0});
    } catch (const Input_error&) {
      refused = true;
    }
    CHECK(refused);
  });
}
