"""The lineage of a step on MPI ranks (evomesh.distributed.lineage):
``evolve(dmesh, ...).lineage`` names each owned point's old triangle by global
id, survives the step's rebalance, and ``gather()`` gives the serial step's
Lineage: bit for bit wherever the serial parent is the same triangle (every
point strictly inside an old triangle), and the same bits on any number of
ranks everywhere.

Plain ``pytest`` runs these on one rank; CI runs them under ``mpiexec -n 2`` and
``-n 4`` too (tools/run-tests.sh; 3 ranks checked by hand).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import evomesh
from evomesh import _core

MPI = pytest.importorskip("mpi4py.MPI")
from evomesh import DistributedLineage  # noqa: E402
from evomesh.distributed.transfer import transfer as distributed_transfer  # noqa: E402 (evomesh.transfer's, with stats)
from mpi_support import check_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)
from test_distributed_step import _DOMAINS, _front, _mesh, _options, _scatter, _with_required  # noqa: E402

COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size


def _steps(name: str, within: bool, layout: str):
    """Two steps of a time loop (a moving front, then random delta) on the
    ranks and serially: yields (old Mesh, distributed output, serial output)
    per step, the serial meshes on every rank."""
    mesh = _mesh(name)
    if name == "two holes":
        mesh = _with_required(mesh)
    options = _options(within, seed=3)
    dmesh = _scatter(mesh, layout, seed=1)
    serial = mesh
    for t in range(2):
        if t == 0:
            delta = _front(serial.points, 1)
            new = evomesh.evolve(dmesh, lambda xy: _front(xy, 1), options=options)
        else:
            delta = np.random.default_rng(7).uniform(0.3, 2.5, serial.n_points)
            new = evomesh.evolve(dmesh, delta[dmesh.global_ids[: dmesh.n_owned]], options=options)
        step = evomesh.evolve(serial, delta, options=options)
        yield serial, new, step
        dmesh, serial = new, step


def _fresh_parents(old: evomesh.Mesh, new: evomesh.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """The lineage's rule on the whole old mesh (one rank holding every old
    triangle): parent and barycentric per new point, -1 and zeros where kept."""
    parent = np.full(new.n_points, -1, dtype=np.int64)
    barycentric = np.zeros((new.n_points, 3))
    fresh = np.flatnonzero(new.origin < 0)
    found, weights = _core.part_parent_triangles(old.points, old.triangles, np.arange(old.n_triangles),
                                                 new.points[fresh])
    parent[fresh], barycentric[fresh] = found, weights
    return parent, barycentric


def _lineage_faults(lineage: evomesh.Lineage, old: evomesh.Mesh, new: evomesh.Mesh) -> list[str]:
    """What fails of: parents contain their points (barycentric coordinates
    sum to 1 and rebuild the point, so they reproduce linear functions, to
    rounding); kept points have none."""
    fresh = new.origin < 0
    eps = np.finfo(np.float64).eps
    weights = lineage.barycentric[fresh]
    parent = lineage.parent_triangle[fresh]
    checks = {
        "matches": lineage.matches(old),
        "kept rows": bool((lineage.parent_triangle[~fresh] == -1).all() and not lineage.barycentric[~fresh].any()),
        "located": bool((parent >= 0).all()),
        "sum to 1": np.abs(weights.sum(axis=1) - 1.0).max(initial=0.0) <= 8 * eps,
        "inside": weights.min(initial=0.0) >= -64 * eps,
    }
    if checks["located"]:
        rebuilt = np.einsum("kj,kjc->kc", weights, old.points[old.triangles[parent]])
        checks["rebuild"] = np.abs(rebuilt - new.points[fresh]).max(initial=0.0) <= 64 * eps * np.abs(old.points).max()
    return [k for k, v in checks.items() if not v]


@pytest.mark.parametrize("within", [True, False], ids=["within", "euclidean"])
@pytest.mark.parametrize("layout", ["even", "weighted"])
@pytest.mark.parametrize("name", list(_DOMAINS))
def test_gathered_lineage_is_the_serial_one(name: str, layout: str, within: bool) -> None:
    """Over a two-step time loop: the gathered lineage equals the rule applied
    on the whole old mesh bit for bit (so it is the same on any number of
    ranks), and the serial step's lineage wherever the parents agree; they
    differ only at points on an old edge (a candidate on an interior
    constraint), a small fraction, and there both parents contain the point."""
    differ = 0
    total = 0
    for old, new, serial in _steps(name, within, layout):
        gathered = new.gather()
        ok, what = True, ""
        if RANK == 0 and gathered.lineage is None:
            ok, what = False, "no lineage"
        elif RANK == 0:
            lineage, reference = gathered.lineage, serial.lineage
            parent, barycentric = _fresh_parents(old, serial)
            same = lineage.parent_triangle == reference.parent_triangle
            differ += int((~same).sum())
            total += int((serial.origin < 0).sum())
            checks = {
                "sizes": (lineage.n_old_points, lineage.n_old_triangles)
                == (reference.n_old_points, reference.n_old_triangles),
                "old_nn": np.array_equal(lineage.old_nn, reference.old_nn),
                "old_f": np.array_equal(lineage.old_f, reference.old_f),
                "the rule on one rank": np.array_equal(lineage.parent_triangle, parent)
                and np.array_equal(lineage.barycentric.view(np.int64), barycentric.view(np.int64)),
                "barycentric where the serial parent is the same":
                    np.array_equal(lineage.barycentric[same].view(np.int64),
                                   reference.barycentric[same].view(np.int64)),
                # (on an old edge: the serial coordinates have an exact zero, as ours)
                "parents differ only on old edges": bool((reference.barycentric[~same] == 0).any(axis=1).all()
                                                         and (lineage.barycentric[~same] == 0).any(axis=1).all()),
                # (of the old triangles containing the point, the least id)
                "parents differ: ours the lesser id": bool((lineage.parent_triangle[~same]
                                                            < reference.parent_triangle[~same]).all()),
                "parents differ only on segments": bool((serial.kind[~same] == int(evomesh.PointKind.BOUNDARY))
                                                        .all()),
            }
            what = ", ".join([k for k, v in checks.items() if not v] + _lineage_faults(lineage, old, gathered))
            ok = not what
        check_everywhere(ok, f"{name}: the gathered lineage differs: {what}")
    if RANK == 0:
        assert differ <= 0.02 * total, f"{differ} of {total} parents differ from the serial step's"
        if name != "crack and a notch":  # (no interior constraint: every new point has one parent)
            assert differ == 0


def test_lineage_rows_are_the_owned_points() -> None:
    """Without gathering: each rank's rows are its owned points (after the
    step's rebalance), their parents old triangle global ids that rebuild them;
    old_nn and old_f are the old mesh's owned points'. A mesh not made by a
    step has none; the lineage is read-only."""
    old = _mesh("two holes")
    dold = _scatter(old, "weighted", seed=4)
    assert dold.lineage is None
    dnew = evomesh.evolve(dold, lambda xy: _front(xy, 0), options=_options(True, 1))
    lineage = dnew.lineage
    check_everywhere(isinstance(lineage, DistributedLineage)
                     and lineage.parent_triangle.shape == (dnew.n_owned,)
                     and lineage.barycentric.shape == (dnew.n_owned, 3)
                     and np.array_equal(lineage.old_global_ids, dold.global_ids[: dold.n_owned])
                     and lineage.old_nn.shape == lineage.old_f.shape == (dold.n_owned,), "the lineage's shapes")
    assert lineage.matches(dold) and not lineage.matches(dnew)  # (the same answer on every rank)
    # scattered: old triangle global ids are the serial indices
    def rows_rebuild(d: Any) -> tuple[bool, np.ndarray]:
        fresh = d.origin[: d.n_owned] < 0
        parent = d.lineage.parent_triangle
        ok = bool((parent[~fresh] == -1).all() and (parent[fresh] >= 0).all()
                  and (parent[fresh] < old.n_triangles).all())
        if ok and fresh.any():
            corners = old.points[old.triangles[parent[fresh]]]
            rebuilt = np.einsum("kj,kjc->kc", d.lineage.barycentric[fresh], corners)
            ok = np.abs(rebuilt - d.owned_points[fresh]).max() <= 1e-13 * np.abs(old.points).max()
        return ok, fresh

    ok, fresh = rows_rebuild(dnew)
    parent = lineage.parent_triangle
    check_everywhere(ok, "the owned rows rebuild the owned points")
    check_everywhere(COMM.allreduce(int(fresh.sum())) > 0, "the step made new points")
    with pytest.raises(AttributeError):
        lineage.parent_triangle = parent  # type: ignore[misc]
    with pytest.raises(ValueError):
        lineage.barycentric[0, 0] = 1.0
    assert "DistributedLineage" in repr(lineage)
    # a user's rebalance moves the rows along (ids kept: the gathered lineage is the same)
    before = dnew.gather()
    for renumber in (False, True):
        moved = dnew.rebalance(weights=lambda xy: 1.0 + xy[:, 0] ** 2, renumber=renumber)
        check_everywhere(moved.lineage is not None and rows_rebuild(moved)[0],
                         f"the rows after rebalance(renumber={renumber}) rebuild the owned points")
        if not renumber:
            after = moved.gather()
            same = RANK != 0 or all(np.array_equal(getattr(before.lineage, k), getattr(after.lineage, k))
                                    for k in ("parent_triangle", "barycentric", "old_nn", "old_f"))
            check_everywhere(same, "the gathered lineage after a rebalance differs")


@pytest.mark.parametrize("name", ["crack and a notch", "disc with a hole"])
def test_linear_transfer_uses_the_lineage(name: str) -> None:
    """transfer(old, new, u) on a step's output places new points by the
    lineage: equal bit for bit to the serial transfer of the gathered meshes
    (which carry it), and to the serial step's transfer wherever the parents
    agree (elsewhere to rounding); linear fields are reproduced."""
    for old, new, serial in _steps(name, True, "weighted"):
        dold = _scatter(old, "even", seed=0)  # (the step's input, as a mesh of its own)
        u = np.sin(3.0 * old.points[:, 0]) + old.points[:, 1] ** 2
        linear = old.points @ np.array([2.0, -1.0]) + 0.5
        stats: dict = {}
        got = distributed_transfer(dold, new, {"u": u[dold.global_ids[: dold.n_owned]],
                                           "linear": linear[dold.global_ids[: dold.n_owned]]}, stats=stats)
        assert stats["used_lineage"]
        gathered = new.gather()
        g_old = dold.gather()
        want = COMM.bcast(evomesh.transfer(g_old, gathered, {"u": u, "linear": linear}) if RANK == 0 else None)
        reference = COMM.bcast(evomesh.transfer(old, serial, u) if RANK == 0 else None)
        same = COMM.bcast(gathered.lineage.parent_triangle == serial.lineage.parent_triangle if RANK == 0 else None)
        mine = new.global_ids[: new.n_owned]
        check_everywhere(np.array_equal(got["u"], want["u"][mine])
                         and np.array_equal(got["linear"], want["linear"][mine]),
                         "the serial transfer of the gathered meshes")
        check_everywhere(np.array_equal(got["u"][same[mine]], reference[mine][same[mine]])
                         and np.allclose(got["u"], reference[mine], rtol=0, atol=1e-14), "the serial step's transfer")
        exact = new.owned_points @ np.array([2.0, -1.0]) + 0.5
        check_everywhere(np.allclose(got["linear"], exact, rtol=0, atol=1e-13), "linear fields reproduced")
