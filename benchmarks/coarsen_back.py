"""Does the mesh come back coarse where a fine request has passed?

``size=h`` keeps a mesh that meets its request where it is (edges within 1.25
times finer to 1.25 times coarser than h: delta = 1); where the mesh is finer
than that, it must coarsen back to h within a step or two. Three runs on the
unit square, each against a fresh mesh for the same final request (four steps
from ``unit_square_mesh``):

* ``spot``: plain ``size=``, a fine disc (radius 0.1, 0.006 inside, grading
  with slope 0.3 to h = 0.03) moved from x = 0.2 to 0.8 in 12 steps, then
  held for 3;
* ``gone``: the spot's path, then size=h everywhere for 3 steps (the fresh
  mesh is then the settled mesh for h alone);
* ``drop``: the same path as an interface, ``evolve(m, size=h, interface=phi,
  interface_band=(0.03, 0.006))`` with phi the signed distance to the circle;
* ``vortex``: a drop (radius 0.15 at (0.5, 0.75)) in the single-vortex flow
  u = (-sin^2(pi x) sin(2 pi y), sin(2 pi x) sin^2(pi y)) cos(pi t / T),
  phi by tracing back to t = 0 (RK4), h = 0.025, band (0.025, 0.008); the far
  field is |phi| > 0.3, as in the report that found this.

Printed per step: points, the median edge / request over the swept region
(spot, drop: edges whose midpoint has request h, within 0.1 of the path's
axis, x in [0.15, 0.6]; vortex: both ends in the far field) and over all
edges where the request is h. At the end: points against the fresh mesh.

    .venv/bin/python benchmarks/coarsen_back.py [--runs spot,gone,drop,vortex] [--vortex-steps 40]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import evomesh
from evomesh.meshgen import unit_square_mesh

H, WIDTH, FINE, GRADE, RADIUS, STEPS, HELD = 0.03, 0.03, 0.006, 0.3, 0.1, 12, 3


def centre(step: int) -> np.ndarray:
    return np.array([0.2 + 0.6 * min(step, STEPS) / STEPS, 0.5])


def circle(c: np.ndarray, r: float = RADIUS):
    return lambda x: np.hypot(x[:, 0] - c[0], x[:, 1] - c[1]) - r


def band_request(distance, h: float, width: float, fine: float):
    return lambda x: np.minimum(h, fine + GRADE * np.maximum(0.0, np.abs(distance(x)) - 0.5 * width))


def spot_request(c: np.ndarray):
    return lambda x: np.minimum(H, FINE + GRADE * np.maximum(0.0, np.hypot(x[:, 0] - c[0], x[:, 1] - c[1]) - RADIUS))


def edges(mesh: evomesh.Mesh) -> np.ndarray:
    t = np.asarray(mesh.triangles)
    return np.unique(np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1), axis=0)


def edge_over_request(mesh: evomesh.Mesh, size, where=None) -> tuple[float, float]:
    """Median edge / request over the edges `where` selects (by midpoint) and over all edges requesting h."""
    e = edges(mesh)
    p = np.asarray(mesh.points)
    mid = 0.5 * (p[e[:, 0]] + p[e[:, 1]])
    request = size(mid)
    ratio = np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1) / request
    coarse = request >= request.max()
    chosen = coarse & (where(mid, p[e[:, 0]], p[e[:, 1]]) if where is not None else True)
    return (float(np.median(ratio[chosen])) if chosen.any() else float("nan")), float(np.median(ratio[coarse]))


def swept(mid: np.ndarray, *_) -> np.ndarray:
    return (np.abs(mid[:, 1] - 0.5) < RADIUS) & (mid[:, 0] > 0.15) & (mid[:, 0] < 0.6)


def settled(h: float) -> evomesh.Mesh:
    mesh = evomesh.evolve(unit_square_mesh(int(1.17 / h**2)), size=h)
    return evomesh.evolve(evomesh.evolve(mesh, size=h), size=h)


def moving(kind: str) -> None:
    mesh = settled(H)
    start = time.perf_counter()
    for step in range(STEPS + HELD + 1):
        c = centre(step)
        if kind == "drop":
            mesh = evomesh.evolve(mesh, size=H, interface=circle(c), interface_band=(WIDTH, FINE), seed=step)
            size = band_request(circle(c), H, WIDTH, FINE)
        else:
            size = spot_request(c) if kind == "spot" or step < STEPS else (lambda x: np.full(len(x), H))
            mesh = evomesh.evolve(mesh, size=size, seed=step)
        inside, far = edge_over_request(mesh, size, swept)
        print(f"{kind:6} {step:>4} {c[0]:6.2f} {mesh.n_points:>7} {inside:>12.3f} {far:>10.3f}")
    fresh = unit_square_mesh(int(1.17 / H**2))
    for step in range(4 if kind != "gone" else 0):
        if kind == "drop":
            fresh = evomesh.evolve(fresh, size=H, interface=circle(c), interface_band=(WIDTH, FINE), seed=step)
        else:
            fresh = evomesh.evolve(fresh, size=size, seed=step)
    fresh = settled(H) if kind == "gone" else fresh
    inside, far = edge_over_request(fresh, size, swept)
    print(f"{kind:6} fresh {'':6} {fresh.n_points:>7} {inside:>12.3f} {far:>10.3f}   points / fresh "
          f"{mesh.n_points / fresh.n_points:.3f} ({time.perf_counter() - start:.1f} s)")


def vortex_phi(t: float, period: float, centre_xy=(0.5, 0.75), radius: float = 0.15, substeps: int = 40):
    """phi(x, t): the signed distance at t = 0 of the point that the flow takes to x at t (RK4 backwards)."""
    def velocity(x: np.ndarray, s: float) -> np.ndarray:
        c = np.cos(np.pi * s / period)
        return np.c_[-np.sin(np.pi * x[:, 0]) ** 2 * np.sin(2 * np.pi * x[:, 1]) * c,
                     np.sin(2 * np.pi * x[:, 0]) * np.sin(np.pi * x[:, 1]) ** 2 * c]

    def phi(x: np.ndarray) -> np.ndarray:
        y, s = np.array(x, dtype=float), t
        dt = -t / substeps
        for _ in range(substeps):
            k1 = velocity(y, s)
            k2 = velocity(y + 0.5 * dt * k1, s + 0.5 * dt)
            k3 = velocity(y + 0.5 * dt * k2, s + 0.5 * dt)
            k4 = velocity(y + dt * k3, s + dt)
            y, s = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4), s + dt
        return np.hypot(y[:, 0] - centre_xy[0], y[:, 1] - centre_xy[1]) - radius

    return phi


def far_from(phi):
    """Edges with both ends where |phi| > 0.3 (the far field)."""
    return lambda mid, a, b: (np.abs(phi(a)) > 0.3) & (np.abs(phi(b)) > 0.3)


def vortex(steps: int, period: float, h: float = 0.025, fine: float = 0.008) -> None:
    mesh = settled(h)
    start = time.perf_counter()
    first = 0
    for step in range(steps + 1):
        phi = vortex_phi(period * step / steps, period)
        try:
            mesh = evomesh.evolve(mesh, size=h, interface=phi, interface_band=(h, fine), seed=step)
        except ValueError as error:  # (a thin filament: a separate finding)
            print(f"vortex {step:>4} stopped: {str(error)[:100]}")
            return
        first = first or mesh.n_points
        size = band_request(phi, h, h, fine)
        far_field, coarse = edge_over_request(mesh, size, far_from(phi))
        print(f"vortex {step:>4} {step / steps:6.2f} {mesh.n_points:>7} {far_field:>12.3f} {coarse:>10.3f}")
    fresh = unit_square_mesh(int(1.17 / h**2))
    for step in range(4):
        fresh = evomesh.evolve(fresh, size=h, interface=phi, interface_band=(h, fine), seed=step)
    far_field, coarse = edge_over_request(fresh, size, far_from(phi))
    print(f"vortex fresh {'':6} {fresh.n_points:>7} {far_field:>12.3f} {coarse:>10.3f}   points / fresh "
          f"{mesh.n_points / fresh.n_points:.3f}, at step 0 {first} ({time.perf_counter() - start:.1f} s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", default="spot,gone,drop,vortex")
    parser.add_argument("--vortex-steps", type=int, default=40)
    parser.add_argument("--vortex-period", type=float, default=2.0)
    args = parser.parse_args()
    print(f"{'run':6} {'step':>4} {'x / t':>6} {'points':>7} {'swept e/h':>12} {'all e/h':>10}")
    for run in args.runs.split(","):
        if run == "vortex":
            vortex(args.vortex_steps, args.vortex_period)
        else:
            moving(run)


if __name__ == "__main__":
    main()
