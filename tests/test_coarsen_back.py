"""Where a fine request has passed, ``size=h`` coarsens the mesh back to h.

The tolerance that keeps a mesh that meets its request still (delta = 1 where
the edges are within 1.25 times finer to 1.25 times coarser than h,
python/evomesh/spacing_function.py, delta_from_size) must not keep a mesh that
is finer than that: within two steps the median edge over h is back in
[0.9, 1.1] there and the point count within 10 % of a mesh made for h alone,
and a few steps later the mesh stays put again. benchmarks/coarsen_back.py
has the figures (a moving interface, a vortex).
"""

from functools import lru_cache

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import evomesh
from evomesh.meshgen import unit_square_mesh
from evomesh.spacing_function import delta_from_size
from invariants import check_evolved, edges_with_counts

H = 0.05


@lru_cache(maxsize=1)
def settled() -> evomesh.Mesh:
    """A mesh that meets size=H: evolve(size=H) changes nothing."""
    mesh = unit_square_mesh(470)
    for step in range(3):
        mesh = evomesh.evolve(mesh, size=H, seed=step)
    return mesh


def spot(centre: np.ndarray, fine: float, radius: float = 0.08):
    """h inside a disc, grading with slope 0.5 up to H outside it."""
    return lambda x: np.minimum(H, fine + 0.5 * np.maximum(0.0, np.hypot(*(x - centre).T) - radius))


def edge_ratios(mesh: evomesh.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Edge length / H and the edges' midpoints."""
    edges, _ = edges_with_counts(mesh.triangles)
    a, b = mesh.points[edges[:, 0]], mesh.points[edges[:, 1]]
    return np.linalg.norm(a - b, axis=1) / H, 0.5 * (a + b)


def test_the_settled_mesh_meets_its_request():
    mesh = settled()
    assert (delta_from_size(mesh, H) == 1).all()
    assert 0.9 <= np.median(edge_ratios(mesh)[0]) <= 1.1


@settings(max_examples=6)
@given(st.floats(0.3, 0.7), st.floats(0.3, 0.7), st.floats(0, 2 * np.pi), st.sampled_from([0.25, 0.4]),
       st.integers(0, 2**16))
def test_a_passing_fine_spot_leaves_no_trail(x, y, angle, fine, seed):
    start = settled()
    direction = np.array([np.cos(angle), np.sin(angle)])
    centres = [np.clip(np.array([x, y]) + 0.08 * k * direction, 0.15, 0.85) for k in range(3)]
    mesh = start
    for k, c in enumerate(centres):  # the spot moves, leaving fine points behind it
        mesh = evomesh.evolve(mesh, size=spot(c, fine * H), seed=seed + k)
    assert mesh.n_points > 1.15 * start.n_points  # (the spot left fine points)
    previous = mesh
    for k in range(2):  # back to H everywhere: two steps
        mesh = evomesh.evolve(previous, size=H, seed=seed + 10 + k)
        check_evolved(previous, mesh)
        previous = mesh
    ratio, middle = edge_ratios(mesh)
    swept = np.min([np.hypot(*(middle - c).T) for c in centres], axis=0) < 0.15
    assert 0.9 <= np.median(ratio[swept]) <= 1.1, np.median(ratio[swept])
    assert 0.9 <= np.median(ratio) <= 1.1
    assert abs(mesh.n_points / start.n_points - 1) <= 0.1, (mesh.n_points, start.n_points)
    # and then it stays put: no point asks for a change within three more steps
    for k in range(3):
        if (delta_from_size(mesh, H) == 1).all():
            break
        mesh = evomesh.evolve(mesh, size=H, seed=seed + 20 + k)
    assert (delta_from_size(mesh, H) == 1).all()
    again = evomesh.evolve(mesh, size=H, seed=seed + 30)
    assert again.stats["unchanged"] == 1 and again.n_points == mesh.n_points
