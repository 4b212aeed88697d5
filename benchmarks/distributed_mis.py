"""The lexical-first MIS on real MPI ranks
(evomesh.distributed.packing.lexical_first_mis): rounds, halo copies and bytes
exchanged against mesh size and rank count, every run checked against the
serial MIS. The sphere systems are benchmarks/mis_rounds.py's (a refining
step's second packing pass: old points plus 3 candidates per refining
triangle, radius 0.75 f / 2, ordered by class, radius and index), cut into
Hilbert ranges of equal count (how `DistributedMesh.scatter` cuts) or into
vertical stripes across the front.

    for p in 2 4 8 16; do
      .venv/bin/mpiexec -n $p .venv/bin/python benchmarks/distributed_mis.py --sizes 1e4,1e5,1e6
    done

Ranks above the core count are oversubscribed: seconds are then wall time of
ranks sharing cores; the rounds, copies and bytes are the algorithm's.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from evomesh import _core
from evomesh.distributed.packing import lexical_first_mis

sys.path.insert(0, str(Path(__file__).parent))
from mis_rounds import hilbert_parts, spheres  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="1e4,1e5")
    parser.add_argument("--header", action="store_true", help="print the table's header first")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    if args.header and comm.rank == 0:
        print("| mesh points | spheres | ranks | layout | rounds | copies / sphere | halo bytes | state bytes "
              "| bytes / sphere | seconds (slowest rank) | serial MIS seconds |")
        print("|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for size in args.sizes.split(","):
        pieces: dict[str, list] = {}
        if comm.rank == 0:
            centers, radii, order, classes = spheres(int(float(size)))
            t = time.perf_counter()
            serial = _core.lexical_first_mis(centers, radii, order, 0).astype(bool)
            serial_seconds = time.perf_counter() - t
            layouts = {"hilbert": hilbert_parts(centers, comm.size),
                       "stripes": np.minimum((centers[:, 0] * comm.size).astype(np.int64), comm.size - 1)}
            for name, part in layouts.items():
                # Ties by position: the order (class, radius, tie) is packing_order's (class, radius, index).
                pieces[name] = [(mine, centers[mine], radii[mine], classes[mine])
                                for mine in (np.flatnonzero(part == r) for r in range(comm.size))]
        for layout in ("hilbert", "stripes"):
            mine, c, r, k = comm.scatter(pieces.get(layout), root=0)
            stats: dict = {}
            comm.Barrier()
            t = time.perf_counter()
            kept = lexical_first_mis(comm, c, r, k, mine.astype(np.int64), stats=stats)
            seconds = comm.allreduce(time.perf_counter() - t, op=MPI.MAX)
            gathered = comm.gather((mine, kept), root=0)
            if comm.rank == 0:
                result = np.zeros(len(radii), bool)
                for index, values in gathered:
                    result[index] = values
                if not np.array_equal(result, serial):
                    raise SystemExit(f"distributed MIS differs from serial at {size} points, {comm.size} ranks")
                total = stats["bytes_halo"] + stats["bytes_states"]
                print(f"| {int(float(size)):,} | {len(radii):,} | {comm.size} | {layout} | {stats['rounds']} "
                      f"| {stats['copies'] / len(radii):.4f} | {stats['bytes_halo']:,} | {stats['bytes_states']:,} "
                      f"| {total / len(radii):.2f} | {seconds:.2f} | {serial_seconds:.2f} |", flush=True)


if __name__ == "__main__":
    main()
