// The step context (step_context.hpp) decides how a step runs, never what it
// gives: filter_sites, profile and release_memory change the stats they name
// and not one output bit; and the core reads no environment variable, so
// EVOMESH_SITE_FILTER and EVOMESH_STAGE_PROFILE (set here for the whole
// process) reach a step only through a context the bindings build.
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "check.hpp"
#include "evomesh/drfc.hpp"
#include "evomesh/frfc.hpp"
#include "evomesh/step_context.hpp"
#include "grid_mesh.hpp"

using namespace evomesh;
using evomesh::testing::grid_mesh;

namespace {

bool same_bits(const std::vector<Vec2>& a, const std::vector<Vec2>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(Vec2)) == 0);
}

double stat(const Evolve_result& result, const std::string& name) {
  for (const auto& [key, value] : result.stats) {
    if (key == name) return value;
  }
  return -1;
}

bool has_stat_prefix(const Evolve_result& result, const std::string& prefix) {
  for (const auto& entry : result.stats) {
    if (entry.first.rfind(prefix, 0) == 0) return true;
  }
  return false;
}

void check_same_mesh(const Evolve_result& a, const Evolve_result& b, const char* what) {
  CHECK(same_bits(a.mesh.points, b.mesh.points)) << what << ": points";
  CHECK(a.mesh.triangles == b.mesh.triangles) << what << ": triangles";
  CHECK(a.mesh.segments == b.mesh.segments) << what << ": segments";
  CHECK(a.mesh.kind == b.mesh.kind) << what << ": kinds";
  CHECK(a.origin == b.origin) << what << ": origin";
  CHECK(a.input_f == b.input_f) << what << ": f";
}

}  // namespace

int main() {
  // What the core read from the environment before the context; it must now ignore them.
  setenv("EVOMESH_SITE_FILTER", "0", 1);
  setenv("EVOMESH_STAGE_PROFILE", "1", 1);
  return evomesh_test::run([] {
    const Mesh_arrays mesh = grid_mesh(60);
    // Refine towards the lower left corner, coarsen towards the upper right:
    // coarse sites hide behind fine neighbours, which the filter drops.
    std::vector<double> delta(mesh.points.size());
    for (std::size_t i = 0; i < delta.size(); ++i) {
      const double s = mesh.points[i][0] + mesh.points[i][1];  // 0 .. 2
      delta[i] = std::pow(2.0, 2.5 * (s - 1.0) - 0.5);       // 0.125 .. 4
    }
    Frfc_options options;
    options.incremental = false;
    Step_context context = Step_context::from_threads(2);
    const Evolve_result filtered = frfc(mesh, delta, options, context);
    CHECK(stat(filtered, "n_filtered_sites") > 0) << "the default context filters sites, whatever the environment";
    CHECK(!has_stat_prefix(filtered, "memory_peak_mib_")) << "no profile unless the context asks for it";
    // The three-argument overload: the same context (threads from the options).
    options.threads = 2;
    check_same_mesh(frfc(mesh, delta, options), filtered, "three-argument frfc");

    context.filter_sites = false;  // what EVOMESH_SITE_FILTER=0 did
    const Evolve_result unfiltered = frfc(mesh, delta, options, context);
    CHECK(stat(unfiltered, "n_filtered_sites") == 0) << "filter_sites = false keeps every site";
    check_same_mesh(unfiltered, filtered, "filter_sites");

    context = Step_context::from_threads(1);
    context.profile = true;  // what EVOMESH_STAGE_PROFILE=1 did
    context.release_memory = false;
    const Evolve_result profiled = frfc(mesh, delta, options, context);
    check_same_mesh(profiled, filtered, "profile, release_memory, threads");
#if defined(__linux__)
    CHECK(has_stat_prefix(profiled, "memory_peak_mib_")) << "profile = true records each stage's peak memory";
    CHECK(has_stat_prefix(profiled, "cpu_seconds_")) << "profile = true records each stage's CPU time";
#endif

    // DRFC reads the same context.
    Drfc_options drfc_options;
    const Evolve_result drfc_filtered = drfc(mesh, delta, drfc_options, Step_context{});
    Step_context keep_sites;
    keep_sites.filter_sites = false;
    const Evolve_result drfc_unfiltered = drfc(mesh, delta, drfc_options, keep_sites);
    check_same_mesh(drfc_unfiltered, drfc_filtered, "drfc filter_sites");

    // The incremental step (delta = 1 but on a corner) takes the context too.
    std::vector<double> local(mesh.points.size(), 1.0);
    for (std::size_t i = 0; i < local.size(); ++i) {
      if (mesh.points[i][0] < 0.2 && mesh.points[i][1] < 0.2) local[i] = 0.7;
    }
    Frfc_options incremental;
    const Evolve_result fast = frfc(mesh, local, incremental, Step_context{});
    CHECK(stat(fast, "incremental_step") == 1) << "the incremental path is taken";
    CHECK(!has_stat_prefix(fast, "memory_peak_mib_")) << "no profile in the incremental step either";
    Step_context profile_fast;
    profile_fast.profile = true;
    profile_fast.release_memory = false;
    check_same_mesh(frfc(mesh, local, incremental, profile_fast), fast, "incremental step, context");
  });
}
