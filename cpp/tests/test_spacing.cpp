// nn_spacing and Spacing_function against brute force, one graph and split ones.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

#include "check.hpp"
#include "evomesh/spacing.hpp"

using namespace evomesh;

namespace {

double cone(const Vec2& site, double weight, const Vec2& x) {
  const double dx = x[0] - site[0], dy = x[1] - site[1];
  return weight + std::sqrt(dx * dx + dy * dy);
}

// min over p != skip of |x - p|.
double brute_nn(const std::vector<Vec2>& points, std::size_t skip) {
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t j = 0; j < points.size(); ++j) {
    if (j == skip) continue;
    const double dx = points[skip][0] - points[j][0], dy = points[skip][1] - points[j][1];
    best = std::min(best, std::sqrt(dx * dx + dy * dy));
  }
  return best;
}

enum class Layout { uniform, clustered, graded };

std::vector<Vec2> make_sites(std::size_t n, Layout layout, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<Vec2> sites;
  while (sites.size() < n) {
    Vec2 p;
    switch (layout) {
      case Layout::uniform: p = {u(rng), u(rng)}; break;
      case Layout::clustered: {  // a few tight blobs over a sparse background
        const int blob = static_cast<int>(u(rng) * 5);
        p = blob == 0 ? Vec2{u(rng), u(rng)} : Vec2{0.2 * blob + 0.02 * g(rng), 0.5 + 0.02 * g(rng)};
        break;
      }
      case Layout::graded: {  // density 1/2 + x: a third of the sites on the left half
        const double v = u(rng);
        p = {u(rng) < 0.5 ? v : std::sqrt(v), u(rng)};
        break;
      }
    }
    sites.push_back(p);
  }
  std::sort(sites.begin(), sites.end());
  sites.erase(std::unique(sites.begin(), sites.end()), sites.end());
  std::shuffle(sites.begin(), sites.end(), rng);
  return sites;
}

// Checks f on queries (all sites when few, else a sample) and random points
// against brute force.
// delta is drawn from [0.4, max_delta]: small weights keep the halos of split
// parts thin enough for a split of a few thousand sites.
void check_case(const char* name, std::size_t n, Layout layout, std::size_t min_sites_per_part,
                int expect_min_parts, std::uint64_t seed, double max_delta = 2.5) {
  std::mt19937_64 rng(seed);
  const std::vector<Vec2> sites = make_sites(n, layout, rng);
  n = sites.size();

  // nn_spacing: the same expression as the brute force, so equal.
  const std::vector<double> nn = nn_spacing(sites);
  std::size_t nn_wrong = 0, nn_first = 0;
  for (std::size_t i = 0; i < n; i += n > 3000 ? 7 : 1) {
    if (nn[i] != brute_nn(sites, i) && nn_wrong++ == 0) nn_first = i;
  }
  CHECK(nn_wrong == 0) << name << ": nn_spacing differs from brute force at " << nn_wrong << " points, first "
                       << nn_first;

  // Weights as FRFC makes them: delta * nn, some zero.
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<double> delta(n), weight(n);
  for (std::size_t i = 0; i < n; ++i) {
    delta[i] = 0.4 * std::pow(max_delta / 0.4, u(rng));
    weight[i] = i % 97 == 5 ? 0.0 : delta[i] * nn[i];
  }
  const Spacing_function f(sites, weight, min_sites_per_part);
  CHECK(f.n_sites() == n) << name;
  CHECK(f.n_parts() >= expect_min_parts) << name << ": " << f.n_parts() << " parts, expected at least "
                                         << expect_min_parts;

  // Queries: sites (every one when few), then random points in and around the box.
  std::vector<Vec2> queries;
  std::vector<std::size_t> site_of_query;
  const std::size_t site_step = n > 4000 ? n / 2000 : 1;
  for (std::size_t i = 0; i < n; i += site_step) {
    queries.push_back(sites[i]);
    site_of_query.push_back(i);
  }
  const std::size_t n_at_sites = queries.size();
  for (int k = 0; k < 2000; ++k) queries.push_back({-0.5 + 2 * u(rng), -0.5 + 2 * u(rng)});
  queries.push_back({50.0, -30.0});  // far outside: every part is asked

  std::vector<double> brute(queries.size());
  for (std::size_t q = 0; q < queries.size(); ++q) {
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < n; ++i) best = std::min(best, cone(sites[i], weight[i], queries[q]));
    brute[q] = best;
  }

  // Lemma 3.1: where p's own cone is the minimum with a margin above rounding
  // (every delta <= 1 site is such: w_p <= nn_p < w_q + |p - q|), f(p) = w_p exactly.
  std::vector<bool> own_minimum(n_at_sites, true);
  for (std::size_t q = 0; q < n_at_sites; ++q) {
    const std::size_t p = site_of_query[q];
    for (std::size_t i = 0; i < n && own_minimum[q]; ++i) {
      own_minimum[q] = i == p || cone(sites[i], weight[i], sites[p]) > weight[p] * (1 + 1e-13);
    }
    if (delta[p] <= 1) CHECK(own_minimum[q]) << name << ": delta <= 1 at site " << p << " but not its own minimum";
  }

  for (const bool certified : {true, false}) {
    for (const int threads : {1, 2}) {
      std::vector<double> value(queries.size());
      std::vector<Index> site(queries.size());
      f.evaluate(queries.data(), queries.size(), value.data(), site.data(), threads, certified);
      std::size_t far = 0, inexact = 0, bad_site = 0, lemma = 0;
      double worst = 0;
      for (std::size_t q = 0; q < queries.size(); ++q) {
        // Relative error (brute is 0 at a zero-weight site: then exactly 0).
        const double error = std::abs(value[q] - brute[q]);
        if (!(error <= 1e-12 * brute[q])) ++far;
        if (brute[q] > 0) worst = std::max(worst, error / brute[q]);
        if (site[q] < 0 || site[q] >= static_cast<Index>(n) ||
            value[q] != cone(sites[site[q]], weight[site[q]], queries[q])) {
          ++bad_site;
        }
        if (q < n_at_sites && own_minimum[q]) {
          ++lemma;
          if (value[q] != weight[site_of_query[q]]) ++inexact;
        }
      }
      CHECK(far == 0) << name << (certified ? " certified" : " walk") << " threads " << threads << ": " << far
                      << " values off brute force by more than 1e-12 relative, worst " << worst;
      CHECK(inexact == 0) << name << ": f(p) != w_p at " << inexact << " of " << lemma << " Lemma 3.1 sites";
      CHECK(lemma > n_at_sites / 10) << name << ": only " << lemma << " Lemma 3.1 sites";
      CHECK(bad_site == 0) << name << ": site_out does not give f at " << bad_site << " queries";
    }
  }
  std::printf("%-28s %6zu sites, %d part(s), %zu hidden, %zu queries\n", name, n, f.n_parts(), f.n_hidden(),
              queries.size());
}

// Cone_scan answers as the graph of all the sites: the same f bits and the same
// site at every query, given every site (the brute force) or only those within
// reach (its use). Exact lattices with binary weights make exact ties, sites
// hidden by tangent discs, and ties broken by ids in another order than the
// indices; the case must reach the scan's tie path (several sites within
// rounding) and hidden sites, or it tests nothing there.
// far_heavy: lattice weights 0.05 k (not dyadic: sites tie in the reals two
// steps apart, w_c - w_h = 0.25 = |c - h|, and the shifted weights round) and one
// far site with the largest weight, so the shift is far above the lattice's.
void check_cone_scan(const char* name, bool lattice, bool with_ids, std::uint64_t seed, bool far_heavy = false) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Vec2> sites;
  std::vector<double> weight;
  if (lattice) {
    for (int i = 0; i < 24; ++i) {
      for (int j = 0; j < 24; ++j) sites.push_back({0.125 * i, 0.125 * j});
    }
    std::shuffle(sites.begin(), sites.end(), rng);
    for (std::size_t k = 0; k < sites.size(); ++k) {
      weight.push_back(far_heavy ? 0.05 * static_cast<double>(rng() % 13) : 0.0625 * static_cast<double>(rng() % 7));
    }
    if (far_heavy) {
      sites.push_back({50.0, 50.0});
      weight.push_back(1000.0 / 3.0);
    }
  } else {
    sites = make_sites(3000, Layout::graded, rng);
    const std::vector<double> nn = nn_spacing(sites);
    for (std::size_t k = 0; k < sites.size(); ++k) weight.push_back(nn[k] * 0.4 * std::pow(5.0, u(rng)));
  }
  const std::size_t n = sites.size();
  std::vector<std::int64_t> ids;
  if (with_ids) {
    for (std::size_t k = 0; k < n; ++k) ids.push_back(static_cast<std::int64_t>(k));
    std::shuffle(ids.begin(), ids.end(), rng);
  }
  const Spacing_function graph(sites, weight, 0, nullptr, with_ids ? &ids : nullptr);
  const Cone_scan scan(sites, weight, with_ids ? &ids : nullptr);
  std::vector<Vec2> queries;
  for (std::size_t k = 0; k < sites.size() - (far_heavy ? 1 : 0); ++k) queries.push_back(sites[k]);
  for (int k = 0; k < 3000; ++k) {
    if (lattice) {  // lattice points, edge midpoints and centres
      queries.push_back({0.0625 * static_cast<double>(rng() % 48), 0.0625 * static_cast<double>(rng() % 48)});
    } else {
      queries.push_back({-0.2 + 1.4 * u(rng), -0.2 + 1.4 * u(rng)});
    }
  }
  std::vector<double> value(queries.size());
  std::vector<Index> site(queries.size());
  graph.evaluate(queries.data(), queries.size(), value.data(), site.data(), 1, /*certified=*/true);
  std::vector<Index> all(n), near;
  for (std::size_t k = 0; k < n; ++k) all[k] = static_cast<Index>(k);
  std::size_t differ = 0, differ_near = 0, tied = 0;
  for (std::size_t q = 0; q < queries.size(); ++q) {
    const Vec2& x = queries[q];
    Index s = -1;
    const double v = scan.evaluate(x, all.data(), n, &s);
    differ += v != value[q] || s != site[q];
    // Only the sites within reach of an upper bound of f (here f itself, and twice f).
    for (const double bound : {value[q], 2 * value[q]}) {
      near.clear();
      for (std::size_t k = 0; k < n; ++k) {
        if (cone(sites[k], weight[k], x) <= scan.reach(bound)) near.push_back(static_cast<Index>(k));
      }
      Index s_near = -1;
      const double v_near = scan.evaluate(x, near.data(), near.size(), &s_near);
      differ_near += v_near != value[q] || s_near != site[q];
    }
    std::size_t within = 0;
    for (std::size_t k = 0; k < n; ++k) {
      within += cone(sites[k], weight[k], x) <= value[q] + 0x1p-48 * (value[q] + scan.shift());
    }
    tied += within > 1;
  }
  CHECK(differ == 0) << name << ": the scan of every site differs from the graph at " << differ << " queries";
  CHECK(differ_near == 0) << name << ": the scan of the sites within reach differs at " << differ_near << " queries";
  if (lattice) {
    CHECK(tied > 100) << name << ": only " << tied << " queries with tied sites";
    CHECK(graph.n_hidden() > 10) << name << ": only " << graph.n_hidden() << " hidden sites";
  }
  bool threw = false;
  try {
    scan.evaluate(queries[0], nullptr, 0);
  } catch (const std::logic_error&) {
    threw = true;
  }
  CHECK(threw) << name << ": a scan of no site";
  std::printf("%-28s %6zu sites, %zu hidden, %zu queries, %zu with tied sites\n", name, n, graph.n_hidden(),
              queries.size(), tied);
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    check_case("two sites", 2, Layout::uniform, 0, 1, 1);
    check_case("uniform 300", 300, Layout::uniform, 0, 1, 2);
    check_case("clustered 2000", 2000, Layout::clustered, 0, 1, 3);
    // Forced splits of small sets (min_sites_per_part), then the default
    // threshold above 2 x 2^12 and 4 x 2^12 sites.
    check_case("uniform 4000 split", 4000, Layout::uniform, 500, 4, 4, 0.8);
    check_case("graded 4000 split", 4000, Layout::graded, 500, 2, 5, 0.8);
    check_case("uniform 10000", 10000, Layout::uniform, 0, 2, 6);
    check_case("uniform 20000", 20000, Layout::uniform, 0, 4, 7);
    check_case("clustered 20000", 20000, Layout::clustered, 0, 1, 8);
    check_cone_scan("cone scan, graded", false, false, 9);
    check_cone_scan("cone scan, lattice", true, false, 10);
    check_cone_scan("cone scan, lattice, ids", true, true, 11);
    check_cone_scan("cone scan, lattice, far shift", true, true, 12, /*far_heavy=*/true);

    // Preconditions throw.
    bool threw = false;
    try {
      nn_spacing({{0.0, 0.0}});
    } catch (const Input_error&) {
      threw = true;
    }
    CHECK(threw) << "nn_spacing of one point";
    threw = false;
    try {
      Spacing_function({{0.0, 0.0}}, {-1.0});
    } catch (const Input_error&) {
      threw = true;
    }
    CHECK(threw) << "negative weight";
  });
}
