"""Step 1 on real MPI ranks (evomesh.distributed.spacing.DistributedSpacing):
halo records and bytes exchanged against mesh size and rank count, and seconds
against the serial step 1 (`_core.step_spacing`) on the same mesh in the same
run; every run is checked bit for bit against the serial values.

The mesh is a square with two holes and two interior cracks (so the local
feature size walks run), refined by a graded request; delta is a moving
front's (0.5 near a circle, 2 elsewhere: both refining and coarsening).

    for p in 2 4 8; do
      .venv/bin/mpiexec -n $p .venv/bin/python benchmarks/distributed_spacing.py --sizes 1e4,1e5
    done

Ranks above the core count are oversubscribed: seconds are then wall time of
ranks sharing cores; records and bytes are the algorithm's.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from mpi4py import MPI

import evomesh
from evomesh import DistributedMesh, _core
from evomesh.distributed.spacing import DistributedSpacing
from evomesh.meshgen import polygon_mesh


def domain(n: int) -> evomesh.Mesh:
    loops = [[(0, 0), (3, 0), (3, 2), (0, 2)], [(0.5, 0.5), (0.5, 1.5), (1.2, 1.5), (1.2, 0.5)],
             [(1.8, 0.5), (1.8, 1.5), (2.5, 1.5), (2.5, 0.5)]]
    area = 6 - 2 * 0.7
    return polygon_mesh(loops, float(np.sqrt(2 * area / n)))


def front_delta(points: np.ndarray) -> np.ndarray:
    distance = np.abs(np.hypot(points[:, 0] - 1.5, points[:, 1] - 1.0) - 0.8)
    return np.where(distance < 0.15, 0.5, 2.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="1e4,1e5")
    parser.add_argument("--header", action="store_true")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    if args.header and comm.rank == 0:
        print("| mesh points | ranks | halo points / point | walk triangles / point | sites / point | skeleton "
              "segments | bytes / point | widenings | seconds (slowest rank) | serial seconds | equal |")
        print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for size in args.sizes.split(","):
        mesh = domain(int(float(size))) if comm.rank == 0 else None
        serial_seconds, reference = 0.0, None
        if comm.rank == 0:
            delta = front_delta(mesh.points)
            t = time.perf_counter()
            reference = _core.step_spacing(mesh.points, mesh.triangles, mesh.segments,
                                           mesh.segment_is_boundary.astype(np.uint8), mesh.kind, delta, True,
                                           segment_tags=mesh.segment_tags, required=mesh.required.astype(np.uint8),
                                           nn=mesh.nn_spacing, nn_grew=mesh._nn_grew)
            serial_seconds = time.perf_counter() - t
        n_points = comm.bcast(mesh.n_points if mesh is not None else 0)
        dmesh = DistributedMesh.scatter(mesh, comm)
        owned = dmesh.global_ids[: dmesh.n_owned]
        comm.Barrier()
        t = time.perf_counter()
        stats: dict = {}
        spacing = DistributedSpacing(dmesh, front_delta(dmesh.owned_points), stats=stats)
        seconds = comm.allreduce(time.perf_counter() - t, op=MPI.MAX)
        f = dmesh.gather_field(spacing.f)
        weight = dmesh.gather_field(spacing.weight)
        del owned
        if comm.rank == 0:
            equal = (np.array_equal(f.view(np.int64), np.asarray(reference["f"]).view(np.int64))
                     and np.array_equal(weight.view(np.int64), np.asarray(reference["weight"]).view(np.int64)))
            print(f"| {n_points:,} | {comm.size} | {stats['halo_points'] / n_points:.3f} | "
                  f"{stats['walk_triangles'] / n_points:.3f} | {stats['sites_received'] / n_points:.3f} | "
                  f"{stats['skeleton_segments']:,} | {stats['bytes'] / n_points:.1f} | {stats['walk_widenings']} | "
                  f"{seconds:.2f} | {serial_seconds:.2f} | {'yes' if equal else 'NO'} |", flush=True)


if __name__ == "__main__":
    main()
