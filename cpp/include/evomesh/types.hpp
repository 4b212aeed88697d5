// Plain data types shared by the evomesh core. No CGAL and no pybind11 here.
#pragma once

#include <array>
#include <cstdio>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace evomesh {

struct Boundary_geometry;  // boundary_geometry.hpp

using Index = std::int64_t;
using Vec2 = std::array<double, 2>;
using Triangle = std::array<Index, 3>;
using Edge = std::array<Index, 2>;

// Per-point label; the numeric order is the packing priority of Section 6
// (corner, boundary, original, Steiner, sampled).
enum class Point_kind : std::uint8_t {
  corner = 0,
  boundary = 1,
  original = 2,
  steiner = 3,
  sampled = 4,
};

// A count held in a double (possibly huge or infinite) for a message; never
// converts to an integer type, which would be undefined beyond its range.
inline std::string format_count(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.4g", value);
  return buffer;
}

// Thrown for malformed user input; the bindings map it to ValueError.
struct Input_error : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

// Throws Input_error unless `count` fits the 4-byte indices that memory-bound
// arrays use (count < 2^32; `what`: "3 x triangles", "points", ...).
inline void check_fits_4_bytes(std::uint64_t count, const char* what) {
  if (count >= (std::uint64_t{1} << 32)) {
    throw Input_error(std::string("meshes with 2^32 or more ") + what + " are not supported");
  }
}

// A triangle mesh as plain arrays. Triangles are counter-clockwise.
// Segments are constraint edges; `segment_is_boundary[k]` tells whether
// segment k is a boundary edge (domain on its left, a -> b) or an interior
// constraint (domain on both sides).
struct Mesh_arrays {
  std::vector<Vec2> points;
  std::vector<Triangle> triangles;
  std::vector<Edge> segments;
  std::vector<std::uint8_t> segment_is_boundary;
  std::vector<Point_kind> kind;
  // Optional (empty: none). An integer tag per segment (boundary conditions,
  // Gmsh physical lines) and per triangle (regions, materials); required points
  // are kept by every step, exactly.
  std::vector<std::int64_t> segment_tags;
  std::vector<std::int64_t> triangle_tags;
  std::vector<std::uint8_t> required;
  // Optional (null: the polygon is the domain, exactly): the curves behind
  // segments of some tags (boundary_geometry.hpp). A step's input only.
  std::shared_ptr<const Boundary_geometry> geometry;
  // Optional, a step's input only (empty: the step computes them): nn_M within
  // the domain at every point and the points where that exceeds the Euclidean
  // distance (keep_within_domain in local_feature_size.hpp), as Mesh.nn_spacing
  // holds them. Used when the step measures nn within the domain.
  std::vector<double> nn_within_domain;
  std::vector<Index> nn_grew;
  // Optional, a step's input only (false: not known): the triangles are the
  // constrained Delaunay triangulation of the points and segments with every
  // edge that is not a segment strictly locally Delaunay (exact predicates), as
  // a step certified it for its own output (Evolve_result::triangulation_certified; the
  // Python Mesh keeps that for the arrays it cannot change). The changed-region
  // step then checks only the edges its update touches (triangulation_update.hpp).
  bool strictly_delaunay = false;
  // Optional, a step's input only (empty: the array positions): global ids
  // (docs/distributed-step.md section 2.2), one per point, triangle
  // and segment, distinct within each array. The step keys by them what it
  // used to key by position: the random streams of the samples (a triangle's
  // by its id, a segment's by its key, a point's ring and repair by its id),
  // the tie order of the packing (class, radius, then the ids) and the order
  // and phase of the spacing repair. So the same mesh in another array order,
  // with the ids of the first, gives the same output points and triangles;
  // with the positions as ids (or none) it gives exactly what it gave before.
  // A segment is still drawn from e[0] to e[1], and a triangle from its
  // vertex t[0]: reversing or rotating one changes its samples.
  std::vector<std::int64_t> point_gids;
  std::vector<std::int64_t> triangle_gids;
  std::vector<std::int64_t> segment_keys;

  std::int64_t point_gid(std::size_t i) const {
    return point_gids.empty() ? static_cast<std::int64_t>(i) : point_gids[i];
  }
  std::int64_t triangle_gid(std::size_t t) const {
    return triangle_gids.empty() ? static_cast<std::int64_t>(t) : triangle_gids[t];
  }
  std::int64_t segment_key(std::size_t k) const {
    return segment_keys.empty() ? static_cast<std::int64_t>(k) : segment_keys[k];
  }
  bool has_global_ids() const { return !point_gids.empty() || !triangle_gids.empty() || !segment_keys.empty(); }
};

}  // namespace evomesh
