"""The paper's growing-circle experiment one dimension up: a sphere growing in
the unit cube, meshed with tetrahedra."""

from __future__ import annotations

import csv
import numbers
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from evomesh.fronts import SpacingLaw
from evomesh.tet_evolution import evolve_tet
from evomesh.tet_mesh import TetMesh, dihedral_angles, radius_edge_ratios, unit_cube_mesh

__all__ = ["GROWING_SPHERE_DEFAULTS", "GrowingSphere", "growing_sphere", "SPHERE_COLUMNS"]

#: Defaults of :func:`growing_sphere`.
GROWING_SPHERE_DEFAULTS: dict[str, Any] = {
    "steps": 6,
    "cells": 8,
    "center": (0.5, 0.5, 0.5),
    "r0": 0.1,
    "r_end": None,
    "band": 0.1,
    "h_min": 0.05,
    "h_max": 0.15,
    "grade": 0.5,
}

#: Columns of the table (one row per mesh: the initial one is step 0).
SPHERE_COLUMNS = ("step", "radius", "points", "tetrahedra", "kept", "kept_fraction", "new_points",
                  "min_dihedral", "max_dihedral", "slivers", "max_radius_edge", "front_edge", "cpu_seconds")


def _sphere_row(step: int, radius: float, mesh: TetMesh, center: np.ndarray, law: SpacingLaw) -> dict[str, float]:
    angles = dihedral_angles(mesh.points, mesh.tetrahedra)
    sliver = ((angles < 10.0) | (angles > 170.0)).any(axis=1)
    edges = np.unique(np.sort(mesh.tetrahedra[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]].reshape(-1, 2),
                              axis=1), axis=0)
    a, b = mesh.points[edges[:, 0]], mesh.points[edges[:, 1]]
    length = np.linalg.norm(b - a, axis=1)
    distance = np.abs(np.linalg.norm(0.5 * (a + b) - center, axis=1) - radius)
    near = distance <= 0.5 * law.band
    kept = int((mesh.origin >= 0).sum()) if step else mesh.n_points
    stats = mesh.stats
    return {
        "step": step, "radius": radius, "points": mesh.n_points, "tetrahedra": mesh.n_tetrahedra, "kept": kept,
        "kept_fraction": float(stats.get("kept_fraction", 1.0)), "new_points": mesh.n_points - kept,
        "min_dihedral": float(angles.min()), "max_dihedral": float(angles.max()), "slivers": int(sliver.sum()),
        "max_radius_edge": float(radius_edge_ratios(mesh.points, mesh.tetrahedra).max()),
        "front_edge": float(np.median(length[near])) if near.any() else float("nan"),
        "cpu_seconds": float(stats.get("cpu_seconds", 0.0)),
    }


class GrowingSphere:
    """The result of :func:`growing_sphere`: ``meshes`` (initial first),
    ``radii`` (one per mesh), ``rows`` (:data:`SPHERE_COLUMNS`, one per mesh)
    and ``files`` (what was written: "table", "meshes", "figures")."""

    def __init__(self, meshes: list[TetMesh], radii: list[float], rows: list[dict[str, float]],
                 center: np.ndarray, law: SpacingLaw):
        self.meshes, self.radii, self.rows = meshes, radii, rows
        self.center, self.law = center, law
        self.files: dict[str, Any] = {}

    def table(self) -> str:
        """The rows as a fixed-width text table."""
        head = ("step", "r", "points", "tets", "kept", "kept %", "new", "min dih", "max dih", "slivers",
                "max R/e", "edge@front", "cpu s")
        lines = [" ".join(f"{h:>10}" for h in head)]
        for r in self.rows:
            lines.append(" ".join([
                f"{r['step']:>10d}", f"{r['radius']:>10.3f}", f"{r['points']:>10d}", f"{r['tetrahedra']:>10d}",
                f"{r['kept']:>10d}", f"{100 * r['kept_fraction']:>10.1f}", f"{r['new_points']:>10d}",
                f"{r['min_dihedral']:>10.2f}", f"{r['max_dihedral']:>10.2f}", f"{r['slivers']:>10d}",
                f"{r['max_radius_edge']:>10.3f}", f"{r['front_edge']:>10.4f}", f"{r['cpu_seconds']:>10.2f}"]))
        return "\n".join(lines)

    def write(self, folder: str | Path, *, figures: bool = True, dpi: int = 110) -> dict[str, Any]:
        """table.csv, mesh_NNN.vtu (with ``kind``/``origin``) and, with
        ``figures``, slice_NNN.png (the mesh cut by the plane z = centre's z,
        the sphere's circle on it) into ``folder`` (created)."""
        from evomesh.io import write_mesh

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        table = folder / "table.csv"
        with open(table, "w", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=SPHERE_COLUMNS)
            writer.writeheader()
            writer.writerows(self.rows)
        files: dict[str, Any] = {"table": table, "meshes": [], "figures": []}
        for k, mesh in enumerate(self.meshes):
            files["meshes"].append(write_mesh(folder / f"mesh_{k:03d}.vtu", mesh))
        if figures:
            from matplotlib.figure import Figure

            from evomesh.plotting import plot_tet_slice, save

            for k, mesh in enumerate(self.meshes):
                fig = plot_tet_slice(mesh, axis=2, value=float(self.center[2]), sphere=(self.center, self.radii[k]),
                                     title=f"step {k}: r = {self.radii[k]:.3f}, {mesh.n_points} points, "
                                           f"slice z = {self.center[2]:g}")
                assert isinstance(fig, Figure)  # (a new figure: no axes were given)
                files["figures"].append(save(fig, folder / f"slice_{k:03d}.png", dpi=dpi))
        self.files = files
        return files


def growing_sphere(
    *,
    steps: int = 6,
    cells: int = 8,
    center: Sequence[float] = (0.5, 0.5, 0.5),
    r0: float = 0.1,
    r_end: float | None = None,
    band: float = 0.1,
    h_min: float = 0.05,
    h_max: float = 0.15,
    grade: float = 0.5,
    seed: int = 0,
    out: str | Path | None = None,
    figures: bool = True,
    progress: bool | None = None,
    **options: Any,
) -> GrowingSphere:
    """A sphere growing in the unit cube: the mesh refined in a band around it
    and coarsened behind it, one :func:`evomesh.evolve` step per radius.

    The initial mesh is :func:`evomesh.unit_cube_mesh` (``cells`` per side).
    Step k (k = 1..steps) asks for the size h(d) of a :class:`SpacingLaw`
    (``h_min`` within ``band / 2`` of the sphere of radius
    r0 + (r_end - r0) k / steps, growing by ``grade`` outside, up to
    ``h_max``) with seed ``seed + k``; by default r_end is the distance from
    the centre to the nearest side (the sphere touches the box at the end).

    Parameters
    ----------
    steps, cells : int
    center : three floats inside the unit cube
    r0, r_end, band, h_min, h_max, grade : float
    seed : int
    out : path, optional
        Folder for :meth:`GrowingSphere.write`.
    figures : bool
    progress : bool or None
        A progress bar (None: when writing to a terminal).
    **options
        :class:`evomesh.TetOptions` fields.

    Returns
    -------
    GrowingSphere
    """
    for name, value in (("steps", steps), ("cells", cells)):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
        if value < 1:
            raise ValueError(f"{name} must be >= 1, got {value}")
    c = np.asarray(center, dtype=np.float64)
    if c.shape != (3,) or not np.isfinite(c).all() or not ((c > 0) & (c < 1)).all():
        raise ValueError(f"center must be a point inside the unit cube, got {center!r}")
    reach = float(min(c.min(), 1.0 - c.max()))
    if isinstance(r0, bool) or not isinstance(r0, numbers.Real) or not 0 <= r0 < reach:
        raise ValueError(f"r0 must be in [0, {reach:g}) (the sphere must start inside the cube), got {r0!r}")
    r_end = reach if r_end is None else r_end
    if isinstance(r_end, bool) or not isinstance(r_end, numbers.Real) or not (np.isfinite(r_end) and r_end > r0):
        raise ValueError(f"r_end must be finite and > r0 = {r0}, got {r_end!r}")
    law = SpacingLaw(h_min, h_max, band, grade=grade)
    from tqdm.auto import tqdm

    mesh = unit_cube_mesh(cells)
    meshes, radii = [mesh], [float(r0)]
    rows = [_sphere_row(0, float(r0), mesh, c, law)]
    for k in tqdm(range(1, steps + 1), desc="growing sphere", unit="step", disable=True if progress is False else None,
                  leave=False):
        radius = float(r0 + (r_end - r0) * k / steps)

        def size(x: np.ndarray, radius: float = radius) -> np.ndarray:
            return law.h(np.abs(np.linalg.norm(x - c, axis=1) - radius))

        started = time.process_time()
        mesh = evolve_tet(mesh, size=size, seed=seed + k, **options)
        meshes.append(mesh)
        radii.append(radius)
        rows.append(_sphere_row(k, radius, mesh, c, law))
        rows[-1]["cpu_seconds"] = time.process_time() - started
    result = GrowingSphere(meshes, radii, rows, c, law)
    if out is not None:
        result.write(out, figures=figures)
    return result
