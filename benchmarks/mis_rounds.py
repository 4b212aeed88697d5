"""Rounds and messages of the lexical-first MIS over a partition
(cpp/src/mis_rounds.cpp, simulated in one process), against mesh size and part
count: does it stay bounded?

The sphere systems are those of a refining step's second packing pass, built
from the public API: the points of an evomesh mesh of the unit square (kept
old points, class 2) and 3 candidates drawn in each triangle where a front
refines (class 4), radius 0.75 f(x) / 2 with f the step's spacing function
(`evomesh.spacing`) for delta = 0.4 within 0.1 of the circle r = 0.3 and 1.5
elsewhere; ordered by `packing_order` (class, radius, index) as the step
orders them. The parts are contiguous ranges of the centres' Hilbert keys
(equal counts: how `DistributedMesh.scatter` cuts), or, adversarially,
vertical stripes (borders across the front, along the radius gradient).
Every run is checked against the serial MIS.

    .venv/bin/python benchmarks/mis_rounds.py --sizes 1e4,1e5,1e6 --parts 2,4,8,16
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import evomesh
from evomesh import _core
from evomesh.distributed.mesh import _hilbert_keys


def spheres(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Centres, radii, their packing order and classes."""
    mesh = evomesh.evolve(evomesh.unit_square_mesh(n), 1.0, seed=seed)
    p = mesh.points
    r = np.hypot(p[:, 0] - 0.5, p[:, 1] - 0.5)
    delta = np.where(np.abs(r - 0.3) < 0.1, 0.4, 1.5)
    f = evomesh.spacing(mesh, delta)
    tri = p[mesh.triangles]
    centroid_r = np.hypot(tri.mean(axis=1)[:, 0] - 0.5, tri.mean(axis=1)[:, 1] - 0.5)
    refining = tri[np.abs(centroid_r - 0.3) < 0.1]
    rng = np.random.default_rng(seed)
    k = 3
    a, b = rng.random((2, len(refining) * k))
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    base = np.repeat(refining, k, axis=0)
    candidates = base[:, 0] + a[:, None] * (base[:, 1] - base[:, 0]) + b[:, None] * (base[:, 2] - base[:, 0])
    centers = np.concatenate([p, candidates])
    radii = 0.75 * np.asarray(f(centers)) / 2
    classes = np.concatenate([np.full(len(p), 2), np.full(len(candidates), 4)]).astype(np.uint8)
    order = _core.packing_order(classes, radii)
    return centers, radii, order, classes


def hilbert_parts(centers: np.ndarray, n_parts: int) -> np.ndarray:
    lo, hi = centers.min(axis=0), centers.max(axis=0)
    cells = ((centers - lo) / (hi - lo).max() * (2**20 - 1)).astype(np.int64)
    keys = _hilbert_keys(cells[:, 0], cells[:, 1], 20)
    part = np.empty(len(centers), np.int64)
    part[np.argsort(keys, kind="stable")] = np.arange(len(centers)) * n_parts // len(centers)
    return part


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="1e4,1e5")
    parser.add_argument("--parts", default="2,4,8,16")
    args = parser.parse_args()
    print("| mesh points | spheres | parts | layout | rounds | messages | messages / sphere | halo pairs "
          "| undecided after round 1 | seconds |")
    print("|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|")
    for size in args.sizes.split(","):
        centers, radii, order, _ = spheres(int(float(size)))
        serial = _core.lexical_first_mis(centers, radii, order, 0)
        for n_parts in (int(x) for x in args.parts.split(",")):
            layouts = {"hilbert": hilbert_parts(centers, n_parts),
                       "stripes": np.minimum((centers[:, 0] * n_parts).astype(np.int64), n_parts - 1)}
            for name, part in layouts.items():
                t = time.perf_counter()
                out = _core.lexical_first_mis_in_rounds(centers, radii, order, 0, part, n_parts)
                seconds = time.perf_counter() - t
                assert np.array_equal(out["kept"], serial), "the rounds must give the serial MIS"
                m = int(out["messages"].sum())
                first = int(out["undecided"][0])
                print(f"| {int(float(size)):,} | {len(centers):,} | {n_parts} | {name} | {out['rounds']} | {m:,} "
                      f"| {m / len(centers):.4f} | {int(out['halo']):,} | {first:,} | {seconds:.2f} |", flush=True)


if __name__ == "__main__":
    main()
