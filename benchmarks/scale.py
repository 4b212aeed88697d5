"""Scale test: one evolve step on graded meshes of 1e6 and 1e7 points.

Builds the graded meshes of ``bench_evolve.py`` (a grid evolved once towards a
band of fine spacing) and times one ``evolve`` step with the band moved, each
size in a fresh process: wall time of the set-up and of the step, and the peak
RSS of the step (``VmHWM`` after a reset) and of the whole process
(``resource.getrusage``). ``max_samples`` is raised for the step (about 8
samples per input point are drawn, so the default 5e7 refuses steps above
about 6e6 points).

A size that would not fit in memory is not started: the peak per input point
measured on the sizes run before it (or ``--bytes-per-point``) times the size
must stay below ``--memory-fraction`` of MemAvailable. The largest size that
fits is run in its place and the bound is printed.

Usage::

    python benchmarks/scale.py [--sizes 1e6,1e7] [--quality on|off] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import time


sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_evolve  # noqa: E402  (same directory)

import evomesh  # noqa: E402


def mem_available_mib() -> float:
    with open("/proc/meminfo") as f:
        for line in f:
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) / 1024.0
    return float("inf")


def worker(size: float, quality: bool) -> dict:
    t0 = time.perf_counter()
    graded, delta, info = bench_evolve.graded_case(size, None)
    setup_seconds = time.perf_counter() - t0
    setup_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    tracked = bench_evolve.reset_peak_memory()
    input_rss = bench_evolve.status_mib("VmRSS")
    t0 = time.perf_counter()
    out = evomesh.evolve(graded, delta, seed=0, quality=quality, max_samples=1e10)
    step_seconds = time.perf_counter() - t0
    step_peak = bench_evolve.status_mib("VmHWM") if tracked else float("nan")
    stats = dict(out.stats)
    samples = stats.get("n_interior_samples_drawn", 0) + stats.get("n_segment_samples", 0)
    return {
        "target": size,
        "n_input_points": graded.n_points,
        "n_output_points": out.n_points,
        "samples_per_input_point": samples / graded.n_points,
        "setup_seconds": setup_seconds,
        "step_seconds": step_seconds,
        "stage_seconds": {k[len("seconds_"):]: v for k, v in stats.items() if k.startswith("seconds_")},
        "input_rss_mib": input_rss,
        "step_peak_mib": step_peak,
        "setup_peak_mib": setup_peak,
        "process_peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "min_angle": stats.get("min_angle", float("nan")),
        "grid_side": info["grid_side"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1e6,1e7")
    parser.add_argument("--quality", choices=["on", "off"], default=None)
    parser.add_argument("--bytes-per-point", type=float, default=None,
                        help="peak bytes per input point assumed before a size has been measured")
    parser.add_argument("--memory-fraction", type=float, default=0.8)
    parser.add_argument("--json")
    parser.add_argument("--worker", type=float, help=argparse.SUPPRESS)
    args = parser.parse_args()
    quality = evomesh.FRFC_DEFAULTS.get("quality", False) if args.quality is None else args.quality == "on"
    if args.worker is not None:
        print(json.dumps(worker(args.worker, quality)))
        return

    print(f"# scale.py: evomesh {evomesh.__version__}, {os.cpu_count()} cpus, quality={'on' if quality else 'off'}, "
          f"MemAvailable {mem_available_mib():.0f} MiB")
    print("\n| target | input pts | output pts | samples drawn / input pt | set-up (s) | step (s) | step peak (MiB) "
          "| process peak (MiB) | peak bytes / input pt |")
    print("|---|---|---|---|---|---|---|---|---|")
    bytes_per_point = args.bytes_per_point
    results = []
    for size in (float(s) for s in args.sizes.split(",")):
        budget = args.memory_fraction * mem_available_mib() * 2**20
        run = size
        if bytes_per_point is not None and bytes_per_point * size > budget:
            fits = budget / bytes_per_point
            unit = 10 ** math.floor(math.log10(fits))
            run = math.floor(fits / unit) * unit  # rounded down to one digit
            print(f"| {size:.0e} | not run: needs about {bytes_per_point * size / 2**30:.1f} GiB "
                  f"({bytes_per_point:.0f} B per input point), {budget / 2**30:.1f} GiB available; "
                  f"largest that fits about {fits:.2g}, running {run:.0e} | | | | | | | |")
            if run < 1e5:
                continue
        cmd = [sys.executable, os.path.abspath(__file__), "--worker", str(run), "--quality", "on" if quality else "off"]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            print(f"| {run:.0e} | failed: {done.stderr.strip().splitlines()[-1] if done.stderr else done.returncode} |")
            continue
        r = json.loads(done.stdout)
        results.append(r)
        bytes_per_point = max(r["process_peak_mib"] * 2**20 / r["n_input_points"], bytes_per_point or 0)
        print(f"| {run:.0e} | {r['n_input_points']} | {r['n_output_points']} | {r['samples_per_input_point']:.1f} "
              f"| {r['setup_seconds']:.1f} | {r['step_seconds']:.1f} | {r['step_peak_mib']:.0f} "
              f"| {r['process_peak_mib']:.0f} | {r['process_peak_mib'] * 2**20 / r['n_input_points']:.0f} |", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
