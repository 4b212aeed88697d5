"""The thread limit of a step on MPI ranks (docs/distributed-step.md, 3.7).

A serial step keeps at most ``threads`` threads working at once: its C++
outline opens one ``Thread_limit`` around its stages. A step on ranks is a
Python outline over many core calls, so :func:`rank_thread_limit` opens the
limit (``_core.ThreadLimit``) around all of them on each rank. The count is
rank-local (ranks may pass different ``threads``; it is kept out of the
agreement on the arguments) and never changes a bit of the result.
"""

from __future__ import annotations

import contextlib
import os
import threading
from fractions import Fraction
from typing import Any, Iterator, Sequence

from .. import _core
from .mesh import _mpi

__all__ = ["node_share", "rank_thread_count", "rank_thread_limit"]

_open = threading.local()  # (a limit already open on this thread: evolve, then step, then packing)


def rank_thread_count(comm: Any, threads: Any = None) -> int:
    """The threads this rank's step may keep busy at once. Collective (every
    rank of `comm` calls it, whatever its own `threads`).

    Parameters
    ----------
    comm : mpi4py intracommunicator
    threads : int or None
        The step's ``threads`` option on this rank (None or 0: unset).

    Returns
    -------
    int >= 1: `threads` when set; else the count EVOMESH_NUM_THREADS names
    (else OMP_NUM_THREADS), taken per rank, as hybrid MPI codes take
    OMP_NUM_THREADS; else this rank's share of the CPUs of its node
    (:func:`node_share`). Dividing by the ranks on the node, not taking the
    serial default on every rank, is what keeps P ranks on a node from
    starting P threads per CPU; ranks the launcher bound to their own cores
    keep all of theirs.
    """
    node = comm.Split_type(_mpi().COMM_TYPE_SHARED)
    try:
        mine = _cpu_set()
        cpu_sets = node.allgather(mine)
    finally:
        node.Free()
    if isinstance(threads, int) and threads > 0:
        return threads
    return _core.environment_thread_count() or node_share(_core.available_cpu_count(), mine, cpu_sets)


def node_share(available: int, mine: Sequence[int] | None, cpu_sets: Sequence[Sequence[int] | None]) -> int:
    """A rank's share of the CPUs of its node: `available` (the CPUs this
    process may use: its affinity mask and cgroup quota, at least 1) times the
    share of its affinity mask `mine` that is its own, where a CPU in the
    masks of k ranks of the node (`cpu_sets`, one a rank, this one's
    included) counts 1/k. So ranks that share every CPU split them evenly (2
    ranks on 8 CPUs: 4 each), ranks bound to disjoint cores keep theirs, and a
    quota is split in proportion. Without masks (not Linux: None) the CPUs are
    split evenly among the node's ranks. At least 1, rounded down.
    """
    if mine is None or not len(mine) or any(s is None for s in cpu_sets):
        return max(1, available // max(1, len(cpu_sets)))
    holders: dict[int, int] = {}
    for cpus in cpu_sets:
        for cpu in cpus:  # type: ignore[union-attr]
            holders[cpu] = holders.get(cpu, 0) + 1
    own = sum((Fraction(1, holders[cpu]) for cpu in mine), Fraction(0))
    return max(1, int(available * own / len(mine)))


def _cpu_set() -> tuple[int, ...] | None:
    """This process's CPU affinity mask (None where the OS does not say)."""
    if not hasattr(os, "sched_getaffinity"):
        return None
    return tuple(sorted(os.sched_getaffinity(0)))


@contextlib.contextmanager
def rank_thread_limit(comm: Any, threads: Any = None, stats: dict[str, Any] | None = None) -> Iterator[int]:
    """Every core call this rank makes inside the block keeps at most
    :func:`rank_thread_count` threads working at once (``_core.ThreadLimit``
    on the calling thread). Collective on entry. A block inside another on the
    same thread keeps the outer limit. Yields the count, also stored as
    ``stats["threads"]`` when `stats` is given."""
    count = getattr(_open, "count", 0)
    if count:
        if stats is not None:
            stats["threads"] = count
        yield count
        return
    count = rank_thread_count(comm, threads)
    if stats is not None:
        stats["threads"] = count
    _open.count = count
    try:
        with _core.ThreadLimit(count):
            yield count
    finally:
        _open.count = 0
