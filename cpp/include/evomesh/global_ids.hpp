// Global ids of a step's input (Mesh_arrays::point_gids, triangle_gids,
// segment_keys; docs/distributed-step.md section 2.2): the orders the
// step visits them in.
#pragma once

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <string>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

// The positions 0 .. ids.size() - 1 sorted by id (ids distinct). Empty when
// that is the identity (no ids, or increasing ones): visit() reads it so.
inline std::vector<Index> order_by_ids(const std::vector<std::int64_t>& ids) {
  std::vector<Index> order;
  if (std::is_sorted(ids.begin(), ids.end())) return order;
  order.resize(ids.size());
  std::iota(order.begin(), order.end(), Index{0});
  std::sort(order.begin(), order.end(), [&](Index a, Index b) { return ids[a] < ids[b]; });
  return order;
}

// The r-th position in `order` (order_by_ids), the identity when it is empty.
inline std::size_t visit(const std::vector<Index>& order, std::size_t r) {
  return order.empty() ? r : static_cast<std::size_t>(order[r]);
}

// Ids lie in [0, kMaxGlobalId): the random streams keyed by them (triangles
// at the id, segments at 2^62 + key, repairs at 5 * 2^60 + id, rings at
// 3 * 2^61 + id) then never share one.
constexpr std::int64_t kMaxGlobalId = std::int64_t{1} << 60;

// Throws Input_error unless `ids` is empty or has `n` distinct values in
// [0, kMaxGlobalId) (`what`: "point_gids", ...).
inline void check_global_ids(const std::vector<std::int64_t>& ids, std::size_t n, const char* what) {
  if (ids.empty()) return;
  if (ids.size() != n) {
    throw Input_error(std::string(what) + ": one id per entry is required (" + std::to_string(ids.size()) +
                      " for " + std::to_string(n) + ")");
  }
  for (std::int64_t id : ids) {
    if (id < 0 || id >= kMaxGlobalId) throw Input_error(std::string(what) + ": ids must lie in [0, 2^60)");
  }
  std::vector<std::int64_t> sorted = ids;
  std::sort(sorted.begin(), sorted.end());
  if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) {
    throw Input_error(std::string(what) + ": ids must be distinct");
  }
}

}  // namespace evomesh
