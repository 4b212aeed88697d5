"""Two phases with a moving interface in the mesh, with scikit-fem.

A disc of a second material (conductivity 10 against 1 outside) is carried
around the unit square by a rotating velocity field. Every step the interface,
the zero set of phi(x) = |x - c(t)| - r, is part of the mesh
(``evomesh.evolve(..., interface=phi)``): triangles are tagged by phase, the
interface is resolved by a band of fine spacing, most old points are kept, and
the temperature is carried over with the conservative transfer. The heat
equation with the phase-dependent conductivity is then solved by backward
Euler (P1 elements, u = 0 on the box). Prints per step the points, the share
of old points kept, the transfer's integral drift, the area that changed
phase, the smallest angle and the worst |phi| at interface points; writes a
``.pvd`` series for ParaView.

    python examples/two_phase.py [--steps 100] [--points 3000] [--out two_phase_output]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import skfem
from skfem.helpers import dot, grad

import evomesh

RADIUS = 0.15
CONDUCTIVITY = {0: 1.0, 1: 10.0}  # outside, inside (the interface's regions below)


def centre(t: float) -> np.ndarray:
    """The disc's centre: once around (0.5, 0.5) at radius 0.25 for t in [0, 1]."""
    return np.array([0.5 + 0.25 * np.cos(2 * np.pi * t), 0.5 + 0.25 * np.sin(2 * np.pi * t)])


def level_set(t: float):
    c = centre(t)
    return lambda x: np.hypot(x[:, 0] - c[0], x[:, 1] - c[1]) - RADIUS


@skfem.BilinearForm
def diffusion(u, v, w):
    return w["kappa"] * dot(grad(u), grad(v))


@skfem.BilinearForm
def mass(u, v, w):
    return u * v


@skfem.LinearForm
def source(v, w):
    x, y = w.x
    return np.exp(-((x - 0.5) ** 2 + (y - 0.5) ** 2) / 0.01) * v


def solve(mesh: evomesh.Mesh, u_old: np.ndarray, dt: float) -> np.ndarray:
    basis = skfem.Basis(mesh.to_skfem(), skfem.ElementTriP1())
    kappa_cells = np.where(mesh.triangle_tags == 1, CONDUCTIVITY[1], CONDUCTIVITY[0])
    kappa = skfem.Basis(mesh.to_skfem(), skfem.ElementTriP0()).interpolate(kappa_cells)
    M = mass.assemble(basis)
    K = diffusion.assemble(basis, kappa=kappa)
    b = M @ u_old + dt * source.assemble(basis)
    return skfem.solve(*skfem.condense(M + dt * K, b, D=basis.get_dofs()))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--points", type=int, default=3000, help="about the points of the initial mesh")
    parser.add_argument("--out", type=Path, default=Path("two_phase_output"))
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    dt = 1.0 / args.steps
    mesh = evomesh.unit_square_mesh(args.points)
    h = float(np.median(mesh.nn_spacing)) * 1.2
    band = (4 * h / 3, h / 3)  # width, spacing: the interface resolved three times finer
    regions = (1, 0)  # inside (phi < 0): 1, outside: 0
    mesh = evomesh.evolve(mesh, size=h, interface=level_set(0.0), interface_band=band, interface_regions=regions)
    u = np.zeros(mesh.n_points)
    files = [evomesh.io.write_mesh(args.out / "two_phase_0000.vtu", mesh, {"u": u})]
    print(f"{'step':>4} {'points':>6} {'kept %':>6} {'drift':>9} {'changed phase':>13} {'min angle':>9} {'|phi|':>8}")
    for step in range(1, args.steps + 1):
        t = step * dt
        phi = level_set(t)
        new = evomesh.evolve(mesh, size=h, interface=phi, interface_band=band, interface_regions=regions, seed=step)
        before = float(mesh.triangle_areas @ u[mesh.triangles].mean(axis=1))
        u = evomesh.transfer(mesh, new, u, method="conservative")
        after = float(new.triangle_areas @ u[new.triangles].mean(axis=1))
        exchange = evomesh.region_exchange(mesh, new)
        changed = float(exchange.area.sum() - np.trace(exchange.area))
        on_interface = np.unique(new.segments[new.segment_tags == evomesh.INTERFACE_TAG])
        kept = 100.0 * (new.origin >= 0).sum() / mesh.n_points
        mesh = new
        u = solve(mesh, u, dt)
        drift = (after - before) / before if before else after
        print(f"{step:4d} {mesh.n_points:6d} {kept:6.1f} {drift:9.1e} {changed:13.5f} "
              f"{mesh.stats['min_angle']:9.2f} {np.abs(phi(mesh.points[on_interface])).max():8.1e}", flush=True)
        files.append(evomesh.io.write_mesh(args.out / f"two_phase_{step:04d}.vtu", mesh,
                                           {"u": u, "phi": phi(mesh.points)}))
    print(f"wrote {evomesh.io.write_pvd(args.out / 'two_phase.pvd', files, list(np.arange(len(files)) * dt))}")


if __name__ == "__main__":
    main()
