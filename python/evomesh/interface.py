"""Level-set interfaces: the zero set of phi as interior constraints that move with phi.

``evolve(mesh, delta, interface=phi)`` runs in three stages:

1. The cut (:func:`cut_mesh`, numpy, O(n log n)): the mesh edges where phi
   changes sign are found, the crossing points placed on phi = 0 (bracketed
   root finding on the edge for a function, linear interpolation for values
   at the points), and every triangle the zero set crosses is split along it.
   For a function, parts of the zero set between the points come first
   (:func:`_split_double_crossings`): edges next to the interface whose ends
   have one sign but where phi takes the other in between (a notch narrower
   than the spacing, where two circles meet) are split there, and a corner
   of the zero set inside a triangle (the notch's tip, where the normals at
   the triangle's two crossings turn sharply: their tangents meet there)
   splits the triangle, so that the cut passes through it.
   The previous interface (interior segments of the interface tag) is
   released: its edges become ordinary interior edges and its points ordinary
   interior points, which the step may remove. An old point next to a
   crossing moves onto it only where the interface then passes through it
   once (no pinch) and its component of one sign keeps a point (a circle
   around one point stays). Triangles take the region tag
   of their side. Every piece of the cut lies in one old triangle, so the
   cut's lineage is exact (barycentric coordinates in the old triangle).
2. The step: :func:`evomesh.evolve` on the cut mesh, with the interface as a
   curve (:class:`LevelSet`) so that every point the step creates on it lies
   on phi = 0 (on the piecewise-linear zero set for values at the points),
   and the spacing as an absolute size taken from the old mesh (the cut's
   short edges next to the crossings must not refine). The core caps the
   spacing near the interface by its local feature size (its own other side
   counts: a filament), and leaves a new interface point on its chord where
   the move onto phi = 0 would make the interface cross or fold onto itself.
3. The lineage of the step (points in the cut) composed with the cut's
   (cut in the old mesh): ``new.lineage`` refers to the old mesh, so
   :func:`evomesh.transfer` and :func:`evomesh.transfer_cells` work as after
   any step.
"""

from __future__ import annotations

import numbers
import re
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from evomesh import _core
from evomesh.geometry import DEFAULT_CORNER_ANGLE, BoundaryGeometry, as_geometry
from evomesh.mesh import Lineage, Mesh, PointKind
from evomesh.mesh_quality import QualityWarning, triangle_angles
from evomesh.spacing_function import DELTA_MAX, DELTA_MIN, _require_mesh, as_delta, delta_from_size

__all__ = ["LevelSet", "INTERFACE_TAG", "cut_mesh", "Cut", "default_regions"]

_CORNER, _BOUNDARY, _STEINER = (int(PointKind[name]) for name in ("CORNER", "BOUNDARY", "STEINER"))

#: Default segment tag of the interface's segments (interface_tag=).
INTERFACE_TAG: int = -1

# Root finding stops when the bracket is below this fraction of the coordinate
# scale (max |x| of the mesh): the crossing is then within 1e-14 of phi = 0,
# two orders inside the 1e-12 promised for interface points.
_ROOT_TOLERANCE = 1e-14
# A crossing this close (relative to the coordinate scale) to a vertex is the
# vertex: phi there is taken as 0 and no point is added.
_ON_VERTEX_TOLERANCE = 1e-13
# A crossing within this fraction of its edge from an interior vertex that no
# constraint holds moves the vertex onto it (instead of a new point next to it):
# the step would remove the vertex anyway (the crossing's sphere covers it), and
# the cut gets no edge shorter than this fraction, so no spacing below it.
_SNAP_FRACTION = 0.1
# The interface must meet the boundary (and other constraints) at least at this
# angle (degrees); below it is "tangent": refused with a clear error.
_MIN_MEETING_ANGLE = 5.0
# Below this fraction of min_angle, an angle next to the interface that the
# step reports in stats (the exception for curves) is also a QualityWarning;
# above it, moving points onto a curve after the quality pass leaves such
# angles routinely (28.6 degrees of 30 after coarsening a disc).
_ANGLE_WARNING_FRACTION = 0.9


class LevelSet:
    """The zero set of a function phi(x) of (k, 2) arrays, as an interface.

    Parameters
    ----------
    phi : callable
        ``phi(x) -> (k,)`` for points x of shape (k, 2), vectorised; negative on
        one side of the interface, positive on the other. Smooth with a non-zero
        gradient near the zero set (a signed distance is ideal).
    gradient : callable, optional
        ``gradient(x) -> (k, 2)``; default: central differences with a step of
        cbrt(eps) times the extent of the points (the mesh's, in a step),
        evaluated with phi itself in one call.
    max_iterations : int, default 50
        Of the Newton projection (:meth:`project`).

    Notes
    -----
    ``project`` moves points onto phi = 0 by Newton's iteration
    x <- x - phi(x) grad phi(x) / |grad phi(x)|^2 until the step is below four
    units of rounding of the coordinates: the result is within a few units of
    rounding of the zero set, whatever the scale of phi (1e160 or 1e-170).
    A step after which |phi| grew is halved (arctan-like phi), and with a given
    gradient a step that removed less than half of phi is lengthened by the
    secant ratio (a gradient off by a constant factor).
    """

    phi: Callable[[np.ndarray], Any]
    gradient: Callable[[np.ndarray], Any] | None
    max_iterations: int

    def __init__(self, phi: Callable[[np.ndarray], Any], gradient: Callable[[np.ndarray], Any] | None = None, *,
                 max_iterations: int = 50):
        if not callable(phi):
            raise TypeError(f"phi must be a function of a (k, 2) array, got {type(phi).__name__}")
        if gradient is not None and not callable(gradient):
            raise TypeError("gradient must be a function of a (k, 2) array or None")
        if isinstance(max_iterations, bool) or not isinstance(max_iterations, numbers.Integral) or max_iterations < 1:
            raise ValueError(f"max_iterations must be a positive integer, got {max_iterations!r}")
        self.phi = phi
        self.gradient = gradient
        self.max_iterations = int(max_iterations)

    def value(self, x: Any) -> np.ndarray:
        """phi at the points x (k, 2), checked: one finite real value each, shape (k,)."""
        points = np.array(x, dtype=np.float64).reshape(-1, 2)
        raw = np.asarray(self.phi(points.copy()))
        if raw.dtype == object or raw.dtype.kind not in "fiu":
            raise TypeError(f"interface phi must return real numbers, got dtype {raw.dtype}")
        values = np.array(np.broadcast_to(raw, (len(points),)) if raw.ndim == 0 else raw, dtype=np.float64)
        if values.shape != (len(points),):
            raise ValueError(f"interface phi(x) must return shape ({len(points)},) for {len(points)} points, got "
                             f"{values.shape}")
        bad = ~np.isfinite(values)
        if bad.any():
            k = int(np.argmax(bad))
            raise ValueError(f"interface phi is {values[k]} at ({points[k, 0]:.17g}, {points[k, 1]:.17g}): it must be "
                             "finite wherever the mesh is")
        return values

    def _value_and_gradient(self, x: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
        """phi and its gradient at x: one call of phi (at x and at x +- step
        along each axis, central differences), or phi and the given gradient."""
        if self.gradient is not None:
            value = self.value(x)
            g = np.asarray(self.gradient(x.copy()), dtype=np.float64)
            if g.shape != x.shape or not np.isfinite(g).all():
                raise ValueError("the interface gradient must return one finite (gx, gy) per point")
            return value, g
        ex = np.array([step, 0.0])
        ey = np.array([0.0, step])
        both = self.value(np.concatenate([x, x + ex, x - ex, x + ey, x - ey])).reshape(5, -1)
        return both[0], np.stack([both[1] - both[2], both[3] - both[4]], axis=1) / (2 * step)

    def project(self, points: Any, scale: float | None = None) -> np.ndarray:
        """The points moved onto phi = 0 (Newton), shape (k, 2); ValueError where
        the gradient vanishes or the iteration does not settle. ``scale``: the
        length of the finite differences' step over cbrt(eps) (default: the
        points' extent)."""
        x = np.array(points, dtype=np.float64).reshape(-1, 2)
        moved, settled = self._newton(x, scale)
        if not settled.all():
            k = int(np.argmin(settled))
            raise ValueError(f"the projection of ({x[k, 0]:.17g}, {x[k, 1]:.17g}) onto phi = 0 did not settle in "
                             f"{self.max_iterations} Newton steps (is phi smooth with a non-zero gradient near its "
                             "zero set?)")
        return moved

    def _newton(self, x: np.ndarray, scale: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Newton's iteration from every point: (the points reached, whether
        each settled). One call of phi per round (two with a given gradient).
        The step is (phi / |g|) g / |g| (no overflow for phi scaled by 1e160,
        no underflow at 1e-170); a step after which |phi| grew is halved
        instead (damped Newton: arctan-like phi); with a given gradient, a step
        that removed less than half of phi lengthens this and the later steps
        by the ratio (a secant correction: a gradient off by a constant factor), so that the end test
        (a step below four units of rounding) holds for the corrected step."""
        x = x.copy()
        settled = np.zeros(len(x), dtype=bool)
        if len(x) == 0:
            return x, settled
        tiny = np.finfo(np.float64).tiny
        if scale is None:
            scale = float(np.ptp(x, axis=0).max()) or float(max(np.abs(x).max(), tiny))
        step_length = np.cbrt(np.finfo(np.float64).eps) * scale
        ulp = np.finfo(np.float64).eps * np.maximum(np.abs(x).max(axis=1), tiny)
        previous = np.full(len(x), np.inf)  # |phi| before the last step
        last = np.zeros_like(x)  # the last step
        factor = np.ones(len(x))  # the secant correction of the step's length
        damped = np.zeros(len(x), dtype=bool)  # the last round halved the step (no secant ratio from it)
        active = np.arange(len(x))
        for _ in range(self.max_iterations):
            xa = x[active]
            value, g = self._value_and_gradient(xa, step_length)
            size = np.abs(value)
            worse = size > previous[active]
            # damped: back to the middle of the last step
            back = active[worse]
            last[back] *= 0.5
            x[back] -= last[back]
            norm = np.hypot(g[:, 0], g[:, 1])
            flat = (norm == 0) & ~worse
            with np.errstate(over="ignore", under="ignore"):
                g2 = (g * g).sum(axis=1)
            plain = (g2 > tiny / np.finfo(np.float64).eps) & np.isfinite(g2)
            ok = ~flat & ~worse
            step = np.zeros_like(xa)
            p, q = ok & plain, ok & ~plain
            step[p] = (value[p] / g2[p])[:, None] * g[p]
            step[q] = (value[q] / norm[q])[:, None] * (g[q] / norm[q][:, None])
            removed = np.where(np.isfinite(previous[active]), 1 - size / previous[active], 1.0)
            slow = ok & (removed < 0.5) & (removed > 0) & ~damped[active] & (self.gradient is not None)
            factor[active[slow]] /= np.maximum(removed[slow], 1e-3)
            damped[active] = worse
            step *= factor[active][:, None]
            x[active[ok]] = xa[ok] - step[ok]
            last[active[ok]] = -step[ok]
            previous[active[ok]] = size[ok]
            moved_by = np.hypot(*np.where(ok[:, None], step, -last[active]).T)
            done = ~flat & (moved_by <= 4 * ulp[active])
            settled[active[done]] = True
            active = active[~done & ~flat]
            if len(active) == 0:
                break
        return x, settled

    def __repr__(self) -> str:
        return f"LevelSet({self.phi!r})"


class _Polyline:
    """Projection onto a set of segments (the piecewise-linear zero set of
    values at the points): the nearest point of the nearest segment, among
    those whose midpoints are the 16 nearest (exact where segments are of
    similar length, which holds for a zero set cut from one mesh)."""

    def __init__(self, a: np.ndarray, b: np.ndarray):
        self.a = a
        self.d = b - a
        self.dd = np.einsum("ij,ij->i", self.d, self.d)
        self.tree = cKDTree(a + 0.5 * self.d)

    def distance_and_closest(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        k = min(16, len(self.a))
        _, item = self.tree.query(x, k=k)
        item = item.reshape(len(x), k)
        q = x[:, None, :] - self.a[item]
        t = np.clip(np.einsum("pkj,pkj->pk", q, self.d[item]) / np.maximum(self.dd[item], np.finfo(float).tiny), 0, 1)
        closest = self.a[item] + t[..., None] * self.d[item]
        gap = np.hypot(*(x[:, None, :] - closest).transpose(2, 0, 1))
        best = np.argmin(gap, axis=1)
        rows = np.arange(len(x))
        return gap[rows, best], closest[rows, best]

    def project(self, points: Any) -> np.ndarray:
        x = np.array(points, dtype=np.float64).reshape(-1, 2)
        return self.distance_and_closest(x)[1] if len(x) else x


# ----------------------------------------------------------------------------------------------------------------
# The cut


def _unique_edges(triangles: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Unique edges (e, 2) with e[:, 0] < e[:, 1], and the edge of every side
    (m, 3): side k runs from vertex k to vertex k + 1."""
    a = triangles
    b = np.roll(triangles, -1, axis=1)
    key = np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b)
    unique, inverse = np.unique(key.ravel(), return_inverse=True)
    return np.stack([unique // n, unique % n], axis=1), inverse.reshape(triangles.shape)


def _edge_roots(level: LevelSet, a: np.ndarray, b: np.ndarray, fa: np.ndarray, fb: np.ndarray,
                tolerance: float) -> np.ndarray:
    """t in (0, 1] with phi(a + t (b - a)) = 0 for phi(a) = fa < 0 <= fb = phi(b),
    to ``tolerance`` in length: the Illinois variant of regula falsi, vectorised
    over the edges (one call of phi per round for all unsettled edges), with a
    bisection whenever a round did not halve the bracket. The result is the
    end of the final bracket where |phi| is smaller."""
    k = len(a)
    t = np.ones(k)
    low, high = np.zeros(k), np.ones(k)
    value_low, value_high = fa.copy(), fb.copy()  # phi at the ends
    weight_low, weight_high = fa.copy(), fb.copy()  # the same, halved by Illinois
    last = np.zeros(k, dtype=np.int8)  # the end replaced in the previous round: -1 low, +1 high
    bisect = np.zeros(k, dtype=bool)
    length = np.hypot(*(b - a).T)
    active = np.flatnonzero(fb != 0)
    for _ in range(200):
        if len(active) == 0:
            break
        lo, hi = low[active], high[active]
        wlo, whi = weight_low[active], weight_high[active]
        width = hi - lo
        guess = lo + width * (wlo / (wlo - whi))
        use_middle = bisect[active] | ~((guess > lo) & (guess < hi))
        guess = np.where(use_middle, lo + 0.5 * width, guess)
        value = level.value(a[active] + guess[:, None] * (b[active] - a[active]))
        on = value == 0
        below = (value < 0) & ~on
        above = (value > 0) & ~on
        # Illinois: an end that stays twice in a row has its weight halved
        weight_high[active[below & (last[active] == -1)]] *= 0.5
        weight_low[active[above & (last[active] == 1)]] *= 0.5
        low[active[below]] = guess[below]
        value_low[active[below]] = value[below]
        weight_low[active[below]] = value[below]
        high[active[above]] = guess[above]
        value_high[active[above]] = value[above]
        weight_high[active[above]] = value[above]
        last[active] = np.where(below, -1, 1)
        new_width = high[active] - low[active]
        bisect[active] = new_width > 0.5 * width
        t[active[on]] = guess[on]
        settled = on | (new_width * length[active] <= tolerance) | (np.nextafter(low[active], 2.0) >= high[active])
        done = active[settled & ~on]
        t[done] = np.where(np.abs(value_low[done]) < np.abs(value_high[done]), low[done], high[done])
        active = active[~settled]
    if len(active):
        raise ValueError("the interface phi: root finding on an edge did not settle in 200 rounds (is phi "
                         "continuous?)")
    return np.where(t > 0, t, np.nextafter(0.0, 1.0))


def _along(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """a + t (b - a), from the nearer end (the rounding is relative to the short part)."""
    return np.where((t <= 0.5)[:, None], a + t[:, None] * (b - a), b - (1 - t)[:, None] * (b - a))


@dataclass(frozen=True)
class Cut:
    """A mesh cut along the zero set of phi (see :func:`cut_mesh`).

    Attributes
    ----------
    mesh : Mesh
        The cut mesh: the interface as interior segments of the interface tag,
        the triangles tagged by side, the previous interface released.
    old_index : ndarray of int, shape (n_cut,)
        The old point each cut point is (-1: a crossing, or an old point moved
        onto a crossing next to it).
    parent_triangle, barycentric : ndarray, shapes (n_cut,) and (n_cut, 3)
        For the others: the old triangle holding them and their barycentric
        coordinates there.
    triangle_parent : ndarray of int, shape (m_cut,)
        The old triangle each cut triangle lies in; -1 for those at a moved
        point (they overlap several).
    triangle_weights : ndarray, shape (m_cut, 3, 3)
        Barycentric coordinates of each cut triangle's vertices in its parent.
    curve : LevelSet or _Polyline
        What new interface points are projected onto: phi's zero set, or the
        piecewise-linear zero set of the values.
    n_crossings, n_moved : int
        Points added on edges, old points moved onto a crossing.
    regions : (int, int)
        Triangle tags of the negative and the positive side.
    scale : float
        The coordinate scale, max |x| of the mesh.
    """

    mesh: Mesh
    old_index: np.ndarray
    parent_triangle: np.ndarray
    barycentric: np.ndarray
    triangle_parent: np.ndarray
    triangle_weights: np.ndarray
    curve: Any
    n_crossings: int
    n_moved: int
    regions: tuple[int, int]
    scale: float


class _Counted:
    """A function that counts its calls (phi's, for stats["interface_phi_calls"])."""

    def __init__(self, function: Callable[[np.ndarray], Any]):
        self.function = function
        self.calls = 0

    def __call__(self, x: np.ndarray) -> Any:
        self.calls += 1
        return self.function(x)


def _level_values(mesh: Mesh, interface: Any) -> tuple[np.ndarray, LevelSet | None]:
    if isinstance(interface, LevelSet):  # (a copy that counts the calls: the user's object is left as it is)
        level = LevelSet(_Counted(interface.phi), interface.gradient, max_iterations=interface.max_iterations)
        return level.value(mesh.points), level
    if callable(interface):
        level = LevelSet(_Counted(interface))
        return level.value(mesh.points), level
    try:
        values = np.asarray(interface)
    except ValueError as error:
        raise ValueError("interface must be a function phi(x) or one value per mesh point") from error
    if values.dtype == object or values.dtype.kind not in "fiu":
        raise TypeError(f"interface must be a function phi(x) of (k, 2) arrays or real values at the points, got "
                        f"{type(interface).__name__} of dtype {values.dtype}")
    if values.shape != (mesh.n_points,):
        raise ValueError(f"interface values must have one value per mesh point: shape ({mesh.n_points},), got "
                         f"{values.shape}")
    values = values.astype(np.float64)
    bad = ~np.isfinite(values)
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(f"interface values must be finite; at point {k} it is {values[k]}")
    return values, None


def cut_mesh(mesh: Mesh, interface: Any, *, interface_tag: int = INTERFACE_TAG,
             regions: tuple[int, int] | None = None) -> Cut:
    """The mesh cut along the zero set of phi, with its lineage in ``mesh``.

    Parameters
    ----------
    mesh : Mesh
    interface : callable, LevelSet, or array_like of shape (n,)
        phi(x) on (k, 2) arrays, or its values at the mesh points.
    interface_tag : int
        Segment tag of the interface; interior segments of this tag in
        ``mesh`` (the previous interface) are released.
    regions : (int, int), optional
        Triangle tags of the negative and the positive side (default: see
        :func:`default_regions`).

    Returns
    -------
    Cut

    Raises
    ------
    ValueError
        phi is not finite, does not change sign on the mesh, or its zero set
        meets a boundary (or another constraint) at less than 5 degrees.
    """
    _require_mesh(mesh)
    interface_tag = _tag(interface_tag, "interface_tag")
    phi, level = _level_values(mesh, interface)
    if not (phi < 0).any() or not (phi > 0).any():
        raise ValueError(
            f"the interface phi does not change sign on the mesh (min {phi.min():.6g}, max {phi.max():.6g} at the "
            "points): there is no zero set to mesh (a zero set between the points is not resolved: refine first)")
    if level is None or _DOUBLE_CROSSING_ROUNDS == 0:  # (values: nothing to sample between the points)
        return _cut(mesh, phi, level, interface_tag, regions)
    fine, fine_phi, refinement, roots = _split_double_crossings(mesh, phi, level, interface_tag)
    cut = _cut(fine, fine_phi, level, interface_tag, regions, stay=mesh.n_points, roots=roots)
    return cut if refinement is None else _through_refinement(cut, mesh.n_points, refinement)


def _cut(mesh: Mesh, phi: np.ndarray, level: LevelSet | None, interface_tag: int, regions: Any,
         stay: int | None = None, roots: tuple[np.ndarray, np.ndarray] | None = None) -> Cut:
    """cut_mesh's body: the cut of ``mesh`` with phi's values at its points.
    Points from index ``stay`` on (the points _split_double_crossings added,
    inside a notch of the other sign) do not move onto a crossing next to them:
    the notch would close again."""
    P, T = mesh.points, mesh.triangles
    n = mesh.n_points
    scale = float(np.abs(P).max())
    edges, side_edge = _unique_edges(T, n)
    # Constraints that stay: boundary segments and interior segments of other tags.
    interior = ~mesh.segment_is_boundary
    released = interior & (mesh.segment_tags == interface_tag)
    kept_segments = mesh.segments[~released]
    kept_tags = mesh.segment_tags[~released]
    on_constraint = np.zeros(n, dtype=bool)
    on_constraint[kept_segments.ravel()] = True
    old_kind = mesh.kind
    movable = ~on_constraint & ~mesh.required
    if stay is not None:
        movable[stay:] = False
    key_constraint = np.sort(kept_segments, axis=1)
    edge_key = edges[:, 0] * n + edges[:, 1]
    edge_is_constraint = np.isin(edge_key, key_constraint[:, 0] * n + key_constraint[:, 1])
    # Boundary points of straight chains may slide along their segment onto a crossing there.
    slides = on_constraint & (old_kind == _BOUNDARY) & ~mesh.required

    # Crossing edges and their parameter t from the negative end (phi < 0) to the other (phi >= 0).
    values = phi.copy()
    neg = values < 0
    cross = np.flatnonzero(neg[edges[:, 0]] != neg[edges[:, 1]])
    lo_first = neg[edges[cross, 0]]
    a_end = np.where(lo_first, edges[cross, 0], edges[cross, 1])
    b_end = np.where(lo_first, edges[cross, 1], edges[cross, 0])
    if level is None:
        fa, fb = values[a_end], values[b_end]
        t = np.where(fb == 0, 1.0, fa / (fa - fb))
    else:
        t = np.empty(len(cross))
        known = np.zeros(len(cross), dtype=bool)
        if roots is not None and len(roots[0]):  # (found already: _corners)
            key = a_end * (1 << 31) + b_end
            at = np.minimum(np.searchsorted(roots[0], key), len(roots[0]) - 1)
            known = roots[0][at] == key
            t[known] = roots[1][at[known]]
        rest = ~known
        t[rest] = _edge_roots(level, P[a_end[rest]], P[b_end[rest]], values[a_end[rest]], values[b_end[rest]],
                              _ROOT_TOLERANCE * scale)
    length = np.hypot(*(P[b_end] - P[a_end]).T)
    raw_crossing = _along(P[a_end], P[b_end], t)

    # The piecewise-linear zero set of the values (before any snapping): what new
    # interface points are projected onto when phi is given at the points.
    curve: Any = level
    if level is None:
        pa, pb = _zero_set_segments(T, side_edge, neg, cross, raw_crossing)
        curve = _Polyline(pa, pb)

    # 1. Crossings at (or within rounding of) a vertex are that vertex: phi there is 0.
    near_a = t * length <= _ON_VERTEX_TOLERANCE * scale
    near_b = (1 - t) * length <= _ON_VERTEX_TOLERANCE * scale
    values[a_end[near_a]] = 0.0
    values[b_end[near_b]] = 0.0
    # 2. A crossing within _SNAP_FRACTION of its edge from a movable vertex moves the vertex onto it.
    d_a, d_b = t * length, (1 - t) * length
    close_a = ~near_a & ~near_b & (t <= _SNAP_FRACTION)
    close_b = ~near_a & ~near_b & (1 - t <= _SNAP_FRACTION)
    along_constraint = edge_is_constraint[cross]
    can_a = close_a & (movable[a_end] | (slides[a_end] & along_constraint))
    can_b = close_b & (movable[b_end] | (slides[b_end] & along_constraint))
    vertex = np.concatenate([a_end[can_a], b_end[can_b]])
    distance = np.concatenate([d_a[can_a], d_b[can_b]])
    crossing_of = np.concatenate([np.flatnonzero(can_a), np.flatnonzero(can_b)])  # (positions in cross)
    order = np.lexsort((distance, vertex))
    first = order[np.r_[True, vertex[order][1:] != vertex[order][:-1]]] if len(order) else order
    moved, crossing_of = vertex[first], crossing_of[first]
    # A move sets phi to 0 at its vertex: it must not take the last point of a
    # component of one sign (a small circle around a vertex would vanish).
    sign_component, n_components = _sign_components(edges, phi)
    rounded = values == 0  # (phi within rounding of 0 at them, or exactly)
    moved, crossing_of = _keep_components(sign_component, n_components, rounded, moved, crossing_of, distance[first])
    points = P.copy()
    while len(moved):
        valid = _valid_moves(points, T, moved, raw_crossing[crossing_of])
        # A moved point is on phi = 0: the interface must pass through it once
        # (two interface segments), not pinch there (two branches of the zero
        # set closer than the spacing, which the points do not separate).
        trial = values.copy()
        trial[moved] = 0.0
        valid &= _interface_degree(T, trial < 0)[moved] <= 2
        if valid.all():
            break
        moved, crossing_of = moved[valid], crossing_of[valid]
    if len(moved):
        points[moved] = raw_crossing[crossing_of]
        values[moved] = 0.0
    is_moved = np.zeros(n, dtype=bool)
    is_moved[moved] = True

    # The crossings again with the snapped values: t is kept where the edge's
    # ends kept their values, and a zero end is the crossing itself.
    neg = values < 0
    zero = values == 0
    cross2 = np.flatnonzero(neg[edges[:, 0]] != neg[edges[:, 1]])
    lo_first = neg[edges[cross2, 0]]
    a2 = np.where(lo_first, edges[cross2, 0], edges[cross2, 1])
    b2 = np.where(lo_first, edges[cross2, 1], edges[cross2, 0])
    position = np.searchsorted(cross, cross2)
    position = np.minimum(position, max(len(cross) - 1, 0))
    same = (cross[position] == cross2) if len(cross) else np.zeros(len(cross2), bool)
    at_vertex = zero[b2]
    new_point = ~at_vertex
    if not same[new_point].all():  # (an edge crossing now had no sign change before: impossible)
        raise AssertionError("cut: a crossing without a computed root")
    crossing_id = np.where(at_vertex, b2, -1)
    new_index = np.flatnonzero(new_point)
    crossing_id[new_index] = n + np.arange(len(new_index))
    new_points = raw_crossing[position[new_index]]
    t_new = t[position[new_index]]
    n_cut = n + len(new_index)
    all_points = np.concatenate([points, new_points])
    edge_crossing = np.full(len(edges), -1, dtype=np.int64)
    edge_crossing[cross2] = crossing_id

    # Lineage of the new points: on their edge, in a triangle holding it.
    side_owner = np.full(len(edges), -1, dtype=np.int64)
    side_slot = np.zeros(len(edges), dtype=np.int64)
    flat = side_edge.ravel()
    side_owner[flat[::-1]] = (np.arange(flat.size) // 3)[::-1]
    side_slot[flat[::-1]] = (np.arange(flat.size) % 3)[::-1]

    def on_edges(edge: np.ndarray, start: np.ndarray, along: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The first triangle with side `edge` and the barycentric coordinates
        there of the point at `along` from the edge's end `start`."""
        owner, slot = side_owner[edge], side_slot[edge]
        weights = np.zeros((len(edge), 3))
        rows = np.arange(len(edge))
        from_start = T[owner, slot] == start  # the side runs start -> other end
        weights[rows, slot] = np.where(from_start, 1 - along, along)
        weights[rows, (slot + 1) % 3] = np.where(from_start, along, 1 - along)
        return owner, weights

    owner, weights_new = on_edges(cross2[new_index], a2[new_index], t_new)

    # Split the triangles the zero set crosses.
    triangles, parent, negative, seg_a, seg_b = _split(T, side_edge, neg, edge_crossing, all_points)
    if len(seg_a) == 0:
        raise ValueError("the interface phi = 0 crosses no triangle of the mesh (every point of one sign lies within "
                         "rounding of phi = 0): there is no zero set to mesh")
    # Barycentric coordinates of the cut triangles' vertices in their parents:
    # an old vertex is a unit vector, a crossing has its weights on its edge.
    point_weights = np.zeros((n_cut, 3))
    point_owner = np.full(n_cut, -1, dtype=np.int64)
    point_weights[n:] = weights_new
    point_owner[n:] = owner
    vertex_weights = np.zeros((len(triangles), 3, 3))
    parent_vertices = T[parent]
    for k in range(3):
        v = triangles[:, k]
        old_vertex = v < n
        for j in range(3):
            vertex_weights[:, k, j] = np.where(old_vertex, v == parent_vertices[:, j], 0.0)
        crossing = np.flatnonzero(~old_vertex)
        owner_vertices = T[point_owner[triangles[crossing, k]]]
        for j in range(3):
            for i in range(3):
                vertex_weights[crossing, k, j] += np.where(owner_vertices[:, i] == parent_vertices[crossing, j],
                                                           point_weights[triangles[crossing, k], i], 0.0)
    # (a crossing lies on an edge of its parent, so its two weights land on that edge's ends)
    triangle_parent = parent.copy()
    # a piece at a moved point is not inside one old triangle: its points are located instead
    triangle_parent[(is_moved[np.minimum(triangles, n - 1)] & (triangles < n)).any(axis=1)] = -1

    # Interface segments: one per crossed triangle; an edge on the zero set with
    # the same side on both of its triangles (phi touches 0 there) or on the
    # boundary is no interface.
    seg = np.stack([seg_a, seg_b], axis=1)
    key = np.minimum(seg_a, seg_b) * n_cut + np.maximum(seg_a, seg_b)
    unique_key, first_index, counts = np.unique(key, return_index=True, return_counts=True)
    interface_segments = seg[first_index[counts == 1]]
    # Region tags
    if regions is None:
        regions = default_regions(mesh, phi)
    negative_tag, positive_tag = _regions(regions)
    tags = np.where(negative, negative_tag, positive_tag).astype(np.int64)
    # Constraints of the cut: kept segments split at their crossings, the interface.
    kept_sorted = np.sort(kept_segments, axis=1)
    kept_edge = np.searchsorted(edge_key, kept_sorted[:, 0] * n + kept_sorted[:, 1])
    split_at = edge_crossing[kept_edge]
    splits = split_at >= n
    pieces = [kept_segments[~splits], np.stack([kept_segments[splits, 0], split_at[splits]], axis=1),
              np.stack([split_at[splits], kept_segments[splits, 1]], axis=1)]
    piece_tags = [kept_tags[~splits], kept_tags[splits], kept_tags[splits]]
    segments = np.concatenate(pieces + [interface_segments])
    segment_tags = np.concatenate(piece_tags + [np.full(len(interface_segments), interface_tag, np.int64)])
    # the interface along a boundary edge is that boundary edge
    boundary_key = np.sort(segments[: len(segments) - len(interface_segments)], axis=1)
    interface_key = np.sort(interface_segments, axis=1)
    duplicate = np.isin(interface_key[:, 0] * n_cut + interface_key[:, 1],
                        boundary_key[:, 0] * n_cut + boundary_key[:, 1])
    if duplicate.any():
        keep = np.r_[np.ones(len(segments) - len(interface_segments), bool), ~duplicate]
        segments, segment_tags = segments[keep], segment_tags[keep]
        interface_segments = interface_segments[~duplicate]
    if len(interface_segments) == 0:
        raise ValueError("the interface phi = 0 lies on the boundary only: there is no interior zero set to mesh")
    required = np.concatenate([mesh.required & ~is_moved, np.zeros(len(new_index), bool)])
    tris, segs, boundary, kind, _, built_tags, _ = _core.prepare_mesh(
        all_points, triangles, segments, False, segment_tags, required.astype(np.uint8) if required.any() else None)
    boundary = boundary.astype(bool)
    if len(tris) != len(triangles) or not (tris == triangles).all():
        raise AssertionError("cut: a piece is not counter-clockwise")
    # Kinds: geometric on the constraints (old interface junctions are no corners
    # any more), except corners the old mesh pinned on constraints that stay;
    # released interface points are Steiner points; other interior points keep theirs.
    old_kinds = np.asarray(old_kind)
    was_on_released = np.zeros(n, dtype=bool)
    was_on_released[mesh.segments[released].ravel()] = True
    kinds = kind.copy()
    old_part = kinds[:n]
    on_segment_now = old_part <= _BOUNDARY
    pinned = on_segment_now & (old_kinds == _CORNER) & ~was_on_released & on_constraint
    old_part[pinned] = _CORNER
    interior_now = ~on_segment_now
    old_part[interior_now] = np.where(old_kinds[interior_now] <= _BOUNDARY, np.uint8(_STEINER),
                                      old_kinds[interior_now])
    kinds[:n] = old_part
    _check_meeting_angles(all_points, segs, built_tags, boundary, interface_tag)
    origin = np.concatenate([np.where(is_moved, -1, np.arange(n)), np.full(len(new_index), -1)])
    cut = Mesh._trusted(all_points, tris, segs, boundary, kinds, origin, {}, None, None, built_tags, tags,
                        required if required.any() else None, tag_names=mesh.tag_names)
    parent_triangle = np.full(n_cut, -1, dtype=np.int64)
    barycentric = np.zeros((n_cut, 3))
    parent_triangle[n:] = owner
    barycentric[n:] = weights_new
    if len(moved):  # (on the old edge of their crossing)
        parent_triangle[moved], barycentric[moved] = on_edges(cross[crossing_of], a_end[crossing_of], t[crossing_of])
    return Cut(mesh=cut, old_index=np.where(origin >= 0, origin, -1), parent_triangle=parent_triangle,
               barycentric=barycentric, triangle_parent=triangle_parent, triangle_weights=vertex_weights,
               curve=curve, n_crossings=len(new_index), n_moved=len(moved), regions=(negative_tag, positive_tag),
               scale=scale)


# Rounds of _split_double_crossings: each halves the edges that phi crosses
# twice and tests the edges next to the crossings found, so a notch gets points
# down to 1/2**rounds of the spacing and as far as `rounds` spacings into it.
_DOUBLE_CROSSING_ROUNDS = 6
# Where on an edge _split_double_crossings looks for the other sign (fractions
# of the edge, nearest the middle first): a notch an eighth of the edge wide.
_SAMPLE_FRACTIONS = np.array([0.5, 0.375, 0.625, 0.25, 0.75, 0.125, 0.875])
# A notch shallower than this fraction of its edge (its deepest sample's
# |phi| over phi's median slope along the crossing edges) is left out: a
# near-tangency of phi = 0 with an edge would put crossings a rounding apart.
_NOTCH_DEPTH = 1 / 32
# A corner of phi = 0 inside a triangle (_corners): the normals at its two
# crossings turn by more than this (degrees), and the corner lies this
# fraction of the triangle inside it and this fraction of the crossings'
# distance off their segment.
_CORNER_TURN = 60.0
_CORNER_MARGIN = 1 / 16
# Zooms of those samples around the one nearest the other sign (each a quarter
# as far apart): a notch down to 1/512 of the edge where phi comes near it.
_ZOOM_ROUNDS = 3
# The pieces of a triangle whose sides (0: v0 -> v1, 1: v1 -> v2, 2: v2 -> v0)
# are split at their midpoints, in labels 0-2 (corners) and 3-5 (the sides'
# midpoints), rotated so that the split sides come first; two split sides have
# two choices of diagonal (v0 - m1 or m0 - v2).
_ONE_SPLIT = np.array([[0, 3, 2], [3, 1, 2]])
_TWO_SPLIT = (np.array([[3, 1, 4], [0, 3, 4], [0, 4, 2]]), np.array([[3, 1, 4], [0, 3, 2], [3, 4, 2]]))
_THREE_SPLIT = np.array([[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]])


@dataclass(frozen=True)
class _Refinement:
    """A mesh with some edges split at their midpoints, in the mesh it came
    from: the old triangle of every triangle and the barycentric coordinates
    of its vertices there; the old triangle and coordinates of every midpoint."""

    triangle_parent: np.ndarray
    triangle_weights: np.ndarray
    point_parent: np.ndarray
    point_weights: np.ndarray


def _split_double_crossings(mesh: Mesh, phi: np.ndarray, level: LevelSet, interface_tag: int
                            ) -> tuple[Mesh, np.ndarray, _Refinement | None, tuple[np.ndarray, np.ndarray]]:
    """The mesh with the edges phi crosses twice split between their crossings,
    and the triangles holding a corner of phi = 0 split at it.

    A part of phi's zero set narrower than the spacing (the notch where two
    circles meet) can hold no mesh point: an edge across it has ends of one
    sign. Every round samples phi on the edges next to the interface (an end
    on an edge where phi changes sign, or both ends close to phi = 0 for
    their length) whose ends have the same sign and that no earlier round
    tested (:func:`_other_sign_on_edges`, 1 to 1 + _ZOOM_ROUNDS calls); where
    phi has the other sign at least _NOTCH_DEPTH of the edge deep, the edge is
    split at its deepest sample (its triangles into 2-4), so the cut crosses
    it twice. Edges on constraints that stay (the boundary, segments of other
    tags) are not split; the previous interface's segments are. At most
    _DOUBLE_CROSSING_ROUNDS rounds. Then :func:`_corners` (the notch's tip
    inside a triangle). Returns the refined mesh, phi at its points (0 at the
    corners), its lineage in ``mesh`` (None: nothing split) and the roots on
    the edges phi crosses, which the cut reuses."""
    P, T = np.array(mesh.points), np.array(mesh.triangles)
    n0 = n = mesh.n_points
    values = phi.copy()
    segments, segment_tags = np.array(mesh.segments), np.array(mesh.segment_tags)
    segment_boundary = np.array(mesh.segment_is_boundary, dtype=bool)
    released = ~segment_boundary & (segment_tags == interface_tag)
    fixed = np.sort(segments[~released], axis=1)
    fixed_key = fixed[:, 0].astype(np.int64) * n0 + fixed[:, 1]
    parent = np.arange(len(T))
    weights = np.broadcast_to(np.eye(3), (len(T), 3, 3)).copy()
    point_parent: list[np.ndarray] = []
    point_weights: list[np.ndarray] = []
    tested = np.zeros(0, dtype=np.int64)  # the keys of the edges whose midpoints were evaluated
    for _ in range(_DOUBLE_CROSSING_ROUNDS):
        edges, side_edge = _unique_edges(T, n)
        neg = values < 0
        crossing = neg[edges[:, 0]] != neg[edges[:, 1]]
        near = np.zeros(n, dtype=bool)
        near[edges[crossing].ravel()] = True
        key = edges[:, 0] * (1 << 31) + edges[:, 1]  # (the same edge keeps its key from round to round)
        # an edge whose ends are closer to phi = 0 than its length allows at twice the median
        # slope of phi along the crossing edges may cross twice, too
        if not crossing.any():  # (phi changes sign only between parts of the domain no edge joins)
            break
        length = np.hypot(*(P[edges[:, 1]] - P[edges[:, 0]]).T)
        slope = np.median(np.abs(values[edges[crossing, 0]] - values[edges[crossing, 1]]) / length[crossing])
        close = np.abs(values[edges[:, 0]]) + np.abs(values[edges[:, 1]]) <= 2 * slope * length
        candidate = ~crossing & (near[edges[:, 0]] | near[edges[:, 1]] | close) & ~np.isin(key, tested)
        old = np.flatnonzero(edges.max(axis=1) < n0)  # (the constraints that stay are old edges)
        candidate[old[np.isin(edges[old, 0] * n0 + edges[old, 1], fixed_key)]] = False
        where = np.flatnonzero(candidate)
        if not len(where):
            break
        tested = np.concatenate([tested, key[where]])
        found, t_found, value = _other_sign_on_edges(level, P[edges[where, 0]], P[edges[where, 1]],
                                                     neg[edges[where, 0]], slope)
        where, t_found, value = where[found], t_found[found], value[found]
        if not len(where):
            break
        t_edge = np.full(len(edges), 0.5)
        t_edge[where] = t_found
        middle = _along(P[edges[where, 0]], P[edges[where, 1]], t_found)
        # the split's position along every side (from its first vertex)
        side_t = np.where(T == edges[side_edge, 0], t_edge[side_edge], 1 - t_edge[side_edge])
        edge_middle = np.full(len(edges), -1, dtype=np.int64)
        edge_middle[where] = n + np.arange(len(where))
        # the midpoints in the old mesh: from a triangle with their edge as side
        owner = np.full(len(edges), -1, dtype=np.int64)
        owner[side_edge.ravel()[::-1]] = (np.arange(side_edge.size) // 3)[::-1]
        slot = np.full(len(edges), -1, dtype=np.int64)
        slot[side_edge.ravel()[::-1]] = (np.arange(side_edge.size) % 3)[::-1]
        o, k = owner[where], slot[where]
        point_parent.append(parent[o])
        along = side_t[o, k][:, None]
        point_weights.append((1 - along) * weights[o, k] + along * weights[o, (k + 1) % 3])
        # split the triangles
        mid = edge_middle[side_edge]
        split = mid >= 0
        count = split.sum(axis=1)
        rotation = np.where(count == 1, np.argmax(split, axis=1),
                            np.where(count == 2, (np.argmin(split, axis=1) + 1) % 3, 0))
        # the split triangles' corners and midpoints, rotated (only theirs: a few near the interface)
        active = np.flatnonzero(count > 0)
        position = np.full(len(T), -1, dtype=np.int64)
        position[active] = np.arange(len(active))
        turn = (rotation[active, None] + np.arange(3)) % 3
        rows = active[:, None]
        labels = np.concatenate([T[rows, turn], mid[rows, turn]], axis=1)  # (split triangles, 6)
        corner_w = weights[rows, turn]  # (split triangles, 3, 3) in the rotated order
        along = side_t[rows, turn][:, :, None]
        label_w = np.concatenate([corner_w, (1 - along) * corner_w + along * np.roll(corner_w, -1, axis=1)], axis=1)
        pieces, piece_of = [T[count == 0]], [np.flatnonzero(count == 0)]
        piece_w = [weights[count == 0]]
        two = np.flatnonzero(count == 2)
        P = np.concatenate([P, middle])
        x = P[labels[position[two]]]  # the diagonals v0 - m1 and m0 - v2
        first = np.hypot(*(x[:, 0] - x[:, 4]).T) <= np.hypot(*(x[:, 3] - x[:, 2]).T)
        for rows_of, template in ((np.flatnonzero(count == 1), _ONE_SPLIT), (two[first], _TWO_SPLIT[0]),
                                  (two[~first], _TWO_SPLIT[1]), (np.flatnonzero(count == 3), _THREE_SPLIT)):
            for local in template:
                pieces.append(labels[position[rows_of]][:, local])
                piece_of.append(rows_of)
                piece_w.append(label_w[position[rows_of]][:, local])
        T = np.concatenate(pieces)
        source = np.concatenate(piece_of)
        parent = parent[source]
        weights = np.concatenate(piece_w)
        # the previous interface's segments split too
        key = np.sort(segments, axis=1)
        at = np.searchsorted(edges[:, 0] * n + edges[:, 1], key[:, 0] * n + key[:, 1])
        cut_at = edge_middle[np.minimum(at, len(edges) - 1)]
        halves = released & (cut_at >= 0)
        segments = np.concatenate([segments[~halves], np.stack([segments[halves, 0], cut_at[halves]], axis=1),
                                   np.stack([cut_at[halves], segments[halves, 1]], axis=1)])
        segment_tags = np.concatenate([segment_tags[~halves], segment_tags[halves], segment_tags[halves]])
        segment_boundary = np.concatenate([segment_boundary[~halves], segment_boundary[halves],
                                           segment_boundary[halves]])
        released = np.concatenate([released[~halves], released[halves], released[halves]])
        values = np.concatenate([values, value])
        n += len(where)
    # Corners of phi = 0 inside a triangle: split there (into three), with phi = 0 at the corner.
    roots, inside, corner = _corners(level, P, T, values)
    if len(inside):
        a, b, c = T[inside, 0], T[inside, 1], T[inside, 2]
        x = n + np.arange(len(inside))
        rest = np.ones(len(T), dtype=bool)
        rest[inside] = False
        corner_weights = _barycentric(P[a], P[b], P[c], corner)
        point_parent.append(parent[inside])
        point_weights.append(np.einsum("ki,kij->kj", corner_weights, weights[inside]))
        child_weights = [np.stack([weights[inside, i], weights[inside, j], point_weights[-1]], axis=1)
                         for i, j in ((0, 1), (1, 2), (2, 0))]
        T = np.concatenate([T[rest], np.stack([a, b, x], 1), np.stack([b, c, x], 1), np.stack([c, a, x], 1)])
        parent = np.concatenate([parent[rest], parent[inside], parent[inside], parent[inside]])
        weights = np.concatenate([weights[rest], *child_weights])
        P = np.concatenate([P, corner])
        values = np.concatenate([values, np.zeros(len(inside))])
        n += len(inside)
    if n == n0:
        return mesh, phi, None, roots
    kind = np.concatenate([np.asarray(mesh.kind), np.full(n - n0, _STEINER, dtype=np.asarray(mesh.kind).dtype)])
    required = np.concatenate([mesh.required, np.zeros(n - n0, dtype=bool)])
    fine = Mesh._trusted(P, T, segments, segment_boundary, kind, np.r_[np.arange(n0), np.full(n - n0, -1)], {},
                         None, None, segment_tags, mesh.triangle_tags[parent], required if required.any() else None,
                         tag_names=mesh.tag_names)
    return (fine, values, _Refinement(parent, weights, np.concatenate(point_parent), np.concatenate(point_weights)),
            roots)


def _barycentric(a: np.ndarray, b: np.ndarray, c: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The barycentric coordinates (k, 3) of the points x in the triangles (a, b, c)."""
    def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]

    area = cross(b - a, c - a)
    wb, wc = cross(x - a, c - a) / area, cross(b - a, x - a) / area
    return np.stack([1 - wb - wc, wb, wc], axis=1)


def _corners(level: LevelSet, P: np.ndarray, T: np.ndarray, values: np.ndarray
             ) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray, np.ndarray]:
    """Corners of phi = 0 inside the triangles it crosses (the tip of the
    notch where two circles meet), where the cut's straight segment between
    the two crossings would cut the corner off.

    The crossings of every edge where phi changes sign are found (the roots
    the cut uses: returned as (keys of (negative end, other end), t), sorted);
    phi's gradient at them in one call. In a triangle whose two crossings'
    normals turn by more than _CORNER_TURN, the tangents there meet at the
    corner's estimate, which moves onto phi = 0 by Newton; it is a corner where
    it lies inside the triangle (_CORNER_MARGIN of it away from the sides)
    and more than _CORNER_MARGIN of the crossings' distance off their
    segment. Returns the roots, the triangles with a corner, and the corners."""
    scale = float(np.abs(P).max())
    edges, side_edge = _unique_edges(T, len(P))
    neg = values < 0
    cross = np.flatnonzero(neg[edges[:, 0]] != neg[edges[:, 1]])
    first_negative = neg[edges[cross, 0]]
    a_end = np.where(first_negative, edges[cross, 0], edges[cross, 1])
    b_end = np.where(first_negative, edges[cross, 1], edges[cross, 0])
    t = _edge_roots(level, P[a_end], P[b_end], values[a_end], values[b_end], _ROOT_TOLERANCE * scale)
    key = a_end * (1 << 31) + b_end
    order = np.argsort(key)
    roots = (key[order], t[order])
    none = (roots, np.zeros(0, dtype=np.int64), np.zeros((0, 2)))
    crossing_of = np.full(len(edges), -1, dtype=np.int64)
    crossing_of[cross] = np.arange(len(cross))
    sides = crossing_of[side_edge]
    inside = np.flatnonzero((sides >= 0).sum(axis=1) == 2)
    if not len(inside):
        return none
    first = np.argmax(sides[inside] >= 0, axis=1)
    second = 2 - np.argmax((sides[inside] >= 0)[:, ::-1], axis=1)
    c1, c2 = sides[inside, first], sides[inside, second]
    used, local = np.unique(np.concatenate([c1, c2]), return_inverse=True)
    at = _along(P[a_end[used]], P[b_end[used]], t[used])
    extent = float(np.ptp(P, axis=0).max())
    _, gradient = level._value_and_gradient(at, np.cbrt(np.finfo(np.float64).eps) * extent)
    norm = np.hypot(*gradient.T)
    known = norm > 0
    unit = gradient / np.where(known, norm, 1.0)[:, None]
    k1, k2 = local[: len(inside)], local[len(inside):]
    x1, x2, n1, n2 = at[k1], at[k2], unit[k1], unit[k2]
    det = n1[:, 0] * n2[:, 1] - n1[:, 1] * n2[:, 0]
    turned = known[k1] & known[k2] & ((n1 * n2).sum(axis=1) < np.cos(np.radians(_CORNER_TURN))) & (det != 0)
    if not turned.any():
        return none
    inside, x1, x2, n1, n2, det = (v[turned] for v in (inside, x1, x2, n1, n2, det))
    # the tangents (y - x1) . n1 = 0 and (y - x2) . n2 = 0 meet at y
    r1, r2 = (x1 * n1).sum(axis=1), (x2 * n2).sum(axis=1)
    estimate = np.stack([r1 * n2[:, 1] - r2 * n1[:, 1], n1[:, 0] * r2 - n2[:, 0] * r1], axis=1) / det[:, None]
    estimate = np.where(np.isfinite(estimate), estimate, x1)
    corner, settled = level._newton(estimate, extent)
    chord = np.hypot(*(x2 - x1).T)
    off = np.abs((x2[:, 0] - x1[:, 0]) * (corner[:, 1] - x1[:, 1]) - (x2[:, 1] - x1[:, 1]) * (corner[:, 0] - x1[:, 0]))
    weights = _barycentric(P[T[inside, 0]], P[T[inside, 1]], P[T[inside, 2]], corner)
    keep = settled & (weights.min(axis=1) >= _CORNER_MARGIN) & (off > _CORNER_MARGIN * chord * chord)
    return roots, inside[keep], corner[keep]


def _other_sign_on_edges(level: LevelSet, a: np.ndarray, b: np.ndarray, negative: np.ndarray, slope: float
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where phi takes the other sign than at the ends on the edges a - b
    (whose ends have one sign, negative or not): (found, t, phi there). phi is
    sampled at _SAMPLE_FRACTIONS of every edge in one call; on an edge where
    it does not change sign but its sample nearest the other sign is within
    reach of it (closer than twice `slope` times the samples' spacing), the
    samples zoom in around that one, a quarter as far apart, up to
    _ZOOM_ROUNDS times (one call each, for all such edges together)."""
    k = len(a)
    found = np.zeros(k, dtype=bool)
    t = np.full(k, 0.5)
    at = np.zeros(k)
    centre, spacing = np.full(k, 0.5), np.full(k, 0.125)
    length = np.hypot(*(b - a).T)
    sign = np.where(negative, 1.0, -1.0)  # (sign * phi > 0 on the other side)
    active = np.arange(k)
    for _ in range(1 + _ZOOM_ROUNDS):
        offsets = (_SAMPLE_FRACTIONS - 0.5) / 0.125  # (-3 .. 3, nearest the middle first)
        u = np.clip(centre[active][None, :] + offsets[:, None] * spacing[active][None, :], 0.0, 1.0)
        m = len(offsets)
        samples = level.value(_along(np.tile(a[active], (m, 1)), np.tile(b[active], (m, 1)), u.ravel())).reshape(m, -1)
        toward = sign[active] * samples  # (> 0: the other sign)
        best = np.argmax(toward, axis=0)  # (the first of equals: nearest the middle)
        rows = np.arange(len(active))
        # a notch counts where it is at least _NOTCH_DEPTH of the edge deep
        # (at phi's median slope), and is split at its deepest sample
        depth = _NOTCH_DEPTH * slope * length[active]
        hit = toward[best, rows] >= depth
        found[active[hit]] = True
        t[active[hit]] = u[best[hit], rows[hit]]
        at[active[hit]] = samples[best[hit], rows[hit]]
        reach = 2 * slope * spacing[active] * length[active]
        keep = ~hit & (depth - toward[best, rows] <= reach)
        centre[active] = u[best, rows]
        spacing[active] *= 0.25
        active = active[keep]
        if not len(active):
            break
    return found, t, at


def _through_refinement(cut: Cut, n0: int, refinement: _Refinement) -> Cut:
    """A cut of a refined mesh (:func:`_split_double_crossings`) with its
    lineage taken to the mesh before the refinement."""
    old_index = np.where(cut.old_index < n0, cut.old_index, -1)
    parent = cut.parent_triangle.copy()
    weights = cut.barycentric.copy()
    located = np.flatnonzero(parent >= 0)
    parent[located] = refinement.triangle_parent[cut.parent_triangle[located]]
    weights[located] = np.einsum("ki,kij->kj", cut.barycentric[located],
                                 refinement.triangle_weights[cut.parent_triangle[located]])
    midpoint = np.flatnonzero(cut.old_index >= n0)
    parent[midpoint] = refinement.point_parent[cut.old_index[midpoint] - n0]
    weights[midpoint] = refinement.point_weights[cut.old_index[midpoint] - n0]
    triangle_parent = cut.triangle_parent.copy()
    triangle_weights = cut.triangle_weights.copy()
    known = np.flatnonzero(triangle_parent >= 0)
    triangle_parent[known] = refinement.triangle_parent[cut.triangle_parent[known]]
    triangle_weights[known] = cut.triangle_weights[known] @ refinement.triangle_weights[cut.triangle_parent[known]]
    return replace(cut, old_index=old_index, parent_triangle=parent, barycentric=weights,
                   triangle_parent=triangle_parent, triangle_weights=triangle_weights)


def _tag(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
    if not -(2**63) <= int(value) < 2**63:
        raise ValueError(f"{name} must fit in int64, got {value}")
    return int(value)


def _regions(regions: Any) -> tuple[int, int]:
    try:
        negative, positive = regions
    except (TypeError, ValueError):
        raise TypeError("interface_regions must be a pair (tag of the negative side, tag of the positive side), got "
                        f"{regions!r}") from None
    return _tag(negative, "interface_regions[0]"), _tag(positive, "interface_regions[1]")


def default_regions(mesh: Mesh, phi: np.ndarray) -> tuple[int, int]:
    """The triangle tags of the two sides when none are given: of the mesh's
    regions (triangle tags), the one where phi is lowest on average (over its
    area) for the negative side, the one where it is highest for the positive
    side. A moving interface thus keeps its two tags from step to step, however
    far it moved (the old inside is where the new phi is lowest, even with no
    overlap left). With a single region (the first step) the positive side keeps
    its tag and the negative side gets a new one, the largest tag plus one.

    Parameters
    ----------
    mesh : Mesh
    phi : ndarray, shape (n,)
        phi at the mesh points.
    """
    tags = mesh.triangle_tags
    values, index = np.unique(tags, return_inverse=True)
    area = mesh.triangle_areas
    mean = np.bincount(index, weights=area * phi[mesh.triangles].mean(axis=1)) / np.bincount(index, weights=area)
    if len(values) == 1:
        return int(values[0]) + 1, int(values[0])
    return int(values[np.argmin(mean)]), int(values[np.argmax(mean)])


def _zero_set_segments(T: np.ndarray, side_edge: np.ndarray, neg: np.ndarray, cross: np.ndarray,
                       crossing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The zero set of the piecewise-linear interpolant: in every triangle with
    a sign change, the segment between the crossings of its two crossed edges
    (degenerate ones dropped)."""
    where = np.full(side_edge.max() + 1, -1, dtype=np.int64)
    where[cross] = np.arange(len(cross))
    s = neg[T]
    count = s.sum(axis=1)
    rows = np.flatnonzero((count == 1) | (count == 2))
    lone = np.where(count[rows] == 1, np.argmax(s[rows], axis=1), np.argmin(s[rows], axis=1))
    first = crossing[where[side_edge[rows, lone]]]
    second = crossing[where[side_edge[rows, (lone + 2) % 3]]]
    proper = (first != second).any(axis=1)
    return first[proper], second[proper]


def _sign_components(edges: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, int]:
    """The connected components of the points where phi < 0 and of those where
    phi > 0, through the mesh edges (label -1 where phi = 0), and their number."""
    n = len(phi)
    sign = np.sign(phi)
    same = (sign[edges[:, 0]] == sign[edges[:, 1]]) & (sign[edges[:, 0]] != 0)
    graph = coo_matrix((np.ones(int(same.sum())), (edges[same, 0], edges[same, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    nonzero = sign != 0
    kept, label = np.unique(label[nonzero], return_inverse=True)
    out = np.full(n, -1, dtype=np.int64)
    out[nonzero] = label
    return out, len(kept)


def _keep_components(component: np.ndarray, n_components: int, rounded: np.ndarray, moved: np.ndarray,
                     crossing_of: np.ndarray, distance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The moves onto crossings (`moved`, `crossing_of`, at `distance`) less,
    in every sign component all of whose points would reach phi = 0 (moved, or
    `rounded`: within rounding of a crossing) by a move, the move of its point
    farthest from its crossing, so the component keeps a point of its sign.
    (A component all of whose points are within rounding of phi = 0 has no
    sign to keep: the points of the previous interface.)"""
    at_zero = rounded.copy()
    at_zero[moved] = True
    labelled = component >= 0
    total = np.bincount(component[labelled], minlength=n_components)
    zeroed = np.bincount(component[labelled & at_zero], minlength=n_components)
    gone = total == zeroed
    own = component[moved]
    candidates = np.flatnonzero(gone[own]) if len(moved) else moved
    if len(candidates):
        order = candidates[np.lexsort((-distance[candidates], own[candidates]))]
        first = order[np.r_[True, own[order][1:] != own[order][:-1]]]
        keep = np.ones(len(moved), dtype=bool)
        keep[first] = False
        moved, crossing_of = moved[keep], crossing_of[keep]
    return moved, crossing_of


def _interface_degree(T: np.ndarray, negative: np.ndarray) -> np.ndarray:
    """At every point v where phi = 0, the number of interface segments the cut
    gives it: the triangles (v, b, c) whose b and c lie on different sides."""
    degree = np.zeros(len(negative), dtype=np.int64)
    for k in range(3):
        differ = negative[T[:, (k + 1) % 3]] != negative[T[:, (k + 2) % 3]]
        degree += np.bincount(T[differ, k], minlength=len(negative))
    return degree


def _valid_moves(points: np.ndarray, T: np.ndarray, moved: np.ndarray, moved_to: np.ndarray) -> np.ndarray:
    """Which of the moves (point moved[k] to moved_to[k]) to make: those that
    keep every triangle at a moved point at least half its area (so positively
    oriented and not much thinner); the moves in a triangle that would lose
    more are undone, until none does. Returns a mask over ``moved``."""
    n = len(points)
    moving = np.zeros(n, dtype=bool)
    moving[moved] = True
    target = points.copy()
    target[moved] = moved_to
    involved = np.flatnonzero(moving[T].any(axis=1))

    def doubled_area(p: np.ndarray) -> np.ndarray:
        d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        return d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]

    before = doubled_area(points[T[involved]])
    while True:
        after = doubled_area(target[T[involved]])
        bad = after < 0.5 * before
        if not bad.any():
            break
        undo = T[involved[bad]].ravel()
        undo = undo[moving[undo]]
        moving[undo] = False
        target[undo] = points[undo]
    return moving[moved]


def _split(T: np.ndarray, side_edge: np.ndarray, neg: np.ndarray, edge_crossing: np.ndarray, points: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Splits every triangle the zero set crosses along it.

    With the lone vertex a (the one on its own side) first and (a, b, c)
    counter-clockwise, the crossings X_ab and X_ac (a crossing point, or the
    vertex b / c itself when phi is 0 there) cut the triangle into (a, X_ab,
    X_ac), on a's side, and the convex polygon (X_ab, b, c, X_ac) (repeated
    vertices dropped), split by its shorter diagonal. A triangle whose lone
    vertex is a zero of phi (X_ab = X_ac = a) is not split.

    Returns the pieces (counter-clockwise), the old triangle of each, each
    piece's side (True: negative) and the ends of the interface segments
    (X_ab, X_ac), oriented with the negative side on their left.
    """
    s = neg[T]
    count = s.sum(axis=1)
    crossed = (count == 1) | (count == 2)
    rows = np.flatnonzero(crossed)
    lone = np.where(count[rows] == 1, np.argmax(s[rows], axis=1), np.argmin(s[rows], axis=1))
    a = T[rows, lone]
    b = T[rows, (lone + 1) % 3]
    c = T[rows, (lone + 2) % 3]
    x_ab = edge_crossing[side_edge[rows, lone]]
    x_ac = edge_crossing[side_edge[rows, (lone + 2) % 3]]
    lone_negative = neg[a]
    degenerate = x_ab == x_ac
    whole = np.flatnonzero(~crossed)
    pieces = [T[whole]]
    parents = [whole]
    sides = [count[whole] == 3]
    # degenerate: the triangle is on the side of its other two vertices
    pieces.append(T[rows[degenerate]])
    parents.append(rows[degenerate])
    sides.append(~lone_negative[degenerate])
    proper = ~degenerate
    r, a, b, c, x_ab, x_ac, lone_negative = (v[proper] for v in (rows, a, b, c, x_ab, x_ac, lone_negative))
    pieces.append(np.stack([a, x_ab, x_ac], axis=1))
    parents.append(r)
    sides.append(lone_negative)
    # the other polygon
    b_is_x, c_is_x = x_ab == b, x_ac == c
    quad = ~b_is_x & ~c_is_x
    q = np.flatnonzero(quad)
    d1 = np.hypot(*(points[x_ab[q]] - points[c[q]]).T)
    d2 = np.hypot(*(points[b[q]] - points[x_ac[q]]).T)
    first_diagonal = d1 <= d2
    qa, qb = q[first_diagonal], q[~first_diagonal]
    for block in (np.stack([x_ab[qa], b[qa], c[qa]], axis=1), np.stack([x_ab[qa], c[qa], x_ac[qa]], axis=1)):
        pieces.append(block)
        parents.append(r[qa])
        sides.append(~lone_negative[qa])
    for block in (np.stack([x_ab[qb], b[qb], x_ac[qb]], axis=1), np.stack([b[qb], c[qb], x_ac[qb]], axis=1)):
        pieces.append(block)
        parents.append(r[qb])
        sides.append(~lone_negative[qb])
    tri = np.flatnonzero(b_is_x ^ c_is_x)
    third = np.where(b_is_x[tri][:, None], np.stack([b[tri], c[tri], x_ac[tri]], axis=1),
                     np.stack([x_ab[tri], b[tri], c[tri]], axis=1))
    pieces.append(third)
    parents.append(r[tri])
    sides.append(~lone_negative[tri])
    seg_a = np.where(lone_negative, x_ab, x_ac)
    seg_b = np.where(lone_negative, x_ac, x_ab)
    return (np.concatenate(pieces).astype(np.int64), np.concatenate(parents).astype(np.int64),
            np.concatenate(sides).astype(bool), seg_a.astype(np.int64), seg_b.astype(np.int64))


def _check_meeting_angles(points: np.ndarray, segments: np.ndarray, tags: np.ndarray, boundary: np.ndarray,
                          interface_tag: int) -> None:
    """ValueError where the interface meets another constraint (the boundary, a
    hole, an interior segment of another tag) at less than _MIN_MEETING_ANGLE
    degrees, or runs along one closer than sin(_MIN_MEETING_ANGLE) times its
    local segment length without meeting it: tangent, or nearly. The sliver
    between them cannot be meshed well at any spacing the interface allows."""
    is_interface = (tags == interface_tag) & ~np.asarray(boundary, dtype=bool)
    n = len(points)
    ends = np.concatenate([segments, segments[:, ::-1]])
    end_interface = np.concatenate([is_interface, is_interface])
    has_interface = np.zeros(n, dtype=bool)
    has_interface[ends[end_interface, 0]] = True
    has_other = np.zeros(n, dtype=bool)
    has_other[ends[~end_interface, 0]] = True
    junction = has_interface & has_other
    limit = np.sin(np.radians(_MIN_MEETING_ANGLE))
    if junction.any():
        at = np.flatnonzero(junction[ends[:, 0]])
        order = at[np.argsort(ends[at, 0], kind="stable")]
        node = ends[order, 0]
        direction = points[ends[order, 1]] - points[node]
        direction /= np.hypot(*direction.T)[:, None]
        kind = end_interface[order]
        for shift in range(1, 8):
            i = np.arange(len(order) - shift)
            j = i + shift
            pair = (node[i] == node[j]) & (kind[i] != kind[j])
            if not pair.any():
                continue
            cosine = np.einsum("kj,kj->k", direction[i[pair]], direction[j[pair]])
            bad = cosine > np.cos(np.radians(_MIN_MEETING_ANGLE))
            if bad.any():
                k = int(node[i[pair][np.argmax(bad)]])
                angle = float(np.degrees(np.arccos(np.clip(cosine[np.argmax(bad)], -1, 1))))
                raise ValueError(
                    f"the interface phi = 0 meets a boundary or constraint segment at {angle:.3g} degrees at "
                    f"({points[k, 0]:.6g}, {points[k, 1]:.6g}): it is tangent to it there (at least "
                    f"{_MIN_MEETING_ANGLE:g} degrees are needed); move the interface or the boundary")
    # Nearly tangent without meeting: an interface point closer to another
    # constraint than sin(angle) times its distance to the nearest junction and
    # than its longest interface segment (the local spacing). Next to a junction
    # where the interface meets at angle theta, points are |x - junction| sin(theta) away.
    others = segments[~is_interface]
    if not len(others):
        return
    iface = segments[is_interface]
    length = np.hypot(*(points[iface[:, 1]] - points[iface[:, 0]]).T)
    longest = np.zeros(n)
    np.maximum.at(longest, iface[:, 0], length)
    np.maximum.at(longest, iface[:, 1], length)
    free = np.flatnonzero((longest > 0) & ~has_other)
    if not len(free):
        return
    reach = longest[free]
    if junction.any():
        to_junction, _ = cKDTree(points[junction]).query(points[free])
        reach = np.minimum(reach, to_junction)
    gap, _ = _Polyline(points[others[:, 0]], points[others[:, 1]]).distance_and_closest(points[free])
    bad = gap < limit * reach
    if bad.any():
        k = int(free[np.argmax(bad)])
        raise ValueError(
            f"the interface phi = 0 comes within {float(gap[np.argmax(bad)]):.3g} of a boundary or constraint segment "
            f"at ({points[k, 0]:.6g}, {points[k, 1]:.6g}) without crossing it there: it is tangent to it, or nearly "
            f"(at this spacing, {longest[k]:.3g}); move the interface or the boundary, or refine there first")


# ----------------------------------------------------------------------------------------------------------------
# The step


def _band(band: Any) -> tuple[float, float, float] | None:
    """(width, spacing, grade) of interface_band=(width, spacing[, grade])."""
    if band is None:
        return None
    try:
        values = [float(v) for v in band]
    except (TypeError, ValueError):
        raise TypeError(f"interface_band must be (width, spacing) or (width, spacing, grade), got {band!r}") from None
    if len(values) not in (2, 3):
        raise TypeError(f"interface_band must be (width, spacing) or (width, spacing, grade), got {band!r}")
    width, spacing = values[:2]
    grade = values[2] if len(values) == 3 else 0.3
    if not (np.isfinite(width) and width >= 0):
        raise ValueError(f"interface_band width must be finite and >= 0, got {width}")
    if not (np.isfinite(spacing) and spacing > 0):
        raise ValueError(f"interface_band spacing must be finite and > 0, got {spacing}")
    if not (np.isfinite(grade) and grade > 0):
        raise ValueError(f"interface_band grade must be finite and > 0, got {grade}")
    return width, spacing, grade


def _spacing_at_cut(mesh: Mesh, cut: Cut, delta: Any, size: Any) -> np.ndarray:
    """The absolute target spacing h at the cut's points: h = delta nn_M at the
    old points (or ``size``), linear along the edges at the crossings; a
    callable size is evaluated at the cut's points. The old points' request is
    checked as evolve checks it (the range of delta)."""
    if size is None:
        h_old = as_delta(mesh, delta) * mesh.nn_spacing
    else:
        h_old = delta_from_size(mesh, size) * mesh.nn_spacing
        if callable(size):
            h = np.asarray(size(np.array(cut.mesh.points)), dtype=np.float64)
            h = np.array(np.broadcast_to(h, (cut.mesh.n_points,)) if h.ndim == 0 else h)
            if h.shape != (cut.mesh.n_points,) or not (np.isfinite(h) & (h > 0)).all():
                raise ValueError("size(x) must return one finite value > 0 per point (at the interface's points too)")
            return h
    h = np.empty(cut.mesh.n_points)
    old = cut.old_index >= 0
    h[old] = h_old[cut.old_index[old]]
    new = np.flatnonzero(~old)
    h[new] = np.einsum("kj,kj->k", cut.barycentric[new], h_old[mesh.triangles[cut.parent_triangle[new]]])
    return h


def _delta_at_cut(mesh: Mesh, cut: Cut, h: np.ndarray) -> tuple[np.ndarray, int]:
    """h over the cut's own spacing as delta, and how many points had it
    clamped into [DELTA_MIN, DELTA_MAX].

    The request (size, delta, interface_band) is checked as every scope checks
    a size (size_request.hpp), against the user's mesh: the spacing nn_M at
    the old points, linear in the old triangle at the cut's new points. Out of
    range raises, never clipped. The cut's own spacing can be far smaller than
    that (a crossing next to an old point: nn of 1e-9 where h is 0.025); a
    factor out of range only because of it is clamped, which only keeps the
    step finer there, and counted in ``stats["interface_delta_clamped"]``."""
    nn = np.empty(cut.mesh.n_points)
    old = cut.old_index >= 0
    nn[old] = mesh.nn_spacing[cut.old_index[old]]
    new = np.flatnonzero(~old)
    nn[new] = np.einsum("kj,kj->k", cut.barycentric[new], mesh.nn_spacing[mesh.triangles[cut.parent_triangle[new]]])
    _core.check_size_delta(h / nn, h, nn, DELTA_MIN, DELTA_MAX)
    delta = h / cut.mesh.nn_spacing
    outside = (delta < DELTA_MIN) | (delta > DELTA_MAX)
    return np.clip(delta, DELTA_MIN, DELTA_MAX), int(outside.sum())


def _interface_geometry(geometry: Any, interface_tag: int, curve: Any, scale: float, on_interface: np.ndarray
                        ) -> BoundaryGeometry:
    """The user's curved boundaries (if any) with the interface's curve added under interface_tag."""
    user = as_geometry(geometry)
    if user is not None and interface_tag in user.tags:
        raise ValueError(f"geometry has a curve for segment tag {interface_tag}, the interface's tag: choose another "
                         "interface_tag")
    on_zero_set = cKDTree(on_interface)

    def to_curve(x: np.ndarray) -> np.ndarray:
        # Newton may end on another branch of phi = 0 (two circles close
        # together): a move longer than 1.5 times the distance to the nearest
        # point known to be on the zero set (a cut's interface point; 1.5 for
        # a phi that is not a distance) went astray, and the point stays on its
        # chord. (The core leaves a point of an interface on its chord, too,
        # where the move exceeds what the local spacing allows.)
        reach, _ = on_zero_set.query(x)
        if isinstance(curve, LevelSet):
            moved, settled = curve._newton(x, scale)
        else:
            moved, settled = curve.project(x), np.ones(len(x), dtype=bool)
        stays = ~settled | (np.hypot(*(moved - x).T) > 1.5 * reach)
        moved[stays] = x[stays]
        return moved

    user_tags = () if user is None else user.tags

    def project(points: np.ndarray, tags: np.ndarray) -> np.ndarray:
        out = points.copy()
        on_interface = tags == interface_tag
        if on_interface.any():
            out[on_interface] = to_curve(points[on_interface])
        if user is not None and (~on_interface).any():
            out[~on_interface] = user.project(points[~on_interface], tags[~on_interface])
        return out

    corner_angle = DEFAULT_CORNER_ANGLE if user is None else user.corner_angle
    return BoundaryGeometry.from_projection(project, (*user_tags, interface_tag), corner_angle=corner_angle)


def _distance_to_interface(cut: Cut, interface_tag: int) -> np.ndarray:
    m = cut.mesh
    segments = m.segments[(m.segment_tags == interface_tag) & ~m.segment_is_boundary]
    line = _Polyline(m.points[segments[:, 0]], m.points[segments[:, 1]])
    return line.distance_and_closest(np.array(m.points))[0]


def _regions_by_component(mesh: Mesh) -> np.ndarray:
    """Triangle tags made constant on every piece of the domain between
    constraints: each piece takes the tag that covers most of its area. The
    step tags a triangle by the region holding its centroid in the cut mesh;
    next to an interface its points moved onto, a thin triangle's centroid can
    fall across the cut's straight interface."""
    T = mesh.triangles
    m = len(T)
    n = mesh.n_points
    edges, side_edge = _unique_edges(T, n)
    constraint = np.sort(mesh.segments, axis=1)
    is_constraint = np.isin(edges[:, 0] * n + edges[:, 1], constraint[:, 0] * n + constraint[:, 1])
    owner = np.repeat(np.arange(m), 3)
    flat = side_edge.ravel()
    order = np.argsort(flat, kind="stable")
    e_sorted = flat[order]
    pair = np.flatnonzero(e_sorted[1:] == e_sorted[:-1])
    open_pair = pair[~is_constraint[e_sorted[pair]]]
    left, right = owner[order[open_pair]], owner[order[open_pair + 1]]
    graph = coo_matrix((np.ones(len(left)), (left, right)), shape=(m, m))
    count, label = connected_components(graph, directed=False)
    tags = mesh.triangle_tags
    values, inverse = np.unique(tags, return_inverse=True)
    weight = coo_matrix((mesh.triangle_areas, (label, inverse)), shape=(count, len(values))).toarray()
    return values[np.argmax(weight, axis=1)][label].astype(np.int64)


def evolve_with_interface(mesh: Mesh, delta: Any, size: Any, interface: Any, interface_tag: Any,
                          interface_regions: Any, interface_band: Any, geometry: Any,
                          run_step: Callable[..., Mesh], **step_arguments: Any) -> Mesh:
    """evolve(mesh, ..., interface=phi): cut, step, compose the lineage (see the module docstring)."""
    _require_mesh(mesh)
    tag = INTERFACE_TAG if interface_tag is None else _tag(interface_tag, "interface_tag")
    band = _band(interface_band)
    cut = cut_mesh(mesh, interface, interface_tag=tag, regions=interface_regions)
    h = _spacing_at_cut(mesh, cut, delta, size)
    if band is not None:
        width, spacing, grade = band
        h = np.minimum(h, spacing + grade * np.maximum(0.0, _distance_to_interface(cut, tag) - 0.5 * width))
    cut_delta, clamped = _delta_at_cut(mesh, cut, h)
    on_interface = np.unique(cut.mesh.segments[(cut.mesh.segment_tags == tag) & ~cut.mesh.segment_is_boundary])
    extent = float(np.ptp(cut.mesh.points, axis=0).max())
    g = _interface_geometry(geometry, tag, cut.curve, extent, cut.mesh.points[on_interface])
    try:
        out = run_step(cut.mesh, cut_delta, geometry=g, **step_arguments)
    except ValueError as error:
        refusal = re.search(r"points \(max_samples is (\S+)\).*the finest spacing asked is (\S+), at "
                            r"(\([^)]*\))", str(error))
        if refusal is None:
            raise
        limit, finest, place = refusal.groups()
        gap, where = _closest_facing_pieces(cut.mesh, tag)
        if gap < float(finest):  # (the interface's own feature is finer than the request anywhere)
            finest, place = f"{gap:.4g}", f"({where[0]:.9g}, {where[1]:.9g})"
            cause = (f"the interface's pieces come within {finest} of each other at {place}, and near phi = 0 the "
                     "spacing follows the distance between them (its local feature size)")
        else:
            cause = ("near phi = 0 the spacing follows the distance between the interface's pieces, its local feature "
                     "size, and interface_band")
        raise ValueError(
            f"the interface step would create more than max_samples = {limit} points: it asks for a "
            f"spacing of {finest} at {place} ({cause}); move the pieces apart there, coarsen interface_band "
            "or raise max_samples") from None
    extra = _placement_report(out, cut.curve, tag, extent)
    extra["interface_delta_clamped"] = float(clamped)
    extra.update(_angle_report(out, step_arguments, tag))
    return _compose(mesh, cut, out, tag, extra)


def _closest_facing_pieces(mesh: Mesh, interface_tag: int) -> tuple[float, np.ndarray]:
    """The least distance between two points of the interface that face each
    other (the line between them at more than 60 degrees to the interface's
    direction at the first: across a gap or a filament, not along the curve),
    and the middle of the two; (inf, NaN) where none do."""
    segments = mesh.segments[(mesh.segment_tags == interface_tag) & ~mesh.segment_is_boundary]
    on = np.unique(segments)
    if len(on) < 3:
        return np.inf, np.full(2, np.nan)
    P = mesh.points
    # the directions of a point's segments, as the mean of their outer products
    # (s s^T: a^T (s s^T) a is the square of a's component along s, whichever way s runs)
    step = P[segments[:, 1]] - P[segments[:, 0]]
    step /= np.maximum(np.hypot(*step.T), np.finfo(np.float64).tiny)[:, None]
    outer = step[:, :, None] * step[:, None, :]
    directions = np.zeros((mesh.n_points, 2, 2))
    np.add.at(directions, segments[:, 0], outer)
    np.add.at(directions, segments[:, 1], outer)
    directions = directions[on] / np.bincount(segments.ravel(), minlength=mesh.n_points)[on][:, None, None]
    distance, nearest = cKDTree(P[on]).query(P[on], k=min(9, len(on)))
    away = P[on][nearest] - P[on][:, None, :]
    along2 = np.einsum("ikj,ijl,ikl->ik", away, directions, away)
    facing = (nearest != np.arange(len(on))[:, None]) & (along2 < 0.25 * distance**2)
    if not facing.any():
        return np.inf, np.full(2, np.nan)
    distance = np.where(facing, distance, np.inf)
    k = int(np.argmin(distance.min(axis=1)))
    j = int(np.argmin(distance[k]))
    return float(distance[k, j]), 0.5 * (P[on[k]] + P[on[nearest[k, j]]])


def _placement_report(out: Mesh, curve: Any, interface_tag: int, extent: float) -> dict[str, float]:
    """Where the interface points of the step's output lie off phi = 0 (a
    function only): the points farther than 8 units of rounding of their
    coordinates (|phi| / |grad phi|), their number and the largest distance,
    and the calls of phi the step made (this evaluation included)."""
    if not isinstance(curve, LevelSet):
        return {}
    on = np.unique(out.segments[(out.segment_tags == interface_tag) & ~out.segment_is_boundary])
    x = out.points[on]
    value, g = curve._value_and_gradient(x, np.cbrt(np.finfo(np.float64).eps) * extent)
    norm = np.hypot(g[:, 0], g[:, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(norm > 0, np.abs(value) / norm, np.where(value == 0, 0.0, np.inf))
    rounding = 8 * np.finfo(np.float64).eps * np.maximum(np.abs(x).max(axis=1), np.finfo(np.float64).tiny)
    far = off > rounding
    phi = curve.phi
    return {"interface_points_off_curve": float(far.sum()),
            "interface_largest_off_curve": float(off[far].max()) if far.any() else 0.0,
            "interface_phi_calls": float(phi.calls) if isinstance(phi, _Counted) else float("nan")}


def _angle_report(out: Mesh, step_arguments: dict[str, Any], interface_tag: int) -> dict[str, float]:
    """The angle promise, kept or reported. evolve promises min_angle (with
    the quality pass on) except near segments meeting under less than 60
    degrees (here: where the interface meets the boundary or another
    constraint; triangles within three of their longest edges of such a point
    are left out), at a capped or failed pass (which warns already), and next
    to curves. Where the smallest other angle is still below min_angle, the
    exception is the curve's (interface points moved onto phi = 0 after the
    quality pass, the refits did not restore the angle, or points were left
    on their chords where phi = 0 folds within the spacing). stats
    "interface_angle_exception" says which applied (bits: 1 the curves', the
    smallest such angle in "interface_min_angle_curve"; 2 the small input
    angles', where the smallest angle is next to a meeting point), with the
    smallest angle and its place ("interface_min_angle", "_x", "_y"); below
    _ANGLE_WARNING_FRACTION of min_angle next to the curve, a QualityWarning
    names them."""
    o = step_arguments["options"]  # (the step's options, overrides applied: evolve makes them)
    stats = out.stats
    report = {"interface_angle_exception": 0.0}
    if not o.quality or stats.get("quality_capped") or stats.get("quality_failed"):
        return report
    # (the angles' rounding: the coordinates' rounding over the shortest edge, in degrees)
    rounding = 64 * np.finfo(np.float64).eps * float(np.abs(out.points).max()) / float(out.nn_spacing.min())
    if float(stats.get("min_angle", 180.0)) >= o.min_angle - 1e-9 - np.degrees(rounding):
        return report
    angles = triangle_angles(out.points, out.triangles).min(axis=1)
    is_interface = (out.segment_tags == interface_tag) & ~out.segment_is_boundary
    on_other = np.zeros(out.n_points, dtype=bool)
    on_other[out.segments[~is_interface].ravel()] = True
    junction = np.intersect1d(out.segments[is_interface].ravel(), np.flatnonzero(on_other))
    corners = out.points[out.triangles]
    centroid = corners.mean(axis=1)
    worst = int(np.argmin(angles))
    away = angles
    if len(junction):
        longest = np.hypot(*(corners - np.roll(corners, 1, axis=1)).transpose(2, 0, 1)).max(axis=1)
        near, _ = cKDTree(out.points[junction]).query(centroid)
        away = np.where(near <= 3 * longest, 180.0, angles)
    threshold = o.min_angle - 1e-9 - np.degrees(rounding)
    curve = float(away.min())
    exception = (1 if curve < threshold else 0) | (2 if away[worst] != angles[worst] else 0)
    x, y = centroid[worst]
    report = {"interface_angle_exception": float(exception), "interface_min_angle": float(angles[worst]),
              "interface_min_angle_x": float(x), "interface_min_angle_y": float(y),
              "interface_min_angle_curve": curve}
    if curve >= _ANGLE_WARNING_FRACTION * o.min_angle:
        return report
    x, y = centroid[int(np.argmin(away))]
    left = stats.get("curve_points_left_on_chords", 0) + stats.get("curve_samples_left_on_chords", 0)
    warnings.warn(f"the smallest angle, {curve:.3g} deg near ({x:.6g}, {y:.6g}), is below min_angle = "
                  f"{o.min_angle:g} next to the interface (evolve's exception for curves): its points moved onto "
                  "phi = 0 after the quality pass and the refits did not restore the angle "
                  f"({int(left)} point(s) left on their chords where phi = 0 folds within the spacing); stats "
                  "'interface_angle_exception' has bit 1. Where phi = 0 is smooth there, a finer interface_band "
                  "resolves it; at a corner of phi = 0 (where two fronts meet or touch) the angle follows the "
                  "corner's and refining does not raise it",
                  QualityWarning, stacklevel=4)
    return report


def _locate_near(mesh: Mesh, cut: Cut, queries: np.ndarray, pieces: np.ndarray | None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The old triangle holding each query and its barycentric coordinates
    there, for points of cut pieces at a moved point (`pieces`, -1: unknown):
    a moved point stays inside the polygon of its old neighbours, so such a
    piece lies in the old triangles at its old vertices; among those, the one
    where the smallest coordinate is largest. Queries found in none (or in no
    piece) are located by the core."""
    T = mesh.triangles
    n = mesh.n_points
    parent = np.full(len(queries), -1, dtype=np.int64)
    weights = np.zeros((len(queries), 3))
    if pieces is not None:
        # the old vertices' triangles (compressed: xadj / adj)
        adj = np.argsort(T.ravel(), kind="stable") // 3
        xadj = np.r_[0, np.cumsum(np.bincount(T.ravel(), minlength=n))]
        corners = cut.mesh.triangles[np.maximum(pieces, 0)]
        corners = np.where((corners < n) & (pieces >= 0)[:, None], corners, -1)
        query_of, candidate = [], []
        for k in range(3):
            v = corners[:, k]
            has = np.flatnonzero(v >= 0)
            count = xadj[v[has] + 1] - xadj[v[has]]
            query_of.append(np.repeat(has, count))
            starts = np.repeat(xadj[v[has]], count)
            offsets = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
            candidate.append(adj[starts + offsets])
        q = np.concatenate(query_of)
        c = np.concatenate(candidate)
        p = mesh.points[T[c]]
        d1, d2, d = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], queries[q] - p[:, 0]
        det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
        w1 = (d[:, 0] * d2[:, 1] - d[:, 1] * d2[:, 0]) / det
        w2 = (d1[:, 0] * d[:, 1] - d1[:, 1] * d[:, 0]) / det
        w = np.stack([1 - w1 - w2, w1, w2], axis=1)
        order = np.lexsort((-w.min(axis=1), q))
        best = order[np.r_[True, q[order][1:] != q[order][:-1]]] if len(order) else order
        inside = w[best].min(axis=1) >= -1e-9
        parent[q[best[inside]]] = c[best[inside]]
        weights[q[best[inside]]] = w[best[inside]]
    missing = np.flatnonzero(parent < 0)
    if len(missing):
        parent[missing], weights[missing] = _core.locate_points(mesh.points, T, queries[missing])
    return parent, weights


def _compose(mesh: Mesh, cut: Cut, out: Mesh, interface_tag: int, extra: dict[str, float]) -> Mesh:
    """The step's output with origin and lineage referring to the old mesh."""
    step_origin = out.origin
    from_cut = step_origin >= 0
    origin = np.full(out.n_points, -1, dtype=np.int64)
    origin[from_cut] = cut.old_index[step_origin[from_cut]]
    parent = np.full(out.n_points, -1, dtype=np.int64)
    barycentric = np.zeros((out.n_points, 3))
    crossing = np.flatnonzero(from_cut & (origin < 0))
    parent[crossing] = cut.parent_triangle[step_origin[crossing]]
    barycentric[crossing] = cut.barycentric[step_origin[crossing]]
    new = np.flatnonzero(~from_cut)
    lineage = out.lineage
    if lineage is not None and len(new):
        piece = lineage.parent_triangle[new]
        known = piece >= 0
        known[known] = cut.triangle_parent[piece[known]] >= 0
        located = new[known]
        pieces = piece[known]
        parent[located] = cut.triangle_parent[pieces]
        barycentric[located] = np.einsum("ki,kij->kj", lineage.barycentric[located], cut.triangle_weights[pieces])
        unknown = new[~known]
    else:
        unknown = new
    if len(unknown):
        parent[unknown], barycentric[unknown] = _locate_near(mesh, cut, out.points[unknown],
                                                             lineage.parent_triangle[unknown] if lineage else None)
    old_f = mesh.nn_spacing.copy()
    if lineage is not None:
        in_cut = np.flatnonzero(cut.old_index >= 0)
        old_f[cut.old_index[in_cut]] = lineage.old_f[in_cut]
    composed = Lineage(mesh.n_points, mesh.n_triangles, parent, barycentric, mesh.nn_spacing, old_f)
    stats = dict(out.stats)
    stats.update({"interface_crossings": float(cut.n_crossings), "interface_points_moved": float(cut.n_moved),
                  "interface_segments": float(((out.segment_tags == interface_tag) & ~out.segment_is_boundary).sum()),
                  "interface_negative_tag": cut.regions[0], "interface_positive_tag": cut.regions[1]})  # (ints: exact)
    stats.update(extra)
    tags = _regions_by_component(out)
    stats["interface_triangles_retagged"] = float((tags != out.triangle_tags).sum())
    nn = out._known_nn()
    return Mesh._trusted(out.points, out.triangles, out.segments, out.segment_is_boundary, out.kind, origin, stats,
                         composed, nn.get("nn"), out.segment_tags, tags,
                         out.required if out.required.any() else None, nn.get("nn_grew"), tag_names=out.tag_names)
