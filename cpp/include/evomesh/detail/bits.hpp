// Compiler builtins behind portable fallbacks (C++17).
#pragma once

#include <cstdint>

// Inlines a function into every caller (where the compiler supports it): for
// search loops that take their visit as a lambda over the caller's state, which
// then stays in registers (nd/kd_tree.hpp: up to 7% on queries).
#if defined(__GNUC__) || defined(__clang__)
#define EVOMESH_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define EVOMESH_ALWAYS_INLINE inline
#endif

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
