"""size= in every scope: the serial step, the step on ranks and the interface
step turn a size into delta through the core's one rule (size_request.hpp):
the same delta for the same request, and the same ValueError for a request
out of range, never a silent clip.

Plain ``pytest`` runs these on one rank; tools/run-tests.sh under mpiexec too.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import evomesh
from evomesh.interface import _spacing_at_cut, cut_mesh
from evomesh.meshgen import disc_with_hole_mesh
from evomesh.spacing_function import delta_from_size

MPI = pytest.importorskip("mpi4py.MPI")
from evomesh import DistributedMesh  # noqa: E402
from evomesh.distributed.spacing import delta_from_size as ranks_delta_from_size  # noqa: E402
from mpi_support import check_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)

COMM = MPI.COMM_WORLD
RANK = COMM.rank
SPACING = 0.08


def _phi(x: np.ndarray) -> np.ndarray:
    return np.hypot(x[:, 0] - 0.2, x[:, 1]) - 0.5


def _on_ranks(mesh: evomesh.Mesh, size):
    """The request on the owned points of `mesh` scattered over the ranks."""
    dmesh = DistributedMesh.scatter(mesh if RANK == 0 else None, COMM)
    owned = size[dmesh.global_ids[: dmesh.n_owned]] if isinstance(size, np.ndarray) else size
    return dmesh, owned


def _sizes(mesh: evomesh.Mesh) -> dict:
    x = mesh.points
    return {
        "uniform": 0.6 * SPACING,  # refines everywhere
        "graded": np.where(x[:, 0] < 0, 0.5 * SPACING, 2.5 * SPACING),  # refines and coarsens
        "callable": lambda y: SPACING * (0.4 + 0.6 * np.abs(y[:, 1])),
    }


@pytest.mark.parametrize("kind", ["uniform", "graded", "callable"])
def test_every_scope_gives_the_same_delta(kind: str) -> None:
    mesh = disc_with_hole_mesh(SPACING)
    size = _sizes(mesh)[kind]
    serial = delta_from_size(mesh, size)
    assert (serial != 1).any()  # the request changes the mesh somewhere
    dmesh, owned = _on_ranks(mesh, size)
    ranks = dmesh.gather_field(ranks_delta_from_size(dmesh, owned))
    check_everywhere(RANK != 0 or np.array_equal(ranks.view(np.int64), serial.view(np.int64)),
                     "delta on the ranks differs from the serial one")
    # The interface step's request at the cut's points that are old points is
    # delta nn there, from the same rule (a callable size it evaluates at the
    # cut's points instead).
    if not callable(size):
        cut = cut_mesh(mesh, _phi)
        h = _spacing_at_cut(mesh, cut, None, size)
        old = cut.old_index >= 0
        assert np.array_equal(h[old], (serial * mesh.nn_spacing)[cut.old_index[old]])


@pytest.mark.parametrize("bad", [1e-9, 1e9])
def test_every_scope_raises_the_same_error_for_a_size_out_of_range(bad: float) -> None:
    mesh = disc_with_hole_mesh(SPACING)
    size = np.full(mesh.n_points, SPACING)
    if bad < 1:
        k = mesh.n_points // 2  # one point asked 1e-9: delta there below 1e-6
        size[k] = bad
    else:
        k = 0  # every point asked 1e9: too fine everywhere, delta far above 1e6
        size[:] = bad
    form = re.escape(f"size {bad:g}") + (r" at point {} is \S+ times its current spacing \S+; one step changes the "
                                          r"spacing by a factor in \[1e-06, 1e\+06\]")
    with pytest.raises(ValueError) as serial:
        evomesh.evolve(mesh, size=size, seed=0)
    message = str(serial.value)
    assert re.fullmatch(form.format(k), message), message
    with pytest.raises(ValueError) as interface:
        evomesh.evolve(mesh, size=size, interface=_phi, seed=0)
    assert str(interface.value) == message
    dmesh, owned = _on_ranks(mesh, size)
    with pytest.raises(ValueError) as ranks:
        evomesh.evolve(dmesh, size=owned, seed=0)
    # (the error of the lowest failing rank, on every rank: _collective's prefix and suffix around it)
    on_ranks = re.sub(r"^on rank \d+: (.*?)( \(ranks \[[\d, ]+\] failed\))?$", r"\1", str(ranks.value))
    if bad < 1 or COMM.size == 1:
        assert on_ranks == message
    else:  # every point is out of range: the lowest failing rank names its first
        assert re.fullmatch(form.format(r"\d+"), on_ranks), on_ranks


def test_the_interface_step_raises_for_a_size_out_of_range_at_its_cut() -> None:
    """A request that is out of range only at the interface's new points (the
    serial step never asks there) raises the same error there instead of
    being clipped to the range."""
    mesh = disc_with_hole_mesh(SPACING)

    def size(x: np.ndarray) -> np.ndarray:
        return np.where(np.abs(_phi(x)) < 1e-9, 1e-9, SPACING)

    assert (delta_from_size(mesh, size) >= 1e-6).all()  # the old points' request is in range
    with pytest.raises(ValueError, match=r"size 1e-09 at point \d+ is \S+ times its current spacing \S+; one step "
                                         r"changes the spacing by a factor in \[1e-06, 1e\+06\]"):
        evomesh.evolve(mesh, size=size, interface=_phi, seed=0)
