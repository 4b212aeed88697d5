#include "evomesh/size_request.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <cstdint>

namespace evomesh {

namespace {

// Edge k of triangle t runs from corner k to corner k + 1; its ratio is its
// length over the request at its midpoint (h[0] when h is the same everywhere,
// else the mean of h at its ends). `ratio(dx, dy, request)` decides how the
// length is computed; the rest is one expression for every caller, so the
// exact ratios have the same bits wherever they are made.
template <class Ratio>
std::array<double, 3> edge_ratios(const std::vector<Vec2>& points, const Triangle& t, const std::vector<double>& h,
                                  bool uniform, Ratio ratio) {
  std::array<double, 3> r;
  for (int k = 0; k < 3; ++k) {
    const Index a = t[k], b = t[(k + 1) % 3];
    r[k] = ratio(points[b][0] - points[a][0], points[b][1] - points[a][1], uniform ? h[0] : 0.5 * (h[a] + h[b]));
  }
  return r;
}

// The ratio of numpy's form: np.hypot, the C library's hypot.
double exact_ratio(double dx, double dy, double request) { return std::hypot(dx, dy) / request; }

// sqrt(dx^2 + dy^2) / request, within 8 units of rounding of exact_ratio
// (hypot is within 1 ulp of |(dx, dy)|, the sum of squares and sqrt within 2.5
// units; each division rounds once); exact_ratio itself where a square or the
// ratio would leave the range where that holds (underflow, overflow, NaN).
// About 6 times cheaper than hypot.
double close_ratio(double dx, double dy, double request) {
  const double squared = dx * dx + dy * dy;
  if (squared >= 0x1p-900 && squared <= 0x1p900) {
    const double ratio = std::sqrt(squared) / request;
    if (ratio >= 0x1p-900 && ratio <= 0x1p900) return ratio;
  }
  return exact_ratio(dx, dy, request);
}

bool is_uniform(const std::vector<double>& h) {
  for (double value : h)
    if (value != h[0]) return false;
  return true;
}

// Adds to at_point[p] the two edges at each corner p (corner k lies on edges k
// and k - 1), triangles in order, corners in order (numpy's bincount order);
// counts the corners at p if `corners` is given. With `only`: the triangles
// with a corner in it, added at those corners (the same additions, in the same
// order, at every point of `only`).
template <class Ratio>
void add_edges_at_corners(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                          const std::vector<double>& h, bool uniform, Ratio ratio, std::vector<double>& at_point,
                          std::vector<std::int64_t>* corners, const std::vector<std::uint8_t>* only) {
  for (const Triangle& t : triangles) {
    if (only && !((*only)[t[0]] || (*only)[t[1]] || (*only)[t[2]])) continue;
    const std::array<double, 3> r = edge_ratios(points, t, h, uniform, ratio);
    for (int k = 0; k < 3; ++k) {
      if (only && !(*only)[t[k]]) continue;
      at_point[t[k]] += r[k] + r[(k + 2) % 3];
      if (corners) ++(*corners)[t[k]];
    }
  }
}

// Adds to around[v] the sum of at_point over the corners of each triangle at v,
// triangles in order; with `only`, at its points (whose triangles' corners
// must have their at_point).
void add_triangle_sums(const std::vector<Triangle>& triangles, const std::vector<double>& at_point,
                       std::vector<double>& around, const std::vector<std::uint8_t>* only) {
  for (const Triangle& t : triangles) {
    if (only && !((*only)[t[0]] || (*only)[t[1]] || (*only)[t[2]])) continue;
    const double sum = at_point[t[0]] + at_point[t[1]] + at_point[t[2]];
    for (Index v : t)
      if (!only || (*only)[v]) around[v] += sum;
  }
}

// Where `close` (a value within relative error `error` of x >= 0) decides x
// against `threshold`: +1 if x > threshold, -1 if x < threshold, 0 if it
// cannot tell (a margin of twice the error, and then twice again for the
// rounding of the margin's own arithmetic). NaN: 0.
int certain_side(double close, double threshold, double error) {
  const double margin = 4 * error * std::fabs(threshold);
  if (close > threshold + margin) return 1;
  if (close < threshold - margin) return -1;
  return 0;
}

std::uint8_t classes_of(double value, double above, double below, double at_least) {
  return static_cast<std::uint8_t>((value > above ? Edge_over_size_above : 0) |
                                   (value < below ? Edge_over_size_below : 0) |
                                   (value >= at_least ? Edge_over_size_at_least : 0));
}

}  // namespace

std::vector<double> edge_over_size_around(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                                          const std::vector<double>& h) {
  const std::size_t n = points.size();
  const bool uniform = is_uniform(h);
  std::vector<double> at_point(n, 0.0);
  std::vector<std::int64_t> corners(n, 0);
  add_edges_at_corners(points, triangles, h, uniform, exact_ratio, at_point, &corners, nullptr);
  for (std::size_t p = 0; p < n; ++p) at_point[p] /= static_cast<double>(2 * corners[p]);
  std::vector<double> around(n, 0.0);
  add_triangle_sums(triangles, at_point, around, nullptr);
  for (std::size_t p = 0; p < n; ++p) around[p] /= static_cast<double>(3 * corners[p]);
  return around;
}

std::vector<std::uint8_t> edge_over_size_classes(const std::vector<Vec2>& points,
                                                 const std::vector<Triangle>& triangles, const std::vector<double>& h,
                                                 double above, double below, double at_least) {
  const std::size_t n = points.size();
  const bool uniform = is_uniform(h);
  // L as edge_over_size_around computes it, with close_ratio for exact_ratio.
  std::vector<double> at_point(n, 0.0);
  std::vector<std::int64_t> corners(n, 0);
  add_edges_at_corners(points, triangles, h, uniform, close_ratio, at_point, &corners, nullptr);
  for (std::size_t p = 0; p < n; ++p) at_point[p] /= static_cast<double>(2 * corners[p]);
  std::vector<double> around(n, 0.0);
  add_triangle_sums(triangles, at_point, around, nullptr);
  for (std::size_t p = 0; p < n; ++p) around[p] /= static_cast<double>(3 * corners[p]);
  // How far that L is from the exact one, relative, with D the most corners
  // at a point: each ratio within 8 units of rounding u = 2^-53 (close_ratio),
  // a sum of two or three positive terms 2 u more per addition, a sum of k
  // positive terms (c <= D of them) within (k - 1) u in each form, each
  // division one rounding: at most (17 + 4 D) u for L. `error` is more than
  // seven times that: room for a C library whose hypot is off by a few ulp.
  const std::int64_t most_corners = n ? *std::max_element(corners.begin(), corners.end()) : 0;
  const double error = (64.0 + 16.0 * static_cast<double>(most_corners)) * 0x1p-52;
  std::vector<std::uint8_t> classes(n, 0);
  std::vector<std::uint8_t> uncertain(n, 0);
  bool any_uncertain = false;
  for (std::size_t p = 0; p < n; ++p) {
    if (corners[p] == 0) continue;  // L is NaN: no class
    const int a = certain_side(around[p], above, error), b = certain_side(around[p], below, error),
              c = certain_side(around[p], at_least, error);
    if (a == 0 || b == 0 || c == 0) {
      uncertain[p] = 1;
      any_uncertain = true;
      continue;
    }
    classes[p] = static_cast<std::uint8_t>((a > 0 ? Edge_over_size_above : 0) | (b < 0 ? Edge_over_size_below : 0) |
                                           (c > 0 ? Edge_over_size_at_least : 0));
  }
  if (!any_uncertain) return classes;
  // The exact L at the points too close to a threshold to tell (none at all
  // but where L falls within about 1e-13 of one): edge_over_size_around's
  // sums restricted to the triangles around them, with the same bits.
  std::vector<std::uint8_t> star = uncertain;
  for (const Triangle& t : triangles)
    if (uncertain[t[0]] || uncertain[t[1]] || uncertain[t[2]]) star[t[0]] = star[t[1]] = star[t[2]] = 1;
  std::fill(at_point.begin(), at_point.end(), 0.0);
  add_edges_at_corners(points, triangles, h, uniform, exact_ratio, at_point, nullptr, &star);
  for (std::size_t p = 0; p < n; ++p)
    if (star[p]) at_point[p] /= static_cast<double>(2 * corners[p]);
  std::fill(around.begin(), around.end(), 0.0);
  add_triangle_sums(triangles, at_point, around, &uncertain);
  for (std::size_t p = 0; p < n; ++p)
    if (uncertain[p]) classes[p] = classes_of(around[p] / static_cast<double>(3 * corners[p]), above, below, at_least);
  return classes;
}

std::vector<std::uint8_t> near_seeds(const std::vector<Triangle>& triangles, const std::vector<std::uint8_t>& points,
                                     const std::vector<std::uint8_t>& seeds, int rings,
                                     const std::vector<std::uint8_t>* through) {
  const std::size_t n = seeds.size();
  std::vector<std::uint8_t> near(n);
  for (std::size_t p = 0; p < n; ++p) near[p] = seeds[p] != 0;
  // Only the marked points are asked about: stop once each is reached (or
  // there is none), and when a ring reaches nothing new.
  const auto all_marked_reached = [&] {
    for (std::size_t p = 0; p < n; ++p)
      if (points[p] && !near[p]) return false;
    return true;
  };
  std::vector<std::uint8_t> reached = near;
  for (int ring = 0; ring < rings && !all_marked_reached(); ++ring) {
    bool grew = false;
    for (const Triangle& t : triangles) {
      if (!(near[t[0]] || near[t[1]] || near[t[2]])) continue;
      for (Index v : t) {
        if (reached[v] || (through != nullptr && !(*through)[v])) continue;
        reached[v] = 1;
        grew = true;
      }
    }
    if (!grew) break;
    near = reached;
  }
  for (std::size_t p = 0; p < n; ++p) near[p] = near[p] && points[p];
  return near;
}

std::vector<std::uint8_t> sharing_a_triangle(const std::vector<Triangle>& triangles,
                                             const std::vector<std::uint8_t>& marked) {
  std::vector<std::uint8_t> sharing(marked.size(), 0);
  for (const Triangle& t : triangles) {
    const bool a = marked[t[0]] != 0, b = marked[t[1]] != 0, c = marked[t[2]] != 0;
    if (a + b + c < 2) continue;
    sharing[t[0]] |= a;
    sharing[t[1]] |= b;
    sharing[t[2]] |= c;
  }
  return sharing;
}

void check_size_delta(const std::vector<double>& delta, const std::vector<double>& h, const std::vector<double>& nn,
                      double delta_min, double delta_max, std::size_t n_checked,
                      const std::vector<std::int64_t>* ids) {
  for (std::size_t p = 0; p < n_checked; ++p) {
    if (delta[p] >= delta_min && delta[p] <= delta_max) continue;
    char buffer[320];
    std::snprintf(buffer, sizeof buffer,
                  "size %g at point %lld is %g times its current spacing %g; one step changes the spacing by a "
                  "factor in [%g, %g]",
                  h[p], static_cast<long long>(ids ? (*ids)[p] : static_cast<std::int64_t>(p)), delta[p], nn[p],
                  delta_min, delta_max);
    throw Input_error(buffer);
  }
}

std::vector<double> delta_from_size(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                                    const std::vector<double>& h, const std::vector<double>& nn,
                                    bool keep_fine_clusters, double delta_min, double delta_max,
                                    std::size_t n_checked, const std::vector<std::int64_t>* ids) {
  using Rule = Size_rule;
  const std::size_t n = points.size();
  const std::vector<std::uint8_t> classes = edge_over_size_classes(
      points, triangles, h, Rule::coarse_tolerance, 1 / Rule::fine_tolerance, 1 / Rule::meets);
  std::vector<std::uint8_t> too_fine(n), meets(n);
  bool any_too_fine = false;
  for (std::size_t p = 0; p < n; ++p) {
    too_fine[p] = (classes[p] & Edge_over_size_below) != 0;
    meets[p] = (classes[p] & Edge_over_size_at_least) != 0;
    any_too_fine = any_too_fine || too_fine[p];
  }
  if (any_too_fine) {
    if (keep_fine_clusters) {
      // A too-fine pocket within the rings of points that meet the request is
      // a settled cluster, kept unless joined (through too-fine points, within
      // the rings) to a coarsening region of at least two points.
      const std::vector<std::uint8_t> pocket = near_seeds(triangles, too_fine, meets, Rule::clearance_rings);
      std::vector<std::uint8_t> open(n);
      for (std::size_t p = 0; p < n; ++p) open[p] = too_fine[p] && !pocket[p];
      const std::vector<std::uint8_t> coarsening = sharing_a_triangle(triangles, open);
      too_fine = near_seeds(triangles, too_fine, coarsening, Rule::clearance_rings, &too_fine);
    }
    // The neighbours of a coarsening point finer than 1 / meets coarsen with it.
    std::vector<std::uint8_t> not_meeting(n);
    for (std::size_t p = 0; p < n; ++p) not_meeting[p] = !meets[p];
    const std::vector<std::uint8_t> around = near_seeds(triangles, not_meeting, too_fine, 1);
    for (std::size_t p = 0; p < n; ++p) too_fine[p] = too_fine[p] || around[p];
  }
  std::vector<double> delta(n);
  for (std::size_t p = 0; p < n; ++p) {
    const double refine = h[p] / (Rule::edge_over_nn_refined * nn[p]);
    if ((classes[p] & Edge_over_size_above) && refine < Rule::refine_below) {
      delta[p] = refine;
    } else if (too_fine[p]) {
      delta[p] = std::max(1.0, h[p] / (Rule::edge_over_nn_coarsened * nn[p]));
    } else {
      delta[p] = 1.0;
    }
  }
  check_size_delta(delta, h, nn, delta_min, delta_max, n_checked, ids);
  return delta;
}

}  // namespace evomesh
