"""Global ids of a step's input (docs/distributed-step.md section 2.2).

The core keys by point, triangle and segment ids what it used to key by array
position: the random streams of the samples, the packing's tie order, the spacing
repair's order and phase, where chains start and the order of triangle fans (in the
incremental step too). With the
positions as ids the step gives exactly what it gave without them; and the same mesh
stored in another array order, with the first order's positions as ids, gives the same
output points, triangles, segments, tags and kinds. (Without the quality pass: its
inserted points still follow the triangulation's history, see the doc's section 2.4.)

The ids reach the core through the private keywords ``point_gids``, ``triangle_gids``
and ``segment_keys`` of ``evomesh._core.frfc``; the distributed layer passes them.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import evomesh
from evomesh import _core
from strategies import grid_mesh


def _constrained_mesh(nx: int, ny: int, shape: str, jitter: float, seed: int) -> evomesh.Mesh:
    """A grid mesh (square, with a hole, or L-shaped) with a few interior constraint
    edges, segment tags, two triangle regions and two required points."""
    base = grid_mesh(nx, ny, jitter=jitter, seed=seed, hole=shape == "hole", notch=shape == "notch")
    tris = base.triangles
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    edges, counts = np.unique(e, axis=0, return_counts=True)
    rng = np.random.default_rng(seed)
    interior = edges[counts == 2]
    constraints = interior[rng.choice(len(interior), min(len(interior), 6), replace=False)]
    boundary = edges[counts == 1]
    tagged = boundary[rng.choice(len(boundary), min(len(boundary), 5), replace=False)]
    segments = np.concatenate([constraints, tagged])
    segment_tags = rng.integers(1, 4, len(segments))
    centroid_x = base.points[tris].mean(axis=1)[:, 0]
    triangle_tags = np.where(centroid_x < 0.5, 1, 2)
    required = np.zeros(base.n_points, bool)
    required[rng.choice(base.n_points, 2, replace=False)] = True
    return evomesh.Mesh(base.points, tris, segments, segment_tags=segment_tags, triangle_tags=triangle_tags,
                        required=required)


def _arrays(mesh: evomesh.Mesh) -> dict[str, np.ndarray]:
    return {
        "points": mesh.points,
        "triangles": mesh.triangles,
        "segments": mesh.segments,
        "segment_is_boundary": mesh.segment_is_boundary.astype(np.uint8),
        "kind": mesh.kind,
        "segment_tags": mesh.segment_tags,
        "triangle_tags": mesh.triangle_tags,
        "required": mesh.required.astype(np.uint8),
    }


def _step(arrays: dict[str, np.ndarray], delta: np.ndarray, options, **ids) -> dict:
    a = arrays
    return _core.frfc(a["points"], a["triangles"], a["segments"], a["segment_is_boundary"], a["kind"], delta,
                      options, segment_tags=a["segment_tags"], triangle_tags=a["triangle_tags"],
                      required=a["required"], **ids)


def _permuted(arrays: dict[str, np.ndarray], rng: np.random.Generator):
    """The same mesh with its points, triangles and segments stored in a random order
    (each triangle keeps its vertex rotation, each segment its direction), the ids
    (the first order's positions) and the point permutation."""
    n = len(arrays["points"])
    point_order = rng.permutation(n)
    new_index = np.empty(n, np.int64)
    new_index[point_order] = np.arange(n)
    triangle_order = rng.permutation(len(arrays["triangles"]))
    segment_order = rng.permutation(len(arrays["segments"]))
    permuted = {
        "points": arrays["points"][point_order],
        "triangles": new_index[arrays["triangles"][triangle_order]],
        "segments": new_index[arrays["segments"][segment_order]],
        "segment_is_boundary": arrays["segment_is_boundary"][segment_order],
        "kind": arrays["kind"][point_order],
        "segment_tags": arrays["segment_tags"][segment_order],
        "triangle_tags": arrays["triangle_tags"][triangle_order],
        "required": arrays["required"][point_order],
    }
    ids = {"point_gids": point_order, "triangle_gids": triangle_order, "segment_keys": segment_order}
    return permuted, ids, point_order


def _as_sets(result: dict, input_ids: np.ndarray | None = None) -> dict[str, object]:
    """A step's output independent of array order: points with their kind and the id
    of the input point they come from, triangles and segments as sets of coordinates
    with their tags."""
    p = result["points"]
    origin = result["origin"]
    from_id = np.where(origin >= 0, (input_ids[origin] if input_ids is not None else origin), -1)
    points = sorted(zip(map(tuple, p.tolist()), result["kind"].tolist(), from_id.tolist()))
    triangles = sorted(
        (tuple(sorted(map(tuple, p[t].tolist()))), tag)
        for t, tag in zip(result["triangles"], result["triangle_tags"].tolist())
    )
    segments = sorted(
        (tuple(sorted(map(tuple, p[s].tolist()))), bool(b), tag)
        for s, b, tag in zip(result["segments"], result["segment_is_boundary"], result["segment_tags"].tolist())
    )
    return {"points": points, "triangles": triangles, "segments": segments}


def _delta(mesh: evomesh.Mesh, kind: str, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = mesh.points[:, 0]
    if kind == "random":
        return np.exp(rng.uniform(np.log(0.2), np.log(5.0), mesh.n_points))
    if kind == "front":  # refine behind a front, coarsen ahead of it
        return np.where(x < 0.4, 0.5, np.where(x > 0.7, 2.0, 1.0))
    if kind == "local":  # delta = 1 but near a few points (the incremental step's case)
        delta = np.ones(mesh.n_points)
        delta[rng.choice(mesh.n_points, 3, replace=False)] = 0.6
        return delta
    return 0.2 * 25.0**x


meshes_with_labels = st.builds(
    _constrained_mesh,
    nx=st.integers(6, 12),
    ny=st.integers(6, 12),
    shape=st.sampled_from(["square", "hole", "notch"]),
    jitter=st.sampled_from([0.0, 0.25]),
    seed=st.integers(0, 2**16),
)


@given(mesh=meshes_with_labels, delta_kind=st.sampled_from(["random", "front", "local", "smooth"]),
       seed=st.integers(0, 2**16))
def test_positions_as_ids_give_the_same_bits(mesh, delta_kind, seed):
    arrays = _arrays(mesh)
    delta = _delta(mesh, delta_kind, seed)
    options = evomesh.FrfcOptions()
    options.seed = seed
    plain = _step(arrays, delta, options)
    ids = {
        "point_gids": np.arange(mesh.n_points),
        "triangle_gids": np.arange(mesh.n_triangles),
        "segment_keys": np.arange(len(mesh.segments)),
    }
    keyed = _step(arrays, delta, options, **ids)
    for name in ("points", "triangles", "segments", "segment_tags", "triangle_tags", "kind", "origin"):
        assert np.array_equal(plain[name], keyed[name]), name
    assert plain["points"].tobytes() == keyed["points"].tobytes()


@given(mesh=meshes_with_labels, delta_kind=st.sampled_from(["random", "front", "local", "smooth"]),
       seed=st.integers(0, 2**16), order_seed=st.integers(0, 2**16),
       ring=st.booleans(), samples=st.sampled_from(["random", "midpoints"]))
def test_permuted_input_with_its_ids_gives_the_same_mesh(mesh, delta_kind, seed, order_seed, ring, samples):
    arrays = _arrays(mesh)
    delta = _delta(mesh, delta_kind, seed)
    options = evomesh.FrfcOptions()
    options.seed = seed
    options.quality = False
    options.ring_samples = ring
    options.samples = getattr(_core.SampleMode, samples)
    reference = _step(arrays, delta, options)
    permuted, ids, point_order = _permuted(arrays, np.random.default_rng(order_seed))
    result = _step(permuted, delta[point_order], options, **ids)
    assert _as_sets(result, ids["point_gids"]) == _as_sets(reference)
    # (and a real step: the reference refines or coarsens the mesh)
    assert len(reference["points"]) != mesh.n_points or not np.array_equal(reference["points"], mesh.points)


@given(mesh=meshes_with_labels, seed=st.integers(0, 2**16), order_seed=st.integers(0, 2**16))
def test_incremental_step_with_ids_matches_the_full_step(mesh, seed, order_seed):
    """Where delta = 1 but near a few points the incremental step runs; with ids too,
    its ties follow them, and it gives the full step's bits."""
    permuted, ids, point_order = _permuted(_arrays(mesh), np.random.default_rng(order_seed))
    delta = _delta(mesh, "local", seed)[point_order]
    options = evomesh.FrfcOptions()
    options.seed = seed
    fast = _step(permuted, delta, options, **ids)
    options.incremental = False
    full = _step(permuted, delta, options, **ids)
    assert fast["stats"]["incremental_step"] == 1 and full["stats"]["incremental_step"] == 0
    for name in ("points", "triangles", "segments", "segment_tags", "triangle_tags", "kind", "origin"):
        assert np.array_equal(fast[name], full[name]), name


def test_positions_as_ids_give_the_same_bits_in_drfc():
    mesh = _constrained_mesh(10, 9, "hole", 0.0, 3)
    a = _arrays(mesh)
    delta = _delta(mesh, "front", 0)
    ids = {"point_gids": np.arange(mesh.n_points), "triangle_gids": np.arange(mesh.n_triangles),
           "segment_keys": np.arange(len(mesh.segments))}
    results = [
        _core.drfc(a["points"], a["triangles"], a["segments"], a["segment_is_boundary"], a["kind"], delta,
                   evomesh.DrfcOptions(), segment_tags=a["segment_tags"], triangle_tags=a["triangle_tags"],
                   required=a["required"], **extra)
        for extra in ({}, ids)
    ]
    for name in ("points", "triangles", "segments", "kind", "origin"):
        assert np.array_equal(results[0][name], results[1][name]), name


def test_ids_change_the_draws():
    """The ids are what the streams read: other ids, other samples (the property above
    cannot hold by ignoring them)."""
    mesh = _constrained_mesh(10, 10, "square", 0.25, 7)
    arrays = _arrays(mesh)
    delta = np.full(mesh.n_points, 0.5)
    options = evomesh.FrfcOptions()
    options.quality = False
    plain = _step(arrays, delta, options)
    shifted = _step(arrays, delta, options, triangle_gids=np.arange(mesh.n_triangles) + 1000)
    assert _as_sets(plain)["points"] != _as_sets(shifted)["points"]


@pytest.mark.parametrize("name, ids, message", [
    ("point_gids", lambda m: np.zeros(m.n_points, np.int64), "distinct"),
    ("point_gids", lambda m: np.arange(m.n_points - 1), "one id per entry"),
    ("triangle_gids", lambda m: np.arange(m.n_triangles) - 1, r"\[0, 2\^60\)"),
    ("segment_keys", lambda m: np.full(len(m.segments), 2**60), r"\[0, 2\^60\)"),
])
def test_bad_ids_are_refused(name, ids, message):
    mesh = _constrained_mesh(6, 6, "square", 0.0, 1)
    with pytest.raises(ValueError, match=f"{name}.*{message}"):
        _step(_arrays(mesh), np.ones(mesh.n_points), evomesh.FrfcOptions(), **{name: ids(mesh)})
