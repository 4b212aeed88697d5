// Functional-Refining-Functional-Coarsening (Section 3.2): one evolution step.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "evomesh/sampling.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

struct Frfc_options {
  double cell_factor = 1.0;          // c in the cell side c f(q) / (2 sqrt 2)
  bool exact_radius = true;          // f(x)/2 from the Apollonius graph; else (f(q)+|x-q|)/2
  // Spheres are B(x, radius_scale * f(x) / 2). 1 is the paper's choice; a smaller
  // scale packs tighter (radius_scale * f is still a valid, Lipschitz spacing).
  double radius_scale = 1.0;
  // Extra factor for spheres centred on segments (corners, boundary points and
  // segment samples): the boundary is a 1-D packing, which leaves larger gaps.
  double boundary_radius_scale = 1.0;
  // Offer candidates on a ring just outside every R-point's sphere (see frfc.cpp).
  bool ring_samples = true;
  // Spacing repair: a kept R-point p with no kept point within
  // repair_ratio * delta(p) nn_M(p) gets its best ring candidate. 0 disables.
  double repair_ratio = 1.75;
  Sample_mode sample_mode = Sample_mode::random_grid;
  bool skip_coarse_triangles = false;  // no samples where all three vertices have delta > 1
  std::uint64_t seed = 0;
  int threads = 0;                   // 0: hardware concurrency (capped at 2 chunks per core)
  double max_samples = 5e7;          // refuse inputs whose sampling would exceed this
};

struct Evolve_result {
  Mesh_arrays mesh;
  std::vector<Index> origin;   // index in the input mesh, -1 for a new point
  std::vector<double> input_f; // f at the input points
  std::vector<double> input_nn;
  std::vector<std::pair<std::string, double>> stats;  // stage timings (s) and counts
};

// Runs FRFC on a validated mesh. delta: one positive finite factor per point.
Evolve_result frfc(const Mesh_arrays& mesh, const std::vector<double>& delta,
                   const Frfc_options& options);

// Maximal chains of segments between corners, in order, for building constraint pieces.
struct Segment_chain {
  std::vector<Index> vertices;  // v0 .. vk along the chain
  std::vector<Index> segments;  // segment index of (v_i, v_{i+1})
  std::vector<std::uint8_t> forward;  // segment k is traversed a -> b
  bool closed = false;
  bool boundary = true;
};
std::vector<Segment_chain> segment_chains(const Mesh_arrays& mesh);

}  // namespace evomesh
