"""Level-set interfaces, ``evolve(mesh, ..., interface=phi)``.

Sections (all by default; pick some with --only):

* ``convergence``: the interface of a circle (radius 0.3) cut from unit-square
  meshes of 1e3 to 6.4e4 points (delta = 1), for phi as a function and as values
  at the points: the Hausdorff distance between the interface polyline and the
  circle against the longest interface segment and against the mesh spacing,
  with fitted log-log slopes (second order: about 2).
* ``growing``: the paper's growing circle (Section 6, 1096 points, band 0.12,
  spacing 0.011 in it, grade 0.5) with the circle as a conforming interface,
  moving by half a band width per step: points, old points kept (and kept by
  the same steps without the interface, the circle only setting the spacing),
  smallest angle, max |phi| on the interface, the drift of the conservative
  transfers (transfer_cells, and transfer(method="conservative")) and the area
  that changed region (evomesh.region_exchange); the figure
  benchmarks/interface_growing_circle.png.
* ``mmg``: side by side with MMG2D's level-set mode (``mmg2d_O3 -ls``, MMG
  5.7.0 from the pymmg 1.0.0 wheel; tools/get-peers.sh, or EVOMESH_MMG2D) on
  the same input mesh and level sets, uniform size h (the input's median
  spacing): interface error, smallest angle, points, old points kept, time.
* ``notch``: two circles (radius 0.18) one spacing apart (gap 1.04 h) or
  overlapping (by 0.52 h: the union's boundary has two corners whose notch is
  narrower than the spacing), one step with size=h from 1.6e4 and 6.4e4
  points: the Hausdorff distance between the interface and the exact zero set,
  with the cut's search for notches and corners and without it (the cut
  before it), phi calls, smallest angle, seconds.
* ``timing``: the seconds of an interface step against a plain step on the
  same mesh (the ratio is the figure; both run here, one after the other).

    python benchmarks/interface.py [--only convergence,growing,mmg,notch,timing] [--figure PATH]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

import evomesh
from evomesh.interface import INTERFACE_TAG
from evomesh.mesh_quality import triangle_angles

sys.path.insert(0, str(Path(__file__).resolve().parent))
from peers import MMG2D_BINARY, write_medit, write_sol  # noqa: E402

HERE = Path(__file__).resolve().parent


def circle(cx: float, cy: float, r: float):
    return lambda x: np.hypot(x[:, 0] - cx, x[:, 1] - cy) - r


def two_circles(d: float, r: float = 0.15):
    return lambda x: np.minimum(circle(0.5 - d / 2, 0.5, r)(x), circle(0.5 + d / 2, 0.5, r)(x))


def interface_segments(mesh: evomesh.Mesh) -> np.ndarray:
    return mesh.segments[(mesh.segment_tags == INTERFACE_TAG) & ~mesh.segment_is_boundary]


def distance_to_segments(points: np.ndarray, a: np.ndarray, b: np.ndarray, chunk: int = 256) -> np.ndarray:
    out = np.empty(len(points))
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    for s in range(0, len(points), chunk):
        p = points[s:s + chunk, None, :]
        t = np.clip(np.einsum("pkj,kj->pk", p - a[None], d) / dd[None], 0, 1)
        out[s:s + chunk] = np.linalg.norm(p - (a[None] + t[..., None] * d[None]), axis=2).min(axis=1)
    return out


def hausdorff_to_circle(points: np.ndarray, segments: np.ndarray, centre: np.ndarray, radius: float) -> float:
    """Sampled Hausdorff distance between a polyline (segments) and a circle."""
    a, b = points[segments[:, 0]], points[segments[:, 1]]
    s = np.linspace(0, 1, 33)[None, :, None]
    on_polyline = (a[:, None] + s * (b - a)[:, None]).reshape(-1, 2)
    from_polyline = np.abs(np.hypot(*(on_polyline - centre).T) - radius).max()
    angles = np.linspace(0, 2 * np.pi, 20000, endpoint=False)
    from_circle = distance_to_segments(centre + radius * np.c_[np.cos(angles), np.sin(angles)], a, b).max()
    return float(max(from_polyline, from_circle))


def convergence() -> None:
    centre, radius = np.array([0.5, 0.5]), 0.3
    phi = circle(*centre, radius)
    print("\n## Convergence: the interface of a circle (radius 0.3), delta = 1\n")
    print("| phi | input points | spacing h | longest interface segment L | Hausdorff distance | max abs(phi) at interface points |")
    print("|---|---:|---:|---:|---:|---:|")
    for kind in ("function", "values"):
        rows = []
        for n in (1000, 2000, 4000, 8000, 16000, 32000, 64000):
            mesh = evomesh.unit_square_mesh(n)
            new = evomesh.evolve(mesh, 1.0, interface=phi if kind == "function" else phi(mesh.points))
            segments = interface_segments(new)
            distance = hausdorff_to_circle(new.points, segments, centre, radius)
            longest = float(np.hypot(*(new.points[segments[:, 1]] - new.points[segments[:, 0]]).T).max())
            spacing = float(np.median(mesh.nn_spacing))
            on_phi = float(np.abs(phi(new.points[np.unique(segments)])).max())
            rows.append((spacing, longest, distance))
            print(f"| {kind} | {mesh.n_points} | {spacing:.4f} | {longest:.4f} | {distance:.3e} | {on_phi:.1e} |")
        h, L, d = (np.log(np.array(column)) for column in zip(*rows))
        print(f"| {kind}: fitted slope | | against h: **{np.polyfit(h, d, 1)[0]:.2f}** | against L: "
              f"**{np.polyfit(L, d, 1)[0]:.2f}** | | |")


def growing(figure: Path | None) -> None:
    warnings.simplefilter("error")  # a QualityWarning would be a failure here
    band, h_min, grade = 0.12, 0.011, 0.5
    start = evomesh.unit_square_mesh(1096)
    h_max = float(np.median(start.nn_spacing))
    print("\n## The growing circle with the circle in the mesh (1096 points, band 0.12, spacing 0.011, grade 0.5)\n")
    print("Each step moves the circle by half a band width; `kept` is the share of the old points the step keeps, "
          "`kept, no interface` the same steps with the circle only setting the spacing (size = the same law "
          "of the distance to the circle). Drifts are relative, |after - before| / |before|.\n")
    print("| step | radius | points | kept | kept, no interface | min angle | max abs(phi) on interface | "
          "drift transfer_cells | drift conservative transfer | area outside -> inside | seconds |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    mesh, plain = start, start
    cells = 1.0 + mesh.points[mesh.triangles].mean(axis=1)[:, 0]
    nodal = np.sin(3 * mesh.points[:, 0]) * np.cos(2 * mesh.points[:, 1]) + 2.0
    shown = []
    r = 0.05
    for step in range(1, 8):
        phi = circle(0.5, 0.5, r)
        t0 = time.perf_counter()
        new = evomesh.evolve(mesh, size=h_max, interface=phi, interface_band=(band, h_min, grade))
        seconds = time.perf_counter() - t0
        def law(x: np.ndarray, phi=phi) -> np.ndarray:  # the same spacing, the circle not in the mesh
            return np.minimum(h_max, h_min + grade * np.maximum(0, np.abs(phi(x)) - band / 2))

        plain_new = evomesh.evolve(plain, size=law)
        moved_cells = evomesh.transfer_cells(mesh, new, cells)
        moved_nodal = evomesh.transfer(mesh, new, nodal, method="conservative")
        drift_cells = abs((new.triangle_areas * moved_cells).sum() / (mesh.triangle_areas * cells).sum() - 1)
        integral = lambda m, u: (m.triangle_areas * u[m.triangles].mean(axis=1)).sum()  # noqa: E731
        drift_nodal = abs(integral(new, moved_nodal) / integral(mesh, nodal) - 1)
        exchange = evomesh.region_exchange(mesh, new)
        tags = list(exchange.tags)
        swept = exchange.area[tags.index(0), tags.index(1)] if 0 in tags and 1 in tags else 0.0
        on = new.points[np.unique(interface_segments(new))]
        print(f"| {step} | {r:.2f} | {new.n_points} | {(new.origin >= 0).sum() / mesh.n_points:.1%} | "
              f"{(plain_new.origin >= 0).sum() / plain.n_points:.1%} | {new.stats['min_angle']:.2f} | "
              f"{np.abs(phi(on)).max():.1e} | {drift_cells:.1e} | {drift_nodal:.1e} | {swept:.4f} | {seconds:.2f} |")
        if step in (1, 4, 7):
            shown.append((new, r))
        mesh, plain, cells, nodal = new, plain_new, moved_cells, moved_nodal
        r += band / 2
    if figure is not None:
        from matplotlib.figure import Figure

        fig = Figure(figsize=(15, 5.3), layout="constrained")
        for ax, (m, radius) in zip(fig.subplots(1, len(shown)), shown):
            inside = m.triangle_tags == m.stats["interface_negative_tag"]
            ax.tripcolor(m.points[:, 0], m.points[:, 1], m.triangles, facecolors=inside.astype(float), cmap="Blues",
                         vmin=-0.5, vmax=3, edgecolors="0.2", linewidth=0.25)
            seg = interface_segments(m)
            ax.plot(*np.transpose(m.points[seg], (2, 1, 0)), color="tab:red", linewidth=1.2)
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"radius {radius:.2f}: {m.n_points} points, min angle {m.stats['min_angle']:.1f}", fontsize=10)
        fig.savefig(figure, dpi=80)
        print(f"\nFigure: {figure.relative_to(HERE.parent) if figure.is_relative_to(HERE.parent) else figure}")


def read_medit_with_refs(path: Path) -> dict[str, np.ndarray]:
    """Vertices, Triangles and Edges of a 2-D Medit file, with their references."""
    tokens = path.read_text().split()
    widths = {"Vertices": 3, "Triangles": 4, "Edges": 3, "Corners": 1, "RequiredVertices": 1, "RequiredEdges": 1,
              "Ridges": 1, "Normals": 2, "NormalAtVertices": 2, "Tangents": 2, "TangentAtVertices": 2}
    out: dict[str, np.ndarray] = {}
    i = 0
    while i < len(tokens):
        key = tokens[i]
        if key in ("MeshVersionFormatted", "Dimension"):
            i += 2
        elif key == "End":
            break
        else:
            n, w = int(tokens[i + 1]), widths[key]
            out[key] = np.array(tokens[i + 2:i + 2 + n * w], dtype=np.float64).reshape(n, w)
            i += 2 + n * w
    return out


def run_mmg_ls(mesh: evomesh.Mesh, values: np.ndarray, h: float) -> tuple[dict[str, np.ndarray], float, str]:
    """mmg2d_O3 -ls 0 on the mesh with the level set's values, size h everywhere."""
    with tempfile.TemporaryDirectory(prefix="evomesh-mmg-ls-") as work:
        w = Path(work)
        corners = np.flatnonzero(mesh.kind == evomesh.PointKind.CORNER)
        write_medit(w / "in.mesh", mesh.points, mesh.triangles, edges=mesh.segments[mesh.segment_is_boundary],
                    corners=corners, required=corners)
        write_sol(w / "in.sol", values)
        command = [str(MMG2D_BINARY), "-v", "1", "-ls", "0", "-hsiz", f"{h:.17g}", "-in", "in.mesh", "-sol", "in.sol",
                   "-out", "out.mesh"]
        t0 = time.perf_counter()
        done = subprocess.run(command, cwd=w, capture_output=True, text=True)
        seconds = time.perf_counter() - t0
        if done.returncode != 0:
            raise RuntimeError(f"mmg2d_O3 failed: {done.stdout[-500:]} {done.stderr[-500:]}")
        return read_medit_with_refs(w / "out.mesh"), seconds, "mmg2d_O3 " + " ".join(command[1:])


def mmg() -> None:
    print("\n## Side by side with MMG2D -ls (the same input mesh and level set, size h = the input's median spacing)\n")
    if not MMG2D_BINARY.is_file():
        print(f"(no MMG2D binary at {MMG2D_BINARY}: run tools/get-peers.sh, or set EVOMESH_MMG2D)")
        return
    print("Interface error: the largest abs(phi) at the interface's points (phi is a signed distance here) and the "
          "sampled Hausdorff distance of the interface polyline to the circle. `kept`: input points in the output "
          "at the same coordinates. MMG gets phi's values at the points (what -ls reads); evomesh gets the "
          "function, or the same values.\n")
    print("| level set | input points | method | points | kept | abs(phi) at interface points | Hausdorff to circle | "
          "min angle | seconds |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|")
    call = ""
    for name, phi, centre, radius in (("circle r=0.3", circle(0.5, 0.5, 0.3), np.array([0.5, 0.5]), 0.3),
                                      ("two circles touching", two_circles(0.3), None, None)):
        for n in (4000, 16000, 64000):
            mesh = evomesh.unit_square_mesh(n)
            h = float(np.median(mesh.nn_spacing))
            values = phi(mesh.points)
            rows = []
            for method, interface in (("evomesh, function", phi), ("evomesh, values", values)):
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", evomesh.QualityWarning)  # (at the touching point)
                    new = evomesh.evolve(mesh, size=h, interface=interface)
                seconds = time.perf_counter() - t0
                seg = interface_segments(new)
                rows.append((method, new.points, new.triangles, seg, int((new.origin >= 0).sum()), seconds))
            out, seconds, call = run_mmg_ls(mesh, values, h)
            points = out["Vertices"][:, :2]
            triangles = out["Triangles"][:, :3].astype(np.int64) - 1
            edges = out["Edges"]
            seg = edges[edges[:, 2] == 10, :2].astype(np.int64) - 1  # MMG's reference of the level-set edges
            kept = int(np.isin(points.view(np.complex128).ravel(), mesh.points.view(np.complex128).ravel()).sum())
            rows.append(("MMG2D -ls", points, triangles, seg, kept, seconds))
            for method, p, t, s, kept, sec in rows:
                error = np.abs(phi(p[np.unique(s)])).max()
                distance = f"{hausdorff_to_circle(p, s, centre, radius):.2e}" if centre is not None else "-"
                angle = triangle_angles(p, t).min()
                print(f"| {name} | {mesh.n_points} | {method} | {len(p)} | {kept / mesh.n_points:.0%} | {error:.1e} | "
                      f"{distance} | {angle:.1f} | {sec:.2f} |")
    print(f"\nMMG call: `{call}` (MMG 5.7.0, single thread).")


def notch() -> None:
    import evomesh.interface as interface

    sys.path.insert(0, str(HERE.parent / "tests"))
    from invariants import hausdorff_to_union_of_circles

    print("\n## Two circles one spacing apart or overlapping (one step, size h = the input's median spacing)\n")
    print("Hausdorff distance between the interface polyline and the exact boundary of the union (both sampled "
          "2e-5 apart). `search off`: the cut without its search for notches and corners.\n")
    print("| input points | h | circles | cut | Hausdorff | / h | phi calls | min angle | seconds |")
    print("|---:|---:|---|---|---:|---:|---:|---:|---:|")
    rounds = interface._DOUBLE_CROSSING_ROUNDS
    r = 0.18
    for n in (16000, 64000):
        mesh = evomesh.unit_square_mesh(n)
        h = float(np.median(mesh.nn_spacing))
        for gap in (1.04, -0.52):
            centres = [(0.5 - r - gap * h / 2, 0.5), (0.5 + r + gap * h / 2, 0.5)]
            left, right = circle(*centres[0], r), circle(*centres[1], r)
            for search in (False, True):
                interface._DOUBLE_CROSSING_ROUNDS = rounds if search else 0
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", evomesh.QualityWarning)  # (the notch's tip is a sharp corner)
                    new = evomesh.evolve(mesh, size=h, interface=lambda x, a=left, b=right: np.minimum(a(x), b(x)))
                seconds = time.perf_counter() - t0
                distance = hausdorff_to_union_of_circles(new.points, interface_segments(new), centres, r)
                what = "apart 1.04 h" if gap > 0 else "overlapping 0.52 h"
                print(f"| {mesh.n_points} | {h:.4f} | {what} | {'search' if search else 'search off'} | "
                      f"{distance:.2e} | {distance / h:.3f} | {new.stats['interface_phi_calls']:g} | "
                      f"{triangle_angles(new.points, new.triangles).min():.1f} | {seconds:.2f} |", flush=True)
    interface._DOUBLE_CROSSING_ROUNDS = rounds


def timing() -> None:
    print("\n## Time of an interface step against a plain step (same mesh, same delta)\n")
    print("| points | delta | plain (incremental) | plain (full) | interface | interface / full |")
    print("|---:|---:|---:|---:|---:|---:|")
    phi = circle(0.5, 0.5, 0.3)
    for n in (20000, 100000):
        mesh = evomesh.unit_square_mesh(n)
        _ = mesh.nn_spacing
        for delta in (1.0, 0.8):
            seconds = []
            for kwargs in ({}, {"incremental": False}, {"interface": phi}):
                t0 = time.perf_counter()
                evomesh.evolve(mesh, delta, **kwargs)
                seconds.append(time.perf_counter() - t0)
            print(f"| {mesh.n_points} | {delta} | {seconds[0]:.2f} | {seconds[1]:.2f} | {seconds[2]:.2f} | "
                  f"{seconds[2] / seconds[1]:.2f} |")
    print("\n(With a geometry the step has no incremental path: the interface step compares with the full one.)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default="convergence,growing,mmg,notch,timing")
    parser.add_argument("--figure", type=Path, default=HERE / "interface_growing_circle.png")
    args = parser.parse_args()
    sections = args.only.split(",")
    if "convergence" in sections:
        convergence()
    if "growing" in sections:
        growing(args.figure)
    if "mmg" in sections:
        mmg()
    if "notch" in sections:
        notch()
    if "timing" in sections:
        timing()


if __name__ == "__main__":
    main()
