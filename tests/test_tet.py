"""Tetrahedral meshes: TetMesh validation, the exact cone envelope f, and the
FRFC step on boxes (validity, quality, lineage, determinism, transfer)."""

from __future__ import annotations

import numpy as np
import pytest

import evomesh
from evomesh import _core
from evomesh.tet_mesh import boundary_faces, dihedral_angles, radius_edge_ratios

BOX = (np.array([0.0, 0.0, 0.0]), np.array([1.0, 1.0, 1.0]))


def check_tet_mesh(mesh: evomesh.TetMesh, lo: np.ndarray, hi: np.ndarray) -> None:
    """Every property a mesh of the box [lo, hi] must have."""
    p, t = mesh.points, mesh.tetrahedra
    assert (_core.tet_orientations(p, t) == 1).all()
    volume = mesh.volumes
    assert (volume > 0).all()
    box_volume = np.prod(hi - lo)
    assert abs(volume.sum() - box_volume) <= 1e-12 * box_volume
    # no orphan or duplicate points
    assert (np.bincount(t.ravel(), minlength=len(p)) > 0).all()
    assert len(np.unique(p, axis=0)) == len(p)
    # the boundary triangles cover exactly the six faces: each lies on one,
    # and their areas per face add up to the face's
    faces, _ = boundary_faces(t)
    q = p[faces]
    area = 0.5 * np.linalg.norm(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), axis=1)
    side = np.full(len(faces), -1)
    for axis in range(3):
        for high, bound in ((0, lo[axis]), (1, hi[axis])):
            on = (q[:, :, axis] == bound).all(axis=1)
            assert not (on & (side >= 0)).any()
            side[on] = 2 * axis + high
            others = [a for a in range(3) if a != axis]
            face_area = np.prod(hi[others] - lo[others])
            assert abs(area[on].sum() - face_area) <= 1e-12 * face_area
    assert (side >= 0).all()
    # the mesh's own faces default to those boundary triangles
    assert len(mesh.faces) == len(faces)


def check_step(old: evomesh.TetMesh, new: evomesh.TetMesh) -> None:
    lo, hi = old.points.min(0), old.points.max(0)
    check_tet_mesh(new, lo, hi)
    kept = new.origin >= 0
    # kept points bit for bit, at most once each; box corners always kept
    assert np.array_equal(new.points[kept].view(np.uint64), old.points[new.origin[kept]].view(np.uint64))
    assert len(np.unique(new.origin[kept])) == kept.sum()
    corners = np.flatnonzero(old.kind == evomesh.TetPointKind.CORNER)
    assert len(corners) == 8 and np.isin(corners, new.origin).all()
    assert radius_edge_ratios(new.points, new.tetrahedra).max() <= 2.0
    # every new point lies in (or on) its parent old tetrahedron
    fresh = ~kept
    parent = new.lineage.parent_tet[fresh]
    assert (parent >= 0).all() and (new.lineage.parent_tet[kept] == -1).all()
    corners_of = old.points[old.tetrahedra[parent]]
    a = np.stack([corners_of[:, k] - corners_of[:, 0] for k in (1, 2, 3)], axis=2)
    lam = np.linalg.solve(a, (new.points[fresh] - corners_of[:, 0])[:, :, None])[:, :, 0]
    assert (lam >= -1e-12).all() and (lam.sum(1) <= 1 + 1e-12).all()


# --- TetMesh --------------------------------------------------------------


def test_unit_cube_mesh_is_a_valid_box_mesh():
    mesh = evomesh.unit_cube_mesh(3)
    assert mesh.n_tetrahedra == 6 * 27 and mesh.n_points == 64
    check_tet_mesh(mesh, *BOX)
    kinds = np.bincount(mesh.kind, minlength=6)
    assert kinds[evomesh.TetPointKind.CORNER] == 8 and kinds[evomesh.TetPointKind.EDGE] == 24
    assert kinds[evomesh.TetPointKind.FACE] == 24 and kinds[evomesh.TetPointKind.ORIGINAL] == 8
    again = evomesh.TetMesh(mesh.points, mesh.tetrahedra)
    assert np.array_equal(again.faces, mesh.faces)


def test_box_mesh_has_exact_faces():
    mesh = evomesh.box_mesh((-0.3, 0.1, 2.0), (0.7, 0.35, 2.9), (3, 2, 4))
    check_tet_mesh(mesh, np.array([-0.3, 0.1, 2.0]), np.array([0.7, 0.35, 2.9]))


def test_tet_mesh_is_immutable_and_leaves_the_input_alone():
    mesh = evomesh.unit_cube_mesh(2)
    points, tets = mesh.points.copy(), mesh.tetrahedra.copy()
    before = points.copy()
    built = evomesh.TetMesh(points, tets)
    assert np.array_equal(points, before)
    with pytest.raises(AttributeError):
        built.points = points
    with pytest.raises(ValueError):
        built.points[0, 0] = 5.0


def _cube():
    mesh = evomesh.unit_cube_mesh(2)
    return mesh.points.copy(), mesh.tetrahedra.copy()


def test_bad_input_raises_clear_errors():
    points, tets = _cube()
    with pytest.raises(ValueError, match="inverted"):
        evomesh.TetMesh(points, tets[:, [0, 2, 1, 3]])
    flat = points.copy()
    flat[tets[0, 3]] = flat[tets[0, 0]] + 0.5 * (flat[tets[0, 1]] - flat[tets[0, 0]])
    with pytest.raises(ValueError, match="flat|duplicate|overlap|inverted"):
        evomesh.TetMesh(flat, tets)
    nan = points.copy()
    nan[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        evomesh.TetMesh(nan, tets)
    with pytest.raises(ValueError, match="repeats a vertex"):
        evomesh.TetMesh(points, np.vstack([tets, [[0, 0, 1, 2]]]))
    with pytest.raises(ValueError, match="more than once"):
        evomesh.TetMesh(points, np.vstack([tets, tets[:1]]))
    with pytest.raises(ValueError, match="orphan"):
        evomesh.TetMesh(np.vstack([points, [[5.0, 5.0, 5.0]]]), tets)
    with pytest.raises(ValueError, match="duplicates"):
        dup = np.concatenate([[len(points)], tets[0, 1:]])
        evomesh.TetMesh(np.vstack([points, points[tets[0, :1]]]), np.vstack([tets, [dup]]))
    with pytest.raises(TypeError):
        evomesh.TetMesh(points.astype(str), tets)
    with pytest.raises(TypeError):
        evomesh.TetMesh(points, tets.astype(float))
    with pytest.raises(ValueError, match="shape"):
        evomesh.TetMesh(points[:, :2], tets)
    with pytest.raises(ValueError, match="out of range"):
        evomesh.TetMesh(points, tets + 100)
    with pytest.raises(ValueError, match="not a triangle of the mesh"):
        evomesh.TetMesh(points, tets, faces=[[0, 1, 26]])


def test_non_manifold_triangle_raises():
    # three tetrahedra on the triangle (0, 1, 2): two above it, one below
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 1], [0.3, 0.3, -1], [0.25, 0.2, 2]], float)
    tets = np.array([[0, 1, 2, 3], [0, 2, 1, 4], [0, 1, 2, 5]])
    with pytest.raises(ValueError, match="shared by 3 tetrahedra"):
        evomesh.TetMesh(points, tets)
    with pytest.raises(ValueError, match="same side"):
        evomesh.TetMesh(points[[0, 1, 2, 3, 5]], np.array([[0, 1, 2, 3], [0, 1, 2, 4]]))


# --- f by branch and bound -------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_cone_envelope_equals_brute_force_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    sites = rng.random((3000, 3))
    sites[:200] = np.round(sites[:200] * 4) / 4  # ties on a lattice
    sites = np.unique(sites, axis=0)
    nn = _core.tet_nn_spacing(sites)
    delta = np.exp(rng.uniform(np.log(0.25), np.log(4.0), len(sites)))
    weights = delta * nn
    queries = np.vstack([rng.random((3000, 3)), sites[:500], rng.random((200, 3)) * 3 - 1])
    fast, evaluations = _core.cone_envelope_3(sites, weights, queries, False, 2)
    slow, _ = _core.cone_envelope_3(sites, weights, queries, True, 2)
    assert np.array_equal(fast.view(np.uint64), slow.view(np.uint64))
    assert evaluations / len(queries) < len(sites) / 10  # the bound prunes


def test_nn_spacing_matches_brute_force():
    rng = np.random.default_rng(5)
    points = rng.random((500, 3))
    d = np.linalg.norm(points[:, None] - points[None], axis=2)
    np.fill_diagonal(d, np.inf)
    assert np.allclose(_core.tet_nn_spacing(points), d.min(1), rtol=0, atol=1e-15)


# --- the step ---------------------------------------------------------------


@pytest.fixture(scope="module")
def cube():
    return evomesh.unit_cube_mesh(6)


@pytest.mark.parametrize("delta", [0.5, 1.0, 2.0])
def test_uniform_steps_are_valid(cube, delta):
    new = evomesh.evolve(cube, delta, seed=1)
    check_step(cube, new)
    assert new.stats["kept_old_points"] > 0


def test_graded_step_then_another_is_valid(cube):
    x = cube.points
    delta = np.where(np.linalg.norm(x - 0.5, axis=1) < 0.3, 0.4, 1.5)
    new = evomesh.evolve(cube, delta, seed=3)
    check_step(cube, new)
    again = evomesh.evolve(new, 1.2, seed=4)
    check_step(new, again)
    assert (again.kind[again.origin < 0] != evomesh.TetPointKind.ORIGINAL).all()


def test_size_request_keeps_the_mesh_near_the_size(cube):
    def h(x):
        return np.minimum(0.2, 0.05 + 0.3 * np.abs(np.linalg.norm(x - [0.4, 0.5, 0.5], axis=1) - 0.2))

    new = evomesh.evolve(cube, size=h, seed=0)
    check_step(cube, new)
    second = evomesh.evolve(new, size=h, seed=1)
    check_step(new, second)
    assert second.n_points > 0.8 * new.n_points  # no drift coarser
    assert second.stats["kept_fraction"] > 0.5
    tolerant = evomesh.evolve(new, size=h, seed=1, size_tolerance=1.4)
    check_step(new, tolerant)


def test_deterministic_across_thread_counts(cube):
    delta = np.linspace(0.4, 2.0, cube.n_points)
    one = evomesh.evolve(cube, delta, seed=7, threads=1)
    two = evomesh.evolve(cube, delta, seed=7, threads=2)
    assert np.array_equal(one.points.view(np.uint64), two.points.view(np.uint64))
    assert np.array_equal(one.tetrahedra, two.tetrahedra)
    assert np.array_equal(one.origin, two.origin)
    refine = 0.4 + 0.2 * cube.points[:, 0]
    a, b = (evomesh.evolve(cube, refine, seed=s) for s in (8, 9))
    assert a.n_points != b.n_points or not np.array_equal(a.points, b.points)  # the seed matters


def test_transfer_is_exact_for_linear_fields(cube):
    new = evomesh.evolve(cube, 0.6, seed=2)
    u = 1.5 - 2.0 * cube.points[:, 0] + 0.25 * cube.points[:, 1] + 3.0 * cube.points[:, 2]
    v = evomesh.transfer(cube, new, u)
    expected = 1.5 - 2.0 * new.points[:, 0] + 0.25 * new.points[:, 1] + 3.0 * new.points[:, 2]
    assert np.allclose(v, expected, rtol=0, atol=1e-13)
    kept = new.origin >= 0
    assert np.array_equal(v[kept], u[new.origin[kept]])
    both = evomesh.transfer(cube, new, {"u": u, "uu": np.stack([u, 2 * u], axis=1)})
    assert both["uu"].shape == (new.n_points, 2)
    with pytest.raises(ValueError, match="lineage"):
        evomesh.transfer(new, cube, v)


def test_step_rejects_bad_requests(cube):
    with pytest.raises(ValueError, match="delta"):
        evomesh.evolve(cube, np.full(cube.n_points, np.nan))
    with pytest.raises(ValueError, match="exactly one"):
        evomesh.evolve(cube, 1.0, size=0.1)
    with pytest.raises(ValueError, match="max_samples"):
        evomesh.evolve(cube, 0.01, max_samples=1e4)
    with pytest.raises(TypeError, match="unknown option"):
        evomesh.evolve(cube, 1.0, min_angle=20.0)
    with pytest.raises(ValueError, match="size"):
        evomesh.evolve(cube, size=lambda x: -np.ones(len(x)))
    def fails_at_samples(x):  # the error raised inside the step's callback reaches the caller
        return np.full(len(x), 0.2) if len(x) == cube.n_points else 1 / 0

    with pytest.raises(ZeroDivisionError):
        evomesh.evolve(cube, size=fails_at_samples)


def test_step_refuses_a_domain_that_is_not_convex():
    mesh = evomesh.unit_cube_mesh(2)
    keep = mesh.points[mesh.tetrahedra].mean(axis=1).sum(axis=1) < 1.6  # a corner cut off
    tets = mesh.tetrahedra[keep]
    used = np.unique(tets)
    remap = np.full(mesh.n_points, -1)
    remap[used] = np.arange(len(used))
    cut = evomesh.TetMesh(mesh.points[used], remap[tets])  # a staircase: not convex
    with pytest.raises(ValueError, match="convex"):
        evomesh.evolve(cut, 1.0)


def test_quality_measures_on_a_regular_tetrahedron():
    points = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    tet = np.array([[0, 1, 2, 3]])
    if _core.tet_orientations(points, tet)[0] < 0:
        tet = tet[:, [0, 2, 1, 3]]
    assert np.allclose(radius_edge_ratios(points, tet), np.sqrt(6) / 4)
    assert np.allclose(dihedral_angles(points, tet), np.degrees(np.arccos(1 / 3)))


def test_sliver_pass_moves_only_new_points(cube):
    def h(x):
        return np.minimum(0.12, 0.03 + 0.3 * np.abs(np.linalg.norm(x - [0.4, 0.5, 0.5], axis=1) - 0.2))

    plain = evomesh.evolve(cube, size=h, seed=5, sliver_angle=0)
    treated = evomesh.evolve(cube, size=h, seed=5)
    check_step(cube, treated)
    # the same packing: the same old points kept, at the same places
    assert np.array_equal(np.sort(plain.origin[plain.origin >= 0]), np.sort(treated.origin[treated.origin >= 0]))
    assert treated.stats["slivers_after"] < treated.stats["slivers_before"]
    dihedral = dihedral_angles(treated.points, treated.tetrahedra)
    assert (dihedral < 10).mean() < (dihedral_angles(plain.points, plain.tetrahedra) < 10).mean()


def test_no_sliver_is_left_on_a_moving_sphere():
    # A small moving sphere: every step's tetrahedra have all their dihedral
    # angles within [10, 170] degrees and radius-edge at most 2, with the old
    # points kept where they were (the same case without the pass has slivers).
    def size_at(centre):
        return lambda x: np.minimum(0.1, 0.03 + 0.3 * np.abs(np.linalg.norm(x - centre, axis=1) - 0.2))

    mesh = evomesh.unit_cube_mesh(5)
    for step in range(4):
        h = size_at(np.array([0.3 + 0.1 * max(step - 1, 0), 0.5, 0.5]))
        new = evomesh.evolve(mesh, size=h, seed=step)
        check_step(mesh, new)
        dihedral = dihedral_angles(new.points, new.tetrahedra)
        assert dihedral.min() >= 10 and dihedral.max() <= 170, (step, dihedral.min(), dihedral.max())
        assert radius_edge_ratios(new.points, new.tetrahedra).max() <= 2
        assert new.stats["slivers_after"] == 0 and new.stats["radius_edge_unresolved"] == 0
        mesh = new
    plain = evomesh.evolve(mesh, size=h, seed=9, sliver_angle=0)
    assert dihedral_angles(plain.points, plain.tetrahedra).min() < 10


def test_points_stay_where_the_request_changes_little():
    # A mesh settled on h, then a request 1.15 times coarser (within the
    # default size_tolerance 1.25): nearly every point stays; with the
    # tolerance off the packing drops many of them.
    def h(x):
        return 0.06 + 0.1 * x[:, 0]

    def coarser(x):
        return 1.15 * h(x)

    mesh = evomesh.evolve(evomesh.evolve(evomesh.unit_cube_mesh(6), size=h, seed=0), size=h, seed=1)
    new = evomesh.evolve(mesh, size=coarser, seed=2)
    check_step(mesh, new)
    assert new.stats["kept_fraction"] >= 0.9
    assert evomesh.evolve(mesh, size=coarser, seed=2, size_tolerance=1).stats["kept_fraction"] < 0.75


def test_face_tags_follow_the_box_sides():
    mesh = evomesh.unit_cube_mesh(4)
    faces, _ = boundary_faces(mesh.tetrahedra)
    q = mesh.points[faces]
    side = np.full(len(faces), -1)
    for axis in range(3):
        for high, bound in ((0, 0.0), (1, 1.0)):
            side[(q[:, :, axis] == bound).all(axis=1)] = 2 * axis + high
    tagged = evomesh.TetMesh(mesh.points, mesh.tetrahedra, faces, face_tags=10 + side)
    new = evomesh.evolve(tagged, 0.6, seed=0)
    p = new.points[new.faces]
    for axis in range(3):
        for high, bound in ((0, 0.0), (1, 1.0)):
            on = (p[:, :, axis] == bound).all(axis=1)
            assert on.any() and (new.face_tags[on] == 10 + 2 * axis + high).all()
    mixed = side.copy()
    mixed[0] = 99
    with pytest.raises(ValueError, match="vary within facet"):
        evomesh.evolve(evomesh.TetMesh(mesh.points, mesh.tetrahedra, faces, face_tags=mixed), 1.0)


def test_required_points_are_kept_under_coarsening():
    mesh = evomesh.unit_cube_mesh(5)
    required = np.zeros(mesh.n_points, bool)
    required[[43, 93]] = True  # interior points; required points near a box edge can leave a tetrahedron above 2
    tagged = evomesh.TetMesh(mesh.points, mesh.tetrahedra, required=required)
    new = evomesh.evolve(tagged, 3.0, seed=0)
    check_step(tagged, new)
    assert np.isin(np.flatnonzero(required), new.origin).all()
    assert np.array_equal(np.sort(new.origin[new.required]), np.flatnonzero(required))
