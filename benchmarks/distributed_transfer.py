"""transfer / transfer_cells on two DistributedMesh against the serial transfers
of the same meshes, in the same run.

Run under MPI, once per rank count (oversubscribing a small machine is fine)::

    for p in 2 4; do
        .venv/bin/mpiexec -n $p .venv/bin/python benchmarks/distributed_transfer.py --points 1e5 1e6
    done

The root builds old (``unit_square_mesh``) and new = one step refining toward
a circle front and coarsening elsewhere (``evolve``), scatters both, times the
serial transfers on the root (one process, no MPI), then the distributed ones
on all ranks (started after a barrier, ended by one; the median of
``--repeat`` runs). One row per method: seconds serial, seconds distributed,
their ratio, CG iterations (conservative), and the bytes sent between ranks per
new point (records of old triangles, their values, and the right-hand side rows
of halo points; summed over ranks). For "linear" the serial baseline is the
transfer of the gathered meshes (no lineage: the points are located, as the
distributed transfer does); the step's own lineage (no search) is shown too.
"""

from __future__ import annotations

import argparse
import time
from functools import partial

import numpy as np
from mpi4py import MPI

import evomesh
from evomesh.distributed import transfer as distributed_transfer
from evomesh.meshgen import unit_square_mesh


def _front(points: np.ndarray) -> np.ndarray:
    r = np.hypot(points[:, 0] - 0.5, points[:, 1] - 0.5)
    return np.where(np.abs(r - 0.3) < 0.1, 0.6, 1.3)


def _smooth(points: np.ndarray) -> np.ndarray:
    return np.sin(3.0 * points[:, 0]) + points[:, 1] ** 2


def _median_seconds(comm, call, repeat: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeat):
        comm.Barrier()
        start = time.perf_counter()
        result = call()
        comm.Barrier()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), result


def _serial_seconds(old, new, g_old, g_new) -> dict[str, float]:
    """The serial transfers on the root: located (gathered meshes, no lineage), with the lineage, P1, P0."""
    u = _smooth(old.points)
    c = _smooth(old.points[old.triangles].mean(axis=1))
    calls = {"linear": partial(evomesh.transfer, g_old, g_new, u),
             "linear_lineage": partial(evomesh.transfer, old, new, u),
             "conservative": partial(evomesh.transfer, old, new, u, method="conservative"),
             "cells": partial(evomesh.transfer_cells, old, new, c)}
    seconds = {}
    for name, call in calls.items():
        start = time.perf_counter()
        call()
        seconds[name] = time.perf_counter() - start
    return seconds


def _one_size(comm, n: float, repeat: int) -> None:
    old = new = None
    if comm.rank == 0:
        old = unit_square_mesh(int(n))
        new = evomesh.evolve(old, _front(old.points), seed=0)
    d_old = evomesh.DistributedMesh.scatter(old, comm)
    d_new = evomesh.DistributedMesh.scatter(new, comm)
    n_new = comm.allreduce(d_new.n_owned)
    g_old, g_new = d_old.gather(), d_new.gather()
    serial = comm.bcast(_serial_seconds(old, new, g_old, g_new) if comm.rank == 0 else None)
    u_owned = _smooth(d_old.owned_points)
    c_owned = _smooth(d_old.points[d_old.triangles].mean(axis=1))
    owned_old = comm.allreduce(len(d_old.triangles))
    rows = []
    for name in ("linear", "conservative", "cells"):
        stats: dict = {}
        if name == "cells":
            call = partial(distributed_transfer.transfer_cells, d_old, d_new, c_owned, stats=stats)
        else:
            call = partial(distributed_transfer.transfer, d_old, d_new, u_owned, method=name, stats=stats)
        seconds, _ = _median_seconds(comm, call, repeat)
        rows.append((name, seconds, stats.get("cg_iterations", 0), comm.allreduce(stats["bytes_moved"]) / n_new,
                     comm.allreduce(stats["old_triangles_held"]) / owned_old))
    if comm.rank == 0:
        for name, seconds, iterations, per_point, held in rows:
            print(f"{n_new:>9d} {name:>13} {serial[name]:>9.3f} {seconds:>9.3f} {serial[name] / seconds:>6.2f} "
                  f"{iterations:>6d} {per_point:>8.1f} {held:>10.3f}")
        print(f"{n_new:>9d} {'(lineage)':>13} {serial['linear_lineage']:>9.3f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=float, nargs="+", default=[1e5])
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        print(f"ranks {comm.size}")
        print(f"{'points':>9} {'method':>13} {'serial s':>9} {'distr. s':>9} {'ratio':>6} {'CG it':>6} "
              f"{'B/point':>8} {'held/owned':>10}")
    for n in args.points:
        _one_size(comm, n, args.repeat)


if __name__ == "__main__":
    main()
