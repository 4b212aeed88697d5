// Domain labelling of a constrained triangulation, shared by constrained_delaunay
// and the quality pass. Internal: included by cpp/src only.
#pragma once

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "evomesh/detail/parallel_sweep.hpp"
#include "evomesh/triangulation.hpp"

namespace evomesh::detail {

enum Domain_label : int { domain_unknown = 0, domain_inside = 1, domain_outside = 2 };

// Sets face->info() to domain_inside / domain_outside for every face of `cdt`:
// infinite faces are outside, the left side of a boundary piece inside and its
// right side outside, both sides of an interior piece inside; regions bounded by
// constraints are flood-filled from those seeds. A piece split by a point lying
// on it is skipped (its sub-edges still bound the same regions). Throws
// std::runtime_error naming `who` when the pieces do not bound a consistent domain.
// The triangulation's constraints are the pieces (each inserted with
// insert_constraint, nothing else constrained): the fill below relies on it.
// `each_face(f)` is called on every face once its label is final, on several
// faces at once (a parallel sweep).
template <class Cdt, class Handles, class Each_face>
void label_domain(Cdt& cdt, const Handles& handles, const std::vector<Constraint_piece>& pieces, const char* who,
                  Each_face each_face) {
  using Face_handle = typename Cdt::Face_handle;
  using Info = typename Cdt::Face::Info;
  const auto fail = [who](const char* what) { throw std::runtime_error(std::string(who) + ": " + what); };
  std::vector<Face_handle> queue;
  auto seed = [&](Face_handle f, int label) {
    if (cdt.is_infinite(f)) label = domain_outside;
    if (f->info() == Info(domain_unknown)) {
      f->info() = Info(label);
      queue.push_back(f);
    } else if (f->info() != Info(label)) {
      fail("the constraints do not bound a consistent domain");
    }
  };
  // Faces swept in parallel (parallel_sweep.hpp), the infinite ones seeded in
  // the order of a sequential sweep. (Below dimension 2 the face container
  // holds edges; CGAL's face iterators then visit nothing, nor does this.)
  auto& faces = cdt.tds().faces();
  const bool has_faces = cdt.dimension() == 2;
  std::vector<std::vector<Face_handle>> infinite(has_faces ? sweep_chunks(faces) : 0);
  if (has_faces) {
    parallel_sweep(faces, [&](std::size_t c, Face_handle f) {
      f->info() = Info(domain_unknown);
      if (cdt.is_infinite(f)) infinite[c].push_back(f);
    });
  }
  for (const Face_handle& f : joined(infinite)) seed(f, domain_outside);
  bool every_piece_an_edge = true;
  for (const auto& piece : pieces) {
    Face_handle f;
    int i;
    if (!cdt.is_edge(handles[piece.a], handles[piece.b], f, i)) {
      every_piece_an_edge = false;
      continue;
    }
    Face_handle left = f, right = f->neighbor(i);
    if (f->vertex(Cdt::ccw(i)) != handles[piece.a]) std::swap(left, right);
    seed(left, domain_inside);
    seed(right, piece.boundary ? domain_outside : domain_inside);
  }
  // When every piece is an edge, only the regions with an outside seed are
  // filled; every face left unknown is inside. Why that is the full fill's
  // answer: a region (faces joined across unconstrained edges) is either
  // unbounded, and holds the infinite faces (outside seeds), or bounded by
  // constraint edges, each of them here a whole piece, both of whose sides are
  // seeded: every region has a seed. The fill covers each region holding an
  // outside seed and fails where it meets an inside one, as the full fill
  // would; the other regions hold inside seeds only, so all their faces are
  // inside. (On a domain whose boundary is its convex hull the fill visits the
  // infinite faces alone: a quarter of the quality pass's set-up on 1e7 points
  // went to filling the inside, one face at a time.) Otherwise every region is
  // filled.
  const bool fill_outside_only = every_piece_an_edge;
  // Breadth first (the queue is read from the front and kept): the labels are
  // those of any order, and a fill by waves from the seeds meets its faces in a
  // more cache-friendly order than a depth-first one (mark_domain on a 1e6-point
  // mesh: 0.10-0.16 s instead of 0.13-0.22 s).
  for (std::size_t head = 0; head < queue.size(); ++head) {
    const auto f = queue[head];
    if (fill_outside_only && f->info() != Info(domain_outside)) continue;
    for (int i = 0; i < 3; ++i) {
      if (f->is_constrained(i)) continue;
      auto g = f->neighbor(i);
      if (g->info() == Info(domain_unknown)) {
        g->info() = f->info();
        queue.push_back(g);
      } else if (g->info() != f->info()) {
        fail("domain boundary is not closed");
      }
    }
  }
  std::vector<std::uint8_t> unseeded(has_faces ? sweep_chunks(faces) : 0, 0);
  if (has_faces) {
    parallel_sweep(faces, [&](std::size_t c, Face_handle f) {
      if (f->info() == Info(domain_unknown)) {
        if (!fill_outside_only) {
          unseeded[c] = 1;
          return;
        }
        f->info() = Info(domain_inside);
      }
      each_face(f);
    });
  }
  for (std::uint8_t u : unseeded) {
    if (u) fail("a region has no seed");
  }
}

template <class Cdt, class Handles>
void label_domain(Cdt& cdt, const Handles& handles, const std::vector<Constraint_piece>& pieces, const char* who) {
  label_domain(cdt, handles, pieces, who, [](const auto&) {});
}

}  // namespace evomesh::detail
