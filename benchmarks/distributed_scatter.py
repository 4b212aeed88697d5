"""DistributedMesh.scatter / gather: time, bytes and balance against mesh size and ranks.

Run under MPI, once per rank count (oversubscribing a small machine is fine)::

    for p in 2 4 8; do
        .venv/bin/mpiexec -n $p .venv/bin/python benchmarks/distributed_scatter.py --points 1e4 1e5 1e6
    done

Rank 0 prints one table row per mesh size: seconds for scatter and gather,
the same as a ratio to the baseline ``comm.bcast(mesh)`` (replicating the whole
pickled Mesh on every rank, what a code without a distributed mesh does),
the bytes scatter and gather move (all ranks' sends, counted in the exchanges),
the bytes of one ``exchange_halo`` of a float64 field, the halo size and the
balance (largest owned count over the mean). Times are the median of
``--repeat`` runs, each started after a barrier and ended by one.
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


def _counting_exchange(comm, dest, records):
    _sent["bytes"] += int(np.asarray(records).nbytes)
    return _exchange(comm, dest, records)


distributed._exchange = _counting_exchange  # count the bytes every exchange sends


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=float, nargs="+", default=[1e4, 1e5])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        print(f"ranks {comm.size}; times in s (median of {args.repeat}), ratio = time / bcast(mesh)")
        print("| points | triangles | ranks | bcast s | scatter s | ratio | gather s | ratio | scatter MB | "
              "gather MB | halo exchange kB | halo points / owned | balance triangles | balance points |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for n in args.points:
        mesh = unit_square_mesh(int(n)) if comm.rank == 0 else None
        bcast_s, _ = timed(comm, lambda mesh=mesh: comm.bcast(mesh, root=0), args.repeat)
        scatter_s, d = timed(comm, lambda mesh=mesh: evomesh.DistributedMesh.scatter(mesh, comm), args.repeat)
        gather_s, back = timed(comm, d.gather, args.repeat)
        scatter_bytes, _ = total_bytes(comm, lambda mesh=mesh: evomesh.DistributedMesh.scatter(mesh, comm))
        gather_bytes, _ = total_bytes(comm, d.gather)
        if comm.rank == 0:
            assert np.array_equal(back.points, mesh.points) and np.array_equal(back.triangles, mesh.triangles)
        halo_bytes = comm.allreduce(int(d._recv_counts.sum()) * 8)
        stats = d.partition_stats()
        halo_ratio = stats["halo_points"].sum() / stats["owned_points"].sum()
        if comm.rank == 0:
            print(f"| {mesh.n_points} | {mesh.n_triangles} | {comm.size} | {bcast_s:.3f} | {scatter_s:.3f} | "
                  f"{scatter_s / bcast_s:.1f} | {gather_s:.3f} | {gather_s / bcast_s:.1f} | "
                  f"{scatter_bytes / 1e6:.1f} | {gather_bytes / 1e6:.1f} | {halo_bytes / 1e3:.1f} | "
                  f"{halo_ratio:.3f} | {stats['triangle_balance']:.3f} | {stats['point_balance']:.3f} |",
                  flush=True)


if __name__ == "__main__":
    main()
