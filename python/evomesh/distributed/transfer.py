"""Field transfers between two :class:`~evomesh.DistributedMesh`:
``evomesh.transfer`` and ``evomesh.transfer_cells`` dispatch here when given
distributed meshes. Each rank works on its own part of ``new`` plus the old
triangles that can touch it; neither mesh is gathered.

What travels (the reach halo of _halo.py, one exchange): each rank cuts its
owned new points (``method="linear"``) or owned new triangles (the supermesh
transfers) into Hilbert chunks and publishes each chunk's box and a reach;
each rank sends every owned old triangle t whose bounding box comes within
the reach of a chunk's box, as the record (centre c_t of t's bounding box,
extra e_t = half its diagonal). Completeness: the sender's test is
``dist(c_t, box) < reach + e_t`` (with slack); if t's bounding box B_t comes
within distance r of the box, some x in B_t has dist(x, box) <= r, and
|c_t - x| <= e_t, so dist(c_t, box) <= r + e_t and t passes. So every old
triangle whose bounding box meets the box grown by the reach is held, whatever
the partitions of old and new. What needs what:

- linear: a new point needs the old triangle containing it (its bounding box
  contains the point: reach 0), the star of its origin if kept (those
  triangles contain the point), and, within rounding outside the old domain,
  the boundary edges within the rounding tolerance (reach: twice it).
- supermesh: a new triangle t needs every old triangle whose bounding box
  meets t's box grown by the C++ core's margin (build_supermesh visits exactly
  those, so the pairs come out in the serial order, below), the stars of its
  kept vertices' origins (they contain the vertices), and for a vertex outside
  the old domain the nearest old boundary edge (reach: t's size; checked,
  else an error names it).

Equality with the serial transfer of the gathered meshes (scattered meshes:
global ids are the serial indices, triangles keep their rotation):

- linear, new a step's output from old: the lineage's parents (by global
  id; they contain the points, so they are held) and weights, checked and
  mixed as serially: bit for bit against the serial transfer of the gathered
  meshes, which carry that lineage (distributed/lineage.py).
- linear otherwise: the same kept copies and the same C++ point location and
  barycentric weights (the containing triangle is unique unless a point lies
  exactly on an old edge or vertex: then CGAL's walk picks one of the
  triangles, in either case the same value up to rounding), the same boundary
  edge rule, the same arithmetic: bit for bit.
- transfer_cells: the held old triangles are sorted by global id, so the
  core's seeds (smallest triangle of a kept point's star, the containing
  triangle of a new point) and its flood over old edges visit the same
  triangles in the same order: the same pairs, areas and sums, bit for bit
  against the serial transfer with ``new.lineage`` for points strictly inside
  old triangles. A new point outside the old domain (curved boundaries) is
  seeded from the nearest old boundary edge instead of the step's walk, which
  can reorder its pairs (rounding) or, for a new triangle that no old one
  overlaps, pick another nearby old triangle to extend from.
- conservative: the right-hand side as above, summed at the owner of each
  point; the P1 mass matrix rows of owned points as the serial ones (stars in
  triangle global-id order, so the same bits); the solve is the serial
  Jacobi-preconditioned CG with distributed dot products, so it agrees with the
  serial transfer to the solver's tolerance (rounding of float64: the serial
  stopping rule), and the integral is restored exactly as serially.

Global sums (CG dot products, the integral defect) are per-rank partial sums
(numpy, fixed order) gathered on every rank and added with ``math.fsum``: the
correctly rounded sum of the partials, independent of the order of ranks.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping

import numpy as np

from .. import _core
from ..field_transfer import (
    _DISTRIBUTED,
    _LINEAGE_SLACK,
    _ROUNDING_ULPS,
    Supermesh,
    _numeric,
    _pairs_within,
    _to_segments,
)
from . import _halo
from .mesh import (
    DistributedMesh,
    _collective,
    _contains,
    _exchange,
    _fingerprint,
    _first_of_each,
    _index_of,
    _mpi,
    _same_everywhere,
    _unique,
)

__all__ = ["transfer", "transfer_cells"]

# An old triangle as it travels: global id, vertex global ids and coordinates,
# region tag, and which of its edges (v[k], v[k+1]) are on the domain's boundary (bit k).
_OLD_TRIANGLE = np.dtype([("gid", "<i8"), ("v", "<i8", (3,)), ("xy", "<f8", (3, 2)), ("tag", "<i8"),
                          ("boundary", "u1")])
# The CG iteration cap of the serial solve (_core.solve_p1_mass).
_MAX_ITERATIONS = 200
# At most this many receiving chunks per rank: the senders' chunk-pair test is
# (their chunks) x (these), so a fixed count keeps it linear in the mesh size;
# coarser boxes only hold a slightly wider band of old triangles along the cuts.
_MAX_CHUNKS = 512


def _receiving_chunks(n: int) -> np.ndarray:
    """Chunk starts of n Hilbert-ordered receiving records."""
    return np.arange(0, n, max(_halo._CHUNK, -(-n // _MAX_CHUNKS)), dtype=np.int64)


# ------------------------------------------------------------------ checks
def _check_pair(old: Any, new: Any, call: str, fingerprints: dict[str, str],
                check_arguments: Callable[[], None] = lambda: None) -> Any:
    """The communicator both meshes live on, after the ranks agreed on the call
    and its `fingerprints` (_same_everywhere); raises on every rank (on the
    communicator of whichever argument is distributed) when they do not fit or
    `check_arguments` raises."""
    comm = old.comm if isinstance(old, DistributedMesh) else new.comm

    def check() -> None:
        check_arguments()
        MPI = _mpi()
        for name, mesh in (("old", old), ("new", new)):
            if not isinstance(mesh, DistributedMesh):
                raise TypeError(f"{name} must be an evomesh.DistributedMesh like the other mesh, got "
                                f"{type(mesh).__name__}: transfer between a Mesh and a DistributedMesh is not "
                                "defined (scatter the Mesh, or gather the DistributedMesh)")
        if MPI.Comm.Compare(old.comm, new.comm) not in (MPI.IDENT, MPI.CONGRUENT):
            raise ValueError("old and new must live on the same communicator (the same ranks in the same order)")
        for name, mesh in (("old", old), ("new", new)):
            if mesh.halo_rings < 1:
                raise ValueError(f"{name} has halo_rings=0: the distributed transfer needs halo_rings >= 1 (the "
                                 "stars of owned points: boundary edges of old, mass matrix rows of new)")

    _same_everywhere(comm, call, fingerprints, check)
    return comm


def _values_kind(values: Any) -> str:
    """One array or several by name: the same on every rank (_fields gathers the names of a mapping)."""
    return "a mapping" if isinstance(values, Mapping) else "an array"


def _fields(comm: Any, values: Any) -> tuple[list[Any], list[Any] | None]:
    """The fields to transfer and their names (None: one array), the names the same on every rank."""
    if isinstance(values, Mapping):
        names = list(values.keys())
        every = comm.allgather([repr(name) for name in names])

        def agree() -> None:
            for r, theirs in enumerate(every):
                if theirs != every[0]:
                    raise ValueError(f"values has fields {theirs} on rank {r} but {every[0]} on rank 0: give the "
                                     "same names in the same order on every rank")

        _collective(comm, agree)
        return [values[name] for name in names], names
    return [values], None


def _field_array(comm: Any, values: Any, rows: int, what: str, name: Any) -> np.ndarray:
    """A numeric field with one row per owned `what`, the same dtype and row
    shape on every rank (checked on every rank). Integer fields become float64."""
    prefix = "" if name is None else f"field {name!r}: "

    def check() -> np.ndarray:
        array = np.asarray(values)
        if array.dtype == object or array.dtype.kind not in "fiuc":
            raise TypeError(f"{prefix}values must be a numeric array, got dtype {array.dtype}")
        if array.ndim == 0 or array.shape[0] != rows:
            raise ValueError(f"{prefix}values must have one row per owned {what} of the old mesh: shape "
                             f"({rows}, ...), got {array.shape}")
        return array

    array = _collective(comm, check)
    layouts = comm.allgather((array.dtype.str, array.shape[1:]))

    def agree() -> None:
        for r, layout in enumerate(layouts):
            if layout != layouts[0]:
                raise ValueError(f"{prefix}values have dtype {layout[0]} and row shape {layout[1]} on rank {r} "
                                 f"but {layouts[0][0]} and {layouts[0][1]} on rank 0")

    _collective(comm, agree)
    return array


# ------------------------------------------------------------ global values
def _global_max(comm: Any, value: float) -> float:
    return float(comm.allreduce(float(value), op=_mpi().MAX))


def _global_sums(comm: Any, partial: np.ndarray) -> np.ndarray:
    """Sums over ranks of per-rank partial sums (a float64 vector, the same
    length everywhere): the correctly rounded sum of the partials (math.fsum),
    so independent of the order of the ranks."""
    partial = np.ascontiguousarray(partial, dtype=np.float64)
    every = np.empty((comm.size,) + partial.shape, dtype=np.float64)
    comm.Allgather(partial, every)
    return np.array([math.fsum(column) for column in every.reshape(comm.size, -1).T]).reshape(partial.shape)


def _bounds(comm: Any, *coordinates: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(lower corner, span, largest |coordinate|) over every rank's coordinates."""
    MPI = _mpi()
    big = np.finfo(np.float64).max
    stacked = np.concatenate([c.reshape(-1, 2) for c in coordinates])
    low = stacked.min(axis=0) if len(stacked) else np.full(2, big)
    high = stacked.max(axis=0) if len(stacked) else np.full(2, -big)
    low = np.array([comm.allreduce(float(x), op=MPI.MIN) for x in low])
    high = np.array([comm.allreduce(float(x), op=MPI.MAX) for x in high])
    if not (high >= low).all():
        return np.zeros(2), 0.0, 0.0
    return low, float((high - low).max()), float(max(np.abs(low).max(), np.abs(high).max()))


# -------------------------------------------------------------- old triangles
def _nearest_triangles(points: np.ndarray, triangles: np.ndarray, queries: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """For each query, the triangle at least distance (ties: the lower index)
    and that distance. Candidates by a k-d tree over the centroids: a triangle
    within distance d of q has its centroid within d + (its largest centroid to
    vertex distance) of q, and d is at most the distance to the nearest
    centroid's triangle."""
    from scipy.spatial import cKDTree

    corners = points[triangles]  # (m, 3, 2)
    centroid = corners.mean(axis=1)
    radius = float(np.sqrt(((corners - centroid[:, None, :]) ** 2).sum(axis=2)).max())
    tree = cKDTree(centroid)
    nearest, _ = tree.query(queries)
    lists = tree.query_ball_point(queries, nearest + radius * (1 + 1e-9) + 1e-300)
    counts = np.array([len(x) for x in lists], dtype=np.int64)
    query = np.repeat(np.arange(len(queries)), counts)
    tri = np.concatenate([np.asarray(x, dtype=np.int64) for x in lists]) if len(lists) else np.zeros(0, np.int64)
    q = queries[query]
    p = corners[tri]
    # distance from q to each edge, 0 when q is inside (all orientations >= 0)
    best = np.full(len(tri), np.inf)
    inside = np.ones(len(tri), bool)
    for k in range(3):
        u, v = p[:, k], p[:, (k + 1) % 3]
        e, w = v - u, q - u
        inside &= e[:, 0] * w[:, 1] - e[:, 1] * w[:, 0] >= 0
        t = np.clip((w * e).sum(axis=1) / np.maximum((e * e).sum(axis=1), np.finfo(float).tiny), 0.0, 1.0)
        best = np.minimum(best, np.hypot(*(w - t[:, None] * e).T))
    best[inside] = 0.0
    order = np.lexsort((tri, best, query))
    first = np.flatnonzero(np.r_[True, query[order][1:] != query[order][:-1]]) if len(order) else order
    return tri[order][first], best[order][first]


class _HeldOld:
    """The old triangles this rank holds for a transfer: those within reach of
    its chunks (module docstring), from every rank (itself too), sorted by global id.

    Attributes
    ----------
    gid, tags : (m,) int64
    triangles : (m, 3) local indices into ``points`` (the owners' rotation)
    point_gid : (p,) int64, sorted; points : (p, 2)
    boundary : (m,) uint8, bit k: edge (triangles[:, k], triangles[:, k + 1]) is on the domain's boundary
    bytes_moved : int, bytes sent to other ranks (records and values)
    """

    def __init__(self, old: DistributedMesh, table: np.ndarray, low: np.ndarray, span: float, magnitude: float):
        comm = old.comm
        self.old = old
        tri = old.triangles
        records = np.empty(len(tri), _OLD_TRIANGLE)
        records["gid"], records["v"], records["xy"] = old.triangle_global_ids, old.global_ids[tri], old.points[tri]
        records["tag"], records["boundary"] = old.triangle_tags, _boundary_bits(old)
        lo, hi = old.points[tri].min(axis=1), old.points[tri].max(axis=1)
        centre = 0.5 * (lo + hi)
        extra = 0.5 * np.hypot(*(hi - lo).T)
        perm, starts = _halo.hilbert_chunks(centre[:, 0], centre[:, 1], low, span)
        box = _halo.chunk_boxes(centre[perm, 0], centre[perm, 1], starts)
        tables = comm.allgather(table)
        index, dest = _halo.sends(centre[perm, 0], centre[perm, 1], extra[perm], starts, box, tables, comm.rank,
                                  magnitude)
        # This rank's own triangles: tested against the box around all its chunks with their largest reach
        # (a superset of what its chunks ask for: one test per triangle instead of dense chunk pairs; more
        # held triangles change no result, see the module docstring).
        mine = np.zeros(0, np.int64)
        if len(table):
            around = np.array([[table[:, 0].min(), table[:, 1].max(), table[:, 2].min(), table[:, 3].max()]])
            gap = _halo.box_distance(centre[:, 0], centre[:, 1], np.repeat(around, len(centre), axis=0))
            mine = np.flatnonzero(gap < (float(table[:, 4].max()) + extra) * (1 + _halo._SLACK) + 1e-12 * magnitude)
        self.send_index = np.concatenate([perm[index], mine])
        self.send_dest = np.concatenate([dest, np.full(len(mine), comm.rank, dtype=np.int64)])
        dest = self.send_dest
        received, _ = _exchange(comm, dest, records[self.send_index])
        self.order = np.argsort(received["gid"], kind="stable")
        held = received[self.order]
        self.bytes_moved = int((dest != comm.rank).sum()) * _OLD_TRIANGLE.itemsize
        self.gid, self.tags, self.boundary = held["gid"], held["tag"], held["boundary"]
        vertex = held["v"].ravel()
        self.point_gid, first = _first_of_each(vertex)
        self.points = np.ascontiguousarray(held["xy"].reshape(-1, 2)[first])
        self.triangles = _index_of(self.point_gid, held["v"]).astype(np.int64).reshape(-1, 3)
        self.n_triangles = len(held)

    def values(self, per_triangle: np.ndarray) -> np.ndarray:
        """Rows given per owned old triangle (e.g. the values at its 3 vertices),
        sent along the same plan: rows per held triangle."""
        received, _ = _exchange(self.old.comm, self.send_dest, np.ascontiguousarray(per_triangle[self.send_index]))
        self.bytes_moved += int((self.send_dest != self.old.comm.rank).sum()) * per_triangle[:1].nbytes
        return received[self.order]

    def point_values(self, values: np.ndarray) -> np.ndarray:
        """A field over old's owned points, at the held points."""
        local = _halo_rows(self.old, values)
        corners = self.values(local[self.old.triangles])  # (m, 3, ...)
        out = np.empty((len(self.point_gid),) + values.shape[1:], dtype=values.dtype)
        out[self.triangles.ravel()] = corners.reshape((-1,) + values.shape[1:])
        return out

    def boundary_edges(self) -> tuple[np.ndarray, np.ndarray]:
        """Boundary edges (a, b) of the held triangles (domain on their left),
        in (triangle gid, side) order, and the held triangle of each."""
        bits = self.boundary.astype(np.int64)
        triangle, side = np.nonzero((bits[:, None] >> np.arange(3)[None, :]) & 1)
        a = self.triangles[triangle, side]
        b = self.triangles[triangle, (side + 1) % 3]
        return np.stack([a, b], axis=1), triangle


def _boundary_bits(old: DistributedMesh) -> np.ndarray:
    """Per owned old triangle, bit k set when its edge (v[k], v[k+1]) is on the
    domain's boundary: no other triangle has it. The neighbours of an owned
    triangle share two of its vertices, which are in the rank's core, so ring 1
    of the halo holds them (halo_rings >= 1)."""
    held = np.concatenate([old.triangles, old.halo_triangles])
    n = np.int64(max(old.n_local, 1))
    directed = np.sort(np.concatenate([held[:, k] * n + held[:, (k + 1) % 3] for k in range(3)]))
    tri = old.triangles
    bits = np.zeros(len(tri), dtype=np.uint8)
    for k in range(3):
        reverse = tri[:, (k + 1) % 3] * n + tri[:, k]
        bits |= (~_contains(directed, reverse)).astype(np.uint8) << k
    return bits


def _halo_rows(mesh: DistributedMesh, values: np.ndarray) -> np.ndarray:
    """Rows on every local point from rows on the owned points: exchange_halo's
    plan, without its per-call checks (the callers checked the field once)."""
    return mesh._halo_rows(np.ascontiguousarray(values))


def _table(box: np.ndarray, reach: np.ndarray) -> np.ndarray:
    return np.column_stack([box, reach]) if len(box) else np.zeros((0, 5))


def _origins(held: _HeldOld, new: DistributedMesh, points: np.ndarray) -> np.ndarray:
    """Held old point of each given new point's origin (old global id), -1 for
    points not kept; raises (as the serial transfer) when a kept point is not
    at its origin's coordinates."""
    origin = new.origin[points]
    kept = origin >= 0
    where = np.full(len(points), -1, dtype=np.int64)
    found = kept & _contains(held.point_gid, origin)
    where[found] = _index_of(held.point_gid, origin[found])
    same = found.copy()
    same[found] = (held.points[where[found]] == new.points[points[found]]).all(axis=1)
    if not same[kept].all():
        k = int(np.flatnonzero(kept & ~same)[0])
        raise ValueError(f"kept point with global id {int(new.global_ids[points[k]])} of new differs from its "
                         f"origin (old global id {int(origin[k])}) or that origin is not a point of old: new was "
                         "not evolved from old")
    return where


def _nearest_boundary(held: _HeldOld, queries: np.ndarray, radius: float | np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For each query, among the held boundary edges within `radius` of it: the
    nearest (smallest distance, then first in (triangle gid, side) order), as
    :func:`evomesh.field_transfer._nearest_boundary_edge` chooses. Returns
    (edge index or -1, its (a, b), parameter t of the closest point, gap; inf where none)."""
    edges, _ = held.boundary_edges()
    q = len(queries)
    chosen = np.full(q, -1, dtype=np.int64)
    best_t, best_gap = np.zeros(q), np.full(q, np.inf)
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (q,))
    if not q or not len(edges):
        return chosen, edges, best_t, best_gap
    a = held.points[edges[:, 0]]
    d = held.points[edges[:, 1]] - a
    dd = np.einsum("ij,ij->i", d, d)
    half = 0.5 * np.sqrt(dd)
    from scipy.spatial import cKDTree

    pair_query, pair_edge = _pairs_within(cKDTree(a + 0.5 * d), queries, float(half.max() + 2.0 * radius.max()))
    t, gap = _to_segments(queries[pair_query], a[pair_edge], d[pair_edge], dd[pair_edge])
    inside = gap <= radius[pair_query]
    pair_query, pair_edge, t, gap = pair_query[inside], pair_edge[inside], t[inside], gap[inside]
    order = np.lexsort((pair_edge, gap, pair_query))
    first = order[np.r_[True, pair_query[order][1:] != pair_query[order][:-1]]] if len(order) else order
    chosen[pair_query[first]] = pair_edge[first]
    best_t[pair_query[first]] = t[first]
    best_gap[pair_query[first]] = gap[first]
    return chosen, edges, best_t, best_gap


# ------------------------------------------------------------------- linear
def _linear(comm: Any, old: DistributedMesh, new: DistributedMesh, fields: list[Any], names: list[Any] | None,
            stats: dict[str, Any]) -> list[np.ndarray]:
    """method="linear": Interpolation of the serial transfer: new points
    placed by ``new.lineage`` when it refers to old (a step's output: parents
    by global id, held since they contain the points), else located in the
    held old triangles by the C++ core, as the serial transfer does without a
    lineage."""
    owned = np.arange(new.n_owned)
    kept = new.origin[owned] >= 0
    located = np.flatnonzero(~kept)
    queries = np.ascontiguousarray(new.points[located])
    low, span, magnitude = _bounds(comm, old.points, new.owned_points)
    # The serial rounding tolerance (_outside_tolerance): max |old point| and |located new point|, over all ranks.
    scale = _global_max(comm, max(float(np.abs(old.points).max(initial=0.0)),
                                  float(np.abs(queries).max(initial=0.0))))
    tolerance = _ROUNDING_ULPS * float(np.finfo(np.float64).eps) * scale
    # Chunks of the owned new points (kept ones too: their origin's star carries the value to copy).
    perm, _ = _halo.hilbert_chunks(new.owned_points[:, 0], new.owned_points[:, 1], low, span)
    starts = _receiving_chunks(len(perm))
    box = _halo.chunk_boxes(new.owned_points[perm, 0], new.owned_points[perm, 1], starts)
    held = _HeldOld(old, _table(box, np.full(len(box), 4.0 * tolerance)), low, span, magnitude)
    stats["old_triangles_held"] = held.n_triangles
    lineage = new.lineage if new.lineage is not None and new.lineage.matches(old) else None
    stats["used_lineage"] = lineage is not None

    def search(at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if len(at) and held.n_triangles:
            return _core.locate_points(held.points, held.triangles, queries[at])
        return np.full(len(at), -1, np.int64), np.zeros((len(at), 3))

    def locate() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        origin = _origins(held, new, owned)
        if lineage is None:
            triangle, weights = search(np.arange(len(queries)))
        else:
            # The serial Interpolation with a lineage: its parents and weights,
            # checked by rebuilding the points; unlocated points searched.
            parent = lineage.parent_triangle[located]
            weights = lineage.barycentric[located].copy()
            known = parent >= 0
            triangle = np.full(len(queries), -1, np.int64)
            held_parent = known & _contains(held.gid, parent)
            triangle[held_parent] = _index_of(held.gid, parent[held_parent])
            rebuilt = np.einsum("kj,kjc->kc", weights[held_parent], held.points[held.triangles[triangle[held_parent]]])
            gap = np.abs(rebuilt - queries[held_parent]).max(initial=0.0)
            if not held_parent[known].all() or gap > _LINEAGE_SLACK * tolerance:
                raise ValueError("new.lineage does not fit old: new was not evolved from old")
            unknown = np.flatnonzero(~known)
            triangle[unknown], weights[unknown] = search(unknown)
        vertices = held.triangles[np.maximum(triangle, 0)] if held.n_triangles else np.zeros((len(queries), 3),
                                                                                             np.int64)
        outside = np.flatnonzero(triangle < 0)
        if len(outside):
            # Within rounding outside the old domain: the nearest boundary edge (serial _nearest_boundary_edge);
            # every boundary edge within the tolerance is held (reach 4 tolerances).
            vertices, weights = vertices.copy(), weights.copy()
            edge, edges, t, gap = _nearest_boundary(held, queries[outside], tolerance)
            bad = np.flatnonzero(edge < 0)
            if len(bad):
                k = int(outside[bad[0]])
                raise ValueError(f"point {queries[k].tolist()} of the new mesh lies outside the old mesh (by more "
                                 f"than the rounding tolerance {tolerance:.3g}): transfer needs the new mesh to cover "
                                 "the same domain (a step with curved boundaries moves the domain: use "
                                 "method='conservative' or transfer_cells, which extend the field there)")
            pair = edges[edge]
            vertices[outside] = np.c_[pair, pair[:, 0]]
            w = np.zeros((len(outside), 3))
            w[:, 0], w[:, 1] = 1.0 - t, t
            weights[outside] = w
        return origin, vertices, weights

    origin, vertices, weights = _collective(comm, locate)
    out = []
    for k, values in enumerate(fields):
        name = None if names is None else names[k]
        array = _field_array(comm, values, old.n_owned, "point", name)
        dtype = array.dtype if array.dtype.kind in "fc" else np.dtype(np.float64)
        flat = held.point_values(array.reshape(old.n_owned, -1))
        # the serial Interpolation.__call__, term for term
        result = np.empty((new.n_owned, flat.shape[1]), dtype=dtype)
        result[kept] = flat[origin[kept]]  # exact copy, bit for bit
        mixed = np.einsum("kj,kjc->kc", weights, flat[vertices].astype(np.result_type(dtype, np.float64)))
        result[located] = mixed.astype(dtype, copy=False)
        out.append(result.reshape((new.n_owned,) + array.shape[1:]))
    stats["bytes_moved"] = held.bytes_moved
    return out


# ---------------------------------------------------------------- supermesh
class _LocalSupermesh:
    """The serial :class:`~evomesh.field_transfer.Supermesh`'s arrays for this
    rank's owned new triangles over the held old triangles (so its
    ``project_cells`` runs unchanged on them), and what the P1 projection needs."""

    # set by Supermesh._find_gaps
    gap_triangle: np.ndarray
    gap_old_triangle: np.ndarray
    gap_area: np.ndarray
    _gap_mass: np.ndarray

    def __init__(self, comm: Any, old: DistributedMesh, new: DistributedMesh, mass: bool):
        self.comm = comm
        tri = new.triangles
        corners = new.points[tri]
        lo, hi = corners.min(axis=1), corners.max(axis=1)
        low, span, magnitude = _bounds(comm, old.points, new.points)
        # build_supermesh's margin around t's box (per coordinate), then as a distance; doubled against rounding.
        margin = 1e-9 * (hi - lo) + 64 * np.finfo(np.float64).eps * np.maximum(np.abs(lo), np.abs(hi))
        size = np.hypot(*(hi - lo).T)
        centroid = corners.mean(axis=1)
        perm, _ = _halo.hilbert_chunks(centroid[:, 0], centroid[:, 1], low, span)
        starts = _receiving_chunks(len(perm))
        box = np.empty((len(starts), 4))
        if len(starts):
            box[:, 0], box[:, 1] = np.minimum.reduceat(lo[perm, 0], starts), np.maximum.reduceat(hi[perm, 0], starts)
            box[:, 2], box[:, 3] = np.minimum.reduceat(lo[perm, 1], starts), np.maximum.reduceat(hi[perm, 1], starts)
        # A vertex outside the old domain seeds from the nearest old boundary edge: held within t's size.
        reach_of = 2.0 * np.hypot(*margin.T) + size
        chunk_reach = np.maximum.reduceat(reach_of[perm], starts) if len(starts) else np.zeros(0)
        held = _HeldOld(old, _table(box, chunk_reach), low, span, magnitude)
        self.held = held
        reach_triangle = np.empty(len(tri))
        if len(starts):
            reach_triangle[perm] = np.repeat(chunk_reach, np.diff(np.append(starts, len(tri))))
        # The magnitude of the serial Supermesh (both meshes' largest coordinate), over all ranks.
        self._magnitude = _global_max(comm, max(float(np.abs(old.points).max(initial=0.0)),
                                                float(np.abs(new.points).max(initial=0.0))))
        self.old = _Part(held.points, held.triangles, held.tags)
        self.new = _Part(new.points, tri, new.triangle_tags)
        self.new_mesh = new
        _collective(comm, self._build, new, mass, reach_triangle)

    def _build(self, new: DistributedMesh, mass: bool, reach_triangle: np.ndarray) -> None:
        held = self.held
        tri = new.triangles
        vertices = _unique(tri.ravel())
        origin = np.full(new.n_local, -1, dtype=np.int64)
        origin[vertices] = _origins(held, new, vertices)
        parent = np.full(new.n_local, -1, dtype=np.int64)
        free = vertices[origin[vertices] < 0]
        if len(free) and held.n_triangles:
            parent[free], _ = _core.locate_points(held.points, held.triangles, np.ascontiguousarray(new.points[free]))
        unknown = free[parent[free] < 0]
        if len(unknown):
            # Outside the old domain (a curved boundary moved it): the old triangle of the nearest old
            # boundary edge seeds the search. Certified: every old triangle within reach of a chunk holding a
            # triangle at the point is held.
            radius = np.zeros(new.n_local)
            np.maximum.at(radius, tri.ravel(), np.repeat(reach_triangle, 3))
            edge, _, _, _ = _nearest_boundary(held, new.points[unknown], radius[unknown])
            missing = np.flatnonzero(edge < 0)
            if len(missing):
                k = int(unknown[missing[0]])
                raise ValueError(f"point with global id {int(new.global_ids[k])} of new lies outside the old "
                                 f"domain by more than the size of its triangles ({float(radius[k]):.3g}): new was "
                                 "not evolved from old")
            _, owner = held.boundary_edges()
            parent[unknown] = owner[edge]
        if held.n_triangles:
            raw = _core.supermesh(held.points, held.triangles, new.points, tri, origin, parent, mass, 0)
        elif len(tri):
            raise ValueError(f"new triangle with global id {int(new.triangle_global_ids[0])} overlaps no old "
                             "triangle: new was not evolved from old")
        else:
            raw = {"offsets": np.zeros(1, np.int64), "old_triangle": np.zeros(0, np.int64), "area": np.zeros(0),
                   "mass": np.zeros((0, 3, 3)), "identical": np.zeros(0, np.int64)}
        self._origin = origin
        self.offsets = raw["offsets"]
        self.old_triangle = raw["old_triangle"]
        self.area = raw["area"]
        self.mass = raw["mass"]
        self.new_triangle = np.repeat(np.arange(len(tri)), np.diff(self.offsets))
        self._find_domain_change(parent)

    def _find_domain_change(self, parent: np.ndarray) -> None:
        """Supermesh._find_domain_change on this rank's part, with the magnitude
        of both whole meshes (so the same gaps): the new triangles the old
        domain leaves uncovered, their stand-in old triangle and gap mass."""
        global_ids = self.new_mesh.triangle_global_ids
        Supermesh._find_gaps(self, parent,  # type: ignore[arg-type]
                             lambda t: f"new triangle with global id {int(global_ids[t])}")

    def cells(self, values: np.ndarray) -> np.ndarray:
        """P0 projection: the serial project_cells on the held values."""
        return Supermesh.project_cells(self, self.held.values(values))  # type: ignore[arg-type]

    def rhs(self, old_point_values: np.ndarray) -> np.ndarray:
        """M_mix u_old (plus the gap's part) on the owned new points, shape
        (n_owned, columns): the local sums, halo rows added at their owners."""
        new = self.new_mesh
        part = self.held.point_values(old_point_values)
        rhs = np.zeros((new.n_local, part.shape[1]))
        if len(self.old_triangle):
            rhs = _core.mixed_mass_times(self.offsets, self.old_triangle, self.mass, self.held.triangles,
                                         new.triangles, new.n_local, np.ascontiguousarray(part))
        if len(self.gap_triangle):
            gap_values = part[self.held.triangles[self.gap_old_triangle]]
            rows = new.triangles[self.gap_triangle].ravel()
            contribution = np.einsum("gab,gbc->gac", self._gap_mass, gap_values).reshape(len(rows), -1)
            for column in range(contribution.shape[1]):
                rhs[:, column] += np.bincount(rows, contribution[:, column], minlength=new.n_local)
        # Rows of halo points to their owners, added there in the order received (by source rank).
        halo = np.arange(new.n_owned, new.n_local)
        record = np.dtype([("gid", "<i8"), ("row", "<f8", (rhs.shape[1],))])
        send = np.empty(len(halo), record)
        send["gid"], send["row"] = new.global_ids[halo], rhs[halo]
        got, _ = _exchange(self.comm, new.owners[halo].astype(np.int64), send)
        self.held.bytes_moved += len(send) * record.itemsize
        owned = rhs[: new.n_owned].copy()
        np.add.at(owned, _index_of(new.global_ids[: new.n_owned], got["gid"]), got["row"])
        return owned


class _Part:
    """Points, triangles and tags of one side of a local supermesh (what the
    serial Supermesh's helpers read from a Mesh)."""

    def __init__(self, points: np.ndarray, triangles: np.ndarray, tags: np.ndarray):
        self.points, self.triangles, self.triangle_tags = points, triangles, tags
        self.n_points, self.n_triangles = len(points), len(triangles)


class _MassSolver:
    """The P1 mass matrix of `new` on the owned rows and a distributed
    Jacobi-preconditioned CG: the serial _core.solve_p1_mass step for step
    (start, stopping rule, iteration cap, integral restored), with halo
    exchanges for the matrix-vector product and order-independent global sums."""

    def __init__(self, new: DistributedMesh):
        import scipy.sparse

        self.new = new
        held = np.concatenate([new.triangles, new.halo_triangles])
        gids = np.concatenate([new.triangle_global_ids, new.halo_triangle_global_ids])
        # Stars in triangle global-id order: the serial row sums, term for term.
        held = held[np.argsort(gids, kind="stable")]
        data, indices, indptr = _core.p1_mass_matrix(new.points, held, 0)
        n = new.n_owned
        end = indptr[n]
        self.matrix = scipy.sparse.csr_matrix((data[:end], indices[:end], indptr[: n + 1]), shape=(n, new.n_local))
        rows = np.repeat(np.arange(n), np.diff(indptr[: n + 1]))
        self.diagonal = np.zeros(n)
        on_diagonal = indices[:end] == rows
        self.diagonal[rows[on_diagonal]] = data[:end][on_diagonal]
        self.row_sum = np.bincount(rows, data[:end], minlength=n)

    def times(self, x: np.ndarray) -> np.ndarray:
        return self.matrix @ _halo_rows(self.new, x)

    def solve(self, rhs: np.ndarray) -> tuple[np.ndarray, int]:
        comm = self.new.comm
        diagonal = self.diagonal

        def total(values: np.ndarray) -> float:
            return float(_global_sums(comm, np.array([values.sum()]))[0])

        eps = float(np.finfo(np.float64).eps)
        out = np.empty_like(rhs)
        most = 0
        for c in range(rhs.shape[1]):
            b = rhs[:, c]
            scale = math.sqrt(total(b * b / diagonal))
            tiny = eps * max(scale, np.finfo(np.float64).tiny)
            u = b / diagonal
            r = b - self.times(u)
            z = r / diagonal
            p = z.copy()
            rz = total(r * z)
            iteration = 0
            while iteration < _MAX_ITERATIONS and not math.sqrt(abs(rz)) <= tiny:
                q = self.times(p)
                pq = total(p * q)
                alpha = rz / pq if pq != 0 else 0.0
                u += alpha * p
                r -= alpha * q
                z = r / diagonal
                rz_new = total(r * z)
                beta = rz_new / rz if rz != 0 else 0.0
                p = z + beta * p
                rz = rz_new
                iteration += 1
            most = max(most, iteration)
            # The integral: 1^T M u = 1^T b, whatever the iteration left over.
            defect = total(b - self.times(u))
            shift = defect / total(self.row_sum)
            out[:, c] = u + shift
        return out, most


# -------------------------------------------------------------- entry points
def transfer(old: Any, new: Any, values: Any, method: str = "linear", *, frame: str = "eulerian",
             stats: dict[str, Any] | None = None) -> np.ndarray | dict[Any, np.ndarray]:
    """:func:`evomesh.transfer` for two :class:`~evomesh.DistributedMesh` on one communicator. Collective.

    Parameters
    ----------
    old, new : DistributedMesh
        ``new`` a mesh of the same domain, normally a step from ``old``: its
        ``origin`` holds old global ids (-1 for new points). Both with
        ``halo_rings >= 1``; any partitions.
    values : array_like, shape (old.n_owned,) or (old.n_owned, ...), or a mapping of them
        A field over old's owned points; a mapping (the same names on every
        rank) gives a dict, with one search for all fields.
    method : {"linear", "conservative"}
        As the serial transfer. "linear": equal bit for bit to the serial
        transfer of the gathered meshes (new points placed by ``new.lineage``
        when new is a step's output from old, else located in the old mesh;
        within rounding outside it on the nearest boundary edge, farther
        outside an error). "conservative": the L2 projection; agrees
        with the serial one to its solver tolerance, and keeps the integral
        (plus what a changed domain gains, minus what it loses, as
        :func:`evomesh.domain_change` says) to rounding.
    frame : {"eulerian", "lagrangian"}
        Accepted for the serial signature; the same without a move (a
        distributed step moves no points).
    stats : dict, optional
        Filled with "bytes_moved" (sent by this rank to others),
        "old_triangles_held", for "linear" "used_lineage", and for
        "conservative" "cg_iterations".

    Returns
    -------
    ndarray, shape (new.n_owned,) + values.shape[1:], or a dict of them
        Over ``new.owned_points``.

    Raises
    ------
    TypeError, ValueError
        On every rank, when any rank's input is bad (as the serial transfer,
        plus: a Mesh paired with a DistributedMesh, different communicators,
        halo_rings=0, field names or dtypes that differ between ranks).
    """
    def check() -> None:
        if frame not in ("eulerian", "lagrangian"):
            raise ValueError(f"frame must be 'eulerian' or 'lagrangian', got {frame!r}")
        if method not in ("linear", "conservative"):
            raise ValueError(f"method must be 'linear' or 'conservative', got {method!r}")

    comm = _check_pair(old, new, "transfer", {"method": _fingerprint(method), "frame": _fingerprint(frame),
                                              "values": _values_kind(values)}, check)
    stats = {} if stats is None else stats
    fields, names = _fields(comm, values)
    if method == "linear":
        out = _linear(comm, old, new, fields, names, stats)
    else:
        arrays = [_field_array(comm, v, old.n_owned, "point", None if names is None else names[k])
                  for k, v in enumerate(fields)]

        def finite() -> None:
            for k, array in enumerate(arrays):
                flat = array.reshape(old.n_owned, -1)
                bad = ~np.isfinite(flat).all(axis=1)
                if bad.any():
                    i = int(np.argmax(bad))
                    prefix = "" if names is None else f"field {names[k]!r}: "
                    raise ValueError(
                        f"{prefix}values at old point {int(old.global_ids[i])} ({old.points[i].tolist()}) are not "
                        "finite: the conservative transfer is a global projection, so one NaN or inf would spread "
                        "over the whole mesh; the linear transfer keeps it to the triangles around that point")

        _collective(comm, finite)
        supermesh = _LocalSupermesh(comm, old, new, mass=True)
        solver = _collective(comm, _MassSolver, new)
        stats["old_triangles_held"] = supermesh.held.n_triangles
        out = []
        iterations = 0
        for array in arrays:
            _, flat, dtype = _numeric(array, old.n_owned, "point")
            parts = []
            for part in ([flat.real, flat.imag] if np.iscomplexobj(flat) else [flat]):
                u, used = solver.solve(supermesh.rhs(np.ascontiguousarray(part)))
                iterations = max(iterations, used)
                parts.append(u)
            result = parts[0] if len(parts) == 1 else parts[0] + 1j * parts[1]
            out.append(result.astype(dtype, copy=False).reshape((new.n_owned,) + array.shape[1:]))
        stats["cg_iterations"] = iterations
        stats["bytes_moved"] = supermesh.held.bytes_moved
    if names is None:
        return out[0]
    return dict(zip(names, out))


def transfer_cells(old: Any, new: Any, values: Any, *, stats: dict[str, Any] | None = None
                   ) -> np.ndarray | dict[Any, np.ndarray]:
    """:func:`evomesh.transfer_cells` for two :class:`~evomesh.DistributedMesh` on one communicator. Collective.

    Parameters
    ----------
    old, new : DistributedMesh
        As :func:`transfer`.
    values : array_like, shape (m_owned,) or (m_owned, ...), or a mapping of them
        A field over old's owned triangles (``old.triangles``, in that order).
    stats : dict, optional
        Filled with "bytes_moved" and "old_triangles_held".

    Returns
    -------
    ndarray, shape (len(new.triangles),) + values.shape[1:], or a dict of them
        Over new's owned triangles: the serial transfer_cells on the gathered
        meshes (bit for bit where the new points lie inside the old domain;
        see the module docstring).

    Raises
    ------
    TypeError, ValueError
        On every rank, as :func:`transfer`.
    """
    comm = _check_pair(old, new, "transfer_cells", {"values": _values_kind(values)})
    stats = {} if stats is None else stats
    fields, names = _fields(comm, values)
    arrays = [_field_array(comm, v, len(old.triangles), "triangle", None if names is None else names[k])
              for k, v in enumerate(fields)]
    supermesh = _LocalSupermesh(comm, old, new, mass=False)
    out = [supermesh.cells(array) for array in arrays]
    stats["old_triangles_held"] = supermesh.held.n_triangles
    stats["bytes_moved"] = supermesh.held.bytes_moved
    if names is None:
        return out[0]
    return dict(zip(names, out))


# evomesh.transfer and evomesh.transfer_cells dispatch here for DistributedMesh arguments.
_DISTRIBUTED.update(transfer=transfer, transfer_cells=transfer_cells)
