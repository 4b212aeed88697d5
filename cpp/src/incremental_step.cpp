#include "evomesh/incremental_step.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <stdexcept>
#include <utility>

#include "evomesh/candidates.hpp"
#include "evomesh/detail/frfc_stages.hpp"
#include "evomesh/detail/sphere_conflict.hpp"
#include "evomesh/detail/step_scope.hpp"
#include "evomesh/global_ids.hpp"
#include "evomesh/local_feature_size.hpp"
#include "evomesh/packing.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/sampling.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/spacing_repair.hpp"
#include "evomesh/triangulation_update.hpp"

namespace evomesh {

namespace {

using detail::Stage_timer;
using namespace frfc_stages;

// The step declines (the full one runs) when delta != 1 at more than this share
// of the points: there the full step is as fast.
constexpr double kMaxActiveShare = 0.5;
// The triangulation is updated (not built whole) while its cavity holds at most
// this share of the input triangles: beyond, building it whole is as fast.
constexpr double kMaxCavityShare = 0.25;

// Relative slack of every distance bound below: far above rounding, so a bound
// computed in floating point still holds for the exact value it stands for.
constexpr double kSlack = 1e-7;

double squared_distance(const Vec2& a, const Vec2& b) {
  const double dx = a[0] - b[0], dy = a[1] - b[1];
  return dx * dx + dy * dy;
}

// Points bucketed in a uniform grid (about two per cell) for range queries.
class Point_grid {
 public:
  explicit Point_grid(const std::vector<Vec2>& points) : points_(points) {
    const std::size_t n = points.size();
    lo_ = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
    Vec2 hi{-lo_[0], -lo_[1]};
    for (const Vec2& p : points) {
      lo_ = {std::min(lo_[0], p[0]), std::min(lo_[1], p[1])};
      hi = {std::max(hi[0], p[0]), std::max(hi[1], p[1])};
    }
    side_ = std::max<std::int64_t>(1, static_cast<std::int64_t>(std::sqrt(static_cast<double>(n) / 2)));
    for (int k = 0; k < 2; ++k) {
      const double extent = hi[k] - lo_[k];
      cell_[k] = extent > 0 ? extent / static_cast<double>(side_) : 1.0;
    }
    start_.assign(static_cast<std::size_t>(side_ * side_) + 1, 0);
    std::vector<std::int64_t> cell_of(n);
    for (std::size_t i = 0; i < n; ++i) {
      cell_of[i] = cell(points[i][0], 0) + side_ * cell(points[i][1], 1);
      ++start_[static_cast<std::size_t>(cell_of[i]) + 1];
    }
    for (std::size_t c = 0; c + 1 < start_.size(); ++c) start_[c + 1] += start_[c];
    members_.resize(n);
    std::vector<std::int64_t> fill(start_.begin(), start_.end() - 1);
    for (std::size_t i = 0; i < n; ++i) members_[static_cast<std::size_t>(fill[cell_of[i]]++)] = static_cast<Index>(i);
  }

  // The smallest of `weight` over the points of every cell (for min_weight_near).
  void set_weights(const std::vector<double>& weight) {
    cell_min_.assign(start_.size() - 1, std::numeric_limits<double>::infinity());
    for (std::size_t c = 0; c + 1 < start_.size(); ++c) {
      for (std::int64_t k = start_[c]; k < start_[c + 1]; ++k) {
        cell_min_[c] = std::min(cell_min_[c], weight[members_[static_cast<std::size_t>(k)]]);
      }
    }
  }
  // A lower bound on the weight of the points within distance r of x.
  double min_weight_near(const Vec2& x, double r) const {
    const std::int64_t x0 = cell(x[0] - r, 0), x1 = cell(x[0] + r, 0);
    const std::int64_t y0 = cell(x[1] - r, 1), y1 = cell(x[1] + r, 1);
    double m = std::numeric_limits<double>::infinity();
    for (std::int64_t cy = y0; cy <= y1; ++cy) {
      for (std::int64_t cx = x0; cx <= x1; ++cx) m = std::min(m, cell_min_[static_cast<std::size_t>(cx + side_ * cy)]);
    }
    return m;
  }

  // Calls visit(i) for every point within distance r of x (and perhaps a few
  // slightly farther: callers only need a superset).
  template <class Visit>
  void visit_within(const Vec2& x, double r, Visit visit) const {
    const std::int64_t x0 = cell(x[0] - r, 0), x1 = cell(x[0] + r, 0);
    const std::int64_t y0 = cell(x[1] - r, 1), y1 = cell(x[1] + r, 1);
    const double r2 = r * r * (1 + kSlack);
    for (std::int64_t cy = y0; cy <= y1; ++cy) {
      for (std::int64_t cx = x0; cx <= x1; ++cx) {
        const std::size_t c = static_cast<std::size_t>(cx + side_ * cy);
        for (std::int64_t k = start_[c]; k < start_[c + 1]; ++k) {
          const Index i = members_[static_cast<std::size_t>(k)];
          const double dx = points_[i][0] - x[0], dy = points_[i][1] - x[1];
          if (dx * dx + dy * dy <= r2) visit(i);
        }
      }
    }
  }

 private:
  std::int64_t cell(double v, int axis) const {
    const double c = std::floor((v - lo_[axis]) / cell_[axis]);
    if (!(c > 0)) return 0;  // also NaN
    return c >= static_cast<double>(side_ - 1) ? side_ - 1 : static_cast<std::int64_t>(c);
  }
  const std::vector<Vec2>& points_;
  Vec2 lo_{0, 0};
  std::array<double, 2> cell_{1, 1};
  std::int64_t side_ = 1;
  std::vector<std::int64_t> start_;
  std::vector<Index> members_;
  std::vector<double> cell_min_;
};

// The Apollonius graph of the sites `marked` (with their weights), for queries
// at which every site that can attain f is marked: the adaptive grids' queries
// (grid_queries), which come without a bound of their own (the points' and the
// candidates' use Cone_scan). Eq. 3: f(x) = min_c (w_c + |x - c|) with w_c >= 0,
// so the site c attaining f(x) has w_c + |x - c| = f(x) <= u(x) for any upper
// bound u; marking every site with w_c + |x - c| <= u(x) for every query x
// (Mark_sites) keeps the minimising site of every query and every site tied with
// it up to rounding, so the answers are those of the graph of all sites
// (Spacing_function::evaluate: a function of the sites near x), with the same
// shift (hidden sites decided alike) and ids (exact ties broken alike).
class Restricted_spacing {
 public:
  Restricted_spacing(const std::vector<Vec2>& points, const std::vector<double>& weight,
                     const std::vector<std::uint8_t>& marked, double shift, const std::vector<std::int64_t>& ids) {
    std::vector<Vec2> sites;
    std::vector<double> weights;
    std::vector<std::int64_t> site_ids;
    for (std::size_t i = 0; i < marked.size(); ++i) {
      if (!marked[i]) continue;
      sites.push_back(points[i]);
      weights.push_back(weight[i]);
      if (!ids.empty()) site_ids.push_back(ids[i]);
    }
    n_sites_ = sites.size();
    if (sites.empty()) {  // no query: a graph that is never asked
      sites.push_back(points[0]);
      weights.push_back(weight[0]);
      if (!ids.empty()) site_ids.push_back(ids[0]);
    }
    function_ = std::make_unique<Spacing_function>(sites, weights, 0, nullptr, &site_ids, shift);
  }
  const Spacing_function& function() const { return *function_; }
  std::size_t n_sites() const { return n_sites_; }

 private:
  std::unique_ptr<Spacing_function> function_;
  std::size_t n_sites_ = 0;
};

// Flags over n items set by `count` queries, in parallel chunks: chunk(begin,
// end, flags) answers queries [begin, end) into its own zeroed flags, and the
// chunks' flags are or-ed (the same flags in any order, for any thread count).
template <class Chunk>
std::vector<std::uint8_t> flags_in_chunks(std::size_t count, std::size_t n, Chunk chunk) {
  const std::size_t chunks =
      std::clamp<std::size_t>(count / 4096, 1, static_cast<std::size_t>(std::max(1, resolve_threads(0))));
  std::vector<std::vector<std::uint8_t>> flags(chunks, std::vector<std::uint8_t>(n, 0));
  parallel_for(chunks, 0, [&](std::size_t c) { chunk(count * c / chunks, count * (c + 1) / chunks, flags[c]); });
  for (std::size_t c = 1; c < chunks; ++c) {
    for (std::size_t i = 0; i < n; ++i) flags[0][i] |= flags[c][i];
  }
  return std::move(flags[0]);
}

// Marks the sites whose cone can attain f at query points (Restricted_spacing):
// near(x, u) for a bound u with w_c + |x - c| <= u for the site c attaining f at
// every query it stands for (at x itself: u >= f(x)) marks the sites c with w_c
// + |x - c| <= u, which keeps c. (Not every site within u of x: a heavy one
// within reach is no minimum there; about a ninth of them, on an even mesh.)
// The slack keeps every site whose cone ties with c's up to rounding, where the
// full step's walk may end (Spacing_function::evaluate, certified = false).
struct Mark_sites {
  const Point_grid& grid;
  const std::vector<Vec2>& points;
  const std::vector<double>& weight;
  std::vector<std::uint8_t> marked;
  double absolute;  // rounding of the coordinates' magnitude
  Mark_sites(const Point_grid& g, const std::vector<Vec2>& p, const std::vector<double>& w, double magnitude)
      : grid(g), points(p), weight(w), marked(p.size(), 0), absolute(1e-12 * magnitude) {}
  void near(const Vec2& x, double u) {
    const double reach = u * (1 + kSlack) + absolute;
    grid.visit_within(x, reach, [&](Index i) {
      if (weight[i] + std::sqrt(squared_distance(x, points[i])) * (1 - kSlack) <= reach) marked[i] = 1;
    });
  }
};

// Triangles whose grid samples the packing certainly rejects, so that not
// drawing them changes nothing (their candidate indices only order them among
// themselves). A sample x of triangle T gets the sphere B(x, s f(x) / 2) (s =
// radius_scale; interpolated radii only differ in triangles with a demoted
// vertex, cheap ones are larger), and comes after every input point in the
// packing order, so it is rejected when it overlaps the kept sphere B(v, r_v)
// of a vertex v: |x - v| - r_v < s f(x) / 2. With H = max over x in T of
// min_v (|x - v| - r_v), it suffices that f > 2H/s on T. f(x) = min_c (w_c +
// |x - c|) over all sites c (Eq. 3). A site other than T's vertices that is
// farther than 2H/s from T cannot go below 2H/s, and one nearer needs w_c +
// dist(c, T) > 2H/s; the vertices' own cones are bounded through the distance to
// the nearest vertex (below). So T is quiet when its vertices are kept by the
// first pass and not demoted, and every site passes its test. H <= R - min_v
// r_v, R the circumradius (below).
// Every bound carries the slack kSlack and the
// rounding of the coordinates, far above the rounding of the packing's tests.
// Triangles in `unsampled` (unsampled_triangles: every vertex settled, say)
// draw no grid samples at all: quiet without the test. On a step's own output
// that is most triangles outside the change.
std::vector<std::uint8_t> quiet_triangles(const Mesh_arrays& mesh, const Point_grid& grid,
                                          const std::vector<double>& weight, const std::vector<double>& radius,
                                          const std::vector<std::uint8_t>& kept,
                                          const std::vector<std::uint8_t>& demoted,
                                          const std::vector<std::uint8_t>& unsampled, double radius_scale,
                                          double magnitude, int threads) {
  const std::size_t m = mesh.triangles.size();
  const std::size_t n = mesh.points.size();
  std::vector<std::uint8_t> quiet(m, 0);
  const double absolute = 64 * std::numeric_limits<double>::epsilon() * magnitude;
  // What a triangle reads of its vertices, in one place (the triangles visit
  // the points in no spatial order: one cache line a vertex, not four);
  // radius -1: not kept by the first pass, or demoted.
  struct Vertex {
    Vec2 p;
    double radius, weight;
  };
  std::vector<Vertex> V(n);
  for (std::size_t i = 0; i < n; ++i) {
    const bool sphere = kept[i] && (demoted.empty() || !demoted[i]);
    V[i] = {mesh.points[i], sphere ? radius[i] : -1.0, weight[i]};
  }
  constexpr std::size_t kBlock = 1 << 14;
  parallel_for((m + kBlock - 1) / kBlock, threads, [&](std::size_t b) {
    for (std::size_t t = b * kBlock; t < std::min(m, (b + 1) * kBlock); ++t) {
      if (!unsampled.empty() && unsampled[t]) {  // no sample to reject: quiet as it is
        quiet[t] = 1;
        continue;
      }
      const Triangle& tri = mesh.triangles[t];
      const Vertex &va = V[tri[0]], &vb = V[tri[1]], &vc = V[tri[2]];
      const double r_min = std::min({va.radius, vb.radius, vc.radius});
      if (!(r_min >= 0)) continue;
      const Vec2 &a = va.p, &b2 = vb.p, &c = vc.p;
      const std::array<const Vec2*, 3> v{&a, &b2, &c};
      // Every point of T is within the circumradius of a vertex (T is covered by
      // the kites v - edge midpoints - circumcentre, or for an obtuse T by their
      // parts cut off by the long edge, whose corners are all within R of v).
      const double ax = b2[0] - a[0], ay = b2[1] - a[1], bx = c[0] - a[0], by = c[1] - a[1];
      const double cross = ax * by - ay * bx;
      const double la = ax * ax + ay * ay, lb = bx * bx + by * by;
      if (!(std::abs(cross) > 1e-3 * std::sqrt(la * lb))) continue;  // near-degenerate: not certified
      const double ox = (la * by - lb * ay) / (2 * cross), oy = (ax * lb - bx * la) / (2 * cross);
      double far = std::sqrt(ox * ox + oy * oy);
      const double w_min = std::min({va.weight, vb.weight, vc.weight});
      far = far * (1 + kSlack) + absolute;
      const double h = far - r_min * (1 - kSlack);
      if (h <= 0) {
        quiet[t] = 1;
        continue;
      }
      // The cones of the vertices: with d(x) the distance to the nearest vertex,
      // h(x) <= d(x) - r_min and w_u + |x - u| >= w_min + d(x), so they need
      // (1 - s/2) d < r_min + s/2 w_min at d = far.
      if (!((1 - radius_scale / 2) * far < (r_min + radius_scale / 2 * w_min) * (1 - kSlack))) continue;
      const double need = 2 * h / radius_scale * (1 + kSlack) + absolute;  // the other cones must exceed this on T
      const double gx = (a[0] + b2[0] + c[0]) / 3, gy = (a[1] + b2[1] + c[1]) / 3;
      // (lengths as square roots of sums of squares: the input's limits, |x| <=
      // 1e75 and no two points within 1e-75 (mesh.py), keep the squares normal,
      // and their rounding is far below kSlack)
      double reach2 = 0;
      for (const Vec2* p : v) reach2 = std::max(reach2, squared_distance(*p, {gx, gy}));
      const double reach = std::sqrt(reach2) * (1 + kSlack);
      // Most often every weight near T is above `need` already.
      if (grid.min_weight_near({gx, gy}, reach + need) > need) {
        quiet[t] = 1;
        continue;
      }
      bool ok = true;
      grid.visit_within({gx, gy}, reach + need, [&](Index site) {
        if (!ok || site == tri[0] || site == tri[1] || site == tri[2]) return;
        // (the distance below is >= 0: a heavy site passes without it)
        if (V[site].weight - absolute > need) return;
        const Vec2& x = V[site].p;
        // Distance from the site to T (0 inside), from below.
        double d2 = std::numeric_limits<double>::infinity();
        bool inside = true;
        for (int e = 0; e < 3; ++e) {
          const Vec2& p = *v[e];
          const Vec2& q = *v[(e + 1) % 3];
          const double dx = q[0] - p[0], dy = q[1] - p[1];
          const double wx = x[0] - p[0], wy = x[1] - p[1];
          inside = inside && dx * wy - dy * wx > 0;
          const double tt = std::clamp((wx * dx + wy * dy) / (dx * dx + dy * dy), 0.0, 1.0);
          const double ex = wx - tt * dx, ey = wy - tt * dy;
          d2 = std::min(d2, ex * ex + ey * ey);
        }
        const double d = inside ? 0.0 : std::sqrt(d2);
        ok = V[site].weight + d * (1 - kSlack) - absolute > need;
      });
      quiet[t] = ok;
    }
  });
  return quiet;
}

// Reaches below grow by this factor: a safe point's radius may exceed nn / 2 by
// kSlack (safe_old_points), which the bounds' derivations then carry (below).
constexpr double kSafeReach = 1 + 4 * kSlack;

// Old points whose sphere conflicts with no other old point's: radius <= (1 +
// kSlack) nn / 2, nn the Euclidean nearest-neighbour distance (not grown within
// the domain), and no conflict by the packing's own test. Two spheres with
// radius <= nn / 2 (1 - kSlack) are disjoint with a margin above rounding (r_p +
// r_q <= (nn_p + nn_q) / 2 <= |p - q|). The others up to (1 + kSlack) nn / 2 (the
// paper's radius f / 2 = nn / 2 at delta = 1, where the double test decides
// between nearest neighbours) are tested against every old point q that can
// conflict: |p - q| < r_p + r_q needs |p - q| < max(nn_p, nn_q)(1 + kSlack), and
// when nn_q > nn_p, q's radius is either in the tested band too (the pair is
// found from q) or below it, and then |p - q| < nn_p (1 + 2 kSlack): each pair
// is met from a point of the band within (1 + 2 kSlack) of its nn. A pair that
// conflicts makes both unsafe. So no two safe spheres conflict, and among old
// points only the unsafe ("dangerous": delta > 1 with f > nn / 2 s, a conflict,
// nn grown within the domain) and the candidates can conflict with a safe one.
// A safe p's radius r_p <= (1 + kSlack) |p - v| / 2 for every other point v,
// which the reaches below cover with kSafeReach.
std::vector<std::uint8_t> safe_old_points(const std::vector<Vec2>& points, const std::vector<double>& radius,
                                          const std::vector<double>& nn, const std::vector<std::uint8_t>& evaluate,
                                          const Point_grid& grid, double magnitude) {
  const std::size_t n = points.size();
  std::vector<std::uint8_t> safe(n, 0), tested(n, 0);
  for (std::size_t p = 0; p < n; ++p) {
    if (!evaluate.empty() && evaluate[p]) continue;
    safe[p] = radius[p] <= 0.5 * nn[p] * (1 + kSlack);
    tested[p] = safe[p] && !(radius[p] <= 0.5 * nn[p] * (1 - kSlack));
  }
  const double absolute = 1e-12 * magnitude;
  const auto conflicting = flags_in_chunks(n, n, [&](std::size_t begin, std::size_t end,
                                                      std::vector<std::uint8_t>& flags) {
    for (std::size_t p = begin; p < end; ++p) {
      if (!tested[p]) continue;
      grid.visit_within(points[p], nn[p] * (1 + 2 * kSlack) + absolute, [&](Index q) {
        if (static_cast<std::size_t>(q) == p || !safe[q]) return;
        const double ex = points[p][0] - points[q][0], ey = points[p][1] - points[q][1];
        if (detail::spheres_conflict(ex, ey, radius[p] + radius[q])) flags[p] = flags[q] = 1;
      });
    }
  });
  for (std::size_t p = 0; p < n; ++p) safe[p] = safe[p] && !conflicting[p];
  return safe;
}

// The first packing pass (frfc_stages::first_packing_pass) on the spheres whose
// fate is not certain, with the same result. The lexical-first MIS restricted to
// a set of spheres closed under overlap (every sphere overlapping a member is a
// member) is the MIS of all spheres restricted to it. The set: the forced
// corners, every segment candidate and dangerous old point, and every safe old
// point that overlaps one of those. A safe old point p overlapping a sphere d
// lies within 2 r_d of d when d is an old point (r_p <= nn_p / 2 <= |p - d| / 2;
// with the (1 + kSlack) of safe_old_points, within kSafeReach of that)
// and within |e - d| + 2 r_d of d when d is a candidate on a segment with end e
// (r_p <= |p - e| / 2). Safe old points outside the set overlap nothing earlier:
// they are kept. Blockers may differ from the full pass's (another kept sphere
// that overlaps); they only feed the sample filters, which are exact with any.
Packing first_pass_near(const Mesh_arrays& mesh, const std::vector<double>& f, const std::vector<double>& nn,
                        const std::vector<std::uint8_t>& evaluate, const Candidates& on_segments,
                        const std::vector<std::uint8_t>& forced, std::size_t n_forced,
                        const std::vector<std::uint8_t>& demoted, const Frfc_options& options, const Point_grid& grid,
                        double magnitude, std::vector<std::uint8_t>& safe, std::size_t& n_packed) {
  const std::size_t n = mesh.points.size();
  const std::size_t n_seg = on_segments.size();
  Packing packing;
  packing.centers = mesh.points;
  packing.centers.insert(packing.centers.end(), on_segments.samples.points.begin(), on_segments.samples.points.end());
  packing.radius = input_point_radii(mesh, f, options);
  packing.radius.insert(packing.radius.end(), on_segments.radius.begin(), on_segments.radius.end());
  std::vector<std::uint8_t> classes(n + n_seg);
  for (std::size_t i = 0; i < n; ++i) {
    classes[i] = old_point_class(mesh.kind[i], forced[i], demoted[i]);
    packing.n_demoted += demoted[i];
  }
  const auto segment_classes = on_segments.classes(/*on_segment=*/true);
  std::copy(segment_classes.begin(), segment_classes.end(), classes.begin() + static_cast<std::ptrdiff_t>(n));
  safe = safe_old_points(mesh.points, packing.radius, nn, evaluate, grid, magnitude);
  const double absolute = 1e-12 * magnitude;
  std::vector<std::uint8_t> member(n + n_seg, 0);
  auto add_near = [&](const Vec2& d, double reach) {
    grid.visit_within(d, reach * kSafeReach + absolute, [&](Index p) { member[p] = 1; });
  };
  for (std::size_t i = 0; i < n; ++i) {
    if (safe[i] && !forced[i]) continue;
    member[i] = 1;
    add_near(mesh.points[i], 2 * packing.radius[i]);
  }
  for (std::size_t j = 0; j < n_seg; ++j) {
    member[n + j] = 1;
    const Edge& e = mesh.segments[on_segments.samples.parent[j]];
    const Vec2& x = on_segments.samples.points[j];
    double to_end = std::numeric_limits<double>::infinity();
    for (Index v : e) to_end = std::min(to_end, std::sqrt(squared_distance(x, mesh.points[v])));
    add_near(x, to_end + 2 * on_segments.radius[j]);
  }
  // Members in the full pass's tie order: input points by global id (index
  // without ids), then the segment candidates (already in their keys' order).
  std::vector<Index> members;
  const std::vector<Index> by_id = order_by_ids(mesh.point_gids);
  for (std::size_t r = 0; r < n; ++r) {
    const std::size_t c = visit(by_id, r);
    if (member[c]) members.push_back(static_cast<Index>(c));
  }
  for (std::size_t c = n; c < n + n_seg; ++c) {
    if (member[c]) members.push_back(static_cast<Index>(c));
  }
  n_packed = members.size();
  std::vector<Vec2> centers(members.size());
  std::vector<double> radii(members.size());
  std::vector<std::uint8_t> member_classes(members.size());
  for (std::size_t k = 0; k < members.size(); ++k) {
    centers[k] = packing.centers[members[k]];
    radii[k] = packing.radius[members[k]];
    member_classes[k] = classes[members[k]];
  }
  std::vector<Index> blocker;
  const auto kept =
      lexical_first_mis(centers, radii, packing_order(member_classes, radii), n_forced, &blocker, /*threads=*/0);
  packing.kept.assign(n + n_seg, 0);
  packing.blocker.assign(n + n_seg, -1);
  for (std::size_t c = 0; c < n; ++c) packing.kept[c] = !member[c];  // safe and alone: kept
  for (std::size_t k = 0; k < members.size(); ++k) {
    packing.kept[members[k]] = kept[k];
    packing.blocker[members[k]] = blocker[k] < 0 ? -1 : members[blocker[k]];
  }
  // As in first_packing_pass: demoted interior points go to the second pass (by global id).
  defer_demoted_points(classes, n, packing);
  if (!mesh.point_gids.empty()) {
    std::sort(packing.deferred.begin(), packing.deferred.end(),
              [&](Index a, Index b) { return mesh.point_gids[a] < mesh.point_gids[b]; });
  }
  return packing;
}

// The second pass (frfc_stages::second_packing_pass) with, of the first pass's
// kept spheres (forced), those that can overlap a sphere of the pass: every
// dangerous or segment one, and the safe old points near one: a safe p overlaps
// B(x, r) only within 2 r + |x - v| of x for any mesh point v != p (r_p <= nn_p
// / 2 <= |p - v| / 2; with safe_old_points' (1 + kSlack), within kSafeReach of
// that), v a vertex of x's triangle, or x itself for a deferred old point. The
// forced spheres' order among themselves does not matter.
void second_pass_near(const Mesh_arrays& mesh, const Candidates& inside, const std::vector<std::uint8_t>& safe,
                      const Point_grid& grid, double magnitude, Packing& packing, std::size_t& n_packed) {
  const std::size_t n = mesh.points.size();
  const std::size_t n_first = packing.kept.size();
  const std::size_t n_deferred = packing.deferred.size();
  std::vector<Vec2> centers;
  std::vector<double> radii;
  std::vector<std::uint8_t> classes;
  for (Index c : packing.deferred) {
    centers.push_back(packing.centers[c]);
    radii.push_back(packing.radius[c]);
    classes.push_back(class_new);
  }
  centers.insert(centers.end(), inside.samples.points.begin(), inside.samples.points.end());
  radii.insert(radii.end(), inside.radius.begin(), inside.radius.end());
  const auto inside_classes = inside.classes(/*on_segment=*/false);
  classes.insert(classes.end(), inside_classes.begin(), inside_classes.end());
  const double absolute = 1e-12 * magnitude;
  std::vector<std::uint8_t> forced_member(n_first, 0);
  for (std::size_t c = 0; c < n_first; ++c) forced_member[c] = packing.kept[c] && (c >= n || !safe[c]);
  // The kept spheres near the deferred points and the candidates, in parallel
  // chunks (each its own flags, or-ed: the same members in any order).
  const auto near = flags_in_chunks(n_deferred + inside.size(), n_first, [&](std::size_t begin, std::size_t end,
                                                                            std::vector<std::uint8_t>& flags) {
    auto add_near = [&](const Vec2& x, double reach) {
      grid.visit_within(x, reach * kSafeReach + absolute, [&](Index p) { flags[p] = 1; });
    };
    for (std::size_t k = begin; k < end; ++k) {
      if (k < n_deferred) {
        add_near(centers[k], 2 * radii[k]);
        continue;
      }
      const std::size_t j = k - n_deferred;
      const Vec2& x = inside.samples.points[j];
      double to_vertex = std::numeric_limits<double>::infinity();
      for (Index v : mesh.triangles[inside.samples.parent[j]]) {
        to_vertex = std::min(to_vertex, std::sqrt(squared_distance(x, mesh.points[v])));
      }
      add_near(x, 2 * inside.radius[j] + to_vertex);
    }
  });
  for (std::size_t p = 0; p < n_first; ++p) {
    if (near[p]) forced_member[p] = packing.kept[p];
  }
  std::vector<Vec2> all_centers;
  std::vector<double> all_radii;
  std::vector<Index> order;
  for (std::size_t c = 0; c < n_first; ++c) {
    if (!forced_member[c]) continue;
    order.push_back(static_cast<Index>(all_centers.size()));
    all_centers.push_back(packing.centers[c]);
    all_radii.push_back(packing.radius[c]);
  }
  const std::size_t n_forced = order.size();
  n_packed = n_forced + centers.size();
  for (Index j : packing_order(classes, radii)) order.push_back(static_cast<Index>(n_forced) + j);
  all_centers.insert(all_centers.end(), centers.begin(), centers.end());
  all_radii.insert(all_radii.end(), radii.begin(), radii.end());
  const auto kept = lexical_first_mis(all_centers, all_radii, order, n_forced);
  for (std::size_t k = 0; k < n_deferred; ++k) packing.kept[packing.deferred[k]] = kept[n_forced + k];
  packing.kept.insert(packing.kept.end(), kept.begin() + static_cast<std::ptrdiff_t>(n_forced + n_deferred),
                      kept.end());
  packing.centers.insert(packing.centers.end(), inside.samples.points.begin(), inside.samples.points.end());
  packing.radius.insert(packing.radius.end(), inside.radius.begin(), inside.radius.end());
}

// An upper bound of f at the points `asked` (elsewhere the weight): f(p) =
// min_c (w_c + |p - c|) over all sites (Eq. 3), so f(p) <= w_q + |p - q| for p
// itself and its mesh neighbours q. (Only the edges at an asked point are
// measured: most points are not asked.)
std::vector<double> spacing_upper_bounds(const Mesh_arrays& mesh, const std::vector<double>& weight,
                                         const std::vector<std::uint8_t>& asked) {
  std::vector<double> u = weight;
  const auto& P = mesh.points;
  for (const Triangle& t : mesh.triangles) {
    if (!asked[t[0]] && !asked[t[1]] && !asked[t[2]]) continue;
    for (int k = 0; k < 3; ++k) {
      const Index p = t[k], q = t[(k + 1) % 3];
      const double d = std::sqrt(squared_distance(P[p], P[q]));
      u[p] = std::min(u[p], weight[q] + d);
      u[q] = std::min(u[q], weight[p] + d);
    }
  }
  return u;
}

// The input points whose nn within the domain exceeds the Euclidean `nn` (the
// input's own list when it brings one, else keep_within_domain's). O(m).
std::vector<Index> nn_grew_within_domain(const Mesh_arrays& mesh, const std::vector<double>& nn) {
  if (!mesh.nn_within_domain.empty()) return mesh.nn_grew;
  std::vector<double> within = nn;
  const auto grew = keep_within_domain(mesh.points, mesh.triangles, within);
  std::vector<Index> out;
  for (std::size_t i = 0; i < grew.size(); ++i) {
    if (grew[i]) out.push_back(static_cast<Index>(i));
  }
  return out;
}

double coordinate_magnitude(const std::vector<Vec2>& points) {
  double m = 0;
  for (const Vec2& p : points) m = std::max({m, std::abs(p[0]), std::abs(p[1])});
  return m;
}

// The changed region (incremental_step.hpp): the sites, triangles and spheres
// whose outcome can differ from the input's, each set by the certificate
// written at the helper that computes it (above).
class Changed_region final : public Step_scope {
 public:
  Changed_region(const Mesh_arrays& mesh, const Frfc_options& options)
      : options_(options), magnitude_(coordinate_magnitude(mesh.points)) {}

  // f at the points by Lemma 3.1, from the sites near the points that need it (Cone_scan).
  Scope_spacing spacing(const Mesh_arrays& mesh, const std::vector<double>& delta,
                        const std::vector<Segment_chain>& chains, Stage_timer& timer) override {
    const std::size_t n = mesh.points.size();
    Step_weights weights = step_weights(mesh, delta, timer, options_.within_domain ? &chains : nullptr);
    if (!options_.within_domain) input_nn_grew_ = nn_grew_within_domain(mesh, weights.nn);
    weight_ = std::move(weights.weight);
    grid_.emplace(mesh.points);
    grid_->set_weights(weight_);
    // (the whole step's graph: every point a site, the same shift and ids)
    cones_.emplace(mesh.points, weight_, &mesh.point_gids);
    std::vector<double> f = weight_;
    std::vector<Index> asked;
    std::vector<std::uint8_t> is_asked(n, 0);
    for (std::size_t i = 0; i < n; ++i) {
      if (delta[i] > 1 || (!weights.evaluate.empty() && weights.evaluate[i])) {
        asked.push_back(static_cast<Index>(i));
        is_asked[i] = 1;
      }
    }
    // f(p) <= u(p), the least cone of p and its mesh neighbours at p
    // (spacing_upper_bounds), so the site attaining f(p) has its cone at p
    // within u(p). (u, not w: the weight of a point that coarsens reaches far,
    // its cone does not win there.)
    const std::vector<double> u = spacing_upper_bounds(mesh, weight_, is_asked);
    scan(mesh, asked.size(), [&](std::size_t k, Vec2& x, double& bound) {
      x = mesh.points[asked[k]];
      bound = u[asked[k]];
    }, [&](std::size_t k, double value) { f[asked[k]] = std::min(value, weight_[asked[k]]); });
    timer.lap("spacing_at_points");
    return {std::move(weights.nn), std::move(f), std::move(weights.evaluate)};
  }

  // The adaptive grids of strongly graded triangles and of segments far longer
  // than f at their ends (asks_spacing) ask f itself (sampling.hpp), in the
  // sample budget's estimate and in the sampling; the whole-mesh scope asks the
  // graph of all sites, certified. Here a graph of the sites near them answers
  // the same: every query x lies in the bounding box B of its triangle (or on
  // its segment ab), f is 1-Lipschitz, so the site c attaining f(x) has |x - c|
  // <= f(x) <= f(v) + |x - v| for any vertex v: c lies within f(v) + 1.5
  // diag(B) of B's centre (within 2 |ab| + f(e) of an end e); Cone_scan::reach
  // adds the rounding of the shifted weights, so that every site that can hide
  // a marked one (the same shift as the whole graph's) is marked too. Triangles
  // that do not ask never query (their grid has at most kQueryCells fine cells),
  // so the estimate is the whole mesh's, and so is a refused budget's error.
  const Spacing_queries* grid_queries(const Mesh_arrays& mesh, const std::vector<double>& f) override {
    if (!options_.adaptive_cells) return nullptr;
    Mark_sites near_graded(*grid_, mesh.points, weight_, magnitude_);
    bool any = false;
    for (const Triangle& t : mesh.triangles) {
      if (!asks_spacing(mesh, f, t, options_.cell_factor)) continue;
      any = true;
      Vec2 lo = mesh.points[t[0]], hi = lo;
      double f_min = f[t[0]];
      for (Index v : t) {
        lo = {std::min(lo[0], mesh.points[v][0]), std::min(lo[1], mesh.points[v][1])};
        hi = {std::max(hi[0], mesh.points[v][0]), std::max(hi[1], mesh.points[v][1])};
        f_min = std::min(f_min, f[v]);
      }
      near_graded.near({0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])},
                       cones_->reach(f_min + 1.5 * std::hypot(hi[0] - lo[0], hi[1] - lo[1])));
    }
    for (const Edge& e : mesh.segments) {
      if (!asks_spacing(mesh, f, e, options_.cell_factor)) continue;
      any = true;
      const Index end = f[e[0]] <= f[e[1]] ? e[0] : e[1];
      const Vec2& a = mesh.points[e[0]];
      const Vec2& b = mesh.points[e[1]];
      near_graded.near(mesh.points[end], cones_->reach(2 * std::hypot(b[0] - a[0], b[1] - a[1]) + f[end]));
    }
    if (!any) return nullptr;
    near_graded_.emplace(mesh.points, weight_, near_graded.marked, cones_->shift(), mesh.point_gids);
    graded_queries_ = spacing_queries(near_graded_->function());
    return &graded_queries_;
  }

  // f at the candidates: x drawn on its parent (a segment or a triangle) has
  // f(x) <= f(v) + |x - v| at the parent's vertices v (f is 1-Lipschitz), so
  // the site attaining f(x) has its cone at x within that bound.
  void f_at_candidates(const Mesh_arrays& mesh, const std::vector<double>& f, Candidates& candidates,
                       bool on_segment, Stage_timer& timer) override {
    detail::parallel_resize(candidates.radius, candidates.size());
    const auto bound_at = [&](const auto& parents) {
      return [&](std::size_t j, Vec2& x, double& bound) {
        x = candidates.samples.points[j];
        bound = std::numeric_limits<double>::infinity();
        for (Index v : parents[candidates.samples.parent[j]]) {
          bound = std::min(bound, f[v] + std::sqrt(squared_distance(x, mesh.points[v])));
        }
      };
    };
    const auto store = [&](std::size_t j, double value) { candidates.radius[j] = value; };
    if (on_segment) scan(mesh, candidates.size(), bound_at(mesh.segments), store);
    else scan(mesh, candidates.size(), bound_at(mesh.triangles), store);
    timer.lap("sample_radii");
  }

  Packing first_pass(const Mesh_arrays& mesh, const Scope_spacing& spacing, const Candidates& on_segments,
                     const std::vector<std::uint8_t>& forced, std::size_t n_forced,
                     const std::vector<std::uint8_t>& demoted) override {
    return first_pass_near(mesh, spacing.f, spacing.nn, spacing.evaluate, on_segments, forced, n_forced, demoted,
                           options_, *grid_, magnitude_, safe_, n_packed_first_);
  }
  // (the scope's graphs are small)
  bool starts_triangulation_early() const override { return true; }

  std::vector<std::uint8_t> quiet_triangles(const Mesh_arrays& mesh, const std::vector<double>& delta,
                                            const Packing& packing, const std::vector<std::uint8_t>& demoted,
                                            const std::vector<std::uint8_t>& settled, Stage_timer& timer) override {
    auto quiet = evomesh::quiet_triangles(mesh, *grid_, weight_, packing.radius, packing.kept, demoted,
                                          unsampled_triangles(mesh, delta, settled, options_), options_.radius_scale,
                                          magnitude_, /*threads=*/0);
    timer.lap("incremental_quiet");
    return quiet;
  }
  void sampled(const Mesh_arrays& mesh, const std::vector<std::uint8_t>& quiet) override {
    std::vector<std::uint8_t> in_region(mesh.points.size(), 0);
    for (std::size_t t = 0; t < quiet.size(); ++t) {
      n_quiet_ += quiet[t];
      if (!quiet[t]) {
        for (Index v : mesh.triangles[t]) in_region[v] = 1;
      }
    }
    for (std::uint8_t r : in_region) n_region_ += r;
    if (near_graded_) n_sites_ += near_graded_->n_sites();
    graded_queries_ = nullptr;
    near_graded_.reset();  // its last use
  }

  void spacing_done() override {
    cones_.reset();
    weight_ = std::vector<double>();  // the sites' weights: the scans were their last use
  }


  void second_pass(const Mesh_arrays& mesh, Candidates& inside, Packing& packing) override {
    second_pass_near(mesh, inside, safe_, *grid_, magnitude_, packing, n_packed_second_);
    safe_ = std::vector<std::uint8_t>();
    grid_.reset();
  }
  // Without the quality pass: the input's triangulation updated where the step
  // changed it (triangulation_update.hpp), or nullopt where that is not certified.
  std::optional<std::vector<Triangle>> triangulation(const Selection& selection,
                                                     const std::vector<Constraint_piece>& pieces,
                                                     Old_mesh_start& old_mesh,
                                                     std::vector<std::pair<std::string, double>>& stats) override {
    const auto waited = std::chrono::steady_clock::now();
    old_mesh.work.wait();
    stats.emplace_back("triangulation_update_wait_seconds",
                       std::chrono::duration<double>(std::chrono::steady_clock::now() - waited).count());
    Triangulation_update_report report;
    auto triangles = updated_constrained_delaunay(*old_mesh.walker, selection.mesh.points, pieces, selection.origin,
                                                  kMaxCavityShare, report, &same_fans_);
    if (!triangles) same_fans_.clear();
    stats.emplace_back("triangulation_update_declined", static_cast<double>(report.declined));
    stats.emplace_back("triangulation_update_cavity_triangles", static_cast<double>(report.n_cavity_triangles));
    stats.emplace_back("triangulation_update_locate_seconds", report.locate_seconds);
    stats.emplace_back("triangulation_update_local_seconds", report.local_seconds);
    stats.emplace_back("triangulation_update_certify_seconds", report.certify_seconds);
    stats.emplace_back("triangulation_update_checked_kept_edges", report.checked_kept_edges ? 1.0 : 0.0);
    return triangles;
  }
  const std::vector<std::uint8_t>* same_fans() const override { return same_fans_.empty() ? nullptr : &same_fans_; }
  // (the walker takes them: the step's peak is the quality pass, the same in both scopes)
  bool keeps_fans() const override { return true; }
  // The input's Euclidean nn is the step's nn except where it grew within the
  // domain (spacing.evaluate; without within_domain the step's nn is Euclidean
  // everywhere, but finish_step's `known` must still exclude the points whose
  // nn within the domain grew: input_nn_grew_).
  const std::vector<double>* reusable_nn(const Scope_spacing& spacing) override {
    euclidean_nn_ = spacing.nn;
    for (std::size_t i = 0; i < spacing.evaluate.size(); ++i) {
      if (spacing.evaluate[i]) euclidean_nn_[i] = std::numeric_limits<double>::quiet_NaN();
    }
    for (Index i : input_nn_grew_) euclidean_nn_[i] = std::numeric_limits<double>::quiet_NaN();
    return &euclidean_nn_;
  }
  // (its graphs and candidates are the change's: trimming between stages cost
  // 0.1-0.25 s of page faults at 1e6 for a peak within 2 % of the trimmed one)
  bool releases_memory_between_stages() const override { return false; }
  void add_counts(std::vector<std::pair<std::string, double>>& stats) const override {
    stats.emplace_back("incremental_region_points", static_cast<double>(n_region_));
    stats.emplace_back("incremental_quiet_triangles", static_cast<double>(n_quiet_));
    stats.emplace_back("incremental_packed_first", static_cast<double>(n_packed_first_));
    stats.emplace_back("incremental_packed_second", static_cast<double>(n_packed_second_));
    stats.emplace_back("incremental_sites", static_cast<double>(n_sites_));
    stats.emplace_back("incremental_cone_scans", static_cast<double>(n_scans_));
    stats.emplace_back("incremental_scanned_cones", static_cast<double>(n_scanned_));
    stats.emplace_back("incremental_step", 1);
  }

 private:
  // f at `count` queries by the cone scan, in parallel chunks: bound_at(k, x,
  // u) gives query k and a bound u >= f(x) (up to rounding), store(k, f(x)).
  // Scanned: the sites whose cone at x is within the scan's reach of u, with
  // this file's slack (as Mark_sites): a superset of what Cone_scan needs.
  template <class Bound_at, class Store>
  void scan(const Mesh_arrays& mesh, std::size_t count, Bound_at bound_at, Store store) {
    constexpr std::size_t kChunk = 4096;
    const std::size_t chunks = (count + kChunk - 1) / kChunk;
    std::vector<std::size_t> scanned(chunks, 0);
    const double absolute = 1e-12 * magnitude_;
    parallel_for(chunks, 0, [&](std::size_t c) {
      std::vector<Index> near;
      for (std::size_t k = c * kChunk; k < std::min(count, (c + 1) * kChunk); ++k) {
        Vec2 x;
        double u;
        bound_at(k, x, u);
        const double reach = cones_->reach(u) * (1 + kSlack) + absolute;
        near.clear();
        grid_->visit_within(x, reach, [&](Index i) {
          if (weight_[i] + std::sqrt(squared_distance(x, mesh.points[i])) * (1 - kSlack) <= reach) near.push_back(i);
        });
        scanned[c] += near.size();
        store(k, cones_->evaluate(x, near.data(), near.size()));
      }
    });
    for (std::size_t k : scanned) n_scanned_ += k;
    n_scans_ += count;
  }

  const Frfc_options& options_;
  const double magnitude_;
  std::vector<double> weight_;  // of the sites (Step_weights)
  std::optional<Point_grid> grid_;
  std::optional<Cone_scan> cones_;  // f at the points and the candidates
  std::optional<Restricted_spacing> near_graded_;  // f in the adaptive grids (grid_queries)
  Spacing_queries graded_queries_;
  std::vector<std::uint8_t> safe_;  // old points no earlier sphere can reject (safe_old_points)
  std::vector<double> euclidean_nn_;
  std::vector<Index> input_nn_grew_;  // without within_domain: the input points whose nn within the domain grew
  std::vector<std::uint8_t> same_fans_;  // triangulation()'s, when it updated the input's
  std::size_t n_sites_ = 0, n_scans_ = 0, n_scanned_ = 0, n_quiet_ = 0, n_region_ = 0;
  std::size_t n_packed_first_ = 0, n_packed_second_ = 0;
};

}  // namespace

bool incremental_applies(const Mesh_arrays& mesh, const std::vector<double>& delta, const Frfc_options& options) {
  if (mesh.geometry || !options.filter_samples) return false;
  std::size_t n_active = 0;
  for (double d : delta) n_active += d != 1;
  return static_cast<double>(n_active) <= kMaxActiveShare * static_cast<double>(mesh.points.size());
}

Evolve_result incremental_frfc(const Mesh_arrays& mesh, const std::vector<double>& delta,
                               const Frfc_options& options, const Step_context& context) {
  if (!incremental_applies(mesh, delta, options)) {
    throw std::invalid_argument("incremental_frfc: the incremental step does not apply here (incremental_applies)");
  }
  Changed_region scope(mesh, options);
  return frfc_over_scope(mesh, mesh, delta, options, context, scope);
}

}  // namespace evomesh
