"""Hostile inputs to the CLI, the files, the tags and the curves."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import evomesh
from evomesh.cli import _size_expression, main
from evomesh.meshgen import polygon_mesh
from invariants import check_valid_mesh

# --------------------------------------------------------------------------------------------------
# evomesh adapt --size-expr: a safe evaluator with bounds


@pytest.mark.parametrize("text", ["9**9**9", "1/0", "e**1000", "10**400", "1e400", "(1/0)*x", "x" * 10**6,
                                  "-" * 900 + "1", "sqrt(x, y)", "clip(x, a_min=0)", "x.real", "__import__('os')",
                                  "lambda: 1", "[x][0]", "'a'", "x if x else y", "sqrt"])
def test_size_expression_refused_before_any_work(text):
    """Refused when parsed, before any point is seen: 9**9**9 no longer runs for ever in Python integers."""
    with pytest.raises(ValueError, match="--size-expr"):
        _size_expression(text)


@pytest.mark.parametrize("text, message", [
    ("1/(x - x)", "gives inf"), ("log(x - 10)", "gives nan"), ("exp(1000*x)", "gives inf"),
    ("0.05 - x", "finite number > 0"), ("x - x", "finite number > 0"),
])
def test_size_expression_judged_at_the_points(text, message):
    size = _size_expression(text)
    points = np.array([[0.0, 0.0], [0.5, 0.25], [1.0, 1.0]])
    with pytest.raises(ValueError, match=message):
        size(points)


@pytest.fixture
def square_file(tmp_path):
    path = tmp_path / "square.vtu"
    evomesh.io.write_mesh(path, evomesh.unit_square_mesh(120))
    return path


@pytest.mark.parametrize("text", ["9**9**9", "1/0", "e**1000", "x" * 10**6, "1/(x - x)", "log(x - 10)",
                                  "0.05 - x"])
def test_adapt_bad_size_expression_is_one_line_and_exit_2(square_file, tmp_path, capsys, text):
    out = tmp_path / "out.vtu"
    assert main(["adapt", str(square_file), str(out), "--size-expr", text, "--quiet"]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("evomesh: error: --size-expr") and len(error.splitlines()) == 1, error
    assert not out.exists()


def test_size_expression_means_what_numpy_means():
    points = np.random.default_rng(1).uniform(0.1, 1.0, (50, 2))
    x, y = points.T
    cases = {
        "0.02 + 0.05*x": 0.02 + 0.05 * x,
        "where(x < 0.5, 0.01, 0.02)": np.where(x < 0.5, 0.01, 0.02),
        "where(0.3 < x < 0.6, 0.01, 0.02)": np.where((0.3 < x) & (x < 0.6), 0.01, 0.02),
        "clip(hypot(x - 0.5, y - 0.5), 0.01, 0.1)": np.clip(np.hypot(x - 0.5, y - 0.5), 0.01, 0.1),
        "2**-3 * pi / e + x**0.5": 2**-3 * np.pi / np.e + x**0.5,
        "-(-x) + abs(sin(y))": x + np.abs(np.sin(y)),
    }
    for text, expected in cases.items():
        assert np.allclose(_size_expression(text)(points), expected, rtol=1e-15, atol=0), text


_NAMES = ("abs", "sqrt", "exp", "log", "log10", "sin", "cos", "tan", "tanh", "arctan2", "hypot", "minimum",
          "maximum", "clip", "where")
_ARITY = {"arctan2": 2, "hypot": 2, "minimum": 2, "maximum": 2, "clip": 3, "where": 3}


def _expressions() -> st.SearchStrategy[str]:
    leaves = st.one_of(
        st.sampled_from(["x", "y", "pi", "e"]),
        st.floats(0, 1e3, allow_nan=False).map(repr),
        st.integers(0, 12).map(lambda k: f"{k}.0"),  # floats in the text: the reference never runs a big int power
    )

    def extend(inner: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
        binary = st.tuples(inner, st.sampled_from(["+", "-", "*", "/", "**"]), inner).map(
            lambda t: f"({t[0]} {t[1]} {t[2]})")
        unary = inner.map(lambda a: f"(-{a})")
        call = st.sampled_from(_NAMES[:-1]).flatmap(
            lambda name: st.lists(inner, min_size=_ARITY.get(name, 1), max_size=_ARITY.get(name, 1)).map(
                lambda args: f"{name}({', '.join(args)})"))
        # comparisons as where's condition (numpy would compute sqrt(x < y) in float16)
        where = st.tuples(inner, st.sampled_from(["<", ">=", "<="]), inner, inner, inner).map(
            lambda t: f"where({t[0]} {t[1]} {t[2]}, {t[3]}, {t[4]})")
        return st.one_of(binary, unary, call, where)

    return st.recursive(leaves, extend, max_leaves=12)


@given(_expressions())
def test_size_expression_agrees_with_numpy_or_says_why(text):
    """Whatever the expression: a ValueError, or the values numpy computes for the same text (finite, > 0)."""
    points = np.array([[0.0, 0.0], [0.25, 0.5], [1.0, 0.75], [3.0, -2.0]])
    try:
        values = _size_expression(text)(points)
    except ValueError:
        return
    assert values.shape == (4,) and np.isfinite(values).all() and (values > 0).all()
    namespace = {name: getattr(np, name) for name in _NAMES} | {"pi": math.pi, "e": math.e}
    namespace |= {"x": points[:, 0], "y": points[:, 1]}
    try:
        with np.errstate(all="ignore"):
            reference = eval(text, {"__builtins__": {}}, namespace)  # noqa: S307 -- text made by the test
    except (OverflowError, ZeroDivisionError):
        return  # Python floats raise where numpy gives inf: the constant part was folded by numpy rules
    assert np.allclose(values, np.broadcast_to(reference, (4,)), rtol=1e-12, atol=0), text


# --------------------------------------------------------------------------------------------------
# Curves: a coarse polygon of the curve is that curve


def _regular_polygon(n: int, radius: float = 1.0) -> np.ndarray:
    angle = 2 * np.pi * np.arange(n) / n
    return radius * np.c_[np.cos(angle), np.sin(angle)]


@pytest.mark.parametrize("sides, spacing", [(12, 0.1), (12, 0.05), (24, 0.1), (24, 0.05)])
def test_polygon_of_a_circle_evolves_with_that_circle(sides, spacing):
    """The chords of a 12-gon stray 3.4 % of the radius from its circle, more than a fine spacing near them:
    the points a step puts on them move that far onto the circle, and that is no sign of a wrong curve."""
    mesh = polygon_mesh([_regular_polygon(sides)], spacing)
    geometry = {0: evomesh.Circle((0, 0), 1.0)}
    for delta in (0.5, 0.5, 2.0):
        mesh = evomesh.evolve(mesh, delta, geometry=geometry)
        check_valid_mesh(mesh)
        assert mesh.euler_characteristic() == 1
        on_boundary = np.unique(mesh.segments[mesh.segment_is_boundary])
        radius = np.hypot(*mesh.points[on_boundary].T)
        new = mesh.origin[on_boundary] < 0
        # new boundary points lie on the circle; kept ones where they were (on the 12-gon)
        assert np.abs(radius[new] - 1).max() <= 1e-14
        assert new.any() and (radius[~new] <= 1 + 1e-14).all()
        assert mesh.stats["curve_largest_move"] <= 1 - math.cos(math.pi / sides) + 1e-12


@pytest.mark.parametrize("curve", [evomesh.Circle((0, 0), 1.2), evomesh.Circle((0.3, 0), 1.0)])
def test_another_circle_is_still_refused(curve):
    mesh = polygon_mesh([_regular_polygon(12)], 0.1)
    with pytest.raises(ValueError, match="is this the curve"):
        evomesh.evolve(mesh, 0.5, geometry={0: curve})


def test_a_curve_for_a_tag_the_mesh_lacks_is_refused():
    mesh = polygon_mesh([_regular_polygon(12)], 0.2)
    with pytest.raises(ValueError, match="segment tag 7 has a curve, but no segment of the mesh has that tag"):
        evomesh.evolve(mesh, 1.0, geometry={0: evomesh.Circle((0, 0), 1.0), 7: evomesh.Circle((0, 0), 0.5)})


# --------------------------------------------------------------------------------------------------
# write_mesh: checked first, written beside the file and renamed


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_write_mesh_pads_a_2d_vector_for_gmsh(tmp_path):
    mesh = evomesh.unit_square_mesh(60)
    path = evomesh.io.write_mesh(tmp_path / "x.msh", mesh)
    evomesh.io.write_mesh(path, mesh, {"vel": mesh.points, "F": np.tile(np.eye(2), (mesh.n_points, 1, 1))})
    back, data = evomesh.io.read_mesh(path)
    assert np.array_equal(back.points, mesh.points)
    assert np.array_equal(data["vel"], np.c_[mesh.points, np.zeros(mesh.n_points)])
    assert np.array_equal(data["F"], np.tile(np.diag([1.0, 1.0, 0.0]).ravel(), (mesh.n_points, 1)))
    assert _leftovers(tmp_path) == []


def test_write_mesh_refusal_leaves_the_old_file(tmp_path):
    mesh = evomesh.unit_square_mesh(60)
    path = evomesh.io.write_mesh(tmp_path / "x.msh", mesh, {"u": mesh.points[:, 0]})
    before = path.read_bytes()
    with pytest.raises(ValueError, match="'w'.*Gmsh files hold 1, 3 or 9 components"):
        evomesh.io.write_mesh(path, mesh, {"w": np.zeros((mesh.n_points, 4))})
    assert path.read_bytes() == before and _leftovers(tmp_path) == []


def test_write_mesh_failure_inside_meshio_leaves_the_old_file(tmp_path, monkeypatch):
    import meshio

    mesh = evomesh.unit_square_mesh(60)
    path = evomesh.io.write_mesh(tmp_path / "x.vtu", mesh)
    before = path.read_bytes()

    def half_then_fail(self, filename, file_format=None, **kwargs):
        with open(filename, "wb") as handle:
            handle.write(b"<VTKFile")  # a truncated file, as meshio leaves one
        raise meshio.WriteError("disk says no")

    monkeypatch.setattr(meshio.Mesh, "write", half_then_fail)
    with pytest.raises(ValueError, match=r"cannot write .*x\.vtu: WriteError: disk says no"):
        evomesh.io.write_mesh(path, mesh)
    assert path.read_bytes() == before and _leftovers(tmp_path) == []


def test_write_mesh_xdmf_with_its_h5_replaces_both(tmp_path):
    pytest.importorskip("h5py")
    mesh = evomesh.unit_square_mesh(60)
    path = evomesh.io.write_mesh(tmp_path / "x.xdmf", mesh, {"u": mesh.points[:, 0]})
    evomesh.io.write_mesh(path, mesh, {"u": 2 * mesh.points[:, 0]})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.h5", "x.xdmf"]
    _, data = evomesh.io.read_mesh(path)
    assert np.array_equal(data["u"], 2 * mesh.points[:, 0])


def test_xdmf_without_h5py_says_how_to_get_it(tmp_path, monkeypatch, capsys):
    mesh = evomesh.unit_square_mesh(60)
    source = evomesh.io.write_mesh(tmp_path / "in.vtu", mesh)
    monkeypatch.setitem(__import__("sys").modules, "h5py", None)  # import h5py now fails
    with pytest.raises(ImportError, match="pip install h5py"):
        evomesh.io.write_mesh(tmp_path / "x.xdmf", mesh)
    assert main(["adapt", str(source), str(tmp_path / "out.xdmf"), "--size-expr", "0.1", "--quiet"]) == 2
    error = capsys.readouterr().err.strip()
    assert "pip install h5py" in error and len(error.splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.vtu"]


# --------------------------------------------------------------------------------------------------
# Tags: int64 exactly, one tag per segment, Gmsh 4.1 and physical names


def _tagged_square(segment_tag: int = 3, triangle_tags=(1, 2)):
    mesh = evomesh.unit_square_mesh(200)
    boundary = mesh.segments[mesh.segment_is_boundary]
    left = mesh.points[mesh.triangles].mean(axis=1)[:, 0] < 0.5
    return evomesh.Mesh(mesh.points, mesh.triangles, boundary, segment_tags=np.full(len(boundary), segment_tag),
                        triangle_tags=np.where(left, *triangle_tags))


def test_int64_tags_are_kept_exactly_or_refused_for_gmsh(tmp_path):
    big = 2**33 + 1
    mesh = _tagged_square(segment_tag=big, triangle_tags=(-(2**40), 5))
    assert mesh.segment_tags.max() == big
    back, _ = evomesh.io.read_mesh(evomesh.io.write_mesh(tmp_path / "m.vtu", mesh))
    assert set(back.segment_tags.tolist()) == {big, 0} and set(back.triangle_tags.tolist()) == {-(2**40), 5}
    new = evomesh.evolve(mesh, 0.7)
    assert big in new.segment_tags
    with pytest.raises(ValueError, match=f"segment tag {big} does not fit in the 32-bit tags of Gmsh"):
        evomesh.io.write_mesh(tmp_path / "m.msh", mesh)
    assert not (tmp_path / "m.msh").exists()


def test_a_segment_given_twice_needs_one_tag():
    mesh = evomesh.unit_square_mesh(60)
    segments = mesh.segments[:3]
    twice = np.r_[segments, segments[1:2, ::-1]]
    with pytest.raises(ValueError, match=rf"segment \({min(segments[1])}, {max(segments[1])}\) is given twice with "
                                         r"different tags: row 1 has tag 7, row 3 has tag 8"):
        evomesh.Mesh(mesh.points, mesh.triangles, twice, segment_tags=[6, 7, 5, 8])
    same = evomesh.Mesh(mesh.points, mesh.triangles, twice, segment_tags=[6, 7, 5, 7])
    assert sorted(set(same.segment_tags.tolist())) == [0, 5, 6, 7]


@pytest.mark.parametrize("file_format", ["gmsh", "gmsh22"])
def test_gmsh_files_from_to_meshio_read_back_with_tags_and_names(tmp_path, file_format):
    import meshio

    names = {(1, 3): "dirichlet", (2, 1): "left", (2, 2): "right"}
    mesh = _tagged_square(triangle_tags=(1, 2))
    mesh = evomesh.Mesh(mesh.points, mesh.triangles, mesh.segments, segment_tags=mesh.segment_tags,
                        triangle_tags=mesh.triangle_tags, tag_names=names)
    mesh.to_meshio().write(tmp_path / "m.msh", file_format=file_format)
    back = evomesh.Mesh.from_meshio(meshio.read(tmp_path / "m.msh"))
    assert np.array_equal(back.points, mesh.points) and np.array_equal(back.kind, mesh.kind)
    rows = lambda m: dict(zip(map(tuple, m.triangles.tolist()), m.triangle_tags.tolist()))  # noqa: E731
    assert rows(back) == rows(mesh)
    assert dict(back.tag_names) == names


def test_physical_names_survive_evolve_pickle_and_adapt(tmp_path):
    import pickle

    names = {(1, 3): "dirichlet", (2, 1): "fluid", (2, 2): "solid"}
    base = _tagged_square()
    mesh = evomesh.Mesh(base.points, base.triangles, base.segments, segment_tags=base.segment_tags,
                        triangle_tags=base.triangle_tags, tag_names=names)
    assert dict(evomesh.evolve(mesh, 0.7).tag_names) == names
    assert dict(pickle.loads(pickle.dumps(mesh)).tag_names) == names
    source = evomesh.io.write_mesh(tmp_path / "in.msh", mesh)
    assert main(["adapt", str(source), str(tmp_path / "out.msh"), "--size-expr", "0.08", "--quiet"]) == 0
    out, _ = evomesh.io.read_mesh(tmp_path / "out.msh")
    assert dict(out.tag_names) == names
    assert set(out.segment_tags.tolist()) == {0, 3} and set(out.triangle_tags.tolist()) == {1, 2}  # 0: region borders


@pytest.mark.parametrize("names, error, message", [
    ({(3, 1): "x"}, ValueError, "dim must be 1"),
    ({1: "x"}, TypeError, "pairs of integers"),
    ({(1, 1): ""}, TypeError, "non-empty string"),
    ({(1, 1): 'say "hi"'}, ValueError, "double quotes"),
    ([("a", 1)], TypeError, "mapping"),
])
def test_tag_names_are_checked(names, error, message):
    mesh = evomesh.unit_square_mesh(60)
    with pytest.raises(error, match=message):
        evomesh.Mesh(mesh.points, mesh.triangles, tag_names=names)


def test_bad_cell_tags_are_called_cell_data_of_triangles():
    import meshio

    mesh = evomesh.unit_square_mesh(200)
    tags = np.ones(mesh.n_triangles)
    tags[5] = 0.5
    m = meshio.Mesh(np.c_[mesh.points, np.zeros(mesh.n_points)], [("triangle", mesh.triangles)],
                    cell_data={"gmsh:physical": [tags]})
    with pytest.raises(ValueError, match=rf"cell data 'gmsh:physical' must hold integers, but 1 of "
                                         rf"{mesh.n_triangles} triangles do not \(first: triangle 5"):
        evomesh.Mesh.from_meshio(m)
