"""Transfers across curved steps: errors and balances.

A disc with a hole, both circles curved (``geometry=``), evolved for ``--steps``
steps with delta alternating between refining and coarsening; after every step
the fields are carried by the linear and the conservative transfer and by
transfer_cells. Prints, per step, the worst error of a constant, of a linear
field and of x^2 + 1 carried from the start, and the integral balance
``integral(new) - integral(old) - (gained - lost)`` relative to the integral
(domain_change's strips).

Usage::

    python benchmarks/transfer_curved.py [--spacing 0.04] [--steps 12]
"""

from __future__ import annotations

import argparse

import numpy as np

import evomesh
from evomesh.meshgen import HOLE_TAG, OUTER_TAG, disc_with_hole_mesh


def integral(mesh: evomesh.Mesh, u: np.ndarray) -> float:
    return float(np.einsum("t,t->", mesh.triangle_areas, u[mesh.triangles].mean(axis=1)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spacing", type=float, default=0.04)
    parser.add_argument("--steps", type=int, default=12)
    args = parser.parse_args()
    geometry = evomesh.BoundaryGeometry({OUTER_TAG: evomesh.Circle((0, 0), 1.0),
                                         HOLE_TAG: evomesh.Circle((0, 0), 0.35)})
    mesh = disc_with_hole_mesh(args.spacing)
    exact = lambda p: p[:, 0] ** 2 + 1.0  # noqa: E731
    lin = lambda p: 0.5 + 2.0 * p[:, 0] - 3.0 * p[:, 1]  # noqa: E731
    smooth = {"linear": exact(mesh.points), "conservative": exact(mesh.points)}
    print(f"{'step':>4} {'points':>7} {'delta':>5} {'const err':>9} {'lin err':>9} "
          f"{'x2+1 linear':>11} {'x2+1 cons':>10} {'balance':>9} {'cells bal':>9} {'area +':>8} {'area -':>8}")
    for step in range(1, args.steps + 1):
        delta = 0.6 if step % 2 else 1.6
        new = evomesh.evolve(mesh, delta, geometry=geometry, seed=step)
        const = max(np.abs(evomesh.transfer(mesh, new, np.ones(mesh.n_points), method=m) - 1).max()
                    for m in ("linear", "conservative"))
        const = max(const, np.abs(evomesh.transfer_cells(mesh, new, np.ones(mesh.n_triangles)) - 1).max())
        lerr = max(np.abs(evomesh.transfer(mesh, new, lin(mesh.points), method=m) - lin(new.points)).max()
                   for m in ("linear", "conservative"))
        change = evomesh.domain_change(mesh, new, smooth["conservative"])
        before = integral(mesh, smooth["conservative"])
        smooth = {m: evomesh.transfer(mesh, new, u, method=m) for m, u in smooth.items()}
        balance = (integral(new, smooth["conservative"]) - before - change.integral_gained
                   + change.integral_lost) / before
        c = 1.0 + mesh.points[mesh.triangles].mean(axis=1)[:, 0] ** 2
        cells = evomesh.domain_change(mesh, new, c)
        c_new = evomesh.transfer_cells(mesh, new, c)
        total = float(mesh.triangle_areas @ c)
        cells_balance = (float(new.triangle_areas @ c_new) - total - cells.integral_gained + cells.integral_lost) / total
        errors = {m: np.abs(u - exact(new.points)).max() for m, u in smooth.items()}
        print(f"{step:4d} {new.n_points:7d} {delta:5.2f} {const:9.1e} {lerr:9.1e} {errors['linear']:11.4f} "
              f"{errors['conservative']:10.4f} {balance:9.1e} {cells_balance:9.1e} {change.area_gained:8.1e} "
              f"{change.area_lost:8.1e}")
        mesh = new


if __name__ == "__main__":
    main()
