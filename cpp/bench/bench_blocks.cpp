// Building-block costs per point (wall time): constrained Delaunay, nn_spacing,
// nn within the domain (keep_within_domain over the Delaunay triangles),
// the Apollonius graph (Spacing_function: parts built in parallel from 2^19
// sites on), and f on one thread at the points (certified) and at sample-like
// points (greedy walk). Points: uniform random in the unit square, or the graded
// bench mesh cached by `bench_evolve --cache-dir`.
//
//   bench_blocks [--n 1e6] [--graded FILE]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "evomesh/local_feature_size.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/triangulation.hpp"

using namespace evomesh;

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Points and delta of a graded case written by bench_evolve (cache format 1).
bool load_graded(const std::string& path, std::vector<Vec2>& points, std::vector<double>& delta) {
  std::ifstream in(path, std::ios::binary);
  std::uint64_t version = 0, n = 0;
  if (!in.read(reinterpret_cast<char*>(&version), sizeof version) || version != 1) return false;
  in.read(reinterpret_cast<char*>(&n), sizeof n);
  points.resize(n);
  in.read(reinterpret_cast<char*>(points.data()), static_cast<std::streamsize>(n * sizeof(Vec2)));
  for (int skip = 0; skip < 4; ++skip) {  // triangles, segments, boundary flags, kinds
    static const std::size_t width[] = {sizeof(Triangle), sizeof(Edge), 1, 1};
    in.read(reinterpret_cast<char*>(&n), sizeof n);
    in.seekg(static_cast<std::streamoff>(n * width[skip]), std::ios::cur);
  }
  in.read(reinterpret_cast<char*>(&n), sizeof n);
  delta.resize(n);
  in.read(reinterpret_cast<char*>(delta.data()), static_cast<std::streamsize>(n * sizeof(double)));
  return static_cast<bool>(in);
}

}  // namespace

int main(int argc, char** argv) {
  double n_points = 1e6;
  std::string graded;
  for (int a = 1; a + 1 < argc; a += 2) {
    const std::string arg = argv[a];
    if (arg == "--n") n_points = std::stod(argv[a + 1]);
    else if (arg == "--graded") graded = argv[a + 1];
  }
  std::vector<Vec2> points;
  std::vector<double> delta;
  if (!graded.empty()) {
    if (!load_graded(graded, points, delta)) {
      std::fprintf(stderr, "cannot read %s\n", graded.c_str());
      return 1;
    }
  } else {
    std::mt19937_64 rng(1);
    std::uniform_real_distribution<double> u(0, 1);
    points.resize(static_cast<std::size_t>(n_points));
    for (auto& p : points) p = {u(rng), u(rng)};
    delta.assign(points.size(), 1.0);
  }
  const std::size_t n = points.size();
  const double us = 1e6 / static_cast<double>(n);
  std::printf("# %zu points (%s), microseconds per point (wall)\n", n, graded.empty() ? "uniform" : graded.c_str());

  auto t0 = std::chrono::steady_clock::now();
  const auto nn = nn_spacing(points);
  std::printf("nn_spacing (kd-tree, all threads)  %6.2f\n", seconds_since(t0) * us);

  t0 = std::chrono::steady_clock::now();
  const auto triangles = constrained_delaunay(points, {});
  std::printf("Delaunay (constrained_delaunay)    %6.2f  (%zu triangles: no constraints, no domain)\n", seconds_since(t0) * us, triangles.size());

  {
    // The same points inside a square boundary (its triangles, not timed).
    std::vector<Vec2> boxed = points;
    double lo = 0, hi = 1;
    for (const Vec2& p : points) lo = std::min({lo, p[0], p[1]}), hi = std::max({hi, p[0], p[1]});
    const double pad = 0.1 * (hi - lo);
    for (const Vec2& c : {Vec2{lo - pad, lo - pad}, Vec2{hi + pad, lo - pad}, Vec2{hi + pad, hi + pad},
                          Vec2{lo - pad, hi + pad}}) {
      boxed.push_back(c);
    }
    const Index m = static_cast<Index>(boxed.size());
    const auto domain = constrained_delaunay(
        boxed, {{m - 4, m - 3, true}, {m - 3, m - 2, true}, {m - 2, m - 1, true}, {m - 1, m - 4, true}});
    std::vector<double> within = nn_spacing(boxed);
    t0 = std::chrono::steady_clock::now();
    keep_within_domain(boxed, domain, within);
    std::printf("nn within the domain (its edges)   %6.2f\n", seconds_since(t0) * us);
  }

  std::vector<double> weight(n);
  for (std::size_t i = 0; i < n; ++i) weight[i] = delta[i] * nn[i];
  t0 = std::chrono::steady_clock::now();
  Spacing_function spacing(points, weight);
  std::printf("Apollonius graph (w = delta nn)    %6.2f  (%zu hidden)\n", seconds_since(t0) * us, spacing.n_hidden());

  std::vector<double> f(n);
  t0 = std::chrono::steady_clock::now();
  spacing.evaluate(points.data(), n, f.data(), nullptr, 1, true);
  std::printf("f at the sites, certified, 1 thr   %6.2f\n", seconds_since(t0) * us);

  // Sample-like queries: each point moved by a quarter of its nn.
  std::vector<Vec2> queries(n);
  for (std::size_t i = 0; i < n; ++i) queries[i] = {points[i][0] + 0.25 * nn[i], points[i][1] + 0.125 * nn[i]};
  t0 = std::chrono::steady_clock::now();
  spacing.evaluate(queries.data(), n, f.data(), nullptr, 1, true);
  std::printf("f at nearby points, certified      %6.2f\n", seconds_since(t0) * us);
  t0 = std::chrono::steady_clock::now();
  spacing.evaluate(queries.data(), n, f.data(), nullptr, 1, false);
  std::printf("f at nearby points, greedy walk    %6.2f\n", seconds_since(t0) * us);

  std::vector<double> zero(n, 0.0);
  t0 = std::chrono::steady_clock::now();
  Spacing_function unweighted(points, zero);
  std::printf("Apollonius graph (w = 0)           %6.2f\n", seconds_since(t0) * us);
  return 0;
}
