#include "evomesh/triangle_fans.hpp"

#include "evomesh/global_ids.hpp"

#include "evomesh/parallel.hpp"

namespace evomesh {

Triangle_fans::Triangle_fans(const Mesh_arrays& mesh) {
  check_fits_4_bytes(3 * std::uint64_t{mesh.triangles.size()}, "3 x triangles (1.43e9 triangles)");
  const std::size_t n = mesh.points.size();
  xadj.assign(n + 1, 0);
  detail::parallel_resize(adj, 3 * mesh.triangles.size());
  for (const auto& t : mesh.triangles) {
    for (Index v : t) ++xadj[v + 1];
  }
  for (std::size_t v = 0; v < n; ++v) xadj[v + 1] += xadj[v];
  std::vector<std::uint32_t> fill(xadj.begin(), xadj.end() - 1);
  // Each fan in the order of the triangles' global ids (positions without them):
  // the walks that take the first triangle of a fan that fits (Mesh_walk::cast
  // along an edge, ring candidates) then take the same whatever the array order.
  const std::vector<Index> by_id = order_by_ids(mesh.triangle_gids);
  for (std::size_t r = 0; r < mesh.triangles.size(); ++r) {
    const std::size_t t = visit(by_id, r);
    for (Index v : mesh.triangles[t]) adj[fill[v]++] = static_cast<std::uint32_t>(t);
  }
}

}  // namespace evomesh
