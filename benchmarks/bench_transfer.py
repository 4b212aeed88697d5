"""Time conservative transfer against evolve and linear transfer.

The mesh is ``evomesh.unit_square_mesh(N)``; the step's delta refines in a
vertical band (x in [0.3, 0.4]) and coarsens elsewhere, as a moving-front step
would. Times are medians over ``--repeats``: evolve, linear transfer of a
vertex field, conservative transfer of a vertex field (supermesh with mass,
the new mesh's mass matrix, the mixed-mass product and the preconditioned CG
solve), transfer_cells (supermesh without mass, P0 projection); also the
relative drift of the integrals.

Usage::

    python benchmarks/bench_transfer.py [--points 1e5] [--repeats 3] [--threads N]
"""

from __future__ import annotations

import argparse
import time
from typing import Callable

import numpy as np

import evomesh


def median_seconds(call: Callable[[], object], repeats: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = call()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=float, default=1e5)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=None)
    args = parser.parse_args()
    mesh = evomesh.unit_square_mesh(int(args.points))
    x = mesh.points[:, 0]
    delta = np.where(np.abs(x - 0.35) < 0.05, 0.5, 1.5)
    t_evolve, new = median_seconds(lambda: evomesh.evolve(mesh, delta, seed=0, threads=args.threads), args.repeats)
    assert isinstance(new, evomesh.Mesh)
    u = np.sin(6 * mesh.points[:, 0]) * np.cos(4 * mesh.points[:, 1])
    c = np.random.default_rng(0).random(mesh.n_triangles)
    t_linear, _ = median_seconds(lambda: evomesh.transfer(mesh, new, u), args.repeats)
    t_cons, u_new = median_seconds(lambda: evomesh.transfer(mesh, new, u, method="conservative"), args.repeats)
    t_cells, c_new = median_seconds(lambda: evomesh.transfer_cells(mesh, new, c), args.repeats)

    def integral(m: evomesh.Mesh, v: np.ndarray) -> float:
        return float((np.abs(m.triangle_areas) * v[m.triangles].mean(axis=1)).sum())

    def total(m: evomesh.Mesh, v: np.ndarray) -> float:
        return float((np.abs(m.triangle_areas) * v).sum())

    assert isinstance(u_new, np.ndarray) and isinstance(c_new, np.ndarray)
    drift_vertex = abs(integral(new, u_new) - integral(mesh, u)) / abs(integral(mesh, u))
    drift_cells = abs(total(new, c_new) - total(mesh, c)) / abs(total(mesh, c))
    print(f"old mesh: {mesh.n_points} points, {mesh.n_triangles} triangles; "
          f"new: {new.n_points} points, {new.n_triangles} triangles; threads {evomesh.default_thread_count()}"
          if args.threads is None else f"threads {args.threads}")
    print(f"evolve                  {t_evolve:8.3f} s")
    print(f"transfer linear         {t_linear:8.3f} s   {t_linear / t_evolve:6.3f} x evolve")
    print(f"transfer conservative   {t_cons:8.3f} s   {t_cons / t_evolve:6.3f} x evolve, "
          f"{t_cons / t_linear:6.1f} x linear   integral drift {drift_vertex:.2e}")
    print(f"transfer_cells          {t_cells:8.3f} s   {t_cells / t_evolve:6.3f} x evolve, "
          f"{t_cells / t_linear:6.1f} x linear   total drift {drift_cells:.2e}")


if __name__ == "__main__":
    main()
