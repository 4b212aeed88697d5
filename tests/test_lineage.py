"""The step's parent map: every new point's old triangle and
barycentric coordinates, so transfer needs no point location."""

import pickle

import numpy as np
import pytest
from hypothesis import given

import evomesh
from evomesh.field_transfer import Interpolation
from evomesh.mesh import Mesh
from evomesh.statistics import new_spacing_at_old_points, nn_at
from strategies import grid_mesh, mesh_and_delta


def _without_lineage(mesh: Mesh) -> Mesh:
    return Mesh._trusted(mesh.points, mesh.triangles, mesh.segments, mesh.segment_is_boundary, mesh.kind, mesh.origin)


@given(mesh_and_delta())
def test_parent_map_rebuilds_every_new_point(case):
    mesh, delta = case
    for method in ("frfc", "drfc"):
        new = evomesh.evolve(mesh, delta, method=method)
        lineage = new.lineage
        assert lineage is not None and lineage.matches(mesh)
        fresh = new.origin < 0
        assert (lineage.parent_triangle[~fresh] == -1).all()
        assert (lineage.parent_triangle[fresh] >= 0).all()  # every new point found its old triangle
        weights = lineage.barycentric[fresh]
        assert np.allclose(weights.sum(axis=1), 1.0, rtol=0, atol=1e-12)
        assert weights.min(initial=0.0) > -1e-9  # inside, up to rounding
        corners = mesh.points[mesh.triangles[lineage.parent_triangle[fresh]]]
        rebuilt = np.einsum("kj,kjc->kc", weights, corners)
        scale = np.abs(mesh.points).max()
        assert np.abs(rebuilt - new.points[fresh]).max(initial=0.0) <= 1e-12 * scale
        assert np.array_equal(lineage.old_nn, evomesh.nn_spacing(mesh))


def test_transfer_uses_the_lineage_and_agrees_with_point_location():
    mesh = grid_mesh(15, 15, jitter=0.25, seed=3, hole=True)
    delta = np.where(mesh.points[:, 0] < 0.5, 0.4, 2.5)
    new = evomesh.evolve(mesh, delta, seed=2)
    values = np.c_[np.sin(5 * mesh.points[:, 0]), mesh.points @ [2.0, -1.0]]
    by_lineage = Interpolation(mesh, new)
    by_search = Interpolation(mesh, _without_lineage(new))
    assert by_lineage.used_lineage and not by_search.used_lineage
    a, b = by_lineage(values), by_search(values)
    assert np.allclose(a, b, rtol=0, atol=1e-12)
    assert np.allclose(a[:, 1], new.points @ [2.0, -1.0], rtol=0, atol=1e-12)  # linear fields reproduced


def test_a_lineage_paired_with_another_mesh_is_refused():
    mesh = grid_mesh(9, 9, jitter=0.2, seed=1)
    new = evomesh.evolve(mesh, 0.5, seed=0)
    other = grid_mesh(9, 9, jitter=0.2, seed=2)  # same sizes, other points
    assert new.lineage.matches(other)
    with pytest.raises(ValueError, match="not evolved from old"):
        evomesh.transfer(other, new, np.zeros(other.n_points))


def test_lineage_survives_pickling_and_is_read_only():
    new = evomesh.evolve(grid_mesh(8, 8), 0.6, seed=1)
    clone = pickle.loads(pickle.dumps(new))
    assert clone.lineage.parent_triangle.tobytes() == new.lineage.parent_triangle.tobytes()
    assert clone.lineage.barycentric.tobytes() == new.lineage.barycentric.tobytes()
    with pytest.raises(ValueError):
        new.lineage.barycentric.flags.writeable = True
    with pytest.raises(AttributeError):
        new.lineage.old_f = None


@given(mesh_and_delta())
def test_new_spacing_at_old_points_matches_a_search(case):
    mesh, delta = case
    new = evomesh.evolve(mesh, delta)
    assert np.array_equal(new_spacing_at_old_points(mesh, new), nn_at(new.points, mesh.points))
    assert np.array_equal(new.nn_spacing, nn_at(new.points, new.points))
