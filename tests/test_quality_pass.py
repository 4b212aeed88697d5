"""The quality pass (Section 6's suggestion): min angle >= 20 degrees where the
domain allows it, a bound on inserted points where it does not, and what it reports."""

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import Delaunay

import evomesh
from evomesh import PointKind
from invariants import check_evolved, integral_inverse_square, spacing_ratio
from strategies import grid_mesh, meshes

MIN_ANGLE = 20.0
# Angles are computed in floating point; the pass decides with the same formula.
ANGLE_TOLERANCE = 1e-6


def polygon_mesh(corners, n_interior: int, *, seed: int = 0) -> evomesh.Mesh:
    """Delaunay triangulation of a convex polygon's corners and random points
    strictly inside it (sampled over a fan from the centroid)."""
    corners = np.asarray(corners, dtype=float)
    rng = np.random.default_rng(seed)
    centre = corners.mean(axis=0)
    k = len(corners)
    which = rng.integers(0, k, n_interior)
    u, v = rng.uniform(0.05, 0.95, (2, n_interior))
    flip = u + v > 0.95
    u[flip], v[flip] = 0.95 - u[flip], 0.95 - v[flip]
    a, b = corners[which], corners[(which + 1) % k]
    inside = centre + u[:, None] * (a - centre) + v[:, None] * (b - centre)
    points = np.r_[corners, inside]
    return evomesh.Mesh(points, Delaunay(points).simplices)


def regular_polygon(k: int, radius: float = 1.0, phase: float = 0.0) -> np.ndarray:
    t = phase + 2 * np.pi * np.arange(k) / k
    return radius * np.c_[np.cos(t), np.sin(t)]


@st.composite
def delta_for(draw, mesh):
    kind = draw(st.sampled_from(["random", "smooth", "constant"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    if kind == "random":
        return np.exp(rng.uniform(np.log(0.2), np.log(5.0), mesh.n_points))
    if kind == "smooth":
        lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
        t = (mesh.points[:, 0] - lo[0]) / (hi[0] - lo[0])
        return 0.2 * 25.0**t
    return np.full(mesh.n_points, draw(st.sampled_from([0.3, 0.7, 1.0, 2.0, 5.0])))


@st.composite
def convex_mesh_and_delta(draw):
    """Convex domains with no angle below 60 degrees: jittered squares (any
    scale), regular triangles, pentagons, hexagons, octagons."""
    if draw(st.booleans()):
        n = draw(st.integers(4, 12))
        scale = draw(st.sampled_from([1.0, 1e-3, 50.0]))
        mesh = grid_mesh(n, draw(st.integers(4, 12)), jitter=draw(st.sampled_from([0.0, 0.1, 0.25])),
                         seed=draw(st.integers(0, 2**16)), scale=scale)
    else:
        k = draw(st.sampled_from([3, 5, 6, 8]))
        corners = regular_polygon(k, draw(st.sampled_from([1.0, 0.01])), draw(st.floats(0, 1)))
        mesh = polygon_mesh(corners, draw(st.integers(3, 60)), seed=draw(st.integers(0, 2**16)))
    return mesh, draw(delta_for(mesh))


@st.composite
def nonconvex_mesh_and_delta(draw):
    """Holes and notches: reflex corners, no angle below 90 degrees."""
    mesh = draw(
        meshes(max_side=12).filter(lambda m: m.euler_characteristic() == 0 or (m.kind == PointKind.CORNER).sum() > 4)
    )
    return mesh, draw(delta_for(mesh))


def min_angle(mesh):
    return evomesh.quality(mesh).min_angle


@pytest.mark.parametrize("method", ["frfc", "drfc"])
@given(case=convex_mesh_and_delta(), seed=st.integers(0, 2**32))
def test_min_angle_on_convex_domains(method, case, seed):
    mesh, delta = case
    new = evomesh.evolve(mesh, delta, method=method, seed=seed)
    check_evolved(mesh, new)
    assert min_angle(new) >= MIN_ANGLE - ANGLE_TOLERANCE
    assert new.stats["quality_capped"] == 0
    assert new.stats["min_angle"] == pytest.approx(min_angle(new), abs=1e-9)


@pytest.mark.parametrize("method", ["frfc", "drfc"])
@given(case=nonconvex_mesh_and_delta(), seed=st.integers(0, 2**32))
def test_min_angle_on_domains_with_holes_and_notches(method, case, seed):
    mesh, delta = case
    new = evomesh.evolve(mesh, delta, method=method, seed=seed)
    check_evolved(mesh, new)
    assert min_angle(new) >= MIN_ANGLE - ANGLE_TOLERANCE


@pytest.mark.parametrize("angle", [30.0, 10.0, 3.0])
@pytest.mark.parametrize("method", ["frfc", "drfc"])
def test_small_input_angles_end_quickly_and_report_where(method, angle):
    """A wedge with a sharp tip: the pass stops (bounded insertions), stays
    valid, and reports the smallest angle, which sits at the tip."""
    t = np.radians(np.linspace(0, angle, 6))
    arc = np.c_[np.cos(t), np.sin(t)]
    rng = np.random.default_rng(1)
    r = rng.uniform(0.3, 0.9, 40)
    s = rng.uniform(0.1, 0.9, 40) * np.radians(angle)
    points = np.r_[[[0.0, 0.0]], arc, np.c_[r * np.cos(s), r * np.sin(s)]]
    mesh = evomesh.Mesh(points, Delaunay(points).simplices)
    delta = np.full(mesh.n_points, 0.5)
    new = evomesh.evolve(mesh, delta, method=method, seed=0)
    check_evolved(mesh, new)
    stats = new.stats
    assert stats["quality_points_added"] <= 0.5 * (new.n_points + stats["quality_points_removed"]) + 1000
    assert stats["min_angle"] == pytest.approx(min_angle(new), abs=1e-9)
    where = np.array([stats["min_angle_x"], stats["min_angle_y"]])
    if angle < 30.0:  # at FRFC's 30 degree bound many triangles tie within rounding
        assert np.allclose(where, evomesh.quality(new).min_angle_location)
    # the input angle cannot be improved; below the target it is the smallest one left
    assert min_angle(new) <= angle + 1e-9
    if angle < MIN_ANGLE:
        assert np.linalg.norm(where) < 0.5


def test_quality_false_is_the_paper_and_the_pass_reports_its_changes():
    mesh = grid_mesh(30, 30, jitter=0.25, seed=4)
    delta = np.exp(np.random.default_rng(2).uniform(np.log(0.3), np.log(3.0), mesh.n_points))
    plain = evomesh.evolve(mesh, delta, seed=3, quality=False)
    good = evomesh.evolve(mesh, delta, seed=3)
    check_evolved(mesh, plain)
    check_evolved(mesh, good)
    assert "quality_points_added" not in plain.stats
    assert min_angle(plain) < MIN_ANGLE <= min_angle(good) + ANGLE_TOLERANCE
    # The pass only drops crowding points and adds new ones: every other point
    # of the paper's output is still there, with the same origin.
    key = lambda m: {tuple(p): o for p, o in zip(m.points, m.origin)}  # noqa: E731
    before, after = key(plain), key(good)
    kept = set(before) & set(after)
    assert all(before[p] == after[p] for p in kept)
    removed = len(before) - len(kept)
    added = len(after) - len(kept)
    assert removed == good.stats["quality_points_removed"]
    assert added == good.stats["quality_points_added"]
    # its points are new, or put back exactly where the packing dropped an input point
    fresh = np.array([tuple(p) not in before for p in good.points])
    restored = fresh & (good.origin >= 0)
    assert restored.sum() == good.stats["restored_points"]
    assert np.array_equal(good.points[restored], mesh.points[good.origin[restored]])
    # Few points at the old 20 degree bound (66 here, under 5 %); the default
    # 30 degrees costs more on this rough size map (delta drawn per point in [0.3, 3]):
    # 781 here (56 %; 272 at 25 degrees).
    assert added <= 0.6 * plain.n_points


def test_new_points_on_segments_stay_on_the_boundary():
    mesh = grid_mesh(12, 12, hole=True)
    delta = np.where(mesh.points[:, 0] < 0.5, 0.3, 3.0)
    new = evomesh.evolve(mesh, delta, seed=0)
    check_evolved(mesh, new)
    fresh = new.origin < 0
    on_segment = np.zeros(new.n_points, bool)
    on_segment[new.segments.ravel()] = True
    assert set(np.unique(new.kind[fresh & on_segment])) <= {PointKind.BOUNDARY}
    assert set(np.unique(new.kind[fresh & ~on_segment])) <= {PointKind.SAMPLED}
    # boundary segments have the domain on their left: the triangle on each is CCW
    b = new.segments[new.segment_is_boundary]
    tri_edges = {(t[i], t[(i + 1) % 3]) for t in new.triangles for i in range(3)}
    assert all((a, c) in tri_edges for a, c in b)


def test_spacing_and_size_with_the_pass():
    """The pass adds a few percent of points and keeps FRFC's spacing."""
    mesh = grid_mesh(40, 40, jitter=0.2, seed=3)
    delta = np.where(mesh.points[:, 0] < 0.5, 0.3, 3.0)
    f = evomesh.spacing(mesh, delta)
    mass = integral_inverse_square(mesh, f)
    for quality in (False, True):
        new = evomesh.evolve(mesh, delta, seed=0, quality=quality)
        assert spacing_ratio(mesh, new, delta).max() < 2.0
        assert new.n_points / mass < 2.0 * 1.3**2  # interpolated sizes: test_evolve.py


@pytest.mark.parametrize("method", ["frfc", "drfc"])
def test_bit_identical_across_processes(method):
    """The pass orders work by exact keys only: the same output in fresh processes
    (CGAL handles are compared by address in places; nothing may depend on it)."""
    code = textwrap.dedent(
        f"""
        import hashlib, sys
        import numpy as np
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        import evomesh
        from strategies import grid_mesh
        mesh = grid_mesh(20, 20, jitter=0.25, seed=5, notch=False)
        delta = np.exp(np.random.default_rng(0).uniform(np.log(0.2), np.log(5), mesh.n_points))
        new = evomesh.evolve(mesh, delta, method={method!r}, seed=1)
        h = hashlib.sha256()
        for a in (new.points, new.triangles, new.segments, new.origin, new.kind):
            h.update(a.tobytes())
        print(h.hexdigest())
        """
    )
    digests = {subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout
               for _ in range(2)}
    assert len(digests) == 1


@pytest.mark.parametrize(
    "options, error, match",
    [
        ({"quality": "yes"}, TypeError, "quality"),
        ({"min_angle": 0.0}, ValueError, "min_angle"),
        ({"min_angle": 45.0}, ValueError, "min_angle"),
        ({"min_angle": np.nan}, ValueError, "min_angle"),
        ({"min_angle": "20"}, TypeError, "min_angle"),
    ],
)
@pytest.mark.parametrize("method", ["frfc", "drfc"])
def test_quality_options_are_validated(method, options, error, match):
    mesh = grid_mesh(5, 5)
    with pytest.raises(error, match=match):
        evomesh.evolve(mesh, 1.0, method=method, **options)


def test_lower_min_angle_adds_fewer_points():
    mesh = grid_mesh(25, 25, jitter=0.25, seed=6)
    delta = np.exp(np.random.default_rng(3).uniform(np.log(0.3), np.log(3.0), mesh.n_points))
    added = []
    for angle in (10.0, 20.0, 25.0):
        new = evomesh.evolve(mesh, delta, seed=1, min_angle=angle)
        check_evolved(mesh, new)
        assert min_angle(new) >= angle - ANGLE_TOLERANCE
        added.append(new.stats["quality_points_added"])
    assert added[0] <= added[1] <= added[2]


def test_smallest_angle_stats_are_the_first_smallest_over_many_blocks() -> None:
    """stats min_angle / min_angle_x / min_angle_y come from blocks of triangles
    in parallel (2^15 each): the first smallest angle in triangle order, as one
    sequential sweep finds it, for any thread count."""
    mesh = evomesh.unit_square_mesh(50_000, seed=3)
    results = [evomesh.evolve(mesh, 1.0, seed=0, threads=t) for t in (1, 2)]
    new = results[0]
    assert new.n_triangles > 3 * 2**15
    p = new.points[new.triangles]  # (t, 3, 2)
    angles = []
    for k in range(3):
        u = p[:, (k + 1) % 3] - p[:, k]
        v = p[:, (k + 2) % 3] - p[:, k]
        angles.append(np.degrees(np.arctan2(np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]), (u * v).sum(axis=1))))
    a = np.stack(angles, axis=1).ravel()  # triangle by triangle, corner by corner: the sweep's order
    first = int(np.argmin(a))
    best, where = a[first], p[first // 3].mean(axis=0)
    for r in results:
        assert r.stats["min_angle"] == pytest.approx(best, abs=1e-12)
        np.testing.assert_allclose([r.stats["min_angle_x"], r.stats["min_angle_y"]], where, rtol=0, atol=1e-15)
    assert results[0].stats["min_angle_x"] == results[1].stats["min_angle_x"]


@given(st.integers(0, 2**16), st.floats(0.4, 2.5))
def test_quality_figures_match_the_numpy_formulas(seed: int, delta: float) -> None:
    """quality() sums up in C++ (one parallel pass) what triangle_angles and
    radius_edge_ratios compute in numpy: same extremes, same mean, same first
    worst triangle; the histogram may differ only for angles within rounding of
    a bin edge (numpy's arccos is not the C library's)."""
    from evomesh.mesh_quality import radius_edge_ratios, triangle_angles

    mesh = evomesh.evolve(evomesh.unit_square_mesh(3000, seed=seed % 7), delta, seed=seed)
    q = evomesh.quality(mesh)
    angles = triangle_angles(mesh.points, mesh.triangles)
    ratio = radius_edge_ratios(mesh.points, mesh.triangles)
    assert q.min_angle == pytest.approx(angles.min(), abs=1e-11)
    assert q.max_angle == pytest.approx(angles.max(), abs=1e-11)
    assert q.max_radius_edge == pytest.approx(ratio.max(), rel=1e-12)
    assert q.mean_radius_edge == pytest.approx(ratio.mean(), rel=1e-12)
    per_triangle = angles.min(axis=1)
    assert per_triangle[q.min_angle_triangle] == pytest.approx(per_triangle.min(), abs=1e-11)
    hist, _ = np.histogram(angles, bins=q.angle_bins)
    assert q.angle_histogram.sum() == 3 * mesh.n_triangles
    near_edge = np.abs(angles - 10 * np.round(angles / 10)) < 1e-9
    assert np.abs(q.angle_histogram - hist).sum() <= 2 * near_edge.sum()


@pytest.mark.parametrize("method, target", [("frfc", 30.0), ("drfc", 20.0)])
def test_sixty_degree_corners_are_not_small_angles(method, target):
    # The long hypothesis profile (test_min_angle_on_convex_domains): an
    # equilateral domain whose corners, in floating point, fell just below 60
    # degrees. CGAL took such a corner for a cluster (a small input angle) and
    # left a triangle of 16.1 degrees there (19.0 at the session's start).
    # Clusters now need an angle below 60 degrees by more than rounding.
    case = np.load(Path(__file__).parent / "data" / "equilateral_sixty_degree_corners.npz")
    mesh = evomesh.Mesh(case["points"], case["triangles"])
    new = evomesh.evolve(mesh, case["delta"], method=method, seed=int(case["seed"]))
    check_evolved(mesh, new)
    assert min_angle(new) >= target - ANGLE_TOLERANCE
    assert new.stats["quality_capped"] == 0
