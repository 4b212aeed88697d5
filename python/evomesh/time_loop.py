"""The moving-front time loop: one evolve() per step, fields carried along.

The paper's use case (Sections 1 and 6): at every time step the mesh is
refined ahead of a moving boundary and coarsened behind it.
"""

from __future__ import annotations

import numbers
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, cast

import numpy as np

from evomesh.evolution import evolve
from evomesh.field_transfer import Interpolation
from evomesh.fronts import Front, SpacingLaw
from evomesh.mesh import Mesh
from evomesh.reporting import format_table, write_csv
from evomesh.spacing_function import _require_mesh, as_delta
from evomesh.statistics import STATISTICS_COLUMNS, step_statistics
from evomesh.typing import ArrayLike, Fields, FloatArray, FrontLike, Law

__all__ = ["Step", "Run", "Driver", "run", "front_at"]


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

    def __init__(
        self,
        initial: Mesh,
        initial_fields: dict[str, np.ndarray],
        front: FrontLike,
        law: Law,
        options: dict[str, Any],
    ) -> None:
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
        # run() and Driver.step() never drop the final step's mesh (keep_meshes=False drops earlier ones)
        return cast(Mesh, self.steps[-1].mesh) if self.steps else self.initial

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
        return write_csv(self.rows, path)

    def __repr__(self) -> str:
        return f"Run(steps={len(self.steps)}, final={self.mesh!r})"


def _step_seed(seed: int, iteration: int) -> int:
    """Independent, reproducible seed for each step."""
    return int(np.random.SeedSequence([seed, iteration]).generate_state(1, np.uint64)[0])


def _as_fields(fields: Fields | None, mesh: Mesh) -> dict[str, np.ndarray]:
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
        Passed to :func:`evomesh.evolve` (options, and ``geometry=`` for
        curved boundaries).

    Attributes
    ----------
    mesh : Mesh
        The current mesh.
    fields : dict of ndarray
        The current fields (the caller may replace them between steps).
    iteration : int
        Steps done so far.
    """

    def __init__(
        self,
        mesh: Mesh,
        law: Law,
        *,
        fields: Fields | None = None,
        method: str = "frfc",
        seed: int = 0,
        **options: Any,
    ) -> None:
        _require_mesh(mesh)
        if not callable(law):
            raise TypeError(
                f"law must be a SpacingLaw or a callable law(mesh, distance) -> delta, got {type(law).__name__}"
            )
        if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or not 0 <= int(seed) < 2**64:
            raise ValueError(f"seed must be an integer in [0, 2**64), got {seed!r}")
        self.mesh: Mesh = mesh
        self.law: Law = law
        self.fields: dict[str, np.ndarray] = _as_fields(fields, mesh)
        self.method: str = method
        self.seed: int = int(seed)
        self.options: dict[str, Any] = dict(options)
        self.iteration: int = 0

    def delta(self, front: FrontLike, t: float | None = None, mesh: Mesh | None = None) -> FloatArray:
        """delta on ``mesh`` (default: the current mesh) for the front at time t."""
        mesh = self.mesh if mesh is None else mesh
        distance = _front_distance(front, mesh.points, t)
        return as_delta(mesh, self.law(mesh, distance))

    def step(self, front: FrontLike = None, t: float | None = None, *, delta: ArrayLike | None = None) -> Step:
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
        nn_old = old.nn_spacing  # cached on the mesh (the step that made it computed it)
        if delta is None:
            distance = _front_distance(front, old.points, t)
            raw: ArrayLike
            if isinstance(self.law, SpacingLaw):
                raw = self.law.delta(old, distance, nn=nn_old)
            else:
                raw = self.law(old, distance)
        else:
            raw = delta
        d = as_delta(old, raw)
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


def _front_distance(front: FrontLike, points: np.ndarray, t: float | None) -> FloatArray | None:
    if front is None:
        return None
    if not isinstance(front, Front) and callable(front):
        # a step without a time passes t=None on to the user's callable, as it always did
        front = front(t)  # type: ignore[arg-type]
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


def front_at(front: FrontLike, t: float | None) -> Front | None:
    """The Front object for time t (a callable front is called with t)."""
    if front is None or isinstance(front, Front) or not callable(front):
        return front
    return front(t)  # type: ignore[arg-type]  # as in _front_distance: t=None is passed on


def run(
    mesh: Mesh,
    front: FrontLike,
    law: Law,
    times: ArrayLike,
    *,
    fields: Fields | None = None,
    method: str = "frfc",
    seed: int = 0,
    progress: bool | None = None,
    callback: Callable[[Step], object] | None = None,
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
