#include "evomesh/spacing_repair.hpp"

#include "evomesh/global_ids.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <mutex>
#include <optional>

#include <CGAL/Delaunay_triangulation_2.h>

#include "evomesh/kernel.hpp"
#include "evomesh/mesh_walk.hpp"
#include "evomesh/nd/kd_tree.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/sampling.hpp"

namespace evomesh {

namespace {

// The kept centres' nearest distances (squared_nearest, squared_two_nearest),
// as nd::Point_tree<2> answers them, without building the tree for queries
// where the centres are spread evenly (most of them): the centres are bucketed
// in a uniform grid (about two a cell, O(n)) and a query searches rings of
// cells around its own until every cell not searched lies farther than the
// second distance found; it takes the tree (built once, when first needed)
// after kMaxRings rings. The answers are the tree's, bit for bit: each distance
// is the same expression of the same two points (Point_tree: the shape of the
// search does not matter), and a centre outside the searched box is at least
// its gap from the query, less the rounding of the cell assignment and of the
// gap (margins of kMargin cells, 64 ulps of the coordinates and a relative 1e-9
// of the squared distance, far above it). O(n) cells: cell^2 >= 2 w^2 / n^2
// for the box's width w.
class Kept_centres {
 public:
  explicit Kept_centres(const std::vector<Vec2>& points) : points_(points) {
    const std::size_t n = points.size();
    Vec2 hi{-std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};
    lo_ = {-hi[0], -hi[1]};
    for (const Vec2& p : points) {
      lo_ = {std::min(lo_[0], p[0]), std::min(lo_[1], p[1])};
      hi = {std::max(hi[0], p[0]), std::max(hi[1], p[1])};
      magnitude_ = std::max({magnitude_, std::abs(p[0]), std::abs(p[1])});
    }
    // square cells of about two centres each over the bounding box
    const double width = std::max(hi[0] - lo_[0], hi[1] - lo_[1]);
    const double area = std::max((hi[0] - lo_[0]) * (hi[1] - lo_[1]), width * width / static_cast<double>(n));
    cell_ = std::sqrt(2 * area / static_cast<double>(std::max<std::size_t>(n, 1)));
    if (!(cell_ > 0) || !std::isfinite(cell_)) cell_ = 1;
    for (int k = 0; k < 2; ++k) {
      side_[k] = std::clamp<std::int64_t>(static_cast<std::int64_t>((hi[k] - lo_[k]) / cell_) + 1, 1, kMaxSide);
    }
    start_.assign(static_cast<std::size_t>(side_[0] * side_[1]) + 1, 0);
    std::vector<std::int64_t> cell_of(n);
    for (std::size_t i = 0; i < n; ++i) {
      cell_of[i] = cell(points[i][0], 0) + side_[0] * cell(points[i][1], 1);
      ++start_[static_cast<std::size_t>(cell_of[i]) + 1];
    }
    for (std::size_t c = 0; c + 1 < start_.size(); ++c) start_[c + 1] += start_[c];
    members_.resize(n);
    std::vector<std::int64_t> fill(start_.begin(), start_.end() - 1);
    for (std::size_t i = 0; i < n; ++i) members_[static_cast<std::size_t>(fill[cell_of[i]]++)] = points[i];
  }

  double squared_nearest(const Vec2& x) const {
    std::array<double, 2> best;
    if (search(x, /*two=*/false, best)) return best[0];
    return tree().squared_nearest(x);
  }
  std::array<double, 2> squared_two_nearest(const Vec2& x) const {
    std::array<double, 2> best;
    if (search(x, /*two=*/true, best)) return best;
    return tree().squared_two_nearest(x);
  }

 private:
  static constexpr int kMaxRings = 3;
  static constexpr double kMargin = 1e-6;  // of a cell
  static constexpr std::int64_t kMaxSide = std::int64_t{1} << 15;

  std::int64_t cell(double v, int axis) const {
    const double c = std::floor((v - lo_[axis]) / cell_);
    if (!(c > 0)) return 0;
    return c >= static_cast<double>(side_[axis] - 1) ? side_[axis] - 1 : static_cast<std::int64_t>(c);
  }
  // Whether the rings of cells around x certify `best` (the nearest, or the two nearest, squared distances).
  bool search(const Vec2& x, bool two, std::array<double, 2>& best) const {
    best = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
    const std::int64_t cx = cell(x[0], 0), cy = cell(x[1], 1);
    for (std::int64_t r = 0; r <= kMaxRings; ++r) {
      for (std::int64_t y = cy - r; y <= cy + r; ++y) {
        if (y < 0 || y >= side_[1]) continue;
        const bool edge_row = y == cy - r || y == cy + r;
        for (std::int64_t xx = cx - r; xx <= cx + r; xx += edge_row ? 1 : 2 * std::max<std::int64_t>(r, 1)) {
          if (xx < 0 || xx >= side_[0]) continue;
          const std::size_t c = static_cast<std::size_t>(xx + side_[0] * y);
          for (std::int64_t k = start_[c]; k < start_[c + 1]; ++k) {
            const Vec2& p = members_[static_cast<std::size_t>(k)];
            const double dx = x[0] - p[0];
            const double dy = x[1] - p[1];
            const double d = dx * dx + dy * dy;
            if (d < best[0]) best = {d, best[0]};
            else if (d < best[1]) best[1] = d;
          }
        }
      }
      // The gap from x to the cells beyond ring r (none beyond the grid's edge).
      double gap = std::numeric_limits<double>::infinity();
      const std::int64_t c[2] = {cx, cy};
      for (int k = 0; k < 2; ++k) {
        if (c[k] - r > 0) gap = std::min(gap, x[k] - (lo_[k] + static_cast<double>(c[k] - r) * cell_));
        if (c[k] + r < side_[k] - 1) gap = std::min(gap, lo_[k] + static_cast<double>(c[k] + r + 1) * cell_ - x[k]);
      }
      gap -= kMargin * cell_ + 64 * std::numeric_limits<double>::epsilon() *
                                    std::max({magnitude_, std::abs(x[0]), std::abs(x[1])});
      const double found = two ? best[1] : best[0];
      if (gap == std::numeric_limits<double>::infinity() || (gap > 0 && found * (1 + 1e-9) < gap * gap)) return true;
    }
    return false;
  }
  const nd::Point_tree<2>& tree() const {
    std::call_once(tree_built_, [&]() { tree_.emplace(points_); });
    return *tree_;
  }

  const std::vector<Vec2>& points_;
  Vec2 lo_{0, 0};
  double magnitude_ = 0;  // of the coordinates
  double cell_ = 1;
  std::int64_t side_[2] = {1, 1};
  std::vector<std::int64_t> start_;
  std::vector<Vec2> members_;
  mutable std::once_flag tree_built_;
  mutable std::optional<nd::Point_tree<2>> tree_;
};

// The gap repair: the paper's nn_M'(p) of an input point is the
// distance from p to its second nearest output point (its nearest other one
// when p is kept). The packing leaves gaps of up to about 2 radius_scale f
// between kept spheres, so nn_M'(p) can reach 1.4 h(p), h = delta nn_M: next
// to a kept point, and where a point was dropped beside a near neighbour. An
// input point with nn_M'(p) > gap_ratio h(p) gets, of kGapDirections points at
// distance h(p) from it (seeded phase) that lie strictly inside a triangle of
// the old mesh seen from p (Mesh_walk::locate_from: no segment in between), the
// one farthest from every output point, if that is at least kGapClearance h(p)
// away. Where the request refines and a fresh packing forms (p has delta(p) < 1
// and was demoted or dropped), its spacing varies more and a bound of gap_ratio
// adds points that compound over repeated steps: refine_ratio is used there.
// Points are served in the order of their global ids (input order without
// them); each sees the points added before.
constexpr double kGapClearance = 0.6;

constexpr double kTwoPi = 6.283185307179586;

// The squared distances from x to its two nearest output points, from those of
// the kept centres (`kept`) and the points added so far (a Delaunay
// triangulation: a second nearest vertex is a neighbour of the nearest; the
// walks start at the last answer).
template <class Delaunay>
std::array<double, 2> with_added(const Vec2& x, const std::array<double, 2>& kept, const Delaunay& added_dt,
                                 typename Delaunay::Vertex_handle& hint) {
  using Vertex_handle = typename Delaunay::Vertex_handle;
  if (added_dt.number_of_vertices() == 0) return kept;
  const Point_2 q = to_cgal(x);
  const Vertex_handle v = added_dt.nearest_vertex(q, hint == Vertex_handle() ? typename Delaunay::Face_handle()
                                                                              : hint->face());
  hint = v;
  const double a1 = CGAL::squared_distance(q, v->point());
  double a2 = std::numeric_limits<double>::infinity();
  auto c = added_dt.incident_vertices(v), done = c;
  if (c != nullptr) do {
    if (!added_dt.is_infinite(c)) a2 = std::min(a2, CGAL::squared_distance(q, c->point()));
  } while (++c != done);
  return kept[0] <= a1 ? std::array<double, 2>{kept[0], std::min(kept[1], a1)}
                       : std::array<double, 2>{a1, std::min(a2, kept[0])};
}

// One open point's gap repair (the serial loop's body, also the distributed
// step's): -1 when its two nearest output points (two_nearest(-1, at); k for
// direction k) leave no
// gap, else the direction k whose point (`directions`, inside(k): seen from p
// inside the old mesh) is farthest from the output points, at least the
// clearance; -1 when none is.
template <class TwoNearest, class Inside>
int gap_choice(const Vec2& at, double delta, double nn, bool demoted, double gap_ratio, double refine_ratio,
               const std::array<Vec2, kGapDirections>& directions, Inside&& inside, TwoNearest&& two_nearest) {
  const auto around = two_nearest(-1, at);
  const bool kept = around[0] == 0;
  if (!(around[1] > gap_target2(delta, nn, demoted, kept, gap_ratio, refine_ratio))) return -1;
  const double h = delta * nn;
  const double clearance2 = kGapClearance * kGapClearance * h * h;
  double best_d2 = -1;
  int best = -1;
  for (int k = 0; k < kGapDirections; ++k) {
    const Vec2& x = directions[k];
    if (!inside(k)) continue;
    const auto e = two_nearest(k, x);
    if (!(e[0] >= clearance2)) continue;
    // farthest from the output points other than p: a kept p is at distance h
    // from every direction (a tie that rounding would break)
    const double dx = x[0] - at[0], dy = x[1] - at[1];
    const double other = kept && e[0] == dx * dx + dy * dy ? e[1] : e[0];
    if (other > best_d2) {
      best_d2 = other;
      best = k;
    }
  }
  return best;
}

template <class Delaunay>
void repair_gaps(const Mesh_arrays& mesh, const Triangle_fans& fans, const std::vector<double>& delta,
                 const std::vector<double>& nn, double gap_ratio, double refine_ratio, std::uint64_t seed,
                 const std::vector<std::uint8_t>& demoted, const std::vector<std::uint8_t>& kept_centre,
                 const Kept_centres& tree, int threads, Delaunay& added_dt, std::vector<Vec2>& added,
                 std::size_t& n_added) {
  if (!(gap_ratio > 0) && !(refine_ratio > 0)) return;
  // squared distances from x to its nearest and second nearest output points
  // (the nearest-vertex walks start at the last answer: points come in input
  // order, neighbours mostly, so a walk is short however many points were added)
  typename Delaunay::Vertex_handle hint;
  auto two_nearest = [&](int, const Vec2& x) { return with_added(x, tree.squared_two_nearest(x), added_dt, hint); };
  // The bound at p (refine_ratio where a fresh packing forms, see above), from
  // whether p is kept (at distance 0 from a kept centre).
  auto target2 = [&](std::size_t p, bool kept) {
    return gap_target2(delta[p], nn[p], demoted[p] != 0, kept, gap_ratio, refine_ratio);
  };
  // Points added later only bring output points nearer: the points whose kept
  // centres alone leave a gap (found in parallel) are all that can need one.
  // A kept point with a kept mesh neighbour within its bound has none (its
  // second nearest kept centre is at most that far; the margin keeps the two
  // computations of that distance apart): most points of a step, found from
  // their triangle fans without a tree query.
  const std::size_t n = mesh.points.size();
  std::vector<std::uint8_t> open(n, 0);
  constexpr std::size_t kChunk = 4096;
  parallel_for((n + kChunk - 1) / kChunk, threads, [&](std::size_t chunk) {
    for (std::size_t p = chunk * kChunk; p < std::min(n, (chunk + 1) * kChunk); ++p) {
      bool certified = false;
      if (kept_centre[p]) {
        const double bound2 = target2(p, true);
        const Vec2& a = mesh.points[p];
        for (Index k = fans.xadj[p]; k < fans.xadj[p + 1] && !certified; ++k) {
          for (Index q : mesh.triangles[fans.adj[k]]) {
            if (static_cast<std::size_t>(q) == p || !kept_centre[q]) continue;
            const double dx = a[0] - mesh.points[q][0], dy = a[1] - mesh.points[q][1];
            certified = certified || (dx * dx + dy * dy) * (1 + 1e-9) <= bound2;
          }
        }
      }
      if (certified) continue;
      const auto around = tree.squared_two_nearest(mesh.points[p]);
      open[p] = around[1] > target2(p, around[0] == 0);
    }
  });
  const Mesh_walk walk(mesh, fans);
  // Points are served in the order of their global ids (positions without them).
  const std::vector<Index> by_id = order_by_ids(mesh.point_gids);
  std::array<Vec2, kGapDirections> directions;
  for (std::size_t r = 0; r < n; ++r) {
    const std::size_t p = visit(by_id, r);
    if (!open[p]) continue;
    const Vec2& at = mesh.points[p];
    gap_directions(at, delta[p] * nn[p], seed, mesh.point_gid(p), directions.data());
    const int best = gap_choice(
        at, delta[p], nn[p], demoted[p] != 0, gap_ratio, refine_ratio, directions,
        [&](int k) { return walk.locate_from(static_cast<Index>(p), directions[k]) >= 0; }, two_nearest);
    if (best < 0) continue;
    added.push_back(directions[best]);
    added_dt.insert(to_cgal(directions[best]));
    ++n_added;
  }
}

// The points added by the spacing repair, for nearest-point queries (walks
// start at the last answer: needy points come in id order, mostly neighbours).
template <class Delaunay>
struct Added_points {
  Delaunay dt;
  typename Delaunay::Vertex_handle hint;
  // squared distance from x to the nearest added point (infinity: none)
  double nearest2(const Vec2& x) {
    if (dt.number_of_vertices() == 0) return std::numeric_limits<double>::infinity();
    const Point_2 q = to_cgal(x);
    hint = dt.nearest_vertex(q, hint == typename Delaunay::Vertex_handle() ? typename Delaunay::Face_handle()
                                                                           : hint->face());
    return CGAL::squared_distance(q, hint->point());
  }
  void insert(const Vec2& x) { dt.insert(to_cgal(x)); }
};

// One needy point's repair (the serial loop's body, also the distributed
// step's): none (-1) when its nearest other point, kept (nn2) or added, is
// within the target, else the candidate farthest from every kept and added
// point (the first of equals; none when every one is at distance 0). kept2:
// each candidate's squared distance to the nearest kept centre.
template <class Added>
int repair_choice(const Vec2& at, double target2, double nn2, const std::vector<Vec2>& candidates,
                  const std::vector<double>& kept2, Added& added) {
  // re-check: an earlier repair may have served p
  if (std::min(nn2, added.nearest2(at)) <= target2) return -1;
  int best = -1;
  double best_d2 = 0;
  for (std::size_t k = 0; k < candidates.size(); ++k) {
    const double e2 = std::min(kept2[k], added.nearest2(candidates[k]));
    if (e2 > best_d2) {
      best_d2 = e2;
      best = static_cast<int>(k);
    }
  }
  return best;
}

}  // namespace

double gap_target2(double delta, double nn, bool demoted, bool kept, double gap_ratio, double refine_ratio) {
  const double ratio = delta < 1 && (demoted || !kept) ? refine_ratio : gap_ratio;
  const double target = ratio * (delta * nn);
  return ratio > 0 ? target * target : std::numeric_limits<double>::infinity();
}

void gap_directions(const Vec2& at, double h, std::uint64_t seed, std::int64_t gid, Vec2* out) {
  Random_stream rng(seed, (std::uint64_t{5} << 60) + static_cast<std::uint64_t>(gid));
  const double phase = rng.uniform() * kTwoPi / kGapDirections;
  for (int k = 0; k < kGapDirections; ++k) {
    const double angle = phase + kTwoPi * k / kGapDirections;
    out[k] = Vec2{at[0] + h * std::cos(angle), at[1] + h * std::sin(angle)};
  }
}

std::vector<Index> decide_gaps(const Gap_requests& requests, const std::vector<Vec2>& added) {
  using Delaunay = CGAL::Delaunay_triangulation_2<Kernel>;
  Delaunay dt;
  for (const Vec2& x : added) dt.insert(to_cgal(x));
  typename Delaunay::Vertex_handle hint;
  const std::size_t m = requests.at.size();
  std::vector<Index> out(m, -1);
  std::array<Vec2, kGapDirections> directions;
  for (std::size_t i = 0; i < m; ++i) {
    std::copy_n(requests.directions.begin() + static_cast<std::ptrdiff_t>(i * kGapDirections), kGapDirections,
                directions.begin());
    // the kept centres' two nearest at p (slot 0) and at each direction (slots 1..)
    auto two_nearest = [&](int k, const Vec2& x) {
      const std::size_t at = i * (kGapDirections + 1) + static_cast<std::size_t>(k + 1);
      return with_added(x, {requests.kept2[2 * at], requests.kept2[2 * at + 1]}, dt, hint);
    };
    const int best = gap_choice(
        requests.at[i], requests.delta[i], requests.nn[i], requests.demoted[i] != 0, requests.gap_ratio,
        requests.refine_ratio, directions,
        [&](int k) { return requests.inside[i * kGapDirections + static_cast<std::size_t>(k)] != 0; }, two_nearest);
    if (best < 0) continue;
    out[i] = best;
    dt.insert(to_cgal(directions[best]));
  }
  return out;
}

double repair_target2(double repair_ratio, double delta, double nn) {
  const double target = repair_ratio * delta * nn;
  return target * target;
}

void kept_distances(const std::vector<Vec2>& kept, const std::vector<Vec2>& queries, std::vector<double>& nearest2,
                    std::vector<double>& second2) {
  nearest2.assign(queries.size(), std::numeric_limits<double>::infinity());
  second2.assign(queries.size(), std::numeric_limits<double>::infinity());
  if (kept.empty()) return;
  const Kept_centres tree(kept);
  for (std::size_t i = 0; i < queries.size(); ++i) {
    const auto two = tree.squared_two_nearest(queries[i]);
    nearest2[i] = two[0];
    second2[i] = two[1];
  }
}

std::vector<Index> decide_repairs(const std::vector<Vec2>& at, const std::vector<double>& target2,
                                  const std::vector<double>& nn2, const std::vector<Index>& xadj,
                                  const std::vector<Vec2>& candidates, const std::vector<double>& kept2,
                                  const std::vector<Vec2>& added) {
  using Delaunay = CGAL::Delaunay_triangulation_2<Kernel>;
  Added_points<Delaunay> points;
  for (const Vec2& x : added) points.insert(x);
  std::vector<Index> out(at.size(), -1);
  std::vector<Vec2> mine;
  std::vector<double> mine2;
  for (std::size_t i = 0; i < at.size(); ++i) {
    mine.assign(candidates.begin() + xadj[i], candidates.begin() + xadj[i + 1]);
    mine2.assign(kept2.begin() + xadj[i], kept2.begin() + xadj[i + 1]);
    const int best = repair_choice(at[i], target2[i], nn2[i], mine, mine2, points);
    if (best < 0) continue;
    out[i] = best;
    points.insert(mine[static_cast<std::size_t>(best)]);
  }
  return out;
}

std::vector<Vec2> repair_spacing(const Spacing_repair_input& input, const Frfc_options& options,
                                 std::vector<std::uint8_t>& kept, std::size_t& n_added) {
  const Mesh_arrays& mesh = input.mesh;
  const Triangle_fans& fans = input.fans;
  const std::vector<double>& delta = input.delta;
  const std::vector<double>& nn = input.nn;
  const std::vector<double>& f = input.f;
  const std::vector<Vec2>& centers = input.centers;
  const std::vector<Index>& segment_owner = input.segment_owner;
  const double reach = ring_reach(options.radius_scale);
  const std::uint64_t seed = options.seed;
  const double repair_ratio = options.ring_samples ? options.repair_ratio : 0.0;
  const double gap_repair_ratio = options.gap_repair_ratio;
  const int threads = 0;  // the step's Thread_limit (Step_context::threads)
  using Delaunay = CGAL::Delaunay_triangulation_2<Kernel>;
  const std::size_t n = mesh.points.size();
  n_added = 0;
  // (fresh arrays sized first, their pages touched on both threads: detail::parallel_resize)
  std::size_t n_kept = 0;
  for (std::size_t c = 0; c < centers.size(); ++c) n_kept += kept[c] != 0;
  std::vector<Vec2> kept_points;
  detail::parallel_resize(kept_points, n_kept);
  std::vector<Index> position_of;
  detail::parallel_resize(position_of, n, Index{-1});
  for (std::size_t c = 0, k = 0; c < centers.size(); ++c) {
    if (!kept[c]) continue;
    if (c < n) position_of[c] = static_cast<Index>(k);
    kept_points[k++] = centers[c];
  }
  if (kept_points.size() < 2) return {};
  const Kept_centres tree(kept_points);
  // nn2 of the kept R-points (delta < 1): the second nearest kept centre, the
  // nearest being the point itself (kept centres are distinct).
  std::vector<double> nn2;
  detail::parallel_resize(nn2, n);
  if (repair_ratio > 0) {
    constexpr std::size_t kChunk = 4096;
    parallel_for((n + kChunk - 1) / kChunk, threads, [&](std::size_t chunk) {
      for (std::size_t p = chunk * kChunk; p < std::min(n, (chunk + 1) * kChunk); ++p) {
        if (position_of[p] >= 0 && delta[p] < 1) nn2[p] = tree.squared_two_nearest(mesh.points[p])[1];
      }
    });
  }
  std::vector<Index> needy;  // (in the order of the points' global ids)
  std::vector<std::uint8_t> is_needy(n, 0);
  const std::vector<Index> by_id = order_by_ids(mesh.point_gids);
  for (std::size_t r = 0; r < n; ++r) {
    const std::size_t p = visit(by_id, r);
    if (!(repair_ratio > 0) || position_of[p] < 0 || !(delta[p] < 1)) continue;
    if (nn2[p] > repair_target2(repair_ratio, delta[p], nn[p])) {
      is_needy[p] = 1;
      needy.push_back(static_cast<Index>(p));
    }
  }
  std::vector<Vec2> added;
  // The segment ring candidates of needy points: (owner, centre index), by
  // owner then centre (a list per input point would be n empty vectors).
  std::vector<std::pair<Index, Index>> on_segments;
  for (std::size_t j = 0; j < segment_owner.size(); ++j) {
    if (segment_owner[j] >= 0 && is_needy[segment_owner[j]]) {
      on_segments.emplace_back(segment_owner[j], static_cast<Index>(n + j));
    }
  }
  std::sort(on_segments.begin(), on_segments.end());
  Added_points<Delaunay> added_points;  // every point added here (segment or interior)
  std::array<Ring_candidate, kRingDirections> ring;
  std::vector<Vec2> candidates;
  std::vector<double> kept2;
  std::vector<Index> segment_of;  // per candidate: its centre index, or -1 (a ring candidate inside)
  for (Index p : needy) {
    candidates.clear();
    segment_of.clear();
    for (auto it = std::lower_bound(on_segments.begin(), on_segments.end(), std::pair<Index, Index>{p, -1});
         it != on_segments.end() && it->first == p; ++it) {
      candidates.push_back(centers[it->second]);
      segment_of.push_back(it->second);
    }
    const int count = ring_candidates_of(mesh, fans, f, reach, seed, static_cast<std::size_t>(p), ring);
    for (int k = 0; k < count; ++k) {
      candidates.push_back(ring[k].x);
      segment_of.push_back(-1);
    }
    kept2.resize(candidates.size());
    for (std::size_t k = 0; k < candidates.size(); ++k) kept2[k] = tree.squared_nearest(candidates[k]);
    const int best = repair_choice(mesh.points[p], repair_target2(repair_ratio, delta[p], nn[p]), nn2[p], candidates,
                                   kept2, added_points);
    if (best < 0) continue;
    if (segment_of[best] >= 0) kept[segment_of[best]] = 1;
    else added.push_back(candidates[best]);
    added_points.insert(candidates[best]);
    ++n_added;
  }
  repair_gaps(mesh, fans, delta, nn, gap_repair_ratio, options.refine_gap_ratio, seed, input.demoted, kept, tree,
              threads, added_points.dt, added, n_added);
  return added;
}

}  // namespace evomesh
