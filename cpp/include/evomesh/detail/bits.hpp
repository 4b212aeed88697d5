// Compiler builtins behind portable fallbacks (C++17).
#pragma once

#include <cstdint>

namespace evomesh::detail {

// Index of the lowest set bit of a non-zero mask.
inline int count_trailing_zeros(std::uint64_t mask) {
#if defined(__GNUC__) || defined(__clang__)
  return __builtin_ctzll(mask);
#else
  int k = 0;
  while (!(mask & 1u)) {
    mask >>= 1;
    ++k;
  }
  return k;
#endif
}

// A hint that `address` will be read soon; no effect where unsupported.
inline void prefetch([[maybe_unused]] const void* address) {
#if defined(__GNUC__) || defined(__clang__)
  __builtin_prefetch(address);
#endif
}

}  // namespace evomesh::detail
