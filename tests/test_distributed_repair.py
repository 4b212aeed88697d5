"""The spacing repair's repair_ratio on MPI ranks (evomesh.distributed_repair,
issue 29): the needy points decided in rounds give the serial step's mesh array
for array on any number of ranks, with the recommended options (less the gap
repair and the quality pass) and with the repair alone.

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
from evomesh import DistributedMesh, distributed_repair  # noqa: E402
from evomesh.distributed_step import evolve_distributed  # noqa: E402
from mpi_support import check_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)
from test_distributed_options import _ARRAYS, _DOMAINS, _delta, _mesh  # noqa: E402

COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size


def _options(which: str, ratio: float = 1.75) -> _core.FrfcOptions:
    """"recommended": the recommended options less the gap repair and the
    quality pass; "alone": the paper's with ring candidates and repair_ratio."""
    if which == "recommended":
        o = _core.FrfcOptions.recommended()
        o.quality = False
        o.gap_repair_ratio = o.refine_gap_ratio = 0.0
    else:
        o = _core.FrfcOptions.paper()
        o.ring_samples = True
    o.repair_ratio = ratio
    o.seed = 3
    return o


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
            repairs.append(serial.stats["n_spacing_repairs"])
        stats_out.append(stats)
        same_out.append(bool(COMM.allreduce(same, op=MPI.LAND)))
    return stats_out, COMM.bcast(repairs), same_out


@pytest.mark.parametrize("name", list(_DOMAINS))
@pytest.mark.parametrize("which", ["recommended", "alone"])
def test_repair_on_ranks_gives_the_serial_meshes(which: str, name: str) -> None:
    stats, repairs, same = _loop(_mesh(name), _options(which), ["front", "front-1", "random"],
                                 layout="weighted" if name == "crack" else "even")
    for t, ok in enumerate(same):
        check_everywhere(ok, f"{which}, step {t} differs from the serial step")
    # The repair added points in the serial step (so the comparison tests it), as many on the ranks.
    assert sum(repairs) > 0
    assert [s["repair"]["repaired"] for s in stats] == repairs


def _dense() -> evomesh.Mesh:
    return polygon_mesh([[(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]], 0.05)


def test_many_needy_points_across_ranks() -> None:
    """repair_ratio = 1 makes hundreds of points needy, many near the ranks'
    borders: decisions wait for other ranks' (copies, several rounds)."""
    stats, repairs, same = _loop(_dense(), _options("recommended", 1.0), ["front", "random"])
    for t, ok in enumerate(same):
        check_everywhere(ok, f"step {t} differs from the serial step")
    assert min(repairs) > 100
    assert [s["repair"]["repaired"] for s in stats] == repairs
    if SIZE > 1:
        assert stats[0]["repair"]["copies"] > 0 and stats[0]["repair"]["rounds"] > 1


def test_without_sharing_added_points_the_ranks_differ(monkeypatch: pytest.MonkeyPatch) -> None:
    """A mutant that does not use the points other ranks' decisions added
    differs from serial on several ranks (so the test above can fail)."""
    if SIZE == 1:
        pytest.skip("one rank shares nothing")
    monkeypatch.setattr(distributed_repair, "_SHARE_ADDED", False)
    _, _, same = _loop(_dense(), _options("recommended", 1.0), ["front", "random"])
    assert not all(same)
