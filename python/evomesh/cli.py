"""The ``evomesh`` command line tool."""

from __future__ import annotations

import argparse
import sys
from typing import Sequence

__all__ = ["main", "build_parser"]


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    from evomesh import __version__
    from evomesh.experiments.growing_circle import GROWING_CIRCLE_DEFAULTS as D

    parser = argparse.ArgumentParser(
        prog="evomesh", description="Simultaneous refinement and coarsening of triangle meshes (Li, Teng, Ungor)."
    )
    parser.add_argument("--version", action="version", version=f"evomesh {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    gc = commands.add_parser(
        "growing-circle",
        help="the paper's experiment (Section 6, Table 1): a circle growing in the unit square",
        description=(
            "Evolve a mesh of the unit square while a circle grows from near the centre until it touches the "
            "box: refined in a band around the circle, coarsened behind it. Prints the statistics table (with "
            "the paper's Table 1 beside it for 6 steps) and writes table.csv, VTU meshes with a .pvd series "
            "and one PNG per step into the output folder."
        ),
    )
    gc.add_argument(
        "--steps", type=_positive_int, default=D["steps"], help="number of steps (default %(default)s)"
    )
    gc.add_argument(
        "--points", type=_positive_int, default=D["n_points"], help="initial mesh size (default %(default)s)"
    )
    gc.add_argument(
        "--band", type=float, default=D["band"], help="full width of the band where h = h_min (default %(default)s)"
    )
    gc.add_argument("--h-min", type=float, default=D["h_min"], help="spacing at the front (default %(default)s)")
    gc.add_argument("--h-max", type=float, default=D["h_max"],
                    help="far-field spacing (default: the median nn spacing of the initial mesh)")
    gc.add_argument(
        "--grade", type=float, default=D["grade"], help="growth dh/dd outside the band (default %(default)s)"
    )
    gc.add_argument("--r0", type=float, default=D["r0"], help="radius at time 0 (default %(default)s)")
    gc.add_argument("--r-end", type=float, default=D["r_end"],
                    help="radius at the last step (default: the circle touches the box)")
    gc.add_argument("--seed", type=int, default=0, help="seed of the sampling (default %(default)s)")
    gc.add_argument("--method", default="frfc", help="evolve method (default %(default)s)")
    gc.add_argument("--out", default="evomesh-growing-circle", help="output folder (default %(default)s)")
    gc.add_argument("--no-quality", action="store_true",
                    help="switch off the quality pass (the paper's plain algorithm)")
    gc.add_argument("--no-figures", action="store_true", help="do not draw the PNG figures")
    gc.add_argument("--quiet", action="store_true", help="no table, no progress bar")
    return parser


def _growing_circle(args: argparse.Namespace) -> int:
    from evomesh.experiments.growing_circle import growing_circle

    result = growing_circle(
        steps=args.steps,
        n_points=args.points,
        r0=args.r0,
        r_end=args.r_end,
        band=args.band,
        h_min=args.h_min,
        h_max=args.h_max,
        grade=args.grade,
        seed=args.seed,
        method=args.method,
        out=args.out,
        figures=not args.no_figures,
        progress=False if args.quiet else None,
        quality=not args.no_quality,
    )
    if not args.quiet:
        initial = result.initial
        print(f"initial mesh: {initial.n_points} points, {initial.n_triangles} triangles")
        print(result.table(paper=args.steps == 6))
        print(f"outputs in {args.out}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``evomesh`` command; returns the exit status
    (0 success, 2 bad arguments or failure, with a one-line message)."""
    parser = build_parser()
    args = parser.parse_args(argv)  # argparse exits with status 2 on malformed options
    try:
        if args.command == "growing-circle":
            return _growing_circle(args)
    except (ValueError, TypeError, OSError) as error:
        lines = str(error).strip().splitlines()
        print(f"evomesh: error: {lines[0] if lines else type(error).__name__}", file=sys.stderr)
        return 2
    parser.error(f"unknown command {args.command!r}")  # pragma: no cover
    return 2  # pragma: no cover


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
