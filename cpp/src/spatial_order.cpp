#include "evomesh/detail/spatial_order.hpp"

#include <CGAL/algorithm.h>
#include <boost/random/linear_congruential.hpp>
#include <boost/random/random_number_generator.hpp>

#include <algorithm>
#include <cstdint>
#include <limits>

#include "evomesh/nd/hilbert_order.hpp"
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

std::vector<Ordered_point> hilbert_grid_order(const Vec2* points, std::size_t n, int threads) {
  const std::vector<std::uint32_t> order = nd::hilbert_grid_permutation<2>(points, n, threads);
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
