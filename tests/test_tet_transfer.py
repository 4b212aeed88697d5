"""Conservative transfer of per-tetrahedron fields (transfer_cells on TetMesh):
exact intersection volumes, conservation, constants, determinism, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import evomesh
from evomesh import _core
from evomesh.field_transfer import TetSupermesh
from evomesh.tet_mesh import tet_volumes


@pytest.fixture(scope="module")
def steps():
    """Two steps on the unit cube: a sphere's shell refined, then the shell moved."""
    m0 = evomesh.unit_cube_mesh(5)

    def shell(centre):
        return lambda x: 0.07 + 0.3 * np.abs(np.linalg.norm(x - centre, axis=1) - 0.25)

    m1 = evomesh.evolve(m0, size=shell([0.5, 0.5, 0.5]), seed=1)
    m2 = evomesh.evolve(m1, size=shell([0.6, 0.5, 0.5]), seed=2)
    return m0, m1, m2


def volume_of(t: np.ndarray) -> float:
    return float(abs(tet_volumes(t, np.arange(4)[None])[0]))


coordinates = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
tetrahedron = st.lists(st.lists(coordinates, min_size=3, max_size=3), min_size=4, max_size=4).map(np.array).filter(
    lambda t: volume_of(t) > 1e-3)


@given(tetrahedron, tetrahedron, st.floats(0.05, 0.95), st.floats(0.05, 0.95))
def test_intersection_volume_adds_up_over_a_split(t, s, a, b):
    """|t n s| is symmetric, at most min(|t|, |s|), |t| for s = t, and additive:
    splitting s at an interior point into four tetrahedra keeps the total."""
    v = _core.tet_intersection_volume(t, s)
    assert v >= 0
    assert abs(v - _core.tet_intersection_volume(s, t)) <= 1e-12
    assert v <= min(volume_of(t), volume_of(s)) + 1e-12
    assert abs(_core.tet_intersection_volume(t, t) - volume_of(t)) <= 1e-12 * volume_of(t)
    weights = np.array([a, (1 - a) * b, (1 - a) * (1 - b) / 2, (1 - a) * (1 - b) / 2])
    inner = weights @ s
    parts = sum(_core.tet_intersection_volume(t, np.vstack([np.delete(s, k, axis=0), inner])) for k in range(4))
    assert abs(parts - v) <= 1e-12


def test_disjoint_and_touching_tetrahedra_do_not_overlap():
    t = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    assert _core.tet_intersection_volume(t, t + 2.0) == 0.0
    mirrored = t * [1, 1, -1]  # shares the face z = 0
    assert _core.tet_intersection_volume(t, mirrored) == 0.0
    half = t * 0.5
    assert abs(_core.tet_intersection_volume(t, half) - 1 / 48) <= 1e-15


def test_supermesh_covers_both_meshes(steps):
    """Per new tetrahedron the pair volumes add up to its volume, per old one to
    its volume: every overlap is found, none twice."""
    for old, new in zip(steps[:-1], steps[1:]):
        s = TetSupermesh(old, new)
        assert (s.volume > 0).all()
        covered_new = np.bincount(s.new_tet, s.volume, minlength=new.n_tetrahedra)
        covered_old = np.bincount(s.old_tet, s.volume, minlength=old.n_tetrahedra)
        assert np.abs(covered_new / new.volumes - 1).max() < 1e-12
        assert np.abs(covered_old / old.volumes - 1).max() < 1e-12
        pairs = s.new_tet * old.n_tetrahedra + s.old_tet
        assert len(np.unique(pairs)) == len(pairs)
    assert TetSupermesh(steps[1], steps[2]).identical > 0  # the shortcut is taken


def test_transfer_cells_conserves_and_keeps_constants(steps):
    rng = np.random.default_rng(3)
    u0 = rng.uniform(0.5, 2.0, steps[0].n_tetrahedra)
    vector = np.stack([u0, -3 * u0], axis=1)
    current, current_vector = u0, vector
    total = (steps[0].volumes * u0).sum()
    for old, new in zip(steps[:-1], steps[1:]):
        before = current.copy()
        given = current.copy()
        current_vector = evomesh.transfer_cells(old, new, current_vector)
        current = evomesh.transfer_cells(old, new, given)
        assert np.array_equal(given, before)  # the caller's values are untouched
        assert current.shape == (new.n_tetrahedra,)
        assert abs((new.volumes * current).sum() - total) <= 1e-12 * abs(total)
        assert np.array_equal(current_vector[:, 0], current)
        # a P0 projection is an average: within the old range
        assert before.min() <= current.min() and current.max() <= before.max()
        constant = evomesh.transfer_cells(old, new, np.full(old.n_tetrahedra, 2.75))
        assert (constant == 2.75).all()
        named = evomesh.transfer_cells(old, new, {"c": np.full(old.n_tetrahedra, 1, dtype=np.int32)})
        assert named["c"].dtype == np.float64 and (named["c"] == 1).all()


def test_kept_tetrahedra_keep_their_values(steps):
    _, m1, m2 = steps
    s = TetSupermesh(m1, m2)
    u = np.arange(m1.n_tetrahedra, dtype=np.float64)
    v = evomesh.transfer_cells(m1, m2, u)
    single = np.diff(s.offsets) == 1
    assert np.array_equal(v[single], u[s.old_tet[s.offsets[:-1][single]]])


def test_same_bits_on_any_thread_count(steps):
    _, m1, m2 = steps
    one = TetSupermesh(m1, m2, threads=1)
    two = TetSupermesh(m1, m2, threads=2)
    assert np.array_equal(one.offsets, two.offsets) and np.array_equal(one.old_tet, two.old_tet)
    assert np.array_equal(one.volume.view(np.uint64), two.volume.view(np.uint64))


def test_bad_transfers_raise(steps):
    m0, m1, _ = steps
    with pytest.raises(ValueError, match="lineage"):
        evomesh.transfer_cells(m1, m0, np.ones(m1.n_tetrahedra))
    with pytest.raises(ValueError, match="one row per tetrahedron"):
        evomesh.transfer_cells(m0, m1, np.ones(m0.n_tetrahedra + 1))
    with pytest.raises(TypeError, match="numeric"):
        evomesh.transfer_cells(m0, m1, np.array(["a"] * m0.n_tetrahedra))
    with pytest.raises(TypeError, match="TetMesh"):
        evomesh.transfer_cells(m0, evomesh.unit_square_mesh(20), np.ones(m0.n_tetrahedra))
