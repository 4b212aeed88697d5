#include "evomesh/spacing.hpp"

#include <CGAL/Apollonius_graph_2.h>
#include <CGAL/Apollonius_graph_filtered_traits_2.h>
#include <CGAL/Mpzf.h>
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Triangulation_ds_vertex_base_2.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <list>
#include <map>
#include <numeric>
#include <optional>
#include <stdexcept>

#include "evomesh/detail/apollonius_filter.hpp"
#include "evomesh/detail/spatial_order.hpp"
#include "evomesh/kernel.hpp"
#include "evomesh/nd/hilbert_order.hpp"
#include "evomesh/nd/kd_tree.hpp"
#include "evomesh/parallel.hpp"

namespace evomesh {

std::vector<double> nn_spacing(const std::vector<Vec2>& points) {
  const std::size_t n = points.size();
  if (n < 2) throw Input_error("nn spacing needs at least two points");
  const auto nn2 = nd::Point_tree<2>(points).squared_nn(0);
  std::vector<double> nn(n);
  for (std::size_t i = 0; i < n; ++i) nn[i] = std::sqrt(nn2[i]);
  return nn;
}

std::vector<double> nn_spacing_after_change(const std::vector<Vec2>& input_points,
                                            const std::vector<double>& input_nn, const std::vector<Vec2>& points,
                                            const std::vector<Triangle>& triangles,
                                            const std::vector<Index>& origin) {
  const std::size_t n = points.size();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (origin.size() != n || input_nn.size() != input_points.size() || n < 2) return nn_spacing(points);
  // The changed points: input points the output lost, and the new points.
  std::vector<std::uint8_t> kept(input_points.size(), 0);
  std::vector<Vec2> changed;
  for (std::size_t i = 0; i < n; ++i) {
    if (origin[i] >= 0) kept[origin[i]] = 1;
    else changed.push_back(points[i]);
  }
  for (std::size_t o = 0; o < input_points.size(); ++o) {
    if (!kept[o]) changed.push_back(input_points[o]);
  }
  if (changed.size() > n / 8) return nn_spacing(points);
  constexpr std::size_t kChunk = 4096;
  const std::size_t n_chunks = (n + kChunk - 1) / kChunk;
  // Kept point p with old nn d = fl(sqrt(m)), m its least squared distance then:
  // m <= bound = fl(d^2) (1 + 1e-15) (d rounds sqrt(m) to nearest; 1e-15 is
  // about 9 units of rounding), so no changed point within squared distance
  // `bound` (computed as the trees compute it) means the old nearest point is
  // kept and no new point is nearer: nn(p) = d, bit for bit.
  std::vector<double> nn(n, nan);
  std::vector<std::uint8_t> open(n, 0);
  {
    const std::optional<nd::Point_tree<2>> changed_tree =
        changed.empty() ? std::nullopt : std::make_optional<nd::Point_tree<2>>(changed);
    parallel_for(n_chunks, 0, [&](std::size_t c) {
      for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
        const double d = origin[i] >= 0 ? input_nn[origin[i]] : nan;
        const double bound = d * d * (1 + 1e-15);
        if (bound >= 0x1p-960 && bound <= 0x1p960 &&
            !(changed_tree && changed_tree->has_point_within(points[i], bound))) {
          nn[i] = d;
        } else {
          open[i] = 1;
        }
      }
    });
  }
  // Upper bounds on the others' nn: their shortest edge, squared (a point
  // without one makes the whole computation fresh).
  std::vector<double> reach(n, std::numeric_limits<double>::infinity());
  for (const Triangle& t : triangles) {
    for (int k = 0; k < 3; ++k) {
      const Index a = t[k], b = t[(k + 1) % 3];
      if (!open[a] && !open[b]) continue;
      const double dx = points[b][0] - points[a][0], dy = points[b][1] - points[a][1];
      const double squared = dx * dx + dy * dy;
      if (open[a]) reach[a] = std::min(reach[a], squared);
      if (open[b]) reach[b] = std::min(reach[b], squared);
    }
  }
  std::vector<Index> open_index;
  std::vector<Vec2> open_points;
  double largest = 0;  // the largest reach, squared
  for (std::size_t i = 0; i < n; ++i) {
    if (!open[i]) continue;
    if (!(reach[i] >= 0x1p-960 && reach[i] <= 0x1p960)) return nn_spacing(points);
    open_index.push_back(static_cast<Index>(i));
    open_points.push_back(points[i]);
    largest = std::max(largest, reach[i]);
  }
  if (open_points.empty()) return nn;
  if (open_points.size() > n / 4) return nn_spacing(points);
  reach = {};
  // Every output point within the largest reach of an open point (the open
  // points among them), in a tree: an open point's nearest other point lies
  // within its reach, so its two nearest points in that tree are itself and its
  // nearest other point of the output (the reach and the trees compute the same
  // squares; the room below only makes the set larger).
  largest *= 1 + 1e-12;
  std::vector<std::uint8_t> near(n, 0);
  {
    const nd::Point_tree<2> open_tree(open_points);
    parallel_for(n_chunks, 0, [&](std::size_t c) {
      for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
        near[i] = open[i] || open_tree.has_point_within(points[i], largest);
      }
    });
  }
  std::vector<Vec2> near_points;
  for (std::size_t i = 0; i < n; ++i) {
    if (near[i]) near_points.push_back(points[i]);
  }
  const nd::Point_tree<2> near_tree(near_points);
  std::vector<double> exact(open_index.size());
  parallel_for((open_index.size() + kChunk - 1) / kChunk, 0, [&](std::size_t c) {
    for (std::size_t k = c * kChunk; k < std::min(open_index.size(), (c + 1) * kChunk); ++k) {
      exact[k] = near_tree.squared_two_nearest(points[open_index[k]])[1];
    }
  });
  bool has_zero = false;
  for (std::size_t k = 0; k < open_index.size(); ++k) {
    has_zero = has_zero || exact[k] == 0;
    nn[open_index[k]] = std::sqrt(exact[k]);
  }
  // A zero is a duplicate or an underflow: nn_spacing says which (and throws).
  if (has_zero) return nn_spacing(points);
  return nn;
}

namespace {

using Ag_kernel = CGAL::Simple_cartesian<double>;
// The robust filtered traits: interval filters, then exact evaluation. The
// predicates need only ring operations on the double inputs, so the exact kernel
// is Mpzf (exact, no allocation for small numbers) instead of the default MP_Float:
// the same decisions, but degenerate inputs (lattices: equal weights on
// cocircular sites, where the filters fail) build about 1.5 times faster. The
// filter is CGAL's interval arithmetic without its exceptions
// (detail/apollonius_filter.hpp): the same decisions again, and on those inputs
// no throw for every site.
using Ag_traits = detail::Apollonius_traits_without_throws<Ag_kernel, CGAL::Simple_cartesian<CGAL::Mpzf>>;
// Every predicate of the traits goes through the filter that checks the flag
// (should a CGAL release name its converter differently, this stops the build).
static_assert(Ag_traits::Compare_x_2::checks_undecided_comparisons &&
              Ag_traits::Compare_y_2::checks_undecided_comparisons &&
              Ag_traits::Compare_weight_2::checks_undecided_comparisons &&
              Ag_traits::Orientation_2::checks_undecided_comparisons &&
              Ag_traits::Is_hidden_2::checks_undecided_comparisons &&
              Ag_traits::Oriented_side_of_bisector_2::checks_undecided_comparisons &&
              Ag_traits::Vertex_conflict_2::checks_undecided_comparisons &&
              Ag_traits::Finite_edge_interior_conflict_2::checks_undecided_comparisons &&
              Ag_traits::Infinite_edge_interior_conflict_2::checks_undecided_comparisons &&
              Ag_traits::Is_degenerate_edge_2::checks_undecided_comparisons);

// Vertex base carrying its site and the index of that site. CGAL's
// Apollonius_graph_vertex_base_2 also holds a list of the sites it hides, a
// 24-byte member even when told not to store them (StoreHidden = false); this
// one has the same interface without it (hidden sites are dropped, as there):
// 40 bytes a vertex instead of 64.
template <class Gt, class Vb = CGAL::Triangulation_ds_vertex_base_2<>>
class Ag_vertex_with_index : public Vb {
  using Hidden_list = std::list<typename Gt::Site_2>;

 public:
  using Geom_traits = Gt;
  using Base = Vb;
  using Point = typename Gt::Point_2;
  using Site_2 = typename Gt::Site_2;
  using Apollonius_graph_data_structure_2 = typename Vb::Triangulation_data_structure;
  using Face_handle = typename Apollonius_graph_data_structure_2::Face_handle;
  using Vertex_handle = typename Apollonius_graph_data_structure_2::Vertex_handle;
  using Hidden_sites_iterator = typename Hidden_list::iterator;
  enum { Store_hidden = false };
  template <typename Tds2>
  struct Rebind_TDS {
    using Vb2 = typename Vb::template Rebind_TDS<Tds2>::Other;
    using Other = Ag_vertex_with_index<Gt, Vb2>;
  };

  Ag_vertex_with_index() : Vb() {}
  explicit Ag_vertex_with_index(const Site_2& p) : Vb(), site_(p) {}
  Ag_vertex_with_index(const Site_2& p, Face_handle f) : Vb(f), site_(p) {}

  const Site_2& site() const { return site_; }
  Site_2& site() { return site_; }
  Face_handle face() const { return Vb::face(); }
  void set_site(const Site_2& p) { site_ = p; }
  std::size_t number_of_hidden_sites() const { return 0; }
  Hidden_sites_iterator hidden_sites_begin() { return no_hidden_sites().begin(); }
  Hidden_sites_iterator hidden_sites_end() { return no_hidden_sites().end(); }
  void add_hidden_site(const Site_2&) {}
  void clear_hidden_sites_container() {}
  bool is_valid(bool verbose = false, int level = 0) const { return Vb::is_valid(verbose, level); }

  Index index = -1;

 private:
  // (an empty list shared by every vertex, never written)
  static Hidden_list& no_hidden_sites() {
    static Hidden_list none;
    return none;
  }
  Site_2 site_;
};

using Ag_tds = CGAL::Triangulation_data_structure_2<Ag_vertex_with_index<Ag_traits>,
                                                    CGAL::Triangulation_face_base_2<Ag_traits>>;
using Apollonius_graph = CGAL::Apollonius_graph_2<Ag_traits, Ag_tds>;
using Site_2 = Ag_traits::Site_2;
using Ag_point = Ag_traits::Point_2;

// Answers are computed in chunks of this many queries (in Hilbert order), each
// starting without a hint, so results are independent of the thread count.
constexpr std::size_t kQueryChunk = 8192;

// sign((wa + |x - a|) - (wb + |x - b|)), the comparison of two cones of f at x
// (Eq. 3) on the weights themselves, not on the graph's shifted ones: ring
// operations only, exact in Mpzf; in Flagged_interval an undecided comparison
// sets the flag. With A = |x - a|^2, B = |x - b|^2, d = wa - wb, e = sqrt(A) -
// sqrt(B): sign(e) = sign(A - B); where d and e have opposite signs, the sign
// is sign(e) times sign(e^2 - d^2), and e^2 - d^2 = (A + B - d^2) - 2 sqrt(AB).
template <class NT>
CGAL::Sign cone_difference_sign(const Vec2& a, double wa, const Vec2& b, double wb, const Vec2& x) {
  const NT ax = NT(x[0]) - NT(a[0]), ay = NT(x[1]) - NT(a[1]);
  const NT bx = NT(x[0]) - NT(b[0]), by = NT(x[1]) - NT(b[1]);
  const NT A = ax * ax + ay * ay, B = bx * bx + by * by;
  const NT d = NT(wa) - NT(wb);
  const int se = static_cast<int>(CGAL::sign(A - B));
  const int sd = static_cast<int>(CGAL::sign(d));
  if (se == 0) return static_cast<CGAL::Sign>(sd);
  if (sd == 0 || sd == se) return static_cast<CGAL::Sign>(se);
  const NT m = A + B - d * d;
  int magnitude;  // sign(|e| - |d|)
  const int sm = static_cast<int>(CGAL::sign(m));
  if (sm > 0) magnitude = static_cast<int>(CGAL::sign(m * m - NT(4) * A * B));
  else magnitude = sm == 0 && CGAL::sign(A * B) == CGAL::ZERO ? 0 : -1;
  return static_cast<CGAL::Sign>(se * magnitude);
}

// cone_difference_sign, exact: the interval filter of the graph's predicates
// (detail/apollonius_filter.hpp), then Mpzf where it cannot decide.
CGAL::Sign compare_cones(const Vec2& a, double wa, const Vec2& b, double wb, const Vec2& x) {
  {
    CGAL::Protect_FPU_rounding<true> protect;
    bool& undecided = detail::interval_undecided;
    undecided = false;
    const CGAL::Sign s = cone_difference_sign<detail::Flagged_interval>(a, wa, b, wb, x);
    if (!undecided) return s;
  }
  ++detail::exact_evaluations;
  return cone_difference_sign<CGAL::Mpzf>(a, wa, b, wb, x);
}

}  // namespace

// Large site sets are split into up to four parts: the cells of a kd split of
// the sites (x at the median, then y at each half's median), each with its own
// Apollonius graph, built in parallel. A part holds the sites of its cell and
// every site within `halo` = max_i w_i of it. Exactness (Eq. 3): any site c with
// w_c + |x - c| <= v has |x - c| <= v since w_c >= 0, so when the nearest site
// of x's part gives v <= halo, all sites that could tie or beat it are in the
// part: its answer is the global one (certified), and at a mesh point p it always
// is, since v <= w_p <= halo. Otherwise (a query far from every site) all parts
// are asked and the best answer wins by the exact predicate. A site hidden in
// the full graph is hidden by a site within w of it, so hiding is decided inside
// its own part too. The parts depend only on the sites, never on the threads.
struct Spacing_function::Impl {
  std::vector<Vec2> sites;
  std::vector<double> weights;
  std::vector<std::int64_t> ids;  // global ids of the sites (empty: their indices)
  double shift = 0.0;
  double halo = 0.0;
  // Cell of a point: the first split is along coordinate `axis` (the longer
  // side of the sites' box, so that a strip of sites splits across its length
  // and the halos stay thin), the second along the other in each half:
  // part (c[axis] < split_x ? 0 : 1) * 2 + (c[1 - axis] < split_y[side] ? 0 : 1).
  int n_parts = 1;
  int axis = 0;
  double split_x = 0;
  double split_y[2] = {0, 0};
  struct Part {
    Apollonius_graph graph;
    double lo_x, lo_y, hi_x, hi_y;  // the cell (infinite at the outside)
    std::size_t n_visible_own = 0;  // sites of the cell that are vertices
    std::size_t n_filtered_own = 0;  // sites of the cell left out as hidden by a neighbour
  };
  std::vector<std::unique_ptr<Part>> parts;

  int part_of(double x, double y) const {
    if (n_parts == 1) return 0;
    const double first = axis == 0 ? x : y, second = axis == 0 ? y : x;
    const int side = first < split_x ? 0 : 1;
    if (n_parts == 2) return side;
    return 2 * side + (second < split_y[side] ? 0 : 1);
  }
};

namespace {

// Sites per part below which one graph is used (splitting costs halo sites and
// buys parallel construction). Measured on 2 cores: 2 or 4 parts build the
// graph 1.8x faster than one from 8e3 sites up (1e4, 3e4, 1e5, 1e6 points).
constexpr std::size_t kMinSitesPerPart = std::size_t{1} << 12;

// Inserts the sites `members` (spatially sorted, previous vertex as hint),
// except those that `skip(order position of each member)` names: sites CGAL would
// find hidden (see dominated_sites), so leaving them out changes nothing.
template <class Skip>
void build_graph(Apollonius_graph& graph, const std::vector<Vec2>& sites, const std::vector<double>& weights,
                 double shift, std::vector<std::size_t> members, const Skip& skip) {
  std::vector<Vec2> pts;
  pts.reserve(members.size());
  for (std::size_t i : members) pts.push_back(sites[i]);
  const auto ordered = detail::spatial_order(pts, detail::Spatial_order::brio);
  // The insertion order of every member (the order of all members, filtered or
  // not, so the graph is built exactly as without the filter).
  std::vector<std::size_t> order(ordered.size());
  for (std::size_t k = 0; k < ordered.size(); ++k) order[k] = static_cast<std::size_t>(ordered[k].index);
  const std::vector<std::uint8_t> skipped = skip(members, order);
  Apollonius_graph::Vertex_handle hint;
  for (const auto& q : ordered) {
    if (skipped[q.index]) continue;
    const std::size_t i = members[q.index];
    const Site_2 site(Ag_point(q.x, q.y), shift - weights[i]);
    auto v = hint == Apollonius_graph::Vertex_handle() ? graph.insert(site) : graph.insert(site, hint);
    if (v != Apollonius_graph::Vertex_handle()) {
      v->index = static_cast<Index>(i);
      hint = v;
    }
  }
  // A site that hides all but one vertex makes CGAL rebuild the graph (clear(),
  // then insert_first/insert_second): the re-created vertices lost their index.
  // Sites are distinct, so the point names the site.
  bool lost = false;
  for (auto v = graph.finite_vertices_begin(); v != graph.finite_vertices_end(); ++v) lost = lost || v->index < 0;
  if (lost) {
    std::map<std::pair<double, double>, Index> index_of;
    for (std::size_t i : members) index_of[{sites[i][0], sites[i][1]}] = static_cast<Index>(i);
    for (auto v = graph.finite_vertices_begin(); v != graph.finite_vertices_end(); ++v) {
      if (v->index < 0) v->index = index_of.at({v->site().point().x(), v->site().point().y()});
    }
  }
}

// For every site p, a mesh neighbour q that hides it in CGAL's sense, -1 for
// none: the disc of p (radius W_p = shift - w_p, as CGAL gets it) lies in q's,
// |p - q| <= W_q - W_p, closed (Apollonius_graph_2's Is_hidden_2, exact).
// Then p never attains the minimum f(x) = min_i w_i + |x - c_i| alone: with the
// rounded shifted weights CGAL decides on, w_q + |x - q| <= w_p + |x - p| for
// every x, and CGAL leaves p out of the graph (hidden) whatever the insertion
// order, since every site whose disc contains q's contains p's. Candidates are
// the triangles' edges (O(n)); a double-precision test with a margin of a
// millionth (far above rounding) discards nearly all pairs before the exact one.
// Only sound hiding matters here: a site this misses is simply inserted.
// Of several neighbours hiding p, the lowest id (`ids`, global ids; null: the
// lowest index): deterministic whatever the array order.
std::vector<Index> dominated_sites(const std::vector<Vec2>& sites, const std::vector<double>& weights, double shift,
                                   const std::vector<Triangle>& triangles, const std::vector<std::int64_t>* ids) {
  const std::size_t n = sites.size();
  const Ag_traits traits;
  const auto hides = traits.is_hidden_2_object();
  constexpr std::size_t kBlock = 1 << 15;
  const std::size_t n_blocks = (triangles.size() + kBlock - 1) / kBlock;
  std::vector<std::vector<std::pair<Index, Index>>> found(n_blocks);  // (hidden p, by q)
  parallel_for(n_blocks, 0, [&](std::size_t b) {
    for (std::size_t t = b * kBlock; t < std::min(triangles.size(), (b + 1) * kBlock); ++t) {
      for (int k = 0; k < 3; ++k) {
        for (int side = 0; side < 2; ++side) {
          const Index p = triangles[t][side == 0 ? k : (k + 1) % 3];
          const Index q = triangles[t][side == 0 ? (k + 1) % 3 : k];
          const double wp = shift - weights[p], wq = shift - weights[q];
          if (!(wq >= wp)) continue;  // exact: CGAL hides p only if W_q >= W_p
          const double dx = sites[p][0] - sites[q][0], dy = sites[p][1] - sites[q][1];
          const double dw = wq - wp;
          // Certainly apart (products in the normal range, where rounding is relative).
          if (dw * dw > 1e-290 && dx * dx + dy * dy > dw * dw * (1 + 1e-6)) continue;
          if (hides(Site_2(Ag_point(sites[q][0], sites[q][1]), wq), Site_2(Ag_point(sites[p][0], sites[p][1]), wp))) {
            found[b].emplace_back(p, q);
          }
        }
      }
    }
  });
  std::vector<Index> by(n, -1);
  for (const auto& block : found) {
    for (const auto& [p, q] : block) {
      if (by[p] < 0 || (ids != nullptr ? (*ids)[q] < (*ids)[by[p]] : q < by[p])) by[p] = q;
    }
  }
  return by;
}

// The median of `values` (a copy), ties broken by position.
double median_of(std::vector<double> values) {
  const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

}  // namespace

Spacing_function::Spacing_function(const std::vector<Vec2>& sites, const std::vector<double>& weights,
                                   std::size_t min_sites_per_part, const std::vector<Triangle>* triangles,
                                   const std::vector<std::int64_t>* site_ids, double shift)
    : impl_(std::make_unique<Impl>()) {
  if (min_sites_per_part == 0) min_sites_per_part = kMinSitesPerPart;
  if (sites.empty()) throw Input_error("spacing function needs at least one site");
  if (sites.size() != weights.size()) throw Input_error("one weight per site is required");
  for (double w : weights) {
    if (!std::isfinite(w) || w < 0) throw Input_error("spacing weights must be finite and >= 0");
  }
  Impl& impl = *impl_;
  impl.sites = sites;
  impl.weights = weights;
  // Apollonius distance is |x - c| - W; with W_i = shift - w_i >= 0 the nearest
  // site minimises w_i + |x - c_i|.
  impl.shift = *std::max_element(weights.begin(), weights.end());
  if (shift != 0) {
    if (!(shift >= impl.shift) || !std::isfinite(shift)) {
      throw Input_error("spacing function: shift must be finite and at least the largest weight");
    }
    impl.shift = shift;
  }
  // Queries between sites have f a little above the weights: twice the largest
  // weight certifies nearly all of them (and every query at a site).
  impl.halo = 2 * impl.shift;
  const std::size_t n = sites.size();

  // The split, and every part's members: its own sites, then those within the
  // halo of its cell (site membership uses a slightly larger halo, so rounding
  // in these comparisons can only add sites).
  std::vector<std::vector<std::size_t>> members;
  std::vector<std::array<double, 4>> cells(1);  // lo_x, lo_y, hi_x, hi_y
  int n_parts = n >= 4 * min_sites_per_part ? 4 : n >= 2 * min_sites_per_part ? 2 : 1;
  if (n_parts > 1) {
    double lo[2] = {sites[0][0], sites[0][1]}, hi[2] = {sites[0][0], sites[0][1]};
    for (const Vec2& s : sites) {
      for (int c = 0; c < 2; ++c) lo[c] = std::min(lo[c], s[c]), hi[c] = std::max(hi[c], s[c]);
    }
    impl.axis = hi[1] - lo[1] > hi[0] - lo[0] ? 1 : 0;  // (a square: x first, as always)
  }
  const int a = impl.axis, b = 1 - impl.axis;
  while (n_parts > 1) {
    std::vector<double> xs(n);
    for (std::size_t i = 0; i < n; ++i) xs[i] = sites[i][a];
    impl.split_x = median_of(std::move(xs));
    if (n_parts == 4) {
      for (int side = 0; side < 2; ++side) {
        std::vector<double> ys;
        for (std::size_t i = 0; i < n; ++i) {
          if ((sites[i][a] < impl.split_x ? 0 : 1) == side) ys.push_back(sites[i][b]);
        }
        impl.split_y[side] = ys.empty() ? 0.0 : median_of(std::move(ys));
      }
    }
    impl.n_parts = n_parts;
    double max_abs = 0;
    for (const auto& s : sites) max_abs = std::max({max_abs, std::abs(s[0]), std::abs(s[1])});
    const double reach = impl.halo * (1 + 1e-6) + 1e-14 * (max_abs + impl.halo);
    const double inf = std::numeric_limits<double>::infinity();
    members.assign(n_parts, {});
    cells.assign(n_parts, {-inf, -inf, inf, inf});
    std::vector<std::size_t> own(n_parts, 0);
    for (std::size_t i = 0; i < n; ++i) ++own[impl.part_of(sites[i][0], sites[i][1])];
    bool balanced = true;
    for (int k = 0; k < n_parts; ++k) balanced = balanced && own[k] >= n / (4 * n_parts);
    std::size_t total = 0;
    for (int k = 0; k < n_parts && balanced; ++k) {
      auto& cell = cells[k];
      const int side = n_parts == 2 ? k : k / 2;
      // (cell: lo_x, lo_y, hi_x, hi_y; the first split along a, the second along b)
      (side == 0 ? cell[2 + a] : cell[a]) = impl.split_x;
      if (n_parts == 4) (k % 2 == 0 ? cell[2 + b] : cell[b]) = impl.split_y[side];
      for (std::size_t i = 0; i < n; ++i) {
        if (impl.part_of(sites[i][0], sites[i][1]) == k) members[k].push_back(i);
      }
      for (std::size_t i = 0; i < n; ++i) {
        const double x = sites[i][0], y = sites[i][1];
        if (impl.part_of(x, y) != k && x >= cell[0] - reach && x <= cell[2] + reach && y >= cell[1] - reach &&
            y <= cell[3] + reach) {
          members[k].push_back(i);
        }
      }
      total += members[k].size();
    }
    // Splitting pays only while the halos stay thin.
    if (balanced && total <= n + n / 4) break;
    n_parts /= 2;
  }
  if (n_parts == 1) {
    impl.n_parts = 1;
    const double inf = std::numeric_limits<double>::infinity();
    cells.assign(1, {-inf, -inf, inf, inf});
    members.assign(1, std::vector<std::size_t>(n));
    std::iota(members[0].begin(), members[0].end(), 0);
  }
  std::vector<Index> dominator;
  if (site_ids != nullptr && site_ids->empty()) site_ids = nullptr;
  if (site_ids != nullptr && site_ids->size() != n) throw Input_error("one id per site is required");
  if (triangles != nullptr) dominator = dominated_sites(sites, weights, impl.shift, *triangles, site_ids);
  if (site_ids != nullptr) impl.ids = *site_ids;
  impl.parts.resize(n_parts);
  parallel_for(static_cast<std::size_t>(n_parts), 0, [&](std::size_t k) {
    auto part = std::make_unique<Impl::Part>();
    part->lo_x = cells[k][0];
    part->lo_y = cells[k][1];
    part->hi_x = cells[k][2];
    part->hi_y = cells[k][3];
    // Leave out the members hidden by a neighbour that comes before them in this
    // part's insertion order: CGAL would find them hidden by the graph it has
    // then and return at once (Apollonius_graph_2::insert: the nearest vertex
    // hides the site, nothing changes), so the graph is the same, vertex for
    // vertex and face for face, and so is every answer of evaluate(). A site
    // whose neighbour comes after it is inserted as before (CGAL removes it when
    // a site hiding it arrives): leaving it out would give the same graph only up
    // to the layout of its data, and at exact ties the walks could then return
    // another of the tied sites.
    std::size_t n_filtered = 0;
    const auto skip = [&](const std::vector<std::size_t>& mem, const std::vector<std::size_t>& order) {
      std::vector<std::uint8_t> out(mem.size(), 0);
      if (dominator.empty()) return out;
      // Members are the cell's own sites, then the halo's, each run increasing.
      const auto own_end = std::partition_point(mem.begin(), mem.end(), [&](std::size_t i) {
        return impl.part_of(impl.sites[i][0], impl.sites[i][1]) == static_cast<int>(k);
      });
      const auto find = [&](std::size_t q) -> std::ptrdiff_t {
        for (const auto& [first, last] : {std::pair{mem.begin(), own_end}, std::pair{own_end, mem.end()}}) {
          const auto it = std::lower_bound(first, last, q);
          if (it != last && *it == q) return it - mem.begin();
        }
        return -1;
      };
      std::vector<std::size_t> rank(mem.size());
      for (std::size_t r = 0; r < order.size(); ++r) rank[order[r]] = r;
      for (std::size_t j = 0; j < mem.size(); ++j) {
        const Index q = dominator[mem[j]];
        if (q < 0) continue;
        const std::ptrdiff_t jq = find(static_cast<std::size_t>(q));
        out[j] = jq >= 0 && rank[static_cast<std::size_t>(jq)] < rank[j];
        n_filtered += out[j] && mem.begin() + static_cast<std::ptrdiff_t>(j) < own_end;
      }
      return out;
    };
    build_graph(part->graph, impl.sites, impl.weights, impl.shift, std::move(members[k]), skip);
    part->n_filtered_own = n_filtered;
    for (auto v = part->graph.finite_vertices_begin(); v != part->graph.finite_vertices_end(); ++v) {
      const Vec2& c = impl.sites[v->index];
      part->n_visible_own += impl.part_of(c[0], c[1]) == static_cast<int>(k);
    }
    impl.parts[k] = std::move(part);
  });
}

Spacing_function::~Spacing_function() = default;

std::size_t Spacing_function::n_sites() const { return impl_->sites.size(); }
int Spacing_function::n_parts() const { return impl_->n_parts; }
std::size_t Spacing_function::n_hidden() const {
  std::size_t visible = 0;
  for (const auto& part : impl_->parts) visible += part->n_visible_own;
  return impl_->sites.size() - visible;
}
std::size_t Spacing_function::n_filtered() const {
  std::size_t filtered = 0;
  for (const auto& part : impl_->parts) filtered += part->n_filtered_own;
  return filtered;
}
const std::vector<Vec2>& Spacing_function::sites() const { return impl_->sites; }
const std::vector<double>& Spacing_function::weights() const { return impl_->weights; }

void Spacing_function::evaluate(const Vec2* queries, std::size_t n, double* f_out, Index* site_out,
                                int threads, bool certified) const {
  if (n == 0) return;
  // Certified queries in CGAL's median Hilbert order; the many uncertified ones
  // (sample radii) in the O(n) grid Hilbert order, which walks about as short.
  // (the grid order as a bare permutation: the many queries of the radii are
  // read in place, 4 bytes of order a query instead of 24)
  std::vector<detail::Ordered_point> sorted;
  std::vector<std::uint32_t> grid_order;
  if (certified) sorted = detail::spatial_order(queries, n, detail::Spatial_order::hilbert, threads);
  else grid_order = nd::hilbert_grid_permutation<2>(queries, n, threads);
  const Impl& impl = *impl_;
  const auto& sites = impl.sites;
  const auto& weights = impl.weights;
  const std::size_t n_chunks = (n + kQueryChunk - 1) / kQueryChunk;
  using Vertex = Apollonius_graph::Vertex_handle;
  // The one formula for f at x given its site, on every path.
  auto cone = [&](Vertex v, const Vec2& x) {
    const Index s = v->index;
    const double dx = x[0] - sites[s][0];
    const double dy = x[1] - sites[s][1];
    return weights[s] + std::sqrt(dx * dx + dy * dy);
  };
  auto id = [&](Vertex v) -> std::int64_t { return impl.ids.empty() ? v->index : impl.ids[v->index]; };
  // Of two sites, whether w is the answer rather than v: its cone is lower at x,
  // exactly, or ties with the lower id.
  auto better = [&](Vertex w, Vertex v, const Vec2& x) {
    const CGAL::Sign s =
        compare_cones(sites[w->index], weights[w->index], sites[v->index], weights[v->index], x);
    return s == CGAL::NEGATIVE || (s == CGAL::ZERO && id(w) < id(v));
  };
  // A bound above the cone of every site the settle step must see from a walk
  // that ended at value `value`: the double cones are within 4 units of
  // rounding of the exact ones, and the graph decides on the shifted weights
  // shift - w, rounded by at most half a unit of `shift` (2^-48 is 32 units).
  auto near_bound = [&](double value) { return value + 0x1p-48 * (value + impl.shift); };
  // The walk: a vertex of the graph near the minimum of x, from `hint` (may be
  // null), and whether some neighbour's cone came within near_bound of its own
  // (false: it is the one exact minimum, see `settle`).
  auto walk = [&](const Apollonius_graph& graph, const Vec2& x, Vertex hint) -> std::pair<Vertex, bool> {
    const Ag_point point(x[0], x[1]);
    // Below three vertices the graph has no faces to walk on; CGAL scans them.
    if (certified || graph.number_of_vertices() < 3) {
      return {hint == Vertex() ? graph.nearest_neighbor(point) : graph.nearest_neighbor(point, hint), true};
    }
    if (hint == Vertex()) hint = graph.nearest_neighbor(point);
    // Greedy descent over Apollonius-graph neighbours, as CGAL's walk does,
    // with the cone values in double; values strictly decrease, so it ends.
    double best = cone(hint, x);
    for (;;) {
      double least = std::numeric_limits<double>::infinity();  // of the neighbours not below best
      auto c = graph.incident_vertices(hint), done = c;
      Vertex next;
      do {
        if (graph.is_infinite(c)) continue;
        const double value = cone(c, x);
        if (value < best) {
          best = value;
          next = c;
          break;
        }
        least = std::min(least, value);
      } while (++c != done);
      if (next == Vertex()) return {hint, least <= near_bound(best)};
      hint = next;
    }
  };
  // The settle step (docs/distributed-step.md, section 3.2): from the walk's
  // end v, the site of f(x) as a function of x and the site set alone, not of
  // the hint or of which other sites the graph holds. Lemma: the segment from
  // a visible site s to x meets cells of the additively weighted Voronoi
  // diagram that follow one another along graph edges (cells that meet only at
  // a vertex are joined by the graph through the sites of that vertex), and
  // every site t met at a point y has w_t + |x - t| <= w_t + |x - y| + |y - t|
  // <= w_s + |x - y| + |y - s| = w_s + |x - s|. So every site whose cone at x is
  // at most v's is joined to v by graph edges through sites whose cones are at
  // most v's: collecting the vertices reachable from v through sites below
  // near_bound finds every site that ties or beats v, up to the rounding the
  // bound covers, and the exact comparison picks the least cone, ties by the
  // least id. Nearly always v's neighbours are all above the bound (the walk
  // saw it) and v is the answer; otherwise the set is a handful of tied sites.
  auto settle = [&](const Apollonius_graph& graph, const Vec2& x, Vertex v, std::vector<Vertex>& reached) {
    const double bound = near_bound(cone(v, x));
    reached.assign(1, v);
    if (graph.number_of_vertices() < 3) {
      for (auto u = graph.finite_vertices_begin(); u != graph.finite_vertices_end(); ++u) {
        if (Vertex(u) != v && cone(u, x) <= bound) reached.push_back(u);
      }
    } else {
      for (std::size_t k = 0; k < reached.size(); ++k) {
        auto c = graph.incident_vertices(reached[k]), done = c;
        do {
          if (graph.is_infinite(c) || cone(c, x) > bound) continue;
          if (std::find(reached.begin(), reached.end(), Vertex(c)) == reached.end()) reached.push_back(c);
        } while (++c != done);
      }
    }
    for (std::size_t k = 1; k < reached.size(); ++k) {
      if (better(reached[k], v, x)) v = reached[k];
    }
    return v;
  };
  parallel_for(n_chunks, threads, [&](std::size_t chunk) {
    const std::size_t begin = chunk * kQueryChunk;
    const std::size_t end = std::min(n, begin + kQueryChunk);
    Vertex hints[4];
    std::vector<Vertex> reached;
    auto nearest = [&](int part, const Vec2& x) {
      const Apollonius_graph& graph = impl.parts[part]->graph;
      const auto [v, near] = walk(graph, x, hints[part]);
      hints[part] = v;
      return near ? settle(graph, x, v, reached) : v;
    };
    for (std::size_t k = begin; k < end; ++k) {
      const std::size_t q = certified ? sorted[k].index : grid_order[k];
      const Vec2 x = certified ? Vec2{sorted[k].x, sorted[k].y} : queries[q];
      const int part = impl.part_of(x[0], x[1]);
      Vertex v = nearest(part, x);
      double value = cone(v, x);
      if (!(value <= impl.halo)) {
        // Not certified by the part: ask every part, keep the best (the same
        // exact comparison and ids as the settle step, so the answer is the one
        // of a single graph).
        for (int other = 0; other < impl.n_parts; ++other) {
          const Impl::Part& cell = *impl.parts[other];
          // The best site is an own site of a cell within `value` of x.
          const double dx = std::max({cell.lo_x - x[0], 0.0, x[0] - cell.hi_x});
          const double dy = std::max({cell.lo_y - x[1], 0.0, x[1] - cell.hi_y});
          if (other == part || std::sqrt(dx * dx + dy * dy) > value * (1 + 1e-9)) continue;
          const Vertex w = nearest(other, x);
          if (w->index != v->index && better(w, v, x)) {
            v = w;
            value = cone(w, x);
          }
        }
      }
      f_out[q] = value;
      if (site_out) site_out[q] = v->index;
    }
  });
}

}  // namespace evomesh

namespace evomesh {

Cone_scan::Cone_scan(const std::vector<Vec2>& sites, const std::vector<double>& weights,
                     const std::vector<std::int64_t>* site_ids, double shift)
    : sites_(sites), weights_(weights), ids_(site_ids != nullptr && !site_ids->empty() ? site_ids : nullptr) {
  if (sites.empty() || sites.size() != weights.size()) throw Input_error("cone scan: one weight per site, some sites");
  if (ids_ != nullptr && ids_->size() != sites.size()) throw Input_error("one id per site is required");
  shift_ = *std::max_element(weights.begin(), weights.end());  // (as Spacing_function's)
  if (shift != 0) {
    if (!(shift >= shift_) || !std::isfinite(shift)) {
      throw Input_error("spacing function: shift must be finite and at least the largest weight");
    }
    shift_ = shift;
  }
}

double Cone_scan::evaluate(const Vec2& x, const Index* near, std::size_t count, Index* site) const {
  if (count == 0) throw std::logic_error("Cone_scan::evaluate: no site to scan");
  // The one formula for f at x given its site (Spacing_function::evaluate's).
  const auto cone = [&](Index s) {
    const double dx = x[0] - sites_[s][0];
    const double dy = x[1] - sites_[s][1];
    return weights_[s] + std::sqrt(dx * dx + dy * dy);
  };
  double best = std::numeric_limits<double>::infinity(), second = best;
  Index least = near[0];
  for (std::size_t k = 0; k < count; ++k) {
    const double value = cone(near[k]);
    if (value < best) {
      second = best;
      best = value;
      least = near[k];
    } else {
      second = std::min(second, value);
    }
  }
  // Spacing_function::evaluate's near_bound: the double cones are within 4 units
  // of rounding of the exact ones, the shifted weights within half a unit of
  // `shift`. Nearly always one site is below it: that site is the answer (a site
  // hiding it would be there too, its cone within rounding of the hidden one's).
  const double bound = best + 0x1p-48 * (best + shift_);
  if (!(second <= bound)) {
    if (site != nullptr) *site = least;
    return best;
  }
  // Sites tied up to rounding: the least visible one by the exact order (ties:
  // the lowest id), visibility tested against every site within rounding of
  // them (each hider of a tied site is one, see above).
  std::vector<Index> tied, hiders;
  const double wide = bound + 0x1p-48 * (best + shift_);
  for (std::size_t k = 0; k < count; ++k) {
    const double value = cone(near[k]);
    if (value <= bound) tied.push_back(near[k]);
    if (value <= wide) hiders.push_back(near[k]);
  }
  const auto id = [&](Index s) -> std::int64_t { return ids_ == nullptr ? s : (*ids_)[static_cast<std::size_t>(s)]; };
  std::sort(tied.begin(), tied.end(), [&](Index a, Index b) {
    const CGAL::Sign s = compare_cones(sites_[a], weights_[a], sites_[b], weights_[b], x);
    return s == CGAL::NEGATIVE || (s == CGAL::ZERO && id(a) < id(b));
  });
  const Ag_traits traits;
  const auto hides = traits.is_hidden_2_object();
  for (Index c : tied) {
    const double wc = shift_ - weights_[c];
    bool hidden = false;
    for (Index d : hiders) {
      const double wd = shift_ - weights_[d];
      // (exact: CGAL hides c only if W_d >= W_c; dominated_sites)
      if (d == c || !(wd >= wc)) continue;
      if (hides(Site_2(Ag_point(sites_[d][0], sites_[d][1]), wd), Site_2(Ag_point(sites_[c][0], sites_[c][1]), wc))) {
        hidden = true;
        break;
      }
    }
    if (hidden) continue;
    if (site != nullptr) *site = c;
    return cone(c);
  }
  throw std::logic_error("Cone_scan::evaluate: every tied site is hidden");
}

}  // namespace evomesh
