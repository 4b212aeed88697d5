"""Cost follows the change: the incremental step (cpp/src/incremental_step.cpp) returns
what the full algorithm returns, bit for bit, on every array of the new mesh
and its lineage; it is taken where delta = 1 on most of the mesh and declines
where it does not apply.

The path is chosen before the work from O(n) counts (stats["incremental_step"]
says which ran), the incremental step's peak memory is not above the full
step's, and a refused sample budget is the same error on both paths. (That a
failure inside the incremental step reaches the caller is checked in C++,
cpp/tests/test_incremental_failures.cpp, by injecting one.)"""

from __future__ import annotations

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import Delaunay

import evomesh
from evomesh.fronts import CircleFront
from strategies import grid_mesh, meshes

ARRAYS = ("points", "triangles", "segments", "segment_is_boundary", "kind", "origin", "segment_tags",
          "triangle_tags", "required")
LINEAGE = ("parent_triangle", "barycentric", "old_nn", "old_f")


def _check_same_step(mesh: evomesh.Mesh, delta: np.ndarray, seed: int = 1, **options) -> evomesh.Mesh:
    """Both paths on the same step; every returned array equal (stats excepted). Returns the incremental one."""
    full = evolve_quietly(mesh, delta, seed, incremental=False, **options)
    fast = evolve_quietly(mesh, delta, seed, incremental=True, **options)
    for name in ARRAYS:
        a, b = getattr(full, name), getattr(fast, name)
        assert (a is None) == (b is None), name
        if a is not None:
            assert a.dtype == b.dtype and np.array_equal(a, b), f"{name} differs"
    for name in LINEAGE:
        a, b = getattr(full.lineage, name), getattr(fast.lineage, name)
        assert np.array_equal(a, b), f"lineage.{name} differs"
    # the output's nn (within the domain), which the next step reads: the
    # incremental step takes it from what changed
    assert np.array_equal(full.nn_spacing, fast.nn_spacing), "nn_spacing differs"
    assert np.array_equal(full._nn_grew, fast._nn_grew), "nn grew at other points"
    assert "incremental_quiet_triangles" not in full.stats
    return fast


def evolve_quietly(mesh, delta, seed, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", evomesh.QualityWarning)
        return evomesh.evolve(mesh, delta, seed=seed, **options)


def _taken(result: evomesh.Mesh) -> bool:
    return "incremental_quiet_triangles" in result.stats


def _stepped_mesh(n: int, seed: int) -> evomesh.Mesh:
    """The output of a step (the typical input): unit_square_mesh evolved once."""
    base = evomesh.unit_square_mesh(n, seed=seed)
    return evomesh.evolve(base, np.ones(base.n_points), seed=seed)


def _front_delta(mesh: evomesh.Mesh, center, radius: float, width: float, amplitude: float) -> np.ndarray:
    """delta = 1 except within `width` of a circle: refines inside the band's inner half, coarsens outside."""
    d = CircleFront(center, radius).signed_distance(mesh.points)
    band = np.abs(d) < width
    return np.where(band, 1.0 - amplitude * np.sin(np.pi * d / width), 1.0)


# Random circular fronts on stepped meshes, and on raw meshes (strategies.meshes).
STEPPED_FRONTS = {
    "n": st.integers(300, 2500),
    "mesh_seed": st.integers(0, 3),
    "center": st.tuples(st.floats(0.1, 0.9), st.floats(0.1, 0.9)),
    "radius": st.floats(0.05, 0.5),
    "width": st.floats(0.02, 0.1),
    "amplitude": st.sampled_from([0.3, 0.5, 0.7]),
    "seed": st.integers(0, 2**16),
}
RAW_FRONTS = {
    "mesh": meshes(max_side=14),
    "center": st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0)),
    "radius": st.floats(0.1, 0.6),
    "width": st.floats(0.05, 0.2),
    "amplitude": st.sampled_from([0.4, 0.8]),
    "seed": st.integers(0, 2**16),
}


def _raw_front_delta(mesh: evomesh.Mesh, center, radius: float, width: float, amplitude: float) -> np.ndarray:
    """_front_delta in the mesh's bounding box scaled to the unit square."""
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    unit = (mesh.points - lo) / (hi - lo)
    d = np.hypot(unit[:, 0] - center[0], unit[:, 1] - center[1]) - radius
    return np.where(np.abs(d) < width, 1.0 - amplitude * np.sin(np.pi * d / width), 1.0)


@given(**STEPPED_FRONTS)
def test_random_fronts_on_stepped_meshes_match_the_full_step(n, mesh_seed, center, radius, width, amplitude, seed):
    mesh = _stepped_mesh(n, mesh_seed)
    delta = _front_delta(mesh, center, radius, width, amplitude)
    fast = _check_same_step(mesh, delta, seed)
    if np.count_nonzero(delta != 1) <= mesh.n_points // 2:
        assert _taken(fast)
        # Most of the mesh is certified untouched: the path did less than the full step.
        assert fast.stats["incremental_quiet_triangles"] > 0
        assert fast.stats["incremental_region_points"] < mesh.n_points
    else:
        assert not _taken(fast)


@given(**RAW_FRONTS)
def test_random_fronts_on_raw_meshes_match_the_full_step(mesh, center, radius, width, amplitude, seed):
    # Raw meshes (grids, holes, reflex corners, exact lattices, tiny and large scales): the
    # certificates decide, the output must not depend on the path.
    _check_same_step(mesh, _raw_front_delta(mesh, center, radius, width, amplitude), seed)


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"radius": "exact", "demote_ratio": None, "gap_repair_ratio": None},
        {"radius": "cheap"},
        {"samples": "barycentre", "cell_factor": 1.0},
        {"samples": "midpoints"},
        {"quality": False},
        {"repair_ratio": None, "gap_repair_ratio": None},
        {"within_domain": False},
        {"ring_samples": False},
        {"threads": 1},
        {"radius_scale": 1.0, "boundary_scale": 1.0},
        {"skip_coarse": True},
    ],
    ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()) or "defaults",
)
def test_options_match_the_full_step(options):
    mesh = _stepped_mesh(3000, 0)
    for center, radius in (((0.3, 0.4), 0.2), ((0.0, 0.0), 0.5), ((0.95, 0.5), 0.1)):
        fast = _check_same_step(mesh, _front_delta(mesh, center, radius, 0.06, 0.5), 3, **options)
        assert _taken(fast)


def _shape_mesh(shape: str, side: int) -> evomesh.Mesh:
    """A side x side grid of the unit square with a hole, a notch, or a crack along y = 0.5 (0.25 < x < 0.75)."""
    if shape != "crack":
        return grid_mesh(side, side, jitter=0.0, hole=shape == "hole", notch=shape == "notch")
    base = grid_mesh(side, side, jitter=0.0)
    p = np.asarray(base.points)
    on_line = np.flatnonzero(np.isclose(p[:, 1], 0.5) & (p[:, 0] > 0.25) & (p[:, 0] < 0.75))
    on_line = on_line[np.argsort(p[on_line, 0])]
    return evomesh.Mesh(p, base.triangles, np.c_[on_line[:-1], on_line[1:]])


@pytest.mark.parametrize("shape", ["hole", "notch", "crack"])
def test_holes_reflex_corners_and_interior_constraints(shape):
    mesh = _shape_mesh(shape, 25)
    for step in range(3):
        x = mesh.points[:, 0]
        band = np.abs(x - (0.2 + 0.25 * step)) < 0.08
        delta = np.where(band, 0.6, 1.0)
        fast = _check_same_step(mesh, delta, step)
        assert _taken(fast)
        mesh = fast


def test_tags_and_required_points_follow_both_paths():
    base = _stepped_mesh(1500, 1)
    centroid_x = base.points[base.triangles].mean(axis=1)[:, 0]
    boundary = base.segment_is_boundary
    seg_tags = np.where(boundary, np.arange(len(base.segments)) % 3 + 1, 7)
    required = np.zeros(base.n_points, bool)
    required[:: 97] = True
    mesh = evomesh.Mesh(base.points, base.triangles, base.segments, segment_tags=seg_tags,
                        triangle_tags=(centroid_x > 0.5).astype(np.int64) + 10, required=required)
    fast = _check_same_step(mesh, _front_delta(mesh, (0.5, 0.5), 0.3, 0.08, 0.6), 5)
    assert _taken(fast)


def test_a_time_loop_of_fronts_stays_on_the_full_path():
    # Steps of a moving front, each from the previous output: every step identical.
    mesh = _stepped_mesh(2000, 2)
    for step in range(4):
        delta = _front_delta(mesh, (0.5, 0.5), 0.15 + 0.08 * step, 0.05, 0.5)
        mesh = _check_same_step(mesh, delta, step)
        assert _taken(mesh)


def test_declines_where_it_does_not_apply():
    mesh = _stepped_mesh(800, 0)
    x = mesh.points[:, 0]
    # delta != 1 at most points: the full step.
    assert not _taken(_check_same_step(mesh, np.where(x < 0.9, 0.7, 1.0)))
    # delta = 1 everywhere: the empty-scope step before it (tests/test_stays_put.py);
    # at one point off 1: taken, and next to nothing is sampled.
    assert _check_same_step(mesh, np.ones(mesh.n_points)).stats["empty_scope"] == 1
    delta = np.ones(mesh.n_points)
    delta[0] = 0.99
    fast = _check_same_step(mesh, delta)
    assert _taken(fast)
    assert fast.stats["incremental_quiet_triangles"] > 0.9 * mesh.n_triangles
    # Switched off: never.
    off = evomesh.evolve(mesh, np.ones(mesh.n_points), seed=1, incremental=False)
    assert not _taken(off)


def test_curved_boundaries_take_the_full_path():
    from evomesh.meshgen import HOLE_TAG, OUTER_TAG, disc_with_hole_mesh

    mesh = disc_with_hole_mesh(0.08)
    circles = {OUTER_TAG: evomesh.Circle((0, 0), 1.0), HOLE_TAG: evomesh.Circle((0, 0), 0.35)}
    geometry = evomesh.BoundaryGeometry(circles)
    result = evomesh.evolve(mesh, np.ones(mesh.n_points), seed=0, geometry=geometry)
    assert not _taken(result)
    assert _taken(evomesh.evolve(mesh, np.ones(mesh.n_points), seed=0))


# The path chosen before the work ----------------------------------------------------------


def _centre_point(mesh: evomesh.Mesh) -> int:
    return int(np.argmin(np.hypot(mesh.points[:, 0] - 0.5, mesh.points[:, 1] - 0.5)))


def _graded_mesh() -> evomesh.Mesh:
    """A grid with three extra points 1e-6 apart in one cell: the triangles around them are
    strongly graded (their adaptive grids ask f itself, sampling.hpp asks_spacing)."""
    base = grid_mesh(30, 30, jitter=0.2, seed=0)
    c = np.array([[0.5 + 0.3 / 29, 0.5 + 0.3 / 29]])
    pts = np.vstack([base.points, c, c + [1e-6, 3e-7], c + [2e-7, 1e-6]])
    return evomesh.Mesh(pts, Delaunay(pts).simplices)


@pytest.mark.parametrize("value", [1e-6, 1e-3, 1e3, 1e6])
@pytest.mark.parametrize("where", ["centre", "boundary", "corner"])
def test_one_changed_point_takes_the_incremental_path_with_the_same_bits(value, where):
    mesh = _stepped_mesh(2000, 0)
    kind = np.asarray(mesh.kind)
    index = {"centre": _centre_point(mesh), "boundary": int(np.flatnonzero(kind == 1)[0]),
             "corner": int(np.flatnonzero(kind == 0)[0])}[where]
    delta = np.ones(mesh.n_points)
    delta[index] = value
    fast = _check_same_step(mesh, delta, 2)
    assert fast.stats["incremental_step"] == 1
    assert evomesh.evolve(mesh, delta, seed=2, incremental=False).stats["incremental_step"] == 0


@pytest.mark.parametrize("band", [None, 0.5, 2.0])
def test_strongly_graded_triangles_take_the_incremental_path_with_the_same_bits(band):
    # The grids of these triangles ask f at their blocks: the step once gave up
    # on them late (after the packing), or its sample estimate, lacking f, refused them.
    mesh = _graded_mesh()
    delta = np.ones(mesh.n_points)
    if band is not None:
        delta[np.abs(mesh.points[:, 0] - 0.3) < 0.1] = band
    fast = _check_same_step(mesh, delta, 4)
    assert fast.stats["incremental_step"] == 1


def _both_paths(mesh, delta, **options):
    """(result or the ValueError's message) of the full and of the default step."""
    out = []
    for incremental in (False, True):
        try:
            out.append(evolve_quietly(mesh, delta, 1, incremental=incremental, **options))
        except ValueError as error:
            out.append(str(error))
    return out


@pytest.mark.parametrize("case", ["one point", "band", "graded"])
def test_a_refused_sample_budget_is_the_same_error_on_both_paths(case):
    mesh = _graded_mesh() if case == "graded" else _stepped_mesh(2000, 0)
    delta = np.ones(mesh.n_points)
    if case == "one point":
        delta[_centre_point(mesh)] = 1e-6
    elif case == "band":
        delta = _front_delta(mesh, (0.5, 0.5), 0.2, 0.06, 0.5)
    # The default path here is the incremental one, so its own error is what the user sees.
    assert evolve_quietly(mesh, delta, 1).stats["incremental_step"] == 1
    refused = 0
    for max_samples in (10.0, 1e3, 1e4, 3e4):
        full, fast = _both_paths(mesh, delta, max_samples=max_samples)
        if isinstance(full, str):
            refused += 1
            assert fast == full and "max_samples" in full
        else:
            assert not isinstance(fast, str), fast
            assert np.array_equal(full.points, fast.points)
    assert refused >= 1


_PEAK_WORKER = """
import json, os, sys
import numpy as np
import evomesh
n, value, incremental = json.loads(sys.argv[1])
base = evomesh.unit_square_mesh(n, seed=0)
mesh = evomesh.evolve(base, np.ones(base.n_points), seed=0)
delta = np.ones(mesh.n_points)
delta[int(np.argmin(np.hypot(mesh.points[:, 0] - 0.5, mesh.points[:, 1] - 0.5)))] = value
os.environ["EVOMESH_STAGE_PROFILE"] = "1"
try:  # the peak from here on (the step resets it after every stage too)
    with open("/proc/self/clear_refs", "w") as refs:
        refs.write("5")
except OSError:
    pass
out = evomesh.evolve(mesh, delta, seed=1, incremental=incremental)
peaks = [v for k, v in out.stats.items() if k.startswith("memory_peak_mib_")]
print(json.dumps({"peak_mib": max(peaks) if peaks else None, "incremental_step": out.stats.get("incremental_step"),
                  "points": out.points.tolist()}))
"""


def test_one_point_at_tiny_delta_takes_no_more_memory_than_the_full_step():
    # One point at delta = 1e-6 on a 2,000-point mesh once took 1.6 GB by default
    # against 72 MB with incremental=False (the incremental attempt sized a sample grid
    # without f, gave up, and the full step ran). Each path in a fresh process; the peak
    # resident memory of the step from the core's own stats (EVOMESH_STAGE_PROFILE).
    runs = {}
    for incremental in (False, True):
        done = subprocess.run([sys.executable, "-c", _PEAK_WORKER, json.dumps([2000, 1e-6, incremental])],
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        runs[incremental] = json.loads(done.stdout.strip().splitlines()[-1])
    full, fast = runs[False], runs[True]
    assert fast["incremental_step"] == 1 and full["incremental_step"] == 0
    assert fast["points"] == full["points"]
    if full["peak_mib"] is None:
        pytest.skip("no memory statistics on this platform (EVOMESH_STAGE_PROFILE reads /proc)")
    # Resident memory is mostly the interpreter's here; 5 % is its noise, the old path was 20x.
    assert fast["peak_mib"] <= 1.05 * full["peak_mib"], (fast["peak_mib"], full["peak_mib"])


# Without the quality pass the incremental step updates the input's
# triangulation where it changed (cpp/src/triangulation_update.cpp) instead of
# building it whole, and certifies the result (every piece an edge, every other
# edge strictly Delaunay), or builds it whole: the same bits either way.

def _declined(result: evomesh.Mesh) -> int:
    return int(result.stats["triangulation_update_declined"])


@given(paper=st.booleans(), **STEPPED_FRONTS)
def test_without_the_quality_pass_the_updated_triangulation_is_the_full_steps(n, mesh_seed, center, radius, width,
                                                                                amplitude, seed, paper):
    options = {"options": evomesh.FrfcOptions.paper()} if paper else {"quality": False}
    mesh = _stepped_mesh(n, mesh_seed)
    delta = _front_delta(mesh, center, radius, width, amplitude)
    fast = _check_same_step(mesh, delta, seed, **options)
    if _taken(fast):
        # A step's output is a constrained Delaunay triangulation without ties: the
        # update is certified unless its cavity is too large to pay.
        assert _declined(fast) in (0, 3)
        if _declined(fast) == 0:
            assert fast.stats["triangulation_update_cavity_triangles"] <= 0.25 * mesh.n_triangles


@given(**RAW_FRONTS)
def test_without_the_quality_pass_raw_meshes_and_lattices_match_the_full_step(mesh, center, radius, width,
                                                                              amplitude, seed):
    # Exact lattices are full of cocircular ties: there the certificate fails and
    # the triangulation is built whole; holes and notches bound the cavity.
    _check_same_step(mesh, _raw_front_delta(mesh, center, radius, width, amplitude), seed, quality=False)


@pytest.mark.parametrize("shape", ["hole", "notch", "crack"])
def test_the_updated_triangulation_keeps_holes_reflex_corners_and_cracks(shape):
    base = _shape_mesh(shape, 31)
    # (a step with the quality pass takes the lattice's exact ties away)
    mesh = evolve_quietly(base, np.full(base.n_points, 0.8), 0)
    declined, checked = [], []
    for step in range(3):
        x = mesh.points[:, 0]
        delta = np.where(np.abs(x - (0.2 + 0.25 * step)) < 0.08, 0.6, 1.0)
        fast = _check_same_step(mesh, delta, step, quality=False)
        assert _taken(fast)
        declined.append(_declined(fast))
        checked.append(int(fast.stats["triangulation_update_checked_kept_edges"]))
        # an updated triangulation is certified, and the next step inherits that
        # for the edges it keeps (the same bits as the full step, checked above)
        assert fast._delaunay and fast.stats["triangulation_certified"] == 1
        mesh = fast
    assert declined == [0, 0, 0]
    # the first input was built whole (with the quality pass): its edges are checked once
    assert checked == [1, 0, 0]


def _flip_one_edge(mesh: evomesh.Mesh) -> evomesh.Mesh:
    """The mesh with one interior edge flipped: a valid triangulation that is not Delaunay."""
    tri = np.asarray(mesh.triangles).copy()
    p = mesh.points
    segments = {tuple(sorted(e)) for e in np.asarray(mesh.segments).tolist()}
    owner = {}
    for t, (a, b, c) in enumerate(tri.tolist()):
        for u, v, w in ((a, b, c), (b, c, a), (c, a, b)):
            owner[(u, v)] = (t, w)
    centre = np.argmin(np.hypot(p[:, 0] - 0.7, p[:, 1] - 0.7))
    for (u, v), (t, w) in sorted(owner.items(), key=lambda item: item[0][0] != centre):
        if (v, u) not in owner or tuple(sorted((u, v))) in segments:
            continue
        s, z = owner[(v, u)]

        def ccw(a, b, c):
            return (p[b, 0] - p[a, 0]) * (p[c, 1] - p[a, 1]) - (p[b, 1] - p[a, 1]) * (p[c, 0] - p[a, 0]) > 0

        if ccw(w, u, z) and ccw(z, v, w):  # the quad is convex: flip u-v to w-z
            tri[t] = (w, u, z)
            tri[s] = (z, v, w)
            return evomesh.Mesh(p, tri, mesh.segments)
    raise AssertionError("no edge to flip")


def test_an_input_that_is_not_delaunay_is_triangulated_whole():
    mesh = _flip_one_edge(_stepped_mesh(1500, 0))
    assert not mesh._delaunay  # a user's mesh is never taken as certified
    delta = _front_delta(mesh, (0.25, 0.25), 0.1, 0.05, 0.5)  # (the flipped edge is far from the change)
    fast = _check_same_step(mesh, delta, 2, quality=False)
    assert _taken(fast)
    assert _declined(fast) == 6
    assert not fast._delaunay  # built whole: not certified


def test_the_updated_triangulation_keeps_nn_within_a_thin_slot():
    # A slot 0.02 wide: points on its two walls are nearest across it, outside
    # the domain, so their nn within the domain grows (the shortest edge). The
    # band refines below the slot only: points above it keep their triangles
    # while their Euclidean nn shrinks. The output's nn within the domain (what
    # the next step reads) must be the full step's, where the update reuses the
    # input's for points whose triangles and nn did not change.
    from evomesh.meshgen import polygon_mesh

    loop = [(0, 0), (1, 0), (1, 0.49), (0.4, 0.49), (0.4, 0.51), (1, 0.51), (1, 1), (0, 1)]
    base = polygon_mesh([loop], 0.03)
    mesh = evolve_quietly(base, np.ones(base.n_points), 0, quality=False)
    assert len(mesh._nn_grew) > 0
    for step in range(3):
        x, y = mesh.points[:, 0], mesh.points[:, 1]
        delta = np.where((y < 0.49) & (y > 0.40) & (np.abs(x - (0.55 + 0.15 * step)) < 0.1), 0.5, 1.0)
        fast = _check_same_step(mesh, delta, step, quality=False)
        assert _taken(fast) and _declined(fast) == 0
        assert len(fast._nn_grew) > 0
        mesh = fast


@pytest.mark.parametrize("options", [{"options": evomesh.FrfcOptions.paper()},
                                     {"within_domain": False, "quality": False}], ids=["paper", "euclidean"])
def test_without_within_domain_nn_behind_a_thin_hole_matches_the_full_step(options):
    # A hole 0.01 thick in a mesh of spacing 0.03: points on its two long sides
    # are nearest across it. With the Euclidean nn of the paper the step still
    # gives its output nn within the domain (Mesh.nn_spacing: the shortest edge
    # there); the changed region, which reuses the input's nn for points whose
    # triangles and nn did not change, must not reuse it where the input's grew.
    from evomesh.meshgen import polygon_mesh

    outer = [(0, 0), (1, 0), (1, 1), (0, 1)]
    hole = [(0.3, 0.495), (0.3, 0.505), (0.7, 0.505), (0.7, 0.495)]
    mesh = polygon_mesh([outer, hole], 0.03)
    assert len(mesh._nn_grew) > 0
    rng = np.random.default_rng(3)
    for step in range(4):
        delta = _front_delta(mesh, rng.uniform(0.2, 0.8, 2), rng.uniform(0.1, 0.3), 0.08, 0.5)
        fast = _check_same_step(mesh, delta, step, **options)
        assert _taken(fast)
        assert len(fast._nn_grew) > 0
        # ... and both are the nn within the domain that a Mesh of these arrays has
        rebuilt = evomesh.Mesh(fast.points, fast.triangles, fast.segments)
        assert np.array_equal(rebuilt.nn_spacing, fast.nn_spacing)
        mesh = fast


LATTICE_OPTIONS = {"default": {}, "no-quality": {"quality": False}, "paper": {"options": evomesh.FrfcOptions.paper()}}


@given(seed=st.integers(0, 2**16), options=st.sampled_from(sorted(LATTICE_OPTIONS)))
def test_random_delta_on_an_exact_lattice_matches_the_full_step(seed, options):
    # A binary lattice (spacing 1/16) with random binary delta in a patch: weights
    # that tie exactly, cones that touch (sites hidden by tangent discs): the
    # changed region's cone scan (Cone_scan) must decide them as the full step's
    # Apollonius graph does. With the paper's radius f / 2 = nn / 2 every pair of
    # lattice neighbours touches: the packing's double test decides, and the
    # changed region's safe points (safe_old_points) must be decided alike.
    mesh = grid_mesh(17, 17)
    rng = np.random.default_rng(seed)
    patch = np.abs(mesh.points - rng.uniform(0.2, 0.8, 2)).max(axis=1) < 0.25
    delta = np.ones(mesh.n_points)
    delta[patch] = rng.choice([0.5, 1.5, 2.0, 3.0], int(patch.sum()))
    fast = _check_same_step(mesh, delta, seed, **LATTICE_OPTIONS[options])
    assert _taken(fast)
    full = evolve_quietly(mesh, delta, seed, incremental=False, **LATTICE_OPTIONS[options])
    # (the case this test is for: the full step's graph hides sites)
    assert full.stats["n_hidden_sites"] > 0


@pytest.mark.parametrize("mesh_seed", [0, 1, 2])
def test_with_the_papers_radius_most_old_points_are_certified_safe(mesh_seed):
    # The paper's spheres B(p, f / 2) at delta = 1 have radius nn / 2: nearest
    # neighbours touch, and the packing's double test decides whether they
    # conflict. The changed region finds those conflicts with the same test
    # (safe_old_points) and leaves every other old point out of its first pass.
    options = {"options": evomesh.FrfcOptions.paper()}
    mesh = _stepped_mesh(3000, mesh_seed)
    mesh = evolve_quietly(mesh, np.ones(mesh.n_points), 1, **options)
    fast = _check_same_step(mesh, _front_delta(mesh, (0.4, 0.5), 0.2, 0.05, 0.5), 3, **options)
    assert _taken(fast)
    # (without the exact test every old point was packed: at least n_points)
    assert fast.stats["incremental_packed_first"] < 0.6 * mesh.n_points
