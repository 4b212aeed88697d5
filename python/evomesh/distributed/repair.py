"""FRFC's spacing repair (repair_ratio; spacing_repair.hpp) on a distributed
mesh, in rounds over the ranks, exactly as the serial step.

The serial repair is sequential: the *needy* points (kept R-points, delta < 1,
whose second nearest kept centre lies beyond the target t(p) = repair_ratio
delta(p) nn_M(p)) are taken in global-id order, and each adds its best ring
candidate (a segment ring candidate becomes kept, an interior one is added),
which later decisions read. Why rounds give the serial result:

* p's decision reads the *added* points only within read(p) = max(t(p),
  2 w(p)) of p, w(p) being the largest distance from p to one of its
  candidates. The re-check asks whether an added point lies within t(p) of p.
  A candidate x is worth min(K(x), A(x)), K and A its distances to the nearest
  kept and added points; an added point at |y - x| >= K(x) does not change that
  value, and K(x) <= |x - p| (p itself is kept), so y matters only if
  |y - p| < 2 |x - p| <= 2 w(p). Everything else p reads is fixed before the
  repair: its candidates, their K (kept centres), nn2(p).
* The point q adds is one of q's candidates: within w(q) of q. So an earlier
  needy q can change p's decision only if |p - q| <= read(p) + w(q): the
  *conflicts* (tested with a relative slack of 1e-9 and a margin of 1e-12 of
  the coordinates, far above rounding: an extra conflict costs a wait, a
  missing one a wrong answer).
* Rounds, as the packing's MIS (distributed_packing): a rank decides each of
  its needy points whose earlier conflicting needy points are all decided,
  with every point they added (its own, and those received), and sends its
  decisions to the ranks holding copies of those points. By induction along
  the global-id order, every decision is the serial one (it reads the same
  added points within its reach, and the same fixed values); each round
  decides at least the earliest undecided needy point, so the rounds end.
  Within a round a rank also goes on down its own points in id order: a point
  whose undecided earlier conflicts are all its own and decided before it in
  that sweep is decided too (``_core.repair_decisions`` sees each choice
  before the next point).

What a rank holds: copies of the kept centres within read(p) of its needy
candidates p (for nn2 and K, exact: the nearest kept centres are among them),
found and sent by the senders (_halo.copies_within_reach, one exchange), and
copies of the needy points of other ranks that conflict with its own (the
same way); the decisions travel only to the ranks holding copies. The
decisions themselves run the serial C++ (spacing_repair.hpp: decide_repairs,
kept_distances, repair_target2), so every compared distance is the serial one
bit for bit.

The gap repair (gap_repair_ratio, refine_gap_ratio) follows in the same
rounds with its own radii (:func:`gap_repair`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import _core
from . import _halo
from .mesh import _collective, _exchange, _mpi, _ranges

__all__ = ["gap_repair", "spacing_repair"]

_SLACK = 1e-9
# A decision sent to the ranks holding a copy of the needy point: its global
# id, whether it added a point and where.
_DECISION = np.dtype([("gid", "<i8"), ("added", "u1"), ("x", "<f8"), ("y", "<f8")])
_NEEDY = np.dtype([("gid", "<i8"), ("x", "<f8"), ("y", "<f8"), ("w", "<f8")])
_XY = np.dtype([("x", "<f8"), ("y", "<f8")])

# Whether the points added by other ranks' decisions are used (always; False
# only in a test, to show that the comparison with serial can fail).
_SHARE_ADDED = True


def _xy(records: np.ndarray) -> np.ndarray:
    return np.column_stack([records["x"], records["y"]]) if len(records) else np.zeros((0, 2))


def spacing_repair(comm: Any, part: dict, f_part: np.ndarray, options: Any, own: np.ndarray,
                   owned_gids: np.ndarray, owned_xy: np.ndarray, owned_kept: np.ndarray, owned_delta: np.ndarray,
                   owned_nn: np.ndarray, kept_xy: np.ndarray, segment_ring: np.ndarray,
                   stats: dict[str, Any] | None = None) -> dict[str, np.ndarray]:
    """The spacing repair's first part (repair_ratio) on the ranks of `comm`:
    the serial step's decisions, each made by the owner of its needy point.
    Collective.

    Parameters
    ----------
    comm : mpi4py intracommunicator
    part : dict
        This rank's part (distributed_step._part); `own`: the part indices of
        the owned points, `owned_gids`, `owned_xy` theirs.
    f_part : (n_part,) float, f on the part.
    options : FrfcOptions (repair_ratio, ring_samples, radius_scale, seed).
    owned_kept : (n_owned,) bool, the owned input points the packing kept.
    owned_delta, owned_nn : (n_owned,) float, delta and nn_M at them.
    kept_xy : (k, 2) float, every centre this rank's packing kept (before any
        projection onto curves).
    segment_ring : structured array (position, x, y, owner), every segment
        ring candidate of every rank (replicated): its position in the serial
        list of segment candidates, centre and R-point's global id.
    stats : dict, optional
        Filled with "rounds", "needy", "repaired", "on_segments" (of them,
        segment candidates made kept) and "copies" (summed over ranks).

    Returns
    -------
    dict: "segment_positions" (the segment candidates this rank's needy points
    made kept), "points" (k, 2) and "gids" (k,) of the interior ring
    candidates they added (with the R-point's global id), each in the serial
    order, and "added": every point they added (both kinds, unprojected).
    """
    MPI = _mpi()
    ratio = options.repair_ratio if options.ring_samples else 0.0
    out = dict(segment_positions=np.zeros(0, np.int64), points=np.zeros((0, 2)), gids=np.zeros(0, np.int64),
               added=np.zeros((0, 2)))
    if not ratio > 0:
        if stats is not None:
            stats.update(rounds=0, needy=0, repaired=0, on_segments=0, copies=0)
        return out

    # The kept R-points with delta < 1 (the ones that can be needy) and their
    # candidates: segment ring candidates by position, then interior ring
    # candidates by direction (the serial order of evaluation).
    eligible = np.flatnonzero(owned_kept & (owned_delta < 1))
    at_xy = owned_xy[eligible]
    gid = owned_gids[eligible]
    ring = segment_ring[np.lexsort((segment_ring["position"], segment_ring["owner"]))]
    s_lo = np.searchsorted(ring["owner"], gid, side="left")
    s_count = np.searchsorted(ring["owner"], gid, side="right") - s_lo
    r_xy, r_xadj, r_dir = _core.part_ring_candidates(part, f_part, options, own[eligible])
    r_xadj = np.asarray(r_xadj, dtype=np.int64)
    r_count = np.diff(r_xadj)
    count = s_count + r_count
    xadj = np.concatenate([[0], np.cumsum(count)]).astype(np.int64)
    cand_xy = np.empty((int(xadj[-1]), 2))
    cand_kind = np.empty(int(xadj[-1]), np.int64)  # segment position, or -1 - direction
    seg_at = _ranges(xadj[:-1], s_count)
    seg_rows = ring[_ranges(s_lo, s_count)]
    cand_xy[seg_at] = _xy(seg_rows)
    cand_kind[seg_at] = seg_rows["position"]
    ring_at = _ranges(xadj[:-1] + s_count, r_count)
    cand_xy[ring_at] = np.asarray(r_xy).reshape(-1, 2)
    cand_kind[ring_at] = -1 - np.asarray(r_dir, dtype=np.int64)
    owner_of = np.repeat(np.arange(len(eligible)), count)
    w = np.zeros(len(eligible))
    np.maximum.at(w, owner_of, np.hypot(*(cand_xy - at_xy[owner_of]).T))
    target2 = np.asarray(_core.repair_targets(ratio, owned_delta[eligible], owned_nn[eligible]))
    read = np.maximum(np.sqrt(target2), 2.0 * w)

    lo, span, magnitude = _bounds(comm, kept_xy)
    margin = 1e-12 * magnitude

    # The kept centres within read(p) of each eligible p (one exchange).
    held_kept = _points_within(comm, (lo, span, magnitude), at_xy, read * (1 + _SLACK) + margin, kept_xy)
    _, nn2 = _core.repair_kept_distances(held_kept, at_xy)
    kept2, _ = _core.repair_kept_distances(held_kept, cand_xy)
    nn2, kept2 = np.asarray(nn2), np.asarray(kept2)
    needy = np.flatnonzero(nn2 > target2)  # (in global-id order, as eligible)

    # Copies of other ranks' needy points that can conflict with ours.
    mine = np.zeros(len(needy), dtype=_NEEDY)
    mine["gid"], mine["x"], mine["y"], mine["w"] = gid[needy], at_xy[needy, 0], at_xy[needy, 1], w[needy]
    send_index, send_dest = _halo.copies_within_reach(comm, lo, span, magnitude, at_xy[needy],
                                                      read[needy] * (1 + _SLACK) + margin, at_xy[needy],
                                                      w[needy] * (1 + _SLACK) + margin)
    copies, _ = _exchange(comm, send_dest, mine[send_index])
    m = len(needy)

    sub_xadj, sub_count = xadj[needy], count[needy]

    def decide(now: np.ndarray, known: np.ndarray) -> np.ndarray:
        n_count = sub_count[now]
        take = _ranges(sub_xadj[now], n_count)
        return np.asarray(_core.repair_decisions(
            at_xy[needy[now]], target2[needy[now]], nn2[needy[now]],
            np.concatenate([[0], np.cumsum(n_count)]).astype(np.int64), np.ascontiguousarray(cand_xy[take]),
            np.ascontiguousarray(kept2[take]), known), dtype=np.int64)

    choice, rounds = _in_rounds(comm, mine, copies, read[needy], margin, send_index, send_dest, decide,
                                lambda i, pick: cand_xy[sub_xadj[i] + pick], np.zeros((0, 2)))
    done = np.flatnonzero(choice >= 0)
    kind = cand_kind[sub_xadj[done] + choice[done]]
    on_segment = kind >= 0
    inside = done[~on_segment]
    out = dict(segment_positions=np.sort(kind[on_segment]),
               points=cand_xy[sub_xadj[inside] + choice[inside]],
               gids=gid[needy[inside]],
               added=cand_xy[sub_xadj[done] + choice[done]])
    if stats is not None:
        stats.update(rounds=rounds, needy=comm.allreduce(m, op=MPI.SUM),
                     repaired=comm.allreduce(len(done), op=MPI.SUM),
                     on_segments=comm.allreduce(int(np.count_nonzero(on_segment)), op=MPI.SUM),
                     copies=comm.allreduce(len(copies), op=MPI.SUM))
    return out


def _in_rounds(comm: Any, mine: np.ndarray, copies: np.ndarray, read: np.ndarray, margin: float,
               send_index: np.ndarray, send_dest: np.ndarray, decide: Any, chosen: Any,
               known: np.ndarray) -> tuple[np.ndarray, int]:
    """The rounds (module docstring) over our requests `mine` (_NEEDY records in
    id order) with copies of the other ranks' that can conflict with them:
    decide(now, known) decides our requests `now` (in order) given the points
    added before (`known`); chosen(i, pick) is where request i's pick lies.
    Our decisions go to the ranks holding copies (send_index, send_dest).
    Returns (our picks, -1 for none; the number of rounds). Collective."""
    MPI = _mpi()
    m = len(mine)
    held = np.concatenate([mine, copies])
    copy_order = np.argsort(copies["gid"], kind="stable")
    # The earlier requests each of ours waits for: (ours, held) pairs.
    wait_i, wait_j = _conflicts(held, m, read, margin)
    decided = np.zeros(len(held), dtype=bool)
    choice = np.full(m, -1, dtype=np.int64)
    added = [np.asarray(known, dtype=np.float64).reshape(-1, 2)]
    told = np.zeros(m, dtype=bool)
    told[send_index] = True
    rounds = 0
    while True:
        undecided = ~decided[:m]
        # Ready: every earlier conflict decided, or (the sweep) ours and ready before it.
        waits_on_other = np.bincount(wait_i[~decided[wait_j] & (wait_j >= m)], minlength=m) > 0
        local = ~decided[wait_j] & (wait_j < m)
        now = np.flatnonzero(_sweep_ready(undecided & ~waits_on_other, wait_i[local], wait_j[local], m))
        if len(now):
            picks = decide(now, np.ascontiguousarray(np.concatenate(added)))
            choice[now] = picks
            decided[now] = True
            added.append(chosen(now[picks >= 0], picks[picks >= 0]).reshape(-1, 2))
        send = np.isin(send_index, now[told[now]])
        at = send_index[send]
        update = np.zeros(len(at), dtype=_DECISION)
        update["gid"] = mine["gid"][at]
        picked = choice[at]
        update["added"] = picked >= 0
        xy = chosen(at[picked >= 0], picked[picked >= 0]).reshape(-1, 2)
        update["x"][picked >= 0], update["y"][picked >= 0] = xy[:, 0], xy[:, 1]
        received, _ = _exchange(comm, send_dest[send], update)
        if len(received):
            where = copy_order[np.searchsorted(copies["gid"][copy_order], received["gid"])]
            decided[m + where] = True
            if _SHARE_ADDED:
                added.append(_xy(received[received["added"] != 0]))
        rounds += 1
        if comm.allreduce(int(np.count_nonzero(~decided[:m])), op=MPI.SUM) == 0:
            return choice, rounds


def _conflicts(held: np.ndarray, m: int, read: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """(i, j): our needy point i (of the first m held) and an earlier held needy
    point j (smaller global id) whose added point it may read: |p_i - p_j| <=
    (read_i + w_j) (1 + slack) + margin."""
    if not m or not len(held):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    from scipy.spatial import cKDTree

    xy = _xy(held)
    reach = (float(read.max()) + float(held["w"].max())) * (1 + 2 * _SLACK) + 2 * margin
    pairs = cKDTree(xy[:m]).sparse_distance_matrix(cKDTree(xy), reach, output_type="ndarray")
    i, j = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
    keep = (held["gid"][j] < held["gid"][i]) & \
        (np.hypot(*(xy[i] - xy[j]).T) <= (read[i] + held["w"][j]) * (1 + _SLACK) + margin)
    i, j = i[keep], j[keep]
    order = np.lexsort((j, i))
    return i[order], j[order]


def _sweep_ready(free: np.ndarray, wait_i: np.ndarray, wait_j: np.ndarray, m: int) -> np.ndarray:
    """Which of our m undecided needy points (in id order) a sweep decides: a
    point is ready when no other rank's undecided point blocks it (`free`) and
    each of our undecided earlier points it waits for (pairs wait_i > wait_j,
    in id order) is ready. In passes over the pairs: a point's readiness only
    depends on earlier ones, so the passes settle in at most the longest chain;
    each pass is vectorised."""
    ready = free.copy()
    if not len(wait_i):
        return ready
    while True:
        blocked = np.zeros(m, dtype=bool)
        blocked[wait_i[~ready[wait_j]]] = True
        nxt = free & ~blocked
        if np.array_equal(nxt, ready):
            return ready
        ready = nxt


def _bounds(comm: Any, xy: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(lower corner, span, magnitude) of every rank's points `xy`, for the halos' chunks and margins."""
    MPI = _mpi()
    big = np.finfo(np.float64).max
    lo = np.array([comm.allreduce(float(xy[:, 0].min()) if len(xy) else big, op=MPI.MIN),
                   comm.allreduce(float(xy[:, 1].min()) if len(xy) else big, op=MPI.MIN)])
    hi = np.array([comm.allreduce(float(xy[:, 0].max()) if len(xy) else -big, op=MPI.MAX),
                   comm.allreduce(float(xy[:, 1].max()) if len(xy) else -big, op=MPI.MAX)])
    span = float(max(hi - lo)) if (hi >= lo).all() else 0.0
    magnitude = float(max(np.abs(lo).max(), np.abs(hi).max())) if (hi >= lo).all() else 0.0
    return lo, span, magnitude


def _points_within(comm: Any, box: tuple[np.ndarray, float, float], query_xy: np.ndarray, reach: np.ndarray,
                   xy: np.ndarray) -> np.ndarray:
    """Our points `xy` and every other rank's within `reach` of one of our
    queries (the senders decide: _halo.copies_within_reach). Collective."""
    index, dest = _halo.copies_within_reach(comm, *box, query_xy, reach, xy, np.zeros(len(xy)))
    records = np.zeros(len(index), dtype=_XY)
    records["x"], records["y"] = xy[index, 0], xy[index, 1]
    got, _ = _exchange(comm, dest, records)
    return np.ascontiguousarray(np.concatenate([np.asarray(xy, dtype=np.float64).reshape(-1, 2), _xy(got)]))


_DIRECTIONS = 16  # (kGapDirections, spacing_repair.hpp)


def gap_repair(comm: Any, dmesh: Any, part: dict, options: Any, own: np.ndarray, owned_gids: np.ndarray,
               owned_xy: np.ndarray, owned_delta: np.ndarray, owned_nn: np.ndarray, owned_demoted: np.ndarray,
               kept_xy: np.ndarray, repaired_xy: np.ndarray, stats: dict[str, Any] | None = None
               ) -> dict[str, np.ndarray]:
    """The spacing repair's gap repair (gap_repair_ratio, refine_gap_ratio;
    spacing_repair.hpp: repair_gaps) on the ranks of `comm`, after
    :func:`spacing_repair`: the serial step's decisions, each made by the
    owner of its input point. Collective.

    The same rounds as the spacing repair's (module docstring), with these
    radii. An input point p is *open* when its second nearest kept centre lies
    beyond its bound t(p) (gap_target2; points added later only bring output
    points nearer, so no other point can need a gap point); p's decision reads
    its two nearest output points and, at each of its 16 directions x (at
    distance h = delta nn_M from p), the two nearest output points of x. The
    latter lie within h + K2(p) of x (K2(p): p's second nearest kept centre,
    at least as far as its second nearest output point), so an added point
    matters only within read(p) = 2 h + K2(p) of p (the re-check reads within
    t(p) < K2(p)); the point p adds lies at h from p. The kept centres within
    read(p) come by halos whose reach grows until it covers 2 h + K2(p) (K2
    from a halo is exact once within its reach). Whether a direction lies inside
    the old mesh seen from p is a walk along p -> x (Mesh_walk::locate_from),
    fixed before the repair: a walk that reaches the part's border is redone
    on the part plus every old triangle within h of p (fetched from their
    owners; a triangle the walk crosses meets the segment p -> x).

    Parameters
    ----------
    dmesh : DistributedMesh (the old mesh, for its triangles)
    owned_demoted : (n_owned,) uint8, the demoted flags (zeros without demotion).
    kept_xy : (k, 2) float, this rank's kept centres (before any projection).
    repaired_xy : (r, 2) float, the points this rank's spacing repair added
        (segment candidates made kept and interior points).
    Others as :func:`spacing_repair`.

    Returns
    -------
    dict: "points" (k, 2) and "gids" (k,): the points added, each with its
    input point's global id, in id order.
    """
    MPI = _mpi()
    gap_ratio, refine_ratio = float(options.gap_repair_ratio), float(options.refine_gap_ratio)
    out = dict(points=np.zeros((0, 2)), gids=np.zeros(0, np.int64))
    # (the serial repair does nothing with fewer than two kept centres)
    if not (gap_ratio > 0 or refine_ratio > 0) or comm.allreduce(len(kept_xy), op=MPI.SUM) < 2:
        if stats is not None:
            stats.update(gap_rounds=0, gap_open=0, gap_added=0, gap_copies=0, gap_walks_redone=0)
        return out
    box = _bounds(comm, np.concatenate([kept_xy, owned_xy]))
    margin = 1e-12 * box[2]
    h = owned_delta * owned_nn
    # Open points: the kept centres within the larger bound decide it exactly.
    first = np.maximum(gap_ratio, refine_ratio) * h
    held = _points_within(comm, box, owned_xy, first * (1 + _SLACK) + margin, kept_xy)
    k1, k2 = (np.asarray(a) for a in _core.repair_kept_distances(held, owned_xy))
    target2 = np.asarray(_core.gap_targets(owned_delta, owned_nn, owned_demoted, (k1 == 0).astype(np.uint8),
                                           gap_ratio, refine_ratio))
    open_ = np.flatnonzero(k2 > target2)  # (in id order)
    at_xy, h_open = owned_xy[open_], h[open_]
    # Kept centres within 2 h + K2 of each open point: K2 from a halo is an
    # upper bound, exact once the halo's reach covers it.
    reach = np.where(np.isfinite(k2[open_]), 2 * h_open + np.sqrt(k2[open_]), 4 * first[open_])
    while True:
        held = _points_within(comm, box, at_xy, reach * (1 + _SLACK) + margin, kept_xy)
        _, k2_open = _core.repair_kept_distances(held, at_xy)
        k2_open = np.asarray(k2_open)
        covered = np.isfinite(k2_open) & (2 * h_open + np.sqrt(k2_open) <= reach)
        if comm.allreduce(bool(covered.all()), op=MPI.LAND):
            break
        reach = np.where(covered, reach, np.where(np.isfinite(k2_open), 2 * h_open + np.sqrt(k2_open), 2 * reach))
    read = 2 * h_open + np.sqrt(k2_open)

    # The directions and their walks, then the kept centres' two nearest at each.
    directions, inside, left = _walks(comm, dmesh, part, own[open_], at_xy, owned_gids[open_], owned_delta[open_],
                                      owned_nn[open_], options.seed, box, margin)
    queries = np.concatenate([at_xy[:, None, :], directions.reshape(-1, _DIRECTIONS, 2)], axis=1).reshape(-1, 2)
    q1, q2 = _core.repair_kept_distances(held, np.ascontiguousarray(queries))
    kept2 = np.ascontiguousarray(np.column_stack([q1, q2]).reshape(-1))
    # The spacing repair's points within reach of our open points.
    known = _points_within(comm, box, at_xy, read * (1 + _SLACK) + margin,
                           np.asarray(repaired_xy, dtype=np.float64).reshape(-1, 2))

    mine = np.zeros(len(open_), dtype=_NEEDY)
    mine["gid"], mine["x"], mine["y"], mine["w"] = owned_gids[open_], at_xy[:, 0], at_xy[:, 1], h_open
    send_index, send_dest = _halo.copies_within_reach(comm, *box, at_xy, read * (1 + _SLACK) + margin, at_xy,
                                                      h_open * (1 + _SLACK) + margin)
    copies, _ = _exchange(comm, send_dest, mine[send_index])
    dirs = directions.reshape(-1, _DIRECTIONS, 2)

    def decide(now: np.ndarray, added: np.ndarray) -> np.ndarray:
        rows = (now[:, None] * (_DIRECTIONS + 1) + np.arange(_DIRECTIONS + 1)[None, :]).reshape(-1)
        return np.asarray(_core.gap_decisions(
            at_xy[now], owned_delta[open_][now], owned_nn[open_][now], owned_demoted[open_][now],
            np.ascontiguousarray(dirs[now].reshape(-1, 2)),
            np.ascontiguousarray(inside.reshape(-1, _DIRECTIONS)[now].reshape(-1)),
            np.ascontiguousarray(kept2.reshape(-1, 2)[rows].reshape(-1)), gap_ratio, refine_ratio, added),
            dtype=np.int64)

    choice, rounds = _in_rounds(comm, mine, copies, read, margin, send_index, send_dest, decide,
                                lambda i, pick: dirs[i, pick], known)
    done = np.flatnonzero(choice >= 0)
    out = dict(points=dirs[done, choice[done]].reshape(-1, 2), gids=owned_gids[open_][done])
    if stats is not None:
        stats.update(gap_rounds=rounds, gap_open=comm.allreduce(len(open_), op=MPI.SUM),
                     gap_added=comm.allreduce(len(done), op=MPI.SUM),
                     gap_copies=comm.allreduce(len(copies), op=MPI.SUM),
                     gap_walks_redone=comm.allreduce(int(np.count_nonzero(left)), op=MPI.SUM))
    return out


def _walks(comm: Any, dmesh: Any, part: dict, points: np.ndarray, at_xy: np.ndarray, gids: np.ndarray,
           delta: np.ndarray, nn: np.ndarray, seed: int, box: tuple[np.ndarray, float, float], margin: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The gap directions of the part's `points` and whether each lies inside
    the old mesh seen from its point: (directions (m 16, 2), inside (m 16),
    left), exact: a point whose walk reached the part's border is walked again
    on the part plus every old triangle within h of it. Collective."""
    MPI = _mpi()
    directions, inside, left = _core.part_gap_candidates(part, points, delta, nn, seed)
    directions, inside, left = np.asarray(directions), np.array(inside), np.asarray(left, dtype=bool)
    if not comm.allreduce(bool(left.any()), op=MPI.LOR):
        return directions, inside, left
    again = np.flatnonzero(left)
    # Every rank's owned triangles within h of a point walked again (a triangle
    # within h of p has its centroid within h + its centroid-vertex distance).
    n_owned_tri = len(dmesh.triangles)
    tri = np.asarray(dmesh.triangles, dtype=np.int64).reshape(-1, 3)
    corners = np.asarray(dmesh.points)[tri]
    centroid = corners.mean(axis=1) if n_owned_tri else np.zeros((0, 2))
    extent = np.sqrt(((corners - centroid[:, None, :]) ** 2).sum(axis=2)).max(axis=1) if n_owned_tri else \
        np.zeros(0)
    index, dest = _halo.copies_within_reach(comm, *box, at_xy[again],
                                            (delta[again] * nn[again]) * (1 + _SLACK) + margin, centroid,
                                            extent * (1 + _SLACK) + margin)
    record = np.dtype([("tgid", "<i8"), ("v", "<i8", (3,)), ("xy", "<f8", (3, 2))])
    rows = np.zeros(len(index), dtype=record)
    rows["tgid"] = np.asarray(dmesh.triangle_global_ids)[index]
    rows["v"] = np.asarray(dmesh.global_ids)[tri[index]]
    rows["xy"] = corners[index]
    got, _ = _exchange(comm, dest, rows)
    new = got[~np.isin(got["tgid"], part["triangle_gids"])]
    new = new[np.unique(new["tgid"], return_index=True)[1]]
    # The part plus those triangles (points in global-id order, as a part's).
    old_gids = part["point_gids"]
    gids_all = np.union1d(old_gids, new["v"].reshape(-1))
    xy = np.empty((len(gids_all), 2))
    at_old = np.searchsorted(gids_all, old_gids)
    xy[at_old] = part["points"]
    at_new = np.searchsorted(gids_all, new["v"].reshape(-1))
    xy[at_new] = new["xy"].reshape(-1, 2)
    extended = dict(part)
    kind = np.full(len(gids_all), dict(_core.POINT_KINDS)["ORIGINAL"], dtype=np.uint8)
    kind[at_old] = part["kind"]
    required = np.zeros(len(gids_all), np.uint8)
    required[at_old] = part["required"]
    extended.update(points=xy, kind=kind, required=required, point_gids=gids_all,
                    triangles=np.concatenate([at_old[np.asarray(part["triangles"])], at_new.reshape(-1, 3)]),
                    triangle_gids=np.concatenate([part["triangle_gids"], new["tgid"]]),
                    segments=at_old[np.asarray(part["segments"])])

    def walk_again() -> tuple[np.ndarray, np.ndarray]:
        d2, in2, left2 = _core.part_gap_candidates(extended, at_old[points[again]], delta[again], nn[again], seed)
        if np.asarray(left2).any():
            raise RuntimeError("gap repair: a walk left the old triangles within its reach (an internal error)")
        return np.asarray(d2), np.asarray(in2)

    d2, in2 = _collective(comm, walk_again)
    per = _DIRECTIONS
    rows_again = (again[:, None] * per + np.arange(per)[None, :]).reshape(-1)
    directions[rows_again] = d2
    inside[rows_again] = in2
    return directions, inside, left
