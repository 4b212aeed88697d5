"""Regression tests for Python-side defects found by trying evomesh as a new user would (transfer far from
the origin, partial runs, write_run / read_mesh validation)."""

import importlib

import meshio
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import evomesh
from evomesh import _core, io, transfer
from evomesh.io import read_mesh, write_run
from invariants import check_evolved, check_valid_mesh
from strategies import grid_mesh, meshes

# evomesh.transfer is the function (the package re-exports it): the module by name
transfer_mod = importlib.import_module("evomesh.field_transfer")


# ---------------------------------------------------------------------------
# (5) transfer far from the origin; nearest boundary edge in O((q + b) log b)

FAR = 1e9


def rotated_far_mesh(nx=21, seed=1, angle_deg=30.0, offset=(FAR, FAR)):
    """A jittered unit-square grid rotated by angle_deg and moved to offset."""
    base = grid_mesh(nx, nx, jitter=0.25, seed=seed)
    th = np.deg2rad(angle_deg)
    rotation = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    return evomesh.Mesh(base.points @ rotation.T + np.asarray(offset), base.triangles)


def local_linear(points):
    x = points[:, 0] - FAR
    y = points[:, 1] - FAR
    return 3.0 * x - 2.0 * y + 0.5


def test_transfer_of_evolve_output_far_from_the_origin():
    mesh = rotated_far_mesh()
    values = local_linear(mesh.points)
    fallback = 0
    for k, delta in enumerate((0.05, 20.0, 0.05, 20.0)):
        new = evomesh.evolve(mesh, delta, seed=k)
        located, _ = _core.locate_points(mesh.points, mesh.triangles, new.points[new.origin < 0])
        fallback += int((located < 0).sum())
        out = transfer(mesh, new, values)
        # a linear field stays linear (up to the rounding of coordinates near 1e9)
        assert np.allclose(out, local_linear(new.points), rtol=0, atol=1e-4)
        kept = new.origin >= 0
        assert np.array_equal(out[kept], values[new.origin[kept]])
        mesh, values = new, out
    assert fallback > 0, "the test needs new points that rounding put outside the old mesh"


def test_run_with_fields_far_from_the_origin():
    mesh = rotated_far_mesh()

    def law(m, distance):  # refine the coarse mesh, coarsen the fine one
        return np.full(m.n_points, 0.05 if m.n_points < 1000 else 20.0)

    result = evomesh.run(mesh, None, law, [1, 2, 3, 4], fields={"u": local_linear(mesh.points)}, progress=False)
    assert len(result.steps) == 4
    for step in result.steps:
        assert np.allclose(step.fields["u"], local_linear(step.mesh.points), rtol=0, atol=1e-4)


def test_outside_tolerance_is_in_ulps_of_the_coordinates():
    mesh = rotated_far_mesh(nx=5)
    eps = np.finfo(np.float64).eps
    tolerance = transfer_mod._outside_tolerance(mesh, mesh.points[:0])
    magnitude = np.abs(mesh.points).max()
    assert tolerance >= 8 * eps * magnitude  # several ulps of |x| ~ 1e9
    assert tolerance <= 64 * eps * magnitude + 1e-11  # but still rounding, not a fraction of the extent
    near = grid_mesh(5, 5)
    assert transfer_mod._outside_tolerance(near, near.points[:0]) < 1e-11


def brute_force_nearest_boundary_edge(old, queries):
    """The former O(q b) search: every query against every boundary edge."""
    edges = old.segments[old.segment_is_boundary]
    a = old.points[edges[:, 0]]
    d = old.points[edges[:, 1]] - a
    dd = np.einsum("ij,ij->i", d, d)
    q = queries[:, None, :]
    t = np.clip(np.einsum("qkj,kj->qk", q - a[None], d) / dd[None], 0.0, 1.0)
    gap = np.linalg.norm(q - (a[None] + t[..., None] * d[None]), axis=2)
    best = gap.argmin(axis=1)
    rows = np.arange(len(best))
    edge = edges[best]
    weights = np.zeros((len(queries), 3))
    weights[:, 0] = 1.0 - t[rows, best]
    weights[:, 1] = t[rows, best]
    return np.c_[edge, edge[:, 0]], weights, gap[rows, best]


def points_on_the_boundary(mesh, rng, count, ulps):
    """Random points of boundary edges (including their end points), moved by
    up to ``ulps`` ulps of the largest coordinate in each direction."""
    edges = mesh.segments[mesh.segment_is_boundary]
    pick = rng.integers(0, len(edges), count)
    t = rng.choice([0.0, 0.5, 1.0, rng.uniform()], count)
    t = np.where(rng.uniform(size=count) < 0.5, rng.uniform(size=count), t)
    a = mesh.points[edges[pick, 0]]
    b = mesh.points[edges[pick, 1]]
    x = a + t[:, None] * (b - a)
    scale = np.finfo(np.float64).eps * np.abs(mesh.points).max()
    return x + rng.uniform(-ulps, ulps, x.shape) * scale


@settings(max_examples=20)
@given(meshes(max_side=10), st.integers(0, 2**16), st.sampled_from([0.0, 1.0, 4.0]),
       st.sampled_from([0.0, 1e6]))
def test_nearest_boundary_edge_is_the_brute_force_one(mesh, seed, ulps, far):
    # far from the origin in units of the mesh's extent (coarse coordinates)
    extent = np.ptp(mesh.points, axis=0).max()
    mesh = evomesh.Mesh(mesh.points + far * extent * np.array([1.0, -0.3]), mesh.triangles)
    rng = np.random.default_rng(seed)
    queries = points_on_the_boundary(mesh, rng, 200, ulps)
    vertices, weights = transfer_mod._nearest_boundary_edge(mesh, queries)
    expected_vertices, expected_weights, _ = brute_force_nearest_boundary_edge(mesh, queries)
    assert np.array_equal(vertices, expected_vertices)
    assert np.array_equal(weights, expected_weights)


def test_nearest_boundary_edge_compares_few_edges_per_query(monkeypatch):
    # 4 * 199 boundary edges; the former search compared every query with all of them
    mesh = grid_mesh(200, 200)
    queries = points_on_the_boundary(mesh, np.random.default_rng(0), 3000, 2.0)
    compared = []
    original = transfer_mod._to_segments

    def counting(q, a, d, dd):
        compared.append(max(len(q), len(a)))
        return original(q, a, d, dd)

    monkeypatch.setattr(transfer_mod, "_to_segments", counting)
    vertices, _ = transfer_mod._nearest_boundary_edge(mesh, queries)
    assert sum(compared) <= 4 * len(queries)
    monkeypatch.undo()
    assert np.array_equal(vertices, brute_force_nearest_boundary_edge(mesh, queries)[0])


def test_points_beyond_rounding_are_refused_far_from_the_origin():
    mesh = rotated_far_mesh(nx=6)
    center = mesh.points.mean(axis=0)
    # 1e-3 of the extent outside: far more than rounding even at 1e9
    grown = evomesh.Mesh((mesh.points - center) * 1.001 + center, mesh.triangles)
    with pytest.raises(ValueError, match="outside the old mesh"):
        transfer(mesh, grown, local_linear(mesh.points))


# ---------------------------------------------------------------------------
# (7) run() keeps the finished steps when a step fails


class FailingLaw:
    """delta 0.7 then 1.3 ...; at call ``fail_at`` (1-based) it returns what
    ``bad`` gives (e.g. NaN, which evolve's delta check refuses) or raises."""

    def __init__(self, fail_at, bad):
        self.fail_at = fail_at
        self.bad = bad
        self.calls = 0

    def __call__(self, mesh, distance):
        self.calls += 1
        if self.calls == self.fail_at:
            return self.bad(mesh)
        return np.full(mesh.n_points, 0.7 if self.calls % 2 else 1.3)


def nan_delta(mesh):
    return np.full(mesh.n_points, np.nan)


def raise_lookup(mesh):
    raise LookupError("no spacing table for this mesh")


@pytest.mark.parametrize("bad, error_type", [(nan_delta, ValueError), (raise_lookup, LookupError)])
def test_a_failing_step_keeps_the_finished_steps(bad, error_type, tmp_path):
    mesh = grid_mesh(9, 9, jitter=0.2, seed=2)
    fields = {"u": mesh.points[:, 0].copy()}
    with pytest.raises(error_type) as caught:
        evomesh.run(mesh, None, FailingLaw(3, bad), [1, 2, 3, 4, 5], fields=fields, progress=False)
    error = caught.value
    partial = error.run
    assert isinstance(partial, evomesh.Run)
    assert [s.iteration for s in partial.steps] == [1, 2]
    assert [s.time for s in partial.steps] == [1.0, 2.0]
    assert partial.meshes[0] is mesh
    for old, new in zip(partial.meshes[:-1], partial.meshes[1:]):
        check_valid_mesh(new)
        check_evolved(old, new)
    assert all(set(f) == {"u"} for f in partial.fields)
    if hasattr(error, "add_note"):
        assert any("2 of 5 steps" in note and "error.run" in note for note in error.__notes__)
    written = write_run(partial, tmp_path, figures=True, dpi=30)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "mesh_000.vtu", "mesh_001.vtu", "mesh_002.vtu", "meshes.pvd", "step_001.png", "step_002.png", "table.csv"]
    assert len(written["meshes"]) == 3
    assert len((tmp_path / "table.csv").read_text().strip().splitlines()) == 1 + 2
    again, data = read_mesh(tmp_path / "mesh_002.vtu")
    assert np.array_equal(again.points, partial.mesh.points)
    assert np.array_equal(data["u"], partial.steps[-1].fields["u"])


def test_a_failing_first_step_gives_an_empty_partial_run(tmp_path):
    mesh = grid_mesh(6, 6)
    with pytest.raises(ValueError) as caught:
        evomesh.run(mesh, None, FailingLaw(1, nan_delta), [1, 2], progress=False)
    assert caught.value.run.steps == [] and caught.value.run.mesh is mesh
    write_run(caught.value.run, tmp_path, figures=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh_000.vtu", "meshes.pvd", "table.csv"]


def test_a_failing_callback_keeps_its_step_and_keep_meshes_false():
    mesh = grid_mesh(7, 7, jitter=0.1, seed=1)

    def callback(step):
        if step.iteration == 2:
            raise RuntimeError("stop")

    with pytest.raises(RuntimeError, match="stop") as caught:
        evomesh.run(mesh, None, lambda m, d: np.full(m.n_points, 0.8), [1, 2, 3], callback=callback,
                    keep_meshes=False, progress=False)
    partial = caught.value.run
    assert len(partial.steps) == 2  # the step that the callback saw had finished
    assert partial.steps[0].mesh is None and partial.steps[1].mesh is not None


def test_argument_errors_carry_no_partial_run():
    mesh = grid_mesh(6, 6)
    with pytest.raises(ValueError) as caught:
        evomesh.run(mesh, None, lambda m, d: np.ones(m.n_points), [])
    assert not hasattr(caught.value, "run")


# ---------------------------------------------------------------------------
# (8) write_run / read_mesh: validation before writing, planar files, integral
# kind / origin, stale files of an earlier series, the packing scale


def small_run(steps, fields=None, **kwargs):
    mesh = grid_mesh(7, 7, jitter=0.15, seed=3)
    fields = fields(mesh) if callable(fields) else fields
    law = lambda m, d: np.full(m.n_points, 0.8)  # noqa: E731
    return evomesh.run(mesh, None, law, np.arange(1.0, steps + 1), fields=fields, progress=False, **kwargs)


def folder_listing(folder):
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else None


def test_write_run_splits_complex_fields(tmp_path):
    result = small_run(
        2, lambda m: {"psi": np.exp(1j * m.points[:, 0]), "c64": (m.points[:, 1] * 1j).astype(np.complex64)}
    )
    io.write_run(result, tmp_path, figures=False)
    for k, fields in enumerate(result.fields):
        _, data = io.read_mesh(tmp_path / f"mesh_{k:03d}.vtu")
        assert "psi" not in data
        assert np.array_equal(data["psi_real"], fields["psi"].real)
        assert np.array_equal(data["psi_imag"], fields["psi"].imag)
        assert data["c64_imag"].dtype == np.float32
        assert np.array_equal(data["c64_imag"], fields["c64"].imag)


FIELD_DTYPES = [np.float64, np.float32, np.float16, np.int8, np.int32, np.int64, np.uint16, np.uint64, np.bool_,
                np.complex128, np.dtype(">f8"), np.dtype(">i4")]


@settings(max_examples=25)
@given(st.sampled_from(FIELD_DTYPES), st.sampled_from([(), (1,), (3,), (2, 2)]), st.integers(0, 2**16))
def test_point_data_round_trip_as_documented(tmp_path_factory, dtype, components, seed):
    mesh = grid_mesh(5, 5)
    rng = np.random.default_rng(seed)
    values = (rng.standard_normal((mesh.n_points,) + components) * 50).astype(dtype)
    if np.dtype(dtype).kind == "c":
        values = values + 1j * rng.standard_normal(values.shape)
    before = values.copy()
    path = tmp_path_factory.mktemp("rt") / "m.vtu"
    io.write_mesh(path, mesh, {"f": values})
    assert np.array_equal(values, before) and values.dtype == before.dtype  # not modified
    _, data = io.read_mesh(path)
    flat = values.reshape(mesh.n_points, -1) if len(components) > 1 else values
    parts = {"f_real": flat.real, "f_imag": flat.imag} if values.dtype.kind == "c" else {"f": flat}
    assert sorted(data) == sorted(parts)
    for name, expected in parts.items():
        assert data[name].shape == expected.shape
        assert np.array_equal(data[name], expected)  # no value is lost


def test_write_run_refuses_a_bad_late_field_before_writing_anything(tmp_path):
    result = small_run(3, lambda m: {"u": m.points[:, 0].copy()})
    folder = tmp_path / "out"
    # the field of the last step only: before the fix table.csv and the first meshes were written
    bad_fields = [
        ({"u": np.zeros(result.mesh.n_points, dtype=np.longdouble)}, ValueError, "float128|longdouble|precision"),
        ({"delta": np.zeros(result.mesh.n_points)}, ValueError, "clashes"),
        ({"a<b": np.zeros(result.mesh.n_points)}, ValueError, "a<b"),
        ({"": np.zeros(result.mesh.n_points)}, ValueError, "empty"),
        ({"u": np.zeros(result.mesh.n_points, dtype=complex), "u_imag": np.zeros(result.mesh.n_points)},
         ValueError, "u_imag"),
        ({"u": np.array(["x"] * result.mesh.n_points)}, TypeError, "numeric"),
        ({"u": np.zeros(result.mesh.n_points + 1)}, ValueError, "one row per point"),
        ({7: np.zeros(result.mesh.n_points)}, TypeError, "strings"),
    ]
    good = result.steps[-1].fields
    for fields, error_type, message in bad_fields:
        if fields.get("u") is not None and fields["u"].dtype == np.longdouble and np.finfo(np.longdouble).bits <= 64:
            continue  # long double is float64 on this platform: nothing to refuse
        result.steps[-1].fields = fields
        with pytest.raises(error_type, match=message) as caught:
            io.write_run(result, folder, figures=True)
        assert "step 3" in str(caught.value)
        assert folder_listing(folder) is None, f"{fields} left files behind"
    result.steps[-1].fields = good
    io.write_run(result, folder, figures=False)
    assert len(folder_listing(folder)) == 6


def test_write_run_refuses_a_bad_field_without_touching_an_earlier_series(tmp_path):
    first = small_run(2)
    io.write_run(first, tmp_path, figures=False)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    second = small_run(1)
    second.steps[0].fields = {"nn_spacing": np.zeros(second.mesh.n_points)}
    with pytest.raises(ValueError, match="nn_spacing"):
        io.write_run(second, tmp_path)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def write_vtu(path, points3, triangles, **point_data):
    meshio.Mesh(points3, [("triangle", np.asarray(triangles))], point_data=point_data).write(path)
    return path


def test_read_mesh_refuses_a_non_planar_mesh(tmp_path):
    mesh = grid_mesh(4, 4)
    z = np.zeros(mesh.n_points)
    flat = write_vtu(tmp_path / "flat.vtu", np.c_[mesh.points, z], mesh.triangles)
    again, _ = io.read_mesh(flat)  # an all-zero z is fine
    assert np.array_equal(again.points, mesh.points)
    z[[3, 7]] = [0.25, -1e-300]
    lifted = write_vtu(tmp_path / "lifted.vtu", np.c_[mesh.points, z], mesh.triangles)
    with pytest.raises(ValueError, match=r"2 of 16 points have z != 0: points 3 \(z = 0.25\), 7"):
        io.read_mesh(lifted)


@pytest.mark.parametrize("name", ["origin", "kind"])
def test_read_mesh_integral_floats_only(tmp_path, name):
    mesh = grid_mesh(4, 4)
    points3 = np.c_[mesh.points, np.zeros(mesh.n_points)]
    truth = {"origin": np.arange(mesh.n_points) - 1, "kind": mesh.kind}[name]
    good = write_vtu(tmp_path / "good.vtu", points3, mesh.triangles, **{name: truth.astype(np.float64)})
    again, data = io.read_mesh(good)
    assert np.array_equal(getattr(again, name), truth) and name not in data
    for bad_value in (0.5, np.nan, 1e300):
        values = truth.astype(np.float64)
        values[5] += bad_value
        bad = write_vtu(tmp_path / "bad.vtu", points3, mesh.triangles, **{name: values})
        with pytest.raises(ValueError, match=rf"'{name}' must hold integers.*point 5"):
            io.read_mesh(bad)


def test_write_run_replaces_an_earlier_series(tmp_path):
    longer = small_run(4)
    io.write_run(longer, tmp_path, figures=True, dpi=30)
    assert "mesh_004.vtu" in folder_listing(tmp_path) and "step_004.png" in folder_listing(tmp_path)
    user_files = ["notes.txt", "mesh_final.vtu", "step_1.png", "mesh_001.vtu.bak", "table.csv.old", "MESH_001.VTU"]
    for name in user_files:
        (tmp_path / name).write_text("mine")
    (tmp_path / "mesh_005.vtu").mkdir()  # a folder, even with a series name, is the user's
    (tmp_path / "mesh_1234.vtu").write_text("old series beyond 999 steps")
    shorter = small_run(2)
    written = io.write_run(shorter, tmp_path, figures=True, dpi=30)
    series = ["mesh_000.vtu", "mesh_001.vtu", "mesh_002.vtu", "meshes.pvd", "step_001.png", "step_002.png",
              "table.csv"]
    assert folder_listing(tmp_path) == sorted(series + user_files + ["mesh_005.vtu"])
    assert all((tmp_path / name).read_text() == "mine" for name in user_files)
    assert [p.name for p in written["meshes"]] == series[:3]
    assert "mesh_003" not in (tmp_path / "meshes.pvd").read_text()
    # without figures, the earlier run's figures go too (they would not match the meshes)
    io.write_run(small_run(1), tmp_path, figures=False)
    assert not [n for n in folder_listing(tmp_path) if n.startswith("step_0")]


def test_packing_scale_is_the_method_default():
    assert io._packing_scale({}) == evomesh.FRFC_DEFAULTS["radius_scale"] == 0.75
    assert io._packing_scale({"method": "frfc"}) == 0.75
    assert io._packing_scale({"method": "drfc"}) == evomesh.DRFC_DEFAULTS["radius_scale"]
    assert io._packing_scale({"method": "frfc", "radius_scale": 0.6}) == 0.6
    assert io._packing_scale(small_run(1).options) == 0.75
