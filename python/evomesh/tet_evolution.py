"""One step of FRFC on a tetrahedral mesh of a convex polyhedron, and the
linear transfer of fields through its lineage. :func:`evomesh.evolve` calls
:func:`evolve_tet` for a :class:`~evomesh.TetMesh`."""

from __future__ import annotations

import dataclasses
import numbers
import time
from typing import Any, Callable

import numpy as np

from evomesh import _core
from evomesh.tet_domains import facet_tags, polyhedral_domain, triangle_facets
from evomesh.tet_mesh import TetLineage, TetMesh, TetPointKind, boundary_faces

__all__ = ["TetOptions", "evolve_tet", "transfer_tet"]

DELTA_MIN, DELTA_MAX = 1e-6, 1e6


@dataclasses.dataclass(frozen=True)
class TetOptions:
    """Options of the tetrahedral step (all optional).

    cell_factor : float, default 2.0
        c in the sampling cell side c f(q) / (2 sqrt 3) (faces c f / (2 sqrt 2),
        edges c f / 2): a cell's diagonal is c f / 2.
    radius_scale : float in (0, 1], default 0.75
        Spheres are B(x, radius_scale f(x) / 2) (1.0: the paper's). Below 1
        the packing is tighter, so a refining request gets new points between
        the old ones (with 1.0 a uniform delta = 0.5 keeps the old points and
        adds none).
    boundary_clearance : float, default 0.5
        A point closer than boundary_clearance f(x) to the plane of a facet
        around it that it is not on is not kept (the near-boundary rule: no
        flat tetrahedron on a facet, no facet point next to an edge).
    max_radius_edge : float, default 2.0
        Delaunay refinement after the packing: a tetrahedron whose
        circumradius exceeds this times its shortest edge gets its
        circumcentre (or its projection onto a facet near it, or onto an edge
        when that projection is near the edge), in rounds,
        with at most a tenth of the points plus 100 insertions
        (``stats["radius_edge_unresolved"]`` counts what is left). 0: none.
    sliver_angle : float in [0, 30], default 10.0
        The sliver pass: every tetrahedron with a dihedral angle below this
        or above 180 minus it (degrees) with a new vertex tries that vertex at
        random points of a small ball (0.15 of its shortest edge; a new
        point on a facet stays in that facet) and keeps the position whose
        tetrahedra around it have the largest margin of dihedral angles
        (radius-edge still within ``max_radius_edge``). Old points, edges
        and corners never move. The slivers left (four old points, say) get
        a new point in their circumsphere (the circumcentre, or its
        projection onto a facet it is near or beyond), and the moves run
        again, up to four times. ``stats`` reports ``slivers_before`` /
        ``slivers_after`` (tetrahedra outside the bounds), ``sliver_points_moved``
        and ``sliver_off_centres`` (points inserted). Slivers are measured,
        not excluded: ``slivers_after`` may be above 0. 0: no pass.
    size_factor : float, default 0.9
        With ``size=h``: f = size_factor h, which
        gives a median edge length close to h (measured against MMG3D:
        benchmarks/tet_moving_sphere.py).
    size_tolerance : float >= 1, default 1.25
        With ``size=h``: where the mean edge length L(p) at an old point is
        within this factor of h(p) either way (the mesh meets the request
        there), the point asks for min(size_factor L(p), nn(p) / radius_scale)
        instead of size_factor h(p): such neighbours never conflict in the
        packing, so they stay. On the moving-sphere benchmark 99 % of these
        points are kept (81-84 % with 1, which always asks for h)
        (benchmarks/README.md).
    max_samples : float, default 5e7
        Refuse (ValueError) a step whose sampling grids hold more cells.
    threads : int or None
        Threads of the parallel stages (None: evomesh.default_thread_count());
        results do not depend on it.
    seed : int, default 0
    """

    cell_factor: float = 2.0
    radius_scale: float = 0.75
    boundary_clearance: float = 0.5
    max_radius_edge: float = 2.0
    sliver_angle: float = 10.0
    size_factor: float = 0.9
    size_tolerance: float = 1.25
    max_samples: float = 5e7
    threads: int | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if field.name not in ("threads", "seed") and (not isinstance(value, numbers.Real)
                                                          or isinstance(value, bool)):
                raise ValueError(f"{field.name} must be a number, got {value!r}")
        for name in ("size_factor", "size_tolerance"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite positive number, got {value!r}")
        if self.size_tolerance < 1:
            raise ValueError(f"size_tolerance must be at least 1, got {self.size_tolerance!r}")
        if self.threads is not None and (not isinstance(self.threads, int) or self.threads < 1):
            raise ValueError(f"threads must be a positive integer or None, got {self.threads!r}")
        if not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {self.seed!r}")
        # The ranges of the step's own options: checked where the step checks them.
        _core.check_tet_options(self.cell_factor, self.radius_scale, self.boundary_clearance, self.max_radius_edge,
                                self.sliver_angle, self.max_samples, self.threads or 0)


def _per_point(value: Any, n: int, name: str) -> np.ndarray:
    array = np.asarray(value)
    if array.dtype == object or array.dtype.kind not in "fiu":
        raise TypeError(f"{name} must be numeric")
    array = np.broadcast_to(array.astype(np.float64), (n,)) if array.ndim == 0 else array.astype(np.float64)
    if array.shape != (n,):
        raise ValueError(f"{name} must be a scalar or have one value per point: shape ({n},), got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} contains NaN or infinite values")
    return array


def _size_values(size: Any, x: np.ndarray) -> np.ndarray:
    values = np.asarray(size(x), dtype=np.float64)
    if values.shape != (len(x),):
        raise ValueError(f"size(x) must return one value per point: shape ({len(x)},), got {values.shape}")
    if not (np.isfinite(values).all() and (values > 0).all()):
        raise ValueError("size(x) must be finite and positive")
    return values


def _barycentric(points: np.ndarray, tetrahedra: np.ndarray, parent: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of x in the tetrahedra `parent`, shape (k, 4)."""
    p = points[tetrahedra[parent]]
    a = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)
    lam = np.linalg.solve(a, (x - p[:, 0])[:, :, None])[:, :, 0]
    return np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)


def _mean_edge_length(mesh: TetMesh) -> np.ndarray:
    """Mean length of the edges at each point, shape (n,)."""
    e = mesh.tetrahedra[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]].reshape(-1, 2)
    e = np.unique(np.sort(e, axis=1), axis=0)
    length = np.linalg.norm(mesh.points[e[:, 1]] - mesh.points[e[:, 0]], axis=1)
    total = np.bincount(e.ravel(), weights=np.repeat(length, 2), minlength=mesh.n_points)
    return total / np.bincount(e.ravel(), minlength=mesh.n_points)


def _size_weight(mesh: TetMesh, h: np.ndarray, options: TetOptions) -> np.ndarray:
    """The weights w_p of a size request: size_factor h(p), except at points
    where the mesh already meets it (the mean edge length L(p) at the point
    within a factor ``size_tolerance`` of h(p) either way), which ask for
    min(size_factor L(p), nn(p) / radius_scale): no two such neighbours
    conflict in the packing (their spheres' radii are at most half their
    shortest edges), so the points stay where the request did not change
    much (as MMG keeps edges within its length bounds)."""
    weight = options.size_factor * h
    if options.size_tolerance <= 1:
        return weight
    length = _mean_edge_length(mesh)
    meets = (length <= options.size_tolerance * h) & (h <= options.size_tolerance * length)
    settled = np.minimum(options.size_factor * length, mesh.nn_spacing / options.radius_scale)
    return np.where(meets, settled, weight)


def evolve_tet(mesh: TetMesh, delta: Any = None, *, size: Any = None, seed: int | None = None,
               options: TetOptions | None = None, **overrides: Any) -> TetMesh:
    """One FRFC step on a tetrahedral mesh of a convex polyhedron.

    Parameters
    ----------
    mesh : TetMesh
        A mesh of a convex polyhedron whose facets meet at 90 degrees or more
        (:func:`evomesh.tet_domains.polyhedral_domain`): a box, or the meshes
        of :func:`evomesh.convex_polyhedron_mesh`. Its facets and edges stay
        exactly where they are; corners are always kept.
    delta : float or array_like, shape (n,)
        New spacing delta(p) nn(p) at every point, in [1e-6, 1e6].
    size : float, array_like of shape (n,), or callable
        Target edge length h instead (exactly one of delta and size): a number,
        one value per point, or h(x) of an (k, 3) array returning (k,) values.
        f = min(cone envelope of size_factor h(p), size_factor h(x)) at new
        points (a per-point array is interpolated linearly in the old
        tetrahedron), so the mesh does not drift coarser between old points.
    seed : int, optional
        Seed of the sampling (default ``options.seed``); the same input gives
        the same bits on any number of threads.
    options : TetOptions, optional
    **overrides
        Single fields of :class:`TetOptions`.

    Returns
    -------
    TetMesh
        With ``origin`` (index in ``mesh``, -1 new; kept points have
        bit-identical coordinates), ``kind``, ``lineage`` (for
        :func:`evomesh.transfer`) and ``stats``.

    Raises
    ------
    ValueError
        A bad request, or a domain the step does not support: not convex
        (an L-shaped block, a box with a hole), facets meeting below 90
        degrees, a non-manifold boundary, a tilted facet whose corners leave
        no float64 points exactly on it, face tags that vary within a facet,
        several regions (tet_tags).
    """
    start = time.process_time()
    if not isinstance(mesh, TetMesh):
        raise TypeError(f"mesh must be a TetMesh, got {type(mesh).__name__}")
    if options is None:
        options = TetOptions()
    elif not isinstance(options, TetOptions):
        raise TypeError(f"options for a TetMesh must be TetOptions, got {type(options).__name__}")
    if overrides:
        unknown = set(overrides) - {f.name for f in dataclasses.fields(TetOptions)}
        if unknown:
            raise TypeError(f"unknown option(s) for a TetMesh: {', '.join(sorted(unknown))}")
        options = dataclasses.replace(options, **overrides)
    if seed is None:
        seed = options.seed
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if (delta is None) == (size is None):
        raise ValueError("give exactly one of delta and size")
    if len(np.unique(mesh.tet_tags)) > 1:
        raise ValueError("evolve on a TetMesh does not support several regions (tet_tags) yet")
    domain = polyhedral_domain(mesh)
    tags_of_facet = facet_tags(mesh, domain)
    n = mesh.n_points
    nn = mesh.nn_spacing
    cap: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    if delta is not None:
        d = _per_point(delta, n, "delta")
        if (d < DELTA_MIN).any() or (d > DELTA_MAX).any():
            raise ValueError(f"delta must be in [{DELTA_MIN:g}, {DELTA_MAX:g}]")
        weight = d * nn
    else:
        kappa = options.size_factor
        if callable(size):
            h = _size_values(size, mesh.points.copy())
            user_size = size

            def cap(x: np.ndarray, tet: np.ndarray) -> np.ndarray:
                return kappa * _size_values(user_size, x)
        else:
            h = _per_point(size, n, "size")
            if not (h > 0).all():
                raise ValueError("size must be positive")
            if np.ndim(size) == 0:
                def cap(x: np.ndarray, tet: np.ndarray) -> np.ndarray:
                    return np.full(len(x), kappa * h[0])
            else:
                def cap(x: np.ndarray, tet: np.ndarray) -> np.ndarray:
                    lam = _barycentric(mesh.points, mesh.tetrahedra, tet, x)
                    return kappa * (lam * h[mesh.tetrahedra[tet]]).sum(axis=1)
        weight = _size_weight(mesh, h, options)
    faces, face_tet = mesh.boundary_faces
    steiner = (mesh.kind >= TetPointKind.STEINER).astype(np.uint8)
    threads = 0 if options.threads is None else options.threads
    out = _core.tet_step(mesh.points, mesh.tetrahedra, faces, face_tet, steiner, mesh.required.astype(np.uint8),
                         weight, *domain.arrays, domain.triangle_facet, options.cell_factor, options.radius_scale,
                         options.boundary_clearance, options.max_radius_edge, options.sliver_angle,
                         options.max_samples, int(seed), threads, cap)
    points, tets, origin = out["points"], out["tetrahedra"], out["origin"]
    new_faces, new_face_tet = boundary_faces(tets)
    face_tags = None
    if tags_of_facet is not None:
        face_tags = tags_of_facet[triangle_facets(out["facets"], new_faces)]
    tet_tags = None if not mesh.tet_tags.any() else np.full(len(tets), mesh.tet_tags[0], np.int64)
    required = None
    if mesh.required.any():
        required = np.zeros(len(points), bool)
        kept = origin >= 0
        required[kept] = mesh.required[origin[kept]]
    stats = dict(out["stats"])
    n_kept = int((origin >= 0).sum())
    stats.update(n_points=float(len(points)), n_tetrahedra=float(len(tets)), kept_old_points=float(n_kept),
                 kept_fraction=n_kept / n, new_points=float(len(points) - n_kept),
                 cpu_seconds=time.process_time() - start)
    lineage = TetLineage(n, mesh.n_tetrahedra, out["parent_tet"])
    return TetMesh._trusted(points, tets, new_faces, face_tags, tet_tags, required, out["kind"], origin, lineage,
                            stats, (new_faces, new_face_tet), mesh.tag_names)


def transfer_tet(old: TetMesh, new: TetMesh, values: Any) -> np.ndarray:
    """Per-vertex field(s) of ``old`` at the points of ``new = evolve(old, ...)``:
    copied at kept points (bit for bit), linear in the old tetrahedron holding
    each new point (its lineage) elsewhere; linear fields are reproduced to
    rounding. values: shape (n_old,) or (n_old, ...)."""
    if not isinstance(old, TetMesh) or not isinstance(new, TetMesh):
        raise TypeError("transfer between tetrahedral meshes needs two TetMesh")
    array = np.asarray(values)
    if array.dtype == object or array.dtype.kind not in "fciub":
        raise TypeError(f"values must be numeric, got dtype {array.dtype}")
    if array.ndim == 0 or len(array) != old.n_points:
        raise ValueError(f"values must have one row per old point ({old.n_points})")
    if array.dtype.kind != "c":
        array = array.astype(np.float64)
    lineage = new.lineage
    if lineage is None or not lineage.matches(old):
        raise ValueError("transfer to a TetMesh needs new = evolve(old, ...) (its lineage locates the new points)")
    out = np.empty((new.n_points,) + array.shape[1:], dtype=array.dtype)
    kept = new.origin >= 0
    out[kept] = array[new.origin[kept]]
    fresh = np.flatnonzero(~kept)
    if len(fresh):
        parent = lineage.parent_tet[fresh]
        lam = _barycentric(old.points, old.tetrahedra, parent, new.points[fresh])
        corner_values = array[old.tetrahedra[parent]]  # (k, 4, ...)
        out[fresh] = np.einsum("kv,kv...->k...", lam, corner_values)
    return out

