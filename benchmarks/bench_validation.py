"""Time ``Mesh()`` validation on graded meshes: the current checks against the older ones.

The meshes are those of ``benchmarks/bench_evolve.py`` (a grid evolved once
towards a band of fine spacing, not timed). For each size the script times

* ``Mesh(points, triangles, segments, kind=kind)`` as a whole (wall and CPU),
* and its stages, by making the same calls ``Mesh.__init__`` makes, one at a time:
  ``topology`` (repeated vertices and triangles, orphans, duplicate points:
  numpy), ``nn`` (nn_M, two points too close), the C++ ``prepare_mesh`` stages
  ``orient``, ``segments`` (edge manifoldness, boundary), ``planar`` and
  ``classify`` (point kinds), ``flatness`` (nearly flat triangles) and ``pinch``
  (a boundary corner within 1024 units of rounding of a boundary edge; after path only);

along two paths in the same process, alternating:

* **after**: ``Mesh()``'s path (planarity by the winding of the boundary,
  flatness in C++);
* **before**: the older checks on the same data: the
  constrained Delaunay triangulation of every edge
  (``prepare_mesh(reference_planarity=True)``, i.e. ``check_planar_mesh_cdt``)
  and the numpy flatness arithmetic. Its ``segments`` stage is the new counting
  sort (the old comparison sort of all edges is gone), so it is a little faster
  than the old code was.

``Mesh() before`` is the sum of its stages plus the rest of ``Mesh()`` (copies,
conversions) as measured on the after path. Times are medians over
``--repeats``; the ratio before / after is taken within one run.

Usage::

    python benchmarks/bench_validation.py [--sizes 1e5,1e6] [--repeats 3] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import evomesh  # noqa: E402
from bench_evolve import graded_case  # noqa: E402
from evomesh import _core  # noqa: E402
from evomesh import mesh as mesh_module  # noqa: E402

STAGES = ("topology", "nn", "orient", "segments", "planar", "classify", "flatness", "pinch")


def cpu_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def numpy_flatness(points: np.ndarray, triangles: np.ndarray) -> None:
    """The older flatness check (numpy over all triangles)."""
    height, longest, rounding = mesh_module._flatness(points, triangles)
    thin = height < mesh_module._MIN_RELATIVE_HEIGHT * longest
    coarse = height < mesh_module._MIN_HEIGHT_ULPS * rounding
    if thin.any() or coarse.any():
        raise ValueError("flat triangle")


def staged(points: np.ndarray, triangles: np.ndarray, segments: np.ndarray, before: bool) -> dict[str, float]:
    """The calls of Mesh.__init__ that do the checking, each timed."""
    out: dict[str, float] = {}

    def lap(name: str, call: Callable[[], Any]) -> Any:
        t0 = time.perf_counter()
        result = call()
        out[name] = time.perf_counter() - t0
        return result

    lap("topology", lambda: mesh_module._check_topology(points, triangles))
    lap("nn", lambda: mesh_module._check_point_distances(points))
    result = _core.prepare_mesh(points, triangles, segments, True, None, None, before)
    for name in ("orient", "segments", "planar", "classify"):
        out[name] = result[-1][f"seconds_{name}"]
    oriented = result[0]
    lap("flatness", lambda: numpy_flatness(points, oriented) if before else mesh_module._check_not_flat(points,
                                                                                                       oriented))
    # The near-touching boundary check (added 2026-12-01, after the faster checks): none before.
    if before:
        out["pinch"] = 0.0
    else:
        lap("pinch", lambda: mesh_module.check_boundary_not_pinched(points, result[1], result[2], result[3]))
    return out


def run_size(target: float, repeats: int) -> dict[str, Any]:
    graded, _, info = graded_case(target, None)
    points = np.ascontiguousarray(graded.points)
    triangles = np.ascontiguousarray(graded.triangles)
    segments = np.ascontiguousarray(graded.segments)
    kind = np.ascontiguousarray(graded.kind)
    whole, whole_cpu = [], []
    stages: dict[str, dict[str, list[float]]] = {"before": {s: [] for s in STAGES}, "after": {s: [] for s in STAGES}}
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), cpu_seconds()
        evomesh.Mesh(points, triangles, segments, kind=kind)
        whole.append(time.perf_counter() - t0)
        whole_cpu.append(cpu_seconds() - c0)
        for path in ("before", "after"):
            for name, seconds in staged(points, triangles, segments, path == "before").items():
                stages[path][name].append(seconds)
    median = {path: {s: float(np.median(v)) for s, v in by.items()} for path, by in stages.items()}
    mesh_after = float(np.median(whole))
    rest = max(0.0, mesh_after - sum(median["after"].values()))
    mesh_before = sum(median["before"].values()) + rest
    return {
        "target": target,
        "n_points": graded.n_points,
        "n_triangles": graded.n_triangles,
        "n_boundary_edges": int(np.count_nonzero(graded.segment_is_boundary)),
        "grid_side": info["grid_side"],
        "repeats": repeats,
        "seconds_mesh_after": mesh_after,
        "cpu_seconds_mesh_after": float(np.median(whole_cpu)),
        "seconds_mesh_before": mesh_before,
        "seconds_rest_of_mesh": rest,
        "stages_before": median["before"],
        "stages_after": median["after"],
        "ratio_planar": median["before"]["planar"] / median["after"]["planar"],
        "ratio_mesh": mesh_before / mesh_after,
    }


def markdown(results: list[dict[str, Any]]) -> str:
    head = ("| points | path | " + " | ".join(STAGES) + " | rest of Mesh() | **Mesh() (s)** | before / after |\n"
            "|---|---|" + "---|" * len(STAGES) + "---|---|---|\n")
    rows = []
    for r in results:
        for path in ("before", "after"):
            stage = r[f"stages_{path}"]
            total = r[f"seconds_mesh_{path}"]
            ratio = f"{r['ratio_mesh']:.1f}x" if path == "after" else ""
            rows.append(f"| {r['n_points']:,} | {path} | " + " | ".join(f"{stage[s]:.3f}" for s in STAGES)
                        + f" | {r['seconds_rest_of_mesh']:.3f} | **{total:.2f}** | {ratio} |")
    return head + "\n".join(rows) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1e5,1e6", help="comma-separated target point counts")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", help="write the results here")
    args = parser.parse_args()
    results = []
    for size in (float(s) for s in args.sizes.split(",")):
        r = run_size(size, args.repeats)
        results.append(r)
        print(json.dumps(r), flush=True)
    print()
    print(markdown(results))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
