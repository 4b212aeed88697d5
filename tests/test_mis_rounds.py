"""The lexical-first MIS computed in rounds by parts that see each
other's states only between rounds (cpp/src/mis_rounds.cpp; the argument in
docs/distributed-step.md, 3.4) equals the serial MIS on every partition."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from evomesh import _core


def _spheres(n, seed, graded):
    rng = np.random.default_rng(seed)
    centers = rng.random((n, 2))
    if graded:  # radii from 1e-3 to 0.05 along x: long chains up the gradient
        radii = 1e-3 + 0.05 * centers[:, 0] ** 2 * rng.uniform(0.8, 1.2, n)
    else:
        radii = rng.uniform(0.01, 0.03, n)
    classes = rng.integers(0, 4, n).astype(np.uint8)
    order = _core.packing_order(classes, radii)
    return centers, radii, order


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 600), seed=st.integers(0, 10**6), graded=st.booleans(), n_parts=st.integers(1, 9),
       layout=st.sampled_from(["random", "stripes", "order"]), forced=st.integers(0, 5))
def test_rounds_give_the_serial_mis_on_any_partition(n, seed, graded, n_parts, layout, forced):
    centers, radii, order = _spheres(n, seed, graded)
    rng = np.random.default_rng(seed + 1)
    if layout == "random":
        part = rng.integers(0, n_parts, n)
    elif layout == "stripes":  # borders across the radius gradient
        part = np.minimum((centers[:, 1] * n_parts).astype(np.int64), n_parts - 1)
    else:  # the worst case: each part a contiguous range of the order, later parts later
        part = np.empty(n, np.int64)
        part[order] = np.arange(n) * n_parts // n
    n_forced = min(forced, n)
    serial = _core.lexical_first_mis(centers, radii, order, n_forced)
    out = _core.lexical_first_mis_in_rounds(centers, radii, order, n_forced, part, n_parts)
    assert np.array_equal(out["kept"], serial)
    assert out["rounds"] == len(out["messages"]) == len(out["undecided"])
    assert out["undecided"][-1] == 0 if n > n_forced else out["rounds"] == 0
    if n_parts == 1 and n > n_forced:
        assert out["rounds"] == 1 and out["messages"].sum() == 0 and out["halo"] == 0


def test_one_round_per_crossing_of_an_ordered_chain():
    """Spheres on a line, each conflicting with the next, ordered left to right, one part each: the states
    cross one border per round, so the rounds are the parts (the bound of 3.4 is tight)."""
    n = 8
    centers = np.stack([np.arange(n, dtype=float), np.zeros(n)], axis=1)
    radii = np.full(n, 0.6)
    order = np.arange(n)
    out = _core.lexical_first_mis_in_rounds(centers, radii, order, 0, np.arange(n), n)
    assert out["rounds"] == n
    assert np.array_equal(out["kept"], np.arange(n) % 2 == 0)


def test_bad_input_is_refused():
    centers, radii, order = _spheres(10, 0, False)
    with pytest.raises(ValueError, match="permutation"):
        _core.lexical_first_mis_in_rounds(centers, radii, np.zeros(10, np.int64), 0, np.zeros(10, np.int64), 1)
    with pytest.raises(ValueError, match="part out of range"):
        _core.lexical_first_mis_in_rounds(centers, radii, order, 0, np.full(10, 3), 2)
    with pytest.raises(ValueError, match="positive"):
        _core.lexical_first_mis_in_rounds(centers, -radii, order, 0, np.zeros(10, np.int64), 1)


def test_radii_twelve_octaves_apart_and_far_out_centres():
    """The conflict search does not scan the cells of a small octave around a large sphere (that took time
    growing with the square of the radius ratio), and a grid cell index that cannot be represented is an error."""
    centers = np.array([[0.0, 0.0], [100.0, 0.0], [0.5, 0.0], [1.0 + 1e-13, 0.0]])
    radii = np.array([1.0, 1e-12, 1e-12, 1e-12])
    order = np.array([0, 1, 2, 3])
    out = _core.lexical_first_mis_in_rounds(centers, radii, order, 0, np.array([0, 1, 0, 1]), 2)
    assert np.array_equal(out["kept"], _core.lexical_first_mis(centers, radii, order, 0))
    assert out["kept"].tolist() == [1, 1, 0, 0]  # (the last two meet the large sphere, 12 octaves up)
    with pytest.raises(ValueError, match="too far out"):
        _core.lexical_first_mis_in_rounds(np.array([[1e19, 0.0], [0.0, 0.0]]), np.array([1.0, 1.0]),
                                          np.array([0, 1]), 0, np.array([0, 0]), 1)
