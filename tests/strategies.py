"""Hypothesis strategies: well-shaped random meshes (with holes and reflex
corners) and per-point factors delta."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st
from scipy.spatial import Delaunay

import evomesh


def grid_mesh(nx: int, ny: int, *, jitter: float = 0.0, seed: int = 0, scale: float = 1.0,
              offset=(0.0, 0.0), hole: bool = False, notch: bool = False) -> evomesh.Mesh:
    """A jittered grid on [0, scale]^2 (+offset), optionally with a square hole in
    the middle or a notch (L-shape, a reflex corner). Boundary points stay on the
    boundary, so the domain is exactly the polygon."""
    rng = np.random.default_rng(seed)
    xs = np.linspace(0.0, 1.0, nx)
    ys = np.linspace(0.0, 1.0, ny)
    x, y = np.meshgrid(xs, ys)
    pts = np.c_[x.ravel(), y.ravel()]
    interior = (pts[:, 0] > 0) & (pts[:, 0] < 1) & (pts[:, 1] > 0) & (pts[:, 1] < 1)
    h = min(1.0 / (nx - 1), 1.0 / (ny - 1))
    pts[interior] += rng.uniform(-jitter, jitter, (int(interior.sum()), 2)) * h
    tris = Delaunay(pts).simplices
    centroids = pts[tris].mean(axis=1)
    keep = np.ones(len(tris), bool)
    if hole and nx >= 6 and ny >= 6:
        # remove the triangles of the grid cells in the middle (exact grid lines)
        lo_x, hi_x = xs[nx // 3], xs[(2 * nx) // 3]
        lo_y, hi_y = ys[ny // 3], ys[(2 * ny) // 3]
        # keep the hole's boundary points unjittered so the hole is a rectangle
        inside = (centroids[:, 0] > lo_x) & (centroids[:, 0] < hi_x) & (centroids[:, 1] > lo_y) & (centroids[:, 1] < hi_y)
        keep &= ~inside
    if notch:
        keep &= ~((centroids[:, 0] > xs[nx // 2]) & (centroids[:, 1] > ys[ny // 2]))
    tris = tris[keep]
    used = np.unique(tris)
    remap = -np.ones(len(pts), np.int64)
    remap[used] = np.arange(len(used))
    pts = pts[used] * scale + np.asarray(offset)
    return evomesh.Mesh(pts, remap[tris])


@st.composite
def meshes(draw, max_side: int = 12):
    nx = draw(st.integers(4, max_side))
    ny = draw(st.integers(4, max_side))
    jitter = draw(st.sampled_from([0.0, 0.1, 0.25]))
    seed = draw(st.integers(0, 2**16))
    shape = draw(st.sampled_from(["square", "hole", "notch"]))
    scale = draw(st.sampled_from([1.0, 1e-3, 50.0]))
    # A hole/notch must follow exact grid lines: no jitter there would be needed,
    # but jittered interior points could cross them, so use no jitter then.
    if shape != "square":
        jitter = 0.0
    return grid_mesh(nx, ny, jitter=jitter, seed=seed, scale=scale, offset=(scale * 0.3, -scale * 2.0),
                     hole=shape == "hole", notch=shape == "notch")


@st.composite
def mesh_and_delta(draw, max_side: int = 12):
    mesh = draw(meshes(max_side=max_side))
    kind = draw(st.sampled_from(["random", "smooth", "constant"]))
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    if kind == "random":
        delta = np.exp(rng.uniform(np.log(0.1), np.log(10.0), mesh.n_points))
    elif kind == "smooth":
        lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
        t = (mesh.points[:, 0] - lo[0]) / (hi[0] - lo[0])
        delta = 0.1 * (100.0 ** t)  # 0.1 .. 10 across the domain
    else:
        delta = np.full(mesh.n_points, draw(st.sampled_from([0.1, 0.5, 1.0, 2.0, 10.0])))
    return mesh, delta
