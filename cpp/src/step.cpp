#include "evomesh/step.hpp"

#include "evomesh/local_feature_size.hpp"

#include <CGAL/exceptions.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <ctime>
#include <fstream>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <unordered_map>
#include <stdexcept>

#if defined(__GLIBC__)
#include <malloc.h>
#endif
#if defined(__unix__)
#include <sys/resource.h>
#endif

namespace evomesh {

namespace detail {

void release_free_memory() {
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
}

double Stage_timer::process_cpu_seconds() {
  timespec t{};
  if (clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t) != 0) return 0.0;
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

void Stage_timer::record_memory(const std::string& name) {
  const double cpu = process_cpu_seconds();
  add("cpu_seconds_" + name, cpu - last_cpu_, false);
  const Kernel_usage usage = kernel_usage();
  add("page_faults_" + name, usage.page_faults - last_usage_.page_faults, false);
  add("system_seconds_" + name, usage.system_seconds - last_usage_.system_seconds, false);
  double peak_kib = -1;
  {
    std::ifstream status("/proc/self/status");
    std::string line;
    while (std::getline(status, line)) {
      if (line.rfind("VmHWM:", 0) == 0) peak_kib = std::stod(line.substr(6));
    }
  }
  if (peak_kib >= 0) add("memory_peak_mib_" + name, peak_kib / 1024, true);
  std::ofstream("/proc/self/clear_refs") << "5";
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 33))
  const struct mallinfo2 heap = mallinfo2();
  add("memory_heap_mib_" + name, static_cast<double>(heap.uordblks + heap.hblkhd) / (1 << 20), true);
#endif
  last_ = std::chrono::steady_clock::now();  // the reading is not the stage's time
  last_cpu_ = process_cpu_seconds();
  last_usage_ = kernel_usage();
}

Stage_timer::Kernel_usage Stage_timer::kernel_usage() {
  Kernel_usage usage;
#if defined(__unix__)
  rusage r{};
  if (getrusage(RUSAGE_SELF, &r) == 0) {
    usage.page_faults = static_cast<double>(r.ru_minflt + r.ru_majflt);
    usage.system_seconds = static_cast<double>(r.ru_stime.tv_sec) + 1e-6 * static_cast<double>(r.ru_stime.tv_usec);
  }
#endif
  return usage;
}

}  // namespace detail

void check_delta(const Mesh_arrays& mesh, const std::vector<double>& delta) {
  if (delta.size() != mesh.points.size()) throw Input_error("delta must have one value per mesh point");
  for (double d : delta) {
    if (!std::isfinite(d) || !(d > 0)) throw Input_error("delta must be finite and > 0");
  }
}

Step_weights step_weights(const Mesh_arrays& mesh, const std::vector<double>& delta, detail::Stage_timer& timer,
                          const std::vector<Segment_chain>* within_domain) {
  const std::size_t n = mesh.points.size();
  Step_weights out;
  // Within the domain (local_feature_size.hpp): nn of points whose nearest point
  // hides behind a constraint is taken within the domain, and the weights are
  // capped by what the domain carries. Lemma 3.1 needs w_p <= nn(p) <= |p - q|,
  // so f is evaluated at the points whose nn grew. The input may bring both.
  if (within_domain && !mesh.nn_within_domain.empty()) {
    out.nn = mesh.nn_within_domain;
    out.evaluate.assign(n, 0);
    for (Index i : mesh.nn_grew) out.evaluate[i] = 1;
  } else {
    out.nn = nn_spacing(mesh.points);
    if (within_domain) out.evaluate = keep_within_domain(mesh.points, mesh.triangles, out.nn);
  }
  std::vector<double>& weight = out.weight;
  weight.resize(n);
  for (std::size_t i = 0; i < n; ++i) weight[i] = delta[i] * out.nn[i];
  if (within_domain) {
    const auto lfs = local_feature_size(mesh, *within_domain, weight);
    for (std::size_t i = 0; i < n; ++i) weight[i] = std::min(weight[i], lfs[i]);
  }
  timer.lap("nn");
  return out;
}

Step_spacing step_spacing(const Mesh_arrays& mesh, const std::vector<double>& delta, F_at_points how, int threads,
                          detail::Stage_timer& timer, const std::vector<Segment_chain>* within_domain,
                          bool filter_sites) {
  const std::size_t n = mesh.points.size();
  Step_spacing spacing;
  Step_weights weights = step_weights(mesh, delta, timer, within_domain);
  spacing.nn = std::move(weights.nn);
  const std::vector<std::uint8_t>& evaluate = weights.evaluate;
  const std::vector<double>& weight = weights.weight;
  // Sites hidden by a mesh neighbour are left out of the Apollonius graph
  // (f is the same). Step_context::filter_sites = false keeps them, for benchmarks only.
  spacing.function =
      std::make_unique<Spacing_function>(mesh.points, weight, 0, filter_sites ? &mesh.triangles : nullptr,
                                         &mesh.point_gids);
  timer.lap("apollonius");
  auto& f = spacing.f;
  f.resize(n);
  if (how == F_at_points::evaluate_all) {
    spacing.function->evaluate(mesh.points.data(), n, f.data(), nullptr, threads);
    for (std::size_t i = 0; i < n; ++i) f[i] = std::min(f[i], weight[i]);
  } else {
    // Lemma 3.1: f(p) = delta(p) nn_M(p) = w_p exactly where delta(p) <= 1; the
    // Apollonius graph answers the others (f_p(p) = w_p is one of the cones, so
    // f(p) <= w_p there too).
    std::vector<Vec2> coarse;
    std::vector<std::size_t> which;
    for (std::size_t i = 0; i < n; ++i) {
      f[i] = weight[i];
      if (delta[i] > 1 || (!evaluate.empty() && evaluate[i])) {
        coarse.push_back(mesh.points[i]);
        which.push_back(i);
      }
    }
    std::vector<double> value(coarse.size());
    spacing.function->evaluate(coarse.data(), coarse.size(), value.data(), nullptr, threads);
    for (std::size_t k = 0; k < which.size(); ++k) f[which[k]] = std::min(value[k], weight[which[k]]);
  }
  timer.lap("spacing_at_points");
  return spacing;
}

void check_sample_budget(double estimate, double max_samples, const char* what) {
  if (estimate > max_samples) {
    throw Input_error("delta asks for too much refinement in one step: " + std::string(what) +
                      " would create about " + format_count(estimate) + " points (max_samples is " +
                      format_count(max_samples) +
                      "); delta is relative (the new spacing is delta times the current one): raise it, refine over "
                      "several steps, or raise max_samples");
  }
}

Spacing_queries spacing_queries(const Spacing_function& function) {
  return [&function](const std::vector<Vec2>& at, std::vector<double>& f) {
    f.resize(at.size());
    function.evaluate(at.data(), at.size(), f.data(), nullptr, 1, /*certified=*/true);
  };
}

void triangulate_selection(Selection selected, const std::vector<Constraint_piece>& pieces,
                           const Quality_options* quality, Evolve_result& result, Early_triangulation* early,
                           const Boundary_geometry* geometry, std::vector<Triangle>* triangles) {
  auto& stats = result.stats;
  Mesh_arrays& mesh = selected.mesh;
  // CGAL's triangulations assume these (a piece from a point to itself, or out
  // of range, is undefined behaviour there): an internal error, never a crash.
  for (const auto& piece : pieces) {
    if (piece.a == piece.b || piece.a < 0 || piece.b < 0 || static_cast<std::size_t>(piece.a) >= mesh.points.size() ||
        static_cast<std::size_t>(piece.b) >= mesh.points.size()) {
      throw std::logic_error("triangulate_selection: a degenerate constraint piece");
    }
  }
  std::vector<Index> selection_index;  // of every output point, -1: inserted by the quality pass
  const Quality_options* const quality_given = quality;  // (a failed pass falls back to the plain CDT)
  if (quality != nullptr) {
    // CGAL's mesher checks its own invariants (these files are built with CGAL's
    // assertions on, see CMakeLists.txt); on near-degenerate input it can fail
    // them. The quality pass is an improvement, not a requirement: then the step
    // keeps the plain constrained Delaunay triangulation of the selected points
    // and says so (stats "quality_failed", a warning in Python), never a crash.
    try {
      Refined_mesh refined = early ? early->finish(mesh.points, mesh.kind, pieces, *quality, mesh.required)
                                   : quality_triangulate(mesh.points, mesh.kind, pieces, *quality, mesh.required);
      result.origin.resize(refined.source.size());
      for (std::size_t i = 0; i < refined.source.size(); ++i) {
        result.origin[i] = refined.source[i] < 0 ? -1 : selected.origin[refined.source[i]];
      }
      result.mesh = std::move(refined.mesh);
      if (geometry) selection_index = std::move(refined.source);
      const auto& report = refined.report;
      stats.emplace_back("quality_points_added", static_cast<double>(report.n_inserted));
      stats.emplace_back("quality_points_added_on_segments", static_cast<double>(report.n_inserted_on_segments));
      stats.emplace_back("quality_points_removed", static_cast<double>(report.n_removed));
      stats.emplace_back("quality_crowded_segments", static_cast<double>(report.n_crowded_segments));
      stats.emplace_back("quality_capped", report.capped ? 1.0 : 0.0);
      stats.emplace_back("quality_points_outside", static_cast<double>(report.n_inserted_outside));
      stats.emplace_back("quality_insert_seconds", report.insert_seconds);
      if (quality->quality_rounds) {
        stats.emplace_back("quality_rounds", static_cast<double>(report.rounds));
        stats.emplace_back("quality_stalled", report.stalled ? 1.0 : 0.0);
        stats.emplace_back("quality_round_limit", report.round_limit ? 1.0 : 0.0);
      }
    } catch (const CGAL::Failure_exception&) {
      stats.emplace_back("quality_failed", 1.0);
      quality = nullptr;
    }
  }
  if (quality == nullptr) {
    mesh.triangles = triangles != nullptr && quality_given == nullptr ? std::move(*triangles)
                                                                      : constrained_delaunay(mesh.points, pieces);
    for (const auto& piece : pieces) {
      mesh.segments.push_back({piece.a, piece.b});
      mesh.segment_is_boundary.push_back(piece.boundary);
    }
    result.mesh = std::move(mesh);
    result.origin = std::move(selected.origin);
    if (geometry) {
      selection_index.resize(result.mesh.points.size());
      for (std::size_t i = 0; i < selection_index.size(); ++i) selection_index[i] = static_cast<Index>(i);
    }
  }
  if (geometry) {
    result.curve_reach = fit_to_curves(*geometry, pieces, selection_index, result, quality);
  }
  // The smallest angle and where it is (Section 6 reports it per step).
  const auto angle = smallest_angle(result.mesh.points, result.mesh.triangles);
  stats.emplace_back("min_angle", angle.first);
  stats.emplace_back("min_angle_x", angle.second[0]);
  stats.emplace_back("min_angle_y", angle.second[1]);
}

std::vector<Index> segment_pieces(const Mesh_arrays& mesh, const std::vector<Constraint_piece>& pieces,
                                  const std::vector<Index>& selection_index) {
  const std::size_t n = mesh.points.size();
  if (selection_index.size() != n) throw std::logic_error("segment_pieces: one selection index per point");
  std::unordered_map<std::uint64_t, Index> piece_of;
  auto key = [](Index a, Index b) {
    return (static_cast<std::uint64_t>(std::min(a, b)) << 32) ^ static_cast<std::uint64_t>(std::max(a, b));
  };
  for (std::size_t k = 0; k < pieces.size(); ++k) piece_of.emplace(key(pieces[k].a, pieces[k].b), static_cast<Index>(k));
  const Segments_at_points at(mesh);
  std::vector<Index> piece(mesh.segments.size(), -1);
  std::vector<Index> walked;
  for (std::size_t v = 0; v < n; ++v) {
    if (selection_index[v] < 0) continue;
    for (Index a = at.xadj[v]; a < at.xadj[v + 1]; ++a) {
      // Along the piece from v, through inserted points, to the next selected point.
      const Index w = at.walk(mesh, selection_index, static_cast<Index>(v), at.adj[a], walked);
      if (selection_index[w] < selection_index[v]) continue;  // (walked from the other end)
      const auto found = piece_of.find(key(selection_index[v], selection_index[w]));
      if (found == piece_of.end()) throw std::logic_error("segment_pieces: a segment on no constraint piece");
      for (Index t : walked) piece[t] = found->second;
    }
  }
  for (Index p : piece) {
    if (p < 0) throw std::logic_error("segment_pieces: a segment between inserted points only");
  }
  return piece;
}

namespace {

// An output point at exactly the coordinates of an input point that the
// selection dropped is that point: the quality pass splits a
// segment at its midpoint or a triangle at its circumcentre, which is often
// where the previous step's pass had put the point the packing just dropped (a
// coarsening that the segments' Gabriel condition or the angle bound undoes).
// It gets that input point's origin, and the kind of a kept point (on a
// segment or not as before: else it stays new), so the lineage says the point
// stayed: a transfer copies its value, the output's nn comes from the input's.
// Returns how many were restored.
std::size_t restore_origins(const Mesh_arrays& input, Evolve_result& result) {
  std::vector<std::uint8_t> referenced(input.points.size(), 0);
  std::size_t n_new = 0;
  for (Index o : result.origin) {
    if (o >= 0) referenced[o] = 1;
    else ++n_new;
  }
  if (n_new == 0) return 0;
  std::vector<Index> dropped;  // sorted by coordinates
  for (std::size_t o = 0; o < input.points.size(); ++o) {
    if (!referenced[o]) dropped.push_back(static_cast<Index>(o));
  }
  if (dropped.empty()) return 0;
  auto less = [&](Index a, Index b) { return input.points[a] < input.points[b]; };
  std::sort(dropped.begin(), dropped.end(), less);
  auto on_segment = [](Point_kind k) { return k == Point_kind::corner || k == Point_kind::boundary; };
  std::size_t n_restored = 0;
  for (std::size_t i = 0; i < result.origin.size(); ++i) {
    if (result.origin[i] >= 0) continue;
    const Vec2& p = result.mesh.points[i];
    const auto it = std::lower_bound(dropped.begin(), dropped.end(), p,
                                     [&](Index a, const Vec2& x) { return input.points[a] < x; });
    if (it == dropped.end() || input.points[*it] != p) continue;  // (input points are distinct)
    const Point_kind was = input.kind[*it];
    if (on_segment(was) != on_segment(result.mesh.kind[i])) continue;
    result.origin[i] = *it;
    result.mesh.kind[i] = kept_point_kind(was, false);
    ++n_restored;
  }
  return n_restored;
}

// A step that kept every input point and added none, in input order, and
// whose triangles and segments are the input's (as sets: the constrained
// Delaunay triangulation of the same points and segments, and nothing for the
// quality pass to do), returns the input's arrays, in their order: a mesh that
// stays put keeps the indices of its triangles and segments (per-cell data and
// tags stay aligned), whichever path built it. Sorting O(m log m), and only
// when the points did not change.
bool adopt_input_order(const Mesh_arrays& input, Evolve_result& result) {
  Mesh_arrays& out = result.mesh;
  if (out.points.size() != input.points.size() || out.triangles.size() != input.triangles.size() ||
      out.segments.size() != input.segments.size() ||
      out.segment_is_boundary.size() != input.segment_is_boundary.size()) {
    return false;
  }
  for (std::size_t i = 0; i < result.origin.size(); ++i) {
    if (result.origin[i] != static_cast<Index>(i)) return false;
  }
  auto same_set = [](auto a, auto b) {
    std::sort(a.begin(), a.end());
    std::sort(b.begin(), b.end());
    return a == b;
  };
  std::vector<Triangle> a(input.triangles.size()), b(out.triangles.size());
  for (std::size_t t = 0; t < a.size(); ++t) a[t] = least_index_first(input.triangles[t]);
  for (std::size_t t = 0; t < b.size(); ++t) b[t] = least_index_first(out.triangles[t]);
  if (!same_set(std::move(a), std::move(b))) return false;
  std::vector<std::array<Index, 3>> sa(input.segments.size()), sb(out.segments.size());
  for (std::size_t s = 0; s < sa.size(); ++s) {
    const Edge& e = input.segments[s];
    sa[s] = {std::min(e[0], e[1]), std::max(e[0], e[1]), input.segment_is_boundary[s]};
  }
  for (std::size_t s = 0; s < sb.size(); ++s) {
    const Edge& e = out.segments[s];
    sb[s] = {std::min(e[0], e[1]), std::max(e[0], e[1]), out.segment_is_boundary[s]};
  }
  if (!same_set(std::move(sa), std::move(sb))) return false;
  out.triangles = input.triangles;
  out.segments = input.segments;
  out.segment_is_boundary = input.segment_is_boundary;
  return true;
}

}  // namespace

void finish_step(const Mesh_arrays& input, Evolve_result& result, detail::Stage_timer& timer, Old_mesh_start* start,
                 const std::vector<double>* input_nn, const std::vector<std::uint8_t>* same_fans) {
  result.stats.emplace_back("restored_points", static_cast<double>(restore_origins(input, result)));
  const bool unchanged = adopt_input_order(input, result);
  if (!unchanged) canonical_triangle_order(result.mesh.points.size(), result.mesh.triangles);
  result.unchanged = unchanged;
  result.stats.emplace_back("unchanged", unchanged ? 1.0 : 0.0);
  std::unique_ptr<Old_mesh_walker> walker;
  if (start != nullptr) {
    start->work.wait();
    walker = std::move(start->walker);
    walker->set_outside(result.curve_reach);
  } else {
    walker = std::make_unique<Old_mesh_walker>(input, result.curve_reach);
  }
  const Old_mesh_walker& old_mesh = *walker;  // for both
  // The output's nn (for the output Mesh) on another thread, beside the walks
  // (both on parallel_for's threads). Both only read the output's points and triangles.
  Background output_nn;
  double nn_seconds = 0;
  output_nn.start(
      [&result, &nn_seconds, &input, input_nn, same_fans]() {
        const auto begin = std::chrono::steady_clock::now();
        try {
          std::vector<double> nn = input_nn ? nn_spacing_after_change(input.points, *input_nn, result.mesh.points,
                                                                      result.mesh.triangles, result.origin)
                                            : nn_spacing(result.mesh.points);
          std::vector<double> within = nn;
          // Known: a kept point with the input's fan and the input's nn, which did
          // not grow within the domain there (input_nn is NaN where it grew).
          std::vector<std::uint8_t> known;
          if (input_nn != nullptr && same_fans != nullptr && same_fans->size() == nn.size()) {
            known.assign(nn.size(), 0);
            for (std::size_t i = 0; i < nn.size(); ++i) {
              const Index o = result.origin[i];
              known[i] = (*same_fans)[i] && o >= 0 && nn[i] == (*input_nn)[static_cast<std::size_t>(o)];
            }
          }
          const auto grew = keep_within_domain(result.mesh.points, result.mesh.triangles, within,
                                               known.empty() ? nullptr : &known);
          for (std::size_t i = 0; i < grew.size(); ++i) {
            if (!grew[i]) continue;
            result.output_nn_grew.push_back(static_cast<Index>(i));
            result.output_nn_grown.push_back(within[i]);
          }
          result.output_nn = std::move(nn);
        } catch (const std::exception&) {  // (duplicates: the caller's check says so)
          result.output_nn.clear();
          result.output_nn_grew.clear();
          result.output_nn_grown.clear();
        }
        nn_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
      },
      resolve_threads(0) > 1);
  const auto walks_begin = std::chrono::steady_clock::now();
  result.parents = parent_map(old_mesh, result.mesh, result.origin);
  if (unchanged) {  // the input's triangles and segments, in their order: their tags
    result.mesh.segment_tags = input.segment_tags;
    result.mesh.triangle_tags = input.triangle_tags;
    result.mesh.required = input.required;
  } else {
    carry_tags(old_mesh, result.origin, result.parents, result.mesh);
  }
  const double walk_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - walks_begin).count();
  output_nn.wait();
  timer.lap("parent_map");
  // Inside the parent_map stage: the walks (and tags) and, beside them, the output's nn.
  result.stats.emplace_back("parent_map_walk_seconds", walk_seconds);
  result.stats.emplace_back("parent_map_output_nn_seconds", nn_seconds);
  auto& stats = result.stats;
  double seconds = 0;
  for (const auto& s : stats) {
    if (s.first.rfind("seconds_", 0) == 0) seconds += s.second;
  }
  stats.emplace_back("seconds_total", seconds);
  stats.emplace_back("parent_walk_steps", static_cast<double>(result.parents.n_walk_steps));
  stats.emplace_back("parent_located_globally", static_cast<double>(result.parents.n_located_globally));
}

void add_step_counts(Evolve_result& result, std::initializer_list<std::pair<const char*, double>> counts) {
  for (const auto& count : counts) result.stats.emplace_back(count.first, count.second);
  result.stats.emplace_back("n_output_points", static_cast<double>(result.mesh.points.size()));
  result.stats.emplace_back("n_output_triangles", static_cast<double>(result.mesh.triangles.size()));
}

}  // namespace evomesh
