"""Step 1 of the step on a distributed mesh: nn, the weights and the spacing
function f, each equal bit for bit to the serial step's (the arguments
are docs/distributed-step.md, sections 3.1 and 3.2).

For a mesh M and delta(p) per point, the serial step computes nn_M(p) (the
distance to the nearest other point, within the domain), the weights
w_p = delta(p) nn_M(p) capped by the local feature size (the distance across the
domain to a facing chain of segments), and f(x) = min_p (w_p + |x - p|). Each of
these reads only what lies within a distance that an upper bound computed from
the rank's own part gives, so a rank computes the bound, receives what lies
within it (``_halo.copies_within_reach``: complete by construction), and then
the exact value:

- nn(p) <= the distance to the nearest *held* point; every point nearer than that
  is within it, so one exchange of the points within that bound makes nn exact.
  Within the domain the serial rule reads p's own triangles only (held).
- The local feature size walks from a point p inside a chain of segments along
  its normal up to w_p (before the cap), crossing the triangles that the walk
  meets within w_p of p: every triangle whose circumscribing disc about its
  centroid comes within w_p of p is received. A walk that still reaches the
  part's border (rounding in the floating-point walk) is reported and widened.
  The chains themselves (which segments form a chain, where it ends, its
  corners) are global objects: every rank holds the *segment skeleton* (the
  segments and their end points), one allgather of O(segments) records, and runs
  the serial ``segment_chains`` on it, in global-id order, so chains, corners and
  the corners' rule are the serial ones.
- f(x) <= f_H(x), the minimum over the held sites (a lemma: every site that
  attains or ties f(x) lies within f(x) of x, since weights are >= 0). The sites
  within f_H(x) of x make the answer exact, and the spacing function's settle
  step returns the exact least cone with ties to the lowest global id, whatever
  other sites the graph holds. Every graph uses the same shift (the largest
  weight over all ranks), so CGAL decides hidden sites on the same rounded
  values.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, cast

import numpy as np

from .. import _core
from ..spacing_function import as_delta
from . import _halo
from .mesh import DistributedMesh, _check_comm, _collective, _exchange, _mpi

__all__ = ["DistributedSpacing", "delta_from_size", "segment_skeleton"]

_POINT = np.dtype([("gid", "<i8"), ("x", "<f8"), ("y", "<f8")])
_SITE = np.dtype([("gid", "<i8"), ("x", "<f8"), ("y", "<f8"), ("w", "<f8")])
_TRIANGLE = np.dtype([("gid", "<i8"), ("v", "<i8", (3,)), ("xy", "<f8", (3, 2))])
_SKELETON_SEGMENT = np.dtype([("gid", "<i8"), ("v", "<i8", (2,)), ("tag", "<i8"), ("boundary", "u1")])
_SKELETON_POINT = np.dtype([("gid", "<i8"), ("x", "<f8"), ("y", "<f8"), ("kind", "u1"), ("required", "u1"),
                            ("owner", "<i4")])
# Widening of a walk that reached the part's border: its reach grows fourfold.
_WIDEN = 4.0


def _union(gids: np.ndarray, xy: np.ndarray, more_gids: np.ndarray, more_xy: np.ndarray) -> tuple[np.ndarray, ...]:
    """The held points followed by the received ones not held (once each)."""
    more_gids, first = np.unique(more_gids, return_index=True)
    new = ~np.isin(more_gids, gids)
    return np.concatenate([gids, more_gids[new]]), np.concatenate([xy, more_xy[first][new]])


def _local_index(sorted_gids: np.ndarray, order: np.ndarray, gids: np.ndarray) -> np.ndarray:
    return order[np.searchsorted(sorted_gids, gids)]


def boundary_flags(dmesh: DistributedMesh) -> np.ndarray:
    """Per owned segment: whether it is on the boundary (an edge of one
    triangle). Local: a segment's smaller-gid end is owned here, so every
    triangle at it is held."""
    held_triangles = np.concatenate([dmesh.triangles, dmesh.halo_triangles]).reshape(-1, 3)
    seg = np.asarray(dmesh.segments, dtype=np.int64).reshape(-1, 2)
    if not len(seg):
        return np.zeros(0, dtype=bool)
    edges = np.sort(np.concatenate([held_triangles[:, [0, 1]], held_triangles[:, [1, 2]],
                                    held_triangles[:, [2, 0]]]), axis=1)
    n = max(len(dmesh.points), 1)
    edge_key, edge_count = np.unique(edges[:, 0] * n + edges[:, 1], return_counts=True)
    sorted_seg = np.sort(seg, axis=1)
    at = np.searchsorted(edge_key, sorted_seg[:, 0] * n + sorted_seg[:, 1])
    return edge_count[np.minimum(at, len(edge_count) - 1)] == 1


def segment_skeleton(dmesh: DistributedMesh) -> tuple[np.ndarray, np.ndarray]:
    """Every segment of the mesh (gid, end gids, tag, boundary flag) in global-id
    order, and its end points (gid, coordinates, kind, required, owner) in
    global-id order, on every rank: one allgather of O(segments) records.
    Collective."""
    comm = dmesh.comm
    seg = np.asarray(dmesh.segments, dtype=np.int64).reshape(-1, 2)
    records = np.empty(len(seg), dtype=_SKELETON_SEGMENT)
    records["gid"] = dmesh.segment_global_ids
    records["v"] = dmesh.global_ids[seg] if len(seg) else np.zeros((0, 2), np.int64)
    records["tag"] = dmesh.segment_tags
    records["boundary"] = boundary_flags(dmesh)
    ends = np.unique(seg.reshape(-1))
    points = np.empty(len(ends), dtype=_SKELETON_POINT)
    points["gid"] = dmesh.global_ids[ends]
    points["x"], points["y"] = dmesh.points[ends, 0], dmesh.points[ends, 1]
    points["kind"] = 0 if dmesh.kind is None else dmesh.kind[ends]
    points["required"] = dmesh.required[ends]
    points["owner"] = dmesh.owners[ends]
    all_segments = np.concatenate(comm.allgather(records))
    all_points = np.concatenate(comm.allgather(points))
    all_segments = all_segments[np.argsort(all_segments["gid"], kind="stable")]
    _, first = np.unique(all_points["gid"], return_index=True)
    return all_segments, all_points[first]


class DistributedSpacing:
    """FRFC's step 1 on a :class:`~evomesh.DistributedMesh`: nn, the weights and
    f at the owned points, equal bit for bit to the serial step's; and f at any
    points a rank asks for (:meth:`evaluate`). Collective.

    Parameters
    ----------
    dmesh : DistributedMesh
    delta : float, array_like of shape (n_owned,), or callable
        The factor per owned point (as :func:`evomesh.evolve` takes it: finite,
        in [DELTA_MIN, DELTA_MAX]), or a function of the owned points'
        coordinates (an (n_owned, 2) array) returning it.
    within_domain : bool, default True
        As in :func:`evomesh.evolve`: nn within the domain and weights capped by
        the local feature size.
    stats : dict, optional
        Filled with figures summed over the ranks: "halo_points" (points
        received for nn), "walk_triangles" (triangles received for the walks),
        "walk_widenings" (rounds of widening), "sites_received" (sites received
        for f at the points), "skeleton_segments", and "bytes" (sent).
    geometry : BoundaryGeometry, optional
        Curved boundaries, as :func:`evomesh.evolve` takes them: on a chain of
        a curved tag the local feature size is also capped where the chain
        turns (as serial). The kinds of `dmesh` must already be the geometry's
        (the step sets them: distributed_step.with_curve_kinds).
    prefetch : bool, default False
        Also fetch, with the sites for f at the points, those that f at any
        point of an owned triangle or segment can need (within f(p) + 2 e(p)
        of each owned point p, e(p) its longest edge): later queries there
        (a step's candidates) then rarely rebuild the graph. The answers are
        the same either way.

    Attributes
    ----------
    nn : ndarray, shape (n_owned,)
        nn_M at the owned points (within the domain when `within_domain`).
    weight : ndarray, shape (n_owned,)
        w = delta nn, capped by the local feature size.
    f : ndarray, shape (n_owned,)
        f at the owned points (Lemma 3.1: the weight where delta <= 1 and nn did
        not grow, else min(f(p), w_p)).
    shift : float
        The largest weight over all ranks (every rank's graph uses it).

    Notes
    -----
    The segment skeleton (every segment with its two end points) is replicated
    on every rank, so memory per rank grows with the number of segments (for a
    domain boundary, like the square root of the number of points). Curved
    boundaries are not part of a DistributedMesh: a step is given them, as
    a serial step is.
    """

    def __init__(self, dmesh: DistributedMesh, delta: Any, *, within_domain: bool = True,
                 stats: dict[str, Any] | None = None, geometry: Any = None, prefetch: bool = False):
        if not isinstance(dmesh, DistributedMesh):
            raise TypeError(f"dmesh must be an evomesh.DistributedMesh, got {type(dmesh).__name__}")
        comm = dmesh.comm
        _check_comm(comm)
        MPI = _mpi()
        self._dmesh = dmesh
        self._geometry = geometry
        self._counts = dict(halo_points=0, walk_triangles=0, sites_received=0, skeleton_segments=0, bytes=0)
        self._widenings = 0
        d = _collective(comm, self._check_delta, delta)
        within = bool(comm.allreduce(bool(within_domain), op=MPI.LAND))
        if within != bool(within_domain):
            raise ValueError("within_domain must be the same on every rank")
        self._frame()

        nn_euclid = self._euclidean_nn()
        n_owned = dmesh.n_owned
        held_triangles = self._held_triangles()[0]
        if within and len(dmesh.points):
            nn_all, grew = _core.nn_within_domain(dmesh.points, held_triangles, nn_euclid)
            grew = np.asarray(grew, dtype=np.int64)
            grew = grew[grew < n_owned]
        else:
            nn_all, grew = nn_euclid, np.zeros(0, dtype=np.int64)
        nn = np.ascontiguousarray(nn_all[:n_owned], dtype=np.float64)
        weight = d * nn
        if within:
            weight = np.minimum(weight, self._feature_size(weight))
        self.nn = nn
        self.weight = weight
        self.shift = float(comm.allreduce(float(weight.max()) if n_owned else 0.0, op=MPI.MAX))
        self._held_weight = dmesh.exchange_halo(weight)
        # The graph over the held sites and every site received so far (built on
        # the first query, rebuilt only when a query brings sites it lacks): a
        # graph over more true sites is still exact where its sites include those
        # that attain f (ties go to the least site id, whatever the set).
        self._graph_cache: Any = None
        self._cache_gids = np.zeros(0, dtype=np.int64)
        self._cache_xy = np.zeros((0, 2))
        self._cache_weight = np.zeros(0)

        f = weight.copy()
        ask = d > 1
        ask[grew] = True
        which = np.flatnonzero(ask)
        if prefetch and comm.allreduce(n_owned > 0, op=MPI.LAND):
            # One fetch for f at the asking points and for a step's candidates
            # later: a candidate x in an owned triangle or on an owned segment
            # with an owned vertex p needs the sites within f(x) <= f(p) + |x - p|
            # of x, so within f(p) + 2 e(p) of p (e(p): p's longest edge), and
            # f(p) <= w(p), or f over the held sites (both upper bounds). The
            # later queries then rarely bring a site the graph lacks, and the
            # graph is built twice rather than once per query batch.
            owned_xy = np.ascontiguousarray(dmesh.owned_points, dtype=np.float64)
            upper = weight.copy()
            if len(which):
                upper[which] = np.minimum(upper[which], self._held_graph().evaluate(owned_xy[which])[0])
            reach = (upper + 2 * _longest_edges(dmesh)) * (1 + 16 * np.finfo(np.float64).eps)
            graph = self._graph_at(owned_xy, "sites_received", reach=reach)
            value = np.asarray(graph.evaluate(owned_xy[which])[0]) if len(which) else np.zeros(0)
        else:
            value = self._evaluate(dmesh.owned_points[which], "sites_received")
        f[which] = np.minimum(value, weight[which])
        self.f = f
        for a in (self.nn, self.weight, self.f):
            a.flags.writeable = False
        if stats is not None:
            stats.update({k: comm.allreduce(v, op=MPI.SUM) for k, v in self._counts.items()})
            stats["walk_widenings"] = self._widenings  # (the same on every rank: the loop is collective)

    # ------------------------------------------------------------------ checks
    def _check_delta(self, delta: Any) -> np.ndarray:
        """delta over the owned points, checked as evolve checks it (a scalar, an
        array or a function of the owned coordinates; finite, in [DELTA_MIN, DELTA_MAX])."""
        dmesh = self._dmesh
        if callable(delta):
            delta = delta(np.array(dmesh.owned_points))
        return as_delta(cast(Any, SimpleNamespace(n_points=dmesh.n_owned)), delta)

    def _frame(self) -> None:
        """The global box the halos' Hilbert chunks are cut over."""
        MPI = _mpi()
        comm, xy = self._dmesh.comm, self._dmesh.owned_points
        big = np.finfo(np.float64).max
        lo = [comm.allreduce(float(xy[:, k].min()) if len(xy) else big, op=MPI.MIN) for k in (0, 1)]
        hi = [comm.allreduce(float(xy[:, k].max()) if len(xy) else -big, op=MPI.MAX) for k in (0, 1)]
        self._lo = np.array(lo)
        self._span = float(max(hi[0] - lo[0], hi[1] - lo[1], 0.0))
        self._magnitude = float(max(abs(lo[0]), abs(lo[1]), abs(hi[0]), abs(hi[1])))

    def _copies(self, query_xy: np.ndarray, reach: np.ndarray, record_xy: np.ndarray, extra: np.ndarray,
                records: np.ndarray) -> np.ndarray:
        """The records of other ranks within reach of this rank's queries (one exchange)."""
        index, dest = _halo.copies_within_reach(self._dmesh.comm, self._lo, self._span, self._magnitude,
                                                np.ascontiguousarray(query_xy, dtype=np.float64), reach,
                                                np.ascontiguousarray(record_xy, dtype=np.float64), extra)
        self._counts["bytes"] += int(len(index)) * records.dtype.itemsize
        return _exchange(self._dmesh.comm, dest, records[index])[0]

    def _held_triangles(self) -> tuple[np.ndarray, np.ndarray]:
        dmesh = self._dmesh
        return (np.concatenate([dmesh.triangles, dmesh.halo_triangles]).reshape(-1, 3),
                np.concatenate([dmesh.triangle_global_ids, dmesh.halo_triangle_global_ids]))

    # ---------------------------------------------------------------- stage 1a
    def _euclidean_nn(self) -> np.ndarray:
        """nn over the whole mesh at the held points, exact at the owned ones."""
        dmesh = self._dmesh
        n_owned = dmesh.n_owned
        held = np.ascontiguousarray(dmesh.points, dtype=np.float64)
        bound = _core.nn_spacing(held) if len(held) > 1 else np.full(len(held), np.inf)
        # Points of other ranks within the bound of an owned point (their owners send them).
        mine = np.empty(n_owned, dtype=_POINT)
        mine["gid"], mine["x"], mine["y"] = dmesh.global_ids[:n_owned], held[:n_owned, 0], held[:n_owned, 1]
        got = self._copies(held[:n_owned], np.asarray(bound[:n_owned], dtype=np.float64), held[:n_owned],
                           np.zeros(n_owned), mine)
        self._counts["halo_points"] += int(len(got))
        gids, xy = _union(dmesh.global_ids, held, got["gid"], np.column_stack([got["x"], got["y"]]))
        if len(xy) < 2:
            return np.full(len(held), np.inf)
        return np.asarray(_core.nn_spacing(np.ascontiguousarray(xy)))[: len(held)]

    # ---------------------------------------------------------------- stage 1b
    def _feature_size(self, limit: np.ndarray) -> np.ndarray:
        """The serial local_feature_size at the owned points (+inf off the chains)."""
        dmesh = self._dmesh
        n_owned = dmesh.n_owned
        lfs = np.full(n_owned, np.inf)
        segments, points = segment_skeleton(dmesh)
        self._counts["skeleton_segments"] = len(segments) if dmesh.comm.rank == 0 else 0
        self._counts["bytes"] += (len(segments) * _SKELETON_SEGMENT.itemsize + len(points) * _SKELETON_POINT.itemsize) \
            * (dmesh.comm.size - 1) // max(dmesh.comm.size, 1)
        if not len(segments):
            return lfs
        pgid = points["gid"]
        local = np.searchsorted(pgid, segments["v"])
        table = _core.chain_table(np.column_stack([points["x"], points["y"]]), local,
                                  segments["boundary"].astype(np.uint8), points["kind"],
                                  segment_tags=segments["tag"], required=points["required"],
                                  point_gids=pgid, segment_keys=segments["gid"],
                                  **({} if self._geometry is None else self._geometry._core_arguments()))
        owned_gids = dmesh.global_ids[:n_owned]  # sorted (owned points are in gid order)
        # The corners' rule.
        corner = np.asarray(table["corner_feature_size"])
        on_owned = np.isin(pgid, owned_gids)
        lfs[np.searchsorted(owned_gids, pgid[on_owned])] = corner[on_owned]
        # The walks, from the owned points inside chains.
        v_gid = pgid[table["point"]]
        take = np.isin(v_gid, owned_gids)
        rows = {k: np.asarray(table[k])[take] for k in ("point", "before", "after", "along", "two_sided",
                                                         "point_chain")}
        at = np.searchsorted(owned_gids, v_gid[take])
        chain_ends = pgid[np.asarray(table["chain_ends"]).reshape(-1, 2)]
        walked = self._walks(rows, pgid, at, limit[at], np.asarray(table["segment_chain"]), segments, chain_ends)
        # No tangent: the serial walk skips the point; on a curved chain, the turn caps the rest.
        walked = np.where(np.isnan(walked), np.inf, np.minimum(walked, np.asarray(table["curve_cap"])[take]))
        lfs[at] = np.minimum(lfs[at], walked)
        return lfs

    def _walks(self, rows: dict[str, np.ndarray], pgid: np.ndarray, at: np.ndarray, limit: np.ndarray,
               segment_chain: np.ndarray, segments: np.ndarray, chain_ends: np.ndarray) -> np.ndarray:
        """chain_feature_sizes at this rank's chain points on its part plus the
        triangles within reach of them, widened until every walk is certified."""
        dmesh = self._dmesh
        comm = dmesh.comm
        MPI = _mpi()
        # This rank's triangles as records others may need.
        own_tri = np.asarray(dmesh.triangles, dtype=np.int64).reshape(-1, 3)
        records = np.empty(len(own_tri), dtype=_TRIANGLE)
        records["gid"] = dmesh.triangle_global_ids
        records["v"] = dmesh.global_ids[own_tri] if len(own_tri) else np.zeros((0, 3), np.int64)
        records["xy"] = dmesh.points[own_tri] if len(own_tri) else np.zeros((0, 3, 2))
        centroid = records["xy"].mean(axis=1) if len(own_tri) else np.zeros((0, 2))
        extra = np.sqrt(((records["xy"] - centroid[:, None, :]) ** 2).sum(axis=2)).max(axis=1) \
            if len(own_tri) else np.zeros(0)
        query_xy = dmesh.owned_points[at]
        reach = np.asarray(limit, dtype=np.float64).copy()
        pending = np.ones(len(at), dtype=bool)
        received = np.zeros(0, dtype=_TRIANGLE)
        walked = np.full(len(at), np.inf)
        diameter = 2 * self._span
        widenings = 0
        while True:
            got = self._copies(query_xy[pending], reach[pending], centroid, extra, records)
            received = np.concatenate([received, got])
            self._counts["walk_triangles"] += int(len(got))
            if pending.any():
                lfs, certified = self._walk_on(self._part(received), rows, pgid, pending, limit, segment_chain,
                                               segments, chain_ends)
                walked[pending] = lfs
                pending[np.flatnonzero(pending)[np.asarray(certified, dtype=bool)]] = False
            if comm.allreduce(int(pending.sum()), op=MPI.SUM) == 0:
                break
            # A reach beyond the mesh's diameter already brought every triangle.
            if comm.allreduce(bool(pending.any() and (reach[pending] > diameter).all()), op=MPI.LOR):
                raise RuntimeError("local feature size: a walk left a part that holds every triangle around it "
                                   "(an internal error)")
            reach[pending] *= _WIDEN
            widenings += 1
        self._widenings = widenings
        return walked

    def _part(self, received: np.ndarray) -> dict[str, np.ndarray]:
        """The held mesh plus the received triangles: points, triangles and triangle gids."""
        dmesh = self._dmesh
        tri, tri_gid = self._held_triangles()
        gids, xy = dmesh.global_ids, np.asarray(dmesh.points, dtype=np.float64)
        if len(received):
            gids, xy = _union(gids, xy, received["v"].reshape(-1), received["xy"].reshape(-1, 2))
            received = received[~np.isin(received["gid"], tri_gid)]
            received = received[np.unique(received["gid"], return_index=True)[1]]
        order = np.argsort(gids, kind="stable")
        sorted_gids = gids[order]
        triangles = np.concatenate([tri, _local_index(sorted_gids, order, received["v"].reshape(-1)).reshape(-1, 3)]) \
            if len(received) else tri
        return dict(points=np.ascontiguousarray(xy), triangles=np.ascontiguousarray(triangles, dtype=np.int64),
                    triangle_gids=np.concatenate([tri_gid, received["gid"]]).astype(np.int64),
                    gids=gids, order=order, sorted_gids=sorted_gids)

    def _walk_on(self, part: dict[str, np.ndarray], rows: dict[str, np.ndarray], pgid: np.ndarray,
                 pending: np.ndarray, limit: np.ndarray, segment_chain: np.ndarray, segments: np.ndarray,
                 chain_ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sorted_gids, order = part["sorted_gids"], part["order"]
        # The skeleton's segments with both ends in the part (every segment a walk can meet).
        v = segments["v"]
        pos = np.searchsorted(sorted_gids, v)
        present = (pos < len(sorted_gids)) & (sorted_gids[np.minimum(pos, len(sorted_gids) - 1)] == v)
        keep = present.all(axis=1)
        seg_local = order[pos[keep]]

        def index(skeleton_rows: np.ndarray) -> np.ndarray:
            return _local_index(sorted_gids, order, pgid[skeleton_rows])

        return _core.chain_feature_sizes(
            part["points"], part["triangles"], part["triangle_gids"], np.ascontiguousarray(seg_local),
            np.ascontiguousarray(segment_chain[keep]), np.arange(len(chain_ends), dtype=np.int64),
            np.ascontiguousarray(chain_ends), index(rows["point"][pending]), index(rows["before"][pending]),
            index(rows["after"][pending]), rows["along"][pending].astype(np.uint8),
            rows["two_sided"][pending].astype(np.uint8), rows["point_chain"][pending].astype(np.int64),
            np.ascontiguousarray(limit[pending], dtype=np.float64))

    # ----------------------------------------------------------------- stage 2
    def _evaluate(self, x: np.ndarray, counter: str) -> np.ndarray:
        graph = self._graph_at(x, counter)
        return np.asarray(graph.evaluate(x)[0]) if graph is not None and len(x) else np.zeros(0)

    def _graph_at(self, x: np.ndarray, counter: str, reach: np.ndarray | None = None) -> Any:
        """A spacing function over the held sites and those of other ranks within
        the bound at x: exact at x. None when this rank has no site. `reach`
        (optional): every site within reach[i] of x[i] instead of the bound."""
        dmesh = self._dmesh
        n_owned = dmesh.n_owned
        held_xy = np.ascontiguousarray(dmesh.points, dtype=np.float64)
        x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 2)
        self._held_graph()
        # The bound: the caller's reach, or f over the sites of the graph so far (true sites: an upper bound).
        if reach is not None:
            bound = reach
        else:
            bound = self._graph_cache.evaluate(x)[0] if len(x) and self._graph_cache is not None \
                else np.zeros(len(x))
        mine = np.empty(n_owned, dtype=_SITE)
        mine["gid"], mine["x"], mine["y"] = dmesh.global_ids[:n_owned], held_xy[:n_owned, 0], held_xy[:n_owned, 1]
        mine["w"] = self.weight
        got = self._copies(x, np.asarray(bound, dtype=np.float64), held_xy[:n_owned], np.zeros(n_owned), mine)
        self._counts[counter] += int(len(got))
        more, first = np.unique(got["gid"], return_index=True)
        new = ~np.isin(more, self._cache_gids)
        if new.any():
            gids = np.concatenate([self._cache_gids, more[new]])
            order = np.argsort(gids, kind="stable")
            take = first[new]
            self._cache_gids = gids[order]
            self._cache_xy = np.concatenate([self._cache_xy, np.column_stack([got["x"][take], got["y"][take]])])[order]
            self._cache_weight = np.concatenate([self._cache_weight, got["w"][take]])[order]
            self._graph_cache = self._graph(self._cache_gids, self._cache_xy, self._cache_weight)
        return self._graph_cache

    def _held_graph(self) -> Any:
        """The graph cache, built over the held sites on first use (None: no site held)."""
        dmesh = self._dmesh
        if self._graph_cache is None and len(dmesh.points):
            order = np.argsort(dmesh.global_ids, kind="stable")
            self._cache_gids = dmesh.global_ids[order]
            self._cache_xy = np.ascontiguousarray(dmesh.points, dtype=np.float64)[order]
            self._cache_weight = np.asarray(self._held_weight)[order]
            self._graph_cache = self._graph(self._cache_gids, self._cache_xy, self._cache_weight)
        return self._graph_cache

    def graph_for(self, x: Any) -> Any:
        """A spacing function (``_core.SpacingFunction``) exact at this rank's
        points `x` ((k, 2)): it holds every site that attains or ties f there.
        Collective. None on a rank that holds no point."""
        q = np.ascontiguousarray(np.asarray(x, dtype=np.float64).reshape(-1, 2))
        return self._graph_at(q, "sites_received")

    def _graph(self, gids: np.ndarray, xy: np.ndarray, weight: np.ndarray) -> Any:
        return _core.SpacingFunction(np.ascontiguousarray(xy), np.ascontiguousarray(weight, dtype=np.float64),
                                     site_ids=np.ascontiguousarray(gids, dtype=np.int64), shift=self.shift)

    def evaluate(self, x: Any) -> np.ndarray:
        """f at this rank's points `x` ((k, 2), any k including 0), exact: the
        serial step's f there, bit for bit. Collective (every rank calls it)."""
        comm = self._dmesh.comm

        def check() -> np.ndarray:
            q = np.asarray(x)
            if q.dtype == object or not np.issubdtype(q.dtype, np.number) or q.ndim != 2 or q.shape[1:] != (2,):
                raise ValueError(f"x must be a numeric (k, 2) array, got shape {q.shape} and dtype {q.dtype}")
            q = np.ascontiguousarray(q, dtype=np.float64)
            if not np.isfinite(q).all():
                raise ValueError("x must be finite")
            return q

        q = _collective(comm, check)
        return self._evaluate(q, "sites_received")



def _longest_edges(dmesh: DistributedMesh) -> np.ndarray:
    """Per owned point, its longest edge over the held triangles (0 without one)."""
    triangles = np.concatenate([dmesh.triangles, dmesh.halo_triangles]).reshape(-1, 3)
    longest = np.zeros(len(dmesh.points))
    for k in range(3):
        a, b = triangles[:, k], triangles[:, (k + 1) % 3]
        length = np.hypot(*(dmesh.points[a] - dmesh.points[b]).T)
        np.maximum.at(longest, a, length)
        np.maximum.at(longest, b, length)
    return longest[: dmesh.n_owned]


def delta_from_size(dmesh: DistributedMesh, size: Any) -> np.ndarray:
    """:func:`evomesh.delta_from_size` on a distributed mesh: delta at the owned
    points, equal bit for bit to the serial function's on the gathered mesh, and
    the same ValueError for a request out of range. Collective.

    The rule is the core's (`_core.delta_from_size`, size_request.hpp), run on
    this rank's points with `_core.SIZE_RULE_RINGS` halo rings (all that an
    owned point's delta reads), its triangles in global-id order (so the sums
    of L run in the serial order), the owned points checked.

    Parameters
    ----------
    size : float, array_like (n_owned,), or callable of the owned coordinates (an (n_owned, 2) array)
    """
    from .. import spacing_function as sf

    comm = dmesh.comm
    n_owned = dmesh.n_owned

    def values() -> np.ndarray:
        return sf._size_values(cast(Any, SimpleNamespace(n_points=n_owned, points=dmesh.owned_points)), size)

    h = _collective(comm, values)
    nn = DistributedSpacing(dmesh, 1.0).nn
    wide = DistributedMesh.from_local(dmesh.points, dmesh.triangles, dmesh.global_ids, comm, owners=dmesh.owners,
                                      halo_rings=_core.SIZE_RULE_RINGS)
    # (the same owned points, maybe in another order; the halo after them)
    owned = np.searchsorted(dmesh.global_ids[:n_owned], wide.global_ids[: wide.n_owned])
    tri = np.concatenate([wide.triangles, wide.halo_triangles]).reshape(-1, 3)
    tri_gid = np.concatenate([wide.triangle_global_ids, wide.halo_triangle_global_ids])
    tri = np.ascontiguousarray(tri[np.argsort(tri_gid, kind="stable")])

    held_h = wide.exchange_halo(h[owned])
    held_nn = wide.exchange_halo(nn[owned])

    def rule() -> np.ndarray:
        return _core.delta_from_size(np.ascontiguousarray(wide.points), tri, held_h, held_nn, True, sf.DELTA_MIN,
                                     sf.DELTA_MAX, n_checked=wide.n_owned, ids=wide.global_ids)

    delta = np.empty(n_owned)
    delta[owned] = _collective(comm, rule)[: wide.n_owned]
    return delta
