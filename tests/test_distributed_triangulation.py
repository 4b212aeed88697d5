"""The constrained Delaunay triangulation on MPI ranks
(evomesh.distributed.triangulation, docs/distributed-step.md 3.5):
the union of the ranks' triangles is the serial ``constrained_delaunay`` of all
points and pieces (holes, interior constraints, concave domains, lattices full
of cocircular points), on any number of ranks and any partition of the points,
with global ids unrelated to position.

Plain ``pytest`` runs these on one rank; CI runs them under ``mpiexec -n 2`` and
``-n 4`` too (tools/run-tests.sh).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from evomesh import _core
from evomesh.meshgen import disc_with_hole_mesh, polygon_mesh, unit_square_mesh
from strategies import grid_mesh

MPI = pytest.importorskip("mpi4py.MPI")
from evomesh.distributed.triangulation import constrained_delaunay  # noqa: E402
from mpi_support import check_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)

COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size


@pytest.fixture(autouse=True, params=[4.0, 1.0], ids=["reach4", "reach1"])
def first_reach(request, monkeypatch):
    """Also with a first reach far below the spacing: nearly every fan then
    certifies only after widening, which is where a loose certificate shows."""
    import evomesh.distributed.triangulation as dt

    monkeypatch.setattr(dt, "_FIRST_REACH", request.param)
    return request.param




def _least_first(t: np.ndarray) -> np.ndarray:
    t = np.take_along_axis(t, (np.argmin(t, axis=1)[:, None] + np.arange(3)[None, :]) % 3, axis=1)
    return t[np.lexsort((t[:, 2], t[:, 1], t[:, 0]))]


_DOMAINS = {
    "disc with hole": lambda: disc_with_hole_mesh(0.12),
    "L-shape": lambda: polygon_mesh([[(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]], 0.15),
    "square": lambda: unit_square_mesh(400, seed=2),
    "lattice with hole": lambda: grid_mesh(13, 11, hole=True),  # exact cocircular quadruples everywhere
    "two holes": lambda: polygon_mesh([[(0, 0), (3, 0), (3, 2), (0, 2)],
                                       [(0.5, 0.5), (0.5, 1.5), (1.2, 1.5), (1.2, 0.5)],
                                       [(1.8, 0.5), (1.8, 1.5), (2.5, 1.5), (2.5, 0.5)]], 0.15),
}
_MESHES: dict = {}


def _mesh(name):
    if name not in _MESHES:
        _MESHES[name] = _DOMAINS[name]()
    return _MESHES[name]


def _owner(points: np.ndarray, layout: str, seed: int) -> np.ndarray:
    n = len(points)
    if layout == "random":
        return np.random.default_rng(seed).integers(0, SIZE, n)
    if layout == "stripes":
        x = (points[:, 0] - points[:, 0].min()) / max(np.ptp(points[:, 0]), 1e-300)
        return np.minimum((x * SIZE).astype(np.int64), SIZE - 1)
    if layout == "one":
        return np.full(n, SIZE - 1, np.int64)
    order = np.lexsort((points[:, 0], points[:, 1]))  # "rows": contiguous ranges of a row-major order
    owner = np.empty(n, np.int64)
    owner[order] = np.arange(n) * SIZE // n
    return owner


def _run(points, segments, boundary, layout, seed, stats=None, owner=None):
    n = len(points)
    rng = np.random.default_rng(seed)
    gids = rng.permutation(n).astype(np.int64) * 3 + 7
    owner = _owner(points, layout, seed) if owner is None else owner
    mine = owner == RANK
    pieces_here = np.arange(len(segments)) % SIZE == (RANK + seed) % SIZE  # pieces given by any rank
    out = constrained_delaunay(COMM, points[mine], gids[mine], gids[segments[pieces_here]], boundary[pieces_here],
                               stats=stats)
    every = np.concatenate(COMM.allgather(out)) if SIZE > 1 else out
    index_of = np.full(gids.max() + 1, -1, np.int64)
    index_of[gids] = np.arange(n)
    return _least_first(index_of[every]) if len(every) else np.zeros((0, 3), np.int64)


@settings(max_examples=12, deadline=None)
@given(name=st.sampled_from(sorted(_DOMAINS)), layout=st.sampled_from(["hilbert-like rows", "random", "stripes",
                                                                        "one"]),
       seed=st.integers(0, 10**6))
def test_union_of_ranks_is_the_serial_cdt(name, layout, seed):
    mesh = _mesh(name)
    boundary = mesh.segment_is_boundary.astype(bool)
    serial = _least_first(_core.constrained_delaunay(mesh.points, mesh.segments, boundary.astype(np.uint8)))
    stats: dict = {}
    got = _run(mesh.points, mesh.segments, boundary, layout, seed, stats)
    check_everywhere(got.shape == serial.shape and np.array_equal(got, serial), f"{name}, {layout}: the serial CDT")
    if SIZE == 1:
        check_everywhere(stats["halo_points"] == 0 and stats["widenings"] == 0, "one rank: no halo, no widening")


@pytest.mark.parametrize("layout", ["hilbert-like rows", "stripes", "random", "by cluster"])
@pytest.mark.parametrize("cloud", ["uniform", "clusters", "line and arc"])
def test_clouds_bounded_by_their_hull(cloud, layout):
    """Clouds whose only pieces are their convex hull's edges: the Delaunay
    triangulation of the hull. Clusters far apart, each on its own rank
    ("by cluster"), make triangles whose circumdiscs are far larger than the
    spacing of the chunks that own them, and put owned points on a rank's local
    hull that are not on the global one (the reach must widen and the hull
    check must catch them); points along a line and an arc give a hull piece
    through collinear points."""
    rng = np.random.default_rng(5)
    group = None
    if cloud == "uniform":
        points = rng.random((300, 2))
    elif cloud == "clusters":
        centres = np.array([[0.0, 0.0], [1.0, 0.2], [0.4, 1.1], [2.0, 2.0]])
        points = np.concatenate([c + 0.05 * rng.random((40, 2)) for c in centres])
        group = np.repeat(np.arange(len(centres)), 40)
    else:
        t = np.linspace(0, np.pi, 80)
        points = np.concatenate([np.stack([np.linspace(-1, 1, 81), np.zeros(81)], axis=1)[1:-1],
                                 np.stack([np.cos(t), 0.3 * np.sin(t) + 0.001], axis=1)])
    hull = _core.convex_hull_vertices(points)
    pieces = np.stack([hull, np.roll(hull, -1)], axis=1)
    boundary = np.ones(len(pieces), bool)
    serial = _least_first(_core.constrained_delaunay(points, pieces, boundary.astype(np.uint8)))
    assert len(serial) >= len(points) - 2  # (a triangulation, not an empty set)
    if layout == "by cluster":
        if group is None:
            return
        owner = group % SIZE
    else:
        owner = None
    got = _run(points, pieces, boundary, layout, 3, owner=owner)
    check_everywhere(np.array_equal(got, serial), f"the triangulation of a {cloud} cloud")


def test_bad_input_on_one_rank_raises_everywhere():
    mesh = _mesh("square")
    mine = np.arange(mesh.n_points) % SIZE == RANK
    gids = np.arange(mesh.n_points, dtype=np.int64)
    points = mesh.points[mine].copy()
    if RANK == SIZE - 1 and len(points):
        points[0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        constrained_delaunay(COMM, points, gids[mine], np.zeros((0, 2), np.int64), np.zeros(0, bool))
    pieces = np.array([[0, 10**9]]) if RANK == 0 else np.zeros((0, 2), np.int64)
    with pytest.raises(ValueError, match="no rank's point"):
        constrained_delaunay(COMM, mesh.points[mine], gids[mine], pieces, np.ones(len(pieces), bool))
    clash = gids[mine].copy()
    if RANK == 0 and len(clash) > 1:
        clash[1] = clash[0]
    with pytest.raises(ValueError, match="global id"):
        constrained_delaunay(COMM, mesh.points[mine], clash, np.array([[0, 1]]) if RANK == 0 else
                             np.zeros((0, 2), np.int64), np.ones(1 if RANK == 0 else 0, bool))
