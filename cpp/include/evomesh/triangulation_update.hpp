// The constrained Delaunay triangulation of a step's output, updated from the
// input's where the step changed it (the changed-region scope; docs/
// distributed-step.md 2.5): the same triangles as constrained_delaunay, from
// the input's triangles where nothing changed and a local triangulation of the
// cavity where something did.
#pragma once

#include <cstddef>
#include <optional>
#include <vector>

#include "evomesh/parent_map.hpp"
#include "evomesh/triangulation.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

struct Triangulation_update_report {
  std::size_t n_cavity_triangles = 0;  // input triangles retriangulated
  std::size_t n_cavity_points = 0;     // points of the local triangulation
  // 0: updated; else why the update declined (the caller triangulates whole):
  // 1 a kept point moved or origins do not fit, 2 a new point not located,
  // 3 the cavity is too large, 4 the cavity's faces are not the cavity,
  // 5 an edge or piece is missing, 6 an edge is not strictly Delaunay (a
  // cocircular tie, or an input that is not a constrained Delaunay triangulation).
  int declined = 0;
  // Seconds: locating the new points and finding the cavity; its local
  // triangulation and flood; the certificates and the output.
  double locate_seconds = 0, local_seconds = 0, certify_seconds = 0;
  // The edges between kept triangles were checked (not inherited from the input's certificate).
  bool checked_kept_edges = false;
};

// constrained_delaunay(points, pieces), the same array, or nullopt (report.declined
// says why). `old_mesh`: the walker of the input mesh; `origin[i]`: the input
// index of output point i (-1 for a new point); kept points at their input
// coordinates. The input triangles that keep their three vertices and have no
// new point in their closed circumdisc (a search from each new point's triangle
// across edges that are not input segments, and across the edge a new point
// lies on) stay; the rest (the cavity) is triangulated by CGAL with the
// cavity's boundary edges and the pieces in it as constraints. The result is
// then certified: every piece is an edge, and every edge that is not a piece is
// strictly locally Delaunay (checked on every edge, kept ones included, with
// exact predicates), so it is the unique constrained Delaunay triangulation of
// the points and pieces, which constrained_delaunay returns. An edge between two
// kept triangles joins the same four points as in the input, so where the input
// says it is strictly Delaunay (Mesh_arrays::strictly_delaunay: a step certified
// it) those edges are not checked again, and the check costs O(c), not O(m). Declines when the
// cavity holds more than `max_cavity_share` of the input triangles. O(m) checks
// and walks plus O(c log c) for a cavity of c triangles. `same_fan` (optional):
// when updated, 1 for every output point whose triangles are all kept (an input
// point that no cavity triangle has: its fan is the input's), else 0.
std::optional<std::vector<Triangle>> updated_constrained_delaunay(const Old_mesh_walker& old_mesh,
                                                                  const std::vector<Vec2>& points,
                                                                  const std::vector<Constraint_piece>& pieces,
                                                                  const std::vector<Index>& origin,
                                                                  double max_cavity_share,
                                                                  Triangulation_update_report& report,
                                                                  std::vector<std::uint8_t>* same_fan = nullptr);

}  // namespace evomesh
