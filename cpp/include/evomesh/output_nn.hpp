// The nearest-neighbour distances of a step's output (Evolve_result::output_nn),
// most of them found while the quality pass runs.
//
// The quality pass (CGAL's mesher, sequential) turns the selected points into
// the output: it adds Steiner points and drops a few crowding ones, and keeps
// the others. So the squared nn among the selected points, computed on the
// other thread while the pass runs (Selection_nn), gives the output's after a
// fix-up that only looks near the points added and dropped:
//
//   nn2_out(o) = min(nn2 of o among the kept selected points,
//                    min over Steiner points s of |o - s|^2)        o selected,
//   nn2_out(s) = min over all other output points of |s - x|^2      s Steiner.
//
// A selected point o whose nn can change has a dropped point d with
// |o - d|^2 <= nn2_sel(o) (its nearest may have gone: o is searched again among
// the kept ones), or a Steiner point s with |o - s|^2 < nn2(o): both are found
// by reverse searches from d and s in the selected points' kd-tree, whose
// nodes carry the largest nn2 below them. Every squared distance is the same
// expression as in a kd-tree over the output (detail/point_tree.hpp), and
// |a - b|^2 has the same bits from either end, so the values are the same bits
// as nn_spacing of the output.
#pragma once

#include <cstddef>
#include <memory>
#include <vector>

#include "evomesh/parallel.hpp"
#include "evomesh/types.hpp"

namespace evomesh {

class Selection_nn {
 public:
  // Builds the kd-tree of `selected` now, on parallel_for's threads (it keeps
  // its own copy of the points: they may go once this returns), then finds
  // their squared nn on another thread when `threads` allows (else now). A
  // step starts it once the early triangulation is done, so that it runs
  // beside the mesher: beside that triangulation's thread, it took its core
  // (the step then waited for that thread longer).
  Selection_nn(const std::vector<Vec2>& selected, int threads);
  ~Selection_nn();
  Selection_nn(const Selection_nn&) = delete;
  Selection_nn& operator=(const Selection_nn&) = delete;

  // The output's squared nn, by output point: `source[i]` is the selected
  // point output point i is (-1: a point the pass added). Waits for the
  // selected points' nn. False when it cannot tell (duplicate points, or the
  // tree or the queries failed): the caller then computes the output's nn from
  // scratch, which says what is wrong.
  bool output_squared_nn(const std::vector<Vec2>& output, const std::vector<Index>& source,
                         std::vector<double>& nn2);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;  // (null when the tree could not be built)
  Background work_;             // (last: joined before the rest goes)
};

}  // namespace evomesh
