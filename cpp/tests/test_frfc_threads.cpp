// frfc() gives bit-identical meshes whatever the number of threads, with and
// without the quality pass.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <vector>

#include "check.hpp"
#include "evomesh/frfc.hpp"
#include "evomesh/triangulation.hpp"
#include "grid_mesh.hpp"

using namespace evomesh;
using evomesh::testing::grid_mesh;

namespace {

bool same_bits(const std::vector<Vec2>& a, const std::vector<Vec2>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(Vec2)) == 0);
}

}  // namespace

int main() {
  return evomesh_test::run([] {
    const Mesh_arrays mesh = grid_mesh(110);
    // Refine towards the lower left corner, coarsen towards the upper right.
    std::vector<double> delta(mesh.points.size());
    for (std::size_t i = 0; i < delta.size(); ++i) {
      const double s = mesh.points[i][0] + mesh.points[i][1];  // 0 .. 2
      delta[i] = std::pow(2.0, 2.5 * (s - 1.0) - 0.5);       // 0.125 .. 4
    }
    for (const bool quality : {false, true}) {
      Evolve_result reference;
      for (const int threads : {1, 2, 4}) {
        Frfc_options options;
        options.threads = threads;
        options.quality = quality;
        const auto t0 = std::chrono::steady_clock::now();
        Evolve_result result = frfc(mesh, delta, options);
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::printf("quality %-3s threads %d: %zu -> %zu points, %zu triangles, %.3f s\n", quality ? "on" : "off",
                    threads, mesh.points.size(), result.mesh.points.size(), result.mesh.triangles.size(), seconds);
        CHECK(result.mesh.points.size() > 1000 && result.mesh.points.size() != mesh.points.size())
            << "a degenerate step";
        if (threads == 1) {
          reference = std::move(result);
          continue;
        }
        CHECK(same_bits(result.mesh.points, reference.mesh.points)) << "points, threads " << threads;
        CHECK(result.mesh.triangles == reference.mesh.triangles) << "triangles, threads " << threads;
        CHECK(result.mesh.segments == reference.mesh.segments) << "segments, threads " << threads;
        CHECK(result.mesh.kind == reference.mesh.kind) << "kinds, threads " << threads;
        CHECK(result.origin == reference.origin) << "origin, threads " << threads;
        CHECK(result.input_f == reference.input_f) << "f, threads " << threads;
      }
    }
  });
}
