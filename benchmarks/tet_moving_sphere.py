"""The moving sphere in the unit cube: evomesh's tetrahedral step against MMG3D.

Size h(x) = min(0.1, hmin + 0.3 | |x - c| - 0.2 |): fine on a sphere of radius
0.2 whose centre c starts at (0.3, 0.5, 0.5) and moves 0.1 in x per step.
Each method first adapts a Kuhn 10^3 cube three times to c0, then steps from
its own output. Per step: points, tetrahedra, the old points kept (bit-identical
coordinates), radius-edge median / p99 / max, dihedral min / median / max and
% of dihedrals below 10 / above 170 degrees, CPU seconds, memory per output point
(evomesh: the step's peak resident memory above the resident memory before it;
MMG3D: its process's peak resident memory), the median edge length over h and f's
kd-tree evaluations per query.

MMG3D (mmg3d_O3 of the mmgpy 0.17.1 wheel, MMG 5.8.0) runs in the same script
when build/peers/mmg-venv holds it (python3 -m venv build/peers/mmg-venv &&
build/peers/mmg-venv/bin/pip install mmgpy==0.17.1; never a dependency of
evomesh). evomesh's size_factor is calibrated on the first moving step so that
its median edge / h is within 5 % of MMG's.

    .venv/bin/python benchmarks/tet_moving_sphere.py [--hmin 0.01] [--steps 4] [--no-mmg | --no-evomesh]
"""

from __future__ import annotations

import argparse
import glob
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

import evomesh
from evomesh.tet_mesh import dihedral_angles, radius_edge_ratios

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def status_bytes(field: str) -> int:
    """A memory figure of this process from /proc/self/status (VmRSS, VmHWM), in bytes."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    raise RuntimeError(f"{field} not in /proc/self/status")


def step_memory(run, *args, **kwargs):
    """run(*args, **kwargs) and the peak resident memory above the resident memory before it
    (the step's own memory: the peak is reset first through /proc/self/clear_refs)."""
    with open("/proc/self/clear_refs", "w") as refs:
        refs.write("5")
    before = status_bytes("VmRSS")
    out = run(*args, **kwargs)
    return out, status_bytes("VmHWM") - before


def size_function(centre: np.ndarray, hmin: float):
    def h(x: np.ndarray) -> np.ndarray:
        return np.minimum(0.1, hmin + 0.3 * np.abs(np.linalg.norm(x - centre, axis=1) - 0.2))
    return h


def edges_of(tets: np.ndarray) -> np.ndarray:
    e = tets[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]].reshape(-1, 2)
    return np.unique(np.sort(e, axis=1), axis=0)


def median_edge_over_h(points: np.ndarray, tets: np.ndarray, h) -> float:
    e = edges_of(tets)
    length = np.linalg.norm(points[e[:, 1]] - points[e[:, 0]], axis=1)
    return float(np.median(length / h(0.5 * (points[e[:, 0]] + points[e[:, 1]]))))


def kept_count(old: np.ndarray, new: np.ndarray) -> int:
    """New points whose coordinates equal an old point's bit for bit."""
    a = np.ascontiguousarray(old).view(np.dtype((np.void, 24))).ravel()
    b = np.ascontiguousarray(new).view(np.dtype((np.void, 24))).ravel()
    return int(np.isin(b, a).sum())


def quality_row(points: np.ndarray, tets: np.ndarray) -> dict:
    rho = radius_edge_ratios(points, tets)
    dihedral = dihedral_angles(points, tets)
    return {"rho_median": float(np.median(rho)), "rho_p99": float(np.percentile(rho, 99)), "rho_max": float(rho.max()),
            "dih_min": float(dihedral.min()), "dih_median": float(np.median(dihedral)), "dih_max": float(dihedral.max()),
            "below10": 100 * float((dihedral < 10).mean()), "above170": 100 * float((dihedral > 170).mean())}


# --- MMG3D ------------------------------------------------------------------


def mmg_binary() -> str | None:
    found = glob.glob(os.path.join(ROOT, "build/peers/mmg-venv/lib/python3*/site-packages/**/mmg3d_O3*"),
                      recursive=True)
    found += glob.glob(os.path.join(ROOT, "build/peers/mmg-venv/bin/mmg3d_O3*"))
    found = [f for f in found if os.access(f, os.X_OK) and not f.endswith(".py")]
    return found[0] if found else None


def write_medit(path: str, points: np.ndarray, tets: np.ndarray, faces: np.ndarray) -> None:
    with open(path, "w") as out:
        out.write("MeshVersionFormatted 2\nDimension 3\n")
        out.write(f"Vertices\n{len(points)}\n")
        np.savetxt(out, np.column_stack([points, np.zeros(len(points))]), fmt="%.17g %.17g %.17g %d")
        out.write(f"Tetrahedra\n{len(tets)}\n")
        np.savetxt(out, np.column_stack([tets + 1, np.ones(len(tets), int)]), fmt="%d")
        out.write(f"Triangles\n{len(faces)}\n")
        np.savetxt(out, np.column_stack([faces + 1, np.ones(len(faces), int)]), fmt="%d")
        out.write("End\n")


def write_sol(path: str, h: np.ndarray) -> None:
    with open(path, "w") as out:
        out.write(f"MeshVersionFormatted 2\nDimension 3\nSolAtVertices\n{len(h)}\n1 1\n")
        np.savetxt(out, h, fmt="%.17g")
        out.write("End\n")


def read_medit(path: str) -> tuple[np.ndarray, np.ndarray]:
    with open(path) as f:
        tokens = f.read().split()
    i = tokens.index("Vertices")
    n = int(tokens[i + 1])
    points = np.array(tokens[i + 2:i + 2 + 4 * n], dtype=float).reshape(n, 4)[:, :3]
    i = tokens.index("Tetrahedra")
    m = int(tokens[i + 1])
    tets = np.array(tokens[i + 2:i + 2 + 5 * m], dtype=np.int64).reshape(m, 5)[:, :4] - 1
    return points, tets


def mmg_step(binary: str, points: np.ndarray, tets: np.ndarray, h) -> tuple[np.ndarray, np.ndarray, float, int]:
    faces, _ = evomesh.tet_mesh.boundary_faces(tets)
    with tempfile.TemporaryDirectory() as tmp:
        write_medit(os.path.join(tmp, "m.mesh"), points, tets, faces)
        write_sol(os.path.join(tmp, "m.sol"), h(points))
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([binary, "-in", "m.mesh", "-sol", "m.sol", "-out", "o.mesh", "-v", "-1"], cwd=tmp, check=True,
                       stdout=subprocess.DEVNULL)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        peak = after.ru_maxrss * 1024  # the largest child so far (MMG3D runs grow step by step)
        new_points, new_tets = read_medit(os.path.join(tmp, "o.mesh"))
    sign = evomesh._core.tet_orientations(new_points, new_tets)
    new_tets = np.where((sign < 0)[:, None], new_tets[:, [0, 2, 1, 3]], new_tets)
    return new_points, new_tets, cpu, peak


# --- the run ------------------------------------------------------------------


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hmin", type=float, default=0.01)
    parser.add_argument("--steps", type=int, default=4)
    parser.add_argument("--no-mmg", action="store_true")
    parser.add_argument("--no-evomesh", action="store_true", help="MMG3D alone (its rows only)")
    parser.add_argument("--size-factor", type=float, default=None, help="skip the calibration")
    parser.add_argument("--sliver-angle", type=float, default=None, help="TetOptions.sliver_angle (0: no sliver pass)")
    args = parser.parse_args()
    centre0 = np.array([0.3, 0.5, 0.5])
    centres = [centre0 + [0.1 * k, 0, 0] for k in range(args.steps + 1)]
    binary = None if args.no_mmg else mmg_binary()
    start_mesh = evomesh.unit_cube_mesh(10)
    header = ("| method | step | points | tets | kept % of old | edge/h median | radius-edge median / p99 / max | "
              "dihedral min / median / max | % < 10 / > 170 | CPU s | evaluations / query | step RSS bytes / point |")
    rows = []

    mmg_ratio = None
    if binary:
        points, tets = start_mesh.points, start_mesh.tetrahedra
        for _ in range(3):
            points, tets, _, _ = mmg_step(binary, points, tets, size_function(centre0, args.hmin))
        for step in range(1, args.steps + 1):
            h = size_function(centres[step], args.hmin)
            new_points, new_tets, cpu, peak = mmg_step(binary, points, tets, h)
            ratio = median_edge_over_h(new_points, new_tets, h)
            mmg_ratio = ratio if mmg_ratio is None else mmg_ratio
            q = quality_row(new_points, new_tets)
            rows.append(("MMG3D 5.8.0", step, len(new_points), len(new_tets),
                         100 * kept_count(points, new_points) / len(points), ratio, q, cpu, float("nan"),
                         peak / len(new_points)))
            print(format_row(rows[-1]), flush=True)
            points, tets = new_points, new_tets
    elif not args.no_mmg:
        print("MMG3D not found under build/peers/mmg-venv: evomesh only", file=sys.stderr)

    def run_evomesh(size_factor: float, steps: int, report: bool) -> float:
        mesh = start_mesh
        for k in range(3):
            mesh = evomesh.evolve(mesh, size=size_function(centre0, args.hmin), seed=k, size_factor=size_factor,
                                  **sliver)
        ratio0 = None
        for step in range(1, steps + 1):
            h = size_function(centres[step], args.hmin)
            t0 = time.process_time()
            new, step_rss = step_memory(evomesh.evolve, mesh, size=h, seed=10 + step, size_factor=size_factor,
                                        **sliver)
            cpu = time.process_time() - t0
            ratio = median_edge_over_h(new.points, new.tetrahedra, h)
            ratio0 = ratio if ratio0 is None else ratio0
            if report:
                q = quality_row(new.points, new.tetrahedra)
                rows.append((f"evomesh (size_factor {size_factor:.3f}, sliver_angle {sliver_angle:g})", step, new.n_points, new.n_tetrahedra,
                             100 * new.stats["kept_fraction"], ratio, q, cpu, new.stats["evaluations_per_sample"],
                             step_rss / new.n_points))
                print(format_row(rows[-1]), "| samples drawn:", int(new.stats["interior_samples"]), "dropped:",
                      int(new.stats["samples_dropped"]), "refinement points:", int(new.stats["refinement_points"]),
                      "slivers before / after the pass:", int(new.stats["slivers_before"]),
                      int(new.stats["slivers_after"]), "moved:", int(new.stats["sliver_points_moved"]),
                      "off-centres:", int(new.stats["sliver_off_centres"]), flush=True)
            mesh = new
        return ratio0

    sliver_angle = evomesh.TetOptions().sliver_angle if args.sliver_angle is None else args.sliver_angle
    sliver = {"sliver_angle": sliver_angle}
    size_factor = args.size_factor if args.size_factor is not None else evomesh.TetOptions().size_factor
    if args.no_evomesh:
        return
    if mmg_ratio is not None and args.size_factor is None:
        for _ in range(3):  # median edge / h scales with the size factor
            ratio = run_evomesh(size_factor, 1, False)
            print(f"calibration: size_factor {size_factor:.4f} -> edge/h {ratio:.4f} (MMG {mmg_ratio:.4f})",
                  flush=True)
            if abs(ratio / mmg_ratio - 1) <= 0.05:
                break
            size_factor *= mmg_ratio / ratio
    run_evomesh(size_factor, args.steps, True)
    print()
    print(header)
    print("| " + " | ".join(["---"] * 12) + " |")
    for row in rows:
        print(format_row(row))


def format_row(row) -> str:
    method, step, n, m, kept, ratio, q, cpu, evaluations, memory = row
    return (f"| {method} | {step} | {n} | {m} | {kept:.1f} | {ratio:.3f} | "
            f"{q['rho_median']:.3f} / {q['rho_p99']:.3f} / {q['rho_max']:.2f} | "
            f"{q['dih_min']:.2f} / {q['dih_median']:.1f} / {q['dih_max']:.1f} | "
            f"{q['below10']:.3f} / {q['above170']:.3f} | {cpu:.2f} | {evaluations:.1f} | {memory:.0f} |")


if __name__ == "__main__":
    main()
