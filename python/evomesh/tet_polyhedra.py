"""Tetrahedral meshes of convex polyhedra: of the hull of given corners, a
tilted box and a regular octahedron, each made by one step of
:func:`evomesh.evolve` from the Delaunay tetrahedra of its corners (so their
facets and edges hold points exactly, :mod:`evomesh.tet_domains`)."""

from __future__ import annotations

from fractions import Fraction
from typing import Any, Sequence

import numpy as np

from evomesh import _core
from evomesh.mesh import _as_points
from evomesh.tet_domains import _popcount, polyhedral_domain
from evomesh.tet_evolution import evolve_tet
from evomesh.tet_mesh import TetMesh, TetPointKind

__all__ = ["convex_polyhedron_mesh", "tilted_box_mesh", "octahedron_mesh"]


def convex_polyhedron_mesh(vertices: Any, size: float, *, seed: int = 0) -> TetMesh:
    """A tetrahedral mesh of the convex hull of ``vertices`` with edges about ``size`` long.

    Parameters
    ----------
    vertices : array_like, shape (k, 3)
        The polyhedron's corners (every one a corner of their hull). Tilted
        facets need corners with few significant bits (multiples of a power
        of two, say) so that points exactly on them exist in float64.
    size : float
        Target edge length (as ``evolve(..., size=size)``).
    seed : int

    Returns
    -------
    TetMesh
        Its boundary triangles cover each facet exactly (their points lie on
        the facet's plane exactly); kinds CORNER, EDGE, FACE, ORIGINAL.

    Raises
    ------
    ValueError
        Non-finite or flat input, a vertex inside the hull or on a facet of
        the others, facets meeting below 90 degrees, facets whose corners
        leave no exact lattice.
    """
    corners = _as_points(vertices, 3)
    if len(corners) < 4:
        raise ValueError(f"a polyhedron needs at least 4 vertices, got {len(corners)}")
    size = _positive_number(size, "size")
    if len(np.unique(corners, axis=0)) != len(corners):
        raise ValueError("vertices contain duplicates")
    tets = _core.delaunay_tetrahedra(corners)
    if len(tets) == 0:
        raise ValueError("the vertices are coplanar: they span no volume")
    used = np.bincount(tets.ravel(), minlength=len(corners)) > 0
    if not used.all():
        raise ValueError(f"vertex {int(np.argmin(used))} {_NOT_A_CORNER}")
    try:
        coarse = TetMesh(corners, tets)
    except ValueError as error:
        if "flat" not in str(error):
            raise
        raise ValueError("four vertices are nearly but not exactly coplanar in float64 (their hull has a nearly flat "
                         "tetrahedron): give each facet's vertices exactly coplanar coordinates with few significant "
                         "bits (multiples of a power of two)") from error
    domain = polyhedral_domain(coarse)
    if (_popcount(domain.point_facets) < 3).any():
        k = int(np.argmax(_popcount(domain.point_facets) < 3))
        raise ValueError(f"vertex {k} {_NOT_A_CORNER}")
    mesh = evolve_tet(coarse, size=size, seed=seed)
    kind = np.where(mesh.kind >= TetPointKind.STEINER, TetPointKind.ORIGINAL, mesh.kind).astype(np.uint8)
    return TetMesh._trusted(mesh.points, mesh.tetrahedra, mesh.faces, kind=kind, boundary=mesh.boundary_faces)


_NOT_A_CORNER = "is not a corner of the hull (it lies inside it, or on one of its edges or facets)"


def _positive_number(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a number, got {type(value).__name__}")
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite positive number, got {value!r}")
    return float(value)


def _quaternion_matrix(q: Sequence[int]) -> np.ndarray:
    """|q|^2 times the rotation of the quaternion q = (a, b, c, d): an integer matrix."""
    a, b, c, d = (int(x) for x in q)
    return np.array([[a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)],
                     [2 * (b * c + a * d), a * a - b * b + c * c - d * d, 2 * (c * d - a * b)],
                     [2 * (b * d - a * c), 2 * (c * d + a * b), a * a - b * b - c * c + d * d]], dtype=np.int64)


def tilted_box_mesh(size: float, lengths: Sequence[float] = (1.0, 0.75, 0.5), *,
                    rotation: Sequence[int] = (7, 3, 2, 1), origin: Sequence[float] = (0.0, 0.0, 0.0),
                    seed: int = 0) -> TetMesh:
    """A tetrahedral mesh of a rectangular box in general position.

    The box [0, a] x [0, b] x [0, c] (``lengths``) is rotated by the integer
    quaternion ``rotation`` = q and scaled by |q|^2 / 2^k (2^k the power of
    two at or above |q|^2; 63/64 for the default, a rotation by 56 degrees
    about (3, 2, 1)), then moved to ``origin``: the matrix's entries are
    multiples of 2^-k, so with dyadic lengths (1, 0.75, 0.1875, ...) every
    corner is exact and the faces planar in float64. ``size``: target edge
    length. ValueError when the corners are not exact (lengths with too many
    significant bits, like 0.1).
    """
    q = np.asarray(rotation)
    if q.shape != (4,) or q.dtype.kind not in "iu" or not q.any():
        raise ValueError("rotation must be four integers, not all zero (a quaternion)")
    sides = np.asarray(lengths, dtype=np.float64)
    if sides.shape != (3,) or not (np.isfinite(sides).all() and (sides > 0).all()):
        raise ValueError("lengths must be three finite positive numbers")
    quaternion = [int(v) for v in q]
    norm = sum(v * v for v in quaternion)
    bits = int(np.ceil(np.log2(norm)))
    integer = _quaternion_matrix(quaternion)
    matrix = integer.astype(np.float64) * 2.0**-bits
    cube = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.float64) * sides
    # Each corner a sum of three exact products; checked exact below (rational arithmetic).
    shift = np.asarray(origin, dtype=np.float64)
    if shift.shape != (3,) or not np.isfinite(shift).all():
        raise ValueError("origin must be three finite coordinates")
    corners = cube @ matrix.T + shift
    for corner, base in zip(corners, cube):
        for i in range(3):
            exact = sum((Fraction(int(integer[i, j])) * Fraction(float(base[j])) for j in range(3)), Fraction(0))
            if Fraction(float(corner[i])) != exact / 2**bits + Fraction(float(shift[i])):
                raise ValueError("the tilted box's corners are not exact in float64: give lengths and origin with "
                                 "fewer significant bits (multiples of a power of two)")
    return convex_polyhedron_mesh(corners, size, seed=seed)


def octahedron_mesh(size: float, radius: float = 1.0, *, centre: Sequence[float] = (0.0, 0.0, 0.0),
                    seed: int = 0) -> TetMesh:
    """A tetrahedral mesh of the regular octahedron with vertices centre +- radius e_i
    (dyadic radius and centre keep its tilted facets exact); ``size``: target edge length."""
    c = np.asarray(centre, dtype=np.float64)
    if c.shape != (3,) or not np.isfinite(c).all():
        raise ValueError("centre must be three finite coordinates")
    eye = np.eye(3) * _positive_number(radius, "radius")
    return convex_polyhedron_mesh(np.concatenate([c + eye, c - eye]), size, seed=seed)
