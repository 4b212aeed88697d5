// The quality pass (quality_triangulate) is a function of its input *sets*:
// the same points and constraint pieces handed in any order give the same
// output points and the same triangles. The triangulation's insertion history
// (its face container order and the rotation of each face) must not reach the
// result: not through the queue of bad faces (ties of quality), not through
// the queue of encroached sub-segments, not through a face's rotation in the
// off-centre or the quality's rounding. Inputs full of exact ties: a lattice
// (every cell cocircular, every triangle of equal quality) with points pushed
// off it so the pass has work, inside a square with a slit, in shuffled orders
// (CGAL's spatial sort breaks ties of coordinates by input position, so each
// order builds the triangulation differently).
#include <algorithm>
#include <array>
#include <cstdio>
#include <numeric>
#include <random>
#include <tuple>
#include <vector>

#include "check.hpp"
#include "evomesh/quality_pass.hpp"

namespace {

using evomesh::Constraint_piece;
using evomesh::Index;
using evomesh::Point_kind;
using evomesh::Quality_options;
using evomesh::Vec2;

struct Input {
  std::vector<Vec2> points;
  std::vector<Point_kind> kind;
  std::vector<Constraint_piece> pieces;
};

// A k x k lattice of spacing 1 on [0, k-1]^2, its boundary as pieces, a slit
// along y = k/2 from x = 1 to x = k/2, and `moved` interior points nudged
// towards a neighbour (thin triangles for the angle rule).
Input lattice(int k, int moved, unsigned seed) {
  Input in;
  auto at = [k](int i, int j) { return static_cast<Index>(j * k + i); };
  for (int j = 0; j < k; ++j) {
    for (int i = 0; i < k; ++i) {
      in.points.push_back({static_cast<double>(i), static_cast<double>(j)});
      const bool edge = i == 0 || j == 0 || i == k - 1 || j == k - 1;
      const bool corner = (i == 0 || i == k - 1) && (j == 0 || j == k - 1);
      in.kind.push_back(corner ? Point_kind::corner : edge ? Point_kind::boundary : Point_kind::original);
    }
  }
  for (int i = 0; i + 1 < k; ++i) {
    in.pieces.push_back({at(i, 0), at(i + 1, 0), true});
    in.pieces.push_back({at(k - 1, i), at(k - 1, i + 1), true});
    in.pieces.push_back({at(i + 1, k - 1), at(i, k - 1), true});
    in.pieces.push_back({at(0, i + 1), at(0, i), true});
  }
  const int mid = k / 2;
  for (int i = 1; i < mid; ++i) in.pieces.push_back({at(i, mid), at(i + 1, mid), false});
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> inner(mid + 1, k - 2);
  for (int m = 0; m < moved; ++m) {
    const Index p = at(inner(rng), inner(rng));
    // (a nudge by a dyadic fraction: still exact ties between the moved points' triangles)
    in.points[p][0] += 0.375;
    in.points[p][1] += 0.125;
  }
  return in;
}

// The same input with its points in order `perm` (new position -> old) and its
// pieces reversed in order.
Input permuted(const Input& in, const std::vector<Index>& perm) {
  Input out;
  std::vector<Index> where(perm.size());
  for (std::size_t k = 0; k < perm.size(); ++k) {
    where[perm[k]] = static_cast<Index>(k);
    out.points.push_back(in.points[perm[k]]);
    out.kind.push_back(in.kind[perm[k]]);
  }
  for (auto it = in.pieces.rbegin(); it != in.pieces.rend(); ++it) {
    out.pieces.push_back({where[it->a], where[it->b], it->boundary, it->tag});
  }
  return out;
}

using Coords = std::array<double, 2>;
using Canonical = std::tuple<std::vector<Coords>, std::vector<std::array<Coords, 3>>, std::size_t>;

// Points sorted; triangles as coordinates rotated to start at their least point, sorted.
Canonical canonical(const evomesh::Refined_mesh& r) {
  const auto& m = r.mesh;
  std::vector<Coords> points;
  for (const Vec2& p : m.points) points.push_back({p[0], p[1]});
  std::sort(points.begin(), points.end());
  std::vector<std::array<Coords, 3>> triangles;
  for (const auto& t : m.triangles) {
    std::array<Coords, 3> c;
    for (int k = 0; k < 3; ++k) c[k] = {m.points[t[k]][0], m.points[t[k]][1]};
    while (c[1] < c[0] || c[2] < c[0]) c = {c[1], c[2], c[0]};
    triangles.push_back(c);
  }
  std::sort(triangles.begin(), triangles.end());
  return {points, triangles, r.report.n_inserted};
}

void check_orders(const Input& in, double min_angle, int orders, const char* what) {
  Quality_options options;
  options.min_angle = min_angle;
  const auto reference = evomesh::quality_triangulate(in.points, in.kind, in.pieces, options);
  const Canonical expected = canonical(reference);
  CHECK(reference.report.n_inserted > 0) << what << ": the pass had nothing to do";
  std::mt19937 rng(7);
  std::vector<Index> perm(in.points.size());
  std::iota(perm.begin(), perm.end(), Index{0});
  for (int o = 0; o < orders; ++o) {
    std::shuffle(perm.begin(), perm.end(), rng);
    const Input p = permuted(in, perm);
    const auto got = evomesh::quality_triangulate(p.points, p.kind, p.pieces, options);
    const Canonical c = canonical(got);
    CHECK(std::get<2>(c) == std::get<2>(expected))
        << what << ", order " << o << ": " << std::get<2>(c) << " points inserted, " << std::get<2>(expected)
        << " in input order";
    CHECK(std::get<0>(c) == std::get<0>(expected)) << what << ", order " << o << ": other output points";
    CHECK(std::get<1>(c) == std::get<1>(expected)) << what << ", order " << o << ": other triangles";
  }
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    check_orders(lattice(12, 6, 1), 30.0, 12, "12x12 lattice, 6 moved, 30 degrees");
    check_orders(lattice(16, 20, 2), 28.0, 8, "16x16 lattice, 20 moved, 28 degrees");
    check_orders(lattice(20, 60, 3), 30.0, 8, "20x20 lattice, 60 moved, 30 degrees");
    check_orders(lattice(9, 8, 4), 20.0, 12, "9x9 lattice, 8 moved, 20 degrees");
  });
}
