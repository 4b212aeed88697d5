"""Reusable checks of the properties every evomesh output must have."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

import evomesh
from evomesh import PointKind
from evomesh.mesh_quality import integral_inverse_square as _integral_inverse_square


def edges_with_counts(triangles: np.ndarray):
    e = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)


def boundary_edges(triangles: np.ndarray) -> np.ndarray:
    edges, counts = edges_with_counts(triangles)
    return edges[counts == 1]


def distance_to_segments(points: np.ndarray, a: np.ndarray, b: np.ndarray, chunk: int = 256) -> np.ndarray:
    """Distance from each point to the nearest of the segments a[k]-b[k]."""
    out = np.empty(len(points))
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    for s in range(0, len(points), chunk):
        p = points[s : s + chunk, None, :]
        t = np.clip(np.einsum("pkj,kj->pk", p - a[None], d) / dd[None], 0, 1)
        closest = a[None] + t[..., None] * d[None]
        out[s : s + chunk] = np.linalg.norm(p - closest, axis=2).min(axis=1)
    return out


def check_valid_mesh(mesh: evomesh.Mesh) -> None:
    """A mesh on its own: CCW triangles, no orphans, no duplicates, segments."""
    areas = mesh.triangle_areas
    assert (areas > 0).all(), f"{int((areas <= 0).sum())} triangles with non-positive area"
    used = np.bincount(mesh.triangles.ravel(), minlength=mesh.n_points)
    assert (used > 0).all(), f"orphan points: {np.flatnonzero(used == 0)[:5]}"
    assert len(np.unique(mesh.points, axis=0)) == mesh.n_points, "duplicate points"
    edges, counts = edges_with_counts(mesh.triangles)
    assert counts.max() <= 2, "an edge of more than two triangles"
    seg = np.sort(mesh.segments, axis=1)
    bnd = edges[counts == 1]
    seg_b = seg[mesh.segment_is_boundary]
    # every boundary edge is a boundary segment and vice versa
    assert len(seg_b) == len(bnd)
    assert (np.unique(seg_b, axis=0) == bnd).all()
    # interior segments are edges of two triangles
    interior = seg[~mesh.segment_is_boundary]
    if len(interior):
        key = {tuple(e) for e in edges[counts == 2]}
        assert all(tuple(e) in key for e in interior)
    assert mesh.origin.shape == (mesh.n_points,)
    assert mesh.kind.shape == (mesh.n_points,)
    on_segment = np.zeros(mesh.n_points, bool)
    on_segment[mesh.segments.ravel()] = True
    assert ((mesh.kind <= PointKind.BOUNDARY) == on_segment).all(), "kind disagrees with segments"


def check_evolved(
    old: evomesh.Mesh, new: evomesh.Mesh, *, rel_area: float = 1e-12, rel_distance: float = 1e-12
) -> None:
    """Output of evolve against its input: domain, boundary, corners, origins.

    Points sampled on a slanted boundary segment are rounded to doubles, so they
    lie on it only up to ulp(|x|): for a mesh far from the origin compared with
    its size, loosen rel_area and rel_distance (relative to the mesh size)."""
    check_valid_mesh(new)
    assert abs(new.area - old.area) <= rel_area * old.area, (new.area, old.area)
    assert new.euler_characteristic() == old.euler_characteristic()
    kept = new.origin >= 0
    # kept points keep their exact coordinates; origins are distinct
    assert (new.points[kept] == old.points[new.origin[kept]]).all()
    assert len(np.unique(new.origin[kept])) == int(kept.sum())
    # every corner of the input is kept, as a corner
    corners = np.flatnonzero(old.kind == PointKind.CORNER)
    assert np.isin(corners, new.origin).all(), "a corner was dropped"
    # boundary edges of the output lie on the input's boundary
    ob = boundary_edges(old.triangles)
    nb = boundary_edges(new.triangles)
    scale = np.ptp(old.points, axis=0).max()
    for probe in (new.points[nb[:, 0]], new.points[nb[:, 1]], new.points[nb].mean(axis=1)):
        dist = distance_to_segments(probe, old.points[ob[:, 0]], old.points[ob[:, 1]])
        assert dist.max() <= rel_distance * scale, dist.max()


def rounding_tolerances(mesh: evomesh.Mesh, steps: int = 1) -> dict[str, float]:
    """Rounding tolerances of check_evolved after `steps` steps. A point sampled
    on a slanted boundary segment is on it only up to ulp(|x|) ~ eps max|x|,
    and a chain straight up to STRAIGHT_ULPS roundings may be straightened
    (its vertices are not corners), which moves the boundary by that much and
    the area by that times the perimeter: large for meshes far from the origin
    or thin (perimeter^2 >> area)."""
    eps = np.finfo(float).eps
    ulps = 4 * steps + evomesh._core.STRAIGHT_ULPS
    reach = float(np.abs(mesh.points).max())
    size = float(np.ptp(mesh.points, axis=0).max())
    b = mesh.segments[mesh.segment_is_boundary]
    perimeter = float(np.linalg.norm(mesh.points[b[:, 1]] - mesh.points[b[:, 0]], axis=1).sum())
    return {
        "rel_area": 1e-12 + ulps * eps * reach * perimeter / mesh.area,
        "rel_distance": 1e-12 + ulps * eps * reach / size,
    }


def nn_in(mesh_points: np.ndarray, probes: np.ndarray) -> np.ndarray:
    """nn_M(x) for probe points x: distance to the nearest mesh point other than x."""
    d, _ = cKDTree(mesh_points).query(probes, k=2)
    return np.where(d[:, 0] == 0, d[:, 1], d[:, 0])


def spacing_ratio(old: evomesh.Mesh, new: evomesh.Mesh, delta: np.ndarray) -> np.ndarray:
    """nn_M'(p) / (delta(p) nn_M(p)) for every input point p."""
    return nn_in(new.points, old.points) / (delta * evomesh.nn_spacing(old))


def integral_inverse_square(mesh: evomesh.Mesh, f, levels: int = 3) -> float:
    """Integral of 1/f^2 over the mesh's domain (evomesh.mesh_quality's, 64 sub-triangles each)."""
    return _integral_inverse_square(mesh.points, mesh.triangles, f, levels=levels)


def hausdorff_to_union_of_circles(points: np.ndarray, segments: np.ndarray, centres: list[tuple[float, float]],
                                  radius: float, step: float = 2e-5) -> float:
    """The Hausdorff distance between the polyline of `segments` and the
    boundary of the union of circles of one radius, both sampled `step` apart."""
    exact = []
    for cx, cy in centres:
        angle = np.linspace(0, 2 * np.pi, int(2 * np.pi * radius / step), endpoint=False)
        p = np.stack([cx + radius * np.cos(angle), cy + radius * np.sin(angle)], axis=1)
        outside = np.ones(len(p), dtype=bool)
        for dx, dy in centres:
            if (dx, dy) != (cx, cy):
                outside &= np.hypot(p[:, 0] - dx, p[:, 1] - dy) >= radius
        exact.append(p[outside])
    on_circles = np.concatenate(exact)
    a, b = points[segments[:, 0]], points[segments[:, 1]]
    k = np.maximum(1, np.ceil(np.hypot(*(b - a).T) / step).astype(int))
    index = np.repeat(np.arange(len(segments)), k)
    t = (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)) / np.repeat(k, k)
    on_polyline = a[index] + t[:, None] * (b - a)[index]
    return float(max(cKDTree(on_circles).query(on_polyline)[0].max(), cKDTree(on_polyline).query(on_circles)[0].max()))
