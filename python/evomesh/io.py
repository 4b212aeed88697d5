"""Files: meshes as VTU (meshio) with a ParaView .pvd time series, run outputs."""

from __future__ import annotations

import importlib
import math
import numbers
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence
from xml.sax.saxutils import quoteattr

import numpy as np
from numpy.typing import ArrayLike

from evomesh.mesh import Mesh
from evomesh.spacing_function import _require_mesh, nn_spacing
from evomesh.tet_mesh import TetMesh
from evomesh.time_loop import Run, front_at

if TYPE_CHECKING:
    import meshio

__all__ = ["to_meshio", "write_mesh", "read_mesh", "write_pvd", "write_run", "check_writable_format",
           "RESERVED_POINT_DATA"]

#: Point data that :func:`write_run` always writes.
RESERVED_POINT_DATA = ("kind", "origin", "required", "nn_spacing", "delta")
# What every written mesh holds (Mesh.to_meshio).
_MESH_POINT_DATA = ("kind", "origin", "required")


#: numpy dtypes that VTU stores (Float32/64, Int8..64, UInt8..64).
_VTU_DTYPES = frozenset(
    np.dtype(t)
    for t in (np.float32, np.float64, np.int8, np.int16, np.int32, np.int64, np.uint8, np.uint16, np.uint32, np.uint64)
)
#: Characters meshio writes unescaped into the VTU's XML (the file then cannot
#: be read) or turns into spaces: <, & and ", and control characters.
_BAD_NAME_CHARACTER = re.compile(r'[<&"\x00-\x1f\x7f]')


def _check_point_data(point_data: Mapping[str, Any] | None, n_points: int, reserved: Sequence[str]) -> list[str]:
    """Check the point data :func:`to_meshio` would write, without converting
    anything; returns the names of the arrays it writes (a complex field gives
    two). Raises TypeError / ValueError naming the offending field."""
    if point_data is None:
        return []
    if not isinstance(point_data, Mapping):
        raise TypeError(f"point data must be a mapping of name -> per-point array, got {type(point_data).__name__}")
    written: dict[str, str] = {}
    for name, values in point_data.items():
        if not isinstance(name, str):
            raise TypeError(f"point data names must be strings, got {name!r}")
        if not name:
            raise ValueError("point data names must not be empty")
        bad = _BAD_NAME_CHARACTER.search(name)
        if bad:
            raise ValueError(
                f"point data name {name!r} contains {bad.group()!r}: VTU files cannot hold <, &, \" or control "
                "characters in names"
            )
        if name in reserved:
            raise ValueError(f"field name {name!r} clashes with evomesh's point data {tuple(reserved)}")
        try:
            array = values if isinstance(values, np.ndarray) else np.asarray(values)
        except ValueError as error:  # ragged nesting
            raise ValueError(f"point data {name!r} must be a rectangular array: {error}") from None
        dtype = array.dtype
        if dtype == object or dtype.kind not in "biufc":  # noqa: E721 -- a numpy dtype comparison, not of types
            raise TypeError(f"point data {name!r} must be numeric, got dtype {dtype}")
        if (dtype.kind == "f" and dtype.itemsize > 8) or (dtype.kind == "c" and dtype.itemsize > 16):
            raise ValueError(
                f"point data {name!r} has dtype {dtype}, which VTU cannot hold without losing precision "
                "(at most 64-bit floats): convert it to float64 / complex128 first"
            )
        if array.ndim == 0 or array.shape[0] != n_points:
            raise ValueError(f"point data {name!r} must have one row per point ({n_points}), got shape {array.shape}")
        if array.ndim > 1 and math.prod(array.shape[1:]) == 0:
            raise ValueError(f"point data {name!r} has no components (shape {array.shape})")
        for out in (f"{name}_real", f"{name}_imag") if dtype.kind == "c" else (name,):
            if out in reserved or out in written:
                clash = out if out in reserved else written[out]
                raise ValueError(
                    f"point data {name!r} would be written as {out!r}, which is also the name of {clash!r} "
                    "(complex fields are written as <name>_real and <name>_imag)"
                )
            written[out] = name
    return list(written)


def _vtu_arrays(name: str, values: Any) -> list[tuple[str, np.ndarray]]:
    """The arrays VTU stores for one checked field (:func:`_check_point_data`):
    native byte order, bool as uint8, float16 as float32, extra axes flattened
    into components, and a complex field split into ``<name>_real`` and
    ``<name>_imag``."""
    array = np.asarray(values)
    if array.ndim > 2:
        array = array.reshape(array.shape[0], -1)
    if array.dtype.kind == "c":
        return _vtu_arrays(f"{name}_real", array.real) + _vtu_arrays(f"{name}_imag", array.imag)
    if array.dtype.kind == "b":
        array = array.astype(np.uint8)
    elif array.dtype.kind == "f" and array.dtype.itemsize < 4:
        array = array.astype(np.float32)
    array = array.astype(array.dtype.newbyteorder("="), copy=False)
    assert array.dtype in _VTU_DTYPES, array.dtype
    return [(name, array)]


def to_meshio(mesh: Mesh | TetMesh, point_data: Mapping[str, ArrayLike] | None = None) -> meshio.Mesh:
    """A meshio.Mesh (:meth:`Mesh.to_meshio`: points with z = 0, a "triangle"
    and a "line" block with their tags as ``gmsh:physical``; for a
    :class:`TetMesh`, :meth:`TetMesh.to_meshio`: "tetra" and "triangle" blocks).

    Point data always includes ``kind``, ``origin`` and ``required``, then the arrays of
    ``point_data`` (each shape (n,) or (n, ...)), stored as VTU can hold them:
    extra axes are flattened into components ((n, 2, 2) -> (n, 4)), bool becomes
    uint8 and float16 float32, and a complex field ``u`` becomes two real arrays
    ``u_real`` and ``u_imag``.

    Raises
    ------
    TypeError
        A name that is not a string, or a field that is not numeric.
    ValueError
        A name that is empty, contains <, &, " or a control character, or
        clashes with ``kind``/``origin`` or another array (also via the
        ``_real``/``_imag`` names of a complex field); a field without one row
        per point or without components; a float / complex dtype wider than
        64-bit parts (VTU would lose precision).
    """
    if not isinstance(mesh, TetMesh):
        _require_mesh(mesh)
    _check_point_data(point_data, mesh.n_points, _MESH_POINT_DATA)
    out = mesh.to_meshio()
    for name, values in (point_data or {}).items():
        out.point_data.update(_vtu_arrays(name, values))
    return out


def _gmsh_arrays(name: str, values: Any) -> list[tuple[str, np.ndarray]]:
    """The arrays a Gmsh file stores for one checked field (:func:`_check_point_data`):
    Gmsh holds 1, 3 or 9 components a point, so a 2-D vector (n, 2) gets a zero
    z, a 2 x 2 tensor (n, 2, 2) a zero third row and column; other widths are
    refused. Complex fields become ``<name>_real`` and ``<name>_imag``."""
    array = np.asarray(values)
    if array.dtype.kind == "c":
        return _gmsh_arrays(f"{name}_real", array.real) + _gmsh_arrays(f"{name}_imag", array.imag)
    if array.dtype.kind == "b":
        array = array.astype(np.uint8)
    shape = array.shape[1:]
    if shape in ((), (1,), (3,), (9,), (3, 3)):
        return [(name, array.reshape(len(array), -1) if array.ndim > 1 else array)]
    if shape == (2,):
        return [(name, np.concatenate([array, np.zeros((len(array), 1), array.dtype)], axis=1))]
    if shape == (2, 2):
        padded = np.zeros((len(array), 3, 3), array.dtype)
        padded[:, :2, :2] = array
        return [(name, padded.reshape(len(array), 9))]
    raise ValueError(
        f"point data {name!r} has shape {array.shape}: Gmsh files hold 1, 3 or 9 components a point (a 2-D vector "
        "(n, 2) and a tensor (n, 2, 2) are padded with zeros); write .vtu for other shapes"
    )


#: The format evomesh writes for a suffix where meshio knows several (.msh: Gmsh, not ANSYS).
_FORMAT_OF_SUFFIX = {".msh": "gmsh"}
_INT32 = np.iinfo(np.int32)
#: Formats that hold a tag per cell in one block per cell type: write_mesh writes
#: the cells there in the mesh's order (a checkpoint; Mesh.from_meshio keeps it).
_IN_ORDER_FORMATS = frozenset({"gmsh22", "vtu", "xdmf"})


def _file_format(path: Path) -> str:
    """meshio's format name for a file name's suffix; ValueError when meshio
    has none."""
    import meshio

    suffix = path.suffix.lower()
    if suffix in _FORMAT_OF_SUFFIX:
        return _FORMAT_OF_SUFFIX[suffix]
    formats = meshio.extension_to_filetypes.get(suffix)
    if not formats:
        raise ValueError(f"cannot tell the format of {path} from its suffix {path.suffix!r} (meshio knows "
                         f"{', '.join(sorted(meshio.extension_to_filetypes))})")
    return formats[0]


def check_writable_format(path: str | Path) -> str:
    """The meshio format :func:`write_mesh` would write ``path`` in, after
    checking that it can: a known suffix, and h5py installed for XDMF.

    Parameters
    ----------
    path : str or Path
        The file to write; only its suffix is looked at.

    Returns
    -------
    str
        meshio's format name ("vtu", "gmsh", "xdmf", ...; ``.msh`` is Gmsh).

    Raises
    ------
    ValueError
        If meshio knows no format for the suffix.
    ImportError
        For ``.xdmf`` / ``.xmf`` without h5py (meshio stores XDMF's arrays in
        HDF5): ``pip install h5py`` (or ``pip install evomesh[xdmf]``).
    """
    file_format = _file_format(Path(path))
    if file_format == "xdmf":
        try:
            importlib.import_module("h5py")
        except ImportError as error:
            raise ImportError(f"writing {Path(path).name} needs h5py (meshio stores XDMF's arrays in HDF5): "
                              "pip install h5py, or pip install evomesh[xdmf]") from error
    return file_format


def _tags_of(mesh: Mesh | TetMesh) -> tuple[tuple[str, np.ndarray], ...]:
    if isinstance(mesh, TetMesh):
        return (("face", mesh.face_tags), ("tetrahedron", mesh.tet_tags))
    return (("segment", mesh.segment_tags), ("triangle", mesh.triangle_tags))


def _check_32_bit_tags(mesh: Mesh | TetMesh, files: str) -> None:
    """Gmsh and Medit files hold 32-bit tags: a larger one would be wrapped, so it is refused."""
    for name, tags in _tags_of(mesh):
        if len(tags) and (tags.min() < _INT32.min or tags.max() > _INT32.max):
            bad = int(tags[(tags < _INT32.min) | (tags > _INT32.max)][0])
            raise ValueError(f"{name} tag {bad} does not fit in the 32-bit tags of {files} files; write .vtu or .xdmf "
                             "(64-bit tags), or renumber the tags")


def _medit_meshio(mesh: TetMesh) -> meshio.Mesh:
    """Medit (.mesh) holds the tetrahedra and faces with one reference each (the tags), and nothing else."""
    import meshio

    cells = [("tetra", np.array(mesh.tetrahedra)), ("triangle", np.array(mesh.faces))]
    tags = [mesh.tet_tags.astype(np.int32), mesh.face_tags.astype(np.int32)]
    return meshio.Mesh(np.array(mesh.points), cells, cell_data={"medit:ref": tags})


#: Where a VTU file's dataset starts: its field data go right after it.
_VTU_GRID = b"<UnstructuredGrid>"


def _add_vtu_field_data(path: Path, field_data: Mapping[str, np.ndarray]) -> None:
    """Insert ``field_data`` (name -> [tag, dim], as Gmsh's physical names)
    into a VTU file meshio wrote (its writer drops field data; its reader and
    ParaView read a ``FieldData`` element of the dataset): one ASCII Int64
    array of two values per name, the name escaped for XML."""
    if not field_data:
        return
    arrays = "".join(
        f'<DataArray type="Int64" Name={quoteattr(name)} NumberOfTuples="{len(values)}" format="ascii">'
        f"{' '.join(str(int(v)) for v in values)}</DataArray>\n"
        for name, values in field_data.items()
    )
    text = b"\n<FieldData>\n" + arrays.encode("utf-8") + b"</FieldData>"
    with open(path, "rb") as source:
        head = source.read(1 << 16)  # (the dataset's tag is in meshio's first lines)
        at = head.find(_VTU_GRID)
        if at < 0:
            raise ValueError(f"cannot write {path}: no {_VTU_GRID.decode()} in meshio's VTU file")
        at += len(_VTU_GRID)
        with open(path.with_name(path.name + ".fields"), "wb") as target:
            target.write(head[:at] + text + head[at:])
            shutil.copyfileobj(source, target)
    os.replace(path.with_name(path.name + ".fields"), path)


def _write_atomically(path: Path, out: meshio.Mesh, file_format: str) -> None:
    """meshio writes into a new folder beside ``path``; the file (and the
    files it refers to, such as an XDMF's .h5) then replace the old ones by
    rename. A failure leaves the old files as they were."""
    target = path.resolve() if path.is_symlink() else path  # write through a link, as open() would
    folder = target.parent if str(target.parent) else Path(".")
    scratch = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=folder))
    try:
        written = scratch / target.name
        try:
            out.write(written, file_format=file_format)
            if file_format == "vtu":
                _add_vtu_field_data(written, out.field_data)
        except (OSError, ImportError):
            raise
        except Exception as error:  # meshio's writers raise many things (WriteError, ValueError, KeyError, ...)
            raise ValueError(f"cannot write {path}: {type(error).__name__}: {error}") from error
        # companions first, the file itself last: it is complete once it appears
        for produced in sorted(scratch.iterdir(), key=lambda item: item.name == target.name):
            os.replace(produced, folder / produced.name)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def write_mesh(path: str | Path, mesh: Mesh | TetMesh, point_data: Mapping[str, ArrayLike] | None = None) -> Path:
    """Write a mesh with meshio (format from the suffix; ``.vtu`` for ParaView).

    A :class:`TetMesh` is written as "tetra" and "triangle" cells (its faces),
    the tetrahedron (region) and face tags per cell and the tag names as for
    a triangle mesh, in ``.msh`` (Gmsh 2.2), ``.vtu`` and ``.xdmf`` files with
    ``kind``, ``origin``, ``required`` and the point data; a Medit ``.mesh``
    file holds the tetrahedra and faces with their tags (32-bit) only: no tag
    names and no point data (``point_data`` is refused there).

    Per-point data: ``kind``, ``origin``, ``required`` and the arrays of
    ``point_data`` (each shape (n,) or (n, ...)), converted and checked as in
    :func:`to_meshio` (complex fields become ``<name>_real`` and
    ``<name>_imag``). Tags as in :meth:`Mesh.to_meshio` (tag names too, in
    Gmsh files). Gmsh files (``.msh``, written as Gmsh 2.2) hold 1, 3 or 9
    components a point and 32-bit tags: a 2-D vector field gets a zero z
    component, a (n, 2, 2) tensor a zero third row and column.

    Everything is checked before anything is written, and the file is written
    beside ``path`` under another name, then renamed: a failure leaves an
    existing file at ``path`` as it was.

    A checkpoint: a ``.msh`` (Gmsh 2.2), ``.vtu`` or ``.xdmf`` file holds
    everything the next step reads, so ``read_mesh(path)[0]`` steps to the
    same bits as ``mesh`` (same request, options and seed): the points, the
    triangles and segments in their order (one cell block per type, a tag
    per cell: the order of the packing and the sampling follows them), the
    tags, ``kind`` (the packing orders points by it: old, Steiner, sampled),
    ``required``, and the tag names (in VTU as a ``FieldData`` element,
    name -> [tag, dim] as Gmsh's physical names). ``origin``, ``lineage`` and
    ``stats`` describe the previous step and are not read by the next one
    (``origin`` is written, the others are not). A :class:`Mesh` rebuilt by
    hand needs the same: ``Mesh(points, triangles, segments, segment_tags=...,
    triangle_tags=..., required=..., kind=...)`` orders segments its own way
    (boundary, then interior), so keep the Mesh (it pickles bit for bit) or
    use these files.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    TypeError, ValueError
        A field or name refused by :func:`to_meshio`; a suffix meshio does
        not know; for Gmsh, a field of another width or a tag beyond int32;
        anything meshio's writer refuses (naming the file).
    ImportError
        ``.xdmf`` without h5py (:func:`check_writable_format`).
    OSError
        The folder does not exist or cannot be written.
    """
    path = Path(path)
    if not isinstance(mesh, TetMesh):
        _require_mesh(mesh)
    file_format = check_writable_format(path)
    _check_point_data(point_data, mesh.n_points, _MESH_POINT_DATA)
    if isinstance(mesh, TetMesh) and file_format == "medit":
        if point_data:
            raise ValueError(f"Medit files hold no point data: write {path.stem}.vtu or .msh for "
                             f"{', '.join(point_data)}")
        _check_32_bit_tags(mesh, "Medit")
        _write_atomically(path, _medit_meshio(mesh), file_format)
        return path
    if file_format == "gmsh":
        _check_32_bit_tags(mesh, "Gmsh")
        arrays = [a for name, values in (point_data or {}).items() for a in _gmsh_arrays(name, values)]
        file_format = "gmsh22"  # tags per cell, read back by meshio and Gmsh alike
    else:
        arrays = [a for name, values in (point_data or {}).items() for a in _vtu_arrays(name, values)]
    # The mesh's order of triangles and segments (a step depends on it), where
    # the format keeps it: Gmsh 2.2, VTU, XDMF (tags per cell).
    out = mesh._to_meshio(in_order=file_format in _IN_ORDER_FORMATS)
    if file_format != "gmsh22":
        out.point_data.pop("gmsh:dim_tags", None)  # only Gmsh files need it
    out.point_data.update(arrays)
    _write_atomically(path, out, file_format)
    return path


def read_mesh(path: str | Path) -> tuple[Mesh | TetMesh, dict[str, np.ndarray]]:
    """Read a mesh written by :func:`write_mesh`.

    Parameters
    ----------
    path : str or Path
        Any format meshio reads; points may have a z coordinate, which must
        then be 0 everywhere, unless the file has tetrahedra.

    Returns
    -------
    mesh : Mesh or TetMesh
        A :class:`TetMesh` when the file has "tetra" cells
        (:meth:`TetMesh.from_meshio`: tags, tag names, faces, kind, origin and
        required as written). Else a Mesh with the file's kind, origin,
        interior segments (line cells), tags, tag names (Gmsh's physical
        names, a VTU's field data), and the order of its triangles and
        segments (:meth:`Mesh.from_meshio`): a file of :func:`write_mesh`
        steps as the mesh that was written.
    point_data : dict of ndarray
        The other point data, as stored (a complex field written by
        :func:`write_mesh` comes back as ``<name>_real`` and ``<name>_imag``).

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    ValueError
        If the file cannot be read, has no triangles (or tetrahedra), has a
        point with z != 0 and no tetrahedra (the mesh is not planar: dropping z
        would change it), has ``kind`` or
        ``origin`` values that are not integers (floats are accepted when
        integral: some writers store them as floats), or does not hold a
        valid mesh.
    ImportError
        If meshio's reader of the format needs a package that is missing
        (h5py for XDMF files with HDF5 arrays).
    """
    import meshio

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file not found: {path}")
    try:
        m = meshio.read(path)
    except ImportError as error:  # an optional reader dependency (h5py for XDMF's HDF5 arrays)
        raise ImportError(f"reading {path.name} needs {error.name or 'a missing module'}: "
                          f"pip install {error.name or str(error)}") from error
    except SystemExit as error:  # meshio exits on some malformed files
        raise ValueError(f"cannot read mesh file {path}: not a valid mesh file") from error
    except (meshio.ReadError, KeyError, IndexError, TypeError, ValueError, EOFError, UnicodeDecodeError) as error:
        raise ValueError(f"cannot read mesh file {path}: {error}") from error
    except Exception as error:  # parsers of the many formats raise many things
        raise ValueError(f"cannot read mesh file {path}: {type(error).__name__}: {error}") from error
    reader = TetMesh._from_meshio if any(block.type == "tetra" for block in m.cells) else Mesh._from_meshio
    try:
        mesh, used = reader(m)
    except ValueError as error:
        raise ValueError(f"mesh file {path}: {error}") from None
    data = {
        name: np.asarray(v)[used]
        for name, v in m.point_data.items()
        if name not in _MESH_POINT_DATA and not name.startswith(("gmsh:", "medit:"))
    }
    return mesh, data


def write_pvd(path: str | Path, files: Sequence[str | Path], times: Sequence[float]) -> Path:
    """A ParaView collection (.pvd) listing ``files`` at ``times``; file names
    are written relative to the .pvd's folder when they lie inside it."""
    path = Path(path)
    if len(files) != len(times):
        raise ValueError(f"files and times must have the same length, got {len(files)} and {len(times)}")
    lines = [
        '<?xml version="1.0"?>',
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
        "  <Collection>",
    ]
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


def _pvd_times(run: Run) -> list[float]:
    times = [s.time for s in run.steps]
    if not times or not all(math.isfinite(t) for t in times):
        return [float(k) for k in range(len(times) + 1)]
    first = times[0] - (times[1] - times[0] if len(times) > 1 else 1.0)
    return [first] + times


#: Files of a run's output series (:func:`write_run`): removed from the folder
#: before a new series is written there, so none of an older run is left behind.
_SERIES_FILE = re.compile(r"table\.csv|meshes\.pvd|mesh_\d{3,}\.vtu|step_\d{3,}\.png")


def write_run(run: Run, folder: str | Path, *, figures: bool = True, dpi: int = 110) -> dict[str, Any]:
    """Write the outputs of a :class:`evomesh.Run` into ``folder`` (created).

    - ``table.csv``: the statistics (:data:`evomesh.statistics.STATISTICS_COLUMNS`).
    - ``mesh_000.vtu`` (initial) ... ``mesh_NNN.vtu`` and ``meshes.pvd`` (open
      the .pvd in ParaView for the time series; the initial mesh is placed one
      time step before the first step). Per-point data: ``kind``
      (:class:`PointKind`), ``origin``, ``nn_spacing`` (nn_M) and ``delta``:
      on mesh k the delta applied to it to make mesh k + 1; on the final mesh
      the delta of the front at the final time (what the next step would
      apply), NaN if the run had no front. The run's fields are added under
      their own names, stored as :func:`to_meshio` describes: a complex field
      ``u`` becomes the real arrays ``u_real`` and ``u_imag`` (VTU has no
      complex type), extra axes become components.
    - ``step_NNN.png`` (``figures=True``): the three panels of
      :func:`evomesh.plotting.plot_step` for every step.

    Meshes a run did not keep (``keep_meshes=False``) are skipped. A partial
    run (``error.run`` of a failed :func:`evomesh.run`) is written like any
    other.

    Every field of every mesh is checked before anything is written: a run
    that cannot be written leaves the folder as it was. Then the files of an
    earlier series in the folder (``table.csv``, ``meshes.pvd``,
    ``mesh_NNN.vtu``, ``step_NNN.png``; no other file) are removed, so that
    none of them is mistaken for part of this run.

    Parameters
    ----------
    run : Run
    folder : str or Path
    figures : bool
    dpi : int
        Resolution of the figures.

    Returns
    -------
    dict
        Paths: "table", "meshes" (list), "pvd", "figures" (list).

    Raises
    ------
    TypeError, ValueError
        A field that VTU cannot hold or whose name cannot be written (see
        :func:`to_meshio`), or that clashes with :data:`RESERVED_POINT_DATA`;
        a bad ``dpi``. Nothing is written or removed then.
    """
    if figures and (isinstance(dpi, bool) or not isinstance(dpi, numbers.Real) or not (math.isfinite(dpi) and dpi > 0)):
        raise ValueError(f"dpi must be a positive number, got {dpi!r}")
    folder = Path(folder)
    meshes, deltas, fields = run.meshes, run.deltas, run.fields
    # 1. everything that can be refused, before any file is touched
    for k, mesh in enumerate(meshes):
        if mesh is None:
            continue
        where = "initial mesh" if k == 0 else f"mesh of step {k}"
        try:
            _check_point_data(fields[k], mesh.n_points, RESERVED_POINT_DATA)
        except (TypeError, ValueError) as error:
            raise type(error)(f"{where}: {error}") from None
        delta_k = deltas[k]
        if delta_k is not None and np.shape(delta_k) != (mesh.n_points,):
            raise ValueError(f"{where}: delta must have shape ({mesh.n_points},), got {np.shape(delta_k)}")
    # 2. the files of an earlier series
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.iterdir():
        if _SERIES_FILE.fullmatch(old.name) and (old.is_file() or old.is_symlink()):
            old.unlink()
    # 3. this run's files
    written: dict[str, Any] = {"table": run.to_csv(folder / "table.csv"), "meshes": [], "figures": []}
    pvd_times = _pvd_times(run)
    listed, listed_times = [], []
    for k, mesh in enumerate(meshes):
        if mesh is None:
            continue
        delta = deltas[k] if deltas[k] is not None else np.full(mesh.n_points, np.nan)
        data: dict[str, Any] = {"nn_spacing": nn_spacing(mesh), "delta": np.asarray(delta, dtype=np.float64)}
        data.update(fields[k] or {})
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
    from evomesh.evolution import DRFC_DEFAULTS, FRFC_DEFAULTS

    method = str(options.get("method", "frfc"))
    defaults = {"frfc": FRFC_DEFAULTS, "drfc": DRFC_DEFAULTS}.get(method, {})
    return float(options.get("radius_scale", defaults.get("radius_scale", 1.0)))
