"""Spacing functions (paper, Section 3.1)."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evomesh import _core
from evomesh.mesh import _MAX_COORDINATE, Mesh, _as_array

__all__ = ["nn_spacing", "spacing", "SpacingFunction", "as_delta", "delta_from_size", "DELTA_MIN", "DELTA_MAX"]

#: Accepted range of the per-point factor delta: the paper's l <= delta <= L
#: (Definition 2.6). At DELTA_MIN one step grades the spacing by six orders of
#: magnitude towards a point (the sampler's grid follows f, so that takes a few
#: rings per octave, not a grid of f(p)-sized cells over the triangle; further
#: down, the quality pass's bound on inserted points and float64 run out); above
#: DELTA_MAX a point's new spacing is 1e6 times its old one, which already
#: coarsens any mesh down to its corners.
DELTA_MIN = 1e-6
DELTA_MAX = 1e6


def nn_spacing(mesh: Mesh) -> np.ndarray:
    """nn_M(p): distance from each point to its nearest other point of the mesh.

    The true nearest point (from the Delaunay triangulation of all points), not
    only the mesh neighbours.

    Returns
    -------
    ndarray, shape (n,)
    """
    _require_mesh(mesh)
    return np.array(mesh.nn_spacing)  # cached on the mesh; a writable copy for the caller


def as_delta(mesh: Mesh, delta: ArrayLike) -> NDArray[np.float64]:
    """Validate a per-point factor delta: shape (n,) (or a scalar), finite, in
    [DELTA_MIN, DELTA_MAX]; returns a float64 copy."""
    array = _as_array(delta, "delta")
    if array.dtype == object or array.dtype.kind not in "fiu":
        raise TypeError(f"delta must be a real numeric array, got dtype {array.dtype}")
    with np.errstate(over="ignore"):  # long double beyond float64 becomes inf, rejected below
        array = np.array(np.broadcast_to(array, (mesh.n_points,)) if array.ndim == 0 else array, dtype=np.float64)
    if array.shape != (mesh.n_points,):
        raise ValueError(f"delta must have one value per point: shape ({mesh.n_points},), got {array.shape}")
    bad = ~np.isfinite(array) | (array <= 0)
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(f"delta must be finite and > 0; delta[{k}] = {array[k]}")
    bad = (array < DELTA_MIN) | (array > DELTA_MAX)
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(
            f"delta must be in [{DELTA_MIN:g}, {DELTA_MAX:g}]; delta[{k}] = {array[k]:g}. delta is relative: the new "
            "spacing at p is delta(p) times the current one, nn_M(p); for an absolute spacing pass size= instead"
        )
    return array


# size= (delta_from_size): the rule and its calibration are the core's
# (size_request.hpp, Size_rule), the same in every scope.


def _size_values(mesh: Mesh, size: Any) -> NDArray[np.float64]:
    """h at the mesh points: a number, one value per point, or a callable h(x)."""
    n = mesh.n_points
    what = "size(x)" if callable(size) else "size"
    values = _as_array(size(np.array(mesh.points)) if callable(size) else size, what)
    if values.dtype == object or values.dtype.kind not in "fiu":
        raise TypeError(f"{what} must be real numbers, got dtype {values.dtype}")
    with np.errstate(over="ignore"):
        h = np.array(np.broadcast_to(values, (n,)) if values.ndim == 0 else values, dtype=np.float64)
    if h.shape != (n,):
        raise ValueError(f"{what} must give one value per point: shape ({n},), got {h.shape}")
    bad = ~np.isfinite(h) | (h <= 0)
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(f"{what} must be finite and > 0; at point {k} it is {h[k]}")
    return h


def delta_from_size(mesh: Mesh, size: ArrayLike | Callable[[np.ndarray], ArrayLike], *,
                    keep_fine_clusters: bool = True) -> NDArray[np.float64]:
    """The relative factor delta(p) that :func:`evomesh.evolve` uses for ``size=h``.

    ``size`` is what MMG and Gmsh users mean by a size: the edge length wanted
    at x. The median edge length of the output over the request is within
    about 10 % of 1 (uniform requests 0.5 to 2 times the current edge length,
    graded ones; benchmarks/stays_put.py). delta keeps its own meaning: the
    new spacing (nearest-neighbour distance) at p is about delta(p) nn_M(p).

    Around each point p, L(p) is the mean of edge length over h (h at the
    edge's midpoint, linear along it) over the edges of p and of its neighbours:

    - L(p) > 1.25: the mesh is too coarse; delta(p) = h(p) / (1.35 nn_M(p)),
      since a refining step's edges are 1.25-1.4 times its new spacing (the
      refined neighbourhood lands inside the band, not at its edge; applied
      where that is below 0.8: a slighter refinement adds a point here and
      there, step after step);
    - L(p) < 1 / 1.25: too fine; delta(p) = h(p) / nn_M(p), except within
      three edges of a point with L >= 1 / 1.1 (a finer cluster among points
      that meet the request: near segments, small angles, required points,
      graded requests; a step that coarsens it gets it back from the quality
      pass) unless a path of at most three edges through too-fine points
      joins it to two too-fine neighbours that coarsen (then it is the rim of
      a region coarsening back, where a fine request has passed), and except
      at a point with no too-fine neighbour (on its own it coarsens nothing:
      its neighbours' spacing caps the spacing around it, and a corner or a
      segment's end point stays anyway). ``keep_fine_clusters=False`` (what
      ``evolve`` uses after a ``displacement=``: a moved mesh has nothing
      settled to keep) drops these exceptions. The neighbours of a coarsening
      point with L < 1 / 1.1 coarsen to the request with it, so a region
      coarsens back to the request (median edge / h within 10 %) in one or
      two steps, not to the fine end of the band;
    - elsewhere the mesh meets the request: delta(p) = 1 exactly, and a step
      leaves such a neighbourhood as it is (the option ``skip_settled``). So
      ``evolve(evolve(m, size=h), size=h)`` changes next to nothing: at most
      0.1 % of the points at the second such step and none from the third on
      (tests/test_stays_put.py, about 1e4 points), where ``m`` was within
      about twice the request; where it was coarser, a step more per doubling
      (see below).

    Limits: a request up to 1.25 times finer or 1.25 times coarser than the
    mesh leaves it as it is (a step that coarsens next to such a place takes
    its finer points to the request); a finer pocket within three edges of
    points that meet the request and joined to no coarsening region (a spot
    refined by a few rings only) is kept, as such a cluster is; coarsening a
    regular lattice by less than about 1.5 changes it little (its packing
    keeps all points or about half of them); a request more than about twice finer than the mesh is met in two
    steps (the spacing function grades from the old points, Lemma 3.1).

    Parameters
    ----------
    mesh : Mesh
    size : float, array_like of shape (n,), or callable
        h > 0: a number, one value per point, or a function h(x) of an (n, 2)
        array of coordinates returning (n,) values (called once, on the points).
    keep_fine_clusters : bool, default True
        See above.

    Returns
    -------
    ndarray, shape (n,)
        delta, in [DELTA_MIN, DELTA_MAX].

    Raises
    ------
    TypeError, ValueError
        h not real, of the wrong shape, not finite and > 0, or asking for a
        factor outside [DELTA_MIN, DELTA_MAX] at a point.
    """
    _require_mesh(mesh)
    h = _size_values(mesh, size)
    # L(p) (each edge against the request at its midpoint, h taken as linear
    # along it; the mean over the edges at p, each counted once per triangle
    # corner at p, then over p and its neighbours), the band, the settled
    # clusters and the check: the core's one rule (size_request.hpp), which
    # the distributed step and the interface step call too.
    return _core.delta_from_size(np.asarray(mesh.points), np.asarray(mesh.triangles), h, mesh.nn_spacing,
                                 keep_fine_clusters, DELTA_MIN, DELTA_MAX)


def _as_sites(x: Any, name: str) -> np.ndarray:
    """Real, shape (k, 2), finite, within the coordinate limit of a Mesh; a float64 copy."""
    array = _as_array(x, name)
    if array.dtype == object or array.dtype.kind not in "fiu":
        raise TypeError(f"{name} must be a real numeric array, got dtype {array.dtype}")
    with np.errstate(over="ignore"):
        array = np.array(array, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"{name} must have shape (k, 2), got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} contain NaN or infinite coordinates")
    if array.size and np.abs(array).max() > _MAX_COORDINATE:
        raise ValueError(f"{name} coordinates must be below {_MAX_COORDINATE:g} in magnitude")
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

    ``triangles`` (optional, indices into ``sites``: the mesh's) lets the
    construction leave out sites hidden by a neighbour before they reach the
    graph; f is the same with or without.
    """

    def __init__(self, sites: Any, weights: Any, triangles: Any = None):
        sites = _as_sites(sites, "sites")
        if len(sites) == 0:
            raise ValueError("a spacing function needs at least one site")
        w = _as_array(weights, "weights")
        if w.dtype == object or w.dtype.kind not in "fiu":
            raise TypeError(f"weights must be a real numeric array, got dtype {w.dtype}")
        with np.errstate(over="ignore"):
            w = np.array(w, dtype=np.float64)
        if w.shape != (len(sites),):
            raise ValueError(f"weights must have shape ({len(sites)},), got {w.shape}")
        if not (np.isfinite(w) & (w >= 0)).all():
            raise ValueError("weights must be finite and >= 0")
        self.sites = sites
        self.weights = w
        tris = None
        if triangles is not None:
            tris = _as_array(triangles, "triangles")
            if tris.dtype == object or tris.dtype.kind not in "iu" or tris.ndim != 2 or tris.shape[1] != 3:
                raise ValueError("triangles must be an integer array of shape (m, 3)")
            if tris.size and (tris.min() < 0 or tris.max() >= len(sites)):
                raise ValueError(f"triangles have a point index out of range [0, {len(sites)})")
        self._graph = _core.SpacingFunction(sites, w, 0, tris)

    @property
    def n_hidden(self) -> int:
        return self._graph.n_hidden

    def _query(self, x: Any) -> tuple[np.ndarray, np.ndarray]:
        array = _as_array(x, "query points")
        single = array.ndim == 1
        array = _as_sites(np.atleast_2d(array) if single else array, "query points")
        f, site = self._graph.evaluate(array)
        return (f[0], site[0]) if single else (f, site)

    def __call__(self, x: Any) -> np.ndarray:
        """f at points x, shape (k, 2) -> (k,) (a single point (2,) gives a float)."""
        return self._query(x)[0]

    def nearest_site(self, x: ArrayLike) -> NDArray[np.int64]:
        """Index of the point p whose cone delta(p) nn(p) + |x - p| is lowest at x."""
        return self._query(x)[1]

    def __repr__(self) -> str:
        return f"SpacingFunction(n_sites={len(self.sites)}, n_hidden={self.n_hidden})"


def spacing(mesh: Mesh, delta: ArrayLike) -> SpacingFunction:
    """The new spacing function of the evolving mesh problem (Eq. 2-3).

    Parameters
    ----------
    mesh : Mesh
    delta : array_like, shape (n,), or a scalar
        Per-point factor: < 1 refines, > 1 coarsens; finite and in
        [:data:`DELTA_MIN`, :data:`DELTA_MAX`] = [1e-6, 1e6].

    Raises
    ------
    TypeError
        If mesh is not a Mesh or delta is not real.
    ValueError
        If delta has the wrong shape, or a value that is NaN, infinite or out of range.
    """
    _require_mesh(mesh)
    d = as_delta(mesh, delta)
    return SpacingFunction(mesh.points, d * mesh.nn_spacing, mesh.triangles)


def _require_mesh(mesh: Any) -> None:
    if not isinstance(mesh, Mesh):
        raise TypeError(f"expected an evomesh.Mesh, got {type(mesh).__name__}")
