// updated_constrained_delaunay (triangulation_update.hpp) against
// constrained_delaunay on the same points and pieces: a square with a square
// hole, points dropped and added in a disc (and on the boundary: a piece split,
// two merged), an exact lattice (ties: declined or equal), and an input with one
// edge flipped (not Delaunay: declined).
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "check.hpp"
#include "evomesh/kernel.hpp"
#include "evomesh/parent_map.hpp"
#include "evomesh/triangulation.hpp"
#include "evomesh/triangulation_update.hpp"

using namespace evomesh;

namespace {

struct Domain {
  std::vector<Vec2> points;
  std::vector<Constraint_piece> pieces;
};

void add_loop(Domain& d, const std::vector<Vec2>& corners, int per_side) {
  const Index first = static_cast<Index>(d.points.size());
  for (std::size_t c = 0; c < corners.size(); ++c) {
    const Vec2 &a = corners[c], &b = corners[(c + 1) % corners.size()];
    for (int k = 0; k < per_side; ++k) {
      const double t = static_cast<double>(k) / per_side;
      d.points.push_back({a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])});
    }
  }
  const Index count = static_cast<Index>(d.points.size()) - first;
  for (Index k = 0; k < count; ++k) d.pieces.push_back({first + k, first + (k + 1) % count, true});
}

bool in_ring(const Vec2& p) { return p[0] > 0.9 && p[0] < 3.1 && p[1] > 0.9 && p[1] < 3.1; }

// A square [0, 4]^2 with a hole [1, 3]^2; interior points random (or a lattice).
Domain square_with_hole(int per_side, int n_interior, std::uint64_t seed, bool lattice) {
  Domain d;
  add_loop(d, {{0, 0}, {4, 0}, {4, 4}, {0, 4}}, per_side);
  add_loop(d, {{1, 1}, {1, 3}, {3, 3}, {3, 1}}, per_side);
  if (lattice) {
    const double h = 4.0 / per_side;
    for (int i = 1; i < per_side; ++i) {
      for (int j = 1; j < per_side; ++j) {
        const Vec2 p{i * h, j * h};
        if (!in_ring(p)) d.points.push_back(p);
      }
    }
    return d;
  }
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.05, 3.95);
  while (static_cast<int>(d.points.size()) < 8 * per_side + n_interior) {
    const Vec2 p{u(rng), u(rng)};
    if (!in_ring(p)) d.points.push_back(p);
  }
  return d;
}

Mesh_arrays as_mesh(const Domain& d) {
  Mesh_arrays m;
  m.points = d.points;
  m.triangles = constrained_delaunay(d.points, d.pieces);
  for (const auto& piece : d.pieces) {
    m.segments.push_back({piece.a, piece.b});
    m.segment_is_boundary.push_back(1);
  }
  m.kind.assign(m.points.size(), Point_kind::original);
  return m;
}

// The step's shape of output: kept points in input order, then the new ones;
// the pieces renumbered (a dropped boundary point merges its two pieces, a new
// boundary point splits one). `origin`: input index or -1.
struct Output {
  std::vector<Vec2> points;
  std::vector<Constraint_piece> pieces;
  std::vector<Index> origin;
};

Output change(const Domain& d, const std::vector<std::uint8_t>& dropped, const std::vector<Vec2>& added,
              const std::vector<std::pair<Index, Vec2>>& on_pieces) {
  Output out;
  std::vector<Index> new_of(d.points.size(), -1);
  for (std::size_t i = 0; i < d.points.size(); ++i) {
    if (dropped[i]) continue;
    new_of[i] = static_cast<Index>(out.points.size());
    out.points.push_back(d.points[i]);
    out.origin.push_back(static_cast<Index>(i));
  }
  for (const Vec2& x : added) {
    out.points.push_back(x);
    out.origin.push_back(-1);
  }
  // Boundary loops: walk each piece chain, skipping dropped points, splitting where asked.
  std::vector<Index> next(d.points.size(), -1);
  for (const auto& piece : d.pieces) next[piece.a] = piece.b;
  for (const auto& piece : d.pieces) {
    if (dropped[piece.a]) continue;
    Index b = piece.b;
    while (dropped[b]) b = next[b];
    Index from = new_of[piece.a];
    for (const auto& [at, x] : on_pieces) {
      if (at != piece.a) continue;
      const Index mid = static_cast<Index>(out.points.size());
      out.points.push_back(x);
      out.origin.push_back(-1);
      out.pieces.push_back({from, mid, true});
      from = mid;
    }
    out.pieces.push_back({from, new_of[b], true});
  }
  return out;
}

void check_update(const Domain& d, const Output& out, bool expect_update, const char* what) {
  const Mesh_arrays input = as_mesh(d);
  const Old_mesh_walker walker(input);
  Triangulation_update_report report;
  const auto updated = updated_constrained_delaunay(walker, out.points, out.pieces, out.origin, 1.0, report);
  const auto whole = constrained_delaunay(out.points, out.pieces);
  if (expect_update) CHECK(updated.has_value()) << what << ": declined " << report.declined;
  if (updated) CHECK(*updated == whole) << what << ": " << updated->size() << " vs " << whole.size() << " triangles";
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    for (std::uint64_t seed = 0; seed < 8; ++seed) {
      const Domain d = square_with_hole(12, 600, seed, false);
      std::mt19937_64 rng(seed + 100);
      std::uniform_real_distribution<double> u(0.05, 3.95);
      const double radius = 0.3 + 0.1 * static_cast<double>(seed % 3);
      Vec2 centre{u(rng), u(rng)};
      while (in_ring(centre)) centre = {u(rng), u(rng)};  // (the disc must hold domain points to add)
      std::vector<std::uint8_t> dropped(d.points.size(), 0);
      for (std::size_t i = 48 + 48; i < d.points.size(); ++i) {  // interior points only
        dropped[i] = std::hypot(d.points[i][0] - centre[0], d.points[i][1] - centre[1]) < radius && rng() % 2 == 0;
      }
      std::vector<Vec2> added;
      while (added.size() < 40) {
        const Vec2 p{centre[0] + radius * (2 * (u(rng) - 0.05) / 3.9 - 1),
                     centre[1] + radius * (2 * (u(rng) - 0.05) / 3.9 - 1)};
        if (p[0] > 0.02 && p[0] < 3.98 && p[1] > 0.02 && p[1] < 3.98 && !in_ring(p)) added.push_back(p);
      }
      check_update(d, change(d, dropped, added, {}), true, "disc");
      // On the boundary: outer point 3 dropped (pieces 2-3, 3-4 merge), a point on piece 7 -> 8.
      dropped.assign(d.points.size(), 0);
      dropped[3] = 1;
      const Vec2 split{0.5 * (d.points[7][0] + d.points[8][0]), 0.5 * (d.points[7][1] + d.points[8][1])};
      check_update(d, change(d, dropped, {{1.7, 0.4}}, {{7, split}}), true, "boundary");
      // Nothing changed: the input's triangles.
      dropped.assign(d.points.size(), 0);
      check_update(d, change(d, dropped, {}, {}), true, "unchanged");
    }
    // An exact lattice: ties decline (or, where none is met, the same triangles).
    {
      const Domain d = square_with_hole(16, 0, 0, true);
      std::vector<std::uint8_t> dropped(d.points.size(), 0);
      dropped[d.points.size() - 5] = 1;
      check_update(d, change(d, dropped, {{3.55, 3.61}}, {}), false, "lattice");
    }
    // One edge flipped: not Delaunay, declined whatever changes elsewhere.
    {
      const Domain d = square_with_hole(12, 600, 42, false);
      Mesh_arrays input = as_mesh(d);
      bool flipped = false;
      for (std::size_t t = 0; t < input.triangles.size() && !flipped; ++t) {
        for (std::size_t s = t + 1; s < input.triangles.size() && !flipped; ++s) {
          const Triangle a = input.triangles[t], b = input.triangles[s];
          for (int k = 0; k < 3 && !flipped; ++k) {
            for (int j = 0; j < 3 && !flipped; ++j) {
              if (a[k] != b[(j + 1) % 3] || a[(k + 1) % 3] != b[j]) continue;
              const Index u = a[k], v = a[(k + 1) % 3], w = a[(k + 2) % 3], z = b[(j + 2) % 3];
              if (u < 96 && v < 96) continue;  // (not a boundary piece)
              if (!(input.points[u][0] > 3.3 && input.points[u][1] < 0.7)) continue;  // (far from the change)
              if (orientation(input.points[w], input.points[u], input.points[z]) > 0 &&
                  orientation(input.points[z], input.points[v], input.points[w]) > 0) {
                input.triangles[t] = {w, u, z};
                input.triangles[s] = {z, v, w};
                flipped = true;
              }
            }
          }
        }
      }
      CHECK(flipped);
      const Old_mesh_walker walker(input);
      std::vector<std::uint8_t> dropped(d.points.size(), 0);
      const Output out = change(d, dropped, {{0.3, 3.7}}, {});
      Triangulation_update_report report;
      const auto updated = updated_constrained_delaunay(walker, out.points, out.pieces, out.origin, 1.0, report);
      CHECK(!updated.has_value());
      CHECK(report.declined == 6) << report.declined;
    }
  });
}
