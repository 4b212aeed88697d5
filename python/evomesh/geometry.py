"""Curved boundaries: the true curve behind a polygonal boundary, per segment tag.

A mesh's boundary is a polygon. Where it approximates a curve (a circle, a
CAD curve, the zero set of a signed distance function), give :func:`evolve` a
:class:`BoundaryGeometry` naming, per segment tag, the curve those segments
lie on::

    geometry = evomesh.BoundaryGeometry({HOLE: evomesh.Circle((0.5, 0.5), 0.2)})
    new = evomesh.evolve(mesh, delta, geometry=geometry)

Then a boundary vertex of a curved tag where the polygon turns by less than
``corner_angle`` degrees is no longer a corner: a step may remove it when it
coarsens, and every boundary point the step creates on that tag (sampled on
a segment, or added by the quality pass) lies on the curve: within a few units
of rounding for :class:`Circle` and :class:`Arc`, to the accuracy of the
function for :class:`SignedDistance`. Kept points never move. Points where the
tag changes, required points and vertices that turn by more than
``corner_angle`` stay corners. Without a geometry the polygon is the domain,
exactly (every bend is a corner).

Any object with ``project(points) -> points`` ((k, 2) arrays) is a curve; a
function ``project(points, tags) -> points`` for all tags at once is given
with :meth:`BoundaryGeometry.from_projection`.
"""

from __future__ import annotations

import hashlib
import math
import numbers
import re
from collections.abc import Callable, Iterable, Mapping
from typing import Any, Protocol

import numpy as np

from evomesh import _core
from evomesh.fronts import _real

#: Default of ``corner_angle`` (degrees): a boundary vertex of a curved tag
#: where the polygon turns by more than this stays a corner. A circle drawn
#: with 12 or more segments turns by at most 30 degrees per vertex; a
#: rectangle's corner turns by 90.
DEFAULT_CORNER_ANGLE: float = float(_core.DEFAULT_CORNER_ANGLE)


class Curve(Protocol):
    """A curve a boundary approximates: moves points onto it."""

    def project(self, points: np.ndarray) -> np.ndarray:  # pragma: no cover - protocol
        ...


def _points(points: Any) -> np.ndarray:
    x = np.asarray(points, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 2:
        raise ValueError(f"points must have shape (k, 2), got {x.shape}")
    return x


def _centre(center: Any) -> np.ndarray:
    c = np.asarray(center, dtype=np.float64)
    if c.shape != (2,) or not np.isfinite(c).all():
        raise ValueError(f"center must be two finite coordinates, got {center!r}")
    return c


class Circle:
    """The circle of ``center`` and ``radius`` (for a full circle or any arc of
    it: the corners at an arc's ends are kept anyway).

    ``project`` moves every point radially onto the circle, to within a few
    units of rounding.
    """

    def __init__(self, center: Any, radius: float):
        self.center = _centre(center)
        self.radius = _real(radius, "radius")
        if not self.radius > 0:
            raise ValueError(f"radius must be > 0, got {self.radius}")

    def project(self, points: Any) -> np.ndarray:
        x = _points(points)
        d = x - self.center
        r = np.hypot(d[:, 0], d[:, 1])
        if (r == 0).any():
            raise ValueError(f"cannot project the centre {self.center.tolist()} of a circle onto it")
        return self.center + d * (self.radius / r)[:, None]

    def __repr__(self) -> str:
        return f"Circle(center={self.center.tolist()}, radius={self.radius!r})"


class Arc(Circle):
    """The arc of the circle (``center``, ``radius``) from ``start`` to ``end``
    (angles in radians, counter-clockwise). Points project onto the nearest
    point of the arc: radially inside its angular range, onto the nearer end
    outside it.
    """

    def __init__(self, center: Any, radius: float, start: float, end: float):
        super().__init__(center, radius)
        self.start = _real(start, "start")
        self.end = _real(end, "end")
        self.sweep = (self.end - self.start) % (2 * math.pi)
        if self.sweep == 0:
            raise ValueError("an arc needs start != end (modulo 2 pi); use Circle for a full circle")

    def project(self, points: Any) -> np.ndarray:
        x = _points(points)
        on_circle = super().project(x)
        d = x - self.center
        angle = (np.arctan2(d[:, 1], d[:, 0]) - self.start) % (2 * math.pi)
        outside = angle > self.sweep
        if outside.any():
            ends = self.center + self.radius * np.array(
                [[math.cos(self.start), math.sin(self.start)], [math.cos(self.end), math.sin(self.end)]])
            q = x[outside]
            near_end = np.hypot(*(q - ends[1]).T) < np.hypot(*(q - ends[0]).T)
            on_circle[outside] = np.where(near_end[:, None], ends[1], ends[0])
        return on_circle

    def __repr__(self) -> str:
        return f"Arc(center={self.center.tolist()}, radius={self.radius!r}, start={self.start!r}, end={self.end!r})"


class SignedDistance:
    """The zero set of a function phi(x) of (k, 2) arrays (a signed distance,
    or any smooth function with a non-zero gradient near the curve).

    ``project`` runs Newton's iteration x <- x - phi(x) grad phi(x) / |grad phi(x)|^2
    until the step is below a few units of rounding of the coordinates (at most
    ``max_iterations`` times; ValueError if it does not settle). ``gradient``
    (k, 2) -> (k, 2) is optional; without it, central differences are used.
    """

    def __init__(self, phi: Callable[[np.ndarray], Any], gradient: Callable[[np.ndarray], Any] | None = None, *,
                 max_iterations: int = 50):
        if not callable(phi):
            raise TypeError("phi must be a function of an (k, 2) array")
        if gradient is not None and not callable(gradient):
            raise TypeError("gradient must be a function of an (k, 2) array or None")
        self.phi = phi
        self.gradient = gradient
        self.max_iterations = int(max_iterations)

    def _phi(self, x: np.ndarray) -> np.ndarray:
        v = np.asarray(self.phi(x), dtype=np.float64).reshape(-1)
        if v.shape != (len(x),) or not np.isfinite(v).all():
            raise ValueError("phi must return one finite value per point")
        return v

    def _grad(self, x: np.ndarray) -> np.ndarray:
        if self.gradient is not None:
            g = np.asarray(self.gradient(x), dtype=np.float64)
            if g.shape != x.shape or not np.isfinite(g).all():
                raise ValueError("gradient must return one finite (gx, gy) per point")
            return g
        h = np.cbrt(np.finfo(np.float64).eps) * np.maximum(1.0, np.abs(x).max(axis=1))
        ex = np.zeros_like(x)
        ex[:, 0] = h
        ey = np.zeros_like(x)
        ey[:, 1] = h
        return np.stack([(self._phi(x + ex) - self._phi(x - ex)) / (2 * h),
                         (self._phi(x + ey) - self._phi(x - ey)) / (2 * h)], axis=1)

    def project(self, points: Any) -> np.ndarray:
        x = _points(points).copy()
        if len(x) == 0:
            return x
        ulp = np.finfo(np.float64).eps * np.maximum(np.abs(x).max(axis=1), np.finfo(np.float64).tiny)
        active = np.ones(len(x), dtype=bool)
        for _ in range(self.max_iterations):
            xa = x[active]
            g = self._grad(xa)
            g2 = (g * g).sum(axis=1)
            if (g2 == 0).any():
                raise ValueError("the signed distance function has a zero gradient at a boundary point")
            step = (self._phi(xa) / g2)[:, None] * g
            x[active] = xa - step
            done = np.hypot(step[:, 0], step[:, 1]) <= 4 * ulp[active]
            idx = np.flatnonzero(active)
            active[idx[done]] = False
            if not active.any():
                return x
        raise ValueError(f"the projection onto the zero set of phi did not settle in {self.max_iterations} "
                         "Newton steps (is phi smooth with a non-zero gradient near the boundary?)")

    def __repr__(self) -> str:
        return f"SignedDistance({self.phi!r})"


class BoundaryGeometry:
    """The curves behind a mesh's boundary, per segment tag.

    Parameters
    ----------
    curves : mapping of int to curve
        Segment tag -> a curve (:class:`Circle`, :class:`Arc`,
        :class:`SignedDistance`, any object with ``project(points)``, or a
        function points -> points). Segments of other tags stay exact polygons.
    corner_angle : float in (0, 180), default :data:`DEFAULT_CORNER_ANGLE`
        A vertex of a curved tag where the polygon turns by more than this
        (degrees) stays a corner.
    """

    def __init__(self, curves: Mapping[int, Any], *, corner_angle: float = DEFAULT_CORNER_ANGLE):
        if not isinstance(curves, Mapping):
            raise TypeError("curves must be a mapping from segment tag to curve")
        self._curves: dict[int, Callable[[np.ndarray], Any]] = {}
        for tag, curve in curves.items():
            if isinstance(tag, bool) or not isinstance(tag, numbers.Integral):
                raise TypeError(f"segment tags must be integers, got {tag!r}")
            project = getattr(curve, "project", curve)
            if not callable(project):
                raise TypeError(f"the curve of tag {tag} has no project(points) and is not callable")
            self._curves[int(tag)] = project
        if not self._curves:
            raise ValueError("a BoundaryGeometry needs at least one curved tag")
        self.tags = tuple(sorted(self._curves))
        self.corner_angle = _real(corner_angle, "corner_angle")
        if not 0 < self.corner_angle < 180:
            raise ValueError(f"corner_angle must be in (0, 180) degrees, got {self.corner_angle}")
        self._project_all: Callable[[np.ndarray, np.ndarray], Any] | None = None

    @classmethod
    def from_projection(cls, project: Callable[[np.ndarray, np.ndarray], Any], tags: Iterable[int], *,
                        corner_angle: float = DEFAULT_CORNER_ANGLE) -> BoundaryGeometry:
        """One function ``project(points, tags) -> points`` for the segment
        tags ``tags``: moves points[i] onto the curve of tag tags[i]."""
        if not callable(project):
            raise TypeError("project must be a function (points, tags) -> points")
        tag_list = list(tags)
        geometry = cls(dict.fromkeys(tag_list, lambda x: x), corner_angle=corner_angle)
        geometry._project_all = project
        return geometry

    def project(self, points: Any, tags: Any) -> np.ndarray:
        """Moves points[i] onto the curve of segment tag tags[i]; (k, 2) float64."""
        x = _points(points)
        t = np.asarray(tags, dtype=np.int64).reshape(-1)
        if t.shape != (len(x),):
            raise ValueError("tags must have one value per point")
        if self._project_all is not None:
            out = _points(self._project_all(x.copy(), t.copy()))
        else:
            out = x.copy()
            for tag in np.unique(t):
                if int(tag) not in self._curves:
                    raise ValueError(f"segment tag {int(tag)} has no curve")
                sel = t == tag
                moved = _points(self._curves[int(tag)](x[sel].copy()))
                if moved.shape != (int(sel.sum()), 2):
                    raise ValueError(f"the curve of tag {int(tag)} returned {moved.shape[0]} points for "
                                     f"{int(sel.sum())}")
                out[sel] = moved
        if out.shape != x.shape:
            raise ValueError(f"the projection returned shape {out.shape} for {x.shape}")
        if not np.isfinite(out).all():
            raise ValueError("the projection returned a non-finite coordinate")
        return np.ascontiguousarray(out, dtype=np.float64)

    def _core_arguments(self) -> dict[str, Any]:
        return {"curved_tags": np.asarray(self.tags, dtype=np.int64), "corner_angle": self.corner_angle,
                "project": self.project}

    def __repr__(self) -> str:
        return f"BoundaryGeometry(tags={list(self.tags)}, corner_angle={self.corner_angle})"

    def _fingerprint(self) -> str:
        """This geometry in a few characters, equal on every process for equal
        parameters (a DistributedMesh's ranks compare it before a step): the
        tags, the corner angle and a hash of each curve's repr (a Circle's or an
        Arc's parameters; a function by its name), memory addresses removed."""
        curves = [(tag, self._curves[tag]) for tag in self.tags] + [(None, self._project_all)]
        text = re.sub(r" at 0x[0-9a-fA-F]+", "", repr(curves))
        return f"{self!r} #{hashlib.sha256(text.encode()).hexdigest()[:12]}"


def as_geometry(geometry: Any) -> BoundaryGeometry | None:
    """None, a BoundaryGeometry, or a mapping tag -> curve (converted)."""
    if geometry is None or isinstance(geometry, BoundaryGeometry):
        return geometry
    if isinstance(geometry, Mapping):
        return BoundaryGeometry(geometry)
    raise TypeError("geometry must be a BoundaryGeometry or a mapping from segment tag to curve, got "
                    f"{type(geometry).__name__}")
