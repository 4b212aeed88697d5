#include "evomesh/detail/spatial_order.hpp"

#include <CGAL/algorithm.h>
#include <boost/random/linear_congruential.hpp>
#include <boost/random/random_number_generator.hpp>

#include <algorithm>
#include <cstdint>
#include <limits>

#include "evomesh/parallel.hpp"

namespace evomesh::detail {

namespace {

// CGAL's Hilbert_sort_median_2 on Ordered_point records: the same recursive
// median splits with the same comparisons, so the same permutation. `limit`:
// ranges of at most this many points stay as they are (CGAL's limit: 1 for
// hilbert_sort, 4 within spatial_sort).
template <int axis, bool up>
bool hilbert_less(const Ordered_point& p, const Ordered_point& q) {
  const double a = axis == 0 ? p.x : p.y;
  const double b = axis == 0 ? q.x : q.y;
  return up ? b < a : a < b;
}

template <int axis, bool up>
Ordered_point* hilbert_split(Ordered_point* begin, Ordered_point* end) {
  if (begin >= end) return begin;
  Ordered_point* middle = begin + (end - begin) / 2;
  std::nth_element(begin, middle, end, hilbert_less<axis, up>);
  return middle;
}

using Hilbert_sort_fn = void (*)(Ordered_point*, Ordered_point*, std::ptrdiff_t);
struct Hilbert_task {
  Ordered_point* begin;
  Ordered_point* end;
  Hilbert_sort_fn sort;
};

// Sorts [begin, end); with `tasks`, splits only `levels` levels and leaves the
// subranges below as tasks.
template <int x, bool upx, bool upy>
void hilbert_sort_range(Ordered_point* begin, Ordered_point* end, std::ptrdiff_t limit, int levels = -1,
                        std::vector<Hilbert_task>* tasks = nullptr) {
  constexpr int y = (x + 1) % 2;
  if (end - begin <= limit) return;
  if (tasks != nullptr && levels == 0) {
    tasks->push_back({begin, end, [](Ordered_point* b, Ordered_point* e, std::ptrdiff_t l) {
                        hilbert_sort_range<x, upx, upy>(b, e, l);
                      }});
    return;
  }
  Ordered_point* m2 = hilbert_split<x, upx>(begin, end);
  Ordered_point* m1 = hilbert_split<y, upy>(begin, m2);
  Ordered_point* m3 = hilbert_split<y, !upy>(m2, end);
  hilbert_sort_range<y, upy, upx>(begin, m1, limit, levels - 1, tasks);
  hilbert_sort_range<x, upx, upy>(m1, m2, limit, levels - 1, tasks);
  hilbert_sort_range<x, upx, upy>(m2, m3, limit, levels - 1, tasks);
  hilbert_sort_range<y, !upy, !upx>(m3, end, limit, levels - 1, tasks);
}

// Hilbert_sort_median_2 on [begin, end); large ranges split two levels, then the
// 16 subranges are sorted in parallel (which does not change the result).
void hilbert_sort(Ordered_point* begin, Ordered_point* end, std::ptrdiff_t limit, int threads) {
  if (end - begin < 65536) {
    hilbert_sort_range<0, false, false>(begin, end, limit);
    return;
  }
  std::vector<Hilbert_task> tasks;
  hilbert_sort_range<0, false, false>(begin, end, limit, 2, &tasks);
  parallel_for(tasks.size(), threads, [&](std::size_t k) { tasks[k].sort(tasks[k].begin, tasks[k].end, limit); });
}

// CGAL's random shuffle in hilbert_sort and spatial_sort (boost::rand48, its
// default seed).
void cgal_shuffle(std::vector<Ordered_point>& points) {
  boost::rand48 random;
  boost::random_number_generator<boost::rand48, std::ptrdiff_t> rng(random);
  CGAL::cpp98::random_shuffle(points.begin(), points.end(), rng);
}

// CGAL's Multiscale_sort as spatial_sort sets it up for 2-D points: the first
// quarter ordered first, recursively, from 16 points up; then the rest by the
// Hilbert sort with limit 4.
void multiscale_sort(Ordered_point* begin, Ordered_point* end, int threads) {
  Ordered_point* middle = begin;
  if (end - begin >= 16) {
    middle = begin + static_cast<std::ptrdiff_t>(static_cast<double>(end - begin) * 0.25);
    multiscale_sort(begin, middle, threads);
  }
  hilbert_sort(middle, end, 4, threads);
}

// Index of the cell (x, y) of a 2^16 x 2^16 grid along the Hilbert curve.
std::uint32_t hilbert_index(std::uint32_t x, std::uint32_t y) {
  std::uint32_t d = 0;
  for (std::uint32_t s = 1u << 15; s > 0; s >>= 1) {
    const std::uint32_t rx = (x & s) > 0, ry = (y & s) > 0;
    d += s * s * ((3 * rx) ^ ry);
    if (ry == 0) {  // rotate the quadrant
      if (rx == 1) {
        x = s - 1 - x;
        y = s - 1 - y;
      }
      std::swap(x, y);
    }
  }
  return d;
}

}  // namespace

// Keys in parallel; the indices by the keys' high half (a stable counting
// sort), then each bucket by (low half, index): the indices sorted by (key,
// index), as two stable radix passes would give, with 8 bytes a point instead
// of 12 (the sample radii sort all candidates: that was the stage's peak).
std::vector<std::uint32_t> hilbert_grid_permutation(const Vec2* points, std::size_t n, int threads) {
  if (n >= std::numeric_limits<std::uint32_t>::max()) throw Input_error("too many points (at most 2^32 - 2)");
  double lo_x = std::numeric_limits<double>::infinity(), lo_y = lo_x, hi_x = -lo_x, hi_y = -lo_x;
  for (std::size_t i = 0; i < n; ++i) {
    lo_x = std::min(lo_x, points[i][0]);
    lo_y = std::min(lo_y, points[i][1]);
    hi_x = std::max(hi_x, points[i][0]);
    hi_y = std::max(hi_y, points[i][1]);
  }
  const double extent = std::max(hi_x - lo_x, hi_y - lo_y);
  const double scale = extent > 0 ? 65535.0 / extent : 0.0;
  std::vector<std::uint32_t> key, order;
  parallel_resize(key, n);
  parallel_resize(order, n);
  constexpr std::size_t kBlock = 1 << 16;
  parallel_for((n + kBlock - 1) / kBlock, threads, [&](std::size_t b) {
    for (std::size_t i = b * kBlock; i < std::min(n, (b + 1) * kBlock); ++i) {
      const auto qx = static_cast<std::uint32_t>(std::min(65535.0, (points[i][0] - lo_x) * scale));
      const auto qy = static_cast<std::uint32_t>(std::min(65535.0, (points[i][1] - lo_y) * scale));
      key[i] = hilbert_index(qx, qy);
    }
  });
  constexpr std::size_t kBuckets = 65536;
  std::vector<std::size_t> start(kBuckets + 1, 0);
  for (std::size_t i = 0; i < n; ++i) ++start[(key[i] >> 16) + 1];
  for (std::size_t d = 0; d < kBuckets; ++d) start[d + 1] += start[d];
  {
    std::vector<std::size_t> next(start.begin(), start.end() - 1);
    for (std::size_t i = 0; i < n; ++i) order[next[key[i] >> 16]++] = static_cast<std::uint32_t>(i);
  }
  constexpr std::size_t kBucketChunk = 256;
  parallel_for(kBuckets / kBucketChunk, threads, [&](std::size_t c) {
    for (std::size_t d = c * kBucketChunk; d < (c + 1) * kBucketChunk; ++d) {
      std::sort(order.begin() + static_cast<std::ptrdiff_t>(start[d]),
                order.begin() + static_cast<std::ptrdiff_t>(start[d + 1]), [&](std::uint32_t u, std::uint32_t v) {
                  const std::uint32_t ku = key[u] & 0xffff, kv = key[v] & 0xffff;
                  return ku < kv || (ku == kv && u < v);
                });
    }
  });
  return order;
}

namespace {

std::vector<Ordered_point> hilbert_grid_order(const Vec2* points, std::size_t n, int threads) {
  const std::vector<std::uint32_t> order = hilbert_grid_permutation(points, n, threads);
  std::vector<Ordered_point> sorted(n);
  constexpr std::size_t kBlock = 1 << 16;
  parallel_for((n + kBlock - 1) / kBlock, threads, [&](std::size_t b) {
    for (std::size_t k = b * kBlock; k < std::min(n, (b + 1) * kBlock); ++k) {
      sorted[k] = {points[order[k]][0], points[order[k]][1], order[k]};
    }
  });
  return sorted;
}

}  // namespace

std::vector<Ordered_point> spatial_order(const Vec2* points, std::size_t n, Spatial_order how, int threads) {
  if (how == Spatial_order::hilbert_grid) return hilbert_grid_order(points, n, threads);
  std::vector<Ordered_point> sorted(n);
  for (std::size_t i = 0; i < n; ++i) sorted[i] = {points[i][0], points[i][1], i};
  cgal_shuffle(sorted);
  Ordered_point* begin = sorted.data();
  Ordered_point* end = begin + n;
  if (how == Spatial_order::hilbert) hilbert_sort(begin, end, 1, threads);
  else multiscale_sort(begin, end, threads);
  return sorted;
}

}  // namespace evomesh::detail
