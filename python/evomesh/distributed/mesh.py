"""A triangle mesh distributed over MPI ranks (mpi4py): :class:`DistributedMesh`.

Each rank holds the points and triangles it **owns**, plus a **halo**: the
rings of triangles around them, with their points, that a step or a solver
reads but another rank owns. Every point, triangle and segment has a global id
(int64) and an owner rank, so the pieces say exactly which global mesh they
make (``gather``). ``rebalance`` cuts and renumbers any partition into the
canonical one. The layout and the partition rules are in
docs/distributed-step.md ("Part 4, as built").

Ownership rules (the contract a distributed step relies on):

- a point is owned by one rank (``owners``);
- a triangle is owned by the owner of its smallest-gid vertex;
- a segment is owned by the owner of its smaller-gid end.

mpi4py is imported only when a method is called, so ``import evomesh`` works
without it (``pip install evomesh[mpi]``; the MPI library itself comes from the
``mpich`` wheel or a system MPI).

Every collective call (these methods, ``evolve`` and the transfers on a
DistributedMesh) begins with one allgather in which the ranks agree that they
are in the same call with the same arguments (``_same_everywhere``: cheap
fingerprints, never big arrays) and that each rank's arguments are valid: a
difference, or bad input on one rank, makes **every** rank raise the same
exception (naming the argument, the ranks or the failing rank), never a hang.
Later checks agree on their outcome with one allreduce (``_collective``).
"""

from __future__ import annotations

import functools
import numbers
import types
from types import MappingProxyType
from typing import Any, Callable, Mapping, TypeVar

import numpy as np

from evomesh import _core
from evomesh.mesh import _MAX_COORDINATE, Mesh, _as_array, _as_tag_names, _frozen

__all__ = ["DistributedMesh", "Renumbering"]

# Records that travel between ranks, sent as raw bytes (no pickling of big arrays).
# kind 255 means "not given" (from_local without kind).
_POINT = np.dtype([("gid", "<i8"), ("xy", "<f8", (2,)), ("origin", "<i8"), ("owner", "<i4"), ("kind", "u1"),
                   ("required", "u1")])
_TRIANGLE = np.dtype([("v", "<i8", (3,)), ("owners", "<i4", (3,)), ("gid", "<i8"), ("tag", "<i8")])
_SEGMENT = np.dtype([("v", "<i8", (2,)), ("owners", "<i4", (2,)), ("gid", "<i8"), ("tag", "<i8"),
                     ("boundary", "u1")])
_UNKNOWN_KIND = 255
# Hilbert curve order of the partition: 2^21 cells a side (keys below 2^42).
_HILBERT_ORDER = 21
# Hilbert curve order of the canonical point order (docs/distributed-step.md 2.4): 2^31 cells a side.
_CANONICAL_ORDER = 31
# What rebalance's distributed sort moves per point: the sort key, the weight
# (fixed point, so prefix sums are exact) and the point's row on its sender.
_SORT_RECORD = np.dtype([("hkey", "<i8"), ("xy", "<f8", (2,)), ("gid", "<i8"), ("weight", "<i8"),
                         ("index", "<i8")])

_T = TypeVar("_T")


def _mpi() -> Any:
    try:
        from mpi4py import MPI
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError("evomesh.DistributedMesh needs mpi4py: pip install 'evomesh[mpi]' (and an MPI: the "
                          "'mpich' wheel or a system MPI)") from error
    return MPI


def _check_comm(comm: Any) -> None:
    MPI = _mpi()
    if not isinstance(comm, MPI.Intracomm):
        raise TypeError(f"comm must be an mpi4py intracommunicator (e.g. MPI.COMM_WORLD), got {type(comm).__name__}")


def _collective(comm: Any, work: Callable[..., _T], *args: Any) -> _T:
    """Run `work` on this rank, then agree across ranks: if it raised anywhere,
    every rank raises. The lowest failing rank's exception type (ValueError or
    TypeError; RuntimeError for anything else) and message, with its rank, are
    raised everywhere, so a rank never waits in a collective that a failed rank
    will not enter. Costs one allreduce (and an allgather on failure)."""
    MPI = _mpi()
    error, result = _attempt(work, *args)
    if comm.allreduce(error is not None, op=MPI.LOR):
        _raise_first(comm.allgather(_report(error)), error)
    return result


def _attempt(work: Callable[..., _T], *args: Any) -> tuple[Exception | None, Any]:
    """(None, work(*args)), or (the exception, None) when it raised."""
    try:
        return None, work(*args)
    except Exception as exc:  # noqa: BLE001 - re-raised on every rank by the caller
        return exc, None


def _report(error: Exception | None) -> tuple[str, str] | None:
    return None if error is None else (type(error).__name__, str(error))


def _raise_first(reports: list[tuple[str, str] | None], error: Exception | None) -> None:
    """Raise, on every rank alike, the failure of the lowest failing rank among
    the ranks' `reports` (None: did not fail); `error` is this rank's own."""
    failed = [rank for rank, report in enumerate(reports) if report is not None]
    if not failed:
        return
    name, message = reports[failed[0]]  # type: ignore[misc]
    kind = {"ValueError": ValueError, "TypeError": TypeError}.get(name, RuntimeError)
    also = f" (ranks {failed} failed)" if len(failed) > 1 else ""
    raise kind(f"on rank {failed[0]}: {message}{also}") from error


def _exchange(comm: Any, dest: np.ndarray, records: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Send records[i] to rank dest[i] (one Alltoall of counts, one Alltoallv of
    bytes). Returns the records received, grouped by source rank in rank order
    (each source's in the order it sent them), and the source rank of each."""
    MPI = _mpi()
    size = comm.size
    dest = np.asarray(dest, dtype=np.int64)
    order = np.argsort(dest, kind="stable")
    send = np.ascontiguousarray(records[order])
    send_counts = np.bincount(dest, minlength=size).astype(np.int64)
    recv_counts = np.empty(size, dtype=np.int64)
    comm.Alltoall(send_counts, recv_counts)
    recv = np.empty((int(recv_counts.sum()),) + records.shape[1:], dtype=records.dtype)
    item = records.dtype.itemsize * int(np.prod(records.shape[1:], dtype=np.int64))
    send_bytes, recv_bytes = send_counts * item, recv_counts * item
    comm.Alltoallv([send.view(np.uint8).reshape(-1), (send_bytes, _offsets(send_bytes)), MPI.BYTE],
                   [recv.view(np.uint8).reshape(-1), (recv_bytes, _offsets(recv_bytes)), MPI.BYTE])
    return recv, np.repeat(np.arange(size, dtype=np.int64), recv_counts)


def _offsets(counts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)


def _hilbert_keys(x: np.ndarray, y: np.ndarray, order: int) -> np.ndarray:
    """Index along the Hilbert curve of integer cells (x, y) in [0, 2^order)^2
    (the usual xy2d rotation, one bit a level; in the core, _core.hilbert_keys)."""
    return np.asarray(_core.hilbert_keys(np.ascontiguousarray(x, dtype=np.int64),
                                         np.ascontiguousarray(y, dtype=np.int64), order))


def _partition(mesh: Mesh, size: int, weights: np.ndarray) -> np.ndarray:
    """The owner rank of every point of `mesh` (the rule of DistributedMesh.scatter)."""
    triangles = mesh.triangles
    m = len(triangles)
    centroid = mesh.points[triangles].mean(axis=1)
    low = centroid.min(axis=0)
    extent = float((centroid.max(axis=0) - low).max())
    scale = ((1 << _HILBERT_ORDER) - 1) / extent if extent > 0 else 0.0
    cells = np.clip(np.floor((centroid - low) * scale), 0, (1 << _HILBERT_ORDER) - 1)
    key = _hilbert_keys(cells[:, 0], cells[:, 1], _HILBERT_ORDER)
    by_key = np.lexsort((np.arange(m), key))  # ties by triangle index: deterministic
    # A point's position: that of its first triangle along the curve.
    _, first = _first_of_each(triangles[by_key].ravel())
    point_position = first // 3
    # Each triangle's weight counts where its owner (the owner of its smallest
    # vertex) will be, so equal cuts of these weights are equal owned work.
    landing = point_position[triangles.min(axis=1)]
    mass = np.bincount(landing, weights=weights, minlength=m)
    total = float(mass.sum())
    before = np.cumsum(mass) - mass
    rank_of_position = np.minimum(np.floor(size * (before + 0.5 * mass) / total), size - 1).astype(np.int32)
    return rank_of_position[point_position]


def _index_of(sorted_gids: np.ndarray, gids: np.ndarray) -> np.ndarray:
    """Positions of `gids` in the sorted array `sorted_gids` (all present)."""
    return np.searchsorted(sorted_gids, gids)


def _contains(sorted_gids: np.ndarray, gids: np.ndarray) -> np.ndarray:
    where = np.minimum(np.searchsorted(sorted_gids, gids), max(len(sorted_gids) - 1, 0))
    return (sorted_gids[where] == gids) if len(sorted_gids) else np.zeros(len(gids), dtype=bool)


def _unique(keys: np.ndarray) -> np.ndarray:
    """Sorted distinct values (sort based: numpy's hash-based unique is slower on int64 keys here)."""
    s = np.sort(keys)
    return s[np.concatenate([[True], s[1:] != s[:-1]])] if len(s) else s


def _first_of_each(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted distinct values and the index of the first occurrence of each."""
    order = np.argsort(keys, kind="stable")
    s = keys[order]
    first = np.concatenate([[True], s[1:] != s[:-1]]) if len(s) else np.zeros(0, bool)
    return s[first], order[first]


def _ranges(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Concatenation of arange(s, s + c) over (starts, counts), vectorised."""
    total = int(counts.sum())
    shift = np.repeat(starts - _offsets(counts), counts)
    return shift + np.arange(total, dtype=np.int64)


class _Directory:
    """Incidence kept by a point's owner: the triangles around each owned point
    (its star) and the segments whose smaller-gid end it is. Answers requests
    "send me the star of gid g" in O(answer) with CSR arrays sorted by gid."""

    def __init__(self, comm: Any, owned_triangles: np.ndarray, owned_segments: np.ndarray):
        rank = comm.rank
        # Every owned triangle goes to the owners of its vertices, once per rank.
        owner = owned_triangles["owners"].astype(np.int64).reshape(-1, 3)
        first_time = np.ones(owner.shape, dtype=bool)
        first_time[:, 1] = owner[:, 1] != owner[:, 0]
        first_time[:, 2] = (owner[:, 2] != owner[:, 0]) & (owner[:, 2] != owner[:, 1])
        which, _ = np.nonzero(first_time)
        star, _ = _exchange(comm, owner[first_time], owned_triangles[which])
        mine = star["owners"] == rank
        vertex = star["v"][mine]
        triangle = np.repeat(np.arange(len(star), dtype=np.int64)[:, None], 3, axis=1)[mine]
        order = np.argsort(vertex, kind="stable")
        self.star = star
        self.star_gid, self.star_triangle = vertex[order], triangle[order]
        low_end = owned_segments["v"].min(axis=1) if len(owned_segments) else np.empty(0, np.int64)
        order = np.argsort(low_end, kind="stable")
        self.segments, self.segment_gid = owned_segments[order], low_end[order]

    def triangles_at(self, requester: np.ndarray, gids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(destination, triangle record) for the stars of `gids`, once per requester."""
        lo = np.searchsorted(self.star_gid, gids, side="left")
        hi = np.searchsorted(self.star_gid, gids, side="right")
        picks = self.star_triangle[_ranges(lo, hi - lo)]
        dest = np.repeat(requester, hi - lo)
        pair = _unique(dest * len(self.star) + picks)
        return pair // max(len(self.star), 1), self.star[pair % max(len(self.star), 1)]

    def own_stars(self, gids: np.ndarray) -> np.ndarray:
        """The triangles around owned points `gids` (no exchange), once each."""
        lo = np.searchsorted(self.star_gid, gids, side="left")
        hi = np.searchsorted(self.star_gid, gids, side="right")
        chosen = np.zeros(len(self.star), dtype=bool)  # a mask, not a sort: most of the star is chosen
        chosen[self.star_triangle[_ranges(lo, hi - lo)]] = True
        return self.star[chosen]

    def segments_at(self, requester: np.ndarray, gids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lo = np.searchsorted(self.segment_gid, gids, side="left")
        hi = np.searchsorted(self.segment_gid, gids, side="right")
        return np.repeat(requester, hi - lo), self.segments[_ranges(lo, hi - lo)]


def _ask(comm: Any, owners: np.ndarray, gids: np.ndarray,
         answer: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Request/response: send each gid to its owner, who answers with
    ``answer(requesters, gids) -> (destinations, records)``. Two exchanges."""
    asked, requester = _exchange(comm, owners, gids.astype(np.int64))
    dest, records = answer(requester, asked)
    return _exchange(comm, dest, records)[0]


def _unique_by(records: np.ndarray, key: np.ndarray) -> np.ndarray:
    _, first = _first_of_each(key)
    return records[np.sort(first)]


def _assemble(comm: Any, points: np.ndarray, owned_triangles: np.ndarray, owned_segments: np.ndarray,
              halo_rings: int) -> dict[str, np.ndarray]:
    """The local arrays of a DistributedMesh from what its owner knows: owned
    triangle and segment records (owners filled in) and point records for at
    least the owned points and the vertices of the owned triangles. Builds the
    halo by asking owners for the stars of the frontier points, ring by ring,
    and the halo exchange plan. Collective; every rank makes the same calls."""
    rank = comm.rank
    directory = _Directory(comm, owned_triangles, owned_segments)
    core = _unique(np.concatenate([points["gid"][points["owner"] == rank], owned_triangles["v"].ravel()]))
    points = _unique_by(points, points["gid"])
    points = points[np.argsort(points["gid"], kind="stable")]
    points = points[_contains(core, points["gid"])]

    def fetch(points: np.ndarray, vertex: np.ndarray, owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The records of the points `vertex` not held yet, from their owners
        (who hold their owned points); all held points, sorted by gid, and the new ones."""
        missing = ~_contains(points["gid"], vertex)
        vertex, first = _first_of_each(vertex[missing])

        def answer(requester: np.ndarray, gids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return requester, points[_index_of(points["gid"], gids)]

        new = _ask(comm, owner[missing][first], vertex, answer)
        held = np.concatenate([points, new])
        return held[np.argsort(held["gid"], kind="stable")], new

    triangles = owned_triangles
    frontier = points
    for _ in range(halo_rings):
        # Ring k: the stars of the points ring k - 1 added (ring 1: of the core).
        # Stars of owned points are known here; the others are asked for.
        own = frontier["owner"] == rank
        found = np.concatenate([directory.own_stars(frontier["gid"][own]),
                                _ask(comm, frontier["owner"][~own], frontier["gid"][~own], directory.triangles_at)])
        found = _unique_by(found, found["gid"])
        new = found[~_contains(np.sort(triangles["gid"]), found["gid"])]
        triangles = np.concatenate([triangles, new])
        points, frontier = fetch(points, new["v"].ravel(), new["owners"].ravel())
    # With no halo, an owned segment's other end may not be held yet.
    points, _ = fetch(points, owned_segments["v"].ravel(), owned_segments["owners"].ravel())
    # Segments: the owned ones and those that are an edge of a held triangle,
    # from the owners of their smaller ends.
    segments = _ask(comm, points["owner"], points["gid"], directory.segments_at)
    gid = points["gid"]
    n_held = len(gid)
    local = _index_of(gid, triangles["v"])
    edges = np.sort(np.concatenate([local[:, [0, 1]], local[:, [1, 2]], local[:, [2, 0]]]), axis=1)
    edge_key = edges[:, 0] * n_held + edges[:, 1]
    ends_held = _contains(gid, segments["v"][:, 0]) & _contains(gid, segments["v"][:, 1])
    segments = segments[ends_held]
    ends = np.sort(_index_of(gid, segments["v"]), axis=1)
    owned_segment = segments["owners"][np.arange(len(segments)), np.argmin(segments["v"], axis=1)] == rank \
        if len(segments) else np.empty(0, bool)
    segments = segments[_contains(_unique(edge_key), ends[:, 0] * n_held + ends[:, 1]) | owned_segment]

    # Local order: owned points by gid, then halo points by gid.
    owned = points["owner"] == rank
    points = np.concatenate([points[owned], points[~owned]])
    order_gid = np.argsort(points["gid"], kind="stable")
    sorted_gid = points["gid"][order_gid]

    def to_local(v: np.ndarray) -> np.ndarray:
        return order_gid[_index_of(sorted_gid, v)].astype(np.int64)

    triangle_owner = triangles["owners"][np.arange(len(triangles)), np.argmin(triangles["v"], axis=1)] \
        if len(triangles) else np.empty(0, np.int32)
    is_owned_triangle = triangle_owner == rank
    low = segments["v"].min(axis=1) if len(segments) else np.empty(0, np.int64)
    low_owner = points["owner"][to_local(low)] if len(low) else np.empty(0, np.int32)
    parts: dict[str, np.ndarray] = {"points": points}
    for prefix, records, mask in (("", triangles, is_owned_triangle), ("halo_", triangles, ~is_owned_triangle)):
        chosen = records[mask]
        chosen = chosen[np.argsort(chosen["gid"], kind="stable")]
        parts[prefix + "triangles"] = to_local(chosen["v"]).reshape(-1, 3)
        parts[prefix + "triangle_global_ids"] = chosen["gid"]
        parts[prefix + "triangle_tags"] = chosen["tag"]
    for prefix, mask in (("", low_owner == rank), ("halo_", low_owner != rank)):
        chosen = segments[mask]
        chosen = chosen[np.argsort(chosen["gid"], kind="stable")]
        parts[prefix + "segments"] = to_local(chosen["v"]).reshape(-1, 2)
        parts[prefix + "segment_global_ids"] = chosen["gid"]
        parts[prefix + "segment_tags"] = chosen["tag"]
        parts[prefix + "segment_is_boundary"] = chosen["boundary"]
    # Halo exchange plan: each halo point asks its owner once; the owner keeps
    # which of its points to send to whom, in the order asked.
    n_owned = int(owned.sum())
    halo = np.arange(n_owned, len(points), dtype=np.int64)
    halo = halo[np.argsort(points["owner"][halo], kind="stable")]
    asked, requester = _exchange(comm, points["owner"][halo], points["gid"][halo])
    parts["send_index"] = to_local(asked)
    parts["send_counts"] = np.bincount(requester, minlength=comm.size).astype(np.int64)
    parts["recv_positions"] = halo
    parts["recv_counts"] = np.bincount(points["owner"][halo], minlength=comm.size).astype(np.int64)
    parts["n_owned"] = np.int64(n_owned)
    return parts


def _integer_array(values: Any, name: str, shape_tail: tuple[int, ...]) -> np.ndarray:
    array = _as_array(values, name)
    if array.size == 0:
        array = array.reshape((0,) + shape_tail)
    if array.dtype == object or array.dtype.kind not in "iu":
        if not (array.size == 0 and array.dtype.kind == "f"):
            raise TypeError(f"{name} must be an integer array, got dtype {array.dtype}")
    if array.ndim != 1 + len(shape_tail) or array.shape[1:] != shape_tail:
        raise ValueError(f"{name} must have shape (k, {', '.join(map(str, shape_tail))}), got {array.shape}"
                         if shape_tail else f"{name} must be one-dimensional, got shape {array.shape}")
    if array.dtype.kind == "u" and array.size and array.max() > np.iinfo(np.int64).max:
        raise ValueError(f"{name} must fit in int64")
    return array.astype(np.int64)


def _per_row(values: Any, name: str, rows: int, what: str) -> np.ndarray:
    array = _integer_array(values, name, ())
    if len(array) != rows:
        raise ValueError(f"{name} must have one entry per {what}: shape ({rows},), got {array.shape}")
    return array


def _unique_within(values: np.ndarray, name: str) -> None:
    if len(values) > 1:
        s = np.sort(values)
        repeated = np.flatnonzero(s[1:] == s[:-1])
        if len(repeated):
            raise ValueError(f"{name} are not unique on this rank: {int(s[repeated[0]])} appears more than once")


def _check_local(points: Any, triangles: Any, global_ids: Any, size: int, owners: Any, segments: Any,
                 segment_tags: Any, triangle_tags: Any, required: Any, kind: Any, origin: Any, tag_names: Any,
                 triangle_global_ids: Any, segment_global_ids: Any) -> dict[str, Any]:
    """from_local's checks of one rank's arrays (no communication)."""
    pts = _as_array(points, "points")
    if pts.size == 0:
        pts = pts.reshape(0, 2)
    if pts.dtype == object or pts.dtype.kind not in "fiu":
        raise TypeError(f"points must be a real numeric array, got dtype {pts.dtype}")
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must have shape (n, 2), got {pts.shape}")
    with np.errstate(over="ignore"):
        pts = pts.astype(np.float64)
    finite = np.isfinite(pts).all(axis=1)
    if not finite.all():
        raise ValueError(f"points contain NaN or infinite coordinates (first at row {int(np.argmin(finite))})")
    if pts.size and np.abs(pts).max() > _MAX_COORDINATE:
        raise ValueError(f"point coordinates must be below {_MAX_COORDINATE:g} in magnitude")
    n = len(pts)
    gids = _per_row(global_ids, "global_ids", n, "point")
    if (gids < 0).any():
        raise ValueError(f"global_ids must be >= 0, got {int(gids.min())}")
    _unique_within(gids, "global_ids")
    tris = _integer_array(triangles, "triangles", (3,))
    if tris.size and (tris.min() < 0 or tris.max() >= n):
        bad = int(np.argmax(((tris < 0) | (tris >= n)).any(axis=1)))
        raise ValueError(f"triangles row {bad} has a point index out of range [0, {n})")
    s = np.sort(tris, axis=1)
    repeated = (s[:, 0] == s[:, 1]) | (s[:, 1] == s[:, 2])
    if repeated.any():
        raise ValueError(f"triangle {int(np.argmax(repeated))} repeats a vertex (zero area)")
    # Counter-clockwise, as in Mesh (exact sign for these double products is not
    # needed here: gather's Mesh checks areas and flatness exactly). Each row is
    # read from its least global id on, so copies of a triangle on
    # different ranks, in any rotation, compute the same products and take the
    # same orientation (a reversed copy gets exactly the negated area).
    start = np.argmin(gids[tris], axis=1)
    p = pts[np.take_along_axis(tris, (start[:, None] + np.arange(3)[None, :]) % 3, axis=1)]
    twice_area = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    if (twice_area == 0).any():
        raise ValueError(f"triangle {int(np.argmax(twice_area == 0))} has zero area")
    tris = np.where((twice_area < 0)[:, None], tris[:, [0, 2, 1]], tris)
    own = None if owners is None else _per_row(owners, "owners", n, "point")
    if own is not None and own.size and (own.min() < 0 or own.max() >= size):
        raise ValueError(f"owners must be ranks in [0, {size}), got {int(own.min())}..{int(own.max())}")
    segs = np.empty((0, 2), np.int64) if segments is None else _integer_array(segments, "segments", (2,))
    if segs.size and (segs.min() < 0 or segs.max() >= n):
        bad = int(np.argmax(((segs < 0) | (segs >= n)).any(axis=1)))
        raise ValueError(f"segments row {bad} has a point index out of range [0, {n})")
    if (segs[:, 0] == segs[:, 1]).any():
        raise ValueError(f"segment {int(np.argmax(segs[:, 0] == segs[:, 1]))} has equal ends")
    if segment_tags is not None and segments is None:
        raise ValueError("segment_tags need segments: one tag per row of segments")
    seg_tags = np.zeros(len(segs), np.int64) if segment_tags is None else \
        _per_row(segment_tags, "segment_tags", len(segs), "segment")
    tri_tags = np.zeros(len(tris), np.int64) if triangle_tags is None else \
        _per_row(triangle_tags, "triangle_tags", len(tris), "triangle")
    req = np.zeros(n, bool)
    if required is not None:
        req = _as_array(required, "required")
        if req.dtype != bool:
            raise TypeError(f"required must be a boolean array (one flag per point), got dtype {req.dtype}")
        if req.shape != (n,):
            raise ValueError(f"required must have one flag per point: shape ({n},), got {req.shape}")
    kinds = np.full(n, _UNKNOWN_KIND, np.int64) if kind is None else _per_row(kind, "kind", n, "point")
    if kind is not None and kinds.size and (kinds.min() < 0 or kinds.max() > 4):
        raise ValueError("kind values must be PointKind values 0..4")
    org = np.full(n, -1, np.int64) if origin is None else _per_row(origin, "origin", n, "point")
    if (org < -1).any():
        raise ValueError("origin values must be point indices >= 0, or -1 for a new point")
    tgids = None if triangle_global_ids is None else \
        _per_row(triangle_global_ids, "triangle_global_ids", len(tris), "triangle")
    sgids = None if segment_global_ids is None else \
        _per_row(segment_global_ids, "segment_global_ids", len(segs), "segment")
    for name, ids in (("triangle_global_ids", tgids), ("segment_global_ids", sgids)):
        if ids is not None:
            if (ids < 0).any():
                raise ValueError(f"{name} must be >= 0")
            _unique_within(ids, name)
    return {"points": pts, "gids": gids, "triangles": tris, "owners": own, "segments": segs,
            "segment_tags": seg_tags, "triangle_tags": tri_tags, "required": req, "kind": kinds, "origin": org,
            "tag_names": _as_tag_names(tag_names), "triangle_global_ids": tgids, "segment_global_ids": sgids,
            "given": (own is not None, kind is not None, tgids is not None, sgids is not None)}


def _check_halo_rings(halo_rings: Any) -> int:
    if isinstance(halo_rings, bool) or not isinstance(halo_rings, (int, np.integer)) or halo_rings < 0:
        raise ValueError(f"halo_rings must be an integer >= 0, got {halo_rings!r}")
    return int(halo_rings)


def _check_root(comm: Any, root: Any) -> int:
    if isinstance(root, bool) or not isinstance(root, (int, np.integer)) or not 0 <= root < comm.size:
        raise ValueError(f"root must be a rank in [0, {comm.size}), got {root!r}")
    return int(root)


def _same_everywhere(comm: Any, call: str, fingerprints: dict[str, str] | Callable[[], dict[str, str]],
                     prepare: Callable[[], _T] | None = None) -> _T:
    """The first collective of every collective call (DistributedMesh's
    methods, :func:`evomesh.evolve` and the transfers on a DistributedMesh):
    the ranks agree that they are in the same `call` with the same arguments
    before any work, so that none goes on into collectives that the others do
    not make (a hang) or into a result that no serial call gives.

    `fingerprints` are this rank's arguments that must agree, by name, as short
    canonical texts (:func:`_fingerprint`: values of small arguments, the kind
    of per-point ones; never big arrays), or a function that makes them.
    `prepare`, run here on every rank, checks and converts this rank's
    arguments; its result is returned. One allgather of (call, fingerprints,
    this rank's failure), then the same verdict on every rank: ranks in
    different calls, else an argument that differs (ValueError naming the
    argument, and the ranks with each value), else a failure of `prepare` or
    of the fingerprints' function (raised everywhere as :func:`_collective`
    raises it).
    """
    error, texts = (None, fingerprints) if isinstance(fingerprints, dict) else _attempt(fingerprints)
    result = None
    if error is None and prepare is not None:
        error, result = _attempt(prepare)
    every = comm.allgather((call, texts, _report(error)))  # (texts None: their function failed)
    calls = [theirs[0] for theirs in every]
    if len(set(calls)) > 1:
        raise ValueError(f"the ranks are in different collective calls: {_by_rank(calls)}; every rank must make "
                         "the same collective calls in the same order") from error
    if all(theirs[1] is not None for theirs in every):
        for name in dict.fromkeys(name for theirs in every for name in theirs[1]):
            values = [theirs[1].get(name, _NOT_GIVEN) for theirs in every]
            if len(set(values)) > 1:
                raise ValueError(f"{call}: {name} must be the same on every rank: {_by_rank(values)}") from error
    _raise_first([theirs[2] for theirs in every], error)
    return result  # type: ignore[return-value]


_NOT_GIVEN = "not given"


def _fingerprint(value: Any, per_point: bool = False) -> str:
    """A short text of an argument that must be the same on every rank, equal
    for equal arguments on any rank: numbers, strings and short tuples of them
    by value, ``None`` as "not given", anything else by its type. With
    `per_point` (delta, size: values over the owned points, or one number, or a
    function of the owned coordinates) only the kind, and a number's value.
    Never raises."""
    try:
        return _fingerprint_of(value, per_point)
    except Exception:  # noqa: BLE001 - (a number float() cannot take, a repr that raises): its type
        return f"a {type(value).__name__}"


def _fingerprint_of(value: Any, per_point: bool) -> str:
    if value is None:
        return _NOT_GIVEN
    if isinstance(value, (bool, np.bool_)):
        return repr(bool(value))
    if isinstance(value, numbers.Integral):
        return repr(int(value))
    if isinstance(value, numbers.Real):  # (1.0 as 1: the same number as an int or a float)
        number = float(value)
        return repr(int(number)) if number.is_integer() else repr(number)
    if isinstance(value, str):
        return repr(value)
    if per_point:
        if isinstance(value, np.ndarray) and value.ndim == 0:
            return _fingerprint(value[()])
        if isinstance(value, (np.ndarray, list, tuple)):
            return "an array"
    elif isinstance(value, (tuple, list)) and len(value) <= 8:
        return "(" + ", ".join(_fingerprint(v) for v in value) + ")"
    elif isinstance(value, np.ndarray) and value.ndim == 1 and len(value) <= 8:
        return _fingerprint(tuple(value.tolist()))
    if isinstance(value, (types.FunctionType, types.BuiltinFunctionType, types.MethodType, functools.partial)):
        return "a function"
    name = type(value).__name__
    return f"{'an' if name[:1] in 'AEIOUaeiou' else 'a'} {name}"


def _by_rank(values: list[str]) -> str:
    """'a on ranks 0, 2; b on rank 1': each value and the ranks that have it."""
    groups: dict[str, list[int]] = {}
    for rank, value in enumerate(values):
        groups.setdefault(value, []).append(rank)
    shown = [f"{value} on {_ranks_text(ranks)}" for value, ranks in list(groups.items())[:4]]
    if len(groups) > 4:
        shown.append(f"{len(groups) - 4} other values on the other ranks")
    return "; ".join(shown)


def _ranks_text(ranks: list[int]) -> str:
    if len(ranks) == 1:
        return f"rank {ranks[0]}"
    listed = ", ".join(map(str, ranks[:6]))
    return f"ranks {listed}" + (f", ... ({len(ranks)} ranks)" if len(ranks) > 6 else "")


def _numbered(records: np.ndarray, key: np.ndarray, comm: Any) -> np.ndarray:
    """Give records (this rank's owned ones) gids: by rank, then by `key` rows
    (lexicographic), from an exclusive scan of the counts."""
    MPI = _mpi()
    order = np.lexsort(key.T[::-1]) if len(key) else np.empty(0, np.int64)
    records = records[order]
    start = comm.exscan(len(records), op=MPI.SUM) or 0
    records["gid"] = start + np.arange(len(records), dtype=np.int64)
    return records


def _canonical(v: np.ndarray) -> np.ndarray:
    """Vertex gids rotated so the smallest comes first (orientation kept)."""
    shift = np.argmin(v, axis=1)
    idx = (shift[:, None] + np.arange(v.shape[1])[None, :]) % v.shape[1]
    return np.take_along_axis(v, idx, axis=1)


def _field_rows(comm: Any, values: Any, rows: int, name: str, what: str = "owned point") -> np.ndarray:
    """`values` as an array of `rows` rows, checked to have the same dtype and
    trailing shape on every rank (else every rank raises). Collective."""

    def check() -> np.ndarray:
        array = np.asarray(values)
        if array.dtype == object:
            raise TypeError(f"{name} must be a numeric array, got dtype object")
        if array.ndim < 1 or len(array) != rows:
            raise ValueError(f"{name} must have one row per {what}: shape ({rows}, ...), got {array.shape}")
        return np.ascontiguousarray(array)

    array = _collective(comm, check)
    layouts = comm.allgather((array.dtype.str, array.shape[1:]))

    def agree() -> None:
        for r, layout in enumerate(layouts):
            if layout != layouts[0]:
                raise ValueError(f"{name} has dtype {layout[0]} and row shape {layout[1]} on rank {r} but "
                                 f"{layouts[0][0]} and {layouts[0][1]} on rank 0")

    _collective(comm, agree)
    return array


class Renumbering:
    """What :meth:`DistributedMesh.rebalance` returns with ``return_map=True``
    beside the new mesh: where this rank's owned entities came from, and a way
    to move values along. Immutable.

    Attributes
    ----------
    points : ndarray of int64, shape (n_owned,)
        ``points[i]`` is the gid, in the mesh ``rebalance`` was called on, of
        the new mesh's owned point ``i`` (``new.global_ids[i]`` now).
    triangles : ndarray of int64, shape (m_owned,)
        Old gid of each owned triangle, in the order of ``new.triangles``.
    segments : ndarray of int64, shape (k_owned,)
        Old gid of each owned segment, in the order of ``new.segments``.
    """

    __slots__ = ("points", "triangles", "segments", "_comm", "_point_dest", "_old_point_gids", "_triangle_dest",
                 "_old_triangle_gids")

    points: np.ndarray
    triangles: np.ndarray
    segments: np.ndarray
    _comm: Any
    # Where each old owned point / triangle was sent, and its old gid (the sender's side of a move).
    _point_dest: np.ndarray
    _old_point_gids: np.ndarray
    _triangle_dest: np.ndarray
    _old_triangle_gids: np.ndarray

    def __init__(self, comm: Any, points: np.ndarray, triangles: np.ndarray, segments: np.ndarray,
                 sent: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]):
        set_ = object.__setattr__
        set_(self, "_comm", comm)
        for name, value in (("points", points), ("triangles", triangles), ("segments", segments),
                            ("_point_dest", sent[0]), ("_old_point_gids", sent[1]), ("_triangle_dest", sent[2]),
                            ("_old_triangle_gids", sent[3])):
            set_(self, name, _frozen(np.asarray(value, dtype=np.int64)))

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("Renumbering is immutable")

    def __repr__(self) -> str:
        return (f"Renumbering(rank={self._comm.rank}, points={len(self.points)}, triangles={len(self.triangles)}, "
                f"segments={len(self.segments)})")

    def _move(self, values: Any, dest: np.ndarray, old_gids: np.ndarray, new_rows: np.ndarray,
              what: str) -> np.ndarray:
        comm = self._comm
        _same_everywhere(comm, f"Renumbering.move_{what}_values", {})
        array = _field_rows(comm, values, len(dest), "values", f"owned {what} of the mesh before rebalance")
        record = np.dtype([("gid", "<i8"), ("value", array.dtype, array.shape[1:])])
        rows = np.empty(len(array), record)
        rows["gid"], rows["value"] = old_gids, array
        rows = _exchange(comm, dest, rows)[0]
        rows = rows[np.argsort(rows["gid"], kind="stable")]
        return np.ascontiguousarray(rows["value"][_index_of(rows["gid"], new_rows)])

    def move_point_values(self, values: Any) -> np.ndarray:
        """Values over the old mesh's owned points, moved to the new owners. Collective.

        Parameters
        ----------
        values : array_like, shape (old n_owned, ...)
            One row per owned point of the mesh ``rebalance`` was called on, in
            its order; any dtype and row shape, the same on every rank.

        Returns
        -------
        ndarray, shape (new n_owned, ...)
            The rows in the new mesh's owned point order (one Alltoallv).
        """
        return self._move(values, self._point_dest, self._old_point_gids, self.points, "point")

    def move_triangle_values(self, values: Any) -> np.ndarray:
        """Values over the old mesh's owned triangles, moved to the new owners. Collective.

        Parameters
        ----------
        values : array_like, shape (old m_owned, ...)
            One row per owned triangle of the old mesh, in its order.

        Returns
        -------
        ndarray, shape (new m_owned, ...)
            The rows in the order of the new mesh's ``triangles``.
        """
        return self._move(values, self._triangle_dest, self._old_triangle_gids, self.triangles, "triangle")


def _point_weights(weights: Any, owned_points: np.ndarray) -> np.ndarray:
    """rebalance's weights on this rank: one finite value >= 0 per owned point."""
    n = len(owned_points)
    if weights is None:
        return np.ones(n)
    name = "weights"
    if callable(weights):
        weights, name = weights(owned_points), "weights(owned_points)"
    w = _as_array(weights, name)
    if w.dtype == object or w.dtype.kind not in "fiub":
        raise TypeError(f"{name} must be a real array, got dtype {w.dtype}")
    if w.shape != (n,):
        raise ValueError(f"{name} must have one value per owned point: shape ({n},), got {w.shape}")
    w = w.astype(np.float64)
    finite = np.isfinite(w)
    if not finite.all():
        raise ValueError(f"{name} must be finite (owned point {int(np.argmin(finite))} has {w[~finite][0]})")
    if (w < 0).any():
        raise ValueError(f"{name} must be >= 0 (owned point {int(np.argmax(w < 0))} has {w[w < 0][0]})")
    return w


def _sort_order(records: np.ndarray) -> np.ndarray:
    """The order of sort records by (Hilbert key, x, y, gid): a total order (gids are unique)."""
    return np.lexsort((records["gid"], records["xy"][:, 1], records["xy"][:, 0], records["hkey"]))


def _bucket_of(records: np.ndarray, splitters: np.ndarray) -> np.ndarray:
    """For each record, the number of splitters not after it in the sort order."""
    both = np.concatenate([records[["hkey", "xy", "gid"]], splitters[["hkey", "xy", "gid"]]])
    is_splitter = np.r_[np.zeros(len(records), bool), np.ones(len(splitters), bool)]
    # A splitter equal to a record (the sampled record itself) sorts before it.
    order = np.lexsort((~is_splitter, both["gid"], both["xy"][:, 1], both["xy"][:, 0], both["hkey"]))
    below = np.cumsum(is_splitter[order])
    bucket = np.empty(len(records), np.int64)
    is_record = ~is_splitter[order]
    bucket[order[is_record]] = below[is_record]
    return bucket


def _hilbert_cut(comm: Any, xy: np.ndarray, gids: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """rebalance's cut of the points (this rank's owned `xy`, `gids`, `weights`).

    Returns each point's position in the global order by (Hilbert key over the
    global bounding box, x, y, gid) and the rank whose range it falls in: ranges
    of equal weight, a point in the range of its weight's midpoint. The order
    is found by a sample sort (regular samples, allgathered splitters; each rank
    then holds a contiguous run of the order, sorts it and numbers it by an
    Exscan). Weights are made fixed point (a multiple of max weight / 2^b, b as
    large as int64 prefix sums allow) so the prefix sums are exact: the result
    depends on the global point set only, not on which rank held what."""
    MPI = _mpi()
    size = comm.size
    n = len(xy)
    total = comm.allreduce(n, op=MPI.SUM)
    if total == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    # One allreduce: the bounding box and the largest weight (signs flipped for MIN).
    extremes = np.full(5, np.inf)
    if n:
        extremes[:2], extremes[2:4], extremes[4] = xy.min(axis=0), -xy.max(axis=0), -weights.max()
    comm.Allreduce(MPI.IN_PLACE, extremes, op=MPI.MIN)
    low, high, largest = extremes[:2], -extremes[2:4], -float(extremes[4])
    if not largest > 0:
        raise ValueError("weights are all zero: their sum over the ranks must be positive")
    # Quantised as in _partition, over the points' bounding box (square cells).
    extent = float((high - low).max())
    top = (1 << _CANONICAL_ORDER) - 1
    scale = top / extent if extent > 0 else 0.0
    cells = np.clip(np.floor((xy - low) * scale), 0, top)
    bits = min(52, 62 - total.bit_length())  # total weight < 2^62: 2 * prefix + weight fits in int64
    records = np.empty(n, _SORT_RECORD)
    records["hkey"] = _hilbert_keys(cells[:, 0], cells[:, 1], _CANONICAL_ORDER)
    records["xy"], records["gid"], records["index"] = xy, gids, np.arange(n)
    records["weight"] = np.floor(weights / largest * 2.0 ** bits + 0.5)
    records = records[_sort_order(records)]
    # Regular samples, about 2 * size per rank on average, in proportion to the
    # rank's share: each run between splitters then holds at most about
    # 1.5 total / size + size points, whatever the input partition.
    samples_here = -(-2 * size * size * n // total)
    picks = ((np.arange(samples_here) + 0.5) * n / max(samples_here, 1)).astype(np.int64)
    samples = np.concatenate(comm.allgather(records[picks]))
    samples = samples[_sort_order(samples)]
    splitters = samples[(np.arange(1, size) * len(samples)) // size]
    run, source = _exchange(comm, _bucket_of(records, splitters), records)
    order = _sort_order(run)
    run, source = run[order], source[order]
    # Positions and prefix weights: Exscans over the runs (Python ints: exact).
    first = comm.exscan(len(run), op=MPI.SUM) or 0
    weight_here = int(run["weight"].sum())
    weight_before = comm.exscan(weight_here, op=MPI.SUM) or 0
    weight_total = comm.allreduce(weight_here, op=MPI.SUM)
    w = run["weight"]
    twice_middle = 2 * (weight_before + np.cumsum(w) - w) + w
    # Rank r takes the points whose weight midpoint lies in [r, r + 1) * total / size.
    starts = np.array([-(-r * 2 * weight_total // size) for r in range(size)], dtype=np.int64)
    rank = np.searchsorted(starts, twice_middle, side="right") - 1
    answer = np.stack([run["index"], first + np.arange(len(run)), rank], axis=1)
    answer = _exchange(comm, source, answer)[0]
    position, owner = np.empty(n, np.int64), np.empty(n, np.int64)
    position[answer[:, 0]], owner[answer[:, 0]] = answer[:, 1], answer[:, 2]
    return position, owner


class DistributedMesh:
    """This rank's part of a triangle mesh distributed over an MPI communicator; immutable.

    Build one with :meth:`scatter` (a :class:`~evomesh.Mesh` on one rank) or
    :meth:`from_local` (pieces already on every rank); :meth:`gather` gives the
    Mesh back. Arrays are read-only; local point indices index ``points``.

    :meth:`rebalance` gives the same mesh in the canonical layout a distributed
    step returns: points cut into ``comm.size`` equal-weight ranges along a
    Hilbert curve and (by default) renumbered along it, triangles and segments
    renumbered in their vertex gid order, halo rebuilt. It depends on the
    global mesh only, not on the partition it is called on, so any pieces
    (``from_local`` of a caller's own cut, a rank owning everything) become
    the same balanced mesh; its :class:`Renumbering` moves fields along.

    Attributes
    ----------
    comm : mpi4py.MPI.Intracomm
        The communicator.
    points : ndarray, shape (n_local, 2)
        The points this rank holds: its ``n_owned`` owned points first, then
        the halo points, each group sorted by global id.
    n_owned : int
        Number of owned points.
    global_ids : ndarray of int64, shape (n_local,)
        Global id of each local point (for a scattered mesh: its index in the
        serial mesh).
    owners : ndarray of int32, shape (n_local,)
        Owner rank of each local point (this rank for the first ``n_owned``).
    triangles : ndarray of int64, shape (m_owned, 3)
        Owned triangles (owned by the owner of their smallest-gid vertex), local
        point indices, counter-clockwise, sorted by triangle global id.
    triangle_global_ids, triangle_tags : ndarray of int64, shape (m_owned,)
    halo_triangles : ndarray of int64, shape (m_halo, 3)
        The triangles of the halo: ``halo_rings`` rings of triangles around the
        owned points and the vertices of owned triangles (ring 1: every
        triangle with a vertex there), that other ranks own.
    halo_triangle_global_ids, halo_triangle_tags : ndarray of int64, shape (m_halo,)
    segments : ndarray of int64, shape (k_owned, 2)
        Owned segments (owned by the owner of their smaller-gid end), local
        indices, orientation as given.
    segment_global_ids, segment_tags : ndarray of int64, shape (k_owned,)
    halo_segments, halo_segment_global_ids, halo_segment_tags
        The other segments that are an edge of a held triangle.
    required : ndarray of bool, shape (n_local,)
    kind : ndarray of uint8, shape (n_local,), or None
        :class:`~evomesh.PointKind` per local point; None when :meth:`from_local`
        was not given kinds (gather then computes them).
    origin : ndarray of int64, shape (n_local,)
    tag_names : mapping, the same on every rank.
    halo_rings : int
    lineage : DistributedLineage or None
        For the mesh ``evomesh.evolve`` returns: where its owned points lie in
        the mesh the step started from (old triangles by global id; nn and f
        at the old points). :meth:`gather` gives the serial
        :class:`~evomesh.Lineage`. None for a mesh made by :meth:`scatter` or
        :meth:`from_local`; :meth:`rebalance` moves it along.
    """

    __slots__ = ("comm", "points", "n_owned", "global_ids", "owners", "triangles", "triangle_global_ids",
                 "triangle_tags", "halo_triangles", "halo_triangle_global_ids", "halo_triangle_tags", "segments",
                 "segment_global_ids", "segment_tags", "halo_segments", "halo_segment_global_ids",
                 "halo_segment_tags", "required", "kind", "origin", "tag_names", "halo_rings", "lineage", "_send_index",
                 "_send_counts", "_recv_positions", "_recv_counts", "_segment_is_boundary", "_trusted")

    comm: Any
    points: np.ndarray
    n_owned: int
    global_ids: np.ndarray
    owners: np.ndarray
    triangles: np.ndarray
    triangle_global_ids: np.ndarray
    triangle_tags: np.ndarray
    halo_triangles: np.ndarray
    halo_triangle_global_ids: np.ndarray
    halo_triangle_tags: np.ndarray
    segments: np.ndarray
    segment_global_ids: np.ndarray
    segment_tags: np.ndarray
    halo_segments: np.ndarray
    halo_segment_global_ids: np.ndarray
    halo_segment_tags: np.ndarray
    required: np.ndarray
    kind: np.ndarray | None
    origin: np.ndarray
    tag_names: Mapping[tuple[int, int], str]
    halo_rings: int
    lineage: Any  # DistributedLineage | None (distributed/lineage.py)
    _send_index: np.ndarray  # owned points to send in a halo exchange, grouped by destination rank
    _send_counts: np.ndarray
    _recv_positions: np.ndarray  # halo positions the received values go to, grouped by source rank
    _recv_counts: np.ndarray
    # Set by scatter: the pieces of a valid Mesh, gathered without re-validation
    # (and with the Mesh's own segment order and boundary flags).
    _segment_is_boundary: np.ndarray
    _trusted: bool

    def __init__(self, *args: Any, **kwargs: Any):
        raise TypeError("make a DistributedMesh with DistributedMesh.scatter(mesh, comm) or "
                        "DistributedMesh.from_local(points, triangles, global_ids, comm)")

    @classmethod
    def _build(cls, comm: Any, parts: dict[str, np.ndarray], tag_names: Mapping[tuple[int, int], str],
               kind_known: bool, halo_rings: int, trusted: bool = False) -> DistributedMesh:
        self = object.__new__(cls)
        set_ = object.__setattr__
        points = parts["points"]
        set_(self, "comm", comm)
        set_(self, "points", _frozen(np.ascontiguousarray(points["xy"])))
        set_(self, "n_owned", int(parts["n_owned"]))
        set_(self, "global_ids", _frozen(points["gid"].astype(np.int64)))
        set_(self, "owners", _frozen(points["owner"].astype(np.int32)))
        set_(self, "required", _frozen(points["required"].astype(bool)))
        set_(self, "kind", _frozen(points["kind"].astype(np.uint8)) if kind_known else None)
        set_(self, "origin", _frozen(points["origin"].astype(np.int64)))
        for name in ("triangles", "triangle_global_ids", "triangle_tags", "halo_triangles",
                     "halo_triangle_global_ids", "halo_triangle_tags", "segments", "segment_global_ids",
                     "segment_tags", "halo_segments", "halo_segment_global_ids", "halo_segment_tags"):
            set_(self, name, _frozen(np.asarray(parts[name], dtype=np.int64)))
        set_(self, "tag_names", MappingProxyType(dict(tag_names)))
        set_(self, "halo_rings", int(halo_rings))
        set_(self, "lineage", None)
        set_(self, "_segment_is_boundary", _frozen(parts["segment_is_boundary"].astype(bool)))
        set_(self, "_trusted", bool(trusted))
        for name in ("send_index", "send_counts", "recv_positions", "recv_counts"):
            set_(self, "_" + name, _frozen(np.asarray(parts[name], dtype=np.int64)))
        return self

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("DistributedMesh is immutable")

    def __copy__(self) -> DistributedMesh:
        return self  # immutable

    def __deepcopy__(self, memo: dict) -> DistributedMesh:
        return self

    def __reduce__(self):
        raise TypeError("a DistributedMesh belongs to its communicator and cannot be pickled; gather() it")

    def __repr__(self) -> str:
        return (f"DistributedMesh(rank={self.comm.rank}/{self.comm.size}, owned_points={self.n_owned}, "
                f"halo_points={len(self.points) - self.n_owned}, owned_triangles={len(self.triangles)}, "
                f"halo_triangles={len(self.halo_triangles)})")

    @property
    def owned_points(self) -> np.ndarray:
        """Coordinates of the owned points, shape (n_owned, 2): ``points[:n_owned]``."""
        return self.points[: self.n_owned]

    @property
    def n_local(self) -> int:
        """Number of points held (owned and halo)."""
        return len(self.points)

    # ------------------------------------------------------------------ scatter
    @classmethod
    def scatter(cls, mesh: Mesh | None, comm: Any, root: int = 0, *, weights: Any = None,
                halo_rings: int = 1) -> DistributedMesh:
        """Partition a Mesh held by `root` over the ranks of `comm`. Collective.

        The partition follows a Hilbert curve through the triangle centroids
        (quantised to 2^21 cells a side over their bounding box; ties by
        triangle index). A point's position on the curve is that of its first
        triangle; the positions are cut into ``comm.size`` contiguous ranges of
        equal weight and a point is owned by the rank of its range. A triangle
        is owned by the owner of its smallest-gid vertex, a segment by the owner
        of its smaller-gid end. Each triangle's weight is counted at the
        position its owner is decided by (that of its smallest vertex), so the
        owned weight per rank is equal up to a few triangles. Global ids are
        the serial indices in `mesh`. Deterministic: the same mesh and size
        give the same partition.

        Parameters
        ----------
        mesh : Mesh or None
            The mesh on `root`; ignored elsewhere (pass None).
        comm : mpi4py.MPI.Intracomm
        root : int, optional
            The rank holding `mesh`.
        weights : array_like of float, shape (n_triangles,), optional (root)
            Work per triangle, non-negative and finite with a positive sum.
            Default 1 each (equal triangle counts). For a step, the expected
            work is the number of points it creates in each triangle plus one:
            ``mesh.triangle_areas() / size**2 + 1`` with ``size`` the target edge
            length at the centroid (the ``size=`` of :func:`evomesh.evolve`; for
            ``delta``: ``size = delta * nn_spacing`` averaged over the vertices).
        halo_rings : int, optional
            Rings of halo triangles (default 1; 0: none). The same on every rank.

        Returns
        -------
        DistributedMesh
            This rank's part.

        Raises
        ------
        TypeError, ValueError
            On every rank, when any rank's arguments are bad (`mesh` not a Mesh
            on root, bad weights, root or halo_rings).
        """
        _check_comm(comm)
        size, rank = comm.size, comm.rank

        def prepare() -> tuple[int, int, Any]:
            r = _check_root(comm, root)
            h = _check_halo_rings(halo_rings)
            if rank != r:
                return r, h, None
            if not isinstance(mesh, Mesh):
                raise TypeError(f"mesh on the root must be an evomesh.Mesh, got {type(mesh).__name__}")
            m = mesh.n_triangles
            if weights is None:
                w = np.ones(m)
            else:
                w = _as_array(weights, "weights")
                if w.dtype == object or w.dtype.kind not in "fiub":
                    raise TypeError(f"weights must be a real array, got dtype {w.dtype}")
                w = w.astype(np.float64)
                if w.shape != (m,):
                    raise ValueError(f"weights must have one value per triangle: shape ({m},), got {w.shape}")
                if not np.isfinite(w).all() or (w < 0).any():
                    raise ValueError("weights must be finite and >= 0")
                if not w.sum() > 0:
                    raise ValueError("weights must have a positive sum")
            return r, h, _root_records(mesh, size, w)

        root_, rings, records = _same_everywhere(
            comm, "DistributedMesh.scatter", {"root": _fingerprint(root), "halo_rings": _fingerprint(halo_rings)},
            prepare)
        if rank == root_:
            (point_dest, point_records), (tri_dest, tri_records), (seg_dest, seg_records) = records
            tag_names: Any = dict(mesh.tag_names)  # type: ignore[union-attr]
        else:
            point_dest, tri_dest, seg_dest = (np.empty(0, np.int64),) * 3
            point_records, tri_records = np.empty(0, _POINT), np.empty(0, _TRIANGLE)
            seg_records = np.empty(0, _SEGMENT)
            tag_names = None
        tag_names = comm.bcast(tag_names, root=root_)
        points = _exchange(comm, point_dest, point_records)[0]
        triangles = _exchange(comm, tri_dest, tri_records)[0]
        segments = _exchange(comm, seg_dest, seg_records)[0]
        parts = _assemble(comm, points, triangles, segments, rings)
        return cls._build(comm, parts, tag_names, True, rings, trusted=True)

    # --------------------------------------------------------------- from_local
    @classmethod
    def from_local(cls, points: Any, triangles: Any, global_ids: Any, comm: Any, owners: Any = None,
                   segments: Any = None, *, segment_tags: Any = None, triangle_tags: Any = None,
                   required: Any = None, kind: Any = None, origin: Any = None, tag_names: Any = None,
                   triangle_global_ids: Any = None, segment_global_ids: Any = None,
                   halo_rings: int = 1) -> DistributedMesh:
        """A DistributedMesh from pieces that already live on the ranks. Collective.

        Each rank passes some points (with their global ids) and some triangles
        and segments over them; a point, triangle or segment may be given on
        several ranks (a halo of the caller's own), and must then agree. The
        union over ranks is the global mesh.

        Parameters
        ----------
        points : array_like, shape (n, 2)
            This rank's points (finite).
        triangles : array_like of int, shape (m, 3)
            Triangles over them (local indices, either orientation; stored
            counter-clockwise).
        global_ids : array_like of int, shape (n,)
            Global id of each point: >= 0, unique on the rank; the same point on
            two ranks has the same id and the same coordinates. ``gather`` orders
            the points by global id (the ids need not be contiguous).
        comm : mpi4py.MPI.Intracomm
        owners : array_like of int, shape (n,), optional
            Owner rank of each point; every rank holding a point must name the
            same owner, and the owner must hold it. Default: the lowest rank
            that holds the point.
        segments : array_like of int, shape (k, 2), optional
            Constraint segments (local indices).
        segment_tags, triangle_tags, required, kind, origin : optional
            As in :class:`~evomesh.Mesh`, per row / per point.
        tag_names : mapping, optional
            As in Mesh; the same on every rank.
        triangle_global_ids, segment_global_ids : array_like of int, optional
            Ids that fix the order ``gather`` returns. Default: numbered by
            owner rank, then by their vertex gids (triangles rotated to start at
            their smallest gid): the canonical order when each rank owns a
            contiguous range of point gids in rank order.
        halo_rings : int, optional
            Rings of halo triangles (default 1).

        Raises
        ------
        TypeError, ValueError
            On every rank when the input of any rank is bad: wrong shapes or
            dtypes, NaN or infinite coordinates, repeated global ids, indices
            out of range, owners out of range or inconsistent, the same global
            id with different coordinates or labels on two ranks, arguments
            given on some ranks only. The message names the rank.
        """
        _check_comm(comm)
        size = comm.size
        def prepare() -> tuple[dict[str, Any], int]:
            return (_check_local(points, triangles, global_ids, size, owners, segments, segment_tags, triangle_tags,
                                 required, kind, origin, tag_names, triangle_global_ids, segment_global_ids),
                    _check_halo_rings(halo_rings))

        local, rings = _same_everywhere(comm, "DistributedMesh.from_local",
                                        {"halo_rings": _fingerprint(halo_rings)}, prepare)
        given = comm.allgather((local["given"], sorted(local["tag_names"].items())))

        def agree() -> None:
            names = ("owners", "kind", "triangle_global_ids", "segment_global_ids")
            for r, (flags, tag_items) in enumerate(given):
                for name, here, there in zip(names, given[0][0], flags):
                    if here != there:
                        raise ValueError(f"{name} is given on rank {0 if here else r} but not on rank "
                                         f"{r if here else 0}: give it on every rank or on none")
                if tag_items != given[0][1]:
                    raise ValueError(f"tag_names differ between rank 0 and rank {r}")

        _collective(comm, agree)
        gids = local["gids"]
        records = np.empty(len(gids), _POINT)
        records["gid"], records["xy"], records["origin"] = gids, local["points"], local["origin"]
        records["kind"], records["required"] = local["kind"], local["required"]
        records["owner"] = -1 if local["owners"] is None else local["owners"]
        # Directory by gid % size: checks that copies agree and decides owners.
        held, holder = _exchange(comm, gids % size, records)
        owner_of = _collective(comm, _decide_owners, held, holder, local["owners"] is not None)
        answer, _ = _exchange(comm, holder, np.stack([held["gid"], owner_of], axis=1).astype(np.int64))
        order = np.argsort(answer[:, 0])
        records["owner"] = answer[order, 1][_index_of(answer[order, 0], gids)] if len(gids) else records["owner"]
        owner = records["owner"]
        # Triangles and segments go to their owners, who keep one copy of each.
        v = gids[local["triangles"]]
        tri = np.empty(len(v), _TRIANGLE)
        tri["v"], tri["owners"], tri["tag"] = v, owner[local["triangles"]], local["triangle_tags"]
        tri["gid"] = -1 if local["triangle_global_ids"] is None else local["triangle_global_ids"]
        tri_owner = tri["owners"][np.arange(len(v)), np.argmin(v, axis=1)] if len(v) else np.empty(0, np.int32)
        tri, _ = _exchange(comm, tri_owner, tri)
        sv = gids[local["segments"]]
        seg = np.empty(len(sv), _SEGMENT)
        seg["v"], seg["tag"], seg["boundary"] = sv, local["segment_tags"], 0
        seg["owners"] = owner[local["segments"]]
        seg["gid"] = -1 if local["segment_global_ids"] is None else local["segment_global_ids"]
        seg_owner = owner[local["segments"]][np.arange(len(sv)), np.argmin(sv, axis=1)] if len(sv) \
            else np.empty(0, np.int32)
        seg, _ = _exchange(comm, seg_owner, seg)
        tri, seg = _collective(comm, _deduplicate, tri, seg)
        if local["triangle_global_ids"] is None:
            tri = _numbered(tri, _canonical(tri["v"]), comm)
        if local["segment_global_ids"] is None:
            seg = _numbered(seg, np.sort(seg["v"], axis=1), comm)
        # Point records of the vertices of owned triangles: asked from their owners.
        tri_vertex, first = _first_of_each(tri["v"].ravel())
        sorted_gids = np.sort(gids)
        mine_sorted = records[np.argsort(gids)]

        def point_records(requester: np.ndarray, asked: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return requester, mine_sorted[_index_of(sorted_gids, asked)]

        vertex_owner = tri["owners"].ravel()[first]
        vertices = _ask(comm, vertex_owner, tri_vertex, point_records)
        pts = np.concatenate([records[records["owner"] == comm.rank], vertices])
        parts = _assemble(comm, pts, tri, seg, rings)
        return cls._build(comm, parts, local["tag_names"], local["given"][1], rings)

    # ------------------------------------------------------------------ gather
    def gather(self, root: int = 0) -> Mesh | None:
        """The whole mesh on `root` (None on the other ranks). Collective.

        Points are in global-id order (for a scattered mesh: exactly the input
        mesh's order), triangles and segments in the order of their global ids
        (a scattered mesh: the input's order and rotation, so the Mesh equals
        the input array for array, without validating it again). A mesh
        assembled by :meth:`from_local` is built by the :class:`Mesh`
        constructor, so it is validated here (O(n log n) on the root) and gets
        the constructor's segment order; its ``origin`` is the per-point
        ``origin`` carried along (not renumbered).

        Raises
        ------
        ValueError
            On every rank, if the assembled mesh is not valid (the Mesh
            constructor's message) or root is bad.

        The Mesh of a step's output (``evomesh.evolve`` on a DistributedMesh)
        carries its lineage (``Mesh.lineage``, from ``self.lineage``) with old
        points and triangles numbered as in the old mesh's ``gather``.
        """
        comm = self.comm
        root_ = _same_everywhere(comm, "DistributedMesh.gather", {"root": _fingerprint(root)},
                                 lambda: _check_root(comm, root))
        owned = slice(0, self.n_owned)
        points = np.empty(self.n_owned, _POINT)
        points["gid"], points["xy"] = self.global_ids[owned], self.points[owned]
        points["origin"], points["required"] = self.origin[owned], self.required[owned]
        points["kind"] = _UNKNOWN_KIND if self.kind is None else self.kind[owned]
        points["owner"] = comm.rank
        tri = np.empty(len(self.triangles), _TRIANGLE)
        tri["v"], tri["gid"], tri["tag"] = self.global_ids[self.triangles], self.triangle_global_ids, \
            self.triangle_tags
        tri["owners"] = comm.rank
        seg = np.empty(len(self.segments), _SEGMENT)
        seg["v"], seg["gid"], seg["tag"] = self.global_ids[self.segments], self.segment_global_ids, self.segment_tags
        seg["boundary"] = self._segment_is_boundary
        seg["owners"] = self.owners[self.segments]
        points = _exchange(comm, np.full(len(points), root_), points)[0]
        tri = _exchange(comm, np.full(len(tri), root_), tri)[0]
        seg = _exchange(comm, np.full(len(seg), root_), seg)[0]
        kind_known = self.kind is not None
        lineage = None if self.lineage is None else self.lineage._gather(comm, self.global_ids[owned], root_)

        def build() -> Mesh | None:
            if comm.rank != root_:
                return None
            pts = points[np.argsort(points["gid"], kind="stable")]
            t = tri[np.argsort(tri["gid"], kind="stable")]
            s = seg[np.argsort(seg["gid"], kind="stable")]
            gids = pts["gid"]
            if self._trusted:  # the pieces of a valid Mesh: its arrays exactly, no second validation
                return Mesh._trusted(pts["xy"], _index_of(gids, t["v"]), _index_of(gids, s["v"]),
                                     s["boundary"].astype(bool), pts["kind"], pts["origin"], lineage=lineage,
                                     segment_tags=s["tag"],
                                     triangle_tags=t["tag"], required=pts["required"].astype(bool),
                                     tag_names=self.tag_names)
            return Mesh(pts["xy"], _index_of(gids, t["v"]), _index_of(gids, s["v"]), segment_tags=s["tag"],
                        triangle_tags=t["tag"], required=pts["required"].astype(bool),
                        kind=pts["kind"] if kind_known else None, origin=pts["origin"], tag_names=self.tag_names)

        return _collective(comm, build)

    # ---------------------------------------------------------------- rebalance
    def rebalance(self, weights: Any = None, *, renumber: bool = True, halo_rings: int | None = None,
                  return_map: bool = False) -> Any:
        """The same mesh, cut into equal-weight ranges along a Hilbert curve. Collective.

        The points are ordered along a Hilbert curve over their global bounding
        box (2^31 cells a side, square cells; ties by exact (x, y), then by
        global id), and the order is cut into ``comm.size`` contiguous ranges
        of equal weight: rank r owns the points whose weight midpoint lies in
        the r-th ``1 / size`` of the total weight. A triangle is then owned by
        the owner of its smallest-gid vertex, a segment by the owner of its
        smaller-gid end, and the halo is rebuilt. The result is a function of
        the global mesh only: the same owned sets, gids and halos whatever
        partition the mesh had (the order is found by a distributed sample sort
        and the weights' prefix sums are exact, see below); no rank ever holds
        a global array.

        This is the canonical output order of a distributed step
        (docs/distributed-step.md, 2.4). With ``renumber=True`` (default):

        - point gids become positions in that order (``Exscan`` of the counts
          plus the local position), so rank r owns a contiguous gid range and
          ranks follow each other along the curve;
        - each triangle is rotated to start at its smallest gid (still
          counter-clockwise) and the triangle gids are the positions of the
          triangles in (g0, g1, g2) order;
        - segment gids are the positions of the segments in (smaller gid,
          larger gid) order; segment orientation is kept;
        - ``origin`` is carried along unchanged (it maps to the gids of the
          mesh a step started from, not to the gids before rebalancing; ask
          for ``return_map`` for those).

        With ``renumber=False`` every gid and every triangle's rotation is
        kept and only the owners change, so :meth:`gather` returns exactly the
        same Mesh as before. Coordinates, tags, ``required``, ``kind`` and
        ``tag_names`` are kept in both cases.

        Balance. With unit weights the owned point counts differ by at most one
        between ranks. With weights, every rank's owned weight is within the
        largest single weight of ``total / size`` (the first and last point of
        each range straddle its ends by at most half their weight each). The
        weights are used in fixed point: each is rounded to a multiple of
        ``max(weights) * 2**-b`` with ``b = min(52, 62 - N.bit_length())`` for
        ``N`` points in all (b = 42 for a million points), so that the
        prefix sums are exact integers; a weight below ``max(weights) * 2**-(b+1)``
        counts as zero.

        Parameters
        ----------
        weights : array_like of float, shape (n_owned,), or callable, optional
            Work per owned point: finite and >= 0, not all zero over the ranks.
            A callable is called with ``owned_points`` (shape (n_owned, 2)) and
            must return such an array. Default 1 each (equal point counts).
        renumber : bool, optional
            Renumber points, triangles and segments into the canonical order
            (default True); False keeps every gid.
        halo_rings : int, optional
            Rings of halo triangles of the result; default ``self.halo_rings``.
            The same on every rank.
        return_map : bool, optional
            Also return a :class:`Renumbering`: the old gids of this rank's
            owned points, triangles and segments in the new mesh, and
            ``move_point_values`` / ``move_triangle_values`` to carry fields
            over the old owned rows to the new ones.

        Returns
        -------
        DistributedMesh, or (DistributedMesh, Renumbering) with ``return_map``

        Raises
        ------
        TypeError, ValueError
            On every rank, when the weights on any rank are bad (wrong length,
            dtype, NaN or infinite, negative; all zero everywhere), or
            ``renumber``, ``halo_rings`` or ``return_map`` are bad or differ
            between ranks. A callable's own exception is raised everywhere too
            (a RuntimeError when it is not a ValueError or TypeError).

        Examples
        --------
        Pieces cut by the caller (say x-stripes) made canonical, and a point
        field over the old owned points moved along::

            d = DistributedMesh.from_local(points, triangles, gids, comm)
            e, renumbering = d.rebalance(return_map=True)
            e.partition_stats()["point_balance"]    # owned counts differ by one at most
            u_new = renumbering.move_point_values(u)  # u: shape (d.n_owned, ...)
        """
        comm = self.comm
        n_owned = self.n_owned

        def prepare() -> tuple[int, bool, bool, np.ndarray]:
            rings = self.halo_rings if halo_rings is None else _check_halo_rings(halo_rings)
            for name, flag in (("renumber", renumber), ("return_map", return_map)):
                if not isinstance(flag, (bool, np.bool_)):
                    raise TypeError(f"{name} must be True or False, got {flag!r}")
            return rings, bool(renumber), bool(return_map), _point_weights(weights, self.owned_points)

        rings, renumber_, return_map_, w = _same_everywhere(
            comm, "DistributedMesh.rebalance", {name: _fingerprint(value) for name, value in (
                ("renumber", renumber), ("halo_rings", halo_rings), ("return_map", return_map))}, prepare)
        wanted_map = return_map_
        # A step's output carries its lineage (rows per owned point): it moves along.
        return_map_ = return_map_ or self.lineage is not None
        old_owned = self.global_ids[:n_owned]
        position, owner_owned = _hilbert_cut(comm, self.owned_points, old_owned, w)
        gid_owned = position if renumber_ else old_owned
        # Every held point's new gid and owner, from its old owner.
        both = self.exchange_halo(np.stack([gid_owned, owner_owned], axis=1))
        gid, owner = both[:, 0], both[:, 1]
        n_local = len(gid)
        points = np.empty(n_local, _POINT)
        points["gid"], points["xy"], points["origin"], points["owner"] = gid, self.points, self.origin, owner
        points["kind"] = _UNKNOWN_KIND if self.kind is None else self.kind
        points["required"] = self.required
        tri = np.empty(len(self.triangles), _TRIANGLE)
        local = self.triangles
        if renumber_ and len(local):  # rotated to start at the smallest new gid (a rotation keeps CCW)
            shift = np.argmin(gid[local], axis=1)
            local = np.take_along_axis(local, (shift[:, None] + np.arange(3)[None, :]) % 3, axis=1)
        tri["v"], tri["owners"], tri["gid"], tri["tag"] = gid[local], owner[local], self.triangle_global_ids, \
            self.triangle_tags
        tri_owner = owner[local][np.arange(len(local)), np.argmin(gid[local], axis=1)] if len(local) \
            else np.empty(0, np.int64)
        seg = np.empty(len(self.segments), _SEGMENT)
        seg["v"], seg["owners"], seg["gid"] = gid[self.segments], owner[self.segments], self.segment_global_ids
        seg["tag"], seg["boundary"] = self.segment_tags, self._segment_is_boundary
        seg_owner = owner[self.segments][np.arange(len(seg)), np.argmin(seg["v"], axis=1)] if len(seg) \
            else np.empty(0, np.int64)
        # Owned points to their new owners; the vertices of each triangle owned
        # elsewhere to the triangle's new owner (few: along the new cuts).
        vertex, dest = local.ravel(), np.repeat(tri_owner, 3)
        across = owner[vertex] != dest
        pair = _unique(dest[across] * n_local + vertex[across])
        points_dest = np.concatenate([owner[:n_owned], pair // max(n_local, 1)])
        points = _exchange(comm, points_dest, points[np.concatenate([np.arange(n_owned), pair % max(n_local, 1)])])[0]
        tri = _exchange(comm, tri_owner, tri)[0]
        seg = _exchange(comm, seg_owner, seg)[0]
        old_point_gids = _exchange(comm, owner_owned, np.stack([gid_owned, old_owned], axis=1))[0] \
            if return_map_ and renumber_ else None
        if renumber_:
            tri = tri[np.lexsort(tri["v"].T[::-1])] if len(tri) else tri
            old_triangle_gids = tri["gid"].copy()
            tri = _numbered(tri, tri["v"], comm)  # already in key order: this numbers them
            seg_key = np.sort(seg["v"], axis=1)
            order = np.lexsort(seg_key.T[::-1]) if len(seg) else np.empty(0, np.int64)
            seg, seg_key = seg[order], seg_key[order]
            old_segment_gids = seg["gid"].copy()
            seg = _numbered(seg, seg_key, comm)
        parts = _assemble(comm, points, tri, seg, rings)
        result = self._build(comm, parts, self.tag_names, self.kind is not None, rings,
                             trusted=self._trusted and not renumber_)
        if not return_map_:
            return result
        sent = (owner_owned, old_owned, tri_owner, self.triangle_global_ids)
        if not renumber_:
            renumbering = Renumbering(comm, result.global_ids[: result.n_owned], result.triangle_global_ids,
                                      result.segment_global_ids, sent)
        else:
            assert old_point_gids is not None
            old_point_gids = old_point_gids[np.argsort(old_point_gids[:, 0])]
            renumbering = Renumbering(
                comm, old_point_gids[_index_of(old_point_gids[:, 0], result.global_ids[: result.n_owned]), 1],
                old_triangle_gids[_index_of(tri["gid"], result.triangle_global_ids)],
                old_segment_gids[_index_of(seg["gid"], result.segment_global_ids)], sent)
        if self.lineage is not None:
            object.__setattr__(result, "lineage", self.lineage._moved(renumbering))
        return (result, renumbering) if wanted_map else result

    # ------------------------------------------------------------ point fields
    def _field(self, values: Any, name: str) -> np.ndarray:
        """values over the owned points, checked to have the same dtype and
        trailing shape on every rank."""
        return _field_rows(self.comm, values, self.n_owned, name)

    def exchange_halo(self, values: Any) -> np.ndarray:
        """Values on every local point from values on the owned points. Collective.

        Parameters
        ----------
        values : array_like, shape (n_owned, ...)
            Any dtype and row shape, the same on every rank.

        Returns
        -------
        ndarray, shape (n_local, ...)
            ``values`` on the owned points, the owners' values on the halo
            points (one Alltoallv with the neighbours; the plan is made once).
        """
        _same_everywhere(self.comm, "DistributedMesh.exchange_halo", {})
        return self._halo_rows(self._field(values, "values"))

    def _halo_rows(self, array: np.ndarray) -> np.ndarray:
        """exchange_halo without its per-call checks: `array` (n_owned, ...),
        contiguous, the same dtype and row shape on every rank (callers that
        checked a field once reuse this)."""
        MPI = _mpi()
        row = int(np.prod(array.shape[1:], dtype=np.int64)) * array.itemsize
        out = np.empty((len(self.points),) + array.shape[1:], dtype=array.dtype)
        out[: self.n_owned] = array
        send = np.ascontiguousarray(array[self._send_index])
        received = np.empty((int(self._recv_counts.sum()),) + array.shape[1:], dtype=array.dtype)
        send_bytes, recv_bytes = self._send_counts * row, self._recv_counts * row
        self.comm.Alltoallv([send.view(np.uint8).reshape(-1), (send_bytes, _offsets(send_bytes)), MPI.BYTE],
                            [received.view(np.uint8).reshape(-1), (recv_bytes, _offsets(recv_bytes)), MPI.BYTE])
        out[self._recv_positions] = received
        return out

    def gather_field(self, values: Any, root: int = 0) -> np.ndarray | None:
        """Values over the owned points gathered on `root`, in the point order of
        :meth:`gather` (global-id order); None on the other ranks. Collective.

        Parameters
        ----------
        values : array_like, shape (n_owned, ...)
        root : int, optional
        """
        comm = self.comm
        root_ = _same_everywhere(comm, "DistributedMesh.gather_field", {"root": _fingerprint(root)},
                                 lambda: _check_root(comm, root))
        array = self._field(values, "values")
        record = np.dtype([("gid", "<i8"), ("value", array.dtype, array.shape[1:])])
        rows = np.empty(len(array), record)
        rows["gid"], rows["value"] = self.global_ids[: self.n_owned], array
        rows = _exchange(comm, np.full(len(rows), root_), rows)[0]
        if comm.rank != root_:
            return None
        return np.ascontiguousarray(rows["value"][np.argsort(rows["gid"], kind="stable")])

    def partition_stats(self) -> dict[str, Any]:
        """Counts per rank and the load balance, the same on every rank. Collective.

        Returns
        -------
        dict
            ``owned_points``, ``halo_points``, ``owned_triangles``,
            ``halo_triangles`` (int64 arrays of shape (size,)), and
            ``point_balance``, ``triangle_balance``: the largest owned count
            over the mean (1.0 is perfect).
        """
        _same_everywhere(self.comm, "DistributedMesh.partition_stats", {})
        counts = np.array([self.n_owned, len(self.points) - self.n_owned, len(self.triangles),
                           len(self.halo_triangles)], dtype=np.int64)
        every = np.empty((self.comm.size, 4), dtype=np.int64)
        self.comm.Allgather(counts, every)
        stats: dict[str, Any] = {name: every[:, k].copy() for k, name in
                                 enumerate(("owned_points", "halo_points", "owned_triangles", "halo_triangles"))}
        for name, column in (("point_balance", 0), ("triangle_balance", 2)):
            mean = every[:, column].mean()
            stats[name] = float(every[:, column].max() / mean) if mean > 0 else 1.0
        return stats


def _root_records(mesh: Mesh, size: int, weights: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """On the root of scatter: (destination, record) for points, triangles and segments."""
    owner = _partition(mesh, size, weights)
    n = mesh.n_points
    points = np.empty(n, _POINT)
    points["gid"] = np.arange(n)
    points["xy"], points["origin"], points["owner"] = mesh.points, mesh.origin, owner
    points["kind"], points["required"] = mesh.kind, mesh.required
    triangles = mesh.triangles
    tri = np.empty(len(triangles), _TRIANGLE)
    tri["v"], tri["owners"], tri["gid"], tri["tag"] = triangles, owner[triangles], np.arange(len(triangles)), \
        mesh.triangle_tags
    tri_owner = owner[triangles.min(axis=1)]
    seg = np.empty(len(mesh.segments), _SEGMENT)
    seg["v"], seg["gid"], seg["tag"] = mesh.segments, np.arange(len(mesh.segments)), mesh.segment_tags
    seg["owners"] = owner[mesh.segments]
    seg["boundary"] = mesh.segment_is_boundary
    seg_owner = owner[mesh.segments.min(axis=1)]
    # Each rank gets its owned points and the vertices of its owned triangles
    # that other ranks own (few: along the cuts).
    vertex, dest = triangles.ravel(), np.repeat(tri_owner.astype(np.int64), 3)
    across = owner[vertex] != dest
    pair = _unique(dest[across] * n + vertex[across])
    dest = np.concatenate([owner.astype(np.int64), pair // n])
    return (dest, points[np.concatenate([np.arange(n), pair % n])]), (tri_owner, tri), (seg_owner, seg)


def _decide_owners(held: np.ndarray, holder: np.ndarray, owners_given: bool) -> np.ndarray:
    """The directory's work in from_local: for the copies of each gid it keeps
    (one row per holder), check they agree and name the owner. Returns the
    owner per row."""
    order = np.lexsort((holder, held["gid"]))
    h, src = held[order], holder[order]
    start = np.ones(len(h), dtype=bool)
    start[1:] = h["gid"][1:] != h["gid"][:-1]
    group = np.cumsum(start) - 1
    first = np.flatnonzero(start)
    for field in ("xy", "origin", "kind", "required"):
        a, b = h[field], h[field][first][group]
        differ = (a != b).reshape(len(h), int(np.prod((a != b).shape[1:]))).any(axis=1)  # (also with no rows)
        if differ.any():
            k = int(np.argmax(differ))
            raise ValueError(f"point with global id {int(h['gid'][k])} has different {field} on rank "
                             f"{int(src[first[group[k]]])} and rank {int(src[k])}")
    if owners_given:
        named = h["owner"][first][group]
        differ = h["owner"] != named
        if differ.any():
            k = int(np.argmax(differ))
            raise ValueError(f"point with global id {int(h['gid'][k])} has owner {int(named[k])} on rank "
                             f"{int(src[first[group[k]]])} but owner {int(h['owner'][k])} on rank {int(src[k])}")
        holds = np.zeros(len(first), dtype=bool)
        np.logical_or.at(holds, group, src == h["owner"])
        if not holds.all():
            k = int(first[np.argmin(holds)])
            raise ValueError(f"point with global id {int(h['gid'][k])} is owned by rank {int(h['owner'][k])}, "
                             "which does not hold it")
        owner = named
    else:
        owner = src[first][group]  # the lowest rank holding the point
    result = np.empty(len(h), dtype=np.int64)
    result[order] = owner
    return result


def _deduplicate(tri: np.ndarray, seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One copy of each triangle (same vertex set) and segment (same ends) an
    owner received; copies must agree on tag and global id."""
    out = []
    for records, what in ((tri, "triangle"), (seg, "segment")):
        key = np.sort(records["v"], axis=1)
        order = np.lexsort(key.T[::-1]) if len(key) else np.empty(0, np.int64)
        r, k = records[order], key[order]  # stable: copies in the order received
        same = (k[1:] == k[:-1]).all(axis=1) if len(k) else np.empty(0, bool)
        for field in ("tag", "gid"):
            clash = same & (r[field][1:] != r[field][:-1])
            if clash.any():
                i = int(np.argmax(clash))
                raise ValueError(f"{what} with vertex global ids {tuple(int(x) for x in k[i])} is given with "
                                 f"different {field}s ({int(r[field][i])} and {int(r[field][i + 1])})")
        keep = np.ones(len(r), dtype=bool)
        keep[1:] = ~same
        out.append(records[np.sort(order[keep])])  # the first copy received (lowest rank)
    return out[0], out[1]
