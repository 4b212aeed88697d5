"""size= in the core (cpp/src/size_request.cpp): the comparisons delta_from_size
reads from L are exactly those of the exact L, and delta_from_size gives the
delta of its numpy form, bit for bit (it sets the cost of a repeated size=
step; the figures are in benchmarks/stays_put.py)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import evomesh
from evomesh import _core
from evomesh.spacing_function import _size_values, delta_from_size
from strategies import any_meshes, mesh_and_delta, random_mesh_arrays

ABOVE, BELOW, AT_LEAST = 1, 2, 4


def exact_classes(points, triangles, h, above, below, at_least) -> np.ndarray:
    """The bits of edge_over_size_classes from edge_over_size_around's L (hypot for every edge)."""
    local = _core.edge_over_size_around(points, triangles, h)
    return ((local > above) * ABOVE | (local < below) * BELOW | (local >= at_least) * AT_LEAST).astype(np.uint8)


def thresholds_at(local: np.ndarray, rng: np.random.Generator) -> list[tuple[float, float, float]]:
    """delta_from_size's thresholds, and thresholds on the exact L values
    themselves and their float neighbours: where the close L cannot tell and
    the core must compute L again with hypot."""
    cases = [(1.25, 1 / 1.25, 1 / 1.1)]
    finite = local[np.isfinite(local)]
    if len(finite):
        for _ in range(3):
            a, b, c = rng.choice(finite, 3)
            cases.append((a, np.nextafter(b, np.inf), np.nextafter(c, -np.inf)))
            cases.append((np.nextafter(a, -np.inf), b, c))
    return cases


@settings(max_examples=40)
@given(random_mesh_arrays(), st.sampled_from([1.0, 1e-140, 1e140]), st.sampled_from(["uniform", "graded", "tiny"]),
       st.integers(0, 2**32 - 1))
def test_classes_are_the_exact_comparisons(arrays, factor, request, seed):
    # factor: edges whose squares leave the range where sqrt(dx^2 + dy^2) is
    # within its bound (they take hypot); "tiny": ratios beyond 2^900 (likewise).
    points, triangles = arrays
    points = points * factor
    rng = np.random.default_rng(seed)
    span = float(np.ptp(points, axis=0).max()) or 1.0
    if request == "uniform":
        h = np.full(len(points), 0.1 * span)
    elif request == "graded":
        h = span * np.exp(rng.uniform(np.log(0.01), np.log(1.0), len(points)))
    else:
        h = np.full(len(points), 1e-300 * span)
    local = _core.edge_over_size_around(points, triangles, h)
    for above, below, at_least in thresholds_at(local, rng):
        assert np.array_equal(_core.edge_over_size_classes(points, triangles, h, above, below, at_least),
                              exact_classes(points, triangles, h, above, below, at_least))


@settings(max_examples=20)
@given(mesh_and_delta(), st.integers(0, 2**32 - 1))
def test_classes_on_grids_where_l_ties(case, seed):
    # Unjittered grids with a uniform request: many points share one L, so a
    # threshold on it puts whole rows of points in the band that needs hypot.
    mesh, delta = case
    points, triangles = np.asarray(mesh.points), np.asarray(mesh.triangles)
    rng = np.random.default_rng(seed)
    for h in (np.full(mesh.n_points, float(np.median(mesh.nn_spacing))), delta * mesh.nn_spacing):
        local = _core.edge_over_size_around(points, triangles, h)
        for above, below, at_least in thresholds_at(local, rng):
            assert np.array_equal(_core.edge_over_size_classes(points, triangles, h, above, below, at_least),
                                  exact_classes(points, triangles, h, above, below, at_least))


def test_classes_of_points_in_no_triangle_and_nan_thresholds():
    points = np.array([[0, 0], [1, 0], [0, 1], [5, 5]], float)
    triangles = np.array([[0, 1, 2]])
    h = np.ones(4)
    classes = _core.edge_over_size_classes(points, triangles, h, 0.5, 2.0, 1.0)
    assert classes[3] == 0  # L is NaN there
    assert np.array_equal(classes, exact_classes(points, triangles, h, 0.5, 2.0, 1.0))
    assert not _core.edge_over_size_classes(points, triangles, h, np.nan, np.nan, np.nan).any()


def numpy_sharing_a_triangle(triangles: np.ndarray, marked: np.ndarray) -> np.ndarray:
    """delta_from_size's too-fine points with a too-fine neighbour, as its numpy form found them."""
    with_another = marked[triangles].sum(axis=1) >= 2
    paired = np.zeros(len(marked), bool)
    paired[triangles[with_another].ravel()] = True
    return marked & paired


@settings(max_examples=20)
@given(any_meshes(), st.sampled_from([0.02, 0.2, 0.6]), st.integers(0, 2**32 - 1))
def test_sharing_a_triangle_is_the_numpy_form(mesh, share, seed):
    triangles = np.asarray(mesh.triangles)
    marked = np.random.default_rng(seed).random(mesh.n_points) < share
    got = _core.sharing_a_triangle(triangles, marked)
    assert got.dtype == np.uint8
    assert np.array_equal(got.view(bool), numpy_sharing_a_triangle(triangles, marked))


def numpy_reached(triangles: np.ndarray, seeds: np.ndarray, rings: int, through: np.ndarray) -> np.ndarray:
    """The points of `through` within `rings` edges of a seed along paths through them (seeds included)."""
    reached = seeds.copy()
    for _ in range(rings):
        star = np.zeros_like(reached)
        star[triangles[reached[triangles].any(axis=1)].ravel()] = True
        reached |= star & through
    return reached


def numpy_delta_from_size(mesh: evomesh.Mesh, size, keep_fine_clusters: bool = True) -> np.ndarray:
    """delta_from_size with every L exact, the comparisons, the pairing and the
    rings in numpy."""
    points, triangles = np.asarray(mesh.points), np.asarray(mesh.triangles)
    h = _size_values(mesh, size)
    local = _core.edge_over_size_around(points, triangles, h)
    nn = mesh.nn_spacing
    with np.errstate(over="ignore"):
        refine = h / (1.35 * nn)
        coarsen = np.maximum(1.0, h / nn)
    too_coarse = (local > 1.25) & (refine < 0.8)
    too_fine = local < 1 / 1.25
    meets = local >= 1 / 1.1
    if too_fine.any() and keep_fine_clusters:
        pocket = numpy_reached(triangles, meets, 3, np.ones_like(meets))
        coarsening = numpy_sharing_a_triangle(triangles, too_fine & ~pocket)
        too_fine = numpy_reached(triangles, coarsening, 3, too_fine)
    too_fine |= numpy_reached(triangles, too_fine, 1, ~meets)
    return np.where(too_coarse, refine, np.where(too_fine, coarsen, 1.0))


@settings(max_examples=25)
@given(mesh_and_delta(), st.booleans())
def test_delta_from_size_is_its_numpy_form(case, keep):
    mesh, delta = case
    nn = mesh.nn_spacing
    typical = float(np.median(nn))
    # per point (around the band's ends and across them), uniform (L ties on grids), a callable
    for size in (delta * nn, 1.25 * typical, lambda x: typical * (0.5 + x[:, 0] - x[:, 0].min())):
        assert np.array_equal(delta_from_size(mesh, size, keep_fine_clusters=keep),
                              numpy_delta_from_size(mesh, size, keep))
