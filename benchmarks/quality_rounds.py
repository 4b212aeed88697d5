"""The quality pass in rounds (``quality_rounds=True``) against the
serial pass (the default) on the same refining step of a graded front.

The step is bench_evolve.py's: a graded mesh with a band of fine spacing,
evolved so the band moves by 0.1 (delta in [0.5, 2]: refining on one side of
the band, coarsening on the other). The same step runs twice per size, once
with each pass, same seed. Reported per pass: the points the pass inserted,
the smallest angle, the median and 10th percentile of the triangles'
smallest angles, the share of triangles below the bound (percent), the rounds
(the serial pass has none), and the seconds of the
quality stage (``stats["seconds_quality"]``) and of the whole step, with the
rounds' times as ratios to the serial ones measured in the same process.

Usage::

    python benchmarks/quality_rounds.py [--sizes 1e4,1e5] [--min-angles 30,20] [--repeats 1] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_evolve import graded_case  # noqa: E402

import evomesh  # noqa: E402
from evomesh.mesh_quality import triangle_angles  # noqa: E402


def smallest_angles(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The smallest angle (degrees) of every triangle."""
    return triangle_angles(points, triangles).min(axis=1)


def run_pass(graded: evomesh.Mesh, delta: np.ndarray, rounds: bool, min_angle: float, repeats: int) -> dict[str, Any]:
    seconds, quality_seconds = [], []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = evomesh.evolve(graded, delta, seed=0, quality_rounds=rounds, min_angle=min_angle)
        seconds.append(time.perf_counter() - t0)
        quality_seconds.append(out.stats["seconds_quality"])
    assert out is not None
    angles = smallest_angles(out.points, out.triangles)
    stats = out.stats
    return {
        "points": len(out.points),
        "inserted": int(stats["quality_points_added"]),
        "min_angle": float(angles.min()),
        "median_angle": float(np.median(angles)),
        "p10_angle": float(np.percentile(angles, 10)),
        "below_percent": float(100.0 * np.mean(angles < min_angle - 1e-9)),
        "rounds": int(stats.get("quality_rounds", 0)),
        "capped": bool(stats["quality_capped"]),
        "stalled": bool(stats.get("quality_stalled", 0)),
        "round_limit": bool(stats.get("quality_round_limit", 0)),
        "quality_seconds": float(np.median(quality_seconds)),
        "step_seconds": float(np.median(seconds)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default="1e4,1e5")
    parser.add_argument("--min-angles", default="30")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    rows = []
    header = (f"{'size':>8} {'angle':>5} {'pass':>7} {'points':>8} {'inserted':>8} {'min':>7} {'median':>7} "
              f"{'p10':>7} {'below%':>7} {'rounds':>6} {'t_qual':>7} {'t_step':>7} {'ratio_q':>7}")
    print(header)
    for size in (float(s) for s in args.sizes.split(",")):
        graded, delta, _ = graded_case(size, None)
        for min_angle in (float(a) for a in args.min_angles.split(",")):
            serial = run_pass(graded, delta, False, min_angle, args.repeats)
            rounds = run_pass(graded, delta, True, min_angle, args.repeats)
            rounds["quality_ratio"] = rounds["quality_seconds"] / serial["quality_seconds"]
            rounds["step_ratio"] = rounds["step_seconds"] / serial["step_seconds"]
            for name, r in (("serial", serial), ("rounds", rounds)):
                flags = "".join(f" {k}" for k in ("capped", "stalled", "round_limit") if r[k])
                ratio = f"{r['quality_ratio']:7.2f}" if "quality_ratio" in r else f"{'':>7}"
                print(f"{len(graded.points):8d} {min_angle:5.1f} {name:>7} {r['points']:8d} {r['inserted']:8d} "
                      f"{r['min_angle']:7.3f} {r['median_angle']:7.3f} {r['p10_angle']:7.3f} {r['below_percent']:7.3f} {r['rounds']:6d} "
                      f"{r['quality_seconds']:7.3f} {r['step_seconds']:7.3f} {ratio}{flags}", flush=True)
            rows.append({"input_points": len(graded.points), "min_angle": min_angle, "serial": serial,
                         "rounds": rounds})
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
