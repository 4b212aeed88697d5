"""Mesh.from_skfem / Mesh.to_skfem: scikit-fem conversion with named tags."""

import numpy as np
import pytest

import evomesh
from evomesh import Mesh

skfem = pytest.importorskip("skfem")


def edge_keys(edges: np.ndarray, n: int) -> np.ndarray:
    edges = np.sort(np.asarray(edges), axis=1).astype(np.int64)
    return edges[:, 0] * n + edges[:, 1]


def tagged_square(n_points: int = 300) -> Mesh:
    """unit_square_mesh with the bottom side tagged 1, the rest 2, the left half region 1."""
    mesh = evomesh.unit_square_mesh(n_points)
    mid = mesh.points[mesh.segments].mean(axis=1)
    segment_tags = np.where(mid[:, 1] < 1e-9, 1, 2)
    centre = mesh.points[mesh.triangles].mean(axis=1)
    triangle_tags = np.where(centre[:, 0] < 0.5, 1, 0)
    return Mesh(mesh.points, mesh.triangles, mesh.segments, segment_tags=segment_tags, triangle_tags=triangle_tags)


def tagged_edges(mesh: Mesh) -> dict:
    """edge key -> tag of the segments with a nonzero tag."""
    tagged = mesh.segment_tags != 0
    return dict(zip(edge_keys(mesh.segments[tagged], mesh.n_points).tolist(), mesh.segment_tags[tagged].tolist()))


def test_round_trip_keeps_points_triangles_and_tags():
    mesh = tagged_square()
    names = ({1: "bottom", 2: "walls"}, {1: "left"})
    m = mesh.to_skfem(*names)
    assert np.array_equal(m.p.T, mesh.points)
    assert np.array_equal(m.t.T, mesh.triangles)  # order and orientation kept
    assert sorted(m.boundaries) == ["bottom", "walls"] and list(m.subdomains) == ["left"]
    assert np.array_equal(np.sort(m.subdomains["left"]), np.flatnonzero(mesh.triangle_tags == 1))
    # the facets of each boundary are exactly the segments of its tag
    for tag, name in names[0].items():
        facets = m.facets[:, m.boundaries[name]].T
        assert np.array_equal(np.sort(edge_keys(facets, mesh.n_points)),
                              np.sort(edge_keys(mesh.segments[mesh.segment_tags == tag], mesh.n_points)))
    back = Mesh.from_skfem(m)
    assert Mesh.skfem_names(m) == names
    assert np.array_equal(back.points, mesh.points) and np.array_equal(back.triangles, mesh.triangles)
    assert np.array_equal(back.triangle_tags, mesh.triangle_tags)
    assert tagged_edges(back) == tagged_edges(mesh)


def test_default_names_and_untagged_mesh():
    plain = evomesh.unit_square_mesh(100)
    m = plain.to_skfem()
    assert not m.boundaries and not m.subdomains
    back = Mesh.from_skfem(m)
    assert not back.segment_tags.any() and not back.triangle_tags.any()
    named = tagged_square(100).to_skfem()
    assert sorted(named.boundaries) == ["tag_1", "tag_2"] and list(named.subdomains) == ["tag_1"]


def test_evolved_tags_survive_the_conversion():
    mesh = tagged_square(400)
    new = evomesh.evolve(evomesh.evolve(mesh, 0.6), 1.8)
    m = new.to_skfem({1: "bottom", 2: "walls"}, {1: "left"})
    # skfem sees the bottom side as "bottom" and the left half as "left"
    mid = m.p[:, m.facets[:, m.boundaries["bottom"]]].mean(axis=1)
    assert np.allclose(mid[1], 0.0)
    walls = m.p[:, m.facets[:, m.boundaries["walls"]]].mean(axis=1)
    assert (walls[1] > 0).all()
    assert len(m.boundaries["bottom"]) + len(m.boundaries["walls"]) == len(m.boundary_facets())
    centre = m.p[:, m.t[:, m.subdomains["left"]]].mean(axis=1)  # the region border zigzags around x = 0.5
    assert (centre[0] < 0.6).all() and len(m.subdomains["left"]) == int((new.triangle_tags == 1).sum())
    back = Mesh.from_skfem(m)
    assert np.array_equal(back.triangle_tags, new.triangle_tags)
    assert tagged_edges(back) == tagged_edges(new)


def test_named_skfem_mesh_converts_with_numbered_tags():
    m = (
        skfem.MeshTri.init_tensor(np.linspace(0, 2, 9), np.linspace(0, 1, 5))
        .with_boundaries({"left": lambda x: x[0] < 1e-9, "right": lambda x: x[0] > 2 - 1e-9,
                          "cut": lambda x: np.abs(x[0] - 1) < 1e-9}, boundaries_only=False)
        .with_subdomains({"b_right": lambda x: x[0] > 1, "a_left": lambda x: x[0] < 1})
    )
    mesh = Mesh.from_skfem(m)
    boundary_names, subdomain_names = Mesh.skfem_names(m)
    assert boundary_names == {1: "cut", 2: "left", 3: "right"}  # sorted names, from 1
    assert subdomain_names == {1: "a_left", 2: "b_right"}
    assert np.array_equal(mesh.points, m.p.T)
    centre = mesh.points[mesh.triangles].mean(axis=1)
    assert np.array_equal(mesh.triangle_tags, np.where(centre[:, 0] < 1, 1, 2))
    mid = mesh.points[mesh.segments].mean(axis=1)
    expected = np.select([np.isclose(mid[:, 0], 1), np.isclose(mid[:, 0], 0), np.isclose(mid[:, 0], 2)], [1, 2, 3], 0)
    assert np.array_equal(mesh.segment_tags, expected)
    assert ((mesh.segment_tags == 1) == ~mesh.segment_is_boundary).all()  # the cut is an interior segment
    # and back, with the original names
    again = mesh.to_skfem(boundary_names, subdomain_names)
    for name in m.boundaries:
        assert set(edge_keys(again.facets[:, again.boundaries[name]].T, mesh.n_points).tolist()) == set(
            edge_keys(m.facets[:, m.boundaries[name]].T, mesh.n_points).tolist())
    for name in m.subdomains:
        assert np.array_equal(np.sort(again.subdomains[name]), np.sort(m.subdomains[name]))


def test_overlapping_names_and_non_triangle_meshes_are_refused():
    m = skfem.MeshTri.init_tensor(np.linspace(0, 1, 4), np.linspace(0, 1, 4)).with_boundaries(
        {"a": lambda x: x[1] < 1e-9, "b": lambda x: x[1] < 1e-9})
    with pytest.raises(ValueError, match="both 'a' and 'b'"):
        Mesh.from_skfem(m)
    with pytest.raises(ValueError, match="triangle mesh"):
        Mesh.from_skfem(skfem.MeshQuad())


def test_skfem_solves_poisson_on_a_converted_mesh():
    """-Δu = 1 on the unit square, u = 0 on the tagged boundary: the centre value
    of a P1 solution on an evolved mesh is close to the series value 0.07367."""
    mesh = evomesh.evolve(tagged_square(1500), 1.0)
    m = mesh.to_skfem({1: "bottom", 2: "walls"})
    basis = skfem.Basis(m, skfem.ElementTriP1())
    from skfem.models.poisson import laplace, unit_load

    A, b = laplace.assemble(basis), unit_load.assemble(basis)
    u = skfem.solve(*skfem.condense(A, b, D=basis.get_dofs({"bottom", "walls"})))
    centre = basis.probes(np.array([[0.5], [0.5]])) @ u
    assert abs(centre[0] - 0.0736713) < 2e-3
