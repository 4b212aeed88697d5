"""The fixed set of steps whose outputs are pinned by hash (a refactor must
leave every hash unchanged).

Regenerate tests/data/pinned_hashes.json only for an intended change of the
algorithm, and say so in the commit:  .venv/bin/python tests/pinned.py --write
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

import evomesh
from strategies import grid_mesh

HASHES = Path(__file__).parent / "data" / "pinned_hashes.json"


def _crack_mesh() -> evomesh.Mesh:
    base = grid_mesh(11, 11, jitter=0.0)
    p = np.asarray(base.points)
    on_line = np.flatnonzero(np.isclose(p[:, 1], 0.5) & (p[:, 0] > 0.25) & (p[:, 0] < 0.75))
    on_line = on_line[np.argsort(p[on_line, 0])]
    return evomesh.Mesh(p, base.triangles, np.c_[on_line[:-1], on_line[1:]])


def meshes() -> dict[str, evomesh.Mesh]:
    return {
        "jittered": grid_mesh(12, 10, jitter=0.25, seed=1),
        "hole": grid_mesh(13, 13, jitter=0.2, seed=2, hole=True),
        "notch": grid_mesh(11, 11, jitter=0.15, seed=3, notch=True),
        "crack": _crack_mesh(),
    }


def deltas(mesh: evomesh.Mesh) -> dict[str, np.ndarray]:
    x = mesh.points[:, 0]
    return {
        "refine": np.full(mesh.n_points, 0.5),
        "graded": np.where(x < 0.5, 0.3, 3.0),
        "coarsen": np.full(mesh.n_points, 2.5),
    }


CASES: dict[str, dict] = {
    "frfc": {"method": "frfc"},
    "frfc-plain": {
        "method": "frfc", "radius_scale": 1.0, "boundary_scale": 1.0, "repair_ratio": None, "quality": False
    },
    "frfc-barycentre": {"method": "frfc", "samples": "barycentre", "cell_factor": 1.0},
    "drfc": {"method": "drfc"},
    "drfc-plain": {"method": "drfc", "quality": False},
}


def digest(mesh: evomesh.Mesh) -> str:
    h = hashlib.sha256()
    for name in ("points", "triangles", "segments", "segment_is_boundary", "kind", "origin"):
        h.update(np.ascontiguousarray(getattr(mesh, name)).tobytes())
    return h.hexdigest()[:16]


def compute() -> dict[str, str]:
    out = {}
    for mesh_name, mesh in meshes().items():
        for delta_name, delta in deltas(mesh).items():
            for case_name, options in CASES.items():
                new = evomesh.evolve(mesh, delta, seed=7, **options)
                out[f"{mesh_name}/{delta_name}/{case_name}"] = digest(new)
    return out


if __name__ == "__main__":
    if "--write" in sys.argv:
        HASHES.write_text(json.dumps(compute(), indent=1, sort_keys=True) + "\n")
        print(f"wrote {HASHES}")
