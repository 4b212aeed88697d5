"""One step against the physical limit.

The limit of a step is what any remesher must at least do: a constrained
Delaunay triangulation of the output points (CGAL, the output's segments as
constraints) plus a nearest-neighbour search of the input (the kd-tree of
``evomesh.nn_spacing``). Both are timed in the same process as the step, on the
same data, alternating with it, so the ratio step / limit is what to read (the
machine is shared and noisy).

    .venv/bin/python benchmarks/bench_limit.py --size 1e6 [--repeats 3] [--threads 2]

Prints per scenario (compare_peers.py's front, band-coarsen, uniform-coarsen):
input and output points, median wall and CPU seconds of evolve (defaults), of the
limit, and their ratio (goal: at most 4); the Apollonius graph of the input
sites alone (``evomesh.spacing(mesh, delta)``, the design's f) against the same
limit; and the stage breakdown of the step.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import evomesh  # noqa: E402
from evomesh import _core  # noqa: E402
from compare_peers import SCENARIOS, scenario  # noqa: E402


def timed(fn, *args, **kwargs):
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - w0, time.process_time() - c0


def limit(mesh: evomesh.Mesh, out: evomesh.Mesh, threads: int | None) -> None:
    """CGAL's constrained Delaunay of the output points + nn of the input."""
    pieces = np.ascontiguousarray(out.segments)
    boundary = np.ascontiguousarray(out.segment_is_boundary.astype(np.uint8))
    _core.constrained_delaunay(out.points, pieces, boundary)
    _core.nn_spacing(mesh.points)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=float, default=1e5)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    rows = []
    print("| scenario | input points | output points | evolve wall s | limit wall s | ratio wall | "
          "evolve CPU s | limit CPU s | ratio CPU | Apollonius graph alone CPU s | its ratio CPU |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenarios.split(","):
        mesh, delta, _ = scenario(name, args.size)
        step_w, step_c, lim_w, lim_c, ag_w, ag_c = [], [], [], [], [], []
        stages: dict[str, list[float]] = {}
        for _ in range(args.repeats):  # alternating: step, limit, step, limit, ...
            out, w, c = timed(evomesh.evolve, mesh, delta, seed=0, threads=args.threads)
            step_w.append(w)
            step_c.append(c)
            for key, value in out.stats.items():
                if key.startswith("seconds_") and key != "seconds_total":
                    stages.setdefault(key[8:], []).append(value)
            _, w, c = timed(limit, mesh, out, args.threads)
            lim_w.append(w)
            lim_c.append(c)
            _, w, c = timed(evomesh.spacing, mesh, delta)
            ag_w.append(w)
            ag_c.append(c)
        row = {"scenario": name, "input_points": mesh.n_points, "output_points": out.n_points,
               "evolve_wall": float(np.median(step_w)), "limit_wall": float(np.median(lim_w)),
               "evolve_cpu": float(np.median(step_c)), "limit_cpu": float(np.median(lim_c)),
               "ag_wall": float(np.median(ag_w)), "ag_cpu": float(np.median(ag_c)),
               "stages": {k: float(np.median(v)) for k, v in stages.items()}}
        rows.append(row)
        print(f"| {name} | {row['input_points']} | {row['output_points']} | {row['evolve_wall']:.2f} | "
              f"{row['limit_wall']:.2f} | {row['evolve_wall'] / row['limit_wall']:.1f} | {row['evolve_cpu']:.2f} | "
              f"{row['limit_cpu']:.2f} | {row['evolve_cpu'] / row['limit_cpu']:.1f} | {row['ag_cpu']:.2f} | "
              f"{row['ag_cpu'] / row['limit_cpu']:.1f} |", flush=True)
    print("\nstage seconds (median):")
    for row in rows:
        total = sum(row["stages"].values())
        parts = sorted(row["stages"].items(), key=lambda kv: -kv[1])
        print(f"  {row['scenario']}: " + ", ".join(f"{k} {v:.2f} ({100 * v / total:.0f}%)" for k, v in parts))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
