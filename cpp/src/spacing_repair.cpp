#include "evomesh/spacing_repair.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include <CGAL/Delaunay_triangulation_2.h>

#include "evomesh/detail/point_tree.hpp"
#include "evomesh/kernel.hpp"
#include "evomesh/sampling.hpp"
#include "evomesh/triangulation.hpp"

namespace evomesh {

namespace {

// Kept points with delta >= 1 (issue 11): the packing leaves gaps of up to about
// 2 radius_scale f between kept spheres, so a kept point p can end up with no
// kept point within 1.4 h(p), h = delta nn_M. One with none within
// gap_ratio h(p) gets, of six points at distance h(p) from it (seeded phase)
// that lie strictly inside a triangle of the old mesh, the one farthest from
// every kept point, if that is at least kCoarseClearance h(p) away.
constexpr double kCoarseClearance = 0.6;

template <class Nearest2, class Delaunay>
void repair_coarse_points(const Mesh_arrays& mesh, const std::vector<double>& delta, const std::vector<double>& nn,
                          double gap_ratio, std::uint64_t seed, const std::vector<Index>& position_of, const std::vector<double>& nn2,
                          Nearest2& nearest2, Delaunay& added_dt, std::vector<Vec2>& added, std::size_t& n_added,
                          const Spacing_repair_input& input) {
  constexpr int kDirections = 6;
  constexpr double kTwoPi = 6.283185307179586;
  std::vector<Index> coarse;
  if (!(gap_ratio > 0)) return;
  for (std::size_t p = 0; p < position_of.size(); ++p) {
    if (position_of[p] < 0 || !(delta[p] >= 1)) continue;
    const double target = gap_ratio * delta[p] * nn[p];
    if (nn2[position_of[p]] > target * target) coarse.push_back(static_cast<Index>(p));
  }
  if (coarse.empty()) return;
  std::vector<Vec2> queries;
  queries.reserve(kDirections * coarse.size());
  for (Index p : coarse) {
    const double h = delta[p] * nn[p];
    Random_stream rng(seed, (std::uint64_t{5} << 60) + static_cast<std::uint64_t>(p));
    const double phase = rng.uniform() * kTwoPi / kDirections;
    for (int k = 0; k < kDirections; ++k) {
      const double angle = phase + kTwoPi * k / kDirections;
      queries.push_back({mesh.points[p][0] + h * std::cos(angle), mesh.points[p][1] + h * std::sin(angle)});
    }
  }
  std::vector<Index> triangle;
  std::vector<std::array<double, 3>> barycentric;
  if (input.locate) (*input.locate)(queries, triangle, barycentric);
  else locate_points(mesh.points, mesh.triangles, queries, triangle, barycentric);
  for (std::size_t i = 0; i < coarse.size(); ++i) {
    const Index p = coarse[i];
    const double h = delta[p] * nn[p];
    const double target = gap_ratio * h;
    double d2 = nn2[position_of[p]];
    if (added_dt.number_of_vertices() > 0) {
      const Point_2 q = to_cgal(mesh.points[p]);
      d2 = std::min(d2, CGAL::squared_distance(q, added_dt.nearest_vertex(q)->point()));
    }
    if (d2 <= target * target) continue;  // an earlier repair served p
    double best_d2 = kCoarseClearance * kCoarseClearance * h * h;
    int best = -1;
    for (int k = 0; k < kDirections; ++k) {
      const std::size_t j = kDirections * i + k;
      if (triangle[j] < 0) continue;
      // strictly inside its triangle (not on an edge: a segment, or a crack)
      if (!(barycentric[j][0] > 1e-9 && barycentric[j][1] > 1e-9 && barycentric[j][2] > 1e-9)) continue;
      const double e2 = nearest2(queries[j]);
      if (e2 >= best_d2) {
        best_d2 = e2;
        best = k;
      }
    }
    if (best < 0) continue;
    const Vec2& x = queries[kDirections * i + best];
    added.push_back(x);
    added_dt.insert(to_cgal(x));
    ++n_added;
  }
}

}  // namespace

std::vector<Vec2> repair_spacing(const Spacing_repair_input& input, const Frfc_options& options,
                                 std::vector<std::uint8_t>& kept, std::size_t& n_added) {
  const Mesh_arrays& mesh = input.mesh;
  const Triangle_fans& fans = input.fans;
  const std::vector<double>& delta = input.delta;
  const std::vector<double>& nn = input.nn;
  const std::vector<double>& f = input.f;
  const std::vector<Vec2>& centers = input.centers;
  const std::vector<Index>& segment_owner = input.segment_owner;
  const double reach = ring_reach(options.radius_scale);
  const std::uint64_t seed = options.seed;
  const double repair_ratio = options.ring_samples ? options.repair_ratio : 0.0;
  const double gap_repair_ratio = options.gap_repair_ratio;
  const int threads = options.threads;
  using Delaunay = CGAL::Delaunay_triangulation_2<Kernel>;
  const std::size_t n = mesh.points.size();
  n_added = 0;
  std::vector<Vec2> kept_points;
  std::vector<Index> position_of(n, -1);
  for (std::size_t c = 0; c < centers.size(); ++c) {
    if (!kept[c]) continue;
    if (c < n) position_of[c] = static_cast<Index>(kept_points.size());
    kept_points.push_back(centers[c]);
  }
  if (kept_points.size() < 2) return {};
  const detail::Point_tree tree(kept_points);
  const std::vector<double> nn2 = tree.squared_nn(threads);
  std::vector<Index> needy;
  std::vector<std::uint8_t> is_needy(n, 0);
  for (std::size_t p = 0; p < n; ++p) {
    if (!(repair_ratio > 0) || position_of[p] < 0 || !(delta[p] < 1)) continue;
    const double target = repair_ratio * delta[p] * nn[p];
    if (nn2[position_of[p]] > target * target) {
      is_needy[p] = 1;
      needy.push_back(static_cast<Index>(p));
    }
  }
  std::vector<Vec2> added;
  std::vector<std::vector<Index>> on_segments(n);  // segment ring candidates (centre indices) of needy points
  for (std::size_t j = 0; j < segment_owner.size(); ++j) {
    if (segment_owner[j] >= 0 && is_needy[segment_owner[j]]) on_segments[segment_owner[j]].push_back(static_cast<Index>(n + j));
  }
  Delaunay added_dt;  // every point added here (segment or interior)
  Delaunay::Vertex_handle hint;
  auto nearest2 = [&](const Vec2& x) {
    double best = tree.squared_nearest(x);
    if (added_dt.number_of_vertices() > 0) {
      const Point_2 q = to_cgal(x);
      hint = added_dt.nearest_vertex(q, hint == Delaunay::Vertex_handle() ? Delaunay::Face_handle() : hint->face());
      best = std::min(best, CGAL::squared_distance(q, hint->point()));
    }
    return best;
  };
  std::array<Ring_candidate, kRingDirections> ring;
  for (Index p : needy) {
    // re-check: an earlier repair may have served p
    const double target = repair_ratio * delta[p] * nn[p];
    double d2 = nn2[position_of[p]];
    if (added_dt.number_of_vertices() > 0) {
      const Point_2 q = to_cgal(mesh.points[p]);
      d2 = std::min(d2, CGAL::squared_distance(q, added_dt.nearest_vertex(q)->point()));
    }
    if (d2 <= target * target) continue;
    Index best_segment = -1;
    Vec2 best_point{0.0, 0.0};
    bool found = false;
    double best_d2 = 0;
    for (Index c : on_segments[p]) {
      const double e2 = nearest2(centers[c]);
      if (e2 > best_d2) {
        best_d2 = e2;
        best_segment = c;
        best_point = centers[c];
        found = true;
      }
    }
    const int count = ring_candidates_of(mesh, fans, f, reach, seed, static_cast<std::size_t>(p), ring);
    for (int k = 0; k < count; ++k) {
      const Vec2& x = ring[k].x;
      const double e2 = nearest2(x);
      if (e2 > best_d2) {
        best_d2 = e2;
        best_segment = -1;
        best_point = x;
        found = true;
      }
    }
    if (!found) continue;
    if (best_segment >= 0) kept[best_segment] = 1;
    else added.push_back(best_point);
    added_dt.insert(to_cgal(best_point));
    ++n_added;
  }
  repair_coarse_points(mesh, delta, nn, gap_repair_ratio, seed, position_of, nn2, nearest2, added_dt, added, n_added, input);
  return added;
}

}  // namespace evomesh
