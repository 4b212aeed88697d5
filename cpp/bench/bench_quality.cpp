// The quality pass alone (quality_triangulate: constrained Delaunay, Ruppert's
// refinement with off-centres to min_angle 30, extraction), wall time: on a
// triangular lattice of about N points in the unit square whose points are moved
// by up to jitter/2 of the spacing (0.9: a bad triangle in every few, the pass
// inserts up to its cap of n/2), or on N uniform random points (jitter < 0); the
// square's sides are boundary pieces.
//
//   bench_quality [N = 1e6] [jitter = 0.3] [repeats = 3]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "evomesh/quality_pass.hpp"

using namespace evomesh;

int main(int argc, char** argv) {
  const double n_target = argc > 1 ? std::stod(argv[1]) : 1e6;
  const double jitter = argc > 2 ? std::stod(argv[2]) : 0.3;  // < 0: uniform random
  const int repeats = std::max(1, argc > 3 ? std::stoi(argv[3]) : 3);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Vec2> pts;
  std::vector<Point_kind> kind;
  std::vector<Constraint_piece> pieces;
  const double h = std::sqrt(2.0 / (std::sqrt(3.0) * n_target));
  const int m = static_cast<int>(std::ceil(1.0 / h));
  // boundary: m pieces a side, counter-clockwise
  for (int side = 0; side < 4; ++side) {
    for (int k = 0; k < m; ++k) {
      const double t = static_cast<double>(k) / m;
      Vec2 p = side == 0 ? Vec2{t, 0} : side == 1 ? Vec2{1, t} : side == 2 ? Vec2{1 - t, 1} : Vec2{0, 1 - t};
      pts.push_back(p);
      kind.push_back(k == 0 ? Point_kind::corner : Point_kind::boundary);
    }
  }
  const Index nb = static_cast<Index>(pts.size());
  for (Index i = 0; i < nb; ++i) pieces.push_back({i, (i + 1) % nb, true});
  if (jitter < 0) {
    for (std::size_t i = 0; i < static_cast<std::size_t>(n_target); ++i) {
      pts.push_back({h + (1 - 2 * h) * u(rng), h + (1 - 2 * h) * u(rng)});
      kind.push_back(Point_kind::sampled);
    }
  } else {
    const double dy = h * std::sqrt(3.0) / 2;
    for (int r = 1; r * dy < 1 - 0.7 * h; ++r) {
      for (int c = 1; (c + 0.5 * (r % 2)) * h < 1 - 0.7 * h; ++c) {
        const double x = (c + 0.5 * (r % 2)) * h + jitter * h * (u(rng) - 0.5);
        const double y = r * dy + jitter * h * (u(rng) - 0.5);
        pts.push_back({x, y});
        kind.push_back(Point_kind::sampled);
      }
    }
  }
  Quality_options options;
  options.min_angle = 30;
  std::vector<double> times;
  std::size_t inserted = 0, n_out = 0, tri = 0;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    const Refined_mesh out = quality_triangulate(pts, kind, pieces, options);
    times.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    inserted = out.report.n_inserted;
    n_out = out.mesh.points.size();
    tri = out.mesh.triangles.size();
  }
  std::sort(times.begin(), times.end());
  std::printf("points %zu inserted %zu out %zu triangles %zu seconds median %.3f min %.3f\n", pts.size(), inserted, n_out, tri,
              times[times.size() / 2], times[0]);
}
