#include "evomesh/quality_pass.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "evomesh/detail/delaunay_mesher.hpp"
#include "evomesh/detail/parallel_sweep.hpp"
#include "evomesh/parallel.hpp"
#include "evomesh/triangulation.hpp"

namespace evomesh {

using namespace detail;

namespace {

// Section 6: drop free points that crowd a piece (see it under more than
// crowding_angle) and return the pieces to split instead. The apex of a side of a
// constrained Delaunay edge sees it under the largest angle of all points visible
// on that side, so only apexes need testing.
std::vector<std::pair<Vertex_handle, Vertex_handle>> drop_crowding_points(
    Cdt& cdt, const std::vector<Vertex_handle>& handles, const std::vector<Constraint_piece>& pieces,
    double crowding_angle, const std::vector<std::uint8_t>& pinned, std::vector<std::uint8_t>& removed,
    Refinement_report& report) {
  std::vector<std::pair<Vertex_handle, Vertex_handle>> crowded;
  const double cos_bound = std::cos(crowding_angle * kPi / 180.0);
  auto crowds = [&](const Point_2& a, const Point_2& p, const Point_2& b) {
    // A choice of which points to drop, not a combinatorial predicate: floating point.
    const double ux = a.x() - p.x(), uy = a.y() - p.y(), vx = b.x() - p.x(), vy = b.y() - p.y();
    return ux * vx + uy * vy < cos_bound * std::sqrt((ux * ux + uy * uy) * (vx * vx + vy * vy));
  };
  for (const auto& piece : pieces) {
    const Vertex_handle a = handles[piece.a], b = handles[piece.b];
    bool dropped = false;
    for (int side = 0; side < (piece.boundary ? 1 : 2); ++side) {
      const Vertex_handle from = side == 0 ? a : b, to = side == 0 ? b : a;
      while (true) {
        Face_handle f;
        int i;
        if (!left_face(cdt, from, to, f, i)) break;
        const Vertex_handle apex = f->vertex(i);
        if (cdt.is_infinite(apex) || cdt.are_there_incident_constraints(apex)) break;
        if (!pinned.empty() && pinned[apex->info().index]) break;  // a required point stays
        if (!crowds(a->point(), apex->point(), b->point())) break;
        removed[apex->info().index] = 1;
        cdt.remove(apex);
        ++report.n_removed;
        dropped = true;
      }
    }
    if (dropped) crowded.emplace_back(a, b);
  }
  report.n_crowded_segments = crowded.size();
  return crowded;
}

// An estimate of the points Ruppert's rules need on the triangulation of the
// domain: his output has O(integral of 1 / lfs^2) points, lfs the local feature
// size (Ruppert 1995, Theorem 1). Summed over the triangles t of the domain:
// area(t) / h(t)^2 = longest(t)^2 / (4 area(t)), h(t) the smallest height of t,
// a feature size within t (where the point set is graded or t is a sliver it
// is small); and over the constraint edges e, from each domain side, |e| / h,
// h the height over e of the triangle on that side: the apex is a feature
// within h of e, and where a feature faces e along its whole length (a
// channel's wall, whose triangles reach across the channel) the rules put
// about |e| / h points on e. Measured: 1.5-4 times the points the pass inserts
// on a 1e-3 channel from coarse meshes, 4-40 times on graded and rough steps.
// With `canonical`, the terms are summed in sorted order, not in the face
// container's: the same sum whatever the triangulation's history (the rounds).
double feature_points(Cdt& cdt, bool canonical) {
  if (cdt.dimension() < 2) return 0;
  auto& faces = cdt.tds().faces();
  std::vector<double> in_chunk(sweep_chunks(faces), 0.0);
  std::vector<std::vector<double>> terms(canonical ? in_chunk.size() : 0);
  parallel_sweep(faces, [&](std::size_t c, Face_handle f) {
    if (cdt.is_infinite(f) || !f->is_in_domain()) return;
    const Point_2 &a = f->vertex(0)->point(), &b = f->vertex(1)->point(), &d = f->vertex(2)->point();
    const double twice_area = std::abs((b.x() - a.x()) * (d.y() - a.y()) - (b.y() - a.y()) * (d.x() - a.x()));
    if (!(twice_area > 0)) return;  // flat in floating point: below the angle rule's floor, never split
    const double longest = std::max({squared_distance(a, b), squared_distance(b, d), squared_distance(d, a)});
    double points = longest / (2 * twice_area);
    for (int i = 0; i < 3; ++i) {
      if (!f->is_constrained(i)) continue;
      // |e| / h = |e|^2 / (2 area)
      points += squared_distance(f->vertex(Cdt::ccw(i))->point(), f->vertex(Cdt::cw(i))->point()) / twice_area;
    }
    if (canonical) terms[c].push_back(points);
    else in_chunk[c] += points;
  });
  double sum = 0;
  if (canonical) {
    std::vector<double> all = joined(terms);
    std::sort(all.begin(), all.end());
    for (double t : all) sum += t;
    return sum;
  }
  for (double s : in_chunk) sum += s;  // (in chunk order: the same sum on any thread count)
  return sum;
}

// The insertions the pass may make beyond its bound where no constraints meet
// under less than 60 degrees: Ruppert's rules then end (proven up to 20.7
// degrees, with off-centres in practice up to 30), and the points they need
// follow the domain's features and the grading of the points handed in, not
// their number (a channel 1e-3 wide from a mesh of spacing 0.2 needs about
// 2 / 1e-3 points on its walls; a step with delta from 0.3 to 3 at random
// neighbours, 0.57 n). Twice the estimate, at most 64 n + 1e6 (a safeguard,
// should some input not let the rules end: one step never grows a mesh
// without bound).
double feature_allowance(Cdt& cdt, std::size_t n, bool canonical) {
  return std::min(2 * feature_points(cdt, canonical), 64 * static_cast<double>(n) + 1e6);
}

// The cap on the rounds of quality_rounds (a safeguard: each round inserts a
// point or drops a face, so the budget bounds them too).
constexpr std::size_t kMaxQualityRounds = 100000;

// The pieces in an order of their points (lowest end, then the other), for a
// pass that must not depend on the order they were handed in.
std::vector<Constraint_piece> pieces_by_points(const std::vector<Constraint_piece>& pieces,
                                               const std::vector<Vec2>& points) {
  std::vector<Constraint_piece> sorted = pieces;
  auto key = [&](const Constraint_piece& p) {
    const Vec2 &a = points[p.a], &b = points[p.b];
    return a < b ? std::make_pair(a, b) : std::make_pair(b, a);
  };
  std::stable_sort(sorted.begin(), sorted.end(),
                   [&](const Constraint_piece& x, const Constraint_piece& y) { return key(x) < key(y); });
  return sorted;
}

// The quality pass on `cdt`, which holds all points (handles by point index).
Refined_mesh quality_pass(Cdt& cdt, const std::vector<Vertex_handle>& handles, const Scaling& scaling,
                          const std::vector<Vec2>& points, const std::vector<Point_kind>& kind,
                          const std::vector<Constraint_piece>& pieces, const Quality_options& options,
                          const std::vector<std::uint8_t>& pinned) {
  using Clock = std::chrono::steady_clock;
  const auto seconds_since = [](Clock::time_point begin) {
    return std::chrono::duration<double>(Clock::now() - begin).count();
  };
  const auto constraints_begin = Clock::now();
  try {
    for (const auto& piece : pieces) cdt.insert_constraint(handles[piece.a], handles[piece.b]);
  } catch (const Cdt::Intersection_of_constraints_exception&) {
    throw crossing_pieces_error(points, pieces);
  }
  Refinement_report report;
  report.insert_seconds = seconds_since(constraints_begin);
  std::vector<std::uint8_t> removed(points.size(), 0);
  std::vector<std::pair<Vertex_handle, Vertex_handle>> crowded;
  const bool rounds = options.quality_rounds;
  if (options.crowding_angle > 0) {
    // (In rounds, pieces in an order of their points: which apex goes first
    // must not follow the order they were handed in.)
    crowded = drop_crowding_points(cdt, handles, rounds ? pieces_by_points(pieces, points) : pieces,
                                   options.crowding_angle, pinned, removed, report);
  }
  mark_domain(cdt, handles, pieces);
  Mesher mesher(cdt, Refinement_criteria(options.min_angle, cdt, nullptr, /*off_centres=*/true, /*canonical=*/rounds));
  mesher.init();
  for (const auto& e : crowded) mesher.queue_split(e.first, e.second);
  double budget = options.max_inserted_fraction * static_cast<double>(points.size()) + options.max_inserted_extra;
  if (!mesher.has_small_angles()) budget += feature_allowance(cdt, points.size(), rounds);
  const auto limit = static_cast<std::size_t>(std::max(0.0, budget));
  const auto refine_begin = Clock::now();
  if (rounds) {
    const Rounds_report r = mesher.run_in_rounds(limit, kMaxQualityRounds);
    report.n_inserted = r.n_inserted;
    report.rounds = r.rounds;
    report.capped = r.capped;
    report.stalled = r.stalled;
    report.round_limit = r.round_limit;
  } else {
    run_mesher(mesher, limit, report);
    report.rounds = 1;
  }
  report.insert_seconds += seconds_since(refine_begin);
  Refined_mesh result = extract(cdt, handles, points, kind, removed, scaling);
  result.f.clear();
  result.report.n_inserted = report.n_inserted;
  result.report.n_removed = report.n_removed;
  result.report.n_crowded_segments = report.n_crowded_segments;
  result.report.rounds = report.rounds;
  result.report.capped = report.capped;
  result.report.stalled = report.stalled;
  result.report.round_limit = report.round_limit;
  result.report.insert_seconds = report.insert_seconds;
  return result;
}

// Whether every point scales exactly (and stays normal) with `s`.
bool scales_exactly(const Vec2* begin, const Vec2* end, const Scaling& s) {
  for (const Vec2* p = begin; p != end; ++p) {
    for (double x : *p) {
      const double y = x * s.to_unit;
      if (y * s.from_unit != x || (y != 0 && !std::isnormal(y))) return false;
    }
  }
  return true;
}

}  // namespace

Refined_mesh quality_triangulate(const std::vector<Vec2>& points, const std::vector<Point_kind>& kind,
                                 const std::vector<Constraint_piece>& pieces, const Quality_options& options,
                                 const std::vector<std::uint8_t>& pinned) {
  options.validate();
  Cdt cdt;
  const Scaling scaling = unit_scaling(points);
  const auto handles = insert_points(cdt, points, scaling.to_unit);
  return quality_pass(cdt, handles, scaling, points, kind, pieces, options, pinned);
}

struct Early_triangulation::Impl {
  Cdt cdt;
  Scaling scaling;
  std::size_t n_first = 0;  // points inserted so far
  bool started = false;
  bool unscaled = false;  // a later batch did not scale exactly: finish() starts afresh
};

Early_triangulation::Early_triangulation() : impl_(std::make_unique<Impl>()) {}
Early_triangulation::~Early_triangulation() = default;

void Early_triangulation::insert_first(const std::vector<Vec2>& first) {
  Impl& impl = *impl_;
  impl.scaling = unit_scaling(first);
  insert_points_only(impl.cdt, first, impl.scaling.to_unit);  // (on the step's second thread: no handles)
  impl.n_first = first.size();
  impl.started = true;
}

void Early_triangulation::insert_more(const std::vector<Vec2>& more) {
  Impl& impl = *impl_;
  if (!impl.started || impl.unscaled) return;
  if (!scales_exactly(more.data(), more.data() + more.size(), impl.scaling)) {
    impl.unscaled = true;
    return;
  }
  std::vector<std::pair<Point_2, Vertex_info>> input;
  input.reserve(more.size());
  for (std::size_t k = 0; k < more.size(); ++k) {
    Vertex_info info;
    info.index = static_cast<Index>(impl.n_first + k);
    input.emplace_back(Point_2(more[k][0] * impl.scaling.to_unit, more[k][1] * impl.scaling.to_unit), info);
  }
  impl.cdt.insert(input.begin(), input.end());
  impl.n_first += more.size();
  if (impl.cdt.number_of_vertices() != impl.n_first) throw Input_error("points contain duplicates");
}

Refined_mesh Early_triangulation::finish(const std::vector<Vec2>& points, const std::vector<Point_kind>& kind,
                                         const std::vector<Constraint_piece>& pieces, const Quality_options& options,
                                         const std::vector<std::uint8_t>& pinned) {
  Impl& impl = *impl_;
  options.validate();
  if (!impl.started || impl.unscaled || impl.n_first > points.size() ||
      !scales_exactly(points.data() + impl.n_first, points.data() + points.size(), impl.scaling) ||
      unit_scaling(points).to_unit != impl.scaling.to_unit) {
    return quality_triangulate(points, kind, pieces, options, pinned);
  }
  Cdt& cdt = impl.cdt;
  std::vector<std::pair<Point_2, Vertex_info>> input;
  input.reserve(points.size() - impl.n_first);
  for (std::size_t i = impl.n_first; i < points.size(); ++i) {
    Vertex_info info;
    info.index = static_cast<Index>(i);
    input.emplace_back(Point_2(points[i][0] * impl.scaling.to_unit, points[i][1] * impl.scaling.to_unit), info);
  }
  cdt.insert(input.begin(), input.end());
  if (cdt.number_of_vertices() != points.size()) throw Input_error("points contain duplicates");
  // The batches inserted early are the first points of the final list.
  const double from_unit = impl.scaling.from_unit;
  const auto handles = vertex_handles(
      cdt, points.size(),
      [&](const Vertex_handle& v) {
        const Vec2& p = points[v->info().index];
        return v->point().x() * from_unit == p[0] && v->point().y() * from_unit == p[1];
      },
      "Early_triangulation: a point inserted early is not the final point at its index");
  Refined_mesh refined = quality_pass(cdt, handles, impl.scaling, points, kind, pieces, options, pinned);
  impl_ = std::make_unique<Impl>();  // the triangulation's memory goes before the step's next stage
  return refined;
}

std::pair<double, Vec2> smallest_angle(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles) {
  // Blocks in parallel, each its first smallest angle; the first smallest of
  // theirs in block order is the first smallest of all (any thread count).
  constexpr std::size_t kBlock = 1 << 15;
  const std::size_t n_blocks = (triangles.size() + kBlock - 1) / kBlock;
  std::vector<std::pair<double, Vec2>> in_block(n_blocks);
  parallel_for(n_blocks, 0, [&](std::size_t b) {
    in_block[b] = smallest_angle_in(points, triangles, b * kBlock, std::min(triangles.size(), (b + 1) * kBlock));
  });
  std::pair<double, Vec2> best{180.0, Vec2{0, 0}};
  for (const auto& candidate : in_block) {
    if (candidate.first < best.first) best = candidate;
  }
  return best;
}

namespace {

Quality_summary summary_of(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles, std::size_t begin,
                           std::size_t end) {
  constexpr double kDegrees = 180.0 / kPi;
  Quality_summary s;
  for (std::size_t t = begin; t < end; ++t) {
    const Vec2& a = points[triangles[t][0]];
    const Vec2& b = points[triangles[t][1]];
    const Vec2& c = points[triangles[t][2]];
    const double l0 = std::sqrt((c[0] - b[0]) * (c[0] - b[0]) + (c[1] - b[1]) * (c[1] - b[1]));  // opposite a
    const double l1 = std::sqrt((a[0] - c[0]) * (a[0] - c[0]) + (a[1] - c[1]) * (a[1] - c[1]));
    const double l2 = std::sqrt((b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]));
    auto angle = [&](double x, double y, double z) {
      return std::acos(std::clamp((y * y + z * z - x * x) / (2 * y * z), -1.0, 1.0)) * kDegrees;
    };
    const double angles[3] = {angle(l0, l1, l2), angle(l1, l2, l0), angle(l2, l0, l1)};
    const double smallest = std::min({angles[0], angles[1], angles[2]});
    if (s.worst < 0 || smallest < s.min_angle) {
      s.min_angle = smallest;
      s.worst = static_cast<Index>(t);
    }
    for (double x : angles) {
      s.max_angle = std::max(s.max_angle, x);
      // numpy.histogram's bins [10 k, 10 (k + 1)), the last one closed
      int bin = std::min(17, std::max(0, static_cast<int>(std::floor(x / 10.0))));
      if (x < 10.0 * bin) --bin;
      else if (bin < 17 && x >= 10.0 * (bin + 1)) ++bin;
      ++s.histogram[bin];
    }
    const double d1x = b[0] - a[0], d1y = b[1] - a[1], d2x = c[0] - a[0], d2y = c[1] - a[1];
    const double area = 0.5 * std::abs(d1x * d2y - d1y * d2x);
    const double ratio = l2 * l0 * l1 / (4 * area) / std::min({l2, l0, l1});
    s.max_radius_edge = std::max(s.max_radius_edge, ratio);
    s.sum_radius_edge += ratio;
  }
  return s;
}

}  // namespace

Quality_summary quality_summary(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles) {
  constexpr std::size_t kBlock = 1 << 15;
  const std::size_t n_blocks = (triangles.size() + kBlock - 1) / kBlock;
  std::vector<Quality_summary> part(n_blocks);
  parallel_for(n_blocks, 0, [&](std::size_t b) {
    part[b] = summary_of(points, triangles, b * kBlock, std::min(triangles.size(), (b + 1) * kBlock));
  });
  Quality_summary all;
  for (const auto& p : part) {  // in block order: the first smallest angle, sums in a fixed order
    if (p.worst >= 0 && (all.worst < 0 || p.min_angle < all.min_angle)) {
      all.min_angle = p.min_angle;
      all.worst = p.worst;
    }
    all.max_angle = std::max(all.max_angle, p.max_angle);
    all.max_radius_edge = std::max(all.max_radius_edge, p.max_radius_edge);
    all.sum_radius_edge += p.sum_radius_edge;
    for (int k = 0; k < 18; ++k) all.histogram[k] += p.histogram[k];
  }
  return all;
}

std::pair<double, Vec2> smallest_angle_in(const std::vector<Vec2>& points, const std::vector<Triangle>& triangles,
                                          std::size_t begin, std::size_t end) {
  double best = 180.0;
  Vec2 where{0, 0};
  // The angle at a corner is atan2(|cross|, dot) of its two edges, and atan2 is
  // most of the cost. A triangle whose every corner has |cross| > tan(beyond)
  // dot (or dot <= 0) has every angle above `beyond`, a little more than the
  // best so far: it cannot hold a smaller one, and its angles are not computed.
  // The others are computed as always, so the answer is the same.
  constexpr double kMarginDegrees = 1e-6;  // far above the rounding of atan2 and tan
  double beyond_tan = -1;                  // < 0: no bound yet (best + margin >= 90)
  auto set_bound = [&]() {
    const double beyond = best + kMarginDegrees;
    beyond_tan = beyond < 89.0 ? std::tan(beyond * kPi / 180.0) : -1;
  };
  for (std::size_t i = begin; i < end; ++i) {
    const Triangle& t = triangles[i];
    double cross[3], dot[3];
    bool may_hold_smaller = beyond_tan < 0;
    for (int k = 0; k < 3; ++k) {
      const Vec2& p = points[t[k]];
      const Vec2& q = points[t[(k + 1) % 3]];
      const Vec2& r = points[t[(k + 2) % 3]];
      const double ux = q[0] - p[0], uy = q[1] - p[1], vx = r[0] - p[0], vy = r[1] - p[1];
      cross[k] = std::abs(ux * vy - uy * vx);
      dot[k] = ux * vx + uy * vy;
      may_hold_smaller = may_hold_smaller || (dot[k] > 0 && !(cross[k] > beyond_tan * dot[k]));
    }
    if (!may_hold_smaller) continue;
    for (int k = 0; k < 3; ++k) {
      const double angle = std::atan2(cross[k], dot[k]) * 180.0 / kPi;
      if (angle < best) {
        best = angle;
        const Vec2& p = points[t[k]];
        const Vec2& q = points[t[(k + 1) % 3]];
        const Vec2& r = points[t[(k + 2) % 3]];
        where = {(p[0] + q[0] + r[0]) / 3.0, (p[1] + q[1] + r[1]) / 3.0};
        set_bound();
      }
    }
  }
  return {best, where};
}

}  // namespace evomesh
