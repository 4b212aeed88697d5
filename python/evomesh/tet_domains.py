"""Convex polyhedral domains of tetrahedral meshes: the facets, edges and
corners that a mesh's boundary makes (what :func:`evomesh.evolve` keeps), and
meshes of a convex polyhedron, a tilted box and a regular octahedron.

A facet is a maximal set of boundary triangles joined across edges whose
four points are exactly coplanar (CGAL's exact orientation); an edge is where
two facets meet, a corner a point on three facets or more. The step keeps
every point it makes on a facet or an edge exactly on it: facets normal to a
coordinate axis hold any coordinates, other facets a float64 lattice spanned
by three of their corners (so their corners need few significant bits:
multiples of a power of two, as the constructors here make them).
"""

from __future__ import annotations

import dataclasses
from fractions import Fraction
from typing import Any, Sequence

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from evomesh import _core
from evomesh.tet_mesh import TetMesh, TetPointKind, _as_points3, _row_keys

__all__ = ["PolyhedralDomain", "polyhedral_domain", "convex_polyhedron_mesh", "tilted_box_mesh", "octahedron_mesh"]

# Below this interior angle (degrees) between two facets the step has no
# guarantee (sharp edges need protecting balls): refused.
MIN_FACET_ANGLE = 90.0


@dataclasses.dataclass(frozen=True)
class PolyhedralDomain:
    """The convex polyhedron a tetrahedral mesh fills.

    Attributes
    ----------
    facets : ndarray, shape (F, 3, 3)
        Three corners of each facet, seen clockwise from inside.
    edge_facets : ndarray of int64, shape (E, 2)
        The two facets of each edge.
    edge_ends : ndarray, shape (E, 2, 3)
        The end corners of each edge.
    neighbours : ndarray of int64, shape (F,)
        Bit mask of the facets sharing a corner with each facet.
    triangle_facet : ndarray of int64, shape (k,)
        The facet of each of the mesh's boundary triangles
        (``mesh.boundary_faces``).
    point_facets : ndarray of int64, shape (n,)
        Bit mask of the facets each mesh point lies on.
    """

    facets: np.ndarray
    edge_facets: np.ndarray
    edge_ends: np.ndarray
    neighbours: np.ndarray
    triangle_facet: np.ndarray
    point_facets: np.ndarray

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(facets, edge_facets, edge_ends, neighbours): what the core takes."""
        return self.facets, self.edge_facets, self.edge_ends, self.neighbours

    def kinds(self) -> np.ndarray:
        """CORNER, EDGE or FACE by the number of facets each point lies on, ORIGINAL inside."""
        count = _popcount(self.point_facets)
        kind = np.full(len(count), TetPointKind.ORIGINAL, np.uint8)
        kind[count == 1] = TetPointKind.FACE
        kind[count == 2] = TetPointKind.EDGE
        kind[count >= 3] = TetPointKind.CORNER
        return kind


def _popcount(masks: np.ndarray) -> np.ndarray:
    bits = (masks[:, None] >> np.arange(64, dtype=np.int64)[None, :]) & 1
    return bits.sum(axis=1)


def _quads_orientation(quads: np.ndarray) -> np.ndarray:
    """Exact orientation sign of each (a, b, c, d), quads of shape (k, 4, 3)."""
    if len(quads) == 0:
        return np.zeros(0, np.int8)
    points = quads.reshape(-1, 3)
    return _core.tet_orientations(points, np.arange(len(points)).reshape(-1, 4))


def polyhedral_domain(mesh: TetMesh) -> PolyhedralDomain:
    """The convex polyhedron whose tetrahedral mesh ``mesh`` is.

    Raises
    ------
    ValueError
        A boundary edge on other than two boundary triangles (a non-manifold
        boundary), more than 64 facets, a domain that is not convex, two
        facets meeting at an interior angle below 90 degrees, or a tilted
        facet whose corners leave no float64 lattice exactly on its plane.
    """
    points = mesh.points
    faces, face_tet = mesh.boundary_faces
    k = len(faces)
    # Boundary edges and the two triangles at each.
    edge_rows = faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)
    triangle = np.repeat(np.arange(k), 3)
    far = faces[:, [2, 0, 1]].ravel()
    _, group = _row_keys(np.sort(edge_rows, axis=1))
    count = np.bincount(group)
    if (count != 2).any():
        g = int(np.argmax(count != 2))
        edge = np.sort(edge_rows[group == g][0]).tolist()
        raise ValueError(f"the boundary is not a closed surface: the edge {edge} is on {count[g]} boundary triangles "
                         "(two needed; a non-manifold boundary)")
    order = np.argsort(group, kind="stable")
    first, second = order[0::2], order[1::2]
    t1, t2 = triangle[first], triangle[second]
    coplanar = _quads_orientation(np.concatenate([points[faces[t1]], points[far[second]][:, None]], axis=1)) == 0
    graph = coo_matrix((np.ones(int(coplanar.sum())), (t1[coplanar], t2[coplanar])), shape=(k, k))
    n_facets, label = connected_components(graph, directed=False)
    if n_facets > 64:
        raise ValueError(f"the domain has {n_facets} planar facets; at most 64 are supported")
    # The facets at each point (a conforming boundary: a point on a facet is a
    # vertex of that facet's triangles).
    point_facets = np.zeros(len(points), np.int64)
    np.bitwise_or.at(point_facets, faces.ravel(), np.repeat(np.left_shift(1, label), 3))
    corners = np.flatnonzero(_popcount(point_facets) >= 3)
    corner_facets = point_facets[corners]
    # Three corners of each facet, chosen by their coordinates: the first
    # (lexicographically), the farthest from it, the one spanning the largest
    # triangle with those two.
    facets = np.empty((n_facets, 3, 3))
    for f in range(n_facets):
        own = corners[(corner_facets >> f) & 1 == 1]
        if len(own) < 3:
            raise ValueError(f"facet {f} has {len(own)} corners (three or more needed)")
        c = points[own][np.lexsort(points[own].T[::-1])]
        a = c[0]
        b = c[int(np.argmax(((c - a) ** 2).sum(axis=1)))]
        third = c[int(np.argmax((np.cross(b - a, c - a) ** 2).sum(axis=1)))]
        facets[f] = a, b, third
    # Outward: a point inside (the fourth vertex of a tetrahedron on the
    # facet) sees them clockwise.
    some = np.unique(label, return_index=True)[1]
    inside = points[mesh.tetrahedra[face_tet[some]].sum(axis=1) - faces[some].sum(axis=1)]
    flip = _quads_orientation(np.concatenate([facets, inside[:, None]], axis=1)) > 0
    facets[flip] = facets[flip][:, [0, 2, 1]]
    # A canonical facet order, by geometry only (the same facets get the same
    # numbers step after step): normal to an axis first, by (axis, plane
    # coordinate); then by their three corners.
    aligned = (facets == facets[:, :1]).all(axis=1)  # (F, 3)
    axis = np.where(aligned.any(axis=1), np.argmax(aligned, axis=1), 3)
    value = np.where(axis < 3, facets[np.arange(n_facets), 0, np.minimum(axis, 2)], 0.0)
    by = np.lexsort(tuple(facets.reshape(n_facets, 9).T[::-1]) + (value, axis))
    rank = np.empty(n_facets, np.int64)
    rank[by] = np.arange(n_facets)
    label = rank[label]
    facets = facets[by]
    point_facets = np.zeros(len(points), np.int64)
    np.bitwise_or.at(point_facets, faces.ravel(), np.repeat(np.left_shift(1, label), 3))
    corner_facets = point_facets[corners]
    # Interior angles at every boundary edge between two facets: reflex
    # where the second triangle's far vertex lies outside the first's plane.
    normal = np.cross(facets[:, 1] - facets[:, 0], facets[:, 2] - facets[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    between = label[t1] != label[t2]
    f1, f2 = label[t1[between]], label[t2[between]]
    reflex = _quads_orientation(np.concatenate([facets[f1], points[far[second[between]]][:, None]], axis=1)) > 0
    turn = np.degrees(np.arccos(np.clip((normal[f1] * normal[f2]).sum(axis=1), -1.0, 1.0)))
    angle = np.where(reflex, 180.0 + turn, 180.0 - turn)
    if (angle < MIN_FACET_ANGLE - 1e-9).any():
        e = int(np.argmin(angle))
        p = points[edge_rows[first[between]][e]]
        raise ValueError(f"facets {f1[e]} and {f2[e]} meet at {angle[e]:.3g} degrees along the edge through "
                         f"{p[0].tolist()} and {p[1].tolist()}: angles below {MIN_FACET_ANGLE:g} degrees are not "
                         "supported (they need protecting balls)")
    # Convex: no reflex edge, every corner on the inner side of every facet's plane.
    quads = np.concatenate([np.repeat(facets, len(corners), axis=0),
                            np.tile(points[corners], (n_facets, 1))[:, None]], axis=1)
    outside = _quads_orientation(quads).reshape(n_facets, len(corners)) > 0
    if reflex.any() or outside.any():
        where = (f"a reflex edge between facets {f1[np.argmax(reflex)]} and {f2[np.argmax(reflex)]}" if reflex.any()
                 else f"corner {points[corners[np.argwhere(outside)[0][1]]].tolist()} outside a facet's plane")
        raise ValueError(f"evolve on a TetMesh supports convex polyhedra only; this domain is not convex ({where}): "
                         "non-convex polyhedra (an L-shaped block, a box with a hole) need conforming boundary "
                         "recovery, which is not implemented yet")
    neighbours = np.zeros(n_facets, np.int64)
    for f in range(n_facets):
        at = (corner_facets >> f) & 1 == 1
        neighbours[f] = np.bitwise_or.reduce(corner_facets[at]) if at.any() else 0
    # Edges: the facet pairs that meet across a boundary edge, between two
    # corners (a convex polyhedron's facets meet along one segment at most).
    pairs = np.unique(np.sort(np.stack([f1, f2], axis=1), axis=1), axis=0)
    ends = np.empty((len(pairs), 2, 3))
    for e, (f, g) in enumerate(pairs):
        at = corners[((corner_facets >> f) & 1 == 1) & ((corner_facets >> g) & 1 == 1)]
        if len(at) != 2:
            raise RuntimeError(f"facets {f} and {g} of a convex polyhedron meet at {len(at)} corners")  # a bug
        p = points[at]
        direction = np.argmax(np.abs(p[1] - p[0]))
        ends[e] = p if p[0, direction] < p[1, direction] else p[::-1]
    # Edge order: along an axis first, by (axis, coordinates across it), then by facets.
    direction = np.argmax(np.abs(ends[:, 1] - ends[:, 0]), axis=1)
    d = ends[:, 1] - ends[:, 0]
    edge_aligned = (np.sum(d != 0, axis=1) == 1)
    edge_axis = np.where(edge_aligned, direction, 3)
    start = ends[:, 0]
    u = start[np.arange(len(ends)), (direction + 1) % 3]
    v = start[np.arange(len(ends)), (direction + 2) % 3]
    edge_order = np.lexsort((pairs[:, 1], pairs[:, 0], np.where(edge_aligned, u, 0.0), np.where(edge_aligned, v, 0.0),
                             edge_axis))
    domain = PolyhedralDomain(facets, pairs[edge_order].astype(np.int64), ends[edge_order], neighbours, label,
                              point_facets)
    # The core checks every tilted facet's lattice (ValueError when there is
    # none) and agrees on the corners' facets.
    exact = _core.tet_domain_incidences(points[corners], *domain.arrays)
    if not np.array_equal(exact, corner_facets):
        raise ValueError("the boundary's facets are not planar in float64 at the corners (a corner lies on a facet's "
                         "plane without being one of its corners)")
    return domain


def facet_tags(mesh: TetMesh, domain: PolyhedralDomain) -> np.ndarray | None:
    """The face tag of each facet (None: no face tags); ValueError when the tags vary within a facet."""
    if not mesh.face_tags.any():
        if len(mesh.faces) != len(mesh.boundary_faces[0]):
            raise ValueError("evolve on a TetMesh does not support interior faces yet")
        return None
    boundary = np.sort(mesh.boundary_faces[0], axis=1)
    given = np.sort(mesh.faces, axis=1)
    _, group = _row_keys(np.concatenate([boundary, given]))
    facet_of_group = np.full(group.max() + 1, -1)
    facet_of_group[group[:len(boundary)]] = domain.triangle_facet
    facet = facet_of_group[group[len(boundary):]]
    if (facet < 0).any():
        raise ValueError("evolve on a TetMesh does not support tagged interior faces yet")
    n_facets = len(domain.facets)
    tags = np.zeros(n_facets, np.int64)
    for f in range(n_facets):
        values = np.unique(mesh.face_tags[facet == f])
        if len(values) > 1:
            raise ValueError(f"face tags vary within facet {f}: not supported yet (one tag per facet)")
        if len(values):
            tags[f] = values[0]
    return tags


def triangle_facets(point_facets: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The facet of each boundary triangle from its points' facet masks."""
    common = np.bitwise_and.reduce(point_facets[faces], axis=1)
    if (common == 0).any() or (common & (common - 1)).any():
        raise RuntimeError("a boundary triangle is not on exactly one facet")  # a bug, never input
    return np.log2(common.astype(np.float64)).astype(np.int64)


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
    from evomesh.tet_evolution import evolve_tet

    corners = _as_points3(vertices)
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
