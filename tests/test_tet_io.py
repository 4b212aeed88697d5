"""Tetrahedral meshes in files (.msh, .vtu, .mesh) and pickles: tags, tag
names and labels kept, a file is a checkpoint, bad files a clear ValueError."""

from __future__ import annotations

import copy
import pickle

import meshio
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import evomesh
import evomesh.io
from evomesh.io import read_mesh, write_mesh


def box_side(mesh: evomesh.TetMesh) -> np.ndarray:
    """1..6: the side of the unit cube each face lies on."""
    centre = mesh.points[mesh.faces].mean(axis=1)
    axis = np.argmax(np.abs(centre - 0.5), axis=1)
    return 1 + 2 * axis + (centre[np.arange(len(centre)), axis] > 0.5)


def tagged_cube(n: int = 3) -> evomesh.TetMesh:
    cube = evomesh.unit_cube_mesh(n)
    left = cube.points[cube.tetrahedra].mean(axis=1)[:, 0] < 0.5
    required = np.zeros(cube.n_points, bool)
    required[[5, 17]] = True
    return evomesh.TetMesh(cube.points, cube.tetrahedra, cube.faces, face_tags=box_side(cube),
                           tet_tags=np.where(left, 7, 8), required=required,
                           tag_names={(2, 1): "x = 0", (3, 7): "left", (3, 8): "right"})


def assert_same(a: evomesh.TetMesh, b: evomesh.TetMesh, labels: bool = True) -> None:
    assert np.array_equal(a.points.view(np.uint64), b.points.view(np.uint64))
    assert np.array_equal(a.tetrahedra, b.tetrahedra)
    assert np.array_equal(a.faces, b.faces)
    assert np.array_equal(a.face_tags, b.face_tags) and np.array_equal(a.tet_tags, b.tet_tags)
    if labels:
        assert np.array_equal(a.kind, b.kind) and np.array_equal(a.origin, b.origin)
        assert np.array_equal(a.required, b.required)
        assert dict(a.tag_names) == dict(b.tag_names)


@pytest.mark.parametrize("suffix", [".msh", ".vtu", ".mesh"])
def test_round_trip_keeps_cells_tags_and_labels(tmp_path, suffix):
    mesh = tagged_cube()
    before = {name: np.array(getattr(mesh, name)) for name in ("points", "tetrahedra", "faces", "face_tags")}
    u = mesh.points @ [1.0, 2.0, 3.0]
    path = write_mesh(tmp_path / f"cube{suffix}", mesh, None if suffix == ".mesh" else {"u": u})
    back, data = read_mesh(path)
    assert isinstance(back, evomesh.TetMesh)
    # Medit holds the cells and their tags only
    assert_same(mesh, back, labels=suffix != ".mesh")
    if suffix == ".mesh":
        assert not back.tag_names and data == {}
    else:
        assert np.array_equal(data["u"], u)
    for name, array in before.items():
        assert np.array_equal(getattr(mesh, name), array)


@pytest.mark.parametrize("suffix", [".msh", ".vtu"])
def test_a_file_is_a_checkpoint(tmp_path, suffix):
    cube = evomesh.unit_cube_mesh(4)
    cube = evomesh.TetMesh(cube.points, cube.tetrahedra, cube.faces, face_tags=box_side(cube),
                           tag_names={(2, 3): "y = 0"})
    first = evomesh.evolve(cube, 0.7, seed=3)
    back, _ = read_mesh(write_mesh(tmp_path / f"step{suffix}", first))
    assert_same(first, back)
    again, resumed = evomesh.evolve(first, 1.3, seed=4), evomesh.evolve(back, 1.3, seed=4)
    assert_same(again, resumed)
    assert dict(resumed.tag_names) == {(2, 3): "y = 0"}


def test_pickle_and_copies_keep_every_bit():
    mesh = evomesh.evolve(evomesh.unit_cube_mesh(3), 0.8, seed=1)
    back = pickle.loads(pickle.dumps(mesh))
    assert_same(mesh, back)
    assert back.lineage is not None and np.array_equal(back.lineage.parent_tet, mesh.lineage.parent_tet)
    assert copy.copy(mesh) is mesh
    assert_same(copy.deepcopy(mesh), mesh)
    tagged = tagged_cube()
    assert_same(pickle.loads(pickle.dumps(tagged)), tagged)


@settings(max_examples=8)
@given(st.lists(st.integers(-(2**31), 2**31 - 1), min_size=2, max_size=2, unique=True),
       st.text(st.characters(min_codepoint=32, max_codepoint=126, exclude_characters='"<&'), min_size=1, max_size=8))
def test_any_int32_tags_and_names_round_trip(tmp_path_factory, tags, name):
    cube = evomesh.unit_cube_mesh(2)
    face_tags = np.where(box_side(cube) % 2 == 0, tags[0], tags[1])
    mesh = evomesh.TetMesh(cube.points, cube.tetrahedra, cube.faces, face_tags=face_tags,
                           tet_tags=np.full(cube.n_tetrahedra, tags[1]), tag_names={(3, tags[1]): name})
    folder = tmp_path_factory.mktemp("tags")
    for suffix in (".msh", ".vtu", ".mesh"):
        back, _ = read_mesh(write_mesh(folder / f"m{suffix}", mesh))
        assert_same(mesh, back, labels=suffix != ".mesh")


def test_to_meshio_groups_cells_by_tag_and_from_meshio_reads_them_back():
    mesh = tagged_cube()
    m = evomesh.io.to_meshio(mesh, {"u": np.arange(mesh.n_points)})
    assert [block.type for block in m.cells] == ["tetra", "tetra"] + ["triangle"] * 6
    back = evomesh.TetMesh.from_meshio(m)
    assert np.array_equal(np.sort(back.tet_tags), np.sort(mesh.tet_tags))
    assert dict(back.tag_names) == dict(mesh.tag_names) and back.n_tetrahedra == mesh.n_tetrahedra


def test_boundary_faces_a_file_leaves_out_get_tag_0(tmp_path):
    cube = evomesh.unit_cube_mesh(2)
    first_side = box_side(cube) == 1
    path = tmp_path / "partial.mesh"
    meshio.Mesh(cube.points, [("tetra", cube.tetrahedra), ("triangle", cube.faces[first_side])],
                cell_data={"medit:ref": [np.ones(cube.n_tetrahedra, int), np.full(first_side.sum(), 5)]}).write(path)
    mesh, _ = read_mesh(path)
    assert len(mesh.faces) == len(cube.faces)
    assert (mesh.face_tags == 5).sum() == first_side.sum() and (mesh.face_tags == 0).sum() == (~first_side).sum()


def test_bad_files_and_requests_raise_value_errors(tmp_path):
    cube = evomesh.unit_cube_mesh(2)
    garbage = tmp_path / "garbage.msh"
    garbage.write_text("$MeshFormat\nnot a mesh\n")
    with pytest.raises(ValueError, match="garbage.msh"):
        read_mesh(garbage)
    hexahedra = tmp_path / "hex.vtu"
    meshio.Mesh(cube.points, [("tetra", cube.tetrahedra), ("hexahedron", np.arange(8)[None])]).write(hexahedra)
    with pytest.raises(ValueError, match="hexahedron"):
        read_mesh(hexahedra)
    inverted = tmp_path / "inverted.vtu"
    meshio.Mesh(cube.points, [("tetra", cube.tetrahedra[:, [1, 0, 2, 3]])]).write(inverted)
    with pytest.raises(ValueError, match="inverted"):
        read_mesh(inverted)
    with pytest.raises(ValueError, match="Medit files hold no point data"):
        write_mesh(tmp_path / "a.mesh", cube, {"u": np.zeros(cube.n_points)})
    huge = evomesh.TetMesh(cube.points, cube.tetrahedra, tet_tags=np.full(cube.n_tetrahedra, 2**40))
    for suffix in (".msh", ".mesh"):
        with pytest.raises(ValueError, match="32-bit"):
            write_mesh(tmp_path / f"huge{suffix}", huge)
    assert not (tmp_path / "huge.msh").exists()
    back, _ = read_mesh(write_mesh(tmp_path / "huge.vtu", huge))  # VTU holds 64-bit tags
    assert (back.tet_tags == 2**40).all()
    with pytest.raises(ValueError, match="dim must be 2"):
        evomesh.TetMesh(cube.points, cube.tetrahedra, tag_names={(1, 1): "edge"})
