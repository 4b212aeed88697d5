"""One evolution step: refine where delta < 1, coarsen where delta > 1."""

from __future__ import annotations

import copy
import numbers
from typing import TYPE_CHECKING, Any, overload

import numpy as np

from evomesh import _core
from evomesh.geometry import as_geometry
from evomesh.mesh import Lineage, Mesh, PointKind, check_boundary_not_pinched, check_mesh_limits
from evomesh.mesh_quality import QualityWarning, _warn_quality
from evomesh.motion import after_step, step_input
from evomesh.spacing_function import _require_mesh, as_delta, delta_from_size
from evomesh.tet_evolution import evolve_tet
from evomesh.tet_mesh import TetMesh

if TYPE_CHECKING:  # mpi4py is optional: the distributed mesh is imported for the type only
    from evomesh.distributed.mesh import DistributedMesh

__all__ = ["evolve", "delaunay_refine", "make_options", "FRFC_DEFAULTS", "DRFC_DEFAULTS", "FrfcOptions", "DrfcOptions",
           "SampleMode", "RadiusRule", "QualityWarning"]

FrfcOptions = _core.FrfcOptions
DrfcOptions = _core.DrfcOptions
SampleMode = _core.SampleMode
RadiusRule = _core.RadiusRule

# Option values as Python users write them (and as FRFC_DEFAULTS shows them).
_SAMPLE_NAMES = {
    "random": SampleMode.random,
    "barycentre": SampleMode.barycentre,
    "midpoints": SampleMode.midpoints,
    "barycentre+midpoints": SampleMode.barycentre_midpoints,
}
_RADIUS_NAMES = {"exact": RadiusRule.exact, "cheap": RadiusRule.cheap, "interpolated": RadiusRule.interpolated}
_ENUMS: dict[str, tuple[type, dict[str, Any]]] = {"samples": (SampleMode, _SAMPLE_NAMES), "radius": (RadiusRule, _RADIUS_NAMES)}
# Options that are not keyword overrides of evolve (evolve has its own seed argument).
_NOT_KEYWORDS = ("seed",)


def _python_value(name: str, value: Any) -> Any:
    """An option field as FRFC_DEFAULTS shows it (strings for enums, None for "off"/"default")."""
    if name in _ENUMS:
        return next(key for key, member in _ENUMS[name][1].items() if member == value)
    if name == "threads":
        return value or None
    if name in ("repair_ratio", "gap_repair_ratio", "refine_gap_ratio", "demote_ratio"):
        return value or None
    return value


def _as_dict(options: Any) -> dict[str, Any]:
    return {name: _python_value(name, getattr(options, name)) for name in type(options).fields if name not in _NOT_KEYWORDS}


#: Options of method="frfc" and their defaults (FrfcOptions.recommended(); read-only view).
FRFC_DEFAULTS: dict[str, Any] = _as_dict(FrfcOptions.recommended())
#: Options of method="drfc" and their defaults (DrfcOptions.recommended()).
DRFC_DEFAULTS: dict[str, Any] = _as_dict(DrfcOptions.recommended())


def _set_field(options: Any, name: str, value: Any) -> None:
    """options.name = value, with the type checks and conversions of the Python API
    (range checks are the core's: Options.validate())."""
    default = getattr(type(options)(), name)
    if name in _ENUMS:
        enum, names = _ENUMS[name]
        if not isinstance(value, enum):
            if value not in names:
                raise ValueError(f"{name} must be one of {', '.join(map(repr, names))}, got {value!r}")
            value = names[value]
    elif name == "threads":
        if value is None:
            value = 0
        elif isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral) or not 1 <= value < 2**31:
            raise ValueError(f"threads must be None or an integer in [1, 2**31), got {value!r}")
    elif name in ("repair_ratio", "gap_repair_ratio", "refine_gap_ratio", "demote_ratio") and value is None:
        value = 0.0
    elif isinstance(default, bool):
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{name} must be a bool, got {type(value).__name__}")
        value = bool(value)
    elif isinstance(default, float):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
            raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
        value = float(value)
    elif isinstance(default, int):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
            raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
        value = int(value)
    setattr(options, name, value)


def make_options(method: str, options: Any = None, **overrides: Any) -> Any:
    """The validated option object of a method: ``options`` (an
    :class:`FrfcOptions`/:class:`DrfcOptions`, copied; default ``recommended()``)
    with keyword ``overrides`` applied. Raises TypeError for an unknown option or
    a value of the wrong type, ValueError for one out of range."""
    types = {"frfc": FrfcOptions, "drfc": DrfcOptions}
    if method not in types:
        raise ValueError(f"unknown method {method!r}; available: 'frfc', 'drfc'")
    kind = types[method]
    if options is None:
        result = kind.recommended()
    elif isinstance(options, kind):
        result = copy.copy(options)
    else:
        raise TypeError(f"options of method {method!r} must be a {kind.__name__}, got {type(options).__name__}")
    known = [name for name in kind.fields if name not in _NOT_KEYWORDS]
    unknown = sorted(set(overrides) - set(known))
    if unknown:
        raise TypeError(f"unknown option(s) for method {method!r}: {', '.join(unknown)}; known: {', '.join(known)}")
    for name, value in overrides.items():
        _set_field(result, name, value)
    try:
        result.validate()
    except ValueError as error:
        raise ValueError(f"{error} (method {method!r})") from None
    return result


def _check_seed(seed: Any) -> int:
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise TypeError(f"seed must be an integer, got {type(seed).__name__}")
    if not 0 <= int(seed) < 2**64:
        raise ValueError(f"seed must be in [0, 2**64), got {seed}")
    return int(seed)


@overload
def evolve(mesh: TetMesh, delta: Any = None, *, size: Any = None, method: str = "frfc", seed: int | None = None,
           options: Any = None, geometry: Any = None, displacement: Any = None, interface: Any = None,
           interface_tag: int | None = None, interface_regions: Any = None, interface_band: Any = None,
           **overrides: Any) -> TetMesh: ...
@overload
def evolve(mesh: DistributedMesh, delta: Any = None, *, size: Any = None, method: str = "frfc", seed: int | None = None,
           options: Any = None, geometry: Any = None, displacement: Any = None, interface: Any = None,
           interface_tag: int | None = None, interface_regions: Any = None, interface_band: Any = None,
           **overrides: Any) -> DistributedMesh: ...
@overload
def evolve(mesh: Mesh, delta: Any = None, *, size: Any = None, method: str = "frfc", seed: int | None = None,
           options: Any = None, geometry: Any = None, displacement: Any = None, interface: Any = None,
           interface_tag: int | None = None, interface_regions: Any = None, interface_band: Any = None,
           **overrides: Any) -> Mesh: ...
def evolve(mesh: Any, delta: Any = None, *, size: Any = None, method: str = "frfc", seed: int | None = None,
           options: Any = None, geometry: Any = None, displacement: Any = None, interface: Any = None,
           interface_tag: int | None = None, interface_regions: Any = None, interface_band: Any = None,
           **overrides: Any) -> Any:
    """Evolve a mesh one step: new spacing delta(p) * nn_M(p) at every point p
    (or the target edge length ``size``).

    Parameters
    ----------
    mesh : Mesh or DistributedMesh
        The current mesh. A :class:`~evomesh.DistributedMesh` (every rank calls
        evolve with delta over its owned points, a scalar, or a function of the
        owned coordinates) is stepped on its ranks without gathering it and
        returns a DistributedMesh whose ``gather()`` is this function's result
        on the gathered mesh, bit for bit, on any number of ranks, with any
        FRFC options, delta or size and curved boundaries (``geometry``;
        evomesh.distributed.step); tags, required points, origin and the
        lineage come along, and a step that returns its input keeps its order.
        Every other argument (a scalar delta or size too, and their kind) must
        be the same on every rank, but ``threads`` (each rank's own thread
        limit, see ``threads`` below): a difference raises the
        same ValueError on every rank before any work, naming the argument
        and the ranks. The quality pass (with ``quality``, the default) runs
        on rank 0 on the gathered kept points and pieces
        (docs/distributed-step.md 3.11).
    delta : array_like, shape (n,), or a scalar
        Per-point factor, relative to the current spacing: the new spacing
        (nearest-neighbour distance) at p is about delta(p) nn_M(p); < 1
        refines (R-points), > 1 coarsens (C-points), 1 keeps the mesh as it is
        there (on evomesh's own output a step with delta = 1 returns it
        unchanged, arrays and all). Every value must be finite and in [:data:`~evomesh.spacing_function.DELTA_MIN`,
        :data:`~evomesh.spacing_function.DELTA_MAX`] = [1e-6, 1e6] (the paper's bounds
        l <= delta <= L); in addition a step whose sampling would create more
        than ``max_samples`` candidate points is refused (refine over several
        steps instead).
    size : float, array_like of shape (n,), or callable, optional
        Target edge length h instead of ``delta`` (exactly one of the two),
        as MMG and Gmsh mean a size: a number, one value per point, or a
        function h(x) of an (n, 2) array of coordinates returning (n,) values.
        The output's median edge length over h is within about 10 % of 1.
        Where the mesh already meets h (its edges within a factor 1.25 finer
        to 1.25 coarser of it) it is left as it is, so the same ``size`` step
        after step changes next to nothing (at most 0.1 % of the points at
        the second step, none from the third on, where the first step's input
        was within about twice h; a step more per halving where it was
        coarser). Where the mesh is finer than that (a fine request or an
        interface band has passed) it coarsens back to h in one or two steps,
        the points next to it that lie within the tolerance too. The factor
        this stands for is
        :func:`~evomesh.spacing_function.delta_from_size` (which says how);
        one step still changes the spacing by at most the factors above.
    method : {"frfc", "drfc"}
        "frfc": Functional-Refining-Functional-Coarsening (paper, Section 3.2).
        "drfc": Delaunay-Refining-Functional-Coarsening (Section 5): Delaunay
        refinement with Ruppert's rules and rule 4 (see :func:`delaunay_refine`),
        then the one-level coarsening of Miller, Talmor and Teng on the refined
        points (lexical-first MIS of B(p, radius_scale f(p)/2), boundary first,
        then original, Steiner and new points) and a constrained Delaunay
        triangulation; no samples are added in the coarsening.
    seed : int, optional
        Seed of the sampling (default: ``options.seed``, 0); the same mesh,
        delta, options and seed give a bit-identical result. ("drfc" draws no
        random numbers.)
    options : FrfcOptions or DrfcOptions, optional
        All options of the method at once (copied, never modified); default
        ``recommended()``. ``FrfcOptions.paper()`` / ``DrfcOptions.paper()``
        run the paper's algorithms exactly. The fields are those of the C++
        core (``cpp/include/evomesh/options.hpp``), which also validates them.
    **overrides
        Single options on top of ``options``, by field name. For "frfc" (defaults in :data:`FRFC_DEFAULTS`):

        cell_factor : float, default 2.0
            c in the sampling cell side c f(q) / (2 sqrt 2). Smaller samples
            more densely: the paper's dense-sample Lemma 4.3 needs c <= c5 <= 1
            (Lemma 3.4), which 1.0 approaches. 2.0 (cell diagonal f(q)) draws a
            quarter of the samples; on the growing circle and a 1e5-point graded
            step it gives the same angles and spacing ratios and 1-2% fewer
            points (benchmarks/METHODS.md).
        radius : {"interpolated", "exact", "cheap"}, default "interpolated"
            Sample sphere radius f(x)/2 from the Apollonius graph ("exact", the
            paper), the paper's cheaper (f(q) + |x - q|)/2, or ("interpolated")
            f(x)/2 except in triangles with a demoted vertex, where the
            size follows the linear interpolation l of f at the vertices:
            min(f, max(1.2 l, f / 1.3))/2. f is a minimum of cones of slope 1, so
            between old points it exceeds the request by up to their spacing;
            with it, delta = 0.8 on a uniform mesh keeps the old spacing.
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
        gap_repair_ratio : float >= 1 or None, default 1.1
            Gap repair: an input point p with delta(p) >= 1 whose
            second nearest output point (the paper's nn_M'(p); the nearest other
            one when p is kept) lies beyond gap_repair_ratio delta(p) nn_M(p)
            gets one more point at distance delta(p) nn_M(p) (of eight
            directions, inside the mesh and seen from p, the one farthest from
            the output points, if at least 0.6 delta(p) nn_M(p) from them).
            None or 0 disables it.
        refine_gap_ratio : float >= 1 or None, default 1.3
            The same, at this ratio, for points with delta(p) < 1 that were
            demoted (see demote_ratio) or dropped: where a fresh packing forms
            its spacing varies more, and a tighter bound adds points that
            compound over repeated steps (ten steps of delta = 0.8). None or 0
            disables it.
        demote_ratio : float >= 1 or None, default 1.1
            An old point p with nn_M(q) > demote_ratio f(q) at p and at all its
            mesh neighbours q (the request refines its whole neighbourhood)
            loses the priority of old points and is packed by size with the new
            points, so a fresh packing can form there; elsewhere old points come
            first as in the paper. None or 0: old points always first (the paper).
        samples : {"random", "barycentre", "midpoints", "barycentre+midpoints"}
            "random": a random point in every grid cell (the paper); the others
            are the practical variations of Section 5.
        skip_coarse : bool, default False
            No samples in triangles whose three vertices have delta > 1.
        skip_settled : bool, default True
            No samples in triangles (on segments) whose every vertex is
            settled: delta = 1 and f = nn_M = its shortest edge, the request
            there being the spacing the mesh has. A step is then idempotent on
            its own output: with delta = 1 (or a ``size`` that the mesh meets)
            it keeps every point, adds none and returns the same triangles
            (the argument is in cpp/src/candidates.cpp). False: the
            paper's sampling, which adds points wherever a sphere fits between
            the old ones (a few per thousand points, step after step).
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
            started beside the packing); None: evomesh.default_thread_count()
            (EVOMESH_NUM_THREADS, else OMP_NUM_THREADS, else the CPUs this
            process may use: affinity and cgroup quota), 1: everything on
            the calling thread. At most this many threads work at once, also
            counting those the step starts beside its stages (several
            processes per node can so share the cores). Results do not
            depend on it. On a DistributedMesh it is each rank's own (ranks
            may differ); None there: EVOMESH_NUM_THREADS (else
            OMP_NUM_THREADS) per rank, else the rank's share of its node's
            CPUs (evomesh.distributed.threads.rank_thread_count).
        quality : bool, default True
            The quality pass (Section 6's suggestion, for both methods): a
            point that sees a segment under more than 120 degrees is dropped and
            the segment split at its midpoint instead; then Delaunay refinement
            (CGAL's mesher: Ruppert's rules 1 and 3) splits every triangle with an
            angle below ``min_angle``. There is no size criterion, so new points
            follow the spacing of the selected points, except where the
            domain's features need more (a channel narrower than that spacing
            gets points at its width). Where segments (boundary or interior)
            meet under less than 60 degrees, the pass stops after
            ``quality_max_fraction`` n + ``quality_max_extra`` (0.5 n + 1000)
            insertions at most and the small angles stay near the small input
            angles. Where no two segments meet under less than 60 degrees
            (consecutive around their common point, measured on either side)
            Ruppert's rules end, and the result has no angle below
            ``min_angle`` with exactly these exceptions: triangles within
            16384 units of rounding of flat (features at the limit of float64)
            are not split for their angles; the pass stops (``quality_capped``
            = 1, a :class:`QualityWarning`) after that bound plus twice F,
            at most 64 n + 10**6, where F estimates the points Ruppert's rules
            need from the constrained Delaunay triangulation of the selected
            points: the sum over its triangles of longest edge**2 / (4 area)
            and over its segment pieces e of |e| / h (h the height of the
            triangle on e) (measured: 1.5 to 40 times what the pass inserts;
            a channel of width w and length L asks for about 2 L / w points);
            CGAL's mesher may fail on near-degenerate geometry
            (``quality_failed`` = 1, a warning); and with ``geometry`` the new
            boundary points move onto their curves after the pass, which
            changes the angles next to the curve (28.6 instead of 30 degrees
            measured after coarsening a disc by 3).
            ``stats`` reports ``quality_points_added`` (``_on_segments``),
            ``quality_points_removed``, ``quality_capped``. False reproduces the
            paper's algorithm.
        within_domain : bool, default True
            Spacing within the domain: nn_M(p) of a point whose nearest point
            hides behind a constraint (across a slit or a thin wall) is its
            shortest edge, and the spacing is capped by the domain's local
            feature size, measured through the domain (a channel's width, a
            short side, the spacing at which a curved boundary piece turns by
            the geometry's corner angle). False: the paper's Euclidean nn_M.
            :attr:`Mesh.nn_spacing` (and so ``size=``) measures within the
            domain either way.
        min_angle : float in (0, 30], default 30.0 (FRFC; 20.0 for DRFC)
            Target smallest angle in degrees (Ruppert's algorithm provably ends
            up to about 20.7 degrees; beyond that the bound on inserted points
            stops it; CGAL's off-centres end in practice up to 30). FRFC's
            default 30 (was 20) costs a few % more points on smooth
            size maps and up to about half more on rough ones.
        quality_rounds : bool, default False
            The quality pass in rounds of independent insertions
            (docs/distributed-step.md section 3.6): each round splits the
            lexical-first maximal independent set (sub-segments first, then the
            worst triangles; two conflict when their cavities share a triangle
            or an edge) of the bad triangles and encroached sub-segments of the
            mesh at the round's start. Its output is a function of the selected
            points and pieces as sets (their order does not matter), which a
            partitioned step needs; the same rules, bound and budget as the
            serial pass, about as many points, a different output.
            ``stats`` adds ``quality_rounds``, ``quality_stalled`` (a round could
            insert nothing with bad triangles left) and ``quality_round_limit``.

        incremental : bool, default True
            Where delta = 1 on most of the mesh (at least half of the points),
            skip the work that certainly changes nothing there (the
            Apollonius graph holds only the sites near the points where f is
            asked, triangles whose samples the packing certainly rejects are not
            sampled, the packing and the spacing repair run near spheres whose
            fate is not certain; cpp/include/evomesh/incremental_step.hpp).
            Without the quality pass (``quality=False``, the paper's options)
            the triangulation is the input's, updated in the cavity where points
            came and went, and certified (every piece an edge, every other edge
            strictly Delaunay) or else built whole
            (``triangulation_update_declined``: 0 when updated). The output is
            the full algorithm's, bit for bit; only ``stats`` differ
            (``incremental_region_points``, ``incremental_quiet_triangles``, ...
            when it was used). Not used with ``geometry``. False: always the
            full algorithm.

        For "drfc" (defaults in :data:`DRFC_DEFAULTS`): ``min_angle`` (also the
        shape criterion of the refinement stage), ``quality``, ``quality_rounds``, ``within_domain``, ``max_samples``
        (refuse a step whose refinement needs more points), ``threads`` as
        above, and

        radius_scale : float in (0, 1], default 0.75
            Spheres B(p, radius_scale f(p)/2) of the coarsening; 1.0 is Miller,
            Talmor and Teng's, 0.75 is FRFC's default, so the two methods compare
            at equal sphere sizes.

        Every output's ``stats`` holds ``min_angle`` (degrees) and its location
        ``min_angle_x``, ``min_angle_y`` (centroid of the triangle that has it).
    geometry : BoundaryGeometry or mapping of segment tag to curve, optional
        Curved boundaries (:mod:`evomesh.geometry`; "frfc" only): boundary
        vertices of the curved tags that turn by less than the geometry's
        ``corner_angle`` may be removed, and every boundary point the step
        creates there lies on the curve. ``stats`` then also holds
        ``curve_points_projected``, ``curve_largest_move`` and
        ``curve_points_dropped_outside`` (interior points a coarser curved
        boundary left outside). Without it the polygon is the domain, exactly.
        With ``displacement``: the curves after the move.
    displacement : array_like of shape (n, 2) or (2,), or callable, optional
        Lagrangian motion: every point p (boundary, interface and
        interior) first moves to p + u(p), then the moved mesh evolves
        (``delta`` and ``size`` arrays are per point of ``mesh``; ``delta`` is
        relative to nn_M before the move, so 1 keeps the resolution however
        the motion squeezed or stretched the mesh; a callable size is
        evaluated at the moved points). u is given at the points, as
        one (dx, dy) for all, or as a function u(x) of an (n, 2) array. A point
        all of whose segments carry one curved tag of ``geometry`` is
        projected onto that curve after the move. Where the motion folds
        triangles (turns one over, or flattens it) the folded region is
        remeshed instead of refused (:func:`evomesh.motion.move`). The
        output's ``origin`` still names the old point each kept point came
        from (it is not at its old coordinates), and its ``lineage``
        (``lineage.moved``) locates every new point in ``mesh`` at the OLD
        positions: :func:`evomesh.transfer` and :func:`evomesh.transfer_cells`
        remap fields from the old mesh as it was (Eulerian; ``frame=
        "lagrangian"`` carries P1 values with the points instead).
        ``stats`` adds the ``motion_*`` counts of :class:`evomesh.motion.Motion`.
    interface : callable, LevelSet, or array_like of shape (n,), optional
        A level-set interface ("frfc" only): phi(x) on (k, 2)
        arrays (or an :class:`evomesh.LevelSet`), or its values at the mesh
        points. Its zero set becomes interior segments of tag ``interface_tag``
        and every triangle gets the region tag of its side. The mesh is first
        cut along phi = 0 (crossings on the edges where phi changes sign: by
        bracketed root finding to 1e-14 of the coordinate scale for a
        function, linearly for values; phi = 0 exactly at points and along
        whole edges is the interface there), the previous interface (interior
        segments of ``interface_tag``) is released so that its points can be
        removed like any other, and the step runs with the interface as a
        curve: every point it creates on it lies on phi = 0 (within a few
        units of rounding for a function; on the piecewise-linear zero set of
        the values), except where the zero set is not a curve at the local
        spacing (two circles touching) or its move onto phi = 0 would make
        the interface cross or fold onto itself (a filament or gap narrower
        than the spacing): there a point stays on its chord
        (``curve_points_left_on_chords``, ``curve_samples_left_on_chords``,
        and ``interface_points_off_curve``, ``interface_largest_off_curve``:
        interface points farther than 8 units of rounding from phi = 0). The
        spacing comes from ``delta``/``size`` at the old points as usual
        (absolute: the cut's short edges next to crossings do not refine;
        a request out of range against the old mesh's spacing raises as
        without an interface, and a factor out of range only against a
        crossing's short edge is clamped, counted in
        ``interface_delta_clamped``),
        capped near the interface by its local feature size (the distance
        across the domain to the next piece of the interface, its own other
        side included: a filament, a narrow ring or a short wave is resolved
        as the step's points see it). The interface is closed (or ends on the
        boundary): an old point is moved onto a crossing only where that
        leaves it on exactly two interface segments and leaves every
        component of one sign of phi a point of its sign, so a component
        around a single point (smaller than the spacing) is meshed; a
        component between the points (inside one triangle) is not seen.
        Where the smallest angle stays below ``min_angle`` (quality pass
        neither capped nor failed), ``interface_angle_exception`` says which
        exception applied, and ``interface_min_angle`` (``_x``, ``_y``) how
        small and where: 2 when only triangles next to where the interface
        meets the boundary or another constraint are below it (small input
        angles), 1 elsewhere next to the interface (the exception for curves
        above: the refits did not restore the angle, or points were left on
        their chords), with a :class:`QualityWarning` below 0.9 ``min_angle``. phi is called in vectorised
        batches: once at the points, once per round of the root finding on
        the crossed edges (typically 10-30, at most 200) and once per Newton
        round of each projection (one batch of the points and their four
        finite-difference neighbours, or phi and the gradient of a
        LevelSet; typically 2-6 rounds, at most ``max_iterations``, for the
        segment samples and each of up to three fits), and once for the
        report; ``interface_phi_calls`` counts them. Several components,
        merging and splitting work. ``new.lineage``
        refers to ``mesh``, so :func:`evomesh.transfer` and
        :func:`evomesh.transfer_cells` work across the move. ValueError when
        phi is not finite, has no sign change on the mesh, or its zero set
        meets the boundary (or another constraint) at less than 5 degrees or
        runs along it without crossing (tangent). ``stats`` adds
        ``interface_crossings``, ``interface_points_moved`` (old points moved
        onto a crossing of one of their edges within a tenth of that edge's
        length: the crossing's sphere would remove them anyway, and the cut
        gets no edge shorter than that), ``interface_segments``,
        ``interface_negative_tag`` and ``interface_positive_tag`` (the region
        tags, as ints: exact beyond 2**53) and ``curve_refits`` (rounds of the quality
        pass after points were projected, so that angles stay above
        ``min_angle``).
    interface_tag : int, optional
        Segment tag of the interface (default :data:`evomesh.INTERFACE_TAG`,
        -1). Keep it from step to step: interior segments of this tag are the
        previous interface, which the next step releases. To name it (in
        files, ``evomesh info``), name the tag in the mesh:
        ``mesh.with_tag_names({**mesh.tag_names, (1, tag): "interface"})``;
        every step keeps the names.
    interface_regions : (int, int), optional
        Triangle tags of the negative and the positive side of phi. Default:
        of the mesh's regions, the one where phi is lowest on average for the
        negative side and the one where it is highest for the positive side,
        so a moving interface keeps its two tags; with one region (the first
        step) the negative side gets a new tag, the largest plus one. Every
        triangle gets the tag of its side (other regions are not kept).
    interface_band : (width, spacing) or (width, spacing, grade), optional
        Spacing ``spacing`` within ``width / 2`` of the interface, growing by
        ``grade`` (default 0.3) per unit of distance beyond; the spacing of
        ``delta``/``size`` where that is smaller.

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
        would need more than ``max_samples`` samples; for a displacement, as
        :func:`evomesh.motion.move` (NaN/inf values, points moved out of the
        domain, crossing boundaries). The input is never modified.
    """
    if type(mesh).__name__ == "DistributedMesh":  # (not imported here: mpi4py is optional)
        from evomesh.distributed.step import evolve_distributed

        def build_options() -> Any:  # (on every rank, once the ranks agree on the arguments)
            o = make_options("frfc", options, **overrides)
            if seed is not None:
                o.seed = _check_seed(seed)
            return o

        # Every argument goes to the ranks' agreement (displacement and interface are refused there, on every rank).
        return evolve_distributed(mesh, delta, size=size, method=method,
                                  build_options=build_options, geometry=geometry, arguments=dict(
                                      seed=seed, options=options, overrides=overrides, displacement=displacement,
                                      interface=interface, interface_tag=interface_tag,
                                      interface_regions=interface_regions, interface_band=interface_band))
    if isinstance(mesh, TetMesh):
        extra = [name for name, value in (("geometry", geometry), ("displacement", displacement),
                                          ("interface", interface), ("interface_tag", interface_tag),
                                          ("interface_regions", interface_regions),
                                          ("interface_band", interface_band)) if value is not None]
        if extra or method != "frfc":
            raise ValueError(f"not yet on a TetMesh: {', '.join(extra) or 'method=' + repr(method)}")
        return evolve_tet(mesh, delta, size=size, seed=seed, options=options, **overrides)
    _require_mesh(mesh)
    if (delta is None) == (size is None):
        raise TypeError(
            "evolve needs exactly one of delta (a real numeric factor per point, relative to the current spacing) "
            "and size (an absolute spacing)"
        )
    if interface is not None:
        if method != "frfc":
            raise ValueError("interface (a level-set interface) is supported by method='frfc' only")
        if displacement is not None:
            raise ValueError(
                "interface= and displacement= cannot be combined in one step: move the mesh first "
                "(evolve(mesh, ..., displacement=u)), then give the interface on the moved mesh"
            )
        from evomesh.interface import evolve_with_interface  # (it calls evolve: imported here, not at the top)

        return evolve_with_interface(mesh, delta, size, interface, interface_tag, interface_regions, interface_band,
                                     geometry, evolve, method=method, seed=seed,
                                     options=make_options(method, options, **overrides))
    if interface_tag is not None or interface_regions is not None or interface_band is not None:
        raise TypeError("interface_tag, interface_regions and interface_band need interface (phi)")
    old, motion = mesh, None
    if displacement is not None:  # Lagrangian motion: move the points, then evolve the moved mesh
        motion, delta, size = step_input(mesh, displacement, delta, size, as_geometry(geometry))
        mesh = motion.mesh
    d = as_delta(mesh, delta) if size is None else delta_from_size(mesh, size, keep_fine_clusters=motion is None)
    o = make_options(method, options, **overrides)
    if method == "frfc" and seed is not None:
        o.seed = _check_seed(seed)
    g = as_geometry(geometry)
    if g is not None and method != "frfc":
        raise ValueError("geometry (curved boundaries) is supported by method='frfc' only")
    core = _core.frfc if method == "frfc" else _core.drfc
    result = core(mesh.points, mesh.triangles, mesh.segments, mesh.segment_is_boundary.astype(np.uint8), mesh.kind, d, o,
                  **mesh._labels(), **mesh._known_nn(), **({} if g is None else g._core_arguments()),
                  strictly_delaunay=mesh._delaunay)
    new = _wrap(result, mesh)
    return new if motion is None else after_step(old, motion, new)


def _wrap(result: dict[str, Any], old: Mesh | None = None, tag_names: Any = None) -> Mesh:
    # Every output satisfies the limits Mesh() puts on inputs, or the step fails
    # here, saying why (a square of side 1e-70 refined step after step).
    # The step brings its output's nn (Euclidean, and within the domain where that is larger).
    # A step that returned its input: the input's Mesh passed these checks.
    unchanged = old is not None and _is_the_input(result, old)
    known = result.get("output_nn")
    if known is not None and len(known) != len(result["points"]):
        known = None
    if not unchanged:
        try:
            nn = check_mesh_limits(result["points"], result["triangles"], known)
            check_boundary_not_pinched(result["points"], result["segments"], result["segment_is_boundary"],
                                       result["kind"])
        except ValueError as error:
            raise ValueError(
                f"the step's output is not a valid mesh in float64: {error}. The requested spacing is beyond what "
                "float64 resolves at these coordinates; rescale the mesh (or translate it towards the origin) or "
                "refine less"
            ) from None
    _warn_quality(result["stats"], stacklevel=4)
    if unchanged:
        assert old is not None
        return _wrap_unchanged(result, old)
    lineage = None
    if old is not None and "parent_triangle" in result:
        lineage = Lineage(old.n_points, old.n_triangles, result["parent_triangle"], result["barycentric"],
                          result["input_nn"], result["input_f"])
    nn_grew = None
    if known is not None:
        nn_grew = result["output_nn_grew"]
        nn[nn_grew] = result["output_nn_grown"]  # (the step's own array: nn within the domain)
    return Mesh._trusted(
        result["points"],
        result["triangles"],
        result["segments"],
        result["segment_is_boundary"],
        result["kind"],
        result["origin"],
        dict(result["stats"]),
        lineage,
        nn,
        result.get("segment_tags"),
        result.get("triangle_tags"),
        result.get("required"),
        nn_grew,
        tag_names=tag_names if old is None else old.tag_names,  # the tags are the input's: so are their names
        delaunay=bool(result.get("triangulation_certified", False)),
    )


_UNCHANGED_ARRAYS = ("points", "triangles", "segments", "segment_is_boundary", "segment_tags", "triangle_tags",
                     "required")


def _is_the_input(result: dict[str, Any], old: Mesh) -> bool:
    """The step says its output is its input (its result's ``unchanged``: the same
    points in the same order, the input's triangles and segments, cpp/src/step.cpp
    adopt_input_order) and its arrays are the input's, bit for bit, but for the
    kinds (a step labels the points it sampled as Steiner points when it keeps
    them), with the same corners (what the boundary check reads). O(n)
    comparisons, against the O(n log n) checks they spare."""
    if not result.get("unchanged", False) or not np.array_equal(result["origin"], np.arange(old.n_points)):
        return False
    kind = np.asarray(result["kind"])
    if kind.shape != old.kind.shape or not np.array_equal(kind == PointKind.CORNER, old.kind == PointKind.CORNER):
        return False
    for name in _UNCHANGED_ARRAYS:
        value = result.get(name)
        mine = getattr(old, name)
        if value is None:  # (an unused label: the input's is all zeros)
            if mine.any():
                return False
        elif not (np.shape(value) == mine.shape and np.array_equal(value, mine)):
            return False
    return True


def _wrap_unchanged(result: dict[str, Any], old: Mesh) -> Mesh:
    """The output Mesh of a step that returned its input (_is_the_input): the
    input Mesh's arrays (immutable, so shared, not copied; the step's kinds),
    its nn, its tag names. The input passed the checks _wrap makes (Mesh() or _wrap made it);
    the same arrays pass them again, so they are not made again (~10 ms at 5e4
    points: flat, inverted and pinched elements, point distances)."""
    lineage = None
    if "parent_triangle" in result:
        lineage = Lineage(old.n_points, old.n_triangles, result["parent_triangle"], result["barycentric"],
                          result["input_nn"], result["input_f"])
    nn, nn_grew = old._nn, old._nn_grew
    if nn is None and result.get("output_nn") is not None and len(result["output_nn"]) == old.n_points:
        nn, nn_grew = np.array(result["output_nn"]), result["output_nn_grew"]
        nn[nn_grew] = result["output_nn_grown"]
    kind = old.kind if np.array_equal(result["kind"], old.kind) else result["kind"]
    return Mesh._trusted(old.points, old.triangles, old.segments, old.segment_is_boundary, kind, result["origin"],
                         dict(result["stats"]), lineage, nn, old.segment_tags, old.triangle_tags, old.required, nn_grew,
                         tag_names=old.tag_names,
                         delaunay=old._delaunay or bool(result.get("triangulation_certified", False)))


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
        ``capped`` (1 if it stopped at its bound, twice the estimate). The
        input's labels carry over as in :func:`evolve`: a new segment has the
        tag of the input segment it splits (``segment_tags``), a triangle the
        tag of the input triangle's region it lies in (``triangle_tags``),
        every input point keeps its ``required`` flag (refinement never moves
        or removes a point), and the ``tag_names`` are the input's.
    """
    _require_mesh(mesh)
    d = as_delta(mesh, delta)
    o = make_options("drfc", min_angle=min_angle, max_samples=max_samples, threads=threads)
    result = _core.drfc_refine(
        mesh.points, mesh.triangles, mesh.segments, mesh.segment_is_boundary.astype(np.uint8), mesh.kind, d, o,
        **mesh._labels(),
    )
    return _wrap(result, tag_names=mesh.tag_names)
