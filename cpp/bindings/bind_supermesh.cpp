// Bindings of the local supermesh: evomesh._core.supermesh.
// Registered by module.cpp's PYBIND11_MODULE through bind_supermesh().
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <cstring>
#include <string>

#include "evomesh/supermesh.hpp"

#include "numpy_arrays.hpp"

namespace py = pybind11;
using namespace evomesh;
using namespace evomesh::bindings;

namespace {

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

// The triangles of an (m, 3) array in place (no copy), checked against n_points.
const Triangle* triangle_view(const Int_array& a, std::size_t n_points, const char* name) {
  if (a.ndim() != 2 || a.shape(1) != 3) throw Input_error(std::string(name) + " must have shape (m, 3)");
  const Index* data = a.data();
  for (py::ssize_t k = 0; k < 3 * a.shape(0); ++k)
    if (data[k] < 0 || static_cast<std::size_t>(data[k]) >= n_points)
      throw Input_error(std::string(name) + " has a point index out of range [0, " + std::to_string(n_points) + ")");
  static_assert(sizeof(Triangle) == 3 * sizeof(Index), "Triangle is three indices");
  return reinterpret_cast<const Triangle*>(data);
}

}  // namespace

void bind_supermesh(py::module_& m) {
  m.def(
      "supermesh",
      [](const Float_array& old_points, const Int_array& old_triangles, const Float_array& new_points,
         const Int_array& new_triangles, const Int_array& origin, const Int_array& parent_triangle, bool mass,
         int threads, bool shortcut) {
        const auto op = points_of(old_points, "old_points");
        const auto ot = triangles_of(old_triangles, op.size(), "old_triangles");
        const auto np_ = points_of(new_points, "new_points");
        const auto nt = triangles_of(new_triangles, np_.size(), "new_triangles");
        const auto org = indices_of(origin, np_.size(), "origin");
        const auto parent = indices_of(parent_triangle, np_.size(), "parent_triangle");
        Supermesh s;
        std::vector<Index> identical;
        {
          py::gil_scoped_release release;
          const auto seed = supermesh_seeds(op.size(), ot, org, parent);
          if (shortcut) identical = identical_old_triangles(op.size(), ot, nt, org, threads);
          s = build_supermesh(op, ot, np_, nt, seed, mass, threads, identical);
        }
        py::dict out;
        const auto pairs = static_cast<py::ssize_t>(s.mass.size() / 9);
        out["offsets"] = to_array(std::move(s.offsets));
        out["old_triangle"] = to_array(std::move(s.old_triangle));
        out["area"] = to_array(std::move(s.area));
        out["mass"] = to_array(std::move(s.mass), {pairs, 3, 3});
        if (identical.empty()) identical.assign(nt.size(), -1);
        out["identical"] = to_array(std::move(identical));
        return out;
      },
      py::arg("old_points"), py::arg("old_triangles"), py::arg("new_points"), py::arg("new_triangles"),
      py::arg("origin"), py::arg("parent_triangle"), py::arg("mass") = true, py::arg("threads") = 0,
      py::arg("shortcut") = true,
      "Local supermesh of new over old, seeded by the step's origin and parent_triangle: dict of offsets "
      "(n_new_triangles + 1,), old_triangle and area (pairs,), mass (pairs, 3, 3) = int phi^new_a phi^old_b "
      "(empty when mass=False), identical (n_new_triangles,): the old triangle a new one is (three kept points), "
      "else -1; those pairs are written without clipping (shortcut=False clips every triangle, for the tests).");

  m.def(
      "p1_mass_matrix",
      [](const Float_array& points, const Int_array& triangles, int threads) {
        const auto p = points_of(points, "points");
        const auto t = triangles_of(triangles, p.size(), "triangles");
        Csr_matrix csr;
        {
          py::gil_scoped_release release;
          csr = p1_mass_matrix(p, t, threads);
        }
        return py::make_tuple(to_array(std::move(csr.data)), to_array(std::move(csr.indices)),
                              to_array(std::move(csr.indptr)));
      },
      py::arg("points"), py::arg("triangles"), py::arg("threads") = 0,
      "The P1 mass matrix of a mesh in compressed rows: (data, indices, indptr), columns sorted in each row.");

  m.def(
      "mixed_mass_times",
      [](const Int_array& offsets, const Int_array& old_triangle, const Float_array& mass,
         const Int_array& old_triangles, const Int_array& new_triangles, std::size_t n_new_points,
         const Float_array& values) {
        if (values.ndim() != 2) throw Input_error("values must have shape (n_old_points, columns)");
        const auto n_old = static_cast<std::size_t>(values.shape(0));
        const auto columns = static_cast<std::size_t>(values.shape(1));
        const Triangle* ot = triangle_view(old_triangles, n_old, "old_triangles");
        const Triangle* nt = triangle_view(new_triangles, n_new_points, "new_triangles");
        const auto m = static_cast<std::size_t>(new_triangles.shape(0));
        const auto pairs = static_cast<std::size_t>(old_triangle.size());
        if (offsets.ndim() != 1 || static_cast<std::size_t>(offsets.shape(0)) != m + 1)
          throw Input_error("offsets must have n_new_triangles + 1 entries");
        if (mass.size() != static_cast<py::ssize_t>(9 * pairs)) throw Input_error("mass must have shape (pairs, 3, 3)");
        const Index* off = offsets.data();
        if (off[0] != 0 || static_cast<std::size_t>(off[m]) != pairs) throw Input_error("offsets do not fit the pairs");
        for (std::size_t t = 0; t < m; ++t)
          if (off[t + 1] < off[t]) throw Input_error("offsets must not decrease");
        const Index* old_tri = old_triangle.data();
        for (std::size_t k = 0; k < pairs; ++k)
          if (old_tri[k] < 0 || old_tri[k] >= old_triangles.shape(0))
            throw Input_error("old_triangle refers to an old triangle out of range");
        py::array_t<double> rhs({static_cast<py::ssize_t>(n_new_points), static_cast<py::ssize_t>(columns)});
        double* out = rhs.mutable_data();
        {
          py::gil_scoped_release release;
          mixed_mass_times(m, off, old_tri, mass.data(), ot, nt, values.data(), columns, n_new_points, out);
        }
        return rhs;
      },
      py::arg("offsets"), py::arg("old_triangle"), py::arg("mass"), py::arg("old_triangles"),
      py::arg("new_triangles"), py::arg("n_new_points"), py::arg("values"),
      "The supermesh's mixed mass matrix times old values (n_old_points, columns): (n_new_points, columns).");

  m.def(
      "solve_p1_mass",
      [](const Float_array& data, const Int_array& indices, const Int_array& indptr, const Float_array& rhs,
         int threads) {
        if (rhs.ndim() != 2) throw Input_error("rhs must have shape (n, columns)");
        const auto n = static_cast<std::size_t>(rhs.shape(0));
        const auto columns = static_cast<std::size_t>(rhs.shape(1));
        if (indptr.ndim() != 1 || static_cast<std::size_t>(indptr.shape(0)) != n + 1)
          throw Input_error("indptr must have n + 1 entries");
        Csr_matrix mass;
        mass.indptr.assign(indptr.data(), indptr.data() + n + 1);
        if (mass.indptr[0] != 0 || mass.indptr[n] != indices.size() || indices.size() != data.size())
          throw Input_error("indptr does not fit indices and data");
        for (std::size_t i = 0; i < n; ++i)
          if (mass.indptr[i + 1] < mass.indptr[i]) throw Input_error("indptr must not decrease");
        mass.indices.assign(indices.data(), indices.data() + indices.size());
        for (const Index j : mass.indices)
          if (j < 0 || static_cast<std::size_t>(j) >= n) throw Input_error("indices out of range");
        mass.data.assign(data.data(), data.data() + data.size());
        std::vector<double> b(rhs.data(), rhs.data() + rhs.size());
        std::vector<double> u;
        int iterations = 0;
        {
          py::gil_scoped_release release;
          u = solve_p1_mass(mass, b, columns, threads, &iterations);
        }
        return py::make_tuple(to_array(std::move(u), {static_cast<py::ssize_t>(n), static_cast<py::ssize_t>(columns)}),
                              iterations);
      },
      py::arg("data"), py::arg("indices"), py::arg("indptr"), py::arg("rhs"), py::arg("threads") = 0,
      "Solves M u = rhs (n, columns) for a P1 mass matrix in compressed rows (from p1_mass_matrix): "
      "Jacobi-preconditioned CG to rounding, then the integral made exact; returns (u, iterations).");
}
