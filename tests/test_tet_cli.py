"""The ``evomesh`` command on tetrahedral meshes: growing-sphere, adapt and info."""

from __future__ import annotations

import csv
import re

import numpy as np
import pytest

import evomesh
import evomesh.io
from evomesh import _core
from evomesh.cli import main


@pytest.fixture
def tet_file(tmp_path):
    cube = evomesh.unit_cube_mesh(4)
    centre = cube.points[cube.faces].mean(axis=1)
    axis = np.argmax(np.abs(centre - 0.5), axis=1)
    side = 1 + 2 * axis + (centre[np.arange(len(centre)), axis] > 0.5)
    mesh = evomesh.TetMesh(cube.points, cube.tetrahedra, cube.faces, face_tags=side, tag_names={(2, 1): "inlet"})
    path = tmp_path / "cube.vtu"
    x = mesh.points
    evomesh.io.write_mesh(path, mesh, {"h": 0.12 + 0.1 * x[:, 2], "u": x @ [1.0, -2.0, 0.5]})
    return mesh, path


def test_growing_sphere_writes_a_table_meshes_and_slices(tmp_path, capsys):
    out = tmp_path / "sphere"
    status = main(["growing-sphere", "--steps", "2", "--cells", "4", "--h-min", "0.12", "--h-max", "0.25",
                   "--out", str(out)])
    assert status == 0
    printed = capsys.readouterr().out
    assert "min dih" in printed and "slivers" in printed
    with open(out / "table.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert [int(r["step"]) for r in rows] == [0, 1, 2]
    assert all(float(r["min_dihedral"]) > 0 for r in rows)
    for k in range(3):
        mesh, _ = evomesh.io.read_mesh(out / f"mesh_{k:03d}.vtu")
        assert isinstance(mesh, evomesh.TetMesh) and abs(mesh.volumes.sum() - 1.0) < 1e-12
        assert (out / f"slice_{k:03d}.png").stat().st_size > 1000
    assert int(rows[2]["points"]) == mesh.n_points


@pytest.mark.parametrize("target", [["--size", "h"], ["--size-expr", "0.12 + 0.1*z"], ["--delta", "h"]])
def test_adapt_a_tetrahedral_file(tet_file, tmp_path, target, capsys):
    mesh, path = tet_file
    out = tmp_path / "out.msh"
    assert main(["adapt", str(path), str(out), *target, "--option", "sliver_angle=12"]) == 0
    assert "tetrahedra" in capsys.readouterr().out
    new, data = evomesh.io.read_mesh(out)
    assert isinstance(new, evomesh.TetMesh)
    assert abs(new.volumes.sum() - 1.0) < 1e-12
    assert np.allclose(data["u"], new.points @ [1.0, -2.0, 0.5], atol=1e-12)  # linear field carried over
    assert set(np.unique(new.face_tags)) == set(range(1, 7)) and dict(new.tag_names) == {(2, 1): "inlet"}


def test_size_field_and_expression_agree(tet_file, tmp_path):
    _, path = tet_file
    assert main(["adapt", str(path), str(tmp_path / "a.vtu"), "--size", "h", "--quiet"]) == 0
    assert main(["adapt", str(path), str(tmp_path / "b.vtu"), "--size-expr", "0.12 + 0.1*z", "--quiet"]) == 0
    a, _ = evomesh.io.read_mesh(tmp_path / "a.vtu")
    b, _ = evomesh.io.read_mesh(tmp_path / "b.vtu")
    assert a.n_points > 0 and b.n_points > 0
    assert abs(a.n_points - b.n_points) < 0.1 * a.n_points  # (the field is linear in the old tetrahedra)


def test_info_on_a_tetrahedral_file(tet_file, capsys):
    mesh, path = tet_file
    assert main(["info", str(path)]) == 0
    printed = capsys.readouterr().out
    assert f"tetrahedra   {mesh.n_tetrahedra}" in printed and "dihedral angles" in printed
    assert '1 "inlet"' in printed and "point data   h, u" in printed


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--size", "h", "--option", "min_angle=25"], "unknown option(s) for a tetrahedral mesh: min_angle"),
        (["--size", "h", "--option", "sliver_angle=45"], "sliver_angle"),
        (["--size", "h", "--paper"], "no --paper"),
        (["--size-expr", "0.1 + w"], "unknown name"),
    ],
)
def test_bad_tetrahedral_adapt_exits_2_with_one_line(tet_file, tmp_path, arguments, message, capsys):
    _, path = tet_file
    out = tmp_path / "out.vtu"
    assert main(["adapt", str(path), str(out), *arguments]) == 2
    error = capsys.readouterr().err.strip()
    assert message in error and len(error.splitlines()) == 1
    assert not out.exists()


def test_z_in_a_size_expression_needs_tetrahedra(tmp_path, capsys):
    path = evomesh.io.write_mesh(tmp_path / "square.vtu", evomesh.unit_square_mesh(100))
    assert main(["adapt", str(path), str(tmp_path / "out.vtu"), "--size-expr", "0.1 + z"]) == 2
    assert "uses z" in capsys.readouterr().err


@pytest.mark.parametrize("field, value, message", [
    ("cell_factor", -1.0, "cell_factor must be finite and > 0"),
    ("radius_scale", 1.5, "radius_scale must be in (0, 1]"),
    ("boundary_clearance", 1.0, "boundary_clearance must be in [0, 1)"),
    ("max_radius_edge", 0.5, "max_radius_edge must be 0 (none)"),
    ("sliver_angle", float("nan"), "sliver_angle must be in [0, 30]"),
    ("max_samples", float("inf"), "max_samples must be finite and > 0"),
])
def test_tet_options_and_the_step_check_the_same_ranges(field, value, message):
    """TetOptions refuses what the C++ step refuses, with the step's own message."""
    with pytest.raises(ValueError, match=re.escape(message)):
        evomesh.TetOptions(**{field: value})
    arguments = dict(cell_factor=2.0, radius_scale=0.75, boundary_clearance=0.5, max_radius_edge=2.0,
                     sliver_angle=10.0, max_samples=5e7, threads=0)
    arguments[field] = value
    with pytest.raises(ValueError, match=re.escape(message)):
        _core.check_tet_options(**arguments)


@pytest.mark.parametrize("axis, value", [(2, 0.5), (0, 0.3), (1, 0.0), (2, 1 / 3)])
def test_slices_tile_the_cross_section(axis, value):
    """The polygons of a slice cover the box's cross-section once (also on a grid plane,
    where faces lie in the plane, and on the boundary), each inside its tetrahedron's shadow."""
    from evomesh.plotting import tet_slice

    mesh = evomesh.evolve(evomesh.unit_cube_mesh(3), 0.7, seed=2)
    polygons, tets = tet_slice(mesh.points, mesh.tetrahedra, axis, value)
    area = 0.0
    for polygon in polygons:
        x, y = polygon[~np.isnan(polygon[:, 0])].T
        area += 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    assert abs(area - 1.0) < 1e-12
    assert len(np.unique(tets)) == len(tets)
