"""What the MPI test files share: a watchdog that ends a rank hanging in a
collective (so a hang fails CI instead of stalling it) and an assertion agreed
on by every rank (a failure on one rank fails the test on all of them instead of
leaving the others waiting)."""

from __future__ import annotations

import faulthandler

import pytest

MPI = pytest.importorskip("mpi4py.MPI")
COMM = MPI.COMM_WORLD
# Seconds a single test may take on any rank before the watchdog ends the process.
WATCHDOG_SECONDS = 120


@pytest.fixture(autouse=True)
def watchdog():
    faulthandler.dump_traceback_later(WATCHDOG_SECONDS, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()
    COMM.Barrier()  # the next test starts together on every rank


def check_everywhere(ok: bool, what: str) -> None:
    """Assert `ok` on every rank, failing on all ranks if it fails on any."""
    failed = [rank for rank, flag in enumerate(COMM.allgather(bool(ok))) if not flag]
    assert not failed, f"{what} fails on ranks {failed}"
