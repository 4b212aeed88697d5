// The triangulation after a Lagrangian motion (triangulate_moved): a square
// with a square region inside it (tag 1 in, tag 2 out) gets its regions from
// the pieces' sides, wherever the inner square moved; a point on a piece, a
// point outside the domain, crossing pieces and a region moved out of the
// domain are reported, not thrown.
#include <algorithm>
#include <cmath>
#include <vector>

#include "check.hpp"
#include "evomesh/motion.hpp"

using namespace evomesh;

namespace {

struct Case {
  std::vector<Vec2> points;
  std::vector<Moved_piece> pieces;
};

// Outer square [0, 4]^2 (counter-clockwise boundary, domain on the left), inner
// square [1, 2]^2 shifted by (dx, dy) as interior pieces with tag 1 on their
// left (inside, counter-clockwise) and 2 on their right, and interior points.
Case nested_squares(double dx, double dy, const std::vector<Vec2>& interior) {
  Case c;
  c.points = {{0, 0}, {4, 0}, {4, 4}, {0, 4}, {1 + dx, 1 + dy}, {2 + dx, 1 + dy}, {2 + dx, 2 + dy}, {1 + dx, 2 + dy}};
  for (Index k = 0; k < 4; ++k) c.pieces.push_back({k, (k + 1) % 4, true, 2, 0});
  for (Index k = 0; k < 4; ++k) c.pieces.push_back({4 + k, 4 + (k + 1) % 4, false, 1, 2});
  c.points.insert(c.points.end(), interior.begin(), interior.end());
  return c;
}

double area(const std::vector<Vec2>& p, const Triangle& t) {
  return 0.5 * ((p[t[1]][0] - p[t[0]][0]) * (p[t[2]][1] - p[t[0]][1]) -
                (p[t[1]][1] - p[t[0]][1]) * (p[t[2]][0] - p[t[0]][0]));
}

void regions_follow_the_moved_interface() {
  for (const double dx : {0.0, 1.5}) {
    const Case c = nested_squares(dx, 0.3, {{0.5, 3.5}, {3.5, 0.5}, {1.5 + dx, 1.8}});
    const Moved_triangulation t = triangulate_moved(c.points, c.pieces);
    CHECK(t.crossing < 0 && t.conflict < 0 && t.unused.empty() && t.on_piece.empty());
    double inside = 0, outside = 0;
    for (std::size_t k = 0; k < t.triangles.size(); ++k) {
      const double a = area(c.points, t.triangles[k]);
      CHECK(a > 0) << "triangle " << k << " is not counter-clockwise";
      (t.triangle_tags[k] == 1 ? inside : outside) += a;
      CHECK(t.triangle_tags[k] == 1 || t.triangle_tags[k] == 2) << t.triangle_tags[k];
    }
    CHECK(std::abs(inside - 1.0) < 1e-14) << inside;
    CHECK(std::abs(outside - 15.0) < 1e-13) << outside;
  }
}

void problems_are_reported() {
  {  // an interior point exactly on the interface's bottom piece (y = 1.3)
    const Case c = nested_squares(0.0, 0.3, {{1.25, 1.3}});
    const Moved_triangulation t = triangulate_moved(c.points, c.pieces);
    CHECK(t.on_piece.size() == 1 && t.on_piece[0][0] == 8 && t.on_piece[0][1] == 4);
  }
  {  // an interior point outside the outer square
    const Case c = nested_squares(0.0, 0.0, {{5.0, 1.0}});
    const Moved_triangulation t = triangulate_moved(c.points, c.pieces);
    CHECK(t.unused.size() == 1 && t.unused[0] == 8);
    CHECK(t.crossing < 0 && t.conflict < 0);
  }
  {  // the inner square pushed through the outer boundary: pieces cross
    const Case c = nested_squares(2.5, 0.0, {});
    const Moved_triangulation t = triangulate_moved(c.points, c.pieces);
    CHECK(t.crossing >= 0);
  }
  {  // the inner square moved wholly outside: its sides meet the outside
    const Case c = nested_squares(4.0, 0.0, {});
    const Moved_triangulation t = triangulate_moved(c.points, c.pieces);
    CHECK(t.crossing < 0 && t.conflict >= 4) << t.conflict;
  }
  {  // duplicate points are an input error (the caller removes them)
    Case c = nested_squares(0.0, 0.0, {{0.5, 0.5}, {0.5, 0.5}});
    bool thrown = false;
    try {
      triangulate_moved(c.points, c.pieces);
    } catch (const Input_error&) {
      thrown = true;
    }
    CHECK(thrown);
  }
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    regions_follow_the_moved_interface();
    problems_are_reported();
  });
}
