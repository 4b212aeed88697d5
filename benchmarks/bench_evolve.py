"""Time one FRFC step through the Python API on graded meshes.

The meshes are the ones of ``cpp/bench/bench_evolve.cpp``: a k x k triangulated
grid on the unit square, evolved once (not timed) towards the spacing
``h_old`` of a vertical band of fine spacing; the timed step moves the band by
``BAND_SHIFT`` with ``delta = clip(h_new / h_old, 0.5, 2)``.

Each size runs in a fresh process, so its peak RSS (``resource.getrusage``,
which includes building the graded mesh) is its own; the peak of the timed step
alone is read from ``VmHWM`` after resetting it (Linux ``/proc/self/clear_refs``).
Reported per size: ``Mesh(...)`` construction of the graded mesh (validation,
including the planarity check; see bench_validation.py), the stage timings
that ``evolve`` returns in ``stats``, the wall time of ``evolve``, and the ratio
of that time to ``_core.constrained_delaunay`` of the output points and
segments, measured in the same process. Times are medians over ``--repeats``.

Usage::

    python benchmarks/bench_evolve.py [--sizes 1e4,1e5] [--repeats 3]
        [--quality on|off] [--threads N] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from typing import Any

import numpy as np

import evomesh
from evomesh import _core

# Keep in sync with cpp/bench/bench_evolve.cpp.
BAND_CENTER = 0.35
BAND_SHIFT = 0.1
BAND_HALF_WIDTH = 0.025
GRADING_LENGTH = 0.05
COARSE_RATIO = 8.0
POINTS_PER_INVERSE_SQUARE_SPACING = 0.0634


def target_spacing(x: np.ndarray, band_center: float, s: float) -> np.ndarray:
    """Spacing s * min(8, 1 + d / 0.05), d the distance to the band."""
    d = np.maximum(0.0, np.abs(x - band_center) - BAND_HALF_WIDTH)
    return s * np.minimum(COARSE_RATIO, 1.0 + d / GRADING_LENGTH)


def structured_grid(k: int) -> tuple[np.ndarray, np.ndarray]:
    """k x k points, (i, j) -> i + k j, cells split along alternating diagonals."""
    i, j = np.meshgrid(np.arange(k), np.arange(k))
    points = np.column_stack([i.ravel() / (k - 1), j.ravel() / (k - 1)])
    ci, cj = np.meshgrid(np.arange(k - 1), np.arange(k - 1))
    ci, cj = ci.ravel(), cj.ravel()
    a = ci + k * cj
    b, c, d = a + 1, a + k, a + k + 1
    even = (ci + cj) % 2 == 0
    first = np.where(even[:, None], np.column_stack([a, b, d]), np.column_stack([a, b, c]))
    second = np.where(even[:, None], np.column_stack([a, d, c]), np.column_stack([b, d, c]))
    triangles = np.stack([first, second], axis=1).reshape(-1, 3)
    return points, triangles


def graded_case(target: float, threads: int | None) -> tuple[evomesh.Mesh, np.ndarray, dict[str, float]]:
    """The graded mesh of about `target` points and the delta of the timed step."""
    t0 = time.perf_counter()
    s = float(np.sqrt(POINTS_PER_INVERSE_SQUARE_SPACING / target))
    k = int(np.ceil(1.0 / (4.0 * s))) + 1
    points, triangles = structured_grid(k)
    grid = evomesh.Mesh(points, triangles)
    setup_delta = target_spacing(grid.points[:, 0], BAND_CENTER, s) * (k - 1)
    # The graded input is fixed: built with the paper's packing (exact radii,
    # old points first), so the timed step and compare_peers.py's front case keep their input.
    graded = evomesh.evolve(grid, setup_delta, seed=0, quality=False, max_samples=1e10, threads=threads,
                            radius="exact", demote_ratio=None, gap_repair_ratio=None, refine_gap_ratio=None)
    x = graded.points[:, 0]
    delta = np.clip(target_spacing(x, BAND_CENTER + BAND_SHIFT, s) / target_spacing(x, BAND_CENTER, s), 0.5, 2.0)
    return graded, delta, {"grid_side": k, "spacing_scale": s, "setup_seconds": time.perf_counter() - t0}


def reset_peak_memory() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def status_mib(key: str) -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def cpu_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def run_size(target: float, repeats: int, quality: bool, threads: int | None) -> dict[str, Any]:
    graded, delta, info = graded_case(target, threads)
    mesh_seconds = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        evomesh.Mesh(graded.points, graded.triangles, graded.segments, kind=graded.kind)
        mesh_seconds.append(time.perf_counter() - t0)
    stages: dict[str, list[float]] = {}
    evolve_seconds, evolve_cpu, cdt_seconds = [], [], []
    counts: dict[str, float] = {}
    step_peak = input_rss = float("nan")
    for r in range(repeats):
        tracked = reset_peak_memory()
        if r == 0:
            input_rss = status_mib("VmRSS")
        t0, c0 = time.perf_counter(), cpu_seconds()
        out = evomesh.evolve(graded, delta, seed=0, quality=quality, threads=threads)
        evolve_seconds.append(time.perf_counter() - t0)
        evolve_cpu.append(cpu_seconds() - c0)
        if r == 0 and tracked:
            step_peak = status_mib("VmHWM")
        for name, value in out.stats.items():
            if name.startswith("seconds_"):
                stages.setdefault(name[len("seconds_"):], []).append(value)
            else:
                counts[name] = value
        t0 = time.perf_counter()
        _core.constrained_delaunay(out.points, out.segments, out.segment_is_boundary.astype(np.uint8))
        cdt_seconds.append(time.perf_counter() - t0)
    samples = counts.get("n_interior_samples_drawn", 0) + counts.get("n_segment_samples", 0)
    return {
        "target": target,
        **info,
        "repeats": repeats,
        "quality": quality,
        "n_input_points": graded.n_points,
        "n_output_points": out.n_points,
        "samples_per_input_point": samples / graded.n_points,
        "mis_spheres_per_input_point": counts.get("n_candidates", 0) / graded.n_points,
        "seconds_mesh_construction": float(np.median(mesh_seconds)),
        **{f"seconds_{name}": float(np.median(v)) for name, v in stages.items()},
        "seconds_evolve": float(np.median(evolve_seconds)),
        "cpu_seconds_evolve": float(np.median(evolve_cpu)),
        "seconds_cdt_baseline": float(np.median(cdt_seconds)),
        "step_peak_mib": step_peak,
        "input_rss_mib": input_rss,
        "process_peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "counts": counts,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1e4,1e5", help="comma-separated target point counts")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quality", choices=["on", "off"], default=None,
                        help="the quality pass (default: evolve's default)")
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--json", help="write the results here")
    parser.add_argument("--worker", type=float, help=argparse.SUPPRESS)
    args = parser.parse_args()
    quality = evomesh.FRFC_DEFAULTS.get("quality", False) if args.quality is None else args.quality == "on"

    if args.worker is not None:
        print(json.dumps(run_size(args.worker, args.repeats, quality, args.threads)))
        return

    print(f"# bench_evolve.py: evomesh {evomesh.__version__}, {os.cpu_count()} cpus, threads={args.threads}, "
          f"quality={'on' if quality else 'off'}, repeats={args.repeats} (medians)")
    results = []
    header_done = False
    for size in (float(s) for s in args.sizes.split(",")):
        cmd = [sys.executable, __file__, "--worker", str(size), "--repeats", str(args.repeats),
               "--quality", "on" if quality else "off"]
        if args.threads is not None:
            cmd += ["--threads", str(args.threads)]
        r = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
        results.append(r)
        stages = [k[len("seconds_"):] for k in r if k.startswith("seconds_")
                  and k not in ("seconds_mesh_construction", "seconds_evolve", "seconds_cdt_baseline")]
        if not header_done:
            print("\n| target | input pts | output pts | samples drawn / input pt | MIS spheres / input pt | Mesh() | "
                  + " | ".join(stages) + " | evolve (s) | CPU s (all threads) | CDT of output | evolve / CDT | step peak (MiB) "
                  "| process peak (MiB) |")
            print("|" + "---|" * (len(stages) + 12))
            header_done = True
        row = [f"{r['target']:.0e}", str(r["n_input_points"]), str(r["n_output_points"]),
               f"{r['samples_per_input_point']:.1f}", f"{r['mis_spheres_per_input_point']:.2f}",
               f"{r['seconds_mesh_construction']:.3f}"]
        row += [f"{r.get('seconds_' + s, float('nan')):.3f}" for s in stages]
        row += [f"{r['seconds_evolve']:.3f}", f"{r['cpu_seconds_evolve']:.2f}", f"{r['seconds_cdt_baseline']:.3f}",
                f"{r['seconds_evolve'] / r['seconds_cdt_baseline']:.0f}", f"{r['step_peak_mib']:.0f}",
                f"{r['process_peak_mib']:.0f}"]
        print("| " + " | ".join(row) + " |", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
