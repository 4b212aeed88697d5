"""DRFC (Section 5): Delaunay refinement with rules 1-4, then the one-level
coarsening of Miller, Talmor and Teng, with FRFC's validity properties."""

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import evomesh
from evomesh import PointKind
from evomesh.evolution import DRFC_DEFAULTS, delaunay_refine
from invariants import check_evolved, nn_in, spacing_ratio
from strategies import grid_mesh, mesh_and_delta, random_meshes
from test_tags import check_labels, tagged

# Relative slack for comparing distances computed in floating point.
RTOL = 1e-12


@given(mesh_and_delta(), st.booleans())
def test_output_is_valid(case, quality):
    mesh, delta = case
    new = evomesh.evolve(mesh, delta, method="drfc", quality=quality)
    check_evolved(mesh, new)


@given(mesh_and_delta())
def test_rule_4_holds_after_the_refinement_stage(case):
    """Every point v of M_I has a neighbour within f(v); at an input point p that
    is nn_MI(p) <= delta(p) nn_M(p) (the paper's rule 4) where delta(p) <= 1."""
    mesh, delta = case
    refined = delaunay_refine(mesh, delta)
    check_evolved(mesh, refined)
    assert refined.stats["capped"] == 0
    n = mesh.n_points
    # the input points come first, unchanged, and nothing is removed
    assert np.array_equal(refined.origin[:n], np.arange(n))
    assert (refined.origin[n:] == -1).all()
    assert np.array_equal(refined.points[:n], mesh.points)
    f = evomesh.spacing(mesh, delta)
    nn = nn_in(refined.points, refined.points)
    old_bound = np.r_[delta * evomesh.nn_spacing(mesh), np.full(refined.n_points - n, np.inf)]
    bound = np.minimum(f(refined.points), old_bound)
    assert (nn <= bound * (1 + RTOL)).all(), (nn / bound).max()
    refine_points = delta <= 1
    target = delta * evomesh.nn_spacing(mesh)
    assert (nn[:n][refine_points] <= target[refine_points] * (1 + RTOL)).all()


@given(mesh_and_delta(max_side=9))
def test_refinement_stage_is_well_shaped_on_square_domains(case):
    """Rule 3: no angle below min_angle away from input angles below 60 degrees
    (grid domains have none, the hole and notch corners are 90 and 270)."""
    mesh, delta = case
    refined = delaunay_refine(mesh, delta, min_angle=20.0)
    assert evomesh.quality(refined).min_angle >= 20.0 - 1e-6


def test_coarsening_adds_no_samples():
    """Step 2 only selects points of M_I (no new samples)."""
    mesh = grid_mesh(25, 25, jitter=0.25, seed=2)
    delta = np.exp(np.random.default_rng(0).uniform(np.log(0.3), np.log(3), mesh.n_points))
    refined = {tuple(p) for p in delaunay_refine(mesh, delta).points}
    new = evomesh.evolve(mesh, delta, method="drfc", quality=False)
    check_evolved(mesh, new)
    assert all(tuple(p) in refined for p in new.points)
    assert new.stats["n_refined_points"] == len(refined)


def test_refines_and_coarsens_where_asked():
    mesh = grid_mesh(30, 30, jitter=0.2, seed=3)
    delta = np.where(mesh.points[:, 0] < 0.5, 0.3, 3.0)
    new = evomesh.evolve(mesh, delta, method="drfc")
    check_evolved(mesh, new)
    left, right = mesh.points[:, 0] < 0.45, mesh.points[:, 0] > 0.55
    assert (new.points[:, 0] < 0.45).sum() > left.sum()
    assert (new.points[:, 0] > 0.55).sum() < right.sum()
    ratio = spacing_ratio(mesh, new, delta)
    # MTT's coarsening keeps nn_M'(p) = Theta(delta nn_M(p)); measured below 3 here
    assert np.percentile(ratio, 99) < 3.0


def test_kinds_origin_and_corners():
    mesh = grid_mesh(15, 15, notch=True)
    delta = np.full(mesh.n_points, 0.5)
    new = evomesh.evolve(mesh, delta, method="drfc")
    check_evolved(mesh, new)
    fresh = new.origin < 0
    assert fresh.any()
    assert set(np.unique(new.kind[fresh])) <= {PointKind.BOUNDARY, PointKind.SAMPLED}
    assert (new.kind[~fresh] == mesh.kind[new.origin[~fresh]]).all()
    second = evomesh.evolve(new, np.full(new.n_points, 2.0), method="drfc")
    check_evolved(new, second)
    kept = second.origin >= 0
    was_sampled = new.kind[second.origin[kept]] == PointKind.SAMPLED
    assert (second.kind[kept][was_sampled] == PointKind.STEINER).all()


def test_holes_and_interior_segments_survive_many_steps():
    mesh = grid_mesh(14, 14, hole=True)
    p = mesh.points
    t = mesh.triangles
    edges = np.unique(np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1), axis=0)
    on_line = np.isclose(p[:, 1], p[:, 1][np.argmin(np.abs(p[:, 1] - 0.15))])
    line = edges[on_line[edges[:, 0]] & on_line[edges[:, 1]]]
    current = first = evomesh.Mesh(p, t, line)
    rng = np.random.default_rng(5)
    for step in range(5):
        delta = np.exp(rng.uniform(np.log(0.4), np.log(2.5), current.n_points))
        nxt = evomesh.evolve(current, delta, method="drfc", seed=step)
        check_evolved(current, nxt)
        assert (~nxt.segment_is_boundary).any()
        current = nxt
    assert current.euler_characteristic() == 0
    assert abs(current.area - first.area) <= 1e-12 * first.area


def test_bit_identical_and_thread_independent():
    mesh = grid_mesh(25, 25, jitter=0.2, seed=1)
    delta = np.exp(np.random.default_rng(0).uniform(np.log(0.2), np.log(5), mesh.n_points))
    a = evomesh.evolve(mesh, delta, method="drfc")
    b = evomesh.evolve(mesh, delta, method="drfc")
    c = evomesh.evolve(mesh, delta, method="drfc", threads=1)
    for name in ("points", "triangles", "segments", "origin", "kind"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes()
        assert getattr(a, name).tobytes() == getattr(c, name).tobytes()


def test_radius_scale_trades_size_for_spacing():
    mesh = grid_mesh(25, 25, jitter=0.2, seed=7)
    delta = np.where(mesh.points[:, 0] < 0.5, 0.4, 2.5)
    small = evomesh.evolve(mesh, delta, method="drfc", radius_scale=0.6)
    large = evomesh.evolve(mesh, delta, method="drfc", radius_scale=1.0)
    assert small.n_points > large.n_points
    assert spacing_ratio(mesh, small, delta).max() <= spacing_ratio(mesh, large, delta).max()


def test_max_samples_guard():
    mesh = grid_mesh(10, 10)
    with pytest.raises(ValueError, match="max_samples"):
        evomesh.evolve(mesh, np.full(mesh.n_points, 0.01), method="drfc", max_samples=1e4)
    with pytest.raises(ValueError, match="max_samples"):
        delaunay_refine(mesh, np.full(mesh.n_points, 0.01), max_samples=1e4)


@pytest.mark.parametrize(
    "options, error, match",
    [
        ({"samples": "random"}, TypeError, "unknown option"),
        ({"radius_scale": 1.5}, ValueError, "radius_scale"),
        ({"radius_scale": 0.0}, ValueError, "radius_scale"),
        ({"max_samples": -1.0}, ValueError, "max_samples"),
        ({"threads": 0}, ValueError, "threads"),
    ],
)
def test_bad_options_are_rejected(options, error, match):
    mesh = grid_mesh(5, 5)
    with pytest.raises(error, match=match):
        evomesh.evolve(mesh, 1.0, method="drfc", **options)


def test_defaults_are_documented():
    expected = {"min_angle": 20.0, "radius_scale": 0.75, "quality": True, "max_samples": 5e7, "threads": None}
    assert {k: DRFC_DEFAULTS[k] for k in expected} == expected
    mesh = grid_mesh(6, 6)
    with pytest.raises(TypeError, match="mesh"):
        delaunay_refine(mesh.points, 1.0)


# delaunay_refine and evolve(method="drfc") carry segment tags,
# triangle tags and required points (test_tags.py's labelling and checks).
@settings(max_examples=12)
@given(random_meshes(max_points=80), st.integers(0, 2**16), st.sampled_from([0.3, 0.6, 1.0]))
def test_delaunay_refine_keeps_the_labels(mesh, seed, delta):
    initial = tagged(mesh, seed)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", evomesh.QualityWarning)
            refined = delaunay_refine(initial, delta)
    except ValueError as error:  # a random cloud may ask too much of float64 or of memory: refused, fine
        assert "max_samples" in str(error) or "not a valid mesh in float64" in str(error)
        return
    check_labels(initial, refined)
    n = initial.n_points
    # refinement only adds: every input point keeps its index and flag
    assert np.array_equal(refined.origin[:n], np.arange(n))
    assert np.array_equal(refined.required[:n], initial.required) and not refined.required[n:].any()
    assert np.array_equal(np.unique(refined.segment_tags), np.unique(initial.segment_tags))


@pytest.mark.parametrize("delta", [0.4, 2.5])
def test_drfc_step_keeps_the_labels(delta):
    initial = tagged(grid_mesh(14, 14, jitter=0.2, seed=4), 3)
    refined = delaunay_refine(initial, delta)
    check_labels(initial, refined)
    new = evomesh.evolve(initial, delta, method="drfc")
    check_labels(initial, new)
    assert new.segment_tags.size == len(new.segments) and new.triangle_tags.size == new.n_triangles
