// Times one FRFC step (Section 3.2) on graded meshes of about 1e4, 1e5, 1e6 points
// (issue 2 "Speed") and larger ones (issue 5 "Scale"): per stage, peak memory, and
// the ratio to a plain CGAL constrained Delaunay of the output points, measured in
// the same run.
//
// The graded mesh (not timed): a k x k triangulated grid on the unit square, then one
// FRFC step towards the spacing h_old of a vertical band of fine spacing (see
// `target_spacing`). The timed step moves the band to the right by kBandShift:
// delta(p) = clamp(h_new(p) / h_old(p), 0.5, 2), a moving front that refines ahead
// of the band, coarsens behind it and leaves the rest (delta = 1) alone.
//
//   bench_evolve [--sizes 1e4,1e5,1e6] [--repeats 3] [--threads 0] [--no-baseline]
//                [--max-samples 5e7] [--json FILE]
#include <malloc.h>
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <CGAL/version.h>

#include "evomesh/frfc.hpp"
#include "evomesh/spacing.hpp"
#include "evomesh/triangulation.hpp"

using namespace evomesh;

namespace {

// Spacing of the band (fine) and away from it: h = s * min(kCoarseRatio, 1 + d / kGradingLength),
// d the distance to the band x in [c - kBandHalfWidth, c + kBandHalfWidth].
constexpr double kBandCenter = 0.35;
constexpr double kBandShift = 0.1;
constexpr double kBandHalfWidth = 0.025;
constexpr double kGradingLength = 0.05;
constexpr double kCoarseRatio = 8.0;
// Output points of the setup step per 1 / s^2 (measured; sets s for a target size).
constexpr double kPointsPerInverseSquareSpacing = 0.205;

double target_spacing(double x, double band_center, double s) {
  const double d = std::max(0.0, std::abs(x - band_center) - kBandHalfWidth);
  return s * std::min(kCoarseRatio, 1.0 + d / kGradingLength);
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// k x k points, (i, j) -> i + k j, each cell split along alternating diagonals.
Mesh_arrays structured_grid(Index k) {
  Mesh_arrays mesh;
  mesh.points.reserve(static_cast<std::size_t>(k * k));
  for (Index j = 0; j < k; ++j) {
    for (Index i = 0; i < k; ++i) {
      mesh.points.push_back({static_cast<double>(i) / static_cast<double>(k - 1),
                             static_cast<double>(j) / static_cast<double>(k - 1)});
    }
  }
  mesh.triangles.reserve(static_cast<std::size_t>(2 * (k - 1) * (k - 1)));
  for (Index j = 0; j + 1 < k; ++j) {
    for (Index i = 0; i + 1 < k; ++i) {
      const Index a = i + k * j, b = a + 1, c = a + k, d = c + 1;
      if ((i + j) % 2 == 0) {
        mesh.triangles.push_back({a, b, d});
        mesh.triangles.push_back({a, d, c});
      } else {
        mesh.triangles.push_back({a, b, c});
        mesh.triangles.push_back({b, d, c});
      }
    }
  }
  orient_triangles(mesh.points, mesh.triangles);
  build_segments(mesh, {});
  mesh.kind = classify_points(mesh);
  return mesh;
}

Frfc_options bench_options(int threads, double max_samples) {
  Frfc_options options;  // python/evomesh/evolve.py FRFC_DEFAULTS
  options.cell_factor = 1.0;
  options.exact_radius = true;
  options.radius_scale = 0.75;
  options.sample_mode = Sample_mode::random_grid;
  options.seed = 0;
  options.threads = threads;
  options.max_samples = max_samples;
  return options;
}

struct Graded_case {
  Mesh_arrays mesh;
  std::vector<double> delta;  // of the timed step
  Index grid_side = 0;
  double spacing_scale = 0;
  double setup_seconds = 0;
};

// The graded mesh of about `target` points and the delta of the timed step.
Graded_case graded_case(double target, int threads, double max_samples) {
  Graded_case out;
  const auto t0 = std::chrono::steady_clock::now();
  const double s = std::sqrt(kPointsPerInverseSquareSpacing / target);
  // Grid spacing 2 s: the setup step refines the band by 2 and coarsens by up to 4.
  const Index k = static_cast<Index>(std::ceil(1.0 / (2.0 * s))) + 1;
  Mesh_arrays grid = structured_grid(k);
  const double grid_spacing = 1.0 / static_cast<double>(k - 1);
  std::vector<double> setup_delta(grid.points.size());
  for (std::size_t i = 0; i < grid.points.size(); ++i) {
    setup_delta[i] = target_spacing(grid.points[i][0], kBandCenter, s) / grid_spacing;
  }
  Evolve_result setup = frfc(grid, setup_delta, bench_options(threads, max_samples));
  out.mesh = std::move(setup.mesh);
  out.delta.resize(out.mesh.points.size());
  for (std::size_t i = 0; i < out.mesh.points.size(); ++i) {
    const double x = out.mesh.points[i][0];
    const double ratio = target_spacing(x, kBandCenter + kBandShift, s) / target_spacing(x, kBandCenter, s);
    out.delta[i] = std::clamp(ratio, 0.5, 2.0);
  }
  out.grid_side = k;
  out.spacing_scale = s;
  out.setup_seconds = seconds_since(t0);
  return out;
}

// Memory from /proc/self/status, in MiB (-1 when unavailable).
double status_mib(const std::string& key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.compare(0, key.size() + 1, key + ":") == 0) {
      std::istringstream fields(line.substr(key.size() + 1));
      double kib = -1;
      fields >> kib;
      return kib / 1024.0;
    }
  }
  return -1;
}

// Returns freed heap to the system and resets VmHWM (Linux >= 4.0), so the next
// peak reading covers only what runs after this call.
bool reset_peak_memory() {
  malloc_trim(0);
  std::ofstream out("/proc/self/clear_refs");
  out << "5";
  out.close();
  return static_cast<bool>(out);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

std::vector<double> parse_sizes(const std::string& text) {
  std::vector<double> sizes;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) sizes.push_back(std::stod(item));
  return sizes;
}

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  }
  return "unknown";
}

const char* const kStages[] = {"nn", "apollonius", "spacing_at_points", "sampling", "sample_radii", "lfmis", "cdt",
                               "total"};

}  // namespace

int main(int argc, char** argv) {
  std::vector<double> sizes{1e4, 1e5, 1e6};
  int repeats = 3, threads = 0;
  bool baseline = true;
  double max_samples = 5e7;
  std::string json_path;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    auto value = [&]() -> std::string {
      if (a + 1 >= argc) throw std::invalid_argument(arg + " needs a value");
      return argv[++a];
    };
    if (arg == "--sizes") sizes = parse_sizes(value());
    else if (arg == "--repeats") repeats = std::stoi(value());
    else if (arg == "--threads") threads = std::stoi(value());
    else if (arg == "--no-baseline") baseline = false;
    else if (arg == "--max-samples") max_samples = std::stod(value());
    else if (arg == "--json") json_path = value();
    else {
      std::fprintf(stderr,
                   "usage: bench_evolve [--sizes 1e4,1e5,1e6] [--repeats 3] [--threads 0] [--no-baseline]"
                   " [--max-samples 5e7] [--json FILE]\n");
      return arg == "--help" || arg == "-h" ? 0 : 2;
    }
  }
  std::printf("# bench_evolve: CGAL %s, %u hardware threads, threads=%d, %s, repeats=%d\n", CGAL_VERSION_STR,
              std::thread::hardware_concurrency(), threads, cpu_model().c_str(), repeats);
  std::printf("| target | input pts | output pts | samples/input pt | nn | apollonius | f at points | sampling"
              " | sample radii | lfmis | cdt | total (s) | CDT of output (s) | total / CDT | step peak (MiB)"
              " | input RSS (MiB) |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  std::fflush(stdout);
  std::ostringstream json;
  json << "[";
  for (std::size_t si = 0; si < sizes.size(); ++si) {
    const double target = sizes[si];
    Graded_case c = graded_case(target, threads, max_samples);
    const Frfc_options options = bench_options(threads, max_samples);
    std::map<std::string, std::vector<double>> stage_seconds;
    std::map<std::string, double> counts;
    std::vector<double> cdt_seconds;
    double peak_mib = -1, input_mib = -1;
    for (int r = 0; r < repeats; ++r) {
      const bool tracked = reset_peak_memory();
      if (r == 0) input_mib = status_mib("VmRSS");
      Evolve_result result = frfc(c.mesh, c.delta, options);
      if (r == 0 && tracked) peak_mib = status_mib("VmHWM");
      for (const auto& [name, value] : result.stats) {
        if (name.rfind("seconds_", 0) == 0) stage_seconds[name.substr(8)].push_back(value);
        else counts[name] = value;
      }
      if (baseline) {
        // The plain CGAL constrained Delaunay of the output points and segments.
        std::vector<Constraint_piece> pieces;
        pieces.reserve(result.mesh.segments.size());
        for (std::size_t k = 0; k < result.mesh.segments.size(); ++k) {
          pieces.push_back({result.mesh.segments[k][0], result.mesh.segments[k][1],
                            result.mesh.segment_is_boundary[k] != 0});
        }
        const auto t0 = std::chrono::steady_clock::now();
        const auto triangles = constrained_delaunay(result.mesh.points, pieces);
        cdt_seconds.push_back(seconds_since(t0));
        if (triangles.size() != result.mesh.triangles.size()) {
          std::fprintf(stderr, "baseline CDT has %zu triangles, FRFC output %zu\n", triangles.size(),
                       result.mesh.triangles.size());
          return 1;
        }
      }
    }
    if (peak_mib < 0) peak_mib = static_cast<double>([] {
      rusage usage{};
      getrusage(RUSAGE_SELF, &usage);
      return usage.ru_maxrss;
    }()) / 1024.0;
    const double n_in = counts["n_input_points"];
    const double samples = counts["n_interior_samples"] + counts["n_segment_samples"];
    const double total = median(stage_seconds["total"]);
    const double cdt = baseline ? median(cdt_seconds) : NAN;
    std::printf("| %.0e | %.0f | %.0f | %.2f |", target, n_in, counts["n_output_points"], samples / n_in);
    for (const char* stage : kStages) std::printf(" %.3f |", median(stage_seconds[stage]));
    std::printf(" %.3f | %.1f | %.0f | %.0f |\n", cdt, total / cdt, peak_mib, input_mib);
    std::fflush(stdout);
    json << (si ? "," : "") << "\n  {\"target\": " << target << ", \"grid_side\": " << c.grid_side
         << ", \"spacing_scale\": " << c.spacing_scale << ", \"setup_seconds\": " << c.setup_seconds
         << ", \"repeats\": " << repeats << ", \"threads\": " << threads;
    for (const auto& [name, values] : stage_seconds) json << ", \"seconds_" << name << "\": " << median(values);
    for (const auto& [name, value] : counts) json << ", \"" << name << "\": " << value;
    if (baseline) json << ", \"seconds_cdt_baseline\": " << cdt;
    json << ", \"peak_step_mib\": " << peak_mib << ", \"input_rss_mib\": " << input_mib << "}";
  }
  json << "\n]\n";
  if (!json_path.empty()) std::ofstream(json_path) << json.str();
  return 0;
}
