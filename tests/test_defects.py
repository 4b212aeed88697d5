"""Regression tests for defects found by trying evomesh as a new user would (core and Mesh): one per defect."""

from __future__ import annotations

import copy
import pickle

import meshio
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import evomesh
import evomesh.io
from evomesh import Mesh, PointKind
from invariants import check_evolved, check_valid_mesh, rounding_tolerances
from strategies import grid_mesh, random_meshes

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
SQUARE_TRIANGLES = np.array([[0, 1, 2], [0, 2, 3]])


def _grid(n: int = 11) -> tuple[np.ndarray, np.ndarray]:
    mesh = grid_mesh(n, n)
    return np.array(mesh.points), np.array(mesh.triangles)


# --- item 1: a kind without corners crashed the process -----------------------------


@pytest.mark.parametrize("kind", [[1, 1, 1, 1], [0, 1, 1, 1], [1, 0, 1, 0]])
@pytest.mark.parametrize("method", ["frfc", "drfc"])
def test_kind_without_corners_neither_crashes_nor_changes_the_domain(kind, method):
    mesh = Mesh(SQUARE, SQUARE_TRIANGLES, kind=kind)
    assert (mesh.kind == PointKind.CORNER).all()  # the square's four turns are corners
    new = evolve_checked(mesh, np.full(4, 50.0), method=method)
    assert new.area == pytest.approx(1.0, rel=1e-15)


def test_kind_from_a_vtu_file_cannot_crash_the_process(tmp_path):
    path = tmp_path / "square.vtu"
    meshio.write_points_cells(
        path, np.c_[SQUARE, np.zeros(4)], [("triangle", SQUARE_TRIANGLES)], point_data={"kind": np.array([1, 1, 1, 1])}
    )
    mesh, _ = evomesh.io.read_mesh(path)
    new = evolve_checked(mesh, np.full(mesh.n_points, 50.0))
    assert new.area == pytest.approx(1.0, rel=1e-15)


def test_the_core_finds_the_corners_itself_whatever_the_kinds():
    # Bypass Mesh: the core recomputes the corners itself, so even kinds that
    # Mesh would correct give a valid step.
    mesh = Mesh(SQUARE, SQUARE_TRIANGLES)
    result = evomesh._core.frfc(
        mesh.points, mesh.triangles, mesh.segments, mesh.segment_is_boundary.astype(np.uint8),
        np.full(4, PointKind.BOUNDARY, dtype=np.uint8), np.full(4, 50.0), evomesh.FrfcOptions(),
    )
    assert len(result["points"]) == 4


def evolve_checked(mesh: Mesh, delta, **options) -> Mesh:
    new = evomesh.evolve(mesh, delta, **options)
    check_evolved(mesh, new, **rounding_tolerances(mesh))
    return new


# --- item 2: a kind that calls a geometric corner "boundary" changed the domain --------


def test_corner_labelled_boundary_stays_a_corner():
    points, triangles = _grid()
    computed = Mesh(points, triangles).kind
    kind = computed.copy()
    kind[0] = PointKind.BOUNDARY  # the corner (0, 0)
    mesh = Mesh(points, triangles, kind=kind)
    assert mesh.kind[0] == PointKind.CORNER
    new = evolve_checked(mesh, np.full(mesh.n_points, 50.0))
    assert new.area == pytest.approx(1.0, rel=1e-14)


def test_moved_boundary_point_with_the_old_kind_keeps_the_bent_boundary():
    points, triangles = _grid()
    old_kind = Mesh(points, triangles).kind
    moved = points.copy()
    bottom_middle = int(np.flatnonzero((points[:, 1] == 0) & (points[:, 0] == 0.5))[0])
    moved[bottom_middle, 1] = -0.05  # the bottom side now bends there
    mesh = Mesh(moved, triangles, kind=old_kind)
    assert mesh.kind[bottom_middle] == PointKind.CORNER
    area = mesh.area
    new = evolve_checked(mesh, np.full(mesh.n_points, 20.0))
    assert new.area == pytest.approx(area, rel=1e-14)
    assert (new.points == moved[bottom_middle]).all(axis=1).any()


def test_crack_ends_labelled_boundary_are_corners():
    points, triangles = _grid()
    # an interior crack along y = 0.5 from x = 0.3 to x = 0.7
    on_line = np.flatnonzero((points[:, 1] == 0.5) & (points[:, 0] >= 0.3 - 1e-12) & (points[:, 0] <= 0.7 + 1e-12))
    on_line = on_line[np.argsort(points[on_line, 0])]
    crack = np.c_[on_line[:-1], on_line[1:]]
    computed = Mesh(points, triangles, crack).kind
    assert (computed[on_line[[0, -1]]] == PointKind.CORNER).all()
    kind = computed.copy()
    kind[on_line] = PointKind.BOUNDARY
    mesh = Mesh(points, triangles, crack, kind=kind)
    assert (mesh.kind[on_line[[0, -1]]] == PointKind.CORNER).all()
    for delta in (0.3, 5.0):
        check_valid_mesh(evolve_checked(mesh, np.full(mesh.n_points, delta)))


def test_kind_can_pin_a_straight_boundary_point_as_a_corner():
    points, triangles = _grid()
    kind = Mesh(points, triangles).kind.copy()
    pinned = int(np.flatnonzero((points[:, 1] == 0) & np.isclose(points[:, 0], 0.3))[0])
    assert kind[pinned] == PointKind.BOUNDARY
    kind[pinned] = PointKind.CORNER
    new = evolve_checked(Mesh(points, triangles, kind=kind), np.full(len(points), 10.0))
    assert pinned in set(new.origin.tolist())


@given(random_meshes(max_points=60), st.data())
@pytest.mark.filterwarnings("ignore::evomesh.QualityWarning")  # random meshes may have tiny input angles
def test_any_kind_on_segments_gives_a_valid_step_on_the_same_domain(mesh, data):
    on_segment = mesh.kind <= PointKind.BOUNDARY
    n = mesh.n_points
    draws = np.array(data.draw(st.lists(st.integers(0, 2), min_size=n, max_size=n)))
    kind = np.where(on_segment, np.minimum(draws, 1), 2 + draws)  # any corner/boundary labels on segments
    relabelled = Mesh(mesh.points, mesh.triangles, mesh.segments, kind=kind)
    assert (relabelled.kind[mesh.kind == PointKind.CORNER] == PointKind.CORNER).all()
    delta = data.draw(st.sampled_from([0.5, 3.0, 50.0]))
    evolve_checked(relabelled, np.full(n, delta))


def test_points_sampled_on_a_slanted_side_are_not_corners():
    # evolve's own boundary samples on a slanted side are rounded off its line;
    # they stay coarsenable (BOUNDARY) when the user rebuilds the mesh.
    points, triangles = _grid()
    c, s = np.cos(0.5), np.sin(0.5)
    rotated = points @ np.array([[c, s], [-s, c]]) + 1e3
    mesh = Mesh(rotated, triangles)
    new = evomesh.evolve(mesh, np.full(mesh.n_points, 0.4), seed=3)
    rebuilt = Mesh(new.points, new.triangles)
    assert (rebuilt.kind == PointKind.CORNER).sum() == 4


# --- item 3: the arrays of a Mesh could be made writeable ---------------------------


@pytest.mark.parametrize("name", ["points", "triangles", "segments", "segment_is_boundary", "kind", "origin"])
def test_mesh_arrays_cannot_be_made_writeable(name):
    mesh = Mesh(*_grid(5))
    array = getattr(mesh, name)
    with pytest.raises(ValueError):
        array.flags.writeable = True
    with pytest.raises(ValueError):
        array.view().flags.writeable = True
    with pytest.raises(ValueError):
        array[...] = 0


# --- item 4: outputs beyond float64's limits --------------------------------------


def test_refining_a_tiny_square_raises_instead_of_returning_an_invalid_mesh():
    side = 1e-70
    mesh = Mesh(SQUARE * side, SQUARE_TRIANGLES)
    with pytest.raises(ValueError, match="not a valid mesh in float64"):
        for step in range(60):
            delta = np.where(np.hypot(*mesh.points.T) < 0.3 * side, 0.01, 1.0)
            # the paper's sizes and the old angle bound of 20 degrees (refine more slowly than the defaults, so the
            # float64 limit comes before the sample budget)
            mesh = evomesh.evolve(mesh, delta, seed=step, radius="exact", demote_ratio=None,
                                   gap_repair_ratio=None, refine_gap_ratio=None, min_angle=20.0)
            # every output that is returned is one Mesh() accepts
            Mesh(mesh.points, mesh.triangles, mesh.segments, kind=mesh.kind)


def test_check_mesh_limits_names_the_problem():
    from evomesh.mesh import check_mesh_limits

    with pytest.raises(ValueError, match="nearest point"):
        check_mesh_limits(np.array([[0.0, 0.0], [1e-80, 0.0], [0.0, 1.0]]), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="negative area"):
        check_mesh_limits(SQUARE, SQUARE_TRIANGLES[:, ::-1])


# --- item 6: a pure coarsening step was refused as too much refinement -----------------


@pytest.mark.parametrize("delta", [1.0, 2.0, 10.0])
def test_coarsening_near_two_close_points_is_not_refused(delta):
    from scipy.spatial import Delaunay

    points, _ = _grid()
    points = np.r_[points, [[0.55, 0.55], [0.55 + 1e-9, 0.55]]]
    mesh = Mesh(points, Delaunay(points).simplices)
    new = evolve_checked(mesh, np.full(mesh.n_points, delta))
    # samples follow f (graded around the close pair), not f's value at the pair
    assert new.stats["n_interior_samples_drawn"] < 50 * mesh.n_points


def test_sampling_density_is_unchanged_where_f_is_even():
    # on a uniform grid no cell can grow: the samples are the paper's grid
    mesh = Mesh(*_grid(21))
    new = evomesh.evolve(mesh, np.full(mesh.n_points, 0.5), seed=1, filter_samples=False)
    assert new.stats["n_interior_samples_drawn"] >= 2 * mesh.n_triangles


# --- item 8: checkpoints, messages -----------------------------------------------


def test_mesh_pickles_and_deep_copies_exactly():
    mesh = evomesh.evolve(Mesh(*_grid(9)), 0.6, seed=2)
    for clone in (pickle.loads(pickle.dumps(mesh)), copy.deepcopy(mesh)):
        for name in ("points", "triangles", "segments", "segment_is_boundary", "kind", "origin"):
            a, b = getattr(mesh, name), getattr(clone, name)
            assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
            with pytest.raises(ValueError):
                b.flags.writeable = True
        assert dict(clone.stats) == dict(mesh.stats)
        again = evomesh.evolve(clone, 1.3, seed=5)
        assert again.points.tobytes() == evomesh.evolve(mesh, 1.3, seed=5).points.tobytes()


def test_degenerate_message_at_a_large_offset_says_to_translate():
    triangle = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 1e-4]]) + 1e12
    with pytest.raises(ValueError, match="translate the mesh towards the origin") as error:
        Mesh(triangle, [[0, 1, 2]])
    assert "units of rounding" in str(error.value)
    Mesh(triangle - 1e12, [[0, 1, 2]])  # the same shape near the origin is fine
