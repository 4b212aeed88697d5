"""FRFC's spacing repair (repair_ratio; spacing_repair.hpp) on a distributed
mesh (issue 29), in rounds over the ranks, exactly as the serial step.

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

The gap repair (gap_repair_ratio, refine_gap_ratio) is not here: its
candidates are located by walks through the old mesh over up to delta(p)
nn_M(p), which may leave the triangles a rank holds.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _core, _halo
from .distributed import _exchange, _mpi, _ranges

__all__ = ["spacing_repair"]

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
        Filled with "rounds", "needy", "repaired" (summed over ranks).

    Returns
    -------
    dict: "segment_positions" (the segment candidates this rank's needy points
    made kept), "points" (k, 2) and "gids" (k,) and "directions" (k,) of the
    interior ring candidates they added (the R-point's global id, the
    direction), each in the serial order.
    """
    MPI = _mpi()
    ratio = options.repair_ratio if options.ring_samples else 0.0
    out = dict(segment_positions=np.zeros(0, np.int64), points=np.zeros((0, 2)), gids=np.zeros(0, np.int64),
               directions=np.zeros(0, np.int64))
    if not ratio > 0:
        if stats is not None:
            stats.update(rounds=0, needy=0, repaired=0)
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

    # Bounds for the halos' Hilbert chunks and margins.
    big = np.finfo(np.float64).max
    lo = np.array([comm.allreduce(float(kept_xy[:, 0].min()) if len(kept_xy) else big, op=MPI.MIN),
                   comm.allreduce(float(kept_xy[:, 1].min()) if len(kept_xy) else big, op=MPI.MIN)])
    hi = np.array([comm.allreduce(float(kept_xy[:, 0].max()) if len(kept_xy) else -big, op=MPI.MAX),
                   comm.allreduce(float(kept_xy[:, 1].max()) if len(kept_xy) else -big, op=MPI.MAX)])
    span = float(max(hi - lo)) if (hi >= lo).all() else 0.0
    magnitude = float(max(np.abs(lo).max(), np.abs(hi).max())) if (hi >= lo).all() else 0.0
    margin = 1e-12 * magnitude

    # The kept centres within read(p) of each eligible p (one exchange).
    index, dest = _halo.copies_within_reach(comm, lo, span, magnitude, at_xy, read * (1 + _SLACK) + margin, kept_xy,
                                            np.zeros(len(kept_xy)))
    records = np.zeros(len(index), dtype=_XY)
    records["x"], records["y"] = kept_xy[index, 0], kept_xy[index, 1]
    got, _ = _exchange(comm, dest, records)
    held_kept = np.ascontiguousarray(np.concatenate([kept_xy, _xy(got)]))
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
    held = np.concatenate([mine, copies])
    m = len(needy)
    copy_order = np.argsort(copies["gid"], kind="stable")
    # The earlier needy points each of ours waits for: (ours, held) pairs.
    wait_i, wait_j = _conflicts(held, m, read[needy], margin)

    decided = np.zeros(len(held), dtype=bool)
    choice = np.full(m, -1, dtype=np.int64)
    known: list[np.ndarray] = [np.zeros((0, 2))]
    told = np.zeros(m, dtype=bool)
    told[send_index] = True
    sub_xadj = xadj[needy]
    sub_count = count[needy]
    rounds = 0
    while True:
        undecided = ~decided[:m]
        # Ready: every earlier conflict decided, or (the sweep) ours and ready before it.
        waits_on_other = np.bincount(wait_i[~decided[wait_j] & (wait_j >= m)], minlength=m) > 0
        local = ~decided[wait_j] & (wait_j < m)
        ready = _sweep_ready(undecided & ~waits_on_other, wait_i[local], wait_j[local], m)
        now = np.flatnonzero(ready)
        if len(now):
            n_count = sub_count[now]
            take = _ranges(sub_xadj[now], n_count)
            picks = np.asarray(_core.repair_decisions(
                at_xy[needy[now]], target2[needy[now]], nn2[needy[now]],
                np.concatenate([[0], np.cumsum(n_count)]).astype(np.int64), np.ascontiguousarray(cand_xy[take]),
                np.ascontiguousarray(kept2[take]), np.ascontiguousarray(np.concatenate(known))), dtype=np.int64)
            choice[now] = picks
            decided[now] = True
            has = picks >= 0
            new_xy = cand_xy[sub_xadj[now[has]] + picks[has]]
            known.append(new_xy)
            tell = now[told[now]]
        else:
            tell = now
        send = np.isin(send_index, tell)
        update = np.zeros(int(send.sum()), dtype=_DECISION)
        at = send_index[send]
        update["gid"] = mine["gid"][at]
        picked = choice[at]
        update["added"] = picked >= 0
        xy = cand_xy[sub_xadj[at[picked >= 0]] + picked[picked >= 0]]
        update["x"][picked >= 0], update["y"][picked >= 0] = xy[:, 0], xy[:, 1]
        received, _ = _exchange(comm, send_dest[send], update)
        if len(received):
            where = copy_order[np.searchsorted(copies["gid"][copy_order], received["gid"])]
            decided[m + where] = True
            if _SHARE_ADDED:
                known.append(_xy(received[received["added"] != 0]))
        rounds += 1
        if comm.allreduce(int(np.count_nonzero(~decided[:m])), op=MPI.SUM) == 0:
            break

    done = np.flatnonzero(choice >= 0)
    kind = cand_kind[sub_xadj[done] + choice[done]]
    on_segment = kind >= 0
    inside = done[~on_segment]
    out = dict(segment_positions=np.sort(kind[on_segment]),
               points=cand_xy[sub_xadj[inside] + choice[inside]],
               gids=gid[needy[inside]], directions=-1 - kind[~on_segment])
    if stats is not None:
        stats.update(rounds=rounds, needy=comm.allreduce(m, op=MPI.SUM),
                     repaired=comm.allreduce(len(done), op=MPI.SUM),
                     copies=comm.allreduce(len(copies), op=MPI.SUM))
    return out


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
