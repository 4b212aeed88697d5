"""Curved boundaries on MPI ranks, and a step that returns its input:
``evolve(dmesh, ..., geometry=g)`` gives the serial ``evolve(mesh, ..., geometry=g)``
mesh on any number of ranks, array for array, and a step whose output is its
input keeps the input's triangle and segment order, as serial.

Plain ``pytest`` runs these on one rank; CI runs them under ``mpiexec -n 2`` and
``-n 4`` too (tools/run-tests.sh).
"""

from __future__ import annotations

import numpy as np
import pytest

import evomesh
from evomesh import _core
from evomesh.meshgen import HOLE_TAG, OUTER_TAG, disc_with_hole_mesh, polygon_mesh

MPI = pytest.importorskip("mpi4py.MPI")
from evomesh import DistributedMesh  # noqa: E402
from evomesh.distributed.step import evolve_distributed  # noqa: E402
from mpi_support import check_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)

COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size
_ARRAYS = ("points", "triangles", "segments", "segment_tags", "segment_is_boundary", "kind", "origin", "required",
           "triangle_tags")
_DISC = evomesh.BoundaryGeometry({OUTER_TAG: evomesh.Circle((0, 0), 1.0), HOLE_TAG: evomesh.Circle((0, 0), 0.35)})
# A square with a hole drawn as a 24-gon whose edges polygon_mesh splits (points on chords, off the circle).
_SQUARE_LOOPS = [[(0, 0), (2, 0), (2, 2), (0, 2)],
                 [(1 + 0.4 * np.cos(t), 1 + 0.4 * np.sin(t)) for t in np.linspace(0, 2 * np.pi, 25)[:-1]]]
_SQUARE = evomesh.BoundaryGeometry({1: evomesh.Circle((1, 1), 0.4)})
_MESHES: dict = {}


def _mesh(name: str) -> evomesh.Mesh:
    if name not in _MESHES:
        _MESHES[name] = disc_with_hole_mesh(0.06) if name == "disc" else polygon_mesh(_SQUARE_LOOPS, 0.12)
    return _MESHES[name]


def _options(within: bool, seed: int, distributed: bool = False) -> _core.FrfcOptions:
    """The paper's options; `distributed`: the recommended ones less what is not
    distributed yet (spacing repair, the quality pass)."""
    options = _core.FrfcOptions.paper()
    if distributed:
        options = _core.FrfcOptions.recommended()
        options.quality = False
        options.repair_ratio = options.gap_repair_ratio = options.refine_gap_ratio = 0.0
    options.within_domain = within
    options.seed = seed
    return options


def _same(gathered: evomesh.Mesh | None, serial: evomesh.Mesh | None) -> bool:
    return RANK != 0 or all(np.array_equal(getattr(gathered, k), getattr(serial, k)) for k in _ARRAYS)


def _requests(t: int):
    """Coarsen (dropping boundary points), (t = 1: refine one half, given by the
    test), ask for what the mesh has (delta = 1), and a varying request."""
    if t == 0:
        return lambda xy: np.full(len(xy), 2.0)
    if t == 2:
        return lambda xy: np.ones(len(xy))
    return lambda xy: 0.5 + np.abs(np.sin(7 * xy[:, 0]) * np.cos(5 * xy[:, 1]))


@pytest.mark.parametrize("within,rings", [(True, False), (False, False), (True, True)],
                         ids=["within", "euclidean", "rings-demotion-skipping"])
@pytest.mark.parametrize("name", ["disc", "square with a circular hole"])
def test_curved_time_loop_on_ranks_gives_the_serial_meshes(name: str, within: bool, rings: bool) -> None:
    """Four steps with the geometry: the gathered mesh equals the serial one
    array for array after every step; new boundary points lie on their curves;
    the points the serial step drops outside the new boundary are dropped on
    the ranks too."""
    mesh = _mesh(name)
    g = _DISC if name == "disc" else _SQUARE
    centre, radius = ((0.0, 0.0), (1.0, 0.35)) if name == "disc" else ((1.0, 1.0), (0.4,))
    options = _options(within, seed=2, distributed=rings)
    dmesh = DistributedMesh.scatter(mesh if RANK == 0 else None, COMM)
    serial = mesh
    for t in range(4):
        stats: dict = {}
        request = _requests(t) if t != 1 else (lambda xy: np.where(xy[:, 0] > centre[0], 0.5, 1.5))
        dmesh = evolve_distributed(dmesh, request, options=options, geometry=g, stats=stats)
        if RANK == 0:
            serial = evomesh.evolve(serial, request(serial.points), options=options, geometry=g)
        gathered = dmesh.gather()
        check_everywhere(_same(gathered, serial), f"step {t} on curves differs from the serial step")
        if RANK == 0:
            assert stats["curve_points_dropped_outside"] == serial.stats.get("curve_points_dropped_outside", 0)
            assert stats["unchanged"] == bool(serial.stats["unchanged"])
            on_curve = np.unique(gathered.segments[np.isin(gathered.segment_tags, list(g.tags))])
            new = on_curve[gathered.origin[on_curve] < 0]
            r = np.hypot(*(gathered.points[new] - centre).T)
            assert (np.min(np.abs(r[:, None] - np.asarray(radius)[None, :]), axis=1) < 1e-12).all()


def test_a_coarsening_step_drops_points_outside_the_new_chords() -> None:
    """The serial step drops an interior point that the coarser curved boundary
    leaves outside (seed 2 on this disc); the ranks drop it too, and the ids of
    the rest are the serial positions."""
    mesh = _mesh("disc")
    options = _options(True, seed=2)
    dmesh = DistributedMesh.scatter(mesh if RANK == 0 else None, COMM)
    stats: dict = {}
    dmesh = evolve_distributed(dmesh, 2.0, options=options, geometry=_DISC, stats=stats)
    serial = evomesh.evolve(mesh, 2.0, options=options, geometry=_DISC) if RANK == 0 else None
    gathered = dmesh.gather()
    check_everywhere(_same(gathered, serial), "the coarsening step on curves differs from the serial step")
    assert stats["curve_points_dropped_outside"] >= 1
    if RANK == 0:
        assert serial is not None
        assert serial.stats["curve_points_dropped_outside"] == stats["curve_points_dropped_outside"]


def test_triangle_tags_on_curves_come_along() -> None:
    """Tags of two regions of a disc drawn as an octagon (corner angle 50
    degrees: its vertices are not corners), refined: each new triangle takes the
    tag of the old triangle at its centroid, also where the centroid lies
    outside the old octagon (new points on the circle bulge out of its chords,
    here by up to 0.15 at a spacing of 0.15; the nearest old triangle, as the
    serial walk's). Then a coarsening step."""
    loops = [[(2 * np.cos(t), 2 * np.sin(t)) for t in np.linspace(0, 2 * np.pi, 9)[:-1]]]
    base = polygon_mesh(loops, 0.5)
    centroid = base.points[base.triangles].mean(axis=1)
    # (boundary tag 1; the region border's segments get tag 0 and stay straight)
    tagged = evomesh.Mesh(base.points, base.triangles, base.segments, segment_tags=np.ones(len(base.segments), int),
                          triangle_tags=np.where(centroid[:, 0] > 0.1, 3, 4))
    g = evomesh.BoundaryGeometry({1: evomesh.Circle((0, 0), 2.0)}, corner_angle=50)
    options = _options(False, 1)
    dmesh = DistributedMesh.scatter(tagged if RANK == 0 else None, COMM)
    serial = tagged
    for t, delta in enumerate([0.15, 1.7]):
        dmesh = evomesh.evolve(dmesh, delta, options=options, geometry=g)
        if RANK == 0:
            serial = evomesh.evolve(serial, delta, options=options, geometry=g)
        gathered = dmesh.gather()
        check_everywhere(_same(gathered, serial), f"step {t}: tags on curves differ from the serial step")
        if RANK == 0:
            # The lineage: new points on the circle outside the old polygon get an old
            # boundary triangle (a negative coordinate), as serial; the serial walk's
            # boundary triangle may be another one there (path-dependent), never inside.
            ours, theirs = gathered.lineage, serial.lineage
            new = gathered.origin < 0
            assert (ours.parent_triangle[new] >= 0).all()
            differ = ours.parent_triangle != theirs.parent_triangle
            assert (ours.barycentric[differ].min(axis=1) < 0).all()
            assert (theirs.barycentric[differ].min(axis=1) < 0).all()
            assert differ.sum() <= 0.1 * new.sum()
            assert np.array_equal(ours.barycentric[~differ], theirs.barycentric[~differ])
    if RANK == 0:
        assert set(np.unique(serial.triangle_tags)) == {3, 4}


def test_a_step_that_returns_its_input_keeps_its_order() -> None:
    """Without curves: a step whose output is its input (delta = 1 on a mesh a
    step made; serial stats "unchanged") keeps the input's triangle and segment
    ids and rotations, as serial; the input here comes from a scatter of a mesh
    whose triangles and segments are shuffled and rotated."""
    base = polygon_mesh([[(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]], 0.15)
    options = _options(True, 1)
    first = evomesh.evolve(evomesh.evolve(base, 1.3, options=options), 1.0, options=options)  # (then it stays)
    rng = np.random.default_rng(0)
    tri = first.triangles[rng.permutation(first.n_triangles)]
    tri = np.roll(tri, 1, axis=1)
    order = rng.permutation(len(first.segments))
    shuffled = evomesh.Mesh(first.points, tri, first.segments[order][:, ::-1], kind=first.kind)
    dmesh = DistributedMesh.scatter(shuffled if RANK == 0 else None, COMM)
    stats: dict = {}
    out = evolve_distributed(dmesh, 1.0, options=options, stats=stats)
    serial = evomesh.evolve(shuffled, 1.0, options=options) if RANK == 0 else None
    check_everywhere(_same(out.gather(), serial), "an unchanged step differs from the serial step")
    if RANK == 0:
        assert serial is not None and serial.stats["unchanged"] == 1 and stats["unchanged"]
        assert np.array_equal(serial.triangles, shuffled.triangles)
