// Sweeps over every face (or vertex) of a CGAL triangulation in parallel, in
// the triangulation's own iteration order. Internal: included by cpp/src only.
//
// A triangulation keeps its faces and vertices in CGAL Compact_containers:
// blocks of slots, some free. Compact_container numbers its slots (index i in
// [0, capacity()), is_used(i), operator[](i): its public interface) in
// iteration order, so fixed chunks of slot numbers can be swept in parallel and
// their results joined in chunk order: the same elements in the same order as
// the iterator gives, for any thread count. A pass over the faces can so keep
// per-chunk results (the bad faces, each chunk's range of triangles) instead
// of first gathering every face into a fresh array: on a 1e7-point quality
// pass that gathering took 0.85 s, mostly first touches of fresh pages,
// against 0.13 s for a sweep. (A sweep itself is memory-bound: a second thread
// does not make it much faster.)
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

#include "evomesh/parallel.hpp"

namespace evomesh::detail {

constexpr std::size_t kSweepChunk = std::size_t{1} << 15;

// The number of chunks parallel_sweep splits `items` into.
template <class Items>
std::size_t sweep_chunks(const Items& items) {
  return (items.capacity() + kSweepChunk - 1) / kSweepChunk;
}

// Calls body(chunk, handle) for every element of the Compact_container `items`
// (a triangulation's tds().faces() or tds().vertices()): chunks of slots in
// parallel (on up to `threads` threads, 0: parallel_for's default), each in
// iteration order. body must be safe to run on several elements at once.
template <class Items, class Body>
void parallel_sweep(Items& items, Body body, int threads = 0) {
  const std::size_t n = items.capacity();
  parallel_for(sweep_chunks(items), threads, [&](std::size_t c) {
    const std::size_t end = std::min(n, (c + 1) * kSweepChunk);
    for (std::size_t i = c * kSweepChunk; i < end; ++i) {
      if (items.is_used(i)) body(c, items.iterator_to(items[i]));
    }
  });
}

// Per-chunk lists joined in chunk order (each freed once copied).
template <class T>
std::vector<T> joined(std::vector<std::vector<T>>& parts) {
  std::vector<std::size_t> offset(parts.size() + 1, 0);
  for (std::size_t c = 0; c < parts.size(); ++c) offset[c + 1] = offset[c] + parts[c].size();
  std::vector<T> all(offset.back());
  parallel_for(parts.size(), 0, [&](std::size_t c) {
    std::copy(parts[c].begin(), parts[c].end(), all.begin() + static_cast<std::ptrdiff_t>(offset[c]));
    parts[c] = std::vector<T>();
  });
  return all;
}

// The handles of the elements for which keep(handle) holds, in iteration order.
template <class Items, class Keep>
std::vector<typename Items::iterator> parallel_gather(Items& items, Keep keep) {
  using Handle = typename Items::iterator;
  std::vector<std::vector<Handle>> in_chunk(sweep_chunks(items));
  parallel_sweep(items, [&](std::size_t c, Handle h) {
    if (keep(h)) in_chunk[c].push_back(h);
  });
  return joined(in_chunk);
}

}  // namespace evomesh::detail
