"""The paper's experiment (Section 6, Table 1): a circle growing in the unit square."""

from __future__ import annotations

import numbers
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from evomesh.fronts import CircleFront, SpacingLaw
from evomesh.io import write_run
from evomesh.meshgen import unit_square_mesh
from evomesh.spacing_function import nn_spacing
from evomesh.time_loop import Run, run

__all__ = ["GROWING_CIRCLE_DEFAULTS", "growing_circle"]


#: Defaults of :func:`growing_circle` (the calibration reported in README).
GROWING_CIRCLE_DEFAULTS: dict[str, Any] = {
    "steps": 6,
    "n_points": 1096,
    "center": (0.5, 0.5),
    "r0": 0.05,
    "r_end": None,
    "band": 0.12,
    "h_min": 0.011,
    "h_max": None,
    "grade": 0.5,
}


def growing_circle(
    *,
    steps: int = 6,
    n_points: int = 1096,
    center: Sequence[float] = (0.5, 0.5),
    r0: float = 0.05,
    r_end: float | None = None,
    band: float = 0.12,
    h_min: float = 0.011,
    h_max: float | None = None,
    grade: float = 0.5,
    seed: int = 0,
    method: str = "frfc",
    out: str | Path | None = None,
    figures: bool = True,
    progress: bool | None = None,
    **options: Any,
) -> Run:
    """The paper's experiment (Section 6, Table 1): a circle growing in the unit square.

    The initial mesh is :func:`evomesh.meshgen.unit_square_mesh` (about
    ``n_points`` points). Step k (k = 1..steps) moves the circle to radius
    r0 + (r_end - r0) k / steps; by default r_end is the distance from the
    centre to the nearest side: at the last step the circle touches the box.

    Parameters
    ----------
    steps : int
    n_points : int
        Size of the initial mesh.
    center : (float, float)
        Centre of the circle, inside the square.
    r0 : float
        Radius at time 0 (before the first step).
    r_end : float, optional
        Radius at the last step (> r0); larger than the default makes the
        circle leave the box through the sides (about 0.7 reaches the corners).
    band, h_min, grade : float
        The :class:`SpacingLaw` (full band width, spacing in the band, slope).
    h_max : float, optional
        Far-field spacing; default the median nn spacing of the initial mesh,
        so the mesh away from the front keeps its spacing (delta about 1), as
        in the paper's first step (1084 of 1096 points kept).
    seed, method, **options
        Passed to :func:`run` / :func:`evomesh.evolve`.
    out : path, optional
        Folder for the outputs (:func:`evomesh.io.write_run`): table CSV, VTU
        meshes with a .pvd series, and (``figures=True``) one PNG per step.
    progress : bool or None
        As in :func:`run`.

    Returns
    -------
    Run
    """
    if isinstance(steps, bool) or not isinstance(steps, numbers.Integral):
        raise TypeError(f"steps must be an integer, got {type(steps).__name__}")
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    c = np.asarray(center, dtype=np.float64)
    if c.shape != (2,) or not np.isfinite(c).all() or not ((c > 0) & (c < 1)).all():
        raise ValueError(f"center must be a point inside the unit square, got {center!r}")
    reach = float(min(c.min(), 1.0 - c.max()))
    if isinstance(r0, bool) or not isinstance(r0, numbers.Real):
        raise TypeError(f"r0 must be a real number, got {type(r0).__name__}")
    if not 0 <= r0 < reach:
        raise ValueError(f"r0 must be in [0, {reach:g}) (the circle must start inside the box), got {r0}")
    if r_end is None:
        r_end = reach
    if isinstance(r_end, bool) or not isinstance(r_end, numbers.Real):
        raise TypeError(f"r_end must be a real number, got {type(r_end).__name__}")
    if not (np.isfinite(r_end) and r_end > r0):
        raise ValueError(f"r_end must be finite and > r0 = {r0}, got {r_end}")
    r_end = float(r_end)
    mesh = unit_square_mesh(n_points)
    if h_max is None:
        h_max = float(np.median(nn_spacing(mesh)))
    law = SpacingLaw(h_min, h_max, band, grade=grade)
    front = CircleFront(c, lambda t: r0 + (r_end - r0) * t / steps)
    times = np.arange(1, steps + 1, dtype=np.float64)
    result = run(mesh, front, law, times, method=method, seed=seed, progress=progress, **options)
    if out is not None:
        write_run(result, out, figures=figures)
    return result
