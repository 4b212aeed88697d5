// Times one FRFC step (Section 3.2) on graded meshes of about 1e4, 1e5, 1e6 points
// and larger ones: per stage, peak memory, and the ratio to a plain CGAL
// constrained Delaunay of the output points, measured in the same run.
//
// The graded mesh (not timed): a k x k triangulated grid on the unit square, then one
// FRFC step towards the spacing h_old of a vertical band of fine spacing (see
// `target_spacing`). The timed step moves the band to the right by kBandShift:
// delta(p) = clamp(h_new(p) / h_old(p), 0.5, 2), a moving front that refines ahead
// of the band, coarsens behind it and leaves the rest (delta = 1) alone.
//
//   bench_evolve [--sizes 1e4,1e5,1e6] [--repeats 3] [--threads 0] [--no-baseline] [--quality]
//                [--max-samples 5e7] [--json FILE] [--cache-dir DIR]
#include <malloc.h>
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
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
constexpr double kPointsPerInverseSquareSpacing = 0.0634;

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

Frfc_options bench_options(int threads, double max_samples, bool quality = false) {
  Frfc_options options = Frfc_options::recommended();  // evolve's defaults, quality pass off unless asked
  options.threads = threads;
  options.max_samples = max_samples;
  options.quality = quality;
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
  // Grid spacing 4 s: the setup step refines the band by 4 and coarsens by up to 2.
  const Index k = static_cast<Index>(std::ceil(1.0 / (4.0 * s))) + 1;
  Mesh_arrays grid = structured_grid(k);
  const double grid_spacing = 1.0 / static_cast<double>(k - 1);
  std::vector<double> setup_delta(grid.points.size());
  for (std::size_t i = 0; i < grid.points.size(); ++i) {
    setup_delta[i] = target_spacing(grid.points[i][0], kBandCenter, s) / grid_spacing;
  }
  // The setup step samples densely in the band: it is not limited by --max-samples.
  // The graded input is fixed: the paper's packing (exact radii, old points first).
  Frfc_options setup_options = bench_options(threads, std::max(max_samples, 1e10));
  setup_options.radius = Radius_rule::exact;
  setup_options.demote_ratio = 0;
  setup_options.gap_repair_ratio = 0;
  setup_options.refine_gap_ratio = 0;
  Evolve_result setup = frfc(grid, setup_delta, setup_options);
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

// Graded meshes are cached as raw arrays so repeated runs (and profiles) skip the setup.
template <class T>
void write_vector(std::ofstream& out, const std::vector<T>& v) {
  const std::uint64_t n = v.size();
  out.write(reinterpret_cast<const char*>(&n), sizeof n);
  out.write(reinterpret_cast<const char*>(v.data()), static_cast<std::streamsize>(n * sizeof(T)));
}

template <class T>
void read_vector(std::ifstream& in, std::vector<T>& v) {
  std::uint64_t n = 0;
  in.read(reinterpret_cast<char*>(&n), sizeof n);
  v.resize(n);
  in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(n * sizeof(T)));
}

constexpr std::uint64_t kCacheVersion = 1;

void save_case(const std::string& path, const Graded_case& c) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(&kCacheVersion), sizeof kCacheVersion);
  write_vector(out, c.mesh.points);
  write_vector(out, c.mesh.triangles);
  write_vector(out, c.mesh.segments);
  write_vector(out, c.mesh.segment_is_boundary);
  write_vector(out, c.mesh.kind);
  write_vector(out, c.delta);
  const std::vector<double> meta{static_cast<double>(c.grid_side), c.spacing_scale, c.setup_seconds};
  write_vector(out, meta);
}

bool load_case(const std::string& path, Graded_case& c) {
  std::ifstream in(path, std::ios::binary);
  std::uint64_t version = 0;
  if (!in.read(reinterpret_cast<char*>(&version), sizeof version) || version != kCacheVersion) return false;
  read_vector(in, c.mesh.points);
  read_vector(in, c.mesh.triangles);
  read_vector(in, c.mesh.segments);
  read_vector(in, c.mesh.segment_is_boundary);
  read_vector(in, c.mesh.kind);
  read_vector(in, c.delta);
  std::vector<double> meta;
  read_vector(in, meta);
  if (!in || meta.size() != 3) return false;
  c.grid_side = static_cast<Index>(meta[0]);
  c.spacing_scale = meta[1];
  c.setup_seconds = meta[2];
  return true;
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

// FNV-1a over the output points and triangles: equal hashes, identical meshes.
std::uint64_t mesh_hash(const Mesh_arrays& mesh) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  auto add = [&h](const void* data, std::size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t k = 0; k < bytes; ++k) h = (h ^ p[k]) * 0x100000001b3ULL;
  };
  add(mesh.points.data(), mesh.points.size() * sizeof(Vec2));
  add(mesh.triangles.data(), mesh.triangles.size() * sizeof(Triangle));
  return h;
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

// User + system CPU seconds of the process so far (all threads).
double cpu_seconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
}

double rusage_max_mib() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<double> sizes{1e4, 1e5, 1e6};
  int repeats = 3, threads = 0;
  bool baseline = true, quality = false;
  double max_samples = 5e7;
  std::string json_path, cache_dir;
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
    else if (arg == "--quality") quality = true;
    else if (arg == "--max-samples") max_samples = std::stod(value());
    else if (arg == "--json") json_path = value();
    else if (arg == "--cache-dir") cache_dir = value();
    else {
      std::fprintf(stderr,
                   "usage: bench_evolve [--sizes 1e4,1e5,1e6] [--repeats 3] [--threads 0] [--no-baseline] [--quality]"
                   " [--max-samples 5e7] [--json FILE] [--cache-dir DIR]\n");
      return arg == "--help" || arg == "-h" ? 0 : 2;
    }
  }
  std::printf("# bench_evolve: CGAL %s, %u hardware threads, threads=%d, %s, quality pass %s, repeats=%d (medians)\n",
              CGAL_VERSION_STR, std::thread::hardware_concurrency(), threads, cpu_model().c_str(), quality ? "on" : "off",
              repeats);
  std::fflush(stdout);
  std::ostringstream json;
  json << "[";
  std::vector<std::string> stages;  // in the order frfc reports them
  for (std::size_t si = 0; si < sizes.size(); ++si) {
    const double target = sizes[si];
    Graded_case c;
    const std::string cache =
        cache_dir.empty() ? "" : cache_dir + "/graded_" + std::to_string(static_cast<long long>(target)) + ".bin";
    if (cache.empty() || !load_case(cache, c)) {
      c = graded_case(target, threads, max_samples);
      if (!cache.empty()) save_case(cache, c);
    }
    const Frfc_options options = bench_options(threads, max_samples, quality);
    std::map<std::string, std::vector<double>> stage_seconds;
    std::map<std::string, double> counts;
    std::vector<double> cdt_seconds, step_cpu_seconds;
    double peak_mib = -1, input_mib = -1;
    std::uint64_t output_hash = 0;
    for (int r = 0; r < repeats; ++r) {
      const bool tracked = reset_peak_memory();
      if (r == 0) input_mib = status_mib("VmRSS");
      const double cpu0 = cpu_seconds();
      Evolve_result result = frfc(c.mesh, c.delta, options);
      step_cpu_seconds.push_back(cpu_seconds() - cpu0);
      if (r == 0) peak_mib = tracked ? status_mib("VmHWM") : rusage_max_mib();
      const std::uint64_t hash = mesh_hash(result.mesh);
      if (r > 0 && hash != output_hash) throw std::runtime_error("FRFC is not deterministic: outputs differ");
      output_hash = hash;
      for (const auto& [name, value] : result.stats) {
        if (name.rfind("seconds_", 0) == 0) {
          const std::string stage = name.substr(8);
          stage_seconds[stage].push_back(value);
          if (std::find(stages.begin(), stages.end(), stage) == stages.end()) stages.push_back(stage);
        } else {
          counts[name] = value;
        }
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
        if (triangles.empty()) throw std::runtime_error("the baseline CDT is empty");
      }
    }
    const double n_in = counts["n_input_points"];
    // samples drawn (interior and on segments), and the spheres left for the MIS
    const double samples = counts["n_interior_samples_drawn"] + counts["n_segment_samples"];
    const double total = median(stage_seconds["total"]);
    const double cdt = baseline ? median(cdt_seconds) : NAN;
    if (si == 0) {
      std::printf("\n| target | input pts | output pts | samples drawn / input pt | MIS spheres / input pt |");
      for (const auto& stage : stages) std::printf(" %s |", stage.c_str());
      std::printf(" CPU s (all threads) | CDT of output | total / CDT | step peak (MiB) | input RSS (MiB) |\n|");
      for (std::size_t k = 0; k < stages.size() + 10; ++k) std::printf("---|");
      std::printf("\n");
    }
    std::printf("| %.0e | %.0f | %.0f | %.1f | %.2f |", target, n_in, counts["n_output_points"], samples / n_in,
                counts["n_candidates"] / n_in);
    for (const auto& stage : stages) std::printf(" %.3f |", median(stage_seconds[stage]));
    std::printf(" %.2f | %.3f | %.0f | %.0f | %.0f |\n", median(step_cpu_seconds), cdt, total / cdt, peak_mib, input_mib);
    std::fflush(stdout);
    json << (si ? "," : "") << "\n  {\"target\": " << target << ", \"grid_side\": " << c.grid_side
         << ", \"spacing_scale\": " << c.spacing_scale << ", \"setup_seconds\": " << c.setup_seconds
         << ", \"repeats\": " << repeats << ", \"threads\": " << threads;
    for (const auto& [name, values] : stage_seconds) json << ", \"seconds_" << name << "\": " << median(values);
    for (const auto& [name, value] : counts) json << ", \"" << name << "\": " << value;
    if (baseline) json << ", \"seconds_cdt_baseline\": " << cdt;
    json << ", \"cpu_seconds_step\": " << median(step_cpu_seconds);
    json << ", \"quality\": " << (quality ? "true" : "false") << ", \"peak_step_mib\": " << peak_mib << ", \"input_rss_mib\": " << input_mib
         << ", \"process_peak_mib\": " << rusage_max_mib() << ", \"output_hash\": \"" << std::hex << output_hash
         << std::dec << "\"}";
  }
  json << "\n]\n";
  if (!json_path.empty()) std::ofstream(json_path) << json.str();
  return 0;
}
