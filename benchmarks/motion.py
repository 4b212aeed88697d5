"""Lagrangian motion, evolve(mesh, ..., displacement=u), and the transfers across the move.

A unit square, ``--steps`` steps at the initial spacing h (``size=h``) of
three motions that keep the domain:

- "expand": with a circular region (tag 1, radius 0.25, its border a zigzag
  of mesh edges) in region 2, the interface pushed outwards by about half a
  cell per step (a smooth radial field, zero from r = 0.48 on);
- "swirl": each circle about the centre turned by 0.5 (1 - (r/0.45)^2)^2 rad
  per step, moves of several cells (no fold);
- "swirl, folding": the same with 6 rad, moves of tens of cells: folded
  triangles, remeshed.

(The swirls run on a square without regions: a swirl winds an interface up
into a spiral, and remeshing does not untangle an interface whose segments
the motion makes cross; that step is refused.)

Per motion: points, old points kept (%, per step: mean and smallest), folded
triangles and dropped points per step, smallest angle, the largest relative
drift per step of a P1 field's integral (transfer, "conservative") and of a P0
field's total per region against what region_exchange says came in (the
material that changed region, as a % of the total, in the last column).

Then "by hand" (without displacement=): move the points and rebuild Mesh, which
refuses a fold, and carry the field by the linear transfer (no lineage): its
integral error per step. Then the cost, as ratios against a step without
motion run in the same script: the step with a displacement (and its parts:
the move, the location of the new points in the old mesh) and the
conservative transfer across it.

    python benchmarks/motion.py [--points 20000] [--steps 10] [--png benchmarks/motion.png]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import evomesh
from evomesh import _core
from evomesh.motion import move

CENTRE = np.array([0.5, 0.5])


def two_regions(n_points: int) -> evomesh.Mesh:
    base = evomesh.unit_square_mesh(n_points)
    centroid = base.points[base.triangles].mean(axis=1)
    tags = np.where(np.hypot(*(centroid - CENTRE).T) < 0.25, 1, 2)
    return evomesh.Mesh(base.points, base.triangles, triangle_tags=tags)


def expansion(amplitude: float):
    def u(x: np.ndarray) -> np.ndarray:
        d = x - CENTRE
        r = np.hypot(d[:, 0], d[:, 1])
        g = amplitude * (r / 0.25) * np.clip(1.0 - (r / 0.48) ** 2, 0.0, None) ** 2
        return g[:, None] * d / np.maximum(r, 1e-300)[:, None]

    return u


def swirl(amplitude: float, radius: float = 0.45):
    def u(x: np.ndarray) -> np.ndarray:
        d = x - CENTRE
        r = np.hypot(d[:, 0], d[:, 1])
        angle = amplitude * np.clip(1.0 - (r / radius) ** 2, 0.0, None) ** 2
        c, s = np.cos(angle), np.sin(angle)
        return np.c_[c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]] - d

    return u


def p1_integral(mesh: evomesh.Mesh, u: np.ndarray) -> float:
    return float(np.einsum("t,t->", mesh.triangle_areas, u[mesh.triangles].mean(axis=1)))


def region_totals(mesh: evomesh.Mesh, c: np.ndarray, tags: np.ndarray) -> np.ndarray:
    weights = mesh.triangle_areas * c
    return np.array([weights[mesh.triangle_tags == t].sum() for t in tags])


def run_motion(mesh: evomesh.Mesh, u, h: float, steps: int) -> dict[str, float]:
    rng = np.random.default_rng(0)
    field = 1.0 + rng.random(mesh.n_points)
    cells = 1.0 + rng.random(mesh.n_triangles)
    kept, folded, dropped, p1_drift, p0_drift, changed = [], [], [], [], [], []
    angle = 90.0
    for step in range(steps):
        new = evomesh.evolve(mesh, size=h, displacement=u, seed=step)
        kept.append(100.0 * (new.origin >= 0).sum() / mesh.n_points)
        folded.append(new.stats["motion_folded_triangles"])
        dropped.append(new.stats["motion_points_dropped"])
        angle = min(angle, evomesh.quality(new).min_angle)
        new_field = evomesh.transfer(mesh, new, field, method="conservative")
        p1_drift.append(abs(p1_integral(new, new_field) - p1_integral(mesh, field)) / p1_integral(mesh, field))
        exchange = evomesh.region_exchange(mesh, new, cells)
        new_cells = evomesh.transfer_cells(mesh, new, cells)
        expected = exchange.integral.sum(axis=0) + exchange.integral_gained
        total = float((mesh.triangle_areas * cells).sum())
        p0_drift.append(float(np.abs(region_totals(new, new_cells, exchange.tags) - expected).max()) / total)
        changed.append(100.0 * exchange.changed_sides / total)
        mesh, field, cells = new, new_field, new_cells
    return {"points": mesh.n_points, "kept_mean": float(np.mean(kept)), "kept_min": float(np.min(kept)),
            "folded": float(np.mean(folded)), "dropped": float(np.mean(dropped)), "min_angle": angle,
            "p1_drift": float(np.max(p1_drift)), "p0_drift": float(np.max(p0_drift)), "changed": float(np.mean(changed))}


def by_hand(mesh: evomesh.Mesh, u, steps: int) -> str:
    """The workaround without displacement=: points moved, Mesh rebuilt, the linear transfer."""
    field = 1.0 + mesh.points[:, 0] ** 2
    errors = []
    for _ in range(steps):
        moved = mesh.points + u(mesh.points)
        try:
            rebuilt = evomesh.Mesh(moved, mesh.triangles, triangle_tags=mesh.triangle_tags)
        except ValueError as error:
            return f"refused: {str(error)[:60]}"
        carried = evomesh.transfer(mesh, rebuilt, field)  # located anew: no lineage, no conservative transfer
        errors.append(abs(p1_integral(rebuilt, carried) - p1_integral(mesh, field)) / p1_integral(mesh, field))
        mesh, field = rebuilt, carried
    return f"{np.mean(errors):.1e} of the integral per step"


def timed(f, repeats: int = 3):
    best, value = np.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        value = f()
        best = min(best, time.perf_counter() - start)
    return best, value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=20000)
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--png", default=None, help="draw the folding swirl's first step (before, moved, after)")
    args = parser.parse_args()
    regions = two_regions(args.points)
    plain = evomesh.unit_square_mesh(args.points)
    h = float(np.median(plain.nn_spacing))
    motions = {"expand": (regions, expansion(0.5 * h / 0.19)), "swirl": (plain, swirl(0.5)),
               "swirl, folding": (plain, swirl(6.0))}
    largest = {name: float(np.hypot(*u(m.points).T).max()) / h for name, (m, u) in motions.items()}
    print(f"{plain.n_points} points, h = {h:.4g}, {args.steps} steps of size=h per motion\n")
    print("| motion | largest move (cells) | points after | kept % (mean, min) | folded / dropped per step "
          "| min angle | P1 drift per step | P0 drift per region | changed region % |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, (mesh, u) in motions.items():
        r = run_motion(mesh, u, h, args.steps)
        print(f"| {name} | {largest[name]:.1f} | {r['points']} | {r['kept_mean']:.1f}, {r['kept_min']:.1f} | "
              f"{r['folded']:.0f} / {r['dropped']:.0f} | {r['min_angle']:.2f} | {r['p1_drift']:.1e} | "
              f"{r['p0_drift']:.1e} | {r['changed']:.2f} |")
    print("\nBy hand (points moved, Mesh rebuilt, linear transfer):")
    for name, (mesh, u) in motions.items():
        print(f"- {name}: {by_hand(mesh, u, min(args.steps, 5))}")

    mesh, u = plain, swirl(0.5)
    static, _ = timed(lambda: evomesh.evolve(mesh, size=h, seed=0))
    moving, new = timed(lambda: evomesh.evolve(mesh, size=h, displacement=u, seed=0))
    moving_only, _ = timed(lambda: move(mesh, u))
    locate, _ = timed(lambda: _core.locate_points(mesh.points, mesh.triangles, new.points))
    still = evomesh.evolve(mesh, size=h, seed=0)
    field = np.random.default_rng(1).random(mesh.n_points)
    transfer_static, _ = timed(lambda: evomesh.transfer(mesh, still, field, method="conservative"))
    transfer_moving, _ = timed(lambda: evomesh.transfer(mesh, new, field, method="conservative"))
    print(f"\nCost (swirl, no fold; best of 3; the step without motion = {static:.3f} s):")
    print(f"- step with a displacement: {moving / static:.2f}x (of which the move {moving_only / static:.2f}x, "
          f"locating the new points in the old mesh {locate / static:.2f}x)")
    print(f"- conservative transfer across it: {transfer_moving / transfer_static:.2f}x the transfer after the "
          f"step without motion ({transfer_static:.3f} s)")

    if args.png:
        from evomesh.plotting import _figure, plot_mesh, save

        small = evomesh.unit_square_mesh(700)
        hs = float(np.median(small.nn_spacing))
        moved = move(small, swirl(6.0))
        after = evomesh.evolve(small, size=hs, displacement=swirl(6.0), seed=0)
        fig, axes = _figure(3)
        plot_mesh(small, ax=axes[0], title="before")
        plot_mesh(moved.mesh, ax=axes[1], title=f"moved: {moved.stats['motion_folded_triangles']:.0f} folded "
                                                 "triangles remeshed")
        plot_mesh(after, ax=axes[2], title=f"after the step ({100 * (after.origin >= 0).mean():.0f}% of points kept)")
        print(f"\nwrote {save(fig, args.png, dpi=60)}")


if __name__ == "__main__":
    main()
