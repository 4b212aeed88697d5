"""The immutable triangle mesh that evomesh evolves."""

from __future__ import annotations

import re
import warnings
from enum import IntEnum
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

from evomesh import _core

__all__ = ["Mesh", "PointKind", "Lineage"]

# The core evaluates polynomials of degree up to 4 in the coordinates, in double
# (squared cosines in CGAL's mesher, areas times lengths in the quality
# criteria): they must stay within float64's normal range [2.2e-308, 1.8e308].
# Hence |x| <= 1e75 and no two points closer than 1e-75; beyond these the
# quality pass loses its angle bound or crashes in CGAL's exact arithmetic
# (measured: extents near 1e-95 and 1e110). Any scale in between works and
# gives the same mesh up to rounding.
_MAX_COORDINATE = 1e75
_MIN_POINT_DISTANCE = 1e-75


PointKind = IntEnum("PointKind", dict(_core.POINT_KINDS), module=__name__)
PointKind.__doc__ = """Per-point label; the value is the packing priority (paper, Section 6).

CORNER points (ends of segment chains, and boundary points where the
boundary turns) are always kept. BOUNDARY points lie on a segment.
ORIGINAL points are interior points of the first mesh, STEINER points were
sampled in an earlier step, SAMPLED points in the step that made the mesh.
Names and values come from the C++ core (evomesh::Point_kind).
"""


def _frozen(array: np.ndarray) -> np.ndarray:
    """A read-only array over an immutable ``bytes`` owner: numpy refuses to make
    it (or any view of it) writeable again, so a Mesh cannot be changed in place.
    (A constant made by _frozen_constant, or an array already frozen, already is
    one, and is returned as it is.)"""
    if isinstance(array, np.ndarray) and array.ndim == 1 and array.strides == (0,) and _owned_by_bytes(array):
        return array
    # (already frozen: a Mesh's array, shared by a step that returns its input)
    if isinstance(array, np.ndarray) and array.flags.c_contiguous and not array.flags.writeable \
            and _owned_by_bytes(array):
        return array
    array = np.ascontiguousarray(array)
    return np.frombuffer(array.tobytes(), dtype=array.dtype).reshape(array.shape)


def _owned_by_bytes(array: np.ndarray) -> bool:
    base: object = array
    while isinstance(base, np.ndarray):
        base = base.base
    return isinstance(base, bytes)


def _frozen_constant(n: int, value: Any, dtype: Any) -> np.ndarray:
    """n copies of `value` as a read-only view of one immutable value (stride 0):
    the labels of an unlabelled mesh and the origin of a user's mesh cost no
    memory (24 bytes a point in a plain mesh: int64 triangle tags, int64 origin)."""
    one = np.frombuffer(np.array([value], dtype=dtype).tobytes(), dtype=dtype)
    return np.broadcast_to(one, (n,))


def _as_array(values: Any, name: str) -> np.ndarray:
    """np.asarray with a clear message for ragged nested sequences."""
    try:
        return np.asarray(values)
    except ValueError as error:  # inhomogeneous (ragged) nesting
        raise ValueError(f"{name} must be a rectangular array, not a ragged nested sequence") from error


def _as_points(points: Any, dim: int = 2) -> np.ndarray:
    """Checked coordinates, shape (n, dim), as a new float64 array."""
    array = _as_array(points, "points")
    if array.dtype == object or array.dtype.kind not in "fiu":
        raise TypeError(f"points must be a real numeric array, got dtype {array.dtype}")
    if array.ndim != 2 or array.shape[1] != dim:
        raise ValueError(f"points must have shape (n, {dim}), got {array.shape}")
    with np.errstate(over="ignore"):  # long double beyond float64 becomes inf, rejected below
        array = array.astype(np.float64)  # always a copy: the caller's array is never touched
    finite = np.isfinite(array).all(axis=1)
    if not finite.all():
        raise ValueError(f"points contain NaN or infinite coordinates (first at row {int(np.argmin(finite))})")
    if array.size and np.abs(array).max() > _MAX_COORDINATE:
        raise ValueError(f"point coordinates must be below {_MAX_COORDINATE:g} in magnitude")
    return array


def _as_indices(values: Any, columns: int, name: str, n_points: int) -> np.ndarray:
    array = _as_array(values, name)
    if array.dtype == object or array.dtype.kind not in "iu":
        raise TypeError(f"{name} must be an integer array, got dtype {array.dtype}")
    if array.ndim != 2 or array.shape[1] != columns:
        if not (array.size == 0 and name == "segments"):
            raise ValueError(f"{name} must have shape (k, {columns}), got {array.shape}")
        array = array.reshape(0, columns)
    if array.size and (array.min() < 0 or array.max() >= n_points):
        bad = int(np.argmax(((array < 0) | (array >= n_points)).any(axis=1)))
        raise ValueError(f"{name} row {bad} has a point index out of range [0, {n_points})")
    return array.astype(np.int64)


def _check_topology(points: np.ndarray, triangles: np.ndarray) -> None:
    n = len(points)
    t = np.sort(triangles, axis=1)
    repeated_vertex = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2])
    if repeated_vertex.any():
        raise ValueError(f"triangle {int(np.argmax(repeated_vertex))} repeats a vertex (zero area)")
    # sorted rows, then equal neighbours (one int64 key per row while n^3 < 2^63)
    if n <= 2**21:
        key = (t[:, 0].astype(np.int64) * n + t[:, 1]) * n + t[:, 2]
        order = np.argsort(key, kind="stable")
        repeated = np.flatnonzero(key[order[1:]] == key[order[:-1]])
    else:
        order = np.lexsort((t[:, 2], t[:, 1], t[:, 0]))
        repeated = np.flatnonzero((t[order[1:]] == t[order[:-1]]).all(axis=1))
    if len(repeated):
        raise ValueError(f"triangle {int(order[repeated].min())} appears more than once")
    used = np.bincount(triangles.ravel(), minlength=n)
    if (used == 0).any():
        raise ValueError(f"point {int(np.argmax(used == 0))} is not used by any triangle (orphan point)")
    order = np.lexsort((points[:, 1], points[:, 0]))
    same = (np.diff(points[order], axis=0) == 0).all(axis=1)
    if same.any():
        k = int(np.argmax(same))
        a, b = sorted((int(order[k]), int(order[k + 1])))
        raise ValueError(f"points {a} and {b} are duplicates")


def _check_point_distances(points: np.ndarray, nn: np.ndarray | None = None) -> np.ndarray:
    """nn_M at every point (returned; `nn` when already known); raises when two points are too close."""
    if nn is None:
        nn = _core.nn_spacing(points)
    if nn.min() < _MIN_POINT_DISTANCE:
        k = int(np.argmin(nn))
        raise ValueError(
            f"point {k} is {nn[k]:.3g} from its nearest point, below {_MIN_POINT_DISTANCE:g}: products of "
            "coordinates would underflow; rescale the mesh"
        )
    return nn


# A triangle whose height is below this fraction of its longest edge (smallest
# angle below ~6e-9 degrees) is degenerate for floating point: CGAL's mesher
# (quality pass, DRFC) splits edges at rounded midpoints, and a vertex that close
# to an edge can end up on its wrong side (measured: crashes below 1e-13).
_MIN_RELATIVE_HEIGHT = 1e-10
# ... and its height must exceed the rounding of its coordinates by this factor.
_MIN_HEIGHT_ULPS = 1024


def _flatness(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Height, longest edge and one unit of rounding of each triangle (numpy; the
    reference of the C++ ``_core.first_flat_triangles``, which does the same
    arithmetic, and the numbers of the error message)."""
    p = points[triangles].reshape(-1, 3, 2)
    edges = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]], axis=1)
    longest = np.sqrt((edges**2).sum(axis=2).max(axis=1))
    twice_area = edges[:, 0, 0] * edges[:, 2, 1] - edges[:, 0, 1] * edges[:, 2, 0]
    height = np.abs(twice_area) / longest
    rounding = np.finfo(float).eps * np.abs(p).max(axis=(1, 2))  # one unit of rounding of the coordinates
    return height, longest, rounding


def _check_not_flat(points: np.ndarray, triangles: np.ndarray) -> None:
    # The first thin / coarse triangle from C++ (O(n), no temporaries), the message from numpy.
    thin, coarse = _core.first_flat_triangles(points, triangles, _MIN_RELATIVE_HEIGHT, _MIN_HEIGHT_ULPS)
    if thin >= 0:
        height, longest, _ = _flatness(points, triangles[thin : thin + 1])
        raise ValueError(
            f"triangle {thin} is degenerate: its height is {height[0] / longest[0]:.1e} of its longest edge "
            f"(at least {_MIN_RELATIVE_HEIGHT:g} is needed)"
        )
    if coarse >= 0:
        height, _, rounding = _flatness(points, triangles[coarse : coarse + 1])
        raise ValueError(
            f"triangle {coarse} is degenerate at this offset: its height {height[0]:.3g} is "
            f"{height[0] / rounding[0]:.3g} units of rounding of its coordinates (|x| up to "
            f"{rounding[0] / np.finfo(float).eps:.3g}; at least {_MIN_HEIGHT_ULPS} are needed); translate the mesh "
            "towards the origin (for example subtract points.mean(axis=0)), which keeps its shape and makes the "
            "rounding smaller"
        )


def check_boundary_not_pinched(points: np.ndarray, segments: np.ndarray, is_boundary: np.ndarray,
                               kind: np.ndarray) -> None:
    """Raise ValueError where the domain nearly touches itself across its outside:
    a boundary corner closer to a boundary edge (other than the edge's own ends)
    than _MIN_HEIGHT_ULPS units of rounding of their coordinates, the limit every
    triangle meets. No triangle witnesses such a gap, and a step's segment
    splits would land on or across the point. Corners suffice (two straight
    chains come closest at an end of one), and a step keeps them and the chains'
    lines, so its output passes when its input does. O(n log n) on the boundary
    (_core.first_pinched_boundary)."""
    boundary = segments[np.asarray(is_boundary, dtype=bool)]
    corner = (np.asarray(kind) == PointKind.CORNER).astype(np.uint8)
    edge, point = _core.first_pinched_boundary(points, boundary, corner, _MIN_HEIGHT_ULPS)
    if edge < 0:
        return
    a, b = (int(v) for v in boundary[edge])
    p, q, r = points[point], points[a], points[b]
    along = np.clip(np.dot(p - q, r - q) / np.dot(r - q, r - q), 0.0, 1.0)
    gap = float(np.hypot(*(p - q - along * (r - q))))
    rounding = np.finfo(float).eps * float(np.abs(np.stack([p, q, r])).max())
    raise ValueError(
        f"the domain nearly touches itself: boundary corner {point} is {gap:.3g} from boundary edge ({a}, {b}), "
        f"{gap / rounding:.3g} units of rounding of their coordinates (at least {_MIN_HEIGHT_ULPS} are needed, as "
        "for the height of a triangle); move the corner away from the edge, or join them (make the corner a "
        "vertex of the edge)"
    )


def check_mesh_limits(points: np.ndarray, triangles: np.ndarray, nn: np.ndarray | None = None) -> np.ndarray:
    """Raise ValueError unless points and counter-clockwise triangles satisfy the
    numeric limits of :class:`Mesh`: coordinates within 1e75, no two points closer
    than 1e-75, every triangle positively oriented and not flat. O(n log n).
    Returns nn_M at the points (computed on the way, unless given as `nn`: the
    Euclidean distances of _core.nn_spacing)."""
    if points.size and not np.isfinite(points).all():
        raise ValueError("points contain NaN or infinite coordinates")
    if points.size and np.abs(points).max() > _MAX_COORDINATE:
        raise ValueError(f"point coordinates must be below {_MAX_COORDINATE:g} in magnitude")
    nn = _check_point_distances(points, nn)
    inverted = _core.first_inverted_triangle(points, triangles)
    if inverted >= 0:
        raise ValueError(f"triangle {inverted} has zero or negative area")
    _check_not_flat(points, triangles)
    return nn


class _ImmutableMesh:
    """What Mesh and TetMesh share: immutability (steps return new meshes;
    copies are the mesh itself) and the point count."""

    __slots__ = ()
    points: np.ndarray

    @property
    def n_points(self) -> int:
        return len(self.points)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"{type(self).__name__} is immutable; evolve() returns a new mesh")

    def __copy__(self) -> Any:
        return self  # immutable


class Mesh(_ImmutableMesh):
    """A valid 2-D triangle mesh with constraint segments; immutable.

    Parameters
    ----------
    points : array_like, shape (n, 2)
        Point coordinates (float64; copied). Finite, at most 1e75 in
        magnitude, and no two points closer than 1e-75 (so the core's
        products of coordinates neither overflow nor underflow); any scale in
        between is fine.
    triangles : array_like of int, shape (m, 3)
        Point indices of each triangle, in either orientation; stored
        counter-clockwise.
    segments : array_like of int, shape (k, 2), optional
        Constraint edges, each an edge of the mesh. Every boundary edge (an edge
        of exactly one triangle) is always a segment, so holes are kept; extra
        segments are interior constraints (material interfaces, cracks).
    kind : array_like of int, shape (n,), optional
        :class:`PointKind` per point; computed from the geometry when omitted
        (a point on segments is a corner unless exactly two segments of the
        same flavour meet there and the chain runs straight through it, up to
        32 units of rounding of its coordinates). A given ``kind`` can only add
        corners: every corner of the geometry is a CORNER whatever ``kind``
        says (so the domain never changes), CORNER on a straight boundary point
        pins it, and CORNER/BOUNDARY must be given exactly for the points on
        segments.
    segment_tags : array_like of int, shape (k,), optional
        An integer tag per row of ``segments`` (boundary-condition ids, Gmsh
        physical lines); boundary edges not in ``segments`` get 0. Every step
        keeps them: each output segment has the tag of the input segment it lies
        on, and a point where the tag changes is a corner (always kept).
    triangle_tags : array_like of int, shape (m,), optional
        An integer tag per triangle (regions, materials). Edges between
        triangles of different tags become interior segments (tag 0 unless
        given), so no triangle of a later step straddles two regions; each
        output triangle has the tag of the region it lies in.
    required : array_like of bool, shape (n,), optional
        Points every step keeps, at their exact coordinates and with their
        origin (a required point on segments is a corner).
    tag_names : mapping of (int, int) to str, optional
        Names of tags, keyed like Gmsh's physical groups: ``(1, tag)`` names a
        segment tag, ``(2, tag)`` a triangle tag (``{(1, 3): "dirichlet"}``).
        Read from and written to Gmsh files (``$PhysicalNames``), carried by
        every step; read-only (``mesh.tag_names``).
    origin : array_like of int, shape (n,), optional
        Index of each point in the mesh it was evolved from, -1 for a new point.

    Raises
    ------
    TypeError
        For arrays of the wrong dtype.
    ValueError
        For any malformed mesh: wrong shapes, fewer than 3 points or no
        triangle, NaN, infinite or out-of-range coordinates, indices out of
        range, zero-area (collinear) or nearly flat triangles (height below
        1e-10 of the longest edge, or below 1024 units of rounding of the
        coordinates), a domain that nearly touches itself (a boundary corner
        within 1024 units of rounding of a boundary edge it is not an end of),
        repeated, overlapping or inverted triangles, duplicate or orphan
        points, an edge shared by more than two triangles, a segment that is
        not a mesh edge, the same segment given twice with different tags, bad
        ``kind``, ``origin`` or ``tag_names``.
        The caller's arrays are never modified.
    """

    __slots__ = ("points", "triangles", "segments", "segment_is_boundary", "kind", "origin", "stats", "lineage", "_nn",
                 "_nn_grew", "segment_tags", "triangle_tags", "required", "tag_names", "_delaunay")

    points: np.ndarray
    triangles: np.ndarray
    segments: np.ndarray
    segment_is_boundary: np.ndarray
    kind: np.ndarray
    origin: np.ndarray
    stats: Mapping[str, float]
    lineage: "Lineage | None"
    segment_tags: np.ndarray
    triangle_tags: np.ndarray
    required: np.ndarray
    tag_names: Mapping[tuple[int, int], str]

    def __init__(self, points: Any, triangles: Any, segments: Any = None, *, segment_tags: Any = None,
                 triangle_tags: Any = None, required: Any = None, kind: Any = None, origin: Any = None,
                 tag_names: Any = None):
        pts = _as_points(points)
        n = len(pts)
        if n < 3:
            raise ValueError(f"a mesh needs at least 3 points, got {n}")
        tris = _as_indices(triangles, 3, "triangles", n)
        if len(tris) == 0:
            raise ValueError("a mesh needs at least one triangle")
        segs = None if segments is None else _as_indices(segments, 2, "segments", n)
        seg_tags = None
        if segment_tags is not None:
            if segs is None:
                raise ValueError("segment_tags need segments: one tag per row of segments")
            seg_tags = _as_tags(segment_tags, len(segs), "segment_tags", "segments")
            _check_repeated_segments_agree(segs, seg_tags)
        tri_tags = None if triangle_tags is None else _as_tags(triangle_tags, len(tris), "triangle_tags", "triangles")
        req = None if required is None else _as_mask(required, n)
        names = _as_tag_names(tag_names)
        _check_topology(pts, tris)
        nn = _check_point_distances(pts)
        if tri_tags is not None:
            # Region borders are constraints: a triangle of a step never straddles two regions.
            segs, seg_tags = _with_region_borders(tris, tri_tags, segs, seg_tags)
        tris, segs, boundary, computed_kind, _, built_tags, _ = _core.prepare_mesh(
            pts, tris, segs, True, seg_tags, None if req is None else req.astype(np.uint8)
        )
        _check_not_flat(pts, tris)
        if kind is None:
            kinds = computed_kind
        else:
            kinds = _as_array(kind, "kind")
            if kinds.dtype == object or kinds.dtype.kind not in "iu":
                raise TypeError(f"kind must be an integer array, got dtype {kinds.dtype}")
            if kinds.shape != (n,):
                raise ValueError(f"kind must have shape ({n},), got {kinds.shape}")
            if kinds.min() < 0 or kinds.max() > 4:
                raise ValueError("kind values must be PointKind values 0..4")
            on_segment = computed_kind <= PointKind.BOUNDARY
            given_on_segment = kinds <= PointKind.BOUNDARY
            if (on_segment != given_on_segment).any():
                bad = int(np.argmax(on_segment != given_on_segment))
                where = "lies" if on_segment[bad] else "does not lie"
                raise ValueError(
                    f"kind of point {bad} is {PointKind(int(kinds[bad])).name} but the point {where} on a segment: "
                    "the kinds corner/boundary are for exactly the points on segments"
                )
            # A kind can add corners, never remove one: every corner of the
            # geometry (where the boundary turns, chain ends) stays a corner, so
            # a stale or wrong kind cannot change the domain.
            kinds = np.where(computed_kind == PointKind.CORNER, np.uint8(PointKind.CORNER), kinds.astype(np.uint8))
        check_boundary_not_pinched(pts, segs, boundary, kinds)
        if origin is None:
            org = _frozen_constant(n, -1, np.int64)
        else:
            org = _as_array(origin, "origin")
            if org.dtype == object or org.dtype.kind not in "iu":
                raise TypeError(f"origin must be an integer array, got dtype {org.dtype}")
            if org.shape != (n,):
                raise ValueError(f"origin must have shape ({n},), got {org.shape}")
            if (org < -1).any() or (org.dtype.kind == "u" and (org > np.iinfo(np.int64).max).any()):
                raise ValueError("origin values must be point indices >= 0, or -1 for a new point")
            org = org.astype(np.int64)
        self._assign(pts, tris, segs, boundary, kinds, org, {}, None, nn, built_tags if seg_tags is not None else None,
                     tri_tags, req, tag_names=names)

    def _assign(self, points, triangles, segments, segment_is_boundary, kind, origin, stats, lineage, nn,
                segment_tags=None, triangle_tags=None, required=None, nn_grew=None, tag_names=None,
                delaunay=False) -> None:
        set_ = object.__setattr__
        # The step that made these (immutable) arrays certified its triangles the
        # constrained Delaunay triangulation of the points and segments, every other
        # edge strictly locally Delaunay (the result's triangulation_certified): the next
        # step's changed-region update inherits that for the edges it keeps
        # (cpp/include/evomesh/triangulation_update.hpp). False when not known.
        set_(self, "_delaunay", bool(delaunay))
        set_(self, "points", _frozen(np.asarray(points, dtype=np.float64)))
        set_(self, "triangles", _frozen(np.asarray(triangles, dtype=np.int64)))
        set_(self, "segments", _frozen(np.asarray(segments, dtype=np.int64).reshape(-1, 2)))
        set_(self, "segment_is_boundary", _frozen(np.asarray(segment_is_boundary, dtype=bool)))
        set_(self, "kind", _frozen(np.asarray(kind, dtype=np.uint8)))
        set_(self, "origin", _frozen(np.asarray(origin, dtype=np.int64)))
        set_(self, "stats", MappingProxyType(dict(stats)))
        set_(self, "lineage", lineage)
        n_segments, n_triangles, n_points = len(self.segments), len(self.triangles), len(self.points)
        set_(self, "segment_tags", _frozen_constant(n_segments, 0, np.int64) if segment_tags is None
             else _frozen(np.asarray(segment_tags, dtype=np.int64)))
        set_(self, "triangle_tags", _frozen_constant(n_triangles, 0, np.int64) if triangle_tags is None
             else _frozen(np.asarray(triangle_tags, dtype=np.int64)))
        set_(self, "required", _frozen_constant(n_points, False, bool) if required is None
             else _frozen(np.asarray(required, dtype=bool)))
        set_(self, "tag_names", MappingProxyType(dict(tag_names or {})))
        # nn: the Euclidean distances, made distances within the domain, unless
        # nn_grew (the points where that made them larger) says it was done.
        if nn is not None and nn_grew is None:
            nn, nn_grew = _core.nn_within_domain(points, triangles, np.asarray(nn, dtype=np.float64))
        set_(self, "_nn", None if nn is None else _frozen(np.asarray(nn, dtype=np.float64)))
        set_(self, "_nn_grew", None if nn is None else _frozen(np.asarray(nn_grew, dtype=np.int64)))

    @classmethod
    def _trusted(cls, points, triangles, segments, segment_is_boundary, kind, origin, stats=None, lineage=None,
                 nn=None, segment_tags=None, triangle_tags=None, required=None, nn_grew=None,
                 tag_names=None, delaunay=False) -> "Mesh":
        """Wrap arrays that evomesh itself produced (already valid); no checks."""
        mesh = cls.__new__(cls)
        mesh._assign(points, triangles, segments, segment_is_boundary, kind, origin, stats or {}, lineage, nn,
                     segment_tags, triangle_tags, required, nn_grew, tag_names, delaunay)
        return mesh

    def _labels(self) -> dict[str, Any]:
        """The labels to hand to the core: None where a label is unused."""
        return {
            "segment_tags": self.segment_tags if self.segment_tags.any() else None,
            "triangle_tags": self.triangle_tags if self.triangle_tags.any() else None,
            "required": self.required.astype(np.uint8) if self.required.any() else None,
        }

    @property
    def nn_spacing(self) -> np.ndarray:
        """nn_M(p) at every point, shape (n,): the distance to the nearest other
        point within the domain (computed once, when the mesh is made; read-only).

        A point whose nearest point is not an edge neighbour (in a constrained
        Delaunay triangulation: one hidden behind a constraint, across a slit or
        a thin wall) gets the length of its shortest edge instead; elsewhere this
        is the Euclidean nearest-neighbour distance of the paper. Steps use the
        same (``within_domain``, the default)."""
        if self._nn is None:
            nn, grew = _core.nn_within_domain(self.points, self.triangles)
            object.__setattr__(self, "_nn", _frozen(nn))
            object.__setattr__(self, "_nn_grew", _frozen(grew))
        return self._nn

    def with_tag_names(self, tag_names: Any) -> "Mesh":
        """This mesh with other tag names (every array the same, shared).

        Parameters
        ----------
        tag_names : mapping of (int, int) to str
            The new names, checked as :class:`Mesh`'s ``tag_names`` (they
            replace the old ones: ``{**mesh.tag_names, (1, 5): "inlet"}`` adds
            one). Names of tags the mesh does not use are kept too: a step may
            bring them into use (an interface's tag, ``(1,
            evomesh.INTERFACE_TAG)``, or its region tags).

        Returns
        -------
        Mesh
        """
        names = _as_tag_names(tag_names)
        return Mesh._trusted(self.points, self.triangles, self.segments, self.segment_is_boundary, self.kind,
                             self.origin, dict(self.stats), self.lineage, self._nn, self.segment_tags,
                             self.triangle_tags, self.required, self._nn_grew, names, self._delaunay)

    def _known_nn(self) -> dict[str, Any]:
        """nn_M within the domain and where it grew, for a step (which then skips
        computing them); empty when not computed yet."""
        return {} if self._nn is None else {"nn": self._nn, "nn_grew": self._nn_grew}

    def __reduce__(self):
        # Pickle and deepcopy round-trip every array bit for bit (checkpoints).
        # Tag names only when there are some: a pickle then reads as before.
        return (
            _unpickle_mesh,
            (self.points, self.triangles, self.segments, self.segment_is_boundary, self.kind, self.origin,
             dict(self.stats), self.lineage, self._nn, self.segment_tags, self.triangle_tags, self.required,
             self._nn_grew) + ((dict(self.tag_names),) if self.tag_names else ()),
        )

    def __deepcopy__(self, memo: dict) -> "Mesh":
        return _unpickle_mesh(*self.__reduce__()[1])

    @classmethod
    def from_meshio(cls, m: Any, *, tags: str | None = None) -> "Mesh":
        """A Mesh from a ``meshio.Mesh`` (any format meshio reads).

        Triangle blocks are concatenated; line cells become segments; a z
        column is dropped when it is 0 everywhere (a non-zero one is refused:
        dropping it would change the mesh); point data ``kind`` and ``origin``
        are used when present (integral floats accepted). Points used by no
        triangle (a Gmsh circle's centre, an isolated physical point) are removed
        with a warning that says how many. Other cells (vertex cells) are
        ignored; quadrilaterals, polygons and higher-order cells are refused.
        With Gmsh tags (``gmsh:physical``), the names of physical groups of
        dimension 1 and 2 (meshio's ``field_data``, name -> [tag, dim]) become
        ``tag_names``. Triangles keep the file's order, and so do segments
        when the line cells are exactly the mesh's segments (every boundary
        edge and interior constraint once; else they come in :class:`Mesh`'s
        order): a step depends on both orders (see
        :func:`evomesh.io.write_mesh`).
        """
        return cls._from_meshio(m, tags)[0]

    @classmethod
    def _from_meshio(cls, m: Any, tags: str | None = None) -> "tuple[Mesh, np.ndarray]":
        """The Mesh and the mask of the meshio points it kept."""
        points = np.asarray(m.points)
        if points.ndim != 2 or points.shape[1] not in (2, 3):
            raise ValueError(f"meshio mesh has points of shape {points.shape}; expected (n, 2) or (n, 3)")
        if points.shape[1] == 3:
            lifted = np.flatnonzero(~(points[:, 2] == 0))  # NaN counts as lifted
            if len(lifted):
                first = ", ".join(f"{int(k)} (z = {points[k, 2]:g})" for k in lifted[:5])
                more = f" and {len(lifted) - 5} more" if len(lifted) > 5 else ""
                raise ValueError(
                    f"not a planar mesh: {len(lifted)} of {len(points)} points have z != 0: points {first}{more}"
                )
            points = points[:, :2]
        if tags is None:
            tags = next((name for name in ("gmsh:physical", "tag", "tags") if name in m.cell_data), None)
        elif tags not in m.cell_data:
            raise ValueError(f"meshio mesh has no cell data {tags!r}; it has: {', '.join(m.cell_data) or 'none'}")
        triangles: list[np.ndarray] = []
        lines: list[np.ndarray] = []
        triangle_tags: list[np.ndarray] = []
        line_tags: list[np.ndarray] = []
        for k, block in enumerate(m.cells):
            block_tags = [] if tags is None else [np.asarray(m.cell_data[tags][k]).reshape(-1)]
            if block.type == "triangle":
                triangles.append(np.asarray(block.data))
                triangle_tags += block_tags
            elif block.type == "line":
                lines.append(np.asarray(block.data))
                line_tags += block_tags
            elif block.type != "vertex":
                raise ValueError(f"cells of type {block.type!r} are not supported: evomesh meshes are linear triangles")
        if not triangles:
            raise ValueError("meshio mesh has no triangle cells")
        tris = np.concatenate(triangles)
        segs = np.concatenate(lines) if lines else None
        tri_tags = None if tags is None else _integral_values(np.concatenate(triangle_tags), tags, "cell data",
                                                              "triangle")
        seg_tags = None if tags is None or not lines else _integral_values(np.concatenate(line_tags), tags,
                                                                           "cell data", "line cell")
        data = {name: np.asarray(values) for name, values in m.point_data.items() if not name.startswith("gmsh:")}
        kind, origin, required = data.get("kind"), data.get("origin"), data.get("required")
        used = np.zeros(len(points), dtype=bool)
        if tris.size and tris.min() >= 0 and tris.max() < len(points):
            used[tris.ravel()] = True
        if tris.size and not used.all() and tris.min() >= 0 and tris.max() < len(points):
            if segs is not None and segs.size and not used[segs.ravel()].all():
                raise ValueError("a line cell uses a point that no triangle uses")
            remap = np.cumsum(used) - 1
            warnings.warn(f"removed {int((~used).sum())} points used by no triangle", UserWarning, stacklevel=2)
            points, tris = points[used], remap[tris]
            segs = None if segs is None else remap[segs]
            kind = None if kind is None else kind[used]
            origin = None if origin is None else origin[used]
            required = None if required is None else required[used]
        names = _names_from_field_data(getattr(m, "field_data", None) or {}) if tags == "gmsh:physical" else {}
        mesh = cls(points, tris, segs, segment_tags=seg_tags, triangle_tags=tri_tags, tag_names=names,
                   required=None if required is None else _integral_values(required, "required").astype(bool),
                   kind=None if kind is None else _integral_values(kind, "kind"),
                   origin=None if origin is None else _integral_values(origin, "origin"))
        if segs is not None:
            mesh = _in_segment_order(mesh, segs)
        return mesh, used

    def to_meshio(self) -> Any:
        """A ``meshio.Mesh`` that Gmsh (2.2 and 4.1) and VTU files hold with its tags.

        Points with z = 0; one "triangle" block per triangle tag and one "line"
        block per segment tag (Gmsh 4.1 keeps one physical tag per block), in
        increasing tag order, each in the mesh's order: a mesh with one triangle
        tag reads back with its triangles in the same order, one with several
        with them grouped by tag (as from any Gmsh file). Tags are cell data
        ``gmsh:physical`` (int64: a tag beyond int32 is kept exactly in VTU;
        Gmsh files hold int32 only), with ``gmsh:geometrical`` (one entity per
        block) and point data ``gmsh:dim_tags`` (the entity of each point)
        that Gmsh files need; ``tag_names`` become ``field_data``
        (name -> [tag, dim], Gmsh's ``$PhysicalNames``). Point data ``kind``,
        ``origin`` and ``required``.

        A mesh with more blocks than points cannot be written as Gmsh 4.1
        (meshio needs a point on every entity; a UserWarning says so): write
        Gmsh 2.2 (:func:`evomesh.io.write_mesh` does) or VTU.

        A step depends on the order of the triangles and segments: a mesh read
        back from blocks grouped by tag steps differently from this one.
        :func:`evomesh.io.write_mesh` writes Gmsh 2.2, VTU and XDMF files with
        one block per cell type in the mesh's order instead (tags per cell),
        and :meth:`from_meshio` keeps that order: a faithful checkpoint.
        Passing ``file_format="gmsh22"`` (or ``"gmsh"``, 4.1) to
        ``meshio.write`` for a ``.msh`` file: meshio's default for that
        suffix is ANSYS, which holds no tags; :func:`evomesh.io.write_mesh`
        picks Gmsh 2.2 by itself.
        """
        return self._to_meshio(in_order=False)

    def _to_meshio(self, in_order: bool) -> Any:
        """to_meshio(); ``in_order``: one block per cell type, in the mesh's
        order, tags per cell (not for Gmsh 4.1, which keeps one tag per block)."""
        points = np.c_[self.points, np.zeros(self.n_points)]
        point_data = {"kind": np.array(self.kind, dtype=np.int32), "origin": np.array(self.origin),
                      "required": np.array(self.required, dtype=np.uint8)}
        return _tagged_meshio(points, [("triangle", 2, self.triangles, self.triangle_tags),
                                       ("line", 1, self.segments, self.segment_tags)], in_order, point_data,
                              self.tag_names)

    @staticmethod
    def skfem_names(m: Any) -> "tuple[dict[int, str], dict[int, str]]":
        """The tag numbering :meth:`from_skfem` uses for a scikit-fem mesh.

        Parameters
        ----------
        m : skfem.MeshTri
            A scikit-fem triangle mesh, with or without named boundaries and
            subdomains.

        Returns
        -------
        boundary_names, subdomain_names : dict of int to str
            Tag -> name, the names of ``m.boundaries`` (``m.subdomains``)
            numbered 1, 2, ... in sorted order (0 means untagged). Pass them to
            :meth:`to_skfem` to get the names back after a round trip.
        """
        boundaries = getattr(m, "boundaries", None) or {}
        subdomains = getattr(m, "subdomains", None) or {}
        return ({tag: name for tag, name in enumerate(sorted(boundaries), start=1)},
                {tag: name for tag, name in enumerate(sorted(subdomains), start=1)})

    @classmethod
    def from_skfem(cls, m: Any) -> "Mesh":
        """A Mesh from a scikit-fem triangle mesh (``skfem.MeshTri``).

        Points are ``m.p.T`` (vertices only), triangles ``m.t.T``, in the
        same order (triangles are stored counter-clockwise). Every facet of a
        named boundary (``m.boundaries``) becomes a segment whose tag is the
        number of its name, and every element of a named subdomain
        (``m.subdomains``) gets the number of its name as triangle tag; names
        are numbered 1, 2, ... in sorted order (0 = untagged; boundary and
        subdomain names are numbered separately). The numbering is not stored:
        :meth:`skfem_names` returns it, so that
        ``mesh.to_skfem(*Mesh.skfem_names(m))`` restores the names.

        Parameters
        ----------
        m : skfem.MeshTri
            A 2-D triangle mesh (a quadratic ``MeshTri2`` gives its linear
            mesh on the vertices).

        Returns
        -------
        Mesh

        Raises
        ------
        ImportError
            If scikit-fem is not installed.
        ValueError
            If ``m`` is not a 2-D triangle mesh, or a facet (element) belongs
            to two named boundaries (subdomains): one tag each cannot say that.
        """
        try:
            import skfem  # noqa: F401  (only to give the install hint)
        except ImportError as error:
            raise ImportError("Mesh.from_skfem needs scikit-fem: pip install evomesh[fem]") from error

        def tags_by_name(groups: Mapping[str, Any], names: Mapping[int, str], count: int, what: str) -> np.ndarray:
            """One tag per facet (element) from skfem's name -> indices; 0 where unnamed."""
            tags = np.zeros(count, np.int64)
            for tag, name in names.items():
                indices = np.asarray(groups[name], dtype=np.int64).reshape(-1)
                if indices.size and (indices.min() < 0 or indices.max() >= count):
                    raise ValueError(f"{name!r} has a {what} index out of range [0, {count})")
                clash = indices[tags[indices] != 0]
                if clash.size:
                    raise ValueError(f"{what} {int(clash[0])} is in both {names[int(tags[clash[0]])]!r} and {name!r}: "
                                     f"evomesh keeps one tag (one name) per {what}")
                tags[indices] = tag
            return tags

        t = np.asarray(m.t)
        if t.ndim != 2 or t.shape[0] != 3 or np.asarray(m.p).shape[0] != 2:
            raise ValueError(f"expected a 2-D triangle mesh (p of shape (2, n), t of shape (3, m)), got "
                             f"{type(m).__name__} with p {np.asarray(m.p).shape} and t {t.shape}")
        n_vertices = int(t.max()) + 1
        points = np.asarray(m.p)[:, :n_vertices].T
        triangles = t.T
        boundary_names, subdomain_names = cls.skfem_names(m)
        segments = segment_tags = triangle_tags = None
        if boundary_names:
            facets = np.asarray(m.facets).T
            facet_tag = tags_by_name(m.boundaries, boundary_names, facets.shape[0], "facet")
            named = np.flatnonzero(facet_tag)
            segments, segment_tags = facets[named], facet_tag[named]
        if subdomain_names:
            triangle_tags = tags_by_name(m.subdomains, subdomain_names, len(triangles), "element")
        return cls(points, triangles, segments, segment_tags=segment_tags, triangle_tags=triangle_tags)

    def to_skfem(self, boundary_names: "dict[int, str] | None" = None,
                 subdomain_names: "dict[int, str] | None" = None) -> Any:
        """This mesh as a scikit-fem ``MeshTri`` with named boundaries and subdomains.

        Points and triangles keep their order and orientation (``p`` is
        ``points.T``, ``t`` is ``triangles.T``; skfem's sorting of ``t`` is
        switched off). Every nonzero segment tag k becomes the boundary
        ``boundary_names[k]`` (the facets of the segments of that tag; interior
        segments too), every nonzero triangle tag k the subdomain
        ``subdomain_names[k]`` (element indices); a tag without a name is
        called ``"tag_<k>"``. Named tags the mesh does not use give empty
        index arrays, so the names of :meth:`skfem_names` survive a round trip.

        Parameters
        ----------
        boundary_names, subdomain_names : dict of int to str, optional
            Tag -> name, e.g. the dicts of :meth:`skfem_names`.

        Returns
        -------
        skfem.MeshTri

        Raises
        ------
        ImportError
            If scikit-fem is not installed.
        """
        import dataclasses

        try:
            import skfem
        except ImportError as error:
            raise ImportError("Mesh.to_skfem needs scikit-fem: pip install evomesh[fem]") from error
        fields = {field.name for field in dataclasses.fields(skfem.MeshTri)}
        keywords = {"sort_t": False} if "sort_t" in fields else {}
        m = skfem.MeshTri(np.ascontiguousarray(self.points.T), np.ascontiguousarray(self.triangles.T), **keywords)
        boundary_names = dict(boundary_names or {})
        subdomain_names = dict(subdomain_names or {})
        boundaries: dict[str, np.ndarray] = {}
        tags = np.union1d(self.segment_tags[self.segment_tags != 0], np.array(list(boundary_names), np.int64))
        if len(tags):
            facets = np.sort(np.asarray(m.facets).T, axis=1).astype(np.int64)
            n = np.int64(self.n_points)
            facet_keys = facets[:, 0] * n + facets[:, 1]
            order = np.argsort(facet_keys)
            segments = np.sort(self.segments, axis=1)
            found = np.searchsorted(facet_keys, segments[:, 0] * n + segments[:, 1], sorter=order)
            segment_facet = order[np.minimum(found, len(order) - 1)]
            for tag in tags.tolist():
                boundaries[boundary_names.get(tag, f"tag_{tag}")] = np.sort(segment_facet[self.segment_tags == tag])
        subdomains: dict[str, np.ndarray] = {}
        named_regions = np.array(list(subdomain_names), np.int64)
        for tag in np.union1d(self.triangle_tags[self.triangle_tags != 0], named_regions).tolist():
            subdomains[subdomain_names.get(tag, f"tag_{tag}")] = np.flatnonzero(self.triangle_tags == tag)
        if boundaries:
            m = m.with_boundaries(boundaries)
        if subdomains:
            m = m.with_subdomains(subdomains)
        return m

    @property
    def n_triangles(self) -> int:
        return len(self.triangles)

    @property
    def triangle_areas(self) -> np.ndarray:
        """Signed areas (positive: counter-clockwise), shape (m,)."""
        p = self.points[self.triangles]
        d1 = p[:, 1] - p[:, 0]
        d2 = p[:, 2] - p[:, 0]
        return 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])

    @property
    def area(self) -> float:
        return float(self.triangle_areas.sum())

    @property
    def kinds(self) -> np.ndarray:
        """``kind`` as an object array of :class:`PointKind` (for display)."""
        return np.array([PointKind(k) for k in self.kind], dtype=object)

    def euler_characteristic(self) -> int:
        """V - E + F (F counts triangles only): 1 for a disc, 1 - h with h holes."""
        t = self.triangles
        edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
        n_edges = len(np.unique(edges, axis=0))
        return self.n_points - n_edges + self.n_triangles

    def __repr__(self) -> str:
        counts = np.bincount(self.kind, minlength=5)
        by_kind = ", ".join(f"{k.name.lower()}={int(c)}" for k, c in zip(PointKind, counts) if c)
        return f"Mesh(n_points={self.n_points}, n_triangles={self.n_triangles}, segments={len(self.segments)}, {by_kind})"


def _unpickle_mesh(points, triangles, segments, segment_is_boundary, kind, origin, stats, lineage=None,
                   nn=None, segment_tags=None, triangle_tags=None, required=None, nn_grew=None,
                   tag_names=None) -> Mesh:
    # A pickle without nn_grew (before 2026-12) holds nn within the domain but
    # not where it grew: nn is then computed again, when first needed.
    return Mesh._trusted(points, triangles, segments, segment_is_boundary, kind, origin, stats, lineage,
                         None if nn_grew is None else nn, segment_tags, triangle_tags, required, nn_grew, tag_names)


def _as_tags(values: Any, length: int, name: str, rows: str) -> np.ndarray:
    array = _as_array(values, name)
    if array.dtype == object or array.dtype.kind not in "iu":
        raise TypeError(f"{name} must be an integer array, got dtype {array.dtype}")
    if array.shape != (length,):
        raise ValueError(f"{name} must have one tag per row of {rows}: shape ({length},), got {array.shape}")
    if array.dtype.kind == "u" and array.size and array.max() > np.iinfo(np.int64).max:
        raise ValueError(f"{name} must fit in int64")
    return array.astype(np.int64)


def _check_repeated_segments_agree(segments: np.ndarray, tags: np.ndarray) -> None:
    """A segment given twice (either direction) must have one tag: a step keeps one."""
    if len(segments) < 2:
        return
    edges = np.sort(segments, axis=1)
    order = np.lexsort((tags, edges[:, 1], edges[:, 0]))
    same = (edges[order[1:]] == edges[order[:-1]]).all(axis=1) & (tags[order[1:]] != tags[order[:-1]])
    if same.any():
        k = int(np.argmax(same))
        i, j = sorted((int(order[k]), int(order[k + 1])))
        a, b = (int(v) for v in edges[order[k]])
        raise ValueError(f"segment ({a}, {b}) is given twice with different tags: row {i} has tag {int(tags[i])}, "
                         f"row {j} has tag {int(tags[j])}; a segment has one tag")


def _tagged_meshio(points: np.ndarray, cell_types: Sequence[tuple[str, int, np.ndarray, np.ndarray]], in_order: bool,
                   point_data: dict[str, np.ndarray], tag_names: Mapping[tuple[int, int], str]) -> Any:
    """A meshio.Mesh of ``points`` (n, 3) and cells given as (meshio type, dim,
    cells, tags), highest dimension first, with Gmsh's tags (``gmsh:physical``,
    ``gmsh:geometrical``, point data ``gmsh:dim_tags``) and the tag names as
    ``field_data`` (name -> [tag, dim]). ``in_order``: one block per cell type
    in the given order, tags per cell; else one block per (type, tag), in
    increasing tag order (Gmsh 4.1 keeps one physical tag per block)."""
    import meshio

    n_points = len(points)
    blocks: list[tuple[str, int, np.ndarray, np.ndarray]] = []  # (type, dim, cells, their tags)
    for kind, dim, cells, cell_tags in cell_types:
        if len(cells) == 0:
            continue
        if in_order:
            blocks.append((kind, dim, np.array(cells), np.array(cell_tags)))
            continue
        order = np.argsort(cell_tags, kind="stable")
        sorted_tags = cell_tags[order]
        starts = np.flatnonzero(np.r_[True, sorted_tags[1:] != sorted_tags[:-1]])
        for first, last in zip(starts, np.r_[starts[1:], len(order)]):
            blocks.append((kind, dim, np.array(cells[order[first:last]]), sorted_tags[first:last]))
    # Gmsh entities: one per block (geometrical tag k + 1 of block k). Every
    # entity must hold a point (meshio's Gmsh 4.1 writer lists only those),
    # and meshio's 4.1 reader keeps points and point data in step only when
    # the points come in entity order: so the points are spread over the
    # entities in index order, sorted by (dim, tag). This classification
    # means nothing else; the cells carry the tags.
    dims = np.array([dim for _, dim, _, _ in blocks], dtype=np.int32)
    entities = np.lexsort((np.arange(len(blocks)), dims))
    if n_points < len(blocks):
        warnings.warn(f"the mesh has more tags ({len(blocks)} blocks of cells) than points: meshio cannot write it "
                      "as Gmsh 4.1 (write Gmsh 2.2 or VTU)", UserWarning, stacklevel=3)
    entity = entities[np.arange(n_points, dtype=np.int64) * len(blocks) // n_points]
    dim_tags = np.c_[dims[entity], entity + 1].astype(np.int32)
    cell_data = {"gmsh:physical": [np.asarray(tags, np.int64) for _, _, _, tags in blocks],
                 "gmsh:geometrical": [np.full(len(c), k + 1, np.int32) for k, (_, _, c, _) in enumerate(blocks)]}
    field_data = {name: np.array([tag, dim], dtype=np.int64) for (dim, tag), name in tag_names.items()}
    return meshio.Mesh(points, [(kind, c) for kind, _, c, _ in blocks], point_data={**point_data,
                       "gmsh:dim_tags": dim_tags}, cell_data=cell_data, field_data=field_data)


#: The dimensions a triangle mesh's tag names refer to.
_TRIANGLE_MESH_TAG_DIMS = {1: "segment", 2: "triangle"}
#: Characters a tag name may not hold: Gmsh writes names in double quotes, one a line.
_BAD_TAG_NAME_CHARACTER = re.compile(r'["\x00-\x1f\x7f]')


def _as_tag_names(names: Any, dims: Mapping[int, str] | None = None) -> dict[tuple[int, int], str]:
    """Checked tag names: (dim, tag) -> name, dim one of ``dims`` (dim -> what
    it tags; default 1 segments, 2 triangles)."""
    dims = _TRIANGLE_MESH_TAG_DIMS if dims is None else dims
    if names is None:
        return {}
    if not isinstance(names, Mapping):
        raise TypeError(f"tag_names must be a mapping of (dim, tag) -> name, got {type(names).__name__}")
    checked: dict[tuple[int, int], str] = {}
    for key, name in names.items():
        if (not isinstance(key, tuple) or len(key) != 2
                or not all(isinstance(k, (int, np.integer)) and not isinstance(k, bool) for k in key)):
            raise TypeError(f"tag_names keys must be (dim, tag) pairs of integers, got {key!r}")
        dim, tag = int(key[0]), int(key[1])
        if dim not in dims:
            allowed = " or ".join(f"{d} ({what} tags)" for d, what in dims.items())
            raise ValueError(f"tag_names key {key!r}: dim must be {allowed}")
        if not -(2**63) <= tag < 2**63:
            raise ValueError(f"tag_names key {key!r}: the tag must fit in int64")
        if not isinstance(name, str) or not name:
            raise TypeError(f"tag_names[{key!r}] must be a non-empty string, got {name!r}")
        bad = _BAD_TAG_NAME_CHARACTER.search(name)
        if bad:
            raise ValueError(f"tag_names[{key!r}] = {name!r} contains {bad.group()!r}: Gmsh files cannot hold "
                             "double quotes or control characters in names")
        checked[(dim, tag)] = name
    return checked


def _as_mask(values: Any, n: int) -> np.ndarray:
    array = _as_array(values, "required")
    if array.dtype != bool:
        raise TypeError(f"required must be a boolean array (one flag per point), got dtype {array.dtype}")
    if array.shape != (n,):
        raise ValueError(f"required must have one flag per point: shape ({n},), got {array.shape}")
    return array.copy()


def _with_region_borders(triangles: np.ndarray, tags: np.ndarray, segments: np.ndarray | None,
                         segment_tags: np.ndarray | None) -> tuple[np.ndarray | None, np.ndarray | None]:
    """segments (and their tags) with every edge between triangles of different
    tags added as an interior segment of tag 0 (unless already a segment)."""
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(len(triangles)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, owner = edges[order], owner[order]
    pair = np.flatnonzero((edges[1:] == edges[:-1]).all(axis=1))
    border = edges[pair[tags[owner[pair]] != tags[owner[pair + 1]]]]
    if len(border) == 0:
        return segments, segment_tags
    if segments is not None and len(segments):
        n = int(triangles.max()) + 1
        known = np.sort(segments, axis=1)
        border = border[~np.isin(border[:, 0] * n + border[:, 1], known[:, 0] * n + known[:, 1])]
    base = np.zeros((0, 2), np.int64) if segments is None else segments
    base_tags = np.zeros(len(base), np.int64) if segment_tags is None else segment_tags
    return np.concatenate([base, border]), np.concatenate([base_tags, np.zeros(len(border), np.int64)])


def _names_from_field_data(field_data: Mapping[str, Any], dims: Sequence[int] = (1, 2)) -> dict[tuple[int, int], str]:
    """Gmsh's physical names (meshio field_data, name -> [tag, dim]) of the
    dimensions ``dims``, as tag_names; other entries are not names of tags."""
    names: dict[tuple[int, int], str] = {}
    for name, value in field_data.items():
        array = np.asarray(value)
        if array.shape != (2,) or array.dtype.kind not in "iuf" or not np.isfinite(array).all():
            continue
        tag, dim = (int(v) for v in array)
        if dim in dims and isinstance(name, str) and name and not _BAD_TAG_NAME_CHARACTER.search(name):
            names.setdefault((dim, tag), name)
    return names


def _in_segment_order(mesh: "Mesh", segments: np.ndarray) -> "Mesh":
    """``mesh`` with its segments in the order of ``segments`` (rows in either
    direction, the line cells of a file) when they are exactly its segments;
    else ``mesh``. Mesh() builds its own order (boundary edges, then interior
    ones); a step's output has another, and the next step depends on it."""
    n = np.int64(mesh.n_points)
    mine = np.sort(mesh.segments, axis=1) @ np.array([n, 1], dtype=np.int64)
    wanted = np.sort(np.asarray(segments, dtype=np.int64), axis=1) @ np.array([n, 1], dtype=np.int64)
    if len(wanted) != len(mine) or len(mine) == 0:
        return mesh
    order = np.argsort(mine)
    index = order[np.minimum(np.searchsorted(mine, wanted, sorter=order), len(mine) - 1)]
    if not np.array_equal(mine[index], wanted) or len(np.unique(index)) != len(index):
        return mesh
    if np.array_equal(index, np.arange(len(index))):
        return mesh
    return Mesh._trusted(mesh.points, mesh.triangles, mesh.segments[index], mesh.segment_is_boundary[index],
                         mesh.kind, mesh.origin, {}, None, mesh._nn, mesh.segment_tags[index], mesh.triangle_tags,
                         mesh.required, mesh._nn_grew, mesh.tag_names)


def _integral_values(values: np.ndarray, name: str, data: str = "point data", item: str = "point") -> np.ndarray:
    """Integer data that files may store as floats: integral floats become
    int64, other floats (and other dtypes) are an error naming the first bad
    item (``data``: "point data" or "cell data"; ``item``: "point", "triangle",
    "line cell")."""
    if values.dtype.kind in "iub":
        return values
    if values.dtype.kind != "f":
        raise ValueError(f"{data} {name!r} must hold integers, got dtype {values.dtype}")
    with np.errstate(invalid="ignore"):
        integral = np.isfinite(values) & (values == np.round(values)) & (np.abs(values) < 2.0**63)
    if not integral.all():
        bad = np.flatnonzero(~integral.reshape(len(values), -1).all(axis=1))
        raise ValueError(
            f"{data} {name!r} must hold integers, but {len(bad)} of {len(values)} {item}s do not (first: {item} "
            f"{int(bad[0])}, {name} = {values[int(bad[0])]!r})"
        )
    return values.astype(np.int64)


class Lineage:
    """How a mesh made by :func:`evomesh.evolve` lies in the mesh it was evolved
    from (``new.lineage``; None for a mesh built by :class:`Mesh`). Read-only.

    Attributes
    ----------
    n_old_points, n_old_triangles : int
        Sizes of the old mesh (checked against the mesh a caller pairs it with).
    parent_triangle : ndarray of int, shape (n_new,)
        For every point not kept (``origin == -1``), the old triangle that
        contains it; -1 for kept points (their old index is ``origin``) and for
        the rare point no old triangle contains. After a step that moved the
        points (``moved``), every point's: kept points moved too.
    barycentric : ndarray, shape (n_new, 3)
        Its barycentric coordinates in that triangle (vertex order of
        ``old.triangles``); they sum to 1 and reproduce linear functions.
    old_nn, old_f : ndarray, shape (n_old,)
        nn_M and the spacing function f at the old points, as the step used them
        (after a move: at the moved points; NaN at points the move dropped).
    motion : Motion or None
        For a step with ``displacement=`` (:func:`evomesh.evolve`): the move
        (:class:`evomesh.motion.Motion`: the moved mesh, the displacement, and
        the step's own lineage relative to the moved mesh). None otherwise.
    """

    __slots__ = ("n_old_points", "n_old_triangles", "parent_triangle", "barycentric", "old_nn", "old_f", "motion")

    n_old_points: int
    n_old_triangles: int
    parent_triangle: np.ndarray
    barycentric: np.ndarray
    old_nn: np.ndarray
    old_f: np.ndarray
    motion: Any

    def __init__(self, n_old_points: int, n_old_triangles: int, parent_triangle: np.ndarray, barycentric: np.ndarray,
                 old_nn: np.ndarray, old_f: np.ndarray, motion: Any = None) -> None:
        set_ = object.__setattr__
        set_(self, "motion", motion)
        set_(self, "n_old_points", int(n_old_points))
        set_(self, "n_old_triangles", int(n_old_triangles))
        set_(self, "parent_triangle", _frozen(np.asarray(parent_triangle, dtype=np.int64)))
        set_(self, "barycentric", _frozen(np.asarray(barycentric, dtype=np.float64).reshape(-1, 3)))
        set_(self, "old_nn", _frozen(np.asarray(old_nn, dtype=np.float64)))
        set_(self, "old_f", _frozen(np.asarray(old_f, dtype=np.float64)))

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("Lineage is immutable")

    def __reduce__(self):
        return (Lineage, (self.n_old_points, self.n_old_triangles, self.parent_triangle, self.barycentric, self.old_nn,
                          self.old_f, self.motion))

    @property
    def moved(self) -> bool:
        """Whether the step moved the old points (``displacement=``): then kept
        points are not at their old coordinates, and ``parent_triangle`` locates
        every new point in the old mesh at the old positions."""
        return self.motion is not None

    def matches(self, old: "Mesh") -> bool:
        """Whether ``old`` has the sizes of the mesh this lineage refers to."""
        return old.n_points == self.n_old_points and old.n_triangles == self.n_old_triangles

    def __repr__(self) -> str:
        located = int((self.parent_triangle >= 0).sum())
        moved = ", moved=True" if self.moved else ""
        return f"Lineage(n_old_points={self.n_old_points}, located={located}{moved})"
