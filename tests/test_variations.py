"""FRFC's practical variations (Section 5) as evolve options: every combination
gives a valid mesh, and each variation does what it says."""

import itertools

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import evomesh
from evomesh import PointKind
from evomesh.evolution import FRFC_DEFAULTS
from invariants import check_evolved, spacing_ratio
from strategies import grid_mesh, mesh_and_delta

SAMPLES = ["random", "barycentre", "midpoints", "barycentre+midpoints"]
COMBINATIONS = list(itertools.product(SAMPLES, [False, True], ["exact", "cheap"], [True, False]))


@pytest.fixture(scope="module")
def cases():
    hole = grid_mesh(12, 12, hole=True)
    notch = grid_mesh(13, 13, notch=True)
    square = grid_mesh(14, 14, jitter=0.25, seed=9)
    return [
        (hole, np.where(hole.points[:, 0] < 0.5, 0.3, 3.0)),
        (notch, np.exp(np.random.default_rng(1).uniform(np.log(0.3), np.log(3.0), notch.n_points))),
        (square, 0.2 * 25.0 ** square.points[:, 0]),
    ]


@pytest.mark.parametrize("samples, skip_coarse, radius, quality", COMBINATIONS)
def test_every_combination_is_valid(cases, samples, skip_coarse, radius, quality):
    for mesh, delta in cases:
        new = evomesh.evolve(mesh, delta, samples=samples, skip_coarse=skip_coarse, radius=radius, quality=quality)
        check_evolved(mesh, new)
        if quality:
            assert evomesh.quality(new).min_angle >= 20.0 - 1e-6


@given(
    mesh_and_delta(max_side=10),
    st.sampled_from(SAMPLES),
    st.booleans(),
    st.sampled_from(["exact", "cheap"]),
    st.booleans(),
    st.integers(0, 2**32),
)
def test_random_combinations_are_valid(case, samples, skip_coarse, radius, quality, seed):
    mesh, delta = case
    new = evomesh.evolve(mesh, delta, seed=seed, samples=samples, skip_coarse=skip_coarse, radius=radius,
                         quality=quality)
    check_evolved(mesh, new)


def _new_interior(mesh, new):
    return new.points[(new.origin < 0) & (new.kind == PointKind.SAMPLED)]


def test_skip_coarse_adds_no_interior_samples_where_all_vertices_coarsen():
    mesh = grid_mesh(16, 16, jitter=0.2, seed=2)
    delta = np.full(mesh.n_points, 2.0)
    # (no gap repair: it adds points beside kept C-points, not samples)
    plain = evomesh.evolve(mesh, delta, quality=False, gap_repair_ratio=None, refine_gap_ratio=None)
    skipped = evomesh.evolve(mesh, delta, quality=False, skip_coarse=True, gap_repair_ratio=None, refine_gap_ratio=None)
    check_evolved(mesh, skipped)
    assert plain.stats["n_interior_samples"] > 0
    assert skipped.stats["n_interior_samples"] == 0
    assert len(_new_interior(mesh, skipped)) == 0
    # mixed: triangles with an R-point are still sampled
    delta = np.where(mesh.points[:, 0] < 0.5, 0.5, 2.0)
    mixed = evomesh.evolve(mesh, delta, quality=False, skip_coarse=True)
    check_evolved(mesh, mixed)
    plain = evomesh.evolve(mesh, delta, quality=False)
    assert 0 < mixed.stats["n_interior_samples"] < plain.stats["n_interior_samples"]


@pytest.mark.parametrize("samples", ["barycentre", "midpoints", "barycentre+midpoints"])
def test_deterministic_samples_are_barycentres_and_midpoints(samples):
    """With delta >= 1 (no ring candidates around R-points) every new point is a
    barycentre of an input triangle or a midpoint of an input edge."""
    mesh = grid_mesh(12, 12, jitter=0.25, seed=3)
    delta = np.full(mesh.n_points, 1.5)
    new = evomesh.evolve(mesh, delta, samples=samples, quality=False, gap_repair_ratio=None, refine_gap_ratio=None)
    check_evolved(mesh, new)
    p, t = mesh.points, mesh.triangles
    allowed = set()
    if "barycentre" in samples:
        allowed |= {tuple(x) for x in (p[t[:, 0]] + p[t[:, 1]] + p[t[:, 2]]) / 3.0}
    edges = np.unique(np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1), axis=0)
    # segments are always split at their midpoints in these modes
    segment_midpoints = {tuple(0.5 * (p[a] + p[b])) for a, b in mesh.segments}
    allowed |= segment_midpoints
    if "midpoints" in samples:
        allowed |= {tuple(0.5 * (p[a] + p[b])) for a, b in edges}
    fresh = new.points[new.origin < 0]
    assert len(fresh) > 0
    assert all(tuple(x) in allowed for x in fresh)


def test_cheap_radius_differs_and_keeps_the_spacing():
    mesh = grid_mesh(25, 25, jitter=0.2, seed=4)
    delta = np.where(mesh.points[:, 0] < 0.5, 0.4, 2.5)
    exact = evomesh.evolve(mesh, delta, seed=1)
    cheap = evomesh.evolve(mesh, delta, seed=1, radius="cheap")
    check_evolved(mesh, cheap)
    assert exact.points.tobytes() != cheap.points.tobytes()
    # (f(q) + |x - q|)/2 >= f(x)/2: larger spheres, so no more points than exact
    assert cheap.n_points <= exact.n_points * 1.05
    assert spacing_ratio(mesh, cheap, delta).max() < 2.5


@pytest.mark.parametrize("samples, skip_coarse, radius, quality", COMBINATIONS[::5])
def test_variations_are_deterministic(samples, skip_coarse, radius, quality):
    mesh = grid_mesh(12, 12, jitter=0.2, seed=5)
    delta = np.exp(np.random.default_rng(5).uniform(np.log(0.3), np.log(3.0), mesh.n_points))
    options = dict(samples=samples, skip_coarse=skip_coarse, radius=radius, quality=quality, seed=11)
    a = evomesh.evolve(mesh, delta, **options)
    b = evomesh.evolve(mesh, delta, threads=1, **options)
    for name in ("points", "triangles", "segments", "origin", "kind"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes()


def test_defaults_are_documented():
    assert FRFC_DEFAULTS["samples"] == "random"
    assert FRFC_DEFAULTS["skip_coarse"] is False
    assert FRFC_DEFAULTS["radius"] == "interpolated"
    assert FRFC_DEFAULTS["quality"] is True
    assert FRFC_DEFAULTS["min_angle"] == 30.0
    assert FRFC_DEFAULTS["demote_ratio"] == 1.1


@given(mesh_and_delta(), st.sampled_from(SAMPLES), st.sampled_from(["exact", "cheap", "interpolated"]),
       st.sampled_from([0.5, 1.0, 2.0]), st.integers(0, 3))
def test_sample_filter_changes_nothing_but_the_work(case, samples, radius, cell_factor, seed):
    """Dropping samples that certainly overlap a kept sphere (the Lipschitz bound) keeps the same spheres."""
    mesh, delta = case
    # (the full step: the incremental one does not draw samples it certainly rejects, test_incremental.py)
    opts = dict(samples=samples, radius=radius, cell_factor=cell_factor, seed=seed, quality=False, incremental=False)
    filtered = evomesh.evolve(mesh, delta, **opts)
    full = evomesh.evolve(mesh, delta, filter_samples=False, **opts)
    assert np.array_equal(filtered.points, full.points)
    assert np.array_equal(filtered.triangles, full.triangles)
    assert np.array_equal(filtered.origin, full.origin)
    assert filtered.stats["n_interior_samples_drawn"] == full.stats["n_interior_samples_drawn"]
    assert filtered.stats["n_interior_samples"] <= full.stats["n_interior_samples"]


def test_sample_filter_drops_most_samples_where_nothing_changes():
    mesh = grid_mesh(30, 30, jitter=0.2, seed=3)
    # (skip_settled=False: with it no sample is drawn at all where delta = 1)
    out = evomesh.evolve(mesh, np.ones(mesh.n_points), cell_factor=1.0, incremental=False, skip_settled=False)
    assert out.stats["n_interior_samples"] < 0.3 * out.stats["n_interior_samples_drawn"]
    out = evomesh.evolve(mesh, np.ones(mesh.n_points), cell_factor=2.0, incremental=False, skip_settled=False)
    assert out.stats["n_interior_samples"] < 0.5 * out.stats["n_interior_samples_drawn"]
    with pytest.raises(TypeError, match="filter_samples"):
        evomesh.evolve(mesh, np.ones(mesh.n_points), filter_samples=1)
