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

// Number of set bits.
inline int popcount(std::uint64_t mask) {
#if defined(__GNUC__) || defined(__clang__)
  return __builtin_popcountll(mask);
#else
  int k = 0;
  for (; mask; mask &= mask - 1) ++k;
  return k;
#endif
}

// SplitMix64's finaliser: the mixing behind every counter-based random stream
// (the same number for the same key, whatever the thread or the order of draws).
inline std::uint64_t mix(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

}  // namespace evomesh::detail
