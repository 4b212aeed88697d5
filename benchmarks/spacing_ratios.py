"""The spacing figures: spacing that tracks the request, shape, size.

* ``scenarios``: the three cases of compare_peers.py (front, band-coarsen,
  uniform-coarsen) through ``evomesh.evolve(M, delta, seed=0)`` only, with the
  spacing ratio: over the input points p, nn_M'(p) / (delta(p) nn_M(p)) where
  nn_M'(p) is the distance to p's nearest *other* output point when p is kept,
  the second nearest output point when it is not (the paper's nn); p50/p99/max,
  the median of nn_M'/f over the output points, n / integral(1/f^2), the
  smallest angle and the share of triangles with an angle below 30 degrees;
* ``uniform``: one step and ten steps of delta = 0.8 on ``unit_square_mesh``
  (median output nn over median input nn, against 0.8 and 0.8^10);
* ``circle``: the growing-circle experiment (share of original points per step).

    .venv/bin/python benchmarks/spacing_ratios.py --size 1e5 [--parts scenarios,uniform,circle]
    .venv/bin/python benchmarks/spacing_ratios.py --size 2e4 --option radius_scale=0.8
"""

from __future__ import annotations

import argparse
import ast
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import evomesh  # noqa: E402
import peers  # noqa: E402
from compare_peers import SCENARIOS, scenario  # noqa: E402


def paper_ratio(mesh: evomesh.Mesh, delta: np.ndarray, points: np.ndarray) -> np.ndarray:
    """nn_M'(p) / (delta(p) nn_M(p)) over the input points, nn_M' the paper's (second nearest of M')."""
    d, _ = cKDTree(points).query(mesh.points, k=2)
    return d[:, 1] / (delta * mesh.nn_spacing)


def scenario_row(name: str, size: float, options: dict[str, Any]) -> dict[str, Any]:
    mesh, delta, _ = scenario(name, size)
    f = evomesh.spacing(mesh, delta)
    t0 = time.perf_counter()
    out = evomesh.evolve(mesh, delta, seed=0, **options)
    seconds = time.perf_counter() - t0
    row = peers.metrics(mesh, delta, out.points, out.triangles, f=f)
    ratio = paper_ratio(mesh, delta, out.points)
    row.update({"scenario": name, "input_points": mesh.n_points, "seconds": seconds,
                "ratio_p50": float(np.percentile(ratio, 50)), "ratio_p99": float(np.percentile(ratio, 99)),
                "ratio_max": float(ratio.max()), "kept_original": int((out.origin >= 0).sum())})
    return row


def uniform_steps(n_points: int, steps: int, options: dict[str, Any]) -> list[float]:
    """Median nn after each step of delta = 0.8, over the initial median nn."""
    mesh = evomesh.unit_square_mesh(n_points, seed=0)
    m0 = float(np.median(mesh.nn_spacing))
    out = []
    for k in range(steps):
        mesh = evomesh.evolve(mesh, 0.8, seed=k, **options)
        out.append(float(np.median(mesh.nn_spacing)) / m0)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=float, default=2e4)
    parser.add_argument("--parts", default="scenarios,uniform,circle")
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--option", action="append", default=[], help="name=value passed to evolve")
    args = parser.parse_args()
    options = {}
    for item in args.option:
        k, v = item.split("=", 1)
        options[k] = ast.literal_eval(v)
    parts = args.parts.split(",")
    if "scenarios" in parts:
        print("| scenario | points | n/∫f⁻² | ratio p50 | p99 | max | nn'/f median | min angle | % < 30° | kept orig | s |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for name in args.scenarios.split(","):
            r = scenario_row(name, args.size, options)
            print(f"| {name} | {r['points']} | {r['n_over_integral']:.3f} | {r['ratio_p50']:.3f} | "
                  f"{r['ratio_p99']:.3f} | {r['ratio_max']:.3f} | {r['output_ratio_median']:.3f} | "
                  f"{r['min_angle']:.1f} | {100 * r['fraction_below_30']:.2f} | {r['kept_original']} | "
                  f"{r['seconds']:.2f} |", flush=True)
    if "uniform" in parts:
        one = uniform_steps(1000, 1, options)[0]
        ten = uniform_steps(500, 10, options)
        print(f"\ndelta = 0.8 on unit_square_mesh: one step (1000 points) median nn ratio {one:.3f} "
              f"({one / 0.8:.3f} of 0.8); ten steps (500 points) {ten[-1]:.4f} ({ten[-1] / 0.8 ** 10:.3f} of 0.8^10); "
              "per step " + ", ".join(f"{a:.3f}" for a in ten), flush=True)
    if "circle" in parts:
        run = evomesh.growing_circle(progress=False, **options)
        print("\ngrowing circle: points " + ", ".join(str(int(x)) for x in run.column("points")) +
              "; original % " + ", ".join(f"{x:.1f}" for x in run.column("original_pct")) +
              "; min angle " + ", ".join(f"{x:.1f}" for x in run.column("min_angle_deg")))
        print("largest share of original points the step's output allows (cells of 0.03): " +
              ", ".join(f"{x:.1f}" for x in original_share_bound(run)) + " %")


def original_share_bound(run: Any, cell: float = 0.03) -> list[float]:
    """Per step: at most sum over cells of min(old points, new points) of the
    new points can be old ones, whatever the step keeps, given how many points
    the output has in each cell (the spacing it asked for): an upper bound on
    "% original" for any output with that distribution of points."""
    meshes = [run.initial] + [step.mesh for step in run.steps]
    lo, hi = run.initial.points.min(axis=0), run.initial.points.max(axis=0)
    bins = [int(np.ceil((hi[k] - lo[k]) / cell)) for k in range(2)]
    box = [[lo[0], hi[0]], [lo[1], hi[1]]]
    bound = []
    for old, new in zip(meshes, meshes[1:]):
        o, _, _ = np.histogram2d(old.points[:, 0], old.points[:, 1], bins=bins, range=box)
        n, _, _ = np.histogram2d(new.points[:, 0], new.points[:, 1], bins=bins, range=box)
        bound.append(100.0 * float(np.minimum(o, n).sum() / n.sum()))
    return bound


if __name__ == "__main__":
    main()
