"""One evolution step: refine where delta < 1, coarsen where delta > 1."""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from evomesh import _core
from evomesh.mesh import Mesh
from evomesh.spacing import _require_mesh, as_delta

__all__ = ["evolve", "FRFC_DEFAULTS"]

_SAMPLE_MODES = {"random": 0, "barycentre": 1, "midpoints": 2, "barycentre+midpoints": 3}
_RADII = ("exact", "cheap")

#: Options of method="frfc" and their defaults.
FRFC_DEFAULTS: dict[str, Any] = {
    "cell_factor": 1.0,
    "radius": "exact",
    "radius_scale": 0.75,
    "boundary_scale": 0.8,
    "repair_ratio": 1.75,
    "samples": "random",
    "skip_coarse": False,
    "max_samples": 5e7,
    "threads": None,
}


def _frfc_options(options: dict[str, Any]) -> dict[str, Any]:
    unknown = sorted(set(options) - set(FRFC_DEFAULTS))
    if unknown:
        raise TypeError(f"unknown option(s) for method 'frfc': {', '.join(unknown)}; known: {', '.join(FRFC_DEFAULTS)}")
    o = {**FRFC_DEFAULTS, **options}
    for name in ("cell_factor", "radius_scale", "boundary_scale", "max_samples"):
        value = o[name]
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
        if not np.isfinite(value) or value <= 0:
            raise ValueError(f"{name} must be finite and > 0, got {value}")
    for name in ("radius_scale", "boundary_scale"):
        if o[name] > 1:
            raise ValueError(f"{name} must be in (0, 1], got {o[name]}")
    repair = o["repair_ratio"]
    if repair is None:
        o["repair_ratio"] = repair = 0.0
    if isinstance(repair, bool) or not isinstance(repair, numbers.Real):
        raise TypeError(f"repair_ratio must be a real number or None, got {type(repair).__name__}")
    if not (repair == 0 or (np.isfinite(repair) and repair >= 1)):
        raise ValueError(f"repair_ratio must be None, 0 or a finite number >= 1, got {repair}")
    if o["samples"] not in _SAMPLE_MODES:
        raise ValueError(f"samples must be one of {', '.join(_SAMPLE_MODES)}, got {o['samples']!r}")
    if o["radius"] not in _RADII:
        raise ValueError(f"radius must be 'exact' or 'cheap', got {o['radius']!r}")
    if not isinstance(o["skip_coarse"], (bool, np.bool_)):
        raise TypeError("skip_coarse must be a bool")
    threads = o["threads"]
    if threads is not None and (
        isinstance(threads, bool) or not isinstance(threads, numbers.Integral) or not 1 <= threads < 2**31
    ):
        raise ValueError(f"threads must be None or an integer in [1, 2**31), got {threads!r}")
    return o


def _check_seed(seed: Any) -> int:
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise TypeError(f"seed must be an integer, got {type(seed).__name__}")
    if not 0 <= int(seed) < 2**64:
        raise ValueError(f"seed must be in [0, 2**64), got {seed}")
    return int(seed)


def evolve(mesh: Mesh, delta: Any, *, method: str = "frfc", seed: int = 0, **options: Any) -> Mesh:
    """Evolve a mesh one step: new spacing delta(p) * nn_M(p) at every point p.

    Parameters
    ----------
    mesh : Mesh
        The current mesh.
    delta : array_like, shape (n,), or a scalar
        Per-point factor: < 1 refines (R-points), > 1 coarsens (C-points).
        Every value must be finite and in [:data:`~evomesh.spacing.DELTA_MIN`,
        :data:`~evomesh.spacing.DELTA_MAX`] = [1e-6, 1e6] (the paper's bounds
        l <= delta <= L); in addition a step whose sampling would create more
        than ``max_samples`` candidate points is refused (refine over several
        steps instead).
    method : {"frfc"}
        "frfc": Functional-Refining-Functional-Coarsening (paper, Section 3.2).
    seed : int
        Seed of the sampling; the same mesh, delta, options and seed give a
        bit-identical result.
    **options
        For "frfc" (defaults in :data:`FRFC_DEFAULTS`):

        cell_factor : float, default 1.0
            c in the sampling cell side c f(q) / (2 sqrt 2). Smaller samples
            more densely (the paper's guarantee needs c <= c5 of Lemma 3.4).
        radius : {"exact", "cheap"}, default "exact"
            Sample sphere radius f(x)/2 from the Apollonius graph, or the paper's
            cheaper (f(q) + |x - q|)/2.
        radius_scale : float in (0, 1], default 0.75
            Spheres are B(x, radius_scale f(x)/2). 1.0 is the paper's choice;
            0.75 packs tighter so that nn_M'(p) stays below 2 delta(p) nn_M(p)
            (see benchmarks/README.md for the measured ratios and sizes).
        boundary_scale : float in (0, 1], default 0.8
            Extra factor on spheres centred on segments: the boundary is a 1-D
            packing and needs a tighter one to resolve a refined boundary and to
            keep interior points from slipping between boundary spheres.
        repair_ratio : float >= 1 or None, default 1.75
            Spacing repair: a kept R-point p (delta < 1) without a kept point
            within repair_ratio delta(p) nn_M(p) gets one more point next to it
            (a candidate just outside its sphere). None or 0 disables it (the
            paper's plain packing).
        samples : {"random", "barycentre", "midpoints", "barycentre+midpoints"}
            "random": a random point in every grid cell (the paper); the others
            are the practical variations of Section 5.
        skip_coarse : bool, default False
            No samples in triangles whose three vertices have delta > 1.
        max_samples : float, default 5e7
            Refuse (ValueError) a step whose sampling would exceed this.
        threads : int or None
            Threads for spacing queries (None: all cores). Results do not
            depend on it.

    Returns
    -------
    Mesh
        The new mesh; ``origin`` maps its points to the input's (-1: new),
        ``kind`` labels them, ``stats`` holds stage timings and counts.

    Raises
    ------
    TypeError
        If mesh is not a :class:`Mesh`, delta is not real, an option is unknown
        or of the wrong type.
    ValueError
        If delta has the wrong shape or a NaN, infinite or out-of-range value,
        the method is unknown, an option value is out of range, or the step
        would need more than ``max_samples`` samples. The input is never modified.
    """
    _require_mesh(mesh)
    d = as_delta(mesh, delta)
    seed = _check_seed(seed)
    if method != "frfc":
        raise ValueError(f"unknown method {method!r}; available: 'frfc'")
    o = _frfc_options(options)
    result = _core.frfc(
        mesh.points,
        mesh.triangles,
        mesh.segments,
        mesh.segment_is_boundary.astype(np.uint8),
        mesh.kind,
        d,
        seed=seed,
        cell_factor=float(o["cell_factor"]),
        exact_radius=o["radius"] == "exact",
        sample_mode=_SAMPLE_MODES[o["samples"]],
        skip_coarse_triangles=bool(o["skip_coarse"]),
        threads=o["threads"] or 0,
        max_samples=float(o["max_samples"]),
        radius_scale=float(o["radius_scale"]),
        boundary_radius_scale=float(o["boundary_scale"]),
        repair_ratio=float(o["repair_ratio"]),
    )
    stats = dict(result["stats"])
    return Mesh._trusted(
        result["points"],
        result["triangles"],
        result["segments"],
        result["segment_is_boundary"],
        result["kind"],
        result["origin"],
        stats,
    )
