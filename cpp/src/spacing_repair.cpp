#include "evomesh/spacing_repair.hpp"

#include <algorithm>
#include <array>

#include <CGAL/Delaunay_triangulation_2.h>

#include "evomesh/detail/point_tree.hpp"
#include "evomesh/kernel.hpp"

namespace evomesh {

std::vector<Vec2> repair_spacing(const Spacing_repair_input& input, const Frfc_options& options,
                                 std::vector<std::uint8_t>& kept, std::size_t& n_added) {
  using Delaunay = CGAL::Delaunay_triangulation_2<Kernel>;
  const Mesh_arrays& mesh = input.mesh;
  const std::vector<double>& delta = input.delta;
  const std::vector<double>& nn = input.nn;
  const std::vector<Vec2>& centers = input.centers;
  const double repair_ratio = options.repair_ratio;
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
  const std::vector<double> nn2 = tree.squared_nn(options.threads);
  std::vector<Index> needy;
  std::vector<std::uint8_t> is_needy(n, 0);
  for (std::size_t p = 0; p < n; ++p) {
    if (position_of[p] < 0 || !(delta[p] < 1)) continue;
    const double target = repair_ratio * delta[p] * nn[p];
    if (nn2[position_of[p]] > target * target) {
      is_needy[p] = 1;
      needy.push_back(static_cast<Index>(p));
    }
  }
  std::vector<Vec2> added;
  if (needy.empty()) return added;
  std::vector<std::vector<Index>> on_segments(n);  // segment ring candidates (centre indices) of needy points
  const std::vector<Index>& owner = input.segment_owner;
  for (std::size_t j = 0; j < owner.size(); ++j) {
    if (owner[j] >= 0 && is_needy[owner[j]]) on_segments[owner[j]].push_back(static_cast<Index>(n + j));
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
  const double reach = ring_reach(options.radius_scale);
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
    const int count =
        ring_candidates_of(mesh, input.fans, input.f, reach, options.seed, static_cast<std::size_t>(p), ring);
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
  return added;
}

}  // namespace evomesh
