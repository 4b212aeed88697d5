"""Fronts (distance against brute force) and the spacing law."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import evomesh
from evomesh import CircleFront, LevelSetFront, PointFront, SpacingLaw
from invariants import distance_to_segments
from strategies import grid_mesh


def probes(n=3000, seed=0, lo=-0.5, hi=1.5):
    return np.random.default_rng(seed).uniform(lo, hi, (n, 2))


def polyline_reference(points, closed, x):
    """Brute force: every segment of the polyline against every probe."""
    a = points
    b = np.roll(points, -1, axis=0)
    if not closed:
        a, b = a[:-1], b[:-1]
    return distance_to_segments(x, a, b)


# --- CircleFront ----------------------------------------------------------------


def test_circle_of_radius_zero_is_its_centre():
    x = probes()
    assert np.allclose(CircleFront((0.2, 0.1), 0.0).distance(x), np.hypot(x[:, 0] - 0.2, x[:, 1] - 0.1))


@pytest.mark.parametrize("radius", [1e-3, 0.3, 2.0])
def test_circle_distance_against_dense_sampling(radius):
    center = np.array([0.45, 0.55])
    x = probes()
    front = CircleFront(center, radius)
    angle = np.linspace(0, 2 * np.pi, 4001)
    ring = center + radius * np.c_[np.cos(angle), np.sin(angle)]
    reference = polyline_reference(ring[:-1], True, x)
    # the 4000-gon lies inside the circle by at most r (1 - cos(pi / 4000))
    assert np.allclose(front.distance(x), reference, atol=radius * 4e-7 + 1e-15)


def test_circle_radius_callable_and_sign():
    front = CircleFront((0.0, 0.0), lambda t: 0.1 + 0.2 * t)
    x = np.array([[1.0, 0.0], [0.0, 0.2], [0.0, 0.0]])
    assert front.radius(1.0) == pytest.approx(0.3)
    assert np.allclose(front.distance(x, 1.0), [0.7, 0.1, 0.3])
    assert np.allclose(front.signed_distance(x, 1.0), [0.7, -0.1, -0.3])
    assert np.allclose(front.distance(x, 0.0), [0.9, 0.1, 0.1])
    line = front.polylines(1.0)[0]
    assert np.allclose(np.hypot(*line.T), 0.3)


def test_circle_bad_input():
    with pytest.raises(ValueError, match="radius"):
        CircleFront((0, 0), -1.0)
    with pytest.raises(ValueError, match="center"):
        CircleFront((0, 0, 0), 1.0)
    with pytest.raises(ValueError, match="center"):
        CircleFront((np.nan, 0), 1.0)
    with pytest.raises(ValueError, match="radius"):
        CircleFront((0, 0), lambda t: -t).distance(np.zeros((1, 2)), 1.0)
    with pytest.raises(ValueError, match="NaN"):
        CircleFront((0, 0), 1.0).distance(np.array([[np.nan, 0.0]]))
    with pytest.raises(ValueError, match="shape"):
        CircleFront((0, 0), 1.0).distance(np.zeros((3, 3)))
    with pytest.raises(TypeError):
        CircleFront((0, 0), "1")


# --- PointFront -----------------------------------------------------------------


@st.composite
def polylines(draw):
    n = draw(st.integers(2, 40))
    closed = draw(st.booleans()) and n >= 3
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    shape = draw(st.sampled_from(["random", "star", "uneven"]))
    if shape == "random":
        points = rng.uniform(0, 1, (n, 2))
    elif shape == "star":
        angle = np.sort(rng.uniform(0, 2 * np.pi, n))
        radius = rng.uniform(0.1, 0.5, n)
        points = 0.5 + radius[:, None] * np.c_[np.cos(angle), np.sin(angle)]
    else:  # one very long segment among short ones: the KD-tree bound must escalate
        points = np.r_[rng.uniform(0, 0.05, (n - 1, 2)), [[5.0, 3.0]]]
    return points, closed


@given(polylines(), st.integers(0, 2**16))
def test_point_front_distance_is_exact(polyline, seed):
    points, closed = polyline
    front = PointFront(points, closed=closed)
    x = probes(500, seed, -3, 6)
    x[:50] = points[np.arange(50) % len(points)] + 1e-9  # near the vertices
    assert np.allclose(front.distance(x), polyline_reference(points, closed, x), rtol=0, atol=1e-12)


def test_point_front_resampled_evenly():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    front = PointFront(square, closed=True).resampled(0.1)
    assert len(front.points) == 40
    gaps = np.hypot(*np.diff(np.vstack([front.points, front.points[:1]]), axis=0).T)
    assert np.allclose(gaps, 0.1)
    assert front.length == pytest.approx(4.0)
    # the curve is unchanged: every new point is on the square
    assert np.allclose(polyline_reference(square, True, front.points), 0, atol=1e-15)
    open_front = PointFront(square, closed=False, spacing=0.3)
    assert np.allclose(open_front.points[[0, -1]], square[[0, -1]])
    assert len(open_front.points) == 11  # round(3 / 0.3) segments
    assert open_front.length <= 3.0  # chords cut the corners
    assert np.allclose(polyline_reference(square, False, open_front.points), 0, atol=1e-15)


def test_point_front_moved_keeps_spacing_and_input():
    angle = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    circle = np.c_[np.cos(angle), np.sin(angle)]
    before = circle.copy()
    front = PointFront(circle, spacing=0.05)
    bigger = front.moved(2.0 * front.points)
    assert bigger.closed and bigger.spacing == 0.05
    gaps = np.hypot(*np.diff(np.vstack([bigger.points, bigger.points[:1]]), axis=0).T)
    assert np.ptp(gaps) < 1e-3 and abs(gaps.mean() - 0.05) < 0.002
    assert np.array_equal(circle, before)
    assert not front.points.flags.writeable
    static = PointFront(circle)
    assert len(static.moved(circle + 1).points) == 30  # no spacing: no resampling


def test_point_front_large_query_is_vectorised():
    angle = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    front = PointFront(np.c_[0.5 + 0.3 * np.cos(angle), 0.5 + 0.3 * np.sin(angle)], spacing=0.01)
    x = probes(200_000, 3, 0, 1)
    d = front.distance(x)
    assert d.shape == (200_000,)
    assert np.allclose(d[:4000], polyline_reference(front.points, True, x[:4000]), rtol=0, atol=1e-12)
    assert np.allclose(d, CircleFront((0.5, 0.5), 0.3).distance(x), atol=1e-4)  # a 188-gon of the 200-gon


def test_point_front_bad_input():
    with pytest.raises(ValueError, match="at least 3"):
        PointFront([[0, 0], [1, 0]], closed=True)
    with pytest.raises(ValueError, match="at least 2"):
        PointFront([[0, 0]], closed=False)
    with pytest.raises(ValueError, match="coincide"):
        PointFront([[0, 0], [0, 0], [0, 0]])
    with pytest.raises(ValueError, match="NaN"):
        PointFront([[0, 0], [1, np.nan], [0, 1]])
    with pytest.raises(ValueError, match="spacing"):
        PointFront([[0, 0], [1, 0], [0, 1]], spacing=-1.0)
    with pytest.raises(TypeError):
        PointFront([[0, 0], [1, 0], [0, 1]], closed="yes")


# --- LevelSetFront --------------------------------------------------------------


def test_level_set_signed_distance_is_exact():
    phi = lambda x, t: np.hypot(x[:, 0] - 0.5, x[:, 1] - 0.5) - 0.2 - 0.1 * t  # noqa: E731
    front = LevelSetFront(phi, signed_distance=True)
    x = probes()
    assert np.allclose(front.distance(x, 1.0), CircleFront((0.5, 0.5), 0.3).distance(x), atol=1e-15)


def test_level_set_linear_phi_is_exact():
    front = LevelSetFront(lambda x, t: 3.0 * x[:, 0] + 4.0 * x[:, 1] - 1.0 - t)
    x = probes()
    reference = np.abs(3.0 * x[:, 0] + 4.0 * x[:, 1] - 1.5) / 5.0
    assert np.allclose(front.distance(x, 0.5), reference, rtol=1e-6, atol=1e-9)


def test_level_set_estimate_near_the_front():
    # |x - c|^2 - r^2 is not a distance; |phi| / |grad phi| is first-order accurate near the zero set
    front = LevelSetFront(lambda x, t: (x[:, 0] - 0.5) ** 2 + (x[:, 1] - 0.5) ** 2 - 0.09)
    reference = CircleFront((0.5, 0.5), 0.3)
    x = probes(5000, 1, 0, 1)
    near = reference.distance(x) < 0.02
    error = np.abs(front.distance(x)[near] - reference.distance(x)[near])
    assert error.max() < 0.02**2 / (2 * 0.28) + 1e-6
    # at the centre the gradient vanishes: infinitely far from the front by the estimate
    assert np.isinf(front.distance(np.array([[0.5, 0.5]])))[0]


def test_level_set_bad_input():
    with pytest.raises(TypeError, match="callable"):
        LevelSetFront(1.0)
    with pytest.raises(ValueError, match="NaN"):
        LevelSetFront(lambda x, t: np.full(len(x), np.nan)).distance(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="shape"):
        LevelSetFront(lambda x, t: np.zeros(len(x) + 1)).distance(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="step"):
        LevelSetFront(lambda x, t: x[:, 0], step=0.0)


def test_fronts_do_not_modify_queries():
    x = probes(100)
    before = x.copy()

    def phi(points, t):
        points += 1.0  # a careless phi: must not reach the caller's array
        return points[:, 0] - 1.5

    for front in (CircleFront((0, 0), 1.0), PointFront(x[:5]), LevelSetFront(phi)):
        front.distance(x, 0.0)
    assert np.array_equal(x, before)


# --- SpacingLaw -----------------------------------------------------------------


def test_spacing_law_h():
    law = SpacingLaw(0.01, 0.05, 0.1, grade=0.5)
    d = np.array([0.0, 0.05, 0.06, 0.1, 0.13, 1.0])
    assert np.allclose(law.h(d), [0.01, 0.01, 0.015, 0.035, 0.05, 0.05])
    assert law.h(0.0) == pytest.approx(0.01)
    assert np.all(np.diff(law.h(np.linspace(0, 1, 100))) >= 0)
    # h is Lipschitz with the grade
    s = np.linspace(0, 1, 1001)
    assert np.abs(np.diff(law.h(s))).max() <= 0.5 * (s[1] - s[0]) + 1e-15


def test_spacing_law_delta_and_clip_bounds():
    mesh = grid_mesh(8, 8, jitter=0.2, seed=1)
    nn = evomesh.nn_spacing(mesh)
    law = SpacingLaw(0.02, 0.1, 0.0, grade=1.0)
    front = CircleFront((0.5, 0.5), 0.25)
    d = front.distance(mesh.points)
    delta = law.delta(mesh, d)
    expected = np.clip(law.h(d) / nn, 0.1, 10.0)
    assert np.array_equal(delta, expected)
    assert np.array_equal(law(mesh, d), expected)
    tight = SpacingLaw(1e-6, 100.0, 0.0, grade=1.0, lower=0.5, upper=1.5)
    clipped = tight.delta(mesh, d)
    assert clipped.min() == 0.5 and clipped.max() == 1.5  # both bounds reached


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"band": -0.1}, "band"),
        ({"h_min": 0.2}, "h_min must be <= h_max"),
        ({"h_min": 0.0}, "h_min"),
        ({"lower": 1.0}, "lower"),
        ({"lower": 0.0}, "lower"),
        ({"upper": 1.0}, "upper"),
        ({"grade": 0.0}, "grade"),
        ({"h_max": np.inf}, "finite"),
    ],
)
def test_spacing_law_bad_parameters(kwargs, message):
    args = {"h_min": 0.01, "h_max": 0.1, "band": 0.1, **kwargs}
    with pytest.raises(ValueError, match=message):
        SpacingLaw(**args)


def test_spacing_law_bad_distances():
    mesh = grid_mesh(5, 5)
    law = SpacingLaw(0.01, 0.1, 0.1)
    with pytest.raises(ValueError, match="NaN"):
        law.delta(mesh, np.full(mesh.n_points, np.nan))
    with pytest.raises(ValueError, match=">= 0"):
        law.delta(mesh, -np.ones(mesh.n_points))
    with pytest.raises(ValueError, match="one value per mesh point"):
        law.delta(mesh, np.ones(3))
    with pytest.raises(TypeError, match="Mesh"):
        law.delta(mesh.points, np.ones(mesh.n_points))
    with pytest.raises(TypeError, match="real number"):
        SpacingLaw("0.01", 0.1, 0.1)
