"""nn_M and the spacing function f (Section 3.1): brute force, Lipschitz, Lemma 3.1."""

import numpy as np
import pytest
from hypothesis import given, settings
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


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 10_000), st.booleans(), st.booleans())
def test_a_strip_of_sites_is_split_across_its_length(seed, vertical, certified):
    """Sites in a thin strip (a changed band's): the first split cuts across the
    strip's length, so its halo stays thin and the graph is built in parts (two:
    a second cut along the strip would make thick halos); the answers are those
    of one graph (spacing.cpp). (Cut along the strip first, it stayed one graph.)"""
    from evomesh import _core

    rng = np.random.default_rng(seed)
    across, along = 12, 400
    i, j = np.meshgrid(np.arange(across), np.arange(along))
    sites = np.column_stack([i.ravel(), j.ravel()]).astype(float) / along
    sites += rng.uniform(-0.3, 0.3, sites.shape) / along
    if not vertical:
        sites = sites[:, ::-1].copy()
    nn = cKDTree(sites).query(sites, k=2)[0][:, 1]
    weights = rng.uniform(0.1, 1.0, len(sites)) * nn
    one = _core.SpacingFunction(sites, weights)
    split = _core.SpacingFunction(sites, weights, min_sites_per_part=len(sites) // 5)
    assert one.n_parts == 1 and split.n_parts == 2
    lo, hi = sites.min(axis=0), sites.max(axis=0)
    long_axis = 1 if vertical else 0
    cut = np.median(sites[:, long_axis])
    on_cut = rng.uniform(lo, hi, (300, 2))
    on_cut[:, long_axis] = cut
    x = np.r_[rng.uniform(lo, hi, (1000, 2)), sites[::7], rng.uniform(-2, 3, (200, 2)), on_cut]
    f1, s1 = one.evaluate(x, certified=certified)
    f4, s4 = split.evaluate(x, certified=certified)
    expected = brute_force_f(sites, weights, x)
    assert np.all(np.abs(f4 - expected) <= 1e-12 * expected)
    assert np.all(np.abs(f4 - f1) <= 1e-12 * f1)
    assert np.array_equal(weights[s4] + np.linalg.norm(x - sites[s4], axis=1), f4)
    if certified:
        assert np.array_equal(s1, s4)


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from([0.3, 1.0, 2.0]), st.booleans())
def test_partitioned_apollonius_graphs_answer_like_one_graph(seed, delta_max, certified):
    """Large site sets are split into parts with halos (spacing.cpp): same f, same sites, same hidden count."""
    from evomesh import _core

    rng = np.random.default_rng(seed)
    k = 70
    i, j = np.meshgrid(np.arange(k), np.arange(k))
    sites = np.column_stack([i.ravel(), j.ravel()]).astype(float) / k
    sites += rng.uniform(-0.3, 0.3, sites.shape) / k
    nn = cKDTree(sites).query(sites, k=2)[0][:, 1]
    weights = rng.uniform(0.1, delta_max, len(sites)) * nn
    one = _core.SpacingFunction(sites, weights)
    split = _core.SpacingFunction(sites, weights, min_sites_per_part=k * k // 5)
    assert one.n_parts == 1
    # Thin halos: four parts. Thicker ones (delta up to 2) mostly two, four when
    # the largest weight drawn stays small (the split pays while halos are thin).
    assert split.n_parts == 4 if delta_max <= 1 else split.n_parts in (2, 4)
    # inside, at the sites, on the cuts, and far outside (answered by every part)
    x = np.r_[rng.random((1000, 2)), sites[::7], rng.uniform(-3, 4, (200, 2)),
              np.column_stack([np.full(200, np.median(sites[:, 0])), rng.random(200)])]
    f1, s1 = one.evaluate(x, certified=certified)
    f4, s4 = split.evaluate(x, certified=certified)
    expected = brute_force_f(sites, weights, x)
    assert np.all(np.abs(f4 - expected) <= 1e-12 * expected)
    assert np.all(np.abs(f4 - f1) <= 1e-12 * f1)
    cone = weights[s4] + np.linalg.norm(x - sites[s4], axis=1)
    assert np.array_equal(cone, f4)
    if certified:
        assert np.array_equal(s1, s4)
    assert one.n_hidden == split.n_hidden


@st.composite
def steep_deltas(draw):
    """A mesh and a delta that jumps or varies fast, so many sites are hidden by a
    neighbour (w_q + |p - q| <= w_p), some exactly (tangent cones: integer weights
    on a grid, where the sum is exact)."""
    mesh, delta = draw(mesh_and_delta())
    kind = draw(st.sampled_from(["jump", "random-wide", "as-drawn", "lattice-tangent"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    x = mesh.points[:, 0]
    if kind == "jump":
        delta = np.where(x < np.median(x), 0.2, draw(st.sampled_from([2.0, 5.0, 20.0])))
    elif kind == "random-wide":
        delta = np.exp(rng.uniform(np.log(0.05), np.log(50.0), mesh.n_points))
    elif kind == "lattice-tangent":
        # Sites on the integer lattice with integer weights: w_p = w_q + |p - q| exactly for axis neighbours.
        k = draw(st.integers(4, 12))
        i, j = np.meshgrid(np.arange(k), np.arange(k))
        points = np.column_stack([i.ravel(), j.ravel()]).astype(float)
        from scipy.spatial import Delaunay

        mesh = evomesh.Mesh(points, Delaunay(points).simplices)
        weight = rng.integers(1, 4, mesh.n_points).astype(float)
        return mesh, weight, True
    return mesh, delta * evomesh.nn_spacing(mesh), False


@settings(max_examples=40, deadline=None)
@given(steep_deltas(), st.integers(0, 1000), st.booleans())
def test_sites_hidden_by_a_neighbour_are_left_out_without_changing_f(case, seed, split):
    """With the mesh's triangles the construction leaves out sites
    hidden by a neighbour; f, the site found and n_hidden are bit for bit those
    of the full construction, certified or not, in one graph or in parts."""
    from evomesh import _core

    mesh, weights, lattice = case
    parts = max(4, mesh.n_points // 5) if split else 0
    full = _core.SpacingFunction(mesh.points, weights, parts)
    filtered = _core.SpacingFunction(mesh.points, weights, parts, mesh.triangles)
    t = mesh.triangles
    x = np.r_[mesh.points, random_points_in_box(mesh, 500, seed), mesh.points[t].mean(axis=1),
              0.5 * (mesh.points[t[:, 0]] + mesh.points[t[:, 1]])]
    for certified in (True, False):
        f_full, s_full = full.evaluate(x, certified=certified)
        f_filtered, s_filtered = filtered.evaluate(x, certified=certified)
        assert np.array_equal(f_full, f_filtered)
        assert np.array_equal(s_full, s_filtered)
    assert full.n_hidden == filtered.n_hidden
    assert full.n_filtered == 0
    assert filtered.n_filtered <= filtered.n_hidden
    if lattice:
        return
    # Every site left out is hidden by a neighbour in real numbers too (up to rounding of the shift).
    p, q = np.r_[t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]], t[:, [1, 0]], t[:, [2, 1]], t[:, [0, 2]]].T
    gap = weights[q] + np.linalg.norm(mesh.points[p] - mesh.points[q], axis=1) - weights[p]
    dominated = np.zeros(mesh.n_points, bool)
    dominated[p[gap <= 1e-12 * weights.max()]] = True
    assert filtered.n_filtered <= dominated.sum()


def test_the_step_filters_sites_and_keeps_f():
    """The step passes the mesh's triangles (n_filtered_sites); f at the points is unchanged."""
    mesh = grid_mesh(12, 12, jitter=0.2, seed=4)
    delta = np.where(mesh.points[:, 0] < 0.5, 0.3, 3.0)
    out = evomesh.evolve(mesh, delta, seed=0)
    assert 0 < out.stats["n_filtered_sites"] <= out.stats["n_hidden_sites"]
    f = evomesh.spacing(mesh, delta)
    assert f.n_hidden == out.stats["n_hidden_sites"]
    from evomesh import _core

    w = delta * evomesh.nn_spacing(mesh)
    assert np.array_equal(f(mesh.points), _core.SpacingFunction(mesh.points, w).evaluate(mesh.points)[0])
