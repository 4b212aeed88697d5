"""Halos by reach (docs/distributed-step.md, section 3): which of a
rank's records another rank must hold, decided by the sender from boxes, so a
halo is complete by construction instead of by a width guess.

A rank sorts its records along a Hilbert curve and cuts them into chunks of
_CHUNK; each chunk publishes its bounding box and a *reach* (one allgather of
five numbers per chunk). A receiver's chunk c asks for every record t of
another rank with dist(t, box_c) < reach_c + extra_t, where extra_t is the
record's own reach (a sphere's radius, half a segment's length, 0 for a point).
Every record within reach of one of c's members passes, whatever the
partition, holes or empty gaps between them: dist(t, box_c) <= |t - x| for any
x in c. The sender tests its records against the receivers' boxes (vectorised,
chunk pairs first), so one exchange moves the halo.
"""

from __future__ import annotations

import numpy as np

from .mesh import _HILBERT_ORDER, _hilbert_keys, _ranges

# Records per chunk: boxes of a few hundred Hilbert-ordered records are tight,
# and P x (n / 256) boxes are cheap to share. At most _MAX_CHUNKS chunks a rank
# (larger chunks beyond 256 x 1024 records): the senders test chunk pairs, a
# (their chunks x my chunks) table per other rank, which must stay small (at 1e6
# points a pass's 4e6 spheres in chunks of 256 made tables of 1e8 entries).
_CHUNK = 256
_MAX_CHUNKS = 1024
# Relative slack on every reach test, far above rounding: more copies are harmless, a missing one is not.
_SLACK = 1e-9


def hilbert_chunks(x: np.ndarray, y: np.ndarray, lo: np.ndarray, span: float) -> tuple[np.ndarray, np.ndarray]:
    """The permutation sorting (x, y) along a Hilbert curve over the box [lo, lo + span]^2,
    and the chunk starts in that order (chunks of _CHUNK records, at most _MAX_CHUNKS of them)."""
    cells = (1 << _HILBERT_ORDER) - 1
    scale = cells / span if span > 0 else 0.0
    ix = np.clip(((x - lo[0]) * scale).astype(np.int64), 0, cells)
    iy = np.clip(((y - lo[1]) * scale).astype(np.int64), 0, cells)
    perm = np.argsort(_hilbert_keys(ix, iy, _HILBERT_ORDER), kind="stable")
    return perm, np.arange(0, len(x), max(_CHUNK, -(-len(x) // _MAX_CHUNKS)), dtype=np.int64)


def chunk_boxes(x: np.ndarray, y: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(xmin, xmax, ymin, ymax) of each chunk of (x, y), already in chunk order."""
    box = np.empty((len(starts), 4))
    if len(starts):
        box[:, 0], box[:, 1] = np.minimum.reduceat(x, starts), np.maximum.reduceat(x, starts)
        box[:, 2], box[:, 3] = np.minimum.reduceat(y, starts), np.maximum.reduceat(y, starts)
    return box


def box_distance(x: np.ndarray, y: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Distance from points (x, y) to boxes (rows xmin, xmax, ymin, ymax), elementwise."""
    dx = np.maximum(np.maximum(box[:, 0] - x, x - box[:, 1]), 0.0)
    dy = np.maximum(np.maximum(box[:, 2] - y, y - box[:, 3]), 0.0)
    return np.hypot(dx, dy)


def sends(x: np.ndarray, y: np.ndarray, extra: np.ndarray, starts: np.ndarray, box: np.ndarray,
          tables: list[np.ndarray], rank: int, magnitude: float,
          already: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(record index, destination rank) of every copy of this rank's records (x,
    y, extra; in chunk order, chunks `starts` with boxes `box`) that another rank
    q's chunk asks for: tables[q] has rows (xmin, xmax, ymin, ymax, reach).
    `already`, a boolean (n, P) array, leaves out copies sent before (and is updated)."""
    n = len(x)
    counts = np.diff(np.append(starts, n))
    extra_max = np.maximum.reduceat(extra, starts) if n else np.zeros(0)
    margin = 1e-12 * magnitude
    index_out, dest_out = [], []
    for q, other in enumerate(tables):
        if q == rank or not len(other) or not n:
            continue
        # Chunk pairs that can hold a (record, asker) pair within reach.
        gap_x = np.maximum(np.maximum(other[None, :, 0] - box[:, None, 1], box[:, None, 0] - other[None, :, 1]), 0)
        gap_y = np.maximum(np.maximum(other[None, :, 2] - box[:, None, 3], box[:, None, 2] - other[None, :, 3]), 0)
        reach = (other[None, :, 4] + extra_max[:, None]) * (1 + _SLACK) + margin
        mine, theirs = np.nonzero(np.hypot(gap_x, gap_y) < reach)
        if not len(mine):
            continue
        index = _ranges(starts[mine], counts[mine])
        asker = np.repeat(theirs, counts[mine])
        near = box_distance(x[index], y[index], other[asker]) < (other[asker, 4] + extra[index]) * (1 + _SLACK) + margin
        index = np.unique(index[near])
        if already is not None:
            index = index[~already[index, q]]
            already[index, q] = True
        index_out.append(index)
        dest_out.append(np.full(len(index), q, dtype=np.int64))
    if not index_out:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(index_out), np.concatenate(dest_out)


def copies_within_reach(comm, lo: np.ndarray, span: float, magnitude: float, query_xy: np.ndarray,
                        query_reach: np.ndarray, record_xy: np.ndarray,
                        record_extra: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(record index, destination rank) of every copy of this rank's records
    that another rank needs: record t goes to rank q when it lies within
    reach + extra_t of one of q's query chunks (every record within
    query_reach[i] + extra_t of query i passes). One allgather of the query
    chunks' boxes; no exchange (the caller sends what it needs of the records)."""
    qperm, qstarts = hilbert_chunks(query_xy[:, 0], query_xy[:, 1], lo, span)
    qx, qy = query_xy[qperm, 0], query_xy[qperm, 1]
    qbox = chunk_boxes(qx, qy, qstarts)
    qreach = np.maximum.reduceat(query_reach[qperm], qstarts) if len(qperm) else np.zeros(0)
    tables = comm.allgather(np.column_stack([qbox, qreach]))
    rperm, rstarts = hilbert_chunks(record_xy[:, 0], record_xy[:, 1], lo, span)
    rx, ry = record_xy[rperm, 0], record_xy[rperm, 1]
    rbox = chunk_boxes(rx, ry, rstarts)
    index, dest = sends(rx, ry, np.asarray(record_extra, dtype=np.float64)[rperm], rstarts, rbox, tables, comm.rank,
                        magnitude)
    return rperm[index], dest
