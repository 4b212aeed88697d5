"""Carry per-vertex fields from a mesh to the mesh evolved from it."""

from __future__ import annotations

from typing import Any, Callable, Literal, Mapping, NamedTuple, overload

import numpy as np
import scipy.sparse
import scipy.sparse.linalg
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from evomesh import _core
from evomesh.mesh import Mesh
from evomesh.spacing_function import _require_mesh
from evomesh.tet_evolution import transfer_tet
from evomesh.tet_mesh import TetMesh

__all__ = ["transfer", "transfer_cells", "domain_change", "DomainChange", "region_exchange", "RegionExchange",
           "Interpolation", "Supermesh", "TetSupermesh"]

# A new point that the core does not locate in the old mesh is accepted on the
# nearest old boundary edge if it lies within _outside_tolerance of it:
#  - rounding: evolve's points on boundary segments (a + t (b - a), projections,
#    midpoints) and the point-segment distance computed here each carry a few
#    roundings of a coordinate, i.e. a few eps * max|x| (absolute, not relative
#    to the extent: far from the origin one ulp of x is much more than eps times
#    the extent). _ROUNDING_ULPS of them is a margin of several times that.
#  - a boundary chain that runs straight up to _core.STRAIGHT_ULPS roundings
#    (the core's test for corners; FRFC projects its samples onto the line through
#    its end corners) may be replaced by a straight piece: the new boundary is
#    then off the old one by up to that many roundings.
_ROUNDING_ULPS = 16 + _core.STRAIGHT_ULPS
# Barycentric coordinates rebuild a point up to their own rounding, amplified in
# thin triangles: a lineage is accepted within this many outside tolerances.
_LINEAGE_SLACK = 1024.0


def _outside_tolerance(old: Mesh, queries: np.ndarray) -> float:
    """Largest distance from the old domain that is accepted as rounding (see above)."""
    magnitude = float(np.abs(old.points).max())
    if len(queries):
        magnitude = max(magnitude, float(np.abs(queries).max()))
    return _ROUNDING_ULPS * float(np.finfo(np.float64).eps) * magnitude


class Interpolation:
    """How each point of ``new`` takes its value from ``old``; reusable for many fields.

    Kept points (``new.origin >= 0``) copy the value at their origin exactly
    (after a step that moved the points, ``new.lineage.moved``, those still at
    their old coordinates); every other point interpolates linearly in the old
    triangle containing it:
    from ``new.lineage`` (the step's parent map, no search) when ``new`` was
    evolved from ``old``, else located by the C++ core (CGAL, O(log n) per point). Points that rounding put
    just outside the old domain interpolate on the nearest old boundary edge:
    "just" is a few ulps of the largest coordinate (_ROUNDING_ULPS eps max|x|, whatever
    the extent: a mesh far from the origin has coarser coordinates) plus the
    1e-12 relative slack with which evolve straightens boundary chains; a
    point farther out is an error, except after a move (``displacement=``),
    where the domain itself may move: a point outside the old domain then takes
    the linear extension of the old field from the old triangle of the nearest
    old boundary edge.

    Attributes
    ----------
    kept : ndarray of bool, shape (n_new,)
    origin : ndarray of int, shape (n_new,)
    vertices : ndarray of int, shape (n_located, 3)
        Old points whose values mix into each non-kept new point.
    weights : ndarray, shape (n_located, 3)
        Barycentric weights (sum to 1).
    """

    def __init__(self, old: Mesh, new: Mesh):
        _require_mesh(old)
        _require_mesh(new)
        lineage = new.lineage
        moved = lineage is not None and lineage.matches(old) and lineage.moved
        origin = _kept_in_place(old, new, moved)
        kept = origin >= 0
        self.n_old = old.n_points
        self.kept = kept
        self.origin = origin
        self.located = np.flatnonzero(~kept)
        queries = new.points[self.located]
        if lineage is not None and lineage.matches(old):
            # The step's parent map: no point location; checked by
            # rebuilding the points from it, which a mismatched old mesh fails.
            triangle = lineage.parent_triangle[self.located]
            weights = lineage.barycentric[self.located]
            rebuilt = np.einsum("kj,kjc->kc", weights, old.points[old.triangles[np.maximum(triangle, 0)]])
            gap = np.where(triangle >= 0, np.abs(rebuilt - queries).max(axis=1, initial=0.0), 0.0)
            if gap.size and gap.max() > _LINEAGE_SLACK * _outside_tolerance(old, queries):
                raise ValueError("new.lineage does not fit old: new was not evolved from old")
            unknown = np.flatnonzero(triangle < 0)
            if len(unknown) and not moved:  # (after a move the step located every point: these are outside)
                triangle = triangle.copy()
                weights = weights.copy()
                triangle[unknown], weights[unknown] = _core.locate_points(old.points, old.triangles, queries[unknown])
            self.used_lineage = True
        else:
            triangle, weights = _core.locate_points(old.points, old.triangles, queries)
            self.used_lineage = False
        vertices = old.triangles[np.maximum(triangle, 0)]
        outside = np.flatnonzero(triangle < 0)
        if len(outside):
            vertices = vertices.copy()
            weights = weights.copy()
            if moved:
                nearest, w = _nearest_old_triangle(old, queries[outside])
                v = old.triangles[nearest]
            else:
                v, w = _nearest_boundary_edge(old, queries[outside])
            vertices[outside] = v
            weights[outside] = w
        self.vertices = vertices
        self.weights = weights

    def __call__(self, values: Any) -> np.ndarray:
        """Values at the new points, shape (n_new,) + values.shape[1:]."""
        array = np.asarray(values)
        if array.dtype == object or array.dtype.kind not in "fiuc":
            raise TypeError(f"values must be a numeric array, got dtype {array.dtype}")
        if array.ndim == 0 or array.shape[0] != self.n_old:
            raise ValueError(
                f"values must have one row per point of the old mesh: shape ({self.n_old}, ...), got {array.shape}"
            )
        dtype = array.dtype if array.dtype.kind in "fc" else np.dtype(np.float64)
        flat = array.reshape(self.n_old, -1)
        out = np.empty((len(self.kept), flat.shape[1]), dtype=dtype)
        out[self.kept] = flat[self.origin[self.kept]]  # exact copy, bit for bit
        mixed = np.einsum("kj,kjc->kc", self.weights, flat[self.vertices].astype(np.result_type(dtype, np.float64)))
        out[self.located] = mixed.astype(dtype, copy=False)
        return out.reshape((len(self.kept),) + array.shape[1:])


def _nearest_boundary_edge(old: Mesh, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation on the nearest boundary edge, for points that lie
    outside the old domain by rounding only.

    Parameters
    ----------
    old : Mesh
    queries : ndarray, shape (q, 2)

    Returns
    -------
    vertices : ndarray of int, shape (q, 3)
        The nearest boundary edge's end points (the first repeated).
    weights : ndarray, shape (q, 3)
        Weights of the closest point of that edge (the third is 0).

    Raises
    ------
    ValueError
        If a query lies farther than :func:`_outside_tolerance` from every
        boundary edge.

    Notes
    -----
    The nearest edge is the one a comparison with every boundary edge would
    choose (smallest distance, then lowest index), but only edges that can lie
    within the tolerance are compared: boundary edges are grouped by length
    (one group per power of two), and in a group whose half-lengths are at most
    H an edge within distance tol of q has its midpoint within tol + H of q,
    found with a k-d tree of the group's midpoints. O((q + b) log b) for b
    boundary edges in a mesh whose boundary edge lengths span a bounded ratio
    (the number of groups is log2 of that ratio), instead of O(q b).
    """
    edges = old.segments[old.segment_is_boundary]
    a = old.points[edges[:, 0]]
    d = old.points[edges[:, 1]] - a
    dd = np.einsum("ij,ij->i", d, d)
    tolerance = _outside_tolerance(old, queries)
    half = 0.5 * np.sqrt(dd)
    _, exponent = np.frexp(half)
    query_parts: list[np.ndarray] = []
    edge_parts: list[np.ndarray] = []
    for level in np.unique(exponent):  # one pass per length scale, not per point
        members = np.flatnonzero(exponent == level)
        tree = cKDTree(a[members] + 0.5 * d[members])
        # 2 tolerances: one for the distance, one for the rounding of midpoints and distances
        q, item = _pairs_within(tree, queries, float(half[members].max()) + 2.0 * tolerance)
        query_parts.append(q)
        edge_parts.append(members[item])
    pair_query = np.concatenate(query_parts)
    pair_edge = np.concatenate(edge_parts)
    t, gap = _to_segments(queries[pair_query], a[pair_edge], d[pair_edge], dd[pair_edge])
    # per query, the smallest gap, then the lowest edge index (as argmin over all edges)
    order = np.lexsort((pair_edge, gap, pair_query))
    first = order[np.r_[True, pair_query[order][1:] != pair_query[order][:-1]]] if len(order) else order
    best_gap = np.full(len(queries), np.inf)
    best_gap[pair_query[first]] = gap[first]
    bad = np.flatnonzero(~(best_gap <= tolerance))
    if len(bad):
        k = int(bad[0])
        _, gaps = _to_segments(queries[k][None, :], a, d, dd)
        raise ValueError(
            f"point {queries[k].tolist()} of the new mesh lies outside the old mesh (by {float(gaps.min()):.3g}, "
            f"more than the rounding tolerance {tolerance:.3g}): transfer needs the new mesh to cover the same domain"
        )
    chosen = np.empty(len(queries), dtype=np.int64)
    chosen[pair_query[first]] = first
    edge = edges[pair_edge[chosen]]
    tb = t[chosen]
    vertices = np.c_[edge, edge[:, 0]]
    weights = np.zeros((len(queries), 3))
    weights[:, 0] = 1.0 - tb
    weights[:, 1] = tb
    return vertices, weights


def _to_segments(q: np.ndarray, a: np.ndarray, d: np.ndarray, dd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parameter of the closest point of each segment a + t d (t in [0, 1]) to
    the matching query, and the distance; rows broadcast."""
    t = np.clip(np.einsum("kj,kj->k", *np.broadcast_arrays(q - a, d)) / dd, 0.0, 1.0)
    gap = np.linalg.norm(q - (a + t[:, None] * d), axis=1)
    return t, gap


def _pairs_within(tree: cKDTree, queries: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """All (query index, tree item) pairs closer than ``radius``: k-nearest
    queries with k doubled for the queries whose k-th neighbour is still within
    the radius (vectorised; no per-query Python loop)."""
    rows = np.arange(len(queries))
    k = min(8, tree.n)
    out_query, out_item = [], []
    while len(rows):
        dist, item = tree.query(queries[rows], k=k, distance_upper_bound=radius)
        dist = dist.reshape(len(rows), k)
        item = item.reshape(len(rows), k)
        found = np.isfinite(dist)
        more = found[:, -1] & (k < tree.n)  # the k-th is within the radius: there may be more
        take = found & ~more[:, None]
        out_query.append(np.broadcast_to(rows[:, None], found.shape)[take])
        out_item.append(item[take])
        rows = rows[more]
        k = min(2 * k, tree.n)
    return np.concatenate(out_query), np.concatenate(out_item)


def _kept_in_place(old: Mesh, new: Mesh, moved: bool) -> np.ndarray:
    """``new.origin`` where a kept point lies at its origin's coordinates, -1
    elsewhere. Kept points that moved are an error unless the step moved them
    (``moved``: its lineage locates them instead)."""
    origin = new.origin
    kept = origin >= 0
    if not kept.any():
        return origin
    if origin.max() >= old.n_points:
        raise ValueError(
            f"new.origin refers to point {int(origin.max())} but old has {old.n_points} points: "
            "new was not evolved from old"
        )
    same = (new.points == old.points[np.maximum(origin, 0)]).all(axis=1) & kept
    if not moved and not same[kept].all():
        raise ValueError("kept points of new differ from their origin in old: new was not evolved from old")
    return np.where(same, origin, -1)


def _boundary_edge_triangles(old: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """The boundary edges (a, b) of ``old`` (domain on their left) and the old
    triangle that has each, as its directed edge a -> b."""
    edges = old.segments[old.segment_is_boundary]
    n = np.int64(old.n_points)
    t = old.triangles
    directed = np.concatenate([t[:, 0] * n + t[:, 1], t[:, 1] * n + t[:, 2], t[:, 2] * n + t[:, 0]])
    order = np.argsort(directed, kind="stable")
    at = np.minimum(np.searchsorted(directed, edges[:, 0] * n + edges[:, 1], sorter=order), len(order) - 1)
    return edges, order[at] % len(t)


def _nearest_old_triangle(old: Mesh, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For points outside the old domain (the domain moved): the old triangle of
    the nearest old boundary edge, and the barycentric coordinates of each point
    in it (extrapolated: the linear extension of the old field).

    The nearest edge is searched among the boundary edges at the
    ``_NEAREST_VERTICES`` boundary vertices nearest the point (a k-d tree): the
    nearest edge overall unless a long edge passes closer than all of their
    edges, which then only changes which neighbouring old triangle extends the
    field. O((q + b) log b) for q points and b boundary edges; deterministic.
    """
    edges, owner = _boundary_edge_triangles(old)
    vertices, first = np.unique(edges[:, 0], return_index=True)
    # every boundary vertex starts one boundary edge (closed loops) and ends another
    ending = np.empty(len(vertices), dtype=np.int64)
    ending[np.searchsorted(vertices, edges[:, 1])] = np.arange(len(edges))
    k = min(_NEAREST_VERTICES, len(vertices))
    _, near = cKDTree(old.points[vertices]).query(queries, k=k)
    near = np.asarray(near).reshape(len(queries), k)
    candidates = np.concatenate([first[near], ending[near]], axis=1)  # (q, 2k) edge indices
    a = old.points[edges[candidates, 0]]
    d = old.points[edges[candidates, 1]] - a
    dd = np.einsum("qkj,qkj->qk", d, d)
    q = queries[:, None, :]
    t = np.clip(np.einsum("qkj,qkj->qk", q - a, d) / dd, 0.0, 1.0)
    gap = np.linalg.norm(q - (a + t[..., None] * d), axis=2)
    edge = candidates[np.arange(len(queries)), np.argmin(gap, axis=1)]
    triangle = owner[edge]
    weights = _barycentric(old.points[old.triangles[triangle]], queries[:, None, :])[:, 0, :]
    return triangle, weights


# Boundary vertices searched around a point outside the old domain (_nearest_old_triangle).
_NEAREST_VERTICES = 4


def _carried(values: Any, origin: np.ndarray, n_old: int) -> np.ndarray:
    """Per-point values of the old mesh at the moved mesh's points (frame="lagrangian")."""
    array = np.asarray(values)
    if array.dtype == object or array.dtype.kind not in "fiuc":
        raise TypeError(f"values must be a numeric array, got dtype {array.dtype}")
    if array.ndim == 0 or array.shape[0] != n_old:
        raise ValueError(f"values must have one row per point of the old mesh: shape ({n_old}, ...), got {array.shape}")
    return array[origin]


# The transfers on two DistributedMesh, registered by evomesh.distributed.transfer
# (which builds on this module, so this one does not import it).
_DISTRIBUTED: dict[str, Callable[..., Any]] = {}


def _distributed(name: str) -> Callable[..., Any]:
    if name not in _DISTRIBUTED:
        raise ImportError("the transfers on DistributedMesh live in evomesh.distributed.transfer: import evomesh")
    return _DISTRIBUTED[name]


Method = Literal["linear", "conservative"]
Frame = Literal["eulerian", "lagrangian"]


@overload
def transfer(
    old: Mesh | TetMesh, new: Mesh | TetMesh, values: Mapping[str, ArrayLike], method: Method = "linear", *,
    frame: Frame = "eulerian"
) -> dict[str, np.ndarray]: ...
@overload
def transfer(
    old: Mesh | TetMesh, new: Mesh | TetMesh, values: ArrayLike, method: Method = "linear", *, frame: Frame = "eulerian"
) -> np.ndarray: ...
def transfer(
    old: Any, new: Any, values: ArrayLike | Mapping[str, ArrayLike], method: Method = "linear", *,
    frame: Frame = "eulerian"
) -> np.ndarray | dict[str, np.ndarray]:
    """Per-vertex field(s) of ``old`` at the points of ``new``.

    ``method="linear"`` (the default): exact copy at kept points
    (``new.origin >= 0``), linear interpolation in the old triangle elsewhere.
    A linear function is reproduced exactly (up to rounding); kept values are
    copied bit for bit.

    ``method="conservative"``: the L2 (Galerkin) projection of the old P1 field
    onto the new P1 space, ``M_new u_new = M_mix u_old`` with
    ``M_mix[i, j] = int phi_i^new phi_j^old`` computed exactly on the
    intersections of old and new triangles (a local :class:`Supermesh`, found
    through ``new.lineage``). The integral over the domain is preserved up to
    rounding (constants lie in both spaces) and linear fields are reproduced;
    values at kept points generally change (the projection is global). The
    system is solved by conjugate gradients preconditioned by the diagonal (the
    scaled P1 mass matrix has condition number at most 4 on any mesh), to
    rounding, with the integral restored exactly at the end.
    Needs ``new = evolve(old, ...)``; chain calls step by step over several
    steps (each step is conservative, so the chain is). A non-finite value is
    refused (the projection is global: it would spread everywhere).

    When the domain changes (curved boundaries, ``geometry=``: the step moves
    the discrete boundary between the chords and the curve), the strips of the
    new domain that no old triangle covers take the linear extension of the
    old field from the nearest old triangle, and the strips the new domain
    leaves out are dropped. Constants and linear fields are still reproduced
    to rounding, and the integral changes by exactly the strips' contribution,
    which :func:`domain_change` reports (``integral_gained - integral_lost``).

    After a step that moved the points (``evolve(old, ..., displacement=u)``,
    ``new.lineage.moved``) the default ``frame="eulerian"`` remaps the field
    from the old mesh AS IT WAS (old points at their old coordinates) onto the
    new mesh: the field stays where it is in space and the mesh moves through
    it, as an ALE remap. Kept points that did not move copy their value; the
    others (moved ones too) interpolate where they now lie in the old mesh
    (the step's lineage located them). The conservative transfer is exact over
    the part of the domain both meshes cover; where the boundary moved, the
    swept strips are gained and lost as above (:func:`domain_change`), and
    :func:`region_exchange` reports the integral that changed region as an
    interface moved. ``frame="lagrangian"`` instead carries the values with the
    points (each kept point keeps its old value, a copy: the old mesh moved
    with the points, as the step moved it, then transferred onto the new mesh;
    conservative for the integral over the moved mesh, which differs from the
    old integral as the motion changes areas). Without a move both frames are
    the same.

    Parameters
    ----------
    old : Mesh
        The mesh the values live on.
    new : Mesh
        A mesh of the same domain, normally ``evolve(old, ...)``; its
        ``origin`` must index ``old`` (with ``method="linear"`` a mesh with all
        origins -1 is interpolated everywhere).
    values : array_like, shape (n_old,) or (n_old, ...), or a mapping of them
        Scalar or vector fields. Floating and complex dtypes are kept; integer
        fields become float64. A mapping (name -> array) gives a dict, with
        one point location (one supermesh) for all fields.
    method : {"linear", "conservative"}
    frame : {"eulerian", "lagrangian"}, default "eulerian"
        After a move (see above): the field stays in space ("eulerian") or
        moves with the points ("lagrangian").

    Returns
    -------
    ndarray, shape (n_new,) + values.shape[1:], or dict of them
        New arrays; the inputs are not modified.

    Raises
    ------
    TypeError
        If old or new is not a Mesh, or values are not numeric.
    ValueError
        If values do not have one row per old point, if new's origins do not
        match old, a new point lies outside the old domain, method is
        unknown, or (conservative) new has no lineage from old.
    """
    if "DistributedMesh" in (type(old).__name__, type(new).__name__):  # (mpi4py is optional: not imported here)
        return _distributed("transfer")(old, new, values, method, frame=frame)
    if isinstance(old, TetMesh) or isinstance(new, TetMesh):
        if method != "linear":
            raise ValueError("transfer between tetrahedral meshes supports method='linear' only (yet)")
        if isinstance(values, Mapping):
            return {name: transfer_tet(old, new, v) for name, v in values.items()}
        return transfer_tet(old, new, values)
    if frame not in ("eulerian", "lagrangian"):
        raise ValueError(f"frame must be 'eulerian' or 'lagrangian', got {frame!r}")
    _require_mesh(old)
    _require_mesh(new)
    lineage = new.lineage
    if frame == "lagrangian" and lineage is not None and lineage.matches(old) and lineage.moved:
        # The old mesh moved with the points (the step's moved mesh, old values
        # copied to its points), then the step's own transfer from it.
        motion = lineage.motion
        origin = motion.mesh.origin
        if isinstance(values, Mapping):
            values = {name: _named(lambda v: _carried(v, origin, old.n_points), name, v) for name, v in values.items()}
        else:
            values = _carried(values, origin, old.n_points)
        old = motion.mesh
        new = Mesh._trusted(new.points, new.triangles, new.segments, new.segment_is_boundary, new.kind, motion.origin,
                            {}, motion.lineage, None, new.segment_tags, new.triangle_tags, new.required)
    if method == "linear":
        interpolation: Any = Interpolation(old, new)
    elif method == "conservative":
        interpolation = Supermesh(old, new, mass=True).project_vertices
    else:
        raise ValueError(f"method must be 'linear' or 'conservative', got {method!r}")
    if isinstance(values, Mapping):
        return {name: _named(interpolation, name, v) for name, v in values.items()}
    return interpolation(values)


@overload
def transfer_cells(old: Mesh | TetMesh, new: Mesh | TetMesh,
                   values: Mapping[str, ArrayLike]) -> dict[str, np.ndarray]: ...
@overload
def transfer_cells(old: Mesh | TetMesh, new: Mesh | TetMesh, values: ArrayLike) -> np.ndarray: ...
def transfer_cells(
    old: Mesh | TetMesh, new: Mesh | TetMesh, values: ArrayLike | Mapping[str, ArrayLike]
) -> np.ndarray | dict[str, np.ndarray]:
    """Per-triangle field(s) of ``old`` on the triangles of ``new``, conservatively.

    The P0 projection ``new[t] = sum_s |t n s| old[s] / |t|`` over the old
    triangles s overlapping t (a local :class:`Supermesh`, found through
    ``new.lineage``): ``sum_t |t| new[t] = sum_s |s| old[s]`` up to rounding,
    and a constant field is reproduced exactly. Where the new domain covers
    area the old one did not (curved boundaries), that part of a new triangle
    takes the value of the nearest old triangle (the one it overlaps most, else
    the one at its points, in its region); the total then changes by
    :func:`domain_change`'s ``integral_gained - integral_lost``. A NaN reaches
    only the new triangles that overlap its old triangle.

    After a step that moved the points (``displacement=``) this remaps from the
    old mesh at its old positions (Eulerian, as :func:`transfer`): when an
    interface between regions moved, the material it swept is carried into the
    region that now covers it, and each new region's total is what
    :func:`region_exchange` says came into it (from every old region, plus the
    strip gained), to rounding.

    Over several steps, chain the calls, one per step::

        c1 = transfer_cells(m0, m1, c0)
        c2 = transfer_cells(m1, m2, c1)

    Each step preserves the total, so the chain does (the drift is the sum of
    the steps' rounding). There is no direct ``m0 -> m2`` transfer: ``m2`` has
    no lineage from ``m0``.

    On tetrahedral meshes (:class:`TetMesh`) the same projection runs over the
    exact intersections of the old and new tetrahedra (a local
    :class:`TetSupermesh`, clipped volumes): ``sum_t |t| new[t] = sum_s |s| old[s]``
    to rounding (measured below 1e-14 relative) and constants are reproduced
    exactly; the domain does not change there, so nothing is gained or lost.

    Parameters
    ----------
    old, new : Mesh or TetMesh
        ``new = evolve(old, ...)`` (``new.lineage`` must refer to old).
    values : array_like, shape (n_old_cells,) or (n_old_cells, ...), or a mapping of them
        Floating and complex dtypes are kept; integer fields become float64.

    Returns
    -------
    ndarray, shape (n_new_cells,) + values.shape[1:], or dict of them

    Raises
    ------
    TypeError, ValueError
        As :func:`transfer` with method="conservative".
    """
    if "DistributedMesh" in (type(old).__name__, type(new).__name__):  # (mpi4py is optional: not imported here)
        return _distributed("transfer_cells")(old, new, values)
    supermesh: Supermesh | TetSupermesh
    if isinstance(old, TetMesh) or isinstance(new, TetMesh):
        supermesh = TetSupermesh(old, new)
    else:
        supermesh = Supermesh(old, new, mass=False)
    if isinstance(values, Mapping):
        return {name: _named(supermesh.project_cells, name, v) for name, v in values.items()}
    return supermesh.project_cells(values)


def _first_pair_cell(offsets: np.ndarray, old_cell: np.ndarray) -> np.ndarray:
    """The old cell of each new cell's first pair (-1 for a new cell without pairs)."""
    nonempty = np.diff(offsets) > 0
    first = np.full(len(offsets) - 1, -1, dtype=np.int64)
    first[nonempty] = old_cell[offsets[:-1][nonempty]]
    return first


def _p0_average(flat: np.ndarray, offsets: np.ndarray, old_cell: np.ndarray, measure: np.ndarray,
                new_cell: np.ndarray, denominator: np.ndarray, reference_cell: np.ndarray) -> np.ndarray:
    """The P0 projection ``sum_s |t n s| old[s] / denominator[t]`` of flat (n_old, k) values over
    a supermesh's pairs (CSR by new cell: offsets, old_cell, measure, new_cell), written relative
    to the value of one old cell per new cell (``reference_cell``): a constant field gives
    differences 0, hence exactly itself."""
    reference = flat[reference_cell]
    nonempty = np.diff(offsets) > 0
    weights = (measure / denominator[new_cell])[:, None]
    mixed = np.zeros((len(offsets) - 1, flat.shape[1]), dtype=flat.dtype)
    if nonempty.any():
        terms = weights * (flat[old_cell] - reference[new_cell])
        mixed[nonempty] = np.add.reduceat(terms, offsets[:-1][nonempty])
    return reference + mixed


class TetSupermesh:
    """The intersections of the tetrahedra of ``new = evolve(old, ...)`` with those of ``old``.

    Built by the C++ core without a global search, as :class:`Supermesh` in
    2-D: a new tetrahedron whose four kept points have origins forming an old
    tetrahedron is that tetrahedron (one pair, its own volume, no clipping);
    every other one floods over the old face adjacency from the old
    tetrahedra at its vertices (the old star of a kept point, the lineage's
    parent of a new one) and clips each old tetrahedron by its four planes
    (at most three tetrahedra per clip), summing the pieces' volumes.
    Parallel over fixed blocks of new tetrahedra: independent of the thread count.

    Attributes
    ----------
    offsets : ndarray of int, shape (n_new_tetrahedra + 1,)
    new_tet, old_tet : ndarray of int, shape (pairs,)
        The overlapping pairs, grouped by new tetrahedron.
    volume : ndarray, shape (pairs,)
        |t n s| per pair (exact up to the rounding of the cut points).
    identical : int
        New tetrahedra that are old ones.
    """

    def __init__(self, old: Mesh | TetMesh, new: Mesh | TetMesh, *, threads: int = 0):
        if not isinstance(old, TetMesh) or not isinstance(new, TetMesh):
            raise TypeError("a transfer between tetrahedral meshes needs two TetMesh")
        lineage = new.lineage
        if lineage is None or not lineage.matches(old):
            raise ValueError(
                "conservative transfer needs new = evolve(old, ...): new.lineage "
                + ("is None" if lineage is None else "refers to a mesh of another size")
            )
        raw = _core.tet_supermesh(old.points, old.tetrahedra, new.points, new.tetrahedra, new.origin,
                                  lineage.parent_tet, threads)
        self.old = old
        self.new = new
        self.offsets = raw["offsets"]
        self.old_tet = raw["old_tet"]
        self.volume = raw["volume"]
        self.identical = int(raw["identical"])
        empty = np.flatnonzero(np.diff(self.offsets) == 0)
        if len(empty):  # (never for a step's output: the old tetrahedra cover the domain)
            t = int(empty[0])
            raise ValueError(f"new tetrahedron {t} (points {new.tetrahedra[t].tolist()}) overlaps no old tetrahedron: "
                             "old and new do not cover the same domain")
        self.new_tet = np.repeat(np.arange(new.n_tetrahedra), np.diff(self.offsets))

    def project_cells(self, values: Any) -> np.ndarray:
        """P0 projection of per-tetrahedron values (see :func:`transfer_cells`)."""
        array, flat, dtype = _numeric(values, self.old.n_tetrahedra, "tetrahedron")
        n_new = self.new.n_tetrahedra
        # Divided by the covered volume (the weights of a new tetrahedron sum to 1 to rounding).
        denominator = np.bincount(self.new_tet, self.volume, minlength=n_new)
        first = _first_pair_cell(self.offsets, self.old_tet)
        out = _p0_average(flat, self.offsets, self.old_tet, self.volume, self.new_tet, denominator, first)
        return out.astype(dtype, copy=False).reshape((n_new,) + array.shape[1:])


def _numeric(values: Any, rows: int, what: str) -> tuple[np.ndarray, np.ndarray, np.dtype]:
    """(array, flat (rows, -1) in float64/complex128, output dtype) of a field."""
    array = np.asarray(values)
    if array.dtype == object or array.dtype.kind not in "fiuc":
        raise TypeError(f"values must be a numeric array, got dtype {array.dtype}")
    if array.ndim == 0 or array.shape[0] != rows:
        raise ValueError(f"values must have one row per {what} of the old mesh: shape ({rows}, ...), got {array.shape}")
    dtype = array.dtype if array.dtype.kind in "fc" else np.dtype(np.float64)
    flat = array.reshape(rows, -1).astype(np.result_type(dtype, np.float64), copy=False)
    return array, flat, dtype


def _p1_mass(mesh: Mesh, threads: int = 0) -> scipy.sparse.csr_matrix:
    """The P1 mass matrix of a mesh: |T| / 12 (1 + delta_ij) per triangle (C++ core, columns sorted)."""
    data, indices, indptr = _core.p1_mass_matrix(mesh.points, mesh.triangles, threads)
    n = mesh.n_points
    return scipy.sparse.csr_matrix((data, indices, indptr), shape=(n, n), copy=False)


def _solve_mass(mass: scipy.sparse.csr_matrix, rhs: np.ndarray, threads: int = 0) -> np.ndarray:
    """Solves ``mass @ u = rhs`` (real, shape (n, columns)) for a P1 mass matrix.

    Conjugate gradients preconditioned by the diagonal (C++ core,
    ``_core.solve_p1_mass``): the diagonally scaled P1 mass matrix has
    eigenvalues in [1/2, 2] on any triangle mesh, however graded (each
    element's scaled 3 x 3 block has eigenvalues 1/2, 1/2 and 2), so the error
    shrinks by about (2 - 1) / (2 + 1) = 1/3 per iteration whatever the mesh:
    O(n) per iteration, 25-35 iterations to the rounding of float64, where a
    sparse LU costs far more at 1e5 points. Then a constant is added so that
    the integral (``1^T mass u = 1^T rhs``) holds to rounding, whatever the
    iteration left over. A better start (the linear transfer) saves only about
    4 of 27 iterations at 1e5 points: the count is set by the rate, not the start.
    """
    u, _ = _core.solve_p1_mass(mass.data, mass.indices, mass.indptr, rhs, threads)
    return u


class Supermesh:
    """The intersections of the triangles of ``new = evolve(old, ...)`` with those of ``old``.

    Built by the C++ core without a global search. A new triangle whose three
    points are kept and whose origins form an old triangle is that triangle:
    its one pair is written directly (|t| and the element mass matrix), which
    covers about 70% of the triangles of a typical step. Every other new
    triangle starts from the old triangles at its vertices (the old star of a
    kept vertex, the lineage's parent triangle of a new one; after a step that
    moved the points, a kept point that moved seeds from its parent too, where
    the step located it, or from the old triangle of the nearest old boundary
    edge when it lies outside the old domain) and floods over old edge
    adjacency; each intersection is clipped (Sutherland-Hodgman) and measured
    (shoelace); with ``mass=True`` also ``int phi_a^new phi_b^old`` over it
    (exact for the quadratic integrand on a fan of the polygon).
    Parallel over fixed blocks of new triangles: independent of the thread count.

    Attributes
    ----------
    new_triangle, old_triangle : ndarray of int, shape (pairs,)
        The overlapping pairs, grouped by new triangle.
    offsets : ndarray of int, shape (n_new_triangles + 1,)
    area : ndarray, shape (pairs,)
        |t n s| per pair.
    mass : ndarray, shape (pairs, 3, 3) (empty when mass=False)
        ``mass[k, a, b] = int_{t n s} phi^new_{t[a]} phi^old_{s[b]}`` (vertex order of the meshes' triangles).
    identical : ndarray of int, shape (n_new_triangles,)
        The old triangle that a new one is (three kept points), else -1.
    """

    def __init__(self, old: Mesh, new: Mesh, *, mass: bool = True, threads: int = 0):
        _require_mesh(old)
        _require_mesh(new)
        lineage = new.lineage
        if lineage is None or not lineage.matches(old):
            raise ValueError(
                "conservative transfer needs new = evolve(old, ...): new.lineage "
                + ("is None" if lineage is None else "refers to a mesh of another size")
            )
        # After a move, only the kept points still at their old coordinates seed
        # from their old star (and give the one-pair shortcut); every other point
        # from where the step located it in the old mesh.
        origin = _kept_in_place(old, new, lineage.moved)
        kept = origin >= 0
        parent = lineage.parent_triangle
        unknown = np.flatnonzero(~kept & (parent < 0))
        if len(unknown):
            parent = parent.copy()
            if lineage.moved:  # outside the old domain: a nearby old triangle seeds the search
                parent[unknown], _ = _nearest_old_triangle(old, new.points[unknown])
            else:  # rare: points the step did not locate
                parent[unknown], _ = _core.locate_points(old.points, old.triangles, new.points[unknown])
        raw = _core.supermesh(old.points, old.triangles, new.points, new.triangles, origin, parent, mass, threads)
        self.old = old
        self.new = new
        self._origin = origin
        self._threads = threads
        self.offsets = raw["offsets"]
        self.old_triangle = raw["old_triangle"]
        self.area = raw["area"]
        self.mass = raw["mass"]
        self.identical = raw["identical"]
        self._new_mass: Any = None  # new's P1 mass matrix, made on first use
        self.new_triangle = np.repeat(np.arange(new.n_triangles), np.diff(self.offsets))
        self._find_domain_change(parent)

    def project_cells(self, values: Any) -> np.ndarray:
        """P0 projection of per-triangle values (see :func:`transfer_cells`)."""
        array, flat, dtype = _numeric(values, self.old.n_triangles, "triangle")
        n_new = self.new.n_triangles
        # Relative to a reference value per new triangle (the old triangle that
        # stands in for it outside the old domain, else its first pair): a
        # constant field gives differences 0, hence exactly itself. The part of
        # a new triangle that no old one covers (a curved boundary moved the
        # domain) takes the value of that nearest old triangle.
        first = _first_pair_cell(self.offsets, self.old_triangle)
        first[self.gap_triangle] = self.gap_old_triangle
        # Divided by the covered area where the old triangles cover t (so the
        # weights sum to 1 to rounding), by |t| where a gap is left: there the
        # gap's own term, (old[s*] - reference) |gap| / |t|, is 0 by the choice of reference.
        denominator = np.bincount(self.new_triangle, self.area, minlength=n_new)
        denominator[self.gap_triangle] = self._new_area[self.gap_triangle]
        out = _p0_average(flat, self.offsets, self.old_triangle, self.area, self.new_triangle, denominator, first)
        return out.astype(dtype, copy=False).reshape((n_new,) + array.shape[1:])

    def _find_domain_change(self, parent: np.ndarray) -> None:
        """Where the new domain covers area the old one did not (a step with curved
        boundaries moves the discrete boundary between the chords and the curve).

        A new triangle t whose pairs leave more than rounding of its area
        uncovered gets a stand-in old triangle s* (``gap_old_triangle``): of its
        pairs the one with the largest overlap, else (t lies wholly outside the
        old domain) the old triangle at one of its points (the star of a kept
        point, the lineage's parent of a new one), preferring t's region tag.
        The old field on the uncovered part U of t is the linear extension E of
        its values on s*. Then ``int_U phi_a^t E`` needs no polygon of U:
        ``int_t phi_a^t E - sum_i int_(t n s_i) phi_a^t E``, the first from the
        P1 element mass of t and E at t's points, the second from each pair's
        mass block and E at s_i's points (E is linear, so it is its own P1
        interpolant on s_i). Exact for the quadratic integrand, so constants and
        linear fields are reproduced and the integral grows by exactly int_U E.
        ``_gap_mass[g]`` maps s*'s three values to t's three right-hand sides.
        """
        self._magnitude = max(float(np.abs(self.old.points).max()), float(np.abs(self.new.points).max()))
        self._find_gaps(parent, lambda t: f"new triangle {t}")

    def _find_gaps(self, parent: np.ndarray, name: Callable[[int], str]) -> None:
        """_find_domain_change's work at ``self._magnitude`` (the distributed
        supermesh's too, on its rank's part); ``name(t)`` names new triangle t
        in the error."""
        old, new = self.old, self.new
        n_new = new.n_triangles
        self._new_area, edge = _areas_and_longest_sides(new)
        covered = np.bincount(self.new_triangle, self.area, minlength=n_new)
        counts = np.diff(self.offsets)
        gap = np.flatnonzero(self._new_area - covered > _area_rounding(self._magnitude, edge, counts))
        stand_in = np.full(len(gap), -1, dtype=np.int64)
        with_pairs = counts[gap] > 0
        if with_pairs.any():
            stand_in[with_pairs] = _largest_overlap(self.new_triangle, self.old_triangle, self.area, gap[with_pairs])
        lone = np.flatnonzero(~with_pairs)
        if len(lone):
            stand_in[lone] = Supermesh._old_triangle_at_points(self, gap[lone], parent)
            missing = lone[stand_in[lone] < 0]
            if len(missing):
                raise ValueError(f"{name(int(gap[missing[0]]))} overlaps no old triangle and none of its points "
                                 "lies in one: new was not evolved from old")
        self.gap_triangle = gap
        self.gap_old_triangle = stand_in
        self.gap_area = self._new_area[gap] - covered[gap]
        self._lost: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # made by _lost_part on first use
        if not len(gap) or self.mass.size == 0:
            self._gap_mass = np.zeros((len(gap), 3, 3))
            return
        self._gap_mass = _gap_mass(self, old, new, gap, stand_in)

    def _lost_part(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Old triangles that new ones leave partly uncovered (the domain lost
        there), their uncovered areas, and every old triangle's area."""
        if self._lost is None:
            old = self.old
            old_area, edge = _areas_and_longest_sides(old)
            covered = np.bincount(self.old_triangle, self.area, minlength=old.n_triangles)
            counts = np.bincount(self.old_triangle, minlength=old.n_triangles)
            lost = np.flatnonzero(old_area - covered > _area_rounding(self._magnitude, edge, counts))
            self._lost = (lost, old_area[lost] - covered[lost], old_area)
        return self._lost

    def _old_triangle_at_points(self, triangles: np.ndarray, parent: np.ndarray) -> np.ndarray:
        """An old triangle at one of the points of each given new triangle (-1 if none):
        the first old triangle around a kept point's origin (if it did not move),
        else the point's parent (where the step located it),
        preferring one with the new triangle's region tag."""
        old, new = self.old, self.new
        incident = np.full(old.n_points, -1, dtype=np.int64)
        flat = old.triangles.ravel()
        incident[flat[::-1]] = (np.arange(len(flat)) // 3)[::-1]  # first triangle of each point
        corners = new.triangles[triangles]  # (k, 3)
        origin = self._origin[corners]
        candidate = np.where(origin >= 0, incident[np.maximum(origin, 0)], parent[corners])
        candidate = np.where(candidate < old.n_triangles, candidate, -1)
        same_region = (candidate >= 0) & (old.triangle_tags[np.maximum(candidate, 0)]
                                          == new.triangle_tags[triangles][:, None])
        score = same_region * 2 + (candidate >= 0)
        return candidate[np.arange(len(triangles)), np.argmax(score, axis=1)]

    def domain_change(self, values: Any = None) -> DomainChange:
        """What the change of domain between old and new does to a field's integral.

        A step with curved boundaries (``geometry=``) moves the discrete boundary:
        the new domain covers strips the old one did not (``area_gained``) and
        leaves out others (``area_lost``). A conservative transfer carries the
        old field's integral over the common part exactly; on the gained strip
        the field is the linear extension from the nearest old triangle, on the
        lost strip it is dropped, so

            integral(new field) = integral(old field) + integral_gained - integral_lost

        up to rounding, for :func:`transfer` (P1, ``method="conservative"``)
        and :func:`transfer_cells` (P0).

        Parameters
        ----------
        values : array_like, shape (n_old_points,) or (n_old_triangles,), optional
            A scalar field at the old points (P1) or on the old triangles (P0;
            when both lengths match, points win). Without it only the areas are given.

        Returns
        -------
        DomainChange
        """
        # the region exchange summed over the regions (one home for the strips' integrals)
        exchange = self.region_exchange(values)
        area_gained, area_lost = float(exchange.area_gained.sum()), float(exchange.area_lost.sum())
        gained, lost = exchange.integral_gained, exchange.integral_lost
        if gained is None or lost is None:
            return DomainChange(area_gained, area_lost, None, None)
        return DomainChange(area_gained, area_lost, float(gained.sum()), float(lost.sum()))

    def region_exchange(self, values: Any = None) -> RegionExchange:
        """How old and new regions (triangle tags) overlap, and a field's integral
        over each overlap: see :func:`region_exchange`.

        Parameters
        ----------
        values : array_like, shape (n_old_points,) or (n_old_triangles,), optional
            A scalar field at the old points (P1; needs ``mass=True``) or on the
            old triangles (P0); when both lengths match, points win.

        Returns
        -------
        RegionExchange
        """
        old, new = self.old, self.new
        tags = np.union1d(old.triangle_tags, new.triangle_tags)
        k = len(tags)
        old_region = np.searchsorted(tags, old.triangle_tags)
        new_region = np.searchsorted(tags, new.triangle_tags)
        cell = old_region[self.old_triangle] * k + new_region[self.new_triangle]
        lost_triangle, lost_area, old_area = self._lost_part()

        def per_cell(weights: np.ndarray) -> np.ndarray:
            return np.bincount(cell, weights, minlength=k * k).reshape(k, k)

        area = per_cell(self.area)
        area_gained = np.bincount(new_region[self.gap_triangle], self.gap_area, minlength=k)
        area_lost = np.bincount(old_region[lost_triangle], lost_area, minlength=k)
        if values is None:
            return RegionExchange(tags, area, None, area_gained, area_lost, None, None)
        field = np.asarray(values, dtype=np.float64)
        if field.shape == (old.n_points,):
            if self.mass.size == 0 and len(self.area):
                raise ValueError("a P1 field's region exchange needs a Supermesh built with mass=True")
            corners = field[old.triangles]
            # int over t n s of the old field: the mass block's columns summed over t's basis (a partition of unity)
            pair = np.einsum("kab,kb->k", self.mass, corners[self.old_triangle])
            gained = np.einsum("gab,gb->g", self._gap_mass, corners[self.gap_old_triangle])
            whole = old_area / 3.0 * corners.sum(axis=1)
            inside = np.bincount(self.old_triangle, pair, minlength=old.n_triangles)
            lost = (whole - inside)[lost_triangle]
        elif field.shape == (old.n_triangles,):
            pair = self.area * field[self.old_triangle]
            gained = self.gap_area * field[self.gap_old_triangle]
            lost = lost_area * field[lost_triangle]
        else:
            raise ValueError(
                f"values must be a scalar field on the old points ({old.n_points},) or triangles "
                f"({old.n_triangles},), got shape {field.shape}"
            )
        return RegionExchange(tags, area, per_cell(pair), area_gained, area_lost,
                              np.bincount(new_region[self.gap_triangle], gained, minlength=k),
                              np.bincount(old_region[lost_triangle], lost, minlength=k))

    def mixed_mass(self) -> scipy.sparse.csr_matrix:
        """``M_mix[i, j] = int phi_i^new phi_j^old``, shape (n_new_points, n_old_points)."""
        if self.mass.size == 0 and len(self.area):
            raise ValueError("this Supermesh was built with mass=False")
        rows = np.broadcast_to(self.new.triangles[self.new_triangle][:, :, None], self.mass.shape)
        cols = np.broadcast_to(self.old.triangles[self.old_triangle][:, None, :], self.mass.shape)
        return scipy.sparse.csr_matrix(
            (self.mass.ravel(), (rows.ravel(), cols.ravel())), shape=(self.new.n_points, self.old.n_points)
        )

    def project_vertices(self, values: Any) -> np.ndarray:
        """L2 projection of per-vertex (P1) values (see :func:`transfer`, method="conservative")."""
        array, flat, dtype = _numeric(values, self.old.n_points, "point")
        if self.mass.size == 0 and len(self.area):
            raise ValueError("this Supermesh was built with mass=False")
        if self._new_mass is None:
            self._new_mass = _p1_mass(self.new, self._threads)
        columns = [flat.real, flat.imag] if np.iscomplexobj(flat) else [flat]
        # rhs = M_mix @ flat without assembling M_mix (per pair, the 3 x 3 block
        # times the old triangle's values, into the new triangle's rows), then
        # M_new u = rhs; the matrices are real: a complex field is two solves.
        bad = ~np.isfinite(flat).all(axis=1)
        if bad.any():
            k = int(np.argmax(bad))
            raise ValueError(
                f"values at old point {k} ({self.old.points[k].tolist()}) are not finite: the conservative transfer "
                "is a global projection, so one NaN or inf would spread over the whole mesh; the linear transfer "
                "keeps it to the triangles around that point"
            )
        parts = []
        for part in columns:
            rhs = _core.mixed_mass_times(self.offsets, self.old_triangle, self.mass, self.old.triangles,
                                         self.new.triangles, self.new.n_points, np.ascontiguousarray(part))
            if len(self.gap_triangle):  # the new domain's area outside the old one (see _find_domain_change)
                gap_values = part[self.old.triangles[self.gap_old_triangle]]  # (g, 3, columns)
                rows = self.new.triangles[self.gap_triangle].ravel()
                contribution = np.einsum("gab,gbc->gac", self._gap_mass, gap_values).reshape(len(rows), -1)
                for column in range(contribution.shape[1]):
                    rhs[:, column] += np.bincount(rows, contribution[:, column], minlength=self.new.n_points)
            parts.append(_solve_mass(self._new_mass, rhs, self._threads))
        out = parts[0] if len(parts) == 1 else parts[0] + 1j * parts[1]
        out = out.astype(dtype, copy=False)
        return out.reshape((self.new.n_points,) + array.shape[1:])


def _named(interpolation: Callable[[Any], np.ndarray], name: Any, values: Any) -> np.ndarray:
    try:
        return interpolation(values)
    except (TypeError, ValueError) as error:
        raise type(error)(f"field {name!r}: {error}") from None


class DomainChange(NamedTuple):
    """The change of domain between a mesh and the mesh evolved from it (see
    :meth:`Supermesh.domain_change`): the areas the new domain gains and
    loses, and a field's integral over them (None without a field)."""

    area_gained: float
    area_lost: float
    integral_gained: float | None
    integral_lost: float | None


def domain_change(old: Mesh, new: Mesh, values: Any = None) -> DomainChange:
    """The area ``new = evolve(old, ...)`` gains and loses against ``old``, and
    a field's integral over them: see :meth:`Supermesh.domain_change`.

    ``transfer(old, new, u, method="conservative")`` changes the integral of u
    by exactly ``integral_gained - integral_lost`` (0 when the domain is kept,
    i.e. without curved boundaries or a boundary that moves: ``displacement=``)."""
    values_given = values is not None
    points_field = values_given and np.shape(values) == (old.n_points,)
    return Supermesh(old, new, mass=not values_given or points_field).domain_change(values)


class RegionExchange(NamedTuple):
    """How the regions (triangle tags) of a mesh and of the mesh evolved from it
    overlap, and what of a field changed region (see :func:`region_exchange`).

    Regions are indexed by ``tags``; row i is old region ``tags[i]``, column j
    new region ``tags[j]``.

    Attributes
    ----------
    tags : ndarray of int, shape (k,)
        The region tags of either mesh, increasing.
    area : ndarray, shape (k, k)
        ``area[i, j]``: the area of old region i that new region j covers.
    integral : ndarray, shape (k, k), or None
        The old field's integral over the same parts (None without a field).
        Off the diagonal: the material that changed sides as an interface
        moved (from region i to region j).
    area_gained, integral_gained : ndarray, shape (k,)
        Per new region: its area outside the old domain, and the integral of
        the field the transfers put there (the linear extension of the nearest
        old triangle; :func:`domain_change`).
    area_lost, integral_lost : ndarray, shape (k,)
        Per old region: its area outside the new domain, and the old field's
        integral there.

    Per new region j, ``transfer_cells(old, new, c)`` integrates to
    ``integral[:, j].sum() + integral_gained[j]``, and per old region i, the
    old field to ``integral[i, :].sum() + integral_lost[i]`` (to rounding).
    """

    tags: np.ndarray
    area: np.ndarray
    integral: np.ndarray | None
    area_gained: np.ndarray
    area_lost: np.ndarray
    integral_gained: np.ndarray | None
    integral_lost: np.ndarray | None

    @property
    def changed_sides(self) -> float:
        """The field's integral over the parts whose region changed (the area
        without a field): the sum of ``integral`` off its diagonal."""
        matrix = self.area if self.integral is None else self.integral
        return float(matrix.sum() - np.trace(matrix))


def region_exchange(old: Mesh, new: Mesh, values: Any = None) -> RegionExchange:
    """What of a field changes region between ``old`` and ``new = evolve(old, ...)``.

    When a step moves an interface between regions (``displacement=``, or a
    level-set interface), the area it sweeps changes region: material of
    region i now lies in region j. The conservative transfers remap the field
    in space, so that material is carried into region j: this says how much.
    Computed exactly on the intersections of old and new triangles (the
    :class:`Supermesh` of the transfers).

    Parameters
    ----------
    old, new : Mesh
        ``new = evolve(old, ...)`` (``new.lineage`` must refer to old).
    values : array_like, shape (n_old_points,) or (n_old_triangles,), optional
        A scalar field at the old points (P1) or on the old triangles (P0; when
        both lengths match, points win). Without it only the areas are given.

    Returns
    -------
    RegionExchange
        ``integral[i, j]``: the old field's integral over old region i and new
        region j; ``changed_sides``: the total off the diagonal. With
        :func:`transfer_cells`, each new region's total is its column sum plus
        ``integral_gained`` (to rounding); the P1 conservative transfer keeps
        the total only (it projects onto functions that straddle the borders).

    Examples
    --------
    >>> x = region_exchange(old, new, density_cells)              # doctest: +SKIP
    >>> x.integral[x.tags == 1, x.tags == 2]  # mass from region 1 into region 2   # doctest: +SKIP
    """
    values_given = values is not None
    points_field = values_given and np.shape(values) == (old.n_points,)
    return Supermesh(old, new, mass=not values_given or points_field).region_exchange(values)


def _gap_mass(supermesh: Any, old: Any, new: Any, gap: np.ndarray, stand_in: np.ndarray) -> np.ndarray:
    """Supermesh._find_domain_change's gap masses: for each uncovered new
    triangle t (`gap`) and its stand-in old triangle s* (`stand_in`), the map
    from s*'s three values to t's three right-hand sides over the uncovered
    part (the supermesh's pairs: new_triangle, old_triangle, mass; _new_area)."""
    s_points = old.points[old.triangles[stand_in]]  # (g, 3, 2)
    t_points = new.points[new.triangles[gap]]
    # int_t phi_a^t E = (M_t e)_a, e = E at t's points = lambda^{s*}(t's points) @ values(s*)
    element = (supermesh._new_area[gap] / 12.0)[:, None, None] * (np.ones((3, 3)) + np.eye(3))
    gap_mass = element @ _barycentric(s_points, t_points)
    pairs = np.flatnonzero(np.isin(supermesh.new_triangle, gap))
    if len(pairs):
        slot = np.searchsorted(gap, supermesh.new_triangle[pairs])
        pair_points = old.points[old.triangles[supermesh.old_triangle[pairs]]]
        # int_(t n s_i) phi_a^t E = sum_b mass_i[a, b] E(s_i's point b)
        pair_terms = supermesh.mass[pairs] @ _barycentric(s_points[slot], pair_points)
        np.subtract.at(gap_mass, slot, pair_terms)
    return gap_mass


def _largest_overlap(new_triangle: np.ndarray, old_triangle: np.ndarray, area: np.ndarray,
                     rows: np.ndarray) -> np.ndarray:
    """For each new triangle in `rows` (sorted, each with pairs), the old triangle
    of its pair of largest overlap area (ties: the last in pair order)."""
    members = np.flatnonzero(np.isin(new_triangle, rows))
    order = members[np.lexsort((area[members], new_triangle[members]))]
    last = order[np.r_[new_triangle[order][1:] != new_triangle[order][:-1], True]]
    return old_triangle[last]


def _areas_and_longest_sides(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Signed areas and the largest coordinate difference along any side, shape (m,) each."""
    p = mesh.points[mesh.triangles]
    d1 = p[:, 1] - p[:, 0]
    d2 = p[:, 2] - p[:, 0]
    area = 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    side = np.maximum(np.abs(d1).max(axis=1), np.abs(d2).max(axis=1))  # (the third side is at most their sum)
    return area, 2.0 * side


def _area_rounding(magnitude: float, side: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Rounding of a triangle's area against the sum of its pairs' areas: each
    shoelace term carries a few roundings of (coordinate magnitude) x (side),
    one such error per pair (in units of the coordinates' rounding, never absolute)."""
    return 64.0 * np.finfo(np.float64).eps * magnitude * side * (1.0 + pairs)


def _barycentric(triangle: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (extrapolated outside) of points in triangles:
    ``triangle`` (k, 3, 2), ``points`` (k, m, 2) -> (k, m, 3)."""
    a = triangle[:, 0, :][:, None, :]
    e1 = (triangle[:, 1, :] - triangle[:, 0, :])[:, None, :]
    e2 = (triangle[:, 2, :] - triangle[:, 0, :])[:, None, :]
    q = points - a
    det = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
    l1 = (q[..., 0] * e2[..., 1] - q[..., 1] * e2[..., 0]) / det
    l2 = (e1[..., 0] * q[..., 1] - e1[..., 1] * q[..., 0]) / det
    return np.stack([1.0 - l1 - l2, l1, l2], axis=-1)
