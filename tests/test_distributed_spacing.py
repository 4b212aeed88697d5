"""Step 1 on MPI ranks (evomesh.distributed.spacing,
docs/distributed-step.md 3.1-3.2): nn, the weights (capped by the local feature
size, whose chains and walks cross ranks) and f at the owned points equal the
serial step's bit for bit, on any number of ranks and any partition; f at
arbitrary points equals the serial spacing function's.

Plain ``pytest`` runs these on one rank; CI runs them under ``mpiexec -n 2`` and
``-n 4`` too (tools/run-tests.sh).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import evomesh
from evomesh import _core
from evomesh.meshgen import disc_with_hole_mesh, polygon_mesh
from strategies import grid_mesh

MPI = pytest.importorskip("mpi4py.MPI")
from evomesh import DistributedMesh  # noqa: E402
from evomesh.distributed.spacing import DistributedSpacing  # noqa: E402
from mpi_support import check_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)

COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size

WIDTH = 2e-3  # a channel between two boxes: the local feature size caps the weights there
CHANNEL = [(0, 0), (1, 0), (1, 0.5 - WIDTH / 2), (2, 0.5 - WIDTH / 2), (2, 0), (3, 0), (3, 1), (2, 1),
           (2, 0.5 + WIDTH / 2), (1, 0.5 + WIDTH / 2), (1, 1), (0, 1)]
GAP = 1e-4  # a slit into a square: across it the nearest point is no edge neighbour
SLIT = [(0, 0), (1, 0), (1, 1), (0, 1), (0, 0.5 + GAP / 2), (0.5, 0.5 + GAP / 2), (0.5, 0.5 - GAP / 2),
        (0, 0.5 - GAP / 2)]


def _cracks() -> evomesh.Mesh:
    """A grid with two interior constraint chains two cells apart (cracks), and a notch."""
    grid = grid_mesh(31, 31, notch=True)
    p = grid.points
    segments = []
    for y in (p[:, 1][np.argmin(np.abs(p[:, 1] - 0.3))], p[:, 1][np.argmin(np.abs(p[:, 1] - 0.3 + 2 / 30))]):
        row = np.flatnonzero((np.abs(p[:, 1] - y) < 1e-12) & (p[:, 0] > 0.1) & (p[:, 0] < 0.9))
        row = row[np.argsort(p[row, 0])]
        segments.extend(zip(row[:-1], row[1:]))
    return evomesh.Mesh(p, grid.triangles, segments=np.array(segments))


_DOMAINS = {
    "channel": lambda: polygon_mesh([CHANNEL], 0.06),
    "cracks and a notch": _cracks,
    "two holes": lambda: polygon_mesh([[(0, 0), (3, 0), (3, 2), (0, 2)],
                                       [(0.5, 0.5), (0.5, 1.5), (1.2, 1.5), (1.2, 0.5)],
                                       [(1.8, 0.5), (1.8, 1.5), (2.5, 1.5), (2.5, 0.5)]], 0.12),
    "disc with a hole": lambda: disc_with_hole_mesh(0.1),
    "slit": lambda: polygon_mesh([SLIT], 0.08),
}
_MESHES: dict = {}


def _mesh(name: str) -> evomesh.Mesh:
    if name not in _MESHES:
        _MESHES[name] = _DOMAINS[name]()
    return _MESHES[name]


def _delta(mesh: evomesh.Mesh, kind: str, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if kind == "random":
        return rng.uniform(0.3, 3.0, mesh.n_points)
    if kind == "coarsen":
        return np.full(mesh.n_points, 2.5)
    if kind == "spiky":  # coarsening everywhere but at a few points: f comes from sites far away
        return np.where(rng.random(mesh.n_points) < 0.1, 0.2, 8.0)
    # a front: refine near a circle, coarsen away from it
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    centre = lo + rng.uniform(0.3, 0.7, 2) * (hi - lo)
    distance = np.abs(np.hypot(*(mesh.points - centre).T) - 0.25 * (hi - lo).min())
    return np.where(distance < 0.1 * (hi - lo).min(), 0.5, 2.0)


def _serial(mesh: evomesh.Mesh, delta: np.ndarray, within: bool) -> dict:
    """The serial step's own step 1, with the arrays evolve passes."""
    return _core.step_spacing(mesh.points, mesh.triangles, mesh.segments, mesh.segment_is_boundary.astype(np.uint8),
                              mesh.kind, delta, within, segment_tags=mesh.segment_tags,
                              required=mesh.required.astype(np.uint8), nn=mesh.nn_spacing, nn_grew=mesh._nn_grew)


def _scatter(mesh: evomesh.Mesh, layout: str, seed: int) -> DistributedMesh:
    if layout == "stripes":  # from_local, cut across y: through the slit and across the channel's walls
        centroid_y = mesh.points[mesh.triangles].mean(axis=1)[:, 1]
        lo, hi = centroid_y.min(), centroid_y.max()
        mine = np.flatnonzero(np.minimum(((centroid_y - lo) / (hi - lo) * SIZE).astype(int), SIZE - 1) == RANK)
        used = np.unique(mesh.triangles[mine])
        local = np.full(mesh.n_points, -1)
        local[used] = np.arange(len(used))
        seg = np.flatnonzero((local[mesh.segments] >= 0).all(axis=1))
        return DistributedMesh.from_local(
            mesh.points[used], local[mesh.triangles[mine]], used, COMM, segments=local[mesh.segments[seg]],
            segment_tags=mesh.segment_tags[seg], required=mesh.required[used], kind=mesh.kind[used],
            triangle_global_ids=mine, segment_global_ids=seg)
    weights = None
    if layout == "weighted":  # uneven triangle weights move every cut
        weights = np.random.default_rng(seed).uniform(0.1, 10.0, len(mesh.triangles))
    elif layout == "crowded":  # most weight on a few triangles: some ranks own a sliver
        weights = np.where(np.random.default_rng(seed).random(len(mesh.triangles)) < 0.02, 1000.0, 1.0)
    return DistributedMesh.scatter(mesh if RANK == 0 else None, COMM, weights=weights)


def _same_bits(mine: np.ndarray, reference: np.ndarray) -> bool:
    return bool(np.array_equal(np.asarray(mine).view(np.int64), np.asarray(reference).view(np.int64)))


@pytest.mark.parametrize("within", [True, False], ids=["within", "euclidean"])
@pytest.mark.parametrize("layout", ["even", "weighted", "crowded", "stripes"])
@pytest.mark.parametrize("kind", ["random", "front", "coarsen", "spiky"])
@pytest.mark.parametrize("name", list(_DOMAINS))
def test_step_one_equals_the_serial_step(name: str, kind: str, layout: str, within: bool) -> None:
    mesh = _mesh(name)
    delta = _delta(mesh, kind, seed=len(name))
    reference = _serial(mesh, delta, within)
    dmesh = _scatter(mesh, layout, seed=3)
    owned = dmesh.global_ids[: dmesh.n_owned]
    stats: dict = {}
    spacing = DistributedSpacing(dmesh, delta[owned], within_domain=within, stats=stats)
    for key, mine in (("nn", spacing.nn), ("weight", spacing.weight), ("f", spacing.f)):
        check_everywhere(_same_bits(mine, np.asarray(reference[key])[owned]), f"{key} differs from the serial step")
    # The cases reach what they are for: the feature size caps weights (channel,
    # cracks), f is evaluated (delta > 1), and ranks exchange halos.
    capped = COMM.allreduce(int((spacing.weight < delta[owned] * spacing.nn).sum()))
    if within and name in ("channel", "cracks and a notch") and kind in ("random", "coarsen"):
        assert capped > 0
    if not within:
        assert capped == 0
    sites_received = COMM.allreduce(int(stats["sites_received"]))
    if SIZE > 1:
        assert stats["halo_points"] > 0
        # (counted over the ranks: a rank whose f its own sites settle receives none; and a front's
        # cut may fall where every rank's are enough, as on the channel's mesh on two ranks)
        assert sites_received > 0 or kind == "front"
        if within and name != "disc with a hole":
            assert stats["walk_triangles"] > 0


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), name=st.sampled_from(["channel", "cracks and a notch", "two holes"]),
       k=st.integers(0, 60))
def test_f_anywhere_equals_the_serial_spacing_function(seed: int, name: str, k: int) -> None:
    """f at points each rank picks (any number, also none, anywhere in the box
    and beyond it) equals the serial spacing function of all the weights."""
    mesh = _mesh(name)
    seed = COMM.bcast(seed)
    delta = _delta(mesh, "random", seed)
    reference = _serial(mesh, delta, True)
    dmesh = _scatter(mesh, "even", seed)
    owned = dmesh.global_ids[: dmesh.n_owned]
    spacing = DistributedSpacing(dmesh, delta[owned])
    rng = np.random.default_rng([seed, RANK])
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    x = lo + rng.uniform(-0.2, 1.2, (k * (RANK % 3), 2)) * (hi - lo)
    x = np.concatenate([x, mesh.points[rng.integers(0, mesh.n_points, k // 2)]])  # also at mesh points
    got = spacing.evaluate(x)
    serial = _core.SpacingFunction(mesh.points, np.asarray(reference["weight"]), triangles=mesh.triangles)
    check_everywhere(_same_bits(got, serial.evaluate(x)[0] if len(x) else np.zeros(0)), "f differs from serial")


def test_delta_as_a_function_of_the_coordinates() -> None:
    mesh = _mesh("two holes")
    dmesh = _scatter(mesh, "even", 0)

    def delta(xy: np.ndarray) -> np.ndarray:
        return 0.5 + xy[:, 0]

    spacing = DistributedSpacing(dmesh, delta)
    reference = _serial(mesh, 0.5 + mesh.points[:, 0], True)
    owned = dmesh.global_ids[: dmesh.n_owned]
    check_everywhere(_same_bits(spacing.f, np.asarray(reference["f"])[owned]), "f from a callable delta")
    assert not spacing.f.flags.writeable


@pytest.mark.parametrize("bad", ["nan", "zero", "length", "text"])
def test_bad_delta_on_one_rank_raises_on_every_rank(bad: str) -> None:
    mesh = _mesh("two holes")
    dmesh = _scatter(mesh, "even", 0)
    delta: object = np.ones(dmesh.n_owned)
    if RANK == SIZE - 1:
        delta = {"nan": np.full(dmesh.n_owned, np.nan), "zero": np.zeros(dmesh.n_owned),
                 "length": np.ones(dmesh.n_owned + 1), "text": np.array(["a"] * dmesh.n_owned)}[bad]
    with pytest.raises((ValueError, TypeError), match=f"on rank {SIZE - 1}"):
        DistributedSpacing(dmesh, delta)


def test_not_a_distributed_mesh() -> None:
    with pytest.raises(TypeError, match="DistributedMesh"):
        DistributedSpacing(_mesh("two holes"), 1.0)
