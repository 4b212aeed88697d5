"""evomesh.transfer and evomesh.transfer_cells on two DistributedMesh:
equal to the serial transfers of the same meshes on any number of ranks and
any partitions of old and new, and failures raised on every rank.

Plain ``pytest`` runs these on one rank; under MPI:
``mpiexec -n K python -m pytest -q -p no:cacheprovider tests/test_distributed_transfer.py``
(K = 2, 3, 4, 7 checked). Every rank builds the same serial meshes
(deterministic), the root scatters them, and each rank compares its owned part
with the serial result indexed by global ids (a scattered mesh's global ids
are its serial indices), so nothing but the reference is gathered.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import evomesh
from evomesh.meshgen import HOLE_TAG, OUTER_TAG, disc_with_hole_mesh, polygon_mesh, unit_square_mesh
from strategies import grid_mesh

MPI = pytest.importorskip("mpi4py.MPI")
COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size
from mpi_support import check_everywhere, raises_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)


# ------------------------------------------------------------------ cases
def _disc_geometry() -> evomesh.BoundaryGeometry:
    return evomesh.BoundaryGeometry({OUTER_TAG: evomesh.Circle((0, 0), 1.0), HOLE_TAG: evomesh.Circle((0, 0), 0.35)})


def _front(points: np.ndarray, centre=(0.5, 0.5), radius: float = 0.3) -> np.ndarray:
    """Refine near a circle, coarsen away from it."""
    r = np.hypot(points[:, 0] - centre[0], points[:, 1] - centre[1])
    return np.where(np.abs(r - radius) < 0.1, 0.5, 1.4)


def _square_front() -> tuple[evomesh.Mesh, evomesh.Mesh]:
    old = unit_square_mesh(700)
    return old, evomesh.evolve(old, _front(old.points), seed=1)


def _holes() -> tuple[evomesh.Mesh, evomesh.Mesh]:
    outer = np.array([[0, 0], [2, 0], [2, 1], [0, 1.0]])
    square = np.array([[0.3, 0.3], [0.6, 0.3], [0.6, 0.6], [0.3, 0.6]])
    triangle = np.array([[1.3, 0.3], [1.6, 0.3], [1.5, 0.7]])
    old = polygon_mesh([outer, square, triangle], 0.07)
    return old, evomesh.evolve(old, _front(old.points, (1.0, 0.5), 0.4), seed=2)


def _curved(delta: float) -> tuple[evomesh.Mesh, evomesh.Mesh]:
    old = disc_with_hole_mesh(0.12)
    return old, evomesh.evolve(old, delta, geometry=_disc_geometry(), seed=3)


CASES = {
    "square_front": _square_front,
    "holes": _holes,
    "curved_refine": lambda: _curved(0.6),  # the new boundary leaves the old one: linear refuses, as serially
    "curved_coarsen": lambda: _curved(1.6),
}
_cache: dict[str, tuple[evomesh.Mesh, evomesh.Mesh]] = {}


def case(name: str) -> tuple[evomesh.Mesh, evomesh.Mesh]:
    """(old, new = evolve(old)), built on every rank (deterministic)."""
    if name not in _cache:
        _cache[name] = CASES[name]()
    return _cache[name]


def scattered(old: evomesh.Mesh, new: evomesh.Mesh, partition: str
              ) -> tuple[evomesh.DistributedMesh, evomesh.DistributedMesh]:
    """Both meshes scattered; "skewed": new cut by weights that grow along x
    and old by weights along y, so the two partitions differ everywhere."""
    def weights(mesh: evomesh.Mesh, axis: int) -> np.ndarray | None:
        if partition != "skewed":
            return None
        centroid = mesh.points[mesh.triangles].mean(axis=1)[:, axis]
        return 1.0 + 8.0 * (centroid - centroid.min())

    d_old = evomesh.DistributedMesh.scatter(old if RANK == 0 else None, COMM, weights=weights(old, 1))
    d_new = evomesh.DistributedMesh.scatter(new if RANK == 0 else None, COMM, weights=weights(new, 0))
    return d_old, d_new


def smooth(points: np.ndarray) -> np.ndarray:
    return np.sin(3.0 * points[:, 0]) + points[:, 1] ** 2 + 0.5


def owned(d: evomesh.DistributedMesh, serial: np.ndarray) -> np.ndarray:
    return serial[d.global_ids[: d.n_owned]]


def lineage_free_reference(d_old: evomesh.DistributedMesh, d_new: evomesh.DistributedMesh, call) -> np.ndarray:
    """call(old, new) on the gathered meshes (which carry no lineage), broadcast."""
    g_old, g_new = d_old.gather(), d_new.gather()
    return COMM.bcast(call(g_old, g_new) if RANK == 0 else None)


def integral(d: evomesh.DistributedMesh, u_owned: np.ndarray) -> float:
    """int of a P1 field over the whole distributed mesh (owned triangles, summed over ranks)."""
    u = d.exchange_halo(u_owned)
    p = d.points[d.triangles]
    area = 0.5 * np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                        - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    return float(np.sum(COMM.allgather(float(np.einsum("t,t->", area, u[d.triangles].mean(axis=1))))))


# ------------------------------------------------------------------ tests
@pytest.mark.parametrize("name", ["square_front", "holes", "curved_coarsen"])
@pytest.mark.parametrize("partition", ["hilbert", "skewed"])
def test_linear_transfer_equals_the_serial_one_bit_for_bit(name, partition):
    old, new = case(name)
    d_old, d_new = scattered(old, new, partition)
    u = smooth(old.points)
    fields = {"u": u, "v": np.c_[u, -2 * u].astype(np.float32), "k": np.arange(old.n_points)}
    got = evomesh.transfer(d_old, d_new, {key: owned(d_old, f) for key, f in fields.items()})
    want = lineage_free_reference(d_old, d_new, lambda o, n: evomesh.transfer(o, n, fields))
    for key in fields:
        shape = (d_new.n_owned,) + fields[key].shape[1:]
        check_everywhere(got[key].dtype == want[key].dtype and got[key].shape == shape
                         and np.array_equal(got[key], owned(d_new, want[key])), f"linear field {key} is the serial one")
    kept = d_new.origin[: d_new.n_owned] >= 0
    check_everywhere(np.array_equal(got["u"][kept], u[d_new.origin[: d_new.n_owned][kept]]),
                     "kept points copy their origin's value")


def test_linear_transfer_refuses_points_outside_the_old_domain_as_serially():
    old, new = case("curved_refine")  # new boundary points on the circle, outside the old chords
    d_old, d_new = scattered(old, new, "hilbert")
    g_old, g_new = d_old.gather(), d_new.gather()
    serial_refuses = None
    if RANK == 0:
        with pytest.raises(ValueError, match="outside the old mesh"):
            evomesh.transfer(g_old, g_new, smooth(old.points))
        serial_refuses = True
    assert COMM.bcast(serial_refuses)
    message = raises_everywhere(ValueError, evomesh.transfer, d_old, d_new, owned(d_old, smooth(old.points)))
    assert "outside the old mesh" in message and "conservative" in message


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("partition", ["hilbert", "skewed"])
def test_transfer_cells_equals_the_serial_one_bit_for_bit(name, partition):
    old, new = case(name)
    d_old, d_new = scattered(old, new, partition)
    centroid = old.points[old.triangles].mean(axis=1)
    c = smooth(centroid)
    fields = {"c": c, "w": np.c_[c, 1j * c]}
    got = evomesh.transfer_cells(d_old, d_new, {key: f[d_old.triangle_global_ids] for key, f in fields.items()})
    want = evomesh.transfer_cells(old, new, fields)
    for key in fields:
        check_everywhere(np.array_equal(got[key], want[key][d_new.triangle_global_ids]) and got[key].dtype
                         == want[key].dtype, f"cell field {key} is the serial one")
    total_old = float(np.einsum("t,t->", old.triangle_areas, c))
    change = evomesh.domain_change(old, new, c)
    areas = new.triangle_areas[d_new.triangle_global_ids]
    total_new = float(np.sum(COMM.allgather(float(np.einsum("t,t->", areas, got["c"])))))
    expected = total_old + change.integral_gained - change.integral_lost
    check_everywhere(abs(total_new - expected) < 1e-12 * abs(expected), "the cell total is kept")


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("partition", ["hilbert", "skewed"])
def test_conservative_transfer_keeps_the_integral_and_agrees_with_serial(name, partition):
    old, new = case(name)
    d_old, d_new = scattered(old, new, partition)
    u = smooth(old.points)
    got = evomesh.transfer(d_old, d_new, owned(d_old, u), method="conservative")
    want = evomesh.transfer(old, new, u, method="conservative")
    # Both solves stop at the rounding of float64 (the serial rule): they agree to a few ulps of the field.
    gap = float(np.abs(got - owned(d_new, want)).max(initial=0.0))
    check_everywhere(gap < 1e-13 * np.abs(want).max(), f"conservative agrees with serial ({gap:.3g})")
    change = evomesh.domain_change(old, new, u)
    expected = float(np.einsum("t,t->", old.triangle_areas, u[old.triangles].mean(axis=1))) \
        + change.integral_gained - change.integral_lost
    total = integral(d_new, got)
    check_everywhere(abs(total - expected) < 1e-12 * abs(expected), "the integral is kept")
    # linear fields are reproduced, constants exactly to rounding
    ones = evomesh.transfer(d_old, d_new, np.ones(d_old.n_owned), method="conservative")
    check_everywhere(np.abs(ones - 1.0).max(initial=0.0) < 1e-12, "constants are reproduced")


def test_conservative_transfer_of_several_fields_and_dtypes():
    old, new = case("square_front")
    d_old, d_new = scattered(old, new, "skewed")
    u = smooth(old.points)
    fields = {"u": u, "z": u + 1j * old.points[:, 0], "v": np.c_[u, 2 * u].astype(np.float32)}
    local = {key: owned(d_old, f) for key, f in fields.items()}
    before = {key: f.copy() for key, f in local.items()}
    stats: dict = {}
    from evomesh.distributed import transfer as distributed_transfer

    got = distributed_transfer.transfer(d_old, d_new, local, method="conservative", stats=stats)
    want = evomesh.transfer(old, new, fields, method="conservative")
    for key in fields:
        ok = got[key].dtype == want[key].dtype and np.abs(got[key] - owned(d_new, want[key])).max(initial=0) \
            < (1e-6 if key == "v" else 1e-13) * np.abs(want[key]).max()
        check_everywhere(ok, f"field {key}")
    check_everywhere(all(np.array_equal(before[k], local[k]) for k in local), "the inputs are not modified")
    check_everywhere(0 < stats["cg_iterations"] < 100 and stats["bytes_moved"] >= 0, "stats are filled")


# Every rank must draw the same examples (they run the same collectives).
@settings(max_examples=6, derandomize=True, database=None)
@given(shape=st.sampled_from(["plain", "hole", "notch"]), side=st.integers(6, 11), delta=st.sampled_from(
    ["refine", "coarsen", "front", "one"]), seed=st.integers(0, 2**16))
def test_random_steps_and_partitions(shape, side, delta, seed):
    """Small jittered grids (holes, reflex corners), a step of each kind, random
    weights for both partitions: linear and cells bit for bit."""
    old = grid_mesh(side, side + 1, jitter=0.3, seed=seed, hole=shape == "hole", notch=shape == "notch")
    d = {"refine": 0.4, "coarsen": 2.0, "front": _front(old.points), "one": 1.0}[delta]
    new = evomesh.evolve(old, d, seed=seed)
    rng = np.random.default_rng(seed)
    w_old, w_new = rng.random(old.n_triangles) + 0.05, rng.random(new.n_triangles) + 0.05
    d_old = evomesh.DistributedMesh.scatter(old if RANK == 0 else None, COMM, weights=w_old if RANK == 0 else None)
    d_new = evomesh.DistributedMesh.scatter(new if RANK == 0 else None, COMM, weights=w_new if RANK == 0 else None)
    u = smooth(old.points)
    got = evomesh.transfer(d_old, d_new, owned(d_old, u))
    want = lineage_free_reference(d_old, d_new, lambda o, n: evomesh.transfer(o, n, u))
    check_everywhere(np.array_equal(got, owned(d_new, want)), "linear is the serial one")
    c = smooth(old.points[old.triangles].mean(axis=1))
    cells = evomesh.transfer_cells(d_old, d_new, c[d_old.triangle_global_ids])
    check_everywhere(np.array_equal(cells, evomesh.transfer_cells(old, new, c)[d_new.triangle_global_ids]),
                     "cells are the serial ones")


# ---------------------------------------------------------------- failures
LAST = SIZE - 1


@pytest.mark.parametrize("method", ["linear", "conservative", "cells"])
def test_bad_values_on_one_rank_raise_everywhere(method):
    old, new = case("square_front")
    d_old, d_new = scattered(old, new, "hilbert")
    call = (lambda v: evomesh.transfer_cells(d_old, d_new, v)) if method == "cells" else \
        (lambda v: evomesh.transfer(d_old, d_new, v, method=method))
    rows = len(d_old.triangles) if method == "cells" else d_old.n_owned
    message = raises_everywhere(ValueError, call, np.zeros(rows + (RANK == LAST)))
    assert f"on rank {LAST}" in message and "one row per owned" in message
    raises_everywhere(TypeError, call, np.array(["a"] * rows) if RANK == LAST else np.zeros(rows))
    message = raises_everywhere(ValueError, call, np.zeros(rows, dtype=np.float32 if RANK == LAST else np.float64)) \
        if SIZE > 1 else "dtype"
    assert "dtype" in message
    if method == "conservative":
        u = np.ones(rows)
        if RANK == LAST and rows:
            u[-1] = np.nan
        message = raises_everywhere(ValueError, call, u)
        assert "not finite" in message


def test_a_mesh_paired_with_a_distributed_mesh_raises_everywhere():
    old, new = case("square_front")
    d_old, d_new = scattered(old, new, "hilbert")
    u = owned(d_old, smooth(old.points))
    message = raises_everywhere(TypeError, evomesh.transfer, d_old, new if RANK == LAST else d_new, u)
    assert "DistributedMesh" in message
    raises_everywhere(TypeError, evomesh.transfer_cells, old, d_new, np.zeros(old.n_triangles))


@pytest.mark.skipif(SIZE == 1, reason="one rank: every communicator is the same group")
def test_meshes_on_different_communicators_raise_everywhere():
    old, new = case("square_front")
    d_old, d_new = scattered(old, new, "hilbert")
    alone = evomesh.DistributedMesh.scatter(new, MPI.COMM_SELF) if RANK == LAST else d_new
    message = raises_everywhere(ValueError, evomesh.transfer, d_old, alone, owned(d_old, smooth(old.points)))
    assert "same communicator" in message
    names = ["u"] if RANK != LAST else ["w"]
    message = raises_everywhere(ValueError, evomesh.transfer, d_old, d_new,
                                {n: owned(d_old, smooth(old.points)) for n in names})
    assert "same names" in message


def test_other_bad_arguments_raise_everywhere():
    old, new = case("square_front")
    d_old, d_new = scattered(old, new, "hilbert")
    u = owned(d_old, smooth(old.points))
    raises_everywhere(ValueError, evomesh.transfer, d_old, d_new, u, method="quadratic" if RANK == LAST else "linear")
    bare = evomesh.DistributedMesh.scatter(new if RANK == 0 else None, COMM, halo_rings=0)
    assert "halo_rings" in raises_everywhere(ValueError, evomesh.transfer, d_old, bare, u)
    # new not evolved from old: a kept point's origin elsewhere
    other = evomesh.evolve(unit_square_mesh(300, seed=4), 0.7, seed=0)
    d_other = evomesh.DistributedMesh.scatter(other if RANK == 0 else None, COMM)
    raises_everywhere(ValueError, evomesh.transfer, d_old, d_other, u)
