"""Soak test: 500 steps of a band front sweeping across the unit square and back.

A meshing library sits inside long simulations; this run looks for drift. A
vertical band front x = c(t) moves from x = 0 to x = 1 in the first half of
the run and back in the second; every step is one
``evomesh.evolve`` through :class:`evomesh.Driver` with the spacing law
delta = clip(h(d) / nn_M, 0.3, 3), h = h_min in the band growing linearly
outside it up to h_max. Per step it records points, triangles, min angle,
spacing ratio, resident memory (current and peak) and seconds, to CSV, and
plots min angle and points against the step. With ``--spacing-figures`` it also
records the spacing figures per step (size n / integral(1/f^2) with f =
evomesh.spacing(M, delta); the spacing ratio nn_M'(p) / (delta(p) nn_M(p)) over
the step's input points, p50/p99/max, nn_M' the paper's second nearest output
point; the share of triangles with an angle below 30 degrees; QualityWarnings
raised by the step) and summarises the worst step of each against the goals
(p99 <= 1.10, max <= 1.35, n / integral <= 1.8, min angle >= 30 degrees).

At the end it checks:
- quality: the min angle of every step stays at or above the method's target
  (``min_angle``, 20 degrees by default, when its quality pass is on);
- memory: the peak resident memory of the second sweep (steps 251-500, the
  same mesh sizes again) exceeds that of the first by less than 10%, and
  repeating the last step 300 times (after 150 warm-up repetitions) grows
  resident memory by less than 2 MiB (no leak; 7 KiB per step would show);
- boundary: at step 500 the four corners are points of the mesh (exactly,
  kind CORNER), every boundary point lies exactly on the square's sides (up
  to 1e-14 with --slanted, whose slanted sides round their samples), the area
  is unchanged up to the rounding of its sum, and the Euler characteristic is 1.

Usage (from the repository root):
    python benchmarks/soak.py                      # 500 steps, a few minutes
    python benchmarks/soak.py --slanted --out /tmp/soak-slanted   # slanted sides
    python benchmarks/soak.py --steps 40 --out /tmp/soak   # quick look
    python benchmarks/soak.py --steps 200 --points 20000 --h-min 0.002 --h-max 0.012 --spacing-figures \
        --leak-repeats 40      # the spacing figures at every step
Outputs: benchmarks/soak.csv, benchmarks/soak.png (or under --out), and a
Markdown summary on stdout (pasted into benchmarks/SOAK.md). Exit status 1 if
a check fails.
"""

from __future__ import annotations

import argparse
import ctypes
import csv
import resource
import sys
import time
import warnings
from fractions import Fraction
from pathlib import Path

import numpy as np

import evomesh
from evomesh import PointKind
from evomesh.time_loop import Driver
from evomesh.fronts import LevelSetFront, SpacingLaw
from evomesh.meshgen import unit_square_mesh

HERE = Path(__file__).resolve().parent
COLUMNS = (
    "step", "front_x", "points", "triangles", "original_pct", "min_angle_deg", "max_radius_edge",
    "spacing_ratio_max", "spacing_ratio_p99", "rss_mb", "peak_rss_mb", "seconds",
)
# the spacing figures (--spacing-figures)
SPACING_COLUMNS = ("n_over_integral", "ratio_p50", "ratio_p99", "ratio_max", "pct_below_30", "pct_below_29_99",
                  "quality_warnings")
SPACING_GOALS = {"ratio_p99": 1.10, "ratio_max": 1.35, "n_over_integral": 1.8}


def spacing_figures(old: evomesh.Mesh, new: evomesh.Mesh, delta: np.ndarray) -> dict[str, float]:
    """The spacing figures of the step old -> new (as benchmarks/spacing_ratios.py computes them)."""
    sys.path.insert(0, str(HERE))
    import peers
    from spacing_ratios import paper_ratio

    f = evomesh.spacing(old, delta)
    m = peers.metrics(old, delta, new.points, new.triangles, f=f)
    ratio = paper_ratio(old, delta, new.points)
    return {"n_over_integral": m["n_over_integral"], "ratio_p50": float(np.percentile(ratio, 50)),
            "ratio_p99": float(np.percentile(ratio, 99)), "ratio_max": float(ratio.max()),
            "pct_below_30": 100.0 * m["fraction_below_30"],
            # off-centres of the quality pass make angles of exactly 30 degrees, which round below it
            "pct_below_29_99": 100.0 * float((peers.triangle_min_angles(new.points, new.triangles) < 29.99).mean())}


def trimmed_rss_mb() -> float:
    """Resident set size after glibc returns its cached free memory (malloc_trim):
    what the process actually holds, without the allocator's warm-up steps."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass
    return rss_mb()


def rss_mb() -> float:
    """Current resident set size of this process (Linux /proc), MiB."""
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    return pages * resource.getpagesize() / 2**20


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux


def front_position(step: int, steps: int) -> float:
    """Triangle wave: x = 0 at step 0, 1 at steps/2, 0 at steps."""
    half = steps / 2
    return step / half if step <= half else (steps - step) / half


# The square's frame -> the domain: identity, or the exact integer map (x, y) ->
# (4x - 3y, 3x + 4y), a rotation by atan(3/4) = 36.87 degrees scaled by 5. On
# dyadic coordinates (multiples of 2**-20) its images are exact, so points on
# a side stay exactly collinear: the sides are slanted yet straight.
SLANTED = np.array([[4.0, -3.0], [3.0, 4.0]])


def band_front(steps: int, transform: np.ndarray, scale: float) -> LevelSetFront:
    """The line u = c(t), u the first coordinate in the square's frame."""
    inverse = np.linalg.inv(transform)
    # phi = (u - c(t)) * scale is a signed distance (the map is a similarity)
    return LevelSetFront(lambda x, t: ((x @ inverse.T)[:, 0] - front_position(int(round(t)), steps)) * scale,
                         signed_distance=True)


def boundary_check(initial: evomesh.Mesh, mesh: evomesh.Mesh) -> dict[str, object]:
    """Corners, area and boundary of ``mesh`` against the initial mesh."""
    corners = initial.points[initial.kind == PointKind.CORNER]
    corner_rows = [np.flatnonzero((mesh.points == c).all(axis=1)) for c in corners]
    corners_kept = all(len(r) == 1 and mesh.kind[r[0]] == PointKind.CORNER for r in corner_rows)
    a = initial.segments[initial.segment_is_boundary]
    b = np.unique(mesh.segments[mesh.segment_is_boundary])
    p, start, end = mesh.points[b], initial.points[a[:, 0]], initial.points[a[:, 1]]
    # distance from every boundary point of the mesh to the initial boundary
    d = end - start
    t = np.clip(np.einsum("pkj,kj->pk", p[:, None] - start[None], d) / np.einsum("kj,kj->k", d, d), 0, 1)
    distances = np.linalg.norm(p[:, None] - (start[None] + t[..., None] * d[None]), axis=2)
    nearest = distances.argmin(axis=1)

    def exactly_on(q, a, c):  # exact orientation test in rationals
        q, a, c = ([Fraction(float(v)) for v in w] for w in (q, a, c))
        return (c[0] - a[0]) * (q[1] - a[1]) - (c[1] - a[1]) * (q[0] - a[0]) == 0

    on_side = [exactly_on(q, start[k], end[k]) for q, k in zip(p, nearest)]
    return {
        "n_corners": len(corners),
        "corners_kept": bool(corners_kept),
        "area_error": abs(mesh.area - initial.area) / initial.area,
        "boundary_distance": float(distances.min(axis=1).max()),
        "boundary_points": len(p),
        "boundary_points_exact": int(sum(on_side)),
        "euler": mesh.euler_characteristic(),
    }


def plot_spacing_figures(rows: list[dict[str, float]], target: float, path: Path) -> None:
    """The spacing figures against the step (--spacing-figures)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    step = [r["step"] for r in rows]
    fig, axes = plt.subplots(5, 1, figsize=(8, 11), sharex=True)
    ax = axes[0]
    ax.plot(step, [r["points"] for r in rows], lw=0.9, color="C1")
    ax.set_ylabel("points")
    ax = axes[1]
    for name, colour in (("ratio_p50", "C0"), ("ratio_p99", "C1"), ("ratio_max", "C3")):
        ax.plot(step, [r[name] for r in rows], lw=0.9, color=colour, label=name.replace("ratio_", ""))
    ax.axhline(SPACING_GOALS["ratio_p99"], color="C1", ls="--", lw=0.7)
    ax.axhline(SPACING_GOALS["ratio_max"], color="C3", ls="--", lw=0.7)
    ax.set_ylabel("nn_M' / (delta nn_M)")
    ax.legend(loc="upper right", ncol=3, fontsize=8)
    ax = axes[2]
    ax.plot(step, [r["n_over_integral"] for r in rows], lw=0.9, color="C2")
    ax.axhline(SPACING_GOALS["n_over_integral"], color="C2", ls="--", lw=0.7, label="goal 1.8")
    ax.set_ylabel("n / integral f^-2")
    ax.legend(loc="upper right", fontsize=8)
    ax = axes[3]
    ax.plot(step, [r["min_angle_deg"] for r in rows], lw=0.9, color="C0", label="min angle (deg)")
    ax.axhline(target, color="C3", ls="--", lw=0.7)
    ax2 = ax.twinx()
    ax2.plot(step, [r["pct_below_30"] for r in rows], lw=0.9, color="C4", label="% triangles < 30 deg")
    ax2.set_ylabel("% < 30 deg", color="C4")
    ax.set_ylim(target - 2, target + 2)  # angles at the bound round a few 1e-7 below it
    ax.set_ylabel("min angle (deg)")
    ax = axes[4]
    ax.plot(step, [r["seconds"] for r in rows], lw=0.9, color="C5")
    ax.set_ylabel("seconds")
    ax.set_xlabel("step (band front: x = 0 -> 1 -> 0)")
    fig.suptitle(f"evomesh soak, spacing figures: {len(rows)} steps of a sweeping band front")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot(rows: list[dict[str, float]], target: float, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    step = [r["step"] for r in rows]
    fig, (ax1, ax2, ax3) = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True)
    ax1.plot(step, [r["min_angle_deg"] for r in rows], lw=0.9)
    ax1.axhline(target, color="C3", ls="--", lw=0.8, label=f"target {target:g} deg")
    ax1.set_ylabel("min angle (deg)")
    ax1.legend(loc="upper right")
    ax2.plot(step, [r["points"] for r in rows], lw=0.9, color="C1")
    ax2.set_ylabel("points")
    ax3.plot(step, [r["rss_mb"] for r in rows], lw=0.9, color="C2", label="current")
    ax3.plot(step, [r["peak_rss_mb"] for r in rows], lw=0.9, color="C4", label="peak")
    ax3.set_ylabel("resident memory (MiB)")
    ax3.set_xlabel("step (band front: x = 0 -> 1 -> 0)")
    ax3.legend(loc="lower right")
    fig.suptitle(f"evomesh soak: {len(rows)} steps of a sweeping band front")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=500)
    parser.add_argument("--points", type=int, default=3000, help="initial mesh size")
    parser.add_argument("--h-min", type=float, default=0.005, help="spacing in the band")
    parser.add_argument("--h-max", type=float, default=0.03, help="far-field spacing")
    parser.add_argument("--band", type=float, default=0.08, help="full band width")
    parser.add_argument("--slanted", action="store_true",
                        help="the square rotated by 36.87 degrees and scaled by 5 (exactly straight slanted sides; "
                        "points sampled on them are rounded)")
    parser.add_argument("--grade", type=float, default=0.3)
    parser.add_argument("--method", default="frfc")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--leak-repeats", type=int, default=300,
                        help="measured repetitions of the last step (leak probe), after half as many unmeasured")
    parser.add_argument("--spacing-figures", action="store_true",
                        help="also record the spacing figures per step and summarise them against their goals")
    parser.add_argument("--out", type=Path, default=HERE, help="folder for soak.csv and soak.png")
    args = parser.parse_args(argv)

    options = {"threads": args.threads}
    # the quality target of the method: its min_angle when its quality pass is on
    defaults = getattr(evomesh, f"{args.method.upper()}_DEFAULTS", {})
    target = float(defaults.get("min_angle", 0.0)) if defaults.get("quality", False) else 0.0
    square = unit_square_mesh(args.points, seed=args.seed)
    transform, scale = (SLANTED, 5.0) if args.slanted else (np.eye(2), 1.0)
    if args.slanted:
        dyadic = np.round(square.points * 2.0**20) / 2.0**20
        mesh = evomesh.Mesh(dyadic @ transform.T, square.triangles)
    else:
        mesh = square
    initial = evomesh.quality(mesh)
    law = SpacingLaw(args.h_min * scale, args.h_max * scale, args.band * scale, grade=args.grade, lower=0.3, upper=3.0)
    driver = Driver(mesh, law, method=args.method, seed=args.seed, **options)
    front = band_front(args.steps, transform, scale)

    rows: list[dict[str, float]] = []
    start = time.perf_counter()
    for k in range(1, args.steps + 1):
        old = driver.mesh
        t0 = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", evomesh.QualityWarning)
            step = driver.step(front, float(k))
        seconds = time.perf_counter() - t0
        for w in caught:  # anything else goes on as usual
            if not issubclass(w.category, evomesh.QualityWarning):
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        s = step.stats
        rows.append({
            "step": k, "front_x": front_position(k, args.steps), "points": s["points"], "triangles": s["triangles"],
            "original_pct": s["original_pct"], "min_angle_deg": s["min_angle_deg"],
            "max_radius_edge": s["max_radius_edge"], "spacing_ratio_max": s["spacing_ratio_max"],
            "spacing_ratio_p99": s["spacing_ratio_p99"], "rss_mb": rss_mb(), "peak_rss_mb": peak_rss_mb(),
            "seconds": seconds,
        })
        if args.spacing_figures:
            rows[-1].update(spacing_figures(old, step.mesh, step.delta))
            rows[-1]["quality_warnings"] = sum(issubclass(w.category, evomesh.QualityWarning) for w in caught)
        del step, old
        if k % 50 == 0:
            r = rows[-1]
            print(f"step {k:4d}: x={r['front_x']:.3f} points={r['points']} min angle={r['min_angle_deg']:.2f} "
                  f"rss={r['rss_mb']:.0f} MiB" + (f" p99={r['ratio_p99']:.3f} max={r['ratio_max']:.3f} "
                                                 f"n/int={r['n_over_integral']:.3f}" if args.spacing_figures else ""),
                  file=sys.stderr, flush=True)
    total = time.perf_counter() - start

    args.out.mkdir(parents=True, exist_ok=True)
    csv_path = args.out / "soak.csv"
    columns = COLUMNS + (SPACING_COLUMNS if args.spacing_figures else ())
    with open(csv_path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        for r in rows:
            writer.writerow({c: (f"{r[c]:.6g}" if isinstance(r[c], float) else r[c]) for c in columns})
    png_path = args.out / "soak.png"
    (plot_spacing_figures if args.spacing_figures else plot)(rows, target, png_path)

    # --- leak probe: the same step again and again must not grow memory ---
    probe_mesh, probe_delta = driver.mesh, driver.delta(front, float(args.steps))
    options = {"method": args.method, "seed": args.seed, **options}
    # warm-up: the allocator settles once (a step of about 1 MiB after ~100 repeats)
    for _ in range(args.leak_repeats // 2):
        evomesh.evolve(probe_mesh, probe_delta, **options)
    probe_rss = []
    for _ in range(args.leak_repeats):
        evomesh.evolve(probe_mesh, probe_delta, **options)
        probe_rss.append(trimmed_rss_mb())
    # medians of the first and last quarters (a leak grows linearly)
    quarter = max(1, args.leak_repeats // 4)
    leak_mib = float(np.median(probe_rss[-quarter:]) - np.median(probe_rss[:quarter]))

    # --- checks ---------------------------------------------------------
    angle = np.array([r["min_angle_deg"] for r in rows])
    points = np.array([r["points"] for r in rows])
    rss = np.array([r["rss_mb"] for r in rows])
    peak = np.array([r["peak_rss_mb"] for r in rows])
    half = len(rows) // 2
    boundary = boundary_check(mesh, driver.mesh)
    peak_first, peak_second = peak[:half].max(), peak.max()
    # resident memory against mesh size: a leak shows as a residual growing with the step
    fit = np.polyfit(points, rss, 1)
    residual = rss - np.polyval(fit, points)
    drift_per_100 = float(np.polyfit(np.arange(len(rss)), residual, 1)[0] * 100)
    checks = {
        # 1e-3 deg: off-centres of the quality pass make angles of exactly the target, which round below it
        f"min angle >= target ({target:g} deg) at every step": bool((angle >= target - 1e-3).all()),
        "peak memory of the 2nd sweep < 1.1 x the 1st": bool(peak_second < 1.1 * peak_first),
        f"repeating the last step {args.leak_repeats} times grows memory by < 2 MiB": leak_mib < 2.0,
        f"{boundary['n_corners']} corners kept exactly (kind CORNER)": boundary["corners_kept"],
        # the sum of triangle areas rounds; the domain itself is exact when its
        # boundary points are exactly on the sides (always for axis-parallel ones)
        "area unchanged up to rounding (1e-13)": boundary["area_error"] <= 1e-13,
        "boundary points on the initial sides" + (" up to 1e-14 x size" if args.slanted else " (exactly)"):
            boundary["boundary_distance"] <= 1e-14 * scale if args.slanted
            else boundary["boundary_points_exact"] == boundary["boundary_points"],
        "Euler characteristic 1": boundary["euler"] == 1,
    }

    ratio = np.array([r["spacing_ratio_max"] for r in rows])
    print(f"## Soak: {len(rows)} steps of a sweeping band front\n")
    print(f"`python benchmarks/soak.py --steps {args.steps} --points {args.points}"
          + "".join(f" --{name.replace('_', '-')} {getattr(args, name):g}" for name in ("h_min", "h_max", "band", "grade")
                    if getattr(args, name) != parser.get_default(name))
          + f"{' --slanted' if args.slanted else ''}{' --spacing-figures' if args.spacing_figures else ''}"
          + (f" --leak-repeats {args.leak_repeats}" if args.leak_repeats != parser.get_default("leak_repeats") else "")
          + "` "
          f"(method {args.method}, threads {args.threads}, seed {args.seed}); {total:.0f} s in total, "
          f"{np.mean([r['seconds'] for r in rows]) * 1e3:.0f} ms per step.\n")
    shape = "unit square" + (" rotated by 36.87 deg and scaled by 5 (slanted sides)" if args.slanted else "")
    print(f"Initial mesh: {shape}, {mesh.n_points} points, min angle {initial.min_angle:.1f} deg. "
          f"Band {args.band:g} wide with h_min = {args.h_min:g}, growing with slope {args.grade:g} to "
          f"h_max = {args.h_max:g}; delta = clip(h(d) / nn_M, 0.3, 3); the front x = c(t) goes "
          f"0 -> 1 (steps 1-{half}) -> 0.\n")
    print("| quantity | min | max | step 1 | step 500 |".replace("500", str(len(rows))))
    print("|---|---|---|---|---|")
    for name, values, fmt in (
        ("points", points, "{:.0f}"),
        ("min angle (deg)", angle, "{:.2f}"),
        ("spacing ratio max", ratio, "{:.2f}"),
        ("resident memory (MiB)", rss, "{:.0f}"),
        ("peak resident memory (MiB)", peak, "{:.0f}"),
    ):
        print(f"| {name} | {fmt.format(values.min())} | {fmt.format(values.max())} | "
              f"{fmt.format(values[0])} | {fmt.format(values[-1])} |")
    if args.spacing_figures:
        seconds = np.array([r["seconds"] for r in rows])
        print("\nThe spacing figures per step (worst step of each; goals: p99 <= 1.10, max <= 1.35, "
              "n/∫f⁻² <= 1.8, min angle >= 30°):\n")
        print("| figure | worst | at step | median over steps | best | steps meeting the goal |")
        print("|---|---|---|---|---|---|")
        for name, key, worst, fmt, goal in (
            ("points", "points", np.argmax, "{:.0f}", None),
            ("n/∫f⁻²", "n_over_integral", np.argmax, "{:.3f}", lambda v: v <= 1.8),
            ("ratio p50", "ratio_p50", np.argmax, "{:.3f}", None),
            ("ratio p99", "ratio_p99", np.argmax, "{:.3f}", lambda v: v <= 1.10),
            ("ratio max", "ratio_max", np.argmax, "{:.3f}", lambda v: v <= 1.35),
            ("min angle (°)", "min_angle_deg", np.argmin, "{:.2f}", lambda v: v >= 30.0 - 0.005),
            ("% triangles < 30°", "pct_below_30", np.argmax, "{:.2f}", None),
            ("% triangles < 29.99°", "pct_below_29_99", np.argmax, "{:.2f}", None),
            ("seconds", "seconds", np.argmax, "{:.2f}", None),
            ("QualityWarnings", "quality_warnings", np.argmax, "{:.0f}", lambda v: v == 0),
        ):
            v = np.array([r[key] for r in rows], dtype=float)
            i = int(worst(v))
            best = v.min() if worst is np.argmax else v.max()
            met = "" if goal is None else f"{int(sum(goal(x) for x in v))} of {len(v)}"
            print(f"| {name} | {fmt.format(v[i])} | {rows[i]['step']} | {fmt.format(np.median(v))} | "
                  f"{fmt.format(best)} | {met} |")
        print(f"\nSeconds per step: mean {seconds.mean():.2f}, total {seconds.sum():.0f}; "
              f"steps with a QualityWarning: {sum(r['quality_warnings'] > 0 for r in rows)}.")
    print(f"\nMemory: peak {peak_first:.0f} MiB after the first sweep, {peak_second:.0f} MiB after the second; "
          f"resident memory minus its linear fit in the point count drifts by {drift_per_100:+.2f} MiB "
          f"per 100 steps (allocator noise of a few MiB); the last step repeated {args.leak_repeats} times "
          f"({probe_mesh.n_points} points) changes it by {leak_mib:+.2f} MiB (median of the last quarter of "
          f"the repeats minus that of the first, resident memory measured after malloc_trim).")
    print(f"Boundary at step {len(rows)}: {boundary['n_corners']} corners kept: {boundary['corners_kept']}, "
          f"relative area change {boundary['area_error']:.1e}; {boundary['boundary_points_exact']} of "
          f"{boundary['boundary_points']} boundary points exactly on the initial sides (exact rational test), "
          f"largest distance {boundary['boundary_distance']:.1e}; Euler characteristic {boundary['euler']}.\n")
    for name, ok in checks.items():
        print(f"- [{'x' if ok else ' '}] {name}")
    print(f"\nPer-step data: `{csv_path.relative_to(HERE.parent) if csv_path.is_relative_to(HERE.parent) else csv_path}`;"
          f" plot: `{png_path.relative_to(HERE.parent) if png_path.is_relative_to(HERE.parent) else png_path}`.")
    return 0 if all(checks.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
