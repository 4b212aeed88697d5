"""The ``evomesh`` command, through its entry point."""

import csv
import shutil
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

import pytest

from evomesh.cli import main

TINY = ["growing-circle", "--points", "120", "--band", "0.1", "--h-min", "0.04"]


def console_script():
    (ep,) = [e for e in entry_points(group="console_scripts") if e.name == "evomesh"]
    return ep


def test_entry_point_is_installed():
    assert console_script().value == "evomesh.cli:main"
    assert console_script().load() is main


def test_growing_circle_tiny_through_the_entry_point(tmp_path, capsys):
    out = tmp_path / "out"
    status = console_script().load()(TINY + ["--steps", "2", "--out", str(out)])
    assert status == 0
    printed = capsys.readouterr().out
    header = next(line for line in printed.splitlines() if line.lstrip().startswith("iter"))
    for column in ("points", "original", "% orig", "triangles", "min angle", "max R/e", "ratio max", "seconds"):
        assert column in header
    assert "paper" not in printed  # only beside a 6-step run
    names = sorted(p.name for p in out.iterdir())
    assert names == ["mesh_000.vtu", "mesh_001.vtu", "mesh_002.vtu", "meshes.pvd", "step_001.png", "step_002.png",
                     "table.csv"]
    with (out / "table.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert [int(r["iteration"]) for r in rows] == [1, 2]


def test_six_steps_print_the_paper_table(tmp_path, capsys):
    assert main(TINY + ["--out", str(tmp_path), "--no-figures", "--seed", "3"]) == 0
    printed = capsys.readouterr().out
    assert "paper" in printed and "1416" in printed and "10.23" in printed
    assert not list(tmp_path.glob("*.png"))
    assert len(list(tmp_path.glob("*.vtu"))) == 7


def test_quiet_prints_nothing(tmp_path, capsys):
    assert main(TINY + ["--steps", "1", "--out", str(tmp_path), "--no-figures", "--quiet"]) == 0
    assert capsys.readouterr().out == ""


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--band", "-1"], "band must be >= 0"),
        (["--h-min", "1.0"], "h_min must be <= h_max"),
        (["--method", "nope"], "method"),
        (["--r0", "0.9"], "r0"),
        (["--r-end", "0.01"], "r_end"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(tmp_path, capsys, arguments, message):
    status = main(TINY + ["--steps", "1", "--no-figures", "--out", str(tmp_path / "x")] + arguments)
    captured = capsys.readouterr()
    assert status == 2
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("evomesh: error:") and message in lines[0]
    assert not (tmp_path / "x").exists()  # nothing written for a rejected run


def test_malformed_options_exit_2(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["growing-circle", "--steps", "0"])
    assert exit_info.value.code == 2
    with pytest.raises(SystemExit) as exit_info:
        main([])
    assert exit_info.value.code == 2


def test_installed_command(tmp_path):
    command = shutil.which("evomesh", path=str(Path(sys.executable).parent))
    assert command is not None, "the evomesh console script is not installed next to the interpreter"
    done = subprocess.run(
        [command] + TINY + ["--steps", "1", "--out", str(tmp_path), "--no-figures", "--quiet"],
        capture_output=True, text=True, timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "table.csv").exists()
    bad = subprocess.run([command, "growing-circle", "--band", "-1", "--out", str(tmp_path / "y")],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and bad.stderr.startswith("evomesh: error: band")


@pytest.fixture
def mesh_file(tmp_path):

    import evomesh
    import evomesh.io

    mesh = evomesh.unit_square_mesh(800, seed=2)
    path = tmp_path / "in.vtu"
    evomesh.io.write_mesh(path, mesh, {"h": 0.02 + 0.05 * mesh.points[:, 0], "u": mesh.points @ [1.0, 3.0]})
    return mesh, path


@pytest.mark.parametrize("target", [["--size", "h"], ["--size-expr", "0.02 + 0.05*x"], ["--delta", "h"]])
def test_adapt_writes_a_valid_mesh_with_its_point_data(mesh_file, tmp_path, target, capsys):
    import numpy as np

    import evomesh.io

    mesh, path = mesh_file
    out = tmp_path / "out.vtu"
    assert main(["adapt", str(path), str(out), *target, "--option", "min_angle=22"]) == 0
    assert "wrote" in capsys.readouterr().out
    new, data = evomesh.io.read_mesh(out)
    assert abs(new.area - mesh.area) < 1e-12
    assert np.allclose(data["u"], new.points @ [1.0, 3.0], atol=1e-12)  # linear field carried over
    assert evomesh.quality(new).min_angle >= 22 - 1e-9


def test_adapt_size_expression_equals_the_size_field(mesh_file, tmp_path):
    import evomesh.io

    _, path = mesh_file
    assert main(["adapt", str(path), str(tmp_path / "a.vtu"), "--size", "h", "--quiet"]) == 0
    assert main(["adapt", str(path), str(tmp_path / "b.vtu"), "--size-expr", "0.02 + 0.05*x", "--quiet"]) == 0
    a, _ = evomesh.io.read_mesh(tmp_path / "a.vtu")
    b, _ = evomesh.io.read_mesh(tmp_path / "b.vtu")
    assert a.points.tobytes() == b.points.tobytes()


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--size", "nope"], "no point data 'nope'"),
        (["--size-expr", "__import__('os')"], "unknown name"),
        (["--size-expr", "x +"], "not a valid expression"),
        (["--size", "h", "--option", "colour=red"], "unknown option"),
        (["--size", "h", "--option", "min_angle"], "NAME=VALUE"),
        (["--size", "h", "--circle", "1:0,0"], "TAG:CX,CY,R"),
        (["--size", "h", "--circle", "1:0,0,-1"], "TAG:CX,CY,R"),
        (["--size", "h", "--corner-angle", "20"], "needs at least one --circle"),
        (["--size", "h", "--circle", "1:0,0,1", "--method", "drfc"], "needs --method frfc"),
    ],
)
def test_adapt_bad_arguments_exit_2_with_one_line(mesh_file, tmp_path, arguments, message, capsys):
    _, path = mesh_file
    out = tmp_path / "out.vtu"
    assert main(["adapt", str(path), str(out), *arguments]) == 2
    error = capsys.readouterr().err.strip()
    assert message in error and len(error.splitlines()) == 1
    assert not out.exists()


def test_adapt_finds_an_unwritable_output_before_reading(tmp_path, capsys):
    missing = tmp_path / "missing.vtu"  # not even read: the output is checked first
    assert main(["adapt", str(missing), str(tmp_path / "no-such-folder" / "out.vtu"), "--size", "h"]) == 2
    assert "output folder" in capsys.readouterr().err
    assert main(["adapt", str(missing), str(tmp_path / "out.unknownsuffix"), "--size", "h"]) == 2


def test_info_prints_the_mesh(mesh_file, capsys):
    mesh, path = mesh_file
    assert main(["info", str(path)]) == 0
    printed = capsys.readouterr().out
    assert f"points     {mesh.n_points}" in printed and "min angle" in printed and "point data h, u" in printed


def test_adapt_with_a_circle(tmp_path, capsys):
    import numpy as np

    import evomesh.io
    from evomesh.meshgen import HOLE_TAG, OUTER_TAG, disc_with_hole_mesh

    path = tmp_path / "disc.msh"
    evomesh.io.write_mesh(path, disc_with_hole_mesh(0.08))
    out = tmp_path / "fine.vtu"
    assert main(["adapt", str(path), str(out), "--size-expr", "0.03 + 0*x", "--circle", f"{OUTER_TAG}:0,0,1",
                 "--circle", f"{HOLE_TAG}:0,0,0.35", "--quiet"]) == 0
    new, _ = evomesh.io.read_mesh(out)
    on = np.unique(new.segments[new.segment_is_boundary.astype(bool)])
    r = np.hypot(*new.points[on].T)
    assert np.minimum(abs(r - 1), abs(r - 0.35)).max() < 1e-12
