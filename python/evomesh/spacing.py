"""Spacing functions (paper, Section 3.1)."""

from __future__ import annotations

from typing import Any

import numpy as np

from evomesh import _core
from evomesh.mesh import Mesh

__all__ = ["nn_spacing", "spacing", "SpacingFunction", "as_delta"]


def nn_spacing(mesh: Mesh) -> np.ndarray:
    """nn_M(p): distance from each point to its nearest other point of the mesh.

    The true nearest point (from the Delaunay triangulation of all points), not
    only the mesh neighbours.

    Returns
    -------
    ndarray, shape (n,)
    """
    _require_mesh(mesh)
    return _core.nn_spacing(mesh.points)


def as_delta(mesh: Mesh, delta: Any) -> np.ndarray:
    """Validate a per-point factor delta: shape (n,) (or a scalar), finite, > 0."""
    array = np.asarray(delta)
    if array.dtype == object or array.dtype.kind not in "fiu":
        raise TypeError(f"delta must be a real numeric array, got dtype {array.dtype}")
    array = np.array(np.broadcast_to(array, (mesh.n_points,)) if array.ndim == 0 else array, dtype=np.float64)
    if array.shape != (mesh.n_points,):
        raise ValueError(f"delta must have one value per point: shape ({mesh.n_points},), got {array.shape}")
    bad = ~np.isfinite(array) | (array <= 0)
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(f"delta must be finite and > 0; delta[{k}] = {array[k]}")
    return array


class SpacingFunction:
    """f(x) = min_p (delta(p) nn_M(p) + |x - p|), callable on points.

    Evaluated through CGAL's Apollonius graph (additively weighted Voronoi
    diagram), in O(log n) per point for spatially coherent queries. It is the
    largest 1-Lipschitz spacing with f(p) <= delta(p) nn_M(p) (Lemma 4.5).

    Attributes
    ----------
    sites : ndarray, shape (n, 2)
        The mesh points.
    weights : ndarray, shape (n,)
        delta(p) nn_M(p) for every point.
    n_hidden : int
        Points whose cone never attains the minimum.
    """

    def __init__(self, sites: np.ndarray, weights: np.ndarray):
        self.sites = sites
        self.weights = weights
        self._graph = _core.SpacingFunction(sites, weights)

    @property
    def n_hidden(self) -> int:
        return self._graph.n_hidden

    def _query(self, x: Any) -> tuple[np.ndarray, np.ndarray]:
        array = np.asarray(x)
        if array.dtype == object or array.dtype.kind not in "fiu":
            raise TypeError(f"query points must be a real numeric array, got dtype {array.dtype}")
        single = array.ndim == 1
        array = np.atleast_2d(array).astype(np.float64)
        if array.ndim != 2 or array.shape[1] != 2:
            raise ValueError(f"query points must have shape (k, 2), got {np.shape(x)}")
        if not np.isfinite(array).all():
            raise ValueError("query points contain NaN or infinite coordinates")
        f, site = self._graph.evaluate(array)
        return (f[0], site[0]) if single else (f, site)

    def __call__(self, x: Any) -> np.ndarray:
        """f at points x, shape (k, 2) -> (k,) (a single point (2,) gives a float)."""
        return self._query(x)[0]

    def nearest_site(self, x: Any) -> np.ndarray:
        """Index of the point p whose cone delta(p) nn(p) + |x - p| is lowest at x."""
        return self._query(x)[1]

    def __repr__(self) -> str:
        return f"SpacingFunction(n_sites={len(self.sites)}, n_hidden={self.n_hidden})"


def spacing(mesh: Mesh, delta: Any) -> SpacingFunction:
    """The new spacing function of the evolving mesh problem (Eq. 2-3).

    Parameters
    ----------
    mesh : Mesh
    delta : array_like, shape (n,)
        Per-point factor: < 1 refines, > 1 coarsens.
    """
    _require_mesh(mesh)
    d = as_delta(mesh, delta)
    return SpacingFunction(mesh.points, d * _core.nn_spacing(mesh.points))


def _require_mesh(mesh: Any) -> None:
    if not isinstance(mesh, Mesh):
        raise TypeError(f"expected an evomesh.Mesh, got {type(mesh).__name__}")
