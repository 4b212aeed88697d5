// One FRFC step on a tetrahedral mesh of a convex polyhedron (the paper's
// Section 3.2 one dimension up): f from the old points' weights (an exact
// cone envelope, nd/cone_envelope.hpp), samples on the domain's edges, facets and
// in the old tetrahedra, the lexical-first MIS of spheres B(x, radius_scale f(x)/2) by
// classes (required < corner < edge < face < old interior < Steiner < sampled;
// old before new within the boundary classes; smaller radius first, ties by a
// global id), then CGAL's Delaunay_triangulation_3 of the kept points. Pure
// C++: no pybind11 here.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "evomesh/tet/polyhedral_domain.hpp"
#include "evomesh/types.hpp"

namespace evomesh::tet {

using Tet = std::array<Index, 4>;
using Face = std::array<Index, 3>;

// Per-point label; the numeric order is the stratum order of the packing.
enum class Tet_point_kind : std::uint8_t {
  corner = 0,    // a corner of the domain (always kept)
  edge = 1,      // on one edge of the domain
  face = 2,      // on one facet of the domain
  original = 3,  // interior, in the user's mesh
  steiner = 4,   // interior, added by an earlier step
  sampled = 5,   // interior, added by this step
};

struct Tet_step_options {
  // c in the sampling cell side c f(q) / (2 sqrt 3) (faces: c f(q) / (2 sqrt 2),
  // edges: c f(q) / 2), f(q) the smallest f at the cell's element's vertices.
  double cell_factor = 2.0;
  // Spheres are B(x, radius_scale f(x) / 2): 1 is the paper's; below 1 packs
  // tighter, so that a refining request (delta < 1) gets new points between
  // the old ones (with 1, a sample nearer than nn(p) to a kept old point p
  // always conflicts with it, whatever delta(p)).
  double radius_scale = 0.75;
  // A candidate (not a corner) is rejected when it lies closer than
  // boundary_clearance f(x) to a facet plane it is not on
  // (Polyhedral_domain::clearance): no interior point sits in a face's
  // shadow (the flat "caps" a bare packing makes there), no face point next
  // to an edge.
  double boundary_clearance = 0.5;
  // Delaunay refinement of tetrahedra whose radius-edge ratio exceeds this
  // (refined_delaunay below; 0: none), with at most a tenth of the kept
  // points plus 100 insertions.
  double max_radius_edge = 2.0;
  // The sliver pass: tetrahedra with a dihedral angle below this or above 180
  // minus it (degrees) get their new vertices perturbed, then points in the
  // circumspheres of those left (Sliver_options); 0: none.
  double sliver_angle = 0;
  // Refuse (Input_error) a step whose grids hold more cells than this.
  double max_samples = 5e7;
  std::uint64_t seed = 0;
  int threads = 0;  // 0: the default (parallel.hpp); results never depend on it

  // Throws Input_error naming the first field out of range (options.cpp, with
  // the 2-D options' checks).
  void validate() const;
};

struct Tet_step_input {
  std::vector<Vec3> points;
  std::vector<Tet> tets;           // positively oriented
  std::vector<Face> boundary;      // the boundary triangles (on the domain's facets)
  std::vector<Index> boundary_tet; // a tetrahedron of each boundary triangle
  std::vector<int> boundary_facet; // the facet of each boundary triangle
  std::vector<std::uint8_t> steiner;   // per point: interior and added by a step
  std::vector<std::uint8_t> required;  // per point: kept whatever the request
  std::vector<double> weight;          // w_p > 0: f(x) = min_p (w_p + |x - p|)
  Polyhedral_domain domain;            // convex; the hull of the points
};

// cap(x, tet, out): the largest f allowed at the new candidates x (each drawn
// in old tetrahedron tet[i]); called on the calling thread with all the
// candidates of a stage at once, or never when empty. (A size request: f is
// capped by kappa h(x), so the mesh does not drift coarser between sparse
// old points, which the cone envelope alone would let it.)
using Size_cap = std::function<void(const std::vector<Vec3>& x, const std::vector<Index>& tet, std::vector<double>& out)>;

struct Tet_step_result {
  std::vector<Vec3> points;
  std::vector<Tet> tets;                  // positively oriented, canonical order
  std::vector<Index> origin;              // old index, -1 new
  std::vector<Index> parent_tet;          // for new points: the old tetrahedron holding them; -1 kept
  std::vector<std::uint8_t> kind;         // Tet_point_kind
  std::vector<std::uint64_t> facets;      // per point: the facets it lies on (Polyhedral_domain::Mask)
  std::vector<double> f;                  // f at each output point (radius f/2)
  std::vector<std::pair<std::string, double>> stats;
};

// Nearest-neighbour distance of each point (Input_error on duplicates).
std::vector<double> tet_nn_spacing(const std::vector<Vec3>& points, int threads);

// Exact orientation sign of each tetrahedron (+1 positive volume).
std::vector<std::int8_t> tet_orientations(const std::vector<Vec3>& points, const std::vector<Tet>& tets);

// f at each query, and the sites evaluated in total (for the bound of the
// B&B); brute force evaluates every site in order (the reference).
std::vector<double> cone_envelope_3(const std::vector<Vec3>& sites, const std::vector<double>& weights,
                                    const std::vector<Vec3>& queries, bool brute_force, std::size_t& evaluations,
                                    int threads);

// The positively oriented finite cells of the Delaunay triangulation of the
// points (spatially sorted insertion), each rotated to put its smallest index
// first (an even permutation), rows sorted: canonical for the point set.
std::vector<Tet> delaunay_tetrahedra(const std::vector<Vec3>& points);

// The sliver pass (refined_delaunay): new points move within picking
// regions (new face points within their facet); old points never move;
// what is left gets points inside the slivers' circumspheres.
struct Sliver_options {
  double min_dihedral = 0;          // degrees: a sliver has a dihedral below it or above 180 minus it; 0: no pass
  double rho = 0.15;                // picking region: rho times the point's shortest edge
  int attempts = 12;                // random positions tried per point
  int rounds = 3;
  int insertion_passes = 4;         // circumcentre insertions, each followed by the perturbation again
  double max_radius_edge = 2.0;     // a move must keep the star within this
  std::size_t first_movable = 0;    // points below this index never move (the kept old points)
  std::uint64_t seed = 0;
};

struct Refinement_report {
  std::vector<Index> moved;     // points the sliver pass moved
  std::vector<std::uint8_t> moved_mask;
  bool was_moved(std::size_t k) const { return k < moved_mask.size() && moved_mask[k]; }
  std::size_t off_centres = 0;  // points inserted in slivers' circumspheres
  std::size_t slivers_before = 0, slivers_after = 0;
  std::size_t inserted = 0;     // refinement and off-centre points
  std::size_t unresolved = 0;   // tetrahedra above the ratio when it stopped
  std::size_t rounds = 0;
  std::vector<Index> hints;     // per inserted point: a vertex of the tetrahedron it split
};

// The Delaunay tetrahedra of `points` after Delaunay refinement of the
// radius-edge ratio (Shewchuk): in rounds, every tetrahedron with circumradius
// above max_ratio times its shortest edge (in canonical order, skipping those
// an earlier insertion of the round destroyed) gets its circumcentre, or, when
// that lies beyond a facet or within half the shortest edge of it, the
// centre's projection onto that facet, or onto an edge of it when the
// projection is that near the edge (kept half the shortest edge from the
// facets it is not on; none near a corner). At most `budget` points,
// appended to `points`.
// Then, with slivers.min_dihedral > 0, the sliver pass (points moved in place).
std::vector<Tet> refined_delaunay(std::vector<Vec3>& points, const Polyhedral_domain& domain, double max_ratio,
                                  std::size_t budget, const Sliver_options& slivers, Refinement_report& report);

Tet_step_result tet_step(const Tet_step_input& input, const Tet_step_options& options, const Size_cap& cap);

}  // namespace evomesh::tet
