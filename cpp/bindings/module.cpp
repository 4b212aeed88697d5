// The thin pybind11 layer: numpy arrays in and out, nothing else. Python
// (python/evomesh) validates shapes, dtypes and values before calling in.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <type_traits>
#include <unordered_map>
#include <vector>

#include "evomesh/boundary_geometry.hpp"
#include "evomesh/candidates.hpp"
#include "evomesh/drfc.hpp"
#include "evomesh/frfc.hpp"
#include "evomesh/global_ids.hpp"
#include "evomesh/kernel.hpp"
#include "evomesh/local_feature_size.hpp"
#include "evomesh/mesh_walk.hpp"
#include "evomesh/nd/hilbert_order.hpp"
#include "evomesh/options.hpp"
#include "evomesh/packing.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/quality_pass.hpp"
#include "evomesh/segment_chains.hpp"
#include "evomesh/size_request.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/spacing_repair.hpp"
#include "evomesh/step.hpp"
#include "evomesh/step_context.hpp"
#include "evomesh/triangle_fans.hpp"
#include "evomesh/triangulation.hpp"

#include "numpy_arrays.hpp"

namespace py = pybind11;
using namespace evomesh;
using namespace evomesh::bindings;

namespace {

// The only place where a step's context meets the environment (step_context.hpp):
// EVOMESH_STAGE_PROFILE (set, not "0": per-stage memory and CPU stats) and
// EVOMESH_SITE_FILTER ("0": keep hidden sites, for benchmarks), read at every call.
bool stage_profile_requested() {
  const char* value = std::getenv("EVOMESH_STAGE_PROFILE");
  return value != nullptr && std::string(value) != "0";
}

Step_context step_context_from_environment(int threads) {
  Step_context context = Step_context::from_threads(threads);
  context.profile = stage_profile_requested();
  const char* filter = std::getenv("EVOMESH_SITE_FILTER");
  context.filter_sites = filter == nullptr || std::string(filter) != "0";
  return context;
}


void require_shape(const py::array& a, py::ssize_t cols, const char* name) {
  if (a.ndim() != 2 || a.shape(1) != cols) {
    throw Input_error(std::string(name) + " must have shape (n, " + std::to_string(cols) + ")");
  }
}

// The core assumes what Python's Mesh checks (a valid planar mesh); the bindings
// check only what is cheap and would otherwise read out of bounds or feed NaN
// to CGAL: shapes, finite coordinates, index ranges.
std::vector<Vec2> to_points(const Float_array& a, const char* name = "points") {
  require_shape(a, 2, name);
  std::vector<Vec2> out(static_cast<std::size_t>(a.shape(0)));
  if (!out.empty()) std::memcpy(out.data(), a.data(), out.size() * sizeof(Vec2));
  for (const auto& p : out) {
    if (!std::isfinite(p[0]) || !std::isfinite(p[1])) throw Input_error(std::string(name) + " must be finite");
  }
  return out;
}

template <std::size_t K>
void require_indices(const std::vector<std::array<Index, K>>& rows, std::size_t n, const char* name) {
  for (const auto& row : rows) {
    for (Index v : row) {
      if (v < 0 || static_cast<std::size_t>(v) >= n) {
        throw Input_error(std::string(name) + " has a point index out of range [0, " + std::to_string(n) + ")");
      }
    }
  }
}

template <std::size_t K>
std::vector<std::array<Index, K>> to_index_rows(const Int_array& a, const char* name) {
  require_shape(a, K, name);
  std::vector<std::array<Index, K>> out(static_cast<std::size_t>(a.shape(0)));
  if (!out.empty()) std::memcpy(out.data(), a.data(), out.size() * sizeof(std::array<Index, K>));
  return out;
}

template <class T>
std::vector<T> to_vector(const py::array_t<T, py::array::c_style | py::array::forcecast>& a) {
  if (a.ndim() != 1) throw Input_error("expected a one-dimensional array");
  return std::vector<T>(a.data(), a.data() + a.shape(0));
}

// Points and triangles whose indices are checked against them.
std::pair<std::vector<Vec2>, std::vector<Triangle>> to_points_and_triangles(const Float_array& points,
                                                                           const Int_array& triangles) {
  auto pts = to_points(points);
  auto tris = to_index_rows<3>(triangles, "triangles");
  require_indices(tris, pts.size(), "triangles");
  return {std::move(pts), std::move(tris)};
}

Float_array points_array(const std::vector<Vec2>& pts) {
  Float_array out({static_cast<py::ssize_t>(pts.size()), py::ssize_t{2}});
  if (!pts.empty()) std::memcpy(out.mutable_data(), pts.data(), pts.size() * sizeof(Vec2));
  return out;
}

template <std::size_t K>
Int_array rows_array(const std::vector<std::array<Index, K>>& rows) {
  Int_array out({static_cast<py::ssize_t>(rows.size()), static_cast<py::ssize_t>(K)});
  if (!rows.empty()) std::memcpy(out.mutable_data(), rows.data(), rows.size() * sizeof(std::array<Index, K>));
  return out;
}

template <class T>
py::array_t<T> vector_array(const std::vector<T>& v) {
  py::array_t<T> out(static_cast<py::ssize_t>(v.size()));
  if (!v.empty()) std::memcpy(out.mutable_data(), v.data(), v.size() * sizeof(T));
  return out;
}

// Pieces (k, 2) of point indices and their boundary flags, checked against n points.
std::vector<Constraint_piece> to_constraint_pieces(const Int_array& pieces, const Byte_array& boundary,
                                                   std::size_t n) {
  auto p = to_index_rows<2>(pieces, "pieces");
  auto b = to_vector<std::uint8_t>(boundary);
  if (b.size() != p.size()) throw Input_error("one boundary flag per piece");
  for (const auto& e : p) {
    for (Index v : e) {
      if (v < 0 || static_cast<std::size_t>(v) >= n) throw Input_error("piece index out of range");
    }
  }
  std::vector<Constraint_piece> cp(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) cp[i] = {p[i][0], p[i][1], b[i] != 0};
  return cp;
}


Byte_array kinds_array(const std::vector<Point_kind>& kind) {
  Byte_array out(static_cast<py::ssize_t>(kind.size()));
  for (std::size_t i = 0; i < kind.size(); ++i) out.mutable_data()[i] = static_cast<std::uint8_t>(kind[i]);
  return out;
}

std::vector<Point_kind> to_kinds(const Byte_array& a) {
  auto raw = to_vector<std::uint8_t>(a);
  std::vector<Point_kind> out(raw.size());
  for (std::size_t i = 0; i < raw.size(); ++i) {
    if (raw[i] > static_cast<std::uint8_t>(Point_kind::sampled)) throw Input_error("kind values must be in 0..4");
    out[i] = static_cast<Point_kind>(raw[i]);
  }
  return out;
}

Mesh_arrays to_mesh(const Float_array& points, const Int_array& triangles, const Int_array& segments,
                    const Byte_array& segment_is_boundary, const Byte_array& kind) {
  Mesh_arrays mesh;
  mesh.points = to_points(points);
  mesh.triangles = to_index_rows<3>(triangles, "triangles");
  mesh.segments = to_index_rows<2>(segments, "segments");
  require_indices(mesh.triangles, mesh.points.size(), "triangles");
  require_indices(mesh.segments, mesh.points.size(), "segments");
  mesh.segment_is_boundary = to_vector<std::uint8_t>(segment_is_boundary);
  mesh.kind = to_kinds(kind);
  if (mesh.kind.size() != mesh.points.size()) throw Input_error("kind must have one value per point");
  if (mesh.segment_is_boundary.size() != mesh.segments.size()) throw Input_error("one boundary flag per segment");
  return mesh;
}

// Optional labels of a mesh (segment and triangle tags, required points), checked
// against its sizes.
void add_labels(Mesh_arrays& mesh, const std::optional<Int_array>& segment_tags,
                const std::optional<Int_array>& triangle_tags, const std::optional<Byte_array>& required) {
  if (segment_tags) {
    mesh.segment_tags = to_vector<std::int64_t>(*segment_tags);
    if (mesh.segment_tags.size() != mesh.segments.size()) throw Input_error("segment_tags: one tag per segment");
  }
  if (triangle_tags) {
    mesh.triangle_tags = to_vector<std::int64_t>(*triangle_tags);
    if (mesh.triangle_tags.size() != mesh.triangles.size()) throw Input_error("triangle_tags: one tag per triangle");
  }
  if (required) {
    mesh.required = to_vector<std::uint8_t>(*required);
    if (mesh.required.size() != mesh.points.size()) throw Input_error("required: one flag per point");
  }
}

// A boundary geometry from Python: the curved tags, the corner angle and
// project(points (k, 2) float64, tags (k,) int64) -> (k, 2) array, called with
// the GIL taken (the step releases it); its exceptions reach the caller.
std::shared_ptr<const Boundary_geometry> to_geometry(const std::optional<Int_array>& curved_tags,
                                                     double corner_angle, const std::optional<py::function>& project) {
  if (!curved_tags) return nullptr;
  if (!project) throw Input_error("geometry: curved_tags given without a projection");
  auto geometry = std::make_shared<Boundary_geometry>();
  geometry->curved_tags = to_vector<std::int64_t>(*curved_tags);
  std::sort(geometry->curved_tags.begin(), geometry->curved_tags.end());
  geometry->curved_tags.erase(std::unique(geometry->curved_tags.begin(), geometry->curved_tags.end()),
                              geometry->curved_tags.end());
  geometry->corner_angle = corner_angle;
  // The Python function outlives the step: the binding's arguments hold it.
  PyObject* function = project->ptr();
  geometry->project = [function](std::vector<Vec2>& points, const std::vector<std::int64_t>& tags) {
    py::gil_scoped_acquire gil;
    const auto k = static_cast<py::ssize_t>(points.size());
    py::array_t<double> x({k, static_cast<py::ssize_t>(2)});
    py::array_t<std::int64_t> t(k);
    std::copy(&points[0][0], &points[0][0] + 2 * points.size(), x.mutable_data());
    std::copy(tags.begin(), tags.end(), t.mutable_data());
    py::object returned = py::reinterpret_borrow<py::function>(function)(x, t);
    auto y = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(returned);
    if (!y || y.ndim() != 2 || y.shape(0) != k || y.shape(1) != 2) {
      throw Input_error("geometry: the projection must return an array of shape (k, 2) for k points");
    }
    std::copy(y.data(), y.data() + 2 * points.size(), &points[0][0]);
  };
  geometry->validate();
  return geometry;
}

// nn_M within the domain and where it grew (Mesh.nn_spacing), if the caller has them.
void add_known_nn(Mesh_arrays& mesh, const std::optional<Float_array>& nn, const std::optional<Int_array>& nn_grew) {
  if (!nn && !nn_grew) return;
  if (!nn || !nn_grew) throw Input_error("nn and nn_grew go together");
  mesh.nn_within_domain = to_vector<double>(*nn);
  mesh.nn_grew = to_vector<Index>(*nn_grew);
  if (mesh.nn_within_domain.size() != mesh.points.size()) throw Input_error("nn: one value per point");
  for (double d : mesh.nn_within_domain) {
    if (!std::isfinite(d) || !(d > 0)) throw Input_error("nn must be finite and > 0");
  }
  for (Index i : mesh.nn_grew) {
    if (i < 0 || static_cast<std::size_t>(i) >= mesh.points.size()) throw Input_error("nn_grew: point index out of range");
  }
}

// A read-only numpy array over an immutable bytes object holding a copy of
// `data` (count elements of T, the given shape): what Python's Mesh keeps
// (mesh.py, _frozen, takes such an array as it is instead of copying it again).
template <class T>
py::array frozen_array(const T* data, std::size_t count, const std::vector<py::ssize_t>& shape) {
  static_assert(std::is_arithmetic_v<T>, "frozen_array: elements of a numeric dtype");
  const auto bytes = static_cast<py::ssize_t>(count * sizeof(T));
  py::object owner = py::reinterpret_steal<py::object>(PyBytes_FromStringAndSize(nullptr, bytes));
  if (!owner) throw py::error_already_set();
  if (count != 0) std::memcpy(PyBytes_AS_STRING(owner.ptr()), data, static_cast<std::size_t>(bytes));
  py::array flat = py::module_::import("numpy").attr("frombuffer")(owner, py::dtype::of<T>());
  return flat.attr("reshape")(py::tuple(py::cast(shape)));
}

// The arrays of a mesh and the input index of every point (-1 for a new one).
py::dict mesh_dict(const Mesh_arrays& mesh, const std::vector<Index>& origin) {
  py::dict out;
  if (!mesh.segment_tags.empty()) out["segment_tags"] = vector_array(mesh.segment_tags);
  if (!mesh.triangle_tags.empty()) out["triangle_tags"] = vector_array(mesh.triangle_tags);
  if (!mesh.required.empty()) out["required"] = vector_array(mesh.required);
  // (read-only, over bytes: the arrays a Mesh keeps; see frozen_array)
  out["points"] = frozen_array(reinterpret_cast<const double*>(mesh.points.data()), mesh.points.size() * 2,
                               {static_cast<py::ssize_t>(mesh.points.size()), py::ssize_t{2}});
  out["triangles"] = frozen_array(reinterpret_cast<const Index*>(mesh.triangles.data()), mesh.triangles.size() * 3,
                                  {static_cast<py::ssize_t>(mesh.triangles.size()), py::ssize_t{3}});
  out["segments"] = frozen_array(reinterpret_cast<const Index*>(mesh.segments.data()), mesh.segments.size() * 2,
                                 {static_cast<py::ssize_t>(mesh.segments.size()), py::ssize_t{2}});
  out["segment_is_boundary"] = vector_array(mesh.segment_is_boundary);
  out["kind"] = kinds_array(mesh.kind);
  out["origin"] = frozen_array(origin.data(), origin.size(), {static_cast<py::ssize_t>(origin.size())});
  return out;
}

py::dict evolve_result_dict(const Evolve_result& r) {
  py::dict out = mesh_dict(r.mesh, r.origin);
  out["input_f"] = frozen_array(r.input_f.data(), r.input_f.size(), {static_cast<py::ssize_t>(r.input_f.size())});
  out["input_nn"] = frozen_array(r.input_nn.data(), r.input_nn.size(), {static_cast<py::ssize_t>(r.input_nn.size())});
  if (!r.output_nn.empty()) {
    out["output_nn"] = vector_array(r.output_nn);
    out["output_nn_grew"] = vector_array(r.output_nn_grew);
    out["output_nn_grown"] = vector_array(r.output_nn_grown);
  }
  out["parent_triangle"] = frozen_array(r.parents.triangle.data(), r.parents.triangle.size(),
                                        {static_cast<py::ssize_t>(r.parents.triangle.size())});
  out["barycentric"] = frozen_array(reinterpret_cast<const double*>(r.parents.barycentric.data()), r.parents.barycentric.size() * 3,
                                    {static_cast<py::ssize_t>(r.parents.barycentric.size()), py::ssize_t{3}});
  out["unchanged"] = r.unchanged;
  out["triangulation_certified"] = r.triangulation_certified;
  py::dict stats;
  for (const auto& s : r.stats) stats[py::str(s.first)] = s.second;
  out["stats"] = stats;
  return out;
}

// The option types, with the same field names as in C++ (one list per type).
#define EVOMESH_FRFC_FIELDS(X)                                                                                  \
  X(cell_factor) X(radius) X(radius_scale) X(boundary_scale) X(ring_samples) X(repair_ratio)                   \
  X(gap_repair_ratio) X(refine_gap_ratio) X(demote_ratio) X(samples) X(adaptive_cells) X(skip_coarse) X(skip_settled) X(filter_samples)            \
  X(max_samples) X(threads) X(seed) X(quality) X(within_domain) X(min_angle) X(crowding_angle)                 \
  X(quality_max_fraction) X(quality_max_extra) X(incremental) X(quality_rounds)
#define EVOMESH_DRFC_FIELDS(X)                                                                                  \
  X(min_angle) X(radius_scale) X(threads) X(max_samples) X(quality) X(crowding_angle) X(quality_max_fraction)    \
  X(quality_max_extra) X(within_domain) X(quality_rounds)

template <class Options>
void bind_option_type(py::class_<Options>& cls, const py::tuple& fields, const char* doc) {
  cls.doc() = doc;
  cls.def(py::init<>())
      .def_static("paper", &Options::paper, "The paper's algorithm exactly.")
      .def_static("recommended", &Options::recommended, "The defaults of evolve().")
      .def("validate", &Options::validate, "Raise ValueError naming the first field out of range.")
      .def_property_readonly_static("fields", [fields](py::object) { return fields; })
      .def("__copy__", [](const Options& o) { return Options(o); })
      .def("__deepcopy__", [](const Options& o, py::dict) { return Options(o); })
      .def("__eq__", [fields](py::object self, py::object other) {
        if (!py::isinstance<Options>(other)) return false;
        for (auto name : fields) {
          if (!self.attr(name).equal(other.attr(name))) return false;
        }
        return true;
      })
      .def(py::pickle(
          [fields](py::object self) {
            py::dict state;
            for (auto name : fields) state[name] = self.attr(name);
            return state;
          },
          [](py::dict state) {
            py::object o = py::cast(Options());
            for (auto item : state) o.attr(item.first) = item.second;
            return o.cast<Options>();
          }))
      .def("__repr__", [fields](py::object self) {
        std::string out = py::str(py::type::of(self).attr("__name__"));
        out += "(";
        bool first = true;
        for (auto name : fields) {
          if (!first) out += ", ";
          first = false;
          out += std::string(py::str(name)) + "=" + std::string(py::repr(self.attr(name)));
        }
        return out + ")";
      });
}

void bind_options(py::module_& m) {
  py::enum_<Sample_mode>(m, "SampleMode", "Where samples are drawn (Section 3.2 step 2; Section 5's variations).")
      .value("random", Sample_mode::random_grid)
      .value("barycentre", Sample_mode::barycentre)
      .value("midpoints", Sample_mode::midpoints)
      .value("barycentre_midpoints", Sample_mode::barycentre_midpoints);
  py::enum_<Radius_rule>(m, "RadiusRule",
                         "Sample sphere radius: exact f(x)/2, the paper's cheap bound, or min(f(x), linear f)/2.")
      .value("exact", Radius_rule::exact)
      .value("cheap", Radius_rule::cheap)
      .value("interpolated", Radius_rule::interpolated);
  // Point kinds as (name, value) pairs; Python makes its IntEnum PointKind from them
  // (an IntEnum compares with numpy arrays, a pybind11 enum does not).
  m.attr("POINT_KINDS") = py::make_tuple(
      py::make_tuple("CORNER", static_cast<int>(Point_kind::corner)),
      py::make_tuple("BOUNDARY", static_cast<int>(Point_kind::boundary)),
      py::make_tuple("ORIGINAL", static_cast<int>(Point_kind::original)),
      py::make_tuple("STEINER", static_cast<int>(Point_kind::steiner)),
      py::make_tuple("SAMPLED", static_cast<int>(Point_kind::sampled)));
  // Packing classes the distributed step keys by (packing.hpp): ring candidates
  // inside are class_ring + round, the other new points inside class_new.
  m.attr("PACKING_CLASS_RING") = static_cast<int>(class_ring);
  m.attr("PACKING_CLASS_NEW") = static_cast<int>(class_new);
  m.attr("MAX_MIN_ANGLE") = kMaxMinAngle;
  m.attr("STRAIGHT_ULPS") = kStraightUlps;
  m.attr("DEFAULT_CORNER_ANGLE") = kDefaultCornerAngle;
  m.def("default_thread_count", &default_thread_count,
        "Threads a step uses by default: EVOMESH_NUM_THREADS, else OMP_NUM_THREADS, else the CPUs this process "
        "may use (affinity and cgroup quota).");

#define EVOMESH_NAME(field) #field,
#define EVOMESH_BIND(field) cls.def_readwrite(#field, &Type::field);
  {
    using Type = Frfc_options;
    py::class_<Type> cls(m, "FrfcOptions");
    bind_option_type(cls, py::tuple(py::cast(std::vector<std::string>{EVOMESH_FRFC_FIELDS(EVOMESH_NAME)})),
                     "Options of FRFC (evolve(method='frfc')); fields as in C++ evomesh::Frfc_options.");
    EVOMESH_FRFC_FIELDS(EVOMESH_BIND)
  }
  {
    using Type = Drfc_options;
    py::class_<Type> cls(m, "DrfcOptions");
    bind_option_type(cls, py::tuple(py::cast(std::vector<std::string>{EVOMESH_DRFC_FIELDS(EVOMESH_NAME)})),
                     "Options of DRFC (evolve(method='drfc')); fields as in C++ evomesh::Drfc_options.");
    EVOMESH_DRFC_FIELDS(EVOMESH_BIND)
  }
#undef EVOMESH_BIND
#undef EVOMESH_NAME
}

}  // namespace

// Global ids of a step's input (Mesh_arrays::point_gids, ...; None: the
// positions), for a caller that holds part of a larger mesh.
void add_global_ids(Mesh_arrays& mesh, const std::optional<Int_array>& point_gids,
                    const std::optional<Int_array>& triangle_gids, const std::optional<Int_array>& segment_keys) {
  if (point_gids) mesh.point_gids = to_vector<std::int64_t>(*point_gids);
  if (triangle_gids) mesh.triangle_gids = to_vector<std::int64_t>(*triangle_gids);
  if (segment_keys) mesh.segment_keys = to_vector<std::int64_t>(*segment_keys);
  check_global_ids(mesh.point_gids, mesh.points.size(), "point_gids");
  check_global_ids(mesh.triangle_gids, mesh.triangles.size(), "triangle_gids");
  check_global_ids(mesh.segment_keys, mesh.segments.size(), "segment_keys");
}

// One step on a mesh given as arrays (frfc, drfc, drfc_refine): the GIL is
// released while `run` works; `to_dict` turns its result into a dict.
template <class Options, class Result, class To_dict>
void bind_step(py::module_& m, const char* name,
               Result (*run)(const Mesh_arrays&, const std::vector<double>&, const Options&, const Step_context&),
               To_dict to_dict, const char* doc) {
  m.def(
      name,
      [run, to_dict](const Float_array& points, const Int_array& triangles, const Int_array& segments,
                     const Byte_array& segment_is_boundary, const Byte_array& kind, const Float_array& delta,
                     const Options& options, std::optional<Int_array> segment_tags,
                     std::optional<Int_array> triangle_tags, std::optional<Byte_array> required,
                     std::optional<Int_array> curved_tags, double corner_angle, std::optional<py::function> project,
                     std::optional<Float_array> nn, std::optional<Int_array> nn_grew,
                     std::optional<Int_array> point_gids, std::optional<Int_array> triangle_gids,
                     std::optional<Int_array> segment_keys, bool strictly_delaunay) {
        Mesh_arrays mesh = to_mesh(points, triangles, segments, segment_is_boundary, kind);
        mesh.strictly_delaunay = strictly_delaunay;
        add_labels(mesh, segment_tags, triangle_tags, required);
        add_known_nn(mesh, nn, nn_grew);
        add_global_ids(mesh, point_gids, triangle_gids, segment_keys);
        mesh.geometry = to_geometry(curved_tags, corner_angle, project);
        auto d = to_vector<double>(delta);
        const Step_context context = step_context_from_environment(options.threads);
        Result r;
        {
          py::gil_scoped_release release;
          r = run(mesh, d, options, context);
        }
        return to_dict(r);
      },
      py::arg("points"), py::arg("triangles"), py::arg("segments"), py::arg("segment_is_boundary"),
      py::arg("kind"), py::arg("delta"), py::arg("options") = Options::recommended(),
      py::arg("segment_tags") = py::none(), py::arg("triangle_tags") = py::none(), py::arg("required") = py::none(),
      py::arg("curved_tags") = py::none(), py::arg("corner_angle") = kDefaultCornerAngle,
      py::arg("project") = py::none(), py::arg("nn") = py::none(), py::arg("nn_grew") = py::none(),
      py::arg("point_gids") = py::none(), py::arg("triangle_gids") = py::none(), py::arg("segment_keys") = py::none(),
      py::arg("strictly_delaunay") = false, doc);
}

PYBIND11_MODULE(_core, m) {
  void bind_supermesh(pybind11::module_&); bind_supermesh(m);  // cpp/bindings/bind_supermesh.cpp
  void bind_motion(pybind11::module_&); bind_motion(m);  // cpp/bindings/bind_motion.cpp
  void bind_mis_rounds(pybind11::module_&); bind_mis_rounds(m);  // cpp/bindings/bind_mis_rounds.cpp
  void bind_quality(pybind11::module_&); bind_quality(m);  // cpp/bindings/bind_quality.cpp
  void bind_tet(pybind11::module_&); bind_tet(m);  // cpp/bindings/bind_tet.cpp (tetrahedral meshes)
  m.doc() = "evomesh C++ core (CGAL): spacing functions, sampling, lexical-first MIS, FRFC";

  m.def(
      "prepare_mesh",
      [](const Float_array& points, const Int_array& triangles, std::optional<Int_array> segments,
         bool check_planar, std::optional<Int_array> segment_tags, std::optional<Byte_array> required,
         bool reference_planarity) {
        Mesh_arrays mesh;
        mesh.points = to_points(points);
        mesh.triangles = to_index_rows<3>(triangles, "triangles");
        std::vector<Edge> user;
        if (segments) user = to_index_rows<2>(*segments, "segments");
        require_indices(mesh.triangles, mesh.points.size(), "triangles");
        require_indices(user, mesh.points.size(), "segments");
        std::vector<std::int64_t> user_tags;
        if (segment_tags) {
          user_tags = to_vector<std::int64_t>(*segment_tags);
          if (user_tags.size() != user.size()) throw Input_error("segment_tags: one tag per segment");
        }
        if (required) {
          mesh.required = to_vector<std::uint8_t>(*required);
          if (mesh.required.size() != mesh.points.size()) throw Input_error("required: one flag per point");
        }
        std::size_t flipped;
        std::vector<std::pair<std::string, double>> seconds;
        {
          py::gil_scoped_release release;
          detail::Stage_timer timer(seconds, stage_profile_requested());
          flipped = orient_triangles(mesh.points, mesh.triangles);
          timer.lap("orient");
          build_segments(mesh, user);
          timer.lap("segments");
          if (check_planar) {
            if (reference_planarity) {
              check_planar_mesh_cdt(mesh.points, mesh.triangles);
            } else {
              std::size_t n_boundary = 0;
              while (n_boundary < mesh.segments.size() && mesh.segment_is_boundary[n_boundary]) ++n_boundary;
              check_planar_mesh(mesh.points, mesh.triangles,
                                std::vector<Edge>(mesh.segments.begin(), mesh.segments.begin() + n_boundary));
            }
          }
          timer.lap("planar");
          if (!user_tags.empty()) mesh.segment_tags = tags_of_segments(mesh.segments, user, user_tags);
          mesh.kind = classify_points(mesh);
          timer.lap("classify");
        }
        py::dict timings;
        for (const auto& [name, value] : seconds) timings[py::str(name)] = value;
        return py::make_tuple(rows_array<3>(mesh.triangles), rows_array<2>(mesh.segments),
                              vector_array<std::uint8_t>(mesh.segment_is_boundary), kinds_array(mesh.kind),
                              flipped, vector_array(mesh.segment_tags), timings);
      },
      py::arg("points"), py::arg("triangles"), py::arg("segments") = py::none(), py::arg("check_planar") = true,
      py::arg("segment_tags") = py::none(), py::arg("required") = py::none(), py::arg("reference_planarity") = false,
      "Orient triangles CCW, build segments, check planarity, classify points (a change of segment tag and a "
      "required point on segments are corners). Returns (triangles, segments, segment_is_boundary, kind, "
      "n_flipped, segment_tags of the built segments: the user's tag, 0 for a boundary edge not given, "
      "{stage: seconds} for seconds_orient, seconds_segments, seconds_planar, seconds_classify). "
      "reference_planarity: the constrained Delaunay triangulation of every edge (check_planar_mesh_cdt, the "
      "older check) instead of the boundary-winding check; for tests and benchmarks.");

  m.def(
      "quality_summary",
      [](const Float_array& points, const Int_array& triangles) {
        auto [pts, tris] = to_points_and_triangles(points, triangles);
        Quality_summary s;
        {
          py::gil_scoped_release release;
          s = quality_summary(pts, tris);
        }
        py::array_t<std::int64_t> hist(18);
        std::copy(s.histogram.begin(), s.histogram.end(), hist.mutable_data());
        return py::make_tuple(s.min_angle, s.max_angle, s.max_radius_edge, s.sum_radius_edge, s.worst, hist);
      },
      py::arg("points"), py::arg("triangles"),
      "(min angle, max angle, max radius-edge, sum of radius-edge, first triangle with the min angle, angle "
      "histogram in 18 bins of 10 degrees): quality()'s figures in one parallel pass.");

  m.def(
      "first_inverted_triangle",
      [](const Float_array& points, const Int_array& triangles) {
        require_shape(points, 2, "points");
        require_shape(triangles, 3, "triangles");
        py::gil_scoped_release release;  // (the arrays stay alive: the caller holds them)
        return first_inverted_triangle(reinterpret_cast<const Vec2*>(points.data()), static_cast<std::size_t>(points.shape(0)),
                                       reinterpret_cast<const Triangle*>(triangles.data()),
                                       static_cast<std::size_t>(triangles.shape(0)));
      },
      py::arg("points"), py::arg("triangles"),
      "The first triangle with zero or negative area in floating point, -1 for none (check_mesh_limits).");

  m.def(
      "first_flat_triangles",
      [](const Float_array& points, const Int_array& triangles, double min_relative_height, double min_height_ulps) {
        require_shape(points, 2, "points");
        require_shape(triangles, 3, "triangles");
        std::array<Index, 2> first;
        {
          py::gil_scoped_release release;
          first = first_flat_triangles(reinterpret_cast<const Vec2*>(points.data()), static_cast<std::size_t>(points.shape(0)),
                                       reinterpret_cast<const Triangle*>(triangles.data()),
                                       static_cast<std::size_t>(triangles.shape(0)), min_relative_height,
                                       min_height_ulps);
        }
        return py::make_tuple(first[0], first[1]);
      },
      py::arg("points"), py::arg("triangles"), py::arg("min_relative_height"), py::arg("min_height_ulps"),
      "(first thin triangle, first coarse triangle), -1 for none: Mesh()'s flatness limits (mesh.py).");

  m.def(
      "first_pinched_boundary",
      [](const Float_array& points, const Int_array& boundary, const Byte_array& corner, double min_ulps) {
        auto pts = to_points(points);
        auto edges = to_index_rows<2>(boundary, "boundary");
        require_indices(edges, pts.size(), "boundary");
        if (corner.ndim() != 1 || static_cast<std::size_t>(corner.shape(0)) != pts.size()) {
          throw Input_error("corner must have one entry per point");
        }
        std::vector<char> is_corner(corner.data(), corner.data() + corner.shape(0));
        std::array<Index, 2> first;
        {
          py::gil_scoped_release release;
          first = first_pinched_boundary(pts, edges, is_corner, min_ulps);
        }
        return py::make_tuple(first[0], first[1]);
      },
      py::arg("points"), py::arg("boundary"), py::arg("corner"), py::arg("min_ulps"),
      "(boundary edge, corner) of the first place where a boundary corner not at the edge's ends lies closer to it "
      "than min_ulps units of rounding, (-1, -1) for none: Mesh()'s limit on gaps outside the domain (mesh.py).");

  m.def(
      "nn_spacing",
      [](const Float_array& points, std::optional<Int_array> triangles, std::optional<Float_array> euclidean) {
        auto pts = to_points(points);
        std::vector<Triangle> tris;
        if (triangles) {
          tris = to_index_rows<3>(*triangles, "triangles");
          require_indices(tris, pts.size(), "triangles");
        }
        std::vector<double> nn;
        if (euclidean) {
          nn = to_vector<double>(*euclidean);
          if (nn.size() != pts.size()) throw Input_error("euclidean: one value per point");
        }
        {
          py::gil_scoped_release release;
          if (!euclidean) nn = nn_spacing(pts);
          if (triangles) keep_within_domain(pts, tris, nn);
        }
        return vector_array(nn);
      },
      py::arg("points"), py::arg("triangles") = py::none(), py::arg("euclidean") = py::none(),
      "nn_M: the distance from every point to the nearest other point; with the triangles, within the domain "
      "(a point whose nearest point is no edge neighbour gets its shortest edge, local_feature_size.hpp). "
      "`euclidean`: the Euclidean distances if already known.");

  m.def(
      "edge_over_size_around",
      [](const Float_array& points, const Int_array& triangles, const Float_array& h) {
        auto [pts, tris] = to_points_and_triangles(points, triangles);
        auto values = to_vector<double>(h);
        if (values.size() != pts.size()) throw Input_error("h: one value per point");
        std::vector<double> around;
        {
          py::gil_scoped_release release;
          around = edge_over_size_around(pts, tris, values);
        }
        return vector_array(around);
      },
      py::arg("points"), py::arg("triangles"), py::arg("h"),
      "L(p) of delta_from_size: the mean of edge length over the request h around each point (size_request.hpp).");

  m.def(
      "edge_over_size_classes",
      [](const Float_array& points, const Int_array& triangles, const Float_array& h, double above, double below,
         double at_least) {
        auto [pts, tris] = to_points_and_triangles(points, triangles);
        auto values = to_vector<double>(h);
        if (values.size() != pts.size()) throw Input_error("h: one value per point");
        std::vector<std::uint8_t> classes;
        {
          py::gil_scoped_release release;
          classes = edge_over_size_classes(pts, tris, values, above, below, at_least);
        }
        return vector_array(classes);
      },
      py::arg("points"), py::arg("triangles"), py::arg("h"), py::arg("above"), py::arg("below"), py::arg("at_least"),
      "Bits per point (uint8): 1 where L > above, 2 where L < below, 4 where L >= at_least, exactly as "
      "edge_over_size_around's L compares, without most of its hypot calls (size_request.hpp).");

  m.def(
      "delta_from_size",
      [](const Float_array& points, const Int_array& triangles, const Float_array& h, const Float_array& nn,
         bool keep_fine_clusters, double delta_min, double delta_max, std::optional<std::size_t> n_checked,
         std::optional<Int_array> ids) {
        auto [pts, tris] = to_points_and_triangles(points, triangles);
        auto values = to_vector<double>(h);
        auto spacing = to_vector<double>(nn);
        if (values.size() != pts.size() || spacing.size() != pts.size()) throw Input_error("h, nn: one value per point");
        const std::size_t checked = n_checked.value_or(pts.size());
        if (checked > pts.size()) throw Input_error("n_checked: at most the number of points");
        std::vector<std::int64_t> names;
        if (ids) {
          names = to_vector<std::int64_t>(*ids);
          if (names.size() < checked) throw Input_error("ids: one id per checked point");
        }
        std::vector<double> delta;
        {
          py::gil_scoped_release release;
          delta = delta_from_size(pts, tris, values, spacing, keep_fine_clusters, delta_min, delta_max, checked,
                                  ids ? &names : nullptr);
        }
        return vector_array(delta);
      },
      py::arg("points"), py::arg("triangles"), py::arg("h"), py::arg("nn"), py::arg("keep_fine_clusters"),
      py::arg("delta_min"), py::arg("delta_max"), py::arg("n_checked") = py::none(), py::arg("ids") = py::none(),
      "size= as delta, the one rule of every scope (size_request.hpp): delta at every point, the first n_checked "
      "(default: all) checked to lie in [delta_min, delta_max] (ValueError naming the point by its id).");
  m.attr("SIZE_RULE_RINGS") = Size_rule::rings;

  m.def(
      "check_size_delta",
      [](const Float_array& delta, const Float_array& h, const Float_array& nn, double delta_min, double delta_max) {
        auto d = to_vector<double>(delta);
        auto values = to_vector<double>(h);
        auto spacing = to_vector<double>(nn);
        if (values.size() != d.size() || spacing.size() != d.size()) throw Input_error("delta, h, nn: one value each");
        check_size_delta(d, values, spacing, delta_min, delta_max, d.size());
      },
      py::arg("delta"), py::arg("h"), py::arg("nn"), py::arg("delta_min"), py::arg("delta_max"),
      "delta_from_size's check of h / nn as delta (ValueError for the first point outside [delta_min, delta_max]).");

  m.def(
      "near_seeds",
      [](const Int_array& triangles, const Byte_array& points, const Byte_array& seeds, int rings,
         std::optional<Byte_array> through) {
        auto tris = to_index_rows<3>(triangles, "triangles");
        auto marked = to_vector<std::uint8_t>(points);
        auto from = to_vector<std::uint8_t>(seeds);
        std::optional<std::vector<std::uint8_t>> via;
        if (through) via = to_vector<std::uint8_t>(*through);
        if (marked.size() != from.size() || (via && via->size() != marked.size()))
          throw Input_error("points, seeds and through: one value per point each");
        require_indices(tris, marked.size(), "triangles");
        if (rings < 0) throw Input_error("rings must be >= 0");
        std::vector<std::uint8_t> near;
        {
          py::gil_scoped_release release;
          near = near_seeds(tris, marked, from, rings, via ? &*via : nullptr);
        }
        return vector_array(near);
      },
      py::arg("triangles"), py::arg("points"), py::arg("seeds"), py::arg("rings"), py::arg("through") = py::none(),
      "Of the marked points, those within `rings` edges of a seed, through points marked in `through` if given "
      "(uint8 mask; size_request.hpp).");

  m.def(
      "sharing_a_triangle",
      [](const Int_array& triangles, const Byte_array& marked) {
        auto tris = to_index_rows<3>(triangles, "triangles");
        auto mask = to_vector<std::uint8_t>(marked);
        require_indices(tris, mask.size(), "triangles");
        std::vector<std::uint8_t> sharing;
        {
          py::gil_scoped_release release;
          sharing = sharing_a_triangle(tris, mask);
        }
        return vector_array(sharing);
      },
      py::arg("triangles"), py::arg("marked"),
      "Of the marked points, those sharing a triangle with another marked point (uint8 mask; size_request.hpp).");

  m.def(
      "nn_within_domain",
      [](const Float_array& points, const Int_array& triangles, std::optional<Float_array> euclidean) {
        auto [pts, tris] = to_points_and_triangles(points, triangles);
        std::vector<double> nn;
        if (euclidean) {
          nn = to_vector<double>(*euclidean);
          if (nn.size() != pts.size()) throw Input_error("euclidean: one value per point");
        }
        std::vector<Index> grew;
        {
          py::gil_scoped_release release;
          if (!euclidean) nn = nn_spacing(pts);
          const auto changed = keep_within_domain(pts, tris, nn);
          for (std::size_t i = 0; i < changed.size(); ++i) {
            if (changed[i]) grew.push_back(static_cast<Index>(i));
          }
        }
        return py::make_tuple(vector_array(nn), vector_array(grew));
      },
      py::arg("points"), py::arg("triangles"), py::arg("euclidean") = py::none(),
      "(nn_M within the domain, the points where it exceeds the Euclidean distance): what Mesh keeps for its "
      "steps (nn_spacing with triangles, and where keep_within_domain changed it).");

  py::class_<Spacing_function>(m, "SpacingFunction")
      .def(py::init([](const Float_array& sites, const Float_array& weights, std::size_t min_sites_per_part,
                       std::optional<Int_array> triangles, std::optional<Int_array> site_ids, double shift) {
             auto s = to_points(sites, "sites");
             auto w = to_vector<double>(weights);
             std::vector<Triangle> t;
             if (triangles) {
               t = to_index_rows<3>(*triangles, "triangles");
               require_indices(t, s.size(), "triangles");
             }
             std::vector<std::int64_t> ids;
             if (site_ids) {
               ids = to_vector<std::int64_t>(*site_ids);
               if (ids.size() != s.size()) throw py::value_error("site_ids: one id per site is required");
               auto sorted_ids = ids;
               std::sort(sorted_ids.begin(), sorted_ids.end());
               if (std::adjacent_find(sorted_ids.begin(), sorted_ids.end()) != sorted_ids.end()) {
                 throw py::value_error("site_ids must be distinct");
               }
             }
             py::gil_scoped_release release;
             return std::make_unique<Spacing_function>(s, w, min_sites_per_part, triangles ? &t : nullptr,
                                                       site_ids ? &ids : nullptr, shift);
           }),
           py::arg("sites"), py::arg("weights"), py::arg("min_sites_per_part") = 0, py::arg("triangles") = py::none(),
           py::arg("site_ids") = py::none(), py::arg("shift") = 0.0,
           "site_ids (optional, int64, distinct): global ids of the sites; exact ties of f go to the site of lowest "
           "id (else of lowest index). shift (optional, >= every weight; 0: the largest weight): graphs over "
           "different site sets that must agree bit for bit pass the same one (a distributed mesh's largest weight).")
      .def(
          "evaluate",
          [](const Spacing_function& self, const Float_array& queries, int threads, bool certified) {
            auto q = to_points(queries, "x");
            std::vector<double> f(q.size());
            std::vector<Index> site(q.size());
            {
              py::gil_scoped_release release;
              self.evaluate(q.data(), q.size(), f.data(), site.data(), threads, certified);
            }
            return py::make_tuple(vector_array(f), vector_array(site));
          },
          py::arg("x"), py::arg("threads") = 0, py::arg("certified") = true)
      .def_property_readonly("n_sites", &Spacing_function::n_sites)
      .def_property_readonly("n_hidden", &Spacing_function::n_hidden)
      .def_property_readonly("n_filtered", &Spacing_function::n_filtered)
      .def_property_readonly("n_parts", &Spacing_function::n_parts);

  m.def(
      "lexical_first_mis",
      [](const Float_array& centers, const Float_array& radii, const Int_array& order, std::size_t n_forced) {
        auto c = to_points(centers, "centers");
        auto r = to_vector<double>(radii);
        auto o = to_vector<Index>(order);
        std::vector<std::uint8_t> kept;
        {
          py::gil_scoped_release release;
          kept = lexical_first_mis(c, r, o, n_forced);
        }
        return vector_array(kept);
      },
      py::arg("centers"), py::arg("radii"), py::arg("order"), py::arg("n_forced") = 0);

  m.def(
      "packing_order",
      [](const Byte_array& classes, const Float_array& radii) {
        return vector_array(packing_order(to_vector<std::uint8_t>(classes), to_vector<double>(radii)));
      },
      py::arg("classes"), py::arg("radii"));

  // Step 1 of FRFC as the serial step computes it (step_weights, step_spacing
  // with Lemma 3.1): the reference the distributed step 1 must equal.
  m.def(
      "step_spacing",
      [](const Float_array& points, const Int_array& triangles, const Int_array& segments,
         const Byte_array& segment_is_boundary, const Byte_array& kind, const Float_array& delta, bool within_domain,
         std::optional<Int_array> segment_tags, std::optional<Byte_array> required, std::optional<Float_array> nn,
         std::optional<Int_array> nn_grew, std::optional<Int_array> point_gids, std::optional<Int_array> triangle_gids,
         std::optional<Int_array> segment_keys) {
        Mesh_arrays mesh = to_mesh(points, triangles, segments, segment_is_boundary, kind);
        add_labels(mesh, segment_tags, std::nullopt, required);
        add_known_nn(mesh, nn, nn_grew);
        add_global_ids(mesh, point_gids, triangle_gids, segment_keys);
        auto d = to_vector<double>(delta);
        if (d.size() != mesh.points.size()) throw Input_error("delta: one value per point");
        Step_weights weights;
        Step_spacing spacing;
        {
          py::gil_scoped_release release;
          std::vector<std::pair<std::string, double>> seconds;
          detail::Stage_timer timer(seconds, false);
          const auto chains = segment_chains(mesh);
          weights = step_weights(mesh, d, timer, within_domain ? &chains : nullptr);
          spacing = step_spacing(mesh, d, F_at_points::lemma_3_1, 0, timer, within_domain ? &chains : nullptr, true);
        }
        py::dict out;
        out["nn"] = vector_array(spacing.nn);
        out["weight"] = vector_array(weights.weight);
        out["f"] = vector_array(spacing.f);
        return out;
      },
      py::arg("points"), py::arg("triangles"), py::arg("segments"), py::arg("segment_is_boundary"), py::arg("kind"),
      py::arg("delta"), py::arg("within_domain") = true, py::arg("segment_tags") = py::none(),
      py::arg("required") = py::none(), py::arg("nn") = py::none(), py::arg("nn_grew") = py::none(),
      py::arg("point_gids") = py::none(), py::arg("triangle_gids") = py::none(), py::arg("segment_keys") = py::none(),
      "FRFC's step 1 (nn, weights w = delta nn capped by the local feature size, f at the points by Lemma 3.1), "
      "as the serial step computes it.");

  // The chains of segments of a mesh's segment skeleton (its points on segments
  // and its segments, in global-id order), what a rank needs of them.
  m.def(
      "chain_table",
      [](const Float_array& points, const Int_array& segments, const Byte_array& segment_is_boundary,
         const Byte_array& kind, std::optional<Int_array> segment_tags, std::optional<Byte_array> required,
         std::optional<Int_array> point_gids, std::optional<Int_array> segment_keys,
         std::optional<Int_array> curved_tags, double corner_angle, std::optional<py::function> project) {
        Mesh_arrays mesh;
        mesh.points = to_points(points);
        mesh.segments = to_index_rows<2>(segments, "segments");
        require_indices(mesh.segments, mesh.points.size(), "segments");
        mesh.segment_is_boundary = to_vector<std::uint8_t>(segment_is_boundary);
        if (mesh.segment_is_boundary.size() != mesh.segments.size()) throw Input_error("one boundary flag per segment");
        mesh.kind = to_kinds(kind);
        if (mesh.kind.size() != mesh.points.size()) throw Input_error("kind must have one value per point");
        add_labels(mesh, segment_tags, std::nullopt, required);
        add_global_ids(mesh, point_gids, std::nullopt, segment_keys);
        mesh.geometry = to_geometry(curved_tags, corner_angle, project);  // (chains end where curves turn)
        std::vector<Segment_chain> chains;
        {
          py::gil_scoped_release release;
          chains = segment_chains(mesh);
        }
        const std::size_t k = mesh.segments.size(), n = mesh.points.size();
        std::vector<std::int64_t> chain_of(k, -1);
        std::vector<std::int64_t> ends(2 * chains.size());
        std::vector<std::uint8_t> closed(chains.size());
        std::vector<Index> v, u, w;
        std::vector<std::uint8_t> along, two_sided;
        std::vector<std::int64_t> chain_of_point;
        std::vector<double> corner(n, std::numeric_limits<double>::infinity()), curve_cap;
        for (std::size_t c = 0; c < chains.size(); ++c) {
          const auto& chain = chains[c];
          const bool on_curve = mesh.geometry && mesh.geometry->is_curved(chain.tag);
          for (Index s : chain.segments) chain_of[s] = static_cast<std::int64_t>(c);
          ends[2 * c] = chain.vertices.front();
          ends[2 * c + 1] = chain.vertices.back();
          closed[c] = chain.closed;
          // as local_feature_size lists them
          for (std::size_t i = 1; i < chain.segments.size(); ++i) {
            v.push_back(chain.vertices[i]);
            u.push_back(chain.vertices[i - 1]);
            w.push_back(chain.closed && i + 1 == chain.vertices.size() ? chain.vertices[0] : chain.vertices[i + 1]);
            along.push_back(chain.forward[i]);
            two_sided.push_back(!chain.boundary);
            chain_of_point.push_back(static_cast<std::int64_t>(c));
            curve_cap.push_back(on_curve ? curve_turn_cap(mesh.points[u.back()], mesh.points[v.back()],
                                                          mesh.points[w.back()], mesh.geometry->corner_angle)
                                         : std::numeric_limits<double>::infinity());
          }
          if (!chain.closed && !on_curve) {  // the corners' rule of local_feature_size
            const Index a = chain.vertices.front(), b = chain.vertices.back();
            const double d = std::hypot(mesh.points[b][0] - mesh.points[a][0], mesh.points[b][1] - mesh.points[a][1]);
            corner[a] = std::min(corner[a], d);
            corner[b] = std::min(corner[b], d);
          }
        }
        py::dict out;
        out["segment_chain"] = vector_array(chain_of);
        out["chain_ends"] = vector_array(ends);
        out["chain_closed"] = vector_array(closed);
        out["point"] = vector_array(v);
        out["before"] = vector_array(u);
        out["after"] = vector_array(w);
        out["along"] = vector_array(along);
        out["two_sided"] = vector_array(two_sided);
        out["point_chain"] = vector_array(chain_of_point);
        out["corner_feature_size"] = vector_array(corner);
        out["curve_cap"] = vector_array(curve_cap);
        return out;
      },
      py::arg("points"), py::arg("segments"), py::arg("segment_is_boundary"), py::arg("kind"),
      py::arg("segment_tags") = py::none(), py::arg("required") = py::none(), py::arg("point_gids") = py::none(),
      py::arg("segment_keys") = py::none(), py::arg("curved_tags") = py::none(),
      py::arg("corner_angle") = kDefaultCornerAngle, py::arg("project") = py::none(),
      "segment_chains of a segment skeleton: the chain of each segment, each chain's end points (2 per chain, "
      "local indices) and closed flag, the points inside chains with their neighbours as local_feature_size walks "
      "from them, the cap a curved chain (a geometry: curved_tags, corner_angle, project) puts on them (curve_turn_cap, +inf off curves), and the "
      "corners' feature size (+inf elsewhere).");

  m.def(
      "chain_feature_sizes",
      [](const Float_array& points, const Int_array& triangles, const Int_array& triangle_gids,
         const Int_array& segments, const Int_array& segment_chain, const Int_array& chain_ids,
         const Int_array& chain_ends, const Int_array& point, const Int_array& before, const Int_array& after,
         const Byte_array& along, const Byte_array& two_sided, const Int_array& point_chain, const Float_array& limit) {
        Mesh_arrays part;
        part.points = to_points(points);
        part.triangles = to_index_rows<3>(triangles, "triangles");
        part.segments = to_index_rows<2>(segments, "segments");
        require_indices(part.triangles, part.points.size(), "triangles");
        require_indices(part.segments, part.points.size(), "segments");
        add_global_ids(part, std::nullopt, triangle_gids, std::nullopt);
        const auto ids = to_vector<std::int64_t>(chain_ids);
        const auto end_rows = to_index_rows<2>(chain_ends, "chain_ends");
        if (end_rows.size() != ids.size()) throw Input_error("chain_ends: one row per chain id");
        std::unordered_map<std::int64_t, std::array<std::int64_t, 2>> ends;
        for (std::size_t c = 0; c < ids.size(); ++c) ends[ids[c]] = {end_rows[c][0], end_rows[c][1]};
        const auto v = to_vector<Index>(point), u = to_vector<Index>(before), w = to_vector<Index>(after);
        const auto a = to_vector<std::uint8_t>(along), t = to_vector<std::uint8_t>(two_sided);
        if (u.size() != v.size() || w.size() != v.size() || a.size() != v.size() || t.size() != v.size()) {
          throw Input_error("chain_feature_sizes: point, before, after, along and two_sided must have one row each");
        }
        std::vector<Chain_point> queries(v.size());
        for (std::size_t k = 0; k < v.size(); ++k) queries[k] = Chain_point{v[k], u[k], w[k], a[k] != 0, t[k] != 0};
        std::vector<double> lfs;
        std::vector<std::uint8_t> certified;
        {
          py::gil_scoped_release release;
          lfs = chain_feature_sizes(part, queries, to_vector<std::int64_t>(point_chain),
                                    to_vector<std::int64_t>(segment_chain), ends, to_vector<double>(limit), certified);
        }
        return py::make_tuple(vector_array(lfs), to_array(std::move(certified)));
      },
      py::arg("points"), py::arg("triangles"), py::arg("triangle_gids"), py::arg("segments"),
      py::arg("segment_chain"), py::arg("chain_ids"), py::arg("chain_ends"), py::arg("point"), py::arg("before"),
      py::arg("after"), py::arg("along"), py::arg("two_sided"), py::arg("point_chain"), py::arg("limit"),
      "The walks of the local feature size on a part of a mesh (local_feature_size.hpp: chain_feature_sizes): "
      "(lfs, certified) per query; certified 0 where a walk reached the part's border.");

  // A rank's part of a mesh for the stages of a distributed step
  // (python/evomesh/distributed/step.py): the held points and triangles with their
  // global ids, and the whole segment skeleton, in global-id order.
  const auto part_mesh = [](const py::dict& part) {
    Mesh_arrays mesh = to_mesh(part["points"].cast<Float_array>(), part["triangles"].cast<Int_array>(),
                               part["segments"].cast<Int_array>(), part["segment_is_boundary"].cast<Byte_array>(),
                               part["kind"].cast<Byte_array>());
    add_labels(mesh, part["segment_tags"].cast<Int_array>(), std::nullopt, part["required"].cast<Byte_array>());
    add_global_ids(mesh, part["point_gids"].cast<Int_array>(), part["triangle_gids"].cast<Int_array>(),
                   part["segment_keys"].cast<Int_array>());
    if (part.contains("curved_tags")) {  // a boundary geometry (geometry.BoundaryGeometry._core_arguments)
      mesh.geometry = to_geometry(part["curved_tags"].cast<Int_array>(), part["corner_angle"].cast<double>(),
                                  part["project"].cast<py::function>());
    }
    return mesh;
  };
  const auto per_point = [](const Float_array& values, const Mesh_arrays& mesh, const char* name) {
    auto v = to_vector<double>(values);
    if (v.size() != mesh.points.size()) throw Input_error(std::string(name) + ": one value per point of the part");
    return v;
  };

  // Optional flags per point of a part (None: the serial default, none set).
  const auto part_flags = [](const std::optional<Byte_array>& flags, const Mesh_arrays& mesh, const char* name) {
    std::vector<std::uint8_t> v = flags ? to_vector<std::uint8_t>(*flags) : std::vector<std::uint8_t>();
    if (flags && v.size() != mesh.points.size()) {
      throw Input_error(std::string(name) + ": one flag per point of the part");
    }
    if (!flags) v.assign(mesh.points.size(), 0);
    return v;
  };

  m.def(
      "part_input_spheres",
      [part_mesh, per_point, part_flags](const py::dict& part, const Float_array& f, const Frfc_options& options,
                                         const std::optional<Byte_array>& demoted) {
        const Mesh_arrays mesh = part_mesh(part);
        const auto fv = per_point(f, mesh, "f");
        const auto d = part_flags(demoted, mesh, "demoted");
        const auto chains = segment_chains(mesh);
        std::size_t n_forced = 0;
        const auto forced = forced_corners(mesh, chains, n_forced, mesh.required);
        std::vector<std::uint8_t> classes(mesh.points.size());
        for (std::size_t i = 0; i < classes.size(); ++i) {
          classes[i] = old_point_class(mesh.kind[i], forced[i] != 0, d[i] != 0);
        }
        return py::make_tuple(vector_array(input_point_radii(mesh, fv, options)), vector_array(classes),
                              vector_array(forced));
      },
      py::arg("part"), py::arg("f"), py::arg("options"), py::arg("demoted") = py::none(),
      "FRFC's first pass at the input points of a part: (radius, packing class, forced) per point; `demoted` "
      "(optional, one flag per point): the demoted points (part_point_flags), packed with the new points.");

  m.def(
      "part_point_flags",
      [part_mesh, per_point](const py::dict& part, const Float_array& nn, const Float_array& f,
                             const Float_array& delta, const Frfc_options& options) {
        const Mesh_arrays mesh = part_mesh(part);
        const auto nv = per_point(nn, mesh, "nn"), fv = per_point(f, mesh, "f"), d = per_point(delta, mesh, "delta");
        const auto chains = segment_chains(mesh);
        std::size_t n_forced = 0;
        const auto forced = forced_corners(mesh, chains, n_forced, mesh.required);
        auto demoted = demoted_points(mesh.triangles, nv, fv, forced, options.demote_ratio);
        auto settled = settled_points(mesh, d, fv);
        return py::make_tuple(to_array(std::move(demoted)), to_array(std::move(settled)));
      },
      py::arg("part"), py::arg("nn"), py::arg("f"), py::arg("delta"), py::arg("options"),
      "The demoted (demoted_points, options.demote_ratio) and settled (settled_points) flags of the points of a "
      "part: (demoted, settled), each exact at the points whose every triangle the part holds (a rank's owned "
      "points); the others' come from their owners.");

  m.def(
      "part_asking_spacing",
      [part_mesh, per_point](const py::dict& part, const Float_array& f, double cell_factor) {
        const Mesh_arrays mesh = part_mesh(part);
        const auto fv = per_point(f, mesh, "f");
        std::vector<std::uint8_t> triangles(mesh.triangles.size()), segments(mesh.segments.size());
        for (std::size_t t = 0; t < triangles.size(); ++t) triangles[t] = asks_spacing(mesh, fv, mesh.triangles[t], cell_factor);
        for (std::size_t s = 0; s < segments.size(); ++s) segments[s] = asks_spacing(mesh, fv, mesh.segments[s], cell_factor);
        return py::make_tuple(to_array(std::move(triangles)), to_array(std::move(segments)));
      },
      py::arg("part"), py::arg("f"), py::arg("cell_factor"),
      "Which triangles and segments of a part have adaptive grids that ask f at points of their bounding box "
      "(asks_spacing): (per triangle, per segment) flags.");

  m.def(
      "part_segment_candidates",
      [part_mesh, per_point, part_flags](const py::dict& part, const Float_array& delta, const Float_array& f,
                                         const Frfc_options& options, const std::optional<Byte_array>& settled,
                                         const Spacing_function* spacing) {
        const Mesh_arrays mesh = part_mesh(part);
        const auto d = per_point(delta, mesh, "delta"), fv = per_point(f, mesh, "f");
        const auto s = part_flags(settled, mesh, "settled");
        Candidates c;
        {
          py::gil_scoped_release release;
          const Spacing_queries queries = spacing != nullptr ? spacing_queries(*spacing) : Spacing_queries();
          c = segment_candidates(mesh, d, fv, segment_chains(mesh), options, spacing != nullptr ? &queries : nullptr,
                                 settled ? &s : nullptr);
        }
        return py::make_tuple(points_array(c.samples.points), vector_array(c.samples.parent),
                              vector_array(c.classes(true)), vector_array(c.owner));
      },
      py::arg("part"), py::arg("delta"), py::arg("f"), py::arg("options"), py::arg("settled") = py::none(),
      py::arg("spacing") = py::none(),
      "FRFC's candidates on every segment of a part (its segments are the whole skeleton): (centres, parent "
      "segment, packing class, ring owner), in the serial step's order; ring owner: the part index of a segment "
      "ring candidate's R-point, -1 for a grid sample. `settled` (optional): the points' settled flags "
      "(default: settled_points on the part); `spacing` (optional): f for the adaptive grids that ask it.");

  m.def(
      "part_interior_candidates",
      [part_mesh, per_point, part_flags](const py::dict& part, const Float_array& delta, const Float_array& f,
                                         const Frfc_options& options, const Byte_array& sampled,
                                         const std::optional<Byte_array>& demoted,
                                         const std::optional<Byte_array>& settled,
                                         const std::optional<Byte_array>& ring_from,
                                         const Spacing_function* spacing) {
        const Mesh_arrays mesh = part_mesh(part);
        const auto d = per_point(delta, mesh, "delta"), fv = per_point(f, mesh, "f");
        const auto dem = part_flags(demoted, mesh, "demoted");
        const auto s = part_flags(settled, mesh, "settled");
        const auto from = part_flags(ring_from, mesh, "ring_from");
        auto quiet = to_vector<std::uint8_t>(sampled);
        if (quiet.size() != mesh.triangles.size()) throw Input_error("sampled: one flag per triangle of the part");
        for (auto& q : quiet) q = q ? 0 : 1;
        Candidates c;
        std::vector<Index> ring_point;
        std::size_t n_drawn = 0;
        {
          py::gil_scoped_release release;
          const Triangle_fans fans(mesh);
          const Spacing_queries queries = spacing != nullptr ? spacing_queries(*spacing) : Spacing_queries();
          c = interior_candidates(mesh, fans, d, fv, dem, Cover_discs{}, options, n_drawn, &quiet,
                                  spacing != nullptr ? &queries : nullptr, settled ? &s : nullptr, &from, &ring_point);
        }
        const std::size_t n_grid = c.size() - ring_point.size();
        std::vector<Index> point(c.size(), -1);
        std::copy(ring_point.begin(), ring_point.end(), point.begin() + static_cast<std::ptrdiff_t>(n_grid));
        return py::make_tuple(points_array(c.samples.points), vector_array(c.samples.parent),
                              vector_array(c.classes(false)), vector_array(point));
      },
      py::arg("part"), py::arg("delta"), py::arg("f"), py::arg("options"), py::arg("sampled"),
      py::arg("demoted") = py::none(), py::arg("settled") = py::none(), py::arg("ring_from") = py::none(),
      py::arg("spacing") = py::none(),
      "FRFC's candidates inside the triangles of a part flagged in `sampled`: (centres, parent triangle, class, "
      "ring point), in the serial step's order (the grid samples by triangle id, then draw; then the ring "
      "candidates by R-point id, then direction). Optional, one flag per point: `demoted`, `settled` (default: "
      "settled_points on the part), `ring_from` (the R-points that offer ring candidates; default none); "
      "`spacing`: f for the adaptive grids that ask it. ring point: the part index of a ring candidate's R-point, "
      "-1 for a grid sample.");

  m.def(
      "part_candidate_radii",
      [part_mesh, per_point, part_flags](const py::dict& part, const Float_array& f, const Spacing_function* spacing,
                                         const Frfc_options& options, bool on_segment, const Float_array& centres,
                                         const Int_array& parent, const std::optional<Byte_array>& demoted) {
        const Mesh_arrays mesh = part_mesh(part);
        const auto fv = per_point(f, mesh, "f");
        const auto dem = part_flags(demoted, mesh, "demoted");
        if (spacing == nullptr && options.radius != Radius_rule::cheap) {
          throw Input_error("part_candidate_radii: a spacing function is needed unless radius is 'cheap'");
        }
        Candidates c;
        c.samples.points = to_points(centres, "centres");
        for (Index p : to_vector<Index>(parent)) {
          const std::size_t limit = on_segment ? mesh.segments.size() : mesh.triangles.size();
          if (p < 0 || static_cast<std::size_t>(p) >= limit) throw Input_error("parent out of range");
          c.samples.parent.push_back(static_cast<std::uint32_t>(p));
        }
        if (c.samples.parent.size() != c.samples.points.size()) throw Input_error("one parent per centre");
        {
          py::gil_scoped_release release;
          // (cheap radii read f at the vertices only: any spacing function will do)
          if (spacing != nullptr) {
            candidate_radii(mesh, *spacing, fv, dem, options, on_segment, c);
          } else {
            const Spacing_function unused(std::vector<Vec2>{{0.0, 0.0}}, std::vector<double>{0.0});
            candidate_radii(mesh, unused, fv, dem, options, on_segment, c);
          }
        }
        return vector_array(c.radius);
      },
      py::arg("part"), py::arg("f"), py::arg("spacing"), py::arg("options"), py::arg("on_segment"),
      py::arg("centres"), py::arg("parent"), py::arg("demoted") = py::none(),
      "FRFC's sphere radii of candidates of a part (candidate_radii); `demoted` (optional): the demoted points "
      "(the interpolated rule's triangles and segments); `spacing` may be None for radius 'cheap'.");

  m.def(
      "part_curve_kinds",
      [part_mesh](const py::dict& part) {
        const Mesh_arrays mesh = part_mesh(part);
        if (!mesh.geometry) throw Input_error("part_curve_kinds: the part has no geometry");
        const Mesh_arrays with_curves = with_curve_kinds(mesh);
        std::vector<std::uint8_t> kind(with_curves.kind.size());
        for (std::size_t i = 0; i < kind.size(); ++i) kind[i] = static_cast<std::uint8_t>(with_curves.kind[i]);
        return to_array(std::move(kind));
      },
      py::arg("part"),
      "The kinds of a part's points with the corners of curved chains taken from its geometry "
      "(boundary_geometry.hpp: with_curve_kinds; only the segments are read).");

  m.def(
      "part_project_segment_candidates",
      [part_mesh](const py::dict& part, const Float_array& centres, const Int_array& parent, const Float_array& radius) {
        const Mesh_arrays mesh = part_mesh(part);
        if (!mesh.geometry) throw Input_error("part_project_segment_candidates: the part has no geometry");
        std::vector<Vec2> c = to_points(centres, "centres");
        std::vector<std::uint32_t> on;
        for (Index p : to_vector<Index>(parent)) {
          if (p < 0 || static_cast<std::size_t>(p) >= mesh.segments.size()) throw Input_error("parent out of range");
          on.push_back(static_cast<std::uint32_t>(p));
        }
        const auto r = to_vector<double>(radius);
        if (on.size() != c.size() || r.size() != c.size()) throw Input_error("one parent and radius per centre");
        const double largest = project_segment_candidates(mesh, on, 0, std::vector<std::uint8_t>(c.size(), 1), r, c);
        return py::make_tuple(points_array(c), largest);
      },
      py::arg("part"), py::arg("centres"), py::arg("parent"), py::arg("radius"),
      "Kept candidates on a part's segments moved onto their curves (project_segment_candidates; all of them "
      "kept): (centres, largest move).");

  // The spacing repair in rounds over ranks (python/evomesh/distributed/repair.py).
  m.def(
      "part_ring_candidates",
      [part_mesh, per_point](const py::dict& part, const Float_array& f, const Frfc_options& options,
                             const Int_array& points) {
        const Mesh_arrays mesh = part_mesh(part);
        const auto fv = per_point(f, mesh, "f");
        const auto at = to_vector<Index>(points);
        for (Index p : at) {
          if (p < 0 || static_cast<std::size_t>(p) >= mesh.points.size()) throw Input_error("points out of range");
        }
        std::vector<Vec2> xy;
        std::vector<Index> xadj{0};
        std::vector<std::uint8_t> direction;
        {
          py::gil_scoped_release release;
          const Triangle_fans fans(mesh);
          const double reach = ring_reach(options.radius_scale);
          std::array<Ring_candidate, kRingDirections> ring;
          for (Index p : at) {
            const int count = ring_candidates_of(mesh, fans, fv, reach, options.seed, static_cast<std::size_t>(p), ring);
            for (int k = 0; k < count; ++k) {
              xy.push_back(ring[k].x);
              direction.push_back(static_cast<std::uint8_t>(ring[k].round));
            }
            xadj.push_back(static_cast<Index>(xy.size()));
          }
        }
        return py::make_tuple(points_array(xy), vector_array(xadj), to_array(std::move(direction)));
      },
      py::arg("part"), py::arg("f"), py::arg("options"), py::arg("points"),
      "The interior ring candidates of the part's `points` (part indices, each with its whole fan held): "
      "(centres, xadj, direction), point i's being xadj[i]..xadj[i + 1], in direction order "
      "(ring_candidates_of, as the spacing repair regenerates them).");

  m.def(
      "repair_targets",
      [](double repair_ratio, const Float_array& delta, const Float_array& nn) {
        const auto d = to_vector<double>(delta), v = to_vector<double>(nn);
        if (d.size() != v.size()) throw Input_error("repair_targets: delta and nn must have one value each");
        std::vector<double> out(d.size());
        for (std::size_t i = 0; i < d.size(); ++i) out[i] = repair_target2(repair_ratio, d[i], v[i]);
        return vector_array(out);
      },
      py::arg("repair_ratio"), py::arg("delta"), py::arg("nn"),
      "The spacing repair's squared targets (repair_ratio delta nn)^2, as the serial step computes them.");

  m.def(
      "repair_kept_distances",
      [](const Float_array& kept, const Float_array& queries) {
        const auto k = to_points(kept, "kept"), q = to_points(queries, "queries");
        std::vector<double> nearest2, second2;
        {
          py::gil_scoped_release release;
          kept_distances(k, q, nearest2, second2);
        }
        return py::make_tuple(vector_array(nearest2), vector_array(second2));
      },
      py::arg("kept"), py::arg("queries"),
      "Squared distances from each query to its nearest and second nearest kept point (the spacing repair's "
      "kept-centre queries, the same values): (nearest2, second2), infinity where none.");

  m.def(
      "repair_decisions",
      [](const Float_array& at, const Float_array& target2, const Float_array& nn2, const Int_array& xadj,
         const Float_array& candidates, const Float_array& kept2, const Float_array& added) {
        const auto a = to_points(at, "at"), c = to_points(candidates, "candidates"), x = to_points(added, "added");
        const auto t = to_vector<double>(target2), n2 = to_vector<double>(nn2), k2 = to_vector<double>(kept2);
        const auto off = to_vector<Index>(xadj);
        if (t.size() != a.size() || n2.size() != a.size() || off.size() != a.size() + 1 || k2.size() != c.size() ||
            off.front() != 0 || static_cast<std::size_t>(off.back()) != c.size() ||
            !std::is_sorted(off.begin(), off.end())) {
          throw Input_error("repair_decisions: one target2 and nn2 per point, xadj (points + 1, from 0 to the "
                            "candidates, non-decreasing), one kept2 per candidate");
        }
        std::vector<Index> out;
        {
          py::gil_scoped_release release;
          out = decide_repairs(a, t, n2, off, c, k2, x);
        }
        return vector_array(out);
      },
      py::arg("at"), py::arg("target2"), py::arg("nn2"), py::arg("xadj"), py::arg("candidates"), py::arg("kept2"),
      py::arg("added"),
      "The spacing repair's decisions at needy points, in the order given (decide_repairs): per point the index "
      "of its chosen candidate among its own, -1 for none; each choice is seen by the later points.");

  m.def(
      "part_gap_candidates",
      [part_mesh](const py::dict& part, const Int_array& points, const Float_array& delta, const Float_array& nn,
                  std::uint64_t seed) {
        const Mesh_arrays mesh = part_mesh(part);
        const auto at = to_vector<Index>(points);
        const auto d = to_vector<double>(delta), v = to_vector<double>(nn);
        if (d.size() != at.size() || v.size() != at.size()) {
          throw Input_error("part_gap_candidates: one delta and nn per point");
        }
        for (Index p : at) {
          if (p < 0 || static_cast<std::size_t>(p) >= mesh.points.size()) throw Input_error("points out of range");
        }
        std::vector<Vec2> xy(at.size() * kGapDirections);
        std::vector<std::uint8_t> inside(at.size() * kGapDirections), left(at.size(), 0);
        {
          py::gil_scoped_release release;
          const Triangle_fans fans(mesh);
          const Mesh_walk walk(mesh, fans);
          for (std::size_t i = 0; i < at.size(); ++i) {
            const std::size_t p = static_cast<std::size_t>(at[i]);
            gap_directions(mesh.points[p], d[i] * v[i], seed, mesh.point_gid(p), &xy[i * kGapDirections]);
            for (int k = 0; k < kGapDirections; ++k) {
              bool out = false;
              const std::size_t j = i * kGapDirections + static_cast<std::size_t>(k);
              inside[j] = walk.locate_from(at[i], xy[j], 64, &out) >= 0;
              left[i] = left[i] || out;
            }
          }
        }
        return py::make_tuple(points_array(xy), to_array(std::move(inside)), to_array(std::move(left)));
      },
      py::arg("part"), py::arg("points"), py::arg("delta"), py::arg("nn"), py::arg("seed"),
      "The gap repair's directions at the part's `points` (gap_directions, kGapDirections each) and whether "
      "each lies inside the mesh seen from its point (Mesh_walk::locate_from): (centres (m k, 2), inside (m k), "
      "left (m): a walk of the point reached the part's border, so its answers are not the whole mesh's).");

  m.def(
      "gap_targets",
      [](const Float_array& delta, const Float_array& nn, const Byte_array& demoted, const Byte_array& kept,
         double gap_ratio, double refine_ratio) {
        const auto d = to_vector<double>(delta), v = to_vector<double>(nn);
        const auto dem = to_vector<std::uint8_t>(demoted), k = to_vector<std::uint8_t>(kept);
        if (v.size() != d.size() || dem.size() != d.size() || k.size() != d.size()) {
          throw Input_error("gap_targets: one delta, nn, demoted and kept flag each");
        }
        std::vector<double> out(d.size());
        for (std::size_t i = 0; i < d.size(); ++i) {
          out[i] = gap_target2(d[i], v[i], dem[i] != 0, k[i] != 0, gap_ratio, refine_ratio);
        }
        return vector_array(out);
      },
      py::arg("delta"), py::arg("nn"), py::arg("demoted"), py::arg("kept"), py::arg("gap_ratio"),
      py::arg("refine_ratio"), "The gap repair's squared bounds (gap_target2), as the serial step computes them.");

  m.def(
      "gap_decisions",
      [](const Float_array& at, const Float_array& delta, const Float_array& nn, const Byte_array& demoted,
         const Float_array& directions, const Byte_array& inside, const Float_array& kept2, double gap_ratio,
         double refine_ratio, const Float_array& added) {
        Gap_requests r;
        r.at = to_points(at, "at");
        r.delta = to_vector<double>(delta);
        r.nn = to_vector<double>(nn);
        r.demoted = to_vector<std::uint8_t>(demoted);
        r.directions = to_points(directions, "directions");
        r.inside = to_vector<std::uint8_t>(inside);
        r.kept2 = to_vector<double>(kept2);
        r.gap_ratio = gap_ratio;
        r.refine_ratio = refine_ratio;
        const std::size_t m = r.at.size(), k = kGapDirections;
        if (r.delta.size() != m || r.nn.size() != m || r.demoted.size() != m || r.directions.size() != m * k ||
            r.inside.size() != m * k || r.kept2.size() != 2 * m * (k + 1)) {
          throw Input_error("gap_decisions: per point one delta, nn, demoted flag, 16 directions and inside flags, "
                            "34 kept distances");
        }
        const auto x = to_points(added, "added");
        std::vector<Index> out;
        {
          py::gil_scoped_release release;
          out = decide_gaps(r, x);
        }
        return vector_array(out);
      },
      py::arg("at"), py::arg("delta"), py::arg("nn"), py::arg("demoted"), py::arg("directions"), py::arg("inside"),
      py::arg("kept2"), py::arg("gap_ratio"), py::arg("refine_ratio"), py::arg("added"),
      "The gap repair's decisions at open points, in the order given (decide_gaps): per point the direction it "
      "adds, -1 for none; each choice is seen by the later points.");

  m.def(
      "part_pieces",
      [part_mesh](const py::dict& part, const Int_array& candidate_segment, const Byte_array& kept_candidate,
                  const Byte_array& kept_point) {
        const Mesh_arrays mesh = part_mesh(part);
        const auto parent = to_vector<Index>(candidate_segment);
        const auto kept_c = to_vector<std::uint8_t>(kept_candidate);
        const auto kept_p = to_vector<std::uint8_t>(kept_point);
        if (kept_c.size() != parent.size()) throw Input_error("kept_candidate: one flag per candidate");
        if (kept_p.size() != mesh.points.size()) throw Input_error("kept_point: one flag per point of the part");
        const std::size_t n = mesh.points.size(), k = mesh.segments.size();
        // The candidates come grouped by segment in segment order, sorted along each (segment_candidates).
        std::vector<Index> begin(k + 1, 0);
        for (std::size_t j = 0; j < parent.size(); ++j) {
          if (parent[j] < 0 || static_cast<std::size_t>(parent[j]) >= k) throw Input_error("candidate_segment out of range");
          if (j > 0 && parent[j] < parent[j - 1]) throw Input_error("candidates must come grouped in segment order");
          ++begin[parent[j] + 1];
        }
        for (std::size_t s = 0; s < k; ++s) begin[s + 1] += begin[s];
        std::vector<Index> out_vertex(n, -1), out_on_segment(parent.size(), -1);
        for (std::size_t v = 0; v < n; ++v) {
          if (kept_p[v]) out_vertex[v] = static_cast<Index>(v);
        }
        for (std::size_t j = 0; j < parent.size(); ++j) {
          if (kept_c[j]) out_on_segment[j] = static_cast<Index>(n + j);
        }
        const auto pieces = constraint_pieces(segment_chains(mesh), out_vertex, begin, out_on_segment);
        std::vector<std::int64_t> ends(2 * pieces.size()), tags(pieces.size());
        std::vector<std::uint8_t> boundary(pieces.size());
        for (std::size_t i = 0; i < pieces.size(); ++i) {
          ends[2 * i] = pieces[i].a;
          ends[2 * i + 1] = pieces[i].b;
          boundary[i] = pieces[i].boundary;
          tags[i] = pieces[i].tag;
        }
        return py::make_tuple(vector_array(ends), to_array(std::move(boundary)), vector_array(tags));
      },
      py::arg("part"), py::arg("candidate_segment"), py::arg("kept_candidate"), py::arg("kept_point"),
      "The constraint pieces between the kept points along every chain of a part's segments (constraint_pieces): "
      "(ends (2k,) as part point index or n + candidate index, boundary, tag).");

  m.def(
      "part_parent_triangles",
      [](const Float_array& points, const Int_array& triangles, const Int_array& triangle_keys,
         const Float_array& queries, std::optional<Int_array> fallback) {
        auto [pts, tris] = to_points_and_triangles(points, triangles);
        const auto keys = to_vector<std::int64_t>(triangle_keys);
        if (keys.size() != tris.size()) throw Input_error("triangle_keys: one key per triangle");
        const auto q = to_points(queries, "queries");
        const auto other = fallback ? to_vector<Index>(*fallback) : std::vector<Index>(q.size(), -1);
        if (other.size() != q.size()) throw Input_error("fallback: one triangle (or -1) per query");
        for (Index t : other) {
          if (t >= static_cast<Index>(tris.size())) throw Input_error("fallback: triangle index out of range");
        }
        std::vector<Index> parent(q.size(), -1);
        std::vector<std::array<double, 3>> bary(q.size(), {0, 0, 0});
        {
          py::gil_scoped_release release;
          std::vector<Index> seed;
          std::vector<std::array<double, 3>> unused;
          locate_points(pts, tris, q, seed, unused);
          // The triangles around each point (compressed lists).
          std::vector<Index> xadj(pts.size() + 1, 0), adj(3 * tris.size());
          for (const auto& t : tris) {
            for (Index v : t) ++xadj[v + 1];
          }
          for (std::size_t v = 0; v < pts.size(); ++v) xadj[v + 1] += xadj[v];
          {
            std::vector<Index> fill(xadj.begin(), xadj.end() - 1);
            for (std::size_t t = 0; t < tris.size(); ++t) {
              for (Index v : tris[t]) adj[fill[v]++] = static_cast<Index>(t);
            }
          }
          // Every triangle that contains q (on its edges included) shares the
          // edge or vertex q lies on with the seed, so it is around one of the
          // seed's vertices: the least key among them is a function of q and the
          // mesh, not of the subset of triangles held. A q outside every
          // triangle by rounding gets the nearest of them (ties: least key).
          for (std::size_t k = 0; k < q.size(); ++k) {
            if (seed[k] < 0) {
              if (other[k] >= 0) {  // (outside by more than rounding: the caller's triangle)
                parent[k] = other[k];
                bary[k] = barycentric_coordinates(pts, tris[parent[k]], q[k]);
              }
              continue;
            }
            Index best = -1, nearest = -1;
            double nearest_gap = std::numeric_limits<double>::infinity();
            for (Index v : tris[seed[k]]) {
              for (Index a = xadj[v]; a < xadj[v + 1]; ++a) {
                const Index t = adj[a];
                const Triangle& tri = tris[t];
                bool inside = true;
                for (int e = 0; e < 3 && inside; ++e) inside = orientation(pts[tri[e]], pts[tri[(e + 1) % 3]], q[k]) >= 0;
                if (inside) {
                  if (best < 0 || keys[t] < keys[best]) best = t;
                  continue;
                }
                const double gap = distance_to_triangle(pts, tri, q[k]);
                if (gap < nearest_gap || (gap == nearest_gap && keys[t] < keys[nearest])) {
                  nearest_gap = gap;
                  nearest = t;
                }
              }
            }
            parent[k] = best >= 0 ? best : nearest;
            bary[k] = barycentric_coordinates(pts, tris[parent[k]], q[k]);  // (the parent map's formula, unclamped)
          }
        }
        Float_array b({static_cast<py::ssize_t>(bary.size()), py::ssize_t{3}});
        if (!bary.empty()) std::memcpy(b.mutable_data(), bary.data(), bary.size() * sizeof(bary[0]));
        return py::make_tuple(vector_array(parent), b);
      },
      py::arg("points"), py::arg("triangles"), py::arg("triangle_keys"), py::arg("queries"),
      py::arg("fallback") = py::none(),
      "The parent of each query in a part of an old mesh (distributed lineage): among the triangles containing it "
      "(exact orientation tests), the one of least key; outside every one by rounding, the nearest; farther "
      "than rounding outside (locate_points), fallback[k] (-1: none). Returns (triangle index or -1, barycentric coordinates (k, 3) in "
      "its vertex order, as the step's parent map computes them).");

  m.def(
      "hilbert_keys",
      [](const Int_array& ix, const Int_array& iy, int order) {
        const auto x = to_vector<std::int64_t>(ix), y = to_vector<std::int64_t>(iy);
        if (x.size() != y.size()) throw Input_error("hilbert_keys: ix and iy must have the same length");
        if (order < 1 || order > 31) throw Input_error("hilbert_keys: order must be in [1, 31]");
        const std::int64_t side = std::int64_t{1} << order;
        std::vector<std::int64_t> keys(x.size());
        {
          py::gil_scoped_release release;
          for (std::size_t i = 0; i < x.size(); ++i) {
            if (x[i] < 0 || x[i] >= side || y[i] < 0 || y[i] >= side) {
              keys[i] = -1;
              continue;
            }
            keys[i] = static_cast<std::int64_t>(nd::hilbert_index<2, std::uint64_t>(
                {static_cast<std::uint32_t>(x[i]), static_cast<std::uint32_t>(y[i])}, static_cast<unsigned>(order)));
          }
        }
        for (std::int64_t k : keys) {
          if (k < 0) throw Input_error("hilbert_keys: cells must lie in [0, 2^order)");
        }
        return vector_array(keys);
      },
      py::arg("ix"), py::arg("iy"), py::arg("order"),
      "Index along the Hilbert curve of integer cells (ix, iy) in [0, 2^order)^2 (nd::hilbert_index, the usual "
      "xy2d).");

  bind_options(m);

  bind_step<Frfc_options>(m, "frfc", &frfc, evolve_result_dict,
                          "Functional-Refining-Functional-Coarsening (Section 3.2): one step; returns a dict of arrays "
                          "and stats.");
  bind_step<Drfc_options>(m, "drfc", &drfc, evolve_result_dict,
                          "Delaunay-Refining-Functional-Coarsening (Section 5); returns the same dict as frfc.");

  bind_step<Drfc_options>(
      m, "drfc_refine", &drfc_refine,
      [](const Refined_mesh& r) {
        py::dict out = mesh_dict(r.mesh, r.source);
        out["f"] = vector_array(r.f);
        py::dict stats;
        stats["points_added"] = static_cast<double>(r.report.n_inserted);
        stats["points_added_on_segments"] = static_cast<double>(r.report.n_inserted_on_segments);
        stats["rounds"] = static_cast<double>(r.report.rounds);
        stats["capped"] = r.report.capped ? 1.0 : 0.0;
        stats["points_outside"] = static_cast<double>(r.report.n_inserted_outside);
        out["stats"] = stats;
        return out;
      },
      "DRFC step 1 alone: Delaunay refinement with Ruppert's rules and rule 4 (Section 5).");

  m.def(
      "constrained_delaunay",
      [](const Float_array& points, const Int_array& pieces, const Byte_array& boundary) {
        auto pts = to_points(points);
        const auto cp = to_constraint_pieces(pieces, boundary, pts.size());
        std::vector<Triangle> tris;
        {
          py::gil_scoped_release release;
          tris = constrained_delaunay(pts, cp);
        }
        return rows_array<3>(tris);
      },
      py::arg("points"), py::arg("pieces"), py::arg("boundary"));

  m.def(
      "triangulate_selection",
      [](const Float_array& points, const Byte_array& kind, const Byte_array& required, const Byte_array& fresh,
         const Int_array& pieces, const Byte_array& boundary, const Int_array& piece_tags, const Frfc_options& options,
         const std::optional<Int_array>& curved_tags, double corner_angle,
         const std::optional<py::function>& project, const std::vector<std::size_t>& batches) {
        Selection selected;
        selected.mesh.points = to_points(points);
        const std::size_t n = selected.mesh.points.size();
        selected.mesh.kind = to_kinds(kind);
        if (selected.mesh.kind.size() != n) throw Input_error("kind: one value per point");
        selected.mesh.required = to_vector<std::uint8_t>(required);
        if (!selected.mesh.required.empty() && selected.mesh.required.size() != n) {
          throw Input_error("required: one flag per point, or none");
        }
        // Origins: a kept input point's is its selection index, a new point's
        // -2 - its index (negative: new to the curve fit, which projects the
        // new points on curves again).
        const auto is_new = to_vector<std::uint8_t>(fresh);
        if (is_new.size() != n) throw Input_error("fresh: one flag per point");
        selected.origin.resize(n);
        for (std::size_t i = 0; i < n; ++i) {
          selected.origin[i] = is_new[i] ? -2 - static_cast<Index>(i) : static_cast<Index>(i);
        }
        auto cp = to_constraint_pieces(pieces, boundary, n);
        const auto tags = to_vector<std::int64_t>(piece_tags);
        if (tags.size() != cp.size()) throw Input_error("piece_tags: one tag per piece");
        for (std::size_t k = 0; k < cp.size(); ++k) {
          if (cp[k].a == cp[k].b) throw Input_error("a piece joins a point to itself");
          cp[k].tag = tags[k];
        }
        options.validate();
        const auto geometry = to_geometry(curved_tags, corner_angle, project);
        const Quality_options quality = options.quality_settings();
        Evolve_result result;
        std::vector<Index> piece_of;
        {
          py::gil_scoped_release release;
          // The step's early triangulation (frfc_stages.hpp Early_start): the
          // same batches give the same insertion history, which the serial
          // quality pass's last bits follow (it is not a function of the set).
          Early_triangulation early;
          const bool batched = options.quality && !geometry && !batches.empty();
          if (batched) {
            std::size_t at = 0;
            for (std::size_t b = 0; b < batches.size(); ++b) {
              const std::size_t end = std::min(n, at + batches[b]);
              const std::vector<Vec2> batch(selected.mesh.points.begin() + static_cast<std::ptrdiff_t>(at),
                                            selected.mesh.points.begin() + static_cast<std::ptrdiff_t>(end));
              if (b == 0) early.insert_first(batch);
              else early.insert_more(batch);
              at = end;
            }
          }
          triangulate_selection(std::move(selected), cp, options.quality ? &quality : nullptr, result,
                                batched ? &early : nullptr, geometry.get());
          for (Index& o : result.origin) {
            if (o <= -2) o = -2 - o;  // (the selection index of every selected point; -1: inserted)
          }
          piece_of = segment_pieces(result.mesh, cp, result.origin);
        }
        py::dict out;
        out["points"] = points_array(result.mesh.points);
        out["kind"] = kinds_array(result.mesh.kind);
        out["triangles"] = rows_array<3>(result.mesh.triangles);
        out["segments"] = rows_array<2>(result.mesh.segments);
        out["segment_is_boundary"] = vector_array(result.mesh.segment_is_boundary);
        out["segment_piece"] = to_array(std::vector<std::int64_t>(piece_of.begin(), piece_of.end()));
        out["selection_index"] = to_array(std::vector<std::int64_t>(result.origin.begin(), result.origin.end()));
        out["curve_reach"] = result.curve_reach;
        py::dict stats;
        for (const auto& [name, value] : result.stats) stats[py::str(name)] = value;
        out["stats"] = stats;
        return out;
      },
      py::arg("points"), py::arg("kind"), py::arg("required"), py::arg("fresh"), py::arg("pieces"),
      py::arg("boundary"), py::arg("piece_tags"), py::arg("options"), py::arg("curved_tags") = py::none(), py::arg("corner_angle") = 0.0,
      py::arg("project") = py::none(), py::arg("batches") = std::vector<std::size_t>(),
      "The step's last stage on a selection (step.hpp triangulate_selection): the quality pass when "
      "options.quality (else the constrained Delaunay triangulation), then the curve fit with a geometry. "
      "`fresh`: the points that are new (no input point). `batches`: the sizes of the step's early triangulation batches (the quality pass's history; no geometry). "
      "{'points', 'kind', 'triangles', 'segments', 'segment_is_boundary', 'segment_piece' (the piece each "
      "segment is part of), 'selection_index' (-1: inserted), 'curve_reach', 'stats'}. The distributed step "
      "runs it on its root for the quality pass (distributed_step._quality_on_root).");

  m.def(
      "convex_hull_vertices",
      [](const Float_array& points) {
        auto pts = to_points(points);
        std::vector<Index> hull;
        {
          py::gil_scoped_release release;
          hull = convex_hull_vertices(pts);
        }
        return vector_array(hull);
      },
      py::arg("points"), "Indices of the extreme points, counter-clockwise (exact).");
  m.def(
      "supports_on_left",
      [](const Float_array& a, const Float_array& b, const Float_array& points) {
        auto pa = to_points(a, "a");
        auto pb = to_points(b, "b");
        auto q = to_points(points);
        if (pa.size() != pb.size()) throw Input_error("a and b must have the same length");
        std::vector<std::uint8_t> ok;
        {
          py::gil_scoped_release release;
          ok = supports_on_left(pa, pb, q);
        }
        return to_array(std::move(ok));
      },
      py::arg("a"), py::arg("b"), py::arg("points"),
      "Per edge (a[k], b[k]): no point strictly to its right (exact).");

  m.def(
      "local_constrained_delaunay",
      [](const Float_array& points, const Int_array& pieces, const Byte_array& boundary) {
        auto pts = to_points(points);
        const auto cp = to_constraint_pieces(pieces, boundary, pts.size());
        Local_triangulation local;
        {
          py::gil_scoped_release release;
          local = local_constrained_delaunay(pts, cp);
        }
        return py::make_tuple(rows_array<3>(local.triangles), rows_array<3>(local.neighbour),
                              to_array(std::move(local.constrained)), to_array(std::move(local.seed)));
      },
      py::arg("points"), py::arg("pieces"), py::arg("boundary"),
      "Every finite face of the CDT, unlabelled (distributed triangulation): (triangles, neighbour, constrained "
      "bits, piece seeds).");

  m.def(
      "locate_points",
      [](const Float_array& points, const Int_array& triangles, const Float_array& queries) {
        auto [pts, tris] = to_points_and_triangles(points, triangles);
        auto q = to_points(queries, "queries");
        std::vector<Index> t;
        std::vector<std::array<double, 3>> bary;
        {
          py::gil_scoped_release release;
          locate_points(pts, tris, q, t, bary);
        }
        Float_array b({static_cast<py::ssize_t>(bary.size()), py::ssize_t{3}});
        if (!bary.empty()) std::memcpy(b.mutable_data(), bary.data(), bary.size() * sizeof(bary[0]));
        return py::make_tuple(vector_array(t), b);
      },
      py::arg("points"), py::arg("triangles"), py::arg("queries"));
}
