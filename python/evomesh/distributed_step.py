"""FRFC's packing on a distributed mesh (issue 29; docs/distributed-step.md,
section 3): the kept points of the step, the same set as the serial step's, on
any number of ranks. Stages, each the serial one on a rank's part:

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

Supported options: those of the paper's FRFC plus ``within_domain`` (no ring
candidates, no demotion, no spacing repair, uniform grids, no settled or coarse
skipping); the quality pass is not part of the packing.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _core
from .distributed import DistributedMesh, _collective, _mpi
from .distributed_packing import lexical_first_mis
from .distributed_spacing import DistributedSpacing, segment_skeleton

__all__ = ["packing"]

# Packing ties, unique over the ranks and in the serial order within each kind:
# input points by global id (< 2^60), segment candidates by their position in
# the serial list, interior candidates by (triangle id, draw).
_SEGMENT_TIE = 1 << 61
_INTERIOR_TIE = 1 << 62
_DRAW_BITS = 20


def _unsupported(options: Any) -> list[str]:
    """What of `options` the distributed packing does not do yet."""
    out = []
    if options.ring_samples:
        out.append("ring_samples")
    if options.demote_ratio > 0:
        out.append("demote_ratio > 0")
    if options.repair_ratio > 0 or options.gap_repair_ratio > 0 or options.refine_gap_ratio > 0:
        out.append("spacing repair (repair_ratio, gap_repair_ratio, refine_gap_ratio)")
    if options.adaptive_cells:
        out.append("adaptive_cells")
    if options.skip_settled or options.skip_coarse:
        out.append("skip_settled / skip_coarse")
    if options.radius == _core.RadiusRule.cheap:
        out.append("radius='cheap'")
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
    MPI = _mpi()
    comm = dmesh.comm
    if options is None:
        options = _core.FrfcOptions.paper()

    def check() -> None:
        if not isinstance(options, _core.FrfcOptions):
            raise TypeError(f"options must be evomesh FrfcOptions, got {type(options).__name__}")
        options.validate()
        missing = _unsupported(options)
        if missing:
            raise ValueError("not yet on a DistributedMesh: " + ", ".join(missing))

    _collective(comm, check)
    step1: dict = {}
    spacing = DistributedSpacing(dmesh, delta, within_domain=options.within_domain, stats=step1)
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
    f_part = values["f"]

    # First pass: the owned input points and the candidates on owned segments.
    radius, classes, forced = _core.part_input_spheres(part, f_part, options)
    own = at_held[:n_owned]
    seg_xy, seg_parent, seg_class = _core.part_segment_candidates(part, values["delta"], f_part, options)
    seg_owner = np.where(segments["v"][:, 0] < segments["v"][:, 1], 0, 1)
    owner_of_segment = spoints["owner"][np.searchsorted(spoints["gid"],
                                                        segments["v"][np.arange(len(segments)), seg_owner])]
    take = np.flatnonzero(owner_of_segment[seg_parent] == comm.rank)
    seg_xy, seg_parent, seg_class = seg_xy[take], seg_parent[take], seg_class[take]
    graph = spacing.graph_for(seg_xy)
    seg_radius = _core.part_candidate_radii(part, f_part, graph, options, True, seg_xy, seg_parent) \
        if graph is not None and len(seg_xy) else np.zeros(0)
    centres = np.concatenate([dmesh.owned_points, seg_xy])
    radii = np.concatenate([radius[own], seg_radius])
    kinds = np.concatenate([classes[own], seg_class]).astype(np.uint8)
    ties = np.concatenate([owned_gids, _SEGMENT_TIE + take]).astype(np.int64)
    first: dict = {}
    kept = lexical_first_mis(comm, centres, radii, kinds, ties, np.concatenate([forced[own] != 0,
                                                                                 np.zeros(len(take), bool)]),
                             stats=first)

    # Second pass: the interior candidates of the owned triangles.
    sampled = np.concatenate([np.ones(len(dmesh.triangles), np.uint8), np.zeros(len(dmesh.halo_triangles), np.uint8)])
    in_xy, in_parent, in_class = _core.part_interior_candidates(part, values["delta"], f_part, options, sampled)
    graph = spacing.graph_for(in_xy)
    in_radius = _core.part_candidate_radii(part, f_part, graph, options, False, in_xy, in_parent) \
        if graph is not None and len(in_xy) else np.zeros(0)
    tri_gid = part["triangle_gids"][in_parent]
    if len(in_parent):
        starts = np.flatnonzero(np.r_[True, in_parent[1:] != in_parent[:-1]])
        draw = np.arange(len(in_parent)) - np.repeat(starts, np.diff(np.r_[starts, len(in_parent)]))
    else:
        draw = np.zeros(0, np.int64)

    def check_ties() -> None:
        if len(draw) and (draw.max() >= 1 << _DRAW_BITS or tri_gid.max() >= 1 << (62 - _DRAW_BITS)):
            raise ValueError("too many candidates in one triangle, or triangle ids too large, for packing ties")

    _collective(comm, check_ties)
    keep = np.flatnonzero(kept)
    centres2 = np.concatenate([centres[keep], in_xy])
    radii2 = np.concatenate([radii[keep], in_radius])
    kinds2 = np.concatenate([np.zeros(len(keep), np.uint8), in_class.astype(np.uint8)])
    ties2 = np.concatenate([ties[keep], _INTERIOR_TIE + (tri_gid << _DRAW_BITS) + draw]).astype(np.int64)
    forced2 = np.concatenate([np.ones(len(keep), bool), np.zeros(len(in_xy), bool)])
    second: dict = {}
    kept2 = lexical_first_mis(comm, centres2, radii2, kinds2, ties2, forced2, stats=second)
    points = centres2[kept2]
    input_gid = np.where(ties2[kept2] < _SEGMENT_TIE, ties2[kept2], -1)
    if stats is not None:
        stats.update(step1=step1, first_pass_rounds=first["rounds"], second_pass_rounds=second["rounds"],
                     segment_candidates=comm.allreduce(len(take), op=MPI.SUM),
                     interior_candidates=comm.allreduce(len(in_xy), op=MPI.SUM),
                     bytes=step1["bytes"] + first["bytes_halo"] + first["bytes_states"] + second["bytes_halo"]
                     + second["bytes_states"])
    return points, input_gid
