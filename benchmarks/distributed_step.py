"""One FRFC step on real MPI ranks (evolve on a DistributedMesh, the
paper's options with within_domain): MIS rounds of both packing passes, the
triangulation's widenings and label rounds, bytes exchanged per point, the
balance of the output, and seconds against the serial evolve of the same mesh
in the same run (on rank 0, one process); every run is checked array for array
against the serial result.

The mesh is a rectangle with two holes, graded (coarse on the left, fine on
the right: a refining front's leftovers), and delta comes from a moving
circle (0.5 near it, 1.5 elsewhere).

    for p in 2 4 8; do   # --options paper | distributed | recommended (the quality pass on rank 0)
      .venv/bin/mpiexec -n $p .venv/bin/python benchmarks/distributed_step.py --sizes 1e4,1e5
    done

Ranks above the core count are oversubscribed: seconds are then wall time of
ranks sharing cores; rounds and bytes are the algorithm's.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

import evomesh
from evomesh import DistributedMesh
from evomesh.distributed.step import evolve_distributed

sys.path.insert(0, str(Path(__file__).parent))
from distributed_spacing import domain  # noqa: E402 (the same plate with two holes)

_ARRAYS = ("points", "triangles", "segments", "segment_tags", "kind", "origin")


def front(xy: np.ndarray) -> np.ndarray:
    distance = np.abs(np.hypot(xy[:, 0] - 1.5, xy[:, 1] - 1.0) - 0.8)
    return np.where(distance < 0.15, 0.5, 1.5)


def _status(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])  # kB
    raise RuntimeError(field)


def _reset_peak() -> int:
    """Resets this process's peak resident memory (VmHWM) to now; returns the resident kB."""
    Path("/proc/self/clear_refs").write_text("5")
    return _status("VmRSS")


def _peak() -> int:
    return _status("VmHWM")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="1e4,1e5")
    parser.add_argument("--header", action="store_true")
    parser.add_argument("--options", choices=["paper", "distributed", "recommended"], default="paper",
                        help="paper: FrfcOptions.paper() with within_domain; distributed: the recommended options "
                             "less the spacing repair and the quality pass; recommended: all of them (the quality "
                             "pass on rank 0)")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    options = evomesh.FrfcOptions.paper()
    if args.options == "distributed":
        options = evomesh.FrfcOptions.recommended()
        options.quality = False
        options.repair_ratio = options.gap_repair_ratio = options.refine_gap_ratio = 0.0
    elif args.options == "recommended":
        options = evomesh.FrfcOptions.recommended()
    options.within_domain = True
    if args.header and comm.rank == 0:
        if options.quality:
            print("| input points | output points | ranks | MIS rounds (pass 1 / 2) | bytes / point (root stage) | "
                  "balance (max / mean owned) | root stage seconds | seconds (slowest rank) | serial seconds | "
                  "serial quality seconds | step peak memory, root / mean of others | min angle | equal |")
            print("|---:|---:|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---|")
        else:
            print("| input points | output points | ranks | MIS rounds (pass 1 / 2) | CDT widenings / label rounds | "
                  "bytes / point | balance (max / mean owned) | seconds (slowest rank) | serial seconds | equal |")
            print("|---:|---:|---:|---|---|---:|---:|---:|---:|---|")
    for size in args.sizes.split(","):
        mesh = domain(int(float(size))) if comm.rank == 0 else None
        serial, serial_seconds = None, 0.0
        if comm.rank == 0:
            t = time.perf_counter()
            serial = evomesh.evolve(mesh, front(mesh.points), options=options)
            serial_seconds = time.perf_counter() - t
        n_points = comm.bcast(mesh.n_points if mesh is not None else 0)
        dmesh = DistributedMesh.scatter(mesh, comm)
        comm.Barrier()
        before = _reset_peak()
        stats: dict = {}
        t = time.perf_counter()
        out = evolve_distributed(dmesh, front, options=options, stats=stats)
        seconds = comm.allreduce(time.perf_counter() - t, op=MPI.MAX)
        owned = np.array(comm.allgather(out.n_owned))
        gathered = out.gather()
        rss = np.array(comm.allgather(_peak() - before))  # (the step's peak above the resident memory before it)
        if comm.rank == 0 and options.quality:
            equal = all(np.array_equal(getattr(gathered, k), getattr(serial, k)) for k in _ARRAYS)
            others = rss[1:].mean() if comm.size > 1 else rss[0]
            print(f"| {n_points:,} | {gathered.n_points:,} | {comm.size} | {stats['first_pass_rounds']} / "
                  f"{stats['second_pass_rounds']} | {stats['bytes'] / n_points:.0f} "
                  f"({stats['root_bytes'] / n_points:.0f}) | {owned.max() / owned.mean():.3f} | "
                  f"{stats['root_seconds']:.2f} | {seconds:.2f} | {serial_seconds:.2f} | "
                  f"{serial.stats['seconds_quality']:.2f} | {rss[0] / others:.2f} | "
                  f"{stats['quality']['min_angle']:.2f} | {'yes' if equal else 'NO'} |", flush=True)
        elif comm.rank == 0:
            equal = all(np.array_equal(getattr(gathered, k), getattr(serial, k)) for k in _ARRAYS)
            cdt = stats["cdt"]
            print(f"| {n_points:,} | {gathered.n_points:,} | {comm.size} | {stats['first_pass_rounds']} / "
                  f"{stats['second_pass_rounds']} | {cdt['widenings']} / {cdt['label_rounds']} | "
                  f"{(stats['bytes'] + cdt['bytes']) / n_points:.0f} | {owned.max() / owned.mean():.3f} | "
                  f"{seconds:.2f} | {serial_seconds:.2f} | {'yes' if equal else 'NO'} |", flush=True)


if __name__ == "__main__":
    main()
