"""Conservative transfer: the P1 L2 projection of transfer(...,
method="conservative") and the P0 projection of transfer_cells, both on the
local supermesh of a step."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse
from hypothesis import given, settings

import evomesh
from evomesh import _core
from evomesh.field_transfer import Supermesh, _p1_mass
from strategies import grid_mesh, mesh_and_delta


def vertex_integral(mesh: evomesh.Mesh, u: np.ndarray) -> np.ndarray:
    """Exact integral of a P1 field (columns separately)."""
    area = np.abs(mesh.triangle_areas)
    flat = u.reshape(mesh.n_points, -1)
    return np.einsum("t,tc->c", area, flat[mesh.triangles].mean(axis=1))


def cell_total(mesh: evomesh.Mesh, c: np.ndarray) -> np.ndarray:
    return np.einsum("t,tc->c", np.abs(mesh.triangle_areas), c.reshape(mesh.n_triangles, -1))


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


def linear(points: np.ndarray) -> np.ndarray:
    lo = points.min(axis=0)
    span = np.ptp(points, axis=0).max()
    x = (points - lo) / span
    return np.c_[2.0 * x[:, 0] - 3.0 * x[:, 1] + 0.5, 1.0 + x[:, 0] + x[:, 1]]


@settings(max_examples=25, deadline=None)
@given(mesh_and_delta(max_side=10))
def test_one_step_preserves_integrals(case):
    mesh, delta = case
    new = evomesh.evolve(mesh, delta, seed=0)
    rng = np.random.default_rng(0)
    u = np.c_[rng.random(mesh.n_points) + 1.0, np.sin(5 * mesh.points[:, 0] / np.ptp(mesh.points))]
    u_new = evomesh.transfer(mesh, new, u, method="conservative")
    assert relative(vertex_integral(new, u_new), vertex_integral(mesh, u)) < 1e-12
    c = rng.random((mesh.n_triangles, 2)) + 0.5
    c_new = evomesh.transfer_cells(mesh, new, c)
    assert c_new.shape == (new.n_triangles, 2)
    assert relative(cell_total(new, c_new), cell_total(mesh, c)) < 1e-12
    # constants exactly, linear fields to rounding
    assert (evomesh.transfer_cells(mesh, new, np.full(mesh.n_triangles, 0.3)) == 0.3).all()
    projected = evomesh.transfer(mesh, new, linear(mesh.points), method="conservative")
    assert np.abs(projected - linear(new.points)).max() < 1e-10


@settings(max_examples=15, deadline=None)
@given(mesh_and_delta(max_side=10))
def test_supermesh_areas(case):
    """Every old and every new triangle is covered by its pieces (a bug in the
    flood fill or the clipping would leave an old triangle short)."""
    mesh, delta = case
    new = evomesh.evolve(mesh, delta, seed=1)
    s = Supermesh(mesh, new)
    old_area = np.abs(mesh.triangle_areas)
    new_area = np.abs(new.triangle_areas)
    assert relative(np.bincount(s.old_triangle, s.area, mesh.n_triangles), old_area) < 1e-10
    assert relative(np.bincount(s.new_triangle, s.area, new.n_triangles), new_area) < 1e-10
    assert np.allclose(s.mass.sum(axis=(1, 2)), s.area, rtol=0, atol=1e-12 * new_area.max())


def test_hundred_chained_steps():
    mesh = grid_mesh(12, 12, jitter=0.25, seed=1)
    rng = np.random.default_rng(3)
    u = np.sin(3 * mesh.points[:, 0]) + mesh.points[:, 1] ** 2
    c = rng.random(mesh.n_triangles)
    u0, c0 = vertex_integral(mesh, u), cell_total(mesh, c)
    worst = 0.0
    for k in range(100):
        # alternately refine and coarsen towards two target spacings
        delta = np.clip((0.07 if k % 2 == 0 else 0.14) / mesh.nn_spacing, 0.2, 5.0)
        new = evomesh.evolve(mesh, delta, seed=k)
        u_new = evomesh.transfer(mesh, new, u, method="conservative")
        c_new = evomesh.transfer_cells(mesh, new, c)
        worst = max(worst, relative(vertex_integral(new, u_new), vertex_integral(mesh, u)),
                    relative(cell_total(new, c_new), cell_total(mesh, c)))
        mesh, u, c = new, u_new, c_new
    assert worst < 1e-12
    assert relative(vertex_integral(mesh, u), u0) < 1e-11
    assert relative(cell_total(mesh, c), c0) < 1e-11


def test_linear_default_unchanged():
    mesh = grid_mesh(8, 8, jitter=0.2, seed=2)
    new = evomesh.evolve(mesh, np.full(mesh.n_points, 0.5), seed=0)
    u = np.random.default_rng(0).random(mesh.n_points)
    assert np.array_equal(evomesh.transfer(mesh, new, u), evomesh.transfer(mesh, new, u, method="linear"))
    with pytest.raises(ValueError, match="method"):
        evomesh.transfer(mesh, new, u, method="quadratic")  # type: ignore[call-overload]


def test_mapping_dtypes_and_errors():
    mesh = grid_mesh(8, 8, jitter=0.2, seed=2)
    new = evomesh.evolve(mesh, np.full(mesh.n_points, 2.0), seed=0)
    fields = {"a": np.ones(mesh.n_points, dtype=np.int64), "z": (1 + 2j) * np.ones(mesh.n_points)}
    out = evomesh.transfer(mesh, new, fields, method="conservative")
    assert out["a"].dtype == np.float64 and np.allclose(out["a"], 1.0)
    assert out["z"].dtype == np.complex128 and np.allclose(out["z"], 1 + 2j)
    cells = evomesh.transfer_cells(mesh, new, {"c": np.arange(mesh.n_triangles)})
    assert relative(cell_total(new, cells["c"]), cell_total(mesh, np.arange(mesh.n_triangles, dtype=float))) < 1e-12
    unrelated = grid_mesh(9, 9)
    for call in (lambda: evomesh.transfer(mesh, unrelated, np.ones(mesh.n_points), method="conservative"),
                 lambda: evomesh.transfer_cells(mesh, unrelated, np.ones(mesh.n_triangles))):
        with pytest.raises(ValueError, match="evolve"):
            call()
    with pytest.raises(ValueError, match="triangle"):
        evomesh.transfer_cells(mesh, new, np.ones(mesh.n_points))


def test_thread_count_independent():
    mesh = grid_mesh(10, 10, jitter=0.25, seed=4)
    new = evomesh.evolve(mesh, np.clip(0.05 / mesh.nn_spacing, 0.2, 5), seed=0)
    one, two, three = (Supermesh(mesh, new, threads=k) for k in (1, 2, 3))
    u = np.c_[np.sin(4 * mesh.points[:, 0]), mesh.points[:, 1] ** 2]
    for other in (two, three):
        assert np.array_equal(one.old_triangle, other.old_triangle) and np.array_equal(one.identical, other.identical)
        assert np.array_equal(one.area, other.area) and np.array_equal(one.mass, other.mass)
        # the mass matrix and the solve too: the projection is bit for bit the same
        assert np.array_equal(one.project_vertices(u), other.project_vertices(u))


@settings(max_examples=15, deadline=None)
@given(mesh_and_delta(max_side=10))
def test_identical_triangle_shortcut(case):
    """A new triangle that is an old one (three kept points) gets its pair
    without clipping: the same pairs, areas and mass entries as the clipping
    (to 1e-14 of the triangle's area), and the same projection."""
    mesh, delta = case
    new = evomesh.evolve(mesh, delta, seed=2)
    arguments = (mesh.points, mesh.triangles, new.points, new.triangles, new.origin, new.lineage.parent_triangle)
    fast = _core.supermesh(*arguments, True, 1, True)
    full = _core.supermesh(*arguments, True, 1, False)
    assert (full["identical"] == -1).all()
    identical = fast["identical"]
    for t in np.flatnonzero(identical >= 0):  # same points, in any order
        assert set(new.origin[new.triangles[t]]) == set(mesh.triangles[identical[t]])
    assert np.array_equal(fast["offsets"], full["offsets"])
    assert np.array_equal(fast["old_triangle"], full["old_triangle"])
    scale = np.repeat(np.abs(new.triangle_areas), np.diff(fast["offsets"]))
    assert np.all(np.abs(fast["area"] - full["area"]) <= 1e-14 * scale)
    assert np.all(np.abs(fast["mass"] - full["mass"]).max(axis=(1, 2)) <= 1e-14 * scale)


def test_identical_triangles_of_an_unchanged_mesh():
    """delta = 1 on a grid keeps most triangles: they all take the shortcut,
    and the projection of a field onto the same space is the field."""
    mesh = grid_mesh(9, 9, jitter=0.2, seed=5)
    new = evomesh.evolve(mesh, 1.0, seed=0)
    s = Supermesh(mesh, new)
    assert (s.identical >= 0).mean() > 0.5
    same = np.flatnonzero(s.identical >= 0)
    assert np.array_equal(np.diff(s.offsets)[same], np.ones(len(same), dtype=np.int64))
    assert np.array_equal(s.old_triangle[s.offsets[same]], s.identical[same])


def test_p1_mass_matrix():
    mesh = grid_mesh(7, 6, jitter=0.3, seed=6)
    t, area = mesh.triangles, np.abs(mesh.triangle_areas)
    local = area[:, None, None] * (np.ones((3, 3)) + np.eye(3))[None] / 12.0
    rows, cols = np.broadcast_to(t[:, :, None], local.shape), np.broadcast_to(t[:, None, :], local.shape)
    expected = scipy.sparse.csr_matrix((local.ravel(), (rows.ravel(), cols.ravel())), shape=(mesh.n_points,) * 2)
    got = _p1_mass(mesh)
    assert got.has_sorted_indices and np.array_equal(got.indptr, expected.indptr)
    assert np.abs((got - expected).toarray()).max() <= 1e-15 * area.max()  # areas rounded apart
