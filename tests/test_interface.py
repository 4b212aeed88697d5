"""Level-set interfaces: evolve(mesh, ..., interface=phi)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

import evomesh
from evomesh.interface import INTERFACE_TAG, _Polyline, cut_mesh
from evomesh.meshgen import HOLE_TAG, disc_with_hole_mesh
from invariants import check_valid_mesh, distance_to_segments


def circle(cx: float, cy: float, r: float):
    return lambda x: np.hypot(x[:, 0] - cx, x[:, 1] - cy) - r


def interface_segments(mesh: evomesh.Mesh, tag: int = INTERFACE_TAG) -> np.ndarray:
    return mesh.segments[(mesh.segment_tags == tag) & ~mesh.segment_is_boundary]


def check_interface(mesh: evomesh.Mesh, phi, *, tol: float | None = 1e-12, min_angle: float | None = 30.0,
                    singular: np.ndarray | None = None, radius: float = 0.0) -> None:
    """What every interface step must give (what the docstring promises):
    everywhere but within ``radius`` of the ``singular`` points of phi = 0
    (kinks, touching points), where the zero set is not a smooth curve."""
    check_valid_mesh(mesh)
    # valid for Mesh(): the same arrays are accepted as a user's mesh
    evomesh.Mesh(mesh.points, mesh.triangles, mesh.segments, segment_tags=mesh.segment_tags,
                 triangle_tags=mesh.triangle_tags)
    segments = interface_segments(mesh)
    assert len(segments)

    def smooth(x: np.ndarray) -> np.ndarray:
        if singular is None:
            return np.ones(len(x), dtype=bool)
        return np.hypot(*(x[:, None, :] - np.asarray(singular)[None]).transpose(2, 0, 1)).min(axis=1) > radius

    on_interface = mesh.points[np.unique(segments)]
    scale = float(np.abs(mesh.points).max())
    if tol is not None:
        assert np.abs(phi(on_interface[smooth(on_interface)])).max() <= tol * scale
    # no triangle straddles it: the tag is the side of phi at the centroid
    negative_tag = int(mesh.stats["interface_negative_tag"])
    positive_tag = int(mesh.stats["interface_positive_tag"])
    assert set(np.unique(mesh.triangle_tags)) <= {negative_tag, positive_tag}
    centroid = mesh.points[mesh.triangles].mean(axis=1)
    where = smooth(centroid)
    assert ((mesh.triangle_tags == negative_tag) == (phi(centroid) < 0))[where].all()
    # closed curves, or ends on the boundary (or at other constraints)
    degree = np.bincount(segments.ravel(), minlength=mesh.n_points)
    on_other = np.zeros(mesh.n_points, dtype=bool)
    others = ~((mesh.segment_tags == INTERFACE_TAG) & ~mesh.segment_is_boundary)
    on_other[mesh.segments[others].ravel()] = True
    assert (degree[~on_other] % 2 == 0).all()
    if min_angle is not None:
        angles = evomesh.mesh_quality.triangle_angles(mesh.points, mesh.triangles).min(axis=1)
        assert angles[where].min() >= min_angle - 1e-9


def test_circle_interface_points_lie_on_phi_zero_and_triangles_on_their_side() -> None:
    mesh = evomesh.unit_square_mesh(2000)
    phi = circle(0.5, 0.5, 0.3)
    new = evomesh.evolve(mesh, 1.0, interface=phi)
    check_interface(new, phi)
    assert new.stats["interface_negative_tag"] == 1 and new.stats["interface_positive_tag"] == 0
    assert new.stats["min_angle"] >= 30.0 - 1e-9


def test_point_values_give_the_piecewise_linear_zero_set() -> None:
    mesh = evomesh.unit_square_mesh(2000)
    phi = circle(0.45, 0.55, 0.27)
    values = phi(mesh.points)
    before = values.copy()
    new = evomesh.evolve(mesh, 1.0, interface=values)
    assert (values == before).all()  # inputs are never modified
    check_interface(new, phi, tol=None)
    # every interface point lies on the zero set of the old mesh's interpolant
    line = cut_mesh(mesh, values).curve
    assert isinstance(line, _Polyline)
    points = new.points[np.unique(interface_segments(new))]
    gap, _ = line.distance_and_closest(points)
    assert gap.max() <= 1e-12
    # a callable on the same zero set lands within the interpolation error
    assert np.abs(phi(points)).max() <= (np.median(mesh.nn_spacing) ** 2) / (8 * 0.27) * 4


@pytest.mark.parametrize("kind", ["callable", "values"])
def test_interface_converges_to_the_circle_at_second_order(kind: str) -> None:
    centre, radius = np.array([0.5, 0.5]), 0.3
    phi = circle(*centre, radius)
    angles = np.linspace(0, 2 * np.pi, 4000, endpoint=False)
    on_circle = centre + radius * np.c_[np.cos(angles), np.sin(angles)]
    spacing, longest, distance = [], [], []
    for n in (1000, 4000, 16000):
        mesh = evomesh.unit_square_mesh(n)
        new = evomesh.evolve(mesh, 1.0, interface=phi if kind == "callable" else phi(mesh.points))
        segments = interface_segments(new)
        a, b = new.points[segments[:, 0]], new.points[segments[:, 1]]
        s = np.linspace(0, 1, 17)[None, :, None]
        from_polyline = np.abs(phi((a[:, None] + s * (b - a)[:, None]).reshape(-1, 2))).max()
        from_circle = distance_to_segments(on_circle, a, b).max()
        distance.append(max(from_polyline, from_circle))  # Hausdorff distance (sampled)
        longest.append(np.hypot(*(b - a).T).max())
        spacing.append(np.median(mesh.nn_spacing))
    slope_longest = np.polyfit(np.log(longest), np.log(distance), 1)[0]
    slope_spacing = np.polyfit(np.log(spacing), np.log(distance), 1)[0]
    assert 1.7 <= slope_longest <= 2.3, slope_longest
    assert 1.6 <= slope_spacing <= 2.4, slope_spacing


def test_growing_circle_keeps_points_and_conserves_integrals_per_region() -> None:
    """The paper's growing circle with the circle in the mesh: moving by half a
    band width per step, at least 60% of the old points stay, and the
    conservative transfers keep the integral (and each region's share) to 1e-12."""
    warnings.simplefilter("error")
    mesh = evomesh.unit_square_mesh(1096)
    h_max = float(np.median(mesh.nn_spacing))
    band, h_min = 0.12, 0.011
    cells = 1.0 + mesh.points[mesh.triangles].mean(axis=1)[:, 0]
    nodal = np.sin(3 * mesh.points[:, 0]) * np.cos(2 * mesh.points[:, 1]) + 2.0
    r = 0.05
    for _ in range(6):
        phi = circle(0.5, 0.5, r)
        new = evomesh.evolve(mesh, size=h_max, interface=phi, interface_band=(band, h_min, 0.5))
        check_interface(new, phi)
        assert (new.origin >= 0).sum() >= 0.6 * mesh.n_points
        moved_cells = evomesh.transfer_cells(mesh, new, cells)
        before, after = (mesh.triangle_areas * cells).sum(), (new.triangle_areas * moved_cells).sum()
        assert abs(after - before) <= 1e-12 * abs(before)
        moved_nodal = evomesh.transfer(mesh, new, nodal, method="conservative")
        before = (mesh.triangle_areas * nodal[mesh.triangles].mean(axis=1)).sum()
        after = (new.triangle_areas * moved_nodal[new.triangles].mean(axis=1)).sum()
        assert abs(after - before) <= 1e-12 * abs(before)
        # per region: what each old region holds goes somewhere, what each new one holds came from somewhere
        exchange = evomesh.region_exchange(mesh, new, cells)
        scale = abs((mesh.triangle_areas * cells).sum())
        for k, tag in enumerate(exchange.tags):
            total = (mesh.triangle_areas * cells)[mesh.triangle_tags == tag].sum()
            assert abs(exchange.integral[k].sum() + exchange.integral_lost[k] - total) <= 1e-12 * scale
            total = (new.triangle_areas * moved_cells)[new.triangle_tags == tag].sum()
            assert abs(exchange.integral[:, k].sum() + exchange.integral_gained[k] - total) <= 1e-12 * scale
        # the sides keep their tags (inside 1, outside 0); the circle grew: material went from outside to
        # inside only, the area of the annulus it swept
        assert list(np.unique(new.triangle_tags)) == [0, 1]
        if len(np.unique(mesh.triangle_tags)) == 2:
            tags = list(exchange.tags)
            outside, inside = tags.index(0), tags.index(1)
            swept = np.pi * (r**2 - (r - band / 2) ** 2)
            assert exchange.area[inside, outside] == 0 and abs(exchange.area[outside, inside] - swept) <= 0.05 * swept
            assert exchange.integral[inside, outside] == 0 and exchange.integral[outside, inside] > 0
        mesh, cells, nodal = new, moved_cells, moved_nodal
        r += band / 2


def test_lineage_covers_the_cut() -> None:
    mesh = evomesh.unit_square_mesh(1500)
    new = evomesh.evolve(mesh, 0.8, interface=circle(0.4, 0.6, 0.25))
    assert new.lineage is not None and new.lineage.matches(mesh)
    interpolation = evomesh.field_transfer.Interpolation(mesh, new)
    assert interpolation.used_lineage
    linear = 3.0 * mesh.points[:, 0] - 2.0 * mesh.points[:, 1] + 0.5
    assert np.allclose(interpolation(linear), 3.0 * new.points[:, 0] - 2.0 * new.points[:, 1] + 0.5,
                       rtol=0, atol=1e-13)
    located = new.lineage.parent_triangle >= 0
    assert located[new.origin < 0].all()


def test_a_second_step_releases_the_previous_interface() -> None:
    mesh = evomesh.unit_square_mesh(2000)
    first = evomesh.evolve(mesh, 1.0, interface=circle(0.5, 0.5, 0.2))
    phi = circle(0.55, 0.5, 0.25)
    second = evomesh.evolve(first, 1.0, interface=phi)
    check_interface(second, phi)
    # the first interface's points that are not on the second one became interior points (or were removed)
    old_interface = np.unique(interface_segments(first))
    survivors = np.flatnonzero(np.isin(second.origin, old_interface))
    on_new = np.zeros(second.n_points, dtype=bool)
    on_new[interface_segments(second).ravel()] = True
    assert not on_new[survivors].any()
    assert (second.kind[survivors] >= evomesh.PointKind.ORIGINAL).all()
    # the tags of the two sides carry over
    assert second.stats["interface_negative_tag"] == first.stats["interface_negative_tag"]
    # the same interface again moves nothing off it: its points stay where they are
    again = evomesh.evolve(second, 1.0, interface=phi)
    check_interface(again, phi)
    assert again.stats["interface_crossings"] == 0


def test_interface_ends_on_the_boundary_and_crosses_a_hole() -> None:
    square = evomesh.unit_square_mesh(1500)
    phi = circle(0.0, 0.4, 0.45)  # meets the bottom side at 27 degrees: angles below 30 there
    check_interface(evomesh.evolve(square, 1.0, interface=phi), phi, min_angle=None)
    disc = disc_with_hole_mesh(0.06)
    line = lambda x: x[:, 1] - 0.3 * x[:, 0] - 0.05  # noqa: E731  (crosses the hole and the outer circle)
    new = evomesh.evolve(disc, 1.0, interface=line)
    check_interface(new, line, min_angle=None)
    ends = np.unique(interface_segments(new))
    on_hole = np.unique(new.segments[new.segment_tags == HOLE_TAG])
    assert np.isin(on_hole, ends).sum() == 2  # the line enters and leaves the hole
    assert abs(new.area - disc.area) <= 1e-12 * disc.area


def test_interface_with_a_curved_boundary() -> None:
    disc = disc_with_hole_mesh(0.06)
    geometry = evomesh.BoundaryGeometry({HOLE_TAG: evomesh.Circle((0, 0), 0.35)})
    phi = circle(0.6, 0.0, 0.2)
    new = evomesh.evolve(disc, 1.5, interface=phi, geometry=geometry)
    check_interface(new, phi, min_angle=None)
    hole = np.unique(new.segments[new.segment_tags == HOLE_TAG])
    assert np.abs(np.hypot(*new.points[hole].T) - 0.35).max() <= 1e-12
    with pytest.raises(ValueError, match="interface's tag"):
        evomesh.evolve(disc, 1.0, interface=phi, interface_tag=HOLE_TAG, geometry=geometry)


def test_phi_zero_exactly_at_points_and_along_whole_edges() -> None:
    mesh = evomesh.unit_square_mesh(1500, jitter=0.0)
    row = np.unique(mesh.points[:, 1])[10]
    phi = lambda x: x[:, 1] - row  # noqa: E731  (zero at every point of a lattice row, along its edges)
    cut = cut_mesh(mesh, phi)
    assert cut.n_crossings == 0  # the interface is made of old edges
    new = evomesh.evolve(mesh, 1.0, interface=phi)
    check_interface(new, phi, tol=0.0)
    assert np.isin(np.flatnonzero(mesh.points[:, 1] == row), new.origin).all()
    # zero at single points only, where phi touches 0 without changing sign: no interface there
    kink = circle(0.5, 0.5, 0.3)
    vertex = mesh.points[np.argmin(np.abs(kink(mesh.points)))]
    touching = lambda x: np.minimum(kink(x), np.hypot(*(x - vertex).T))  # noqa: E731
    new = evomesh.evolve(mesh, 1.0, interface=touching)
    check_interface(new, touching, tol=1e-12)


def test_two_circles_merge_and_split() -> None:
    mesh = evomesh.unit_square_mesh(3000)
    negative_components = []
    for distance in (0.5, 0.34, 0.3, 0.26, 0.3, 0.34, 0.5):
        phi = lambda x, d=distance: np.minimum(circle(0.5 - d / 2, 0.5, 0.15)(x),  # noqa: E731
                                               circle(0.5 + d / 2, 0.5, 0.15)(x))
        if distance == 0.3:
            # touching: phi = 0 has a cusp (two notches of zero angle), which the
            # cut follows into the spacing; the angles there are reported
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", evomesh.QualityWarning)
                mesh = evomesh.evolve(mesh, 1.0, interface=phi)
        else:
            mesh = evomesh.evolve(mesh, 1.0, interface=phi)
        # where the circles touch or cross, phi = 0 is not a smooth curve: its kinks
        half_chord = np.sqrt(max(0.15**2 - (distance / 2) ** 2, 0.0))
        kinks = np.array([[0.5, 0.5 - half_chord], [0.5, 0.5 + half_chord]])
        check_interface(mesh, phi, singular=kinks, radius=0.05)
        inside = np.flatnonzero(mesh.triangle_tags == mesh.stats["interface_negative_tag"])
        negative_components.append(_components(mesh, inside))
    # apart, touching (either), merged, touching, apart
    assert negative_components == [2, 2, negative_components[2], 1, negative_components[4], 2, 2]


def _components(mesh: evomesh.Mesh, triangles: np.ndarray) -> int:
    t = mesh.triangles[triangles]
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(len(t)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    same = np.flatnonzero((edges[order][1:] == edges[order][:-1]).all(axis=1))
    graph = coo_matrix((np.ones(len(same)), (owner[order][same], owner[order][same + 1])), shape=(len(t), len(t)))
    return connected_components(graph, directed=False)[0]


def test_regions_band_and_tag_are_the_users() -> None:
    mesh = evomesh.unit_square_mesh(1500)
    phi = circle(0.5, 0.5, 0.25)
    new = evomesh.evolve(mesh, 1.0, interface=phi, interface_tag=7, interface_regions=(4, 9),
                         interface_band=(0.1, 0.008))
    assert set(np.unique(new.triangle_tags)) == {4, 9}
    assert len(new.segments[new.segment_tags == 7]) and not (new.segment_tags == INTERFACE_TAG).any()
    centroid = new.points[new.triangles].mean(axis=1)
    assert ((new.triangle_tags == 4) == (phi(centroid) < 0)).all()
    # the band: spacing near the interface is the band's, far from it the mesh's
    near = np.abs(phi(new.points)) < 0.03
    assert np.median(new.nn_spacing[near]) <= 1.3 * 0.008
    far = np.abs(phi(new.points)) > 0.3
    assert np.median(new.nn_spacing[far]) >= 0.8 * np.median(mesh.nn_spacing)


def test_the_same_step_gives_the_same_bits() -> None:
    mesh = evomesh.unit_square_mesh(1200)
    phi = circle(0.5, 0.45, 0.3)
    a = evomesh.evolve(mesh, 0.7, interface=phi, seed=3)
    b = evomesh.evolve(mesh, 0.7, interface=phi, seed=3, threads=1)
    for name in ("points", "triangles", "segments", "segment_tags", "triangle_tags", "origin", "kind"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(a.lineage.barycentric, b.lineage.barycentric)


def _arrays(mesh: evomesh.Mesh) -> list[np.ndarray]:
    return [mesh.points, mesh.triangles, mesh.segments, mesh.triangle_tags, mesh.segment_tags, mesh.kind]


@pytest.mark.parametrize(
    "interface, message",
    [
        (lambda x: np.hypot(*(x - 0.5).T) + 1.0, "does not change sign"),
        (lambda x: np.where(x[:, 0] > 0.9, np.nan, x[:, 0] - 0.5), "finite"),
        (lambda x: np.where(x[:, 0] > 0.9, np.inf, x[:, 0] - 0.5), "finite"),
        (lambda x: x[:, 0] ** 2, "does not change sign"),  # zero along a side only
        (circle(0.5, 0.5, 0.5), "tangent"),  # touches the four sides
        (circle(0.5, 0.5, 0.4995), "tangent"),  # nearly: within the spacing without crossing
        (lambda x: np.zeros(len(x) + 1), "shape"),
        (lambda x: np.array(["a"] * len(x)), "real"),
        (np.zeros(3), "one value per mesh point"),
        (np.r_[np.full(1097, -1.0), np.nan], "finite"),
        (np.r_[np.full(1097, -1.0), np.inf], "finite"),
        (np.r_[np.full(1097, -1.0), 0.0], "does not change sign"),
    ],
)
def test_bad_interfaces_are_refused_and_nothing_is_lost(interface, message) -> None:  # type: ignore[no-untyped-def]
    mesh = evomesh.unit_square_mesh(1096)
    assert mesh.n_points == 1098
    before = [a.copy() for a in _arrays(mesh)]
    with pytest.raises((ValueError, TypeError), match=message):
        evomesh.evolve(mesh, 1.0, interface=interface)
    assert all(np.array_equal(a, b) for a, b in zip(_arrays(mesh), before))


@pytest.mark.parametrize("angle, refused", [(2.0, True), (4.0, True), (8.0, False), (30.0, False)])
def test_an_interface_meeting_the_boundary_at_a_small_angle_is_tangent(angle: float, refused: bool) -> None:
    mesh = evomesh.unit_square_mesh(1096)
    slope = np.tan(np.radians(angle))
    phi = lambda x: x[:, 1] - slope * (x[:, 0] - 0.5)  # noqa: E731  (leaves the bottom side at `angle`)
    if refused:
        with pytest.raises(ValueError, match="tangent"):
            evomesh.evolve(mesh, 1.0, interface=phi)
    else:
        check_interface(evomesh.evolve(mesh, 1.0, interface=phi), phi, min_angle=None)


def test_argument_checks() -> None:
    mesh = evomesh.unit_square_mesh(500)
    phi = circle(0.5, 0.5, 0.3)
    with pytest.raises(ValueError, match="frfc"):
        evomesh.evolve(mesh, 1.0, interface=phi, method="drfc")
    with pytest.raises(TypeError, match="need interface"):
        evomesh.evolve(mesh, 1.0, interface_tag=3)
    with pytest.raises(TypeError, match="interface_tag"):
        evomesh.evolve(mesh, 1.0, interface=phi, interface_tag=1.5)
    with pytest.raises(TypeError, match="interface_regions"):
        evomesh.evolve(mesh, 1.0, interface=phi, interface_regions=3)
    with pytest.raises(TypeError, match="interface_band"):
        evomesh.evolve(mesh, 1.0, interface=phi, interface_band=(0.1,))
    with pytest.raises(ValueError, match="spacing"):
        evomesh.evolve(mesh, 1.0, interface=phi, interface_band=(0.1, -1.0))
    with pytest.raises(TypeError, match="exactly one"):
        evomesh.evolve(mesh, interface=phi)
    with pytest.raises(ValueError, match="delta"):
        evomesh.evolve(mesh, 1e9, interface=phi)


def test_level_set_projection() -> None:
    level = evomesh.LevelSet(circle(0.0, 0.0, 1.0))
    x = np.array([[2.0, 0.5], [-0.3, 0.1], [0.0, -0.7]])
    on = level.project(x)
    assert np.abs(np.hypot(*on.T) - 1.0).max() <= 4e-16
    with pytest.raises(ValueError, match="zero gradient"):
        evomesh.LevelSet(lambda p: (p**2).sum(axis=1) - 1.0).project(np.array([[0.0, 0.0]]))
    with pytest.raises(TypeError):
        evomesh.LevelSet(3.0)  # type: ignore[arg-type]


@given(cx=st.floats(0.2, 0.8), cy=st.floats(0.2, 0.8), r=st.floats(0.05, 0.6), coarsen=st.sampled_from([0.7, 1.0, 1.6]))
def test_random_circles(cx: float, cy: float, r: float, coarsen: float) -> None:
    mesh = evomesh.unit_square_mesh(700)
    phi = circle(cx, cy, r)
    try:
        new = evomesh.evolve(mesh, coarsen, interface=phi)
    except ValueError as error:  # only the documented refusals
        assume("tangent" not in str(error) and "change sign" not in str(error))
        raise
    # near the boundary the interface meets it at small angles: angles only where it is inside
    inside = np.hypot(*(mesh.points - [cx, cy]).T).max() > r and min(cx, cy, 1 - cx, 1 - cy) > r + 0.05
    check_interface(new, phi, min_angle=30.0 if inside else None)
