// Options of a step, in one place: one type per method, with the paper's
// algorithm and the recommended defaults as named presets, and the only range
// checks (validate()). Python binds these types with the same field names
// (evomesh.FrfcOptions, evomesh.DrfcOptions); the benchmarks use them too.
#pragma once

#include <cstdint>

#include "evomesh/types.hpp"

namespace evomesh {

// Interior and segment samples (Section 3.2 step 2, and Section 5's variations).
enum class Sample_mode : std::uint8_t {
  random_grid = 0,  // one random point in each grid cell's part inside the triangle (the paper)
  barycentre = 1,   // the barycentre of every triangle
  midpoints = 2,    // the midpoint of every edge
  barycentre_midpoints = 3,
};

// Radius of a sample's sphere: f(x)/2 from the Apollonius graph, or the paper's
// cheaper (f(q) + |x - q|)/2 with q the triangle's vertex of smallest f, or
// (interpolated) f(x)/2 except in triangles (segments) with a demoted
// vertex (packing.hpp, demoted_points), where the size follows the linear
// interpolation l of f at the vertices: min(f, max(1.2 l, f / 1.3))/2
// (candidates.cpp). f is a minimum of cones of slope 1 at the old points, so
// between them it rises by up to about their spacing (by 72 % at delta = 0.8 on
// a uniform mesh): spheres that follow it pack at nearly the old spacing
// however close to 1 delta is. l follows the request between the old points.
enum class Radius_rule : std::uint8_t { exact = 0, cheap = 1, interpolated = 2 };

// The quality pass of Section 6 (refinement.hpp): Delaunay refinement of the
// selected points to an angle bound, after crowded segments are split.
struct Quality_options {
  // Triangles with a smaller angle (degrees) are split at their circumcentre (Ruppert's
  // rule 3). Up to about 20.7 Ruppert's algorithm provably ends when the domain has no
  // angle below 60 degrees; beyond that only the bound on inserted points stops it.
  double min_angle = 20.0;
  // A point that sees a segment under more than crowding_angle degrees is dropped
  // and the segment is split at its midpoint instead. 0 turns it off.
  double crowding_angle = 120.0;
  // The pass stops after max_inserted_fraction * n + max_inserted_extra insertions
  // (n: points handed in), so small input angles cannot make it run long.
  double max_inserted_fraction = 0.5;
  double max_inserted_extra = 1000;
  // Refine in rounds of independent insertions (docs/distributed-step.md
  // section 3.6): every round splits a lexical-first maximal independent set of
  // the bad triangles and encroached sub-segments of the mesh at its start, so
  // the output is a function of the input sets (any order of points and pieces)
  // and a partitioned step can reproduce it. false: one point at a time from the
  // worst triangle (the serial pass).
  bool quality_rounds = false;

  // Throws Input_error naming the first field out of range.
  void validate() const;
};

// The largest min_angle accepted (degrees).
constexpr double kMaxMinAngle = 30.0;

struct Frfc_options {
  double cell_factor = 2.0;    // c in the cell side c f(q) / (2 sqrt 2); the paper's c5 <= 1
  Radius_rule radius = Radius_rule::interpolated;
  // Spheres are B(x, radius_scale f(x) / 2); 1 is the paper's choice, smaller packs tighter.
  double radius_scale = 0.75;
  // Extra factor for spheres centred on segments (a 1-D packing leaves larger gaps).
  double boundary_scale = 0.8;
  // Candidates on a ring just outside every R-point's sphere (frfc.cpp).
  bool ring_samples = true;
  // Spacing repair: a kept R-point p with no kept point within
  // repair_ratio * delta(p) nn_M(p) gets its best ring candidate. 0 disables.
  double repair_ratio = 1.75;
  // An old point p with nn_M(p) > demote_ratio * f(p) (the request refines its
  // neighbourhood: delta(p) < 1 / demote_ratio at an R-point) loses the priority
  // of old points and is packed with the new points by size (packing.hpp,
  // demoted_points). 0: old points always first (the paper).
  double demote_ratio = 1.1;
  // Gap repair: an input point p with delta(p) >= 1 whose second
  // nearest output point (the paper's nn_M'(p): its nearest other one when p is
  // kept) lies beyond gap_repair_ratio * delta(p) nn_M(p) gets one more point at
  // distance delta(p) nn_M(p) (spacing_repair.hpp). 0 disables (the paper).
  double gap_repair_ratio = 1.1;
  // The same, at this ratio, for points with delta(p) < 1 that were demoted or
  // dropped: where a fresh packing forms, its spacing varies more and a bound
  // of 1.1 adds points that compound over repeated steps (ten steps of delta =
  // 0.8 at 1.1: 0.57 of 0.8^10; at 1.3: 0.97; benchmarks/README.md).
  // Kept R-points that were not demoted use gap_repair_ratio. 0 disables.
  double refine_gap_ratio = 1.3;
  Sample_mode samples = Sample_mode::random_grid;
  // Grid cells grow where f's Lipschitz bound from the triangle's vertices
  // allows (sampling.cpp); false: the paper's uniform cells of side c f(q)/(2 sqrt 2).
  bool adaptive_cells = true;
  bool skip_coarse = false;     // no samples where all three vertices have delta > 1
  // No samples in a triangle (on a segment) whose every vertex is settled:
  // delta = 1 and f = nn_M = its shortest edge, the request there being the
  // spacing the mesh has (candidates.hpp, settled_points). With it a step is
  // idempotent on its own output; false: the paper's sampling.
  bool skip_settled = true;
  // Interior samples that certainly overlap a kept sphere are dropped before
  // their radius is computed; the output is the same either way.
  bool filter_samples = true;
  double max_samples = 5e7;     // refuse steps whose sampling would exceed this
  int threads = 0;              // 0: default_thread_count() (parallel.hpp: EVOMESH_NUM_THREADS, OMP_NUM_THREADS, CPUs)
  std::uint64_t seed = 0;
  bool quality = true;          // the quality pass of Section 6
  // nn_M within the domain and the spacing capped by the local feature size
  // (local_feature_size.hpp); false: the paper's Euclidean nn_M.
  bool within_domain = true;
  double min_angle = 30.0;      // its angle bound (degrees, up to kMaxMinAngle; was 20)
  // Where delta = 1 on most of the mesh, skip the work that certainly changes
  // nothing there (incremental_step.hpp): the same output, bit for bit, at a
  // cost that follows the change. false: always the full algorithm.
  bool incremental = true;
  double crowding_angle = 120.0;
  double quality_max_fraction = 0.5;
  double quality_max_extra = 1000;
  bool quality_rounds = false;  // Quality_options::quality_rounds

  // The paper's FRFC exactly: spheres B(x, f(x)/2) everywhere, cells of side
  // f(q)/(2 sqrt 2) (c5 = 1), exact radii, no ring candidates, no repair, no
  // quality pass.
  static Frfc_options paper();
  // The defaults (what a default-constructed Frfc_options holds).
  static Frfc_options recommended() { return {}; }
  Quality_options quality_settings() const;
  void validate() const;
};

struct Drfc_options {
  // Step 1: Delaunay refinement with Ruppert's rules 1 and 3 for this angle
  // (degrees) and rule 4 for the spacing function f; also the quality pass's bound.
  double min_angle = 20.0;
  // Step 2: spheres B(p, radius_scale f(p) / 2) on the refined points; 1 is the
  // one-level coarsening of Miller, Talmor and Teng.
  double radius_scale = 0.75;
  int threads = 0;
  // Refuse a step whose refinement would need more points than this (estimated
  // from f as FRFC's sampling is), and stop refining at twice the estimate.
  double max_samples = 5e7;
  bool quality = true;  // the quality pass of Section 6 on the coarsened points
  bool within_domain = true;  // as Frfc_options::within_domain
  double crowding_angle = 120.0;
  double quality_max_fraction = 0.5;
  double quality_max_extra = 1000;
  bool quality_rounds = false;  // Quality_options::quality_rounds

  // Section 5's DRFC exactly: Miller-Talmor-Teng spheres, no quality pass.
  static Drfc_options paper();
  static Drfc_options recommended() { return {}; }
  Quality_options quality_settings() const;
  void validate() const;
};

}  // namespace evomesh
