"""Lexical-first MIS: disjointness, maximality and agreement with brute force."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import evomesh
from evomesh import _core


def brute_force_lfmis(c, r, order, n_forced=0):
    kept = np.zeros(len(c), bool)
    for k, i in enumerate(order):
        if k < n_forced:
            kept[i] = True
            continue
        j = np.flatnonzero(kept)
        d2 = ((c[j] - c[i]) ** 2).sum(axis=1)
        if not (d2 < (r[j] + r[i]) ** 2).any():
            kept[i] = True
    return kept


@st.composite
def sphere_systems(draw):
    n = draw(st.integers(1, 400))
    seed = draw(st.integers(0, 2**32 - 1))
    spread = draw(st.sampled_from([1.0, 10.0, 1000.0]))
    rng = np.random.default_rng(seed)
    c = rng.random((n, 2))
    if draw(st.booleans()):  # clustered and duplicated centres
        c = np.round(c * 8) / 8
    r = 0.01 * np.exp(rng.uniform(0, np.log(spread), n))
    return c, r, rng.permutation(n)


@given(sphere_systems())
def test_lfmis_matches_brute_force(system):
    c, r, order = system
    kept = evomesh.lexical_first_mis(c, r, order)
    assert np.array_equal(kept, brute_force_lfmis(c, r, order))


@given(sphere_systems())
def test_kept_spheres_disjoint_and_rejected_conflict_with_earlier(system):
    c, r, order = system
    kept = evomesh.lexical_first_mis(c, r, order)
    rank = np.empty(len(c), int)
    rank[order] = np.arange(len(c))
    d = np.linalg.norm(c[:, None] - c[None], axis=2)
    conflict = d < r[:, None] + r[None]
    np.fill_diagonal(conflict, False)
    assert not conflict[np.ix_(kept, kept)].any()
    for i in np.flatnonzero(~kept):
        assert (conflict[i] & kept & (rank < rank[i])).any()


def test_forced_spheres_kept_even_when_overlapping():
    c = np.array([[0.0, 0.0], [0.1, 0.0], [0.05, 0.0], [1.0, 1.0]])
    r = np.array([1.0, 1.0, 0.01, 0.01])
    kept = evomesh.lexical_first_mis(c, r, [0, 1, 2, 3], n_forced=2)
    assert kept.tolist() == [True, True, False, True]


def test_default_order_is_by_radius():
    c = np.array([[0.0, 0.0], [0.5, 0.0]])
    kept = evomesh.lexical_first_mis(c, [0.4, 0.2])
    assert kept.tolist() == [False, True]


def test_touching_spheres_do_not_conflict():
    c = np.array([[0.0, 0.0], [1.0, 0.0]])
    assert evomesh.lexical_first_mis(c, [0.5, 0.5]).all()


def test_packing_order_class_then_radius_then_index():
    classes = np.array([2, 0, 0, 1, 0], np.uint8)
    radii = np.array([0.1, 0.3, 0.2, 0.1, 0.2])
    assert _core.packing_order(classes, radii).tolist() == [2, 4, 1, 3, 0]


@pytest.mark.parametrize(
    "kwargs, error",
    [
        (dict(centers=np.zeros((2, 3)), radii=[1, 1]), ValueError),
        (dict(centers=np.zeros((2, 2)), radii=[1]), ValueError),
        (dict(centers=[[0, 0], [1, 1]], radii=[1, -1]), ValueError),
        (dict(centers=[[0, 0], [np.nan, 1]], radii=[1, 1]), ValueError),
        (dict(centers=[[0, 0], [1, 1]], radii=[1, 1], order=[0, 0]), ValueError),
        (dict(centers=[[0, 0], [1, 1]], radii=[1, 1], order=[0.0, 1.0]), TypeError),
    ],
)
def test_bad_input(kwargs, error):
    with pytest.raises(error):
        evomesh.lexical_first_mis(**kwargs)
