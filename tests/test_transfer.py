"""Field transfer: exact at kept points, linear elsewhere."""

import numpy as np
import pytest
from hypothesis import given, settings

import evomesh
from evomesh import _core, transfer
from strategies import grid_mesh, mesh_and_delta


def linear(points, a=3.0, b=-2.0, c=0.5):
    return a * points[:, 0] + b * points[:, 1] + c


@pytest.fixture(scope="module")
def evolved():
    old = grid_mesh(14, 14, jitter=0.2, seed=3)
    delta = np.where(old.points[:, 0] < 0.5, 0.35, 2.5)
    new = evolve_checked(old, delta)
    return old, new


def evolve_checked(old, delta, seed=0):
    new = evomesh.evolve(old, delta, seed=seed)
    kept = new.origin >= 0
    assert kept.any() and (~kept).any(), "the test needs kept and new points"
    return new


@settings(max_examples=15)
@given(mesh_and_delta(max_side=10))
def test_linear_functions_are_reproduced(case):
    old, delta = case
    new = evomesh.evolve(old, delta, seed=1)
    scale = np.ptp(old.points, axis=0).max()
    offset = old.points.min(axis=0)
    values = linear((old.points - offset) / scale)
    out = transfer(old, new, values)
    assert np.allclose(out, linear((new.points - offset) / scale), rtol=0, atol=1e-12)


def test_kept_values_are_copied_bit_for_bit(evolved):
    old, new = evolved
    rng = np.random.default_rng(0)
    kept = new.origin >= 0
    for values in (rng.standard_normal(old.n_points), rng.standard_normal(old.n_points).astype(np.float32)):
        out = transfer(old, new, values)
        assert out.dtype == values.dtype
        assert np.array_equal(out[kept].view(np.uint8), values[new.origin[kept]].view(np.uint8))


def test_new_points_interpolate_inside_the_old_triangle(evolved):
    old, new = evolved
    # a non-linear field stays within the range of the old triangle's values
    values = np.sin(7 * old.points[:, 0]) * np.cos(5 * old.points[:, 1])
    out = transfer(old, new, values)
    assert out.min() >= values.min() - 1e-15 and out.max() <= values.max() + 1e-15


def test_vector_fields_and_mappings(evolved):
    old, new = evolved
    vector = np.c_[linear(old.points), linear(old.points, 1.0, 1.0, 0.0)]
    tensor = np.stack([vector, 2 * vector], axis=2)  # (n, 2, 2)
    out = transfer(old, new, {"v": vector, "T": tensor, "i": old.kind})
    assert out["v"].shape == (new.n_points, 2)
    assert out["T"].shape == (new.n_points, 2, 2)
    assert np.allclose(out["v"][:, 0], linear(new.points), atol=1e-12)
    assert np.allclose(out["T"][:, :, 1], 2 * out["T"][:, :, 0])
    assert out["i"].dtype == np.float64  # integer fields are interpolated as floats


def test_inputs_are_not_modified(evolved):
    old, new = evolved
    values = linear(old.points)
    before = values.copy()
    out = transfer(old, new, values)
    assert np.array_equal(values, before)
    out[:] = 0.0  # the result is a new array
    assert np.array_equal(values, before)


def test_transfer_to_an_unrelated_mesh_of_the_same_domain():
    old = grid_mesh(9, 9, jitter=0.2, seed=1)
    other = grid_mesh(13, 7, jitter=0.1, seed=2)  # origin all -1: every point is located
    assert np.allclose(transfer(old, other, linear(old.points)), linear(other.points), atol=1e-12)


def test_points_outside_by_rounding_use_the_boundary():
    old = grid_mesh(6, 6)
    # a copy of the mesh blown up by 4 ulps around the centre: boundary points lie just outside
    eps = np.finfo(np.float64).eps
    other = evomesh.Mesh((old.points - 0.5) * (1 + 4 * eps) + 0.5, old.triangles)
    triangle, _ = _core.locate_points(old.points, old.triangles, other.points)
    assert (triangle < 0).sum() > 0, "the test needs points that the core does not locate"
    assert np.allclose(transfer(old, other, linear(old.points)), linear(other.points), atol=1e-12)
    # 1e-9 outside a unit mesh near the origin is not rounding (millions of ulps)
    for factor in (1e-9, 1e-2):
        far = evomesh.Mesh((old.points - 0.5) * (1 + factor) + 0.5, old.triangles)
        with pytest.raises(ValueError, match="outside"):
            transfer(old, far, linear(old.points))


def test_bad_input(evolved):
    old, new = evolved
    with pytest.raises(ValueError, match="one row per point"):
        transfer(old, new, np.ones(old.n_points + 1))
    with pytest.raises(ValueError, match="one row per point"):
        transfer(old, new, 1.0)
    with pytest.raises(ValueError, match="field 'u'"):
        transfer(old, new, {"u": np.ones(3)})
    with pytest.raises(TypeError, match="numeric"):
        transfer(old, new, np.array(["a"] * old.n_points))
    with pytest.raises(TypeError, match="Mesh"):
        transfer(old.points, new, np.ones(old.n_points))
    with pytest.raises(TypeError, match="Mesh"):
        transfer(old, None, np.ones(old.n_points))
    # new was not evolved from this mesh: its origins do not match
    unrelated = grid_mesh(14, 14, jitter=0.2, seed=4)
    with pytest.raises(ValueError, match="not evolved from"):
        transfer(unrelated, new, np.ones(unrelated.n_points))
    small = grid_mesh(4, 4)
    with pytest.raises(ValueError, match="not evolved from"):
        transfer(small, new, np.ones(small.n_points))
