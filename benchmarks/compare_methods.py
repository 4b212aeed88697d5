"""Compare FRFC, its practical variations, the quality pass and DRFC.

Two cases:

* the growing circle of the paper's Section 6 (``evomesh.growing_circle``, six
  steps from the 1096-point mesh), figures aggregated over the six steps;
* one step on a graded mesh of about 1e5 points: a vertical band of fine spacing
  that moves right by 0.1 (refines ahead of the band, coarsens behind it), the
  case of cpp/bench/bench_evolve.cpp.

Columns: points, % of output points kept from the input, triangles, smallest
angle, largest radius-edge ratio, spacing ratio nn_M'(p) / (delta(p) nn_M(p))
over the input points (max and 99th percentile), n / integral(1/f^2) (size
relative to the spacing function; integral by a midpoint rule on 16 sub-triangles
per triangle), the points the quality pass adds, and seconds of evolve (fastest
of --repeats runs).

    python benchmarks/compare_methods.py [--points 1e5] [--repeats 2] [--skip-circle] [--skip-graded]
                                         [--markdown benchmarks/results/methods.md]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

import evomesh
from evomesh.mesh_quality import integral_inverse_square as _integral_inverse_square

# label, method, options
CONFIGURATIONS = [
    ("FRFC, no quality pass (paper)", "frfc", {"quality": False}),
    ("FRFC + quality pass (default)", "frfc", {}),
    ("FRFC + pass, skip_coarse", "frfc", {"skip_coarse": True}),
    ("FRFC + pass, barycentre", "frfc", {"samples": "barycentre"}),
    ("FRFC + pass, midpoints", "frfc", {"samples": "midpoints"}),
    ("FRFC + pass, barycentre+midpoints", "frfc", {"samples": "barycentre+midpoints"}),
    ("FRFC + pass, cheap radius", "frfc", {"radius": "cheap"}),
    ("FRFC + pass, cell_factor 1", "frfc", {"cell_factor": 1.0}),
    ("FRFC + pass, cell_factor 1.5", "frfc", {"cell_factor": 1.5}),
    ("FRFC + pass, cell_factor 2", "frfc", {"cell_factor": 2.0}),
    ("FRFC, no pass, cell_factor 1", "frfc", {"cell_factor": 1.0, "quality": False}),
    ("DRFC, no quality pass", "drfc", {"quality": False}),
    ("DRFC + quality pass (default)", "drfc", {}),
]

# Band of fine spacing (as in cpp/bench/bench_evolve.cpp).
BAND_CENTER, BAND_SHIFT, BAND_HALF_WIDTH, GRADING_LENGTH, COARSE_RATIO = 0.35, 0.1, 0.025, 0.05, 8.0
POINTS_PER_INVERSE_SQUARE_SPACING = 0.104


def integral_inverse_square(mesh: evomesh.Mesh, f, levels: int = 2) -> float:
    """Integral of 1/f^2 over the mesh: midpoint rule on 4**levels sub-triangles."""
    return _integral_inverse_square(mesh.points, mesh.triangles, f, levels=levels)


def spacing_ratio(old: evomesh.Mesh, new: evomesh.Mesh, delta: np.ndarray) -> np.ndarray:
    d, _ = cKDTree(new.points).query(old.points, k=2)
    nn_new = np.where(d[:, 0] == 0, d[:, 1], d[:, 0])
    return nn_new / (delta * evomesh.nn_spacing(old))


def step_figures(old, new, delta, seconds, mass) -> dict:
    q = evomesh.quality(new)
    ratio = spacing_ratio(old, new, delta)
    return {
        "points": new.n_points,
        "kept_pct": 100.0 * float((new.origin >= 0).sum()) / new.n_points,
        "triangles": new.n_triangles,
        "min_angle": q.min_angle,
        "max_radius_edge": q.max_radius_edge,
        "ratio_max": float(ratio.max()),
        "ratio_p99": float(np.percentile(ratio, 99)),
        "size": new.n_points / mass,
        "seconds": seconds,
        "added": new.stats.get("quality_points_added", 0.0),
    }


def growing_circle(label: str, method: str, options: dict, repeats: int) -> dict:
    runs = [evomesh.growing_circle(method=method, figures=False, progress=False, **options) for _ in range(repeats)]
    run = min(runs, key=lambda r: sum(s.stats["seconds"] for s in r.steps))
    meshes, deltas = run.meshes, run.deltas
    rows = []
    for k, step in enumerate(run.steps):
        old, new, delta = meshes[k], meshes[k + 1], deltas[k]
        mass = integral_inverse_square(old, evomesh.spacing(old, delta))
        rows.append(step_figures(old, new, delta, step.stats["seconds"], mass))
    # over the six steps: means of sizes, worst of quality and spacing, total time
    return {
        "label": label,
        "points": np.mean([r["points"] for r in rows]),
        "kept_pct": np.mean([r["kept_pct"] for r in rows]),
        "triangles": np.mean([r["triangles"] for r in rows]),
        "min_angle": min(r["min_angle"] for r in rows),
        "max_radius_edge": max(r["max_radius_edge"] for r in rows),
        "ratio_max": max(r["ratio_max"] for r in rows),
        "ratio_p99": max(r["ratio_p99"] for r in rows),
        "size": np.mean([r["size"] for r in rows]),
        "seconds": sum(r["seconds"] for r in rows),
        "added": np.mean([r["added"] for r in rows]),
    }


def band_spacing(x: np.ndarray, center: float, s: float) -> np.ndarray:
    d = np.maximum(0.0, np.abs(x - center) - BAND_HALF_WIDTH)
    return s * np.minimum(COARSE_RATIO, 1.0 + d / GRADING_LENGTH)


def structured_grid(k: int) -> evomesh.Mesh:
    xs = np.linspace(0.0, 1.0, k)
    x, y = np.meshgrid(xs, xs)
    points = np.c_[x.ravel(), y.ravel()]
    i, j = np.meshgrid(np.arange(k - 1), np.arange(k - 1))
    a = (i + k * j).ravel()
    b, c, d = a + 1, a + k, a + k + 1
    alt = ((i + j) % 2 == 0).ravel()
    t1 = np.where(alt[:, None], np.c_[a, b, d], np.c_[a, b, c])
    t2 = np.where(alt[:, None], np.c_[a, d, c], np.c_[b, d, c])
    return evomesh.Mesh(points, np.r_[t1, t2])


def graded_case(target: float):
    """A graded mesh of about `target` points and the delta of the timed step."""
    s = np.sqrt(POINTS_PER_INVERSE_SQUARE_SPACING / target)
    k = int(np.ceil(1.0 / (2.0 * s))) + 1
    grid = structured_grid(k)
    setup_delta = band_spacing(grid.points[:, 0], BAND_CENTER, s) / (1.0 / (k - 1))
    mesh = evomesh.evolve(grid, setup_delta, seed=0)
    x = mesh.points[:, 0]
    delta = np.clip(band_spacing(x, BAND_CENTER + BAND_SHIFT, s) / band_spacing(x, BAND_CENTER, s), 0.5, 2.0)
    return mesh, delta


def graded(label: str, method: str, options: dict, mesh, delta, mass, repeats: int) -> dict:
    seconds = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        new = evomesh.evolve(mesh, delta, method=method, seed=0, **options)
        seconds = min(seconds, time.perf_counter() - t0)
    return {"label": label, **step_figures(mesh, new, delta, seconds, mass)}


HEADER = (
    "| configuration | points | % kept | triangles | min angle | max R/e | ratio max | ratio p99 "
    "| n / ∫f⁻² | pass adds | seconds |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
)


def row(r: dict) -> str:
    return (
        f"| {r['label']} | {r['points']:.0f} | {r['kept_pct']:.1f} | {r['triangles']:.0f} | {r['min_angle']:.2f} "
        f"| {r['max_radius_edge']:.3f} | {r['ratio_max']:.2f} | {r['ratio_p99']:.2f} | {r['size']:.3f} "
        f"| {r['added']:.0f} | {r['seconds']:.3f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--points", type=float, default=1e5, help="size of the graded mesh")
    parser.add_argument("--skip-circle", action="store_true")
    parser.add_argument("--skip-graded", action="store_true")
    parser.add_argument("--repeats", type=int, default=2, help="runs per configuration; the fastest is reported")
    parser.add_argument("--markdown", type=Path, help="also write the tables to this file")
    args = parser.parse_args()
    out = []
    if not args.skip_circle:
        out += ["### Growing circle (Section 6), 6 steps from 1096 points",
                "Means over the steps (points, % kept, triangles, n/∫f⁻², points the pass adds), "
                "worst step (angle, R/e, ratios), total seconds.", "", HEADER]
        for label, method, options in CONFIGURATIONS:
            out.append(row(growing_circle(label, method, options, args.repeats)))
            print(out[-1], flush=True)
        out.append("")
    if not args.skip_graded:
        t0 = time.perf_counter()
        mesh, delta = graded_case(args.points)
        mass = integral_inverse_square(mesh, evomesh.spacing(mesh, delta))
        setup = time.perf_counter() - t0
        out += [f"### One step on a graded mesh of {mesh.n_points} points (moving band, delta in [0.5, 2])",
                f"(setup {setup:.1f} s, not timed; n/∫f⁻² of the input: {mesh.n_points / mass:.3f})", "", HEADER]
        for label, method, options in CONFIGURATIONS:
            out.append(row(graded(label, method, options, mesh, delta, mass, args.repeats)))
            print(out[-1], flush=True)
        out.append("")
    text = "\n".join(out)
    print("\n" + text)
    if args.markdown:
        args.markdown.write_text(text + "\n")


if __name__ == "__main__":
    main()
