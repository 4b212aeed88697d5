"""Cost follows the change: what one FRFC step costs against
the fraction of the mesh that changes, and what a bit-identical incremental
step would have to pay at least.

The input is the output of a step (``unit_square_mesh(n)`` evolved with
delta = 1, a quasi-uniform mesh that is a fixed point of delta = 1 steps; see
benchmarks/README.md). The timed step has delta = 1 except in a front band
``0.3 <= x < 0.3 + w`` (the whole square for 100 %) where
``delta = 1 - 0.5 sin(2 pi (x - 0.3) / w)`` refines (down to 0.5) and coarsens (up to 1.5);
the band touches about the fraction w of the points (the density is uniform).
"0 %" is delta = 1 everywhere.

For every fraction, ``--repeats`` alternating runs of

* the full step (``evomesh.evolve(..., incremental=False)``, wall seconds),
* the incremental step (``incremental=True``, the default), asserted equal;
* the whole-mesh stages the incremental step still runs: it rebuilds the
  constrained Delaunay triangulation of *all* selected points and runs the
  quality pass, the parent map and the output checks on the whole mesh. (The
  triangle array used to be CGAL's face order, a function of the whole
  insertion history, so a bit-identical step had to; ``--order-evidence``
  showed a 1 % band reordering every triangle far away. Triangles now come in
  a canonical order, so a local update of the triangulation could return the
  same arrays: docs/distributed-step.md, 2.5.) "whole-mesh stages" =
  the incremental run's ``quality`` + ``parent_map`` seconds + evolve's time
  outside the core. The triangulation itself runs on the second thread beside
  the packing (in both paths), so its time is given apart: one plain
  ``constrained_delaunay`` of the output;
* "history-bound": the full step's own seconds for the work that follows the
  triangulation's insertion history with the default (serial) quality pass:
  the three batches of its early triangulation (every selected point;
  ``early_triangulation_insert_seconds``) and the pass's insertions
  (constraint pieces and off-centres; ``quality_insert_seconds``). The serial
  pass computes each off-centre in the face's stored rotation, which follows
  that history, so a step with the same bits must do this work as the full step
  does it, one insertion after another: it bounds any such step's wall time
  from below (docs/distributed-step.md 2.5),

and the medians, with the ratios taken run by run.

Command (tables in benchmarks/README.md, "Cost follows the change")::

    .venv/bin/python benchmarks/bench_incremental.py --sizes 1e5,1e6 --repeats 3 --order-evidence

``--loop``: the same comparison in a time loop, where the input is
what the previous step of the loop returned (a step's own output: its
triangles in canonical order and, without the quality pass, certified strictly
Delaunay, which the next update inherits): the 5 % band at x = 0.3 evolves the
stepped mesh (not timed), then the timed step moves the band to x = 0.6::

    .venv/bin/python benchmarks/bench_incremental.py --loop --sizes 1e5,1e6 --repeats 5 --options no-quality

``--one-point``: delta = 1 except at the point nearest the
centre (1e-6: refine there, 1e3: coarsen there), and for comparison the 5 % front
band above. Each path runs in a fresh process
(one per path and case): the peak resident memory of the step (the largest
``memory_peak_mib_*`` stat under ``EVOMESH_STAGE_PROFILE=1``, VmHWM reset just
before the step), the same less the resident memory before the step, and the
median wall seconds of ``--repeats`` steps without the profile; the two paths'
outputs are compared by digest::

    .venv/bin/python benchmarks/bench_incremental.py --one-point --sizes 2e3,1e5 --repeats 5
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np

import evomesh
from evomesh import _core

FRACTIONS = (0.0, 0.01, 0.05, 0.2, 1.0)
SELECTION_STAGES = ("nn", "apollonius", "spacing_at_points", "sampling", "sample_radii", "lfmis", "spacing_repair")


# The step's options (--options): evolve's defaults, or without the quality pass
# (recommended less the pass; the paper's), where the incremental step updates the
# triangulation instead of building it whole.
OPTIONS: dict = {}


def options_named(name: str) -> dict:
    if name == "paper":
        return {"options": evomesh.FrfcOptions.paper()}
    if name == "no-quality":
        return {"quality": False}
    return {}


def stepped_mesh(n: int) -> evomesh.Mesh:
    """The output of one step on the quasi-uniform unit_square_mesh (not timed), with the bench's options."""
    grid = evomesh.unit_square_mesh(n, seed=0)
    return evomesh.evolve(grid, np.ones(grid.n_points), seed=0, **OPTIONS)


def front_delta(mesh: evomesh.Mesh, fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """delta of a front band touching about `fraction` of the points, and the band mask."""
    x = mesh.points[:, 0]
    if fraction >= 1.0:
        x0, w = 0.0, 1.0
    else:
        x0, w = 0.3, fraction
    band = (x >= x0) & (x < x0 + w) if fraction > 0 else np.zeros(mesh.n_points, bool)
    delta = np.where(band, 1.0 - 0.5 * np.sin(2 * np.pi * (x - x0) / max(w, 1e-300)), 1.0)
    return delta, band


def order_evidence(mesh: evomesh.Mesh) -> dict[str, float]:
    """Triangles far from a 1 % band (x > 0.5), present in the outputs of the delta = 1 step and
    of the 1 % band step: how many have the same index and the same first vertex in both arrays."""
    a = evomesh.evolve(mesh, np.ones(mesh.n_points), seed=1)
    b = evomesh.evolve(mesh, front_delta(mesh, 0.01)[0], seed=1)

    def keyed(m: evomesh.Mesh) -> dict:
        out = {}
        for i, t in enumerate(m.triangles):
            pts = [tuple(m.points[v]) for v in t]
            if min(p[0] for p in pts) > 0.5:
                out[tuple(sorted(pts))] = (i, pts.index(min(pts)))
        return out

    ka, kb = keyed(a), keyed(b)
    common = [k for k in ka if k in kb]
    return {
        "far_triangles": len(common),
        "same_index": sum(ka[k][0] == kb[k][0] for k in common),
        "same_rotation": sum(ka[k][1] == kb[k][1] for k in common),
    }


ARRAYS = ("points", "triangles", "segments", "segment_is_boundary", "kind", "origin")
LINEAGE = ("parent_triangle", "barycentric", "old_nn", "old_f")


def assert_same(full: evomesh.Mesh, fast: evomesh.Mesh) -> None:
    for name in ARRAYS:
        assert np.array_equal(getattr(full, name), getattr(fast, name)), name
    for name in LINEAGE:
        assert np.array_equal(getattr(full.lineage, name), getattr(fast.lineage, name)), name
    # the output's nn that the next step reads (the incremental step takes it from the change)
    assert np.array_equal(full.nn_spacing, fast.nn_spacing), "nn_spacing"


def history_bound_seconds(full: evomesh.Mesh) -> float:
    """What follows the triangulation's insertion history with the default (serial)
    quality pass, and so must run as the full step runs it for the same bits: the
    early triangulation's batches (all points) and the pass's insertions. The full
    step's own seconds for it (sequential work: a lower bound on any bit-identical
    step's wall time; 0 without the pass)."""
    return full.stats.get("early_triangulation_insert_seconds", 0.0) + full.stats.get("quality_insert_seconds", 0.0)


def timed_pair(mesh: evomesh.Mesh, delta: np.ndarray, seed: int) -> tuple[evomesh.Mesh, evomesh.Mesh, dict]:
    """The full and the incremental step on the same input, one after the other,
    asserted equal: both results, wall and CPU seconds (CPU: the process's, both
    threads; steadier than wall time on a shared machine)."""
    t, c = time.perf_counter(), time.process_time()
    full = evomesh.evolve(mesh, delta, seed=seed, incremental=False, **OPTIONS)
    wall_full, cpu_full = time.perf_counter() - t, time.process_time() - c
    t, c = time.perf_counter(), time.process_time()
    fast = evomesh.evolve(mesh, delta, seed=seed, incremental=True, **OPTIONS)
    wall_fast, cpu_fast = time.perf_counter() - t, time.process_time() - c
    assert_same(full, fast)
    return full, fast, {"full": wall_full, "incremental": wall_fast, "ratio": wall_fast / wall_full,
                        "cpu_ratio": cpu_fast / cpu_full}


def run(n: int, repeats: int, evidence: bool, fractions: tuple[float, ...] = FRACTIONS) -> list[dict]:
    t0 = time.perf_counter()
    mesh = stepped_mesh(n)
    print(f"# n = {n}: stepped mesh of {mesh.n_points} points in {time.perf_counter() - t0:.1f} s", flush=True)
    if evidence:
        print("# triangle order far from a 1 % band:", order_evidence(mesh), flush=True)
    rows = []
    for fraction in fractions:
        delta, band = front_delta(mesh, fraction)
        samples = []
        for r in range(repeats):
            # alternate the two paths; the ratio of each pair is measured in the same run
            full, fast, pair = timed_pair(mesh, delta, 1)
            wall_full, wall_fast = pair["full"], pair["incremental"]
            s = fast.stats
            t = time.perf_counter()
            _core.constrained_delaunay(full.points, full.segments, full.segment_is_boundary.astype(np.uint8))
            cdt = time.perf_counter() - t
            # the whole-mesh stages of the incremental run (the same code as the full step's)
            floor = s.get("seconds_quality", 0.0) + s.get("seconds_parent_map", 0.0) + (wall_fast - s["seconds_total"])
            history = history_bound_seconds(full)
            samples.append({"full": wall_full, "incremental": wall_fast, "ratio": wall_fast / wall_full,
                            "history": history, "history_ratio": history / wall_full,
                            "cpu_ratio": pair["cpu_ratio"],
                            "floor": floor, "floor_ratio": floor / wall_full, "cdt": cdt, "cdt_ratio": cdt / wall_full})
            if r == 0:
                changed = 1.0 - len({tuple(p) for p in mesh.points} & {tuple(p) for p in full.points}) / mesh.n_points
                taken = "incremental_quiet_triangles" in fast.stats
                region = fast.stats.get("incremental_region_points", float(mesh.n_points)) / mesh.n_points
                # (without the quality pass: 0 when the triangulation was updated, not built whole)
                update = fast.stats.get("triangulation_update_declined")
                stages = {k[8:]: v for k, v in fast.stats.items() if k.startswith("seconds_")}
        med = {k: statistics.median(x[k] for x in samples) for k in samples[0]}
        row = {"n": mesh.n_points, "fraction": fraction, "band_points": int(band.sum()), "points_changed": changed,
               "taken": taken, "region": region, **med}
        rows.append(row)
        print(f"{mesh.n_points:>9} {100 * fraction:>5.0f}% band {row['band_points']:>8} changed {100 * changed:6.2f}% "
              f"region {100 * region:6.2f}% | full {med['full']:7.2f} s  incremental {med['incremental']:7.2f} s  "
              f"ratio {med['ratio']:.3f} (CPU {med['cpu_ratio']:.3f}) | floor {med['floor']:6.2f} s ({med['floor_ratio']:.2f}), cdt "
              f"{med['cdt']:5.2f} s ({med['cdt_ratio']:.2f}), history-bound {med['history']:5.2f} s "
              f"({med['history_ratio']:.3f}) | same bits, "
              f"{'incremental' if taken else 'full (declined)'}", flush=True)
        print("   incremental stages:", {k: round(v, 3) for k, v in stages.items()},
              "" if update is None else f"triangulation update declined: {update:g}", flush=True)
        # (the first run's stages over the median full step: where the incremental step's time goes)
        print("   stage / full step:", {k: round(v / med["full"], 3) for k, v in stages.items() if k != "total"}, flush=True)
    return rows


def markdown(rows: list[dict]) -> str:
    lines = [
        "| points | band | points changed | region (sampled/packed) | full step (s) | incremental (s) "
        "| **incremental / full** | path | whole-mesh stages (s) | / full | CDT of the output (s) | / full "
        "| history-bound (s) | / full |",
        "|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['n']:,} | {100 * r['fraction']:.0f} % | {100 * r['points_changed']:.2f} % "
            f"| {100 * r['region']:.1f} % | {r['full']:.2f} | {r['incremental']:.2f} | **{r['ratio']:.3f}** "
            f"| {'incremental' if r['taken'] else 'full (declined)'} | {r['floor']:.2f} | {r['floor_ratio']:.2f} "
            f"| {r['cdt']:.2f} | {r['cdt_ratio']:.2f} | {r['history']:.2f} | {r['history_ratio']:.3f} |"
        )
    return "\n".join(lines)


def band_at(mesh: evomesh.Mesh, x0: float, w: float = 0.05) -> np.ndarray:
    """delta of the front band [x0, x0 + w) (as front_delta) on any mesh."""
    x = mesh.points[:, 0]
    inside = (x >= x0) & (x < x0 + w)
    return np.where(inside, 1.0 - 0.5 * np.sin(2 * np.pi * (x - x0) / w), 1.0)


def run_loop(n: int, repeats: int) -> dict:
    """The 5 % band moved along a time loop: full and incremental steps on the loop's
    previous output, alternating, asserted equal; medians of the run-by-run ratios."""
    mesh = stepped_mesh(n)
    previous = evomesh.evolve(mesh, band_at(mesh, 0.3), seed=1, **OPTIONS)  # the loop's last step (not timed)
    delta = band_at(previous, 0.6)
    samples, stages = [], {}
    for _ in range(repeats):
        full, fast, pair = timed_pair(previous, delta, 2)
        wall_full, wall_fast = pair["full"], pair["incremental"]
        samples.append({**pair, "history_ratio": history_bound_seconds(full) / wall_full})
        for k, v in fast.stats.items():
            if k.startswith("seconds_") and k != "seconds_total":
                stages.setdefault(k[8:], []).append(v / wall_full)
        stages.setdefault("outside the core", []).append((wall_fast - fast.stats["seconds_total"]) / wall_full)
    med = {k: statistics.median(x[k] for x in samples) for k in samples[0]}
    update = fast.stats.get("triangulation_update_declined")
    inherited = fast.stats.get("triangulation_update_checked_kept_edges") == 0
    runs = ", ".join(f"{x['ratio']:.3f}" for x in samples)
    print(f"{previous.n_points:>9} loop, 5% band | full {med['full']:6.2f} s  incremental {med['incremental']:6.2f} s  "
          f"ratio {med['ratio']:.3f} (CPU {med['cpu_ratio']:.3f}; runs {runs})"
          f" | same bits"
          + (f" | history-bound / full {med['history_ratio']:.3f}" if med["history_ratio"] > 0 else "")
          + ("" if update is None else f" | update declined {update:g}, kept edges {'inherited' if inherited else 'checked'}"),
          flush=True)
    print("   stage / full step (medians):", {k: round(statistics.median(v), 3) for k, v in stages.items()}, flush=True)
    return {"n": previous.n_points, **med}


ONE_POINT_CASES = (("point", 1e-6), ("point", 1e3), ("band", 0.05))


def _resident_mib(field: str) -> float:
    """VmRSS or VmHWM of this process in MiB (Linux), NaN elsewhere."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith(field + ":"):
                    return float(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


def one_point_worker(n: int, kind: str, value: float, incremental: bool, repeats: int) -> dict:
    """In a fresh process: the step's peak memory (profiled run), then its time (plain runs)."""
    mesh = stepped_mesh(n)
    if kind == "point":
        delta = np.ones(mesh.n_points)
        delta[int(np.argmin(np.hypot(mesh.points[:, 0] - 0.5, mesh.points[:, 1] - 0.5)))] = value
    else:
        delta = front_delta(mesh, value)[0]
    os.environ["EVOMESH_STAGE_PROFILE"] = "1"
    before = _resident_mib("VmRSS")
    try:  # the step's peak, not the mesh building's (the step resets it after every stage too)
        with open("/proc/self/clear_refs", "w") as refs:
            refs.write("5")
    except OSError:
        pass
    out = evomesh.evolve(mesh, delta, seed=1, incremental=incremental)
    peaks = [v for k, v in out.stats.items() if k.startswith("memory_peak_mib_")]
    peak = max(peaks) if peaks else _resident_mib("VmHWM")
    os.environ["EVOMESH_STAGE_PROFILE"] = "0"
    seconds = []
    for _ in range(repeats):
        t = time.perf_counter()
        evomesh.evolve(mesh, delta, seed=1, incremental=incremental)
        seconds.append(time.perf_counter() - t)
    digest = hashlib.sha256()
    for name in ARRAYS:
        digest.update(np.ascontiguousarray(getattr(out, name)).tobytes())
    for name in LINEAGE:
        digest.update(np.ascontiguousarray(getattr(out.lineage, name)).tobytes())
    return {"n": mesh.n_points, "peak_mib": peak, "step_mib": peak - before, "seconds": statistics.median(seconds),
            "incremental_step": out.stats.get("incremental_step", float("nan")), "digest": digest.hexdigest()}


def run_one_point(n: int, repeats: int) -> None:
    print(f"# one point changed, n = {n}: each path in a fresh process", flush=True)
    for kind, value in ONE_POINT_CASES:
        res = {}
        for incremental in (False, True):
            cmd = [sys.executable, __file__, "--one-point-worker", json.dumps([n, kind, value, incremental, repeats])]
            line = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.strip().splitlines()[-1]
            res[incremental] = json.loads(line)
        full, fast = res[False], res[True]
        assert full["digest"] == fast["digest"], "the two paths differ"
        path = "incremental" if fast["incremental_step"] == 1 else "full"
        case = f"delta {value:g} at one point" if kind == "point" else f"{100 * value:g} % front band"
        print(f"{full['n']:>9} {case:<22} | full {full['seconds']:.4f} s peak {full['peak_mib']:.1f} MiB "
              f"(step {full['step_mib']:.1f}) | default ({path}) {fast['seconds']:.4f} s peak {fast['peak_mib']:.1f} MiB "
              f"(step {fast['step_mib']:.1f}) | time ratio {fast['seconds'] / full['seconds']:.3f}, peak ratio "
              f"{fast['peak_mib'] / full['peak_mib']:.3f} | same bits", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="1e5,1e6")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--fractions", default=",".join(str(f) for f in FRACTIONS),
                        help="band widths as fractions of the square (default: %(default)s)")
    parser.add_argument("--order-evidence", action="store_true")
    parser.add_argument("--options", choices=["recommended", "no-quality", "paper"], default="recommended",
                        help="the step's options: evolve's defaults, less the quality pass, or the paper's")
    parser.add_argument("--one-point", action="store_true", help="the one-point table instead")
    parser.add_argument("--loop", action="store_true", help="the 5 %% band in a time loop (the input a step's output)")
    parser.add_argument("--one-point-worker", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one_point_worker:
        print(json.dumps(one_point_worker(*json.loads(args.one_point_worker))))
        return
    if args.one_point:
        for size in args.sizes.split(","):
            run_one_point(int(float(size)), args.repeats)
        return
    OPTIONS.update(options_named(args.options))
    if args.loop:
        for size in args.sizes.split(","):
            run_loop(int(float(size)), args.repeats)
        return
    rows = []
    for size in args.sizes.split(","):
        rows += run(int(float(size)), args.repeats, args.order_evidence,
                    tuple(float(f) for f in args.fractions.split(",")))
    print()
    print(markdown(rows))


if __name__ == "__main__":
    main()
