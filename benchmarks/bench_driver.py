"""A whole time step through the driver against evolve alone.

One moving-front step on the graded mesh of bench_evolve.py (about --size
points): ``evolve`` alone, then ``Driver.step`` on the same mesh and delta
(evolve + transfer of two fields + statistics), and ``transfer`` of a field with
the step's lineage against the same transfer with a point location in the old
mesh (what transfer did before the lineage). Medians of --repeats, measured in
one process; evolve and Driver.step alternate (A, B, A, B, ...) so that a
shared machine's load falls on both alike.

    .venv/bin/python benchmarks/bench_driver.py --size 2e5 --repeats 5
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import evomesh
from bench_evolve import graded_case
from evomesh.mesh import Mesh


def median_seconds(work, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        work()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=float, default=2e5)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json", default=None, help="write the figures here too")
    args = parser.parse_args()

    mesh, delta, _ = graded_case(args.size, None)
    fields = {"u": np.sin(mesh.points[:, 0] * 7), "v": mesh.points @ [1.0, 2.0]}

    def evolve_alone():
        return evomesh.evolve(mesh, delta, seed=1)

    def driver_step():
        driver = evomesh.Driver(mesh, lambda m, d: delta, fields=fields, seed=0)
        return driver.step(delta=delta)

    new = evolve_alone()
    blind = Mesh._trusted(new.points, new.triangles, new.segments, new.segment_is_boundary, new.kind, new.origin)
    evolve_times, step_times = [], []
    for _ in range(args.repeats):  # alternated
        for work, times in ((evolve_alone, evolve_times), (driver_step, step_times)):
            t0 = time.perf_counter()
            work()
            times.append(time.perf_counter() - t0)
    evolve_s, step_s = float(np.median(evolve_times)), float(np.median(step_times))
    with_lineage = median_seconds(lambda: evomesh.transfer(mesh, new, fields["u"]), args.repeats)
    located = median_seconds(lambda: evomesh.transfer(mesh, blind, fields["u"]), args.repeats)
    gap = float(np.abs(evomesh.transfer(mesh, new, fields["v"]) - new.points @ [1.0, 2.0]).max())
    figures = {
        "input_points": mesh.n_points,
        "output_points": new.n_points,
        "new_points": int((new.origin < 0).sum()),
        "evolve_s": evolve_s,
        "driver_step_s": step_s,
        "driver_step_over_evolve": step_s / evolve_s,
        "evolve_all_s": evolve_times,
        "driver_step_all_s": step_times,
        "pairwise_ratios": [b / a for a, b in zip(evolve_times, step_times)],
        "transfer_lineage_s": with_lineage,
        "transfer_point_location_s": located,
        "parent_map_s": float(new.stats["seconds_parent_map"]),
        "parent_walk_steps_per_new_point": float(new.stats["parent_walk_steps"]) / max(1, int((new.origin < 0).sum())),
        "parent_located_globally": float(new.stats["parent_located_globally"]),
        "linear_field_error": gap,
    }
    for name, value in figures.items():
        if isinstance(value, list):
            value = "[" + ", ".join(f"{v:.4g}" for v in value) + "]"
        print(f"{name:34s} {value:.4g}" if isinstance(value, float) else f"{name:34s} {value}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(figures, f, indent=1)


if __name__ == "__main__":
    main()
