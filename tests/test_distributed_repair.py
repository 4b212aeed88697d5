"""The spacing repair on MPI ranks (evomesh.distributed.repair): the
needy points (repair_ratio) and then the open points (the gap repair,
gap_repair_ratio and refine_gap_ratio) decided in rounds give the serial step's
mesh array for array on any number of ranks, with the recommended options (less
the quality pass) and with each repair ratio alone.

Plain ``pytest`` runs these on one rank; CI runs them under ``mpiexec -n 2`` and
``-n 4`` too (tools/run-tests.sh).
"""

from __future__ import annotations

import numpy as np
import pytest

import evomesh
from evomesh import _core
from evomesh.meshgen import polygon_mesh

MPI = pytest.importorskip("mpi4py.MPI")
from evomesh import DistributedMesh  # noqa: E402
from evomesh.distributed import repair as distributed_repair  # noqa: E402
from evomesh.distributed.step import evolve_distributed  # noqa: E402
from mpi_support import check_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)
from test_distributed_options import _ARRAYS, _DOMAINS, _delta, _mesh  # noqa: E402

COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size


def _options(which: str, ratio: float = 1.75) -> _core.FrfcOptions:
    """"recommended": the recommended options less the quality pass (repair_ratio
    set to `ratio`); else the paper's with ring candidates and only the repair
    ratio named `which` at its recommended value."""
    if which == "recommended":
        o = _core.FrfcOptions.recommended()
        o.quality = False
        o.repair_ratio = ratio
    else:
        o = _core.FrfcOptions.paper()
        o.ring_samples = True
        setattr(o, which, getattr(_core.FrfcOptions.recommended(), which))
    o.seed = 3
    return o


def _repaired(stats: dict) -> int:
    """The points the ranks' repair added (the serial n_spacing_repairs)."""
    r = stats["repair"]
    return r["repaired"] + r["gap_added"]


def _loop(mesh: evomesh.Mesh, options: _core.FrfcOptions, kinds: list[str], layout: str = "even"
          ) -> tuple[list[dict], list[float], list[bool]]:
    """A time loop on the ranks and serial: (the ranks' stats, the serial
    n_spacing_repairs, whether each gathered step equals the serial one)."""
    box = (mesh.points.min(axis=0), mesh.points.max(axis=0))
    weights = np.random.default_rng(1).uniform(0.1, 10.0, len(mesh.triangles)) if layout == "weighted" else None
    dmesh = DistributedMesh.scatter(mesh if RANK == 0 else None, COMM, weights=weights)
    serial = mesh
    stats_out, repairs, same_out = [], [], []
    for t, kind in enumerate(kinds):
        stats: dict = {}
        dmesh = evolve_distributed(dmesh, lambda xy, t=t, kind=kind: _delta(xy, kind, t, box), options=options,
                                   stats=stats)
        gathered = dmesh.gather()
        same = True
        if RANK == 0:
            serial = evomesh.evolve(serial, _delta(serial.points, kind, t, box), options=options)
            same = all(np.array_equal(getattr(gathered, k), getattr(serial, k)) for k in _ARRAYS)
            repairs.append(serial.stats.get("n_spacing_repairs", 0))
        stats_out.append(stats)
        same_out.append(bool(COMM.allreduce(same, op=MPI.LAND)))
    return stats_out, COMM.bcast(repairs), same_out


@pytest.mark.parametrize("name", list(_DOMAINS))
@pytest.mark.parametrize("which", ["recommended", "repair_ratio", "gap_repair_ratio", "refine_gap_ratio"])
def test_repair_on_ranks_gives_the_serial_meshes(which: str, name: str) -> None:
    stats, repairs, same = _loop(_mesh(name), _options(which), ["front", "front-1", "random"],
                                 layout="weighted" if name == "crack" else "even")
    for t, ok in enumerate(same):
        check_everywhere(ok, f"{which}, step {t} differs from the serial step")
    # The repair added points in the serial step (so the comparison tests it), as many on the ranks.
    assert sum(repairs) > 0
    assert [_repaired(s) for s in stats] == repairs


def _dense() -> evomesh.Mesh:
    return polygon_mesh([[(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]], 0.05)


def test_many_needy_points_across_ranks() -> None:
    """repair_ratio = 1 makes hundreds of points needy and open, many near the
    ranks' borders: decisions wait for other ranks' (copies, several rounds),
    and some gap walks leave a rank's triangles (walked again on fetched ones)."""
    stats, repairs, same = _loop(_dense(), _options("recommended", 1.0), ["front", "random", "front"])
    for t, ok in enumerate(same):
        check_everywhere(ok, f"step {t} differs from the serial step")
    assert min(repairs) > 100
    assert [_repaired(s) for s in stats] == repairs
    if SIZE > 1:
        repair = [s["repair"] for s in stats]
        assert all(r["copies"] > 0 and r["gap_copies"] > 0 for r in repair)
        assert max(r["rounds"] for r in repair) > 1 and max(r["gap_rounds"] for r in repair) > 1
        assert sum(r["gap_walks_redone"] for r in repair) > 0
    assert sum(s["repair"]["on_segments"] for s in stats) > 0  # (segment ring candidates made kept)


def test_without_sharing_added_points_the_ranks_differ(monkeypatch: pytest.MonkeyPatch) -> None:
    """A mutant that does not use the points other ranks' decisions added
    differs from serial on several ranks (so the tests above can fail): with
    repair_ratio 1, or with the gap repair alone (repair_ratio 0)."""
    if SIZE == 1:
        pytest.skip("one rank shares nothing")
    monkeypatch.setattr(distributed_repair, "_SHARE_ADDED", False)
    same = []
    for ratio in (1.0, 0.0):
        same += _loop(_dense(), _options("recommended", ratio), ["front", "random", "front"])[2]
    assert not all(same)


def test_curved_loops_on_ranks_give_the_serial_meshes() -> None:
    """With curved boundaries (test_distributed_curves): segment ring
    candidates the repair makes kept move onto their curves as the others."""
    from test_distributed_curves import _DISC, _SQUARE, _requests
    from test_distributed_curves import _mesh as curved_mesh

    flips, repairs = 0, 0.0
    for name, g, split in (("disc", _DISC, 0.0), ("square with a circular hole", _SQUARE, 1.0)):
        mesh = curved_mesh(name)
        options = _options("recommended", 1.0)
        dmesh = DistributedMesh.scatter(mesh if RANK == 0 else None, COMM)
        serial = mesh
        for t in range(4):
            stats: dict = {}
            request = _requests(t) if t != 1 else (lambda xy, split=split: np.where(xy[:, 0] > split, 0.5, 1.5))
            dmesh = evolve_distributed(dmesh, request, options=options, geometry=g, stats=stats)
            gathered = dmesh.gather()
            same = True
            if RANK == 0:
                serial = evomesh.evolve(serial, request(serial.points), options=options, geometry=g)
                same = all(np.array_equal(getattr(gathered, k), getattr(serial, k)) for k in _ARRAYS)
                repairs += serial.stats.get("n_spacing_repairs", 0)
            check_everywhere(same, f"{name}, step {t} differs from the serial step")
            flips += stats["repair"]["on_segments"]
    assert COMM.bcast(repairs) > 0 and flips > 0
