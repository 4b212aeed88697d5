// The domain of a tetrahedral step: a convex polyhedron given by its planar
// facets and the edges where two of them meet. Points on a facet or an edge
// lie on it exactly in float64 (CGAL's exact orientation says so), so the
// Delaunay tetrahedra of the points have the polyhedron as their hull and
// every facet is a union of hull triangles. A facet normal to a coordinate
// axis holds every point whose coordinate equals its plane's; another facet
// holds the lattice a + s (b - a) + t (c - a), s and t multiples of 2^-bits,
// where the constructor finds a `bits` that keeps sample lattice points
// exact (Input_error when no such lattice exists: corners whose coordinates
// have too many significant bits). Edges likewise: p + l (q - p), l a
// multiple of 2^-bits. Every point made on a facet or an edge is checked
// exactly and dropped when it misses. Pure C++: no pybind11 here.
#pragma once

#include <array>
#include <bitset>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh::tet {

using Vec3 = std::array<double, 3>;

class Polyhedral_domain {
 public:
  using Mask = std::uint64_t;  // bit f: facet f
  static constexpr std::size_t max_facets = 64;

  Polyhedral_domain() = default;

  // facets[f] = (a, b, c): three points of facet f, outward (x inside the
  // domain sees them clockwise: orientation(a, b, c, x) < 0); edge_facets[e]:
  // the two facets of edge e, edge_ends[e] its two end corners. Neighbours:
  // facets that share a corner (for the clearance rule). Input_error on more
  // than max_facets facets, collinear facet points, or no exact lattice.
  Polyhedral_domain(const std::vector<std::array<Vec3, 3>>& facets, const std::vector<std::array<int, 2>>& edge_facets,
                    const std::vector<std::array<Vec3, 2>>& edge_ends, const std::vector<Mask>& neighbours);

  std::size_t n_facets() const { return facets_.size(); }
  std::size_t n_edges() const { return edges_.size(); }

  // The facets whose plane holds x exactly.
  Mask incidences(const Vec3& x) const;
  static int count(Mask m) { return static_cast<int>(std::bitset<64>(m).count()); }
  static int first(Mask m) {
    for (int f = 0; f < 64; ++f) {
      if (m >> f & 1u) return f;
    }
    return -1;
  }
  // The edge whose two facets are both in m (-1: none).
  int edge_of(Mask m) const;

  // Signed distance from facet f's plane, positive inside (rounded; exact in
  // sign and value on an axis-aligned facet).
  double distance(std::size_t f, const Vec3& x) const;
  // The near-boundary distance of a point on the facets `on`: the nearest
  // plane among the facets it is not on that share a corner with every facet
  // it is on (all facets for an interior point; for a face point, the facets
  // around its face; for an edge point, those at its end corners).
  double clearance(const Vec3& x, Mask on) const;
  // x strictly inside every facet not in `except` (exact).
  bool strictly_inside(const Vec3& x, Mask except) const;
  // Facets sharing a corner with f.
  Mask neighbours(std::size_t f) const { return facets_[f].neighbours; }

  // x moved onto facet f exactly (the lattice point nearest its projection);
  // false when that point misses the plane.
  bool snap_to_facet(std::size_t f, Vec3& x) const;
  // The facet's axis when it is normal to one (-1 otherwise), and the axis
  // to drop to see it as a planar region (its normal's largest component).
  int facet_axis(std::size_t f) const { return facets_[f].axis; }
  int facet_projection_axis(std::size_t f) const { return facets_[f].projection_axis; }
  // |n_k| for the unit normal n and k the projection axis (lengths in the
  // projection shrink by at most this).
  double facet_projection_scale(std::size_t f) const { return facets_[f].projection_scale; }

  // Edge e: its facets, its direction's largest component (`axis`), whether
  // it is parallel to that axis, and |d_axis| / |d|.
  std::array<int, 2> edge_facets(std::size_t e) const { return edges_[e].facets; }
  int edge_axis(std::size_t e) const { return edges_[e].axis; }
  bool edge_is_axis_aligned(std::size_t e) const { return edges_[e].aligned; }
  double edge_axis_scale(std::size_t e) const { return edges_[e].axis_scale; }
  // The point of edge e whose coordinate `axis` is near `value`, exactly on
  // the edge (its start with that coordinate replaced on an axis-aligned
  // edge, else the nearest lattice point); false when it misses the line.
  bool edge_point(std::size_t e, double value, Vec3& x) const;

 private:
  struct Facet {
    Vec3 a, b, c, e1, e2;
    Vec3 inward;  // unit normal pointing inside
    int axis = -1;
    int projection_axis = 0;
    double projection_scale = 1;
    int bits = 0;  // lattice resolution 2^-bits
    double gram[3] = {0, 0, 0};  // e1.e1, e1.e2, e2.e2
    Mask neighbours = 0;
  };
  struct Domain_edge {
    std::array<int, 2> facets;
    Vec3 p, q, d;
    int axis = 0;
    bool aligned = false;
    double axis_scale = 1;
    int bits = 0;
  };
  bool on_plane(std::size_t f, const Vec3& x) const;
  bool lattice_point(const Facet& facet, double s, double t, Vec3& x) const;

  std::vector<Facet> facets_;
  std::vector<Domain_edge> edges_;
};

}  // namespace evomesh::tet
