"""Tetrahedral steps on convex polyhedra other than the cube: evomesh against MMG3D.

Domains: a tilted box (evomesh.tilted_box_mesh: sides 1 x 0.75 x 0.5 times
63/64, rotated 56 degrees about (3, 2, 1)), the regular octahedron of radius 1
(evomesh.octahedron_mesh), a thin slab [0, 1]^2 x [0, 1/16] and the unit cube
with the corner (1, 1, 1) cut off by x + y + z = 2.5. On each, a size
h(x) = min(hmax, hmin + 0.3 | |x - c| - r |) fine on a sphere of radius r
(0.25 of the domain's diameter; the slab: a cylinder-like cut of it) whose
centre c moves by 0.05 of the diameter per step along the domain's longest
direction. Each method adapts the same initial mesh three times to the first
centre, then steps from its own output. Per step: points, kept % of the old
points (bit-identical coordinates), median edge / h, radius-edge max, dihedral
min / max, % of dihedrals below 10 / above 170 degrees, CPU seconds; per
domain, evomesh's points over MMG3D's. evomesh's size_factor is calibrated per
domain on the first step to MMG's median edge / h (within 5 %).

MMG3D: mmg3d_O3 of the mmgpy 0.17.1 wheel under build/peers/mmg-venv (see
tet_moving_sphere.py); without it, evomesh alone.

    .venv/bin/python benchmarks/tet_domains.py [--hmin 0.02] [--steps 3] [--no-mmg] [--domains octahedron,...]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Callable

import numpy as np

import evomesh

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tet_moving_sphere import kept_count, median_edge_over_h, mmg_binary, mmg_step, quality_row  # noqa: E402


def domains() -> dict[str, tuple[Callable[[], evomesh.TetMesh], np.ndarray, np.ndarray, float]]:
    """name -> (initial mesh, first centre, direction of motion, diameter)."""
    cut_cube = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1) if i + j + k < 3]
                        + [[1, 1, 0.5], [1, 0.5, 1], [0.5, 1, 1]], float)
    tilted = evomesh.tilted_box_mesh(0.2)
    lo, hi = tilted.points.min(0), tilted.points.max(0)
    return {
        "tilted box": (lambda: evomesh.tilted_box_mesh(0.2), lo + 0.3 * (hi - lo), (hi - lo) / np.linalg.norm(hi - lo),
                       float(np.linalg.norm(hi - lo))),
        "octahedron": (lambda: evomesh.octahedron_mesh(0.3), np.array([-0.3, 0.0, 0.0]), np.array([1.0, 0, 0]), 2.0),
        "thin slab": (lambda: evomesh.box_mesh((0, 0, 0), (1, 1, 0.0625), (8, 8, 1)), np.array([0.3, 0.5, 0.03]),
                      np.array([1.0, 0, 0]), float(np.sqrt(2))),
        "cut cube": (lambda: evomesh.convex_polyhedron_mesh(cut_cube, 0.2), np.array([0.3, 0.5, 0.5]),
                     np.array([1.0, 1, 1]) / np.sqrt(3), float(np.sqrt(3))),
    }


def size_function(centre: np.ndarray, radius: float, hmin: float, hmax: float):
    def h(x: np.ndarray) -> np.ndarray:
        return np.minimum(hmax, hmin + 0.3 * np.abs(np.linalg.norm(x - centre, axis=1) - radius))
    return h


def run_domain(name: str, make, centre0: np.ndarray, direction: np.ndarray, diameter: float, args, binary):
    radius, hmax = 0.25 * diameter, 0.08 * diameter
    centres = [centre0 + 0.05 * diameter * k * direction for k in range(args.steps + 1)]
    sizes = [size_function(c, radius, args.hmin, hmax) for c in centres]
    start = make()
    rows = []
    mmg_ratio, mmg_points = None, []
    if binary:
        points, tets = start.points, start.tetrahedra
        for _ in range(3):
            points, tets, _, _ = mmg_step(binary, points, tets, sizes[0])
        for step in range(1, args.steps + 1):
            new_points, new_tets, cpu, _ = mmg_step(binary, points, tets, sizes[step])
            ratio = median_edge_over_h(new_points, new_tets, sizes[step])
            mmg_ratio = ratio if mmg_ratio is None else mmg_ratio
            mmg_points.append(len(new_points))
            rows.append((name, "MMG3D 5.8.0", step, len(new_points), 100 * kept_count(points, new_points) / len(points),
                         ratio, quality_row(new_points, new_tets), cpu))
            print(format_row(rows[-1]), flush=True)
            points, tets = new_points, new_tets

    def run(size_factor: float, steps: int, report: bool) -> tuple[float, list[int], int]:
        mesh = start
        for k in range(3):
            mesh = evomesh.evolve(mesh, size=sizes[0], seed=k, size_factor=size_factor)
        ratio0, counts, unresolved = None, [], 0
        for step in range(1, steps + 1):
            t0 = time.process_time()
            new = evomesh.evolve(mesh, size=sizes[step], seed=10 + step, size_factor=size_factor)
            cpu = time.process_time() - t0
            ratio = median_edge_over_h(new.points, new.tetrahedra, sizes[step])
            ratio0 = ratio if ratio0 is None else ratio0
            counts.append(new.n_points)
            unresolved += int(new.stats["radius_edge_unresolved"]) + int(new.stats["slivers_after"])
            if report:
                rows.append((name, f"evomesh (size_factor {size_factor:.3f})", step, new.n_points,
                             100 * new.stats["kept_fraction"], ratio, quality_row(new.points, new.tetrahedra), cpu))
                print(format_row(rows[-1]), flush=True)
            mesh = new
        return ratio0, counts, unresolved

    size_factor = evomesh.TetOptions().size_factor
    if mmg_ratio is not None:
        for _ in range(3):
            ratio, _, _ = run(size_factor, 1, False)
            if abs(ratio / mmg_ratio - 1) <= 0.05:
                break
            size_factor *= mmg_ratio / ratio
    _, counts, unresolved = run(size_factor, args.steps, True)
    summary = f"{name}: unresolved radius-edge or slivers over the steps: {unresolved}"
    if mmg_points:
        summary += f"; points / MMG3D's: {' '.join(f'{a / b:.2f}' for a, b in zip(counts, mmg_points))}"
    return rows, summary


def format_row(row) -> str:
    name, method, step, n, kept, ratio, q, cpu = row
    return (f"| {name} | {method} | {step} | {n} | {kept:.1f} | {ratio:.3f} | {q['rho_max']:.2f} | "
            f"{q['dih_min']:.2f} / {q['dih_max']:.1f} | {q['below10']:.3f} / {q['above170']:.3f} | {cpu:.2f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hmin", type=float, default=0.02)
    parser.add_argument("--steps", type=int, default=3)
    parser.add_argument("--no-mmg", action="store_true")
    parser.add_argument("--domains", default="tilted box,octahedron,thin slab,cut cube")
    args = parser.parse_args()
    binary = None if args.no_mmg else mmg_binary()
    if binary is None and not args.no_mmg:
        print("MMG3D not found under build/peers/mmg-venv: evomesh only", file=sys.stderr)
    table, summaries = [], []
    all_domains = domains()
    for name in args.domains.split(","):
        rows, summary = run_domain(name, *all_domains[name], args, binary)
        table += rows
        summaries.append(summary)
    print()
    print("| domain | method | step | points | kept % of old | edge/h median | radius-edge max | dihedral min / max | "
          "% < 10 / > 170 | CPU s |")
    print("| " + " | ".join(["---"] * 10) + " |")
    for row in table:
        print(format_row(row))
    print()
    for summary in summaries:
        print(summary)


if __name__ == "__main__":
    main()
