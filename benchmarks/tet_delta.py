"""Tetrahedral steps with a delta request: f's evaluations per query and the spacing ratio.

The mesh: the moving sphere's (tet_moving_sphere.py) after three steps of
size h(x) = min(0.1, hmin + 0.3 | |x - c| - 0.2 |) from a Kuhn 10^3 cube.
Then one step ``evomesh.evolve(mesh, delta, seed=0)`` per delta: uniform
values and "graded", delta(p) = 2^(4 x - 2) (0.25 at x = 0 to 4 at x = 1).
Per step: points, tetrahedra, kept % of the old points, f's kd-tree
evaluations per query (stats: evaluations_per_sample, the boundary and
interior samples, and evaluations_per_old_point), the spacing ratio
nn_M'(p) / (delta(p) nn_M(p)) over the old points p (nn_M' the distance to
the second nearest output point, as in spacing_ratios.py) p50 / p99 / max,
CPU seconds.

    .venv/bin/python benchmarks/tet_delta.py [--hmin 0.015] [--deltas 0.5,1,2,4,graded]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
from scipy.spatial import cKDTree

import evomesh

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tet_moving_sphere import size_function  # noqa: E402


def delta_values(name: str, mesh: evomesh.TetMesh) -> np.ndarray:
    if name == "graded":
        return 2.0 ** (4 * mesh.points[:, 0] - 2)
    return np.full(mesh.n_points, float(name))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hmin", type=float, default=0.015)
    parser.add_argument("--deltas", default="0.5,1,2,4,graded")
    args = parser.parse_args()
    mesh = evomesh.unit_cube_mesh(10)
    for k in range(3):
        mesh = evomesh.evolve(mesh, size=size_function(np.array([0.3, 0.5, 0.5]), args.hmin), seed=k)
    print(f"mesh: {mesh.n_points} points, {mesh.n_tetrahedra} tetrahedra (hmin {args.hmin:g})")
    print("| delta | points | tets | kept % | evaluations / sample | evaluations / old point | "
          "nn'/(delta nn) p50 / p99 / max | CPU s |")
    print("| " + " | ".join(["---"] * 8) + " |")
    for name in args.deltas.split(","):
        delta = delta_values(name, mesh)
        t0 = time.process_time()
        out = evomesh.evolve(mesh, delta, seed=0)
        cpu = time.process_time() - t0
        d, _ = cKDTree(out.points).query(mesh.points, k=2)
        ratio = d[:, 1] / (delta * mesh.nn_spacing)
        s = out.stats
        print(f"| {name} | {out.n_points} | {out.n_tetrahedra} | {100 * s['kept_fraction']:.1f} | "
              f"{s['evaluations_per_sample']:.1f} | {s['evaluations_per_old_point']:.1f} | "
              f"{np.percentile(ratio, 50):.3f} / {np.percentile(ratio, 99):.3f} / {ratio.max():.3f} | {cpu:.1f} |",
              flush=True)


if __name__ == "__main__":
    main()
