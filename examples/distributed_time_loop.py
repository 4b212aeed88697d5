"""A time loop on MPI ranks that never gathers the mesh.

A front (a circle) moves across a plate with two holes; every step refines
near it and coarsens elsewhere (FRFC, the paper's options; --quality: the
recommended ones, with the quality pass), on every rank at once, and carries a
field along with the conservative transfer. Rank 0 makes the first mesh and scatters it; after that
each rank only holds its part.

    mpiexec -n 4 python examples/distributed_time_loop.py --points 20000 --steps 6
    mpiexec -n 4 python examples/distributed_time_loop.py --quality   # smallest angle 30 degrees

Each step prints the global number of points, the balance (largest owned
count over the mean), the smallest angle, and the integral of the field
before and after the transfer (equal up to rounding). Without the quality
pass the angles are the packing's (small ones where the spacing changes fast,
as in the serial step with quality=False); with --quality the pass runs on
rank 0, which then holds the kept points and their triangulation for that
stage (docs/distributed-step.md 3.11).
The meshes equal the serial loop's, step by step, on any number of ranks
(tests/test_distributed_step.py and tests/test_distributed_quality.py check
that on 1-7 ranks).
"""

from __future__ import annotations

import argparse

import numpy as np
from mpi4py import MPI

import evomesh
from evomesh.meshgen import polygon_mesh

PLATE = [[(0, 0), (3, 0), (3, 2), (0, 2)], [(0.5, 0.5), (0.5, 1.5), (1.1, 1.5), (1.1, 0.5)],
         [(1.9, 0.5), (1.9, 1.5), (2.5, 1.5), (2.5, 0.5)]]


def target_size(xy: np.ndarray, t: float, h: float) -> np.ndarray:
    """The spacing wanted: h / 4 within 0.1 of a circle of radius 0.5 moving right, growing
    away from it (slope 0.5) up to h."""
    centre = np.array([0.4 + 0.35 * t, 1.0])
    distance = np.abs(np.hypot(xy[:, 0] - centre[0], xy[:, 1] - centre[1]) - 0.5)
    return np.minimum(h, h / 4 + 0.5 * np.maximum(distance - 0.1, 0.0))


def smallest_angle(dmesh: evomesh.DistributedMesh) -> float:
    """The smallest angle (degrees) of the owned triangles, over all ranks."""
    p = dmesh.points[dmesh.triangles]
    smallest = 180.0
    for k in range(3):
        u, v = p[:, (k + 1) % 3] - p[:, k], p[:, (k + 2) % 3] - p[:, k]
        cos = (u * v).sum(axis=1) / np.hypot(*u.T) / np.hypot(*v.T)
        if len(cos):
            smallest = min(smallest, float(np.degrees(np.arccos(np.clip(cos, -1, 1))).min()))
    return dmesh.comm.allreduce(smallest, op=MPI.MIN)


def integral(dmesh: evomesh.DistributedMesh, u: np.ndarray) -> float:
    """The integral of the P1 field u (over the owned points) on the owned triangles, summed over ranks."""
    held = dmesh.exchange_halo(u)
    p = dmesh.points[dmesh.triangles]
    u1, u2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    area = 0.5 * np.abs(u1[:, 0] * u2[:, 1] - u1[:, 1] * u2[:, 0])
    return dmesh.comm.allreduce(float((area * held[dmesh.triangles].mean(axis=1)).sum()), op=MPI.SUM)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=20000)
    parser.add_argument("--steps", type=int, default=6)
    parser.add_argument("--quality", action="store_true",
                        help="the recommended options, with the quality pass (on rank 0)")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    area = 6.0 - 2 * 0.6
    h = float(np.sqrt(2 * area / args.points))
    mesh = polygon_mesh(PLATE, h) if comm.rank == 0 else None
    dmesh = evomesh.DistributedMesh.scatter(mesh, comm)  # the only time one rank holds the whole mesh
    del mesh
    options = evomesh.FrfcOptions.recommended() if args.quality else evomesh.FrfcOptions.paper()
    u = np.exp(-((dmesh.owned_points[:, 0] - 1.5) ** 2 + (dmesh.owned_points[:, 1] - 1.0) ** 2))
    if comm.rank == 0:
        print(f"ranks {comm.size}")
        print("step  points  balance  min_angle  integral_before  integral_after")
    for step in range(1, args.steps + 1):
        before = integral(dmesh, u)
        def size(xy: np.ndarray, step: int = step) -> np.ndarray:
            return target_size(xy, step, h)

        new = evomesh.evolve(dmesh, size=size, options=options, within_domain=True, seed=step)
        u = evomesh.transfer(dmesh, new, u, method="conservative")
        dmesh = new
        after = integral(dmesh, u)
        total = comm.allreduce(dmesh.n_owned, op=MPI.SUM)
        owned = np.array(comm.allgather(dmesh.n_owned))
        angle = smallest_angle(dmesh)
        if comm.rank == 0:
            print(f"{step:4d}  {total:6d}  {owned.max() / owned.mean():7.3f}  {angle:9.2f}  {before:.15f}  "
                  f"{after:.15f}", flush=True)


if __name__ == "__main__":
    main()
