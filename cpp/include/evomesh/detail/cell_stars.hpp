// Vertex stars and facet adjacency of a simplicial mesh (triangles or
// tetrahedra), and the visit marks of a flood fill over it: what the local
// supermeshes (supermesh.cpp in 2-D, tet_supermesh.cpp in 3-D) walk on.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "evomesh/parallel.hpp"
#include "evomesh/types.hpp"

namespace evomesh::detail {

// Vertex -> cells (its star), compressed: star[start[v] .. start[v+1]) in increasing cell order.
struct Vertex_stars {
  std::vector<Index> start;
  std::vector<Index> star;
};

template <std::size_t K>
Vertex_stars vertex_stars(std::size_t n_points, const std::vector<std::array<Index, K>>& cells) {
  Vertex_stars s;
  s.start.assign(n_points + 1, 0);
  for (const auto& c : cells)
    for (const Index v : c) ++s.start[v + 1];
  for (std::size_t v = 0; v < n_points; ++v) s.start[v + 1] += s.start[v];
  s.star.resize(K * cells.size());
  std::vector<Index> fill(s.start.begin(), s.start.end() - 1);
  for (std::size_t k = 0; k < cells.size(); ++k)
    for (const Index v : cells[k]) s.star[fill[v]++] = static_cast<Index>(k);
  return s;
}

template <std::size_t K>
bool has_vertex(const std::array<Index, K>& cell, Index v) {
  return std::find(cell.begin(), cell.end(), v) != cell.end();
}

// neighbour[K s + k]: the cell across the facet of s made of its vertices
// s[k], s[k+1], ..., s[k+K-2] (indices mod K; in 2-D the edge (s[k], s[k+1])),
// -1 on the boundary: the first other cell of the star of s[k] that has the
// facet's other vertices. Parallel over fixed blocks of cells.
template <std::size_t K>
std::vector<Index> facet_adjacency(const Vertex_stars& stars, const std::vector<std::array<Index, K>>& cells,
                                   int threads) {
  constexpr std::size_t block_size = 1024;
  const std::size_t m = cells.size();
  std::vector<Index> neighbour(K * m, -1);
  parallel_for((m + block_size - 1) / block_size, threads, [&](std::size_t block) {
    for (std::size_t s = block * block_size, end = std::min(m, s + block_size); s < end; ++s)
      for (std::size_t k = 0; k < K; ++k) {
        const Index a = cells[s][k];
        for (Index i = stars.start[a]; i < stars.start[a + 1]; ++i) {
          const Index u = stars.star[i];
          bool shares_facet = static_cast<std::size_t>(u) != s;
          for (std::size_t j = 1; shares_facet && j + 1 < K; ++j)
            shares_facet = has_vertex(cells[u], cells[s][(k + j) % K]);
          if (shares_facet) {
            neighbour[K * s + k] = u;
            break;
          }
        }
      }
  });
  return neighbour;
}

// Visited marks of cells, one array per worker thread (a generation counter
// avoids clearing it between flood fills).
struct Visit_marks {
  std::vector<std::uint32_t> stamp;
  std::uint32_t generation = 0;
  std::uint32_t next(std::size_t n) {
    if (stamp.size() != n || generation == std::numeric_limits<std::uint32_t>::max()) {
      stamp.assign(n, 0);
      generation = 0;
    }
    return ++generation;
  }
};

}  // namespace evomesh::detail
