"""Input validation at the Python boundary.

Every malformed input raises a clear TypeError or ValueError (never a crash, a
RuntimeError or a silently wrong result), and the caller's arrays are never
modified, whether the call succeeds or fails.
"""

from __future__ import annotations

import copy
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

import evomesh
from evomesh import PointKind
from evomesh.spacing_function import DELTA_MAX, DELTA_MIN
from invariants import check_evolved, check_valid_mesh, spacing_ratio
from strategies import grid_mesh

# The unit square as two triangles, and a 3x3 grid (an interior point 4).
SQUARE_POINTS = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
SQUARE_TRIANGLES = np.array([[0, 1, 2], [1, 3, 2]])
GRID_POINTS = np.array([[x, y] for y in (0.0, 0.5, 1.0) for x in (0.0, 0.5, 1.0)])
GRID_TRIANGLES = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [3, 4, 7], [3, 7, 6], [4, 5, 8], [4, 8, 7]])


def _snapshot(args: dict) -> dict:
    return {k: copy.deepcopy(v) for k, v in args.items()}


def _assert_unchanged(before: dict, after: dict) -> None:
    for key, old in before.items():
        new = after[key]
        if isinstance(old, np.ndarray):
            assert isinstance(new, np.ndarray) and new.dtype == old.dtype
            assert np.array_equal(new, old, equal_nan=new.dtype.kind == "f"), f"{key} was modified"
        else:
            assert type(new) is type(old)
            if isinstance(old, list):
                assert repr(new) == repr(old), f"{key} was modified"


# ---------------------------------------------------------------------------
# Mesh
# ---------------------------------------------------------------------------

P, T = SQUARE_POINTS, SQUARE_TRIANGLES


def _with(points=P, triangles=T, **extra):
    return {"points": points, "triangles": triangles, **extra}


def _row(array, row, value):
    out = np.array(array, dtype=float)
    out[row] = value
    return out


# (id, Mesh keyword arguments, exception, message pattern)
MESH_CASES = [
    # shapes and dtypes
    ("points-1d", _with(points=np.arange(4.0)), ValueError, r"shape \(n, 2\)"),
    ("points-3-columns", _with(points=np.zeros((4, 3))), ValueError, r"shape \(n, 2\)"),
    ("points-3d", _with(points=np.zeros((4, 2, 1))), ValueError, r"shape \(n, 2\)"),
    ("points-scalar", _with(points=1.0), ValueError, r"shape \(n, 2\)"),
    ("points-ragged", _with(points=[[0, 0], [1, 0], [0]]), ValueError, "ragged"),
    ("points-str", _with(points=np.array([["0", "0"], ["1", "0"], ["0", "1"]])), TypeError, "real numeric"),
    ("points-object", _with(points=np.array([[0, 0], [1, 0], [0, None]], dtype=object)), TypeError, "real numeric"),
    ("points-none", _with(points=None), TypeError, "real numeric"),
    ("points-complex", _with(points=P.astype(complex)), TypeError, "real numeric"),
    ("points-bool", _with(points=P.astype(bool)), TypeError, "real numeric"),
    ("points-structured", _with(points=np.zeros(4, dtype=[("x", "f8"), ("y", "f8")])), TypeError, "real numeric"),
    ("triangles-float", _with(triangles=T.astype(float)), TypeError, "integer"),
    ("triangles-bool", _with(triangles=T.astype(bool)), TypeError, "integer"),
    ("triangles-str", _with(triangles=T.astype(str)), TypeError, "integer"),
    ("triangles-none", _with(triangles=None), TypeError, "integer"),
    ("triangles-4-columns", _with(triangles=np.array([[0, 1, 2, 3]])), ValueError, r"shape \(k, 3\)"),
    ("triangles-1d", _with(triangles=np.array([0, 1, 2])), ValueError, r"shape \(k, 3\)"),
    ("triangles-ragged", _with(triangles=[[0, 1, 2], [1, 3]]), ValueError, "ragged"),
    ("segments-float", _with(segments=np.array([[0.0, 1.0]])), TypeError, "integer"),
    ("segments-3-columns", _with(segments=np.array([[0, 1, 2]])), ValueError, r"shape \(k, 2\)"),
    # NaN / inf / magnitude
    ("points-nan", _with(points=_row(P, 1, [np.nan, 0.0])), ValueError, "NaN or infinite"),
    ("points-inf", _with(points=_row(P, 2, [0.0, np.inf])), ValueError, "NaN or infinite"),
    ("points-minus-inf", _with(points=_row(P, 3, [-np.inf, 1.0])), ValueError, "NaN or infinite"),
    ("points-1e200", _with(points=P * 1e200), ValueError, "magnitude"),
    ("points-beyond-1e75", _with(points=P * 1.5e75), ValueError, "magnitude"),
    ("points-longdouble-overflow", _with(points=P.astype(np.longdouble) * np.longdouble(1e308) * 10), ValueError, "NaN or infinite|magnitude"),
    ("points-1e-300-apart", _with(points=P * 1e-300), ValueError, "underflow"),
    ("points-1e-76-apart", _with(points=P * 1e-76), ValueError, "underflow"),
    ("points-subnormal", _with(points=P * 5e-324), ValueError, "underflow|zero area|duplicates"),
    # indices
    ("index-too-large", _with(triangles=np.array([[0, 1, 4], [1, 3, 2]])), ValueError, "out of range"),
    ("index-negative", _with(triangles=np.array([[0, 1, -1], [1, 3, 2]])), ValueError, "out of range"),
    ("index-uint64-huge", _with(triangles=np.array([[0, 1, 2**63 + 5]], dtype=np.uint64)), ValueError, "out of range"),
    ("index-int8", _with(triangles=np.array([[0, 1, 2], [1, 3, 2]], dtype=np.int8)), None, None),  # fine: any integer dtype
    ("segment-index-out-of-range", _with(segments=np.array([[0, 9]])), ValueError, "out of range"),
    # empty / too small
    ("empty-points", _with(points=np.zeros((0, 2)), triangles=np.zeros((0, 3), int)), ValueError, "at least 3 points"),
    ("empty-lists", _with(points=[], triangles=[]), ValueError, r"shape \(n, 2\)"),
    ("no-triangles", _with(triangles=np.zeros((0, 3), int)), ValueError, "at least one triangle"),
    ("two-points", _with(points=P[:2], triangles=np.array([[0, 1, 1]])), ValueError, "at least 3 points"),
    # degenerate
    ("collinear-only", _with(points=[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]], triangles=[[0, 1, 2]]), ValueError, "zero area"),
    ("collinear-only-many", _with(points=np.c_[np.arange(6.0), 2 * np.arange(6.0)], triangles=[[0, 1, 2], [2, 3, 4], [3, 4, 5]]), ValueError, "zero area"),
    ("collinear-triangle", _with(points=np.r_[P, [[2.0, 0.0]]], triangles=[[0, 1, 2], [1, 3, 2], [0, 1, 4]]), ValueError, "zero area"),
    ("repeated-vertex", _with(triangles=np.array([[0, 1, 1], [1, 3, 2]])), ValueError, "repeats a vertex"),
    # not exactly collinear, but flat at floating-point precision (crashed CGAL's mesher)
    ("nearly-flat", _with(points=[[1.0000000000000001e-15, 5.0000000000000008e-15], [5.0000000000000008e-15, 9.0000000000000011e-15], [3.0000000000000006e-15, 7.0000000000000009e-15], [9.0000000000000011e-15, 9.0000000000000011e-15]], triangles=[[2, 1, 0], [3, 1, 2]]), ValueError, "degenerate"),
    ("nearly-flat-relative-1e-12", _with(points=np.r_[P[[0, 1, 3]], [[0.5, 1e-12]]], triangles=[[0, 3, 2], [3, 1, 2], [0, 1, 3]]), ValueError, "degenerate"),
    ("thin-but-fine-1e-8", _with(points=np.r_[P[[0, 1, 3]], [[0.5, 1e-8]]], triangles=[[0, 3, 2], [3, 1, 2], [0, 1, 3]]), None, None),
    # duplicates
    ("duplicate-triangle", _with(triangles=np.array([[0, 1, 2], [1, 3, 2], [2, 1, 0]])), ValueError, "more than once"),
    ("duplicate-point", _with(points=np.r_[P, [[1.0, 1.0]]], triangles=[[0, 1, 2], [1, 3, 2], [1, 4, 2]]), ValueError, "duplicates"),
    # overlapping / inverted / non-manifold
    ("overlapping-shared-edge", _with(triangles=np.array([[0, 1, 2], [1, 3, 2], [0, 1, 3]])), ValueError, "overlap"),
    ("overlapping-disjoint", _with(points=np.r_[P, [[0.1, 0.1], [0.4, 0.1], [0.1, 0.4]]], triangles=[[0, 1, 2], [1, 3, 2], [4, 5, 6]]), ValueError, "overlap|cross|not a planar"),
    ("triangle-over-point", _with(points=np.r_[P, [[0.2, 0.2], [3.0, 2.0]]], triangles=[[0, 1, 2], [1, 3, 2], [4, 3, 5]]), ValueError, "overlap|cross|planar"),
    ("tangled-inverted", _with(points=_row(GRID_POINTS, 4, [0.5, 1.3]), triangles=GRID_TRIANGLES), ValueError, "overlap|cross|planar"),
    ("hanging-point-on-edge", _with(points=[[0, 0], [2, 0], [0, 2], [1, 0], [1, -1]], triangles=[[0, 1, 2], [0, 4, 3], [3, 4, 1]]), ValueError, "cross|overlap|planar"),
    ("non-manifold-edge", _with(points=np.r_[P, [[2.0, 0.5]], [[-1.0, 0.5]]], triangles=[[0, 1, 2], [1, 3, 2], [1, 4, 2], [0, 5, 2]]), ValueError, "non-manifold|overlap"),
    ("non-manifold-fin", _with(points=np.r_[P, [[0.5, 0.5 + 1e-3]]], triangles=[[0, 1, 2], [1, 3, 2], [1, 2, 4]]), ValueError, "non-manifold|overlap|cross|planar"),
    # points in no triangle
    ("orphan-point", _with(points=np.r_[P, [[5.0, 5.0]]]), ValueError, "orphan"),
    ("orphan-point-inside", _with(points=np.r_[P, [[0.3, 0.3]]]), ValueError, "orphan"),
    # segments
    ("segment-not-an-edge", _with(segments=np.array([[0, 3]])), ValueError, "not an edge"),
    ("segment-self-loop", _with(segments=np.array([[1, 1]])), ValueError, "itself"),
    # kind / origin
    ("kind-out-of-range", _with(kind=[0, 0, 0, 7]), ValueError, "PointKind"),
    ("kind-negative", _with(kind=[0, 0, -1, 0]), ValueError, "PointKind"),
    ("kind-float", _with(kind=[0.0, 0.0, 0.0, 0.0]), TypeError, "integer"),
    ("kind-shape", _with(kind=[0, 0, 0]), ValueError, "shape"),
    ("kind-interior-on-boundary", _with(kind=[0, 0, 0, int(PointKind.ORIGINAL)]), ValueError, "corner/boundary"),
    ("origin-float", _with(origin=[0.0, 1.0, 2.0, 3.0]), TypeError, "integer"),
    ("origin-shape", _with(origin=[0, 1]), ValueError, "shape"),
    ("origin-below-minus-one", _with(origin=[0, 1, -2, 3]), ValueError, "origin"),
]


@pytest.mark.parametrize("kwargs, error, match", [c[1:] for c in MESH_CASES], ids=[c[0] for c in MESH_CASES])
def test_mesh_rejects_malformed_input(kwargs, error, match):
    before = _snapshot(kwargs)
    if error is None:
        check_valid_mesh(evomesh.Mesh(**kwargs))
    else:
        with pytest.raises(error, match=match) as info:
            evomesh.Mesh(**kwargs)
        assert "\n" not in str(info.value), "messages are one line"
    _assert_unchanged(before, kwargs)


@pytest.mark.parametrize(
    "points, triangles",
    [
        (P.astype(np.float32), T.astype(np.int32)),
        (P.astype(np.int64), T.astype(np.uint16)),
        (np.asfortranarray(P), np.asfortranarray(T)),
        (np.repeat(P, 2, axis=0)[::2], np.repeat(T, 3, axis=1)[:, ::3]),  # non-contiguous views
        (P.tolist(), T.tolist()),
        (P.astype(np.longdouble), T),
    ],
    ids=["float32-int32", "int-points-uint16", "fortran", "strided", "lists", "longdouble"],
)
def test_mesh_accepts_any_real_and_integer_layout(points, triangles):
    mesh = evomesh.Mesh(points, triangles)
    check_valid_mesh(mesh)
    assert mesh.points.dtype == np.float64 and mesh.triangles.dtype == np.int64
    assert np.array_equal(mesh.points, np.asarray(P, dtype=float))


def test_mesh_accepts_read_only_input_and_never_modifies_or_aliases_it():
    points = GRID_POINTS.copy()
    triangles = GRID_TRIANGLES[:, ::-1].copy()  # clockwise: Mesh re-orients its own copy
    points.flags.writeable = False
    triangles.flags.writeable = False
    mesh = evomesh.Mesh(points, triangles)
    assert np.array_equal(points, GRID_POINTS)
    assert np.array_equal(triangles, GRID_TRIANGLES[:, ::-1])
    assert not np.shares_memory(mesh.points, points)
    assert not np.shares_memory(mesh.triangles, triangles)
    # a writable input changed later does not change the mesh
    writable = GRID_POINTS.copy()
    mesh2 = evomesh.Mesh(writable, GRID_TRIANGLES)
    writable[:] = 0
    assert np.array_equal(mesh2.points, GRID_POINTS)


def test_mesh_is_immutable():
    mesh = evomesh.Mesh(P, T)
    with pytest.raises(AttributeError):
        mesh.points = P
    for name in ("points", "triangles", "segments", "segment_is_boundary", "kind", "origin"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(mesh, name)[...] = 0
    with pytest.raises(TypeError):
        mesh.stats["x"] = 1.0


@pytest.mark.parametrize("scale", [1e15, 1e-15, 2.0**-200, 5e72, 1e-72])
def test_huge_and_tiny_coordinates_are_valid_and_scale_invariant(scale):
    base = grid_mesh(9, 9, jitter=0.2, seed=3)
    delta = np.exp(np.random.default_rng(1).uniform(np.log(0.3), np.log(3.0), base.n_points))
    reference = evomesh.evolve(base, delta, seed=5)
    scaled = evomesh.Mesh(base.points * scale, base.triangles)
    new = evomesh.evolve(scaled, delta, seed=5)
    check_evolved(scaled, new)
    # the same mesh up to rounding: exact predicates and scale-free sampling,
    # but constructed points (samples, quality-pass circumcentres) round
    # differently at another scale, and a near-tie in the packing can flip
    assert abs(new.n_points - reference.n_points) <= max(2, 0.03 * reference.n_points)
    kept_new, kept_reference = set(new.origin[new.origin >= 0]), set(reference.origin[reference.origin >= 0])
    assert len(kept_new ^ kept_reference) <= max(2, 0.03 * len(kept_reference))
    if new.n_points == reference.n_points and np.array_equal(new.origin, reference.origin):
        assert np.allclose(new.points / scale, reference.points, rtol=0, atol=1e-9)
    assert new.area == pytest.approx(reference.area * scale**2, rel=1e-12)
    assert evomesh.quality(new).min_angle == pytest.approx(evomesh.quality(reference).min_angle, abs=5.0)


def test_coordinate_limits_are_inclusive_of_the_documented_range():
    check_valid_mesh(evomesh.Mesh(P * 1e75, T))
    check_valid_mesh(evomesh.Mesh(P * 1e-75, T))


def test_disconnected_and_pinched_meshes_are_valid():
    """Two components, and two triangles sharing only a vertex: valid input."""
    for points, triangles in [
        ([[0, 0], [1, 0], [0, 1], [5, 5], [6, 5], [5, 6]], [[0, 1, 2], [3, 4, 5]]),
        ([[0, 0], [1, 0], [1, 1], [2, 1], [2, 2]], [[0, 1, 2], [2, 3, 4]]),
    ]:
        mesh = evomesh.Mesh(np.asarray(points, float), triangles)
        for d in (0.3, 1.0, 3.0):
            check_evolved(mesh, evomesh.evolve(mesh, d))


# ---------------------------------------------------------------------------
# evolve
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def mesh():
    return evomesh.Mesh(GRID_POINTS, GRID_TRIANGLES)


N = len(GRID_POINTS)

# (id, delta, exception, message pattern)
DELTA_CASES = [
    ("nan", np.r_[np.ones(N - 1), np.nan], ValueError, "finite"),
    ("inf", np.r_[np.inf, np.ones(N - 1)], ValueError, "finite"),
    ("negative", np.r_[np.ones(N - 1), -1.0], ValueError, "> 0"),
    ("zero", 0.0, ValueError, "> 0"),
    ("negative-scalar", -2.0, ValueError, "> 0"),
    ("below-min", np.full(N, DELTA_MIN / 2), ValueError, r"must be in \["),
    ("above-max", np.full(N, DELTA_MAX * 2), ValueError, r"must be in \["),
    ("subnormal", 5e-324, ValueError, r"must be in \["),
    ("huge", 1e300, ValueError, r"must be in \["),
    ("too-short", np.ones(N - 1), ValueError, "one value per point"),
    ("too-long", np.ones(N + 1), ValueError, "one value per point"),
    ("column", np.ones((N, 1)), ValueError, "one value per point"),
    ("empty", np.ones(0), ValueError, "one value per point"),
    ("ragged", [[1.0], [1.0, 2.0]], ValueError, "ragged"),
    ("str", "1", TypeError, "real numeric"),
    ("none", None, TypeError, "real numeric"),
    ("bool", np.ones(N, bool), TypeError, "real numeric"),
    ("complex", np.ones(N, complex), TypeError, "real numeric"),
    ("object", np.array([1.0] * N, dtype=object), TypeError, "real numeric"),
]


@pytest.mark.parametrize("delta, error, match", [c[1:] for c in DELTA_CASES], ids=[c[0] for c in DELTA_CASES])
@pytest.mark.parametrize("function", ["evolve", "spacing"])
def test_bad_delta_is_rejected(mesh, function, delta, error, match):
    before = copy.deepcopy(delta)
    with pytest.raises(error, match=match) as info:
        getattr(evomesh, function)(mesh, delta)
    assert "\n" not in str(info.value)
    if isinstance(delta, np.ndarray):
        assert np.array_equal(delta, before, equal_nan=delta.dtype.kind == "f")


@pytest.mark.parametrize("delta", [0.01, DELTA_MAX, 1.0, np.float32(0.5), 2, np.full(N, 0.5, np.float32)])
def test_delta_in_range_is_accepted(mesh, delta):
    check_evolved(mesh, evomesh.evolve(mesh, delta))


def test_delta_min_grades_towards_every_point_in_one_step(mesh):
    """The documented lower bound everywhere: f = 1e-6 nn_M at the points and
    1-Lipschitz, so one step grades geometrically towards every point (about
    log(1e6) rings each). The sampler sizes its cells by f itself inside the
    triangles and segments far larger than f at their ends; sized by the
    vertices' bound alone it drew fine cells over all of them (1.1e7 candidates
    for these 9 points, refused by max_samples before that, 2026-12-01)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", evomesh.QualityWarning)  # the quality pass reaches its bound
        new = evomesh.evolve(mesh, DELTA_MIN)
    check_evolved(mesh, new)
    ratio = spacing_ratio(mesh, new, np.full(N, DELTA_MIN))
    assert 0.9 < ratio.min() and ratio.max() < 1.1  # measured 1.000 - 1.033
    assert new.stats["n_candidates"] < 1e5  # measured 4052
    with pytest.raises(ValueError, match="max_samples"):
        evomesh.evolve(mesh, DELTA_MIN, max_samples=1000)
    with pytest.raises(ValueError, match="too much refinement"):
        evomesh.evolve(mesh, 0.05, max_samples=100)


def test_evolve_never_modifies_its_input(mesh):
    delta = np.linspace(0.3, 3.0, N)
    frozen = {name: getattr(mesh, name).copy() for name in ("points", "triangles", "segments", "kind", "origin")}
    delta_before = delta.copy()
    delta.flags.writeable = False
    new = evomesh.evolve(mesh, delta)
    check_evolved(mesh, new)
    assert np.array_equal(delta, delta_before)
    for name, value in frozen.items():
        assert np.array_equal(getattr(mesh, name), value)


OPTION_CASES = [
    ({"method": "drfc-typo"}, ValueError, "method"),
    ({"method": None}, ValueError, "method"),
    ({"seed": -1}, ValueError, "seed"),
    ({"seed": 2**64}, ValueError, "seed"),
    ({"seed": 1.5}, TypeError, "seed"),
    ({"seed": True}, TypeError, "seed"),
    ({"seed": "1"}, TypeError, "seed"),
    ({"no_such_option": 1}, TypeError, "unknown option"),
    ({"cell_factor": 0.0}, ValueError, "cell_factor"),
    ({"cell_factor": np.nan}, ValueError, "cell_factor"),
    ({"cell_factor": "1"}, TypeError, "cell_factor"),
    ({"radius_scale": 1.5}, ValueError, "radius_scale"),
    ({"radius_scale": -0.5}, ValueError, "radius_scale"),
    ({"max_samples": np.inf}, ValueError, "max_samples"),
    ({"max_samples": -1}, ValueError, "max_samples"),
    ({"samples": "everywhere"}, ValueError, "samples"),
    ({"radius": "approximate"}, ValueError, "radius"),
    ({"skip_coarse": "yes"}, TypeError, "skip_coarse"),
    ({"threads": 0}, ValueError, "threads"),
    ({"threads": -3}, ValueError, "threads"),
    ({"threads": 2.0}, ValueError, "threads"),
    ({"threads": 2**40}, ValueError, "threads"),
]


@pytest.mark.parametrize("options, error, match", OPTION_CASES, ids=[str(c[0]) for c in OPTION_CASES])
def test_bad_options_are_rejected(mesh, options, error, match):
    with pytest.raises(error, match=match) as info:
        evomesh.evolve(mesh, 1.0, **options)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("not_a_mesh", [None, (P, T), P, "mesh.msh"])
@pytest.mark.parametrize("function", ["evolve", "spacing", "nn_spacing", "quality"])
def test_functions_require_a_mesh(function, not_a_mesh):
    args = (not_a_mesh,) if function in ("nn_spacing", "quality") else (not_a_mesh, 1.0)
    with pytest.raises(TypeError, match="Mesh"):
        getattr(evomesh, function)(*args)


# ---------------------------------------------------------------------------
# spacing functions
# ---------------------------------------------------------------------------

QUERY_CASES = [
    ([np.nan, 0.5], ValueError, "NaN or infinite"),
    ([[0.5, 0.5], [np.inf, 0.0]], ValueError, "NaN or infinite"),
    ([[1e76, 0.0]], ValueError, "magnitude"),
    ([[1.0, 2.0, 3.0]], ValueError, "shape"),
    (np.zeros((2, 2, 2)), ValueError, "shape"),
    (0.5, ValueError, "shape"),
    ("ab", TypeError, "real numeric"),
    ([[0.5, None]], TypeError, "real numeric"),
    ([[0.5, 0.5], [0.5]], ValueError, "ragged"),
]


@pytest.mark.parametrize("x, error, match", QUERY_CASES, ids=[f"query{i}" for i in range(len(QUERY_CASES))])
def test_spacing_function_rejects_bad_queries(mesh, x, error, match):
    f = evomesh.spacing(mesh, 0.5)
    with pytest.raises(error, match=match):
        f(x)
    with pytest.raises(error, match=match):
        f.nearest_site(x)


def test_spacing_function_queries_of_any_layout(mesh):
    f = evomesh.spacing(mesh, 0.5)
    x = np.array([[0.25, 0.25], [0.75, 0.5]])
    expected = f(x)
    assert f(x.astype(np.float32)).shape == (2,)
    assert np.array_equal(f(x.tolist()), expected)
    assert np.array_equal(f(np.asfortranarray(x)), expected)
    assert f(x[0]) == expected[0]
    assert f(np.zeros((0, 2))).shape == (0,)


SITE_CASES = [
    ({"sites": [[0, 0], [np.nan, 1]], "weights": [1, 1]}, ValueError, "NaN or infinite"),
    ({"sites": [[0, 0], [1e76, 1]], "weights": [1, 1]}, ValueError, "magnitude"),
    ({"sites": np.zeros((0, 2)), "weights": np.zeros(0)}, ValueError, "at least one site"),
    ({"sites": [[0, 0, 0]], "weights": [1]}, ValueError, "shape"),
    ({"sites": [[0, 0], [1, 1]], "weights": [1]}, ValueError, "shape"),
    ({"sites": [[0, 0], [1, 1]], "weights": [[1], [1]]}, ValueError, "shape"),
    ({"sites": [[0, 0], [1, 1]], "weights": [1, np.nan]}, ValueError, "finite"),
    ({"sites": [[0, 0], [1, 1]], "weights": [1, -1]}, ValueError, ">= 0"),
    ({"sites": [[0, 0], [1, 1]], "weights": ["a", "b"]}, TypeError, "real numeric"),
    ({"sites": "sites", "weights": [1]}, TypeError, "real numeric"),
]


@pytest.mark.parametrize("kwargs, error, match", SITE_CASES, ids=[f"sites{i}" for i in range(len(SITE_CASES))])
def test_spacing_function_constructor_validates(kwargs, error, match):
    before = _snapshot(kwargs)
    with pytest.raises(error, match=match):
        evomesh.SpacingFunction(**kwargs)
    _assert_unchanged(before, kwargs)


def test_spacing_function_constructor_copies_its_input():
    sites = np.array([[0.0, 0.0], [1.0, 0.0]])
    weights = np.array([0.5, 0.25])
    f = evomesh.SpacingFunction(sites, weights)
    sites[:] = 7.0
    weights[:] = 9.0
    assert f(np.array([0.0, 0.0])) == pytest.approx(0.5)


# ---------------------------------------------------------------------------
# fronts: their constructors and distance queries
# ---------------------------------------------------------------------------

fronts = pytest.importorskip("evomesh.fronts")

FRONT_CASES = [
    ("circle-center-nan", lambda: fronts.CircleFront([np.nan, 0.0], 1.0), ValueError),
    ("circle-center-shape", lambda: fronts.CircleFront([0.0, 0.0, 0.0], 1.0), ValueError),
    ("circle-center-str", lambda: fronts.CircleFront("ab", 1.0), TypeError),
    ("circle-radius-negative", lambda: fronts.CircleFront([0.0, 0.0], -1.0), ValueError),
    ("circle-radius-nan", lambda: fronts.CircleFront([0.0, 0.0], np.nan), ValueError),
    ("circle-radius-str", lambda: fronts.CircleFront([0.0, 0.0], "1"), TypeError),
    ("circle-radius-of-t-nan", lambda: fronts.CircleFront([0.0, 0.0], lambda t: np.nan).distance([[0.0, 0.0]], 1.0), ValueError),
    ("circle-t-nan", lambda: fronts.CircleFront([0.0, 0.0], lambda t: t).distance([[0.0, 0.0]], np.nan), ValueError),
    ("circle-query-nan", lambda: fronts.CircleFront([0.0, 0.0], 1.0).distance([[np.nan, 0.0]]), ValueError),
    ("circle-query-shape", lambda: fronts.CircleFront([0.0, 0.0], 1.0).distance([0.0, 0.0, 0.0]), ValueError),
    ("points-too-few", lambda: fronts.PointFront([[0.0, 0.0], [1.0, 0.0]]), ValueError),
    ("points-coincide", lambda: fronts.PointFront([[0.0, 0.0]] * 3), ValueError),
    ("points-nan", lambda: fronts.PointFront([[0.0, 0.0], [np.nan, 0.0], [1.0, 1.0]]), ValueError),
    ("points-spacing-zero", lambda: fronts.PointFront([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], spacing=0.0), ValueError),
    ("points-spacing-inf", lambda: fronts.PointFront([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], spacing=np.inf), ValueError),
    ("points-closed-str", lambda: fronts.PointFront([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], closed="yes"), TypeError),
    ("points-spacing-tiny", lambda: fronts.PointFront([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], spacing=1e-8), ValueError),
    ("points-spacing-subnormal", lambda: fronts.PointFront([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], spacing=5e-324),
     ValueError),
    ("levelset-not-callable", lambda: fronts.LevelSetFront(3), TypeError),
    ("levelset-returns-str", lambda: fronts.LevelSetFront(lambda x, t: "a").distance([[0.0, 0.0]]), TypeError),
    ("levelset-returns-shape", lambda: fronts.LevelSetFront(lambda x, t: x).distance([[0.0, 0.0]]), ValueError),
    ("levelset-returns-nan", lambda: fronts.LevelSetFront(lambda x, t: x[:, 0] * np.nan).distance([[0.0, 0.0]]), ValueError),
    ("law-h-min-zero", lambda: fronts.SpacingLaw(0.0, 1.0, 0.1), ValueError),
    ("law-h-min-above-h-max", lambda: fronts.SpacingLaw(2.0, 1.0, 0.1), ValueError),
    ("law-nan", lambda: fronts.SpacingLaw(np.nan, 1.0, 0.1), ValueError),
    ("law-band-negative", lambda: fronts.SpacingLaw(0.1, 1.0, -0.1), ValueError),
    ("law-lower-zero", lambda: fronts.SpacingLaw(0.1, 1.0, 0.1, lower=0.0), ValueError),
    ("law-upper-below-one", lambda: fronts.SpacingLaw(0.1, 1.0, 0.1, upper=0.5), ValueError),
]


@pytest.mark.parametrize("call, error", [c[1:] for c in FRONT_CASES], ids=[c[0] for c in FRONT_CASES])
def test_fronts_reject_malformed_input(call, error):
    with pytest.raises(error):
        call()


@pytest.mark.parametrize(
    "distance, error",
    [(-1.0, ValueError), (np.nan, ValueError), ("far", TypeError)],
    ids=["negative", "nan", "str"],
)
def test_spacing_law_rejects_bad_distances(mesh, distance, error):
    law = fronts.SpacingLaw(0.1, 1.0, 0.1)
    d = np.full(mesh.n_points, distance)
    with pytest.raises(error):
        law.delta(mesh, d)
    with pytest.raises(ValueError, match="one value per mesh point"):
        law.delta(mesh, np.ones(3))


# ---------------------------------------------------------------------------
# mesh files (evomesh.io) and the command line
# ---------------------------------------------------------------------------

io = pytest.importorskip("evomesh.io")
meshio = pytest.importorskip("meshio")

def test_mesh_file_round_trip_never_modifies_the_mesh(tmp_path):
    mesh = grid_mesh(6, 6, hole=True)
    path = io.write_mesh(tmp_path / "m.vtu", mesh)
    again, _ = io.read_mesh(path)
    check_valid_mesh(again)
    assert np.array_equal(again.points, mesh.points) and np.array_equal(again.triangles, mesh.triangles)
    assert np.array_equal(again.kind, mesh.kind)


def test_missing_mesh_file_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        io.read_mesh(tmp_path / "missing.vtu")


@pytest.mark.parametrize(
    "name, content",
    [("garbage.vtu", b"garbage\x00\x01\x02"), ("truncated.vtu", b'<?xml version="1.0"?><VTKFile type="Unstr'),
     ("empty.vtu", b""), ("mesh.unknown-suffix", b"0 0\n1 0\n0 1\n")],
    ids=["garbage", "truncated", "empty", "unknown-format"],
)
def test_corrupt_mesh_file_raises_value_error(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ValueError):
        io.read_mesh(path)


def test_mesh_file_with_a_malformed_mesh_raises_value_error(tmp_path):
    """A well-formed file holding an invalid mesh goes through Mesh's checks."""
    points = np.c_[SQUARE_POINTS, np.zeros(4)]
    path = tmp_path / "bad.vtu"
    meshio.Mesh(points, [("triangle", np.array([[0, 1, 2], [1, 3, 2], [0, 1, 3]]))]).write(path)  # overlapping
    with pytest.raises(ValueError):
        io.read_mesh(path)


def test_mesh_file_with_an_orphan_point_is_read_without_it(tmp_path):
    path = tmp_path / "orphan.vtu"
    points = np.c_[SQUARE_POINTS, np.zeros(4)]
    meshio.Mesh(points, [("triangle", np.array([[0, 1, 2]]))], point_data={"u": np.arange(4.0)}).write(path)
    with pytest.warns(UserWarning, match="removed 1 points used by no triangle"):
        mesh, data = io.read_mesh(path)
    assert mesh.n_points == 3 and np.array_equal(data["u"], [0.0, 1.0, 2.0])


def test_cli_errors_are_one_line_and_exit_non_zero(tmp_path, capsys):
    cli = pytest.importorskip("evomesh.cli")
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    base = ["growing-circle", "--steps", "1", "--points", "120", "--no-figures", "--quiet"]
    for extra in (["--out", str(blocker)], ["--out", str(tmp_path / "o"), "--h-max", "nan"],
                  ["--out", str(tmp_path / "o"), "--h-min", "inf"], ["--out", str(tmp_path / "o"), "--method", "x"]):
        assert cli.main(base + extra) != 0
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("evomesh: error:"), lines


def test_unbounded_sizes_are_refused_at_once(capsys):
    """Sizes that could only exhaust memory or time are refused before any work."""
    from evomesh.meshgen import MAX_POINTS, unit_square_mesh

    cli = pytest.importorskip("evomesh.cli")
    with pytest.raises(ValueError, match="at most"):
        unit_square_mesh(MAX_POINTS + 1)
    with pytest.raises(ValueError, match="at most"):
        unit_square_mesh(10**11)
    assert cli.main(["growing-circle", "--points", "100000000000", "--no-figures", "--quiet"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "at most" in lines[0], lines
    with pytest.raises(ValueError, match="points on a front"):
        fronts.PointFront([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]).resampled(1e-9)


def test_point_front_rejects_coordinates_beyond_the_mesh_limit():
    with pytest.raises(ValueError):
        fronts.PointFront([[0.0, 0.0], [1e300, 0.0], [1.0, 1e300]]).distance([[1.0, 1.0]])


# ---------------------------------------------------------------------------
# the compiled core's own checks (callers that bypass Mesh)
# ---------------------------------------------------------------------------

_CORE_CHECKS = textwrap.dedent(
    """
    import numpy as np
    from evomesh import _core
    points = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    bad = np.array([[0, 1, 9], [1, 3, 2]])
    calls = {
        "prepare_mesh index": lambda: _core.prepare_mesh(points, bad),
        "prepare_mesh negative": lambda: _core.prepare_mesh(points, -bad),
        "prepare_mesh segment": lambda: _core.prepare_mesh(points, bad[1:], np.array([[0, 7]])),
        "prepare_mesh nan": lambda: _core.prepare_mesh(np.where(points == 1, np.nan, points), bad[1:]),
        "locate_points index": lambda: _core.locate_points(points, bad, points),
        "locate_points nan query": lambda: _core.locate_points(points, bad[1:], np.full((1, 2), np.nan)),
        "nn_spacing inf": lambda: _core.nn_spacing(np.where(points == 1, np.inf, points)),
        "spacing nan site": lambda: _core.SpacingFunction(np.where(points == 1, np.nan, points), np.ones(4)),
        "spacing nan query": lambda: _core.SpacingFunction(points, np.ones(4)).evaluate(np.full((3, 2), np.nan)),
    }
    for name, call in calls.items():
        try:
            call()
        except ValueError:
            print("ValueError", name)
        else:
            print("accepted", name)
    """
)


def test_core_bindings_reject_bad_indices_and_non_finite_coordinates():
    """cpp/bindings/module.cpp checks index ranges and finiteness itself (run in
    a child process: before the check, an out-of-range index read out of bounds)."""
    done = subprocess.run([sys.executable, "-c", _CORE_CHECKS], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    lines = done.stdout.strip().splitlines()
    assert len(lines) == 9 and all(line.startswith("ValueError") for line in lines), lines


def test_refused_step_reports_a_sane_sample_count():
    """Run in a child process: under tools/sanitize.sh the undefined behaviour aborts."""
    code = textwrap.dedent(
        """
        import evomesh, numpy as np
        mesh = evomesh.Mesh(np.array({points!r}), {triangles!r})
        try:
            evomesh.evolve(mesh, 1.0, cell_factor=1e-300)
        except ValueError as error:
            print(error)
        """
    ).format(points=GRID_POINTS.tolist(), triangles=GRID_TRIANGLES.tolist())
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "too much refinement" in done.stdout
    assert "-" not in done.stdout.split("about")[1].split("points")[0]


@pytest.mark.parametrize("first", [0, 32767, 32768, 70001, 99999])
def test_triangle_limit_checks_find_the_first_hit_over_parallel_blocks(first):
    # _core.first_inverted_triangle / first_flat_triangles scan the caller's arrays
    # in parallel blocks of 2^15 triangles: the first hit over all blocks, as numpy
    # finds it (check_mesh_limits and Mesh() raise on that index).
    from evomesh import _core
    from evomesh.mesh import _MIN_HEIGHT_ULPS, _MIN_RELATIVE_HEIGHT, _flatness

    rng = np.random.default_rng(first)
    m = 150_000
    points = rng.random((3 * m, 2))
    triangles = np.arange(3 * m).reshape(m, 3)
    d1, d2 = points[triangles[:, 1]] - points[triangles[:, 0]], points[triangles[:, 2]] - points[triangles[:, 0]]
    area = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    triangles[area < 0] = triangles[area < 0][:, ::-1]  # every triangle counter-clockwise
    height, longest, _ = _flatness(points, triangles)
    keep = height >= 1e-3 * longest
    triangles = triangles[keep][: first + 30_000]
    assert len(triangles) > first
    flipped = triangles.copy()
    later = rng.choice(np.arange(first, len(triangles)), size=5)
    flipped[np.concatenate([[first], later])] = flipped[np.concatenate([[first], later])][:, ::-1]
    assert _core.first_inverted_triangle(points, triangles) == -1
    assert _core.first_inverted_triangle(points, flipped) == first
    flat = triangles.copy()
    flat[first, 2] = flat[first, 0]  # zero height (a repeated vertex): thin and coarse
    a = _core.first_flat_triangles(points, flat, _MIN_RELATIVE_HEIGHT, _MIN_HEIGHT_ULPS)
    assert tuple(a) == (first, first)
    assert tuple(_core.first_flat_triangles(points, triangles, _MIN_RELATIVE_HEIGHT, _MIN_HEIGHT_ULPS)) == (-1, -1)


@pytest.mark.parametrize("bad", [3, -1, 2**40])
def test_triangle_limit_checks_refuse_indices_out_of_range(bad):
    from evomesh import _core

    points = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    triangles = np.array([[0, 1, 2]] * 40_000 + [[0, 1, bad]])
    with pytest.raises(ValueError, match="out of range"):
        _core.first_inverted_triangle(points, triangles)
    with pytest.raises(ValueError, match="out of range"):
        _core.first_flat_triangles(points, triangles, 1e-10, 1024)
