"""FRFC's step on MPI ranks (evomesh.distributed.step): the kept
points of the packing, and the step's mesh, equal the serial step's on any
number of ranks and partitions.

Plain ``pytest`` runs these on one rank; CI runs them under ``mpiexec -n 2`` and
``-n 4`` too (tools/run-tests.sh).
"""

from __future__ import annotations

import numpy as np
import pytest

import evomesh
from evomesh import _core
from evomesh.meshgen import disc_with_hole_mesh, polygon_mesh
from strategies import crack_mesh

MPI = pytest.importorskip("mpi4py.MPI")
from evomesh import DistributedMesh  # noqa: E402
from evomesh.distributed.step import packing  # noqa: E402
from mpi_support import check_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)

COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size


def _cracks() -> evomesh.Mesh:
    return crack_mesh(21)


_DOMAINS = {
    "L-shape": lambda: polygon_mesh([[(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]], 0.12),
    "two holes": lambda: polygon_mesh([[(0, 0), (3, 0), (3, 2), (0, 2)],
                                       [(0.5, 0.5), (0.5, 1.5), (1.2, 1.5), (1.2, 0.5)],
                                       [(1.8, 0.5), (1.8, 1.5), (2.5, 1.5), (2.5, 0.5)]], 0.15),
    "disc with a hole": lambda: disc_with_hole_mesh(0.1),
    "crack and a notch": _cracks,
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
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    centre = lo + rng.uniform(0.3, 0.7, 2) * (hi - lo)
    distance = np.abs(np.hypot(*(mesh.points - centre).T) - 0.25 * (hi - lo).min())
    return np.where(distance < 0.1 * (hi - lo).min(), 0.4, 2.0)


def _options(within: bool, seed: int) -> _core.FrfcOptions:
    options = _core.FrfcOptions.paper()
    options.within_domain = within
    options.seed = seed
    return options


def _scatter(mesh: evomesh.Mesh, layout: str, seed: int) -> DistributedMesh:
    weights = None
    if layout == "weighted":
        weights = np.random.default_rng(seed).uniform(0.1, 10.0, len(mesh.triangles))
    return DistributedMesh.scatter(mesh if RANK == 0 else None, COMM, weights=weights)


def _sorted_rows(a: np.ndarray) -> np.ndarray:
    return a[np.lexsort(a.T[::-1])]


@pytest.mark.parametrize("within", [True, False], ids=["within", "euclidean"])
@pytest.mark.parametrize("layout", ["even", "weighted"])
@pytest.mark.parametrize("kind", ["random", "front"])
@pytest.mark.parametrize("name", list(_DOMAINS))
def test_packing_keeps_the_serial_points(name: str, kind: str, layout: str, within: bool) -> None:
    mesh = _mesh(name)
    delta = _delta(mesh, kind, seed=len(name))
    options = _options(within, seed=11)
    dmesh = _scatter(mesh, layout, seed=5)
    stats: dict = {}
    points, input_gid = packing(dmesh, delta[dmesh.global_ids[: dmesh.n_owned]], options, stats=stats)
    mine = np.concatenate(COMM.allgather(points))
    gids = np.concatenate(COMM.allgather(input_gid))
    serial = evomesh.evolve(mesh, delta, options=options, seed=11)
    check_everywhere(mine.shape == serial.points.shape
                     and np.array_equal(_sorted_rows(mine), _sorted_rows(serial.points)), "kept points differ")
    # The input points kept are the serial step's, by global id (origin).
    kept_old = np.sort(serial.origin[serial.origin >= 0])
    check_everywhere(np.array_equal(np.sort(gids[gids >= 0]), kept_old), "kept input points differ")
    assert stats["segment_candidates"] > 0 and stats["interior_candidates"] > 0
    if SIZE > 1:
        assert stats["first_pass_rounds"] >= 1 and stats["second_pass_rounds"] >= 1


def test_packing_refuses_what_is_not_options() -> None:
    dmesh = _scatter(_mesh("L-shape"), "even", 0)
    with pytest.raises(TypeError, match="FrfcOptions"):
        packing(dmesh, np.ones(dmesh.n_owned), "paper")


_ARRAYS = ("points", "triangles", "segments", "segment_tags", "segment_is_boundary", "kind", "origin", "required")


def _with_required(mesh: evomesh.Mesh) -> evomesh.Mesh:
    """The mesh with a few interior points required (forced in every step)."""
    required = np.zeros(mesh.n_points, bool)
    inside = np.flatnonzero(mesh.kind == int(evomesh.PointKind.ORIGINAL))
    required[inside[:: max(len(inside) // 5, 1)]] = True
    return evomesh.Mesh(mesh.points, mesh.triangles, mesh.segments, segment_tags=mesh.segment_tags,
                        required=required)


def _front(points: np.ndarray, t: int) -> np.ndarray:
    """A circle moving to the right: refine near it, coarsen elsewhere."""
    centre = np.array([0.3 + 0.35 * t, 0.7])
    distance = np.abs(np.hypot(points[:, 0] - centre[0], points[:, 1] - centre[1]) - 0.4)
    return np.where(distance < 0.1, 0.5, 1.5)


@pytest.mark.parametrize("within", [True, False], ids=["within", "euclidean"])
@pytest.mark.parametrize("layout", ["even", "weighted"])
@pytest.mark.parametrize("name", list(_DOMAINS))
def test_a_time_loop_on_ranks_gives_the_serial_meshes(name: str, layout: str, within: bool) -> None:
    """Three steps of a moving front, and one of random delta: every gathered
    mesh equals the serial step's array for array, and every step's output is
    balanced."""
    mesh = _mesh(name)
    if name == "two holes":
        mesh = _with_required(mesh)
    options = _options(within, seed=2)
    dmesh = _scatter(mesh, layout, seed=1)
    serial = mesh
    for t in range(4):
        if t < 3:
            dmesh = evomesh.evolve(dmesh, lambda xy, t=t: _front(xy, t), options=options)
            if RANK == 0:
                serial = evomesh.evolve(serial, _front(serial.points, t), options=options)
        else:
            rng = np.random.default_rng(9)
            gathered = dmesh.gather()
            delta = COMM.bcast(rng.uniform(0.4, 2.5, gathered.n_points) if RANK == 0 else None)
            dmesh = evomesh.evolve(dmesh, delta[dmesh.global_ids[: dmesh.n_owned]], options=options)
            if RANK == 0:
                serial = evomesh.evolve(serial, delta, options=options)
        gathered = dmesh.gather()
        same = RANK != 0 or all(np.array_equal(getattr(gathered, k), getattr(serial, k)) for k in _ARRAYS)
        check_everywhere(same, f"step {t} differs from the serial step")
        owned = np.array(COMM.allgather(dmesh.n_owned))
        assert owned.max() <= 1.1 * owned.mean() + 1
        assert not np.shares_memory(dmesh.points, mesh.points)


@pytest.mark.parametrize("name", ["L-shape", "disc with a hole"])
def test_size_requests_on_ranks_give_the_serial_meshes(name: str) -> None:
    """evolve(dmesh, size=h): delta_from_size on the ranks (the core's rule
    on each rank's part with SIZE_RULE_RINGS halo rings) equals the serial
    one bit for bit, and so do the meshes, step after step: refining half the
    domain, coarsening the other, then the same request again (it stays put)."""
    from evomesh.distributed.spacing import delta_from_size
    from evomesh.spacing_function import delta_from_size as serial_delta_from_size

    mesh = _mesh(name)
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    middle, h = 0.5 * (lo[0] + hi[0]), 0.06 * float((hi - lo).max())

    def size(xy: np.ndarray) -> np.ndarray:
        return np.where(xy[:, 0] < middle, 0.5 * h, 2.0 * h)

    options = _options(True, 6)
    dmesh = _scatter(mesh, "weighted", 3)
    serial = mesh
    first = None
    for t in range(3):
        delta = dmesh.gather_field(delta_from_size(dmesh, size))
        if RANK == 0:
            reference = serial_delta_from_size(serial, size)
            first = reference if first is None else first
        same = RANK != 0 or np.array_equal(delta.view(np.int64), reference.view(np.int64))
        check_everywhere(same, f"step {t}: delta_from_size differs from the serial one")
        dmesh = evomesh.evolve(dmesh, size=size, options=options)
        if RANK == 0:
            serial = evomesh.evolve(serial, size=size, options=options)
        gathered = dmesh.gather()
        same = RANK != 0 or all(np.array_equal(getattr(gathered, k), getattr(serial, k)) for k in _ARRAYS)
        check_everywhere(same, f"step {t} (size=) differs from the serial step")
    if RANK == 0:  # the first request refines and coarsens
        assert (first < 1).any() and (first > 1).any()


def test_evolve_on_ranks_raises_everywhere_for_bad_delta_on_one_rank() -> None:
    dmesh = _scatter(_mesh("L-shape"), "even", 0)
    delta = np.ones(dmesh.n_owned)
    if RANK == SIZE - 1:
        delta[0] = np.nan
    with pytest.raises(ValueError, match=f"on rank {SIZE - 1}"):
        evomesh.evolve(dmesh, delta, options=_options(True, 0))


def test_triangle_tags_come_along() -> None:
    """Regions (triangle tags bounded by an interior constraint): each new
    triangle takes the tag of the old triangle at its centroid, as serial."""
    mesh = _mesh("crack and a notch")
    centroid = mesh.points[mesh.triangles].mean(axis=1)
    tagged = evomesh.Mesh(mesh.points, mesh.triangles, mesh.segments, segment_tags=mesh.segment_tags,
                          triangle_tags=np.where(centroid[:, 1] > 0.3, 2, 5), tag_names={(2, 2): "top"})
    options = _options(True, 4)
    dmesh = _scatter(tagged, "weighted", 2)
    serial = tagged
    for t in range(2):
        dmesh = evomesh.evolve(dmesh, lambda xy, t=t: _front(xy, t), options=options)
        if RANK == 0:
            serial = evomesh.evolve(serial, _front(serial.points, t), options=options)
        gathered = dmesh.gather()
        same = RANK != 0 or (np.array_equal(gathered.triangle_tags, serial.triangle_tags)
                             and all(np.array_equal(getattr(gathered, k), getattr(serial, k)) for k in _ARRAYS))
        check_everywhere(same, f"step {t}: triangle tags differ from the serial step")
    if RANK == 0:
        assert set(np.unique(gathered.triangle_tags)) == {2, 5} and gathered.tag_names == serial.tag_names


def test_the_worked_example_runs_without_gathering(capsys, monkeypatch) -> None:
    """examples/distributed_time_loop.py on this communicator: the point count stays near the request,
    the transfer keeps the integral, every step is balanced."""
    import importlib.util
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "examples" / "distributed_time_loop.py"
    spec = importlib.util.spec_from_file_location("distributed_time_loop", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    monkeypatch.setattr(sys, "argv", ["distributed_time_loop.py", "--points", "3000", "--steps", "3"])
    monkeypatch.setattr(DistributedMesh, "gather", lambda *a, **k: pytest.fail("the example gathered the mesh"))
    example.main()
    out = capsys.readouterr().out
    if RANK == 0:
        rows = [line.split() for line in out.splitlines() if line.split() and line.split()[0].isdigit()]
        assert [row[0] for row in rows] == ["1", "2", "3"]
        points = [int(row[1]) for row in rows]
        # (the paper's FRFC coarsens behind the front more slowly than it refines)
        assert max(points) < 1.3 * min(points)
        for row in rows:
            assert float(row[2]) <= 1.1
            assert abs(float(row[4]) - float(row[5])) <= 1e-12 * abs(float(row[4]))


def test_size_request_where_a_fine_spot_has_passed_is_the_serial_one() -> None:
    """delta_from_size's rings through too-fine points (the rim of a region
    coarsening back) on the ranks, as the serial ones, bit for bit."""
    from evomesh.distributed.spacing import delta_from_size
    from evomesh.meshgen import unit_square_mesh
    from evomesh.spacing_function import delta_from_size as serial_delta_from_size

    h = 0.05
    mesh = evomesh.evolve(unit_square_mesh(470), size=h)
    for k in range(3):  # a fine spot moving across: a trail of fine points
        centre = np.array([0.3 + 0.1 * k, 0.5])
        mesh = evomesh.evolve(mesh, size=lambda x, c=centre: np.minimum(h, 0.0125 + 0.5 * np.maximum(
            0.0, np.hypot(*(x - c).T) - 0.08)), seed=k)
    dmesh = _scatter(mesh, "weighted", 5)
    delta = dmesh.gather_field(delta_from_size(dmesh, h))
    if RANK == 0:
        reference = serial_delta_from_size(mesh, h)
        assert (reference > 1).mean() > 0.2  # the trail coarsens
    same = RANK != 0 or np.array_equal(delta.view(np.int64), reference.view(np.int64))
    check_everywhere(same, "delta_from_size on a trail differs from the serial one")
