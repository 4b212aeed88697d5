"""Time the spacing function's construction (the step's ``apollonius`` stage)
with and without the filter of hidden sites.

Scenario ``band-coarsen`` of ``benchmarks/compare_peers.py``: the mesh
``unit_square_mesh(n, seed=0)`` and delta = 1 in the band ``|x - 0.5| < 0.1``,
rising linearly to 10 at x = 0 and x = 1 (most of the domain coarsens, by up to
10); ``front`` is the graded step of ``benchmarks/bench_evolve.py``.

For each size, alternating before / after in one process:

* **construction**: ``_core.SpacingFunction(points, w)`` (before: every site is
  inserted) against ``_core.SpacingFunction(points, w, 0, triangles)`` (after:
  sites hidden by a neighbour inserted before them are left out), with
  ``w = delta nn_M``: the work of the step's ``apollonius`` stage. f and the
  nearest sites at the mesh points and at 1e5 random points are checked to be
  bit-identical.
* **step**: ``evolve(mesh, delta, seed=0)`` with ``EVOMESH_SITE_FILTER=0``
  (before) and without it (after): the ``apollonius`` stage and the whole step
  (``seconds_total``, wall), and a check that both outputs are bit-identical.

Times are medians over ``--repeats``.

Usage::

    python benchmarks/bench_site_filter.py [--sizes 1e5,1e6] [--repeats 3]
        [--scenarios band-coarsen,front] [--json FILE]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import evomesh  # noqa: E402
from bench_evolve import graded_case  # noqa: E402
from evomesh import _core  # noqa: E402


def scenario(name: str, size: float) -> tuple[evomesh.Mesh, np.ndarray]:
    if name == "front":
        mesh, delta, _ = graded_case(size, None)
        return mesh, delta
    if name == "band-coarsen":
        mesh = evomesh.unit_square_mesh(int(size), seed=0)
        x = mesh.points[:, 0]
        return mesh, 1.0 + 9.0 * np.clip((np.abs(x - 0.5) - 0.1) / 0.4, 0.0, 1.0)
    raise ValueError(name)


def digest(mesh: evomesh.Mesh) -> str:
    h = hashlib.sha256()
    for array in (mesh.points, mesh.triangles, mesh.segments, mesh.kind):
        h.update(np.ascontiguousarray(array).tobytes())
    return h.hexdigest()[:16]


def run(name: str, size: float, repeats: int) -> dict[str, Any]:
    mesh, delta = scenario(name, size)
    points, triangles = mesh.points, mesh.triangles
    w = delta * mesh.nn_spacing
    rng = np.random.default_rng(0)
    lo, hi = points.min(axis=0), points.max(axis=0)
    queries = np.r_[points, lo + rng.random((100_000, 2)) * (hi - lo)]
    build = {"before": [], "after": []}
    counts: dict[str, int] = {}
    for _ in range(repeats):
        for path in ("before", "after"):
            t0 = time.perf_counter()
            f = _core.SpacingFunction(points, w, 0, triangles if path == "after" else None)
            build[path].append(time.perf_counter() - t0)
            counts[f"n_hidden_{path}"] = f.n_hidden
            counts[f"n_filtered_{path}"] = f.n_filtered
            counts["n_parts"] = f.n_parts
            values = [f.evaluate(queries, certified=c) for c in (True, False)]
            if path == "before":
                reference = values
            else:
                for (v1, s1), (v2, s2) in zip(reference, values):
                    assert np.array_equal(v1, v2) and np.array_equal(s1, s2), "f changed"
            del f
    step: dict[str, dict[str, list[float]]] = {p: {"apollonius": [], "total": [], "wall": []}
                                               for p in ("before", "after")}
    digests = {}
    for _ in range(repeats):
        for path in ("before", "after"):
            if path == "before":
                os.environ["EVOMESH_SITE_FILTER"] = "0"
            else:
                os.environ.pop("EVOMESH_SITE_FILTER", None)
            t0 = time.perf_counter()
            out = evomesh.evolve(mesh, delta, seed=0)
            step[path]["wall"].append(time.perf_counter() - t0)
            step[path]["apollonius"].append(out.stats["seconds_apollonius"])
            step[path]["total"].append(out.stats["seconds_total"])
            digests[path] = digest(out)
            counts[f"n_filtered_sites_{path}"] = int(out.stats["n_filtered_sites"])
            counts["n_hidden_sites"] = int(out.stats["n_hidden_sites"])
            counts["n_output_points"] = out.n_points
    os.environ.pop("EVOMESH_SITE_FILTER", None)
    assert digests["before"] == digests["after"], "the step's output changed"
    med = {p: {k: float(np.median(v)) for k, v in by.items()} for p, by in step.items()}
    return {
        "scenario": name,
        "n_points": mesh.n_points,
        "repeats": repeats,
        **counts,
        "construction_before": float(np.median(build["before"])),
        "construction_after": float(np.median(build["after"])),
        "step_before": med["before"],
        "step_after": med["after"],
        "output_digest": digests["after"],
    }


def markdown(results: list[dict[str, Any]]) -> str:
    head = ("| scenario | points | hidden sites | left out (after) | construction before (s) | after (s) | ratio | "
            "step `apollonius` before (s) | after (s) | ratio | whole step before (s) | after (s) | ratio |\n"
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n")
    rows = []
    for r in results:
        b, a = r["step_before"], r["step_after"]
        rows.append(
            f"| {r['scenario']} | {r['n_points']:,} | {r['n_hidden_after']:,} | {r['n_filtered_after']:,} | "
            f"{r['construction_before']:.2f} | {r['construction_after']:.2f} | "
            f"{r['construction_before'] / r['construction_after']:.3f} | {b['apollonius']:.2f} | "
            f"{a['apollonius']:.2f} | {b['apollonius'] / a['apollonius']:.3f} | {b['total']:.2f} | "
            f"{a['total']:.2f} | {b['total'] / a['total']:.3f} |")
    return head + "\n".join(rows) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1e5,1e6")
    parser.add_argument("--scenarios", default="band-coarsen")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", help="write the results here")
    args = parser.parse_args()
    results = []
    for name in args.scenarios.split(","):
        for size in (float(s) for s in args.sizes.split(",")):
            r = run(name, size, args.repeats)
            results.append(r)
            print(json.dumps(r), flush=True)
    print()
    print(markdown(results))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
