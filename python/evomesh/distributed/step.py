"""FRFC's step on a distributed mesh (docs/distributed-step.md,
sections 3 and 3.7): the serial step's mesh, on any number of ranks, without
gathering it. The packing's stages, each the serial one on a rank's part:

1. Step 1 (distributed_spacing.DistributedSpacing): nn, weights, f.
2. The part: the rank's held points and triangles plus the *segment skeleton*
   (every segment and its end points, replicated; distributed_spacing.
   segment_skeleton), in global-id order, so chains, corners and the candidates
   on segments are the serial ones. Every rank samples every segment (1-D,
   O(segments)) and keeps the candidates of the segments it owns; the global
   position of a candidate in the serial list is then known everywhere and is
   its packing tie.
3. Candidate radii from a spacing function exact at the candidates
   (DistributedSpacing.graph_for).
4. First pass: the lexical-first MIS in rounds (distributed_packing) over the
   owned input points (ties: global ids) and segment candidates.
5. Interior candidates of the owned triangles (streams keyed by triangle id,
   clipping from the stored rotation, as serial), their radii, second pass with
   the first pass's kept spheres forced.
6. The spacing repair (distributed_repair): the needy R-points, then the gap
   repair's open points, each decided by its owner in rounds, as serial.

Then (:func:`step`) the constraint pieces along the chains, the distributed
constrained Delaunay triangulation and the output in the serial order;
:func:`evolve_distributed` (what ``evomesh.evolve`` calls on a DistributedMesh)
adds size requests and the rebalance.

Supported options: all of FRFC's (within_domain, ring candidates, demotion,
settled and coarse skipping, adaptive cells, the cheap radius, the spacing
repair with repair_ratio, gap_repair_ratio and refine_gap_ratio) except the
quality pass, which is refused by name; curved boundaries (``geometry``) too.
"""

from __future__ import annotations

import time
from typing import Any, Callable, Mapping

import numpy as np

from .. import _core
from ..geometry import as_geometry
from ..mesh_quality import _warn_quality
from . import _halo
from .mesh import _NOT_GIVEN, DistributedMesh, _collective, _exchange, _fingerprint, _mpi, _same_everywhere
from .packing import lexical_first_mis
from .repair import gap_repair, spacing_repair
from .spacing import DistributedSpacing, boundary_flags, delta_from_size, segment_skeleton
from .threads import rank_thread_limit

__all__ = ["evolve_distributed", "packing", "step", "with_curve_kinds"]

# Packing ties, unique over the ranks and in the serial order within each kind:
# input points by global id (< 2^60), segment candidates by their position in
# the serial list, interior grid samples by (triangle id, draw), interior ring
# candidates by (R-point id, direction). The keys sort as the serial output
# (select_output), with the demoted input points the second pass keeps last.
_SEGMENT_TIE = 1 << 61
_INTERIOR_TIE = 1 << 62
_DRAW_BITS = 20
_RING_TIE = _INTERIOR_TIE + (1 << 61)
_RING_BITS = 3  # (kRingDirections = 6 directions)
_DEFERRED_KEY = _RING_TIE + (1 << 60)
# The spacing repair's points inside: (1 << 60) + 2 id + (0 for a needy
# point's ring candidate, 1 for a gap point), the id its input point's (< 2^59;
# a needy point's ring candidate is regenerated at the undemoted reach, so it
# may lie elsewhere than the packing's candidate of its direction: a key of its
# own). Their output order comes from the order keys (_pack).
_REPAIR_TIE = 1 << 60
_KIND = dict(_core.POINT_KINDS)  # PointKind's values


def _global_rank(comm: Any, keys: np.ndarray) -> np.ndarray:
    """The position of each of this rank's rows of `keys` ((n, c) int64, rows
    unique over all ranks) in the lexicographic order of every rank's rows.
    Collective: a sample sort (each rank sends its rows to the rank of their key
    range, which sorts them; an exclusive scan of the counts numbers them), so no
    rank holds more than its share plus the splitters."""
    MPI = _mpi()
    size = comm.size
    row = np.dtype([(f"k{i}", "<i8") for i in range(keys.shape[1])])
    record = np.dtype([("key", row), ("index", "<i8")])
    mine = np.zeros(len(keys), dtype=record)
    for i in range(keys.shape[1]):
        mine["key"][f"k{i}"] = keys[:, i]
    mine["index"] = np.arange(len(keys))
    mine = mine[np.argsort(mine["key"], kind="stable")]
    # Splitters from evenly spaced samples of every rank's sorted rows.
    take = np.linspace(0, len(mine) - 1, min(len(mine), 32 * size)).astype(np.int64)
    samples = np.sort(np.concatenate(comm.allgather(mine["key"][take])), kind="stable")
    splitters = samples[np.linspace(0, len(samples), size + 1).astype(np.int64)[1:-1]] if len(samples) else samples
    bucket = np.searchsorted(splitters, mine["key"], side="right") if len(splitters) else np.zeros(len(mine), np.int64)
    tagged = np.zeros(len(mine), dtype=[("key", row), ("index", "<i8"), ("source", "<i4")])
    tagged["key"], tagged["index"], tagged["source"] = mine["key"], mine["index"], comm.rank
    got, _ = _exchange(comm, bucket, tagged)
    got = got[np.argsort(got["key"], kind="stable")]
    first = comm.exscan(len(got), op=MPI.SUM) or 0
    answer = np.zeros(len(got), dtype=[("index", "<i8"), ("rank", "<i8")])
    answer["index"], answer["rank"] = got["index"], first + np.arange(len(got))
    back, _ = _exchange(comm, got["source"], answer)
    out = np.empty(len(keys), dtype=np.int64)
    out[back["index"]] = back["rank"]
    return out


def _part(dmesh: DistributedMesh, skeleton: tuple[np.ndarray, np.ndarray], held_f: np.ndarray,
          held_delta: np.ndarray, skeleton_f: np.ndarray, skeleton_delta: np.ndarray) -> tuple[dict, np.ndarray, dict]:
    """The part's arrays (held points and the skeleton's, in gid order), where
    the held points went, and f and delta on it."""
    segments, spoints = skeleton
    held_gids = dmesh.global_ids
    gids = np.union1d(held_gids, spoints["gid"])
    n = len(gids)
    xy = np.empty((n, 2))
    kind = np.zeros(n, np.uint8)
    required = np.zeros(n, np.uint8)
    f = np.empty(n)
    delta = np.empty(n)
    at_held = np.searchsorted(gids, held_gids)
    at_skel = np.searchsorted(gids, spoints["gid"])
    xy[at_skel, 0], xy[at_skel, 1] = spoints["x"], spoints["y"]
    kind[at_skel], required[at_skel] = spoints["kind"], spoints["required"]
    f[at_skel], delta[at_skel] = skeleton_f, skeleton_delta
    xy[at_held] = dmesh.points
    if dmesh.kind is not None:
        kind[at_held] = dmesh.kind
    required[at_held] = dmesh.required
    f[at_held], delta[at_held] = held_f, held_delta
    triangles = np.concatenate([dmesh.triangles, dmesh.halo_triangles]).reshape(-1, 3)
    part = dict(points=xy, triangles=at_held[triangles], segments=np.searchsorted(gids, segments["v"]),
                segment_is_boundary=segments["boundary"].astype(np.uint8), kind=kind,
                segment_tags=segments["tag"], required=required, point_gids=gids,
                triangle_gids=np.concatenate([dmesh.triangle_global_ids, dmesh.halo_triangle_global_ids]),
                segment_keys=segments["gid"])
    return part, at_held, dict(f=f, delta=delta)


def _point_flags(dmesh: DistributedMesh, part: dict, at_held: np.ndarray, skeleton: tuple[np.ndarray, np.ndarray],
                 spacing: DistributedSpacing, values: dict, options: Any) -> tuple[Any, Any]:
    """The demoted (options.demote_ratio > 0) and settled (options.skip_settled)
    flags over the part, each None when not asked for. Both read a point's whole
    fan (nn and f at every point sharing a triangle with it; its shortest edge),
    which the part holds at the owned points only: every point's flags are its
    owner's, sent to the halo (exchange_halo) and to every rank for the
    skeleton's points (replicated like the skeleton). Collective."""
    if not (options.demote_ratio > 0 or options.skip_settled):
        return None, None
    comm = dmesh.comm
    n_owned = dmesh.n_owned
    gids = part["point_gids"]
    nn = np.zeros(len(gids))  # (0 at the skeleton's other points: their flags come from their owners)
    nn[at_held] = dmesh.exchange_halo(spacing.nn)
    demoted, settled = _core.part_point_flags(part, nn, values["f"], values["delta"], options)
    own = at_held[:n_owned]
    owned = np.ascontiguousarray(np.column_stack([demoted[own], settled[own]]), dtype=np.uint8)
    flags = np.zeros((len(gids), 2), np.uint8)
    spoints = skeleton[1]
    owned_gids = dmesh.global_ids[:n_owned]
    mine = np.isin(owned_gids, spoints["gid"])
    rows = np.zeros(int(np.count_nonzero(mine)), dtype=[("gid", "<i8"), ("flags", "u1", (2,))])
    rows["gid"], rows["flags"] = owned_gids[mine], owned[mine]
    rows = np.concatenate(comm.allgather(rows))
    flags[np.searchsorted(gids, rows["gid"])] = rows["flags"]
    flags[at_held] = dmesh.exchange_halo(owned)
    return (np.ascontiguousarray(flags[:, 0]) if options.demote_ratio > 0 else None,
            np.ascontiguousarray(flags[:, 1]) if options.skip_settled else None)


def _grid_graph(comm: Any, spacing: DistributedSpacing, part: dict, f_part: np.ndarray, rows: np.ndarray) -> Any:
    """A spacing function exact wherever the adaptive grids of the simplices
    `rows` (this rank's triangles or segments whose grids ask f, as part
    indices) ask it, or None when no rank has such a simplex. Collective.

    Why exact: a grid asks f at block centres x inside its simplex's bounding box,
    within sqrt(2) r of the simplex's centroid c (every vertex within r of c). For
    a vertex v, u(x) = f(v) + |x - v| <= f(v) + (1 + sqrt(2)) r bounds f(x), and
    every site attaining or tying f(x) lies within u(x) of x (weights are
    non-negative, docs/distributed-step.md 3.2), so within f(v) + (1 + 2 sqrt(2)) r
    of c. The graph holds every site within f_min + 4 r of c (f at the vertices
    is exact on the part), so its answer at x is the serial f(x), bit for bit."""
    MPI = _mpi()
    if not comm.allreduce(len(rows) > 0, op=MPI.LOR):
        return None
    corners = part["points"][rows]  # (k, 2 or 3, 2)
    centre = corners.mean(axis=1).reshape(-1, 2)
    r = np.sqrt(((corners - centre[:, None, :]) ** 2).sum(axis=2)).max(axis=1) if len(rows) else np.zeros(0)
    f_min = f_part[rows].min(axis=1) if len(rows) else np.zeros(0)
    # (1 % above the bound: the centroid and r are rounded)
    return spacing._graph_at(centre, "sites_received", reach=1.01 * (f_min + 4.0 * r))


def _onto_curves(comm: Any, part: dict, xy: np.ndarray, parent: np.ndarray, radius: np.ndarray,
                 rows: np.ndarray, times: int) -> tuple[np.ndarray, float]:
    """The kept candidates xy[rows] on the part's segments `parent[rows]` moved
    onto their curves (those of curved tags; the part holds the geometry), and
    the largest move over all ranks. `times`: 2 without the quality pass, whose
    root runs the serial fit_to_curves itself (1): the serial FRFC projects them
    before triangulating and fit_to_curves projects them again after (a
    projection need not be idempotent to the last bit). Collective."""
    MPI = _mpi()

    def project() -> tuple[np.ndarray, float]:
        moved, largest = xy[rows], 0.0
        if not len(rows):
            return moved, largest
        args = (parent[rows], radius[rows])
        for _ in range(times):
            moved, move = _core.part_project_segment_candidates(part, moved, *args)
            largest = max(largest, float(move))
        return np.asarray(moved), largest

    moved, largest = _collective(comm, project)
    return moved, float(comm.allreduce(largest, op=MPI.MAX))


def packing(dmesh: DistributedMesh, delta: Any, options: Any = None, *, stats: dict[str, Any] | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """The kept points of one FRFC step on a distributed mesh: this rank's share
    (its owned input points kept, and the kept candidates of its segments and
    triangles). Collective. The union over the ranks is the serial step's
    selection (before the quality pass), on any number of ranks.

    Parameters
    ----------
    dmesh : DistributedMesh
    delta : array_like (n_owned,) or callable of the owned coordinates
    options : evomesh FrfcOptions, optional (default: the paper's, ``FrfcOptions.paper()``)
    stats : dict, optional
        Filled with the rounds of the two passes, candidate counts (summed over
        ranks) and step 1's figures.

    Returns
    -------
    (points (k, 2), input_gid (k,)): the kept points this rank contributes, and
    for each the global id of the input point it keeps (-1 for a new point).
    """
    with rank_thread_limit(dmesh.comm, getattr(options, "threads", None), stats):
        packed = _pack(dmesh, delta, options, stats)
    return packed["points"], packed["input_gid"]


def _pack(dmesh: DistributedMesh, delta: Any, options: Any, stats: dict[str, Any] | None,
          geometry: Any = None) -> dict[str, Any]:
    MPI = _mpi()
    comm = dmesh.comm
    if options is None:
        options = _core.FrfcOptions.paper()

    def check() -> None:
        if not isinstance(options, _core.FrfcOptions):
            raise TypeError(f"options must be evomesh FrfcOptions, got {type(options).__name__}")
        options.validate()
        fans = [name for name, on in (("demote_ratio > 0", options.demote_ratio > 0),
                                      ("skip_settled", options.skip_settled),
                                      ("ring_samples", options.ring_samples),
                                      ("the gap repair", options.gap_repair_ratio > 0 or
                                       options.refine_gap_ratio > 0)) if on]
        if fans and dmesh.halo_rings < 1:
            # (they read every owned point's whole fan of triangles, which ring 1 holds)
            raise ValueError(", ".join(fans) + " on a DistributedMesh need a halo of at least one ring of "
                             "triangles (halo_rings=1, the default); this one has halo_rings=0")

    _collective(comm, check)
    projections = 1 if options.quality else 2  # (_onto_curves)
    step1: dict = {}
    spacing = DistributedSpacing(dmesh, delta, within_domain=options.within_domain, stats=step1, geometry=geometry,
                                 prefetch=True)
    n_owned = dmesh.n_owned
    owned_delta = _collective(comm, spacing._check_delta, delta)
    held_f = dmesh.exchange_halo(spacing.f)
    held_delta = dmesh.exchange_halo(owned_delta)
    skeleton = segment_skeleton(dmesh)
    segments, spoints = skeleton
    # f and delta at the skeleton's points, from their owners (replicated like the skeleton).
    owned_gids = dmesh.global_ids[:n_owned]
    mine = np.isin(owned_gids, spoints["gid"])
    pairs = np.concatenate(comm.allgather(np.column_stack([owned_gids[mine].astype(np.float64),
                                                           spacing.f[mine], owned_delta[mine]])))
    pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
    part, at_held, values = _part(dmesh, skeleton, held_f, held_delta, pairs[:, 1], pairs[:, 2])
    if geometry is not None:
        part.update(geometry._core_arguments())
    f_part = values["f"]
    demoted, settled = _point_flags(dmesh, part, at_held, skeleton, spacing, values, options)
    cheap = options.radius == _core.RadiusRule.cheap

    def radii_of(xy: np.ndarray, parent: np.ndarray, on_segment: bool) -> np.ndarray:
        """The candidates' sphere radii (collective unless cheap: f from a graph exact at them)."""
        graph = None
        if not cheap:
            # The sites that can attain f at x lie within f(x) of x, and f(x) <=
            # f(v) + |x - v| at every vertex v of x's parent (f is 1-Lipschitz, and
            # exact at every point of the part): a bound without asking a graph for
            # f at every candidate (a larger reach only fetches a superset).
            corners = np.asarray(part["segments"] if on_segment else part["triangles"])[parent]
            gap = part["points"][corners] - xy[:, None, :]
            bound = (f_part[corners] + np.hypot(gap[..., 0], gap[..., 1])).min(axis=1, initial=np.inf)
            graph = spacing._graph_at(np.ascontiguousarray(xy, dtype=np.float64), "sites_received",
                                      reach=bound * (1 + 16 * np.finfo(np.float64).eps))
        if not len(xy) or (graph is None and not cheap):
            return np.zeros(0)
        return _core.part_candidate_radii(part, f_part, graph, options, on_segment, xy, parent, demoted)

    # First pass: the owned input points (less the demoted ones inside, which
    # the serial first pass orders last and defers) and the candidates on owned
    # segments.
    radius, classes, forced = _core.part_input_spheres(part, f_part, options, demoted)
    own = at_held[:n_owned]
    n_segments = len(segments)
    seg_owner = np.where(segments["v"][:, 0] < segments["v"][:, 1], 0, 1)
    owner_of_segment = spoints["owner"][np.searchsorted(spoints["gid"],
                                                        segments["v"][np.arange(n_segments), seg_owner])]
    asks_triangle, asks_segment = _core.part_asking_spacing(part, f_part, options.cell_factor) \
        if options.adaptive_cells else (None, None)
    seg_graph = None
    n_asking = 0
    if asks_segment is not None:
        asking = part["segments"][(asks_segment != 0) & (owner_of_segment == comm.rank)]
        n_asking += len(asking)
        seg_graph = _grid_graph(comm, spacing, part, f_part, asking)
    seg_xy, seg_parent, seg_class, seg_ring_owner = _core.part_segment_candidates(
        part, values["delta"], f_part, options, settled, seg_graph)
    del seg_graph
    # Every rank samples every segment, exactly on its own (the adaptive grids
    # of the others' may ask f where this rank's graph is not exact): each
    # candidate's position in the serial list comes from the owners' counts.
    take = np.flatnonzero(owner_of_segment[seg_parent] == comm.rank)
    counts = np.bincount(seg_parent[take], minlength=n_segments).astype(np.int64)
    counts = comm.allreduce(counts, op=MPI.SUM) if comm.size > 1 else counts
    all_parent = np.repeat(np.arange(n_segments, dtype=np.int64), counts)
    seg_start = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    first_local = np.searchsorted(seg_parent, seg_parent[take], side="left")
    position = seg_start[seg_parent[take]] + (take - first_local)
    seg_xy, seg_parent, seg_class = seg_xy[take], seg_parent[take], seg_class[take]
    # The segment ring candidates (few: two per R-point on a segment), replicated
    # for the spacing repair: their R-point's owner decides on them.
    ringed = np.flatnonzero(np.asarray(seg_ring_owner)[take] >= 0)
    segment_ring = np.zeros(len(ringed), dtype=[("position", "<i8"), ("x", "<f8"), ("y", "<f8"), ("owner", "<i8")])
    segment_ring["position"], segment_ring["x"], segment_ring["y"] = position[ringed], seg_xy[ringed, 0], \
        seg_xy[ringed, 1]
    segment_ring["owner"] = part["point_gids"][np.asarray(seg_ring_owner)[take][ringed]]
    seg_radius = radii_of(seg_xy, seg_parent, True)
    deferred = classes[own] == _core.PACKING_CLASS_NEW  # (demoted inside: class_new)
    first_inputs = np.flatnonzero(~deferred)
    centres = np.concatenate([dmesh.owned_points[first_inputs], seg_xy])
    radii = np.concatenate([radius[own][first_inputs], seg_radius])
    kinds = np.concatenate([classes[own][first_inputs], seg_class]).astype(np.uint8)
    ties = np.concatenate([owned_gids[first_inputs], _SEGMENT_TIE + position]).astype(np.int64)
    n_first_inputs = len(first_inputs)
    first: dict = {}
    kept = lexical_first_mis(comm, centres, radii, kinds, ties,
                             np.concatenate([forced[own][first_inputs] != 0, np.zeros(len(take), bool)]),
                             stats=first, check_ties=False)

    # On curves: the kept candidates on segments of curved tags move onto their
    # curves before the triangulation (as serial: after the packing, which used
    # the sampled positions). Twice: the serial step projects them again after
    # triangulating (fit_to_curves; a projection need not be idempotent to the
    # last bit), and a CDT is a function of its points and constraints.
    on_curve = np.flatnonzero(kept[n_first_inputs:])
    curve_move = 0.0
    if geometry is not None:
        projected, curve_move = _onto_curves(comm, part, seg_xy, seg_parent, seg_radius, on_curve, projections)

    # Second pass: the deferred input points and the interior candidates of the owned triangles.
    sampled = np.concatenate([np.ones(len(dmesh.triangles), np.uint8), np.zeros(len(dmesh.halo_triangles), np.uint8)])
    in_graph = None
    if asks_triangle is not None:
        asking = part["triangles"][(asks_triangle != 0) & (sampled != 0)]
        n_asking += len(asking)
        in_graph = _grid_graph(comm, spacing, part, f_part, asking)
    ring_from = None
    if options.ring_samples:  # (ring candidates drawn by the R-point's owner, which holds its fan)
        ring_from = np.zeros(len(part["point_gids"]), np.uint8)
        ring_from[own] = 1
    in_xy, in_parent, in_class, in_point = _core.part_interior_candidates(
        part, values["delta"], f_part, options, sampled, demoted, settled, ring_from, in_graph)
    del in_graph
    in_radius = radii_of(in_xy, in_parent, False)
    tri_gid = part["triangle_gids"][in_parent]
    grid = in_point < 0
    n_grid = int(np.count_nonzero(grid))  # (the grid samples come first, grouped by triangle)
    if n_grid:
        starts = np.flatnonzero(np.r_[True, in_parent[1:n_grid] != in_parent[: n_grid - 1]])
        draw = np.arange(n_grid) - np.repeat(starts, np.diff(np.r_[starts, n_grid]))
    else:
        draw = np.zeros(0, np.int64)
    ring_gid = part["point_gids"][in_point[~grid]]
    direction = in_class[~grid].astype(np.int64) - _core.PACKING_CLASS_RING

    def check_ties() -> None:
        if (len(draw) and (draw.max() >= 1 << _DRAW_BITS or tri_gid[:n_grid].max() >= 1 << (61 - _DRAW_BITS))) \
                or (len(ring_gid) and ring_gid.max() >= 1 << (60 - _RING_BITS)) \
                or (n_owned and owned_gids.max() >= 1 << 59):
            raise ValueError("too many candidates in one triangle, or triangle or point ids too large, for packing "
                             "ties")
        if deferred.any() and np.isin(owned_gids[deferred], spoints["gid"]).any():
            raise ValueError("a demoted point on a segment has an inside point's kind (a segment's end points "
                             "must have kind CORNER or BOUNDARY)")

    _collective(comm, check_ties)
    in_ties = np.concatenate([_INTERIOR_TIE + (tri_gid[:n_grid] << _DRAW_BITS) + draw,
                              _RING_TIE + (ring_gid << _RING_BITS) + direction]).astype(np.int64)
    keep = np.flatnonzero(kept)
    late = np.flatnonzero(deferred)
    centres2 = np.concatenate([centres[keep], dmesh.owned_points[late], in_xy])
    radii2 = np.concatenate([radii[keep], radius[own][late], in_radius])
    kinds2 = np.concatenate([np.zeros(len(keep), np.uint8), classes[own][late], in_class.astype(np.uint8)])
    # (a deferred point's tie, its id, puts it before the interior candidates of
    # its class and radius, as the serial second pass does)
    ties2 = np.concatenate([ties[keep], owned_gids[late], in_ties]).astype(np.int64)
    forced2 = np.concatenate([np.ones(len(keep), bool), np.zeros(len(late) + len(in_xy), bool)])
    second: dict = {}
    kept2 = lexical_first_mis(comm, centres2, radii2, kinds2, ties2, forced2, stats=second, check_ties=False)
    points = centres2[kept2]
    keys = ties2[kept2]
    # The serial output lists the deferred input points it keeps after the interior candidates.
    late_kept = np.flatnonzero(kept2[len(keep): len(keep) + len(late)]) + len(keep)
    keys[np.searchsorted(np.flatnonzero(kept2), late_kept)] += _DEFERRED_KEY
    kept_inputs = np.sort(np.concatenate([owned_gids[first_inputs[kept[:n_first_inputs]]],
                                          owned_gids[late[kept2[len(keep): len(keep) + len(late)]]]]))

    if geometry is not None and len(on_curve):
        # (the kept segment candidates are forced in the second pass: all kept)
        rows = np.flatnonzero((keys >= _SEGMENT_TIE) & (keys < _INTERIOR_TIE))  # (in tie order)
        points = points.copy()
        points[rows[np.searchsorted(keys[rows], _SEGMENT_TIE + position[on_curve])]] = projected

    # The spacing repair (distributed_repair), on the kept centres before any
    # projection. Its points come last in the serial output: the segment
    # candidates it keeps (by position, after the deferred input points), then
    # the interior ring candidates it adds (by their R-points' ids): order keys
    # (1, position) and (2, R-point id) after (0, key) for the others.
    repair: dict = {}
    repaired = spacing_repair(comm, part, f_part, options, own, owned_gids, dmesh.owned_points,
                              np.isin(owned_gids, kept_inputs), owned_delta, spacing.nn, centres2[kept2],
                              np.concatenate(comm.allgather(segment_ring)), stats=repair)
    flipped = np.concatenate(comm.allgather(repaired["segment_positions"]))
    flip = np.flatnonzero(np.isin(position, flipped))  # (on this rank's segments)
    flip_xy = seg_xy[flip]
    if geometry is not None:  # (moved onto their curves as the other kept segment candidates)
        flip_xy, move = _onto_curves(comm, part, seg_xy, seg_parent, seg_radius, flip, projections)
        curve_move = max(curve_move, move)
    # Then the gap repair (after all of the above: order keys (3, input point id)).
    gaps = gap_repair(comm, dmesh, part, options, own, owned_gids, dmesh.owned_points, owned_delta, spacing.nn,
                      demoted[own] if demoted is not None else np.zeros(n_owned, np.uint8), centres2[kept2],
                      repaired["added"], stats=repair)
    ring_keys = _REPAIR_TIE + (repaired["gids"] << 1)
    points = np.concatenate([points, flip_xy, repaired["points"], gaps["points"]])
    order_keys = np.concatenate([np.column_stack([np.zeros(len(keys), np.int64), keys]),
                                 np.column_stack([np.ones(len(flip), np.int64), position[flip]]),
                                 np.column_stack([np.full(len(ring_keys), 2, np.int64), repaired["gids"]]),
                                 np.column_stack([np.full(len(gaps["gids"]), 3, np.int64), gaps["gids"]])])
    keys = np.concatenate([keys, _SEGMENT_TIE + position[flip], ring_keys,
                           _REPAIR_TIE + (gaps["gids"] << 1) + 1]).astype(np.int64)
    input_gid = np.where(keys < _REPAIR_TIE, keys, np.where(keys >= _DEFERRED_KEY, keys - _DEFERRED_KEY, -1))
    if stats is not None:
        stats.update(step1=step1, first_pass_rounds=first["rounds"], second_pass_rounds=second["rounds"],
                     segment_candidates=comm.allreduce(len(take), op=MPI.SUM),
                     interior_candidates=comm.allreduce(len(in_xy), op=MPI.SUM),
                     demoted_points=comm.allreduce(int(np.count_nonzero(deferred)), op=MPI.SUM),
                     asking_grids=comm.allreduce(n_asking, op=MPI.SUM), repair=repair,
                     bytes=step1["bytes"] + first["bytes_halo"] + first["bytes_states"] + second["bytes_halo"]
                     + second["bytes_states"])
    return dict(points=points, keys=keys, order_keys=order_keys, input_gid=input_gid, part=part, at_held=at_held,
                skeleton=skeleton, all_segment_parent=all_parent,
                kept_segment_candidates=np.concatenate([position[kept[n_first_inputs:]], position[flip]]),
                kept_inputs=kept_inputs, spacing=spacing, forced_corner=forced[own] == 1, f_part=f_part,
                demoted=demoted, settled=settled, curve_move=curve_move)


# A point of the step's output as the ranks look it up (distributed_triangulation._lookup).
_OUT_POINT = np.dtype([("gid", "<i8"), ("x", "<f8"), ("y", "<f8"), ("owner", "<i4"), ("required", "u1"),
                       ("origin", "<i8"), ("id", "<i8"), ("kind", "u1")])  # gid: packing key; id: output global id


def _replaced(dmesh: DistributedMesh, **fields: Any) -> DistributedMesh:
    """A DistributedMesh with some fields replaced (the others shared: immutable)."""
    out = object.__new__(DistributedMesh)
    for name in DistributedMesh.__slots__:
        if name in fields:
            object.__setattr__(out, name, fields[name])
        elif hasattr(dmesh, name):
            object.__setattr__(out, name, getattr(dmesh, name))
    return out


def with_curve_kinds(dmesh: DistributedMesh, geometry: Any) -> DistributedMesh:
    """`dmesh` with the kinds a step with `geometry` (curved boundaries) gives
    its points (the serial with_curve_kinds, boundary_geometry.hpp): a boundary
    vertex of a curved tag is a corner only where the boundary turns by more than
    the geometry's corner angle, at a tag change or at a required point. Computed
    on the replicated segment skeleton (only segments are read), so every rank
    agrees. ValueError on every rank for a curved tag no segment has. Collective."""
    segments, spoints = segment_skeleton(dmesh)
    if dmesh.kind is None:
        raise ValueError("curved boundaries need the points' kinds: give kind= to DistributedMesh.from_local")

    def kinds() -> np.ndarray:
        part = dict(points=np.column_stack([spoints["x"], spoints["y"]]), triangles=np.zeros((0, 3), np.int64),
                    segments=np.searchsorted(spoints["gid"], segments["v"]),
                    segment_is_boundary=segments["boundary"].astype(np.uint8), kind=spoints["kind"],
                    segment_tags=segments["tag"], required=spoints["required"], point_gids=spoints["gid"],
                    triangle_gids=np.zeros(0, np.int64), segment_keys=segments["gid"],
                    **geometry._core_arguments())
        return np.asarray(_core.part_curve_kinds(part))

    new = _collective(dmesh.comm, kinds)
    at = np.minimum(np.searchsorted(spoints["gid"], dmesh.global_ids), max(len(spoints) - 1, 0))
    on = (spoints["gid"][at] == dmesh.global_ids) if len(spoints) else np.zeros(len(dmesh.global_ids), bool)
    kind = np.array(dmesh.kind, dtype=np.uint8)
    kind[on] = new[at[on]]
    kind.flags.writeable = False
    return _replaced(dmesh, kind=kind)


def _used(comm: Any, keys: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Which of this rank's points (`keys`) a triangle of any rank uses: the
    used keys meet the asked ones at the directory rank key % P. Collective."""
    size = comm.size
    used = np.unique(triangles.reshape(-1))
    directory, _ = _exchange(comm, used % size, used)
    directory = np.unique(directory)
    asks, asker = _exchange(comm, keys % size, np.ascontiguousarray(keys))
    answer = np.column_stack([asks, np.isin(asks, directory)]).astype(np.int64)
    back, _ = _exchange(comm, asker, answer)
    back = back[np.argsort(back[:, 0], kind="stable")]
    return back[np.searchsorted(back[:, 0], keys), 1].astype(bool) if len(keys) else np.zeros(0, bool)


def _same_rows(comm: Any, old_keys: np.ndarray, old_payload: np.ndarray, new_keys: np.ndarray
               ) -> np.ndarray | None:
    """Whether the rows `new_keys` ((k, c) int64) of all ranks are, as a set,
    the rows `old_keys` of all ranks (each set without repeats); if so, the
    `old_payload` row ((k, d) int64) of each new row, else None. Rows meet at
    the directory rank (first column) % P. Collective."""
    size = comm.size
    c, d = old_keys.shape[1], old_payload.shape[1]
    olds, _ = _exchange(comm, old_keys[:, 0] % size, np.ascontiguousarray(np.hstack([old_keys, old_payload])))
    news, asker = _exchange(comm, new_keys[:, 0] % size, np.ascontiguousarray(np.hstack(
        [new_keys, np.arange(len(new_keys))[:, None]])))
    olds = olds[np.lexsort(olds[:, :c].T[::-1])]
    order = np.lexsort(news[:, :c].T[::-1])
    same = len(olds) == len(news) and np.array_equal(olds[:, :c], news[order, :c])
    if not comm.allreduce(bool(same), op=_mpi().LAND):
        return None
    answer = np.hstack([news[order, c:], olds[:, c:]])  # (asker's index, payload)
    back, _ = _exchange(comm, asker[order], np.ascontiguousarray(answer))
    out = np.empty((len(new_keys), d), dtype=np.int64)
    out[back[:, 0]] = back[:, 1:]
    return out


def _input_order(old: DistributedMesh, n_out: int, ids: np.ndarray, origin: np.ndarray, tri_ids: np.ndarray,
                 seg_ids: np.ndarray, seg_boundary: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """When the step returned its input (the serial adopt_input_order, step.cpp:
    every point kept with its id, the same triangles and the same segments with
    the same boundary flags), the input's order: for each of this rank's new
    triangles (`tri_ids`, ids rotated least first) the old triangle's global id
    and stored rotation (4 columns), and for each new segment (`seg_ids`) the old
    segment's global id, stored orientation and tag (4 columns). None otherwise.
    A mesh that stays put keeps the indices of its triangles and segments, so
    per-cell data stays aligned. Collective."""
    comm = old.comm
    MPI = _mpi()
    if comm.allreduce(n_out, op=MPI.SUM) != comm.allreduce(old.n_owned, op=MPI.SUM) or \
            not comm.allreduce(bool(np.array_equal(ids, origin)), op=MPI.LAND):
        return None
    stored = old.global_ids[np.asarray(old.triangles, dtype=np.int64).reshape(-1, 3)]
    roll = np.argmin(stored, axis=1)
    least = np.take_along_axis(stored, (roll[:, None] + np.arange(3)[None, :]) % 3, axis=1)
    triangles = _same_rows(comm, least, np.column_stack([old.triangle_global_ids, stored]), tri_ids)
    if triangles is None:
        return None
    seg = old.global_ids[np.asarray(old.segments, dtype=np.int64).reshape(-1, 2)]
    flags = boundary_flags(old).astype(np.int64)
    segments = _same_rows(comm, np.column_stack([np.sort(seg, axis=1), flags]),
                          np.column_stack([old.segment_global_ids, seg, old.segment_tags]),
                          np.column_stack([np.sort(seg_ids, axis=1), seg_boundary.astype(np.int64)]))
    if segments is None:
        return None
    return triangles, segments


def step(dmesh: DistributedMesh, delta: Any, options: Any = None, *, stats: dict[str, Any] | None = None,
         geometry: Any = None) -> DistributedMesh:
    """One FRFC step on a distributed mesh (what ``evolve(dmesh, delta,
    options=...)`` runs). Collective.

    The packing (:func:`packing`), the constraint pieces between the kept
    points along every chain (every rank holds the segment skeleton and the kept
    flags on it, and gives a share of the pieces), and the distributed
    constrained Delaunay triangulation (distributed_triangulation). The result
    is a DistributedMesh over the same communicator: each rank owns the points
    it kept; a point's global id is its position in the serial step's output
    (the rank of its packing key), a triangle's the serial canonical position,
    a segment's the serial piece order; ``origin`` holds the input global id of
    a kept input point and -1 for a new one; kinds, required points and tags as
    the serial step gives them. ``gather`` returns the serial step's mesh (the
    quality pass off) array for array. The input is not modified.

    Every core call runs under this rank's thread limit
    (evomesh.distributed.threads.rank_thread_count: ``options.threads``, else
    EVOMESH_NUM_THREADS, else the rank's share of its node's CPUs), stored as
    ``stats["threads"]``; the result does not depend on it.
    """
    with rank_thread_limit(dmesh.comm, getattr(options, "threads", None), stats):
        return _step(dmesh, delta, options, stats, geometry)


def _step(dmesh: DistributedMesh, delta: Any, options: Any, stats: dict[str, Any] | None,
          geometry: Any) -> DistributedMesh:
    MPI = _mpi()
    comm = dmesh.comm
    if options is None:
        options = _core.FrfcOptions.paper()

    def check() -> None:
        if dmesh.kind is None:
            raise ValueError("the step needs the points' kinds: give kind= to DistributedMesh.from_local "
                             "(scatter and a step's output have them)")

    _collective(comm, check)
    input_kind = np.asarray(dmesh.kind)  # (restore_origins reads the input's own kinds)
    if geometry is not None:
        dmesh = with_curve_kinds(dmesh, geometry)
    packed = _pack(dmesh, delta, options, stats, geometry)
    part = packed["part"]
    gids = part["point_gids"]
    n_part = len(gids)

    # The pieces, the same list on every rank: kept flags on the skeleton are replicated.
    kept_inputs = np.concatenate(comm.allgather(packed["kept_inputs"]))
    kept_point = np.isin(gids, kept_inputs).astype(np.uint8)
    kept_candidate = np.zeros(len(packed["all_segment_parent"]), np.uint8)
    kept_candidate[np.concatenate(comm.allgather(packed["kept_segment_candidates"])).astype(np.int64)] = 1
    ends, boundary, tags = _core.part_pieces(part, packed["all_segment_parent"], kept_candidate, kept_point)
    ends = np.asarray(ends, dtype=np.int64)
    keys = np.where(ends < n_part, gids[np.minimum(ends, n_part - 1)], _SEGMENT_TIE + (ends - n_part)).reshape(-1, 2)
    share = np.flatnonzero(np.arange(len(keys)) % comm.size == comm.rank)
    pieces, piece_boundary, piece_tags = keys[share], boundary[share].astype(bool), tags[share]

    points, point_keys, order_keys = packed["points"], packed["keys"], packed["order_keys"]
    if options.quality:
        # The quality pass: on the root (the serial last stage, on the gathered selection).
        return _quality_on_root(dmesh, packed, options, geometry, keys, boundary, tags, kept_inputs, input_kind,
                                stats)

    # The triangulation, each triangle on the rank of its least id.
    cdt: dict = {}
    from .triangulation import _lookup, constrained_delaunay

    triangles = constrained_delaunay(comm, points, point_keys, pieces, piece_boundary, stats=cdt)
    old = packed["input_gid"]
    dropped = 0
    if geometry is not None:
        # Interior points that a coarser curved boundary left outside are in no
        # triangle: dropped, as serial (fit_to_curves).
        used = _used(comm, point_keys, triangles)
        dropped = int(comm.allreduce(int((~used).sum()), op=MPI.SUM))
        points, point_keys, order_keys, old = points[used], point_keys[used], order_keys[used], old[used]

    # The output mesh from the ranks' pieces: the points they kept, their
    # triangles' and pieces' vertices looked up by id.
    owned_gids = dmesh.global_ids[: dmesh.n_owned]
    mine = np.zeros(len(points), dtype=_OUT_POINT)
    mine["gid"], mine["x"], mine["y"], mine["owner"] = point_keys, points[:, 0], points[:, 1], comm.rank
    mine["origin"] = old
    is_old = old >= 0
    at_old = np.searchsorted(owned_gids, old[is_old])
    mine["required"][is_old] = dmesh.required[: dmesh.n_owned][at_old]
    # Kinds as the serial step gives them: a kept input point keeps its own, a
    # new point on a segment is a boundary point, one inside a sampled point.
    mine["kind"] = _selected_kinds(dmesh, packed, point_keys, old)
    # Output ids: the order keys' order is the serial output's point order (kept
    # input points by input id, then segment candidates, then interior
    # candidates, then the spacing repair's points), so a point's id is its
    # order key's rank; a triangle's is the rank of its vertex ids
    # rotated to the least first (the serial canonical order); a segment's is the
    # piece's position in the pieces' list (chain order, as serial).
    mine["id"] = _global_rank(comm, order_keys)
    wanted = np.unique(np.concatenate([point_keys, triangles.reshape(-1), pieces.reshape(-1)]))
    found = _collective(comm, _lookup, comm, mine, wanted, "point")
    ids = found["id"]
    local = np.searchsorted(found["gid"], triangles)
    tri_ids = ids[local].reshape(-1, 3)
    roll = np.argmin(tri_ids, axis=1)
    rotate = (roll[:, None] + np.arange(3)[None, :]) % 3
    local = np.take_along_axis(local.reshape(-1, 3), rotate, axis=1)
    tri_ids = np.take_along_axis(tri_ids, rotate, axis=1)
    triangle_gids = _global_rank(comm, tri_ids)
    xy = np.column_stack([found["x"], found["y"]])
    reach = 0.0
    if geometry is not None:
        # How far outside the old domain a new triangle may reach: a chord
        # between points on a curve strays from the old polygon by at most about
        # its sagitta, under its length (as the serial step's curve_reach).
        ends = np.searchsorted(found["gid"], pieces)
        on_curve = np.isin(piece_tags, np.asarray(geometry.tags, dtype=np.int64))
        length = np.hypot(*(xy[ends[on_curve, 1]] - xy[ends[on_curve, 0]]).T) if on_curve.any() else np.zeros(1)
        reach = float(comm.allreduce(max(float(length.max()), 2 * packed["curve_move"]), op=MPI.MAX))
    segments = np.searchsorted(found["gid"], pieces).reshape(-1, 2)
    out, same = _output(dmesh, packed, found, ids, local, tri_ids, triangle_gids, segments, share, piece_tags,
                        piece_boundary, len(point_keys), mine["id"], mine["origin"], reach)
    if stats is not None:
        stats.update(cdt=cdt, pieces=len(keys), triangles=comm.allreduce(len(triangles), op=MPI.SUM),
                     unchanged=same)
        if geometry is not None:
            stats.update(curve_points_dropped_outside=dropped, curve_reach=reach)
    return out


def _selected_kinds(dmesh: DistributedMesh, packed: dict, point_keys: np.ndarray, old: np.ndarray) -> np.ndarray:
    """The kinds of this rank's kept points as the serial selection gives them:
    a kept input point keeps its own, a new point on a segment is a boundary
    point, one inside a sampled point."""
    kind = np.where((point_keys >= _SEGMENT_TIE) & (point_keys < _INTERIOR_TIE), _KIND["BOUNDARY"],
                    _KIND["SAMPLED"]).astype(np.uint8)
    is_old = old >= 0
    at_old = np.searchsorted(dmesh.global_ids[: dmesh.n_owned], old[is_old])
    assert dmesh.kind is not None  # (checked by step)
    was = dmesh.kind[: dmesh.n_owned][at_old]
    # (kept_point_kind, step.hpp: a forced corner is a corner, a sampled point of an earlier step a Steiner point)
    kind[is_old] = np.where(packed["forced_corner"][at_old], _KIND["CORNER"],
                            np.where(was == _KIND["SAMPLED"], _KIND["STEINER"], was))
    return kind


def _output(dmesh: DistributedMesh, packed: dict, found: np.ndarray, ids: np.ndarray, local: np.ndarray,
            tri_ids: np.ndarray, triangle_gids: np.ndarray, segments: np.ndarray, segment_gids: np.ndarray,
            segment_tags: np.ndarray, segment_boundary: np.ndarray, n_owned: int, owned_ids: np.ndarray,
            owned_origin: np.ndarray, reach: float) -> tuple[DistributedMesh, bool]:
    """The step's DistributedMesh from this rank's part of the output: `found`
    (_OUT_POINT rows of the points its triangles and segments use, and its own;
    `ids` their output ids), its triangles (`local` rows into `found`, stored
    least id first; `tri_ids` as ids) with their global ids, its segments
    (rows into `found`) with global ids, tags and boundary flags, and the ids
    and origins of the `n_owned` points it owns; triangle tags carried from the
    old mesh (a centroid up to `reach` outside it: the nearest old triangle),
    the input's order when the step returned its input, and the lineage.
    Returns the mesh and whether the step returned its input. Collective."""
    comm = dmesh.comm
    xy = np.column_stack([found["x"], found["y"]])
    triangle_tags = _carried_triangle_tags(dmesh, xy[local[:, 0]], xy[local[:, 1]], xy[local[:, 2]], reach)
    same = _input_order(dmesh, n_owned, owned_ids, owned_origin, tri_ids, ids[segments], segment_boundary)
    if same is not None:
        # The step returned its input: the input's triangle and segment order and rotations (as serial).
        by_id = np.argsort(ids, kind="stable")
        triangle_gids, local = same[0][:, 0], by_id[np.searchsorted(ids[by_id], same[0][:, 1:])]
        segment_gids, segments = same[1][:, 0], by_id[np.searchsorted(ids[by_id], same[1][:, 1:3])]
        segment_tags = same[1][:, 3]
    out = DistributedMesh.from_local(
        xy, local, ids, comm, owners=found["owner"], segments=segments, segment_tags=segment_tags,
        required=found["required"].astype(bool), origin=found["origin"], kind=found["kind"],
        tag_names=dict(dmesh.tag_names), triangle_global_ids=triangle_gids, segment_global_ids=segment_gids,
        triangle_tags=triangle_tags)
    # A step's output is valid by construction, as the serial step's: gather
    # returns its arrays as they are (Mesh._trusted), in the serial order.
    object.__setattr__(out, "_segment_is_boundary", boundary_flags(out))
    object.__setattr__(out, "_trusted", True)
    from .lineage import step_lineage  # (where the output's points lie in dmesh)
    object.__setattr__(out, "lineage", step_lineage(dmesh, out, packed["spacing"], reach))
    return out, same is not None


# A kept point on its way to the root's quality pass (_quality_on_root).
_SELECTED = np.dtype([("order0", "<i8"), ("order1", "<i8"), ("x", "<f8"), ("y", "<f8"), ("key", "<i8"),
                      ("kind", "u1"), ("required", "u1"), ("origin", "<i8"), ("rank", "<i4")])
# An input point the packing dropped (restore_origins).
_DROPPED = np.dtype([("x", "<f8"), ("y", "<f8"), ("gid", "<i8"), ("kind", "u1")])


def _quality_on_root(dmesh: DistributedMesh, packed: dict, options: Any, geometry: Any, keys: np.ndarray,
                     boundary: np.ndarray, tags: np.ndarray, kept_inputs: np.ndarray, input_kind: np.ndarray,
                     stats: dict[str, Any] | None) -> DistributedMesh:
    """The step's last stage with the quality pass (docs/distributed-step.md
    3.11): the kept points (in the serial output order: their order keys) and
    the pieces go to rank 0, which runs the serial triangulate_selection on
    them (the quality pass, and the curve fit with a geometry), gives the
    output points that stand where a dropped input point stood its origin
    (restore_origins), and sends each rank the points it owns (kept points
    stay where they were kept, a new point goes to a rank of its triangles),
    the triangles of its least ids and the segments of its least ends. The
    serial pass is one global sequence (docs 3.6): its result, here, is the
    serial step's, bit for bit, on any number of ranks; the root holds the
    output's points and triangulation for that stage. Collective."""
    comm = dmesh.comm
    root = 0
    points, point_keys, order_keys, old = packed["points"], packed["keys"], packed["order_keys"], packed["input_gid"]
    rows = np.zeros(len(points), dtype=_SELECTED)
    rows["order0"], rows["order1"] = order_keys[:, 0], order_keys[:, 1]
    rows["x"], rows["y"], rows["key"], rows["origin"], rows["rank"] = points[:, 0], points[:, 1], point_keys, old, \
        comm.rank
    rows["kind"] = _selected_kinds(dmesh, packed, point_keys, old)
    is_old = old >= 0
    owned_gids = dmesh.global_ids[: dmesh.n_owned]
    rows["required"][is_old] = dmesh.required[: dmesh.n_owned][np.searchsorted(owned_gids, old[is_old])]
    gone = np.flatnonzero(~np.isin(owned_gids, kept_inputs))
    dropped = np.zeros(len(gone), dtype=_DROPPED)
    dropped["x"], dropped["y"] = dmesh.points[gone, 0], dmesh.points[gone, 1]
    dropped["gid"] = owned_gids[gone]
    dropped["kind"] = input_kind[gone]
    selected = comm.gather(rows, root=root)
    dropped_all = comm.gather(dropped, root=root)

    def work() -> Any:
        if comm.rank != root:
            return None
        begin = time.perf_counter()
        packages, summary = _root_stage(comm.size, np.concatenate(selected), np.concatenate(dropped_all), options,
                                        geometry, keys, boundary, tags)
        summary["root_seconds"] = time.perf_counter() - begin
        summary["bytes"] = sum(len(a) for a in selected) * _SELECTED.itemsize + \
            sum(len(a) for a in dropped_all) * _DROPPED.itemsize + \
            sum(sum(v.nbytes for v in package.values()) for package in packages)
        return packages, summary

    done = _collective(comm, work)
    mine = comm.scatter(done[0] if comm.rank == root else None, root=root)
    summary = comm.bcast(done[1] if comm.rank == root else None, root=root)
    found = mine["points"]
    ids = found["id"]
    local = np.searchsorted(ids, mine["triangles"]).reshape(-1, 3)
    segments = np.searchsorted(ids, mine["segments"]).reshape(-1, 2)
    own = found["owner"] == comm.rank
    out, same = _output(dmesh, packed, found, ids, local, mine["triangles"], mine["triangle_gids"], segments,
                        mine["segment_gids"], mine["segment_tags"], mine["segment_boundary"],
                        int(own.sum()), ids[own], found["origin"][own], summary["curve_reach"])
    _warn_quality(summary["stats"], stacklevel=5)
    if stats is not None:
        stats.update(quality=summary["stats"], quality_on_root=True, pieces=len(keys),
                     triangles=summary["triangles"], unchanged=same, root_points=summary["points"],
                     root_seconds=summary["root_seconds"], root_bytes=summary["bytes"])
        if geometry is not None:
            stats.update(curve_points_dropped_outside=int(summary["stats"].get("curve_points_dropped_outside", 0)),
                         curve_reach=summary["curve_reach"])
    return out


def _root_stage(size: int, sel: np.ndarray, dropped: np.ndarray, options: Any, geometry: Any, keys: np.ndarray,
                boundary: np.ndarray, tags: np.ndarray) -> tuple[list[dict], dict]:
    """_quality_on_root's work on the root: the serial last stage on the
    gathered selection, and each rank's share of its output."""
    sel = sel[np.lexsort((sel["order1"], sel["order0"]))]  # the serial selection's order
    by_key = np.argsort(sel["key"], kind="stable")
    at = np.searchsorted(sel["key"], keys, sorter=by_key)
    pieces = by_key[np.minimum(at, len(sel) - 1)] if len(sel) else at
    if len(sel) == 0 or (sel["key"][pieces] != keys).any():
        raise RuntimeError("the quality pass: a piece's end is no kept point (an internal error)")
    extra = geometry._core_arguments() if geometry is not None else {}
    # The serial step's early triangulation batches (frfc_stages.hpp Early_start):
    # the first pass's kept points (input points and segment candidates), then
    # the second pass's (interior candidates, deferred input points), then the
    # spacing repair's. The serial quality pass follows the insertion history.
    first = (sel["order0"] == 0) & (sel["key"] < _INTERIOR_TIE)
    late = (sel["order0"] == 0) & (sel["key"] >= _INTERIOR_TIE)
    batches = [int(first.sum()), int(late.sum()), int(len(sel) - first.sum() - late.sum())]
    res = _core.triangulate_selection(np.column_stack([sel["x"], sel["y"]]), sel["kind"], sel["required"],
                                      (sel["origin"] < 0).astype(np.uint8), pieces, boundary.astype(np.uint8),
                                      np.asarray(tags, dtype=np.int64), options, batches=batches, **extra)
    index = res["selection_index"]
    xy, kind = res["points"], res["kind"]
    n = len(xy)
    new = index < 0
    of = np.maximum(index, 0)
    origin = np.where(new, -1, sel["origin"][of])
    owner = np.where(new, -1, sel["rank"][of]).astype(np.int64)
    required = np.where(new, 0, sel["required"][of]).astype(np.uint8)
    # restore_origins (step.cpp): an output point without origin at exactly the
    # coordinates of a dropped input point, on a segment or not as it was, is that point.
    restored = 0
    fresh = np.flatnonzero(origin < 0)
    if len(fresh) and len(dropped):
        pair = np.dtype([("x", "<f8"), ("y", "<f8")])
        table = np.zeros(len(dropped), dtype=pair)
        table["x"], table["y"] = dropped["x"] + 0.0, dropped["y"] + 0.0  # (-0.0 == 0.0)
        order = np.argsort(table, order=("x", "y"))
        table = table[order]
        ask = np.zeros(len(fresh), dtype=pair)
        ask["x"], ask["y"] = xy[fresh, 0] + 0.0, xy[fresh, 1] + 0.0
        at = np.minimum(np.searchsorted(table, ask), len(table) - 1)
        hit = table[at] == ask
        was = dropped["kind"][order[at]]
        on_segment = np.isin(kind[fresh], [_KIND["CORNER"], _KIND["BOUNDARY"]])
        hit &= np.isin(was, [_KIND["CORNER"], _KIND["BOUNDARY"]]) == on_segment
        origin[fresh[hit]] = dropped["gid"][order[at[hit]]]
        kind[fresh[hit]] = np.where(was[hit] == _KIND["SAMPLED"], _KIND["STEINER"], was[hit])
        restored = int(hit.sum())
    # The triangles least id first, in the canonical order (rows sorted).
    tri = res["triangles"]
    roll = np.argmin(tri, axis=1)
    tri = np.take_along_axis(tri, (roll[:, None] + np.arange(3)[None, :]) % 3, axis=1)
    order = np.lexsort((tri[:, 2], tri[:, 1], tri[:, 0]))
    tri = tri[order]
    # A new point goes to a rank that owns a vertex of one of its triangles.
    while (owner < 0).any():
        corner = owner[tri]
        known = corner.max(axis=1)
        unknown = (corner < 0) & (known >= 0)[:, None]
        if not unknown.any():
            owner[owner < 0] = 0
            break
        owner[tri[unknown]] = np.broadcast_to(known[:, None], corner.shape)[unknown]
    seg = res["segments"]
    seg_tags = np.asarray(tags, dtype=np.int64)[res["segment_piece"]] if len(seg) else np.zeros(0, np.int64)
    seg_boundary = res["segment_is_boundary"].astype(bool)
    table = np.zeros(n, dtype=_OUT_POINT)
    table["gid"] = table["id"] = np.arange(n)
    table["x"], table["y"], table["owner"], table["required"], table["origin"], table["kind"] = \
        xy[:, 0], xy[:, 1], owner, required, origin, kind
    tri_rank = owner[tri[:, 0]]
    seg_rank = owner[seg.min(axis=1)] if len(seg) else np.zeros(0, np.int64)
    # Each rank's rows, from one stable sort per array (not a scan per rank).
    def split(rank_of: np.ndarray) -> list[np.ndarray]:
        order = np.argsort(rank_of, kind="stable")
        return np.split(order, np.searchsorted(rank_of[order], np.arange(1, size)))

    tri_of, seg_of, own_of = split(tri_rank), split(seg_rank), split(owner)
    packages = []
    for rank in range(size):
        t, s = tri_of[rank], seg_of[rank]
        used = np.unique(np.concatenate([own_of[rank], tri[t].reshape(-1), seg[s].reshape(-1)]))
        packages.append(dict(points=table[used], triangles=tri[t], triangle_gids=t.astype(np.int64),
                             segments=seg[s], segment_gids=s.astype(np.int64), segment_tags=seg_tags[s],
                             segment_boundary=seg_boundary[s]))
    stats = dict(res["stats"])
    stats["restored_points"] = restored
    return packages, dict(stats=stats, curve_reach=float(res["curve_reach"]), triangles=len(tri), points=n)


def _carried_triangle_tags(old: DistributedMesh, a: np.ndarray, b: np.ndarray, c: np.ndarray,
                           reach: float = 0.0) -> np.ndarray:
    """The tag of each new triangle (a, b, c) (this rank's, in their stored
    rotation): that of the old triangle containing its centroid, as the serial
    carry_tags (parent_map.cpp): region borders are constraints, so a new
    triangle lies in one region. The old triangles whose bounding boxes contain
    a centroid come by the transfer's reach halo (distributed_transfer._HeldOld).
    After a step on curves, a centroid may lie outside the old domain by up to
    `reach`: it gets the nearest old triangle (the serial walk stops in a
    boundary triangle within that distance). Collective."""
    from .transfer import _bounds, _HeldOld, _nearest_triangles, _receiving_chunks, _table

    comm = old.comm
    MPI = _mpi()
    centroid = (a + b + c) / 3.0
    tagged = comm.allreduce(bool(len(old.triangle_tags) and (old.triangle_tags != 0).any()), op=MPI.LOR)
    if not tagged:
        return np.zeros(len(centroid), dtype=np.int64)
    low, span, magnitude = _bounds(comm, old.points, centroid)
    perm, _ = _halo.hilbert_chunks(centroid[:, 0], centroid[:, 1], low, span)
    starts = _receiving_chunks(len(perm))
    box = _halo.chunk_boxes(centroid[perm, 0], centroid[perm, 1], starts)
    held = _HeldOld(old, _table(box, np.full(len(box), reach)), low, span, magnitude)

    def locate() -> np.ndarray:
        if not len(centroid):
            return np.zeros(0, dtype=np.int64)
        found = _core.locate_points(held.points, held.triangles, centroid)[0] if held.n_triangles \
            else np.full(len(centroid), -1)
        outside = np.flatnonzero(found < 0)
        if len(outside) and reach > 0 and held.n_triangles:
            found[outside], distance = _nearest_triangles(held.points, held.triangles, centroid[outside])
            if (distance > reach).any():
                found[outside[distance > reach]] = -1
        if (found < 0).any():
            raise RuntimeError("carry_tags: a new triangle outside the old mesh (an internal error)")
        return np.asarray(held.tags[found], dtype=np.int64)

    return _collective(comm, locate)


def evolve_distributed(dmesh: DistributedMesh, delta: Any = None, *, size: Any = None, method: str = "frfc",
                       options: Any = None, stats: dict[str, Any] | None = None,
                       build_options: Callable[[], Any] | None = None, geometry: Any = None,
                       arguments: Mapping[str, Any] | None = None) -> DistributedMesh:
    """:func:`evomesh.evolve` on a :class:`~evomesh.DistributedMesh` (it calls
    this, with `build_options` making the options from its arguments as for a
    Mesh, and its other `arguments` by name: seed, options, overrides,
    displacement, interface, interface_tag, interface_regions, interface_band).
    Collective: every rank calls it with its own delta. The step is
    :func:`step`, the result rebalanced (:meth:`DistributedMesh.rebalance`,
    global ids kept: the serial step's output order) with its lineage moved
    along. `options`: an FrfcOptions, when called directly (default: the
    paper's).

    Before any work the ranks agree on every argument but the per-point
    values (:func:`_request_fingerprints`; a difference raises the same
    ValueError on every rank, naming the argument and the ranks), then check
    and convert them (a failure on one rank raises on all). The rest (size's
    conversion, the step, the rebalance) runs under this rank's thread limit
    (:func:`evomesh.distributed.threads.rank_thread_count`)."""
    arguments = {"options": options} if arguments is None else arguments

    def check() -> tuple[Any, Any]:
        if (delta is None) == (size is None):
            raise TypeError("evolve on a DistributedMesh needs exactly one of delta and size (each a value per "
                            "owned point, a scalar, or a function of the owned coordinates)")
        if method != "frfc":
            raise ValueError(f"not yet on a DistributedMesh: method={method!r} (only 'frfc')")
        if arguments.get("displacement") is not None or arguments.get("interface") is not None:
            raise ValueError("not yet on a DistributedMesh: displacement= and interface= (gather() the mesh, evolve "
                             "it on the root, and scatter() the result)")
        if any(arguments.get(name) is not None for name in _INTERFACE_ARGUMENTS):
            raise TypeError("interface_tag, interface_regions and interface_band need interface (phi)")
        if build_options is not None:
            o = build_options()
        else:
            o = _core.FrfcOptions.paper() if options is None else options
            if not isinstance(o, _core.FrfcOptions):
                raise TypeError(f"options must be evomesh FrfcOptions, got {type(o).__name__}")
            o.validate()
        return o, as_geometry(geometry)

    o, g = _same_everywhere(dmesh.comm, "evolve",
                            lambda: _request_fingerprints(delta, size, method, geometry, arguments), check)
    with rank_thread_limit(dmesh.comm, o.threads, stats):  # (size's conversion and the rebalance too)
        out = step(dmesh, delta if size is None else delta_from_size(dmesh, size), o, stats=stats, geometry=g)
        return out.rebalance(renumber=False)  # (the lineage moves along)


_INTERFACE_ARGUMENTS = ("interface_tag", "interface_regions", "interface_band")
# Options that may differ between ranks: the result does not depend on them.
_RANK_LOCAL_OPTIONS = ("threads",)


def _request_fingerprints(delta: Any, size: Any, method: Any, geometry: Any,
                          arguments: Mapping[str, Any]) -> dict[str, str]:
    """What must be the same on every rank for a step, as short texts
    (distributed._fingerprint): the method, the kind of delta and size (and a
    number's value), the geometry's parameters, the seed, the options (field by
    field) and every keyword override, the interface arguments. Per-point
    values (arrays, functions) only by kind: comparing them is the step's work."""
    fingerprints = {"method": _fingerprint(method), "delta": _fingerprint(delta, per_point=True),
                    "size": _fingerprint(size, per_point=True), "geometry": _geometry_fingerprint(geometry)}
    for name, value in arguments.items():
        if name == "overrides":
            fingerprints.update({key: _fingerprint(v) for key, v in value.items() if key not in _RANK_LOCAL_OPTIONS})
        elif name == "options":
            fingerprints["options"] = _fingerprint(value)
            if isinstance(value, (_core.FrfcOptions, _core.DrfcOptions)):
                fingerprints.update({f"options.{field}": _fingerprint(_option_value(getattr(value, field)))
                                     for field in type(value).fields if field not in _RANK_LOCAL_OPTIONS})
        else:
            fingerprints[name] = _fingerprint(value, per_point=name in ("displacement", "interface"))
    return fingerprints


def _option_value(value: Any) -> Any:
    """An option field as a plain value (an enum by its name)."""
    return value if isinstance(value, (bool, int, float, str)) else str(value)


def _geometry_fingerprint(geometry: Any) -> str:
    try:
        g = as_geometry(geometry)
    except Exception:  # noqa: BLE001 - the check after the agreement says what is wrong with it
        return _fingerprint(geometry)
    return _NOT_GIVEN if g is None else g._fingerprint()
