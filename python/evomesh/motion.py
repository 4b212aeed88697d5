"""Lagrangian motion: a step that moves the points of a mesh before it evolves it.

``evolve(mesh, delta, displacement=u)`` moves every point p of ``mesh`` to
p + u(p) (boundary, interface and interior points alike), then evolves the
moved mesh as usual. Where the motion folds triangles (turns one over, or
squeezes it flat), the folded region is remeshed: its interior points that
came too close to others are dropped and the moved points are triangulated
again (constrained Delaunay, with the moved boundary and interface segments as
constraints; each region keeps its tag, flood-filled from the sides of its
borders). The move itself is :func:`move`; the step's lineage relates the new
mesh to the old one at the OLD positions (see :class:`Motion` and
:func:`evomesh.transfer`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from evomesh import _core
from evomesh.geometry import BoundaryGeometry
from evomesh.mesh import (
    _MIN_HEIGHT_ULPS,
    _MIN_RELATIVE_HEIGHT,
    Lineage,
    Mesh,
    _as_array,
)
from evomesh.spacing_function import DELTA_MAX, DELTA_MIN, _require_mesh, as_delta

__all__ = ["Motion", "move"]

# Interior points of a folded region are kept only as far as the spheres
# B(p, _FOLD_SPACING nn_M(p)) (nn_M before the move) stay apart: two points
# that a fold brought together would otherwise ask the step for a spacing of
# their distance (delta is relative to nn_M), a refinement that never goes away.
_FOLD_SPACING = 0.25
# Triangles within this factor of Mesh's flatness limits count as folded (see _folded).
_FLAT_MARGIN = 2.0
# Rounds of "triangulate, drop the points that keep the result from being a
# mesh"; each drops every offending point at once, so two or three suffice.
_MAX_REPAIR_ROUNDS = 16


class Motion(NamedTuple):
    """A move of a mesh's points (:func:`move`), and how a step went on from it.

    Attributes
    ----------
    mesh : Mesh
        The moved mesh: the old points at p + u(p) (those a fold repair
        dropped left out), a valid :class:`Mesh`. Its ``origin`` indexes the
        old mesh.
    displacement : ndarray, shape (n_old, 2)
        The displacement applied to every old point (after boundary points were
        projected onto their curve); rows of dropped points included.
    stats : dict
        ``motion_largest_displacement``, ``motion_folded_triangles`` (turned
        over or flat after the move), ``motion_remeshed`` (1 when the folded
        region was triangulated again), ``motion_points_dropped`` (interior
        points the repair dropped: brought within a quarter of their spacing of
        another point by a fold, moved onto a segment, or passed by a moving
        boundary), ``motion_points_dropped_outside`` (of those, the ones a
        moving boundary passed), ``motion_points_projected`` (boundary points
        moved onto their curve).
    origin : ndarray of int, shape (n_new,), or None
        After a step: each new point's index in ``mesh`` (-1: new).
    lineage : Lineage or None
        After a step: the step's own lineage, relative to ``mesh``.
    """

    mesh: Mesh
    displacement: np.ndarray
    stats: dict
    origin: np.ndarray | None = None
    lineage: Lineage | None = None


def _as_displacement(mesh: Mesh, displacement: Any) -> np.ndarray:
    """The displacement at every point, (n, 2) float64 (a copy), checked finite."""
    if callable(displacement):
        values = _as_array(displacement(np.array(mesh.points)), "displacement(x)")
        what = "displacement(x)"
    else:
        values = _as_array(displacement, "displacement")
        what = "displacement"
    if values.dtype == object or values.dtype.kind not in "fiu":
        raise TypeError(f"{what} must be real numbers, got dtype {values.dtype}")
    with np.errstate(over="ignore"):  # long double beyond float64 becomes inf, refused below
        u = np.array(np.broadcast_to(values, (mesh.n_points, 2)) if values.shape == (2,) else values, dtype=np.float64)
    if u.shape != (mesh.n_points, 2):
        raise ValueError(f"{what} must have one (dx, dy) per point: shape ({mesh.n_points}, 2) (or (2,) for a "
                         f"translation), got {u.shape}")
    bad = ~np.isfinite(u).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(f"{what} at point {k} ({mesh.points[k].tolist()}) is not finite: {u[k].tolist()}; "
                         f"{int(bad.sum())} point(s) have a NaN or infinite displacement")
    with np.errstate(over="ignore"):
        moved = mesh.points + u
    bad = ~np.isfinite(moved).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(f"{what} at point {k} moves it beyond float64: {u[k].tolist()}")
    return u


def _curve_of_points(mesh: Mesh, geometry: BoundaryGeometry) -> tuple[np.ndarray, np.ndarray]:
    """The points whose segments all carry one curved tag of ``geometry``, and that tag."""
    segments, tags = mesh.segments, mesh.segment_tags
    low = np.full(mesh.n_points, np.iinfo(np.int64).max)
    high = np.full(mesh.n_points, np.iinfo(np.int64).min)
    for column in (0, 1):
        np.minimum.at(low, segments[:, column], tags)
        np.maximum.at(high, segments[:, column], tags)
    on_one_tag = (low == high) & np.isin(low, np.asarray(geometry.tags, dtype=np.int64))
    points = np.flatnonzero(on_one_tag)
    return points, low[points]


def _side_tags(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Region tag on the left and on the right of every segment a -> b (0 outside)."""
    n = np.int64(mesh.n_points)
    t = mesh.triangles
    directed = np.concatenate([t[:, 0] * n + t[:, 1], t[:, 1] * n + t[:, 2], t[:, 2] * n + t[:, 0]])
    owner = np.tile(np.arange(len(t)), 3)
    order = np.argsort(directed, kind="stable")
    keys = directed[order]

    def tag_of(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        key = a * n + b
        at = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
        found = keys[at] == key
        return np.where(found, mesh.triangle_tags[owner[order[at]]], 0)

    a, b = mesh.segments[:, 0], mesh.segments[:, 1]
    return tag_of(a, b), tag_of(b, a)


def _folded(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Triangles turned over or flat by Mesh's limits (height below 1e-10 of the
    longest edge or below 1024 units of rounding), with a margin of
    _FLAT_MARGIN so that Mesh(), whose arithmetic may round differently, never
    refuses what passes here. The limits certify the sign of the floating-point
    area, so no exact predicate is needed."""
    p = points[triangles]
    e0, e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]
    twice_area = e0[:, 0] * (-e2[:, 1]) - e0[:, 1] * (-e2[:, 0])
    longest = np.sqrt(np.maximum(np.maximum((e0**2).sum(1), (e1**2).sum(1)), (e2**2).sum(1)))
    height = twice_area / np.where(longest > 0, longest, 1.0)
    rounding = np.finfo(np.float64).eps * np.abs(p).max(axis=(1, 2))
    return (~(twice_area > 0) | (height < _FLAT_MARGIN * _MIN_RELATIVE_HEIGHT * longest)
            | (height < _FLAT_MARGIN * _MIN_HEIGHT_ULPS * rounding))


def _flat_vertex(points: np.ndarray, triangles: np.ndarray, droppable: np.ndarray) -> np.ndarray:
    """For each (flat) triangle, the droppable vertex to drop: the one opposite its
    longest edge if droppable, else another droppable one; -1 if none is."""
    p = points[triangles]
    opposite = np.stack([((p[:, 2] - p[:, 1]) ** 2).sum(1), ((p[:, 0] - p[:, 2]) ** 2).sum(1),
                         ((p[:, 1] - p[:, 0]) ** 2).sum(1)], axis=1)
    score = droppable[triangles] * (1.0 + (opposite == opposite.max(axis=1, keepdims=True)))
    best = np.argmax(score, axis=1)
    rows = np.arange(len(triangles))
    return np.where(score[rows, best] > 0, triangles[rows, best], -1)


def _twice_areas(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    p = points[triangles]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]


def _check_orientation_and_resolution(mesh: Mesh, moved: np.ndarray, folded: np.ndarray) -> None:
    """Where the move folds triangles, the two reasons no remeshing can help:
    the moved domain is turned over (the signed areas of the moved triangles
    sum to the area the moved boundary encloses, with its orientation: below
    zero the boundary runs the other way round, as in a mirror image), or a
    folded triangle is below float64's resolution at its new coordinates
    (its height before the move under Mesh's 1024 units of rounding of the
    moved coordinates: the displacement is too large for the mesh's size)."""
    twice = _twice_areas(moved, mesh.triangles)
    total = float(twice.sum())
    if not total > 0:
        raise _nothing_changed(
            f"the displacement turns the domain over: the moved triangles' areas sum to {0.5 * total:.6g} (before: "
            f"{mesh.area:.6g}), and {int((twice < 0).sum())} of {mesh.n_triangles} triangles are inverted, as in a "
            "mirror image; a motion must keep the orientation (to mirror a mesh, make a new Mesh of the mirrored "
            "points and the same triangles: Mesh orients them)")
    t = mesh.triangles[folded]
    old = mesh.points[t]
    longest = np.sqrt(np.max([((old[:, k] - old[:, (k + 1) % 3]) ** 2).sum(axis=1) for k in range(3)], axis=0))
    height = _twice_areas(mesh.points, t) / longest
    rounding = np.finfo(np.float64).eps * np.abs(moved[t]).max(axis=(1, 2))
    below = height < _FLAT_MARGIN * _MIN_HEIGHT_ULPS * rounding  # (as _folded: such a triangle is folded)
    if below.any():
        k = int(np.argmax(below))
        largest = float(np.hypot(*(moved[t[k]] - mesh.points[t[k]]).T).max())
        raise _nothing_changed(
            f"the displacement (up to {largest:.6g} at triangle {int(np.flatnonzero(folded)[k])}, points "
            f"{t[k].tolist()}) moves the mesh to coordinates of magnitude {np.abs(moved[t[k]]).max():.6g}, where "
            f"float64 rounds to {rounding[k]:.3g}: the triangle's height {height[k]:.3g} is below "
            f"{_FLAT_MARGIN:g} x {_MIN_HEIGHT_ULPS} units of rounding (a Mesh needs {_MIN_HEIGHT_ULPS}, the move a "
            "margin), so float64 cannot hold it there: the displacement exceeds float64's resolution relative to "
            "the mesh size; translate the problem instead of the mesh")


def _describe(mesh: Mesh, k: int, moved: np.ndarray) -> str:
    return f"point {k} (from {mesh.points[k].tolist()} to {moved[k].tolist()})"


def _nothing_changed(message: str) -> ValueError:
    return ValueError(f"{message}; the mesh was not changed")


def _inside_old_domain(mesh: Mesh, queries: np.ndarray) -> np.ndarray:
    triangle, _ = _core.locate_points(mesh.points, mesh.triangles, queries)
    return triangle >= 0


def _remesh(mesh: Mesh, moved: np.ndarray, folded: np.ndarray, stats: dict) -> tuple[np.ndarray, np.ndarray,
                                                                                     np.ndarray]:
    """Points kept, triangles and triangle tags of the moved mesh where the move
    folded ``folded`` triangles: constrained Delaunay of the kept moved points,
    regions from the segments' sides (_core.triangulate_moved). Returns (kept
    point indices, triangles in kept indices, triangle tags)."""
    n = mesh.n_points
    droppable = ~mesh.required  # interior points (not on a segment) that no step must keep
    droppable[mesh.segments.ravel()] = False
    suspect = np.zeros(n, dtype=bool)
    suspect[mesh.triangles[folded].ravel()] = True
    suspect &= droppable
    # Points of the folded region that came closer than _FOLD_SPACING (nn_M(p) + nn_M(q))
    # to a point q kept before them are dropped: every other point first, then the
    # folded region's in index order (deterministic; lexical-first MIS).
    order = np.concatenate([np.flatnonzero(~suspect), np.flatnonzero(suspect)])
    radius = _FOLD_SPACING * mesh.nn_spacing
    keep = _core.lexical_first_mis(moved, radius, order, int((~suspect).sum())).astype(bool)
    fixed = ~droppable
    same = np.lexsort((moved[:, 1], moved[:, 0]))
    twins = np.flatnonzero((moved[same[1:]] == moved[same[:-1]]).all(axis=1))
    if len(twins):  # (the MIS drops a droppable twin; two fixed ones collide)
        both_fixed = fixed[same[twins]] & fixed[same[twins + 1]]
        if both_fixed.any():
            a, b = sorted(int(v) for v in same[[twins[both_fixed][0], twins[both_fixed][0] + 1]])
            raise _nothing_changed(f"the displacement moves boundary/interface points {a} and {b} onto the same "
                                   f"place {moved[a].tolist()}")
        keep[np.where(fixed[same[twins]], same[twins + 1], same[twins])] = False
    left, right = _side_tags(mesh)
    is_boundary = mesh.segment_is_boundary.astype(np.uint8)
    dropped_outside = 0
    # Each round triangulates and drops the interior points of one kind of
    # trouble (on a segment, outside the domain, in a flat triangle), or fails
    # naming a point it must not drop.
    for _ in range(_MAX_REPAIR_ROUNDS):
        index = np.flatnonzero(keep)
        local = np.full(n, -1, dtype=np.int64)
        local[index] = np.arange(len(index))
        result = _core.triangulate_moved(moved[index], local[mesh.segments], is_boundary, left, right)
        if result["crossing"] >= 0:
            k = int(result["crossing"])
            a, b = (int(v) for v in mesh.segments[k])
            what = "boundary" if mesh.segment_is_boundary[k] else "interior"
            raise _nothing_changed(
                f"the displacement makes {what} segment {k} (points {a}, {b}, moved to {moved[a].tolist()}, "
                f"{moved[b].tolist()}) cross another segment: the moved boundary and interfaces must not cross")
        on_piece = result["on_piece"]
        if len(on_piece):  # (the pieces it splits seed no region: nothing else is final this round)
            point = index[on_piece[:, 0]]
            stuck = ~droppable[point]
            if stuck.any():
                k = int(np.argmax(stuck))
                a, b = (int(v) for v in mesh.segments[on_piece[k, 1]])
                raise _nothing_changed(f"the displacement moves {_describe(mesh, int(point[k]), moved)} onto "
                                       f"segment ({a}, {b}): boundary and interface segments must not touch")
            keep[point] = False
            continue
        if result["conflict"] >= 0:
            k = int(result["conflict"])
            a, b = (int(v) for v in mesh.segments[k])
            raise _nothing_changed(
                f"the displacement changes which regions the segments bound (segment {k}, points {a}, {b}: its sides "
                "meet the outside or another region): a hole or a region moved across another")
        unused = index[result["unused"]]
        if len(unused):
            stuck = ~droppable[unused]
            if stuck.any():  # (a fixed point is on a segment, so only a crossing could leave it out)
                raise _nothing_changed(f"the displacement moves {_describe(mesh, int(unused[stuck][0]), moved)} "
                                       "outside the moved domain")
            inside_old = _inside_old_domain(mesh, moved[unused])
            if not inside_old.all():
                k = int(unused[~inside_old][0])
                raise _nothing_changed(
                    f"the displacement moves {_describe(mesh, k, moved)} outside the domain (the boundary does not "
                    f"move there); {int((~inside_old).sum())} point(s) leave the domain")
            keep[unused] = False  # the moving boundary passed them: the domain shrank there
            dropped_outside += len(unused)
            continue
        triangles = index[result["triangles"]]
        flat = np.flatnonzero(_folded(moved, triangles))
        if len(flat):
            vertex = _flat_vertex(moved, triangles[flat], droppable)
            if (vertex < 0).any():
                t = triangles[flat[int(np.argmax(vertex < 0))]]
                raise _nothing_changed(
                    f"the displacement squeezes boundary/interface points {t.tolist()} (moved to "
                    f"{moved[t].tolist()}) into a flat triangle")
            keep[vertex] = False
            continue
        stats["motion_points_dropped_outside"] = float(dropped_outside)
        return index, local[triangles], result["triangle_tags"]
    raise _nothing_changed(f"the folded region could not be remeshed in {_MAX_REPAIR_ROUNDS} rounds")


def move(mesh: Mesh, displacement: Any, *, geometry: BoundaryGeometry | None = None) -> Motion:
    """Move every point of ``mesh`` by ``displacement``, remeshing where the motion folds triangles.

    Parameters
    ----------
    mesh : Mesh
    displacement : array_like, shape (n, 2) or (2,), or callable
        u(p) at every point (a (2,) array: the same for all), or a function
        u(x) of an (n, 2) array of coordinates returning (n, 2). Every value
        must be finite.
    geometry : BoundaryGeometry, optional
        The curves of the boundary AFTER the move: a point all of whose
        segments carry one curved tag is projected onto that tag's curve after
        it moved (so a rigid motion of the mesh and of its curves keeps the
        boundary on the curves to rounding).

    Returns
    -------
    Motion
        The moved mesh (a valid :class:`Mesh`), the applied displacement and
        statistics. Without folded triangles the moved mesh has the old
        triangles (same order) at the moved points. Otherwise interior points
        of the folded triangles are dropped where they came closer than a
        quarter of their old spacing nn_M to another point (in index order),
        and the moved points are triangulated again (constrained Delaunay of
        the moved boundary and interface segments; regions keep their tags);
        interior points that a moving boundary passed are dropped too.

    Raises
    ------
    TypeError
        If the displacement is not numeric.
    ValueError
        If the displacement has the wrong shape or a NaN/infinite value (the
        message names the first such point), moves an interior point out of
        the domain where the boundary does not move, makes boundary or
        interface segments cross or touch (the domain itself would fold),
        moves two boundary points onto each other, moves a hole or region
        across another, turns the domain over (a mirror image: every triangle
        inverted), or moves a triangle to coordinates where float64 cannot
        hold it (its height below 2 x 1024 units of rounding there: a rigid
        translation by 1e11 of a mesh of spacing 0.03; one that float64 can
        hold is accepted). Nothing is changed then (the input is never
        modified).
    """
    _require_mesh(mesh)
    u = _as_displacement(mesh, displacement)
    moved = mesh.points + u
    stats: dict[str, float] = {
        "motion_largest_displacement": float(np.hypot(u[:, 0], u[:, 1]).max()),
        "motion_points_projected": 0.0,
    }
    if geometry is not None:
        on_curve, tags = _curve_of_points(mesh, geometry)
        if len(on_curve):
            moved[on_curve] = geometry.project(moved[on_curve], tags)
            u = moved - mesh.points
            stats["motion_points_projected"] = float(len(on_curve))
    folded = _folded(moved, mesh.triangles)
    if folded.any():
        _check_orientation_and_resolution(mesh, moved, folded)
    stats["motion_folded_triangles"] = float(folded.sum())
    stats["motion_remeshed"] = float(folded.any())
    stats["motion_points_dropped_outside"] = 0.0
    labels = {"segment_tags": mesh.segment_tags if mesh.segment_tags.any() else None,
              "triangle_tags": mesh.triangle_tags if mesh.triangle_tags.any() else None}
    if folded.any():
        kept, triangles, triangle_tags = _remesh(mesh, moved, folded, stats)
        local = np.full(mesh.n_points, -1, dtype=np.int64)
        local[kept] = np.arange(len(kept))
        segments = local[mesh.segments]
        labels["triangle_tags"] = triangle_tags if labels["triangle_tags"] is not None else None
    else:
        kept, triangles, segments = np.arange(mesh.n_points), mesh.triangles, mesh.segments
    stats["motion_points_dropped"] = float(mesh.n_points - len(kept))
    try:
        moved_mesh = Mesh(moved[kept], triangles, segments, **labels, required=mesh.required[kept],
                          kind=mesh.kind[kept], origin=kept, tag_names=mesh.tag_names)
    except ValueError as error:
        raise _nothing_changed(f"the displacement does not leave a valid mesh: {error}") from None
    return Motion(moved_mesh, u, stats)


def step_input(mesh: Mesh, displacement: Any, delta: Any, size: Any,
               geometry: BoundaryGeometry | None) -> tuple[Motion, Any, Any]:
    """What :func:`evomesh.evolve` evolves for ``displacement=``: the move, and
    the request (delta or size) at the moved mesh's points.

    ``delta`` is relative to the spacing BEFORE the move: the moved point p is
    asked for the spacing delta(p) nn_M(p) with the old nn_M, i.e. the factor
    delta(p) nn_M(p) / nn_moved(p) on the moved mesh, so delta = 1 keeps the
    resolution the mesh had wherever the motion squeezed or stretched it (a
    shear brings points closer: relative to the moved spacing, delta = 1 would
    refine there, step after step), and a zero displacement is the step
    without one, bit for bit. Arrays are checked against ``mesh`` and
    restricted to the points the move kept; a callable size is evaluated at the
    moved points by the step."""
    if delta is not None:
        delta = as_delta(mesh, delta)
    elif not callable(size):
        array = _as_array(size, "size")
        if array.ndim and array.shape != (mesh.n_points,):
            raise ValueError(f"size must give one value per point: shape ({mesh.n_points},), got {array.shape}")
    motion = move(mesh, displacement, geometry=geometry)
    origin = motion.mesh.origin
    if delta is not None:
        moved_nn = motion.mesh.nn_spacing
        # (the same nn gives the factor 1 exactly: delta unchanged where nothing moved)
        factor = np.where(moved_nn == mesh.nn_spacing[origin], 1.0, mesh.nn_spacing[origin] / moved_nn)
        return motion, np.clip(delta[origin] * factor, DELTA_MIN, DELTA_MAX), None
    if not callable(size) and np.ndim(size):
        size = np.asarray(size)[origin]
    return motion, None, size


def after_step(old: Mesh, motion: Motion, new: Mesh) -> Mesh:
    """``new`` (a step's output from ``motion.mesh``) related to ``old``: origins
    index old, and the lineage locates every new point in old at the old
    positions (an Eulerian remap: see :func:`evomesh.transfer`); the step's own
    lineage stays in ``lineage.motion``."""
    step_origin = np.array(new.origin)
    through = motion.mesh.origin
    origin = np.where(step_origin >= 0, through[np.maximum(step_origin, 0)], -1)
    parent, barycentric = _core.locate_points(old.points, old.triangles, new.points)
    step = new.lineage
    old_nn = np.full(old.n_points, np.nan)
    old_f = np.full(old.n_points, np.nan)
    if step is not None:
        old_nn[through] = step.old_nn
        old_f[through] = step.old_f
    done = Motion(motion.mesh, motion.displacement, motion.stats, step_origin, step)
    lineage = Lineage(old.n_points, old.n_triangles, parent, barycentric, old_nn, old_f, motion=done)
    stats = dict(new.stats)
    stats.update(motion.stats)
    known = new._known_nn()
    return Mesh._trusted(new.points, new.triangles, new.segments, new.segment_is_boundary, new.kind, origin, stats,
                         lineage, known.get("nn"), new.segment_tags, new.triangle_tags, new.required,
                         known.get("nn_grew"), tag_names=new.tag_names)
