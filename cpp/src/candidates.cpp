#include "evomesh/candidates.hpp"

#include "evomesh/global_ids.hpp"
#include "evomesh/detail/sphere_conflict.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "evomesh/kernel.hpp"
#include "evomesh/packing.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/triangulation.hpp"

namespace evomesh {

namespace {

constexpr double kMargin = 1.02;

// The interpolated size (Radius_rule::interpolated) in a triangle or segment with
// a demoted end: min(f(x), max(kInterpolatedScale l(x), f(x) / kInterpolatedFloor)).
// l runs below f between the old points (f is a minimum of cones); the scale
// gives back part of that gap so that spheres of the same radius_scale pack at
// about the spacing they do where f is used, and the floor keeps the size
// within a factor of f (so at most kInterpolatedFloor^2 times the points of
// the paper's spheres where delta is far below 1). Calibrated on delta = 0.8
// over unit_square_mesh: median output nn 0.82 of the old after one step
// (0.8 asked), 0.137 after ten (0.107 asked; 0.10 with no floor, but then
// delta = 0.1 gives 12 times the paper's size).
constexpr double kInterpolatedScale = 1.2;
constexpr double kInterpolatedFloor = 1.3;

// Interior ring candidates of every R-point, in point order, except those in a
// cover disc of their triangle: appended to `blocks` (one per fixed block of
// points, joined later in order) with their rounds.
void add_interior_ring_samples(const Mesh_arrays& mesh, const Triangle_fans& fans, const std::vector<double>& delta,
                               const std::vector<double>& f, double reach, double demoted_reach,
                               const std::vector<std::uint8_t>& demoted, std::uint64_t seed,
                               const Cover_discs& cover, int threads, std::vector<Sample_set>& blocks,
                               std::vector<std::int8_t>& ring_round, const std::vector<std::uint8_t>* ring_from,
                               std::vector<Index>* ring_point) {
  const std::size_t n = mesh.points.size();
  constexpr std::size_t kBlock = 4096;
  const std::size_t n_blocks = (n + kBlock - 1) / kBlock;
  const std::size_t first = blocks.size();
  blocks.resize(first + n_blocks);
  std::vector<std::vector<std::int8_t>> rounds(n_blocks);
  std::vector<std::vector<Index>> points(ring_point != nullptr ? n_blocks : 0);
  const std::vector<Index> by_id = order_by_ids(mesh.point_gids);  // (points in the order of their ids)
  parallel_for(n_blocks, threads, [&](std::size_t b) {
    std::array<Ring_candidate, kRingDirections> ring;
    Sample_set& out = blocks[first + b];
    for (std::size_t r = b * kBlock; r < std::min(n, (b + 1) * kBlock); ++r) {
      const std::size_t p = visit(by_id, r);
      if (!(delta[p] < 1) || (ring_from != nullptr && !(*ring_from)[p])) continue;
      const double d = !demoted.empty() && demoted[p] ? demoted_reach : reach;
      const int count = ring_candidates_of(mesh, fans, f, d, seed, p, ring);
      for (int k = 0; k < count; ++k) {
        const Ring_candidate& r = ring[k];
        if (in_cover(cover, mesh.triangles[r.triangle], r.x)) continue;
        out.points.push_back(r.x);
        out.parent.push_back(static_cast<std::uint32_t>(r.triangle));
        rounds[b].push_back(static_cast<std::int8_t>(r.round));
        if (ring_point != nullptr) points[b].push_back(static_cast<Index>(p));
      }
    }
  });
  std::size_t total = 0;
  for (const auto& r : rounds) total += r.size();
  ring_round.reserve(total);
  for (const auto& r : rounds) ring_round.insert(ring_round.end(), r.begin(), r.end());
  if (ring_point != nullptr) {
    ring_point->reserve(ring_point->size() + total);
    for (const auto& q : points) ring_point->insert(ring_point->end(), q.begin(), q.end());
  }
}

// Segment ring candidates: one each way from an R-point, on the segment, merged
// into the per-segment sample lists (which stay sorted along each segment).
void add_segment_ring_samples(const Mesh_arrays& mesh, const std::vector<double>& delta, const std::vector<double>& f,
                              double radius_scale, Sample_set& on_segments, std::vector<std::int8_t>& segment_round,
                              std::vector<Index>& segment_owner) {
  const double reach = ring_reach(radius_scale);
  segment_round.assign(on_segments.points.size(), -1);
  segment_owner.assign(on_segments.points.size(), -1);
  std::vector<std::pair<Index, double>> extra;  // (segment, t)
  std::vector<std::int8_t> extra_round;
  std::vector<Index> extra_owner;
  for (std::size_t s = 0; s < mesh.segments.size(); ++s) {
    const Edge& e = mesh.segments[s];
    const Vec2& a = mesh.points[e[0]];
    const Vec2& b = mesh.points[e[1]];
    const double length = std::hypot(b[0] - a[0], b[1] - a[1]);
    // round 0 for the segment leaving a point, 1 for the one entering it
    if (delta[e[0]] < 1) {
      extra.emplace_back(static_cast<Index>(s), reach * f[e[0]] / length);
      extra_round.push_back(0);
      extra_owner.push_back(e[0]);
    }
    if (delta[e[1]] < 1) {
      extra.emplace_back(static_cast<Index>(s), 1.0 - reach * f[e[1]] / length);
      extra_round.push_back(1);
      extra_owner.push_back(e[1]);
    }
  }
  if (extra.empty()) return;
  // Merge into the per-segment lists, keeping each segment's samples sorted by t.
  std::vector<std::pair<Index, double>> all;
  all.reserve(on_segments.points.size() + extra.size());
  for (std::size_t j = 0; j < on_segments.points.size(); ++j) {
    const Edge& e = mesh.segments[on_segments.parent[j]];
    const Vec2& a = mesh.points[e[0]];
    const Vec2& b = mesh.points[e[1]];
    const double dx = b[0] - a[0], dy = b[1] - a[1];
    const double t = ((on_segments.points[j][0] - a[0]) * dx + (on_segments.points[j][1] - a[1]) * dy) / (dx * dx + dy * dy);
    all.emplace_back(on_segments.parent[j], t);
  }
  std::vector<Vec2> points = std::move(on_segments.points);
  std::vector<std::int8_t> rounds(points.size(), -1);
  std::vector<Index> owners(points.size(), -1);
  for (std::size_t i = 0; i < extra.size(); ++i) {
    const auto [s, t] = extra[i];
    if (!(t > 0 && t < 1)) continue;
    const Edge& e = mesh.segments[s];
    const Vec2& a = mesh.points[e[0]];
    const Vec2& b = mesh.points[e[1]];
    const Vec2 x{a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])};
    if ((x[0] == a[0] && x[1] == a[1]) || (x[0] == b[0] && x[1] == b[1])) continue;
    all.emplace_back(s, t);
    points.push_back(x);
    rounds.push_back(extra_round[i]);
    owners.push_back(extra_owner[i]);
  }
  std::vector<std::size_t> order(all.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  // (segments in the order of their keys, as sample_segments visits them)
  std::sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) {
    if (all[i].first != all[j].first) return mesh.segment_key(all[i].first) < mesh.segment_key(all[j].first);
    if (all[i].second != all[j].second) return all[i].second < all[j].second;
    return i < j;
  });
  on_segments.points.clear();
  on_segments.parent.clear();
  segment_round.clear();
  segment_owner.clear();
  for (std::size_t i : order) {
    const Vec2& x = points[i];
    // drop exact duplicates (a ring sample can coincide with a grid sample only by accident)
    if (!on_segments.points.empty() && on_segments.points.back() == x) continue;
    on_segments.points.push_back(x);
    on_segments.parent.push_back(static_cast<std::uint32_t>(all[i].first));
    segment_round.push_back(rounds[i]);
    segment_owner.push_back(owners[i]);
  }
}

// Samples on a straight chain (all its vertices within kStraightUlps units of
// rounding of the line through its end corners A, B: the tolerance that decides
// corners, triangulation.hpp) are projected onto that line. Chain points
// kept from earlier steps are rounded; sampling between them would let new
// boundary points drift by a rounding per step, while the projection keeps
// every boundary point within a rounding or two of the original side for any
// number of steps. A projection that would not lie strictly between its
// segment's end points (in the order along AB) keeps the sample as drawn.
void snap_to_straight_chains(const Mesh_arrays& mesh, const std::vector<Segment_chain>& chains, Sample_set& on_segments) {
  std::vector<Index> chain_of(mesh.segments.size(), -1);
  std::vector<std::uint8_t> straight(chains.size(), 0);
  for (std::size_t c = 0; c < chains.size(); ++c) {
    const auto& chain = chains[c];
    if (chain.closed || chain.vertices.size() < 3) continue;  // a single segment is exact already
    const Vec2& a = mesh.points[chain.vertices.front()];
    const Vec2& b = mesh.points[chain.vertices.back()];
    const double dx = b[0] - a[0], dy = b[1] - a[1];
    const double length2 = dx * dx + dy * dy;
    bool ok = length2 > 0;
    double reach = std::max({std::abs(a[0]), std::abs(a[1]), std::abs(b[0]), std::abs(b[1])});
    for (Index v : chain.vertices) reach = std::max({reach, std::abs(mesh.points[v][0]), std::abs(mesh.points[v][1])});
    const double tolerance = kStraightUlps * std::numeric_limits<double>::epsilon() * reach * std::sqrt(length2);
    for (std::size_t k = 1; ok && k + 1 < chain.vertices.size(); ++k) {
      const Vec2& v = mesh.points[chain.vertices[k]];
      const double cross = dx * (v[1] - a[1]) - dy * (v[0] - a[0]);
      ok = std::abs(cross) <= tolerance;  // distance from AB within kStraightUlps roundings
    }
    if (!ok) continue;
    straight[c] = 1;
    for (Index seg : chain.segments) chain_of[seg] = static_cast<Index>(c);
  }
  for (std::size_t j = 0; j < on_segments.points.size(); ++j) {
    const Index c = chain_of[on_segments.parent[j]];
    if (c < 0) continue;
    const auto& chain = chains[c];
    const Vec2& a = mesh.points[chain.vertices.front()];
    const Vec2& b = mesh.points[chain.vertices.back()];
    const double dx = b[0] - a[0], dy = b[1] - a[1];
    const double length2 = dx * dx + dy * dy;
    auto along = [&](const Vec2& p) { return ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / length2; };
    const Vec2& x = on_segments.points[j];
    const double t = along(x);
    const Vec2 y{a[0] + t * dx, a[1] + t * dy};
    const Edge& e = mesh.segments[on_segments.parent[j]];
    const double t0 = along(mesh.points[e[0]]), t1 = along(mesh.points[e[1]]);
    const double ty = along(y);
    if (ty > std::min(t0, t1) && ty < std::max(t0, t1) && y != mesh.points[e[0]] && y != mesh.points[e[1]]) {
      on_segments.points[j] = y;
    }
  }
}

}  // namespace

std::vector<std::uint8_t> Candidates::classes(bool on_segment) const {
  std::vector<std::uint8_t> out(size());
  for (std::size_t j = 0; j < out.size(); ++j) out[j] = new_point_class(on_segment, round[j]);
  return out;
}

double ring_reach(double radius_scale) {
  return kMargin * radius_scale / (1.0 - 0.5 * radius_scale);
}

int ring_candidates_of(const Mesh_arrays& mesh, const Triangle_fans& fans, const std::vector<double>& f, double reach,
                       std::uint64_t seed, std::size_t p, std::array<Ring_candidate, kRingDirections>& out) {
  constexpr double kTwoPi = 6.283185307179586;
  const Vec2& c = mesh.points[p];
  const double d = reach * f[p];
  Random_stream rng(seed, (std::uint64_t{3} << 61) + static_cast<std::uint64_t>(mesh.point_gid(p)));
  const double phase = rng.uniform() * kTwoPi / kRingDirections;
  int count = 0;
  for (int k = 0; k < kRingDirections; ++k) {
    const double angle = phase + kTwoPi * k / kRingDirections;
    const Vec2 x{c[0] + d * std::cos(angle), c[1] + d * std::sin(angle)};
    for (Index a = fans.xadj[p]; a < fans.xadj[p + 1]; ++a) {
      const Triangle& t = mesh.triangles[fans.adj[a]];
      if (orientation(mesh.points[t[0]], mesh.points[t[1]], x) > 0 &&
          orientation(mesh.points[t[1]], mesh.points[t[2]], x) > 0 &&
          orientation(mesh.points[t[2]], mesh.points[t[0]], x) > 0) {
        out[count++] = {x, fans.adj[a], k};
        break;
      }
    }
  }
  return count;
}

std::vector<std::uint8_t> settled_points(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                         const std::vector<double>& f) {
  const std::size_t n = mesh.points.size();
  std::vector<double> shortest2(n, std::numeric_limits<double>::infinity());
  for (const Triangle& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      const Index u = t[k], v = t[(k + 1) % 3];
      const double dx = mesh.points[u][0] - mesh.points[v][0], dy = mesh.points[u][1] - mesh.points[v][1];
      const double d2 = dx * dx + dy * dy;
      shortest2[u] = std::min(shortest2[u], d2);
      shortest2[v] = std::min(shortest2[v], d2);
    }
  }
  constexpr double kRoundings = 8 * std::numeric_limits<double>::epsilon();
  std::vector<std::uint8_t> settled(n, 0);
  for (std::size_t p = 0; p < n; ++p) {
    settled[p] = delta[p] == 1 && std::isfinite(shortest2[p]) && f[p] >= std::sqrt(shortest2[p]) * (1 - kRoundings);
  }
  return settled;
}

std::vector<std::uint8_t> unsampled_triangles(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                              const std::vector<std::uint8_t>& settled, const Frfc_options& options) {
  std::vector<std::uint8_t> skip;
  if (!options.skip_coarse && !options.skip_settled) return skip;
  skip.resize(mesh.triangles.size());
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    skip[t] = (options.skip_coarse && delta[tri[0]] > 1 && delta[tri[1]] > 1 && delta[tri[2]] > 1) ||
              (options.skip_settled && settled[tri[0]] && settled[tri[1]] && settled[tri[2]]);
  }
  return skip;
}

Candidates segment_candidates(const Mesh_arrays& mesh, const std::vector<double>& delta, const std::vector<double>& f,
                              const std::vector<Segment_chain>& chains, const Frfc_options& options,
                              const Spacing_queries* queries, const std::vector<std::uint8_t>* settled_given) {
  Candidates on_segments;
  on_segments.samples = sample_segments(mesh, f, options.cell_factor, options.samples, options.seed,
                                        options.adaptive_cells, queries);
  if (options.skip_settled) {
    // (the samples of a segment come from its own random stream: dropping a
    // segment's changes no other's)
    const auto settled = settled_given != nullptr ? *settled_given : settled_points(mesh, delta, f);
    Sample_set& samples = on_segments.samples;
    std::size_t k = 0;
    for (std::size_t j = 0; j < samples.points.size(); ++j) {
      const Edge& e = mesh.segments[samples.parent[j]];
      if (settled[e[0]] && settled[e[1]]) continue;
      samples.points[k] = samples.points[j];
      samples.parent[k] = samples.parent[j];
      ++k;
    }
    samples.points.resize(k);
    samples.parent.resize(k);
  }
  on_segments.round.assign(on_segments.size(), -1);
  on_segments.owner.assign(on_segments.size(), -1);
  if (options.ring_samples) {
    add_segment_ring_samples(mesh, delta, f, options.radius_scale, on_segments.samples, on_segments.round,
                             on_segments.owner);
  }
  snap_to_straight_chains(mesh, chains, on_segments.samples);
  return on_segments;
}

Candidates interior_candidates(const Mesh_arrays& mesh, const Triangle_fans& fans, const std::vector<double>& delta,
                               const std::vector<double>& f, const std::vector<std::uint8_t>& demoted,
                               const Cover_discs& cover,
                               const Frfc_options& options, std::size_t& n_drawn,
                               const std::vector<std::uint8_t>* quiet, const Spacing_queries* queries,
                               const std::vector<std::uint8_t>* settled_given,
                               const std::vector<std::uint8_t>* ring_from, std::vector<Index>* ring_point) {
  // options.skip_settled (unsampled_triangles) is why a step is idempotent on
  // its own output. Let M be the output of a step, and step again
  // with delta = 1 (or with a size= request that M meets: delta_from_size
  // gives exactly 1 there). At every point p,
  // f(p) = nn_M(p) (Lemma 3.1), and nn_M(p) is an edge of p (the nearest
  // neighbour is a Delaunay neighbour; M is a constrained Delaunay
  // triangulation with non-encroached segments), so every point is settled
  // (settled_points) and:
  // 1. no candidate: every triangle and segment is skipped here, and ring
  //    candidates exist only around points with delta < 1;
  // 2. every point is kept: spheres B(p, s f(p) / 2) with s <= 1 are pairwise
  //    disjoint (s nn(p) / 2 + s nn(q) / 2 <= |p - q|), nothing else is
  //    packed, and none is demoted (nn = f is below demote_ratio f);
  // 3. no repair: the spacing repair serves points with delta < 1, and the
  //    gap repair's distance at a kept point with delta = 1 is that of its
  //    nearest other output point, nn(p) <= gap_repair_ratio nn(p);
  // 4. the same points with the same constraint pieces (the segments between
  //    consecutive kept chain points: M's segments) have the same constrained
  //    Delaunay triangulation, M up to cocircular ties, in which the quality
  //    pass finds no crowded segment and, when M met min_angle, no triangle
  //    to split.
  // So the step returns M's points, every one kept. The paper's sampling
  // (skip_settled = false) offers samples wherever a sphere fits between
  // the old ones: in M's larger triangles, a few per thousand points a step.
  std::vector<std::uint8_t> settled;
  if (options.skip_settled && settled_given == nullptr) settled = settled_points(mesh, delta, f);
  std::vector<std::uint8_t> skip =
      unsampled_triangles(mesh, delta, settled_given != nullptr ? *settled_given : settled, options);
  if (quiet != nullptr) {
    if (skip.empty()) skip = *quiet;
    else for (std::size_t t = 0; t < skip.size(); ++t) skip[t] = skip[t] || (*quiet)[t];
  }
  n_drawn = 0;
  // Grid samples, then ring candidates, in blocks joined once (join_samples).
  std::vector<Sample_set> blocks = sample_triangle_blocks(mesh, f, options.cell_factor, options.samples, options.seed,
                                                          skip, cover, /*threads=*/0, &n_drawn,
                                                          options.adaptive_cells, queries);
  std::size_t n_grid = 0;
  for (const Sample_set& block : blocks) n_grid += block.points.size();
  std::vector<std::int8_t> ring_round;
  if (options.ring_samples) {
    // Around a demoted point the interpolated sizes are about kInterpolatedScale f(p):
    // the closest sphere that misses p's is then kMargin s (1 + kInterpolatedScale) f(p) / 2
    // away (0.84 f at s = 0.75), not ring_reach(s) f (1.22 f). Rings at the mean of the two
    // (1.03 f) measured best: at 0.84 f ten steps of delta = 0.8 overshoot by 32 %.
    const double near = kMargin * options.radius_scale * (1 + kInterpolatedScale) / 2;
    const double demoted_reach = options.radius == Radius_rule::interpolated
                                     ? 0.5 * (near + ring_reach(options.radius_scale))
                                     : ring_reach(options.radius_scale);
    add_interior_ring_samples(mesh, fans, delta, f, ring_reach(options.radius_scale), demoted_reach, demoted,
                              options.seed, cover, /*threads=*/0, blocks, ring_round, ring_from, ring_point);
  }
  Candidates inside;
  inside.samples = join_samples(blocks);
  inside.round.reserve(n_grid + ring_round.size());
  inside.round.assign(n_grid, -1);
  inside.round.insert(inside.round.end(), ring_round.begin(), ring_round.end());
  return inside;
}

std::vector<double> input_point_radii(const Mesh_arrays& mesh, const std::vector<double>& f,
                                      const Frfc_options& options) {
  std::vector<double> radius(mesh.points.size());
  for (std::size_t i = 0; i < radius.size(); ++i) {
    radius[i] = 0.5 * options.radius_scale * f[i];
    if (mesh.kind[i] == Point_kind::corner || mesh.kind[i] == Point_kind::boundary) radius[i] *= options.boundary_scale;
  }
  return radius;
}

void candidate_radii(const Mesh_arrays& mesh, const Spacing_function& spacing, const std::vector<double>& f,
                     const std::vector<std::uint8_t>& demoted, const Frfc_options& options, bool on_segment,
                     Candidates& candidates) {
  detail::parallel_resize(candidates.radius, candidates.size());
  if (options.radius != Radius_rule::cheap) {
    spacing.evaluate(candidates.samples.points.data(), candidates.size(), candidates.radius.data(), nullptr,
                     /*threads=*/0, /*certified=*/false);
  }
  candidate_radii_from_f(mesh, f, demoted, options, on_segment, candidates);
}

void candidate_radii_from_f(const Mesh_arrays& mesh, const std::vector<double>& f,
                            const std::vector<std::uint8_t>& demoted, const Frfc_options& options, bool on_segment,
                            Candidates& candidates) {
  const Sample_set& samples = candidates.samples;
  const std::size_t m = samples.points.size();
  if (candidates.radius.size() != m) {
    if (options.radius != Radius_rule::cheap) throw std::logic_error("candidate_radii_from_f: f at every candidate");
    detail::parallel_resize(candidates.radius, m);
  }
  double* out = candidates.radius.data();
  if (options.radius != Radius_rule::cheap) {
    if (options.radius == Radius_rule::interpolated && !demoted.empty()) {
      constexpr std::size_t kBlock = 1 << 16;
      parallel_for((m + kBlock - 1) / kBlock, /*threads=*/0, [&](std::size_t b) {
        for (std::size_t j = b * kBlock; j < std::min(m, (b + 1) * kBlock); ++j) {
          const Vec2& x = samples.points[j];
          double linear;
          if (on_segment) {
            const Edge& e = mesh.segments[samples.parent[j]];
            if (!demoted[e[0]] && !demoted[e[1]]) continue;
            const Vec2& a = mesh.points[e[0]];
            const Vec2& c = mesh.points[e[1]];
            const double dx = c[0] - a[0], dy = c[1] - a[1];
            const double t = std::clamp(((x[0] - a[0]) * dx + (x[1] - a[1]) * dy) / (dx * dx + dy * dy), 0.0, 1.0);
            linear = (1 - t) * f[e[0]] + t * f[e[1]];
          } else {
            const Triangle& tri = mesh.triangles[samples.parent[j]];
            if (!demoted[tri[0]] && !demoted[tri[1]] && !demoted[tri[2]]) continue;
            auto w = barycentric_coordinates(mesh.points, tri, x);
            for (double& v : w) v = std::max(v, 0.0);
            linear = (w[0] * f[tri[0]] + w[1] * f[tri[1]] + w[2] * f[tri[2]]) / (w[0] + w[1] + w[2]);
          }
          if (linear > 0) out[j] = std::min(out[j], std::max(kInterpolatedScale * linear, out[j] / kInterpolatedFloor));
        }
      });
    }
  } else {
    for (std::size_t j = 0; j < m; ++j) {
      Index q;
      if (on_segment) {
        const Edge& e = mesh.segments[samples.parent[j]];
        q = f[e[0]] <= f[e[1]] ? e[0] : e[1];
      } else {
        const Triangle& t = mesh.triangles[samples.parent[j]];
        q = t[0];
        if (f[t[1]] < f[q]) q = t[1];
        if (f[t[2]] < f[q]) q = t[2];
      }
      const Vec2& x = samples.points[j];
      out[j] = f[q] + std::hypot(x[0] - mesh.points[q][0], x[1] - mesh.points[q][1]);
    }
  }
  for (std::size_t j = 0; j < m; ++j) out[j] *= 0.5 * options.radius_scale * (on_segment ? options.boundary_scale : 1.0);
}

// A sample x is certainly rejected when it lies within cover(c) of a kept
// sphere B(c, r_c) at an input point c: f is 1-Lipschitz, so its radius is at
// least s (f(c) - |x - c|) / 2 (s = radius_scale; also for the cheap radius,
// which is at least f(x) / 2), and |x - c| < r_c + that radius when
// |x - c| (1 + s/2) < r_c + s f(c) / 2. Each triangle vertex v offers one such
// disc: its own when v is kept, else that of the kept input point that rejected
// it. Samples in a disc of their triangle are dropped before their radius is
// computed (the factor 1 - 1e-9 keeps rounding on the safe side); the kept
// spheres are the same as without. The interpolated radius min(f(x), l(x)) is
// also at least s m_v / 2, m_v the smallest f at a vertex of a triangle around
// v (l is a mean of f at x's triangle's vertices): v's disc is then cut to
// r_c + s m_v / 2.
Cover_discs cover_discs(const Mesh_arrays& mesh, const std::vector<double>& f,
                        const std::vector<double>& radius, const std::vector<std::uint8_t>& kept,
                        const std::vector<Index>& blocker, double radius_scale, bool interpolated) {
  const std::size_t n = mesh.points.size();
  check_fits_4_bytes(n, "points");
  Cover_discs cover;
  cover.points = &mesh.points;
  cover.centre.assign(n, 0);
  cover.reach.assign(n, 0.0);
  const double s = radius_scale;
  std::vector<double> floor;
  if (interpolated) {
    floor = f;
    for (const auto& t : mesh.triangles) {
      const double m = std::min({f[t[0]], f[t[1]], f[t[2]]});
      for (Index v : t) floor[v] = std::min(floor[v], m);
    }
  }
  for (std::size_t v = 0; v < n; ++v) {
    const Index c = kept[v] ? static_cast<Index>(v) : blocker[v];
    if (c < 0 || static_cast<std::size_t>(c) >= n) continue;
    double reach = (radius[c] + 0.5 * s * f[c]) / (1 + 0.5 * s);
    if (interpolated) reach = std::min(reach, radius[c] + 0.5 * s * kInterpolatedScale * floor[v]);
    cover.centre[v] = static_cast<std::uint32_t>(c);
    cover.reach[v] = reach * (1 - 1e-9);
  }
  return cover;
}

// With its radius known, a sample that overlaps the kept sphere of a vertex of
// its triangle (or of the kept point that rejected that vertex) is rejected by
// the packing for sure: the test is the packing's own conflict test, so
// dropping it here changes nothing.
void drop_blocked_candidates(const Mesh_arrays& mesh, const std::vector<Vec2>& centers,
                             const std::vector<double>& radius, const std::vector<std::uint8_t>& kept,
                             const std::vector<Index>& blocker, int threads, Candidates& inside) {
  const std::size_t m = inside.size();
  std::vector<std::uint8_t> drop(m, 0);
  constexpr std::size_t kBlock = 1 << 16;
  parallel_for((m + kBlock - 1) / kBlock, threads, [&](std::size_t b) {
    for (std::size_t j = b * kBlock; j < std::min(m, (b + 1) * kBlock); ++j) {
      const Vec2& x = inside.samples.points[j];
      const double r = inside.radius[j];
      for (Index v : mesh.triangles[inside.samples.parent[j]]) {
        const Index c = kept[v] ? v : blocker[v];
        if (c < 0) continue;
        const double ex = centers[c][0] - x[0];
        const double ey = centers[c][1] - x[1];
        const double sum = r + radius[c];
        if (detail::spheres_conflict(ex, ey, sum)) {
          drop[j] = 1;
          break;
        }
      }
    }
  });
  std::size_t k = 0;
  for (std::size_t j = 0; j < m; ++j) {
    if (drop[j]) continue;
    inside.samples.points[k] = inside.samples.points[j];
    inside.samples.parent[k] = inside.samples.parent[j];
    inside.round[k] = inside.round[j];
    inside.radius[k] = inside.radius[j];
    ++k;
  }
  inside.samples.points.resize(k);
  inside.samples.parent.resize(k);
  inside.round.resize(k);
  inside.radius.resize(k);
}

}  // namespace evomesh
