// Binding of the tetrahedral step (tet/tet_step.hpp): evomesh._core.tet_*.
// Python (evomesh/tet_mesh.py, evomesh/tet_evolution.py) validates the mesh
// first; this layer checks shapes, finiteness and index ranges only.
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "evomesh/tet/tet_step.hpp"
#include "evomesh/tet/tet_supermesh.hpp"

#include "numpy_arrays.hpp"

namespace py = pybind11;
using namespace evomesh;
using namespace evomesh::tet;
using namespace evomesh::bindings;

namespace {

// A Python exception raised by the size callback, left pending in the
// interpreter while the core unwinds.
struct Callback_failed {};

std::vector<Vec3> to_points3(const Float_array& a, const char* name) {
  if (a.ndim() != 2 || a.shape(1) != 3) throw Input_error(std::string(name) + " must have shape (n, 3)");
  std::vector<Vec3> out(static_cast<std::size_t>(a.shape(0)));
  if (!out.empty()) std::memcpy(out.data(), a.data(), out.size() * sizeof(Vec3));
  for (const auto& p : out) {
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
      throw Input_error(std::string(name) + " must be finite");
    }
  }
  return out;
}

template <std::size_t K>
std::vector<std::array<Index, K>> to_cells(const Int_array& a, std::size_t n_points, const char* name) {
  if (a.ndim() != 2 || a.shape(1) != static_cast<py::ssize_t>(K)) {
    throw Input_error(std::string(name) + " must have shape (m, " + std::to_string(K) + ")");
  }
  std::vector<std::array<Index, K>> out(static_cast<std::size_t>(a.shape(0)));
  if (!out.empty()) std::memcpy(out.data(), a.data(), out.size() * sizeof(out[0]));
  for (const auto& c : out) {
    for (Index v : c) {
      if (v < 0 || static_cast<std::size_t>(v) >= n_points) throw Input_error(std::string(name) + ": index out of range");
    }
  }
  return out;
}

template <class T, class Array>
std::vector<T> to_vector(const Array& a, std::size_t n, const char* name) {
  if (a.ndim() != 1 || static_cast<std::size_t>(a.shape(0)) != n) {
    throw Input_error(std::string(name) + " needs one value per row");
  }
  return std::vector<T>(a.data(), a.data() + n);
}

// The domain from its arrays (Polyhedral_domain): facets (F, 3, 3), the
// facets (E, 2) and end corners (E, 2, 3) of its edges, a neighbour mask per facet.
Polyhedral_domain to_domain(const Float_array& facets, const Int_array& edge_facets, const Float_array& edge_ends,
                            const Int_array& neighbours) {
  if (facets.ndim() != 3 || facets.shape(1) != 3 || facets.shape(2) != 3) throw Input_error("facets must have shape (F, 3, 3)");
  const auto n_edges = edge_facets.ndim() == 2 ? edge_facets.shape(0) : 0;
  if (edge_facets.ndim() != 2 || edge_facets.shape(1) != 2) throw Input_error("edge_facets must have shape (E, 2)");
  if (edge_ends.ndim() != 3 || edge_ends.shape(0) != n_edges || edge_ends.shape(1) != 2 || edge_ends.shape(2) != 3) {
    throw Input_error("edge_ends must have shape (E, 2, 3)");
  }
  std::vector<std::array<Vec3, 3>> f(static_cast<std::size_t>(facets.shape(0)));
  if (!f.empty()) std::memcpy(f.data(), facets.data(), f.size() * sizeof(f[0]));
  std::vector<std::array<int, 2>> ef(static_cast<std::size_t>(n_edges));
  for (std::size_t e = 0; e < ef.size(); ++e) {
    for (std::size_t i = 0; i < 2; ++i) {
      const auto facet = edge_facets.at(static_cast<py::ssize_t>(e), static_cast<py::ssize_t>(i));
      if (facet < 0 || facet >= facets.shape(0)) throw Input_error("edge_facets must index facets");
      ef[e][i] = static_cast<int>(facet);
    }
  }
  std::vector<std::array<Vec3, 2>> ends(static_cast<std::size_t>(n_edges));
  if (!ends.empty()) std::memcpy(ends.data(), edge_ends.data(), ends.size() * sizeof(ends[0]));
  const auto masks = to_vector<std::int64_t>(neighbours, f.size(), "neighbours");
  for (const auto& facet : f) {
    for (const auto& p : facet) {
      if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) throw Input_error("facets must be finite");
    }
  }
  for (const auto& edge : ends) {
    for (const auto& p : edge) {
      if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) throw Input_error("edge_ends must be finite");
    }
  }
  return Polyhedral_domain(f, ef, ends, std::vector<Polyhedral_domain::Mask>(masks.begin(), masks.end()));
}

py::array_t<double> points_array(std::vector<Vec3>&& points) {
  const auto n = static_cast<py::ssize_t>(points.size());
  std::vector<double> flat(3 * points.size());
  if (!points.empty()) std::memcpy(flat.data(), points.data(), flat.size() * sizeof(double));
  return to_array(std::move(flat), {n, 3});
}

// The step's options from the Python values, checked (Tet_step_options::validate).
Tet_step_options tet_options(double cell_factor, double radius_scale, double boundary_clearance,
                             double max_radius_edge, double sliver_angle, double max_samples, std::uint64_t seed,
                             int threads) {
  Tet_step_options options;
  options.cell_factor = cell_factor;
  options.radius_scale = radius_scale;
  options.boundary_clearance = boundary_clearance;
  options.max_radius_edge = max_radius_edge;
  options.sliver_angle = sliver_angle;
  options.max_samples = max_samples;
  options.seed = seed;
  options.threads = threads;
  options.validate();
  return options;
}

py::array_t<std::int64_t> tets_array(std::vector<Tet>&& tets) {
  const auto m = static_cast<py::ssize_t>(tets.size());
  std::vector<std::int64_t> flat(4 * tets.size());
  if (!tets.empty()) std::memcpy(flat.data(), tets.data(), flat.size() * sizeof(std::int64_t));
  return to_array(std::move(flat), {m, 4});
}

}  // namespace

void bind_tet(py::module_& m) {
  m.def(
      "tet_nn_spacing",
      [](const Float_array& points, int threads) {
        auto p = to_points3(points, "points");
        std::vector<double> nn;
        {
          py::gil_scoped_release release;
          nn = tet_nn_spacing(p, threads);
        }
        return to_array(std::move(nn));
      },
      py::arg("points"), py::arg("threads") = 0, "Distance from each 3-D point to its nearest other point.");

  m.def(
      "tet_orientations",
      [](const Float_array& points, const Int_array& tets) {
        auto p = to_points3(points, "points");
        auto t = to_cells<4>(tets, p.size(), "tetrahedra");
        std::vector<std::int8_t> sign;
        {
          py::gil_scoped_release release;
          sign = tet_orientations(p, t);
        }
        return to_array(std::move(sign));
      },
      py::arg("points"), py::arg("tetrahedra"), "Exact orientation sign of each tetrahedron (+1: positive volume).");

  m.def(
      "cone_envelope_3",
      [](const Float_array& sites, const Float_array& weights, const Float_array& queries, bool brute_force,
         int threads) {
        auto s = to_points3(sites, "sites");
        auto w = to_vector<double>(weights, s.size(), "weights");
        auto q = to_points3(queries, "queries");
        std::vector<double> f;
        std::size_t evaluations = 0;
        {
          py::gil_scoped_release release;
          f = cone_envelope_3(s, w, q, brute_force, evaluations, threads);
        }
        return py::make_tuple(to_array(std::move(f)), evaluations);
      },
      py::arg("sites"), py::arg("weights"), py::arg("queries"), py::arg("brute_force") = false,
      py::arg("threads") = 0,
      "f(x) = min_p (w_p + |x - p|) at each query (exact branch and bound, or brute force), and the sites "
      "evaluated in total.");

  m.def(
      "delaunay_tetrahedra",
      [](const Float_array& points) {
        auto p = to_points3(points, "points");
        std::vector<Tet> t;
        {
          py::gil_scoped_release release;
          t = delaunay_tetrahedra(p);
        }
        return tets_array(std::move(t));
      },
      py::arg("points"), "Delaunay tetrahedra of the points (canonical order).");

  m.def(
      "tet_step",
      [](const Float_array& points, const Int_array& tets, const Int_array& boundary, const Int_array& boundary_tet,
         const Byte_array& steiner, const Byte_array& required, const Float_array& weight, const Float_array& facets,
         const Int_array& edge_facets, const Float_array& edge_ends, const Int_array& neighbours,
         const Int_array& boundary_facet,
         double cell_factor, double radius_scale, double boundary_clearance, double max_radius_edge, double sliver_angle, double max_samples, std::uint64_t seed, int threads,
         std::optional<py::function> cap) {
        Tet_step_input in;
        in.points = to_points3(points, "points");
        const std::size_t n = in.points.size();
        in.tets = to_cells<4>(tets, n, "tetrahedra");
        in.boundary = to_cells<3>(boundary, n, "boundary");
        in.boundary_tet = to_vector<Index>(boundary_tet, in.boundary.size(), "boundary_tet");
        for (Index t : in.boundary_tet) {
          if (t < 0 || static_cast<std::size_t>(t) >= in.tets.size()) throw Input_error("boundary_tet out of range");
        }
        in.steiner = to_vector<std::uint8_t>(steiner, n, "steiner");
        in.required = to_vector<std::uint8_t>(required, n, "required");
        in.weight = to_vector<double>(weight, n, "weight");
        in.domain = to_domain(facets, edge_facets, edge_ends, neighbours);
        const auto facet_of = to_vector<std::int64_t>(boundary_facet, in.boundary.size(), "boundary_facet");
        for (std::int64_t f : facet_of) {
          if (f < 0 || static_cast<std::size_t>(f) >= in.domain.n_facets()) throw Input_error("boundary_facet out of range");
          in.boundary_facet.push_back(static_cast<int>(f));
        }
        const Tet_step_options options = tet_options(cell_factor, radius_scale, boundary_clearance, max_radius_edge,
                                                     sliver_angle, max_samples, seed, threads);
        Size_cap size_cap;
        if (cap) {
          size_cap = [&cap](const std::vector<Vec3>& x, const std::vector<Index>& tet, std::vector<double>& out) {
            py::gil_scoped_acquire gil;
            try {
              std::vector<Vec3> xs = x;
              std::vector<Index> ts = tet;
              py::array_t<double> values((*cap)(points_array(std::move(xs)), to_array(std::move(ts))));
              if (values.ndim() != 1) throw Input_error("the size request must return one value per point");
              out.assign(values.data(), values.data() + values.shape(0));
            } catch (py::error_already_set& e) {
              e.restore();
              throw Callback_failed{};
            }
          };
        }
        Tet_step_result r;
        try {
          py::gil_scoped_release release;
          r = tet_step(in, options, size_cap);
        } catch (const Callback_failed&) {
          throw py::error_already_set();
        }
        py::dict out;
        out["points"] = points_array(std::move(r.points));
        out["tetrahedra"] = tets_array(std::move(r.tets));
        out["origin"] = to_array(std::vector<std::int64_t>(r.origin.begin(), r.origin.end()));
        out["parent_tet"] = to_array(std::vector<std::int64_t>(r.parent_tet.begin(), r.parent_tet.end()));
        out["kind"] = to_array(std::move(r.kind));
        out["facets"] = to_array(std::vector<std::int64_t>(r.facets.begin(), r.facets.end()));
        out["f"] = to_array(std::move(r.f));
        py::dict stats;
        for (const auto& [name, value] : r.stats) stats[py::str(name)] = value;
        out["stats"] = stats;
        return out;
      },
      py::arg("points"), py::arg("tetrahedra"), py::arg("boundary"), py::arg("boundary_tet"), py::arg("steiner"),
      py::arg("required"), py::arg("weight"), py::arg("facets"), py::arg("edge_facets"),
      py::arg("edge_ends"), py::arg("neighbours"), py::arg("boundary_facet"), py::arg("cell_factor"), py::arg("radius_scale"),
      py::arg("boundary_clearance"),
      py::arg("max_radius_edge"), py::arg("sliver_angle"), py::arg("max_samples"), py::arg("seed"), py::arg("threads"), py::arg("cap") = py::none(),
      "One FRFC step on a convex polyhedron's tetrahedral mesh (evomesh.tet_evolution drives it).");

  m.def(
      "tet_domain_incidences",
      [](const Float_array& points, const Float_array& facets, const Int_array& edge_facets, const Float_array& edge_ends,
         const Int_array& neighbours) {
        auto p = to_points3(points, "points");
        const Polyhedral_domain domain = to_domain(facets, edge_facets, edge_ends, neighbours);
        std::vector<std::int64_t> on(p.size());
        {
          py::gil_scoped_release release;
          for (std::size_t k = 0; k < p.size(); ++k) on[k] = static_cast<std::int64_t>(domain.incidences(p[k]));
        }
        return to_array(std::move(on));
      },
      py::arg("points"), py::arg("facets"), py::arg("edge_facets"), py::arg("edge_ends"), py::arg("neighbours"),
      "Checks the domain (its facets' exact lattices) and returns the facets each point lies on exactly, as a bit "
      "mask per point.");

  m.def(
      "check_tet_options",
      [](double cell_factor, double radius_scale, double boundary_clearance, double max_radius_edge,
         double sliver_angle, double max_samples, int threads) {
        tet_options(cell_factor, radius_scale, boundary_clearance, max_radius_edge, sliver_angle, max_samples, 0,
                    threads);
      },
      py::arg("cell_factor"), py::arg("radius_scale"), py::arg("boundary_clearance"), py::arg("max_radius_edge"),
      py::arg("sliver_angle"), py::arg("max_samples"), py::arg("threads"),
      "Raises ValueError naming the first option of the tetrahedral step out of range (the step's own check).");

  m.def(
      "tet_supermesh",
      [](const Float_array& old_points, const Int_array& old_tets, const Float_array& new_points,
         const Int_array& new_tets, const Int_array& origin, const Int_array& parent_tet, int threads) {
        const auto op = to_points3(old_points, "old_points");
        const auto ot = to_cells<4>(old_tets, op.size(), "old_tetrahedra");
        const auto np_ = to_points3(new_points, "new_points");
        const auto nt = to_cells<4>(new_tets, np_.size(), "new_tetrahedra");
        const auto org = to_vector<Index>(origin, np_.size(), "origin");
        const auto parent = to_vector<Index>(parent_tet, np_.size(), "parent_tet");
        Tet_supermesh s;
        {
          py::gil_scoped_release release;
          s = build_tet_supermesh(op, ot, np_, nt, org, parent, threads);
        }
        py::dict out;
        out["offsets"] = to_array(std::move(s.offsets));
        out["old_tet"] = to_array(std::move(s.old_tet));
        out["volume"] = to_array(std::move(s.volume));
        out["identical"] = s.identical;
        return out;
      },
      py::arg("old_points"), py::arg("old_tetrahedra"), py::arg("new_points"), py::arg("new_tetrahedra"),
      py::arg("origin"), py::arg("parent_tet"), py::arg("threads") = 0,
      "Local supermesh of new over old tetrahedra, seeded by the step's origin and parent_tet: dict of offsets "
      "(n_new_tetrahedra + 1,), old_tet and volume (pairs,) = |t n s|, identical (new tetrahedra that are old "
      "ones).");

  m.def(
      "tet_intersection_volume",
      [](const Float_array& t, const Float_array& s) {
        const auto a = to_points3(t, "t");
        const auto b = to_points3(s, "s");
        if (a.size() != 4 || b.size() != 4) throw Input_error("t and s must have shape (4, 3)");
        return tet_intersection_volume({a[0], a[1], a[2], a[3]}, {b[0], b[1], b[2], b[3]});
      },
      py::arg("t"), py::arg("s"), "Volume of the intersection of two tetrahedra (4, 3) (for the tests).");
}
