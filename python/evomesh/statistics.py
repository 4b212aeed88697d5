"""Statistics of one evolution step: the paper's Table 1 columns plus ours."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from evomesh.mesh import Mesh
from evomesh.mesh_quality import quality
from evomesh.spacing_function import _require_mesh, as_delta
from evomesh.typing import ArrayLike, FloatArray

__all__ = ["STATISTICS_COLUMNS", "new_spacing_at_old_points", "nn_at", "step_statistics"]

#: Columns of the per-step statistics; the first six are the paper's Table 1.
STATISTICS_COLUMNS = (
    "iteration",
    "points",
    "original_points",
    "original_pct",
    "triangles",
    "min_angle_deg",
    "time",
    "max_radius_edge",
    "spacing_ratio_max",
    "spacing_ratio_p99",
    "seconds",
)


def nn_at(points: np.ndarray, probes: np.ndarray, tree: cKDTree | None = None) -> FloatArray:
    """nn_M(x) at probe points: distance to the nearest mesh point other than x
    itself (x may or may not be a mesh point), shape (k,)."""
    tree = cKDTree(points) if tree is None else tree
    d, _ = tree.query(probes, k=2)
    return np.where(d[:, 0] == 0, d[:, 1], d[:, 0])


def new_spacing_at_old_points(old: Mesh, new: Mesh) -> FloatArray:
    """nn_M'(p) for every old point p: the distance from p to its nearest other
    point of the new mesh, shape (old.n_points,). Kept points read the new mesh's
    cached nn spacing; only the removed ones are searched for (a k-d tree of the
    new points), so a step that keeps most points costs O(n) here."""
    _require_mesh(old)
    _require_mesh(new)
    out = np.empty(old.n_points)
    kept = np.flatnonzero(new.origin >= 0)
    origin = new.origin[kept]
    if len(origin) and origin.max() >= old.n_points:
        raise ValueError("new.origin does not index old: new was not evolved from old")
    out[origin] = new.nn_spacing[kept]
    removed = np.ones(old.n_points, dtype=bool)
    removed[origin] = False
    if removed.any():
        out[removed] = nn_at(new.points, old.points[removed])
    return out


def step_statistics(old: Mesh, new: Mesh, delta: ArrayLike, *, nn_old: np.ndarray | None = None) -> dict[str, float]:
    """Statistics of one evolution step, as in the paper's Table 1 plus ours.

    Parameters
    ----------
    old, new : Mesh
        The mesh before and after the step (``new.origin`` indexes ``old``).
    delta : array_like, shape (old.n_points,)
        The factor applied to ``old``.
    nn_old : ndarray, optional
        ``nn_spacing(old)`` if already computed.

    Returns
    -------
    dict
        points, original_points (points of new kept from old, the paper's
        "# of original points"), original_pct (100 * original / points),
        triangles, min_angle_deg, max_radius_edge, and the spacing ratio
        nn_M'(p) / (delta(p) nn_M(p)) over the old points p: its maximum
        (spacing_ratio_max) and 99th percentile (spacing_ratio_p99). The
        paper's guarantee (Definition 2.6) is ratio <= 1 up to a constant.
    """
    _require_mesh(old)
    _require_mesh(new)
    d = as_delta(old, delta)
    nn_old = old.nn_spacing if nn_old is None else nn_old
    ratio = new_spacing_at_old_points(old, new) / (d * nn_old)
    q = quality(new)
    original = int((new.origin >= 0).sum())
    return {
        "points": new.n_points,
        "original_points": original,
        "original_pct": 100.0 * original / new.n_points,
        "triangles": new.n_triangles,
        "min_angle_deg": q.min_angle,
        "max_radius_edge": q.max_radius_edge,
        "spacing_ratio_max": float(ratio.max()),
        "spacing_ratio_p99": float(np.percentile(ratio, 99)),
    }
