"""The moving-front driver end to end, its files, and the paper's experiment."""

import csv
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import evomesh
from evomesh import CircleFront, Driver, LevelSetFront, PointFront, SpacingLaw
from evomesh.io import read_mesh, write_run
from evomesh.plotting import plot_step
from evomesh.reporting import PAPER_TABLE1
from evomesh.statistics import STATISTICS_COLUMNS
from invariants import check_evolved, spacing_ratio
from strategies import grid_mesh

LAW = SpacingLaw(0.03, 0.1, 0.05, grade=0.5)


def small_front():
    return CircleFront((0.5, 0.5), lambda t: 0.1 + 0.1 * t)


def linear(points):
    return 2.0 * points[:, 0] - 3.0 * points[:, 1] + 1.0


@pytest.fixture(scope="module")
def small_run():
    mesh = grid_mesh(11, 11, jitter=0.2, seed=5)
    fields = {"u": linear(mesh.points), "velocity": np.c_[mesh.points[:, 1], -mesh.points[:, 0]]}
    steps = []
    result = evomesh.run(mesh, small_front(), LAW, [1.0, 2.0, 3.0], fields=fields, seed=7, progress=False,
                         callback=steps.append)
    return mesh, fields, steps, result


@pytest.fixture(scope="module")
def written(small_run, tmp_path_factory):
    folder = tmp_path_factory.mktemp("run")
    return folder, write_run(small_run[3], folder, figures=True, dpi=40)


def test_run_steps_are_valid_evolutions(small_run):
    mesh, _, steps, result = small_run
    assert len(result.steps) == 3 and steps == result.steps  # the callback saw every step
    meshes = result.meshes
    assert meshes[0] is mesh
    for old, new in zip(meshes[:-1], meshes[1:]):
        check_evolved(old, new)
    assert [s.time for s in result.steps] == [1.0, 2.0, 3.0]
    assert np.array_equal(result.times, [1.0, 2.0, 3.0])
    assert result.mesh is meshes[-1]


def test_run_applies_the_law(small_run):
    _, _, _, result = small_run
    front = small_front()
    for k, step in enumerate(result.steps):
        old = result.meshes[k]
        assert np.array_equal(step.delta, LAW.delta(old, front.distance(old.points, step.time)))
    assert np.array_equal(result.next_delta, LAW.delta(result.mesh, front.distance(result.mesh.points, 3.0)))
    assert len(result.deltas) == len(result.meshes)


def test_run_carries_fields(small_run):
    mesh, fields, _, result = small_run
    assert np.array_equal(fields["u"], linear(mesh.points))  # caller's arrays untouched
    for m, f in zip(result.meshes, result.fields):
        assert set(f) == {"u", "velocity"}
        assert np.allclose(f["u"], linear(m.points), atol=1e-12)  # linear stays exact
        assert np.allclose(f["velocity"], np.c_[m.points[:, 1], -m.points[:, 0]], atol=1e-12)


def test_statistics_match_recomputation(small_run):
    _, _, _, result = small_run
    for k, row in enumerate(result.rows):
        old, new, delta = result.meshes[k], result.meshes[k + 1], result.steps[k].delta
        assert list(row) == list(STATISTICS_COLUMNS)
        assert row["iteration"] == k + 1
        assert row["points"] == new.n_points and row["triangles"] == new.n_triangles
        assert row["original_points"] == int((new.origin >= 0).sum())
        assert row["original_pct"] == pytest.approx(100 * row["original_points"] / new.n_points)
        assert row["min_angle_deg"] == evomesh.quality(new).min_angle
        ratio = spacing_ratio(old, new, delta)
        assert row["spacing_ratio_max"] == pytest.approx(ratio.max(), rel=1e-12)
        assert row["spacing_ratio_p99"] == pytest.approx(np.percentile(ratio, 99), rel=1e-12)
        assert row["seconds"] > 0


def test_files_written(small_run, written):
    _, _, _, result = small_run
    folder, paths = written
    names = sorted(p.name for p in folder.iterdir())
    assert names == ["mesh_000.vtu", "mesh_001.vtu", "mesh_002.vtu", "mesh_003.vtu", "meshes.pvd",
                     "step_001.png", "step_002.png", "step_003.png", "table.csv"]
    assert all(p.stat().st_size > 1000 for p in paths["figures"])
    root = ET.parse(folder / "meshes.pvd").getroot()
    datasets = root.find("Collection").findall("DataSet")
    assert [d.get("file") for d in datasets] == [f"mesh_{k:03d}.vtu" for k in range(4)]
    assert [float(d.get("timestep")) for d in datasets] == [0.0, 1.0, 2.0, 3.0]


def test_table_and_meshes_from_files_agree(small_run, written):
    """The statistics in table.csv, recomputed from the written VTU files alone."""
    _, _, _, result = small_run
    folder, _ = written
    with (folder / "table.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert list(rows[0]) == list(STATISTICS_COLUMNS)
    meshes, data = zip(*(read_mesh(folder / f"mesh_{k:03d}.vtu") for k in range(4)))
    for k, row in enumerate(rows):
        old, new = meshes[k], meshes[k + 1]
        assert set(data[k]) == {"nn_spacing", "delta", "u", "velocity"}
        assert np.array_equal(data[k]["nn_spacing"], evomesh.nn_spacing(old))
        assert np.array_equal(new.origin, result.meshes[k + 1].origin)
        assert np.array_equal(new.kind, result.meshes[k + 1].kind)
        assert int(row["points"]) == new.n_points
        assert int(row["triangles"]) == new.n_triangles
        assert int(row["original_points"]) == int((new.origin >= 0).sum())
        assert float(row["original_pct"]) == pytest.approx(100 * (new.origin >= 0).sum() / new.n_points)
        assert float(row["min_angle_deg"]) == pytest.approx(evomesh.quality(new).min_angle, rel=1e-12)
        assert float(row["max_radius_edge"]) == pytest.approx(evomesh.quality(new).max_radius_edge, rel=1e-12)
        ratio = spacing_ratio(old, new, data[k]["delta"])
        assert float(row["spacing_ratio_max"]) == pytest.approx(ratio.max(), rel=1e-12)
        assert float(row["spacing_ratio_p99"]) == pytest.approx(np.percentile(ratio, 99), rel=1e-12)
    # final mesh: the delta the next step would apply for the front at the last time
    assert np.array_equal(data[3]["delta"], result.next_delta)


def test_run_is_deterministic(small_run):
    mesh, fields, _, result = small_run
    again = evomesh.run(mesh, small_front(), LAW, [1.0, 2.0, 3.0], fields=fields, seed=7, progress=False)
    for a, b in zip(result.meshes, again.meshes):
        assert np.array_equal(a.points, b.points) and np.array_equal(a.triangles, b.triangles)
    other = evomesh.run(mesh, small_front(), LAW, [1.0], seed=8, progress=False)
    assert not np.array_equal(other.mesh.points, result.meshes[1].points)


def test_driver_with_a_moving_point_front_and_own_delta():
    mesh = grid_mesh(10, 10, jitter=0.2, seed=2)
    angle = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    front = PointFront(0.5 + 0.15 * np.c_[np.cos(angle), np.sin(angle)], spacing=0.02)

    def my_delta(m, distance):
        return np.where(distance < 0.1, 0.5, 1.5)

    driver = Driver(mesh, my_delta, fields={"u": linear(mesh.points)}, seed=1)
    for k in range(2):
        old = driver.mesh
        step = driver.step(front, t=float(k))
        assert np.array_equal(step.delta, my_delta(old, front.distance(old.points)))
        check_evolved(old, driver.mesh)
        front = front.moved(0.5 + 1.5 * (front.points - 0.5))  # the simulation moves the front
    assert driver.iteration == 2
    assert np.allclose(driver.fields["u"], linear(driver.mesh.points), atol=1e-12)


def test_run_with_level_set_callable_front_and_no_kept_meshes():
    mesh = grid_mesh(9, 9, jitter=0.1, seed=3)
    level_set = LevelSetFront(lambda x, t: x[:, 0] - 0.2 * t)

    def front(t):
        return level_set if t < 1.5 else PointFront([[0.4, 0.0], [0.4, 1.0]], closed=False)

    result = evomesh.run(mesh, front, LAW, [1.0, 2.0], keep_meshes=False, progress=False)
    assert result.meshes[1] is None and result.mesh is not None
    assert len(result.rows) == 2


def test_plot_step_has_three_panels(small_run):
    _, _, _, result = small_run
    figure = plot_step(result.meshes[0], result.meshes[1], result.steps[0].delta, front=small_front(), t=1.0)
    panels = [ax for ax in figure.axes if ax.get_label() != "<colorbar>"]
    assert len(panels) == 3
    assert all(ax.collections or ax.lines for ax in panels)


def test_growing_circle_meets_the_paper_targets():
    """The paper's experiment with the paper's preference for old points (exact
    radii, old points first, no gap repair: radius="exact", demote_ratio=None,
    gap_repair_ratio=None, refine_gap_ratio=None): at least 70% of
    the points kept in every step and a minimum angle at least the paper's worst.
    With the defaults the band gets the spacing it asks for, which takes
    more new points: see test_growing_circle_with_the_defaults."""
    result = evomesh.growing_circle(progress=False, radius="exact", demote_ratio=None, gap_repair_ratio=None,
                                    refine_gap_ratio=None)
    assert 1050 <= result.initial.n_points <= 1150
    assert evomesh.quality(result.initial).min_angle > 30
    assert len(result.steps) == len(PAPER_TABLE1) == 6
    assert result.column("original_pct").min() >= 70.0
    assert result.column("min_angle_deg").min() >= 10.23
    # the circle touches the box at the last step
    front = result.front
    assert front.radius(6.0) == pytest.approx(0.5)
    table = result.table(paper=True)
    assert "paper" in table and "1416" in table


def test_growing_circle_with_the_defaults():
    """The band gets more of the spacing it asks for (measured nn'/h max
    1.23-1.60 at the input points, 1.54-1.75 before), at the price of old points
    (measured 60-71 %, not the 70 % asked for in every step)."""
    result = evomesh.growing_circle(progress=False)
    assert result.column("spacing_ratio_max").max() <= 1.65
    assert result.column("original_pct").min() >= 55.0
    assert result.column("min_angle_deg").min() >= 25.0


def test_unit_square_mesh():
    mesh = evomesh.unit_square_mesh()
    assert mesh.area == pytest.approx(1.0)
    again = evomesh.unit_square_mesh()
    assert np.array_equal(mesh.points, again.points)
    assert np.array_equal(mesh.triangles, again.triangles)
    assert evomesh.unit_square_mesh(300).n_points == pytest.approx(300, rel=0.1)
    with pytest.raises(ValueError, match="jitter"):
        evomesh.unit_square_mesh(jitter=0.5)
    with pytest.raises(TypeError):
        evomesh.unit_square_mesh(100.0)


def test_bad_input():
    mesh = grid_mesh(5, 5)
    front = small_front()
    with pytest.raises(ValueError, match="non-empty"):
        evomesh.run(mesh, front, LAW, [])
    with pytest.raises(ValueError, match="finite"):
        evomesh.run(mesh, front, LAW, [np.nan])
    with pytest.raises(TypeError, match="law"):
        evomesh.run(mesh, front, 0.5, [1.0])
    with pytest.raises(TypeError, match="Mesh"):
        evomesh.run(mesh.points, front, LAW, [1.0])
    with pytest.raises(ValueError, match="field 'u'"):
        evomesh.run(mesh, front, LAW, [1.0], fields={"u": np.ones(3)})
    with pytest.raises(TypeError, match="mapping"):
        evomesh.run(mesh, front, LAW, [1.0], fields=[np.ones(mesh.n_points)])
    with pytest.raises(ValueError, match="seed"):
        evomesh.run(mesh, front, LAW, [1.0], seed=-1)
    with pytest.raises(ValueError, match="NaN"):
        evomesh.run(mesh, LevelSetFront(lambda x, t: np.full(len(x), np.nan)), LAW, [1.0])
    with pytest.raises(ValueError, match="needs the distance"):
        evomesh.run(mesh, None, LAW, [1.0])
    with pytest.raises(ValueError, match="delta"):
        evomesh.run(mesh, front, lambda m, d: -np.ones(m.n_points), [1.0])
    with pytest.raises(TypeError, match="front"):
        evomesh.run(mesh, 3.0, LAW, [1.0])
    with pytest.raises(TypeError, match="unknown option"):
        evomesh.run(mesh, front, LAW, [1.0], no_such_option=1)
    with pytest.raises(ValueError, match="band"):
        evomesh.growing_circle(band=-1.0)
    with pytest.raises(ValueError, match="r0"):
        evomesh.growing_circle(r0=0.7)
