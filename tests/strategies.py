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
        cx, cy = centroids[:, 0], centroids[:, 1]
        inside = (cx > lo_x) & (cx < hi_x) & (cy > lo_y) & (cy < hi_y)
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


# ---------------------------------------------------------------------------
# Fuzzing: random point-cloud meshes, invalid mutations, bad delta.
# Arrays come from a numpy generator seeded by hypothesis: cheap to draw, and
# every case is reproducible from its seed.
# ---------------------------------------------------------------------------

_LAYOUTS = ("uniform", "clustered", "integer-grid", "lines", "annulus")


def crack_mesh(n: int) -> evomesh.Mesh:
    """A notched n x n grid with an interior crack (segments tagged 7) along the
    grid row nearest y = 0.3, from x = 0.1 to 0.9."""
    grid = grid_mesh(n, n, notch=True)
    p = grid.points
    y = p[:, 1][np.argmin(np.abs(p[:, 1] - 0.3))]
    row = np.flatnonzero((np.abs(p[:, 1] - y) < 1e-12) & (p[:, 0] > 0.1) & (p[:, 0] < 0.9))
    row = row[np.argsort(p[row, 0])]
    return evomesh.Mesh(p, grid.triangles, segments=np.stack([row[:-1], row[1:]], axis=1),
                        segment_tags=np.full(len(row) - 1, 7))


def holes_mesh() -> evomesh.Mesh:
    """A plate with two holes and a few interior points required."""
    from evomesh.meshgen import polygon_mesh

    mesh = polygon_mesh([[(0, 0), (3, 0), (3, 2), (0, 2)], [(0.5, 0.5), (0.5, 1.5), (1.2, 1.5), (1.2, 0.5)],
                         [(1.8, 0.5), (1.8, 1.5), (2.5, 1.5), (2.5, 0.5)]], 0.17)
    required = np.zeros(mesh.n_points, bool)
    inside = np.flatnonzero(mesh.kind == int(evomesh.PointKind.ORIGINAL))
    required[inside[:: max(len(inside) // 5, 1)]] = True
    return evomesh.Mesh(mesh.points, mesh.triangles, mesh.segments, segment_tags=mesh.segment_tags,
                        required=required)


def _random_cloud(rng: np.random.Generator, layout: str, n: int) -> np.ndarray:
    if layout == "uniform":
        return rng.random((n, 2))
    if layout == "clustered":  # graded: clusters 3 to 300 times finer than a uniform background
        k = int(rng.integers(1, 4))
        centres = rng.random((k, 2))
        scales = 10.0 ** -rng.uniform(0.5, 2.5, k)
        which = rng.integers(0, k, n)
        pts = centres[which] + rng.normal(size=(n, 2)) * scales[which, None]
        return np.r_[pts, rng.random((max(4, n // 3), 2)), [[-0.2, -0.2], [1.2, -0.2], [1.2, 1.2], [-0.2, 1.2]]]
    if layout == "integer-grid":  # many collinear and cocircular points: exact predicates matter
        m = int(rng.integers(3, 12))
        return rng.integers(0, m, (n, 2)).astype(float)
    if layout == "lines":  # points on a few lines plus a few off them: near-collinear triples
        k = int(rng.integers(1, 4))
        a = rng.random((k, 2))
        d = rng.normal(size=(k, 2))
        which = rng.integers(0, k, n)
        t = rng.uniform(-1, 1, n)
        pts = a[which] + t[:, None] * d[which]
        return np.r_[pts, rng.random((max(3, n // 10), 2))]
    # annulus: a ring of points, a hole in the middle after triangle removal
    angle = rng.uniform(0, 2 * np.pi, n)
    radius = rng.uniform(0.5, 1.0, n)
    return np.c_[radius * np.cos(angle), radius * np.sin(angle)]


def _without_flat_triangles(pts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    p = pts[tris]
    ab = p[:, 1] - p[:, 0]
    ac = p[:, 2] - p[:, 0]
    det = ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0]
    size = np.linalg.norm(ab, axis=1) * np.linalg.norm(ac, axis=1)
    return tris[np.abs(det) > 1e-10 * size]


def _compact(pts: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used = np.unique(tris)
    remap = -np.ones(len(pts), np.int64)
    remap[used] = np.arange(len(used))
    return pts[used], remap[tris]


@st.composite
def random_mesh_arrays(draw, max_points: int = 150):
    """(points, triangles) of a Delaunay triangulation of a random point cloud
    (uniform, clustered, on an integer grid, on lines, in an annulus), with some
    triangles removed (holes, pinched vertices, several components), at a random
    scale and offset. Usually valid; flat Delaunay triangles can leave a point
    on an edge, which Mesh rightly rejects."""
    layout = draw(st.sampled_from(_LAYOUTS))
    n = draw(st.integers(4, max_points))
    seed = draw(st.integers(0, 2**32 - 1))
    drop = draw(st.sampled_from([0.0, 0.0, 0.1, 0.3]))
    # up to near the documented coordinate limits (|x| <= 1e75, distances >= 1e-75)
    scale = draw(st.sampled_from([1.0, 1.0, 1e-9, 1e9, 1e15, 1e-15, 3.7e72, 2.3e-68]))
    offset = draw(st.sampled_from([0.0, 0.0, 1.0, -1e3]))
    rng = np.random.default_rng(seed)
    pts = np.unique(_random_cloud(rng, layout, n), axis=0)
    if len(pts) < 3 or np.linalg.matrix_rank(pts - pts.mean(axis=0), tol=1e-9) < 2:
        pts = np.r_[pts, [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]]
        pts = np.unique(pts, axis=0)
    tris = _without_flat_triangles(pts, Delaunay(pts).simplices.astype(np.int64))
    if layout == "annulus":
        inner = np.linalg.norm(pts[tris].mean(axis=1), axis=1) < 0.55
        if (~inner).any():
            tris = tris[~inner]
    if drop and len(tris) > 4:
        tris = tris[rng.random(len(tris)) >= drop]
    if len(tris) == 0:
        tris = _without_flat_triangles(pts, Delaunay(pts).simplices.astype(np.int64))[:1]
    pts, tris = _compact(pts, tris)
    if scale > 1e20:  # an offset would push the points past the coordinate limit
        offset = 0.0
    pts = (pts + offset) * scale
    return pts, tris


@st.composite
def random_meshes(draw, max_points: int = 150):
    """A valid evomesh.Mesh from random_mesh_arrays (cases Mesh rejects are
    filtered out and counted as the event 'random mesh rejected')."""
    from hypothesis import event, reject

    pts, tris = draw(random_mesh_arrays(max_points=max_points))
    try:
        return evomesh.Mesh(pts, tris)
    except ValueError as error:
        event(f"random mesh rejected: {str(error).split(' ')[0:3]}")
        reject()


@st.composite
def any_meshes(draw):
    """A grid mesh (holes, notches) or a random point-cloud mesh."""
    if draw(st.booleans()):
        return draw(meshes())
    return draw(random_meshes())


@st.composite
def deltas(draw, n: int, low: float = 0.1, high: float = 10.0):
    """A valid per-point factor for n points in [low, high]: random, smooth in
    the index, two-valued (sharp refine/coarsen interface), constant, or high
    everywhere but at one or two points (their cones can hide all others)."""
    kind = draw(st.sampled_from(["random", "smooth", "two-valued", "constant", "one-fine", "two-fine"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    lo, hi = np.log(low), np.log(high)
    if kind == "random":
        return np.exp(rng.uniform(lo, hi, n))
    if kind == "smooth":
        return np.exp(lo + (hi - lo) * (0.5 + 0.5 * np.sin(np.linspace(0, rng.uniform(1, 20), n))))
    if kind == "two-valued":
        return np.where(rng.random(n) < 0.5, np.exp(rng.uniform(lo, 0)), np.exp(rng.uniform(0, hi)))
    if kind in ("one-fine", "two-fine"):
        delta = np.full(n, high)
        delta[rng.choice(n, 1 if kind == "one-fine" else 2, replace=False)] = low
        return delta
    return np.full(n, np.exp(rng.uniform(lo, hi)))


def _interior_edges(tris: np.ndarray) -> np.ndarray:
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    edges, counts = np.unique(e, axis=0, return_counts=True)
    return edges[counts == 2]


def _interior_vertices(tris: np.ndarray) -> np.ndarray:
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    edges, counts = np.unique(e, axis=0, return_counts=True)
    on_boundary = np.zeros(tris.max() + 1, bool)
    on_boundary[edges[counts == 1].ravel()] = True
    return np.flatnonzero(~on_boundary[: tris.max() + 1])


#: Mutations that always make a valid mesh invalid (Mesh must raise).
INVALID_MUTATIONS = (
    "index-too-large", "index-negative", "repeated-vertex", "duplicate-triangle", "duplicate-point",
    "orphan-point", "nan", "inf", "beyond-1e75", "non-manifold-edge", "vertex-outside-its-star",
    "float-triangles", "string-points", "no-triangles", "collinear-only", "points-1d",
)
#: Mutations that may or may not leave a valid mesh (Mesh raises or accepts).
MAYBE_MUTATIONS = ("random-triangle", "swap-points", "move-point", "drop-triangles", "move-point-onto-edge")


@st.composite
def mutated_mesh_arrays(draw, invalid: bool = True):
    """(points, triangles, mutation) from a valid mesh by one mutation: from
    INVALID_MUTATIONS (invalid=True) or MAYBE_MUTATIONS (invalid=False)."""
    mesh = draw(any_meshes())
    pts = np.array(mesh.points)
    tris = np.array(mesh.triangles)
    n, m = len(pts), len(tris)
    mutation = draw(st.sampled_from(INVALID_MUTATIONS if invalid else MAYBE_MUTATIONS))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    i, j = int(rng.integers(m)), int(rng.integers(3))
    v = int(rng.integers(n))
    span = np.ptp(pts, axis=0).max()
    if mutation == "index-too-large":
        tris[i, j] = n + int(rng.integers(0, 3))
    elif mutation == "index-negative":
        tris[i, j] = -1 - int(rng.integers(0, 3))
    elif mutation == "repeated-vertex":
        tris[i, (j + 1) % 3] = tris[i, j]
    elif mutation == "duplicate-triangle":
        tris = np.r_[tris, tris[i : i + 1, rng.permutation(3)]]
    elif mutation == "duplicate-point":
        pts = np.r_[pts, pts[tris[i, j]][None]]
        tris[i, j] = n
    elif mutation == "orphan-point":
        pts = np.r_[pts, [pts.min(axis=0) - (0.5 + rng.random(2)) * span]]
    elif mutation in ("nan", "inf"):
        pts[v, int(rng.integers(2))] = np.nan if mutation == "nan" else -np.inf
    elif mutation == "beyond-1e75":
        pts[v, int(rng.integers(2))] = 1.01e75 * rng.choice([-1, 1])
    elif mutation == "non-manifold-edge":
        edges = _interior_edges(tris)
        if len(edges) == 0:  # a single triangle: make an edge of it shared three times
            edges = tris[:1, :2]
            pts = np.r_[pts, pts[edges[0]].mean(axis=0)[None] + [[span, span * 0.5]]]
            tris = np.r_[tris, [[edges[0][0], edges[0][1], n]]]
            n += 1
        a, b = edges[int(rng.integers(len(edges)))]
        far = pts.max(axis=0) + (1 + rng.random(2)) * span
        pts = np.r_[pts, far[None]]
        tris = np.r_[tris, [[a, b, n]]]
    elif mutation == "vertex-outside-its-star":
        inner = _interior_vertices(tris)
        if len(inner) == 0:  # no interior vertex: fall back to a repeated vertex
            tris[i, (j + 1) % 3] = tris[i, j]
        else:
            w = int(inner[rng.integers(len(inner))])
            link = np.unique(tris[(tris == w).any(axis=1)])
            link = link[link != w]
            u = int(link[rng.integers(len(link))])
            # beyond a link vertex on the ray from w: outside the star polygon
            pts[w] = pts[u] + rng.uniform(0.1, 2.0) * (pts[u] - pts[w])
    elif mutation == "float-triangles":
        tris = tris.astype(float)
    elif mutation == "string-points":
        pts = pts.astype(str)
    elif mutation == "no-triangles":
        tris = tris[:0]
    elif mutation == "collinear-only":  # exactly collinear: small integers times a power of two
        t = np.unique(rng.integers(-50, 50, max(3, n))).astype(float)
        if len(t) < 3:
            t = np.array([0.0, 1.0, 2.0])
        pts = np.c_[t, 2 * t + 1] * 2.0 ** int(rng.integers(-30, 30))
        k = len(pts)
        tris = np.c_[np.arange(k - 2), np.arange(1, k - 1), np.arange(2, k)]
    elif mutation == "points-1d":
        pts = pts[:, 0]
    elif mutation == "random-triangle":
        tris = np.r_[tris, [rng.choice(n, 3, replace=False)]]
    elif mutation == "swap-points":
        a, b = rng.choice(n, 2, replace=False)
        pts[[a, b]] = pts[[b, a]]
    elif mutation == "move-point":
        pts[v] = pts.min(axis=0) + rng.random(2) * np.ptp(pts, axis=0)
    elif mutation == "drop-triangles":
        keep = rng.random(m) >= rng.uniform(0.05, 0.5)
        keep[int(rng.integers(m))] = True
        tris = tris[keep]
    else:  # move-point-onto-edge: a vertex onto the midpoint of a random edge (hanging node)
        a, b = tris[i, j], tris[i, (j + 1) % 3]
        pts[v] = 0.5 * (pts[a] + pts[b])
    return pts, tris, mutation


#: Bad delta for a mesh of n points; each must raise ValueError or TypeError.
BAD_DELTAS = ("nan", "inf", "negative", "zero", "below-min", "above-max", "too-short", "too-long", "column", "str")


@st.composite
def bad_deltas(draw, n: int):
    kind = draw(st.sampled_from(BAD_DELTAS))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    delta = np.exp(rng.uniform(np.log(0.2), np.log(5.0), n))
    k = int(rng.integers(n))
    if kind in ("nan", "inf", "negative", "zero", "below-min", "above-max"):
        delta[k] = {"nan": np.nan, "inf": np.inf, "negative": -delta[k], "zero": 0.0,
                    "below-min": 1e-7 * rng.random(), "above-max": 1e6 * (1 + rng.random())}[kind]
    elif kind == "too-short":
        delta = delta[: int(rng.integers(n))]
    elif kind == "too-long":
        delta = np.r_[delta, delta[: int(rng.integers(1, n + 1))]]
    elif kind == "column":
        delta = delta[:, None]
    else:
        delta = delta.astype(str)
    return delta, kind
