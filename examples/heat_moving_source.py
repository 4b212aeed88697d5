"""Transient heat with a moving source on an adaptive mesh (evomesh + scikit-fem).

Solves u_t = k Δu + s(x, t) on the plate [-1, 1]^2 with a circular hole of
radius 0.25, where s is a Gaussian source circling the hole. P1 elements,
backward Euler. Every step the mesh is evolved towards an absolute spacing
h(x) that is fine near the source and coarse elsewhere (``evolve(mesh,
size=h)``) and the temperature is carried over with the conservative (L2)
transfer, which keeps the heat integral ∫u up to rounding. Boundary
conditions come from segment tags: u = 0 on the outer boundary (tag 1), an
insulated hole (tag 2, natural condition). Writes a ParaView series.

The hole is a curved boundary (``evomesh.BoundaryGeometry`` with a
``Circle``): its points follow the spacing, and every new one lies on the circle.

    python examples/heat_moving_source.py --points 20000 --steps 20 --out heat_output

Needs scikit-fem: ``pip install evomesh[fem]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Callable

import numpy as np
import skfem
from scipy.sparse import csr_matrix
from scipy.spatial import Delaunay
from skfem.models.poisson import laplace, mass

import evomesh
import evomesh.io

OUTER, HOLE = 1, 2  # segment tags
HALF_WIDTH, RADIUS = 1.0, 0.25  # plate [-1, 1]^2, hole radius
K = 0.01  # diffusivity
SIGMA = 0.04  # source width
ORBIT = 0.6  # the source circles the hole at this radius ...
OMEGA = np.pi  # ... at this angular speed (half a turn per unit time)
RATIO = 8.0  # coarsest / finest spacing


def plate_with_hole(h: float, hole_spacing: float, radius: float = RADIUS, half_width: float = HALF_WIDTH,
                    ) -> evomesh.Mesh:
    """A structured mesh of the square [-w, w]^2 minus a disc, without Gmsh.

    Grid points of spacing ``h`` away from the hole plus a polygon of spacing
    ``hole_spacing`` on it, triangulated by ``scipy.spatial.Delaunay``;
    triangles whose centroid lies in the hole are dropped. Boundary segments
    are tagged by their distance from the centre: ``HOLE`` near the hole,
    ``OUTER`` on the square.
    """
    n_hole = int(np.ceil(2 * np.pi * radius / hole_spacing))
    angle = 2 * np.pi * np.arange(n_hole) / n_hole
    hole = radius * np.c_[np.cos(angle), np.sin(angle)]
    x = np.linspace(-half_width, half_width, int(np.ceil(2 * half_width / h)) + 1)
    grid = np.stack(np.meshgrid(x, x), axis=-1).reshape(-1, 2)
    grid = grid[np.hypot(*grid.T) > radius + 0.75 * max(h, hole_spacing)]
    points = np.concatenate([hole, grid])
    triangles = Delaunay(points).simplices
    triangles = triangles[np.hypot(*points[triangles].mean(axis=1).T) > radius]
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    edges, count = np.unique(edges, axis=0, return_counts=True)
    segments = edges[count == 1]  # boundary edges: in one triangle only
    middle = np.hypot(*points[segments].mean(axis=1).T)
    tags = np.where(middle < 0.5 * (radius + half_width), HOLE, OUTER)
    return evomesh.Mesh(points, triangles, segments, segment_tags=tags)


def hole_geometry() -> evomesh.BoundaryGeometry:
    """The hole is a circle: new points on it go onto the circle, and its vertices may be coarsened away."""
    return evomesh.BoundaryGeometry({HOLE: evomesh.Circle((0.0, 0.0), RADIUS)})


def source_centre(t: float) -> np.ndarray:
    return ORBIT * np.array([np.cos(OMEGA * t), np.sin(OMEGA * t)])


def spacing(t: float, h_min: float) -> Callable[[np.ndarray], np.ndarray]:
    """h(x): h_min at the source, RATIO * h_min a few source widths away."""
    centre = source_centre(t)

    def h(x: np.ndarray) -> np.ndarray:
        d2 = ((x - centre) ** 2).sum(axis=1)
        return h_min * (RATIO - (RATIO - 1) * np.exp(-d2 / (2 * (4 * SIGMA) ** 2)))

    return h


def finest_spacing(n_points: int) -> float:
    """h_min such that the spacing h(x) gives about n_points points: a mesh of
    nearest-neighbour spacing h has about 2 / (sqrt(3) h^2) points per unit area."""
    rng = np.random.default_rng(0)
    x = rng.uniform(-HALF_WIDTH, HALF_WIDTH, (200_000, 2))
    x = x[np.hypot(*x.T) > RADIUS]
    area = (2 * HALF_WIDTH) ** 2 - np.pi * RADIUS**2
    density = area * np.mean(2 / (np.sqrt(3) * spacing(0.0, 1.0)(x) ** 2))
    return float(np.sqrt(density / n_points))


def solve_step(mesh: evomesh.Mesh, u_old: np.ndarray, t: float, dt: float,
               seconds: dict[str, float]) -> tuple[np.ndarray, csr_matrix]:
    """One backward Euler step on ``mesh``: (M + dt k K) u = M u_old + dt b(t); returns u and M.
    Adds the time of the assembly (mesh conversion, basis, matrices, condensation) and of the
    linear solve to ``seconds["assembly"]`` and ``seconds["solve"]``."""
    start = time.perf_counter()
    m = mesh.to_skfem({OUTER: "outer", HOLE: "hole"})
    basis = skfem.Basis(m, skfem.ElementTriP1())
    centre = source_centre(t)

    @skfem.LinearForm
    def load(v, w):
        d2 = (w.x[0] - centre[0]) ** 2 + (w.x[1] - centre[1]) ** 2
        return np.exp(-d2 / (2 * SIGMA**2)) / (2 * np.pi * SIGMA**2) * v

    M, A = mass.assemble(basis), laplace.assemble(basis)
    lhs, rhs = M + dt * K * A, M @ u_old + dt * load.assemble(basis)
    system = skfem.condense(lhs, rhs, D=basis.get_dofs("outer"))  # u = 0 there; the hole is insulated
    seconds["assembly"] += time.perf_counter() - start
    start = time.perf_counter()
    u = skfem.solve(*system)
    seconds["solve"] += time.perf_counter() - start
    return u, M


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=20_000, help="target number of mesh points")
    parser.add_argument("--steps", type=int, default=20, help="number of time steps")
    parser.add_argument("--dt", type=float, default=0.05, help="time step")
    parser.add_argument("--out", type=Path, default=Path("heat_output"), help="output folder (.vtu files and heat.pvd)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    h_min = finest_spacing(args.points)
    mesh = plate_with_hole(RATIO * h_min, hole_spacing=2 * h_min)
    for _ in range(3):  # correct the estimate by the points actually made
        mesh = evomesh.evolve(mesh, size=spacing(0.0, h_min), geometry=hole_geometry())
        h_min *= np.sqrt(mesh.n_points / args.points)
    mesh = evomesh.evolve(mesh, size=spacing(0.0, h_min), geometry=hole_geometry())
    u = np.zeros(mesh.n_points)
    M = mass.assemble(skfem.Basis(mesh.to_skfem(), skfem.ElementTriP1()))
    files = [evomesh.io.write_mesh(args.out / "heat_0000.vtu", mesh, {"u": u})]
    times = [0.0]
    print(f"initial mesh: {mesh.n_points} points, {mesh.n_triangles} triangles, h from {h_min:.4g} to "
          f"{RATIO * h_min:.4g}; hole: {int((mesh.segment_tags == HOLE).sum())} segments on the circle "
          "(a curved boundary: its points follow the spacing)")
    print(f"{'step':>4} {'t':>5} {'points':>7} {'kept %':>6} {'heat ∫u':>10} {'strips ∫u':>10} {'transfer Δ∫u/∫u':>16} "
          f"{'evolve s':>8} {'transfer s':>10} {'assembly s':>10} {'solve s':>7}")
    timings: dict[str, list[float]] = {"evolve": [], "transfer": [], "assembly": [], "solve": []}
    for step in range(1, args.steps + 1):
        t = step * args.dt
        seconds = {"assembly": 0.0, "solve": 0.0}
        start = time.perf_counter()
        new = evomesh.evolve(mesh, size=spacing(t, h_min), geometry=hole_geometry())
        seconds["evolve"] = time.perf_counter() - start
        start = time.perf_counter()
        u_new = evomesh.transfer(mesh, new, u, method="conservative")
        strip = evomesh.domain_change(mesh, new, u)  # what the moved boundary did to ∫u
        seconds["transfer"] = time.perf_counter() - start
        heat_before = float(np.sum(M @ u))
        u, M = solve_step(new, u_new, t, args.dt, seconds)
        heat_transferred = float(np.sum(M @ u_new))  # the new mass matrix: ∫u_new on the new mesh
        # the transfer conserves ∫u up to what the strips between the old chords and the circle carry
        boundary = strip.integral_gained - strip.integral_lost
        drift = (heat_transferred - heat_before - boundary) / heat_before if heat_before else heat_transferred
        kept = 100.0 * (new.origin >= 0).sum() / mesh.n_points
        mesh = new
        for name, value in seconds.items():
            timings[name].append(value)
        print(f"{step:4d} {t:5.2f} {mesh.n_points:7d} {kept:6.1f} {np.sum(M @ u):10.5f} {boundary:10.2e} {drift:16.1e} "
              f"{seconds['evolve']:8.3f} {seconds['transfer']:10.3f} {seconds['assembly']:10.3f} "
              f"{seconds['solve']:7.3f}", flush=True)
        files.append(evomesh.io.write_mesh(args.out / f"heat_{step:04d}.vtu", mesh,
                                           {"u": u, "h": spacing(t, h_min)(mesh.points)}))
        times.append(t)
    median = {name: float(np.median(values)) for name, values in timings.items()}
    print("median per step: " + ", ".join(f"{name} {value:.3f} s" for name, value in median.items())
          + f"; (evolve + transfer) / (assembly + solve) = "
          f"{(median['evolve'] + median['transfer']) / (median['assembly'] + median['solve']):.2f}")
    print(f"wrote {evomesh.io.write_pvd(args.out / 'heat.pvd', files, times)} ({len(files)} steps)")


if __name__ == "__main__":
    main()
