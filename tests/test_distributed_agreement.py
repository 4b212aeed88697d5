"""Every rank agrees before any rank works: a collective call whose arguments
differ between ranks (or ranks in different calls) raises the same ValueError
on every rank, naming the argument and the ranks, and never hangs (every test
here runs under the watchdog of mpi_support: a hang ends the rank and fails).

Plain ``pytest`` runs these on one rank (where nothing can differ: the
disagreements are skipped); CI runs them under ``mpiexec -n 2`` and ``-n 4``
too (tools/run-tests.sh).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import evomesh

MPI = pytest.importorskip("mpi4py.MPI")
from mpi_support import check_everywhere, raises_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)

COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size
# The rank given other arguments (the last: rank 0 alone holds a scattered mesh's root part).
ODD = SIZE - 1
needs_two = pytest.mark.skipif(SIZE < 2, reason="needs a second rank to disagree with")

_MESHES: dict = {}


def _dmesh() -> evomesh.DistributedMesh:
    if "square" not in _MESHES:
        mesh = evomesh.unit_square_mesh(300) if RANK == 0 else None
        _MESHES["square"] = evomesh.DistributedMesh.scatter(mesh, COMM)
    return _MESHES["square"]


def _same_message_everywhere(message: str) -> None:
    check_everywhere(len(set(COMM.allgather(message))) == 1, "the same message on every rank")


def _circle(radius: float) -> evomesh.BoundaryGeometry:
    return evomesh.BoundaryGeometry({1: evomesh.Circle((0.5, 0.5), radius)})


def _paper(radius_scale: float = 1.0) -> evomesh.FrfcOptions:
    options = evomesh.FrfcOptions.paper()
    options.radius_scale = radius_scale
    return options


def _ranks_text(ranks: list[int]) -> str:
    return f"rank {ranks[0]}" if len(ranks) == 1 else f"ranks {', '.join(map(str, ranks))}"


# Per argument: evolve's keyword arguments on every rank but ODD, and on ODD.
# (The arguments need not make a valid step: the ranks disagree before any check.)
_DISAGREEMENTS = {
    "seed": (dict(delta=1.0, seed=0), dict(delta=1.0, seed=1)),  # (seed=comm.rank: no serial step gives that mesh)
    "quality": (dict(delta=1.0, quality=True), dict(delta=1.0)),  # (an override on some ranks only)
    "cell_factor": (dict(delta=1.0, cell_factor=1.0), dict(delta=1.0, cell_factor=1.5)),
    "options": (dict(delta=1.0), dict(delta=1.0, options=evomesh.FrfcOptions.paper())),
    "options.radius_scale": (dict(delta=1.0, options=_paper()), dict(delta=1.0, options=_paper(0.9))),
    "method": (dict(delta=1.0), dict(delta=1.0, method="drfc")),
    "delta": (dict(delta=1.0), dict(delta=0.8)),  # (a number is one request for the whole mesh)
    "delta ": (dict(delta=1.0), dict(delta="per point")),  # a number on some ranks, an array on others
    "delta  ": (dict(delta=1.0), dict(size=0.05)),
    "size": (dict(size=0.05), dict(size=lambda x: np.full(len(x), 0.05))),
    "geometry": (dict(delta=1.0, geometry=_circle(0.4)), dict(delta=1.0)),
    "geometry ": (dict(delta=1.0, geometry=_circle(0.4)), dict(delta=1.0, geometry=_circle(0.41))),
    "interface": (dict(delta=1.0), dict(delta=1.0, interface=lambda x: x[:, 0] - 0.5)),
    "displacement": (dict(delta=1.0), dict(delta=1.0, displacement="per point")),
    "interface_band": (dict(delta=1.0, interface_band=(0.1, 0.01)), dict(delta=1.0, interface_band=(0.1, 0.02))),
    "interface_tag": (dict(delta=1.0, interface_tag=-1), dict(delta=1.0, interface_tag=-2)),
}


@needs_two
@pytest.mark.parametrize("case", list(_DISAGREEMENTS))
def test_evolve_arguments_that_differ_raise_on_every_rank(case: str) -> None:
    d = _dmesh()
    kwargs = dict(_DISAGREEMENTS[case][RANK == ODD])
    for name, value in kwargs.items():
        if value == "per point":
            kwargs[name] = np.ones(d.n_owned) if name == "delta" else np.zeros((d.n_owned, 2))
    message = raises_everywhere(ValueError, evomesh.evolve, d, **kwargs)
    assert message.startswith(f"evolve: {case.strip()} must be the same on every rank: "), message
    assert f" on {_ranks_text(list(range(ODD)))}; " in message and message.endswith(f" on rank {ODD}"), message
    _same_message_everywhere(message)
    check_everywhere(COMM.allreduce(1) == SIZE, "the communicator works afterwards")


@needs_two
def test_the_message_names_the_ranks_of_each_value() -> None:
    message = raises_everywhere(ValueError, evomesh.evolve, _dmesh(), 1.0, seed=RANK % 2)
    assert message == (f"evolve: seed must be the same on every rank: 0 on {_ranks_text(list(range(0, SIZE, 2)))}; "
                       f"1 on {_ranks_text(list(range(1, SIZE, 2)))}"), message


def test_agreed_arguments_a_distributed_step_refuses_raise_on_every_rank() -> None:
    """Given alike on every rank, displacement and interface are refused alike
    (not yet distributed), and interface_* without interface as serially."""
    d = _dmesh()
    message = raises_everywhere(ValueError, evomesh.evolve, d, 1.0, displacement=np.zeros((d.n_owned, 2)))
    assert "not yet on a DistributedMesh: displacement= and interface=" in message
    raises_everywhere(ValueError, evomesh.evolve, d, 1.0, interface=lambda x: x[:, 0] - 0.5)
    message = raises_everywhere(TypeError, evomesh.evolve, d, 1.0, interface_band=(0.1, 0.01))
    assert "need interface" in message
    raises_everywhere(TypeError, evomesh.evolve, d, 1.0, seed="one")


def test_arguments_that_agree_give_the_serial_step() -> None:
    """What the agreement lets through is the serial step: the same keyword
    overrides and seed on every rank, the threads (which never change the
    result) different."""
    d = _dmesh()
    mesh = d.gather()
    out = evomesh.evolve(d, 0.8, seed=7, quality=False, threads=1 + RANK % 2).gather()
    same = RANK != 0 or np.array_equal(out.points, evomesh.evolve(mesh, 0.8, seed=7, quality=False).points)
    check_everywhere(same, "the agreed step equals the serial one")


@needs_two
@pytest.mark.parametrize("name", ["method", "values"])
def test_transfer_arguments_that_differ_raise_on_every_rank(name: str) -> None:
    d = _dmesh()
    u = np.zeros(d.n_owned)
    kwargs = {"method": dict(values=u, method="conservative" if RANK == ODD else "linear"),
              "values": dict(values={"u": u} if RANK == ODD else u)}[name]
    message = raises_everywhere(ValueError, evomesh.transfer, d, d, **kwargs)
    assert message.startswith(f"transfer: {name} must be the same on every rank: "), message
    assert message.endswith(f" on rank {ODD}"), message


# Collective calls, each with arguments that are valid alone.
_CALLS = {
    "evolve": lambda d: evomesh.evolve(d, 1.0),
    "DistributedMesh.gather": lambda d: d.gather(),
    "DistributedMesh.rebalance": lambda d: d.rebalance(),
    "DistributedMesh.exchange_halo": lambda d: d.exchange_halo(np.zeros(d.n_owned)),
    "DistributedMesh.gather_field": lambda d: d.gather_field(np.zeros(d.n_owned)),
    "DistributedMesh.partition_stats": lambda d: d.partition_stats(),
    "transfer": lambda d: evomesh.transfer(d, d, np.zeros(d.n_owned)),
}


@needs_two
@pytest.mark.parametrize("other", [name for name in _CALLS if name != "evolve"])
def test_ranks_in_different_calls_raise_on_every_rank(other: str) -> None:
    d = _dmesh()
    message = raises_everywhere(ValueError, _CALLS["evolve" if RANK != ODD else other], d)
    assert message == (f"the ranks are in different collective calls: evolve on {_ranks_text(list(range(ODD)))}; "
                       f"{other} on rank {ODD}; "
                       "every rank must make the same collective calls in the same order"), message
    _same_message_everywhere(message)


def test_every_mpi_test_file_runs_under_the_watchdog() -> None:
    """Each test file that uses MPI imports the watchdog (a hang fails) and is
    named test_distributed*.py (tools/run-tests.sh runs those under mpiexec)."""
    here = Path(__file__).parent
    for path in sorted(here.glob("test_*.py")):
        text = path.read_text()
        if "mpi4py" not in text:
            continue
        assert path.name.startswith("test_distributed"), f"{path.name} uses MPI: name it test_distributed*.py"
        assert re.search(r"^from mpi_support import .*\bwatchdog\b", text, re.M), \
            f"{path.name} uses MPI without mpi_support's watchdog"
    assert "tests/test_distributed*.py" in (here.parent / "tools" / "run-tests.sh").read_text()


@pytest.mark.skipif(SIZE != 1, reason="starts its own two ranks once")
def test_a_hang_fails_instead_of_waiting(tmp_path: Path) -> None:
    """Two ranks that wait for each other in different collectives: the
    watchdog ends them and mpiexec fails, in seconds."""
    mpiexec = Path(sys.executable).parent / "mpiexec"
    if not mpiexec.exists():
        pytest.skip("no mpiexec next to the interpreter (pip install mpich)")
    (tmp_path / "test_hang.py").write_text(textwrap.dedent("""
        from mpi_support import COMM, watchdog  # noqa: F401

        def test_hang():
            if COMM.rank == 0:
                COMM.recv(source=1)
            else:
                COMM.Barrier()
    """))
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PMI_", "PMIX_", "HYDRA_", "MPI"))}
    env.update(EVOMESH_MPI_TEST_TIMEOUT="3", PYTHONPATH=str(Path(__file__).parent))
    start = time.monotonic()
    done = subprocess.run([str(mpiexec), "-n", "2", sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           str(tmp_path / "test_hang.py")], env=env, cwd=tmp_path, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode != 0, done.stdout + done.stderr
    assert "Timeout" in done.stderr, done.stderr  # faulthandler's traceback of the hung rank
    assert time.monotonic() - start < 240
