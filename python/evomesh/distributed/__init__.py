"""Partitioned meshes on MPI ranks (``pip install evomesh[mpi]``).

* :mod:`evomesh.distributed.mesh` -- :class:`DistributedMesh` (scatter, from_local, gather, rebalance,
  halos) and :class:`Renumbering`;
* :mod:`evomesh.distributed.step` -- FRFC's step on a DistributedMesh (what ``evolve`` runs for one);
* its stages: :mod:`~evomesh.distributed.spacing` (nn, f and size), :mod:`~evomesh.distributed.packing`
  (the lexical-first MIS in rounds), :mod:`~evomesh.distributed.repair`,
  :mod:`~evomesh.distributed.triangulation`, :mod:`~evomesh.distributed.lineage`, and its thread limit,
  :mod:`~evomesh.distributed.threads`;
* :mod:`evomesh.distributed.transfer` -- ``transfer`` and ``transfer_cells`` between DistributedMeshes.

The design and its correctness arguments: docs/distributed-step.md. mpi4py is imported only when a
collective is called, so ``import evomesh`` works without it.
"""

from evomesh.distributed.mesh import DistributedMesh, Renumbering

__all__ = ["DistributedMesh", "Renumbering"]
