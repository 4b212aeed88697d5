"""The output's nn that a step hands to the next, computed beside the
parent map: the same bits as a fresh computation on the output, on lattices
(equal distances everywhere), jittered grids, incremental steps and steps whose
quality pass adds and drops points."""

import numpy as np
import pytest
from hypothesis import given

import evomesh
from evomesh import _core
from strategies import grid_mesh, mesh_and_delta


def _assert_fresh(new: evomesh.Mesh) -> None:
    nn, grew = _core.nn_within_domain(new.points, new.triangles)
    np.testing.assert_array_equal(new.nn_spacing, nn)
    np.testing.assert_array_equal(new._nn_grew, grew)


@given(mesh_and_delta())
def test_a_steps_nn_is_the_outputs(case):
    mesh, delta = case
    for method in ("frfc", "drfc"):
        _assert_fresh(evomesh.evolve(mesh, delta, method=method, seed=3))


@pytest.mark.parametrize("delta", [0.45, 0.8, 1.0, 1.7])
@pytest.mark.parametrize("jitter", [0.0, 0.2])
def test_the_steps_nn_on_lattices_and_grids(delta: float, jitter: float) -> None:
    """On lattices and jittered grids, refined and coarsened, with the quality
    pass adding points, by the full step and the incremental one."""
    mesh = evomesh.unit_square_mesh(3000, jitter=jitter, seed=2)
    x = mesh.points[:, 0]
    for d in (np.full(mesh.n_points, delta), np.where(np.abs(x - 0.5) < 0.1, delta, 1.0)):
        new = evomesh.evolve(mesh, d, seed=1)
        _assert_fresh(new)
        again = evomesh.evolve(new, np.where(np.abs(new.points[:, 1] - 0.3) < 0.05, 0.7, 1.0), seed=2)
        _assert_fresh(again)


def test_points_the_quality_pass_drops() -> None:
    """Steps whose quality pass drops crowding points."""
    rng = np.random.default_rng(5)
    for hole in (False, True):
        mesh = grid_mesh(24, 24, jitter=0.3, hole=hole)
        for seed in range(3):
            delta = np.exp(rng.uniform(np.log(0.3), np.log(3.0), mesh.n_points))
            new = evomesh.evolve(mesh, delta, seed=seed)
            assert new.stats["quality_points_removed"] > 0
            _assert_fresh(new)


def test_constant_arrays_of_a_plain_mesh_are_free_and_frozen() -> None:
    """An unlabelled user mesh: tags, required flags and origin are views of one
    value (no memory a point), read-only for good, and equal to the arrays they
    stand for, also after a pickle round trip and through a step."""
    import pickle

    mesh = evomesh.unit_square_mesh(500, seed=4)
    n, m = mesh.n_points, mesh.n_triangles
    for array, value, size in ((mesh.triangle_tags, 0, m), (mesh.segment_tags, 0, len(mesh.segments)),
                               (mesh.required, False, n), (mesh.origin, -1, n)):
        assert array.shape == (size,) and array.strides == (0,)
        assert (array == value).all()
        with pytest.raises(ValueError):
            array.flags.writeable = True
    again = pickle.loads(pickle.dumps(mesh))
    np.testing.assert_array_equal(again.origin, mesh.origin)
    np.testing.assert_array_equal(again.triangle_tags, mesh.triangle_tags)
    new = evomesh.evolve(mesh, 0.7, seed=1)
    assert new.triangle_tags.strides == (0,) and (new.triangle_tags == 0).all()
    assert ((new.origin >= -1) & (new.origin < n)).all()


@pytest.mark.parametrize("jitter", [0.0, 0.2])
def test_an_incremental_steps_nn_from_the_change(jitter: float) -> None:
    """A narrow band on a 2e4-point mesh: the incremental step takes the output's
    nn from the input's where nothing near changed (nn_spacing_after_change);
    the same bits as a fresh computation, on a lattice (ties) and a jittered grid,
    refined and coarsened, and again on the stepped mesh."""
    mesh = evomesh.unit_square_mesh(20000, jitter=jitter, seed=3)
    for value in (0.6, 1.6):
        x = mesh.points[:, 0]
        new = evomesh.evolve(mesh, np.where(np.abs(x - 0.4) < 0.02, value, 1.0), seed=1)
        assert "incremental_quiet_triangles" in new.stats  # the incremental path
        _assert_fresh(new)
        y = new.points[:, 1]
        again = evomesh.evolve(new, np.where(np.abs(y - 0.7) < 0.015, 1 / value, 1.0), seed=2)
        assert "incremental_quiet_triangles" in again.stats
        _assert_fresh(again)
