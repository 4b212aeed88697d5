"""The lexical-first MIS on MPI ranks (evomesh.distributed.packing):
the kept set equals the serial packing's on any number of ranks and any
partition, including partitions that cut the order into contiguous ranges (the
worst case for rounds) and spheres whose conflicts cross gaps (no mesh, no
neighbourhood assumed).

Plain ``pytest`` runs these on one rank; CI runs them under ``mpiexec -n 2`` and
``-n 4`` too (tools/run-tests.sh). Every rank draws the same spheres from the
same seed, keeps its share, and compares the gathered result with the serial
``_core.lexical_first_mis`` on the whole set.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from evomesh import _core

MPI = pytest.importorskip("mpi4py.MPI")
from evomesh.distributed.packing import lexical_first_mis  # noqa: E402
from mpi_support import check_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)

COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size




def _system(n: int, seed: int, kind: str):
    """Spheres as a step makes them: every class, radii graded or uniform, some
    exact ties in (class, radius), a few forced spheres first."""
    rng = np.random.default_rng(seed)
    centers = rng.random((n, 2))
    if kind == "graded":  # long chains up the gradient
        radii = 1e-3 + 0.05 * centers[:, 0] ** 2 * rng.uniform(0.8, 1.2, n)
    elif kind == "ties":  # a lattice of equal spheres: every tie broken by the key
        side = max(1, int(np.sqrt(n)))
        centers = np.stack([np.arange(n) % side, np.arange(n) // side], axis=1) / side
        radii = np.full(n, 0.6 / side)
    else:
        radii = rng.uniform(0.01, 0.03, n)
    classes = rng.integers(1, 5, n).astype(np.uint8)
    n_forced = min(n, int(rng.integers(0, 4)))
    forced = np.zeros(n, dtype=bool)
    forced[:n_forced] = True
    classes[forced] = 0
    ties = rng.permutation(n).astype(np.int64) * 3 + 7  # global ids unrelated to position
    return centers, radii, classes, ties, forced


def _serial(centers, radii, classes, ties, forced):
    order = np.lexsort((ties, radii, classes))
    return _core.lexical_first_mis(centers, radii, order, int(forced.sum())).astype(bool)


def _owner(centers, ties, radii, classes, layout: str, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n = len(centers)
    if layout == "random":
        return rng.integers(0, SIZE, n)
    if layout == "stripes":  # borders across the radius gradient
        return np.minimum((centers[:, 1] * SIZE).astype(np.int64), SIZE - 1)
    if layout == "order":  # each rank a contiguous range of the order: one round per crossing
        owner = np.empty(n, np.int64)
        owner[np.lexsort((ties, radii, classes))] = np.arange(n) * SIZE // max(n, 1)
        return owner
    return np.zeros(n, np.int64)  # "one": everything on rank 0, the others empty


def _distributed(centers, radii, classes, ties, forced, owner, stats=None):
    mine = owner == RANK
    kept_mine = lexical_first_mis(COMM, centers[mine], radii[mine], classes[mine], ties[mine], forced[mine],
                                  stats=stats)
    parts = COMM.allgather((np.flatnonzero(mine), kept_mine))
    kept = np.zeros(len(centers), dtype=bool)
    for index, values in parts:
        kept[index] = values
    return kept


@settings(max_examples=25, deadline=None)
@given(n=st.integers(0, 500), seed=st.integers(0, 10**6), kind=st.sampled_from(["graded", "uniform", "ties"]),
       layout=st.sampled_from(["random", "stripes", "order", "one"]))
def test_kept_set_is_the_serial_one_on_any_partition(n, seed, kind, layout):
    centers, radii, classes, ties, forced = _system(n, seed, kind)
    stats: dict = {}
    kept = _distributed(centers, radii, classes, ties, forced, _owner(centers, ties, radii, classes, layout, seed),
                        stats)
    check_everywhere(np.array_equal(kept, _serial(centers, radii, classes, ties, forced)), "the serial kept set")
    check_everywhere(stats["undecided"][-1] == 0 and stats["rounds"] == len(stats["undecided"]),
                     "the rounds end decided")
    if SIZE == 1:
        check_everywhere(stats["rounds"] == 1 and stats["copies"] == 0, "one rank: one sweep, no copies")


def test_conflicts_across_a_gap_reach_the_other_rank():
    """Two large spheres far from everything else, on different ranks, conflict
    across an empty band: the halo comes from the spheres' reach, not from a mesh."""
    centers = np.array([[0.0, 0.0], [1.0, 0.0]] + [[0.0, 5.0 + 0.01 * i] for i in range(20)])
    radii = np.array([0.6, 0.6] + [0.001] * 20)
    classes = np.array([2, 1] + [3] * 20, dtype=np.uint8)
    ties = np.arange(len(centers), dtype=np.int64)
    forced = np.zeros(len(centers), dtype=bool)
    owner = np.zeros(len(centers), np.int64)
    owner[1] = SIZE - 1  # the earlier sphere (class 1) on the last rank
    kept = _distributed(centers, radii, classes, ties, forced, owner)
    check_everywhere(not kept[0] and kept[1], "the later sphere is rejected by the earlier one on another rank")


def test_rounds_follow_an_ordered_chain_across_ranks():
    """A chain ordered across the ranks takes one round per rank: the bound of 3.4 is reached and held."""
    n = 4 * SIZE
    centers = np.stack([np.arange(n, dtype=float), np.zeros(n)], axis=1)
    radii = np.full(n, 0.6)
    classes = np.ones(n, dtype=np.uint8)
    ties = np.arange(n, dtype=np.int64)
    forced = np.zeros(n, dtype=bool)
    owner = np.arange(n) * SIZE // n
    stats: dict = {}
    kept = _distributed(centers, radii, classes, ties, forced, owner, stats)
    check_everywhere(np.array_equal(kept, np.arange(n) % 2 == 0), "alternate spheres kept")
    check_everywhere(stats["rounds"] == SIZE, f"{SIZE} rounds")


def test_bad_input_on_one_rank_raises_everywhere():
    centers, radii, classes, ties, forced = _system(40, 1, "uniform")
    mine = np.arange(40) % SIZE == RANK
    bad_radii = radii[mine].copy()
    if RANK == SIZE - 1 and len(bad_radii):
        bad_radii[0] = -1.0
    with pytest.raises(ValueError, match="radii"):
        lexical_first_mis(COMM, centers[mine], bad_radii, classes[mine], ties[mine], forced[mine])
    repeated = ties[mine].copy()
    if RANK == 0 and len(repeated) > 1:
        repeated[1] = repeated[0]
    with pytest.raises(ValueError, match="unique"):
        lexical_first_mis(COMM, centers[mine], radii[mine], classes[mine], repeated, forced[mine])
    late_forced = forced[mine].copy()
    late_forced[:] = False
    if RANK == SIZE - 1 and len(late_forced):
        late_forced[-1] = True  # a forced sphere of class >= 1 after unforced ones of class 1
    c = classes[mine].copy()
    c[:] = 1
    with pytest.raises(ValueError, match="forced"):
        lexical_first_mis(COMM, centers[mine], radii[mine], c, ties[mine], late_forced)
