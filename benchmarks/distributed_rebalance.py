"""DistributedMesh.rebalance: balance before and after, bytes moved, time against scatter.

Run under MPI, once per rank count (oversubscribing a small machine is fine)::

    for p in 2 4 8; do
        .venv/bin/mpiexec -n $p .venv/bin/python benchmarks/distributed_rebalance.py --points 1e4 1e5
    done
    for p in 2 4; do
        .venv/bin/mpiexec -n $p .venv/bin/python benchmarks/distributed_rebalance.py --points 1e6 --repeat 1
    done

The mesh is graded (a jittered lattice of the unit square with x mapped to
x^2: dense near x = 0) and given to ``from_local`` in x-stripes of equal width,
a deliberately skewed partition (what a code that cuts its domain by
coordinates hands over). Rank 0 prints one table row per size: the point
balance (largest owned count over the mean) before and after ``rebalance()``,
the bytes ``rebalance`` sends per point (all ranks' sends: every
point-to-point exchange and the halo exchange it makes), the same for
``scatter`` of the same mesh from rank 0, and the seconds of ``rebalance``
against the seconds of ``scatter`` in the same run (the ratio is the figure to
compare between machines). Times are the median of ``--repeat`` runs, each
started after a barrier and ended by one. The setup (building the mesh, cutting
the stripes on rank 0 and sending them out) is not timed.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from mpi4py import MPI

import evomesh
import evomesh.distributed as distributed
from evomesh.meshgen import unit_square_mesh

_sent = {"bytes": 0}
_exchange = distributed._exchange
_exchange_halo = distributed.DistributedMesh.exchange_halo


def _counting_exchange(comm, dest, records):
    _sent["bytes"] += int(np.asarray(records).nbytes)
    return _exchange(comm, dest, records)


def _counting_exchange_halo(self, values):
    row = np.asarray(values)[:1].nbytes
    _sent["bytes"] += int(self._send_counts.sum()) * row
    return _exchange_halo(self, values)


distributed._exchange = _counting_exchange  # count the bytes every exchange sends
distributed.DistributedMesh.exchange_halo = _counting_exchange_halo


def timed(comm, call, repeat):
    seconds, result = [], None
    for _ in range(repeat):
        comm.Barrier()
        start = time.perf_counter()
        result = call()
        comm.Barrier()
        seconds.append(time.perf_counter() - start)
    return float(np.median(seconds)), result


def total_bytes(comm, call):
    _sent["bytes"] = 0
    result = call()
    return comm.allreduce(_sent["bytes"]), result


def graded_mesh(n: int) -> evomesh.Mesh:
    base = unit_square_mesh(n)
    return evomesh.Mesh(np.c_[base.points[:, 0] ** 2, base.points[:, 1]], base.triangles)


def stripes(mesh: evomesh.Mesh, size: int) -> list[dict]:
    """from_local's arguments per rank: points owned by x-stripes of equal width,
    each rank holding the triangles with a vertex it owns."""
    x = mesh.points[:, 0]
    owner = np.minimum(np.floor((x - x.min()) / np.ptp(x) * size), size - 1).astype(np.int64)
    pieces = []
    for rank in range(size):
        mine = (owner[mesh.triangles] == rank).any(axis=1)
        used = np.unique(mesh.triangles[mine])
        pieces.append(dict(points=mesh.points[used], triangles=np.searchsorted(used, mesh.triangles[mine]),
                           global_ids=used, owners=owner[used], kind=mesh.kind[used]))
    return pieces


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=float, nargs="+", default=[1e4, 1e5])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        print(f"ranks {comm.size}; times in s (median of {args.repeat}); ratio = rebalance s / scatter s")
        print("| points | ranks | balance before | balance after | rebalance s | scatter s | ratio | "
              "rebalance B/point | scatter B/point |")
        print("|---|---|---|---|---|---|---|---|---|")
    for n in args.points:
        mesh = graded_mesh(int(n)) if comm.rank == 0 else None
        piece = comm.scatter(stripes(mesh, comm.size) if comm.rank == 0 else None, root=0)
        skewed = evomesh.DistributedMesh.from_local(comm=comm, **piece)
        del piece
        before = skewed.partition_stats()["point_balance"]
        rebalance_s, balanced = timed(comm, skewed.rebalance, args.repeat)
        scatter_s, _ = timed(comm, lambda mesh=mesh: evomesh.DistributedMesh.scatter(mesh, comm), args.repeat)
        rebalance_bytes, _ = total_bytes(comm, skewed.rebalance)
        scatter_bytes, _ = total_bytes(comm, lambda mesh=mesh: evomesh.DistributedMesh.scatter(mesh, comm))
        after = balanced.partition_stats()["point_balance"]
        points = comm.allreduce(balanced.n_owned)
        if comm.rank == 0:
            print(f"| {points} | {comm.size} | {before:.3f} | {after:.4f} | {rebalance_s:.3f} | {scatter_s:.3f} | "
                  f"{rebalance_s / scatter_s:.2f} | {rebalance_bytes / points:.0f} | {scatter_bytes / points:.0f} |",
                  flush=True)


if __name__ == "__main__":
    main()
