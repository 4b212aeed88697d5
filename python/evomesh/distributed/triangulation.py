"""The constrained Delaunay triangulation of points and pieces owned by MPI
ranks (docs/distributed-step.md, section 3.5): every rank returns the
triangles whose least global id it owns, and together they are exactly the
serial ``constrained_delaunay`` of all the points and pieces (inside the domain
the boundary pieces bound), on any number of ranks.

Why it is exact. CGAL decides cocircular points by a symbolic perturbation in
(x, y) order, so the CDT's triangle set is a function of its points and pieces,
and whether a triangle belongs to it depends only on the points and pieces that
meet its closed circumdisc (the locality lemma of section 3.5). A rank holds
its own points plus every point and piece within a *reach* of each chunk of
its points (_halo.py: complete by construction). A local triangle whose
circumdisc lies within that reach of the chunk of one of its own vertices is
certified: it is a global triangle. Around an owned point v, when every local
triangle at v is certified and v's fan is closed (or its open edges support the
global convex hull, checked exactly against every rank's extreme points), the
local fan is the global one, so the rank has every triangle it owns. Where that
fails, the chunk's reach widens (to the failing circumdiscs, at least fourfold)
and the rank asks again; the loop ends when no rank fails (an allreduce), at
the latest when a reach covers the whole domain.

The domain labels (inside / outside the pieces' domain, holes kept) come from
the pieces' sides as in the serial fill, over the certified triangles only
(joined across unconstrained edges into components, scipy's connected
components), and components with no seed of their own take their label from
other ranks' copies of the same triangles, in rounds; what no seed reaches is
inside, as in the serial fill where every piece is an edge.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .. import _core
from . import _halo
from .mesh import _check_comm, _collective, _exchange, _mpi

__all__ = ["constrained_delaunay"]

_POINT = np.dtype([("gid", "<i8"), ("x", "<f8"), ("y", "<f8"), ("owner", "<i4")])
_PIECE = np.dtype([("a", _POINT), ("b", _POINT), ("boundary", "u1")])
_LABEL = np.dtype([("key", "<i8", (3,)), ("label", "u1")])
_INSIDE, _OUTSIDE = 1, 2
# Initial reach of a chunk, in units of its mean spacing: most fans certify at once.
_FIRST_REACH = 4.0
_SLACK = 1e-9


def _check(points: Any, global_ids: Any, pieces: Any, boundary: Any) -> tuple[np.ndarray, ...]:
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1:] != (2,) or not np.issubdtype(p.dtype, np.number):
        raise ValueError(f"points must be a numeric (n, 2) array, got shape {p.shape}")
    p = np.ascontiguousarray(p, dtype=np.float64)
    if not np.isfinite(p).all():
        raise ValueError("points must be finite")
    g = np.asarray(global_ids)
    if g.shape != (len(p),) or not np.issubdtype(g.dtype, np.integer) or (len(g) and g.min() < 0):
        raise ValueError(f"global_ids must be non-negative integers, one per point (shape ({len(p)},))")
    e = np.asarray(pieces)
    if e.size == 0:
        e = np.zeros((0, 2), np.int64)
    if e.ndim != 2 or e.shape[1:] != (2,) or not np.issubdtype(e.dtype, np.integer):
        raise ValueError(f"pieces must be an integer (k, 2) array of global ids, got shape {e.shape}")
    b = np.asarray(boundary)
    if b.shape != (len(e),) or b.dtype != bool:
        raise ValueError(f"boundary must be a boolean array with one value per piece (shape ({len(e)},))")
    if len(e) and (e[:, 0] == e[:, 1]).any():
        raise ValueError("a piece joins a point to itself")
    return p, g.astype(np.int64), e.astype(np.int64), b


def _lookup(comm: Any, records: np.ndarray, gids: np.ndarray, what: str = "piece end") -> np.ndarray:
    """The point records (gid, x, y, owner, and any further fields) of `gids`, from the directory rank gid % P
    (three exchanges, made on every rank whatever it finds, so that a failure here
    never leaves another rank waiting); ValueError for a repeated gid or a gid
    that is no rank's point."""
    size = comm.size
    problem = ""
    directory, _ = _exchange(comm, records["gid"] % size, records)
    directory = directory[np.argsort(directory["gid"], kind="stable")]
    repeated = directory["gid"][1:][directory["gid"][1:] == directory["gid"][:-1]]
    if len(repeated):
        problem = f"global id {int(repeated[0])} is given by two points (global ids must be unique over all ranks)"
    asks, asker = _exchange(comm, gids % size, np.ascontiguousarray(gids))
    at = np.minimum(np.searchsorted(directory["gid"], asks), max(len(directory) - 1, 0))
    found = (directory["gid"][at] == asks) if len(directory) else np.zeros(len(asks), bool)
    answer = np.zeros(len(asks), dtype=records.dtype)
    answer["gid"] = asks
    answer["owner"] = -1
    answer[found] = directory[at[found]]
    back, _ = _exchange(comm, asker, answer)
    # (answers come back grouped by directory rank; match them to the questions by gid)
    back = back[np.argsort(back["gid"], kind="stable")]
    out = back[np.searchsorted(back["gid"], gids)] if len(gids) else back[:0]
    if problem:
        raise ValueError(problem)
    if (out["owner"] < 0).any():
        raise ValueError(f"{what} {int(out['gid'][out['owner'] < 0][0])} is no rank's point")
    return out


def _circumcircles(xy: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a, b, c = xy[triangles[:, 0]], xy[triangles[:, 1]], xy[triangles[:, 2]]
    bx, by = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    cx, cy = c[:, 0] - a[:, 0], c[:, 1] - a[:, 1]
    d = 2 * (bx * cy - by * cx)
    lb, lc = bx * bx + by * by, cx * cx + cy * cy
    with np.errstate(divide="ignore", invalid="ignore"):
        ox, oy = (cy * lb - by * lc) / d, (bx * lc - cx * lb) / d
    centre = np.stack([a[:, 0] + ox, a[:, 1] + oy], axis=1)
    radius = np.hypot(ox, oy)
    radius[~np.isfinite(radius)] = np.inf  # (a flat face never certifies)
    return centre, radius


def constrained_delaunay(comm: Any, points: Any, global_ids: Any, pieces: Any, boundary: Any,
                         stats: dict[str, Any] | None = None) -> np.ndarray:
    """This rank's share of the constrained Delaunay triangulation of every
    rank's points and pieces: the triangles inside the domain whose least global
    id is one of this rank's points.

    Parameters
    ----------
    comm : mpi4py intracommunicator
    points : (n, 2) float array, this rank's points
    global_ids : (n,) non-negative integers, unique over all ranks
    pieces : (k, 2) integer array of global ids
        Constraint segments (any rank may give a piece, each once); a boundary
        piece has the domain on the left of a -> b, an interior one on both sides.
    boundary : (k,) bool
    stats : dict, optional
        Filled with "widenings" (rounds of reach widening), "label_rounds",
        "halo_points" and "halo_pieces" (copies held, summed over ranks) and
        "bytes" (halo and label records sent, summed over ranks).

    Returns
    -------
    (m, 3) int64 array of global ids: counter-clockwise, each rotated to start at
    its least id, rows sorted. The union over ranks is the serial
    ``constrained_delaunay`` of all points and pieces.
    """
    _check_comm(comm)
    MPI = _mpi()
    rank, size = comm.rank, comm.size
    xy, gid, piece_gids, piece_boundary = _collective(comm, _check, points, global_ids, pieces, boundary)
    n = len(xy)
    own = np.zeros(n, dtype=_POINT)
    own["gid"], own["x"], own["y"], own["owner"] = gid, xy[:, 0], xy[:, 1], rank
    ends = _collective(comm, _lookup, comm, own, piece_gids.reshape(-1))

    def check_unique_pieces() -> np.ndarray:
        # Each piece once: sent to the owner of its smaller end, which keeps one copy.
        records = np.zeros(len(piece_gids), dtype=_PIECE)
        records["a"], records["b"] = ends[0::2], ends[1::2]
        records["boundary"] = piece_boundary
        low = np.where(records["a"]["gid"] < records["b"]["gid"], records["a"]["owner"], records["b"]["owner"])
        got, _ = _exchange(comm, low, records)
        key = np.sort(np.stack([got["a"]["gid"], got["b"]["gid"]], axis=1), axis=1)
        order = np.lexsort((key[:, 1], key[:, 0]))
        same = (key[order][1:] == key[order][:-1]).all(axis=1)
        if same.any():
            raise ValueError(f"the piece {tuple(int(v) for v in key[order][1:][same][0])} is given twice")
        return got

    my_pieces = _collective(comm, check_unique_pieces)

    # Chunks of this rank's points (and of its pieces, by midpoint) along a Hilbert curve.
    big = np.finfo(np.float64).max
    lo = np.array([comm.allreduce(float(xy[:, k].min()) if n else big, op=MPI.MIN) for k in (0, 1)])
    hi = np.array([comm.allreduce(float(xy[:, k].max()) if n else -big, op=MPI.MAX) for k in (0, 1)])
    span = float(max(hi - lo)) if (hi >= lo).all() else 0.0
    magnitude = float(max(np.abs(lo).max(), np.abs(hi).max())) if (hi >= lo).all() else 0.0
    perm, starts = _halo.hilbert_chunks(own["x"], own["y"], lo, span)
    own = own[perm]
    box = _halo.chunk_boxes(own["x"], own["y"], starts)
    counts = np.diff(np.append(starts, n))
    area = (box[:, 1] - box[:, 0]) * (box[:, 3] - box[:, 2])
    side = np.maximum(box[:, 1] - box[:, 0], box[:, 3] - box[:, 2])
    spacing = np.where(area > 0, np.sqrt(np.maximum(area, 0) / np.maximum(counts, 1)), side / np.maximum(counts, 1))
    reach = np.maximum(_FIRST_REACH * spacing, 1e-9 * max(span, magnitude, 1e-300))
    chunk_of = np.repeat(np.arange(len(starts)), counts)
    mid_x = 0.5 * (my_pieces["a"]["x"] + my_pieces["b"]["x"])
    mid_y = 0.5 * (my_pieces["a"]["y"] + my_pieces["b"]["y"])
    half = 0.5 * np.hypot(my_pieces["b"]["x"] - my_pieces["a"]["x"], my_pieces["b"]["y"] - my_pieces["a"]["y"])
    piece_perm, piece_starts = _halo.hilbert_chunks(mid_x, mid_y, lo, span)
    my_pieces, mid_x, mid_y, half = my_pieces[piece_perm], mid_x[piece_perm], mid_y[piece_perm], half[piece_perm]
    piece_box = _halo.chunk_boxes(mid_x, mid_y, piece_starts)

    # Every rank's extreme points: the global hull is supported by a line iff they all are.
    hull = xy[_core.convex_hull_vertices(xy)] if n else np.zeros((0, 2))
    extreme = np.concatenate(comm.allgather(hull))

    n_total = comm.allreduce(n, op=MPI.SUM)
    k_total = comm.allreduce(len(my_pieces), op=MPI.SUM)
    sent_points = np.zeros((n, size), dtype=bool)
    sent_pieces = np.zeros((len(my_pieces), size), dtype=bool)
    held_points = [own, my_pieces["a"], my_pieces["b"]]  # (a piece's far end may be another rank's)
    held_pieces = [my_pieces]
    bytes_sent = 0
    widenings = 0
    while True:
        tables = comm.allgather(np.column_stack([box, reach]))
        index, dest = _halo.sends(own["x"], own["y"], np.zeros(n), starts, box, tables, rank, magnitude,
                                  sent_points)
        got_points, _ = _exchange(comm, dest, own[index])
        pindex, pdest = _halo.sends(mid_x, mid_y, half, piece_starts, piece_box, tables, rank, magnitude,
                                    sent_pieces)
        got_pieces, _ = _exchange(comm, pdest, my_pieces[pindex])
        bytes_sent += len(index) * _POINT.itemsize + len(pindex) * _PIECE.itemsize
        held_points += [got_points, got_pieces["a"], got_pieces["b"]]
        held_pieces.append(got_pieces)
        local = np.concatenate(held_points)
        local = local[np.unique(local["gid"], return_index=True)[1]]
        local_pieces = np.concatenate(held_pieces)
        piece_key = np.sort(np.stack([local_pieces["a"]["gid"], local_pieces["b"]["gid"]], axis=1), axis=1)
        local_pieces = local_pieces[np.unique(piece_key, axis=0, return_index=True)[1]] if len(local_pieces) \
            else local_pieces
        held_points, held_pieces = [local], [local_pieces]

        lxy = np.stack([local["x"], local["y"]], axis=1)
        pieces_local = np.stack([np.searchsorted(local["gid"], local_pieces["a"]["gid"]),
                                 np.searchsorted(local["gid"], local_pieces["b"]["gid"])], axis=1)
        triangles, neighbour, constrained, seed = _core.local_constrained_delaunay(
            lxy, pieces_local, local_pieces["boundary"].astype(np.uint8))
        # The chunk of each owned point, by local index (-1: a copy).
        owned_local = local["owner"] == rank
        chunk_local = np.full(len(local), -1, np.int64)
        chunk_local[np.searchsorted(local["gid"], own["gid"])] = chunk_of
        centre, radius = _circumcircles(lxy, triangles)
        # Certified through each corner that is an owned point: disc within the reach of its chunk.
        need = np.full(triangles.shape, np.inf)
        certified = np.zeros(len(triangles), dtype=bool)
        for k in range(3):
            c = chunk_local[triangles[:, k]]
            has = c >= 0
            d = np.full(len(triangles), np.inf)
            d[has] = (_halo.box_distance(centre[has, 0], centre[has, 1], box[c[has]]) + radius[has]) \
                * (1 + _SLACK) + 1e-12 * magnitude
            need[:, k] = d
            certified[has] |= d[has] <= reach[c[has]]
        if len(local) == n_total and len(local_pieces) == k_total:
            certified[:] = True  # (this rank holds every point and piece: nothing is missing)
        # Open edges (neighbour -1): the edge opposite corner k, from corner k+1 to k+2.
        open_edge = neighbour < 0
        supported = np.ones(triangles.shape, dtype=bool)
        rows, corners = np.nonzero(open_edge)
        if len(rows):
            a = lxy[triangles[rows, (corners + 1) % 3]]
            b = lxy[triangles[rows, (corners + 2) % 3]]
            supported[rows, corners] = _core.supports_on_left(a, b, extreme).astype(bool)
        # Per owned point: its fan certified and closed (or supported by the global hull).
        fails = np.zeros(len(local), dtype=bool)
        wanted = np.zeros(len(local))
        for k in range(3):
            v = triangles[:, k]
            bad = owned_local[v] & ~certified
            fails[v[bad]] = True
            np.maximum.at(wanted, v[bad], need[bad, k])
            for e in (1, 2):  # the two edges at corner k: opposite corners k+1 and k+2
                corner = (k + e) % 3
                unsupported = owned_local[v] & open_edge[:, corner] & ~supported[:, corner]
                fails[v[unsupported]] = True
                wanted[v[unsupported]] = np.inf
        # An owned point in no local triangle has its fan still to find (unless the points are all collinear).
        alone = np.ones(len(local), dtype=bool)
        alone[triangles.reshape(-1)] = False
        fails |= alone & owned_local
        wanted[alone & owned_local] = np.inf
        # A chunk whose reach spans every point has all of them already: nothing more to ask.
        fails &= ~((chunk_local >= 0) & (reach[np.maximum(chunk_local, 0)] > 2 * span + 1e-12 * magnitude))
        failing_chunks = np.unique(chunk_local[fails & owned_local])
        if comm.allreduce(len(failing_chunks), op=MPI.SUM) == 0:
            break
        widenings += 1
        want = np.zeros(len(starts))
        np.maximum.at(want, chunk_local[fails & owned_local], wanted[fails & owned_local])
        grow = failing_chunks
        reach[grow] = np.maximum(4 * reach[grow], np.where(np.isfinite(want[grow]), want[grow] * 1.05, 0))

    own_position = np.full(len(local), -1, np.int64)
    own_position[np.searchsorted(local["gid"], own["gid"])] = np.arange(n)
    labels, label_rounds, label_bytes = _labels(comm, local, triangles, neighbour, constrained, seed, certified,
                                                open_edge, supported, sent_points, own_position, rank)
    bytes_sent += label_bytes
    owned_triangles = owned_local[triangles] & (local["gid"][triangles] == local["gid"][triangles].min(axis=1,
                                                                                                   keepdims=True))
    mine = owned_triangles.any(axis=1) & (labels == _INSIDE)
    out = local["gid"][triangles[mine]]
    # Rotate to the least id first (orientation kept), rows sorted.
    shift = np.argmin(out, axis=1)
    out = np.take_along_axis(out, (shift[:, None] + np.arange(3)[None, :]) % 3, axis=1)
    out = out[np.lexsort((out[:, 2], out[:, 1], out[:, 0]))]
    if stats is not None:
        stats.update(widenings=widenings, label_rounds=label_rounds,
                     halo_points=comm.allreduce(int((local["owner"] != rank).sum()), op=MPI.SUM),
                     halo_pieces=comm.allreduce(int(len(local_pieces) - len(my_pieces)), op=MPI.SUM),
                     bytes=comm.allreduce(int(bytes_sent), op=MPI.SUM))
    return out


def _matches(keys: np.ndarray, asked: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (row of keys, row of asked) with equal (k0, k1, k2), by one lexicographic sort."""
    both = np.concatenate([keys, asked])
    tag = np.concatenate([np.zeros(len(keys), np.int64), np.ones(len(asked), np.int64)])
    index = np.concatenate([np.arange(len(keys)), np.arange(len(asked))])
    order = np.lexsort((tag, both[:, 2], both[:, 1], both[:, 0]))
    b, t, i = both[order], tag[order], index[order]
    pair = (b[1:] == b[:-1]).all(axis=1) & (t[:-1] == 0) & (t[1:] == 1)
    return i[:-1][pair], i[1:][pair]


def _labels(comm: Any, local: np.ndarray, triangles: np.ndarray, neighbour: np.ndarray, constrained: np.ndarray,
            seed: np.ndarray, certified: np.ndarray, open_edge: np.ndarray, supported: np.ndarray,
            sent_points: np.ndarray, own_position: np.ndarray, rank: int) -> tuple[np.ndarray, int, int]:
    """Inside / outside for every certified local triangle (0 elsewhere): piece
    seeds and the global hull's unconstrained edges (outside) filled over
    components of certified triangles, then rounds with the other ranks' copies."""
    MPI = _mpi()
    m = len(triangles)
    free_edge = ((constrained[:, None] >> np.arange(3)[None, :]) & 1) == 0
    seeds = seed.astype(np.uint8).copy()
    # An unconstrained edge on the global hull: the infinite side is outside, as in the serial fill.
    seeds[(open_edge & supported & free_edge).any(axis=1)] |= _OUTSIDE
    # Components: certified triangles joined across unconstrained edges to certified neighbours.
    rows, corners = np.nonzero((neighbour >= 0) & free_edge)
    other = neighbour[rows, corners]
    join = certified[rows] & certified[other]
    graph = coo_matrix((np.ones(int(join.sum())), (rows[join], other[join])), shape=(m, m))
    _, component = connected_components(graph, directed=False)
    component_label = np.zeros(int(component.max()) + 1 if m else 0, dtype=np.uint8)
    np.bitwise_or.at(component_label, component[certified], seeds[certified])
    if (component_label == _INSIDE | _OUTSIDE).any():
        raise RuntimeError("distributed constrained_delaunay: the pieces do not bound a consistent domain")
    keys = np.sort(local["gid"][triangles], axis=1)
    # The ranks that may hold a copy of a triangle: those owning a corner or sent an owned corner.
    corner_owner = local["owner"][triangles]
    corner_position = own_position[triangles]
    ours = (corner_owner == rank).any(axis=1)
    told = np.zeros(len(component_label), dtype=bool)
    rounds = bytes_sent = 0
    while True:
        rounds += 1
        label = np.where(certified, component_label[component], 0)
        fresh = certified & ours & (label > 0) & ~told[component]
        told[component[certified & (label > 0)]] = True
        send_rows, send_dest = [], []
        for q in range(comm.size):
            if q == rank:
                continue
            at_q = (corner_owner == q).any(axis=1)
            for k in range(3):
                has = corner_position[:, k] >= 0
                at_q[has] |= sent_points[corner_position[has, k], q]
            rows_q = np.flatnonzero(fresh & at_q)
            send_rows.append(rows_q)
            send_dest.append(np.full(len(rows_q), q, dtype=np.int64))
        rows_out = np.concatenate(send_rows) if send_rows else np.zeros(0, np.int64)
        records = np.zeros(len(rows_out), dtype=_LABEL)
        records["key"], records["label"] = keys[rows_out], label[rows_out]
        got, _ = _exchange(comm, np.concatenate(send_dest) if send_dest else np.zeros(0, np.int64), records)
        bytes_sent += records.nbytes
        changed = 0
        if len(got):
            mine, theirs = _matches(keys, got["key"])
            keep = certified[mine]
            c, value = component[mine[keep]], got["label"][theirs[keep]]
            heard = np.zeros(len(component_label), dtype=np.uint8)
            np.bitwise_or.at(heard, c, value)
            clash = (heard > 0) & (component_label > 0) & (heard != component_label)
            if ((heard == _INSIDE | _OUTSIDE) | clash).any():
                raise RuntimeError("distributed constrained_delaunay: ranks disagree on a domain label")
            new = (heard > 0) & (component_label == 0)
            component_label[new] = heard[new]
            changed = int(new.sum())
        if comm.allreduce(changed, op=MPI.SUM) == 0 and rounds > 1:
            break
    label = np.where(certified, component_label[component], 0)
    label[certified & (label == 0)] = _INSIDE
    return label, rounds, comm.allreduce(int(bytes_sent), op=MPI.SUM)
