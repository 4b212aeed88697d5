#include "evomesh/detail/delaunay_mesher.hpp"

#include "evomesh/detail/domain.hpp"
#include "evomesh/detail/parallel_sweep.hpp"
#include "evomesh/parallel.hpp"

namespace evomesh::detail {

bool left_face(const Cdt& cdt, Vertex_handle a, Vertex_handle b, Face_handle& f, int& i) {
  if (!cdt.is_edge(a, b, f, i)) return false;
  if (f->vertex(Cdt::ccw(i)) != a) {
    const Face_handle g = f->neighbor(i);
    i = g->index(f);
    f = g;
  }
  return true;
}

void mark_domain(Cdt& cdt, const std::vector<Vertex_handle>& handles, const std::vector<Constraint_piece>& pieces) {
  label_domain(cdt, handles, pieces, "refinement",
               [](const Face_handle& f) { f->set_in_domain(f->info() == domain_inside); });
}

std::size_t run_mesher(Mesher& mesher, std::size_t budget, Refinement_report& report) {
  std::size_t inserted = 0;
  while (inserted < budget && mesher.insert_one_point()) ++inserted;
  if (inserted == budget && !mesher.is_done()) report.capped = true;
  report.n_inserted += inserted;
  return inserted;
}

Refined_mesh extract(Cdt& cdt, const std::vector<Vertex_handle>& handles, const std::vector<Vec2>& input_points,
                     const std::vector<Point_kind>& input_kind, const std::vector<std::uint8_t>& removed,
                     const Scaling& scaling) {
  Refined_mesh result;
  Mesh_arrays& out = result.mesh;
  const std::size_t n = input_kind.size();
  std::vector<Index> input_to_out(n, -1);
  for (std::size_t i = 0; i < n; ++i) {
    if (removed[i]) continue;
    input_to_out[i] = static_cast<Index>(result.source.size());
    result.source.push_back(static_cast<Index>(i));
  }
  // The points the mesher inserted (no point index; sorted below, so the
  // sweep's order does not matter).
  std::vector<Vertex_handle> inserted = parallel_gather(cdt.tds().vertices(), [&](Vertex_handle v) {
    return !cdt.is_infinite(v) && v->info().index < 0;
  });
  // Ruppert: a point the mesher inserts lies in the domain (a refinement point
  // behind a constraint splits the constraint instead); counted, never expected.
  for (const Vertex_handle& v : inserted) {
    bool in_domain = false;
    auto f = cdt.incident_faces(v), done = f;
    do {
      in_domain = in_domain || (!cdt.is_infinite(f) && f->is_in_domain());
    } while (++f != done);
    if (!in_domain) ++result.report.n_inserted_outside;
  }
  std::sort(inserted.begin(), inserted.end(), [](Vertex_handle u, Vertex_handle w) {
    return u->point().x() < w->point().x() || (u->point().x() == w->point().x() && u->point().y() < w->point().y());
  });
  const std::size_t n_kept = result.source.size();
  const std::size_t n_out = n_kept + inserted.size();
  parallel_resize(out.points, n_out);
  parallel_resize(out.kind, n_out);
  parallel_resize(result.f, n_out);
  // In input order (the arrays read and written in order; each vertex once), in
  // parallel blocks; then the inserted points.
  constexpr std::size_t kBlock = std::size_t{1} << 15;
  parallel_for((n + kBlock - 1) / kBlock, 0, [&](std::size_t b) {
    for (std::size_t i = b * kBlock; i < std::min(n, (b + 1) * kBlock); ++i) {
      const Index o = input_to_out[i];
      if (o < 0) continue;
      auto& info = handles[i]->info();
      info.out = o;
      out.points[o] = input_points[i];
      out.kind[o] = input_kind[i];
      result.f[o] = info.f * scaling.from_unit;
    }
  });
  parallel_for((inserted.size() + kBlock - 1) / kBlock, 0, [&](std::size_t b) {
    for (std::size_t k = b * kBlock; k < std::min(inserted.size(), (b + 1) * kBlock); ++k) {
      const Index o = static_cast<Index>(n_kept + k);
      auto& info = inserted[k]->info();
      info.out = o;
      out.points[o] = {inserted[k]->point().x() * scaling.from_unit, inserted[k]->point().y() * scaling.from_unit};
      out.kind[o] = Point_kind::sampled;
      result.f[o] = info.f * scaling.from_unit;
    }
  });
  parallel_resize(result.source, n_out, Index{-1});
  // Triangles and constraint edges from the finite faces, in face order: two
  // parallel sweeps over the face container (parallel_sweep.hpp), the first
  // counting each chunk's triangles, the second writing them to the chunk's own
  // range (allocated here, not by the threads). (Below dimension 2 the face
  // container holds edges, and there are no faces.)
  auto& faces = cdt.tds().faces();
  const std::size_t n_chunks = cdt.dimension() == 2 ? sweep_chunks(faces) : 0;
  auto is_triangle = [&](const Face_handle& f) { return !cdt.is_infinite(f) && f->is_in_domain(); };
  std::vector<std::size_t> first_triangle(n_chunks + 1, 0);
  if (n_chunks > 0) {
    parallel_sweep(faces, [&](std::size_t c, Face_handle f) { first_triangle[c + 1] += is_triangle(f); });
  }
  for (std::size_t c = 0; c < n_chunks; ++c) first_triangle[c + 1] += first_triangle[c];
  parallel_resize(out.triangles, first_triangle[n_chunks]);
  // Constraint edges: boundary ones oriented with the domain on their left.
  // (Each constraint edge from one side: the one with the smaller address when
  // both are finite; sorted below.)
  std::vector<std::vector<std::pair<Edge, std::uint8_t>>> chunk_segments(n_chunks);
  std::vector<std::uint8_t> outside(n_chunks, 0);
  std::vector<std::size_t> next_triangle(first_triangle.begin(), first_triangle.begin() + n_chunks);
  if (n_chunks > 0) {
    parallel_sweep(faces, [&](std::size_t c, Face_handle f) {
      if (cdt.is_infinite(f)) return;
      if (f->is_in_domain()) {
        out.triangles[next_triangle[c]++] = {f->vertex(0)->info().out, f->vertex(1)->info().out,
                                             f->vertex(2)->info().out};
      }
      auto& segs = chunk_segments[c];
      for (int i = 0; i < 3; ++i) {
        if (!f->is_constrained(i)) continue;
        const Face_handle g = f->neighbor(i);
        if (!cdt.is_infinite(g) && &*g < &*f) continue;
        const bool f_in = f->is_in_domain();
        const bool g_in = !cdt.is_infinite(g) && g->is_in_domain();
        const Index a = f->vertex(Cdt::ccw(i))->info().out, b = f->vertex(Cdt::cw(i))->info().out;
        if (f_in && g_in) segs.push_back({{std::min(a, b), std::max(a, b)}, 0});
        else if (f_in) segs.push_back({{a, b}, 1});
        else if (g_in) segs.push_back({{b, a}, 1});
        else outside[c] = 1;
      }
    });
  }
  for (std::uint8_t o : outside) {
    if (o) throw std::runtime_error("refinement: a constraint lies outside the domain");
  }
  std::vector<std::pair<Edge, std::uint8_t>> segments;
  for (auto& segs : chunk_segments) {
    segments.insert(segments.end(), segs.begin(), segs.end());
    segs = {};
  }
  std::sort(segments.begin(), segments.end());
  for (const auto& s : segments) {
    out.segments.push_back(s.first);
    out.segment_is_boundary.push_back(s.second);
    for (Index v : s.first) {
      if (out.kind[v] > Point_kind::boundary) out.kind[v] = Point_kind::boundary;
      if (result.source[v] < 0) ++result.report.n_inserted_on_segments;
    }
  }
  // Each new point on a constraint was counted once per constraint edge at it (two).
  result.report.n_inserted_on_segments /= 2;
  return result;
}

}  // namespace evomesh::detail
