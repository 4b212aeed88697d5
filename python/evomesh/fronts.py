"""Moving fronts and the spacing law derived from the distance to them.

The paper's use case (Sections 1 and 6): a boundary moves through the domain;
ahead of it the mesh is refined, behind it coarsened. A front gives the
distance from any point to it at time t; :class:`SpacingLaw` turns distances
into the per-point factor delta of the Evolving Mesh Problem (Section 2.3):
"apply a proper monotonic function to the distance from it to the closest
point on the moving boundary".
"""

from __future__ import annotations

import abc
import numbers
from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from evomesh.mesh import _MAX_COORDINATE, Mesh
from evomesh.spacing_function import _require_mesh

__all__ = ["Front", "CircleFront", "PointFront", "LevelSetFront", "SpacingLaw", "as_query_points"]

# Rows per block of the vectorised point-to-segment distances (bounds memory).
_CHUNK = 65536


def as_query_points(x: ArrayLike, name: str = "x") -> np.ndarray:
    """Validate query points: real, shape (k, 2), finite; returns a float64 copy."""
    array = np.asarray(x)
    if array.dtype == object or array.dtype.kind not in "fiu":
        raise TypeError(f"{name} must be a real numeric array, got dtype {array.dtype}")
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"{name} must have shape (k, 2), got {array.shape}")
    array = np.array(array, dtype=np.float64)
    if not np.isfinite(array).all():
        raise ValueError(f"{name} contains NaN or infinite coordinates")
    if array.size and np.abs(array).max() > _MAX_COORDINATE:
        raise ValueError(f"{name} coordinates must be below {_MAX_COORDINATE:g} in magnitude")
    return array


def _real(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    return value


def _time(t: float | None) -> float:
    return 0.0 if t is None else _real(t, "t")


class Front(abc.ABC):
    """Base class of fronts: ``distance(x, t)`` is the unsigned distance from
    each point of x, shape (k, 2), to the front at time t, shape (k,)."""

    @abc.abstractmethod
    def distance(self, x: ArrayLike, t: float | None = None) -> np.ndarray:
        """Unsigned distance from each point of x, shape (k, 2), to the front at time t."""

    def polylines(self, t: float | None = None) -> list[np.ndarray]:
        """The front at time t as polylines (for drawing); empty if not explicit."""
        return []


class CircleFront(Front):
    """A circle whose radius may grow or shrink with time.

    Parameters
    ----------
    center : array_like, shape (2,)
    radius : float or callable
        The radius, or a function ``radius(t) -> float`` of the time; must be
        finite and >= 0.

    Notes
    -----
    The distance is exact: ``| |x - center| - radius(t) |``.
    """

    def __init__(self, center: ArrayLike, radius: float | Callable[[float], float]):
        c = np.asarray(center)
        if c.dtype == object or c.dtype.kind not in "fiu":
            raise TypeError(f"center must be a real numeric array, got dtype {c.dtype}")
        if c.shape != (2,):
            raise ValueError(f"center must have shape (2,), got {c.shape}")
        if not np.isfinite(c).all():
            raise ValueError("center must be finite")
        self.center = c.astype(np.float64)
        self.center.flags.writeable = False
        if not callable(radius):
            r = _real(radius, "radius")
            if r < 0:
                raise ValueError(f"radius must be >= 0, got {r}")
        self._radius = radius

    def radius(self, t: float | None = None) -> float:
        """The radius at time t (t is ignored for a constant radius)."""
        if not callable(self._radius):
            return float(self._radius)
        r = _real(self._radius(_time(t)), "radius(t)")
        if r < 0:
            raise ValueError(f"radius(t) must be >= 0, got {r} at t = {t}")
        return r

    def signed_distance(self, x: ArrayLike, t: float | None = None) -> np.ndarray:
        """Distance with sign: negative inside the circle, shape (k,)."""
        x = as_query_points(x)
        return np.hypot(x[:, 0] - self.center[0], x[:, 1] - self.center[1]) - self.radius(t)

    def distance(self, x: ArrayLike, t: float | None = None) -> np.ndarray:
        return np.abs(self.signed_distance(x, t))

    def polylines(self, t: float | None = None) -> list[np.ndarray]:
        angle = np.linspace(0.0, 2.0 * np.pi, 257)
        r = self.radius(t)
        return [self.center + r * np.c_[np.cos(angle), np.sin(angle)]]

    def __repr__(self) -> str:
        r = "<function>" if callable(self._radius) else f"{self._radius:g}"
        return f"CircleFront(center=({self.center[0]:g}, {self.center[1]:g}), radius={r})"


def _segment_distance(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|x - segment(a, b)| row by row (broadcasting over leading axes)."""
    d = b - a
    dd = np.einsum("...j,...j->...", d, d)
    t = np.einsum("...j,...j->...", x - a, d) / np.where(dd > 0, dd, 1.0)
    t = np.clip(t, 0.0, 1.0)
    closest = a + t[..., None] * d
    return np.hypot(x[..., 0] - closest[..., 0], x[..., 1] - closest[..., 1])


class PointFront(Front):
    """A front given by points: the polyline through them (closed or open).

    The paper's suggestion for real moving boundaries (Section 6): approximate
    the boundary by points, move the points, keep them evenly spaced.

    Parameters
    ----------
    points : array_like, shape (k, 2)
        Vertices in order along the front (k >= 2; k >= 3 if closed).
    closed : bool, default True
        Whether the last point connects back to the first.
    spacing : float, optional
        If given, the points are re-sampled at (about) this arc-length spacing,
        and :meth:`moved` re-samples again after every move.

    Notes
    -----
    ``distance(x, t)`` is the exact distance to the polyline (its segments, not
    only its vertices); t is ignored: a PointFront is one position of the front,
    :meth:`moved` gives the next. Candidates come from a KD-tree on the vertices
    (the segments next to the k nearest vertices); a segment whose ends are both
    farther than r_k cannot be closer than sqrt(r_k^2 - L^2/4) (L: longest
    segment), so k doubles only for the points where that bound does not settle
    the answer.
    """

    def __init__(self, points: ArrayLike, closed: bool = True, *, spacing: float | None = None):
        if not isinstance(closed, (bool, np.bool_)):
            raise TypeError("closed must be a bool")
        pts = as_query_points(points, "points")
        need = 3 if closed else 2
        if len(pts) < need:
            kind = "closed" if closed else "open"
            raise ValueError(f"a {kind} PointFront needs at least {need} points, got {len(pts)}")
        self.closed = bool(closed)
        self.spacing = None if spacing is None else _real(spacing, "spacing")
        if self.spacing is not None:
            if self.spacing <= 0:
                raise ValueError(f"spacing must be > 0, got {self.spacing}")
            pts = _resample(pts, self.closed, self.spacing)
        self.points = pts
        self.points.flags.writeable = False
        ends = np.arange(len(pts))
        nxt = (ends + 1) % len(pts)
        if not self.closed:
            ends, nxt = ends[:-1], nxt[:-1]
        self._a = pts[ends]
        self._b = pts[nxt]
        lengths = np.hypot(*(self._b - self._a).T)
        if not (lengths > 0).any():
            raise ValueError("the points of a PointFront must not all coincide")
        self._max_length = float(lengths.max())
        self._tree = cKDTree(pts)

    @property
    def length(self) -> float:
        """Arc length of the polyline."""
        return float(np.hypot(*(self._b - self._a).T).sum())

    def resampled(self, spacing: float) -> PointFront:
        """The same curve through evenly spaced points (arc-length spacing about
        ``spacing``, exactly length / round(length / spacing))."""
        return PointFront(self.points, self.closed, spacing=spacing)

    def moved(self, new_points: ArrayLike) -> PointFront:
        """The front at its next position: same closedness and spacing; if this
        front has a spacing the new points are re-sampled evenly."""
        return PointFront(new_points, self.closed, spacing=self.spacing)

    def polylines(self, t: float | None = None) -> list[np.ndarray]:
        return [np.vstack([self.points, self.points[:1]]) if self.closed else self.points.copy()]

    def _segments_at(self, vertex: np.ndarray) -> np.ndarray:
        """The (up to) two segments at each vertex, shape vertex.shape + (2,)."""
        n = len(self.points)
        before = vertex - 1
        after = vertex.copy()
        if self.closed:
            before %= n
        else:
            n_seg = n - 1
            before = np.where(before < 0, 0, before)
            after = np.where(after >= n_seg, n_seg - 1, after)
        return np.stack([before, after], axis=-1)

    def distance(self, x: ArrayLike, t: float | None = None) -> np.ndarray:
        x = as_query_points(x)
        out = np.empty(len(x))
        n = len(self.points)
        for start in range(0, len(x), _CHUNK):
            q = x[start : start + _CHUNK]
            result = np.full(len(q), np.inf)
            todo = np.arange(len(q))
            k = min(4, n)
            while len(todo):
                r, vertex = self._tree.query(q[todo], k=k)
                r = r.reshape(len(todo), -1)
                vertex = vertex.reshape(len(todo), -1)
                seg = self._segments_at(vertex).reshape(len(todo), -1)
                dist = _segment_distance(q[todo, None, :], self._a[seg], self._b[seg]).min(axis=1)
                result[todo] = dist
                if k >= n:
                    break
                # A segment not examined has both ends at least r_k away.
                bound_sq = r[:, -1] ** 2 - 0.25 * self._max_length**2
                settled = dist**2 <= bound_sq
                todo = todo[~settled]
                k = min(2 * k, n)
            out[start : start + len(q)] = result
        return out

    def __repr__(self) -> str:
        return f"PointFront(n_points={len(self.points)}, closed={self.closed}, spacing={self.spacing})"


#: Most points a PointFront is resampled to (about 0.8 GB of coordinates).
MAX_FRONT_POINTS = 50_000_000


def _resample(points: np.ndarray, closed: bool, spacing: float) -> np.ndarray:
    """Evenly spaced points along the polyline by arc length."""
    path = np.vstack([points, points[:1]]) if closed else points
    lengths = np.hypot(*np.diff(path, axis=0).T)
    keep = np.r_[True, lengths > 0]  # drop repeated points
    path = path[keep]
    arc = np.r_[0.0, np.cumsum(lengths[lengths > 0])]
    total = arc[-1]
    if total == 0:
        raise ValueError("the points of a PointFront must not all coincide")
    with np.errstate(over="ignore"):
        ratio = total / spacing  # inf for a subnormal spacing: refused below
    if not ratio <= MAX_FRONT_POINTS:
        raise ValueError(
            f"spacing {spacing:g} would put about {ratio:.3g} points on a front of length {total:.6g}; "
            f"at most {MAX_FRONT_POINTS:.0e} are allowed: use a larger spacing"
        )
    n_segments = max(int(round(ratio)), 3 if closed else 1)
    s = np.linspace(0.0, total, n_segments + 1)
    if closed:
        s = s[:-1]  # the last equals the first
    return np.c_[np.interp(s, arc, path[:, 0]), np.interp(s, arc, path[:, 1])]


class LevelSetFront(Front):
    """The zero level set of a function phi(x, t).

    Parameters
    ----------
    phi : callable
        ``phi(x, t) -> (k,)`` for points x of shape (k, 2), vectorised.
    signed_distance : bool, default False
        Declare that phi is a signed distance function: then the distance is
        exactly |phi|.
    step : float, optional
        Finite-difference step of the gradient; default 1e-6 times
        max(1, |x|) per point.

    Notes
    -----
    Without ``signed_distance`` the distance is the first-order estimate
    |phi(x)| / |grad phi(x)|, the gradient by central differences (4 more
    evaluations of phi). It is exact for linear phi and a good estimate near
    the front, where the spacing law needs it most; far away it can be off by
    the curvature of phi (``|x|^2 - r^2`` gives (|x|^2 - r^2) / (2|x|), not
    | |x| - r |). Where the gradient vanishes and phi != 0 the distance is inf.
    """

    def __init__(
        self,
        phi: Callable[[np.ndarray, float], ArrayLike],
        *,
        signed_distance: bool = False,
        step: float | None = None,
    ):
        if not callable(phi):
            raise TypeError(f"phi must be callable phi(x, t), got {type(phi).__name__}")
        if not isinstance(signed_distance, (bool, np.bool_)):
            raise TypeError("signed_distance must be a bool")
        self.phi = phi
        self.signed_distance = bool(signed_distance)
        self.step = None if step is None else _real(step, "step")
        if self.step is not None and self.step <= 0:
            raise ValueError(f"step must be > 0, got {self.step}")

    def _phi(self, x: np.ndarray, t: float) -> np.ndarray:
        value = np.asarray(self.phi(x.copy(), t))
        if value.dtype == object or value.dtype.kind not in "fiu":
            raise TypeError(f"phi must return real numbers, got dtype {value.dtype}")
        value = np.array(np.broadcast_to(value, (len(x),)) if value.ndim == 0 else value, dtype=np.float64)
        if value.shape != (len(x),):
            raise ValueError(f"phi(x, t) must return shape ({len(x)},), got {value.shape}")
        if np.isnan(value).any():
            raise ValueError(f"phi(x, t) returned NaN (first at row {int(np.argmax(np.isnan(value)))})")
        return value

    def value(self, x: ArrayLike, t: float | None = None) -> np.ndarray:
        """phi(x, t), validated, shape (k,)."""
        return self._phi(as_query_points(x), _time(t))

    def distance(self, x: ArrayLike, t: float | None = None) -> np.ndarray:
        x = as_query_points(x)
        t = _time(t)
        value = self._phi(x, t)
        if self.signed_distance:
            return np.abs(value)
        h = self.step if self.step is not None else 1e-6 * np.maximum(1.0, np.abs(x).max(axis=1))
        h = np.broadcast_to(h, (len(x),))
        ex = np.c_[h, np.zeros(len(x))]
        ey = np.c_[np.zeros(len(x)), h]
        # one call for the four stencil points keeps phi vectorised
        stencil = self._phi(np.concatenate([x + ex, x - ex, x + ey, x - ey]), t).reshape(4, len(x))
        grad = np.hypot(stencil[0] - stencil[1], stencil[2] - stencil[3]) / (2 * h)
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.abs(value) / grad
        d = np.where(value == 0, 0.0, np.where(grad > 0, d, np.inf))
        return d

    def __repr__(self) -> str:
        return f"LevelSetFront(phi={getattr(self.phi, '__name__', self.phi)!r}, signed_distance={self.signed_distance})"


class SpacingLaw:
    """Target spacing from the distance to the front, and the resulting delta.

    h(d) = h_min inside the band (d <= band / 2), growing linearly with slope
    ``grade`` outside it, up to h_max:

        h(d) = min(h_max, h_min + grade * max(0, d - band / 2))

    and delta(p) = clip(h(d(p)) / nn_M(p), lower, upper), the paper's bounds
    0 < l < 1 < L of Definition 2.6 (Section 6: "delta values are linearly
    related with the distance to the boundary").

    Parameters
    ----------
    h_min, h_max : float
        Spacing at the front and far from it (0 < h_min <= h_max), in length units.
    band : float
        Full width of the band around the front where h = h_min (>= 0).
    grade : float, default 0.3
        dh/dd outside the band (> 0). Below 1 keeps h 1-Lipschitz, as a
        well-shaped mesh needs (Section 2.2).
    lower, upper : float, default 0.1 and 10
        The clip bounds l and L of delta.
    """

    def __init__(
        self, h_min: float, h_max: float, band: float, *, grade: float = 0.3, lower: float = 0.1, upper: float = 10.0
    ):
        self.h_min = _real(h_min, "h_min")
        self.h_max = _real(h_max, "h_max")
        self.band = _real(band, "band")
        self.grade = _real(grade, "grade")
        self.lower = _real(lower, "lower")
        self.upper = _real(upper, "upper")
        if self.h_min <= 0:
            raise ValueError(f"h_min must be > 0, got {self.h_min}")
        if self.h_min > self.h_max:
            raise ValueError(f"h_min must be <= h_max, got h_min={self.h_min} > h_max={self.h_max}")
        if self.band < 0:
            raise ValueError(f"band must be >= 0, got {self.band}")
        if self.grade <= 0:
            raise ValueError(f"grade must be > 0, got {self.grade}")
        if not 0 < self.lower < 1:
            raise ValueError(f"lower must be in (0, 1) (the paper's 0 < l < 1), got {self.lower}")
        if not self.upper > 1:
            raise ValueError(f"upper must be > 1 (the paper's L > 1), got {self.upper}")

    def h(self, distance: ArrayLike) -> np.ndarray:
        """Target spacing h(d) for distances d >= 0 (array or scalar), same shape."""
        d = np.asarray(distance)
        if d.dtype == object or d.dtype.kind not in "fiu":
            raise TypeError(f"distance must be a real numeric array, got dtype {d.dtype}")
        d = d.astype(np.float64)
        if np.isnan(d).any():
            raise ValueError("distance contains NaN")
        if (d < 0).any():
            raise ValueError("distance must be >= 0")
        return np.minimum(self.h_max, self.h_min + self.grade * np.maximum(0.0, d - 0.5 * self.band))

    def delta(self, mesh: Mesh, distance: ArrayLike | None, *, nn: np.ndarray | None = None) -> np.ndarray:
        """delta(p) = clip(h(d(p)) / nn_M(p), lower, upper) for every mesh point.

        Parameters
        ----------
        mesh : Mesh
        distance : array_like, shape (n,)
            Distance from each mesh point to the front.
        nn : ndarray, shape (n,), optional
            ``nn_spacing(mesh)`` if already computed.

        Returns
        -------
        ndarray, shape (n,)
        """
        _require_mesh(mesh)
        if distance is None:
            raise ValueError("a SpacingLaw needs the distance to a front: pass a front")
        d = np.asarray(distance)
        if d.shape != (mesh.n_points,):
            raise ValueError(f"distance must have one value per mesh point: shape ({mesh.n_points},), got {d.shape}")
        h = self.h(d)
        if nn is None:
            nn = mesh.nn_spacing  # cached on the mesh
        return np.clip(h / nn, self.lower, self.upper)

    def size(self, mesh: Mesh, distance: ArrayLike | None) -> np.ndarray:
        """The absolute spacing h(d) at the mesh points, shape (n,), for
        ``evolve(mesh, size=law.size(mesh, distance))`` (not clipped)."""
        if distance is None:
            raise ValueError("a SpacingLaw needs the distance to a front: pass a front")
        d = np.asarray(distance)
        if d.shape != (mesh.n_points,):
            raise ValueError(f"distance must have one value per mesh point: shape ({mesh.n_points},), got {d.shape}")
        return np.asarray(self.h(d), dtype=np.float64)

    def __call__(self, mesh: Mesh, distance: ArrayLike | None) -> np.ndarray:
        return self.delta(mesh, distance)

    def __repr__(self) -> str:
        return (
            f"SpacingLaw(h_min={self.h_min:g}, h_max={self.h_max:g}, band={self.band:g}, grade={self.grade:g}, "
            f"lower={self.lower:g}, upper={self.upper:g})"
        )
