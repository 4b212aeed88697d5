"""Mesh()'s planarity check: the boundary-winding check accepts and
refuses exactly what the reference check (a constrained Delaunay triangulation of
every edge, ``check_planar_mesh_cdt``) does, and the C++ flatness limits are
numpy's.

Both checks run after the same orientation and edge checks
(``_core.prepare_mesh``), so inputs that fail those fail both alike; the
comparison is about what is left: overlapping, nested, touching or
double-covering triangles, crossing boundaries, points on edges, duplicates.
Small integer coordinates make the degenerate cases (a point exactly on an
edge, collinear overlapping edges, coincident points) frequent.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.spatial import Delaunay

import evomesh
from evomesh import _core
from evomesh.mesh import _MIN_HEIGHT_ULPS, _MIN_RELATIVE_HEIGHT, _flatness


def _outcome(points: np.ndarray, triangles: np.ndarray, reference: bool) -> str:
    try:
        _core.prepare_mesh(points, triangles, None, True, None, None, reference)
    except ValueError as error:
        return f"refused ({error})"
    return "accepted"


def _same_outcome(points, triangles) -> str:
    """Both checks' verdict (asserting they agree), for meshes without orphans."""
    new = _outcome(points, triangles, False)
    old = _outcome(points, triangles, True)
    assert new.startswith("accepted") == old.startswith("accepted"), f"new: {new}; reference: {old}"
    return new


def _without_orphans(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used = np.unique(triangles)
    remap = -np.ones(len(points), np.int64)
    remap[used] = np.arange(len(used))
    return points[used], remap[triangles]


def _delaunay(points: np.ndarray) -> np.ndarray:
    try:
        return Delaunay(points).simplices.astype(np.int64)
    except Exception:  # all collinear
        return np.zeros((0, 3), np.int64)


@st.composite
def triangle_soups(draw):
    """Subsets of the Delaunay triangulations of up to three small integer point
    sets (their points kept apart as separate indices even where they coincide),
    plus random triangles, mirrored or moved points: overlaps, nested pieces,
    touching corners, points on edges, duplicates, flipped triangles."""
    side = draw(st.integers(2, 7))
    coordinate = st.tuples(st.integers(0, side), st.integers(0, side))
    points, triangles = [], []
    for _ in range(draw(st.integers(1, 3))):
        cloud = np.array(draw(st.lists(coordinate, min_size=3, max_size=12, unique=True)), float)
        if points:  # a further piece, scaled and shifted on a grid of quarters: it may coincide, touch or nest
            cloud = cloud * draw(st.sampled_from([1.0, 0.5, 0.25, 2.0])) + np.array(
                draw(st.tuples(*[st.sampled_from([0.0, 0.25, 0.5, 1.0, 1.25]) for _ in range(2)])))
        tris = _delaunay(cloud)
        if len(tris) == 0:
            continue
        keep = np.array(draw(st.lists(st.booleans(), min_size=len(tris), max_size=len(tris))))
        if not keep.any():
            keep[draw(st.integers(0, len(tris) - 1))] = True
        triangles.append(tris[keep] + sum(len(p) for p in points))
        points.append(cloud)
    assume(points)
    pts = np.concatenate(points)
    tris = np.concatenate(triangles)
    n = len(pts)
    for _ in range(draw(st.integers(0, 2))):  # random extra triangles over the same points
        a, b, c = (draw(st.integers(0, n - 1)) for _ in range(3))
        if len({a, b, c}) == 3:
            tris = np.r_[tris, [[a, b, c]]]
    for _ in range(draw(st.integers(0, 2))):  # a point moved to a grid point (maybe onto another)
        pts[draw(st.integers(0, n - 1))] = draw(coordinate)
    if draw(st.booleans()):  # a point merged into another: same coordinates, two indices
        pts[draw(st.integers(0, n - 1))] = pts[draw(st.integers(0, n - 1))]
    return _without_orphans(pts, tris)


@settings(max_examples=400)
@given(triangle_soups())
def test_boundary_winding_check_decides_like_the_cdt_check(soup):
    points, triangles = soup
    _same_outcome(points, triangles)


@settings(max_examples=60)
@given(st.integers(3, 9), st.integers(0, 2**16), st.sampled_from(["copy", "overlap", "nested", "apart", "flip"]))
def test_two_pieces_of_a_valid_mesh(n_side, seed, how):
    """A jittered grid and a copy of part of it (moved, scaled or mirrored):
    refused exactly when the copy overlaps; one point moved across an edge
    (a flipped triangle, oriented again by Mesh) is refused."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 1, n_side), np.linspace(0, 1, n_side))
    pts = np.c_[x.ravel(), y.ravel()]
    inner = (pts > 0).all(axis=1) & (pts < 1).all(axis=1)
    pts[inner] += rng.uniform(-0.2, 0.2, (int(inner.sum()), 2)) / (n_side - 1)
    tris = Delaunay(pts).simplices.astype(np.int64)
    if how == "flip":
        inner_points = np.flatnonzero(inner)
        assume(len(inner_points))
        v = int(rng.choice(inner_points))
        star = tris[(tris == v).any(axis=1)]
        u = int(rng.choice(star[star != v]))
        moved = pts.copy()
        moved[v] = pts[u] + rng.uniform(0.05, 1.5) * (pts[u] - pts[v])
        verdict = _same_outcome(moved, tris)
        assert not verdict.startswith("accepted")
        return
    part = tris[rng.random(len(tris)) < 0.5]
    assume(len(part))
    piece_points, piece = _without_orphans(pts, part)
    shift = {"copy": 0.0, "overlap": 0.3, "nested": 0.0, "apart": 1.5}[how]
    scale = 0.3 if how == "nested" else 1.0
    piece_points = piece_points * scale + shift + (0.35 if how == "nested" else 0.0)
    all_points = np.r_[pts, piece_points]
    all_triangles = np.r_[tris, piece + len(pts)]
    verdict = _same_outcome(all_points, all_triangles)
    assert verdict.startswith("accepted") == (how == "apart")


def _double_cover_annulus(k: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed strip of 2k quads going twice around the origin (angles of odd
    multiples of pi / (2k), so no two points coincide), radii varying so the two
    turns differ: every triangle positive, every interior edge shared the right
    way, every vertex locally fine, yet the plane is covered twice."""
    m = 2 * k
    angle = 4 * np.pi * (np.arange(m) + 0.5) / m
    wobble = 0.2 * np.sin(angle / 2)
    inner = np.c_[np.cos(angle), np.sin(angle)] * (1.0 + wobble)[:, None]
    outer = np.c_[np.cos(angle), np.sin(angle)] * (2.0 + wobble)[:, None]
    points = np.r_[inner, outer]
    i = np.arange(m)
    j = (i + 1) % m
    triangles = np.r_[np.c_[i, j, m + j], np.c_[i, m + j, m + i]]
    return points, triangles


def _square_ring(lo: float, hi: float, hole_lo: float, hole_hi: float) -> tuple[np.ndarray, np.ndarray]:
    """The square [lo, hi]^2 without [hole_lo, hole_hi]^2: 8 points, 8 triangles."""
    outer = np.array([[lo, lo], [hi, lo], [hi, hi], [lo, hi]])
    inner = np.array([[hole_lo, hole_lo], [hole_hi, hole_lo], [hole_hi, hole_hi], [hole_lo, hole_hi]])
    points = np.r_[outer, inner]
    triangles = []
    for a in range(4):
        b = (a + 1) % 4
        triangles += [[a, b, 4 + b], [a, 4 + b, 4 + a]]
    return points, np.array(triangles)


def _square(lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    return np.array([[lo, lo], [hi, lo], [hi, hi], [lo, hi]]), np.array([[0, 1, 2], [0, 2, 3]])


def _union(*meshes):
    points, triangles, offset = [], [], 0
    for p, t in meshes:
        points.append(np.asarray(p, float))
        triangles.append(np.asarray(t) + offset)
        offset += len(p)
    return np.concatenate(points), np.concatenate(triangles)


CASES = {
    # accepted
    "ring": (_square_ring(0, 3, 1, 2), True),
    "ring with an island in its hole": (_union(_square_ring(0, 5, 1, 4), _square(2, 3)), True),
    "island touching nothing, apart": (_union(_square(0, 1), _square(2, 3)), True),
    "bowtie (triangles sharing a point)": (([[0, 0], [1, 0], [1, 1], [2, 1], [2, 2]], [[0, 1, 2], [2, 3, 4]]), True),
    # refused
    "square on a square": (_union(_square(0, 3), _square(1, 2)), False),
    "ring over a square": (_union(_square(0, 5), _square_ring(1, 4, 2, 3)), False),
    "square over a ring's hole and ring": (_union(_square_ring(0, 5, 1, 4), _square(0.5, 4.5)), False),
    "double-cover annulus": (_double_cover_annulus(12), False),
    "corner on an edge from outside": (([[0, 0], [2, 0], [1, 2], [1, 0], [2, -1], [0, -1]], [[0, 1, 2], [3, 4, 5]]),
                                       False),
    "edges overlapping collinearly": (([[0, 0], [2, 0], [1, 1], [1, 0], [3, 0], [2, -1]], [[0, 1, 2], [3, 4, 5]]),
                                      False),
    "coincident corners": (([[0, 0], [1, 0], [1, 1], [1, 1], [2, 1], [2, 2]], [[0, 1, 2], [3, 4, 5]]), False),
}


@pytest.mark.parametrize("name", list(CASES))
def test_named_cases(name):
    (points, triangles), accepted = CASES[name]
    verdict = _same_outcome(np.asarray(points, float), np.asarray(triangles, np.int64))
    assert verdict.startswith("accepted") == accepted, verdict
    if not accepted and name != "coincident corners":
        assert any(word in verdict for word in ("overlap", "cross", "planar")), verdict


def test_orphan_points_are_refused_by_the_core_check():
    points, triangles = _square(0, 1)
    with pytest.raises(ValueError, match="orphan"):
        _core.prepare_mesh(np.r_[points, [[0.5, 0.2]]], triangles)


@settings(max_examples=200)
@given(st.integers(0, 2**32 - 1), st.sampled_from([1e-14, 1e-11, 1e-10, 1e-9, 1e-3]),
       st.sampled_from([1e-6, 1.0, 1e9, 1e15]))
def test_flatness_in_cpp_matches_numpy(seed, flatness, offset):
    """_core.first_flat_triangles finds the same first thin and first coarse
    triangle as the numpy arithmetic it replaces."""
    rng = np.random.default_rng(seed)
    m = 50
    a = rng.uniform(-1, 1, (m, 2))
    b = a + rng.uniform(-1, 1, (m, 2))
    # c near the line ab: height about `flatness` times |ab|, sometimes just around the limit
    t = rng.uniform(-0.5, 1.5, m)[:, None]
    normal = np.c_[-(b - a)[:, 1], (b - a)[:, 0]]
    c = a + t * (b - a) + normal * flatness * rng.choice([0.5, 0.99, 1.0, 1.01, 2.0], m)[:, None]
    points = np.r_[a, b, c] + offset
    triangles = np.c_[np.arange(m), np.arange(m) + m, np.arange(m) + 2 * m]
    with np.errstate(invalid="ignore", divide="ignore"):  # offsets can round a triangle to a point: 0 / 0
        height, longest, rounding = _flatness(points, triangles)
    thin = height < _MIN_RELATIVE_HEIGHT * longest
    coarse = height < _MIN_HEIGHT_ULPS * rounding
    expected_thin = int(np.argmax(thin)) if thin.any() else -1
    expected_coarse = int(np.argmax(coarse)) if coarse.any() else -1
    got_thin, got_coarse = _core.first_flat_triangles(points, triangles, _MIN_RELATIVE_HEIGHT, _MIN_HEIGHT_ULPS)
    assert got_thin == expected_thin
    if expected_thin < 0:
        assert got_coarse == expected_coarse


def test_mesh_refuses_a_double_cover():
    points, triangles = _double_cover_annulus(16)
    with pytest.raises(ValueError, match="overlap|cross|planar"):
        evomesh.Mesh(points, triangles)
