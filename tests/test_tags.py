"""Tags and required points through steps, and meshio round trips."""

import warnings

import meshio
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import evomesh
import evomesh.io
from evomesh import Mesh, PointKind, _core
from invariants import check_valid_mesh
from strategies import grid_mesh, random_meshes


def tagged(mesh: Mesh, seed: int) -> Mesh:
    """The same mesh with segment tags by side, a split side, region tags and
    three required points."""
    rng = np.random.default_rng(seed)
    p, t, s = np.array(mesh.points), np.array(mesh.triangles), np.array(mesh.segments)
    lo, hi = p.min(axis=0), p.max(axis=0)
    mid = (p[s].mean(axis=1) - lo) / (hi - lo)
    segment_tags = np.select([mid[:, 1] < 0.5, mid[:, 0] > 0.5], [1 + (mid[:, 0] > 0.5), 3], 4)
    centre = (p[t].mean(axis=1) - lo) / (hi - lo)
    triangle_tags = np.where(np.hypot(*(centre - 0.5).T) < 0.3, 7, 8)
    required = np.zeros(len(p), bool)
    required[rng.choice(len(p), size=min(3, len(p)), replace=False)] = True
    return Mesh(p, t, s, segment_tags=segment_tags, triangle_tags=triangle_tags, required=required)


def check_labels(initial: Mesh, mesh: Mesh) -> None:
    """Tags against the initial mesh's geometry; required points present."""
    check_valid_mesh(mesh)
    mids = mesh.points[mesh.segments].mean(axis=1)
    a, b = initial.points[initial.segments[:, 0]], initial.points[initial.segments[:, 1]]
    d = b - a
    along = np.clip(np.einsum("qkj,kj->qk", mids[:, None] - a[None], d) / np.einsum("kj,kj->k", d, d)[None], 0, 1)
    nearest = np.linalg.norm(mids[:, None] - (a[None] + along[..., None] * d[None]), axis=2).argmin(axis=1)
    assert (mesh.segment_tags == initial.segment_tags[nearest]).all()
    found, _ = _core.locate_points(initial.points, initial.triangles, mesh.points[mesh.triangles].mean(axis=1))
    assert (found >= 0).all() and (mesh.triangle_tags == initial.triangle_tags[found]).all()
    for point in initial.points[initial.required]:
        row = np.flatnonzero((mesh.points == point).all(axis=1))
        assert len(row) == 1 and mesh.required[row[0]]


@settings(max_examples=6)
@given(random_meshes(max_points=80), st.integers(0, 2**16), st.sampled_from(["frfc", "drfc"]))
def test_tags_and_required_points_survive_twenty_steps(mesh, seed, method):
    initial = tagged(mesh, seed)
    current = initial
    for step in range(20):
        delta = np.full(current.n_points, 0.6 if step % 2 == 0 else 1.8)
        try:
            with warnings.catch_warnings():  # near-degenerate random clouds may defeat the quality pass
                warnings.simplefilter("ignore", evomesh.QualityWarning)
                current = evomesh.evolve(current, delta, method=method, seed=step)
        except ValueError as error:  # a random cloud may ask too much of float64 or of memory: refused, fine
            assert "max_samples" in str(error) or "not a valid mesh in float64" in str(error)
            break
        check_labels(initial, current)


def test_a_tag_change_is_a_kept_corner():
    mesh = grid_mesh(11, 11)
    s = np.array(mesh.segments)
    mid = mesh.points[s].mean(axis=1)
    tags = np.where(mid[:, 0] < 0.45, 1, 2)  # the bottom side changes tag at x = 0.4..0.5
    tagged_mesh = Mesh(mesh.points, mesh.triangles, s, segment_tags=tags)
    change = np.flatnonzero(np.isclose(mesh.points[:, 0], 0.4) & (mesh.points[:, 1] == 0))[0]
    assert tagged_mesh.kind[change] == PointKind.CORNER
    coarse = evomesh.evolve(tagged_mesh, 8.0)
    assert change in set(coarse.origin.tolist())


def test_triangle_tags_make_region_borders_constraints():
    mesh = grid_mesh(9, 9)
    tags = (mesh.points[mesh.triangles].mean(axis=1)[:, 0] > 0.5).astype(int)
    regions = Mesh(mesh.points, mesh.triangles, triangle_tags=tags)
    assert (~regions.segment_is_boundary).sum() == 8  # the border x = 0.5
    new = evomesh.evolve(regions, 5.0)
    centre_x = new.points[new.triangles].mean(axis=1)[:, 0]
    assert ((centre_x > 0.5) == (new.triangle_tags == 1)).all()


def test_label_arguments_are_checked():
    mesh = grid_mesh(5, 5)
    with pytest.raises(ValueError, match="segment_tags need segments"):
        Mesh(mesh.points, mesh.triangles, segment_tags=[1])
    with pytest.raises(ValueError, match="one tag per row of triangles"):
        Mesh(mesh.points, mesh.triangles, triangle_tags=[1, 2])
    with pytest.raises(TypeError, match="integer"):
        Mesh(mesh.points, mesh.triangles, triangle_tags=np.zeros(mesh.n_triangles))
    with pytest.raises(TypeError, match="boolean"):
        Mesh(mesh.points, mesh.triangles, required=np.zeros(mesh.n_points, int))


@pytest.mark.parametrize("suffix, file_format", [(".msh", "gmsh22"), (".msh", "gmsh"), (".vtu", None), (".xdmf", None)])
def test_meshio_round_trip_keeps_points_triangles_and_tags(tmp_path, suffix, file_format):
    """Gmsh 2.2 and 4.1 (meshio's default for .msh), VTU, XDMF. Triangles come back grouped by tag (one cell
    block per tag, which Gmsh 4.1 needs), each the same row with the same tag."""
    mesh = tagged(grid_mesh(8, 8, jitter=0.2, seed=3), seed=1)
    mesh = evomesh.evolve(mesh, 0.7, seed=0)
    path = tmp_path / f"mesh{suffix}"
    mesh.to_meshio().write(path, file_format=file_format)
    back = Mesh.from_meshio(meshio.read(path))
    assert np.array_equal(back.points, mesh.points)
    rows = lambda m: dict(zip(map(tuple, m.triangles.tolist()), m.triangle_tags.tolist()))  # noqa: E731
    assert back.n_triangles == mesh.n_triangles and rows(back) == rows(mesh)
    key = lambda m: {tuple(sorted(e)): t for e, t in zip(m.segments.tolist(), m.segment_tags.tolist())}  # noqa: E731
    assert key(back) == key(mesh)
    assert np.array_equal(back.required, mesh.required)
    assert np.array_equal(back.kind, mesh.kind)


def test_from_meshio_drops_an_orphan_and_refuses_lifted_points():
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 0]])
    with pytest.warns(UserWarning, match="removed 1 points"):
        mesh = Mesh.from_meshio(meshio.Mesh(points, [("triangle", np.array([[0, 1, 2]]))]))
    assert mesh.n_points == 3
    points[1, 2] = 0.5
    with pytest.raises(ValueError, match="z != 0"):
        Mesh.from_meshio(meshio.Mesh(points[:3], [("triangle", np.array([[0, 1, 2]]))]))
    with pytest.raises(ValueError, match="quad"):
        Mesh.from_meshio(meshio.Mesh(np.c_[points[:, :2], np.zeros(4)], [("quad", np.array([[0, 1, 3, 2]]))]))


def test_write_and_read_mesh_keep_tags(tmp_path):
    mesh = tagged(grid_mesh(7, 7), seed=2)
    path = evomesh.io.write_mesh(tmp_path / "m.vtu", mesh, {"u": mesh.points[:, 0]})
    back, data = evomesh.io.read_mesh(path)
    rows = lambda m: dict(zip(map(tuple, m.triangles.tolist()), m.triangle_tags.tolist()))  # noqa: E731
    assert rows(back) == rows(mesh) and back.required.sum() == 3
    assert set(data) == {"u"}


CHECKPOINT_ARRAYS = ("points", "triangles", "segments", "segment_is_boundary", "kind", "segment_tags",
                     "triangle_tags", "required")


@pytest.mark.parametrize("suffix", [".msh", ".vtu"])
def test_write_and_read_mesh_make_a_checkpoint(tmp_path, suffix):
    # A step depends on the order of the triangles and segments and on kind: a
    # mesh read back has them all, so it steps to the same bits as the mesh in memory.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", evomesh.QualityWarning)
        mesh = evomesh.evolve(tagged(grid_mesh(16, 16, jitter=0.2, seed=3), seed=1), 0.7, seed=0)
        mesh = evomesh.evolve(mesh, np.where(mesh.points[:, 0] < 0.5, 0.8, 1.0), seed=1).with_tag_names(NAMES)
        back, _ = evomesh.io.read_mesh(evomesh.io.write_mesh(tmp_path / f"m{suffix}", mesh))
        for name in CHECKPOINT_ARRAYS:
            assert np.array_equal(getattr(back, name), getattr(mesh, name)), name
        assert dict(back.tag_names) == NAMES and np.array_equal(back.nn_spacing, mesh.nn_spacing)
        delta = np.where(mesh.points[:, 1] < 0.4, 0.6, 1.3)
        for options in ({}, {"options": evomesh.FrfcOptions.paper()}):
            a, b = (evomesh.evolve(m, delta, seed=5, **options) for m in (mesh, back))
            for name in CHECKPOINT_ARRAYS + ("origin",):
                assert np.array_equal(getattr(a, name), getattr(b, name)), name
            assert np.array_equal(a.lineage.parent_triangle, b.lineage.parent_triangle)
            assert np.array_equal(a.lineage.barycentric, b.lineage.barycentric)


NAMES = {(1, 1): "bottom", (1, 3): "right", (2, 7): "inside", (2, 8): "outside <&> ü",
         (1, evomesh.INTERFACE_TAG): "interface"}


def test_tag_names_survive_interfaces_motion_refinement_and_files(tmp_path, capsys):
    # Names are kept by every kind of step (an interface's tag is named when the
    # mesh names it, here before it exists), in Gmsh and VTU files, and shown by info.
    from evomesh.cli import main

    mesh = tagged(grid_mesh(14, 14, jitter=0.2, seed=4), seed=5).with_tag_names(NAMES)
    assert dict(mesh.tag_names) == NAMES
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", evomesh.QualityWarning)
        cut = evomesh.evolve(mesh, size=0.1, interface=lambda x: np.hypot(*(x - 0.5).T) - 0.15,
                             interface_regions=(7, 8))
        moved = evomesh.evolve(cut, size=0.1, displacement=lambda x: 0.02 * np.c_[x[:, 1] * (1 - x[:, 1]),
                                                                                   np.zeros(len(x))])
        refined = evomesh.delaunay_refine(moved, 0.6)
    for out in (cut, moved, refined, evomesh.motion.move(mesh, (0.5, 0.0)).mesh):
        assert dict(out.tag_names) == NAMES
    assert (cut.segment_tags == evomesh.INTERFACE_TAG).any()
    for suffix in (".vtu", ".msh"):
        path = evomesh.io.write_mesh(tmp_path / f"m{suffix}", refined)
        back, _ = evomesh.io.read_mesh(path)
        assert dict(back.tag_names) == NAMES, suffix
    assert main(["info", str(tmp_path / "m.vtu")]) == 0
    printed = capsys.readouterr().out
    count = int((refined.segment_tags == evomesh.INTERFACE_TAG).sum())
    assert f'{evomesh.INTERFACE_TAG} "interface": {count}' in printed
    assert f'7 "inside": {int((refined.triangle_tags == 7).sum())}' in printed
    assert '(named, unused: 3 "right")' not in printed  # (the right side is still tagged 3)
    assert f'3 "right": {int((refined.segment_tags == 3).sum())}' in printed


def test_with_tag_names_checks_the_names_and_shares_the_arrays():
    mesh = evomesh.unit_square_mesh(100)
    named = mesh.with_tag_names({(1, 0): "wall"})
    assert named.points is mesh.points and named.nn_spacing is mesh.nn_spacing
    assert dict(named.tag_names) == {(1, 0): "wall"} and not mesh.tag_names
    with pytest.raises(ValueError, match="dim must be 1"):
        mesh.with_tag_names({(3, 0): "x"})


def test_cell_transfer_is_conservative_per_region_over_steps():
    mesh = tagged(grid_mesh(12, 12, jitter=0.2, seed=5), seed=3)
    values = np.sin(7 * mesh.points[mesh.triangles].mean(axis=1)[:, 0]) + 2.0
    totals = {tag: float((mesh.triangle_areas * values)[mesh.triangle_tags == tag].sum()) for tag in (7, 8)}
    for step in range(10):
        new = evomesh.evolve(mesh, 0.6 if step % 2 == 0 else 1.8, seed=step)
        values = evomesh.transfer_cells(mesh, new, values)
        mesh = new
        for tag, total in totals.items():
            now = float((mesh.triangle_areas * values)[mesh.triangle_tags == tag].sum())
            assert abs(now - total) <= 1e-12 * abs(total), (step, tag, now, total)


def test_interface_region_tags_in_stats_are_exact_ints():
    mesh = evomesh.unit_square_mesh(300)
    big = 2**60 + 1  # (a float holds 2**60 exactly, not 2**60 + 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", evomesh.QualityWarning)
        out = evomesh.evolve(mesh, size=0.08, interface=lambda x: np.hypot(*(x - 0.5).T) - 0.2,
                             interface_regions=(big, big + 2))
    for name, tag in (("interface_negative_tag", big), ("interface_positive_tag", big + 2)):
        assert type(out.stats[name]) is int and out.stats[name] == tag
    assert set(out.triangle_tags.tolist()) == {big, big + 2}
