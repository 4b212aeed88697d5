"""How close to f can a mesh that follows the request be?

Two things are asked of one step: nn_M'(p) / (delta(p) nn_M(p)) <= 1.10
at the 99th percentile over the input points (the new spacing follows the
request h = delta nn_M at the old points), and a median of nn_M' / f over the
output points in [0.75, 1.0]. f(x) = min_p (h(p) + |x - p|) is the largest
1-Lipschitz spacing below h at the old points: between old points it exceeds
any interpolation of h by up to the distance to the nearest old point.

This script measures the median of h_lin / f over an ideal mesh whose spacing
is exactly the request interpolated linearly over the old triangles (h_lin):
points drawn uniformly in every old triangle, weighted by the point density
h_lin^-2 of a mesh with that spacing. A mesh that follows the request has
about that median; evomesh's measured median is printed beside it.

    .venv/bin/python benchmarks/nn_over_f.py --size 1e5
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import evomesh  # noqa: E402
from compare_peers import SCENARIOS, scenario  # noqa: E402


def ideal_median(mesh: evomesh.Mesh, delta: np.ndarray, draws: int, seed: int = 0) -> float:
    """Median of h_lin / f over a mesh with spacing h_lin (density h_lin^-2)."""
    rng = np.random.default_rng(seed)
    P, T = mesh.points, mesh.triangles
    h = delta * mesh.nn_spacing
    a, b, c = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]
    area = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    t = rng.choice(len(T), size=draws, p=area / area.sum())
    u, v = rng.random(draws), rng.random(draws)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    lam = np.stack([1 - u - v, u, v], axis=1)
    x = lam[:, :1] * a[t] + lam[:, 1:2] * b[t] + lam[:, 2:] * c[t]
    h_lin = (lam * h[T[t]]).sum(axis=1)
    ratio = h_lin / evomesh.spacing(mesh, delta)(x)
    weight = h_lin**-2.0
    order = np.argsort(ratio)
    cumulative = np.cumsum(weight[order])
    return float(ratio[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])


def measured(mesh: evomesh.Mesh, delta: np.ndarray) -> tuple[float, float]:
    """evomesh's median nn_M'/f over its output points and the ratio's p99."""
    out = evomesh.evolve(mesh, delta, seed=0)
    f = evomesh.spacing(mesh, delta)
    nn_out = out.nn_spacing
    d, _ = cKDTree(out.points).query(mesh.points, k=2)
    return float(np.median(nn_out / f(out.points))), float(np.percentile(d[:, 1] / (delta * mesh.nn_spacing), 99))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=float, default=2e4)
    parser.add_argument("--draws", type=int, default=400_000)
    args = parser.parse_args()
    cases = [(name, *scenario(name, args.size)[:2]) for name in SCENARIOS]
    square = evomesh.unit_square_mesh(int(args.size), seed=0)
    for d in (0.8, 0.5):
        cases.append((f"uniform delta={d}", square, np.full(square.n_points, d)))
    print("| case | ideal median h_lin/f | evomesh median nn'/f | evomesh ratio p99 |")
    print("|---|---|---|---|")
    for name, mesh, delta in cases:
        delta = np.broadcast_to(np.asarray(delta, dtype=np.float64), (mesh.n_points,))
        ideal = ideal_median(mesh, delta, args.draws)
        got, p99 = measured(mesh, delta)
        print(f"| {name} ({mesh.n_points} points) | {ideal:.3f} | {got:.3f} | {p99:.3f} |")


if __name__ == "__main__":
    main()
