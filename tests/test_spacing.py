"""nn_M and the spacing function f (Section 3.1): brute force, Lipschitz, Lemma 3.1."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import cKDTree

import evomesh
from strategies import grid_mesh, mesh_and_delta


def brute_force_f(points, weights, x):
    out = np.empty(len(x))
    for s in range(0, len(x), 512):
        d = np.linalg.norm(x[s : s + 512, None, :] - points[None], axis=2)
        out[s : s + 512] = (weights[None] + d).min(axis=1)
    return out


def random_points_in_box(mesh, k, seed):
    rng = np.random.default_rng(seed)
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    return lo + rng.random((k, 2)) * (hi - lo)


@given(mesh_and_delta())
def test_nn_spacing_is_true_nearest_neighbour(case):
    mesh, _ = case
    d, _ = cKDTree(mesh.points).query(mesh.points, k=2)
    assert np.array_equal(evomesh.nn_spacing(mesh), d[:, 1])


@given(mesh_and_delta(), st.integers(0, 1000))
def test_spacing_matches_brute_force(case, seed):
    mesh, delta = case
    f = evomesh.spacing(mesh, delta)
    w = delta * evomesh.nn_spacing(mesh)
    x = np.r_[random_points_in_box(mesh, 400, seed), mesh.points]
    expected = brute_force_f(mesh.points, w, x)
    got = f(x)
    assert np.all(np.abs(got - expected) <= 1e-12 * expected)
    # the reported site attains the minimum
    site = f.nearest_site(x)
    cone = w[site] + np.linalg.norm(x - mesh.points[site], axis=1)
    assert np.all(np.abs(cone - expected) <= 1e-12 * expected)


@given(mesh_and_delta(), st.integers(0, 1000))
def test_spacing_is_1_lipschitz(case, seed):
    mesh, delta = case
    f = evomesh.spacing(mesh, delta)
    x = random_points_in_box(mesh, 300, seed)
    y = random_points_in_box(mesh, 300, seed + 1)
    y[::2] = x[::2] + 1e-3 * (y[::2] - x[::2])  # close pairs too
    lhs = np.abs(f(x) - f(y))
    rhs = np.linalg.norm(x - y, axis=1)
    assert np.all(lhs <= rhs + 1e-12 * np.maximum(f(x), f(y)))


@given(mesh_and_delta())
def test_lemma_3_1_holds_exactly(case):
    mesh, delta = case
    nn = evomesh.nn_spacing(mesh)
    f = evomesh.spacing(mesh, delta)(mesh.points)
    refine = delta <= 1
    assert np.array_equal(f[refine], (delta * nn)[refine])
    assert np.all(nn[~refine] <= f[~refine])
    assert np.all(f[~refine] <= (delta * nn)[~refine])


def test_spacing_single_point_query_and_repr():
    mesh = grid_mesh(5, 5)
    f = evomesh.spacing(mesh, np.ones(mesh.n_points))
    value = f(np.array([0.5, 0.5]))
    assert np.isscalar(value) or np.ndim(value) == 0
    assert "SpacingFunction" in repr(f)


def test_hidden_sites_counted():
    # a point with a huge delta next to a fine one: its cone never attains the minimum
    mesh = grid_mesh(6, 6)
    delta = np.full(mesh.n_points, 1.0)
    delta[mesh.n_points // 2] = 1e6
    assert evomesh.spacing(mesh, delta).n_hidden >= 1


@pytest.mark.parametrize("bad", [np.nan, -1.0, 0.0, np.inf])
def test_bad_delta_values(bad):
    mesh = grid_mesh(4, 4)
    delta = np.ones(mesh.n_points)
    delta[3] = bad
    with pytest.raises(ValueError, match="delta"):
        evomesh.spacing(mesh, delta)


def test_bad_delta_shape_and_queries():
    mesh = grid_mesh(4, 4)
    with pytest.raises(ValueError, match="one value per point"):
        evomesh.spacing(mesh, np.ones(3))
    f = evomesh.spacing(mesh, 1.0)
    with pytest.raises(ValueError):
        f(np.zeros((3, 3)))
    with pytest.raises(ValueError):
        f(np.array([[np.nan, 0.0]]))
    with pytest.raises(TypeError):
        evomesh.spacing("not a mesh", 1.0)
