// Selection_nn (output_nn.hpp): the output's squared nn, completed from the
// selected points' after points are dropped and added, has the same bits as a
// kd-tree over the output (nn_spacing), on random points, lattices (many equal
// distances), clusters, any thread count and any share dropped or added; and
// it declines (false) where the output has duplicates or is not the selection.
#include <cmath>
#include <cstdint>
#include <vector>

#include "check.hpp"
#include "evomesh/output_nn.hpp"
#include "evomesh/spacing.hpp"

using namespace evomesh;

namespace {

struct Random {
  std::uint64_t state;
  double uniform() {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state >> 11) * 0x1.0p-53;
  }
};

// An output from `selected`: every `drop_every`-th point dropped (0: none),
// then `added` points (from `extra`) inserted at spread positions.
struct Output {
  std::vector<Vec2> points;
  std::vector<Index> source;
};
Output make_output(const std::vector<Vec2>& selected, std::size_t drop_every, const std::vector<Vec2>& extra) {
  Output out;
  std::size_t e = 0;
  for (std::size_t i = 0; i < selected.size(); ++i) {
    if (drop_every > 0 && i % drop_every == 3) continue;
    out.points.push_back(selected[i]);
    out.source.push_back(static_cast<Index>(i));
    if (e < extra.size() && i % 5 == 1) {
      out.points.push_back(extra[e++]);
      out.source.push_back(-1);
    }
  }
  for (; e < extra.size(); ++e) {
    out.points.push_back(extra[e]);
    out.source.push_back(-1);
  }
  return out;
}

void check_case(const char* name, const std::vector<Vec2>& selected, std::size_t drop_every,
                const std::vector<Vec2>& extra) {
  const Output out = make_output(selected, drop_every, extra);
  const std::vector<double> expected = nn_spacing(out.points);
  for (int threads : {1, 2, 4}) {
    Selection_nn nn(selected, threads);
    std::vector<double> nn2;
    const bool ok = nn.output_squared_nn(out.points, out.source, nn2);
    CHECK(ok) << name << " threads " << threads;
    if (!ok) continue;
    CHECK(nn2.size() == expected.size()) << name;
    std::size_t differ = 0;
    for (std::size_t i = 0; i < expected.size() && i < nn2.size(); ++i) differ += std::sqrt(nn2[i]) != expected[i];
    CHECK(differ == 0) << name << " threads " << threads << ": " << differ << " of " << expected.size() << " differ";
  }
}

std::vector<Vec2> random_points(std::size_t n, std::uint64_t seed, double lo = 0, double hi = 1) {
  Random r{seed};
  std::vector<Vec2> p(n);
  for (auto& x : p) x = {lo + (hi - lo) * r.uniform(), lo + (hi - lo) * r.uniform()};
  return p;
}

std::vector<Vec2> lattice(std::size_t side, double step, double x0 = 0) {
  std::vector<Vec2> p;
  for (std::size_t i = 0; i < side; ++i) {
    for (std::size_t j = 0; j < side; ++j) p.push_back({x0 + step * static_cast<double>(i), step * static_cast<double>(j)});
  }
  return p;
}

void check_cases() {
  const auto uniform = random_points(20000, 1);
  check_case("random, nothing dropped or added", uniform, 0, {});
  check_case("random, dropped", uniform, 7, {});
  check_case("random, added", uniform, 0, random_points(3000, 2));
  check_case("random, dropped and added", uniform, 2, random_points(9000, 3));
  // added points in a cluster: they are each other's nearest, and crowd a few selected ones
  check_case("cluster added", uniform, 11, random_points(2000, 4, 0.40, 0.41));
  // lattices: four equal nearest distances everywhere; added at cell centres and on edges
  const auto grid = lattice(120, 0.25);
  std::vector<Vec2> centres, halves;
  for (std::size_t i = 0; i + 1 < 120; i += 3) {
    for (std::size_t j = 0; j + 1 < 120; j += 2) {
      centres.push_back({0.25 * (static_cast<double>(i) + 0.5), 0.25 * (static_cast<double>(j) + 0.5)});
      halves.push_back({0.25 * (static_cast<double>(j) + 0.5), 0.25 * static_cast<double>(i)});
    }
  }
  check_case("lattice, dropped", grid, 4, {});
  check_case("lattice, centres added", grid, 0, centres);
  check_case("lattice, dropped, edge midpoints added", grid, 3, halves);
  // a graded cloud: nn over six orders of magnitude
  std::vector<Vec2> graded = random_points(5000, 5);
  for (auto& x : graded) x = {std::pow(x[0], 6.0), x[1]};
  check_case("graded, dropped and added", graded, 5, random_points(500, 6, 0, 1e-3));
  check_case("two points", {{0, 0}, {1, 0}}, 0, {{0.5, 0.5}});
}

void check_declines() {
  const auto points = random_points(1000, 7);
  {
    // a duplicate added point
    Output out = make_output(points, 0, {points[10]});
    Selection_nn nn(points, 2);
    std::vector<double> nn2;
    CHECK(!nn.output_squared_nn(out.points, out.source, nn2)) << "duplicate";
  }
  {
    // an output point that is not the selected point it names
    Output out = make_output(points, 0, {});
    out.points[5][0] += 1e-3;
    Selection_nn nn(points, 2);
    std::vector<double> nn2;
    CHECK(!nn.output_squared_nn(out.points, out.source, nn2)) << "moved";
  }
  {
    // a selected point listed twice
    Output out = make_output(points, 0, {});
    out.source[6] = out.source[5];
    out.points[6] = out.points[5];
    Selection_nn nn(points, 1);
    std::vector<double> nn2;
    CHECK(!nn.output_squared_nn(out.points, out.source, nn2)) << "twice";
  }
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    check_cases();
    check_declines();
  });
}
