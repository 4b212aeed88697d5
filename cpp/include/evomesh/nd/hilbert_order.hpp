// The Hilbert order of points in D dimensions on a grid over their bounding
// box: consecutive points are near each other, in O(n) (a counting sort on the
// keys). Header-only, dimension-generic; the 2-D core's orders
// (detail/spatial_order.hpp) and the 3-D step use it.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "evomesh/nd/kd_tree.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/types.hpp"

namespace evomesh::nd {

// Bits of the grid order per axis: a 2^bits cube of cells, the key in 32 bits
// (16 in 2-D, 10 in 3-D).
template <std::size_t D>
constexpr unsigned kHilbertBits = 32 / D;

// The index along the Hilbert curve of the cell with coordinates x (each below
// 2^bits; D bits <= the bits of Key) on a 2^bits grid: Skilling's transform
// ("Programming the Hilbert curve", 2004) from axes to the transposed index,
// then the bits interleaved, axis 0 most significant. In 2-D it is the usual
// xy2d (d += s^2 ((3 rx) ^ ry), then rotate the quadrant) for every bits.
template <std::size_t D, class Key = std::uint32_t>
Key hilbert_index(std::array<std::uint32_t, D> x, unsigned bits = kHilbertBits<D>) {
  static_assert(D >= 2, "a Hilbert curve in 2 or more dimensions");
  const std::uint32_t top = std::uint32_t{1} << (bits - 1);
  for (std::uint32_t q = top; q > 1; q >>= 1) {  // the reflections and exchanges, top bit first
    const std::uint32_t p = q - 1;
    for (std::size_t i = 0; i < D; ++i) {
      if (x[i] & q) {
        x[0] ^= p;
      } else {
        const std::uint32_t t = (x[0] ^ x[i]) & p;
        x[0] ^= t;
        x[i] ^= t;
      }
    }
  }
  for (std::size_t i = 1; i < D; ++i) x[i] ^= x[i - 1];  // Gray encode
  std::uint32_t t = 0;
  for (std::uint32_t q = top; q > 1; q >>= 1) {
    if (x[D - 1] & q) t ^= q - 1;
  }
  for (std::size_t i = 0; i < D; ++i) x[i] ^= t;
  Key d = 0;
  for (unsigned b = bits; b-- > 0;) {
    for (std::size_t i = 0; i < D; ++i) d = static_cast<Key>((d << 1) | ((x[i] >> b) & 1u));
  }
  return d;
}

// The permutation of the points (indices) along the Hilbert curve on a
// 2^kHilbertBits<D> grid over their bounding box (square cells: the longest
// side sets the scale), ties in input order. Keys in parallel; the indices by
// the keys' high half (a stable counting sort), then each bucket by (low half,
// index): the indices sorted by (key, index), as two stable radix passes would
// give, with 8 bytes a point instead of 12. The order never depends on
// `threads` (0: the default, parallel.hpp). Fewer than 2^32 - 1 points.
template <std::size_t D>
std::vector<std::uint32_t> hilbert_grid_permutation(const Point<D>* points, std::size_t n, int threads = 0) {
  if (n >= std::numeric_limits<std::uint32_t>::max()) throw Input_error("too many points (at most 2^32 - 2)");
  Point<D> lo, hi;
  lo.fill(std::numeric_limits<double>::infinity());
  hi.fill(-std::numeric_limits<double>::infinity());
  for (std::size_t k = 0; k < n; ++k) {
    for (std::size_t i = 0; i < D; ++i) {
      lo[i] = std::min(lo[i], points[k][i]);
      hi[i] = std::max(hi[i], points[k][i]);
    }
  }
  double extent = hi[0] - lo[0];
  for (std::size_t i = 1; i < D; ++i) extent = std::max(extent, hi[i] - lo[i]);
  constexpr double cells = static_cast<double>((std::uint32_t{1} << kHilbertBits<D>) - 1);
  const double scale = extent > 0 ? cells / extent : 0.0;
  std::vector<std::uint32_t> key, order;
  detail::parallel_resize(key, n);
  detail::parallel_resize(order, n);
  constexpr std::size_t kBlock = 1 << 16;
  parallel_for((n + kBlock - 1) / kBlock, threads, [&](std::size_t b) {
    for (std::size_t k = b * kBlock; k < std::min(n, (b + 1) * kBlock); ++k) {
      std::array<std::uint32_t, D> cell;
      for (std::size_t i = 0; i < D; ++i) {
        cell[i] = static_cast<std::uint32_t>(std::min(cells, (points[k][i] - lo[i]) * scale));
      }
      key[k] = hilbert_index<D>(cell);
    }
  });
  constexpr std::size_t kBuckets = 65536;
  std::vector<std::size_t> start(kBuckets + 1, 0);
  for (std::size_t k = 0; k < n; ++k) ++start[(key[k] >> 16) + 1];
  for (std::size_t d = 0; d < kBuckets; ++d) start[d + 1] += start[d];
  {
    std::vector<std::size_t> next(start.begin(), start.end() - 1);
    for (std::size_t k = 0; k < n; ++k) order[next[key[k] >> 16]++] = static_cast<std::uint32_t>(k);
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

}  // namespace evomesh::nd
