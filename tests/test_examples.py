"""The scripts in examples/ run on small sizes."""

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("skfem")

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def run_example(name: str, *args: str, cwd: Path) -> str:
    result = subprocess.run([sys.executable, str(EXAMPLES / name), *args], cwd=cwd, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_heat_moving_source(tmp_path):
    out = run_example("heat_moving_source.py", "--points", "2000", "--steps", "3", "--out", str(tmp_path / "heat"),
                      cwd=tmp_path)
    assert sorted(p.name for p in (tmp_path / "heat").iterdir()) == [
        "heat.pvd", "heat_0000.vtu", "heat_0001.vtu", "heat_0002.vtu", "heat_0003.vtu"]
    rows = [line.split() for line in out.splitlines() if line.split() and line.split()[0].isdigit()]
    assert [row[0] for row in rows] == ["1", "2", "3"]
    for row in rows:
        # the conservative transfer keeps ∫u up to what the strips a moved curved boundary gains or loses carry
        assert abs(float(row[6])) < 1e-10


def test_curved_hole_cycle(tmp_path):
    out = run_example("curved_hole_cycle.py", "--points", "2000", "--cycles", "2", cwd=tmp_path)
    rows = [line.split() for line in out.splitlines() if line.split() and line.split()[0].isdigit()]
    assert len(rows) == 5
    hole = [int(row[-2]) for row in rows]
    assert hole[1] < 0.7 * hole[0] and hole[3] < 0.8 * hole[2]  # coarsening removes hole points
    assert hole[2] > 1.3 * hole[1] and hole[4] > 1.3 * hole[3]  # refining puts new ones on the circle
    polygon = run_example("curved_hole_cycle.py", "--points", "2000", "--cycles", "1", "--polygon", cwd=tmp_path)
    rows = [line.split() for line in polygon.splitlines() if line.split() and line.split()[0].isdigit()]
    # without the geometry the polygon's vertices are corners, all kept (a step may add points on its chords,
    # which leaves the polygon, and so the hole's area error, as it was)
    assert all(int(row[-2]) >= int(rows[0][-2]) for row in rows)
    assert len({row[-1] for row in rows}) == 1


def test_two_phase(tmp_path):
    """The interface in the mesh moves with the disc; the transfer keeps the integral; the interface is on phi = 0."""
    out = run_example("two_phase.py", "--steps", "4", "--points", "1500", "--out", str(tmp_path / "tp"), cwd=tmp_path)
    rows = [line.split() for line in out.splitlines() if line.split() and line.split()[0].isdigit()]
    assert [row[0] for row in rows] == ["1", "2", "3", "4"]
    for row in rows:
        assert float(row[2]) >= 60.0  # % of old points kept
        assert abs(float(row[3])) < 1e-12  # conservative transfer
        assert float(row[4]) > 0  # material changed phase as the disc moved
        assert float(row[5]) >= 30.0 - 1e-9  # smallest angle
        assert float(row[6]) < 1e-12  # interface points on phi = 0
    assert (tmp_path / "tp" / "two_phase.pvd").exists() and len(list((tmp_path / "tp").glob("*.vtu"))) == 5
