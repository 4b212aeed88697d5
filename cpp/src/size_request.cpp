#include "evomesh/size_request.hpp"

#include <cmath>
#include <cstdint>

namespace evomesh {

std::vector<double> edge_over_size_around(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                                          const std::vector<double>& h) {
  const std::size_t n = points.size();
  bool uniform = true;
  for (double value : h) uniform = uniform && value == h[0];
  std::vector<double> at_point(n, 0.0);
  std::vector<std::int64_t> corners(n, 0);
  for (const Triangle& t : triangles) {
    double ratio[3];
    for (int k = 0; k < 3; ++k) {
      const Vec2 &a = points[t[k]], &b = points[t[(k + 1) % 3]];
      const double length = std::hypot(b[0] - a[0], b[1] - a[1]);
      ratio[k] = length / (uniform ? h[0] : 0.5 * (h[t[k]] + h[t[(k + 1) % 3]]));
    }
    // corner k lies on edges k and k - 1
    for (int k = 0; k < 3; ++k) {
      at_point[t[k]] += ratio[k] + ratio[(k + 2) % 3];
      ++corners[t[k]];
    }
  }
  for (std::size_t p = 0; p < n; ++p) at_point[p] /= static_cast<double>(2 * corners[p]);
  std::vector<double> around(n, 0.0);
  for (const Triangle& t : triangles) {
    const double sum = at_point[t[0]] + at_point[t[1]] + at_point[t[2]];
    for (Index v : t) around[v] += sum;
  }
  for (std::size_t p = 0; p < n; ++p) around[p] /= static_cast<double>(3 * corners[p]);
  return around;
}

std::vector<std::uint8_t> near_seeds(const std::vector<Triangle>& triangles, const std::vector<std::uint8_t>& points,
                                     const std::vector<std::uint8_t>& seeds, int rings) {
  std::vector<std::uint8_t> near(seeds.size());
  for (std::size_t p = 0; p < seeds.size(); ++p) near[p] = seeds[p] != 0;
  std::vector<std::uint8_t> reached = near;
  for (int ring = 0; ring < rings; ++ring) {
    for (const Triangle& t : triangles) {
      if (near[t[0]] || near[t[1]] || near[t[2]]) reached[t[0]] = reached[t[1]] = reached[t[2]] = 1;
    }
    near = reached;
  }
  for (std::size_t p = 0; p < near.size(); ++p) near[p] = near[p] && points[p];
  return near;
}

}  // namespace evomesh
