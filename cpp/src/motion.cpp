// The triangulation of a mesh's points after a Lagrangian motion: see evomesh/motion.hpp.
#include "evomesh/motion.hpp"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "evomesh/detail/insert_points.hpp"
#include "evomesh/kernel.hpp"
#include "evomesh/triangulation.hpp"

namespace evomesh {

namespace {

// A face's region: unknown until the fill reaches it, then outside or a region
// tag; `source` is the piece whose side started the fill that reached it (-1:
// the infinite faces), so a conflict names a piece.
struct Region {
  enum State : std::uint8_t { unknown, outside, inside } state = unknown;
  std::int64_t tag = 0;
  Index source = -1;
  bool same(const Region& other) const {
    return state == other.state && (state != inside || tag == other.tag);
  }
};

using Vb = CGAL::Triangulation_vertex_base_with_info_2<Index, Kernel>;
using Fb_info = CGAL::Triangulation_face_base_with_info_2<Region, Kernel>;
using Fb = CGAL::Constrained_triangulation_face_base_2<Kernel, Fb_info>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
// Constraints may pass through points (split there: reported as on_piece) but
// two that cross away from a point throw; no coordinate is ever constructed.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<Kernel, Tds,
                                                       CGAL::No_constraint_intersection_requiring_constructions_tag>;

// The points strictly inside piece a -> b, in order from a: from a, the
// neighbour collinear with a and b and between them, and so on (the
// triangulation split the constraint at each of them, so each is a neighbour
// of the previous one).
std::vector<Index> points_on_piece(const Cdt& cdt, Cdt::Vertex_handle a, Cdt::Vertex_handle b) {
  std::vector<Index> out;
  Cdt::Vertex_handle at = a;
  while (at != b) {
    Cdt::Vertex_handle next;
    auto c = cdt.incident_vertices(at), done = c;
    do {
      if (cdt.is_infinite(c)) continue;
      if (Cdt::Vertex_handle(c) == b) {
        next = b;
        break;
      }
      if (CGAL::collinear(a->point(), c->point(), b->point()) &&
          CGAL::collinear_are_strictly_ordered_along_line(at->point(), c->point(), b->point())) {
        next = c;
        break;
      }
    } while (++c != done);
    if (next == Cdt::Vertex_handle()) break;  // (cannot happen: the constraint runs along such edges)
    if (next != b) out.push_back(next->info());
    at = next;
  }
  return out;
}

}  // namespace

Moved_triangulation triangulate_moved(const std::vector<Vec2>& points, const std::vector<Moved_piece>& pieces) {
  for (const auto& piece : pieces)
    if (piece.a < 0 || piece.b < 0 || static_cast<std::size_t>(piece.a) >= points.size() ||
        static_cast<std::size_t>(piece.b) >= points.size() || piece.a == piece.b)
      throw Input_error("a piece has a point index out of range or repeats a point");
  Moved_triangulation out;
  Cdt cdt;
  const auto handles = detail::insert_points(cdt, points);
  for (std::size_t k = 0; k < pieces.size(); ++k) {
    try {
      cdt.insert_constraint(handles[pieces[k].a], handles[pieces[k].b]);
    } catch (const Cdt::Intersection_of_constraints_exception&) {
      out.crossing = static_cast<Index>(k);
      return out;
    }
  }
  // Seeds: the infinite faces are outside; each piece that is an edge gives
  // its left face the left tag and its right face the right tag (the outside
  // for a boundary piece). A piece split by points on it seeds nothing: the
  // caller drops those points (or fails) and triangulates again.
  std::vector<Cdt::Face_handle> queue;
  auto seed = [&](Cdt::Face_handle f, Region label) {
    if (cdt.is_infinite(f)) label = {Region::outside, 0, label.source};
    if (f->info().state == Region::unknown) {
      f->info() = label;
      queue.push_back(f);
    } else if (!f->info().same(label) && out.conflict < 0) {
      out.conflict = label.source >= 0 ? label.source : f->info().source;
    }
  };
  for (auto f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f) f->info() = Region{};
  if (cdt.dimension() == 2) {
    auto c = cdt.incident_faces(cdt.infinite_vertex()), done = c;
    do seed(c, {Region::outside, 0, -1});
    while (++c != done);
  }
  for (std::size_t k = 0; k < pieces.size(); ++k) {
    const Moved_piece& piece = pieces[k];
    Cdt::Face_handle f;
    int i;
    if (!cdt.is_edge(handles[piece.a], handles[piece.b], f, i)) {
      for (const Index v : points_on_piece(cdt, handles[piece.a], handles[piece.b]))
        out.on_piece.push_back({v, static_cast<Index>(k)});
      continue;
    }
    Cdt::Face_handle left = f, right = f->neighbor(i);
    if (f->vertex(Cdt::ccw(i)) != handles[piece.a]) std::swap(left, right);
    const auto source = static_cast<Index>(k);
    seed(left, {Region::inside, piece.left, source});
    seed(right, piece.boundary ? Region{Region::outside, 0, source} : Region{Region::inside, piece.right, source});
  }
  // Fill across unconstrained edges (breadth first from the seeds).
  for (std::size_t head = 0; head < queue.size(); ++head) {
    const auto f = queue[head];
    for (int i = 0; i < 3; ++i) {
      if (f->is_constrained(i)) continue;
      const auto g = f->neighbor(i);
      if (g->info().state == Region::unknown) {
        g->info() = f->info();
        queue.push_back(g);
      } else if (!g->info().same(f->info()) && out.conflict < 0) {
        out.conflict = f->info().source >= 0 ? f->info().source : g->info().source;
      }
    }
  }
  std::vector<std::uint8_t> used(points.size(), 0);
  out.triangles.reserve(cdt.number_of_faces());
  out.triangle_tags.reserve(cdt.number_of_faces());
  for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
    if (f->info().state != Region::inside) continue;
    const Triangle t = {f->vertex(0)->info(), f->vertex(1)->info(), f->vertex(2)->info()};
    out.triangles.push_back(t);
    out.triangle_tags.push_back(f->info().tag);
    for (const Index v : t) used[v] = 1;
  }
  for (std::size_t v = 0; v < points.size(); ++v)
    if (!used[v]) out.unused.push_back(static_cast<Index>(v));
  const std::vector<Index> order = canonical_triangle_order(points.size(), out.triangles);
  std::vector<std::int64_t> tags(order.size());
  for (std::size_t k = 0; k < order.size(); ++k) tags[k] = out.triangle_tags[order[k]];
  out.triangle_tags = std::move(tags);
  return out;
}

}  // namespace evomesh
