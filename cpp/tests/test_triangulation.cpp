// The domain of constrained_delaunay (a square with a square hole), and the
// corner decisions of classify_points / runs_straight_through.
#include <set>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "check.hpp"
#include "evomesh/quality_pass.hpp"
#include "evomesh/triangulation.hpp"

using namespace evomesh;

namespace {

double signed_area(const std::vector<Vec2>& p, const Triangle& t) {
  const Vec2 &a = p[t[0]], &b = p[t[1]], &c = p[t[2]];
  return 0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]));
}

// Adds the closed loop through `corners`, each side split into `per_side` pieces,
// as boundary pieces in the given order (domain on the left).
void add_loop(std::vector<Vec2>& points, std::vector<Constraint_piece>& pieces, const std::vector<Vec2>& corners,
              int per_side) {
  const Index first = static_cast<Index>(points.size());
  for (std::size_t c = 0; c < corners.size(); ++c) {
    const Vec2 &a = corners[c], &b = corners[(c + 1) % corners.size()];
    for (int k = 0; k < per_side; ++k) {
      const double t = static_cast<double>(k) / per_side;
      points.push_back({a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])});
    }
  }
  const Index count = static_cast<Index>(points.size()) - first;
  for (Index k = 0; k < count; ++k) pieces.push_back({first + k, first + (k + 1) % count, true});
}

void check_square_with_hole(int per_side, int n_interior, std::uint64_t seed) {
  std::vector<Vec2> points;
  std::vector<Constraint_piece> pieces;
  add_loop(points, pieces, {{0, 0}, {4, 0}, {4, 4}, {0, 4}}, per_side);  // outer, counter-clockwise
  add_loop(points, pieces, {{1, 1}, {1, 3}, {3, 3}, {3, 1}}, per_side);  // hole, clockwise
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.05, 3.95);
  std::size_t in_hole = 0;
  while (static_cast<int>(points.size()) < 8 * per_side + n_interior) {
    const Vec2 p{u(rng), u(rng)};
    const bool hole = p[0] > 0.95 && p[0] < 3.05 && p[1] > 0.95 && p[1] < 3.05;
    const bool ring = p[0] > 0.9 && p[0] < 3.1 && p[1] > 0.9 && p[1] < 3.1;
    if (ring && !hole) continue;  // keep clear of the hole's boundary
    in_hole += hole;              // points in the hole are triangulated, then dropped with it
    points.push_back(p);
  }
  const std::vector<Triangle> triangles = constrained_delaunay(points, pieces);
  double area = 0;
  std::size_t clockwise = 0, centroid_in_hole = 0;
  for (const auto& t : triangles) {
    const double a = signed_area(points, t);
    if (!(a > 0)) ++clockwise;
    area += a;
    const double cx = (points[t[0]][0] + points[t[1]][0] + points[t[2]][0]) / 3;
    const double cy = (points[t[0]][1] + points[t[1]][1] + points[t[2]][1]) / 3;
    if (cx > 1 && cx < 3 && cy > 1 && cy < 3) ++centroid_in_hole;
  }
  CHECK(std::abs(area - 12.0) <= 1e-12 * 12) << "area " << area << " instead of 12, per_side " << per_side;
  CHECK(clockwise == 0) << clockwise << " triangles not counter-clockwise";
  CHECK(centroid_in_hole == 0) << centroid_in_hole << " triangles in the hole";
  CHECK(!triangles.empty());
  // Every piece is an edge of the output: the triangulation is conforming.
  std::size_t missing = 0;
  for (const auto& piece : pieces) {
    bool found = false;
    for (const auto& t : triangles) {
      for (int k = 0; k < 3 && !found; ++k) found = t[k] == piece.a && t[(k + 1) % 3] == piece.b;
    }
    if (!found) ++missing;
  }
  CHECK(missing == 0) << missing << " boundary pieces are not edges with the domain on their left";
  {
    Mesh_arrays mesh;
    mesh.points = points;
    mesh.triangles = triangles;
    CHECK(orient_triangles(mesh.points, mesh.triangles) == 0);
    build_segments(mesh, {});
    std::vector<Edge> boundary;
    for (std::size_t k = 0; k < mesh.segments.size(); ++k) {
      if (mesh.segment_is_boundary[k]) boundary.push_back(mesh.segments[k]);
    }
    std::vector<Index> used(points.size(), 0);
    for (const auto& t : triangles) for (Index v : t) used[v] = 1;
    bool orphans = false;
    for (Index u : used) orphans = orphans || u == 0;
    check_planar_mesh_cdt(points, triangles);  // throws if triangles overlap
    if (!orphans) check_planar_mesh(points, triangles, boundary);
  }
  std::printf("square with hole: %zu points (%zu in the hole), %zu triangles, area %.17g\n", points.size(), in_hole,
              triangles.size(), area);
}

// The message of the std::runtime_error that constrained_delaunay throws ("" when none).
std::string domain_error(const std::vector<Vec2>& points, const std::vector<Constraint_piece>& pieces) {
  try {
    constrained_delaunay(points, pieces);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

// label_domain's two fills (domain.hpp): only the regions with an outside seed
// when every piece is an edge, every region otherwise; and its errors.
void check_domain_labels() {
  std::vector<Vec2> points;
  std::vector<Constraint_piece> pieces;
  add_loop(points, pieces, {{0, 0}, {4, 0}, {4, 4}, {0, 4}}, 8);
  add_loop(points, pieces, {{1, 1}, {1, 3}, {3, 3}, {3, 1}}, 4);
  points.push_back({2, 2});  // in the hole
  points.push_back({0.5, 3.5});
  auto area_of = [&](const std::vector<Vec2>& p, const std::vector<Triangle>& triangles) {
    double area = 0;
    for (const auto& t : triangles) area += signed_area(p, t);
    return area;
  };
  CHECK(area_of(points, constrained_delaunay(points, pieces)) == 12.0);
  // A point on the first piece splits it: that piece is no edge, every region is filled.
  {
    auto split = points;
    split.push_back({0.25, 0});
    CHECK(area_of(split, constrained_delaunay(split, pieces)) == 12.0);
  }
  // An open boundary: the outside leaks in through the missing piece.
  {
    auto open = pieces;
    open.erase(open.begin() + 3);
    const std::string message = domain_error(points, open);
    CHECK(message.find("domain boundary is not closed") != std::string::npos) << message;
  }
  // An open boundary while a point splits a piece (the fill of every region).
  {
    auto split = points;
    split.push_back({0.25, 0});
    auto open = pieces;
    open.erase(open.begin() + 3);
    const std::string message = domain_error(split, open);
    CHECK(message.find("domain boundary is not closed") != std::string::npos) << message;
  }
  // Points on every piece of the hole: no piece bounds it whole, so nothing
  // seeds it (the fill of every region says so; taking it for inside would
  // fill the hole).
  {
    std::vector<Vec2> p;
    std::vector<Constraint_piece> loops;
    add_loop(p, loops, {{0, 0}, {4, 0}, {4, 4}, {0, 4}}, 1);
    add_loop(p, loops, {{1, 1}, {1, 3}, {3, 3}, {3, 1}}, 1);
    for (Vec2 x : std::vector<Vec2>{{1, 2}, {2, 3}, {3, 2}, {2, 1}, {2, 2}}) p.push_back(x);
    const std::string message = domain_error(p, loops);
    CHECK(message.find("a region has no seed") != std::string::npos) << "'" << message << "'";
  }
  // The hole's loop turned around: its inside is seeded inside from one piece
  // and outside from the next.
  {
    auto turned = pieces;
    std::swap(turned[32].a, turned[32].b);
    const std::string message = domain_error(points, turned);
    CHECK(message.find("constrained_delaunay:") != std::string::npos) << "no error: " << message;
  }
}

// A 3 x 3 grid of the square [0, 2]^2 (points row by row), CCW triangles.
Mesh_arrays grid_mesh() {
  Mesh_arrays mesh;
  for (int y = 0; y < 3; ++y) {
    for (int x = 0; x < 3; ++x) mesh.points.push_back({static_cast<double>(x), static_cast<double>(y)});
  }
  for (int y = 0; y < 2; ++y) {
    for (int x = 0; x < 2; ++x) {
      const Index a = 3 * y + x, b = a + 1, c = a + 4, d = a + 3;
      mesh.triangles.push_back({a, b, c});
      mesh.triangles.push_back({a, c, d});
    }
  }
  return mesh;
}

void check_classification() {
  // runs_straight_through
  CHECK(runs_straight_through({0, 0}, {1, 0}, {2, 0}));
  CHECK(!runs_straight_through({0, 0}, {1, 1e-3}, {2, 0})) << "a bend";
  CHECK(!runs_straight_through({0, 0}, {1, 0}, {0.5, 0})) << "u and w on one side of p";
  CHECK(!runs_straight_through({0, 0}, {0, 0}, {2, 0})) << "p at u";
  {
    // A point placed on a segment as a + t (b - a) is off the line by rounding only.
    const Vec2 a{0.1, 0.7}, b{3.3, -1.9};
    std::size_t bent = 0;
    for (int k = 1; k < 100; ++k) {
      const double t = k / 100.0;
      if (!runs_straight_through(a, {a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])}, b)) ++bent;
    }
    CHECK(bent == 0) << bent << " points on a segment taken for corners";
    // ... but a displacement well above rounding is a corner, at any scale.
    for (const double scale : {1e-6, 1.0, 1e6}) {
      const Vec2 u{0, 0}, w{2 * scale, 0}, p{scale, 1e-9 * scale};
      CHECK(!runs_straight_through(u, p, w)) << "bend of 1e-9 relative at scale " << scale;
    }
  }

  // classify_points on a 3 x 3 grid: 4 corners, 4 side midpoints, 1 interior point.
  Mesh_arrays mesh = grid_mesh();
  build_segments(mesh, {});
  CHECK(mesh.segments.size() == 8) << mesh.segments.size() << " boundary segments";
  std::vector<Point_kind> kind = classify_points(mesh);
  const Point_kind C = Point_kind::corner, B = Point_kind::boundary, O = Point_kind::original;
  CHECK(kind == std::vector<Point_kind>({C, B, C, B, O, B, C, B, C})) << "plain square";

  // An interior constraint from the bottom midpoint (1) to the centre (4): where
  // it meets the boundary and where it ends are corners.
  mesh = grid_mesh();
  build_segments(mesh, {{0, 1}, {1, 2}, {2, 5}, {5, 8}, {8, 7}, {7, 6}, {6, 3}, {3, 0}, {1, 4}});
  kind = classify_points(mesh);
  CHECK(kind == std::vector<Point_kind>({C, C, C, B, C, B, C, B, C})) << "interior constraint";
  std::size_t n_interior = 0;
  for (auto b : mesh.segment_is_boundary) n_interior += b == 0;
  CHECK(n_interior == 1) << n_interior << " interior segments";

  // The right side's midpoint moved outwards: the boundary bends there.
  mesh = grid_mesh();
  mesh.points[5] = {2.25, 1};
  build_segments(mesh, {});
  kind = classify_points(mesh);
  CHECK(kind[5] == C) << "bent side";
  CHECK(kind[3] == B && kind[1] == B && kind[7] == B) << "straight sides";

  // A segment that is not a mesh edge throws.
  mesh = grid_mesh();
  bool threw = false;
  try {
    build_segments(mesh, {{0, 8}});
  } catch (const Input_error&) {
    threw = true;
  }
  CHECK(threw) << "segment (0, 8) is not an edge";
}

}  // namespace

// Mesh()'s planarity check (boundary winding) against the reference
// (a constrained Delaunay triangulation of every edge) on meshes that are locally
// fine everywhere but cover the plane twice, and on valid ones.
bool refused(void (*check)(const std::vector<Vec2>&, const std::vector<Triangle>&, bool), const std::vector<Vec2>& p,
             const std::vector<Triangle>& t, bool reference) {
  try {
    check(p, t, reference);
  } catch (const Input_error&) {
    return true;
  }
  return false;
}

void prepare_and_check(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles, bool reference) {
  Mesh_arrays mesh;
  mesh.points = points;
  mesh.triangles = triangles;
  orient_triangles(mesh.points, mesh.triangles);
  build_segments(mesh, {});
  if (reference) {
    check_planar_mesh_cdt(mesh.points, mesh.triangles);
    return;
  }
  std::vector<Edge> boundary;
  for (std::size_t k = 0; k < mesh.segments.size(); ++k) {
    if (mesh.segment_is_boundary[k]) boundary.push_back(mesh.segments[k]);
  }
  check_planar_mesh(mesh.points, mesh.triangles, boundary);
}

void add_square(std::vector<Vec2>& p, std::vector<Triangle>& t, double lo, double hi) {
  const Index a = static_cast<Index>(p.size());
  p.insert(p.end(), {{lo, lo}, {hi, lo}, {hi, hi}, {lo, hi}});
  t.push_back({a, a + 1, a + 2});
  t.push_back({a, a + 2, a + 3});
}

void check_planarity_cases() {
  struct Case {
    const char* name;
    std::vector<Vec2> points;
    std::vector<Triangle> triangles;
    bool planar;
  };
  std::vector<Case> cases;
  {
    // A strip going twice around the origin: every vertex and edge is fine.
    Case c{"double-cover annulus", {}, {}, false};
    const int m = 24;
    for (int ring = 0; ring < 2; ++ring) {
      for (int i = 0; i < m; ++i) {
        const double angle = 4 * M_PI * (i + 0.5) / m;
        const double r = 1.0 + ring + 0.2 * std::sin(angle / 2);
        c.points.push_back({r * std::cos(angle), r * std::sin(angle)});
      }
    }
    for (Index i = 0; i < m; ++i) {
      const Index j = (i + 1) % m;
      c.triangles.push_back({i, j, m + j});
      c.triangles.push_back({i, m + j, m + i});
    }
    cases.push_back(c);
  }
  {
    Case c{"square inside a square", {}, {}, false};
    add_square(c.points, c.triangles, 0, 3);
    add_square(c.points, c.triangles, 1, 2);
    cases.push_back(c);
  }
  {
    Case c{"two squares apart", {}, {}, true};
    add_square(c.points, c.triangles, 0, 1);
    add_square(c.points, c.triangles, 2, 3);
    cases.push_back(c);
  }
  {
    Case c{"corner on an edge from outside", {{0, 0}, {2, 0}, {1, 2}, {1, 0}, {2, -1}, {0, -1}}, {{0, 1, 2}, {3, 4, 5}},
           false};
    cases.push_back(c);
  }
  {
    Case c{"bowtie", {{0, 0}, {1, 0}, {1, 1}, {2, 1}, {2, 2}}, {{0, 1, 2}, {2, 3, 4}}, true};
    cases.push_back(c);
  }
  for (const auto& c : cases) {
    const bool by_winding = refused(prepare_and_check, c.points, c.triangles, false);
    const bool by_cdt = refused(prepare_and_check, c.points, c.triangles, true);
    CHECK(by_winding == !c.planar) << c.name << ": boundary winding check " << (by_winding ? "refused" : "accepted");
    CHECK(by_cdt == !c.planar) << c.name << ": reference check " << (by_cdt ? "refused" : "accepted");
  }
}

// The quality pass's angle rule stops below a height of 16 * 1024 units of
// rounding (delaunay_mesher.hpp, kAngleRuleFloorUlps): two points of the unit
// square `gap` apart make triangles with a tiny angle there. Above the floor
// (gap 1e-9) the pass refines them to min_angle; below it (gap 1e-12, heights of
// at most 4500 units of rounding) it leaves them, where refining would only
// cascade into the rounding of the coordinates (or to the bound on inserted
// points: what this test catches without the floor).
void check_angle_rule_floor(double gap, bool refined) {
  std::vector<Vec2> points;
  std::vector<Constraint_piece> pieces;
  add_loop(points, pieces, {{0, 0}, {1, 0}, {1, 1}, {0, 1}}, 1);
  points.push_back({0.5, 0.5});
  points.push_back({0.5 + gap, 0.5 + 0.3 * gap});
  std::vector<Point_kind> kind(points.size(), Point_kind::original);
  for (std::size_t i = 0; i < 4; ++i) kind[i] = Point_kind::corner;
  Quality_options options;
  options.min_angle = 30;
  const Refined_mesh out = quality_triangulate(points, kind, pieces, options);
  CHECK(!out.report.capped) << "gap " << gap << ": the pass ran to its bound (" << out.report.n_inserted << " points)";
  double smallest = 180;
  const auto& p = out.mesh.points;
  for (const auto& t : out.mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      const Vec2 &a = p[t[k]], &b = p[t[(k + 1) % 3]], &c = p[t[(k + 2) % 3]];
      const double u0 = b[0] - a[0], u1 = b[1] - a[1], v0 = c[0] - a[0], v1 = c[1] - a[1];
      smallest = std::min(smallest, std::atan2(std::abs(u0 * v1 - u1 * v0), u0 * v0 + u1 * v1) * 180 / 3.141592653589793);
    }
  }
  std::printf("angle rule floor, gap %g: %zu points inserted, smallest angle %.3g\n", gap, out.report.n_inserted, smallest);
  if (refined) {
    CHECK(smallest >= 29.9) << "gap " << gap << ": smallest angle " << smallest;
  } else {
    CHECK(smallest < 1) << "gap " << gap << ": refined below the floor (smallest angle " << smallest << ")";
    CHECK(out.report.n_inserted < 200) << "gap " << gap << ": " << out.report.n_inserted << " points inserted";
  }
}

// canonical_triangle_order: triangles in order, a few out of place, renumbered
// where a point moved to the end of the point order, and shuffled all give the
// reference order (each rotated to its least index, sorted), with `order` the
// input position of every output triangle.
void check_canonical_order_fast_paths() {
  std::mt19937_64 rng(7);
  const std::size_t n = 6000, m = 40000;
  std::vector<Triangle> base;
  {
    std::set<Triangle> seen;
    std::uniform_int_distribution<Index> pick(0, static_cast<Index>(n) - 1);
    while (base.size() < m) {
      Triangle t{pick(rng), pick(rng), pick(rng)};
      if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;
      if (seen.insert(least_index_first(t)).second) base.push_back(t);
    }
  }
  auto reference = [](std::vector<Triangle> t) {
    for (Triangle& x : t) x = least_index_first(x);
    std::sort(t.begin(), t.end());
    return t;
  };
  const std::vector<Triangle> sorted = reference(base);
  std::vector<std::pair<std::string, std::vector<Triangle>>> cases;
  cases.emplace_back("in order", sorted);
  for (std::size_t moved : {1, 5, 60, 400}) {
    std::vector<Triangle> t = sorted;
    for (std::size_t k = 0; k < moved; ++k) {  // move one triangle to another position
      const std::size_t from = rng() % t.size(), to = rng() % t.size();
      const Triangle x = t[from];
      t.erase(t.begin() + static_cast<std::ptrdiff_t>(from));
      t.insert(t.begin() + static_cast<std::ptrdiff_t>(to), x);
    }
    cases.emplace_back(std::to_string(moved) + " moved", t);
  }
  {  // a block of points (indices 100-179) renumbered last, as a step puts its demoted points after the others
    std::vector<Triangle> t = sorted;
    for (Triangle& x : t) {
      for (Index& v : x) v = v >= 100 && v < 180 ? static_cast<Index>(n) - 80 + (v - 100) : v >= 180 ? v - 80 : v;
    }
    cases.emplace_back("block last", t);
  }
  {  // a few triangles displaced backward and a few forward, in runs
    std::vector<Triangle> t = sorted;
    std::rotate(t.begin() + 1000, t.begin() + 1030, t.begin() + 9000);
    std::rotate(t.begin() + 20000, t.begin() + 29990, t.begin() + 30000);
    cases.emplace_back("runs displaced", t);
  }
  for (Index p : {Index{0}, Index{17}, Index{2999}}) {  // point p renumbered last, the rest shifted down
    std::vector<Triangle> t = sorted;
    for (Triangle& x : t) {
      for (Index& v : x) v = v == p ? static_cast<Index>(n) - 1 : v > p ? v - 1 : v;
    }
    cases.emplace_back("point " + std::to_string(p) + " last", t);
  }
  {
    std::vector<Triangle> t = base;
    std::shuffle(t.begin(), t.end(), rng);
    cases.emplace_back("shuffled", t);
  }
  for (const auto& [name, input] : cases) {
    std::vector<Triangle> t = input;
    const std::vector<Index> order = canonical_triangle_order(n, t);
    CHECK(t == reference(input)) << name;
    bool positions = order.size() == t.size();
    for (std::size_t k = 0; k < order.size() && positions; ++k) {
      positions = least_index_first(input[static_cast<std::size_t>(order[k])]) == t[k];
    }
    CHECK(positions) << name << ": order names the input position of each output triangle";
  }
}

int main() {
  return evomesh_test::run([] {
    check_canonical_order_fast_paths();
    check_angle_rule_floor(1e-9, true);
    check_angle_rule_floor(1e-12, false);
    check_planarity_cases();
    check_square_with_hole(1, 0, 1);
    check_square_with_hole(1, 40, 2);
    check_square_with_hole(5, 300, 3);
    check_domain_labels();
    check_classification();
  });
}
