"""What the MPI test files share: a watchdog that ends a rank hanging in a
collective (so a hang fails CI instead of stalling it), an assertion agreed on
by every rank (a failure on one rank fails the test on all of them instead of
leaving the others waiting), and a check that a collective call raises on every
rank.

Every test file that uses MPI imports ``watchdog`` from here (an autouse
fixture; test_distributed_agreement.py checks that each one does) and is named
tests/test_distributed*.py, the files tools/run-tests.sh runs under mpiexec.
"""

from __future__ import annotations

import faulthandler
import os

import pytest

MPI = pytest.importorskip("mpi4py.MPI")
COMM = MPI.COMM_WORLD
# Seconds a single test may take on any rank before the watchdog ends the process
# (its traceback on stderr, exit status 1, so mpiexec fails).
WATCHDOG_SECONDS = float(os.environ.get("EVOMESH_MPI_TEST_TIMEOUT", "120"))


def _terminal_stderr(config) -> int:
    """The terminal's stderr: pytest captures fd 2 during a test, and a rank
    the watchdog ends cannot hand over what was captured. pytest's own
    faulthandler plugin keeps a copy of it."""
    try:
        from _pytest.faulthandler import fault_handler_stderr_fd_key

        return config.stash[fault_handler_stderr_fd_key]
    except (ImportError, KeyError):  # (another pytest: the captured fd, which at least fails)
        return 2


@pytest.fixture(autouse=True)
def watchdog(request):
    faulthandler.dump_traceback_later(WATCHDOG_SECONDS, exit=True, file=_terminal_stderr(request.config))
    yield
    COMM.Barrier()  # the next test starts together on every rank (under the watchdog: a rank gone elsewhere fails)
    faulthandler.cancel_dump_traceback_later()


def check_everywhere(ok: bool, what: str) -> None:
    """Assert `ok` on every rank, failing on all ranks if it fails on any."""
    failed = [rank for rank, flag in enumerate(COMM.allgather(bool(ok))) if not flag]
    assert not failed, f"{what} fails on ranks {failed}"


def raises_everywhere(exception: type[Exception], call, *args, **kwargs) -> str:
    """Run a collective call that must raise `exception` on every rank; its message."""
    try:
        call(*args, **kwargs)
    except exception as error:
        message = str(error)
    else:
        message = None
    check_everywhere(message is not None, f"{exception.__name__} is raised")
    return message or ""
