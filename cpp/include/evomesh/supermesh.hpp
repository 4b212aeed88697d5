// A local supermesh of two meshes of the same domain: every pair
// (new triangle t, old triangle s) whose intersection has positive area, with
// that area and the exact mixed mass entries  int_{t n s} phi_a^new phi_b^old.
//
// No global search: the old triangles overlapping t are found by a flood fill
// over old edge adjacency, seeded with an old triangle at each vertex of t (for
// a kept vertex one incident to its old index, for a new vertex its parent
// triangle from the step's lineage). The fill crosses every old triangle whose
// bounding box overlaps t's (slightly enlarged) box, so it reaches every old
// triangle that intersects t even across zero-area contacts.
//
// Most of a step's new triangles are old ones (three kept vertices whose
// origins form an old triangle): such a triangle overlaps that old triangle
// only (the old triangles do not overlap and the kept points did not move), so
// its one pair is written directly, with |t| and the P1 element mass matrix,
// without the flood fill or the clipping.
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

struct Supermesh {
  // CSR by new triangle: pairs offsets[t] .. offsets[t+1] - 1 belong to new triangle t.
  std::vector<Index> offsets;
  std::vector<Index> old_triangle;  // per pair
  std::vector<double> area;         // per pair: |t n s| (shoelace of the clipped polygon)
  // per pair (only when mass was requested): mass[9 k + 3 a + b] =
  // int_{t n s} phi^new_{t[a]} phi^old_{s[b]} (vertex order of the input triangles).
  std::vector<double> mass;
};

// Area of the intersection of two triangles (any orientation), by
// Sutherland-Hodgman clipping of s against the three edges of t and the
// shoelace formula. Exposed for the tests.
double triangle_intersection_area(const std::array<Vec2, 3>& t, const std::array<Vec2, 3>& s);

// The supermesh of new_triangles over old_triangles. seed[v] is an old triangle
// touching new point v, or -1 when unknown; every new triangle needs at least
// one vertex with a seed (Input_error otherwise). Triangles must be
// counter-clockwise. identical (empty: none known) has one entry per new
// triangle: an old triangle with the same three points (see
// identical_old_triangles), or -1; those triangles get their one pair without
// clipping. Parallel over fixed blocks of new triangles on `threads` threads
// (0: the default); the result does not depend on the thread count.
Supermesh build_supermesh(const std::vector<Vec2>& old_points, const std::vector<Triangle>& old_triangles,
                          const std::vector<Vec2>& new_points, const std::vector<Triangle>& new_triangles,
                          const std::vector<Index>& seed, bool with_mass, int threads = 0,
                          const std::vector<Index>& identical = {});

// Per new triangle, the old triangle whose vertices are the origins of its
// three vertices (all kept: origin >= 0), or -1. The caller guarantees that
// kept points have their origin's coordinates (then the two are one triangle).
// Found in the old vertex star of the first origin: O(old triangles + new
// triangles x star size).
std::vector<Index> identical_old_triangles(std::size_t n_old_points, const std::vector<Triangle>& old_triangles,
                                           const std::vector<Triangle>& new_triangles,
                                           const std::vector<Index>& origin, int threads = 0);

// A sparse matrix in compressed rows (columns sorted within a row).
struct Csr_matrix {
  std::vector<Index> indptr;
  std::vector<Index> indices;
  std::vector<double> data;
};

// The P1 mass matrix of a triangle mesh, M[i][j] = sum over triangles T of
// |T| / 12 (1 + [i == j]) for i, j vertices of T. Each entry sums its triangles
// in increasing triangle order (deterministic, whatever the thread count).
Csr_matrix p1_mass_matrix(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles, int threads = 0);

// rhs[i][c] = sum over pairs k (of new triangle t, old triangle s) and a, b with
// new_triangles[t][a] == i of mass[9 k + 3 a + b] * values[old_triangles[s][b]][c]:
// the supermesh's mixed mass matrix times the old values (n_old x columns, row
// major), without assembling it. rhs (n_new x columns) is overwritten. The
// arrays are a Supermesh's (offsets has n_new_triangles + 1 entries); pairs are
// added in order: deterministic. Indices must be in range (the caller checks).
void mixed_mass_times(std::size_t n_new_triangles, const Index* offsets, const Index* old_triangle,
                      const double* mass, const Triangle* old_triangles, const Triangle* new_triangles,
                      const double* values, std::size_t columns, std::size_t n_new_points, double* rhs);

// Solves M u = rhs for a P1 mass matrix M (from p1_mass_matrix), each of the
// `columns` columns of rhs (n x columns, row major) on its own: conjugate
// gradients preconditioned by the diagonal, from u = rhs / diagonal, until the
// preconditioned residual is at the rounding of float64 (the diagonally scaled
// P1 mass matrix has eigenvalues in [1/2, 2] on any mesh: each element's scaled
// block has eigenvalues 1/2, 1/2, 2, so the error shrinks by about 1/3 per
// iteration); then a constant is added so that 1^T M u = 1^T rhs to rounding.
// Sums run over fixed blocks of rows added in order: the result does not depend
// on the thread count. Returns u (n x columns) and the largest iteration count.
std::vector<double> solve_p1_mass(const Csr_matrix& mass, const std::vector<double>& rhs, std::size_t columns,
                                  int threads, int* iterations = nullptr);

// seed for build_supermesh from an evolve step: origin[v] >= 0 (kept point) gives
// an old triangle incident to old point origin[v]; otherwise parent_triangle[v].
std::vector<Index> supermesh_seeds(std::size_t n_old_points, const std::vector<Triangle>& old_triangles,
                                   const std::vector<Index>& origin, const std::vector<Index>& parent_triangle);

}  // namespace evomesh
