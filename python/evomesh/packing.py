"""Sphere packings: the lexical-first maximal independent set (Section 3.2)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evomesh import _core

__all__ = ["lexical_first_mis"]


def lexical_first_mis(
    centers: ArrayLike, radii: ArrayLike, order: ArrayLike | None = None, *, n_forced: int = 0
) -> NDArray[np.bool_]:
    """Lexical-first maximal independent set of the sphere conflict graph.

    Two spheres conflict when their interiors overlap, |c1 - c2| < r1 + r2.
    Spheres are visited in ``order``; a sphere is kept unless it conflicts with
    a sphere kept before it. The first ``n_forced`` spheres of the order are kept
    unconditionally (mesh corners). O(n log n) with a kd-tree (hand-written, C++).

    Parameters
    ----------
    centers : array_like, shape (n, 2)
    radii : array_like, shape (n,)
        Finite and > 0.
    order : array_like of int, shape (n,), optional
        A permutation of 0..n-1; default: increasing radius, ties by index.
    n_forced : int

    Returns
    -------
    ndarray of bool, shape (n,)
        True for kept spheres.
    """
    c = np.asarray(centers, dtype=np.float64)
    r = np.asarray(radii, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 2:
        raise ValueError(f"centers must have shape (n, 2), got {c.shape}")
    if r.shape != (len(c),):
        raise ValueError(f"radii must have shape ({len(c)},), got {r.shape}")
    if order is None:
        order = np.lexsort((np.arange(len(r)), r))
    o = np.asarray(order)
    if o.dtype.kind not in "iu":
        raise TypeError(f"order must be an integer array, got dtype {o.dtype}")
    if o.shape != (len(c),) or not np.array_equal(np.sort(o), np.arange(len(c))):
        raise ValueError("order must be a permutation of 0..n-1")
    if not 0 <= n_forced <= len(c):
        raise ValueError(f"n_forced must be in [0, {len(c)}]")
    return _core.lexical_first_mis(c, r, o.astype(np.int64), int(n_forced)).astype(bool)
