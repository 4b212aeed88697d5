#include "evomesh/frfc.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>

#include <CGAL/Delaunay_triangulation_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include "evomesh/detail/point_tree.hpp"
#include "evomesh/kernel.hpp"
#include "evomesh/packing.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/triangulation.hpp"

namespace evomesh {

namespace {

using detail::Stage_timer;

// Packing priority classes (Section 6): corner, boundary (existing, then ring
// candidates by round, then other segment samples), original, Steiner (points
// sampled in an earlier step), interior ring candidates by round, sampled now.
enum Priority : std::uint8_t {
  prio_corner = 0,
  prio_boundary = 1,
  prio_boundary_ring = 2,  // + round (0, 1)
  prio_boundary_sample = 4,
  prio_original = 5,
  prio_steiner = 6,
  prio_ring = 7,  // + round (0 .. kRingDirections - 1)
  prio_sampled = 7 + 6,
};

// Around every R-point p (delta < 1) f is a cone of slope 1 with its tip
// f(p) = delta nn_M(p) (Lemma 3.1). A sphere B(y, k f(y)/2) with f(y) = f(p) + |y - p|
// misses B(p, k f(p)/2) once |y - p| >= k f(p) / (1 - k/2). Candidates just beyond
// that distance are the smallest spheres that can be p's neighbours; offering them
// keeps nn_M'(p) close to f(p) instead of leaving the ring around p to spheres
// centred further away (the grid samples land there only up to a cell size).
//
// Ring candidates are packed in rounds: first one candidate per R-point (in
// radius order), then a second one, and so on, so that the rings of neighbouring
// R-points cannot take every place around p before p's own ring is offered.
// `inside_round`/`segment_round` receive the round of every sample (-1: not a ring sample).
constexpr int kRingDirections = 6;
constexpr double kMargin = 1.02;

double ring_reach(double radius_scale) {
  return kMargin * radius_scale / (1.0 - 0.5 * radius_scale);
}

// Work started on another thread and waited for later; the destructor waits
// too, so an exception on the main path never leaves a running thread behind.
class Background {
 public:
  template <class Work>
  void start(Work work, bool on_thread) {
    if (!on_thread) {
      work();
      return;
    }
    thread_ = std::thread([this, work]() {
      try {
        work();
      } catch (...) {
        error_ = std::current_exception();
      }
    });
  }
  void wait() {
    if (thread_.joinable()) thread_.join();
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
  }
  ~Background() {
    if (thread_.joinable()) thread_.join();
  }

 private:
  std::thread thread_;
  std::exception_ptr error_;
};

// Triangles around each point (compressed lists).
struct Triangle_fans {
  std::vector<Index> xadj, adj;
  explicit Triangle_fans(const Mesh_arrays& mesh) : xadj(mesh.points.size() + 1, 0), adj(3 * mesh.triangles.size()) {
    const std::size_t n = mesh.points.size();
    for (const auto& t : mesh.triangles) {
      for (Index v : t) ++xadj[v + 1];
    }
    for (std::size_t v = 0; v < n; ++v) xadj[v + 1] += xadj[v];
    std::vector<Index> fill(xadj.begin(), xadj.end() - 1);
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
      for (Index v : mesh.triangles[t]) adj[fill[v]++] = static_cast<Index>(t);
    }
  }
};

// The interior ring candidates of the R-point p, in round order: emit(x,
// triangle, round) for each of the kRingDirections points at distance reach f(p)
// (random phase from the seed) that lies strictly inside a triangle around p.
template <class Emit>
void ring_candidates_of(const Mesh_arrays& mesh, const Triangle_fans& fans, const std::vector<double>& f, double reach,
                        std::uint64_t seed, std::size_t p, Emit&& emit) {
  constexpr double kTwoPi = 6.283185307179586;
  const Vec2& c = mesh.points[p];
  const double d = reach * f[p];
  Random_stream rng(seed, (std::uint64_t{3} << 61) + p);
  const double phase = rng.uniform() * kTwoPi / kRingDirections;
  for (int k = 0; k < kRingDirections; ++k) {
    const double angle = phase + kTwoPi * k / kRingDirections;
    const Vec2 x{c[0] + d * std::cos(angle), c[1] + d * std::sin(angle)};
    for (Index a = fans.xadj[p]; a < fans.xadj[p + 1]; ++a) {
      const Triangle& t = mesh.triangles[fans.adj[a]];
      if (orientation(mesh.points[t[0]], mesh.points[t[1]], x) > 0 &&
          orientation(mesh.points[t[1]], mesh.points[t[2]], x) > 0 &&
          orientation(mesh.points[t[2]], mesh.points[t[0]], x) > 0) {
        emit(x, fans.adj[a], k);
        break;
      }
    }
  }
}

// Interior ring candidates of every R-point, in point order, appended to
// `inside` (with their rounds), except those in a cover disc of their triangle.
// Points are handled in parallel in fixed blocks joined in order.
void add_interior_ring_samples(const Mesh_arrays& mesh, const Triangle_fans& fans, const std::vector<double>& delta,
                               const std::vector<double>& f, double reach, std::uint64_t seed,
                               const std::vector<Disc>& cover, int threads, Sample_set& inside,
                               std::vector<std::int8_t>& inside_round) {
  const std::size_t n = mesh.points.size();
  constexpr std::size_t kBlock = 4096;
  const std::size_t n_blocks = (n + kBlock - 1) / kBlock;
  std::vector<Sample_set> blocks(n_blocks);
  std::vector<std::vector<std::int8_t>> rounds(n_blocks);
  parallel_for(n_blocks, threads, [&](std::size_t b) {
    for (std::size_t p = b * kBlock; p < std::min(n, (b + 1) * kBlock); ++p) {
      if (!(delta[p] < 1)) continue;
      ring_candidates_of(mesh, fans, f, reach, seed, p, [&](const Vec2& x, Index t, int round) {
        if (in_cover(cover, mesh.triangles[t], x)) return;
        blocks[b].points.push_back(x);
        blocks[b].parent.push_back(t);
        rounds[b].push_back(static_cast<std::int8_t>(round));
      });
    }
  });
  for (std::size_t b = 0; b < n_blocks; ++b) {
    inside.points.insert(inside.points.end(), blocks[b].points.begin(), blocks[b].points.end());
    inside.parent.insert(inside.parent.end(), blocks[b].parent.begin(), blocks[b].parent.end());
    inside_round.insert(inside_round.end(), rounds[b].begin(), rounds[b].end());
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
  std::sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) {
    if (all[i].first != all[j].first) return all[i].first < all[j].first;
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
    on_segments.parent.push_back(all[i].first);
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

// Spacing repair. The packing guarantees nn_M'(p) = Theta(f(p)) only up to a
// constant; where an R-point p that was kept ends up with no kept point within
// repair_ratio * delta(p) nn_M(p) (its ring blocked by larger spheres kept
// earlier), keep the ring candidate of p farthest from every kept point: first
// its candidates on segments (centres with segment_owner p, whose `kept` flag
// is set), then its interior ones (regenerated, as the sample filter may have
// dropped them; returned). That candidate lies just outside p's sphere, so
// afterwards nn_M'(p) is about 1.2 f(p). Nearest kept points come from a static
// kd-tree over the kept centres plus a Delaunay triangulation of the points
// added here. `n_added` receives the number of candidates added.
std::vector<Vec2> repair_spacing(const Mesh_arrays& mesh, const Triangle_fans& fans, const std::vector<double>& delta,
                                 const std::vector<double>& nn, const std::vector<double>& f, double reach,
                                 std::uint64_t seed, const std::vector<Vec2>& centers,
                                 const std::vector<Index>& segment_owner, double repair_ratio, int threads,
                                 std::vector<std::uint8_t>& kept, std::size_t& n_added) {
  using Delaunay = CGAL::Delaunay_triangulation_2<Kernel>;
  const std::size_t n = mesh.points.size();
  n_added = 0;
  std::vector<Vec2> kept_points;
  std::vector<Index> position_of(n, -1);
  for (std::size_t c = 0; c < centers.size(); ++c) {
    if (!kept[c]) continue;
    if (c < n) position_of[c] = static_cast<Index>(kept_points.size());
    kept_points.push_back(centers[c]);
  }
  if (kept_points.size() < 2) return {};
  const detail::Point_tree tree(kept_points);
  const std::vector<double> nn2 = tree.squared_nn(threads);
  std::vector<Index> needy;
  std::vector<std::uint8_t> is_needy(n, 0);
  for (std::size_t p = 0; p < n; ++p) {
    if (position_of[p] < 0 || !(delta[p] < 1)) continue;
    const double target = repair_ratio * delta[p] * nn[p];
    if (nn2[position_of[p]] > target * target) {
      is_needy[p] = 1;
      needy.push_back(static_cast<Index>(p));
    }
  }
  std::vector<Vec2> added;
  if (needy.empty()) return added;
  std::vector<std::vector<Index>> on_segments(n);  // segment ring candidates (centre indices) of needy points
  for (std::size_t j = 0; j < segment_owner.size(); ++j) {
    if (segment_owner[j] >= 0 && is_needy[segment_owner[j]]) on_segments[segment_owner[j]].push_back(static_cast<Index>(n + j));
  }
  Delaunay added_dt;  // every point added here (segment or interior)
  Delaunay::Vertex_handle hint;
  auto nearest2 = [&](const Vec2& x) {
    double best = tree.squared_nearest(x);
    if (added_dt.number_of_vertices() > 0) {
      const Point_2 q = to_cgal(x);
      hint = added_dt.nearest_vertex(q, hint == Delaunay::Vertex_handle() ? Delaunay::Face_handle() : hint->face());
      best = std::min(best, CGAL::squared_distance(q, hint->point()));
    }
    return best;
  };
  for (Index p : needy) {
    // re-check: an earlier repair may have served p
    const double target = repair_ratio * delta[p] * nn[p];
    double d2 = nn2[position_of[p]];
    if (added_dt.number_of_vertices() > 0) {
      const Point_2 q = to_cgal(mesh.points[p]);
      d2 = std::min(d2, CGAL::squared_distance(q, added_dt.nearest_vertex(q)->point()));
    }
    if (d2 <= target * target) continue;
    Index best_segment = -1;
    Vec2 best_point{0.0, 0.0};
    bool found = false;
    double best_d2 = 0;
    for (Index c : on_segments[p]) {
      const double e2 = nearest2(centers[c]);
      if (e2 > best_d2) {
        best_d2 = e2;
        best_segment = c;
        best_point = centers[c];
        found = true;
      }
    }
    ring_candidates_of(mesh, fans, f, reach, seed, static_cast<std::size_t>(p), [&](const Vec2& x, Index, int) {
      const double e2 = nearest2(x);
      if (e2 > best_d2) {
        best_d2 = e2;
        best_segment = -1;
        best_point = x;
        found = true;
      }
    });
    if (!found) continue;
    if (best_segment >= 0) kept[best_segment] = 1;
    else added.push_back(best_point);
    added_dt.insert(to_cgal(best_point));
    ++n_added;
  }
  return added;
}

}  // namespace

std::vector<Segment_chain> segment_chains(const Mesh_arrays& mesh) {
  const std::size_t n = mesh.points.size();
  const std::size_t k = mesh.segments.size();
  // Segments incident to each vertex (compressed lists: xadj/adj).
  std::vector<Index> xadj(n + 1, 0), adj(2 * k);
  for (const auto& e : mesh.segments) {
    ++xadj[e[0] + 1];
    ++xadj[e[1] + 1];
  }
  for (std::size_t v = 0; v < n; ++v) xadj[v + 1] += xadj[v];
  {
    std::vector<Index> fill(xadj.begin(), xadj.end() - 1);
    for (std::size_t s = 0; s < k; ++s) {
      adj[fill[mesh.segments[s][0]]++] = static_cast<Index>(s);
      adj[fill[mesh.segments[s][1]]++] = static_cast<Index>(s);
    }
  }
  // Chains end at corners: those of the geometry (classify_points, whatever the
  // kinds say) and points labelled corner. So every closed loop has a corner,
  // and a kind that calls a turning point "boundary" cannot straighten the
  // boundary through it (issue 9).
  const std::vector<Point_kind> geometric = classify_points(mesh);
  std::vector<std::uint8_t> is_corner(n, 0);
  for (std::size_t v = 0; v < n; ++v) {
    is_corner[v] = geometric[v] == Point_kind::corner || (xadj[v + 1] > xadj[v] && mesh.kind[v] == Point_kind::corner);
  }
  std::vector<std::uint8_t> used(k, 0);
  std::vector<Segment_chain> chains;
  auto walk = [&](Index start, Index first_segment) {
    Segment_chain chain;
    chain.boundary = mesh.segment_is_boundary[first_segment] != 0;
    Index v = start, s = first_segment;
    chain.vertices.push_back(v);
    while (true) {
      used[s] = 1;
      const Edge& e = mesh.segments[s];
      const bool forward = e[0] == v;
      const Index w = forward ? e[1] : e[0];
      chain.segments.push_back(s);
      chain.forward.push_back(forward);
      if (w == start) {
        chain.closed = true;
        break;
      }
      chain.vertices.push_back(w);
      if (is_corner[w]) break;
      const Index s0 = adj[xadj[w]], s1 = adj[xadj[w] + 1];
      s = s0 == s ? s1 : s0;
      v = w;
      if (used[s]) break;
    }
    chains.push_back(std::move(chain));
  };
  for (std::size_t v = 0; v < n; ++v) {
    if (!is_corner[v]) continue;
    for (Index a = xadj[v]; a < xadj[v + 1]; ++a) {
      if (!used[adj[a]]) walk(static_cast<Index>(v), adj[a]);
    }
  }
  for (std::size_t s = 0; s < k; ++s) {
    if (!used[s]) throw std::logic_error("segment_chains: a loop of segments without a corner");
  }
  return chains;
}

Evolve_result frfc(const Mesh_arrays& mesh, const std::vector<double>& delta, const Frfc_options& options) {
  const std::size_t n = mesh.points.size();
  if (delta.size() != n) throw Input_error("delta must have one value per mesh point");
  for (double d : delta) {
    if (!std::isfinite(d) || !(d > 0)) throw Input_error("delta must be finite and > 0");
  }
  options.validate();
  Evolve_result result;
  auto& stats = result.stats;
  Stage_timer timer(stats);
  const Thread_limit thread_limit(options.threads);  // also for the stages without a threads argument

  // Step 1: nn_M and the spacing function f (Section 3.1).
  result.input_nn = nn_spacing(mesh.points);
  std::vector<double> weight(n);
  for (std::size_t i = 0; i < n; ++i) weight[i] = delta[i] * result.input_nn[i];
  timer.lap("nn");
  Spacing_function spacing(mesh.points, weight);
  timer.lap("apollonius");
  auto& f = result.input_f;
  f.resize(n);
  // Lemma 3.1: f(p) = delta(p) nn_M(p) = w_p exactly where delta(p) <= 1; the
  // Apollonius graph answers the others (f_p(p) = w_p is one of the cones, so
  // f(p) <= w_p there too).
  {
    std::vector<Vec2> coarse;
    std::vector<std::size_t> which;
    for (std::size_t i = 0; i < n; ++i) {
      f[i] = weight[i];
      if (delta[i] > 1) {
        coarse.push_back(mesh.points[i]);
        which.push_back(i);
      }
    }
    std::vector<double> value(coarse.size());
    spacing.evaluate(coarse.data(), coarse.size(), value.data(), nullptr, options.threads);
    for (std::size_t k = 0; k < which.size(); ++k) f[which[k]] = std::min(value[k], weight[which[k]]);
  }
  timer.lap("spacing_at_points");

  // Step 2a: samples on segments, with the ring candidates of R-points on them.
  const double estimate = estimate_sample_count(mesh, f, options.cell_factor, options.max_samples, options.adaptive_cells);
  if (estimate > options.max_samples) {
    throw Input_error("delta asks for too much refinement in one step: sampling would create about " +
                      format_count(estimate) + " points (max_samples is " +
                      format_count(options.max_samples) +
                      "); delta is relative (the new spacing is delta times the current one): raise it, refine over "
                      "several steps, or raise max_samples");
  }
  Sample_set on_segments = sample_segments(mesh, f, options.cell_factor, options.samples, options.seed,
                                           options.adaptive_cells);
  std::vector<std::int8_t> segment_round(on_segments.points.size(), -1);
  std::vector<Index> segment_owner(on_segments.points.size(), -1);
  if (options.ring_samples) {
    add_segment_ring_samples(mesh, delta, f, options.radius_scale, on_segments, segment_round, segment_owner);
  }
  const auto chains = segment_chains(mesh);
  snap_to_straight_chains(mesh, chains, on_segments);
  const std::size_t n_seg = on_segments.points.size();
  timer.lap("sampling");

  // Sphere radii: radius_scale f(x) / 2, exact from the Apollonius graph or
  // (f(q) + |x - q|) / 2 with q the vertex of smallest f (Section 3.2, step 2).
  auto sample_radii = [&](const Sample_set& samples, bool on_segment, double* out) {
    const std::size_t m = samples.points.size();
    if (options.radius == Radius_rule::exact) {
      spacing.evaluate(samples.points.data(), m, out, nullptr, options.threads, /*certified=*/false);
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
  };
  // Candidates of the boundary and old-point classes: input points, then segment samples.
  std::vector<Vec2> centers;
  centers.reserve(n + n_seg);
  centers.insert(centers.end(), mesh.points.begin(), mesh.points.end());
  centers.insert(centers.end(), on_segments.points.begin(), on_segments.points.end());
  std::vector<double> radius(n + n_seg);
  for (std::size_t i = 0; i < n; ++i) {
    radius[i] = 0.5 * options.radius_scale * f[i];
    if (mesh.kind[i] == Point_kind::corner || mesh.kind[i] == Point_kind::boundary) radius[i] *= options.boundary_scale;
  }
  sample_radii(on_segments, true, radius.data() + n);
  timer.lap("sample_radii");

  // Steps 3-5: order the spheres, lexical-first MIS; corners are always kept.
  // Every interior sample comes after every input point and segment sample in
  // the order (its classes are last), so the MIS is computed in two passes: the
  // first over input points and segment samples decides them for good; the
  // second goes on with the interior samples, the spheres kept so far forced.
  std::vector<std::uint8_t> forced_corner(n, 0);
  for (std::size_t i = 0; i < n; ++i) forced_corner[i] = mesh.kind[i] == Point_kind::corner;
  for (const auto& chain : chains) {
    forced_corner[chain.vertices.front()] = 1;
    forced_corner[chain.vertices.back()] = 1;
  }
  std::vector<std::uint8_t> priority(n + n_seg);
  std::size_t n_forced = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (forced_corner[i]) {
      priority[i] = prio_corner;
      ++n_forced;
      continue;
    }
    switch (mesh.kind[i]) {
      case Point_kind::corner:
      case Point_kind::boundary: priority[i] = prio_boundary; break;
      case Point_kind::original: priority[i] = prio_original; break;
      default: priority[i] = prio_steiner; break;
    }
  }
  for (std::size_t j = 0; j < n_seg; ++j) {
    priority[n + j] = segment_round[j] < 0 ? prio_boundary_sample : prio_boundary_ring + segment_round[j];
  }
  const auto first_order = packing_order(priority, radius);
  std::vector<Index> blocker;
  auto kept = lexical_first_mis(centers, radius, first_order, n_forced, &blocker);
  const std::vector<std::uint8_t> kept_first(kept);
  // The kept input points and segment samples are final: the quality pass's
  // triangulation of them starts now, on a second thread, beside the interior
  // sampling and packing.
  std::vector<Vec2> first_points;
  for (std::size_t c = 0; c < n + n_seg; ++c) {
    if (kept_first[c]) first_points.push_back(centers[c]);
  }
  Early_triangulation early;
  Background early_work;
  if (options.quality) {
    early_work.start([&]() { early.insert_first(first_points); }, resolve_threads(options.threads) > 1);
  }
  timer.lap("lfmis");

  // Step 2b: interior samples. A sample x is certainly rejected when it lies
  // within cover(c) of a kept sphere B(c, r_c) at an input point c: f is
  // 1-Lipschitz, so its radius is at least s (f(c) - |x - c|) / 2 (s =
  // radius_scale; also for the cheap radius, which is at least f(x) / 2), and
  // |x - c| < r_c + that radius when |x - c| (1 + s/2) < r_c + s f(c) / 2. Each
  // triangle vertex v offers one such disc: its own when v is kept, else that of
  // the kept input point that rejected it. Samples in a disc of their triangle
  // are dropped before their radius is computed (the factor 1 - 1e-9 keeps
  // rounding on the safe side); the kept spheres are the same as without.
  std::vector<Disc> cover;
  if (options.filter_samples) {
    cover.assign(n, Disc{{0.0, 0.0}, 0.0});
    const double s = options.radius_scale;
    for (std::size_t v = 0; v < n; ++v) {
      const Index c = kept[v] ? static_cast<Index>(v) : blocker[v];
      if (c < 0 || static_cast<std::size_t>(c) >= n) continue;
      cover[v] = {mesh.points[c], (radius[c] + 0.5 * s * f[c]) / (1 + 0.5 * s) * (1 - 1e-9)};
    }
  }
  std::vector<std::uint8_t> skip;
  if (options.skip_coarse) {
    skip.resize(mesh.triangles.size());
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
      const auto& tri = mesh.triangles[t];
      skip[t] = delta[tri[0]] > 1 && delta[tri[1]] > 1 && delta[tri[2]] > 1;
    }
  }
  std::size_t n_drawn = 0;
  Sample_set inside = sample_triangles(mesh, f, options.cell_factor, options.samples, options.seed, skip, cover,
                                       options.threads, &n_drawn, options.adaptive_cells);
  std::vector<std::int8_t> inside_round(inside.points.size(), -1);
  const Triangle_fans fans(mesh);
  const double reach = ring_reach(options.radius_scale);
  if (options.ring_samples) {
    add_interior_ring_samples(mesh, fans, delta, f, reach, options.seed, cover, options.threads, inside, inside_round);
  }
  timer.lap("sampling");
  std::vector<double> inside_radius(inside.points.size());
  sample_radii(inside, false, inside_radius.data());
  timer.lap("sample_radii");
  if (options.filter_samples) {
    // With its radius known, a sample that overlaps the kept sphere of a vertex
    // of its triangle (or of the kept point that rejected that vertex) is
    // rejected by the packing for sure: the test is the packing's own conflict
    // test, so dropping it here changes nothing.
    const std::size_t m = inside.points.size();
    std::vector<std::uint8_t> drop(m, 0);
    constexpr std::size_t kBlock = 1 << 16;
    parallel_for((m + kBlock - 1) / kBlock, options.threads, [&](std::size_t b) {
      for (std::size_t j = b * kBlock; j < std::min(m, (b + 1) * kBlock); ++j) {
        const Vec2& x = inside.points[j];
        const double r = inside_radius[j];
        for (Index v : mesh.triangles[inside.parent[j]]) {
          const Index c = kept[v] ? v : blocker[v];
          if (c < 0) continue;
          const double ex = centers[c][0] - x[0];
          const double ey = centers[c][1] - x[1];
          const double sum = r + radius[c];
          if (ex * ex + ey * ey < sum * sum) {
            drop[j] = 1;
            break;
          }
        }
      }
    });
    std::size_t k = 0;
    for (std::size_t j = 0; j < m; ++j) {
      if (drop[j]) continue;
      inside.points[k] = inside.points[j];
      inside.parent[k] = inside.parent[j];
      inside_round[k] = inside_round[j];
      inside_radius[k] = inside_radius[j];
      ++k;
    }
    inside.points.resize(k);
    inside.parent.resize(k);
    inside_round.resize(k);
    inside_radius.resize(k);
    timer.lap("lfmis");
  }
  const std::size_t n_in = inside.points.size();

  // Second pass: the kept spheres of the first (in their order, forced), then the
  // interior samples by class, radius and index.
  std::vector<Index> second_order;
  {
    std::vector<Vec2> second_centers;
    std::vector<double> second_radius;
    for (Index c : first_order) {
      if (!kept[c]) continue;
      second_order.push_back(static_cast<Index>(second_centers.size()));
      second_centers.push_back(centers[c]);
      second_radius.push_back(radius[c]);
    }
    const std::size_t n_first = second_order.size();
    std::vector<std::uint8_t> inside_priority(n_in);
    for (std::size_t j = 0; j < n_in; ++j) {
      inside_priority[j] = inside_round[j] < 0 ? prio_sampled : prio_ring + inside_round[j];
    }
    for (Index j : packing_order(inside_priority, inside_radius)) second_order.push_back(static_cast<Index>(n_first + j));
    second_centers.insert(second_centers.end(), inside.points.begin(), inside.points.end());
    second_radius.insert(second_radius.end(), inside_radius.begin(), inside_radius.end());
    const auto second_kept = lexical_first_mis(second_centers, second_radius, second_order, n_first);
    kept.insert(kept.end(), second_kept.begin() + static_cast<std::ptrdiff_t>(n_first), second_kept.end());
  }
  centers.insert(centers.end(), inside.points.begin(), inside.points.end());
  const std::size_t total = n + n_seg + n_in;
  timer.lap("lfmis");
  std::size_t n_repairs = 0;
  std::vector<Vec2> repair_points;
  if (options.repair_ratio > 0 && options.ring_samples) {
    repair_points = repair_spacing(mesh, fans, delta, result.input_nn, f, reach, options.seed, centers, segment_owner,
                                   options.repair_ratio, options.threads, kept, n_repairs);
  }
  timer.lap("spacing_repair");

  // Output points: kept input points in input order and kept segment samples
  // (the first points of the early triangulation), kept interior samples, then
  // the points of the spacing repair (on segments, then inside).
  std::vector<Index> out_index(total, -1);
  Mesh_arrays out;
  std::vector<std::size_t> out_order;
  out_order.reserve(total);
  for (std::size_t c = 0; c < n + n_seg; ++c) {
    if (kept_first[c]) out_order.push_back(c);
  }
  for (std::size_t c = n + n_seg; c < total; ++c) {
    if (kept[c]) out_order.push_back(c);
  }
  for (std::size_t c = 0; c < n + n_seg; ++c) {
    if (kept[c] && !kept_first[c]) out_order.push_back(c);
  }
  for (std::size_t c : out_order) {
    out_index[c] = static_cast<Index>(out.points.size());
    out.points.push_back(centers[c]);
    if (c < n) {
      result.origin.push_back(static_cast<Index>(c));
      Point_kind k = mesh.kind[c];
      if (forced_corner[c]) k = Point_kind::corner;
      else if (k == Point_kind::sampled) k = Point_kind::steiner;
      out.kind.push_back(k);
    } else {
      result.origin.push_back(-1);
      out.kind.push_back(c < n + n_seg ? Point_kind::boundary : Point_kind::sampled);
    }
  }
  for (const Vec2& x : repair_points) {
    out.points.push_back(x);
    result.origin.push_back(-1);
    out.kind.push_back(Point_kind::sampled);
  }

  // Constraint pieces between consecutive kept points along every chain.
  std::vector<Index> segment_sample_begin(mesh.segments.size() + 1, 0);
  for (Index parent : on_segments.parent) ++segment_sample_begin[parent + 1];
  for (std::size_t s = 0; s < mesh.segments.size(); ++s) segment_sample_begin[s + 1] += segment_sample_begin[s];
  std::vector<Constraint_piece> pieces;
  std::vector<Index> along;
  for (const auto& chain : chains) {
    along.clear();
    for (std::size_t k = 0; k < chain.segments.size(); ++k) {
      const Index v = chain.vertices[k];
      if (kept[v]) along.push_back(out_index[v]);
      const Index s = chain.segments[k];
      const Index b = segment_sample_begin[s], e = segment_sample_begin[s + 1];
      if (chain.forward[k]) {
        for (Index j = b; j < e; ++j) {
          if (kept[n + j]) along.push_back(out_index[n + j]);
        }
      } else {
        for (Index j = e; j-- > b;) {
          if (kept[n + j]) along.push_back(out_index[n + j]);
        }
      }
    }
    if (chain.closed) along.push_back(along.front());
    else if (kept[chain.vertices.back()]) along.push_back(out_index[chain.vertices.back()]);
    // All segments of a boundary chain are oriented alike (domain on the left).
    const bool flip = chain.boundary && !chain.forward.front();
    for (std::size_t k = 0; k + 1 < along.size(); ++k) {
      Constraint_piece piece{along[k], along[k + 1], chain.boundary};
      if (flip) std::swap(piece.a, piece.b);
      pieces.push_back(piece);
    }
  }
  std::vector<Index> origin = std::move(result.origin);
  const Quality_options quality = options.quality_settings();
  early_work.wait();
  triangulate_selection(std::move(out), std::move(origin), pieces,
                        options.quality ? &quality : nullptr, result, options.quality ? &early : nullptr);
  timer.lap(options.quality ? "quality" : "cdt");
  finish_step(mesh, result, timer);
  stats.emplace_back("n_input_points", static_cast<double>(n));
  stats.emplace_back("n_segment_samples", static_cast<double>(n_seg));
  stats.emplace_back("n_interior_samples", static_cast<double>(n_in));
  stats.emplace_back("n_interior_samples_drawn", static_cast<double>(n_drawn));
  stats.emplace_back("n_candidates", static_cast<double>(total));
  stats.emplace_back("n_spacing_repairs", static_cast<double>(n_repairs));
  stats.emplace_back("n_hidden_sites", static_cast<double>(spacing.n_hidden()));
  stats.emplace_back("n_output_points", static_cast<double>(result.mesh.points.size()));
  stats.emplace_back("n_output_triangles", static_cast<double>(result.mesh.triangles.size()));
  return result;
}

void finish_step(const Mesh_arrays& input, Evolve_result& result, Stage_timer& timer) {
  result.parents = parent_map(input, result.mesh, result.origin);
  timer.lap("parent_map");
  auto& stats = result.stats;
  double seconds = 0;
  for (const auto& s : stats) {
    if (s.first.rfind("seconds_", 0) == 0) seconds += s.second;
  }
  stats.emplace_back("seconds_total", seconds);
  stats.emplace_back("parent_walk_steps", static_cast<double>(result.parents.n_walk_steps));
  stats.emplace_back("parent_located_globally", static_cast<double>(result.parents.n_located_globally));
}

void triangulate_selection(Mesh_arrays selected, std::vector<Index> origin,
                           const std::vector<Constraint_piece>& pieces, const Quality_options* quality,
                           Evolve_result& result, Early_triangulation* early) {
  auto& stats = result.stats;
  // CGAL's triangulations assume these (a piece from a point to itself, or out
  // of range, is undefined behaviour there): an internal error, never a crash.
  for (const auto& piece : pieces) {
    if (piece.a == piece.b || piece.a < 0 || piece.b < 0 || static_cast<std::size_t>(piece.a) >= selected.points.size() ||
        static_cast<std::size_t>(piece.b) >= selected.points.size()) {
      throw std::logic_error("triangulate_selection: a degenerate constraint piece");
    }
  }
  if (quality == nullptr) {
    selected.triangles = constrained_delaunay(selected.points, pieces);
    for (const auto& piece : pieces) {
      selected.segments.push_back({piece.a, piece.b});
      selected.segment_is_boundary.push_back(piece.boundary);
    }
    result.mesh = std::move(selected);
    result.origin = std::move(origin);
  } else {
    Refined_mesh refined = early ? early->finish(selected.points, selected.kind, pieces, *quality)
                                 : quality_triangulate(selected.points, selected.kind, pieces, *quality);
    result.origin.resize(refined.source.size());
    for (std::size_t i = 0; i < refined.source.size(); ++i) {
      result.origin[i] = refined.source[i] < 0 ? -1 : origin[refined.source[i]];
    }
    result.mesh = std::move(refined.mesh);
    const auto& report = refined.report;
    stats.emplace_back("quality_points_added", static_cast<double>(report.n_inserted));
    stats.emplace_back("quality_points_added_on_segments", static_cast<double>(report.n_inserted_on_segments));
    stats.emplace_back("quality_points_removed", static_cast<double>(report.n_removed));
    stats.emplace_back("quality_crowded_segments", static_cast<double>(report.n_crowded_segments));
    stats.emplace_back("quality_capped", report.capped ? 1.0 : 0.0);
  }
  // The smallest angle and where it is (Section 6 reports it per step).
  const auto angle = smallest_angle(result.mesh.points, result.mesh.triangles);
  stats.emplace_back("min_angle", angle.first);
  stats.emplace_back("min_angle_x", angle.second[0]);
  stats.emplace_back("min_angle_y", angle.second[1]);
}

}  // namespace evomesh
