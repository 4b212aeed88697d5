"""The lineage of a distributed step: where every owned point of
``evolve(dmesh, ...)``'s output lies in the mesh the step started from, with
old triangles named by global id, and nn and f at the old points as the step
used them. :meth:`~evomesh.DistributedMesh.gather` turns it into the serial
:class:`~evomesh.Lineage` of the gathered mesh.

Where a new point is (:func:`step_lineage`): each rank locates its owned new
points that are not kept in the old triangles within reach of them (the
transfer's reach halo, distributed_transfer._HeldOld: every old triangle whose
bounding box comes within a few rounding units of the rank's chunks of those
points, whatever the partitions), one exchange and an O(n log n) point
location in the C++ core (``_core.part_parent_triangles``).

Which old triangle. A point strictly inside an old triangle has one parent;
the serial step's parent map finds it by a visibility walk, and its
barycentric coordinates come from the same C++ formula here
(``barycentric_coordinates`` of parent_map.cpp, unclamped), so they are equal
bit for bit. A point on an old edge or vertex (a candidate on an interior
constraint segment, which is an edge of two old triangles) lies in several;
the serial walk stops in whichever it reaches first from a neighbouring new
point, which depends on the walks of the whole new mesh. Here the rule is a
function of the point and the old mesh only, so the same on any number of
ranks: among the old triangles containing the point (exact orientation
tests), the one of least global id. A point outside every old triangle by
rounding (a boundary candidate just off its segment) gets the nearest of the
old triangles around the vertices of the one point location finds (ties:
least global id), with a coordinate negative by rounding, as the serial walk
gives; a point farther outside, -1 (the serial step's rare unlocated point).
Both rules give barycentric coordinates that sum to 1 and reproduce linear
functions (to rounding) whichever triangle is chosen.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import _core
from ..mesh import Lineage, _frozen
from . import _halo
from .mesh import _collective, _exchange, _index_of, _mpi

__all__ = ["DistributedLineage", "step_lineage"]

# The reach of the held old triangles around a rank's new points, in units of
# eps * (largest |coordinate|): the core's boundary_rounding (16 + kStraightUlps
# = 48 units) with room to spare, so every old triangle within the rounding
# tolerance of a point is held.
_REACH_ULPS = 128.0


class DistributedLineage:
    """How this rank's owned points of a distributed step's output lie in the
    mesh the step started from (``new.lineage`` for ``new = evomesh.evolve(dmesh,
    ...)``; None for a DistributedMesh made by ``scatter`` or ``from_local``).
    Read-only; :meth:`~evomesh.DistributedMesh.gather` gives the serial
    :class:`~evomesh.Lineage` of the gathered mesh.

    Attributes
    ----------
    n_old_points, n_old_triangles : int
        Global sizes of the old mesh.
    parent_triangle : ndarray of int64, shape (n_owned,)
        Per owned point of the new mesh (in its order): the global id of the
        old triangle containing it; -1 for a kept point (``origin >= 0``) and
        for a point no old triangle contains. A point on an old edge or vertex
        gets, of the old triangles containing it, the one of least global id
        (the serial step may name another one there; module docstring).
    barycentric : ndarray, shape (n_owned, 3)
        Its barycentric coordinates in that triangle, in the triangle's stored
        vertex order (its rotation in the old mesh); zeros where
        ``parent_triangle`` is -1. They sum to 1 and reproduce linear functions.
    old_global_ids : ndarray of int64, shape (old n_owned,)
        The old mesh's owned points on this rank when the step ran, in its order.
    old_nn, old_f : ndarray, shape (old n_owned,)
        nn_M and the spacing function f at those points, as the step used them.
    """

    __slots__ = ("n_old_points", "n_old_triangles", "parent_triangle", "barycentric", "old_global_ids", "old_nn",
                 "old_f", "_old_triangle_global_ids")

    n_old_points: int
    n_old_triangles: int
    parent_triangle: np.ndarray
    barycentric: np.ndarray
    old_global_ids: np.ndarray
    old_nn: np.ndarray
    old_f: np.ndarray
    _old_triangle_global_ids: np.ndarray  # the old mesh's owned triangles on this rank (gather numbers them)

    def __init__(self, n_old_points: int, n_old_triangles: int, parent_triangle: np.ndarray,
                 barycentric: np.ndarray, old_global_ids: np.ndarray, old_nn: np.ndarray, old_f: np.ndarray,
                 old_triangle_global_ids: np.ndarray) -> None:
        set_ = object.__setattr__
        set_(self, "n_old_points", int(n_old_points))
        set_(self, "n_old_triangles", int(n_old_triangles))
        set_(self, "parent_triangle", _frozen(np.ascontiguousarray(parent_triangle, dtype=np.int64)))
        set_(self, "barycentric", _frozen(np.ascontiguousarray(barycentric, dtype=np.float64).reshape(-1, 3)))
        set_(self, "old_global_ids", _frozen(np.ascontiguousarray(old_global_ids, dtype=np.int64)))
        set_(self, "old_nn", _frozen(np.ascontiguousarray(old_nn, dtype=np.float64)))
        set_(self, "old_f", _frozen(np.ascontiguousarray(old_f, dtype=np.float64)))
        set_(self, "_old_triangle_global_ids", _frozen(np.ascontiguousarray(old_triangle_global_ids,
                                                                            dtype=np.int64)))

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("DistributedLineage is immutable")

    def __repr__(self) -> str:
        located = int((self.parent_triangle >= 0).sum())
        return f"DistributedLineage(n_old_points={self.n_old_points}, owned={len(self.parent_triangle)}, " \
               f"located={located})"

    def matches(self, old: Any) -> bool:
        """Whether the DistributedMesh ``old`` has the global sizes of the mesh
        this lineage refers to. Collective."""
        MPI = _mpi()
        comm = old.comm
        sizes = comm.allreduce(np.array([old.n_owned, len(old.triangles)], dtype=np.int64), op=MPI.SUM)
        return int(sizes[0]) == self.n_old_points and int(sizes[1]) == self.n_old_triangles

    def _moved(self, renumbering: Any) -> DistributedLineage:
        """The lineage of the mesh ``rebalance`` made (its owned points are
        other ranks' before): the per-point rows moved along. Collective."""
        return DistributedLineage(self.n_old_points, self.n_old_triangles,
                                  renumbering.move_point_values(self.parent_triangle),
                                  renumbering.move_point_values(self.barycentric), self.old_global_ids,
                                  self.old_nn, self.old_f, self._old_triangle_global_ids)

    def _gather(self, comm: Any, owned_gids: np.ndarray, root: int) -> Lineage | None:
        """The serial Lineage of the gathered mesh on `root` (None elsewhere):
        rows in point global-id order, old triangles named by their position in
        the old mesh's triangle global-id order (the gathered old mesh's).
        Collective."""
        new = np.empty(len(owned_gids), [("gid", "<i8"), ("parent", "<i8"), ("barycentric", "<f8", (3,))])
        new["gid"], new["parent"], new["barycentric"] = owned_gids, self.parent_triangle, self.barycentric
        old = np.empty(len(self.old_global_ids), [("gid", "<i8"), ("nn", "<f8"), ("f", "<f8")])
        old["gid"], old["nn"], old["f"] = self.old_global_ids, self.old_nn, self.old_f
        new = _exchange(comm, np.full(len(new), root), new)[0]
        old = _exchange(comm, np.full(len(old), root), old)[0]
        triangles = _exchange(comm, np.full(len(self._old_triangle_global_ids), root),
                              self._old_triangle_global_ids)[0]
        if comm.rank != root:
            return None
        new = new[np.argsort(new["gid"], kind="stable")]
        old = old[np.argsort(old["gid"], kind="stable")]
        triangles = np.sort(triangles)
        parent = new["parent"].copy()
        located = parent >= 0
        parent[located] = _index_of(triangles, parent[located])
        return Lineage(self.n_old_points, self.n_old_triangles, parent, new["barycentric"], old["nn"], old["f"])


def step_lineage(old: Any, new: Any, spacing: Any, outside: float = 0.0) -> DistributedLineage:
    """The lineage of a distributed step's output `new` in the mesh `old` it
    started from (distributed_step.step calls it), with nn and f from its
    step 1 (`spacing`, a DistributedSpacing of `old`). Collective.

    Every owned new point not kept (``origin == -1``) is located among the old
    triangles within reach (module docstring); parents are named by global id.
    After a step on curves (`outside` > 0: the step's curve reach), a point
    outside the old polygon by more than rounding gets the nearest old triangle
    (ties: least global id) and a negative coordinate, as the serial walk's
    boundary triangle within that reach.
    """
    from .transfer import _bounds, _HeldOld, _nearest_triangles, _receiving_chunks, _table

    MPI = _mpi()
    comm = old.comm
    n_owned = new.n_owned
    located = np.flatnonzero(new.origin[:n_owned] < 0)
    queries = np.ascontiguousarray(new.points[located])
    low, span, magnitude = _bounds(comm, old.points, queries)
    perm, _ = _halo.hilbert_chunks(queries[:, 0], queries[:, 1], low, span)
    starts = _receiving_chunks(len(perm))
    box = _halo.chunk_boxes(queries[perm, 0], queries[perm, 1], starts)
    reach = max(_REACH_ULPS * float(np.finfo(np.float64).eps) * magnitude, outside)
    held = _HeldOld(old, _table(box, np.full(len(box), reach)), low, span, magnitude)

    def locate() -> tuple[np.ndarray, np.ndarray]:
        parent = np.full(n_owned, -1, dtype=np.int64)
        barycentric = np.zeros((n_owned, 3))
        if len(queries) and held.n_triangles:
            found, weights = _core.part_parent_triangles(held.points, held.triangles, held.gid, queries)
            missed = np.flatnonzero(found < 0)
            if outside > 0 and len(missed):  # (only the few points outside the old polygon)
                fallback, distance = _nearest_triangles(held.points, held.triangles, queries[missed])
                fallback[distance > outside] = -1
                found[missed], weights[missed] = _core.part_parent_triangles(
                    held.points, held.triangles, held.gid, queries[missed], fallback)
            hit = found >= 0
            parent[located[hit]] = held.gid[found[hit]]
            barycentric[located[hit]] = weights[hit]
        return parent, barycentric

    parent, barycentric = _collective(comm, locate)
    sizes = comm.allreduce(np.array([old.n_owned, len(old.triangles)], dtype=np.int64), op=MPI.SUM)
    return DistributedLineage(int(sizes[0]), int(sizes[1]), parent, barycentric, old.global_ids[: old.n_owned],
                              spacing.nn, spacing.f, old.triangle_global_ids)
