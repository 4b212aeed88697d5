"""Element quality: angles and radius-edge ratios (paper, Definition 2.1)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from evomesh import _core
from evomesh.mesh import Mesh
from evomesh.spacing_function import _require_mesh

__all__ = ["quality", "Quality", "triangle_angles", "integral_inverse_square"]


def triangle_angles(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Interior angles in degrees, shape (m, 3); angle k is at vertex k."""
    p = points[triangles]
    e0 = p[:, 2] - p[:, 1]  # opposite vertex 0
    e1 = p[:, 0] - p[:, 2]
    e2 = p[:, 1] - p[:, 0]
    l0, l1, l2 = (np.linalg.norm(e, axis=1) for e in (e0, e1, e2))

    # angle opposite a, law of cosines, clipped for rounding
    def angle(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
        return np.degrees(np.arccos(np.clip((b * b + c * c - a * a) / (2 * b * c), -1.0, 1.0)))

    return np.stack([angle(l0, l1, l2), angle(l1, l2, l0), angle(l2, l0, l1)], axis=1)


@dataclass(frozen=True)
class Quality:
    """Quality figures of a mesh.

    Attributes
    ----------
    min_angle, max_angle : float
        Smallest and largest interior angle, degrees.
    max_radius_edge : float
        Largest circumradius / shortest edge (1/sqrt(3) for equilateral).
    mean_radius_edge : float
    n_points, n_triangles : int
    angle_histogram : ndarray, shape (18,)
        Counts of all angles in 10-degree bins [0, 10), ..., [170, 180].
    angle_bins : ndarray, shape (19,)
    min_angle_triangle : int
        Index of the triangle with the smallest angle.
    min_angle_location : ndarray, shape (2,)
        Centroid of that triangle.
    """

    min_angle: float
    max_angle: float
    max_radius_edge: float
    mean_radius_edge: float
    n_points: int
    n_triangles: int
    angle_histogram: np.ndarray = field(repr=False)
    angle_bins: np.ndarray = field(repr=False)
    min_angle_triangle: int
    min_angle_location: np.ndarray = field(repr=False)

    def table(self) -> str:
        rows = [
            ("points", f"{self.n_points}"),
            ("triangles", f"{self.n_triangles}"),
            ("min angle (deg)", f"{self.min_angle:.2f}"),
            ("max angle (deg)", f"{self.max_angle:.2f}"),
            ("max radius-edge", f"{self.max_radius_edge:.3f}"),
            ("mean radius-edge", f"{self.mean_radius_edge:.3f}"),
        ]
        width = max(len(r[0]) for r in rows)
        lines = [f"{name:<{width}}  {value}" for name, value in rows]
        lines.append("angle histogram (10-degree bins): " + " ".join(str(int(c)) for c in self.angle_histogram))
        return "\n".join(lines)


def radius_edge_ratios(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    p = points[triangles]
    a = np.linalg.norm(p[:, 1] - p[:, 0], axis=1)
    b = np.linalg.norm(p[:, 2] - p[:, 1], axis=1)
    c = np.linalg.norm(p[:, 0] - p[:, 2], axis=1)
    d1 = p[:, 1] - p[:, 0]
    d2 = p[:, 2] - p[:, 0]
    area = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    circumradius = a * b * c / (4 * area)
    return circumradius / np.minimum(np.minimum(a, b), c)


def quality(mesh: Mesh) -> Quality:
    """Angles and radius-edge ratios of every triangle, summarised (one parallel
    pass in C++ with the formulas of triangle_angles and radius_edge_ratios)."""
    _require_mesh(mesh)
    min_angle, max_angle, max_ratio, sum_ratio, worst, hist = _core.quality_summary(mesh.points, mesh.triangles)
    bins = np.arange(0, 181, 10, dtype=float)
    return Quality(
        min_angle=float(min_angle),
        max_angle=float(max_angle),
        max_radius_edge=float(max_ratio),
        mean_radius_edge=float(sum_ratio) / mesh.n_triangles,
        n_points=mesh.n_points,
        n_triangles=mesh.n_triangles,
        angle_histogram=hist,
        angle_bins=bins,
        min_angle_triangle=int(worst),
        min_angle_location=mesh.points[mesh.triangles[worst]].mean(axis=0),
    )


def integral_inverse_square(
    points: np.ndarray, triangles: np.ndarray, f: Callable[[np.ndarray], np.ndarray], levels: int = 2,
    chunk: int = 100_000,
) -> float:
    """The integral of 1/f^2 over triangles (the paper's measure of the smallest
    mesh for a spacing f: n / integral is the size ratio the benchmarks report).

    Midpoint rule on each triangle split into 4**levels similar triangles, in
    chunks of ``chunk`` triangles (bounded memory).

    Parameters
    ----------
    points : ndarray, shape (n, 2)
    triangles : ndarray of int, shape (m, 3)
    f : callable
        f(x) for x of shape (k, 2), returning (k,) positive values.
    """
    k = 2**levels
    bary = np.array([((i + s / 3) / k, (j + s / 3) / k) for i in range(k) for j in range(k - i)
                     for s in ((1, 2) if i + j < k - 1 else (1,))])
    p = np.asarray(points)[np.asarray(triangles)]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    areas = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    total = 0.0
    for start in range(0, len(p), chunk):
        q = p[start : start + chunk]
        x = q[:, None, 0] + bary[None, :, 0, None] * (q[:, None, 1] - q[:, None, 0]) + bary[None, :, 1, None] * (
            q[:, None, 2] - q[:, None, 0]
        )
        values = 1.0 / np.asarray(f(x.reshape(-1, 2)), dtype=np.float64) ** 2
        total += float((values.reshape(len(q), -1).mean(axis=1) * areas[start : start + chunk]).sum())
    return total


class QualityWarning(UserWarning):
    """A step did not meet its angle goal: the quality pass could not run on the
    selected points (its mesher failed on near-degenerate geometry; the step
    returned their plain constrained Delaunay triangulation,
    ``stats["quality_failed"] == 1``), or it stopped at its bound on inserted
    points (``stats["quality_capped"] == 1``, small input angles or unresolved
    features). The step's mesh is valid either way."""


def _warn_quality(stats: dict[str, Any], stacklevel: int) -> None:
    """The QualityWarning a step's stats call for (serial and distributed steps)."""
    if stats.get("quality_failed"):
        warnings.warn(
            "the quality pass failed on this step's points (near-degenerate geometry); the step kept their plain "
            f"constrained Delaunay triangulation (min angle {stats.get('min_angle', float('nan')):.3g} deg)",
            QualityWarning,
            stacklevel=stacklevel,
        )
    if stats.get("quality_capped"):
        warnings.warn(
            "the quality pass stopped at its bound on inserted points before every angle met min_angle (smallest "
            f"angle {stats.get('min_angle', float('nan')):.3g} deg, near ({stats.get('min_angle_x', 0):.6g}, "
            f"{stats.get('min_angle_y', 0):.6g})): the domain has small input angles or features the "
            "spacing does not resolve; refine there, or raise quality_max_fraction / quality_max_extra",
            QualityWarning,
            stacklevel=stacklevel,
        )
