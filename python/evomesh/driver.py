"""The moving-front time loop: one evolve() per step, fields carried along.

The paper's use case (Sections 1 and 6): at every time step the mesh is
refined ahead of a moving boundary and coarsened behind it.
"""

from __future__ import annotations

import csv
import numbers
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from scipy.spatial import cKDTree

from evomesh.evolution import evolve
from evomesh.fronts import CircleFront, Front, SpacingLaw
from evomesh.mesh import Mesh
from evomesh.mesh_quality import quality
from evomesh.spacing_function import _require_mesh, as_delta, nn_spacing
from evomesh.field_transfer import Interpolation

__all__ = [
    "Step",
    "Run",
    "Driver",
    "run",
    "step_statistics",
    "nn_at",
    "growing_circle",
    "GROWING_CIRCLE_DEFAULTS",
    "PAPER_TABLE1",
    "STATISTICS_COLUMNS",
]

#: Columns of the per-step statistics; the first six are the paper's Table 1.
STATISTICS_COLUMNS = (
    "iteration",
    "points",
    "original_points",
    "original_pct",
    "triangles",
    "min_angle_deg",
    "time",
    "max_radius_edge",
    "spacing_ratio_max",
    "spacing_ratio_p99",
    "seconds",
)

#: Table 1 of the paper: iteration, # points, # original points (kept from the
#: previous step), % original, # triangles, min angle (degrees).
PAPER_TABLE1 = (
    (1, 1416, 1084, 76.55, 2702, 17.29),
    (2, 1836, 1328, 72.33, 3542, 14.31),
    (3, 2183, 1487, 68.12, 4236, 14.86),
    (4, 2068, 1469, 71.03, 4006, 16.30),
    (5, 1625, 1198, 73.72, 3117, 10.23),
    (6, 1220, 878, 71.97, 2308, 14.36),
)


def nn_at(points: np.ndarray, probes: np.ndarray, tree: cKDTree | None = None) -> np.ndarray:
    """nn_M(x) at probe points: distance to the nearest mesh point other than x
    itself (x may or may not be a mesh point), shape (k,)."""
    tree = cKDTree(points) if tree is None else tree
    d, _ = tree.query(probes, k=2)
    return np.where(d[:, 0] == 0, d[:, 1], d[:, 0])


def step_statistics(old: Mesh, new: Mesh, delta: Any, *, nn_old: np.ndarray | None = None) -> dict[str, float]:
    """Statistics of one evolution step, as in the paper's Table 1 plus ours.

    Parameters
    ----------
    old, new : Mesh
        The mesh before and after the step (``new.origin`` indexes ``old``).
    delta : array_like, shape (old.n_points,)
        The factor applied to ``old``.
    nn_old : ndarray, optional
        ``nn_spacing(old)`` if already computed.

    Returns
    -------
    dict
        points, original_points (points of new kept from old, the paper's
        "# of original points"), original_pct (100 * original / points),
        triangles, min_angle_deg, max_radius_edge, and the spacing ratio
        nn_M'(p) / (delta(p) nn_M(p)) over the old points p: its maximum
        (spacing_ratio_max) and 99th percentile (spacing_ratio_p99). The
        paper's guarantee (Definition 2.6) is ratio <= 1 up to a constant.
    """
    _require_mesh(old)
    _require_mesh(new)
    d = as_delta(old, delta)
    nn_old = nn_spacing(old) if nn_old is None else nn_old
    ratio = nn_at(new.points, old.points) / (d * nn_old)
    q = quality(new)
    original = int((new.origin >= 0).sum())
    return {
        "points": new.n_points,
        "original_points": original,
        "original_pct": 100.0 * original / new.n_points,
        "triangles": new.n_triangles,
        "min_angle_deg": q.min_angle,
        "max_radius_edge": q.max_radius_edge,
        "spacing_ratio_max": float(ratio.max()),
        "spacing_ratio_p99": float(np.percentile(ratio, 99)),
    }


@dataclass
class Step:
    """One step of a run: ``mesh`` was evolved from the previous mesh with ``delta``.

    Attributes
    ----------
    iteration : int
        1 for the first step.
    time : float
        The front's time for this step.
    mesh : Mesh or None
        The new mesh (None if the run did not keep it).
    delta : ndarray, shape (n_previous,) or None
        The factor applied to the previous mesh.
    fields : dict of ndarray or None
        The user's fields on ``mesh``.
    stats : dict
        The row of the statistics table (:data:`STATISTICS_COLUMNS`).
    """

    iteration: int
    time: float
    mesh: Mesh | None
    delta: np.ndarray | None
    fields: dict[str, np.ndarray] | None
    stats: dict[str, float] = field(default_factory=dict)


def _format_value(name: str, value: Any) -> str:
    if name in ("original_pct",):
        return f"{value:.2f}"
    if name in ("min_angle_deg",):
        return f"{value:.2f}"
    if name in ("max_radius_edge", "spacing_ratio_max", "spacing_ratio_p99", "seconds"):
        return f"{value:.3f}"
    if name == "time":
        return f"{value:g}"
    return str(int(value))


_HEADERS = {
    "iteration": "iter",
    "points": "points",
    "original_points": "original",
    "original_pct": "% orig",
    "triangles": "triangles",
    "min_angle_deg": "min angle",
    "time": "t",
    "max_radius_edge": "max R/e",
    "spacing_ratio_max": "ratio max",
    "spacing_ratio_p99": "ratio p99",
    "seconds": "seconds",
}


def format_table(rows: Sequence[Mapping[str, Any]], *, paper: bool = False) -> str:
    """A fixed-width text table of statistics rows; with ``paper=True`` the
    paper's Table 1 columns are shown next to ours for the same iteration."""
    columns = list(STATISTICS_COLUMNS)
    headers = [_HEADERS[c] for c in columns]
    body = [[_format_value(c, row[c]) for c in columns] for row in rows]
    if paper:
        headers += ["| paper: points", "original", "% orig", "triangles", "min angle"]
        for line, row in zip(body, rows):
            ref = [p for p in PAPER_TABLE1 if p[0] == int(row["iteration"])]
            if ref:
                _, pts, orig, pct, tris, angle = ref[0]
                line += [f"| {pts}", str(orig), f"{pct:.2f}", str(tris), f"{angle:.2f}"]
            else:
                line += ["|", "", "", "", ""]
    widths = [max(len(h), *(len(r[i]) for r in body)) if body else len(h) for i, h in enumerate(headers)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(headers, widths))]
    lines += ["  ".join(v.rjust(w) for v, w in zip(r, widths)) for r in body]
    return "\n".join(lines)


class Run:
    """The result of :func:`run`: meshes, deltas, fields and statistics.

    Attributes
    ----------
    initial : Mesh
        The mesh before the first step.
    steps : list of Step
    front : Front, callable or None
        The front the run followed.
    law : SpacingLaw or callable
    next_delta : ndarray or None
        delta on the final mesh for the front at the final time (what the next
        step would apply if the front stopped); None if the run has no front.
    options : dict
        method, seed and evolve options used.
    """

    def __init__(self, initial: Mesh, initial_fields: dict[str, np.ndarray], front: Any, law: Any, options: dict[str, Any]):
        self.initial = initial
        self.initial_fields = initial_fields
        self.front = front
        self.law = law
        self.options = options
        self.steps: list[Step] = []
        self.next_delta: np.ndarray | None = None

    @property
    def meshes(self) -> list[Mesh | None]:
        """The initial mesh then the mesh of every step (None where not kept)."""
        return [self.initial] + [s.mesh for s in self.steps]

    @property
    def mesh(self) -> Mesh:
        """The final mesh."""
        return self.steps[-1].mesh if self.steps else self.initial

    @property
    def fields(self) -> list[dict[str, np.ndarray] | None]:
        """The fields on each mesh of :attr:`meshes`."""
        return [self.initial_fields] + [s.fields for s in self.steps]

    @property
    def deltas(self) -> list[np.ndarray | None]:
        """deltas[k] is the factor on meshes[k]: the one applied to make
        meshes[k + 1], and :attr:`next_delta` for the final mesh."""
        return [s.delta for s in self.steps] + [self.next_delta]

    @property
    def times(self) -> np.ndarray:
        return np.array([s.time for s in self.steps])

    @property
    def rows(self) -> list[dict[str, float]]:
        """The statistics table, one dict per step (keys :data:`STATISTICS_COLUMNS`)."""
        return [dict(s.stats) for s in self.steps]

    def column(self, name: str) -> np.ndarray:
        if name not in STATISTICS_COLUMNS:
            raise ValueError(f"unknown column {name!r}; columns: {', '.join(STATISTICS_COLUMNS)}")
        return np.array([s.stats[name] for s in self.steps])

    def table(self, *, paper: bool = False) -> str:
        """The statistics as text; ``paper=True`` adds Table 1 of the paper."""
        return format_table(self.rows, paper=paper)

    def to_csv(self, path: str | Path) -> Path:
        """Write the statistics table as CSV (header :data:`STATISTICS_COLUMNS`)."""
        path = Path(path)
        with path.open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(STATISTICS_COLUMNS)
            for row in self.rows:
                writer.writerow([_csv_value(c, row[c]) for c in STATISTICS_COLUMNS])
        return path

    def __repr__(self) -> str:
        return f"Run(steps={len(self.steps)}, final={self.mesh!r})"


def _csv_value(name: str, value: Any) -> str:
    if name in ("iteration", "points", "original_points", "triangles"):
        return str(int(value))
    return repr(float(value))


def _step_seed(seed: int, iteration: int) -> int:
    """Independent, reproducible seed for each step."""
    return int(np.random.SeedSequence([seed, iteration]).generate_state(1, np.uint64)[0])


def _as_fields(fields: Any, mesh: Mesh) -> dict[str, np.ndarray]:
    if fields is None:
        return {}
    if not isinstance(fields, Mapping):
        raise TypeError(f"fields must be a mapping of name -> per-point array, got {type(fields).__name__}")
    out = {}
    for name, values in fields.items():
        if not isinstance(name, str):
            raise TypeError(f"field names must be strings, got {name!r}")
        array = np.asarray(values)
        if array.dtype == object or array.dtype.kind not in "fiuc":
            raise TypeError(f"field {name!r} must be numeric, got dtype {array.dtype}")
        if array.ndim == 0 or array.shape[0] != mesh.n_points:
            raise ValueError(f"field {name!r} must have one row per point: ({mesh.n_points}, ...), got {array.shape}")
        out[name] = array.copy()
    return out


class Driver:
    """Step-by-step moving-front evolution, for simulations that move the
    front themselves (e.g. a :class:`PointFront` advected by a solution).

    Parameters
    ----------
    mesh : Mesh
        The initial mesh.
    law : SpacingLaw or callable
        ``law(mesh, distance) -> delta`` (shape (n,)); a :class:`SpacingLaw`
        is such a callable. ``distance`` is None when a step has no front.
    fields : mapping of str -> array_like, optional
        Per-point fields (shape (n,) or (n, ...)) carried through every step
        with :func:`evomesh.transfer`; copied, never modified.
    method : str
        Passed to :func:`evomesh.evolve`.
    seed : int
        Each step uses a seed derived from (seed, iteration): reproducible.
    **options
        Passed to :func:`evomesh.evolve`.

    Attributes
    ----------
    mesh : Mesh
        The current mesh.
    fields : dict of ndarray
        The current fields (the caller may replace them between steps).
    iteration : int
        Steps done so far.
    """

    def __init__(self, mesh: Mesh, law: Any, *, fields: Any = None, method: str = "frfc", seed: int = 0, **options: Any):
        _require_mesh(mesh)
        if not callable(law):
            raise TypeError(f"law must be a SpacingLaw or a callable law(mesh, distance) -> delta, got {type(law).__name__}")
        if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or not 0 <= int(seed) < 2**64:
            raise ValueError(f"seed must be an integer in [0, 2**64), got {seed!r}")
        self.mesh = mesh
        self.law = law
        self.fields = _as_fields(fields, mesh)
        self.method = method
        self.seed = int(seed)
        self.options = dict(options)
        self.iteration = 0

    def delta(self, front: Any, t: Any = None, mesh: Mesh | None = None) -> np.ndarray:
        """delta on ``mesh`` (default: the current mesh) for the front at time t."""
        mesh = self.mesh if mesh is None else mesh
        distance = _front_distance(front, mesh.points, t)
        return as_delta(mesh, self.law(mesh, distance))

    def step(self, front: Any = None, t: Any = None, *, delta: Any = None) -> Step:
        """Evolve the current mesh once.

        Parameters
        ----------
        front : Front, callable t -> Front, or None
        t : float, optional
            The front's time.
        delta : array_like, optional
            Use this factor instead of the law's.

        Returns
        -------
        Step
            With the new mesh, the delta applied, the transferred fields and
            the statistics row.
        """
        old = self.mesh
        nn_old = nn_spacing(old)
        if delta is None:
            distance = _front_distance(front, old.points, t)
            d = self.law.delta(old, distance, nn=nn_old) if isinstance(self.law, SpacingLaw) else self.law(old, distance)
        else:
            d = delta
        d = as_delta(old, d)
        iteration = self.iteration + 1
        start = _time.perf_counter()
        new = evolve(old, d, method=self.method, seed=_step_seed(self.seed, iteration), **self.options)
        seconds = _time.perf_counter() - start
        fields = {}
        if self.fields:
            interpolation = Interpolation(old, new)
            fields = {name: interpolation(values) for name, values in self.fields.items()}
        stats = {"iteration": iteration, **step_statistics(old, new, d, nn_old=nn_old)}
        stats["time"] = float("nan") if t is None else float(t)
        stats["seconds"] = float(new.stats.get("seconds_total", seconds))
        stats = {c: stats[c] for c in STATISTICS_COLUMNS}
        self.mesh = new
        self.fields = fields
        self.iteration = iteration
        return Step(iteration, stats["time"], new, d, fields, stats)


def _front_distance(front: Any, points: np.ndarray, t: Any) -> np.ndarray | None:
    if front is None:
        return None
    if not isinstance(front, Front) and callable(front):
        front = front(t)
    if not hasattr(front, "distance"):
        raise TypeError(f"front must be a Front, a callable t -> Front, or None; got {type(front).__name__}")
    distance = np.asarray(front.distance(points, t), dtype=np.float64)
    if distance.shape != (len(points),):
        raise ValueError(f"front distance must have shape ({len(points)},), got {distance.shape}")
    if np.isnan(distance).any():
        raise ValueError("front distance contains NaN")
    if (distance < 0).any():
        raise ValueError("front distance must be >= 0")
    return distance


def front_at(front: Any, t: Any) -> Any:
    """The Front object for time t (a callable front is called with t)."""
    if front is None or isinstance(front, Front) or not callable(front):
        return front
    return front(t)


def run(
    mesh: Mesh,
    front: Any,
    law: Any,
    times: Any,
    *,
    fields: Any = None,
    method: str = "frfc",
    seed: int = 0,
    progress: bool | None = None,
    callback: Callable[[Step], Any] | None = None,
    keep_meshes: bool = True,
    **options: Any,
) -> Run:
    """Evolve a mesh along a moving front: one :func:`evomesh.evolve` per time.

    Step k computes the distance from the points of mesh k-1 to the front at
    ``times[k-1]``, delta = law(mesh, distance), evolves, transfers the fields
    and records the statistics (:func:`step_statistics`).

    Parameters
    ----------
    mesh : Mesh
    front : Front, callable t -> Front, or None
        E.g. :class:`CircleFront` with a radius function of t, a function
        returning the :class:`PointFront` of each time, or None for a law that
        ignores distances.
    law : SpacingLaw or callable
        ``law(mesh, distance) -> delta``, shape (n,).
    times : array_like, shape (steps,)
        Time of every step.
    fields : mapping of str -> array_like, optional
        Per-point fields carried through every step (:func:`evomesh.transfer`).
    method, seed, **options
        Passed to :func:`evomesh.evolve` (the seed of step k is derived from
        (seed, k)). Same inputs and seed give identical results.
    progress : bool or None
        Progress bar (tqdm, on stderr): None shows it only for runs lasting
        more than 2 seconds on a terminal.
    callback : callable, optional
        ``callback(step)`` after every step, with the :class:`Step`.
    keep_meshes : bool, default True
        False keeps only the final mesh and fields (for very large meshes);
        statistics are kept for every step.

    Returns
    -------
    Run

    Raises
    ------
    Exception
        Whatever a step raises (e.g. ValueError from the law or from
        :func:`evomesh.evolve`, KeyboardInterrupt), re-raised unchanged in type,
        message and traceback, so ``except ValueError`` still catches it. The
        steps finished before it are not lost: the exception carries them as
        ``error.run``, a :class:`Run` with those steps (its ``next_delta`` is
        None), which :func:`evomesh.io.write_run` writes like any run; on
        Python >= 3.11 a note on the exception says so. Errors in the
        arguments (raised before the first step) carry no ``run``.

    Examples
    --------
    >>> try:  # doctest: +SKIP
    ...     result = run(mesh, front, law, times)
    ... except ValueError as error:
    ...     result = error.run  # the finished steps
    ...     write_run(result, "partial")
    """
    from tqdm.auto import tqdm

    times = np.asarray(times)
    if times.dtype == object or times.dtype.kind not in "fiu":
        raise TypeError(f"times must be real numbers, got dtype {times.dtype}")
    times = np.atleast_1d(times).astype(np.float64)
    if times.ndim != 1 or len(times) == 0:
        raise ValueError(f"times must be a non-empty 1-d sequence, got shape {times.shape}")
    if not np.isfinite(times).all():
        raise ValueError("times must be finite")
    if callback is not None and not callable(callback):
        raise TypeError("callback must be callable")
    if progress is not None and not isinstance(progress, (bool, np.bool_)):
        raise TypeError("progress must be True, False or None")
    driver = Driver(mesh, law, fields=fields, method=method, seed=seed, **options)
    result = Run(mesh, dict(driver.fields), front, law, {"method": method, "seed": seed, **options})
    bar = tqdm(
        total=len(times),
        desc="evomesh",
        unit="step",
        disable=None if progress is None else not progress,
        delay=2.0 if progress is None else 0.0,
        leave=False,
    )
    try:
        for t in times:
            step = driver.step(front, float(t))
            if not keep_meshes and result.steps:
                previous = result.steps[-1]
                previous.mesh = previous.fields = previous.delta = None
            result.steps.append(step)
            bar.set_postfix(points=step.stats["points"], refresh=False)
            bar.update(1)
            if callback is not None:
                callback(step)
    except BaseException as error:
        _attach_partial_run(error, result, len(times))
        raise
    finally:
        bar.close()
    if front is not None:
        result.next_delta = driver.delta(front, float(times[-1]))
    return result


def _attach_partial_run(error: BaseException, result: Run, planned: int) -> None:
    """Give ``error`` the partial run as ``error.run`` and, where exceptions
    take notes (Python >= 3.11), a note saying so; the type, message and
    traceback are left alone. Exceptions that take no attributes are left
    alone too."""
    try:
        error.run = result  # type: ignore[attr-defined]
    except (AttributeError, TypeError):  # exceptions with __slots__ or read-only attributes
        return
    if hasattr(error, "add_note"):
        finished = len(result.steps)
        error.add_note(
            f"evomesh.run: {finished} of {planned} steps finished before this error; "
            f"error.run holds them (a Run; evomesh.io.write_run writes it)"
        )


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
    from evomesh.meshgen import unit_square_mesh

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
        from evomesh.io import write_run

        write_run(result, out, figures=figures)
    return result
