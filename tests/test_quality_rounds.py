"""The quality pass in rounds of independent insertions
(docs/distributed-step.md section 3.6, option ``quality_rounds``): its output is a
function of the input *sets* (any order of points and pieces, either direction
of an interior piece, any thread count), and it is a valid quality mesh."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import evomesh
from evomesh import _core
from evomesh.mesh_quality import triangle_angles
from invariants import check_evolved, check_valid_mesh
from strategies import grid_mesh

MIN_ANGLE = 30.0
ANGLE_TOLERANCE = 1e-6


def _square_loop(lo: float, hi: float, per_side: int, clockwise: bool = False) -> np.ndarray:
    t = np.linspace(0.0, 1.0, per_side, endpoint=False)
    s = lo + (hi - lo) * t
    loop = np.concatenate([np.c_[s, 0 * s + lo], np.c_[0 * s + hi, s], np.c_[hi + lo - s, 0 * s + hi],
                           np.c_[0 * s + lo, hi + lo - s]])
    return loop[::-1] if clockwise else loop


def domain(layout: str, n: int, seed: int):
    """Points, pieces (m, 2), boundary flags and the domain's area. Boundary pieces
    have the domain on their left. Layouts: a unit square with random interior
    points, the same with a slit (interior pieces), with a square hole, a lattice
    full of exact ties (cocircular cells) with some points nudged, and a thin
    wedge (a corner of about 20 degrees: CGAL's clusters)."""
    rng = np.random.default_rng(seed)
    pieces, boundary = [], []

    def add_loop(loop: np.ndarray, first: int, is_boundary: bool = True) -> None:
        k = len(loop)
        for i in range(k):
            pieces.append((first + i, first + (i + 1) % k))
            boundary.append(is_boundary)

    if layout == "wedge":
        corners = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.36]])
        edge = [corners[i] + (corners[(i + 1) % 3] - corners[i]) * t
                for i in range(3) for t in np.linspace(0, 1, 6, endpoint=False)]
        outer = np.array(edge)
        u, v = rng.uniform(0.02, 0.94, (2, n))
        flip = u + v > 0.96
        u[flip], v[flip] = 0.96 - u[flip], 0.96 - v[flip]
        inside = corners[0] + u[:, None] * (corners[1] - corners[0]) + v[:, None] * (corners[2] - corners[0])
        add_loop(outer, 0)
        return np.r_[outer, inside], np.array(pieces), np.array(boundary, np.uint8), 0.18
    outer = _square_loop(0.0, 1.0, 6)
    points = [outer]
    add_loop(outer, 0)
    area = 1.0
    if layout == "lattice":
        k = max(3, int(np.sqrt(n)))
        g = (np.arange(k) + 1.0) / (k + 1)
        x, y = np.meshgrid(g, g)
        inner = np.c_[x.ravel(), y.ravel()]
        moved = rng.choice(len(inner), size=max(1, len(inner) // 5), replace=False)
        inner[moved] += np.array([0.375, 0.125]) / (k + 1)  # dyadic nudges: exact ties remain
        points.append(inner)
    else:
        inner = rng.uniform(0.02, 0.98, (n, 2))
        if layout == "hole":
            hole = _square_loop(0.4, 0.6, 2, clockwise=True)
            add_loop(hole, len(outer))
            points.append(hole)
            area -= 0.04
            inner = inner[np.abs(inner - 0.5).max(axis=1) > 0.12]
        if layout == "slit":
            slit = np.c_[np.linspace(0.2, 0.6, 5), np.full(5, 0.5)]
            first = len(outer)
            for i in range(4):
                pieces.append((first + i, first + i + 1))
                boundary.append(False)
            points.append(slit)
            inner = inner[np.abs(inner[:, 1] - 0.5) > 0.01]
        points.append(inner)
    return np.concatenate(points), np.array(pieces), np.array(boundary, np.uint8), area


def shuffled(points, pieces, boundary, seed: int):
    """The same sets: points permuted, pieces permuted, interior pieces reversed."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(len(points))
    where = np.empty_like(perm)
    where[perm] = np.arange(len(perm))
    order = rng.permutation(len(pieces))
    new_pieces = where[pieces[order]]
    flip = (boundary[order] == 0) & (rng.random(len(order)) < 0.5)
    new_pieces[flip] = new_pieces[flip][:, ::-1]
    return points[perm], new_pieces, boundary[order]


def canonical(result):
    """Points sorted by (x, y); triangles as sorted rows of sorted point ranks."""
    p = result["points"]
    order = np.lexsort((p[:, 1], p[:, 0]))
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    t = np.sort(rank[result["triangles"]], axis=1)
    s = np.sort(rank[result["segments"]], axis=1)
    return p[order], t[np.lexsort(t.T[::-1])], s[np.lexsort(s.T[::-1])]


def smallest_angles(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The smallest angle (degrees) of every triangle."""
    return triangle_angles(points, triangles).min(axis=1)


def check_quality_mesh(points, pieces, result, area: float) -> None:
    """Positive areas, the domain's area, every input piece a chain of output
    segments through new points only, every input point kept or dropped for
    crowding, no duplicate points."""
    p, t = result["points"], result["triangles"]
    e1, e2 = p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]
    twice = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    assert (twice > 0).all(), f"{int((twice <= 0).sum())} triangles with non-positive area"
    assert abs(twice.sum() / 2 - area) <= 1e-12 * area * 1e3
    assert len(np.unique(p, axis=0)) == len(p)
    source = result["source"]
    out_of = -np.ones(len(points), np.int64)
    out_of[source[source >= 0]] = np.flatnonzero(source >= 0)
    neighbours: dict[int, set[int]] = {}
    for a, b in result["segments"]:
        neighbours.setdefault(int(a), set()).add(int(b))
        neighbours.setdefault(int(b), set()).add(int(a))
    for a, b in pieces:
        start, goal = int(out_of[a]), int(out_of[b])
        assert start >= 0 and goal >= 0, "an end of a piece was dropped"
        # walk from a through new points only (each on two sub-segments) to b
        found = goal in neighbours.get(start, ())
        for first in neighbours.get(start, ()):
            previous, at = start, first
            while not found and source[at] < 0:
                following = [v for v in neighbours[at] if v != previous]
                if len(following) != 1:
                    break
                previous, at = at, following[0]
            found = found or at == goal
        assert found, f"piece {a}-{b} is not a chain of output segments"


LAYOUTS = ["random", "slit", "hole", "lattice", "wedge"]


@given(layout=st.sampled_from(LAYOUTS), n=st.integers(5, 250), seed=st.integers(0, 2**16),
       shuffle_seed=st.integers(0, 2**16), min_angle=st.sampled_from([20.0, 28.0, 30.0]))
def test_rounds_output_is_a_function_of_the_input_sets(layout, n, seed, shuffle_seed, min_angle):
    points, pieces, boundary, _ = domain(layout, n, seed)
    first = _core.quality_triangulate(points, pieces, boundary, min_angle=min_angle, quality_rounds=True)
    again = _core.quality_triangulate(*shuffled(points, pieces, boundary, shuffle_seed), min_angle=min_angle,
                                      quality_rounds=True)
    for x, y in zip(canonical(first), canonical(again)):
        assert x.shape == y.shape and np.array_equal(x, y)
    assert first["stats"] == again["stats"]


@given(layout=st.sampled_from(LAYOUTS), n=st.integers(5, 250), seed=st.integers(0, 2**16))
def test_rounds_output_is_a_valid_quality_mesh(layout, n, seed):
    points, pieces, boundary, area = domain(layout, n, seed)
    serial = _core.quality_triangulate(points, pieces, boundary, quality_rounds=False)
    rounds = _core.quality_triangulate(points, pieces, boundary, quality_rounds=True)
    check_quality_mesh(points, pieces, rounds, area)
    stats = rounds["stats"]
    assert stats["stalled"] == 0 and stats["round_limit"] == 0 and stats["points_outside"] == 0
    assert stats["rounds"] >= 1 or stats["points_added"] == 0
    # where the serial pass meets the angle bound, so do the rounds
    serial_min = smallest_angles(serial["points"], serial["triangles"]).min()
    if serial_min >= MIN_ANGLE - ANGLE_TOLERANCE and not stats["capped"]:
        assert smallest_angles(rounds["points"], rounds["triangles"]).min() >= MIN_ANGLE - ANGLE_TOLERANCE
    # the same points dropped for crowding as the serial pass (the same rule)
    assert stats["points_removed"] == serial["stats"]["points_removed"]


def test_rounds_stop_at_the_budget_cut_by_the_order():
    # (a domain with a small angle: the budget is max_fraction n + max_extra alone)
    points, pieces, boundary, area = domain("wedge", 400, 3)
    full = _core.quality_triangulate(points, pieces, boundary, quality_rounds=True)
    assert full["stats"]["points_added"] > 20
    cut = _core.quality_triangulate(points, pieces, boundary, max_fraction=0.0, max_extra=20.0, quality_rounds=True)
    assert cut["stats"]["points_added"] == 20 and cut["stats"]["capped"] == 1
    check_quality_mesh(points, pieces, cut, area)
    again = _core.quality_triangulate(*shuffled(points, pieces, boundary, 9), max_fraction=0.0, max_extra=20.0,
                                      quality_rounds=True)
    for x, y in zip(canonical(cut), canonical(again)):
        assert np.array_equal(x, y)


def test_quality_triangulate_rejects_bad_input():
    points, pieces, boundary, _ = domain("random", 10, 0)
    with pytest.raises(ValueError, match="piece index"):
        _core.quality_triangulate(points, pieces + len(points), boundary, quality_rounds=True)
    with pytest.raises(ValueError, match="one flag per piece"):
        _core.quality_triangulate(points, pieces, boundary[:-1], quality_rounds=True)
    with pytest.raises(ValueError, match="finite"):
        _core.quality_triangulate(np.where(points == points[7], np.nan, points), pieces, boundary)
    with pytest.raises(ValueError, match="min_angle"):
        _core.quality_triangulate(points, pieces, boundary, min_angle=40.0, quality_rounds=True)


def staggered_lattice(m: int):
    """The unit square cut into m equal pieces a side, with interior points in
    columns h / 2 apart (h = 1 / m), every other column shifted by h / 2: the
    lattice a graded mesh has next to its coarse sides. Splitting a side's
    piece there makes triangles whose points encroach the next piece but one,
    so Delaunay refinement at 30 degrees splits every other piece of a side,
    one after the other."""
    h = 1.0 / m
    columns = []
    for j in range(1, 2 * m - 1):
        ys = np.arange(1, m) * h if j % 2 == 1 and j > 1 else (np.arange(m) + 0.5) * h
        columns.append(np.c_[np.full(len(ys), j * h / 2), ys])
    t = np.arange(m) * h
    loop = np.r_[np.c_[t, 0 * t], np.c_[0 * t + 1, t], np.c_[1 - t, 0 * t + 1], np.c_[0 * t, 1 - t]]
    pieces = np.c_[np.arange(len(loop)), (np.arange(len(loop)) + 1) % len(loop)]
    return np.concatenate([loop, *columns]), pieces, np.ones(len(pieces), np.uint8)


def test_rounds_are_bounded_where_splits_march_along_a_side():
    # (12,882 points; before runs of equal pieces were split in one go: 83
    # rounds, the splits marching along the sides)
    points, pieces, boundary = staggered_lattice(80)
    serial = _core.quality_triangulate(points, pieces, boundary, quality_rounds=False)
    rounds = _core.quality_triangulate(points, pieces, boundary, quality_rounds=True)
    stats = rounds["stats"]
    assert stats["rounds"] <= 30
    assert stats["stalled"] == 0 and stats["round_limit"] == 0 and stats["capped"] == 0
    check_quality_mesh(points, pieces, rounds, 1.0)
    angles = smallest_angles(rounds["points"], rounds["triangles"])
    assert angles.min() >= MIN_ANGLE - ANGLE_TOLERANCE
    # the sides' pieces split at once: at most one extra point a piece (and the
    # triangles' points near it) over the serial pass's
    assert stats["points_added"] <= 1.5 * serial["stats"]["points_added"]
    again = _core.quality_triangulate(*shuffled(points, pieces, boundary, 5), quality_rounds=True)
    for x, y in zip(canonical(rounds), canonical(again)):
        assert np.array_equal(x, y)


@given(m=st.integers(6, 50), n_extra=st.integers(0, 3), seed=st.integers(0, 2**16),
       min_angle=st.sampled_from([25.0, 30.0]))
def test_rounds_on_lattices_are_bounded_and_valid(m, n_extra, seed, min_angle):
    points, pieces, boundary = staggered_lattice(m)
    points = np.r_[points, np.random.default_rng(seed).uniform(0.003, 0.997, (n_extra, 2))]
    rounds = _core.quality_triangulate(points, pieces, boundary, min_angle=min_angle, quality_rounds=True)
    stats = rounds["stats"]
    assert stats["rounds"] <= 30
    assert stats["stalled"] == 0 and stats["round_limit"] == 0 and stats["capped"] == 0
    check_quality_mesh(points, pieces, rounds, 1.0)
    assert smallest_angles(rounds["points"], rounds["triangles"]).min() >= min_angle - ANGLE_TOLERANCE


def test_a_split_that_does_not_march_splits_no_run():
    # A square grid, one point near a corner: a few splits at the corner, none
    # along the sides (splitting the sides' 396 pieces adds about 1,200 points).
    g = np.linspace(0.0, 1.0, 100)
    x, y = np.meshgrid(g, g)
    points = np.r_[np.c_[x.ravel(), y.ravel()], [[0.004, 0.003]]]
    index = np.arange(100 * 100).reshape(100, 100)
    loop = np.r_[index[0, :-1], index[:-1, -1], index[-1, :0:-1], index[:0:-1, 0]]
    pieces = np.c_[loop, np.roll(loop, -1)]
    boundary = np.ones(len(pieces), np.uint8)
    serial = _core.quality_triangulate(points, pieces, boundary, quality_rounds=False)
    rounds = _core.quality_triangulate(points, pieces, boundary, quality_rounds=True)
    assert rounds["stats"]["points_added"] <= serial["stats"]["points_added"] + 10
    assert smallest_angles(rounds["points"], rounds["triangles"]).min() >= MIN_ANGLE - ANGLE_TOLERANCE


def graded_step(side: int = 24):
    mesh = grid_mesh(side, side, jitter=0.3, seed=4, hole=True)
    x = mesh.points[:, 0]
    return mesh, np.where(x < 0.4, 0.45, 1.0)


def test_evolve_with_quality_rounds():
    mesh, delta = graded_step()
    out = evomesh.evolve(mesh, delta, seed=1, quality_rounds=True)
    check_evolved(mesh, out)
    check_valid_mesh(out)
    assert out.stats["quality_rounds"] >= 1
    assert out.stats["quality_stalled"] == 0 and out.stats["quality_round_limit"] == 0
    assert out.stats["quality_capped"] == 0
    assert smallest_angles(out.points, out.triangles).min() >= MIN_ANGLE - ANGLE_TOLERANCE
    # the serial pass (the default) reports no rounds
    default = evomesh.evolve(mesh, delta, seed=1)
    assert "quality_rounds" not in default.stats
    drfc = evomesh.evolve(mesh, delta, seed=1, method="drfc", quality_rounds=True)
    check_evolved(mesh, drfc)
    assert drfc.stats["quality_rounds"] >= 1


def test_evolve_with_quality_rounds_is_the_same_on_any_thread_count():
    mesh, delta = graded_step(30)
    one = evomesh.evolve(mesh, delta, seed=2, quality_rounds=True, threads=1)
    two = evomesh.evolve(mesh, delta, seed=2, quality_rounds=True, threads=3)
    assert np.array_equal(one.points, two.points)
    assert np.array_equal(one.triangles, two.triangles)
    assert np.array_equal(one.segments, two.segments)


def test_quality_rounds_option():
    assert evomesh.FrfcOptions().quality_rounds is False
    assert evomesh.DrfcOptions.recommended().quality_rounds is False
    assert evomesh.FRFC_DEFAULTS["quality_rounds"] is False
    assert evomesh.evolution.make_options("frfc", quality_rounds=True).quality_rounds is True
    with pytest.raises(TypeError, match="quality_rounds must be a bool"):
        evomesh.evolution.make_options("frfc", quality_rounds=1)
