"""Files: meshes as VTU (meshio) with a ParaView .pvd time series, run outputs."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Sequence
from xml.sax.saxutils import quoteattr

import numpy as np

from evomesh.mesh import Mesh
from evomesh.spacing import _require_mesh, nn_spacing

__all__ = ["to_meshio", "write_mesh", "read_mesh", "write_pvd", "write_run", "RESERVED_POINT_DATA"]

#: Point data that :func:`write_run` always writes.
RESERVED_POINT_DATA = ("kind", "origin", "nn_spacing", "delta")


def to_meshio(mesh: Mesh, point_data: Mapping[str, Any] | None = None):
    """A meshio.Mesh: points with z = 0, a "triangle" block, and a "line" block
    for the interior constraint segments (boundary segments are implied by the
    triangles). Point data always includes ``kind`` and ``origin``."""
    import meshio

    _require_mesh(mesh)
    cells = [("triangle", np.asarray(mesh.triangles, dtype=np.int64))]
    interior = mesh.segments[~mesh.segment_is_boundary]
    if len(interior):
        cells.append(("line", np.asarray(interior, dtype=np.int64)))
    data: dict[str, np.ndarray] = {"kind": mesh.kind.astype(np.int32), "origin": mesh.origin.astype(np.int64)}
    for name, values in (point_data or {}).items():
        array = np.asarray(values)
        if array.shape[:1] != (mesh.n_points,):
            raise ValueError(f"point data {name!r} must have one row per point ({mesh.n_points}), got {array.shape}")
        data[name] = array
    points = np.c_[mesh.points, np.zeros(mesh.n_points)]
    return meshio.Mesh(points, cells, point_data=data)


def write_mesh(path: str | Path, mesh: Mesh, point_data: Mapping[str, Any] | None = None) -> Path:
    """Write a mesh with meshio (format from the suffix; ``.vtu`` for ParaView).

    Per-point data: ``kind``, ``origin`` and the arrays of ``point_data``
    (each shape (n,) or (n, c)).
    """
    path = Path(path)
    to_meshio(mesh, point_data).write(path)
    return path


def read_mesh(path: str | Path) -> tuple[Mesh, dict[str, np.ndarray]]:
    """Read a mesh written by :func:`write_mesh`: the Mesh (with its kind,
    origin and interior segments) and the other point data."""
    import meshio

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file not found: {path}")
    try:
        m = meshio.read(path)
    except SystemExit as error:  # meshio exits on some malformed files
        raise ValueError(f"cannot read mesh file {path}: not a valid mesh file") from error
    except (meshio.ReadError, KeyError, IndexError, TypeError, ValueError, EOFError, UnicodeDecodeError) as error:
        raise ValueError(f"cannot read mesh file {path}: {error}") from error
    except Exception as error:  # parsers of the many formats raise many things
        raise ValueError(f"cannot read mesh file {path}: {type(error).__name__}: {error}") from error
    tri_blocks = [c.data for c in m.cells if c.type == "triangle"]
    if not tri_blocks:
        raise ValueError(f"mesh file {path} has no triangles")
    triangles = np.concatenate(tri_blocks)
    lines = [c.data for c in m.cells if c.type == "line"]
    segments = np.concatenate(lines) if lines else None
    data = {name: np.asarray(v) for name, v in m.point_data.items()}
    kind = data.pop("kind", None)
    origin = data.pop("origin", None)
    mesh = Mesh(
        np.asarray(m.points)[:, :2],
        triangles,
        segments,
        kind=None if kind is None else kind.astype(np.int64),
        origin=None if origin is None else origin.astype(np.int64),
    )
    return mesh, data


def write_pvd(path: str | Path, files: Sequence[str | Path], times: Sequence[float]) -> Path:
    """A ParaView collection (.pvd) listing ``files`` at ``times``; file names
    are written relative to the .pvd's folder when they lie inside it."""
    path = Path(path)
    if len(files) != len(times):
        raise ValueError(f"files and times must have the same length, got {len(files)} and {len(times)}")
    lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">', "  <Collection>"]
    for name, t in zip(files, times):
        name = Path(name)
        try:
            name = name.resolve().relative_to(path.parent.resolve())
        except ValueError:
            pass
        lines.append(f'    <DataSet timestep="{float(t)!r}" group="" part="0" file={quoteattr(name.as_posix())}/>')
    lines += ["  </Collection>", "</VTKFile>", ""]
    path.write_text("\n".join(lines))
    return path


def _pvd_times(run) -> list[float]:
    times = [s.time for s in run.steps]
    if not times or not all(math.isfinite(t) for t in times):
        return [float(k) for k in range(len(times) + 1)]
    first = times[0] - (times[1] - times[0] if len(times) > 1 else 1.0)
    return [first] + times


def write_run(run, folder: str | Path, *, figures: bool = True, dpi: int = 110) -> dict[str, Any]:
    """Write the outputs of a :class:`evomesh.Run` into ``folder`` (created).

    - ``table.csv``: the statistics (:data:`evomesh.driver.STATISTICS_COLUMNS`).
    - ``mesh_000.vtu`` (initial) ... ``mesh_NNN.vtu`` and ``meshes.pvd`` (open
      the .pvd in ParaView for the time series; the initial mesh is placed one
      time step before the first step). Per-point data: ``kind``
      (:class:`PointKind`), ``origin``, ``nn_spacing`` (nn_M) and ``delta``:
      on mesh k the delta applied to it to make mesh k + 1; on the final mesh
      the delta of the front at the final time (what the next step would
      apply), NaN if the run had no front. The run's fields are added under
      their own names.
    - ``step_NNN.png`` (``figures=True``): the three panels of
      :func:`evomesh.plotting.plot_step` for every step.

    Meshes a run did not keep (``keep_meshes=False``) are skipped.

    Returns
    -------
    dict
        Paths: "table", "meshes" (list), "pvd", "figures" (list).
    """
    from evomesh.driver import front_at

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written: dict[str, Any] = {"table": run.to_csv(folder / "table.csv"), "meshes": [], "figures": []}
    meshes, deltas, fields = run.meshes, run.deltas, run.fields
    pvd_times = _pvd_times(run)
    listed, listed_times = [], []
    for k, mesh in enumerate(meshes):
        if mesh is None:
            continue
        delta = deltas[k] if deltas[k] is not None else np.full(mesh.n_points, np.nan)
        data: dict[str, Any] = {"nn_spacing": nn_spacing(mesh), "delta": np.asarray(delta, dtype=np.float64)}
        for name, values in (fields[k] or {}).items():
            if name in RESERVED_POINT_DATA:
                raise ValueError(f"field name {name!r} clashes with evomesh's point data {RESERVED_POINT_DATA}")
            data[name] = values
        path = write_mesh(folder / f"mesh_{k:03d}.vtu", mesh, data)
        written["meshes"].append(path)
        listed.append(path)
        listed_times.append(pvd_times[k])
    written["pvd"] = write_pvd(folder / "meshes.pvd", listed, listed_times)
    if figures:
        from evomesh.plotting import plot_step, save

        scale = _packing_scale(run.options)
        for k, step in enumerate(run.steps, start=1):
            old, new = meshes[k - 1], meshes[k]
            if old is None or new is None or step.delta is None:
                continue
            fig = plot_step(
                old,
                new,
                step.delta,
                front=front_at(run.front, step.time),
                t=step.time,
                packing_scale=scale,
                title=f"step {step.iteration} (t = {step.time:g})",
            )
            written["figures"].append(save(fig, folder / f"step_{k:03d}.png", dpi=dpi))
    return written


def _packing_scale(options: Mapping[str, Any]) -> float:
    """Radius scale of the packing spheres used by evolve: the run's
    ``radius_scale`` option, else the method's default (``<METHOD>_DEFAULTS``)."""
    from evomesh import evolve as evolve_module

    method = str(options.get("method", "frfc"))
    defaults = getattr(evolve_module, f"{method.upper()}_DEFAULTS", {})
    return float(options.get("radius_scale", defaults.get("radius_scale", 1.0)))
