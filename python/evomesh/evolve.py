"""One evolution step: refine where delta < 1, coarsen where delta > 1."""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from evomesh import _core
from evomesh.mesh import Mesh, check_mesh_limits
from evomesh.spacing import _require_mesh, as_delta

__all__ = ["evolve", "delaunay_refine", "FRFC_DEFAULTS", "DRFC_DEFAULTS"]

_SAMPLE_MODES = {"random": 0, "barycentre": 1, "midpoints": 2, "barycentre+midpoints": 3}
_RADII = ("exact", "cheap")

#: Options of method="frfc" and their defaults.
FRFC_DEFAULTS: dict[str, Any] = {
    "cell_factor": 2.0,
    "radius": "exact",
    "radius_scale": 0.75,
    "boundary_scale": 0.8,
    "repair_ratio": 1.75,
    "samples": "random",
    "skip_coarse": False,
    "filter_samples": True,
    "max_samples": 5e7,
    "threads": None,
    "quality": True,
    "min_angle": 20.0,
}

#: Options of method="drfc" and their defaults.
DRFC_DEFAULTS: dict[str, Any] = {
    "min_angle": 20.0,
    "radius_scale": 0.75,
    "quality": True,
    "max_samples": 5e7,
    "threads": None,
}

# Angles above this make Ruppert's refinement rely on its bound on inserted points.
_MAX_MIN_ANGLE = 30.0


def _check_real(o: dict[str, Any], name: str) -> None:
    value = o[name]
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be finite and > 0, got {value}")


def _check_common(o: dict[str, Any]) -> None:
    """Options shared by both methods: min_angle, quality, threads."""
    _check_real(o, "min_angle")
    if o["min_angle"] > _MAX_MIN_ANGLE:
        raise ValueError(f"min_angle must be in (0, {_MAX_MIN_ANGLE:g}], got {o['min_angle']}")
    if not isinstance(o["quality"], (bool, np.bool_)):
        raise TypeError("quality must be a bool")
    threads = o["threads"]
    if threads is not None and (
        isinstance(threads, bool) or not isinstance(threads, numbers.Integral) or not 1 <= threads < 2**31
    ):
        raise ValueError(f"threads must be None or an integer in [1, 2**31), got {threads!r}")


def _drfc_options(options: dict[str, Any]) -> dict[str, Any]:
    unknown = sorted(set(options) - set(DRFC_DEFAULTS))
    if unknown:
        raise TypeError(f"unknown option(s) for method 'drfc': {', '.join(unknown)}; known: {', '.join(DRFC_DEFAULTS)}")
    o = {**DRFC_DEFAULTS, **options}
    for name in ("radius_scale", "max_samples"):
        _check_real(o, name)
    if o["radius_scale"] > 1:
        raise ValueError(f"radius_scale must be in (0, 1], got {o['radius_scale']}")
    _check_common(o)
    return o


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
    for name in ("skip_coarse", "filter_samples"):
        if not isinstance(o[name], (bool, np.bool_)):
            raise TypeError(f"{name} must be a bool")
    _check_common(o)
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
    method : {"frfc", "drfc"}
        "frfc": Functional-Refining-Functional-Coarsening (paper, Section 3.2).
        "drfc": Delaunay-Refining-Functional-Coarsening (Section 5): Delaunay
        refinement with Ruppert's rules and rule 4 (see :func:`delaunay_refine`),
        then the one-level coarsening of Miller, Talmor and Teng on the refined
        points (lexical-first MIS of B(p, radius_scale f(p)/2), boundary first,
        then original, Steiner and new points) and a constrained Delaunay
        triangulation; no samples are added in the coarsening.
    seed : int
        Seed of the sampling; the same mesh, delta, options and seed give a
        bit-identical result. ("drfc" draws no random numbers.)
    **options
        For "frfc" (defaults in :data:`FRFC_DEFAULTS`):

        cell_factor : float, default 2.0
            c in the sampling cell side c f(q) / (2 sqrt 2). Smaller samples
            more densely: the paper's dense-sample Lemma 4.3 needs c <= c5 <= 1
            (Lemma 3.4), which 1.0 approaches. 2.0 (cell diagonal f(q)) draws a
            quarter of the samples; on the growing circle and a 1e5-point graded
            step it gives the same angles and spacing ratios and 1-2% fewer
            points (benchmarks/METHODS.md).
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
        filter_samples : bool, default True
            Drop interior samples that certainly overlap a kept sphere at a
            vertex of their triangle before computing their radius (f is
            1-Lipschitz, so their sphere cannot miss it). The output is
            bit-identical either way; on is faster and uses less memory.
        max_samples : float, default 5e7
            Refuse (ValueError) a step whose sampling would exceed this.
        threads : int or None
            Threads of the parallel stages (nn, Apollonius graph parts,
            sampling, spacing queries, the MIS tree, and the triangulation
            started beside the packing); None: all cores, 1: everything on
            the calling thread. Results do not depend on it.
        quality : bool, default True
            The quality pass (Section 6's suggestion, for both methods): a
            point that sees a segment under more than 120 degrees is dropped and
            the segment split at its midpoint instead; then Delaunay refinement
            (CGAL's mesher: Ruppert's rules 1 and 3) splits every triangle with an
            angle below ``min_angle``. There is no size criterion, so new points
            follow the spacing of the selected points. The result has no angle
            below ``min_angle`` whenever the domain has none below 60 degrees;
            otherwise the pass stops after 0.5 n + 1000 insertions at most and
            the small angles stay near the small input angles. ``stats`` reports
            ``quality_points_added`` (``_on_segments``), ``quality_points_removed``,
            ``quality_capped``. False reproduces the paper's algorithm.
        min_angle : float in (0, 30], default 20.0
            Target smallest angle in degrees (Ruppert's algorithm provably ends
            up to about 20.7 degrees; beyond that the bound on inserted points
            stops it).

        For "drfc" (defaults in :data:`DRFC_DEFAULTS`): ``min_angle`` (also the
        shape criterion of the refinement stage), ``quality``, ``max_samples``
        (refuse a step whose refinement needs more points), ``threads`` as
        above, and

        radius_scale : float in (0, 1], default 0.75
            Spheres B(p, radius_scale f(p)/2) of the coarsening; 1.0 is Miller,
            Talmor and Teng's, 0.75 is FRFC's default, so the two methods compare
            at equal sphere sizes.

        Every output's ``stats`` holds ``min_angle`` (degrees) and its location
        ``min_angle_x``, ``min_angle_y`` (centroid of the triangle that has it).

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
    if method == "drfc":
        o = _drfc_options(options)
        result = _core.drfc(
            mesh.points,
            mesh.triangles,
            mesh.segments,
            mesh.segment_is_boundary.astype(np.uint8),
            mesh.kind,
            d,
            min_angle=float(o["min_angle"]),
            radius_scale=float(o["radius_scale"]),
            threads=o["threads"] or 0,
            max_samples=float(o["max_samples"]),
            quality=bool(o["quality"]),
        )
        return _wrap(result)
    if method != "frfc":
        raise ValueError(f"unknown method {method!r}; available: 'frfc', 'drfc'")
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
        filter_samples=bool(o["filter_samples"]),
        threads=o["threads"] or 0,
        max_samples=float(o["max_samples"]),
        radius_scale=float(o["radius_scale"]),
        boundary_radius_scale=float(o["boundary_scale"]),
        repair_ratio=float(o["repair_ratio"]),
        quality=bool(o["quality"]),
        min_angle=float(o["min_angle"]),
    )
    return _wrap(result)


def _wrap(result: dict[str, Any]) -> Mesh:
    # Every output satisfies the limits Mesh() puts on inputs, or the step fails
    # here, saying why (issue 9: a square of side 1e-70 refined step after step).
    try:
        check_mesh_limits(result["points"], result["triangles"])
    except ValueError as error:
        raise ValueError(
            f"the step's output is not a valid mesh in float64: {error}. The requested spacing is beyond what "
            "float64 resolves at these coordinates; rescale the mesh (or translate it towards the origin) or "
            "refine less"
        ) from None
    return Mesh._trusted(
        result["points"],
        result["triangles"],
        result["segments"],
        result["segment_is_boundary"],
        result["kind"],
        result["origin"],
        dict(result["stats"]),
    )


def delaunay_refine(mesh: Mesh, delta: Any, *, min_angle: float = 20.0, max_samples: float = 5e7,
                    threads: int | None = None) -> Mesh:
    """DRFC's first step alone (paper, Section 5): Delaunay refinement towards delta.

    Ruppert's rules (split encroached segments at their midpoints, split
    triangles with an angle below ``min_angle`` at their circumcentres unless
    that encroaches a segment) and rule 4 in terms of the spacing function f of
    :func:`evomesh.spacing`: a triangle is split while the nearest neighbour of
    one of its vertices v is farther than f(v), so every point v of the result
    has a neighbour within f(v). At an input point p, f(p) = delta(p) nn_M(p)
    when delta(p) <= 1 (Lemma 3.1): the paper's rule; where delta(p) >= 1 it
    never triggers. No point is removed.

    Parameters
    ----------
    mesh : Mesh
    delta : array_like, shape (n,), or a scalar
    min_angle : float in (0, 30], default 20.0
    max_samples : float, default 5e7
        Refuse (ValueError) a refinement estimated to need more points.
    threads : int or None

    Returns
    -------
    Mesh
        The refined mesh: the input points first (same indices, ``origin`` =
        index), then the new points (``origin`` -1; kind BOUNDARY on segments,
        SAMPLED inside). ``stats``: ``points_added``,
        ``points_added_on_segments``, ``rounds`` (passes with exact f),
        ``capped`` (1 if it stopped at its bound, twice the estimate).
    """
    _require_mesh(mesh)
    d = as_delta(mesh, delta)
    o = {"min_angle": min_angle, "quality": True, "threads": threads, "max_samples": max_samples}
    _check_common(o)
    _check_real(o, "max_samples")
    result = _core.drfc_refine(
        mesh.points,
        mesh.triangles,
        mesh.segments,
        mesh.segment_is_boundary.astype(np.uint8),
        mesh.kind,
        d,
        min_angle=float(min_angle),
        threads=threads or 0,
        max_samples=float(max_samples),
    )
    return _wrap(result)
