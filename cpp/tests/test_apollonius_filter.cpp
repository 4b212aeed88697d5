// The Apollonius graph's interval filter without exceptions
// (detail/apollonius_filter.hpp) against CGAL's own filtered traits: the same
// graph (finite edges, hidden sites) and the same nearest sites, on inputs where
// the filter fails for most insertions (lattices with equal or few distinct
// weights: cocircular sites) and on random ones; and Flagged_interval's
// comparisons flag exactly the undecided ones.
#include <CGAL/Apollonius_graph_2.h>
#include <CGAL/Apollonius_graph_filtered_traits_2.h>
#include <CGAL/Mpzf.h>
#include <CGAL/Simple_cartesian.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "check.hpp"
#include "evomesh/detail/apollonius_filter.hpp"
#include "evomesh/spacing.hpp"

namespace {

using Kernel = CGAL::Simple_cartesian<double>;
using Exact = CGAL::Simple_cartesian<CGAL::Mpzf>;
using Cgal_traits = CGAL::Apollonius_graph_filtered_traits_2<Kernel, CGAL::Integral_domain_without_division_tag, Exact>;
using Our_traits = evomesh::detail::Apollonius_traits_without_throws<Kernel, Exact>;

struct Site {
  double x, y, w;
};

using Edge_key = std::array<double, 6>;  // the two sites (x, y, w), smaller first

template <class Traits>
struct Graph_summary {
  std::set<Edge_key> edges;
  std::size_t n_vertices = 0;
  std::vector<std::array<double, 3>> nearest;  // site nearest to each query
  bool valid = false;
};

template <class Traits>
Graph_summary<Traits> build(const std::vector<Site>& sites, const std::vector<std::array<double, 2>>& queries) {
  using Graph = CGAL::Apollonius_graph_2<Traits>;
  using Site_2 = typename Traits::Site_2;
  using Point_2 = typename Traits::Point_2;
  Graph graph;
  for (const Site& s : sites) graph.insert(Site_2(Point_2(s.x, s.y), s.w));
  Graph_summary<Traits> out;
  out.valid = graph.is_valid();
  out.n_vertices = graph.number_of_vertices();
  auto key = [](const Site_2& s) { return std::array<double, 3>{s.x(), s.y(), s.weight()}; };
  for (auto e = graph.finite_edges_begin(); e != graph.finite_edges_end(); ++e) {
    auto a = key(e->first->vertex(CGAL::Triangulation_cw_ccw_2().ccw(e->second))->site());
    auto b = key(e->first->vertex(CGAL::Triangulation_cw_ccw_2().cw(e->second))->site());
    if (b < a) std::swap(a, b);
    out.edges.insert({a[0], a[1], a[2], b[0], b[1], b[2]});
  }
  for (const auto& q : queries) {
    const auto v = graph.nearest_neighbor(Point_2(q[0], q[1]));
    out.nearest.push_back(key(v->site()));
  }
  return out;
}

void compare(const char* name, const std::vector<Site>& sites, const std::vector<std::array<double, 2>>& queries,
             bool degenerate) {
  evomesh::detail::exact_evaluations = 0;
  const auto ours = build<Our_traits>(sites, queries);
  const std::size_t exact = evomesh::detail::exact_evaluations;
  // On a lattice the interval filter fails: the exact path is exercised.
  CHECK(!degenerate || exact > 0) << name;
  const auto cgal = build<Cgal_traits>(sites, queries);
  CHECK(ours.valid) << name;
  CHECK(cgal.valid) << name;
  CHECK(ours.n_vertices == cgal.n_vertices) << name << ours.n_vertices << " vs " << cgal.n_vertices;
  CHECK(ours.edges == cgal.edges) << name << ours.edges.size() << " vs " << cgal.edges.size() << " edges";
  CHECK(ours.nearest == cgal.nearest) << name;
  std::printf("%s: %zu sites, %zu vertices, %zu edges, %zu exact evaluations\n", name, sites.size(), ours.n_vertices,
              ours.edges.size(), exact);
}

// A k x k lattice of spacing h; weight(i, j) per site; queries at the sites, the
// cell centres and the edge midpoints (where nearest sites tie).
void lattice(const char* name, int k, double (*weight)(int, int)) {
  std::vector<Site> sites;
  std::vector<std::array<double, 2>> queries;
  const double h = 1.0 / (k - 1);
  for (int j = 0; j < k; ++j) {
    for (int i = 0; i < k; ++i) {
      sites.push_back({i * h, j * h, weight(i, j) * h});
      queries.push_back({i * h, j * h});
      queries.push_back({(i + 0.5) * h, (j + 0.5) * h});
      queries.push_back({(i + 0.5) * h, j * h});
    }
  }
  // Shuffled insertion: the conflicts are found in another order.
  std::mt19937 rng(7);
  std::shuffle(sites.begin(), sites.end(), rng);
  compare(name, sites, queries, true);
}

void flagged_interval() {
  using evomesh::detail::Flagged_interval;
  using evomesh::detail::interval_undecided;
  CGAL::Protect_FPU_rounding<true> rounding;
  const Flagged_interval one(1.0);
  interval_undecided = false;
  CHECK(one > 0 && !(one < 0) && one != 0 && CGAL::sign(one) == CGAL::POSITIVE);
  CHECK(!interval_undecided) << "decided comparisons flagged";
  // An interval around 0 (as the error of a near-degenerate predicate leaves
  // it), squared and added to: its sign is undecided.
  const Flagged_interval eps(Flagged_interval::Interval(-1e-17, 1e-17));
  const Flagged_interval around_zero = eps * one + eps * eps;
  CHECK(!interval_undecided);
  CHECK(around_zero.interval().inf() < 0 && around_zero.interval().sup() >= 0)
      << around_zero.interval().inf() << " " << around_zero.interval().sup();
  (void)(around_zero < 0);
  CHECK(interval_undecided) << "an undecided comparison did not set the flag";
  interval_undecided = false;
  (void)CGAL::sign(around_zero);
  CHECK(interval_undecided) << "an undecided sign did not set the flag";
  interval_undecided = false;
  CHECK(CGAL::compare(Flagged_interval(2.0), one) == CGAL::LARGER && !interval_undecided);
  CHECK(CGAL::sign(Flagged_interval(0.0)) == CGAL::ZERO && !interval_undecided) << "exact zero";
}

// evomesh's Spacing_function (four graphs built on threads, queries on threads)
// on a lattice with equal weights and a band of larger ones, where most
// insertions need the exact path: certified f against brute force (the
// minimum of w_c + |x - c| over all sites; ties between lattice sites are equal
// up to rounding).
void spacing_function_on_lattice() {
  const int k = 150;
  const double h = 1.0 / (k - 1);
  std::vector<evomesh::Vec2> sites;
  std::vector<double> weights;
  for (int j = 0; j < k; ++j) {
    for (int i = 0; i < k; ++i) {
      sites.push_back({i * h, j * h});
      weights.push_back((i > 60 && i < 90 ? 3.0 : 1.0) * h);
    }
  }
  const evomesh::Spacing_function f(sites, weights);
  CHECK(f.n_parts() > 1) << f.n_parts();
  std::vector<evomesh::Vec2> queries;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  for (int q = 0; q < 1500; ++q) queries.push_back({u(rng), u(rng)});
  for (int q = 0; q < 500; ++q) queries.push_back(sites[static_cast<std::size_t>(q) * 41 % sites.size()]);
  std::vector<double> value(queries.size());
  f.evaluate(queries.data(), queries.size(), value.data(), nullptr, /*threads=*/2, /*certified=*/true);
  int wrong = 0;
  for (std::size_t q = 0; q < queries.size(); ++q) {
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t c = 0; c < sites.size(); ++c) {
      best = std::min(best, weights[c] + std::hypot(queries[q][0] - sites[c][0], queries[q][1] - sites[c][1]));
    }
    wrong += !(std::abs(value[q] - best) <= 1e-12 * best);
  }
  CHECK(wrong == 0) << wrong << " of " << queries.size() << " queries off the brute-force minimum";
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    flagged_interval();
    spacing_function_on_lattice();
    lattice("lattice, equal weights", 24, [](int, int) { return 1.0; });
    lattice("lattice, zero weights", 24, [](int, int) { return 0.0; });
    lattice("lattice, two weights in bands", 24, [](int i, int) { return i < 12 ? 1.0 : 2.0; });
    lattice("lattice, weights 0.5 / 1 / 2 in a checkerboard", 24,
            [](int i, int j) { return (i + j) % 3 == 0 ? 0.5 : ((i + j) % 3 == 1 ? 1.0 : 2.0); });
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(0, 1), w(0, 0.05);
    std::vector<Site> sites;
    std::vector<std::array<double, 2>> queries;
    for (int i = 0; i < 3000; ++i) {
      sites.push_back({u(rng), u(rng), w(rng)});
      queries.push_back({u(rng), u(rng)});
    }
    compare("random sites and weights", sites, queries, false);
  });
}
