"""Conservative transfer of per-tetrahedron fields (transfer_cells) on the moving sphere.

The mesh and the steps of benchmarks/tet_moving_sphere.py (a Kuhn 10^3 cube adapted
three times to a sphere of radius 0.2 centred at (0.3, 0.5, 0.5), then steps moving
it 0.1 in x). Per step: tetrahedra, supermesh pairs per new tetrahedron, the share of
new tetrahedra that are old ones (no clipping), the largest |sum of pair volumes /
volume - 1| over old and new tetrahedra, the relative change of the integral of a
random field (one step, and chained from the first step; sums without rounding,
math.fsum of the rounded terms), and the CPU time of
transfer_cells against the step's own (the ratio is the figure: both run here).

    .venv/bin/python benchmarks/tet_transfer.py [--hmin 0.02] [--steps 3]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from tet_moving_sphere import size_function

import evomesh
from evomesh.field_transfer import TetSupermesh


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hmin", type=float, default=0.02)
    parser.add_argument("--steps", type=int, default=3)
    args = parser.parse_args()
    centre = np.array([0.3, 0.5, 0.5])
    mesh = evomesh.unit_cube_mesh(10)
    for k in range(3):
        mesh = evomesh.evolve(mesh, size=size_function(centre, args.hmin), seed=k)
    rng = np.random.default_rng(0)
    u = rng.uniform(0.5, 2.0, mesh.n_tetrahedra)
    total = math.fsum(mesh.volumes * u)
    print(f"{'step':>4} {'tets':>9} {'pairs/tet':>9} {'identical':>9} {'cover err':>9} {'step err':>9} "
          f"{'chain err':>9} {'step s':>7} {'xfer s':>7} {'ratio':>6}")
    for step in range(1, args.steps + 1):
        centre = centre + [0.1, 0.0, 0.0]
        started = time.process_time()
        new = evomesh.evolve(mesh, size=size_function(centre, args.hmin), seed=10 + step)
        step_seconds = time.process_time() - started
        started = time.process_time()
        v = evomesh.transfer_cells(mesh, new, u)
        transfer_seconds = time.process_time() - started
        s = TetSupermesh(mesh, new)
        cover = max(np.abs(np.bincount(s.new_tet, s.volume, minlength=new.n_tetrahedra) / new.volumes - 1).max(),
                    np.abs(np.bincount(s.old_tet, s.volume, minlength=mesh.n_tetrahedra) / mesh.volumes - 1).max())
        before = math.fsum(mesh.volumes * u)  # exact sums of the rounded terms
        after = math.fsum(new.volumes * v)
        print(f"{step:>4} {new.n_tetrahedra:>9} {len(s.volume) / new.n_tetrahedra:>9.2f} "
              f"{s.identical / new.n_tetrahedra:>9.1%} {cover:>9.1e} {abs(after - before) / before:>9.1e} "
              f"{abs(after - total) / total:>9.1e} {step_seconds:>7.2f} {transfer_seconds:>7.2f} "
              f"{transfer_seconds / step_seconds:>6.2f}")
        mesh, u = new, v


if __name__ == "__main__":
    main()
