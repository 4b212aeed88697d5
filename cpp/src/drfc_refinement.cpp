#include "evomesh/drfc_refinement.hpp"

#include "evomesh/detail/delaunay_mesher.hpp"
#include "evomesh/triangulation.hpp"

namespace evomesh {

using namespace detail;

Refined_mesh spacing_refine(const Mesh_arrays& mesh, const Spacing_function& spacing,
                            const std::vector<double>& f_at_points, double min_angle,
                            std::size_t max_inserted, int threads) {
  const std::size_t n = mesh.points.size();
  if (f_at_points.size() != n) throw Input_error("spacing_refine: one f value per point");
  if (!(min_angle >= 0 && min_angle < 60)) throw Input_error("min_angle must be in [0, 60)");
  Cdt cdt;
  const Scaling scaling = unit_scaling(mesh.points);
  const auto handles = insert_points(cdt, mesh.points, scaling.to_unit);
  std::vector<Constraint_piece> pieces(mesh.segments.size());
  for (std::size_t k = 0; k < pieces.size(); ++k) {
    pieces[k] = {mesh.segments[k][0], mesh.segments[k][1], mesh.segment_is_boundary[k] != 0};
  }
  try {
    for (const auto& piece : pieces) cdt.insert_constraint(handles[piece.a], handles[piece.b]);
  } catch (const Cdt::Intersection_of_constraints_exception&) {
    throw crossing_pieces_error(mesh.points, pieces);
  }
  // Sites of the input points: the Apollonius nearest site, or the point itself
  // where its own cone is the minimum (f(p) = delta(p) nn(p), Lemma 3.1).
  {
    std::vector<double> f_eval(n);
    std::vector<Index> site(n);
    spacing.evaluate(mesh.points.data(), n, f_eval.data(), site.data(), threads);
    const auto& weights = spacing.weights();
    for (std::size_t i = 0; i < n; ++i) {
      auto& info = handles[i]->info();
      info.f = f_at_points[i] * scaling.to_unit;
      info.site = weights[i] <= f_eval[i] ? static_cast<Index>(i) : site[i];
      info.exact = true;
    }
  }
  mark_domain(cdt, handles, pieces);
  const Spacing_data data{&spacing.sites(), &spacing.weights(), scaling};
  Mesher mesher(cdt, Refinement_criteria(min_angle, cdt, &data, /*off_centres=*/false));
  mesher.init();
  Refinement_report report;
  std::vector<Vertex_handle> estimated;
  std::vector<Vec2> queries;
  std::vector<double> values;
  std::vector<Index> sites;
  while (true) {
    ++report.rounds;
    const std::size_t inserted = run_mesher(mesher, max_inserted - report.n_inserted, report);
    // Exact f at the points inserted in this pass; a lower f can break rule 4 again.
    estimated.clear();
    for (auto v = cdt.finite_vertices_begin(); v != cdt.finite_vertices_end(); ++v) {
      if (!v->info().exact) estimated.push_back(v);
    }
    queries.resize(estimated.size());
    for (std::size_t k = 0; k < estimated.size(); ++k) {
      queries[k] = {estimated[k]->point().x() * scaling.from_unit, estimated[k]->point().y() * scaling.from_unit};
    }
    values.resize(estimated.size());
    sites.resize(estimated.size());
    spacing.evaluate(queries.data(), queries.size(), values.data(), sites.data(), threads);
    for (std::size_t k = 0; k < estimated.size(); ++k) {
      auto& info = estimated[k]->info();
      info.f = values[k] * scaling.to_unit;
      info.site = sites[k];
      info.exact = true;
    }
    if (inserted == 0 || report.capped) break;
    mesher.rescan_faces();
  }
  std::vector<std::uint8_t> removed(n, 0);
  Refined_mesh result = extract(cdt, handles, mesh.points, mesh.kind, removed, scaling);
  result.report.n_inserted = report.n_inserted;
  result.report.rounds = report.rounds;
  result.report.capped = report.capped;
  return result;
}

}  // namespace evomesh
