// Bindings of the triangulation after a Lagrangian motion:
// evomesh._core.triangulate_moved. Registered by module.cpp through bind_motion().
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <cstring>
#include <string>

#include "evomesh/motion.hpp"

#include "numpy_arrays.hpp"

namespace py = pybind11;
using namespace evomesh;
using namespace evomesh::bindings;

void bind_motion(py::module_& m) {
  m.def(
      "triangulate_moved",
      [](const Float_array& points, const Int_array& pieces, const Byte_array& boundary, const Int_array& left,
         const Int_array& right) {
        if (points.ndim() != 2 || points.shape(1) != 2) throw Input_error("points must have shape (n, 2)");
        std::vector<Vec2> p(static_cast<std::size_t>(points.shape(0)));
        if (!p.empty()) std::memcpy(p.data(), points.data(), p.size() * sizeof(Vec2));
        for (const auto& x : p)
          if (!std::isfinite(x[0]) || !std::isfinite(x[1])) throw Input_error("points must be finite");
        if (pieces.ndim() != 2 || pieces.shape(1) != 2) throw Input_error("pieces must have shape (k, 2)");
        const auto k = static_cast<std::size_t>(pieces.shape(0));
        if (boundary.ndim() != 1 || static_cast<std::size_t>(boundary.shape(0)) != k || left.ndim() != 1 ||
            static_cast<std::size_t>(left.shape(0)) != k || right.ndim() != 1 ||
            static_cast<std::size_t>(right.shape(0)) != k)
          throw Input_error("boundary, left and right must have one entry per piece");
        std::vector<Moved_piece> pc(k);
        for (std::size_t i = 0; i < k; ++i)
          pc[i] = {pieces.data()[2 * i], pieces.data()[2 * i + 1], boundary.data()[i] != 0, left.data()[i],
                   right.data()[i]};
        Moved_triangulation t;
        {
          py::gil_scoped_release release;
          t = triangulate_moved(p, pc);
        }
        py::dict out;
        const auto m_tri = static_cast<py::ssize_t>(t.triangles.size());
        std::vector<Index> flat(3 * t.triangles.size());
        if (!flat.empty()) std::memcpy(flat.data(), t.triangles.data(), flat.size() * sizeof(Index));
        out["triangles"] = to_array(std::move(flat), {m_tri, 3});
        out["triangle_tags"] = to_array(std::move(t.triangle_tags));
        out["unused"] = to_array(std::move(t.unused));
        std::vector<Index> on(2 * t.on_piece.size());
        for (std::size_t i = 0; i < t.on_piece.size(); ++i) {
          on[2 * i] = t.on_piece[i][0];
          on[2 * i + 1] = t.on_piece[i][1];
        }
        out["on_piece"] = to_array(std::move(on), {static_cast<py::ssize_t>(t.on_piece.size()), 2});
        out["conflict"] = t.conflict;
        out["crossing"] = t.crossing;
        return out;
      },
      py::arg("points"), py::arg("pieces"), py::arg("boundary"), py::arg("left"), py::arg("right"),
      "Constrained Delaunay triangulation of distinct points with the pieces (k, 2) as constraints, regions "
      "flood-filled from the pieces' sides (left/right: region tag on each side; boundary pieces have the outside "
      "on their right). Returns a dict: triangles (m, 3) counter-clockwise inside the domain, triangle_tags (m,), "
      "unused (points in no such triangle), on_piece (j, 2) of (point, piece) for points inside a piece, conflict "
      "(a piece whose side met another region's fill, or -1), crossing (a piece that crossed an earlier one, or -1; "
      "then nothing else is filled).");
}
