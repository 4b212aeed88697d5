"""The immutable tetrahedral mesh that evomesh evolves in 3-D, its generators
and its quality measures."""

from __future__ import annotations

import warnings
from enum import IntEnum
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

from evomesh import _core
from evomesh.mesh import (
    _as_indices,
    _as_mask,
    _as_points,
    _as_tag_names,
    _as_tags,
    _frozen,
    _frozen_constant,
    _ImmutableMesh,
    _integral_values,
    _names_from_field_data,
    _tagged_meshio,
)

__all__ = ["TetMesh", "TetPointKind", "TetLineage", "unit_cube_mesh", "box_mesh", "radius_edge_ratios",
           "dihedral_angles"]

#: The dimensions a tetrahedral mesh's tag names refer to.
TET_MESH_TAG_DIMS = {2: "face", 3: "tetrahedron"}
#: Cell data that hold tags in files, in the order they are looked for.
_TAG_CELL_DATA = ("gmsh:physical", "medit:ref", "tag", "tags")
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

    def __reduce__(self):
        return (TetLineage, (self.n_old_points, self.n_old_tetrahedra, self.parent_tet))


def _row_keys(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted rows of equal keys together: (order, inverse key index) where
    equal rows of ``rows`` get the same group number (numbers in sorted order)."""
    if len(rows) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    new_group = np.ones(len(rows), bool)
    low, span = int(rows.min()), int(rows.max()) - int(rows.min()) + 1
    if span ** rows.shape[1] < 2**62:
        # One int64 key per row, in the rows' lexicographic order: a stable
        # argsort of it is the lexsort's order, several times faster.
        key = np.zeros(len(rows), np.int64)
        for column in rows.T:
            key = key * span + (column.astype(np.int64) - low)
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        new_group[1:] = sorted_key[1:] != sorted_key[:-1]
    else:
        order = np.lexsort(rows.T[::-1])
        sorted_rows = rows[order]
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


class TetMesh(_ImmutableMesh):
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
    tag_names : mapping of (int, int) to str, optional
        Names of tags: ``(2, tag)`` a face tag, ``(3, tag)`` a tetrahedron
        (region) tag, as Gmsh's physical names; kept by every step and by
        Gmsh and VTU files.

    Attributes
    ----------
    points, tetrahedra, faces, face_tags, tet_tags, required : ndarray (read-only)
    tag_names : Mapping[tuple[int, int], str]
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
                 "stats", "tag_names", "_nn", "_boundary")

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
    tag_names: Mapping[tuple[int, int], str]
    _nn: np.ndarray | None
    _boundary: tuple[np.ndarray, np.ndarray] | None

    def __init__(self, points: Any, tetrahedra: Any, faces: Any = None, *, face_tags: Any = None,
                 tet_tags: Any = None, required: Any = None, tag_names: Any = None):
        pts = _as_points(points, 3)
        n = len(pts)
        if n < 4:
            raise ValueError(f"a tetrahedral mesh needs at least 4 points, got {n}")
        tets = _as_indices(tetrahedra, 4, "tetrahedra", n)
        if len(tets) == 0:
            raise ValueError("a tetrahedral mesh needs at least one tetrahedron")
        tet_t = None if tet_tags is None else _as_tags(tet_tags, len(tets), "tet_tags", "tetrahedra")
        req = None if required is None else _as_mask(required, n)
        names = _as_tag_names(tag_names, TET_MESH_TAG_DIMS)
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
        self._assign(pts, tets, fcs, f_tags, tet_t, req, None, None, None, {}, nn, (bnd, bnd_tet), names)

    def _assign(self, points, tetrahedra, faces, face_tags, tet_tags, required, kind, origin, lineage, stats,
                nn=None, boundary=None, tag_names=None) -> None:
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
        set_(self, "tag_names", MappingProxyType(dict(tag_names or {})))
        set_(self, "_nn", None if nn is None else _frozen(np.asarray(nn, dtype=np.float64)))

    @classmethod
    def _trusted(cls, points, tetrahedra, faces, face_tags=None, tet_tags=None, required=None, kind=None,
                 origin=None, lineage=None, stats=None, boundary=None, tag_names=None, nn=None) -> TetMesh:
        """Wrap arrays that evomesh itself produced (already valid); no checks."""
        mesh = cls.__new__(cls)
        mesh._assign(points, tetrahedra, faces, face_tags, tet_tags, required, kind, origin, lineage, stats or {},
                     nn, boundary, tag_names)
        return mesh

    def __reduce__(self):
        # Pickle and deepcopy keep every array bit for bit (checkpoints).
        return (_unpickle_tet_mesh, (self.points, self.tetrahedra, self.faces, self.face_tags, self.tet_tags,
                                     self.required, self.kind, self.origin, self.lineage, dict(self.stats),
                                     dict(self.tag_names), self._nn))

    def __deepcopy__(self, memo: dict) -> TetMesh:
        return _unpickle_tet_mesh(*self.__reduce__()[1])

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

    def to_meshio(self) -> Any:
        """A ``meshio.Mesh`` that Gmsh and VTU files hold with its tags: a
        "tetra" and a "triangle" block per tag (increasing), tags as cell data
        ``gmsh:physical``, ``tag_names`` as ``field_data`` (name -> [tag,
        dim]), point data ``kind``, ``origin`` and ``required``.
        :func:`evomesh.io.write_mesh` writes one block per cell type in the
        mesh's order instead (tags per cell)."""
        return self._to_meshio(in_order=False)

    def _to_meshio(self, in_order: bool) -> Any:
        point_data = {"kind": np.array(self.kind, dtype=np.int32), "origin": np.array(self.origin),
                      "required": np.array(self.required, dtype=np.uint8)}
        return _tagged_meshio(np.array(self.points), [("tetra", 3, self.tetrahedra, self.tet_tags),
                                                      ("triangle", 2, self.faces, self.face_tags)], in_order,
                              point_data, self.tag_names)

    @classmethod
    def from_meshio(cls, m: Any, *, tags: str | None = None) -> TetMesh:
        """A TetMesh from a ``meshio.Mesh`` with "tetra" cells.

        Tetrahedron blocks are concatenated (in the file's order), triangle
        cells become ``faces``; boundary triangles the file does not list are
        added with tag 0 (a Medit or Gmsh file may list only the tagged ones).
        Tags come from the cell data ``tags`` (default: the first of
        ``gmsh:physical``, ``medit:ref``, ``tag``, ``tags``), tag names from
        Gmsh's physical names (``field_data``) of dimension 2 and 3, point data
        ``kind``, ``origin`` and ``required`` when present (integral floats
        accepted). Points used by no tetrahedron are removed with a warning;
        line and vertex cells are ignored; other cell types are refused
        (ValueError), as is anything :class:`TetMesh` refuses (inverted
        tetrahedra among them: the file's orientation is never changed).
        """
        return cls._from_meshio(m, tags)[0]

    @classmethod
    def _from_meshio(cls, m: Any, tags: str | None = None) -> tuple[TetMesh, np.ndarray]:
        """The TetMesh and the mask of the meshio points it kept."""
        points = np.asarray(m.points)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"a tetrahedral mesh needs points of shape (n, 3), got {points.shape}")
        if tags is None:
            tags = next((name for name in _TAG_CELL_DATA if name in m.cell_data), None)
        elif tags not in m.cell_data:
            raise ValueError(f"meshio mesh has no cell data {tags!r}; it has: {', '.join(m.cell_data) or 'none'}")
        cells: dict[str, list[np.ndarray]] = {"tetra": [], "triangle": []}
        cell_tags: dict[str, list[np.ndarray]] = {"tetra": [], "triangle": []}
        for k, block in enumerate(m.cells):
            if block.type in cells:
                cells[block.type].append(np.asarray(block.data))
                if tags is not None:
                    cell_tags[block.type].append(np.asarray(m.cell_data[tags][k]).reshape(-1))
            elif block.type not in ("vertex", "line"):
                raise ValueError(f"cells of type {block.type!r} are not supported: a TetMesh holds linear "
                                 "tetrahedra (and triangles as faces)")
        if not cells["tetra"]:
            raise ValueError("meshio mesh has no tetra cells")
        tets = np.concatenate(cells["tetra"]).astype(np.int64)
        faces = np.concatenate(cells["triangle"]).astype(np.int64) if cells["triangle"] else None
        tet_tags = face_tags = None
        if tags is not None:
            tet_tags = _integral_values(np.concatenate(cell_tags["tetra"]), tags, "cell data", "tetrahedron")
            if faces is not None:
                face_tags = _integral_values(np.concatenate(cell_tags["triangle"]), tags, "cell data", "triangle")
        data = {name: np.asarray(v) for name, v in m.point_data.items() if name in ("kind", "origin", "required")}
        used = np.zeros(len(points), dtype=bool)
        if tets.size and tets.min() >= 0 and tets.max() < len(points):
            used[tets.ravel()] = True
            if not used.all():
                if faces is not None and faces.size and (faces.min() < 0 or faces.max() >= len(points)
                                                         or not used[faces.ravel()].all()):
                    raise ValueError("a triangle cell uses a point that no tetrahedron uses")
                remap = np.cumsum(used) - 1
                warnings.warn(f"removed {int((~used).sum())} points used by no tetrahedron", UserWarning, stacklevel=3)
                points, tets = points[used], remap[tets]
                faces = None if faces is None else remap[faces]
                data = {name: v[used] for name, v in data.items()}
        if faces is not None:
            faces, face_tags = _with_boundary(tets, faces, face_tags)
        names = _names_from_field_data(getattr(m, "field_data", None) or {}, tuple(TET_MESH_TAG_DIMS)) \
            if tags == "gmsh:physical" else {}
        required = data.get("required")
        mesh = cls(points, tets, faces, face_tags=face_tags, tet_tags=tet_tags, tag_names=names,
                   required=None if required is None else _integral_values(required, "required").astype(bool))
        kind, origin = data.get("kind"), data.get("origin")
        if kind is None and origin is None:
            return mesh, used
        if kind is not None:
            kind = _integral_values(kind, "kind").reshape(-1)
            if len(kind) != mesh.n_points or kind.min() < 0 or kind.max() > max(TetPointKind):
                raise ValueError(f"point data 'kind' must hold one TetPointKind (0 to {int(max(TetPointKind))}) "
                                 "per point")
        if origin is not None:
            origin = _integral_values(origin, "origin").reshape(-1)
            if len(origin) != mesh.n_points:
                raise ValueError("point data 'origin' must hold one value per point")
        labelled = cls._trusted(mesh.points, mesh.tetrahedra, mesh.faces, mesh.face_tags, mesh.tet_tags,
                                mesh.required, mesh.kind if kind is None else kind, origin, None, None,
                                mesh.boundary_faces, mesh.tag_names, mesh._nn)
        return labelled, used

    def __repr__(self) -> str:
        return f"TetMesh({self.n_points} points, {self.n_tetrahedra} tetrahedra, {len(self.faces)} faces)"


def _unpickle_tet_mesh(points, tetrahedra, faces, face_tags, tet_tags, required, kind, origin, lineage, stats,
                       tag_names, nn) -> TetMesh:
    return TetMesh._trusted(points, tetrahedra, faces, face_tags, tet_tags, required, kind, origin, lineage, stats,
                            None, tag_names, nn)


def _with_boundary(tetrahedra: np.ndarray, faces: np.ndarray, face_tags: np.ndarray | None
                   ) -> tuple[np.ndarray, np.ndarray | None]:
    """faces (and tags) with the boundary triangles they miss added (tag 0)."""
    boundary, _ = boundary_faces(tetrahedra)
    _, group = _row_keys(np.sort(np.concatenate([faces, boundary]), axis=1))
    listed = np.zeros(group.max() + 1, bool)
    listed[group[:len(faces)]] = True
    missing = boundary[~listed[group[len(faces):]]]
    if len(missing) == 0:
        return faces, face_tags
    tags = np.zeros(len(faces), np.int64) if face_tags is None else np.asarray(face_tags, np.int64)
    return np.concatenate([faces, missing]), np.concatenate([tags, np.zeros(len(missing), np.int64)])


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
