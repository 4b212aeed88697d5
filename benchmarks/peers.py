"""Peer remeshers and the metrics shared by benchmarks/compare_peers.py.

Three ways to adapt one input mesh to one size map h (given at the input
vertices, linear in between):

* :func:`run_evomesh`: ``evomesh.evolve(mesh, delta, seed=0)`` with
  ``delta = h / mesh.nn_spacing``;
* :func:`run_mmg2d`: the ``mmg2d_O3`` binary (MMG 5.7.0, from the pymmg 1.0.0
  wheel; ``tools/get-peers.sh`` puts it in ``build/peers/``) on a Medit ``.mesh``
  of the input with boundary Edges, Corners and RequiredVertices, and h as an
  isotropic metric in a ``.sol`` file (MMG's unit edge length is h);
* :func:`run_gmsh`: Gmsh's Python API (``pip install gmsh``) meshing the domain
  rebuilt as a geometry (4 points, 4 lines, a plane surface) with a PostView
  background field that interpolates h on the input triangles.

Neither peer is a dependency of evomesh: each runner raises :class:`PeerUnavailable`
when its peer is missing. :func:`metrics` measures any output (points, triangles)
with the same code.
"""

from __future__ import annotations

import os
import resource
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

import evomesh
from evomesh.mesh_quality import integral_inverse_square

REPO = Path(__file__).resolve().parent.parent
MMG2D_BINARY = Path(os.environ.get("EVOMESH_MMG2D", REPO / "build" / "peers" / "mmg2d_O3"))
CORNER_KIND = 0  # evomesh.PointKind.CORNER


class PeerUnavailable(RuntimeError):
    """The peer is not installed, or it failed on this input."""


# ---------------------------------------------------------------- Medit files


def write_medit(path: Path | str, points: np.ndarray, triangles: np.ndarray, edges: np.ndarray | None = None,
                corners: np.ndarray | None = None, required: np.ndarray | None = None,
                edge_refs: np.ndarray | None = None) -> None:
    """A 2-D Medit ``.mesh`` (ASCII, 1-based indices, references 0 except edge_refs)."""
    with open(path, "w") as f:
        f.write("MeshVersionFormatted 2\n\nDimension 2\n\n")
        f.write(f"Vertices\n{len(points)}\n")
        np.savetxt(f, np.column_stack([points, np.zeros(len(points))]), fmt="%.17g %.17g %d")
        f.write(f"\nTriangles\n{len(triangles)}\n")
        np.savetxt(f, np.column_stack([triangles + 1, np.zeros(len(triangles), dtype=np.int64)]), fmt="%d")
        if edges is not None and len(edges):
            refs = np.ones(len(edges), dtype=np.int64) if edge_refs is None else edge_refs
            f.write(f"\nEdges\n{len(edges)}\n")
            np.savetxt(f, np.column_stack([edges + 1, refs]), fmt="%d")
        if corners is not None and len(corners):
            f.write(f"\nCorners\n{len(corners)}\n")
            np.savetxt(f, np.asarray(corners) + 1, fmt="%d")
        if required is not None and len(required):
            f.write(f"\nRequiredVertices\n{len(required)}\n")
            np.savetxt(f, np.asarray(required) + 1, fmt="%d")
        f.write("\nEnd\n")


def write_sol(path: Path | str, values: np.ndarray) -> None:
    """A Medit ``.sol`` with one scalar (an isotropic size) at each vertex."""
    with open(path, "w") as f:
        f.write(f"MeshVersionFormatted 2\n\nDimension 2\n\nSolAtVertices\n{len(values)}\n1 1\n")
        np.savetxt(f, values, fmt="%.17g")
        f.write("\nEnd\n")


def read_medit(path: Path | str) -> dict[str, np.ndarray]:
    """Vertices (x, y), Triangles and Edges (0-based, references dropped) of a 2-D Medit ``.mesh``."""
    tokens = Path(path).read_text().split()
    out: dict[str, np.ndarray] = {}
    widths = {"Vertices": 3, "Triangles": 4, "Edges": 3, "Corners": 1, "RequiredVertices": 1, "RequiredEdges": 1,
              "Ridges": 1, "Normals": 2, "NormalAtVertices": 2, "Tangents": 2, "TangentAtVertices": 2,
              "Quadrilaterals": 5}
    i = 0
    while i < len(tokens):
        key = tokens[i]
        if key in ("MeshVersionFormatted", "Dimension"):
            i += 2
        elif key in widths:
            n = int(tokens[i + 1])
            w = widths[key]
            block = np.array(tokens[i + 2:i + 2 + n * w], dtype=np.float64).reshape(n, w)
            i += 2 + n * w
            if key == "Vertices":
                out["points"] = block[:, :2]
            elif key == "Triangles":
                out["triangles"] = block[:, :3].astype(np.int64) - 1
            elif key == "Edges":
                out["edges"] = block[:, :2].astype(np.int64) - 1
        elif key == "End":
            break
        else:
            raise ValueError(f"{path}: unknown Medit keyword {key!r}")
    return out


# ---------------------------------------------------------------- the three remeshers


def _timed_children(fn):
    """Wall and CPU seconds (this process and its children) of fn()."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0, c0 = time.perf_counter(), time.process_time()
    value = fn()
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = time.process_time() - c0 + (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return value, wall, cpu


def run_evomesh(mesh: evomesh.Mesh, h: np.ndarray, **options: Any) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    delta = h / mesh.nn_spacing
    out, wall, cpu = _timed_children(lambda: evomesh.evolve(mesh, delta, seed=0, **options))
    info = {"wall_seconds": wall, "cpu_seconds": cpu, "version": evomesh.__version__,
            "call": "evomesh.evolve(mesh, h / mesh.nn_spacing, seed=0" + "".join(f", {k}={v!r}" for k, v in options.items())
            + ")"}
    return out.points, out.triangles, info


def _corner_indices(mesh: evomesh.Mesh) -> np.ndarray:
    return np.flatnonzero(np.asarray(mesh.kind) == CORNER_KIND)


def mmg2d_flags(hgrad: float | None) -> list[str]:
    return ["-v", "1"] + ([] if hgrad is None else ["-hgrad", f"{hgrad:g}"])


def run_mmg2d(mesh: evomesh.Mesh, h: np.ndarray, hgrad: float | None = -1.0, binary: Path | str | None = None,
              keep: Path | str | None = None) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """MMG2D on the input mesh with the isotropic metric h (edge length h).

    Timed: the mmg2d_O3 process (its reading and writing of the files included;
    writing the input and reading the output in Python are not). hgrad=None
    keeps MMG's default gradation 1.3; -1 turns gradation off.
    """
    binary = Path(binary or MMG2D_BINARY)
    if not (binary.is_file() and os.access(binary, os.X_OK)):
        raise PeerUnavailable(f"no MMG2D binary at {binary} (run tools/get-peers.sh)")
    work = Path(keep) if keep else Path(tempfile.mkdtemp(prefix="evomesh-mmg2d-"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        boundary = mesh.segments[np.asarray(mesh.segment_is_boundary, dtype=bool)]
        corners = _corner_indices(mesh)
        write_medit(work / "in.mesh", mesh.points, mesh.triangles, edges=boundary, corners=corners, required=corners)
        write_sol(work / "in.sol", h)
        cmd = [str(binary), *mmg2d_flags(hgrad), "-in", "in.mesh", "-sol", "in.sol", "-out", "out.mesh"]
        proc, wall, cpu = _timed_children(
            lambda: subprocess.run(cmd, cwd=work, capture_output=True, text=True, env={**os.environ, "OMP_NUM_THREADS": "1"}))
        log = proc.stdout + proc.stderr
        if proc.returncode != 0 or not (work / "out.mesh").exists():
            tail = " | ".join(line.strip() for line in log.strip().splitlines()[-4:])
            raise PeerUnavailable(f"mmg2d_O3 exited {proc.returncode}: {tail}")
        out = read_medit(work / "out.mesh")
        version = next((line.split("Release")[1].split("(")[0].strip() for line in log.splitlines() if "Release" in line),
                       "?")
        info = {"wall_seconds": wall, "cpu_seconds": cpu, "version": f"MMG2D {version}",
                "call": "mmg2d_O3 " + " ".join(cmd[1:]), "log_tail": log.strip().splitlines()[-12:]}
        return out["points"], out["triangles"], info
    finally:
        if not keep:
            shutil.rmtree(work, ignore_errors=True)


GMSH_ALGORITHMS = {1: "MeshAdapt", 2: "Automatic", 5: "Delaunay", 6: "Frontal-Delaunay", 8: "Frontal-Delaunay for quads"}


def run_gmsh(mesh: evomesh.Mesh, h: np.ndarray, algorithm: int = 6) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Gmsh meshing the input's bounding rectangle with h as a PostView background field.

    Timed: from building the geometry and the view to the extracted arrays
    (gmsh.initialize and finalize excluded), single-threaded.
    """
    try:
        import gmsh
    except ImportError as e:
        raise PeerUnavailable(f"gmsh not importable ({e}); run tools/get-peers.sh") from e
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    gmsh.initialize(["gmsh", "-nopopup"], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.Verbosity", 2)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.MaxNumThreads1D", 1)
        gmsh.option.setNumber("Mesh.MaxNumThreads2D", 1)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.Algorithm", algorithm)

        def remesh():
            gmsh.model.add("domain")
            geo = gmsh.model.geo
            corners = [(lo[0], lo[1]), (hi[0], lo[1]), (hi[0], hi[1]), (lo[0], hi[1])]
            pts = [geo.addPoint(x, y, 0.0) for x, y in corners]
            lines = [geo.addLine(pts[i], pts[(i + 1) % 4]) for i in range(4)]
            geo.addPlaneSurface([geo.addCurveLoop(lines)])
            geo.synchronize()
            view = gmsh.view.add("h")
            tri = mesh.points[mesh.triangles]  # (m, 3, 2)
            data = np.concatenate([tri[:, :, 0], tri[:, :, 1], np.zeros((len(tri), 3)), h[mesh.triangles]], axis=1)
            gmsh.view.addListData(view, "ST", len(tri), data.ravel().tolist())
            field = gmsh.model.mesh.field.add("PostView")
            gmsh.model.mesh.field.setNumber(field, "ViewTag", view)
            gmsh.model.mesh.field.setAsBackgroundMesh(field)
            gmsh.model.mesh.generate(2)
            tags, coords, _ = gmsh.model.mesh.getNodes()
            _, elem_nodes = gmsh.model.mesh.getElementsByType(2)
            index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
            index[tags.astype(np.int64)] = np.arange(len(tags))
            return coords.reshape(-1, 3)[:, :2].copy(), index[np.asarray(elem_nodes, dtype=np.int64)].reshape(-1, 3)

        (points, triangles), wall, cpu = _timed_children(remesh)
        version = gmsh.__version__
    finally:
        gmsh.finalize()
    info = {"wall_seconds": wall, "cpu_seconds": cpu, "version": f"Gmsh {version}",
            "call": f"gmsh API: PostView background field, Mesh.Algorithm={algorithm} ({GMSH_ALGORITHMS.get(algorithm, '?')}), "
                    "MeshSizeFromPoints=0, MeshSizeFromCurvature=0, MeshSizeExtendFromBoundary=0, NumThreads=1"}
    return points, triangles, info


# ---------------------------------------------------------------- metrics


def triangle_areas(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    a, b, c = (points[triangles[:, i]] for i in range(3))
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def triangle_min_angles(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Smallest angle of each triangle, degrees."""
    p = points[triangles]
    angles = []
    for i in range(3):
        u = p[:, (i + 1) % 3] - p[:, i]
        v = p[:, (i + 2) % 3] - p[:, i]
        cross = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
        dot = (u * v).sum(axis=1)
        angles.append(np.degrees(np.arctan2(cross, dot)))
    return np.min(angles, axis=0)


def nearest_other(tree: cKDTree, queries: np.ndarray) -> np.ndarray:
    """Distance from each query to its nearest point of the tree other than itself
    (the second nearest when the query coincides with a tree point)."""
    d, _ = tree.query(queries, k=2)
    return np.where(d[:, 0] == 0.0, d[:, 1], d[:, 0])


def metrics(mesh: evomesh.Mesh, delta: np.ndarray, points: np.ndarray, triangles: np.ndarray,
            f=None) -> dict[str, Any]:
    """The same figures for any output (points, triangles) of the step (mesh, delta).

    h(p) = delta(p) nn_M(p) at the input points; f = evomesh.spacing(mesh, delta).
    """
    used = np.unique(triangles)
    if len(used) < len(points):  # drop vertices no triangle uses
        remap = np.full(len(points), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        points, triangles = points[used], remap[triangles]
    f = f if f is not None else evomesh.spacing(mesh, delta)
    h = delta * mesh.nn_spacing
    areas = triangle_areas(points, triangles)
    tree = cKDTree(points)
    input_ratio = nearest_other(tree, mesh.points) / h
    nn_out = nearest_other(tree, points)
    min_angles = triangle_min_angles(points, triangles)
    n = len(points)
    return {
        "points": n,
        "triangles": len(triangles),
        "n_over_integral": n / integral_inverse_square(points, triangles, f, levels=2),
        "input_ratio_p50": float(np.percentile(input_ratio, 50)),
        "input_ratio_p99": float(np.percentile(input_ratio, 99)),
        "input_ratio_max": float(input_ratio.max()),
        "output_ratio_median": float(np.median(nn_out / f(points))),
        "min_angle": float(min_angles.min()),
        "fraction_below_30": float((min_angles < 30.0).mean()),
        "area": float(np.abs(areas).sum()),
        "inverted": int((areas <= 0).sum()),
    }
