"""Domains at the edge of what float64 resolves (found by the long hypothesis
profile of test_fuzz.py, 2026-12-01; the meshes are in tests/data/fuzz_*.npz).

* A domain that nearly touches itself across its outside: the fuzzer's
  "move-point-onto-edge" put boundary corner 6 within 0.3 units of rounding of
  boundary edge (1, 8). No triangle witnesses that gap, so Mesh()'s flatness
  limit let it through, and a step then split the edge at a rounded midpoint on
  or across the corner (CGAL's "Unauthorized intersections of constraints"
  escaped as RuntimeError, or two output points were equal). Mesh() now asks of
  such gaps what it asks of triangle heights: 1024 units of rounding.
* A DRFC step on a 12-point mesh whose quality pass cascaded towards a small
  angle (a domain wedge of 12.5 degrees between two holes touching at its apex)
  until triangles were 779 units of rounding high. The edge at that apex outside
  the small angle's cluster saw the domain only, and CGAL's concentric shells
  never reduced the cluster; every constraint edge at such an apex now keeps the
  two-sided encroachment test. As a safety net the angle rule stops below a
  height of 16 * 1024 units of rounding (C++ test_triangulation).
* Chains of steps on a domain with a thin notch (an outer angle of 1e-12 rad)
  met the opposite case: there the two-sided test made the notch's sides
  encroach each other until they met. A cluster with no wedge of the domain now
  sees the domain only.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import evomesh
from evomesh import PointKind, _core
from invariants import check_evolved, check_valid_mesh

DATA = Path(__file__).parent / "data"
EPS = np.finfo(float).eps


def _pinched_case(name: str):
    case = np.load(DATA / f"fuzz_point_on_edge_{name}.npz")
    return case["points"], case["triangles"], case["delta"], int(case["seed"])


def _rewrapped(mesh: evomesh.Mesh) -> evomesh.Mesh:
    """A step's output given back to Mesh() as a user would: it must be accepted."""
    return evomesh.Mesh(mesh.points, mesh.triangles, mesh.segments, segment_tags=mesh.segment_tags,
                        triangle_tags=mesh.triangle_tags, required=mesh.required, kind=mesh.kind)


@pytest.mark.parametrize("name", ["crossing_pieces", "duplicate_output"])
def test_a_domain_that_nearly_touches_itself_is_refused(name: str) -> None:
    points, triangles, _, _ = _pinched_case(name)
    before = points.copy()
    with pytest.raises(ValueError, match=r"nearly touches itself: boundary corner 6 is .* from boundary edge \(1, 8\)"):
        evomesh.Mesh(points, triangles)
    assert np.array_equal(points, before)


def _moved_off_the_edge(gap: float) -> tuple[np.ndarray, np.ndarray]:
    """The fuzzer's mesh with corner 6 moved `gap` off edge (1, 8), into the domain:
    an outer angle of about gap / 0.46 at corner 8."""
    points, triangles, _, _ = _pinched_case("crossing_pieces")
    a, b = points[1], points[8]
    u = (b - a) / np.linalg.norm(b - a)
    normal = np.array([-u[1], u[0]])
    side = np.sign(np.dot(points[9] - a, normal))
    moved = points.copy()
    moved[6] = a + np.dot(points[6] - a, u) * u + side * gap * normal
    return moved, triangles


@pytest.mark.parametrize("gap", [1e-14, 2e-13])
def test_gaps_below_1024_units_of_rounding_are_refused(gap: float) -> None:
    with pytest.raises(ValueError, match="nearly touches itself"):
        evomesh.Mesh(*_moved_off_the_edge(gap))


@pytest.mark.parametrize("gap", [3e-13, 1e-11, 1e-10, 1e-6])
@pytest.mark.parametrize("method", ["frfc", "drfc"])
def test_steps_near_a_tiny_outer_angle_stay_valid(gap: float, method: str) -> None:
    # Just above the limit the domain is accepted; steps keep it, and their
    # outputs (with new points on the sides of the angle, close to the other
    # side) are accepted by Mesh() again, step after step.
    mesh = evomesh.Mesh(*_moved_off_the_edge(gap))
    rng = np.random.default_rng(7)
    for seed in range(6):
        delta = np.exp(rng.uniform(np.log(0.3), np.log(3.0), mesh.n_points))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", evomesh.QualityWarning)
            new = evomesh.evolve(mesh, delta, method=method, seed=seed)
        check_evolved(mesh, new, rel_area=1e-9, rel_distance=1e-9)
        mesh = _rewrapped(new)


def test_drfc_on_a_small_angle_between_two_holes_stays_above_the_flatness_limit() -> None:
    case = np.load(DATA / "fuzz_drfc_thin_output.npz")
    mesh = evomesh.Mesh(case["points"], case["triangles"])
    for method in ("drfc", "frfc"):
        new = evomesh.evolve(mesh, case["delta"], method=method, seed=int(case["seed"]))
        check_evolved(mesh, new, rel_area=1e-9, rel_distance=1e-9)
        _rewrapped(new)
        # No cascade into the apex (it reached 9e-12 from it, 156 points):
        # the nearest point is at the spacing of the step, and the smallest
        # angle is the domain's own 12.54 degrees there.
        apex = mesh.points[6]
        gaps = np.linalg.norm(new.points - apex, axis=1)
        assert np.sort(gaps)[1] > 1e-4
        assert evomesh.quality(new).min_angle > 12.5
        assert new.n_points < 400


def _pinches_by_brute_force(points, boundary, corner, min_ulps):
    """(edge, corner) as _core.first_pinched_boundary defines it, in numpy."""
    a, b = points[boundary[:, 0]], points[boundary[:, 1]]
    on_boundary = np.zeros(len(points), bool)
    on_boundary[boundary.ravel()] = True
    candidates = np.flatnonzero(on_boundary & corner.astype(bool))
    for s in range(len(boundary)):
        q = points[candidates]
        d = b[s] - a[s]
        t = np.clip(((q - a[s]) @ d) / (d @ d), 0.0, 1.0)
        gap = np.hypot(*(q - a[s] - t[:, None] * d).T)
        reach = np.maximum(np.abs(q).max(axis=1), max(np.abs(a[s]).max(), np.abs(b[s]).max()))
        ratio = gap / (EPS * reach)
        ok = (candidates != boundary[s, 0]) & (candidates != boundary[s, 1]) & (ratio < min_ulps)
        if ok.any():
            best = min(zip(ratio[ok], candidates[ok]))
            return s, int(best[1])
    return -1, -1


@given(st.integers(4, 60), st.integers(0, 2**32 - 1), st.floats(1e12, 1e15), st.floats(0.0, 1.0))
def test_the_pinch_search_finds_what_brute_force_finds(n: int, seed: int, min_ulps: float, corner_share: float):
    # Random polylines (no need for a valid domain: the search is about distances),
    # at scales where many pairs are within min_ulps units of rounding.
    rng = np.random.default_rng(seed)
    points = rng.uniform(-1, 1, (n, 2)) * 10.0 ** rng.integers(-3, 4)
    order = rng.permutation(n)
    boundary = np.stack([order, np.roll(order, -1)], axis=1)[: rng.integers(1, n + 1)]
    corner = (rng.uniform(size=n) < corner_share).astype(np.uint8)
    expected = _pinches_by_brute_force(points, boundary, corner, min_ulps)
    got = _core.first_pinched_boundary(points, boundary, corner, min_ulps)
    if expected[0] >= 0 or got[0] >= 0:
        # Ratios within rounding of min_ulps may fall either way (numpy's and C++'s
        # distances differ by an ulp or two); otherwise the answer is the same.
        assert got[0] == expected[0] and got[1] == expected[1]


def test_the_limit_is_in_units_of_rounding_not_absolute() -> None:
    # The same shape far from the origin has a larger unit of rounding: a gap of
    # 1e-6 is 1e8 units at |x| ~ 1 but 4.5 units at |x| ~ 1e9.
    points, triangles = _moved_off_the_edge(1e-6)
    evomesh.Mesh(points, triangles)
    with pytest.raises(ValueError, match="nearly touches itself"):
        evomesh.Mesh(points + 1e9, triangles)
    kind = evomesh.Mesh(points, triangles).kind
    assert (kind[[1, 6, 8]] == PointKind.CORNER).all()
    check_valid_mesh(evomesh.Mesh(points, triangles))


def test_the_core_says_valueerror_when_its_constraint_pieces_cross() -> None:
    # Below Mesh(): the core given the pinched mesh anyway (as a caller of
    # _core could) raises a ValueError naming the crossing, not CGAL's bare
    # "Unauthorized intersections of constraints" RuntimeError.
    points, triangles, delta, seed = _pinched_case("crossing_pieces")
    tris, segs, boundary, kind, *_ = _core.prepare_mesh(points, triangles, None, True, None, None)
    options = evomesh.FrfcOptions()
    options.seed = seed
    with pytest.raises(ValueError, match="constraint pieces of the step's mesh cross"):
        _core.frfc(points, tris, segs, boundary.astype(np.uint8), kind, delta, options)


def test_a_sliver_reaching_a_close_pair_is_sampled_by_f_not_by_its_vertices() -> None:
    # The long hypothesis profile of test_defects.py: a 33-point random mesh
    # with two points 8.4e-5 apart and a 0.0075 degree sliver from them across
    # the domain. delta = 0.5 was refused ("sampling would create about 5e+07
    # points"); with max_samples raised it drew 9.5e7 samples in 76 s for 610
    # output points. Grid blocks are now sized by f at their centres: 14k.
    case = np.load(DATA / "fuzz_sliver_refinement.npz")
    mesh = evomesh.Mesh(case["points"], case["triangles"], case["segments"], kind=case["kind"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", evomesh.QualityWarning)
        new = evomesh.evolve(mesh, np.full(mesh.n_points, float(case["delta"])))
    check_evolved(mesh, new)
    assert new.stats["n_candidates"] < 1e5
    assert evomesh.quality(new).min_angle > 29
