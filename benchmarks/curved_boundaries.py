"""Curved boundaries on a disc with a hole (evomesh.meshgen.disc_with_hole_mesh).

Coarsen by 3, then refine back to the initial spacing and to half of it, with
and without the circles' geometry; prints per step the points, the boundary
points, their largest distance from the circles, the area error against the true
domain and the smallest angle.

    python benchmarks/curved_boundaries.py [--spacing 0.02]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

import evomesh
from evomesh.meshgen import HOLE_TAG, OUTER_TAG, disc_with_hole_mesh

OUTER, HOLE = 1.0, 0.35


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spacing", type=float, default=0.02)
    args = parser.parse_args()
    h = args.spacing
    true_area = math.pi * (OUTER**2 - HOLE**2)
    geometry = evomesh.BoundaryGeometry({OUTER_TAG: evomesh.Circle((0, 0), OUTER), HOLE_TAG: evomesh.Circle((0, 0), HOLE)})
    print("| geometry | step | points | boundary points | max distance from the circles | area error | min angle |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for name, g in (("circles", geometry), ("none (polygon)", None)):
        mesh = disc_with_hole_mesh(h)
        for label, delta, size in (("initial", None, None), ("coarsen x3", 3.0, None), ("refine to h", None, h),
                                   ("refine to h/2", None, h / 2)):
            if label != "initial":
                mesh = evomesh.evolve(mesh, delta, size=size, geometry=g)
            on = np.unique(mesh.segments[mesh.segment_is_boundary.astype(bool)])
            r = np.hypot(*mesh.points[on].T)
            gap = np.minimum(abs(r - OUTER), abs(r - HOLE)).max()
            print(f"| {name} | {label} | {mesh.n_points} | {len(on)} | {gap:.1e} | "
                  f"{(mesh.area - true_area) / true_area:+.2e} | {evomesh.quality(mesh).min_angle:.1f} |")


if __name__ == "__main__":
    main()
