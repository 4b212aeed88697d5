"""Coarsen and refine a square with a circular hole, and watch the hole.

With the hole's geometry (``evomesh.BoundaryGeometry({HOLE: evomesh.Circle(...)})``)
its vertices are no longer corners: coarsening removes them, refinement adds
new ones on the circle (not on the chords), so the number of hole points
follows the spacing and the hole's area error shrinks as the spacing does.
``--polygon`` runs the same cycle without the geometry: every vertex of the
hole polygon is then a corner, kept forever, and the area error stays that of
the initial polygon.

    python examples/curved_hole_cycle.py --points 4000 --cycles 3
"""

from __future__ import annotations

import argparse

import numpy as np
from heat_moving_source import HALF_WIDTH, HOLE, plate_with_hole

import evomesh

RADIUS = 0.4


def hole_points(mesh: evomesh.Mesh) -> int:
    """Number of points on the segments tagged HOLE."""
    return len(np.unique(mesh.segments[mesh.segment_tags == HOLE]))


def hole_area_error(mesh: evomesh.Mesh) -> float:
    """(polygonal hole area - pi R^2) / (pi R^2); the hole area is the square's minus the mesh's."""
    hole_area = (2 * HALF_WIDTH) ** 2 - mesh.area
    return (hole_area - np.pi * RADIUS**2) / (np.pi * RADIUS**2)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=4000, help="about this many points in the fine mesh")
    parser.add_argument("--cycles", type=int, default=3, help="coarsen/refine cycles")
    parser.add_argument("--hole-points", type=int, default=64, help="vertices of the hole polygon")
    parser.add_argument("--polygon", action="store_true", help="no geometry: the hole stays the initial polygon")
    args = parser.parse_args(argv)
    geometry = None if args.polygon else evomesh.BoundaryGeometry({HOLE: evomesh.Circle((0.0, 0.0), RADIUS)})

    h = np.sqrt(2 / np.sqrt(3) * ((2 * HALF_WIDTH) ** 2 - np.pi * RADIUS**2) / args.points)
    mesh = evomesh.evolve(plate_with_hole(h, 2 * np.pi * RADIUS / args.hole_points, radius=RADIUS), size=h,
                          geometry=geometry)
    if geometry is None:
        print("without a geometry the hole is a polygon whose vertices are corners, kept by every step")
    header = [("step", 4), ("operation", 18), ("points", 7), ("median nn/h", 11), ("hole points", 11),
              ("hole area error", 15)]
    print(" ".join(f"{name:>{width}}" for name, width in header))

    def report(step: int, operation: str) -> None:
        print(f"{step:4d} {operation:>18} {mesh.n_points:7d} {np.median(mesh.nn_spacing) / h:11.2f} "
              f"{hole_points(mesh):11d} {hole_area_error(mesh):15.2e}")

    report(0, "initial")
    for cycle in range(args.cycles):
        mesh = evomesh.evolve(mesh, 3.0, geometry=geometry)
        report(2 * cycle + 1, "coarsen x3")
        mesh = evomesh.evolve(mesh, size=h, geometry=geometry)
        report(2 * cycle + 2, "refine to size h")


if __name__ == "__main__":
    main()
