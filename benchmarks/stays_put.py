"""Does a mesh stay put when the request does not change?

For a uniform, a graded (h = 0.004 + 0.02 x), a curved (disc with a hole and its
circles), a tagged mesh, a square with two holes and an L-shape (about 1.2e4
points each at --scale 1): first ``new = evolve(m, size=h)``, then
``evolve(size=h)`` and ``evolve(delta=1)`` step after step. Printed per step:
the points changed ((points not kept + points added) / n of the input), the
median edge length over the request, and the cost of the step against a full
step (``incremental=False``) on the same input, timed in the same run: the
whole call (``ratio``) and the core's own seconds (``core``, stats
``seconds_total``: without the Python checks and the Mesh around it), medians
of ``--repeats`` runs of each (``--clock cpu``: the whole call's process CPU
time instead of wall time, steadier on a shared machine; ``core`` stays
wall time); ``empty``
is 1 where the step was the empty-scope step (cpp/src/empty_scope.cpp: the
input certified to be the full step's output, returned without the stages).
The goal: a stays-put step costs at most 10 % of a full step.

    .venv/bin/python benchmarks/stays_put.py [--steps 5] [--scale 1] [--repeats 3] [--cases uniform,graded]
        [--clock wall|cpu]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import evomesh
from evomesh.geometry import Circle
from evomesh.meshgen import HOLE_TAG, OUTER_TAG, disc_with_hole_mesh, polygon_mesh, unit_square_mesh


def changed_fraction(old: evomesh.Mesh, new: evomesh.Mesh) -> float:
    """(input points not kept + output points that are new) / input points."""
    origin = np.asarray(new.origin)
    kept = np.unique(origin[origin >= 0]).size
    added = int((origin < 0).sum())
    return ((old.n_points - kept) + added) / old.n_points


def median_edge_over_request(mesh: evomesh.Mesh, size) -> float:
    t = np.asarray(mesh.triangles)
    edges = np.unique(np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1), axis=0)
    p = np.asarray(mesh.points)
    length = np.linalg.norm(p[edges[:, 0]] - p[edges[:, 1]], axis=1)
    mid = 0.5 * (p[edges[:, 0]] + p[edges[:, 1]])
    request = size(mid) if callable(size) else np.full(len(edges), float(size))
    return float(np.median(length / request))


def tagged(mesh: evomesh.Mesh) -> evomesh.Mesh:
    p, t, s = np.array(mesh.points), np.array(mesh.triangles), np.array(mesh.segments)
    mid = p[s].mean(axis=1)
    segment_tags = np.select([mid[:, 1] < 0.5, mid[:, 0] > 0.5], [1 + (mid[:, 0] > 0.5), 3], 4)
    centre = p[t].mean(axis=1)
    triangle_tags = np.where(np.hypot(*(centre - 0.5).T) < 0.3, 7, 8)
    required = np.zeros(len(p), bool)
    required[[5, len(p) // 2, len(p) - 7]] = True
    return evomesh.Mesh(p, t, s, segment_tags=segment_tags, triangle_tags=triangle_tags, required=required)


def ring(centre, radius: float, k: int) -> np.ndarray:
    angle = np.linspace(0, 2 * np.pi, k, endpoint=False)
    return np.asarray(centre, float) + radius * np.c_[np.cos(angle), np.sin(angle)]


def cases(scale: float):
    geometry = {OUTER_TAG: Circle((0, 0), 1.0), HOLE_TAG: Circle((0, 0), 0.35)}
    h_uniform = 0.01 / np.sqrt(scale)
    yield "uniform", unit_square_mesh(int(4000 * scale)), h_uniform, None
    yield "graded", unit_square_mesh(int(4000 * scale)), lambda x: (0.004 + 0.02 * x[:, 0]) / np.sqrt(scale), None
    yield "curved", disc_with_hole_mesh(0.03 / np.sqrt(scale)), 0.016 / np.sqrt(scale), geometry
    yield "tagged", tagged(unit_square_mesh(int(4000 * scale))), h_uniform, None
    square = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], float)
    yield "holes", polygon_mesh([square, ring((0.3, 0.3), 0.12, 24), ring((0.7, 0.65), 0.15, 5)], h_uniform), \
        h_uniform, None
    l_shape = np.array([(0, 0), (1, 0), (1, 0.5), (0.5, 0.5), (0.5, 1), (0, 1)], float)
    yield "L-shape", polygon_mesh([l_shape], 0.75 * h_uniform), 0.75 * h_uniform, None


def timed(repeats: int, function, *args, clock=time.perf_counter, **kwargs):
    """The last result, the median seconds of the whole call on `clock` and the
    median core seconds (stats seconds_total, wall time)."""
    wall, core = [], []
    for _ in range(repeats):
        start = clock()
        result = function(*args, **kwargs)
        wall.append(clock() - start)
        core.append(result.stats["seconds_total"])
    return result, float(np.median(wall)), float(np.median(core))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--scale", type=float, default=1.0, help="point count factor of the meshes")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--stages", action="store_true", help="the costliest stages of each case's last step")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each step timed (medians)")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                        help="the whole call's time: wall, or process CPU time (steadier when the machine is shared)")
    parser.add_argument("--cases", default="uniform,graded,curved,tagged,holes,L-shape",
                        help="comma-separated case names")
    args = parser.parse_args()
    kw = {"threads": args.threads}
    clock = time.perf_counter if args.clock == "wall" else time.process_time
    print(f"{'case':8} {'request':7} {'step':>4} {'n_in':>7} {'n_out':>7} {'changed':>8} {'edge/h':>7} "
          f"{'t_step':>7} {'t_full':>7} {'ratio':>6} {'core':>6} {'empty':>5}")
    for name, mesh, size, geometry in cases(args.scale):
        if name not in args.cases.split(","):
            continue
        first = evomesh.evolve(mesh, size=size, geometry=geometry, **kw)
        print(f"{name:8} {'first':7} {0:>4} {mesh.n_points:>7} {first.n_points:>7} {'':>8} "
              f"{median_edge_over_request(first, size):7.3f}")
        for request in ("size", "delta"):
            current = first
            for step in range(1, args.steps + 1):
                what = {"size": size} if request == "size" else {"delta": 1.0}
                new, seconds, core_step = timed(args.repeats, evomesh.evolve, current, geometry=geometry, clock=clock,
                                                 **what, **kw)
                reference, full, core_full = timed(args.repeats, evomesh.evolve, current, geometry=geometry,
                                                   clock=clock, incremental=False, **what, **kw)
                core = core_step / core_full
                print(f"{name:8} {request:7} {step:>4} {current.n_points:>7} {new.n_points:>7} "
                      f"{changed_fraction(current, new):8.2%} {median_edge_over_request(new, size):7.3f} "
                      f"{seconds:7.3f} {full:7.3f} {seconds / full:6.2f} {core:6.3f} "
                      f"{int(new.stats.get('empty_scope', 0)):>5}")
                if args.stages and step == args.steps:
                    stages = sorted(((v, k[8:]) for k, v in new.stats.items()
                                     if k.startswith("seconds_") and k != "seconds_total"), reverse=True)
                    python = seconds - new.stats.get("seconds_total", 0.0)
                    print("    stages of the last step (s): " + ", ".join(f"{k} {v:.3f}" for v, k in stages[:6])
                          + f"; outside the core {python:.3f}")
                current = new


if __name__ == "__main__":
    main()
