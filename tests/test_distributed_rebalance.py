"""DistributedMesh.rebalance: the points cut into equal-weight
Hilbert ranges and renumbered along the curve, the same result whatever
partition the mesh came in.

Plain ``pytest`` runs these on one rank; CI also runs them under ``mpiexec -n 2``
and ``-n 4`` (tools/run-tests.sh), and any K works:
``mpiexec -n K python -m pytest -q -p no:cacheprovider tests/test_distributed_rebalance.py``.
Every rank builds the same global mesh, hands its share to ``from_local`` (or
the root scatters it), and checks its part of the result against a serial
oracle written here from the definition (docs/distributed-step.md, 2.4): the
expected pieces go through ``from_local``, whose halos tests/test_distributed.py
checks, and every public array must be equal.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import evomesh
from evomesh.distributed.mesh import Renumbering, _hilbert_keys
from evomesh.meshgen import unit_square_mesh
from strategies import any_meshes

MPI = pytest.importorskip("mpi4py.MPI")
COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size
from mpi_support import check_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)
from test_distributed import PUBLIC, assert_same_mesh, mesh_named, raises_everywhere  # noqa: E402

BAD_RANK = SIZE - 1


# ------------------------------------------------------------ the oracle
def canonical_order(points: np.ndarray) -> np.ndarray:
    """Old index at each new position: Hilbert keys (2^31 cells a side over the
    bounding box, square cells), ties by (x, y), then by old index."""
    low = points.min(axis=0)
    extent = (points.max(axis=0) - low).max()
    top = (1 << 31) - 1
    cells = np.clip(np.floor((points - low) * (top / extent)), 0, top)
    key = _hilbert_keys(cells[:, 0], cells[:, 1], 31)
    return np.lexsort((np.arange(len(points)), points[:, 1], points[:, 0], key))


def cut(weights_in_order: np.ndarray, size: int) -> np.ndarray:
    """Rank of each position: the range of equal weight its weight's midpoint lies in
    (exact in floating point for the integer weights used here)."""
    before = np.cumsum(weights_in_order) - weights_in_order
    middle = before + 0.5 * weights_in_order
    return np.minimum(np.floor(size * middle / weights_in_order.sum()), size - 1).astype(np.int64)


def expected(mesh: evomesh.Mesh, halo_rings: int, weights: np.ndarray | None = None) -> evomesh.DistributedMesh:
    """The rebalanced mesh built from the definition, through from_local."""
    old_of_new = canonical_order(mesh.points)
    new_of_old = np.empty_like(old_of_new)
    new_of_old[old_of_new] = np.arange(len(old_of_new))
    w = np.ones(mesh.n_points) if weights is None else weights[old_of_new]
    owner = cut(w, SIZE)  # by new gid
    tris = new_of_old[mesh.triangles]
    tris = np.take_along_axis(tris, (np.argmin(tris, axis=1)[:, None] + np.arange(3)) % 3, axis=1)
    tri_order = np.lexsort(tris.T[::-1])
    tris, tri_tags = tris[tri_order], mesh.triangle_tags[tri_order]
    segs = new_of_old[mesh.segments]
    seg_order = np.lexsort(np.sort(segs, axis=1).T[::-1])
    segs, seg_tags = segs[seg_order], mesh.segment_tags[seg_order]
    mine_t = owner[tris[:, 0]] == RANK
    mine_s = owner[segs.min(axis=1)] == RANK
    used = np.unique(np.concatenate([np.flatnonzero(owner == RANK), tris[mine_t].ravel(), segs[mine_s].ravel()]))
    return evomesh.DistributedMesh.from_local(
        mesh.points[old_of_new][used], np.searchsorted(used, tris[mine_t]), used, COMM, owners=owner[used],
        segments=np.searchsorted(used, segs[mine_s]), segment_tags=seg_tags[mine_s], triangle_tags=tri_tags[mine_t],
        required=mesh.required[old_of_new][used], kind=mesh.kind[old_of_new][used],
        origin=mesh.origin[old_of_new][used], tag_names=dict(mesh.tag_names),
        triangle_global_ids=np.flatnonzero(mine_t), segment_global_ids=np.flatnonzero(mine_s), halo_rings=halo_rings)


# ------------------------------------------------------- input partitions
def point_owners(mesh: evomesh.Mesh, how: str) -> np.ndarray:
    if how == "random":
        return np.random.default_rng(7).integers(0, SIZE, mesh.n_points)
    if how == "x_stripes":
        x = mesh.points[:, 0]
        return np.minimum(np.floor((x - x.min()) / np.ptp(x) * SIZE), SIZE - 1).astype(np.int64)
    if how == "all_on_last_rank":
        return np.full(mesh.n_points, SIZE - 1)
    raise ValueError(how)


def distributed(mesh: evomesh.Mesh, how: str, halo_rings: int = 1) -> evomesh.DistributedMesh:
    """`mesh` (gids = its indices) over the ranks in one of several partitions."""
    if how == "scatter":
        return evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM, halo_rings=halo_rings)
    if how == "round_robin":  # triangles dealt round robin, the lowest rank holding a point owns it
        mine_t, owners = np.arange(mesh.n_triangles) % SIZE == RANK, None
    else:
        owner = point_owners(mesh, how)
        mine_t = (owner[mesh.triangles] == RANK).any(axis=1)  # every owned point is in a held triangle
    used = np.unique(mesh.triangles[mine_t])
    if how != "round_robin":
        owners = owner[used]
    mine_s = np.isin(mesh.segments, used).all(axis=1)
    return evomesh.DistributedMesh.from_local(
        mesh.points[used], np.searchsorted(used, mesh.triangles[mine_t]).reshape(-1, 3), used, COMM, owners=owners,
        segments=np.searchsorted(used, mesh.segments[mine_s]).reshape(-1, 2), segment_tags=mesh.segment_tags[mine_s],
        triangle_tags=mesh.triangle_tags[mine_t], required=mesh.required[used], kind=mesh.kind[used],
        origin=mesh.origin[used], tag_names=dict(mesh.tag_names), triangle_global_ids=np.flatnonzero(mine_t),
        segment_global_ids=np.flatnonzero(mine_s), halo_rings=halo_rings)


PARTITIONS = ("scatter", "random", "x_stripes", "all_on_last_rank", "round_robin")


def same_arrays(a: evomesh.DistributedMesh, b: evomesh.DistributedMesh) -> bool:
    return all(np.array_equal(getattr(a, name), getattr(b, name)) for name in PUBLIC) \
        and a.halo_rings == b.halo_rings and dict(a.tag_names) == dict(b.tag_names)


# ------------------------------------------------------------------ tests
@pytest.mark.parametrize("name, partitions", [
    ("tags_required_names", PARTITIONS),
    ("holes", PARTITIONS),
    ("two_triangles", PARTITIONS),  # most ranks own nothing before and after
    ("disc_with_hole_curves", ("scatter", "random")),
    ("shuffled_tags", ("scatter", "x_stripes")),
])
def test_rebalance_is_the_canonical_order_whatever_the_partition(name, partitions):
    mesh = mesh_named(name)
    want = expected(mesh, halo_rings=1)
    for how in partitions:
        got = distributed(mesh, how).rebalance()
        check_everywhere(same_arrays(got, want), f"rebalance of the {how} partition is the canonical mesh")


@pytest.mark.parametrize("halo_rings", [0, 2])
def test_halo_rings_of_the_result(halo_rings):
    mesh = mesh_named("tags_required_names")
    d = distributed(mesh, "random", halo_rings=halo_rings)
    check_everywhere(same_arrays(d.rebalance(), expected(mesh, halo_rings)), "the input's rings by default")
    other = 1 if halo_rings == 0 else 0
    check_everywhere(same_arrays(d.rebalance(halo_rings=other), expected(mesh, other)), "rings asked for")


def test_weights_are_cut_into_equal_ranges():
    """Power-of-two weights (exact in the oracle's floating point too): the same
    cut as the definition, for any partition; an array and a callable agree."""
    mesh = mesh_named("holes")
    weight = 2.0 ** np.random.default_rng(3).integers(0, 4, mesh.n_points)
    want = expected(mesh, 1, weight)
    for how in ("scatter", "x_stripes", "all_on_last_rank"):
        d = distributed(mesh, how)
        got = d.rebalance(weight[d.global_ids[: d.n_owned]])
        check_everywhere(same_arrays(got, want), f"weighted rebalance of the {how} partition")
    by_position = {tuple(p): w for p, w in zip(mesh.points.tolist(), weight)}
    got = d.rebalance(lambda xy: np.array([by_position[tuple(p)] for p in xy.tolist()]))
    check_everywhere(same_arrays(got, want), "a callable of the owned points gives the same")


@pytest.mark.parametrize("how", ["x_stripes", "all_on_last_rank"])
def test_unit_weights_balance_the_owned_points(how):
    """A graded mesh (dense near x = 0) in x-stripes is badly balanced; after:
    owned counts differ by at most one, at >= 200 points a rank."""
    base = unit_square_mesh(max(1000, 220 * SIZE))
    graded = evomesh.Mesh(np.c_[base.points[:, 0] ** 3, base.points[:, 1]], base.triangles)
    d = distributed(graded, how)
    stats = d.rebalance().partition_stats()
    counts = stats["owned_points"]
    assert counts.sum() == graded.n_points and counts.min() >= 200
    assert counts.max() - counts.min() <= 1 and counts.max() <= 1.1 * counts.mean()
    assert stats["point_balance"] == counts.max() / counts.mean()
    if SIZE > 1:
        assert d.partition_stats()["point_balance"] > 1.1  # the test starts from a skewed partition


def test_owned_weight_is_within_one_weight_of_the_ideal():
    """Any finite weights >= 0 (zeros included): each rank's owned weight is
    within the largest weight of total / size (the documented bound)."""
    mesh = mesh_named("disc_with_hole_curves")
    rng = np.random.default_rng(11)
    weight = rng.random(mesh.n_points) * 10.0 ** rng.integers(-3, 3, mesh.n_points)
    weight[rng.random(mesh.n_points) < 0.1] = 0.0
    d = distributed(mesh, "random")
    e, renumbering = d.rebalance(weight[d.global_ids[: d.n_owned]], return_map=True)
    owned = np.array(COMM.allgather(weight[renumbering.points].sum()))
    ideal = weight.sum() / SIZE
    assert (np.abs(owned - ideal) <= weight.max() * (1 + 1e-9)).all(), (owned, ideal, weight.max())


def test_gather_after_rebalance_is_the_input_renumbered():
    """The gathered mesh is the input with its points permuted (the Renumbering
    says how), the same triangles, segments and labels."""
    mesh = mesh_named("tags_required_names")
    d = distributed(mesh, "x_stripes")
    e, renumbering = d.rebalance(return_map=True)
    back = e.gather()
    old_of_new = e.gather_field(renumbering.points)
    if RANK == 0:
        assert np.array_equal(np.sort(old_of_new), np.arange(mesh.n_points))
        new_of_old = np.argsort(old_of_new)
        for name in ("points", "required", "kind", "origin"):
            assert np.array_equal(getattr(back, name), getattr(mesh, name)[old_of_new]), name
        # Along the curve: Hilbert keys over the bounding box never decrease with the gid.
        assert np.array_equal(canonical_order(back.points), np.arange(back.n_points))

        def triangle_rows(tris, tags):
            return sorted(tuple(np.roll(t, -int(np.argmin(t)))) + (int(g),) for t, g in zip(tris, tags))

        def segment_rows(segs, tags):  # the Mesh constructor orients interior segments its own way
            return sorted(tuple(np.sort(s)) + (int(g),) for s, g in zip(segs, tags))

        assert triangle_rows(back.triangles, back.triangle_tags) == \
            triangle_rows(new_of_old[mesh.triangles], mesh.triangle_tags)
        assert segment_rows(back.segments, back.segment_tags) == \
            segment_rows(new_of_old[mesh.segments], mesh.segment_tags)
        assert dict(back.tag_names) == dict(mesh.tag_names)


def test_renumbering_maps_owned_entities_to_their_old_gids():
    mesh = mesh_named("shuffled_tags")
    d = distributed(mesh, "scatter")
    e, renumbering = d.rebalance(return_map=True)
    check_everywhere(isinstance(renumbering, Renumbering), "a Renumbering")
    with pytest.raises(AttributeError):
        renumbering.points = None
    check_everywhere(not renumbering.points.flags.writeable, "read-only arrays")
    old = e.exchange_halo(renumbering.points)  # old gid of every held point
    ok = (np.array_equal(e.owned_points, mesh.points[renumbering.points])
          and np.array_equal(e.points, mesh.points[old])
          and np.array_equal(e.triangle_tags, mesh.triangle_tags[renumbering.triangles])
          and np.array_equal(e.segment_tags, mesh.segment_tags[renumbering.segments])
          and np.array_equal(old[e.segments], mesh.segments[renumbering.segments]))  # orientation kept
    # Triangles: the same ones, rotated (orientation kept) to start at the smallest new gid.
    new_rows, old_rows = old[e.triangles], mesh.triangles[renumbering.triangles]
    rotations = [np.roll(old_rows, -k, axis=1) for k in range(3)]
    ok = ok and bool(np.logical_or.reduce([(new_rows == r).all(axis=1) for r in rotations]).all())
    ok = ok and bool((np.argmin(e.global_ids[e.triangles], axis=1) == 0).all())
    check_everywhere(ok, "the renumbering names each owned entity's old gid")
    # Old gids are unique over the ranks and cover the mesh.
    every = np.concatenate(COMM.allgather(renumbering.points))
    assert np.array_equal(np.sort(every), np.arange(mesh.n_points))


@pytest.mark.parametrize("renumber", [True, False])
def test_values_move_with_their_points_and_triangles(renumber):
    mesh = mesh_named("tags_required_names")
    d = distributed(mesh, "x_stripes")
    e, renumbering = d.rebalance(renumber=renumber, return_map=True)
    gid, tgid = d.global_ids[: d.n_owned], d.triangle_global_ids
    moved = renumbering.move_point_values(np.c_[gid * 2.0, -gid])  # any row shape
    labels = renumbering.move_triangle_values((tgid % 5).astype(np.int8))  # any dtype
    check_everywhere(np.array_equal(moved, np.c_[renumbering.points * 2.0, -renumbering.points])
                     and labels.dtype == np.int8 and np.array_equal(labels, renumbering.triangles % 5),
                     "values land on the rows that hold their old gids")
    check_everywhere(np.array_equal(renumbering.move_point_values(d.required[: d.n_owned]), e.required[: e.n_owned]),
                     "a field of the points is the new mesh's")
    message = raises_everywhere(ValueError, renumbering.move_point_values,
                                np.zeros(d.n_owned + (RANK == BAD_RANK)))
    assert f"rank {BAD_RANK}" in message and "one row per owned point of the mesh before rebalance" in message


@pytest.mark.parametrize("how", ["scatter", "random"])
def test_renumber_false_keeps_the_gids_and_moves_the_owners(how):
    mesh = mesh_named("tags_required_names")
    d = distributed(mesh, how)
    kept, renumbering = d.rebalance(renumber=False, return_map=True)
    renumbered, moved = d.rebalance(return_map=True)
    check_everywhere(np.array_equal(np.sort(kept.global_ids[: kept.n_owned]), np.sort(moved.points)),
                     "the same owned points as with renumbering")
    check_everywhere(np.array_equal(renumbering.points, kept.global_ids[: kept.n_owned])
                     and np.array_equal(renumbering.triangles, kept.triangle_global_ids), "the identity map")
    back, before = kept.gather(), d.gather()
    if RANK == 0:
        assert_same_mesh(back, before)
        if how == "scatter":
            assert_same_mesh(back, mesh)


def test_rebalance_twice_changes_nothing():
    d = distributed(mesh_named("holes"), "random").rebalance()
    again, renumbering = d.rebalance(return_map=True)
    check_everywhere(same_arrays(again, d), "a canonical mesh is its own rebalance")
    check_everywhere(np.array_equal(renumbering.points, d.global_ids[: d.n_owned])
                     and np.array_equal(renumbering.triangles, d.triangle_global_ids)
                     and np.array_equal(renumbering.segments, d.segment_global_ids), "the identity map")


# Every rank must draw the same examples (they run the same collectives).
@settings(max_examples=10, derandomize=True, database=None)
@given(mesh=any_meshes(), seed=st.integers(0, 2**16), halo_rings=st.integers(0, 2))
def test_random_meshes_and_partitions_give_one_result(mesh, seed, halo_rings):
    """Grids with holes and notches, random clouds with several components,
    extreme scales: a random partition and the scatter give the same result,
    and it is the definition's."""
    owner = np.random.default_rng(seed).integers(0, SIZE, mesh.n_points)
    mine_t = (owner[mesh.triangles] == RANK).any(axis=1)
    used = np.unique(mesh.triangles[mine_t])
    mine_s = np.isin(mesh.segments, used).all(axis=1)
    d = evomesh.DistributedMesh.from_local(
        mesh.points[used], np.searchsorted(used, mesh.triangles[mine_t]).reshape(-1, 3), used, COMM,
        owners=owner[used], segments=np.searchsorted(used, mesh.segments[mine_s]).reshape(-1, 2),
        kind=mesh.kind[used], halo_rings=halo_rings)
    got = d.rebalance()
    scattered = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM, halo_rings=halo_rings)
    check_everywhere(same_arrays(got, scattered.rebalance()), "the same result from two partitions")
    check_everywhere(same_arrays(got, expected(mesh, halo_rings)), "the definition's result")


@pytest.mark.skipif(SIZE < 2, reason="needs a rank that differs")
def test_halo_rings_must_agree():
    d = distributed(mesh_named("holes"), "scatter")
    message = raises_everywhere(ValueError, d.rebalance, halo_rings=2 if RANK == BAD_RANK else 1)
    assert "halo_rings must be the same on every rank" in message
    message = raises_everywhere(ValueError, d.rebalance, renumber=RANK != BAD_RANK)
    assert "renumber must be the same on every rank" in message


def _bad_weights(d: evomesh.DistributedMesh, how: str):
    weight = np.ones(d.n_owned)
    if how == "all_zero":
        return np.zeros(d.n_owned)
    if RANK != BAD_RANK:
        return weight
    if how == "wrong_length":
        return np.ones(d.n_owned + 1)
    if how == "two_columns":
        return np.ones((d.n_owned, 2))
    if how in ("nan", "negative", "infinite"):
        weight[-1] = {"nan": np.nan, "negative": -1.0, "infinite": np.inf}[how]  # (every rank owns points here)
        return weight
    if how == "callable_raises":
        return lambda xy: 1 / 0
    if how == "callable_wrong_shape":
        return lambda xy: np.ones(len(xy) + 1)
    raise ValueError(how)


@pytest.mark.parametrize("how, exception", [
    ("wrong_length", ValueError), ("two_columns", ValueError), ("nan", ValueError), ("negative", ValueError),
    ("infinite", ValueError), ("all_zero", ValueError), ("callable_raises", RuntimeError),
    ("callable_wrong_shape", ValueError)])
def test_bad_weights_raise_on_every_rank(how, exception):
    d = distributed(mesh_named("holes"), "scatter")
    weights = _bad_weights(d, how)
    message = raises_everywhere(exception, d.rebalance, weights)
    if how != "all_zero":
        assert f"rank {BAD_RANK}" in message
    assert COMM.allreduce(1) == SIZE  # the communicator still works


def test_bad_flags_raise_on_every_rank():
    d = distributed(mesh_named("holes"), "scatter")
    # (with other ranks, a flag given otherwise on one rank is first a disagreement)
    alone = TypeError if SIZE == 1 else ValueError
    raises_everywhere(alone, d.rebalance, renumber="yes" if RANK == BAD_RANK else True)
    raises_everywhere(alone, d.rebalance, return_map=1 if RANK == BAD_RANK else False)
    raises_everywhere(TypeError, d.rebalance, return_map=1)
    raises_everywhere(ValueError, d.rebalance, halo_rings=-1 if RANK == BAD_RANK else 1)
    raises_everywhere(TypeError, d.rebalance, np.array(["a"] * d.n_owned))


def test_rebalance_does_not_change_its_input():
    d = distributed(mesh_named("holes"), "x_stripes")
    before = {name: np.array(getattr(d, name)) for name in PUBLIC if isinstance(getattr(d, name), np.ndarray)}
    weight = np.ones(d.n_owned)
    d.rebalance(weight)
    check_everywhere(all(np.array_equal(getattr(d, name), value) for name, value in before.items())
                     and (weight == 1).all(), "the input and the weights are unchanged")
