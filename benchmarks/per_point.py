"""Cost per input point of one evolve step against size (memory and time per point).

For each scenario of ``compare_peers.py`` (``front``: the graded mesh of
``bench_evolve.py`` with the band moved; ``band-coarsen``; ``uniform-coarsen``)
and each size, one fresh process builds the mesh (``compare_peers.scenario``,
not timed) and runs ``evomesh.evolve(mesh, delta, seed=0)`` with the current
defaults ``--repeats`` times: wall and CPU seconds (user + system, all threads)
per input point, the stage seconds of ``stats``, and the step's peak RSS
(``VmHWM`` after a reset, first repeat; it includes the input mesh and the
interpreter) in bytes per input point.

While the first repeat runs, this (parent) process samples the worker's
``VmRSS`` every few milliseconds; the time of the highest sample, laid against
the stage seconds in the order ``stats`` lists them, names the stage that sets
the peak (approximate: stages that overlap in threads are laid end to end).

Rows go to ``--json`` (appended per size, so a long run keeps what it has);
``--plot`` draws ``benchmarks/seconds_per_point.png`` from that file::

    .venv/bin/python benchmarks/per_point.py --scenarios front,band-coarsen,uniform-coarsen \\
        --sizes 1e4,1e5,1e6 --json benchmarks/per_point.json
    .venv/bin/python benchmarks/per_point.py --append --trim --scenarios front --sizes 1e6,1e7 --repeats 1 \\
        --max-samples 1e10 --json benchmarks/per_point.json
    .venv/bin/python benchmarks/per_point.py --tables --plot --json benchmarks/per_point.json
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def _cpu() -> float:
    u = resource.getrusage(resource.RUSAGE_SELF)
    return u.ru_utime + u.ru_stime


def malloc_trim() -> bool:
    """Give the heap that building the input freed back to the OS (glibc), so the step's peak is not
    measured on top of memory the set-up left behind."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6").malloc_trim(0)
        return True
    except OSError:
        return False


def output_hash(mesh) -> str:
    """sha256 of the output mesh's arrays, as tests/pinned.py digests them (16 hex digits)."""
    import hashlib

    import numpy as np

    h = hashlib.sha256()
    for name in ("points", "triangles", "segments", "segment_is_boundary", "kind", "origin"):
        h.update(np.ascontiguousarray(getattr(mesh, name)).tobytes())
    return h.hexdigest()[:16]


def worker(name: str, size: float, repeats: int, trim: bool = False, max_samples: float | None = None) -> dict:
    import numpy as np

    import evomesh
    from bench_evolve import reset_peak_memory, status_mib
    from compare_peers import scenario

    t0 = time.perf_counter()
    mesh, delta, _ = scenario(name, size)
    setup = time.perf_counter() - t0
    walls, cpus, stages, stage_cpus, marks = [], [], {}, {}, None
    stage_peaks: dict = {}
    digest = ""
    step_peak = input_rss = float("nan")
    for r in range(repeats):
        if trim:
            malloc_trim()
        tracked = reset_peak_memory()
        if r == 0:
            input_rss = status_mib("VmRSS")
            start = time.time()
        t0, c0 = time.perf_counter(), _cpu()
        out = evomesh.evolve(mesh, delta, seed=0, **({} if max_samples is None else {"max_samples": max_samples}))
        walls.append(time.perf_counter() - t0)
        cpus.append(_cpu() - c0)
        if r == 0:
            marks = (start, time.time())
            if tracked:
                step_peak = status_mib("VmHWM")
            stage_order = [k[len("seconds_"):] for k in out.stats if k.startswith("seconds_")]
            first_stages = {k: float(out.stats["seconds_" + k]) for k in stage_order}
            # EVOMESH_STAGE_PROFILE (--profile): the step resets VmHWM at every stage, so its peak is the
            # largest stage peak (or what came after the last stage)
            stage_peaks = {k[len("memory_peak_mib_"):]: float(v) for k, v in out.stats.items()
                           if k.startswith("memory_peak_mib_")}
            if stage_peaks:
                step_peak = max(step_peak, *stage_peaks.values())
            digest = output_hash(out)
        for k, v in out.stats.items():
            if k.startswith("seconds_"):
                stages.setdefault(k[len("seconds_"):], []).append(float(v))
            if k.startswith("cpu_seconds_"):
                stage_cpus.setdefault(k[len("cpu_seconds_"):], []).append(float(v))
        del out
    n = mesh.n_points
    return {
        "scenario": name, "target": size, "trim": trim, "n_input_points": n, "repeats": repeats, "setup_seconds": setup,
        "wall_seconds": float(np.median(walls)), "cpu_seconds": float(np.median(cpus)),
        "wall_all": walls, "cpu_all": cpus,
        "wall_per_point": float(np.median(walls)) / n, "cpu_per_point": float(np.median(cpus)) / n,
        "stage_seconds": {k: float(np.median(v)) for k, v in stages.items()}, "stage_order": stage_order,
        "first_stage_seconds": first_stages,
        "step_peak_mib": step_peak, "input_rss_mib": input_rss,
        "step_peak_bytes_per_point": step_peak * 2**20 / n,
        "step_marks": marks,
        "output_hash": digest,
        "stage_cpu_seconds": {k: float(np.median(v)) for k, v in stage_cpus.items()},
        "stage_peak_mib": stage_peaks,
    }


def sample_rss(pid: int, samples: list, stop: threading.Event, period: float = 0.005) -> None:
    path = f"/proc/{pid}/statm"
    page = os.sysconf("SC_PAGE_SIZE")
    while not stop.is_set():
        try:
            with open(path) as f:
                rss = int(f.read().split()[1]) * page
        except (OSError, ValueError, IndexError):
            break
        samples.append((time.time(), rss))
        time.sleep(period)


def peak_stage(row: dict, samples: list) -> dict:
    start, end = row["step_marks"]
    inside = [(t, b) for t, b in samples if start <= t <= end]
    if not inside:
        return {}
    t_peak, b_peak = max(inside, key=lambda s: s[1])
    offset = t_peak - start
    clock, stage = 0.0, "after the stages (output to Python)"
    for name in row["stage_order"]:
        if name == "total":
            continue
        clock += row["first_stage_seconds"].get(name, 0.0)
        if offset <= clock:
            stage = name
            break
    return {"peak_sample_mib": b_peak / 2**20, "peak_offset_s": offset, "peak_stage": stage,
            "rss_samples": len(inside)}


def run(args: argparse.Namespace) -> None:
    rows = []
    if args.json and os.path.exists(args.json) and args.append:
        with open(args.json) as f:
            rows = json.load(f)
    for name in args.scenarios.split(","):
        for size in (float(s) for s in args.sizes.split(",")):
            load = os.getloadavg()
            cmd = [sys.executable, os.path.abspath(__file__), "--worker", name, str(size), "--repeats", str(args.repeats)]
            if args.trim:
                cmd.append("--trim")
            if args.max_samples is not None:
                cmd += ["--max-samples", str(args.max_samples)]
            env = dict(os.environ)
            if args.profile:
                env["EVOMESH_STAGE_PROFILE"] = "1"
            proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
            samples: list = []
            stop = threading.Event()
            th = threading.Thread(target=sample_rss, args=(proc.pid, samples, stop), daemon=True)
            th.start()
            out, err = proc.communicate()
            stop.set()
            th.join()
            if proc.returncode != 0:
                print(f"{name} {size:.0e}: failed: {err.strip().splitlines()[-1:]}", flush=True)
                continue
            row = json.loads(out)
            row["loadavg_before"] = load
            row["loadavg_after"] = os.getloadavg()
            row.update(peak_stage(row, samples))
            if row.get("stage_peak_mib"):  # measured in the step itself (--profile)
                row["peak_stage"] = max(row["stage_peak_mib"], key=row["stage_peak_mib"].get)
            rows.append(row)
            print(f"{name:16s} {size:8.0e} n={row['n_input_points']:9d} wall {row['wall_seconds']:8.3f} s "
                  f"({row['wall_per_point'] * 1e6:.2f} us/pt) CPU {row['cpu_seconds']:8.2f} s "
                  f"({row['cpu_per_point'] * 1e6:.2f} us/pt) peak {row['step_peak_mib']:.0f} MiB "
                  f"({row['step_peak_bytes_per_point']:.0f} B/pt, at {row.get('peak_stage')}) "
                  f"load {load[0]:.2f}->{row['loadavg_after'][0]:.2f} output {row['output_hash']}", flush=True)
            if args.json:
                with open(args.json, "w") as f:
                    json.dump(rows, f, indent=1)


def plot(path: str, png: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with open(path) as f:
        rows = json.load(f)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for i, name in enumerate(dict.fromkeys(r["scenario"] for r in rows)):
        latest = {r["target"]: r for r in rows if r["scenario"] == name}  # a size run again: its last run
        rs = sorted(latest.values(), key=lambda r: r["n_input_points"])
        n = [r["n_input_points"] for r in rs]
        color = f"C{i}"
        ax.plot(n, [r["wall_per_point"] * 1e6 for r in rs], "o-", color=color, label=f"{name}, wall")
        ax.plot(n, [r["cpu_per_point"] * 1e6 for r in rs], "s--", color=color, alpha=0.6, label=f"{name}, CPU")
    ax.set_xscale("log")
    ax.set_xlabel("input points")
    ax.set_ylabel("µs per input point (one evolve step)")
    ax.set_ylim(bottom=0)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("evomesh.evolve, defaults, 2 shared cores")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    print(f"wrote {png}")


def locate_peak(row: dict) -> str:
    """The stage whose (end-to-end) time span holds the highest RSS sample (with --profile: the stage
    whose own peak RSS is highest)."""
    if row.get("stage_peak_mib"):
        return max(row["stage_peak_mib"], key=row["stage_peak_mib"].get)
    if "peak_offset_s" not in row:
        return "?"
    clock = 0.0
    for name in row["stage_order"]:
        if name == "total":
            continue
        clock += row["first_stage_seconds"].get(name, 0.0)
        if row["peak_offset_s"] <= clock:
            return name
    return "after the stages (output to Python)"


def tables(path: str) -> None:
    with open(path) as f:
        rows = json.load(f)
    rows.sort(key=lambda r: (r["scenario"] != "front", r["scenario"], r["n_input_points"], bool(r.get("trim"))))
    print("| scenario | trim | input pts | wall (s) | CPU (s) | wall µs / pt | CPU µs / pt | wall / wall at 1e5 | CPU / CPU at 1e5 "
          "| step peak (MiB) | input RSS (MiB) | peak B / input pt | (peak - input) B / input pt | peak during | load avg (1 min) before -> after |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|")
    for r in rows:
        base = [b for b in rows if b["scenario"] == r["scenario"] and b["target"] == 1e5 and not b.get("trim")][-1:]
        rw = rc = "-"
        if base:
            rw = f"{r['wall_per_point'] / base[0]['wall_per_point']:.2f}"
            rc = f"{r['cpu_per_point'] / base[0]['cpu_per_point']:.2f}"
        n = r["n_input_points"]
        print(f"| {r['scenario']} | {'yes' if r.get('trim') else 'no'} | {n:,} | {r['wall_seconds']:.3f} | {r['cpu_seconds']:.2f} | {r['wall_per_point'] * 1e6:.2f} "
              f"| {r['cpu_per_point'] * 1e6:.2f} | {rw} | {rc} | {r['step_peak_mib']:,.0f} | {r['input_rss_mib']:,.0f} "
              f"| {r['step_peak_bytes_per_point']:,.0f} | {(r['step_peak_mib'] - r['input_rss_mib']) * 2**20 / n:,.0f} "
              f"| {locate_peak(r)} | {r['loadavg_before'][0]:.2f} -> {r['loadavg_after'][0]:.2f} |")
    print()
    for r in rows:
        if r["target"] < 1e6:
            continue
        st = r["stage_seconds"]
        total = st.get("total", r["wall_seconds"])
        names = [k for k in r["stage_order"] if k != "total"]
        print(f"Stages, {r['scenario']} {r['n_input_points']:,} (medians of {r['repeats']}; total {total:.2f} s, "
              f"evolve wall {r['wall_seconds']:.2f} s):\n")
        print("| stage | " + " | ".join(names) + " | rest of evolve | evolve |")
        print("|---|" + "---:|" * (len(names) + 2))
        rest = r["wall_seconds"] - sum(st[k] for k in names)
        print("| s | " + " | ".join(f"{st[k]:.2f}" for k in names) + f" | {rest:.2f} | {r['wall_seconds']:.2f} |")
        print("| % of evolve | " + " | ".join(f"{100 * st[k] / r['wall_seconds']:.1f}" for k in names)
              + f" | {100 * rest / r['wall_seconds']:.1f} | 100 |")
        cpu = r.get("stage_cpu_seconds") or {}
        if cpu:
            print("| CPU s / wall s | " + " | ".join(f"{cpu[k] / st[k]:.2f}" if k in cpu and st[k] > 0 else "-"
                                                     for k in names) + " | | |")
        peaks = r.get("stage_peak_mib") or {}
        if peaks:
            print("| peak RSS (MiB) | " + " | ".join(f"{peaks[k]:,.0f}" if k in peaks else "-" for k in names) + " | | |")
        print(f"\noutput {r.get('output_hash', '?')}\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default="front")
    parser.add_argument("--sizes", default="1e4,1e5,1e6")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", default=str(HERE / "per_point.json"))
    parser.add_argument("--append", action="store_true", help="keep the rows already in --json")
    parser.add_argument("--plot", action="store_true", help="only draw --png from --json")
    parser.add_argument("--tables", action="store_true", help="only print the markdown tables of --json")
    parser.add_argument("--png", default=str(HERE / "seconds_per_point.png"))
    parser.add_argument("--trim", action="store_true",
                        help="malloc_trim(0) before each step, so the input RSS is the live heap, not the set-up's leftovers")
    parser.add_argument("--max-samples", type=float, default=None,
                        help="evolve's max_samples (the default 5e7 refuses the front step above about 6e6 points)")
    parser.add_argument("--profile", action="store_true",
                        help="EVOMESH_STAGE_PROFILE=1: CPU seconds and peak RSS of every stage, measured in the step")
    parser.add_argument("--worker", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(worker(args.worker[0], float(args.worker[1]), args.repeats, args.trim, args.max_samples)))
    elif args.plot or args.tables:
        if args.tables:
            tables(args.json)
        if args.plot:
            plot(args.json, args.png)
    else:
        run(args)


if __name__ == "__main__":
    main()
