"""Every path that makes triangles returns them in the canonical order
(each rotated to start at its least point index, orientation kept; rows sorted),
so the arrays, not only the triangle set, are a function of the points and
constraints; a mesh that does not change keeps its input's order."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import evomesh
from strategies import grid_mesh


def assert_canonical(triangles: np.ndarray) -> None:
    t = np.asarray(triangles)
    assert len(t) > 0
    assert np.all(t[:, 0] < t[:, 1]) and np.all(t[:, 0] < t[:, 2]), "a triangle does not start at its least index"
    later = np.lexsort(t.T[::-1])
    assert np.array_equal(later, np.arange(len(t))), "triangles are not sorted"
    assert len(np.unique(t, axis=0)) == len(t)


def assert_step_order(result: evomesh.Mesh, mesh: evomesh.Mesh) -> None:
    """Canonical, or the input's own order when the step changed nothing."""
    if result.stats.get("unchanged", 0) == 1:
        assert np.array_equal(result.triangles, mesh.triangles)
    else:
        assert_canonical(result.triangles)


def _shuffled(mesh: evomesh.Mesh, seed: int) -> evomesh.Mesh:
    """The same mesh with its triangles in another order and rotation (an input that is not canonical)."""
    rng = np.random.default_rng(seed)
    t = np.asarray(mesh.triangles)[rng.permutation(mesh.n_triangles)]
    t = np.stack([np.roll(row, -k) for row, k in zip(t, rng.integers(0, 3, len(t)))])
    tags = None if mesh.triangle_tags is None else np.asarray(mesh.triangle_tags)
    return evomesh.Mesh(mesh.points, t, segments=mesh.segments, segment_tags=mesh.segment_tags,
                        triangle_tags=tags, kind=mesh.kind)


@settings(max_examples=12, deadline=None)
@given(n=st.integers(8, 14), seed=st.integers(0, 50), shape=st.sampled_from(["square", "hole", "notch"]),
       low=st.floats(0.4, 1.0), high=st.floats(1.0, 2.5))
def test_every_step_path_returns_canonical_triangles(n, seed, shape, low, high):
    mesh = _shuffled(grid_mesh(n, n, jitter=0.2, seed=seed, hole=shape == "hole", notch=shape == "notch"), seed)
    x = mesh.points[:, 0]
    delta = np.where(x < 0.5, low, high)
    assert_step_order(evomesh.evolve(mesh, delta, seed=seed), mesh)
    assert_step_order(evomesh.evolve(mesh, delta, seed=seed, method="drfc"), mesh)
    assert_step_order(evomesh.evolve(mesh, delta, seed=seed, quality=False), mesh)
    assert_canonical(evomesh.delaunay_refine(mesh, np.full(mesh.n_points, 0.7)).triangles)
    # one point asks for a change: the incremental path
    one = np.ones(mesh.n_points)
    one[mesh.n_points // 2] = 0.4
    assert_step_order(evomesh.evolve(mesh, one, seed=seed), mesh)


def test_incremental_and_full_paths_give_the_same_arrays():
    mesh = evomesh.evolve(grid_mesh(30, 30, jitter=0.2, seed=4), 1.0, seed=1)
    delta = np.ones(mesh.n_points)
    delta[np.linalg.norm(mesh.points - 0.5, axis=1) < 0.1] = 0.5
    fast = evomesh.evolve(mesh, delta, seed=3)
    full = evomesh.evolve(mesh, delta, seed=3, incremental=False)
    assert fast.stats["incremental_step"] == 1 and full.stats["incremental_step"] == 0
    assert np.array_equal(fast.points, full.points)
    assert np.array_equal(fast.triangles, full.triangles)
    assert_canonical(fast.triangles)


def test_motion_and_interface_steps_return_canonical_triangles():
    mesh = evomesh.evolve(grid_mesh(16, 16, jitter=0.2, seed=5), 1.0, seed=1)
    swirl = 0.02 * np.stack([np.sin(np.pi * mesh.points[:, 1]), np.sin(np.pi * mesh.points[:, 0])], axis=1)
    interior = np.asarray(mesh.kind) == 2
    moved = evomesh.evolve(mesh, size=0.08, displacement=np.where(interior[:, None], swirl, 0.0))
    assert_canonical(moved.triangles)
    cut = evomesh.evolve(mesh, size=0.08, interface=lambda p: np.hypot(p[:, 0] - 0.5, p[:, 1] - 0.5) - 0.3)
    assert_canonical(cut.triangles)
    assert np.array_equal(np.asarray(cut.triangle_tags), np.asarray(cut.triangle_tags))


def test_an_unchanged_mesh_keeps_its_input_order():
    mesh = _shuffled(evomesh.evolve(grid_mesh(14, 14, jitter=0.2, seed=6), 1.0, seed=1), 3)
    same = evomesh.evolve(mesh, 1.0, seed=2)
    assert same.stats["unchanged"] == 1
    assert np.array_equal(same.triangles, mesh.triangles)
