// Bindings of the local supermesh (issue 12): evomesh._core.supermesh.
// Registered by module.cpp's PYBIND11_MODULE through bind_supermesh().
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <cstring>
#include <string>

#include "evomesh/supermesh.hpp"

namespace py = pybind11;
using namespace evomesh;

namespace {

using Float_array = py::array_t<double, py::array::c_style | py::array::forcecast>;
using Int_array = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;

std::vector<Vec2> points_of(const Float_array& a, const char* name) {
  if (a.ndim() != 2 || a.shape(1) != 2) throw Input_error(std::string(name) + " must have shape (n, 2)");
  std::vector<Vec2> out(static_cast<std::size_t>(a.shape(0)));
  if (!out.empty()) std::memcpy(out.data(), a.data(), out.size() * sizeof(Vec2));
  for (const auto& p : out)
    if (!std::isfinite(p[0]) || !std::isfinite(p[1])) throw Input_error(std::string(name) + " must be finite");
  return out;
}

std::vector<Triangle> triangles_of(const Int_array& a, std::size_t n_points, const char* name) {
  if (a.ndim() != 2 || a.shape(1) != 3) throw Input_error(std::string(name) + " must have shape (m, 3)");
  std::vector<Triangle> out(static_cast<std::size_t>(a.shape(0)));
  if (!out.empty()) std::memcpy(out.data(), a.data(), out.size() * sizeof(Triangle));
  for (const auto& t : out)
    for (const Index v : t)
      if (v < 0 || static_cast<std::size_t>(v) >= n_points)
        throw Input_error(std::string(name) + " has a point index out of range [0, " + std::to_string(n_points) +
                          ")");
  return out;
}

std::vector<Index> indices_of(const Int_array& a, std::size_t n, const char* name) {
  if (a.ndim() != 1 || static_cast<std::size_t>(a.shape(0)) != n)
    throw Input_error(std::string(name) + " must have shape (" + std::to_string(n) + ",)");
  return std::vector<Index>(a.data(), a.data() + n);
}

template <class T>
py::array_t<T> to_array(const std::vector<T>& v) {
  py::array_t<T> out(static_cast<py::ssize_t>(v.size()));
  if (!v.empty()) std::memcpy(out.mutable_data(), v.data(), v.size() * sizeof(T));
  return out;
}

}  // namespace

void bind_supermesh(py::module_& m) {
  m.def(
      "supermesh",
      [](const Float_array& old_points, const Int_array& old_triangles, const Float_array& new_points,
         const Int_array& new_triangles, const Int_array& origin, const Int_array& parent_triangle, bool mass,
         int threads) {
        const auto op = points_of(old_points, "old_points");
        const auto ot = triangles_of(old_triangles, op.size(), "old_triangles");
        const auto np_ = points_of(new_points, "new_points");
        const auto nt = triangles_of(new_triangles, np_.size(), "new_triangles");
        const auto org = indices_of(origin, np_.size(), "origin");
        const auto parent = indices_of(parent_triangle, np_.size(), "parent_triangle");
        Supermesh s;
        {
          py::gil_scoped_release release;
          const auto seed = supermesh_seeds(op.size(), ot, org, parent);
          s = build_supermesh(op, ot, np_, nt, seed, mass, threads);
        }
        py::dict out;
        out["offsets"] = to_array(s.offsets);
        out["old_triangle"] = to_array(s.old_triangle);
        out["area"] = to_array(s.area);
        py::array_t<double> mm({static_cast<py::ssize_t>(s.mass.size() / 9), py::ssize_t{3}, py::ssize_t{3}});
        if (!s.mass.empty()) std::memcpy(mm.mutable_data(), s.mass.data(), s.mass.size() * sizeof(double));
        out["mass"] = mm;
        return out;
      },
      py::arg("old_points"), py::arg("old_triangles"), py::arg("new_points"), py::arg("new_triangles"),
      py::arg("origin"), py::arg("parent_triangle"), py::arg("mass") = true, py::arg("threads") = 0,
      "Local supermesh of new over old, seeded by the step's origin and parent_triangle: dict of offsets "
      "(n_new_triangles + 1,), old_triangle and area (pairs,), mass (pairs, 3, 3) = int phi^new_a phi^old_b "
      "(empty when mass=False).");
}
