"""The immutable tetrahedral mesh that evomesh evolves in 3-D, its generators
and its quality measures."""

from __future__ import annotations

from enum import IntEnum
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

from evomesh import _core
from evomesh.mesh import _as_array, _as_indices, _as_mask, _as_tags, _frozen, _frozen_constant

__all__ = ["TetMesh", "TetPointKind", "TetLineage", "unit_cube_mesh", "box_mesh", "radius_edge_ratios",
           "dihedral_angles"]

_MAX_COORDINATE = 1e75
# A tetrahedron whose volume is below this fraction of its longest edge cubed
# is degenerate for floating point (its smallest dihedral angle is ~1e-8 deg).
_MIN_RELATIVE_VOLUME = 1e-10


class TetPointKind(IntEnum):
    """Per-point label of a :class:`TetMesh`; the value is the packing order.

    CORNER, EDGE and FACE points lie on a corner, an edge or a face of the box
    (corners are always kept); ORIGINAL points are interior points of the
    user's mesh, STEINER points interior points added by an earlier step,
    SAMPLED points interior points added by the step that made the mesh.
    """

    CORNER = 0
    EDGE = 1
    FACE = 2
    ORIGINAL = 3
    STEINER = 4
    SAMPLED = 5


# The outward faces of a positively oriented tetrahedron (a, b, c, d): each
# is an odd permutation of the tetrahedron with its opposite vertex last.
_OUTWARD_FACES = np.array([[1, 2, 3], [0, 2, 1], [0, 1, 3], [0, 3, 2]])


class TetLineage:
    """Where each point of a step's output came from: ``parent_tet[i]`` is the
    old tetrahedron holding a new point i (-1 for kept points, whose
    ``origin`` says which old point they are). Enough for a linear transfer."""

    __slots__ = ("n_old_points", "n_old_tetrahedra", "parent_tet")

    n_old_points: int
    n_old_tetrahedra: int
    parent_tet: np.ndarray

    def __init__(self, n_old_points: int, n_old_tetrahedra: int, parent_tet: np.ndarray):
        object.__setattr__(self, "n_old_points", int(n_old_points))
        object.__setattr__(self, "n_old_tetrahedra", int(n_old_tetrahedra))
        object.__setattr__(self, "parent_tet", _frozen(np.asarray(parent_tet, dtype=np.int64)))

    def matches(self, old: TetMesh) -> bool:
        return old.n_points == self.n_old_points and len(old.tetrahedra) == self.n_old_tetrahedra

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("TetLineage is immutable")


def _as_points3(points: Any) -> np.ndarray:
    array = _as_array(points, "points")
    if array.dtype == object or array.dtype.kind not in "fiu":
        raise TypeError(f"points must be a real numeric array, got dtype {array.dtype}")
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {array.shape}")
    with np.errstate(over="ignore"):
        array = array.astype(np.float64)  # a copy: the caller's array is never touched
    finite = np.isfinite(array).all(axis=1)
    if not finite.all():
        raise ValueError(f"points contain NaN or infinite coordinates (first at row {int(np.argmin(finite))})")
    if array.size and np.abs(array).max() > _MAX_COORDINATE:
        raise ValueError(f"point coordinates must be below {_MAX_COORDINATE:g} in magnitude")
    return array


def _row_keys(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted rows of equal keys together: (order, inverse key index) where
    equal rows of ``rows`` get the same group number (numbers in sorted order)."""
    if len(rows) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = np.lexsort(rows.T[::-1])
    sorted_rows = rows[order]
    new_group = np.ones(len(rows), bool)
    new_group[1:] = (sorted_rows[1:] != sorted_rows[:-1]).any(axis=1)
    group = np.empty(len(rows), np.int64)
    group[order] = np.cumsum(new_group) - 1
    return order, group


def _canonical_oriented(faces: np.ndarray) -> np.ndarray:
    """Each oriented triangle rotated (an even permutation) to put its smallest index first."""
    first = np.argmin(faces, axis=1)
    index = (first[:, None] + np.arange(3)[None, :]) % 3
    return np.take_along_axis(faces, index, axis=1)


def boundary_faces(tetrahedra: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The triangles on one tetrahedron only, oriented outward, and that tetrahedron.

    Raises ValueError when a triangle is shared by more than two tetrahedra
    (non-manifold) or two tetrahedra on the same side of their common triangle.
    """
    m = len(tetrahedra)
    faces = tetrahedra[:, _OUTWARD_FACES].reshape(-1, 3)
    owner = np.repeat(np.arange(m), 4)
    _, group = _row_keys(np.sort(faces, axis=1))
    count = np.bincount(group)
    if (count > 2).any():
        g = int(np.argmax(count > 2))
        raise ValueError(f"the triangle {sorted(faces[group == g][0].tolist())} is shared by {count[g]} tetrahedra "
                         "(a non-manifold mesh)")
    shared = count[group] == 2
    if shared.any():
        _, oriented_group = _row_keys(_canonical_oriented(faces[shared]))
        same = np.bincount(oriented_group) > 1
        if same.any():
            g = int(np.argmax(same))
            tets = owner[shared][oriented_group == g]
            raise ValueError(f"tetrahedra {int(tets[0])} and {int(tets[1])} lie on the same side of their common "
                             "triangle (they overlap)")
    once = ~shared
    return faces[once], owner[once]


def tet_volumes(points: np.ndarray, tetrahedra: np.ndarray) -> np.ndarray:
    p = points[tetrahedra]
    u, v, w = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    return np.einsum("ij,ij->i", u, np.cross(v, w)) / 6.0


def _edges_of(p: np.ndarray) -> np.ndarray:
    pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    return np.stack([p[:, j] - p[:, i] for i, j in pairs], axis=1)


def radius_edge_ratios(points: np.ndarray, tetrahedra: np.ndarray) -> np.ndarray:
    """Circumradius over shortest edge of each tetrahedron (regular: 0.612)."""
    p = np.asarray(points, dtype=np.float64)[np.asarray(tetrahedra)]
    u, v, w = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    det = np.einsum("ij,ij->i", u, np.cross(v, w))
    offset = ((u**2).sum(1)[:, None] * np.cross(v, w) + (v**2).sum(1)[:, None] * np.cross(w, u)
              + (w**2).sum(1)[:, None] * np.cross(u, v)) / (2 * det[:, None])
    radius = np.sqrt((offset**2).sum(1))
    shortest = np.sqrt((_edges_of(p) ** 2).sum(2).min(1))
    return radius / shortest


def dihedral_angles(points: np.ndarray, tetrahedra: np.ndarray) -> np.ndarray:
    """The six interior dihedral angles of each tetrahedron, in degrees, shape (m, 6)."""
    p = np.asarray(points, dtype=np.float64)[np.asarray(tetrahedra)]
    out = np.empty((len(p), 6))
    pairs = [(0, 1, 2, 3), (0, 2, 1, 3), (0, 3, 1, 2), (1, 2, 0, 3), (1, 3, 0, 2), (2, 3, 0, 1)]
    for k, (i, j, a, b) in enumerate(pairs):
        e = p[:, j] - p[:, i]
        n1 = np.cross(e, p[:, a] - p[:, i])
        n2 = np.cross(e, p[:, b] - p[:, i])
        cos = np.einsum("ij,ij->i", n1, n2) / np.sqrt((n1**2).sum(1) * (n2**2).sum(1))
        out[:, k] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return out


def _check_cells(points: np.ndarray, tetrahedra: np.ndarray) -> None:
    n = len(points)
    t = np.sort(tetrahedra, axis=1)
    repeated_vertex = (t[:, 1:] == t[:, :-1]).any(axis=1)
    if repeated_vertex.any():
        raise ValueError(f"tetrahedron {int(np.argmax(repeated_vertex))} repeats a vertex (it is flat)")
    order, group = _row_keys(t)
    repeated = np.bincount(group) > 1
    if repeated.any():
        raise ValueError(f"tetrahedron {int(np.flatnonzero(group == np.argmax(repeated))[0])} appears more than once")
    used = np.bincount(tetrahedra.ravel(), minlength=n)
    if (used == 0).any():
        raise ValueError(f"point {int(np.argmax(used == 0))} is not used by any tetrahedron (orphan point)")
    sign = _core.tet_orientations(points, tetrahedra)
    if (sign < 0).any():
        raise ValueError(f"tetrahedron {int(np.argmax(sign < 0))} is inverted (negative volume): list its vertices "
                         "so that the fourth sees the first three counter-clockwise")
    if (sign == 0).any():
        raise ValueError(f"tetrahedron {int(np.argmax(sign == 0))} is flat (zero volume)")
    longest = np.sqrt((_edges_of(points[tetrahedra]) ** 2).sum(2).max(1))
    relative = tet_volumes(points, tetrahedra) / longest**3
    if (relative < _MIN_RELATIVE_VOLUME).any():
        k = int(np.argmin(relative))
        raise ValueError(f"tetrahedron {k} is nearly flat: its volume is {relative[k]:.1e} of its longest edge cubed "
                         f"(at least {_MIN_RELATIVE_VOLUME:g} is needed)")


class TetMesh:
    """An immutable tetrahedral mesh.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        Coordinates (finite).
    tetrahedra : array_like of int, shape (m, 4)
        Vertex indices, positively oriented (the fourth vertex sees the first
        three counter-clockwise: positive volume).
    faces : array_like of int, shape (k, 3), optional
        Tagged triangles: every boundary triangle of the mesh must be among
        them, in either orientation (default: the boundary triangles, oriented
        outward).
    face_tags : array_like of int, shape (k,), optional
        One tag per row of ``faces`` (default 0).
    tet_tags : array_like of int, shape (m,), optional
        One region tag per tetrahedron (default 0).
    required : array_like of bool, shape (n,), optional
        Points every step keeps.

    Attributes
    ----------
    points, tetrahedra, faces, face_tags, tet_tags, required : ndarray (read-only)
    kind : ndarray of uint8, shape (n,)
        :class:`TetPointKind` of each point (box strata on an axis-aligned box).
    origin : ndarray of int64, shape (n,)
        Index of each point in the mesh a step came from (-1: new).
    lineage : TetLineage or None
        Set by :func:`evomesh.evolve`.
    stats : Mapping[str, float]

    Raises
    ------
    TypeError
        Non-numeric points or non-integer indices, tags or a non-boolean mask.
    ValueError
        Wrong shapes, NaN or infinite coordinates, indices out of range,
        inverted, flat or nearly flat tetrahedra (volume below 1e-10 of the
        longest edge cubed), repeated tetrahedra, duplicate or orphan points,
        a triangle shared by more than two tetrahedra or two tetrahedra on the
        same side of one, faces that are not triangles of the mesh or that
        miss a boundary triangle.
    The caller's arrays are never modified.
    """

    __slots__ = ("points", "tetrahedra", "faces", "face_tags", "tet_tags", "required", "kind", "origin", "lineage",
                 "stats", "_nn", "_boundary")

    points: np.ndarray
    tetrahedra: np.ndarray
    faces: np.ndarray
    face_tags: np.ndarray
    tet_tags: np.ndarray
    required: np.ndarray
    kind: np.ndarray
    origin: np.ndarray
    lineage: TetLineage | None
    stats: Mapping[str, float]
    _nn: np.ndarray | None
    _boundary: tuple[np.ndarray, np.ndarray] | None

    def __init__(self, points: Any, tetrahedra: Any, faces: Any = None, *, face_tags: Any = None,
                 tet_tags: Any = None, required: Any = None):
        pts = _as_points3(points)
        n = len(pts)
        if n < 4:
            raise ValueError(f"a tetrahedral mesh needs at least 4 points, got {n}")
        tets = _as_indices(tetrahedra, 4, "tetrahedra", n)
        if len(tets) == 0:
            raise ValueError("a tetrahedral mesh needs at least one tetrahedron")
        tet_t = None if tet_tags is None else _as_tags(tet_tags, len(tets), "tet_tags", "tetrahedra")
        req = None if required is None else _as_mask(required, n)
        _check_cells(pts, tets)
        nn = _core.tet_nn_spacing(pts)  # raises on duplicate points
        bnd, bnd_tet = boundary_faces(tets)
        if faces is None:
            if face_tags is not None:
                raise ValueError("face_tags need faces: one tag per row of faces")
            fcs, f_tags = bnd, None
        else:
            fcs = _as_indices(faces, 3, "faces", n)
            f_tags = None if face_tags is None else _as_tags(face_tags, len(fcs), "face_tags", "faces")
            _check_faces(tets, fcs, bnd)
        self._assign(pts, tets, fcs, f_tags, tet_t, req, None, None, None, {}, nn, (bnd, bnd_tet))

    def _assign(self, points, tetrahedra, faces, face_tags, tet_tags, required, kind, origin, lineage, stats,
                nn=None, boundary=None) -> None:
        set_ = object.__setattr__
        n, m = len(points), len(tetrahedra)
        set_(self, "points", _frozen(np.asarray(points, dtype=np.float64)))
        set_(self, "tetrahedra", _frozen(np.asarray(tetrahedra, dtype=np.int64)))
        set_(self, "faces", _frozen(np.asarray(faces, dtype=np.int64).reshape(-1, 3)))
        k = len(self.faces)
        set_(self, "face_tags", _frozen_constant(k, 0, np.int64) if face_tags is None
             else _frozen(np.asarray(face_tags, dtype=np.int64)))
        set_(self, "tet_tags", _frozen_constant(m, 0, np.int64) if tet_tags is None
             else _frozen(np.asarray(tet_tags, dtype=np.int64)))
        set_(self, "required", _frozen_constant(n, False, bool) if required is None
             else _frozen(np.asarray(required, dtype=bool)))
        set_(self, "_boundary", None if boundary is None else tuple(_frozen(a) for a in boundary))
        if kind is None:
            kind = _box_kinds(self.points, self.boundary_faces[0])
        set_(self, "kind", _frozen(np.asarray(kind, dtype=np.uint8)))
        set_(self, "origin", _frozen_constant(n, -1, np.int64) if origin is None
             else _frozen(np.asarray(origin, dtype=np.int64)))
        set_(self, "lineage", lineage)
        set_(self, "stats", MappingProxyType(dict(stats)))
        set_(self, "_nn", None if nn is None else _frozen(np.asarray(nn, dtype=np.float64)))

    @classmethod
    def _trusted(cls, points, tetrahedra, faces, face_tags=None, tet_tags=None, required=None, kind=None,
                 origin=None, lineage=None, stats=None, boundary=None) -> TetMesh:
        """Wrap arrays that evomesh itself produced (already valid); no checks."""
        mesh = cls.__new__(cls)
        mesh._assign(points, tetrahedra, faces, face_tags, tet_tags, required, kind, origin, lineage, stats or {},
                     None, boundary)
        return mesh

    @property
    def n_points(self) -> int:
        return len(self.points)

    @property
    def n_tetrahedra(self) -> int:
        return len(self.tetrahedra)

    @property
    def boundary_faces(self) -> tuple[np.ndarray, np.ndarray]:
        """The boundary triangles (outward) and the tetrahedron of each."""
        if self._boundary is None:
            object.__setattr__(self, "_boundary", tuple(_frozen(a) for a in boundary_faces(self.tetrahedra)))
        assert self._boundary is not None
        return self._boundary[0], self._boundary[1]

    @property
    def nn_spacing(self) -> np.ndarray:
        """Distance from each point to its nearest other point, shape (n,)."""
        if self._nn is None:
            object.__setattr__(self, "_nn", _frozen(_core.tet_nn_spacing(self.points)))
        assert self._nn is not None
        return self._nn

    @property
    def volumes(self) -> np.ndarray:
        return tet_volumes(self.points, self.tetrahedra)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("TetMesh is immutable; evolve() returns a new mesh")

    def __repr__(self) -> str:
        return f"TetMesh({self.n_points} points, {self.n_tetrahedra} tetrahedra, {len(self.faces)} faces)"


def _check_faces(tetrahedra: np.ndarray, faces: np.ndarray, boundary: np.ndarray) -> None:
    all_faces = np.sort(tetrahedra[:, _OUTWARD_FACES].reshape(-1, 3), axis=1)
    given = np.sort(faces, axis=1)
    _, group = _row_keys(np.concatenate([all_faces, given, np.sort(boundary, axis=1)]))
    n_all, n_given = len(all_faces), len(given)
    in_mesh = np.zeros(group.max() + 1, bool)
    in_mesh[group[:n_all]] = True
    given_group = group[n_all:n_all + n_given]
    if not in_mesh[given_group].all():
        raise ValueError(f"face {int(np.argmin(in_mesh[given_group]))} is not a triangle of the mesh")
    if len(np.unique(given_group)) != n_given:
        raise ValueError("faces contain the same triangle twice")
    listed = np.zeros(group.max() + 1, bool)
    listed[given_group] = True
    missing = ~listed[group[n_all + n_given:]]
    if missing.any():
        raise ValueError(f"faces must include every boundary triangle; {boundary[int(np.argmax(missing))].tolist()} "
                         "is missing")


def _box_kinds(points: np.ndarray, boundary: np.ndarray) -> np.ndarray:
    """CORNER/EDGE/FACE for boundary points by how many planes of the bounding
    box they lie on (a point on a boundary triangle off those planes: FACE),
    ORIGINAL inside."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    planes = ((points == lo) | (points == hi)).sum(axis=1)
    kind = np.full(len(points), TetPointKind.ORIGINAL, np.uint8)
    on_boundary = np.zeros(len(points), bool)
    on_boundary[boundary.ravel()] = True
    kind[on_boundary] = TetPointKind.FACE
    kind[on_boundary & (planes == 2)] = TetPointKind.EDGE
    kind[on_boundary & (planes == 3)] = TetPointKind.CORNER
    return kind


def _kuhn_tetrahedra(shape: tuple[int, int, int]) -> np.ndarray:
    """The Kuhn (Freudenthal) subdivision of a grid of nx * ny * nz cubes into
    6 tetrahedra each, positively oriented; vertex (i, j, k) has index
    (i * (ny + 1) + j) * (nz + 1) + k."""
    nx, ny, nz = shape
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    base = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)

    def index(c: np.ndarray) -> np.ndarray:
        return (c[:, 0] * (ny + 1) + c[:, 1]) * (nz + 1) + c[:, 2]

    eye = np.eye(3, dtype=np.int64)
    tets = []
    for perm, parity in (((0, 1, 2), 1), ((1, 2, 0), 1), ((2, 0, 1), 1), ((0, 2, 1), -1), ((2, 1, 0), -1),
                         ((1, 0, 2), -1)):
        c0 = base
        c1 = c0 + eye[perm[0]]
        c2 = c1 + eye[perm[1]]
        c3 = c2 + eye[perm[2]]
        cols = [index(c0), index(c1), index(c2), index(c3)]
        if parity < 0:
            cols[2], cols[3] = cols[3], cols[2]
        tets.append(np.stack(cols, axis=1))
    return np.concatenate(tets)


def box_mesh(lower: Sequence[float] = (0.0, 0.0, 0.0), upper: Sequence[float] = (1.0, 1.0, 1.0),
             n: int | Sequence[int] = 4) -> TetMesh:
    """A Kuhn tetrahedral mesh of the box [lower, upper] with n cells per side
    (or (nx, ny, nz)); the box's faces are exact (coordinates equal to the bounds)."""
    lo = np.asarray(lower, dtype=np.float64)
    hi = np.asarray(upper, dtype=np.float64)
    if lo.shape != (3,) or hi.shape != (3,) or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise ValueError("lower and upper must be three finite coordinates")
    if not (hi > lo).all():
        raise ValueError("upper must exceed lower on every axis")
    counts = np.broadcast_to(np.asarray(n), (3,))
    if counts.dtype.kind not in "iu":
        raise TypeError("n must be an integer or three integers")
    if (counts < 1).any():
        raise ValueError("n must be at least 1")
    axes = [np.linspace(lo[a], hi[a], int(counts[a]) + 1) for a in range(3)]
    x, y, z = np.meshgrid(*axes, indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    tets = _kuhn_tetrahedra((int(counts[0]), int(counts[1]), int(counts[2])))
    sign = _core.tet_orientations(points, tets)
    if (sign <= 0).any():
        raise ValueError("the box is too thin for float64 at this resolution")
    return TetMesh._trusted(points, tets, boundary_faces(tets)[0])


def unit_cube_mesh(n: int = 4) -> TetMesh:
    """A Kuhn tetrahedral mesh of the unit cube with n cells per side (6 n^3 tetrahedra)."""
    return box_mesh((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), n)
