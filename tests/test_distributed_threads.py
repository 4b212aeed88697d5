"""The thread limit on MPI ranks (evomesh.distributed.threads): a step on a
DistributedMesh runs its core calls under each rank's own ``threads`` (or,
unset, EVOMESH_NUM_THREADS, else the rank's share of its node's CPUs), seen
from the core's counts of its parallel loops; the gathered mesh is the same
bits whatever the threads.

Plain ``pytest`` runs these on one rank; CI runs them under ``mpiexec -n 2`` and
``-n 4`` too (tools/run-tests.sh).
"""

from __future__ import annotations

import numpy as np
import pytest

import evomesh
from evomesh import _core
from evomesh.meshgen import polygon_mesh

MPI = pytest.importorskip("mpi4py.MPI")
from evomesh import DistributedMesh  # noqa: E402
from evomesh.distributed.step import evolve_distributed  # noqa: E402
from evomesh.distributed.threads import node_share  # noqa: E402
from mpi_support import check_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)

COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size
_ARRAYS = ("points", "triangles", "segments", "segment_tags", "segment_is_boundary", "kind", "origin", "required")
_MESH: list = []


def _mesh() -> evomesh.Mesh:
    """An L-shape of about 4,000 points: on 3 ranks every rank still has loops of 3 items or more."""
    if not _MESH:
        _MESH.append(polygon_mesh([[(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]], 0.03))
    return _MESH[0]


def _front(xy: np.ndarray) -> np.ndarray:
    distance = np.abs(np.hypot(xy[:, 0] - 0.8, xy[:, 1] - 0.9) - 0.5)
    return np.where(distance < 0.1, 0.5, 1.5)


def _step(dmesh: DistributedMesh, options: _core.FrfcOptions) -> tuple[evomesh.Mesh | None, dict, dict]:
    """The gathered step, its stats and the core's counts of the loops the step ran on this rank."""
    stats: dict = {}
    _core._parallel_counts(reset=True)
    out = evolve_distributed(dmesh, _front, options=options, stats=stats)
    counts = _core._parallel_counts(reset=True)
    return out.gather(), stats, counts


@pytest.mark.parametrize("quality", [False, True], ids=["no quality", "quality on the root"])
def test_each_rank_keeps_to_its_threads_and_the_bits_do_not_change(quality: bool) -> None:
    """threads=1 on every rank, 2 on every rank, and 1, 2, 3 by rank: a rank's
    loops run on exactly its threads (1: no loop on a second thread), never more
    at once, and every gathered mesh is the serial step's."""
    mesh = _mesh()
    dmesh = DistributedMesh.scatter(mesh if RANK == 0 else None, COMM)
    serial = None
    for threads in (1, 2, 1 + RANK % 3):
        options = _core.FrfcOptions.recommended()
        options.quality = quality
        options.threads = threads
        if RANK == 0 and serial is None:
            serial = evomesh.evolve(mesh, _front(mesh.points), options=options)
        gathered, stats, counts = _step(dmesh, options)
        check_everywhere(stats["threads"] == threads, f"the limit is threads={threads}")
        if threads == 1:
            check_everywhere(counts["regions"] == 0, f"threads=1 ran no loop on two threads: {counts}")
        else:
            check_everywhere(counts["widest"] == threads and counts["peak_running"] <= threads,
                             f"threads={threads}: loops on {threads} threads, no more at once: {counts}")
        same = RANK != 0 or all(np.array_equal(getattr(gathered, k), getattr(serial, k)) for k in _ARRAYS)
        check_everywhere(same, f"threads={threads}: the gathered step is the serial one")


def test_the_default_does_not_oversubscribe_the_node() -> None:
    """threads unset: EVOMESH_NUM_THREADS on each rank when set, else the
    ranks of a node together take at most its CPUs (or one thread each);
    every loop keeps to the rank's count."""
    dmesh = DistributedMesh.scatter(_mesh() if RANK == 0 else None, COMM)
    options = _core.FrfcOptions.recommended()
    options.quality = False
    _, stats, counts = _step(dmesh, options)
    threads = stats["threads"]
    node = COMM.Split_type(MPI.COMM_TYPE_SHARED)
    try:
        total = node.allreduce(threads)
        cpus = len(set().union(*node.allgather(_affinity())))
        n_node = node.size
    finally:
        node.Free()
    if _core.environment_thread_count():
        check_everywhere(threads == _core.environment_thread_count(), "EVOMESH_NUM_THREADS holds on each rank")
    else:
        check_everywhere(total <= max(cpus, n_node), f"{total} threads on a node of {cpus} CPUs, {n_node} ranks")
    check_everywhere(counts["widest"] <= threads and counts["peak_running"] <= threads, f"{counts} within {threads}")


def _affinity() -> set[int]:
    import os

    return set(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else set(range(_core.available_cpu_count()))


def test_node_share() -> None:
    """A rank's share of its node's CPUs, from the ranks' affinity masks."""
    every = tuple(range(8))
    assert node_share(8, every, [every, every]) == 4  # two unbound ranks split the node
    assert node_share(8, every, [every] * 3) == 2  # rounded down
    assert node_share(2, (0, 1), [(0, 1)] * 3) == 1  # never less than one
    assert node_share(4, (0, 1, 2, 3), [(0, 1, 2, 3), (4, 5, 6, 7)]) == 4  # bound to their own cores
    assert node_share(4, (0, 1, 2, 3), [(0, 1, 2, 3), (2, 3, 4, 5)]) == 3  # two of its CPUs shared
    assert node_share(2, every, [every, every]) == 1  # a cgroup quota of 2 CPUs, split
    assert node_share(6, None, [None, None, None]) == 2  # no masks: split evenly
    assert node_share(6, (0,), [(0,)]) == 6  # alone on its node
