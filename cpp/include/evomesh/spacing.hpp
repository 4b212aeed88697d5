// Spacing functions (Section 3.1 of Li, Teng, Ungor).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "evomesh/types.hpp"

namespace evomesh {

// nn_M(p): distance from every point to its nearest other point (all points,
// not only mesh neighbours), from a static kd-tree queried in parallel
// (nd/kd_tree.hpp).
// Precondition: at least two points, no duplicates (throws Input_error).
std::vector<double> nn_spacing(const std::vector<Vec2>& points);

// nn_spacing(points) of a step's output, the same bits, from what the step
// changed: output point i is input point origin[i] (-1: a new point) at the same
// coordinates, and input_nn[o] is input point o's nn_spacing in the input (NaN:
// unknown). A kept point keeps its nn when no removed input point and no new
// point is as near as its old nearest point (then that point is kept and nothing
// nearer came: the minimum is the same expression over the same points); the
// others take their nn among the output points near them, with the triangles'
// edges as upper bounds. Falls back to nn_spacing(points) when the change is
// large. O(n + k log k) for k changed points (plus a tree query per point).
std::vector<double> nn_spacing_after_change(const std::vector<Vec2>& input_points,
                                            const std::vector<double>& input_nn, const std::vector<Vec2>& points,
                                            const std::vector<Triangle>& triangles,
                                            const std::vector<Index>& origin);

// f(x) = min_i (weight_i + |x - site_i|), the lower envelope of cones of
// slope 1 (Eq. 3). Evaluated through CGAL's Apollonius graph (additively
// weighted Voronoi diagram): the site minimising weight_i + |x - site_i| is
// the Apollonius nearest neighbour for the shifted weights W - weight_i >= 0.
class Spacing_function {
 public:
  // Large site sets are split into up to four parts (a kd split of the sites),
  // each with its own Apollonius graph built in parallel, when every part has at
  // least `min_sites_per_part` sites and the halos stay thin; answers are the
  // same as from one graph (see spacing.cpp). 0 picks the default (2^12).
  // Preconditions: sites distinct and finite, weights finite and >= 0.
  // `triangles` (optional; indices into `sites`, e.g. the mesh whose points are
  // the sites): their edges are tested for sites hidden by a neighbour (exact);
  // such a site is not inserted when that neighbour comes before it in the
  // insertion order. The graphs are then exactly those built without
  // `triangles` (CGAL would find the site hidden and change nothing), so f, the
  // sites found and n_hidden() are bit for bit the same.
  // `site_ids` (optional; global ids of the sites, Mesh_arrays::point_gids):
  // exact ties of f go to the site of lowest id (else of lowest index), and of
  // several neighbours hiding a site, the one of lowest id counts.
  // `shift` (optional, >= every weight; 0: the largest weight): the graph stores
  // the weights as shift - w, and CGAL decides which sites are hidden on those
  // rounded values. Graphs over different site sets that must agree bit for bit
  // (a rank's part of a distributed mesh, docs/distributed-step.md 3.2) pass the
  // same shift, the largest weight of the whole mesh.
  Spacing_function(const std::vector<Vec2>& sites, const std::vector<double>& weights,
                   std::size_t min_sites_per_part = 0, const std::vector<Triangle>* triangles = nullptr,
                   const std::vector<std::int64_t>* site_ids = nullptr, double shift = 0);

  // Number of Apollonius graphs the sites are split into (1, 2 or 4).
  int n_parts() const;
  ~Spacing_function();
  Spacing_function(const Spacing_function&) = delete;
  Spacing_function& operator=(const Spacing_function&) = delete;

  // f at n query points. `site_out` (optional) receives the minimising site.
  // The answer at x is the site c of least w_c + |x - c| (exact comparison; exact
  // ties: lowest id) among the visible sites, and f = w_c + sqrt(dx*dx + dy*dy)
  // in double: a function of x and of the sites near x only, the same bits
  // whatever the hint, the thread count, the kd parts, `certified`, or which other
  // sites the graph holds (any superset of the sites within f(x) of x answers
  // alike; docs/distributed-step.md 3.2). `certified` picks the walk to the graph
  // vertex the settle step starts from: CGAL's exact nearest neighbour, or
  // (false) a greedy walk in floating point, several times faster (FRFC's sample
  // radii). Queries are answered in Hilbert order with the previous answer as hint.
  void evaluate(const Vec2* queries, std::size_t n, double* f_out, Index* site_out = nullptr,
                int threads = 0, bool certified = true) const;

  std::size_t n_sites() const;
  // Sites whose cone never attains the minimum (hidden in the Apollonius graph).
  std::size_t n_hidden() const;
  // Of those, the sites left out (hidden by a neighbour along `triangles` that
  // was inserted before them): they never reached the Apollonius graph.
  std::size_t n_filtered() const;
  const std::vector<Vec2>& sites() const;
  const std::vector<double>& weights() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// f(x) from the few sites that can attain it at x, by a direct scan: the answer
// Spacing_function::evaluate gives with a graph of all the sites (the exact
// least cone w_c + |x - c| among the visible sites, exact ties to the lowest id,
// f = w_c + sqrt(dx*dx + dy*dy) in double), provided the scanned sites hold
// every site whose cone at x is at most reach(u) for some u >= f(x). Visible:
// not hidden in CGAL's sense (Apollonius_graph_2's Is_hidden_2 on the shifted
// weights shift - w, as the graph decides): a hidden site is skipped, its hider
// is scanned too (its cone is within rounding of the hidden one's). For the
// changed-region step, whose queries each come with such a bound and a handful
// of sites under it: no graph to build (incremental_step.cpp).
class Cone_scan {
 public:
  // `sites`, `weights`, `site_ids`, `shift`: as Spacing_function's, whose graph
  // of all the sites this answers like (same shift: 0 is the largest weight).
  // The vectors are referenced, not copied: they must outlive the scan.
  Cone_scan(const std::vector<Vec2>& sites, const std::vector<double>& weights,
            const std::vector<std::int64_t>* site_ids = nullptr, double shift = 0);
  // What the scanned sites' cones must reach at x, given u >= f(x): u plus
  // 2^-44 (u + shift), above every rounding the answer depends on.
  double reach(double u) const { return u + 0x1p-44 * (u + shift_); }
  // f(x) from the sites near[0, count) (indices into the sites; count >= 1, the
  // set above); `site` (optional) receives the site attaining it.
  double evaluate(const Vec2& x, const Index* near, std::size_t count, Index* site = nullptr) const;
  double shift() const { return shift_; }

 private:
  const std::vector<Vec2>& sites_;
  const std::vector<double>& weights_;
  const std::vector<std::int64_t>* ids_;
  double shift_ = 0;
};

}  // namespace evomesh
