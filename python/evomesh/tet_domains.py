"""Convex polyhedral domains of tetrahedral meshes: the facets, edges and
corners that a mesh's boundary makes (what :func:`evomesh.evolve` keeps;
:mod:`evomesh.tet_polyhedra` builds meshes of such domains).

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

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from evomesh import _core
from evomesh.tet_mesh import TetMesh, TetPointKind, _row_keys

__all__ = ["PolyhedralDomain", "polyhedral_domain", "facet_tags", "triangle_facets"]

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
