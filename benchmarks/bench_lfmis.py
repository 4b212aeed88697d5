"""The lexical-first MIS stage with one and two threads.

Builds one mesh of a ``compare_peers.py`` scenario (default: ``front`` at 1e6
points, not timed), then runs ``evomesh.evolve(mesh, delta, seed=0,
threads=t)`` alternately for each thread count of ``--threads``, ``--repeats``
times each, in this one process (the machine is shared: medians and ratios
taken within the run). Prints, per thread count, the median of
``stats["seconds_lfmis"]`` and of the step's wall time, their ratios to the
first thread count, and whether every output equals the first one
(``per_point.output_hash``: the arrays ``tests/pinned.py`` digests)::

    .venv/bin/python benchmarks/bench_lfmis.py --size 1e6 --repeats 5 --threads 1,2
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="front")
    parser.add_argument("--size", type=float, default=1e6)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", default="1,2", help="comma-separated thread counts")
    args = parser.parse_args()

    import evomesh
    from compare_peers import scenario
    from per_point import output_hash

    threads = [int(t) for t in args.threads.split(",")]
    mesh, delta, _ = scenario(args.scenario, args.size)
    print(f"{args.scenario}: {mesh.n_points} input points, threads {threads}, {args.repeats} repeats", flush=True)
    lfmis: dict[int, list[float]] = {t: [] for t in threads}
    wall: dict[int, list[float]] = {t: [] for t in threads}
    digests: dict[int, set[str]] = {t: set() for t in threads}
    for r in range(args.repeats):
        for t in threads:
            t0 = time.perf_counter()
            out = evomesh.evolve(mesh, delta, seed=0, threads=t)
            wall[t].append(time.perf_counter() - t0)
            lfmis[t].append(float(out.stats["seconds_lfmis"]))
            digests[t].add(output_hash(out))
            print(f"  repeat {r} threads {t}: lfmis {lfmis[t][-1]:.3f} s, step {wall[t][-1]:.3f} s", flush=True)
            del out
    base = threads[0]
    for t in threads:
        lm, wm = statistics.median(lfmis[t]), statistics.median(wall[t])
        print(f"threads {t}: lfmis median {lm:.3f} s (x{statistics.median(lfmis[base]) / lm:.2f} vs {base}), "
              f"step median {wm:.3f} s (x{statistics.median(wall[base]) / wm:.2f})")
    same = len(set().union(*digests.values())) == 1
    print("outputs equal across thread counts and repeats:", same, sorted(set().union(*digests.values())))


if __name__ == "__main__":
    main()
