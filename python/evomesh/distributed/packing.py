"""The lexical-first maximal independent set of a packing, computed by MPI ranks
that each own some of the spheres (the argument is
docs/distributed-step.md, section 3.4).

The serial rule (packing.hpp, the paper's lexical-first MIS): spheres are taken
in the order (class, radius, tie), smaller first; a sphere is kept unless an
earlier kept sphere conflicts with it (|c1 - c2| < r1 + r2). Here every rank
holds its own spheres plus a copy of every other sphere that can conflict with
one of them (the halo, found from boxes of Hilbert-ordered chunks, below), and
the ranks decide in rounds: each round a rank sweeps its undecided spheres in
the order and decides those whose earlier conflicting spheres are all decided
(``_core.MisPart``), then tells the ranks holding copies of them. Every sphere
decided gets its serial state (induction along the order), and each round
decides at least the globally earliest undecided sphere, so the rounds end and
the kept set is the serial one on any number of ranks.

The halo is exact by construction, not by a width guess (_halo.py): a sphere t
of rank q can conflict with a sphere of rank r's chunk c only if the distance
from t's centre to c's box is below r_max(c) + r_t, so q sends r exactly the
spheres that pass that test (one exchange), whatever the partition, holes or
gaps between the spheres.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import _core
from . import _halo
from .mesh import _check_comm, _collective, _exchange, _mpi

__all__ = ["lexical_first_mis"]

# A sphere's record: its tie key (a global id), class, forced flag, radius and centre.
_SPHERE = np.dtype([("tie", "<i8"), ("cls", "u1"), ("forced", "u1"), ("r", "<f8"), ("x", "<f8"), ("y", "<f8")])
# A state update: tie key and state (1 kept, 2 rejected).
_STATE = np.dtype([("tie", "<i8"), ("state", "u1")])


def _check(centers: Any, radii: Any, classes: Any, ties: Any, forced: Any) -> tuple[np.ndarray, ...]:
    c = np.asarray(centers)
    if c.ndim != 2 or c.shape[1:] != (2,) or not np.issubdtype(c.dtype, np.number):
        raise ValueError(f"centers must be a numeric (n, 2) array, got shape {c.shape} and dtype {c.dtype}")
    n = len(c)
    c = np.ascontiguousarray(c, dtype=np.float64)
    r = np.ascontiguousarray(np.asarray(radii, dtype=np.float64))
    if r.shape != (n,):
        raise ValueError(f"radii must have one value per centre: shape ({n},), got {r.shape}")
    if not (np.isfinite(c).all() and np.isfinite(r).all() and (r > 0).all()):
        raise ValueError("centres must be finite and radii finite and > 0")
    k = np.asarray(classes)
    if k.shape != (n,) or not np.issubdtype(k.dtype, np.integer) or (n and (k.min() < 0 or k.max() > 255)):
        raise ValueError(f"classes must be integers in [0, 255], one per centre (shape ({n},))")
    t = np.asarray(ties)
    if t.shape != (n,) or not np.issubdtype(t.dtype, np.integer) or (n and t.min() < 0):
        raise ValueError(f"ties must be non-negative integers (global ids), one per centre (shape ({n},))")
    f = np.zeros(n, dtype=bool) if forced is None else np.asarray(forced)
    if f.shape != (n,) or f.dtype != bool:
        raise ValueError(f"forced must be a boolean array with one value per centre (shape ({n},))")
    return c, r, k.astype(np.uint8), t.astype(np.int64), f


def lexical_first_mis(comm: Any, centers: Any, radii: Any, classes: Any, ties: Any, forced: Any = None,
                      stats: dict[str, Any] | None = None, *, check_ties: bool = True) -> np.ndarray:
    """The lexical-first MIS of the spheres B(centers[i], radii[i]) owned by all
    ranks of `comm`, each rank passing its own: the serial packing's kept set,
    on any number of ranks and any partition.

    Parameters
    ----------
    comm : mpi4py intracommunicator
    centers : (n, 2) float array, this rank's sphere centres
    radii : (n,) float array, > 0
    classes : (n,) integers in [0, 255]
        The packing class (corner, boundary, original, Steiner, sampled: smaller first).
    ties : (n,) non-negative integers
        A global key unique over all ranks (e.g. a global id): the order is
        (class, radius, tie), as the serial packing_order with ties by position.
    forced : (n,) bool, optional
        Spheres kept whatever they meet (the serial ``n_forced``); they must come
        before every other sphere in the order.
    check_ties : bool, default True
        Check that ties are unique over the ranks and forced spheres come
        first (an exchange of every tie); False for a caller that guarantees
        both (evomesh.distributed.step).
    stats : dict, optional
        Filled with "rounds", "copies" (halo spheres held, summed over ranks),
        "bytes_halo" and "bytes_states" (sent, summed over ranks), and
        "undecided" (per round, summed over ranks).

    Returns
    -------
    (n,) bool array: kept, for this rank's spheres in the order given.

    Raises
    ------
    ValueError or TypeError on every rank when any rank's input is bad.
    """
    _check_comm(comm)
    MPI = _mpi()
    c, r, k, t, f = _collective(comm, _check, centers, radii, classes, ties, forced)
    n = len(c)

    def check_order() -> None:
        # Forced spheres first in the order (class, radius, tie), over all ranks.
        key = np.lexsort((t, r, k))
        last_forced = [(int(k[i]), float(r[i]), int(t[i])) for i in key[f[key]][-1:]]
        first_free = [(int(k[i]), float(r[i]), int(t[i])) for i in key[~f[key]][:1]]
        ends = comm.allgather((last_forced, first_free))
        latest = max((e for pair in ends for e in pair[0]), default=None)
        earliest = min((e for pair in ends for e in pair[1]), default=None)
        if latest is not None and earliest is not None and latest > earliest:
            raise ValueError("forced spheres must come before every other sphere in the order (class, radius, tie)")

    def check_ties_unique() -> None:
        # Each tie to rank tie % P, which looks for repeats: O(n) work and bytes.
        got, _ = _exchange(comm, t % comm.size, t)
        if len(np.unique(got)) != len(got):
            raise ValueError("ties must be unique over all ranks (a global id per sphere)")

    if check_ties:
        _collective(comm, check_order)
        _collective(comm, check_ties_unique)

    records = np.empty(n, dtype=_SPHERE)
    records["tie"], records["cls"], records["forced"], records["r"] = t, k, f, r
    records["x"], records["y"] = c[:, 0], c[:, 1]
    big = np.finfo(np.float64).max
    lo = np.array([comm.allreduce(float(c[:, 0].min()) if n else big, op=MPI.MIN),
                   comm.allreduce(float(c[:, 1].min()) if n else big, op=MPI.MIN)])
    hi = np.array([comm.allreduce(float(c[:, 0].max()) if n else -big, op=MPI.MAX),
                   comm.allreduce(float(c[:, 1].max()) if n else -big, op=MPI.MAX)])
    span = float(max(hi - lo)) if (hi >= lo).all() else 0.0
    magnitude = float(max(np.abs(lo).max(), np.abs(hi).max())) if (hi >= lo).all() else 0.0

    # The halo (_halo.py): every other rank's spheres that can conflict with one
    # of ours, a sphere's reach being its radius on both sides.
    perm, starts = _halo.hilbert_chunks(records["x"], records["y"], lo, span)
    mine = records[perm]
    box = _halo.chunk_boxes(mine["x"], mine["y"], starts)
    r_max = np.maximum.reduceat(mine["r"], starts) if n else np.zeros(0)
    tables = comm.allgather(np.column_stack([box, r_max]))
    send_index, send_dest = _halo.sends(mine["x"], mine["y"], mine["r"], starts, box, tables, comm.rank, magnitude)
    copies, _ = _exchange(comm, send_dest, mine[send_index])
    bytes_halo = int(send_index.size) * _SPHERE.itemsize

    # Every sphere held, in the global order; the rank decides its own.
    held = np.concatenate([mine, copies])
    owned = np.zeros(len(held), dtype=np.uint8)
    owned[:n] = 1
    order = np.lexsort((held["tie"], held["r"], held["cls"]))
    part = _core.MisPart(np.stack([held["x"], held["y"]], axis=1), held["r"], order, owned)
    state = np.where(held["forced"] != 0, 1, 0).astype(np.uint8)
    # Where copies of our spheres live, and where our copies' states come from (by tie).
    copy_tie_order = np.argsort(copies["tie"], kind="stable")
    copy_ties = copies["tie"][copy_tie_order]
    told = np.zeros(n, dtype=bool)
    told[send_index] = True

    rounds = 0
    bytes_states = 0
    undecided_per_round = []
    while True:
        state, decided = part.sweep(state)
        rounds += 1
        # The decided spheres that some rank holds a copy of: (tie, state) to it.
        send = np.isin(send_index, decided[told[decided]]) if len(decided) else np.zeros(len(send_index), bool)
        update = np.empty(int(send.sum()), dtype=_STATE)
        update["tie"] = mine["tie"][send_index[send]]
        update["state"] = state[send_index[send]]
        got, _ = _exchange(comm, send_dest[send], update)
        bytes_states += update.nbytes
        if len(got):
            where = copy_tie_order[np.searchsorted(copy_ties, got["tie"])]
            state[n + where] = got["state"]
        left = comm.allreduce(part.undecided, op=MPI.SUM)
        undecided_per_round.append(left)
        if left == 0:
            break
    kept = np.empty(n, dtype=bool)
    kept[perm] = state[:n] == 1
    if stats is not None:
        stats.update(rounds=rounds, copies=comm.allreduce(len(copies), op=MPI.SUM),
                     bytes_halo=comm.allreduce(bytes_halo, op=MPI.SUM),
                     bytes_states=comm.allreduce(bytes_states, op=MPI.SUM),
                     undecided=undecided_per_round)
    return kept
