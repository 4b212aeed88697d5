// Binding of the quality pass alone (Section 6, serial or in rounds):
// evomesh._core.quality_triangulate, for tests and benchmarks that hand it a
// point set and pieces directly. Registered by module.cpp through bind_quality().
#include <CGAL/exceptions.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "evomesh/options.hpp"
#include "evomesh/quality_pass.hpp"

#include "numpy_arrays.hpp"

namespace py = pybind11;
using namespace evomesh;
using namespace evomesh::bindings;

void bind_quality(py::module_& m) {
  m.def(
      "quality_triangulate",
      [](const Float_array& points, const Int_array& pieces, const Byte_array& boundary, double min_angle,
         double crowding_angle, double max_fraction, double max_extra, bool quality_rounds) {
        if (points.ndim() != 2 || points.shape(1) != 2) throw Input_error("points must have shape (n, 2)");
        if (pieces.ndim() != 2 || pieces.shape(1) != 2) throw Input_error("pieces must have shape (m, 2)");
        if (boundary.ndim() != 1 || boundary.shape(0) != pieces.shape(0)) {
          throw Input_error("boundary must have one flag per piece");
        }
        const auto n_points = static_cast<std::size_t>(points.shape(0));
        std::vector<Vec2> pts(n_points);
        for (std::size_t i = 0; i < n_points; ++i) {
          pts[i] = {points.at(i, 0), points.at(i, 1)};
          if (!std::isfinite(pts[i][0]) || !std::isfinite(pts[i][1])) throw Input_error("points must be finite");
        }
        std::vector<Constraint_piece> cp(static_cast<std::size_t>(pieces.shape(0)));
        for (std::size_t i = 0; i < cp.size(); ++i) {
          const std::int64_t a = pieces.at(i, 0), b = pieces.at(i, 1);
          if (a < 0 || b < 0 || static_cast<std::size_t>(a) >= n_points || static_cast<std::size_t>(b) >= n_points) {
            throw Input_error("piece index out of range");
          }
          if (a == b) throw Input_error("a piece joins a point to itself");
          cp[i].a = static_cast<Index>(a);
          cp[i].b = static_cast<Index>(b);
          cp[i].boundary = boundary.at(i) != 0;
        }
        const Quality_options options{min_angle, crowding_angle, max_fraction, max_extra, quality_rounds};
        const std::vector<Point_kind> kind(pts.size(), Point_kind::original);
        Refined_mesh r;
        {
          py::gil_scoped_release release;
          try {
            r = quality_triangulate(pts, kind, cp, options);
          } catch (const CGAL::Failure_exception& e) {
            throw std::runtime_error(std::string("quality_triangulate: CGAL failure: ") + e.what());
          }
        }
        const auto n = static_cast<py::ssize_t>(r.mesh.points.size());
        std::vector<double> xy;
        xy.reserve(2 * r.mesh.points.size());
        for (const auto& q : r.mesh.points) xy.insert(xy.end(), {q[0], q[1]});
        std::vector<std::int64_t> tris;
        tris.reserve(3 * r.mesh.triangles.size());
        for (const auto& t : r.mesh.triangles) tris.insert(tris.end(), {t[0], t[1], t[2]});
        std::vector<std::int64_t> segs;
        for (const auto& s : r.mesh.segments) segs.insert(segs.end(), {s[0], s[1]});
        py::dict out;
        out["points"] = to_array(std::move(xy), {n, 2});
        out["triangles"] = to_array(std::move(tris), {static_cast<py::ssize_t>(r.mesh.triangles.size()), 3});
        out["segments"] = to_array(std::move(segs), {static_cast<py::ssize_t>(r.mesh.segments.size()), 2});
        out["source"] = to_array(std::vector<std::int64_t>(r.source.begin(), r.source.end()));
        py::dict stats;
        stats["points_added"] = static_cast<double>(r.report.n_inserted);
        stats["points_removed"] = static_cast<double>(r.report.n_removed);
        stats["points_outside"] = static_cast<double>(r.report.n_inserted_outside);
        stats["rounds"] = static_cast<double>(r.report.rounds);
        stats["capped"] = r.report.capped ? 1.0 : 0.0;
        stats["stalled"] = r.report.stalled ? 1.0 : 0.0;
        stats["round_limit"] = r.report.round_limit ? 1.0 : 0.0;
        out["stats"] = stats;
        return out;
      },
      py::arg("points"), py::arg("pieces"), py::arg("boundary"), py::arg("min_angle") = 30.0,
      py::arg("crowding_angle") = 120.0, py::arg("max_fraction") = 0.5, py::arg("max_extra") = 1000.0,
      py::arg("quality_rounds") = false,
      "The quality pass alone on the constrained Delaunay triangulation of points and pieces (boundary "
      "pieces with the domain on their left): {'points', 'triangles', 'segments', 'source' (input index, "
      "-1 new), 'stats'}.");
}
