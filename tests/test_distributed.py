"""evomesh.DistributedMesh: scatter/gather round trips, ownership, halos, exchanges
and failure propagation on any number of MPI ranks.

Plain ``pytest`` runs these on one rank (COMM_WORLD of size 1); CI also runs
``mpiexec -n 2`` and ``-n 4`` (tools/run-tests.sh), and any K works:
``mpiexec -n K python -m pytest -q -p no:cacheprovider tests/test_distributed.py``.
Every rank runs the same tests in the same order; a property is checked on
every rank and agreed on (``check_everywhere``), so a failure on one rank fails
the test on all of them instead of leaving the others waiting. A watchdog
(faulthandler, a thread that also fires inside a blocking MPI call) ends a
rank that hangs, so a hang fails CI instead of stalling it.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import evomesh
from evomesh.distributed.mesh import _hilbert_keys
from evomesh.meshgen import disc_with_hole_mesh, polygon_mesh, unit_square_mesh
from strategies import any_meshes, grid_mesh

MPI = pytest.importorskip("mpi4py.MPI")
COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size
from mpi_support import check_everywhere, raises_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)


# ----------------------------------------------------------------- meshes
def _shuffled(mesh: evomesh.Mesh, seed: int) -> evomesh.Mesh:
    """The same mesh with its points and triangles in a random order (global ids
    unrelated to space)."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(mesh.n_points)
    inverse = np.empty_like(perm)
    inverse[perm] = np.arange(len(perm))
    tri_order = rng.permutation(mesh.n_triangles)
    return evomesh.Mesh(mesh.points[perm], inverse[mesh.triangles][tri_order], inverse[mesh.segments],
                        segment_tags=mesh.segment_tags, triangle_tags=mesh.triangle_tags[tri_order],
                        required=mesh.required[perm], tag_names=mesh.tag_names)


def _tagged_grid() -> evomesh.Mesh:
    """A square with a hole, two regions, tagged boundary pieces, required points and names."""
    base = grid_mesh(13, 11, hole=True)
    centroid = base.points[base.triangles].mean(axis=1)
    tri_tags = np.where(centroid[:, 0] < 0.5, 3, 4)
    segs = base.segments
    mid = base.points[segs].mean(axis=1)
    seg_tags = np.where(mid[:, 1] < 1e-12, 7, np.where(mid[:, 0] < 1e-12, 8, 9))
    required = np.zeros(base.n_points, bool)
    required[::17] = True
    return evomesh.Mesh(base.points, base.triangles, segs, segment_tags=seg_tags, triangle_tags=tri_tags,
                        required=required, tag_names={(1, 7): "bottom", (1, 8): "left", (2, 3): "steel"})


def _holes() -> evomesh.Mesh:
    outer = np.array([[0, 0], [2, 0], [2, 1], [0, 1.0]])
    square = np.array([[0.3, 0.3], [0.6, 0.3], [0.6, 0.6], [0.3, 0.6]])
    triangle = np.array([[1.3, 0.3], [1.6, 0.3], [1.5, 0.7]])
    return polygon_mesh([outer, square, triangle], 0.08)


def _two_triangles() -> evomesh.Mesh:
    return evomesh.Mesh([[0, 0], [1, 0], [1, 1], [0, 1]], [[0, 1, 2], [0, 2, 3]])


MESHES = {
    "square": lambda: unit_square_mesh(600),
    "disc_with_hole_curves": lambda: disc_with_hole_mesh(0.1),
    "holes": _holes,
    "tags_required_names": _tagged_grid,
    "shuffled_tags": lambda: _shuffled(_tagged_grid(), 5),
    "two_triangles": _two_triangles,
}
_cache: dict[str, evomesh.Mesh] = {}


def mesh_named(name: str) -> evomesh.Mesh:
    """Built on every rank (deterministic): the root scatters it, the others check against it."""
    if name not in _cache:
        _cache[name] = MESHES[name]()
    return _cache[name]


def assert_same_mesh(a: evomesh.Mesh, b: evomesh.Mesh) -> None:
    for name in ("points", "triangles", "segments", "segment_is_boundary", "kind", "origin", "segment_tags",
                 "triangle_tags", "required"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
        assert getattr(a, name).dtype == getattr(b, name).dtype, name
    assert dict(a.tag_names) == dict(b.tag_names)


def held_triangles(d: evomesh.DistributedMesh) -> np.ndarray:
    return np.concatenate([d.triangle_global_ids, d.halo_triangle_global_ids])


# ------------------------------------------------------------------ tests
def test_hilbert_keys_walk_the_grid_cell_by_cell():
    order = 4
    x, y = np.meshgrid(np.arange(16), np.arange(16))
    keys = _hilbert_keys(x.ravel(), y.ravel(), order)
    assert np.array_equal(np.sort(keys), np.arange(256))
    cells = np.c_[x.ravel(), y.ravel()][np.argsort(keys)]
    assert (np.abs(np.diff(cells, axis=0)).sum(axis=1) == 1).all()  # consecutive keys are neighbours


@pytest.mark.skipif(SIZE > 1, reason="one subprocess is enough")
def test_import_evomesh_without_mpi4py():
    code = ("import sys; sys.modules['mpi4py'] = None; import evomesh\n"
            "try:\n    evomesh.DistributedMesh.scatter(None, None)\nexcept ImportError as e:\n"
            "    print('ImportError', e)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "ImportError" in out and "evomesh[mpi]" in out


@pytest.mark.parametrize("name", sorted(MESHES))
@pytest.mark.parametrize("halo_rings", [1, 2])
def test_scatter_then_gather_returns_the_input(name, halo_rings):
    mesh = mesh_named(name)
    d = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM, halo_rings=halo_rings)
    back = d.gather()
    if RANK == 0:
        assert_same_mesh(back, mesh)
    else:
        assert back is None
    # Gathered on another root, the same.
    root = SIZE - 1
    back = d.gather(root=root)
    check_everywhere((back is None) == (RANK != root), "gather returns a Mesh on the root only")
    if RANK == root:
        assert_same_mesh(back, mesh)


# Every rank must draw the same examples (they run the same collectives), so the
# examples are derandomized here whatever the profile says.
@settings(max_examples=12, derandomize=True, database=None)
@given(mesh=any_meshes(), halo_rings=st.integers(0, 2), weighted=st.booleans())
def test_random_meshes_round_trip_with_exact_halos(mesh, halo_rings, weighted):
    """Grids with holes and notches, random clouds with several components,
    pinched vertices, extreme scales; uniform or random weights."""
    weights = np.random.default_rng(mesh.n_points).random(mesh.n_triangles) + 0.01 if weighted else None
    d = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM, weights=weights, halo_rings=halo_rings)
    back = d.gather()
    same = RANK != 0 or all(np.array_equal(getattr(back, a), getattr(mesh, a))
                            for a in ("points", "triangles", "segments", "kind", "segment_tags"))
    check_everywhere(same, "gather(scatter(mesh)) == mesh")
    _check_ownership_and_halo(mesh, d, halo_rings)
    values = d.exchange_halo(d.global_ids[: d.n_owned] * 2 + 1)
    check_everywhere(np.array_equal(values, d.global_ids * 2 + 1), "exchange_halo gives the owners' values")


@pytest.mark.parametrize("name", ["square", "holes", "tags_required_names", "shuffled_tags", "two_triangles"])
@pytest.mark.parametrize("halo_rings", [0, 1, 2])
def test_ownership_and_halo(name, halo_rings):
    mesh = mesh_named(name)
    d = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM, halo_rings=halo_rings)
    _check_ownership_and_halo(mesh, d, halo_rings)


def _check_ownership_and_halo(mesh: evomesh.Mesh, d: evomesh.DistributedMesh, halo_rings: int) -> None:
    gid = d.global_ids
    # Local arrays describe the global mesh.
    local_ok = (np.array_equal(gid[d.triangles], mesh.triangles[d.triangle_global_ids])
                and np.array_equal(gid[d.halo_triangles], mesh.triangles[d.halo_triangle_global_ids])
                and np.array_equal(d.points, mesh.points[gid])
                and np.array_equal(gid[d.segments], mesh.segments[d.segment_global_ids])
                and np.array_equal(d.triangle_tags, mesh.triangle_tags[d.triangle_global_ids])
                and np.array_equal(d.segment_tags, mesh.segment_tags[d.segment_global_ids])
                and np.array_equal(d.required, mesh.required[gid]) and np.array_equal(d.kind, mesh.kind[gid])
                and np.array_equal(d.owned_points, d.points[: d.n_owned])
                and (d.owners[: d.n_owned] == RANK).all() and (d.owners[d.n_owned:] != RANK).all()
                and np.array_equal(np.sort(gid[: d.n_owned]), gid[: d.n_owned])
                and np.array_equal(np.sort(gid[d.n_owned:]), gid[d.n_owned:]))
    check_everywhere(local_ok, "local arrays match the serial mesh")
    # Every point owned once; owners agree wherever a point is held.
    owner = np.full(mesh.n_points, -1)
    for g, o in zip(COMM.allgather(gid[: d.n_owned]), range(SIZE)):
        assert (owner[g] == -1).all()
        owner[g] = o
    assert (owner >= 0).all()
    check_everywhere(np.array_equal(d.owners, owner[gid]), "owners agree across ranks")
    # Every triangle owned once, by the owner of its smallest-gid vertex; segments likewise.
    owned = np.concatenate(COMM.allgather(d.triangle_global_ids))
    assert np.array_equal(np.sort(owned), np.arange(mesh.n_triangles))
    check_everywhere((owner[mesh.triangles[d.triangle_global_ids].min(axis=1)] == RANK).all(),
                     "a triangle is owned by the owner of its smallest vertex")
    segs = np.concatenate(COMM.allgather(d.segment_global_ids))
    assert np.array_equal(np.sort(segs), np.arange(len(mesh.segments)))
    check_everywhere((owner[mesh.segments[d.segment_global_ids].min(axis=1)] == RANK).all(),
                     "a segment is owned by the owner of its smaller end")
    # The halo: exactly the rings around the owned points and owned triangles' vertices.
    core = np.zeros(mesh.n_points, bool)
    core[owner == RANK] = True
    core[mesh.triangles[owner[mesh.triangles.min(axis=1)] == RANK].ravel()] = True
    held = owner[mesh.triangles.min(axis=1)] == RANK
    reach = core
    for _ in range(halo_rings):
        held |= reach[mesh.triangles].any(axis=1)
        reach = reach.copy()
        reach[mesh.triangles[held].ravel()] = True
    check_everywhere(np.array_equal(np.sort(held_triangles(d)), np.flatnonzero(held)),
                     "the held triangles are the owned ones and the halo rings")
    wanted_points = np.zeros(mesh.n_points, bool)
    wanted_points[mesh.triangles[held].ravel()] = True
    wanted_points[owner == RANK] = True
    owned_segments = mesh.segments[owner[mesh.segments.min(axis=1)] == RANK]
    wanted_points[owned_segments.ravel()] = True  # only adds points without a halo
    check_everywhere(np.array_equal(np.sort(gid), np.flatnonzero(wanted_points)),
                     "the held points are the owned ones and the vertices of held triangles")
    if halo_rings >= 1:
        # Every triangle sharing a vertex with an owned triangle is held.
        owned_vertex = np.zeros(mesh.n_points, bool)
        owned_vertex[mesh.triangles[d.triangle_global_ids].ravel()] = True
        check_everywhere(np.isin(np.flatnonzero(owned_vertex[mesh.triangles].any(axis=1)), held_triangles(d)).all(),
                         "the halo holds every triangle next to an owned one")
    # Held segments: those that are edges of held triangles.
    edges = {tuple(sorted(e)) for t in mesh.triangles[held] for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    expected = [k for k, s in enumerate(mesh.segments) if tuple(sorted(s)) in edges or owner[min(s)] == RANK]
    got = np.sort(np.concatenate([d.segment_global_ids, d.halo_segment_global_ids]))
    check_everywhere(np.array_equal(got, expected), "the held segments: the owned ones, the edges of held triangles")


@pytest.mark.parametrize("name", ["square", "holes", "shuffled_tags"])
def test_exchange_halo_and_gather_field(name):
    mesh = mesh_named(name)
    d = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM)
    gid = d.global_ids
    values = np.c_[gid * 3.0 + 0.5, -gid * 1.0][: d.n_owned]
    full = d.exchange_halo(values)
    check_everywhere(np.array_equal(full, np.c_[gid * 3.0 + 0.5, -gid * 1.0]), "halo values are the owners'")
    labels = d.exchange_halo((gid[: d.n_owned] % 7).astype(np.int16))
    check_everywhere(labels.dtype == np.int16 and np.array_equal(labels, gid % 7), "integer fields too")
    field = d.gather_field(values)
    if RANK == 0:
        n = mesh.n_points
        assert np.array_equal(field, np.c_[np.arange(n) * 3.0 + 0.5, -np.arange(n) * 1.0])
    else:
        assert field is None
    message = raises_everywhere(ValueError, d.exchange_halo, np.zeros(d.n_owned + (RANK == SIZE - 1)))
    assert f"rank {SIZE - 1}" in message


def _pieces(d: evomesh.DistributedMesh) -> dict:
    """The arrays of a DistributedMesh as from_local input (owned and halo together)."""
    return dict(points=d.points, triangles=np.concatenate([d.triangles, d.halo_triangles]), global_ids=d.global_ids,
                segments=np.concatenate([d.segments, d.halo_segments]),
                segment_tags=np.concatenate([d.segment_tags, d.halo_segment_tags]),
                triangle_tags=np.concatenate([d.triangle_tags, d.halo_triangle_tags]),
                required=d.required, kind=d.kind, origin=d.origin, tag_names=dict(d.tag_names),
                triangle_global_ids=np.concatenate([d.triangle_global_ids, d.halo_triangle_global_ids]),
                segment_global_ids=np.concatenate([d.segment_global_ids, d.halo_segment_global_ids]))


PUBLIC = ("points", "n_owned", "global_ids", "owners", "triangles", "triangle_global_ids", "triangle_tags",
          "halo_triangles", "halo_triangle_global_ids", "halo_triangle_tags", "segments", "segment_global_ids",
          "segment_tags", "halo_segments", "halo_segment_global_ids", "halo_segment_tags", "required", "kind",
          "origin")


@pytest.mark.parametrize("name", ["disc_with_hole_curves", "tags_required_names", "shuffled_tags"])
def test_from_local_on_the_pieces_of_a_scatter_is_the_same(name):
    mesh = mesh_named(name)
    d = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM)
    e = evomesh.DistributedMesh.from_local(comm=COMM, owners=d.owners, **_pieces(d))
    same = all(np.array_equal(getattr(d, a), getattr(e, a)) for a in PUBLIC) and d.tag_names == e.tag_names
    check_everywhere(same, "from_local(pieces of scatter) equals the scatter")
    # With halos fed back in and x2 via exchange: same plan.
    v = e.exchange_halo(e.global_ids[: e.n_owned])
    check_everywhere(np.array_equal(v, e.global_ids), "exchange_halo after from_local")
    # Without owners (the lowest rank holding a point owns it): another partition, the same mesh.
    f = evomesh.DistributedMesh.from_local(comm=COMM, **_pieces(d))
    back = f.gather()
    if RANK == 0:
        assert_same_mesh(back, mesh)


@pytest.mark.parametrize("name", ["holes", "tags_required_names"])
def test_from_local_on_arbitrary_chunks(name):
    """Triangles dealt round-robin (no locality), without triangle or segment ids
    or kinds: the gathered mesh has the input's points and the same triangle and
    segment sets, in the canonical order when one rank owns everything."""
    mesh = mesh_named(name)
    mine = np.arange(mesh.n_triangles) % SIZE == RANK
    tris = mesh.triangles[mine]
    used = np.unique(tris)
    local = np.searchsorted(used, tris)
    seg_mine = np.isin(mesh.segments, used).all(axis=1)  # given by every rank that holds both ends
    segs = np.searchsorted(used, mesh.segments[seg_mine])
    d = evomesh.DistributedMesh.from_local(mesh.points[used], local[:, ::-1], used, COMM, segments=segs,
                                           segment_tags=mesh.segment_tags[seg_mine],
                                           triangle_tags=mesh.triangle_tags[mine], required=mesh.required[used],
                                           tag_names=dict(mesh.tag_names))
    check_everywhere(d.kind is None, "kind unknown")
    back = d.gather()
    if RANK == 0:
        assert np.array_equal(back.points, mesh.points)
        assert np.array_equal(back.required, mesh.required)
        if name == "tags_required_names":  # kinds computed from the geometry, as when it was made
            assert np.array_equal(back.kind, mesh.kind)

        def rows(t, tags):
            return sorted(tuple(np.roll(r, -int(np.argmin(r)))) + (int(g),) for r, g in zip(t, tags))

        assert rows(back.triangles, back.triangle_tags) == rows(mesh.triangles, mesh.triangle_tags)
        assert sorted(map(tuple, np.sort(back.segments, axis=1))) == sorted(map(tuple, np.sort(mesh.segments, 1)))
        if SIZE == 1:
            key = [tuple(np.roll(r, -int(np.argmin(r)))) for r in back.triangles]
            assert key == sorted(key)


def test_uniform_weights_balance_owned_triangles():
    mesh = _shuffled(unit_square_mesh(1200), 1)  # 2268 triangles, gids unrelated to space
    assert mesh.n_triangles >= 2000
    d = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM)
    stats = d.partition_stats()
    counts = stats["owned_triangles"]
    assert counts.sum() == mesh.n_triangles and counts.max() <= 1.1 * counts.mean()
    assert stats["triangle_balance"] == counts.max() / counts.mean()
    assert np.array_equal(stats["owned_points"], COMM.allgather(d.n_owned))


def test_weights_balance_the_owned_work():
    mesh = unit_square_mesh(1200)
    centroid = mesh.points[mesh.triangles].mean(axis=1)
    weights = 1.0 + 20.0 * (np.hypot(*(centroid - 0.3).T) < 0.25)  # a refined spot: 20x the work
    d = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM, weights=weights if RANK == 0 else None)
    work = np.array(COMM.allgather(weights[d.triangle_global_ids].sum()))
    assert work.max() <= 1.1 * work.mean()
    # Deterministic: the same call gives the same partition.
    again = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM,
                                            weights=weights if RANK == 0 else None)
    check_everywhere(np.array_equal(again.global_ids, d.global_ids), "the partition is deterministic")


def test_distributed_mesh_is_immutable():
    d = evomesh.DistributedMesh.scatter(mesh_named("square") if RANK == 0 else None, COMM)
    with pytest.raises(AttributeError):
        d.n_owned = 0
    for name in PUBLIC:
        value = getattr(d, name)
        if isinstance(value, np.ndarray):
            assert not value.flags.writeable
            with pytest.raises(ValueError):
                value.setflags(write=True)
    with pytest.raises(TypeError):
        evomesh.DistributedMesh()


# --------------------------------------------------- failure on one rank only
BAD_RANK = SIZE - 1


def _bad_pieces(d: evomesh.DistributedMesh, how: str) -> dict:
    pieces = {k: np.array(v) if isinstance(v, np.ndarray) else v for k, v in _pieces(d).items()}
    if RANK != BAD_RANK:
        return pieces
    if how == "nan":
        pieces["points"][0, 1] = np.nan
    elif how == "duplicate_gid":
        pieces["global_ids"][1] = pieces["global_ids"][0]
    elif how == "triangle_out_of_range":
        pieces["triangles"][0, 2] = len(pieces["points"])
    elif how == "moved_copy":  # a point held elsewhere too, at other coordinates
        halo = d.n_owned if d.n_owned < len(d.points) else 0
        pieces["points"][halo, 0] += 1e-3
    elif how == "tag_names":
        pieces["tag_names"] = {(2, 99): "other"}
    elif how == "owners_out_of_range":
        pieces["owners"] = np.full(len(pieces["points"]), SIZE, np.int32)
    return pieces


@pytest.mark.parametrize("how", ["nan", "duplicate_gid", "triangle_out_of_range", "moved_copy", "tag_names",
                                 "owners_out_of_range"])
def test_bad_input_on_one_rank_raises_on_every_rank(how):
    mesh = mesh_named("tags_required_names")
    d = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM)
    pieces = _bad_pieces(d, how)
    owners = pieces.pop("owners", None)
    if how in ("moved_copy", "tag_names") and SIZE == 1:
        pytest.skip("needs a second rank to disagree with")
    message = raises_everywhere(ValueError, evomesh.DistributedMesh.from_local, comm=COMM, owners=owners, **pieces)
    assert f"rank {BAD_RANK}" in message
    # The communicator still works afterwards.
    assert COMM.allreduce(1) == SIZE


def test_bad_scatter_arguments_raise_on_every_rank():
    mesh = mesh_named("square")
    raises_everywhere(TypeError, evomesh.DistributedMesh.scatter, "not a mesh" if RANK == 0 else None, COMM)
    bad = np.ones(mesh.n_triangles)
    bad[3] = np.nan
    raises_everywhere(ValueError, evomesh.DistributedMesh.scatter, mesh if RANK == 0 else None, COMM,
                      weights=bad if RANK == 0 else None)
    raises_everywhere(ValueError, evomesh.DistributedMesh.scatter, mesh if RANK == 0 else None, COMM, root=SIZE)
    raises_everywhere(ValueError, evomesh.DistributedMesh.scatter, mesh if RANK == 0 else None, COMM,
                      halo_rings=-1 if RANK == BAD_RANK else 1)
    if SIZE > 1:  # arguments that differ between ranks would make them call different collectives
        message = raises_everywhere(ValueError, evomesh.DistributedMesh.scatter, mesh if RANK == 0 else None, COMM,
                                    halo_rings=2 if RANK == BAD_RANK else 1)
        assert "halo_rings must be the same on every rank" in message
        d = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM)
        raises_everywhere(ValueError, d.gather, root=1 if RANK == BAD_RANK else 0)
    with pytest.raises(TypeError, match="intracommunicator"):
        evomesh.DistributedMesh.scatter(mesh, comm=None)


def test_gather_of_an_invalid_mesh_raises_on_every_rank():
    """from_local checks each rank's pieces; the global checks are Mesh's, in
    gather, and a failure there also raises on every rank."""
    mesh = mesh_named("square")
    d = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM)
    pieces = _pieces(d)
    owners = np.array(d.owners)
    if RANK == BAD_RANK:  # a point no triangle uses: locally fine, an orphan in the whole mesh
        pieces["points"] = np.vstack([pieces["points"], [[10.0, 10.0]]])
        pieces["global_ids"] = np.append(pieces["global_ids"], 10**9)
        pieces["required"] = np.append(pieces["required"], False)
        pieces["kind"] = np.append(pieces["kind"], 3)
        pieces["origin"] = np.append(pieces["origin"], -1)
        owners = np.append(owners, RANK)
    e = evomesh.DistributedMesh.from_local(comm=COMM, owners=owners, **pieces)
    message = raises_everywhere(ValueError, e.gather)
    assert "not used by any triangle" in message


def test_evolve_on_a_distributed_mesh_says_what_it_does_not_do_yet():
    mesh = unit_square_mesh(300)
    d = evomesh.DistributedMesh.scatter(mesh if RANK == 0 else None, COMM)
    with pytest.raises(ValueError, match="method='drfc'"):
        evomesh.evolve(d, 1.0, method="drfc")
    with pytest.raises(ValueError, match="displacement="):
        evomesh.evolve(d, 1.0, displacement=np.zeros((d.n_owned, 2)))


# A nearly flat triangle whose doubled area, in floating point, is positive read from its first point
# and exactly zero read from the other two.
_NEAR_FLAT = np.array([[14.04744410987757, 93.25137503871372], [14.252896770644508, 93.5558792717922],
                       [14.663802092178335, 94.16488773794907]])


def test_copies_of_a_triangle_in_any_rotation_get_one_orientation():
    """Each rank gives the same triangle in its own rotation: every rank reads it from its least global id,
    so all ranks decide alike (before, a rank whose rotation gave area 0 refused what the others took)."""
    rotations = [[0, 1, 2], [1, 2, 0], [2, 0, 1]]
    for first in range(3):
        rows = np.array([rotations[(first + RANK) % 3]])
        d = evomesh.DistributedMesh.from_local(_NEAR_FLAT, rows, np.arange(3), COMM)
        owned = np.asarray(d.global_ids)[np.asarray(d.triangles)]
        check_everywhere(len(owned) == 0 or sorted(owned[0].tolist()) == [0, 1, 2], "the triangle is kept")
        cyclic = [owned[0].tolist()[k:] + owned[0].tolist()[:k] for k in range(3)] if len(owned) else [[0, 1, 2]]
        check_everywhere([0, 1, 2] in cyclic, "it keeps the orientation its least global id gives")
