"""Carry per-vertex fields from a mesh to the mesh evolved from it."""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from evomesh import _core
from evomesh.mesh import Mesh
from evomesh.spacing import _require_mesh

__all__ = ["transfer", "Interpolation"]

# A new point farther than this (relative to the old mesh's extent) from the
# old domain is an error, not rounding.
_OUTSIDE_TOLERANCE = 1e-9
_CHUNK = 4096


class Interpolation:
    """How each point of ``new`` takes its value from ``old``; reusable for many fields.

    Kept points (``new.origin >= 0``) copy the value at their origin exactly;
    every other point interpolates linearly in the old triangle containing it,
    located by the C++ core (CGAL, O(log n) per point). Points that rounding put
    just outside the old domain interpolate on the nearest old boundary edge.

    Attributes
    ----------
    kept : ndarray of bool, shape (n_new,)
    origin : ndarray of int, shape (n_new,)
    vertices : ndarray of int, shape (n_located, 3)
        Old points whose values mix into each non-kept new point.
    weights : ndarray, shape (n_located, 3)
        Barycentric weights (sum to 1).
    """

    def __init__(self, old: Mesh, new: Mesh):
        _require_mesh(old)
        _require_mesh(new)
        origin = new.origin
        kept = origin >= 0
        if kept.any():
            if origin.max() >= old.n_points:
                raise ValueError(
                    f"new.origin refers to point {int(origin.max())} but old has {old.n_points} points: "
                    "new was not evolved from old"
                )
            if not (new.points[kept] == old.points[origin[kept]]).all():
                raise ValueError("kept points of new differ from their origin in old: new was not evolved from old")
        self.n_old = old.n_points
        self.kept = kept
        self.origin = origin
        self.located = np.flatnonzero(~kept)
        queries = new.points[self.located]
        triangle, weights = _core.locate_points(old.points, old.triangles, queries)
        vertices = old.triangles[np.maximum(triangle, 0)]
        outside = np.flatnonzero(triangle < 0)
        if len(outside):
            vertices = vertices.copy()
            weights = weights.copy()
            v, w = _nearest_boundary_edge(old, queries[outside])
            vertices[outside] = v
            weights[outside] = w
        self.vertices = vertices
        self.weights = weights

    def __call__(self, values: Any) -> np.ndarray:
        """Values at the new points, shape (n_new,) + values.shape[1:]."""
        array = np.asarray(values)
        if array.dtype == object or array.dtype.kind not in "fiuc":
            raise TypeError(f"values must be a numeric array, got dtype {array.dtype}")
        if array.ndim == 0 or array.shape[0] != self.n_old:
            raise ValueError(
                f"values must have one row per point of the old mesh: shape ({self.n_old}, ...), got {array.shape}"
            )
        dtype = array.dtype if array.dtype.kind in "fc" else np.dtype(np.float64)
        flat = array.reshape(self.n_old, -1)
        out = np.empty((len(self.kept), flat.shape[1]), dtype=dtype)
        out[self.kept] = flat[self.origin[self.kept]]  # exact copy, bit for bit
        mixed = np.einsum("kj,kjc->kc", self.weights, flat[self.vertices].astype(np.result_type(dtype, np.float64)))
        out[self.located] = mixed.astype(dtype, copy=False)
        return out.reshape((len(self.kept),) + array.shape[1:])


def _nearest_boundary_edge(old: Mesh, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation on the nearest boundary edge, for points that lie
    outside the old domain by rounding only."""
    edges = old.segments[old.segment_is_boundary]
    a = old.points[edges[:, 0]]
    b = old.points[edges[:, 1]]
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    scale = float(np.ptp(old.points, axis=0).max())
    vertices = np.empty((len(queries), 3), dtype=np.int64)
    weights = np.zeros((len(queries), 3))
    for start in range(0, len(queries), _CHUNK):
        q = queries[start : start + _CHUNK, None, :]
        t = np.clip(np.einsum("qkj,kj->qk", q - a[None], d) / dd[None], 0.0, 1.0)
        gap = np.linalg.norm(q - (a[None] + t[..., None] * d[None]), axis=2)
        best = gap.argmin(axis=1)
        rows = np.arange(len(best))
        worst = gap[rows, best].max()
        if worst > _OUTSIDE_TOLERANCE * scale:
            k = start + int(np.argmax(gap[rows, best]))
            raise ValueError(
                f"point {queries[k].tolist()} of the new mesh lies outside the old mesh (by {worst:.3g}): "
                "transfer needs the new mesh to cover the same domain"
            )
        tb = t[rows, best]
        edge = edges[best]
        vertices[start : start + len(best)] = np.c_[edge, edge[:, 0]]
        weights[start : start + len(best), 0] = 1.0 - tb
        weights[start : start + len(best), 1] = tb
    return vertices, weights


def transfer(old: Mesh, new: Mesh, values: Any) -> Any:
    """Per-vertex field(s) of ``old`` at the points of ``new``.

    Exact copy at kept points (``new.origin >= 0``), linear interpolation in
    the old triangle elsewhere. A linear function is reproduced exactly (up to
    rounding); kept values are copied bit for bit.

    Parameters
    ----------
    old : Mesh
        The mesh the values live on.
    new : Mesh
        A mesh of the same domain, normally ``evolve(old, ...)``; its
        ``origin`` must index ``old`` (a mesh with all origins -1 is
        interpolated everywhere).
    values : array_like, shape (n_old,) or (n_old, ...), or a mapping of them
        Scalar or vector fields. Floating and complex dtypes are kept; integer
        fields become float64. A mapping (name -> array) gives a dict, with
        one point location for all fields.

    Returns
    -------
    ndarray, shape (n_new,) + values.shape[1:], or dict of them
        New arrays; the inputs are not modified.

    Raises
    ------
    TypeError
        If old or new is not a Mesh, or values are not numeric.
    ValueError
        If values do not have one row per old point, if new's origins do not
        match old, or a new point lies outside the old domain.
    """
    interpolation = Interpolation(old, new)
    if isinstance(values, Mapping):
        return {name: _named(interpolation, name, v) for name, v in values.items()}
    return interpolation(values)


def _named(interpolation: Interpolation, name: Any, values: Any) -> np.ndarray:
    try:
        return interpolation(values)
    except (TypeError, ValueError) as error:
        raise type(error)(f"field {name!r}: {error}") from None
