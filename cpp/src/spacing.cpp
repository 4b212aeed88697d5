#include "evomesh/spacing.hpp"

#include <CGAL/Apollonius_graph_2.h>
#include <CGAL/Apollonius_graph_filtered_traits_2.h>
#include <CGAL/Apollonius_graph_vertex_base_2.h>
#include <CGAL/Mpzf.h>
#include <CGAL/Delaunay_triangulation_2.h>
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>
#include <CGAL/hilbert_sort.h>
#include <CGAL/spatial_sort.h>
#include <CGAL/Spatial_sort_traits_adapter_2.h>
#include <CGAL/property_map.h>
#include <CGAL/algorithm.h>
#include <boost/random/linear_congruential.hpp>
#include <boost/random/random_number_generator.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <thread>

#include "evomesh/kernel.hpp"
#include "evomesh/parallel.hpp"

namespace evomesh {

std::vector<double> nn_spacing(const std::vector<Vec2>& points) {
  using Vb = CGAL::Triangulation_vertex_base_with_info_2<Index, Kernel>;
  using Tds = CGAL::Triangulation_data_structure_2<Vb>;
  using Delaunay = CGAL::Delaunay_triangulation_2<Kernel, Tds>;
  const std::size_t n = points.size();
  if (n < 2) throw Input_error("nn spacing needs at least two points");
  std::vector<std::pair<Point_2, Index>> input;
  input.reserve(n);
  for (std::size_t i = 0; i < n; ++i) input.emplace_back(to_cgal(points[i]), static_cast<Index>(i));
  Delaunay dt;
  dt.insert(input.begin(), input.end());  // spatially sorted insert
  if (dt.number_of_vertices() != n) throw Input_error("points contain duplicates");
  std::vector<double> nn2(n, std::numeric_limits<double>::infinity());
  for (auto e = dt.finite_edges_begin(); e != dt.finite_edges_end(); ++e) {
    const auto f = e->first;
    const int i = e->second;
    const auto va = f->vertex(Delaunay::cw(i));
    const auto vb = f->vertex(Delaunay::ccw(i));
    const double d2 = CGAL::squared_distance(va->point(), vb->point());
    nn2[va->info()] = std::min(nn2[va->info()], d2);
    nn2[vb->info()] = std::min(nn2[vb->info()], d2);
  }
  std::vector<double> nn(n);
  for (std::size_t i = 0; i < n; ++i) nn[i] = std::sqrt(nn2[i]);
  return nn;
}

namespace {

using Ag_kernel = CGAL::Simple_cartesian<double>;
// The robust filtered traits: interval filters, then exact evaluation. The
// predicates need only ring operations on the double inputs, so the exact kernel
// is Mpzf (exact, no allocation for small numbers) instead of the default MP_Float:
// the same decisions, but degenerate inputs (lattices: equal weights on
// cocircular sites, where the filters fail) build about 1.5 times faster.
using Ag_traits = CGAL::Apollonius_graph_filtered_traits_2<Ag_kernel, CGAL::Integral_domain_without_division_tag,
                                                           CGAL::Simple_cartesian<CGAL::Mpzf>>;

// Vertex base carrying the index of its site.
template <class Gt, class Vb = CGAL::Triangulation_ds_vertex_base_2<>>
class Ag_vertex_with_index : public CGAL::Apollonius_graph_vertex_base_2<Gt, false, Vb> {
  using Base = CGAL::Apollonius_graph_vertex_base_2<Gt, false, Vb>;

 public:
  template <typename Tds2>
  struct Rebind_TDS {
    using Vb2 = typename Vb::template Rebind_TDS<Tds2>::Other;
    using Other = Ag_vertex_with_index<Gt, Vb2>;
  };
  using Base::Base;
  Index index = -1;
};

using Ag_tds = CGAL::Triangulation_data_structure_2<Ag_vertex_with_index<Ag_traits>,
                                                    CGAL::Triangulation_face_base_2<Ag_traits>>;
using Apollonius_graph = CGAL::Apollonius_graph_2<Ag_traits, Ag_tds>;
using Site_2 = Ag_traits::Site_2;
using Ag_point = Ag_traits::Point_2;

// Answers are computed in chunks of this many queries (in Hilbert order), each
// starting without a hint, so results are independent of the thread count.
constexpr std::size_t kQueryChunk = 8192;

// A query point with its index, sorted in place (contiguous, unlike sorting
// indices into the point array).
struct Query {
  double x, y;
  std::size_t index;
};

// CGAL::hilbert_sort with the median policy, on Query records: the same random
// shuffle (boost::rand48, default seed), then the same recursive median splits
// with the same comparisons, so it yields exactly the permutation
// CGAL::hilbert_sort gives on indices. The subranges below the top levels are
// independent and sorted in parallel; that does not change the result.
template <int axis, bool up>
bool hilbert_less(const Query& p, const Query& q) {
  const double a = axis == 0 ? p.x : p.y;
  const double b = axis == 0 ? q.x : q.y;
  return up ? b < a : a < b;
}

template <int axis, bool up>
Query* hilbert_split(Query* begin, Query* end) {
  if (begin >= end) return begin;
  Query* middle = begin + (end - begin) / 2;
  std::nth_element(begin, middle, end, hilbert_less<axis, up>);
  return middle;
}

using Hilbert_sort_fn = void (*)(Query*, Query*);
struct Hilbert_task {
  Query* begin;
  Query* end;
  Hilbert_sort_fn sort;
};

// Sorts [begin, end); with `tasks`, splits only `levels` levels and leaves the
// subranges below as tasks.
template <int x, bool upx, bool upy>
void hilbert_sort_range(Query* begin, Query* end, int levels = -1, std::vector<Hilbert_task>* tasks = nullptr) {
  constexpr int y = (x + 1) % 2;
  if (end - begin <= 1) return;
  if (tasks != nullptr && levels == 0) {
    tasks->push_back({begin, end, [](Query* b, Query* e) { hilbert_sort_range<x, upx, upy>(b, e); }});
    return;
  }
  Query* m2 = hilbert_split<x, upx>(begin, end);
  Query* m1 = hilbert_split<y, upy>(begin, m2);
  Query* m3 = hilbert_split<y, !upy>(m2, end);
  hilbert_sort_range<y, upy, upx>(begin, m1, levels - 1, tasks);
  hilbert_sort_range<x, upx, upy>(m1, m2, levels - 1, tasks);
  hilbert_sort_range<x, upx, upy>(m2, m3, levels - 1, tasks);
  hilbert_sort_range<y, !upy, !upx>(m3, end, levels - 1, tasks);
}

void hilbert_sort_queries(std::vector<Query>& queries, int threads) {
  boost::rand48 random;
  boost::random_number_generator<boost::rand48, std::ptrdiff_t> rng(random);
  CGAL::cpp98::random_shuffle(queries.begin(), queries.end(), rng);
  Query* begin = queries.data();
  Query* end = begin + queries.size();
  if (queries.size() < 65536) {
    hilbert_sort_range<0, false, false>(begin, end);
    return;
  }
  std::vector<Hilbert_task> tasks;
  hilbert_sort_range<0, false, false>(begin, end, 2, &tasks);  // 16 subranges
  parallel_for(tasks.size(), threads, [&](std::size_t k) { tasks[k].sort(tasks[k].begin, tasks[k].end); });
}

}  // namespace

struct Spacing_function::Impl {
  std::vector<Vec2> sites;
  std::vector<double> weights;
  double shift = 0.0;
  Apollonius_graph graph;
};

Spacing_function::Spacing_function(const std::vector<Vec2>& sites, const std::vector<double>& weights)
    : impl_(std::make_unique<Impl>()) {
  if (sites.empty()) throw Input_error("spacing function needs at least one site");
  if (sites.size() != weights.size()) throw Input_error("one weight per site is required");
  for (double w : weights) {
    if (!std::isfinite(w) || w < 0) throw Input_error("spacing weights must be finite and >= 0");
  }
  impl_->sites = sites;
  impl_->weights = weights;
  // Apollonius distance is |x - c| - W; with W_i = shift - w_i >= 0 the nearest
  // site minimises w_i + |x - c_i|.
  impl_->shift = *std::max_element(weights.begin(), weights.end());
  std::vector<Ag_point> pts;
  pts.reserve(sites.size());
  for (const auto& s : sites) pts.emplace_back(s[0], s[1]);
  std::vector<std::size_t> order(sites.size());
  std::iota(order.begin(), order.end(), 0);
  using Sort_traits = CGAL::Spatial_sort_traits_adapter_2<
      Ag_kernel, CGAL::Pointer_property_map<Ag_point>::type>;
  CGAL::spatial_sort(order.begin(), order.end(), Sort_traits(CGAL::make_property_map(pts)));
  Apollonius_graph::Vertex_handle hint;
  for (std::size_t i : order) {
    const Site_2 site(pts[i], impl_->shift - weights[i]);
    auto v = hint == Apollonius_graph::Vertex_handle() ? impl_->graph.insert(site)
                                                        : impl_->graph.insert(site, hint);
    if (v != Apollonius_graph::Vertex_handle()) {
      v->index = static_cast<Index>(i);
      hint = v;
    }
  }
  // A site that hides all but one vertex makes CGAL rebuild the graph (clear(),
  // then insert_first/insert_second): the re-created vertices lost their index.
  // Sites are distinct, so the point names the site.
  auto& graph = impl_->graph;
  bool lost = false;
  for (auto v = graph.finite_vertices_begin(); v != graph.finite_vertices_end(); ++v) lost = lost || v->index < 0;
  if (lost) {
    std::map<std::pair<double, double>, Index> index_of;
    for (std::size_t i = 0; i < sites.size(); ++i) index_of[{sites[i][0], sites[i][1]}] = static_cast<Index>(i);
    for (auto v = graph.finite_vertices_begin(); v != graph.finite_vertices_end(); ++v) {
      if (v->index < 0) v->index = index_of.at({v->site().point().x(), v->site().point().y()});
    }
  }
}

Spacing_function::~Spacing_function() = default;

std::size_t Spacing_function::n_sites() const { return impl_->sites.size(); }
std::size_t Spacing_function::n_hidden() const {
  return impl_->sites.size() - impl_->graph.number_of_vertices();
}
const std::vector<Vec2>& Spacing_function::sites() const { return impl_->sites; }
const std::vector<double>& Spacing_function::weights() const { return impl_->weights; }

void Spacing_function::evaluate(const Vec2* queries, std::size_t n, double* f_out, Index* site_out,
                                int threads, bool certified) const {
  if (n == 0) return;
  std::vector<Query> sorted(n);
  for (std::size_t i = 0; i < n; ++i) sorted[i] = {queries[i][0], queries[i][1], i};
  hilbert_sort_queries(sorted, threads);
  const auto& graph = impl_->graph;
  const auto& sites = impl_->sites;
  const auto& weights = impl_->weights;
  const std::size_t n_chunks = (n + kQueryChunk - 1) / kQueryChunk;
  parallel_for(n_chunks, threads, [&](std::size_t chunk) {
    const std::size_t begin = chunk * kQueryChunk;
    const std::size_t end = std::min(n, begin + kQueryChunk);
    auto cone = [&](Apollonius_graph::Vertex_handle v, const Vec2& x) {
      const Index s = v->index;
      const double dx = x[0] - sites[s][0];
      const double dy = x[1] - sites[s][1];
      return weights[s] + std::sqrt(dx * dx + dy * dy);
    };
    Apollonius_graph::Vertex_handle hint;
    for (std::size_t k = begin; k < end; ++k) {
      const std::size_t q = sorted[k].index;
      const Vec2 x{sorted[k].x, sorted[k].y};
      const Ag_point point(x[0], x[1]);
      if (hint == Apollonius_graph::Vertex_handle()) {
        hint = graph.nearest_neighbor(point);
      } else if (certified || graph.dimension() < 2) {
        // (the greedy walk needs a 2-D graph: one or two visible sites are answered by CGAL)
        hint = graph.nearest_neighbor(point, hint);
      } else {
        // Greedy descent over Apollonius-graph neighbours, as CGAL's walk does,
        // with the cone values in double; values strictly decrease, so it ends.
        double best = cone(hint, x);
        for (bool moved = true; moved;) {
          moved = false;
          auto c = graph.incident_vertices(hint), done = c;
          do {
            if (graph.is_infinite(c)) continue;
            const double value = cone(c, x);
            if (value < best) {
              best = value;
              hint = c;
              moved = true;
              break;
            }
          } while (++c != done);
        }
      }
      f_out[q] = cone(hint, x);
      if (site_out) site_out[q] = hint->index;
    }
  });
}

}  // namespace evomesh
