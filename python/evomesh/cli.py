"""The ``evomesh`` command line tool."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import sys
from typing import Any, Callable, Sequence

import numpy as np

from evomesh.tet_evolution import TetOptions, evolve_tet, transfer_tet
from evomesh.tet_mesh import dihedral_angles, radius_edge_ratios

__all__ = ["main", "build_parser"]

_TET_OPTION_NAMES = frozenset(f.name for f in dataclasses.fields(TetOptions))


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

    from evomesh.experiments.growing_sphere import GROWING_SPHERE_DEFAULTS as S

    gs = commands.add_parser(
        "growing-sphere",
        help="the growing-circle experiment one dimension up: a sphere growing in the unit cube (tetrahedra)",
        description=(
            "Evolve a tetrahedral mesh of the unit cube while a sphere grows from near the centre until it "
            "touches the box: refined in a band around the sphere, coarsened behind it. Prints a table per step "
            "(points, kept, dihedral angles, slivers, radius-edge ratios) and writes table.csv, VTU meshes and one "
            "PNG per mesh (the slice z = 0.5) into the output folder."
        ),
    )
    gs.add_argument("--steps", type=_positive_int, default=S["steps"], help="number of steps (default %(default)s)")
    gs.add_argument("--cells", type=_positive_int, default=S["cells"],
                    help="cells per side of the initial cube mesh (default %(default)s)")
    gs.add_argument("--band", type=float, default=S["band"],
                    help="full width of the band where h = h_min (default %(default)s)")
    gs.add_argument("--h-min", type=float, default=S["h_min"], help="spacing at the sphere (default %(default)s)")
    gs.add_argument("--h-max", type=float, default=S["h_max"], help="far-field spacing (default %(default)s)")
    gs.add_argument("--grade", type=float, default=S["grade"],
                    help="growth dh/dd outside the band (default %(default)s)")
    gs.add_argument("--r0", type=float, default=S["r0"], help="radius at time 0 (default %(default)s)")
    gs.add_argument("--r-end", type=float, default=S["r_end"],
                    help="radius at the last step (default: the sphere touches the box)")
    gs.add_argument("--seed", type=int, default=0, help="seed of the sampling (default %(default)s)")
    gs.add_argument("--option", action="append", default=[], metavar="NAME=VALUE",
                    help="a TetOptions field, e.g. --option sliver_angle=12 (repeatable)")
    gs.add_argument("--out", default="evomesh-growing-sphere", help="output folder (default %(default)s)")
    gs.add_argument("--no-figures", action="store_true", help="do not draw the PNG figures")
    gs.add_argument("--quiet", action="store_true", help="no table, no progress bar")

    adapt = commands.add_parser(
        "adapt",
        help="one adaptation step of a mesh file: refine and coarsen to a size or a factor",
        description=(
            "Read a triangle or tetrahedral mesh (any format meshio reads: .msh, .vtu, .mesh, .xdmf, ...), evolve "
            "it once towards an "
            "absolute spacing (--size FIELD or --size-expr EXPR) or a factor of its current spacing (--delta "
            "FIELD), carry its point data over (linear interpolation, exact at kept points) and write it (format "
            "from OUT's suffix)."
        ),
    )
    adapt.add_argument("input", metavar="IN", help="input mesh file")
    adapt.add_argument("output", metavar="OUT", help="output mesh file")
    target = adapt.add_mutually_exclusive_group(required=True)
    target.add_argument("--size", metavar="FIELD", help="point data of IN holding the absolute target spacing")
    target.add_argument("--delta", metavar="FIELD", help="point data of IN holding the factor delta (<1 refine)")
    target.add_argument("--size-expr", metavar="EXPR",
                        help="absolute spacing as an expression in x and y (and z for tetrahedra), e.g. "
                             "'0.02 + 0.1*x': numbers, pi, e, "
                             "+ - * / **, comparisons and abs sqrt exp log log10 sin cos tan tanh arctan2 hypot "
                             "minimum maximum clip where; at most 1000 characters")
    adapt.add_argument("--method", choices=("frfc", "drfc"), default="frfc", help="default %(default)s")
    adapt.add_argument("--seed", type=int, default=0, help="seed of the sampling (default %(default)s)")
    adapt.add_argument("--paper", action="store_true", help="the paper's algorithm exactly (options preset paper())")
    adapt.add_argument("--option", action="append", default=[], metavar="NAME=VALUE",
                       help="any evolve option, e.g. --option min_angle=25 --option quality=False, or a TetOptions "
                            "field for a tetrahedral mesh (repeatable)")
    adapt.add_argument("--circle", action="append", default=[], metavar="TAG:CX,CY,R",
                       help="segments of TAG lie on the circle of centre (CX, CY) and radius R: a curved boundary "
                            "(repeatable; frfc only)")
    adapt.add_argument("--corner-angle", type=float, default=None, metavar="DEG",
                       help="with --circle: vertices turning by more than DEG stay corners (default 30)")
    adapt.add_argument("--quiet", action="store_true", help="no progress bar, no summary")

    info = commands.add_parser("info", help="points, cells, kinds, tags and quality of a mesh file (triangles or "
                                            "tetrahedra)")
    info.add_argument("input", metavar="IN", help="mesh file")
    return parser


# What an --size-expr may use: numbers, x and y, the constants pi and e,
# + - * / ** and comparisons (for where), and these numpy functions with their
# number of arguments. Nothing else: the text comes from a command line and is
# evaluated by walking its syntax tree, never by eval().
_EXPR_FUNCTIONS: dict[str, tuple[Any, int]] = {
    "abs": (np.abs, 1), "sqrt": (np.sqrt, 1), "exp": (np.exp, 1), "log": (np.log, 1), "log10": (np.log10, 1),
    "sin": (np.sin, 1), "cos": (np.cos, 1), "tan": (np.tan, 1), "tanh": (np.tanh, 1), "arctan2": (np.arctan2, 2),
    "hypot": (np.hypot, 2), "minimum": (np.minimum, 2), "maximum": (np.maximum, 2), "clip": (np.clip, 3),
    "where": (np.where, 3),
}
_EXPR_CONSTANTS = {"pi": np.pi, "e": np.e}
_EXPR_COORDINATES = ("x", "y", "z")
_EXPR_NAMES = (*_EXPR_COORDINATES, *_EXPR_CONSTANTS, *_EXPR_FUNCTIONS)
# Bounds that keep parsing and evaluation short whatever the text: its length,
# its number of syntax nodes and how deeply they nest (each node is one numpy
# operation over the points, in float64: no Python integer power can run away).
_EXPR_MAX_LENGTH = 1000
_EXPR_MAX_NODES = 200
_EXPR_MAX_DEPTH = 32
_EXPR_BINARY = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.true_divide,
                ast.Pow: np.power}
_EXPR_COMPARE = {ast.Lt: np.less, ast.LtE: np.less_equal, ast.Gt: np.greater, ast.GtE: np.greater_equal}


def _size_expression(text: str) -> Callable[[np.ndarray], np.ndarray]:
    """A checked function h(points) from an --size-expr text.

    Everything that can be refused without points is refused here, before any
    work: text longer than 1000 characters, syntax other than numbers, ``x``,
    ``y``, ``pi``, ``e``, ``+ - * / **``, comparisons and calls of the allowed
    numpy functions with their number of arguments, more than 200 syntax nodes
    or 32 levels of nesting, and constant parts that are not finite
    (``9**9**9``, ``1/0``, ``e**1000``: constants are folded in float64). The
    function raises ValueError naming the first point where the size is not a
    finite number > 0 (``1/x`` at x = 0, ``log(x)`` at x < 0).
    """
    if not isinstance(text, str):
        raise TypeError(f"--size-expr must be a string, got {type(text).__name__}")
    if len(text) > _EXPR_MAX_LENGTH:
        raise ValueError(f"--size-expr is {len(text)} characters long; at most {_EXPR_MAX_LENGTH} are allowed")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as error:
        raise ValueError(f"--size-expr is not a valid expression: {error.msg}") from None
    except (RecursionError, MemoryError):
        raise ValueError("--size-expr nests too deeply") from None
    nodes = list(ast.walk(tree))
    if len(nodes) > _EXPR_MAX_NODES:
        raise ValueError(f"--size-expr has {len(nodes)} syntax nodes; at most {_EXPR_MAX_NODES} are allowed")
    depth = {id(tree): 0}
    for node in nodes:  # breadth first: a parent before its children
        for child in ast.iter_child_nodes(node):
            depth[id(child)] = depth[id(node)] + 1
            if depth[id(child)] > _EXPR_MAX_DEPTH:
                raise ValueError(f"--size-expr nests deeper than {_EXPR_MAX_DEPTH} levels")
    evaluate = _compile_expression(tree.body)
    uses_z = any(isinstance(n, ast.Name) and n.id == "z" for n in nodes)

    def size(points: np.ndarray) -> np.ndarray:
        dim = points.shape[1]
        if uses_z and dim < 3:
            raise ValueError("--size-expr uses z, but the mesh is two-dimensional")
        xyz = [np.ascontiguousarray(points[:, k], dtype=np.float64) for k in range(dim)]
        with np.errstate(all="ignore"):  # judged on the result below, point by point
            values = np.broadcast_to(np.asarray(evaluate(*xyz), dtype=np.float64), (len(points),))
        bad = ~(np.isfinite(values) & (values > 0))
        if bad.any():
            k = int(np.argmax(bad))
            where = ", ".join(f"{name} = {c[k]:.6g}" for name, c in zip(_EXPR_COORDINATES, xyz))
            raise ValueError(f"--size-expr gives {values[k]:.6g} at point {k} ({where}); "
                             "a size must be a finite number > 0")
        return values

    return size


def _compile_expression(node: ast.AST) -> Callable[..., Any]:
    """A function (x, y[, z]) -> values for one checked node of an --size-expr
    tree; parts without coordinates are folded into one float64 constant, which
    must be finite (so 9**9**9 and 1/0 are refused here)."""
    evaluate = _compile_node(node)
    if not _uses_coordinates(node):
        with np.errstate(all="ignore"):
            value = np.asarray(evaluate(np.zeros(1), np.zeros(1), np.zeros(1)), dtype=np.float64)
        if not np.isfinite(value).all():
            raise ValueError(f"--size-expr: {ast.unparse(node)} is not a finite number in float64 "
                             f"(it is {float(value.reshape(-1)[0])})")
        constant = value.reshape(-1)[0] if value.size == 1 else value
        return lambda *xyz: constant
    return evaluate


def _uses_coordinates(node: ast.AST) -> bool:
    return any(isinstance(n, ast.Name) and n.id in _EXPR_COORDINATES for n in ast.walk(node))


def _compile_node(node: ast.AST) -> Callable[..., Any]:
    allowed = f"allowed: numbers, {', '.join(_EXPR_NAMES)}, + - * / ** and comparisons"
    if isinstance(node, ast.Constant):
        value = node.value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"--size-expr may not use the constant {value!r}; {allowed}")
        try:
            number = np.float64(float(value))
        except OverflowError:
            number = np.float64(np.inf)
        if not np.isfinite(number):
            raise ValueError("--size-expr has a number beyond float64's range (about 1.8e308)")
        return lambda *xyz: number
    if isinstance(node, ast.Name):
        if node.id in _EXPR_COORDINATES:
            axis = _EXPR_COORDINATES.index(node.id)
            return lambda *xyz: xyz[axis]
        if node.id in _EXPR_CONSTANTS:
            constant = np.float64(_EXPR_CONSTANTS[node.id])
            return lambda *xyz: constant
        if node.id in _EXPR_FUNCTIONS:
            raise ValueError(f"--size-expr uses the function {node.id!r} without calling it")
        raise ValueError(f"--size-expr uses unknown name {node.id!r}; {allowed}")
    if isinstance(node, ast.BinOp) and type(node.op) in _EXPR_BINARY:
        op = _EXPR_BINARY[type(node.op)]
        left, right = _compile_expression(node.left), _compile_expression(node.right)
        return lambda *xyz: op(left(*xyz), right(*xyz))
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        operand = _compile_expression(node.operand)
        if isinstance(node.op, ast.USub):
            return lambda *xyz: np.negative(operand(*xyz))
        return operand
    if isinstance(node, ast.Compare) and all(type(op) in _EXPR_COMPARE for op in node.ops):
        # a < b < c means a < b and b < c, element by element
        terms = [_compile_expression(n) for n in (node.left, *node.comparators)]
        ops = [_EXPR_COMPARE[type(op)] for op in node.ops]

        def compare(*xyz: np.ndarray) -> Any:
            values = [term(*xyz) for term in terms]
            result = ops[0](values[0], values[1])
            for k in range(1, len(ops)):
                result = np.logical_and(result, ops[k](values[k], values[k + 1]))
            return result.astype(np.float64)  # 1 or 0; bool would make numpy compute sqrt(x < y) in float16

        return compare
    if isinstance(node, ast.Call):
        name = node.func.id if isinstance(node.func, ast.Name) else None
        if name not in _EXPR_FUNCTIONS:
            called = name if name is not None else ast.unparse(node.func)[:40]
            raise ValueError(f"--size-expr calls unknown name {called!r}; its functions are "
                             f"{', '.join(_EXPR_FUNCTIONS)}")
        function, arity = _EXPR_FUNCTIONS[name]
        if node.keywords or len(node.args) != arity or any(isinstance(a, ast.Starred) for a in node.args):
            raise ValueError(f"--size-expr: {name} takes {arity} argument{'s' if arity > 1 else ''} "
                             "(no keywords)")
        arguments = [_compile_expression(a) for a in node.args]
        return lambda *xyz: function(*(argument(*xyz) for argument in arguments))
    raise ValueError(f"--size-expr may not use {ast.unparse(node)[:40]!r} ({type(node).__name__}); {allowed}")


def _parse_options(items: Sequence[str]) -> dict:
    import ast

    options = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"--option must be NAME=VALUE, got {item!r}")
        try:
            options[name] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            options[name] = value  # a bare word: a string option such as samples=barycentre
    return options


def _parse_circles(items: Sequence[str], corner_angle: float | None) -> Any:
    import evomesh

    if not items:
        if corner_angle is not None:
            raise ValueError("--corner-angle needs at least one --circle")
        return None
    curves = {}
    for item in items:
        tag, sep, rest = item.partition(":")
        numbers = rest.split(",")
        try:
            if not sep or len(numbers) != 3:
                raise ValueError
            curves[int(tag)] = evomesh.Circle((float(numbers[0]), float(numbers[1])), float(numbers[2]))
        except (ValueError, TypeError):
            raise ValueError(f"--circle must be TAG:CX,CY,R with a positive radius, got {item!r}") from None
    kwargs = {} if corner_angle is None else {"corner_angle": corner_angle}
    return evomesh.BoundaryGeometry(curves, **kwargs)


def _check_output(path: str) -> None:
    import os
    from pathlib import Path

    from evomesh.io import check_writable_format

    out = Path(path)
    check_writable_format(out)  # the suffix; h5py for .xdmf
    folder = out.parent if str(out.parent) else Path(".")
    if not folder.is_dir():
        raise ValueError(f"output folder {folder} does not exist")
    if not os.access(folder, os.W_OK) or (out.exists() and not os.access(out, os.W_OK)):
        raise ValueError(f"cannot write {path}")


def _adapt(args: argparse.Namespace) -> int:
    from pathlib import Path

    from tqdm.auto import tqdm

    import evomesh
    from evomesh.evolution import make_options
    from evomesh.io import read_mesh, write_mesh

    # Everything checkable without reading the mesh is checked first.
    _check_output(args.output)
    if not Path(args.input).is_file():
        raise ValueError(f"input mesh file not found: {args.input}")
    size_function = _size_expression(args.size_expr) if args.size_expr else None
    overrides = _parse_options(args.option)
    base = (evomesh.FrfcOptions if args.method == "frfc" else evomesh.DrfcOptions).paper() if args.paper else None
    tet_options = bool(overrides) and set(overrides) <= _TET_OPTION_NAMES
    if not tet_options:  # (TetOptions fields are checked once the file shows tetrahedra)
        make_options(args.method, base, **overrides)
    geometry = _parse_circles(args.circle, args.corner_angle)
    if geometry is not None and args.method != "frfc":
        raise ValueError("--circle (a curved boundary) needs --method frfc")
    with tqdm(total=3, desc="evomesh adapt", unit="stage", disable=True if args.quiet else None, leave=False) as bar:
        mesh, data = read_mesh(args.input)
        bar.update(1)
        field = args.size or args.delta
        if field is not None and field not in data:
            raise ValueError(f"{args.input} has no point data {field!r}; it has: {', '.join(data) or 'none'}")
        target = {"size": size_function} if size_function else {"size": data[field]} if args.size else {}
        delta = data[field] if args.delta else None
        if isinstance(mesh, evomesh.TetMesh):
            if args.paper or geometry is not None or args.method != "frfc":
                raise ValueError("a tetrahedral mesh takes no --paper, --circle or --method drfc (yet)")
            unknown = sorted(set(overrides) - _TET_OPTION_NAMES)
            if unknown:
                raise ValueError(f"unknown option(s) for a tetrahedral mesh: {', '.join(unknown)} (TetOptions has "
                                 f"{', '.join(sorted(_TET_OPTION_NAMES))})")
            new: Any = evolve_tet(mesh, delta, seed=args.seed, options=TetOptions(**overrides), **target)
        else:
            if tet_options:
                make_options(args.method, base, **overrides)
            new = evomesh.evolve(mesh, delta, method=args.method, seed=args.seed, options=base, geometry=geometry,
                                 **target, **overrides)
        bar.update(1)
        fields = {name: values for name, values in data.items() if np.asarray(values).dtype.kind in "biufc"}
        if isinstance(mesh, evomesh.TetMesh):
            carried = {name: transfer_tet(mesh, new, values) for name, values in fields.items()}
        else:
            carried = evomesh.transfer(mesh, new, fields) if fields else {}
        write_mesh(args.output, new, carried or None)
        bar.update(1)
    if not args.quiet:
        kept = f"{mesh.n_points} -> {new.n_points} points ({int((new.origin >= 0).sum())} kept)"
        if isinstance(new, evomesh.TetMesh):
            angles = dihedral_angles(new.points, new.tetrahedra)
            print(f"{kept}, {new.n_tetrahedra} tetrahedra, dihedral angles {angles.min():.2f} to {angles.max():.2f} "
                  f"deg; wrote {args.output}")
        else:
            q = evomesh.quality(new)
            print(f"{kept}, {new.n_triangles} triangles, min angle {q.min_angle:.2f} deg; wrote {args.output}")
    return 0


def _info(args: argparse.Namespace) -> int:
    import evomesh
    from evomesh.io import read_mesh

    mesh, data = read_mesh(args.input)
    if isinstance(mesh, evomesh.TetMesh):
        return _info_tet(args.input, mesh, data)
    q = evomesh.quality(mesh)
    counts = np.bincount(mesh.kind, minlength=5)
    nn = mesh.nn_spacing
    print(f"{args.input}")
    kinds = ", ".join(f"{k.name.lower()} {int(c)}" for k, c in zip(evomesh.PointKind, counts) if c)
    print(f"  points     {mesh.n_points}  ({kinds})")
    print(f"  triangles  {mesh.n_triangles}, area {mesh.area:.6g}, holes {1 - mesh.euler_characteristic()}")
    print(f"  segments   {len(mesh.segments)} ({int(mesh.segment_is_boundary.sum())} boundary)")
    for line in _tag_lines(mesh):
        print(f"  {line}")
    print(f"  spacing    nn min {nn.min():.4g}, median {np.median(nn):.4g}, max {nn.max():.4g}")
    print(f"  quality    min angle {q.min_angle:.2f} deg, max radius/edge {q.max_radius_edge:.3f}")
    print(f"  point data {', '.join(data) or 'none'}")
    return 0


def _info_tet(path: str, mesh: Any, data: dict) -> int:
    import evomesh

    counts = np.bincount(mesh.kind, minlength=len(evomesh.TetPointKind))
    nn = mesh.nn_spacing
    angles = dihedral_angles(mesh.points, mesh.tetrahedra)
    slivers = int(((angles < 10.0) | (angles > 170.0)).any(axis=1).sum())
    ratio = radius_edge_ratios(mesh.points, mesh.tetrahedra)
    print(f"{path}")
    kinds = ", ".join(f"{k.name.lower()} {int(c)}" for k, c in zip(evomesh.TetPointKind, counts) if c)
    print(f"  points       {mesh.n_points}  ({kinds})")
    print(f"  tetrahedra   {mesh.n_tetrahedra}, volume {mesh.volumes.sum():.6g}")
    print(f"  faces        {len(mesh.faces)} ({len(mesh.boundary_faces[0])} boundary)")
    for line in _tag_lines(mesh, ((2, "faces     ", mesh.face_tags), (3, "tetrahedra", mesh.tet_tags))):
        print(f"  {line}")
    print(f"  spacing      nn min {nn.min():.4g}, median {np.median(nn):.4g}, max {nn.max():.4g}")
    print(f"  quality      dihedral angles {angles.min():.2f} to {angles.max():.2f} deg, {slivers} tetrahedra outside "
          f"[10, 170], radius/edge median {np.median(ratio):.3f}, max {ratio.max():.3f}")
    print(f"  point data   {', '.join(data) or 'none'}")
    return 0


def _tag_lines(mesh: Any, cells: Sequence[tuple[int, str, np.ndarray]] | None = None) -> list[str]:
    """The tags of a mesh's cells with their counts and names (``tag "name":
    count``, in increasing tag order), and the names of tags no cell carries;
    ``cells``: (dim, label, tags), default a triangle mesh's segments and triangles."""
    lines = []
    names = mesh.tag_names
    if cells is None:
        cells = ((1, "segments ", mesh.segment_tags), (2, "triangles", mesh.triangle_tags))
    for k, (dim, what, tags) in enumerate(cells):
        values, counts = np.unique(tags, return_counts=True)
        used = set(values.tolist())
        listed = ", ".join(f"{v}{_quoted(names.get((dim, v)))}: {c}" for v, c in zip(values.tolist(), counts.tolist()))
        unused = sorted(tag for d, tag in names if d == dim and tag not in used)
        if unused:
            listed += f" (named, unused: {', '.join(f'{v}{_quoted(names[(dim, v)])}' for v in unused)})"
        lines.append(f"{'tags' if k == 0 else '':<{11 if len(cells[0][1]) < 10 else 13}}{what} {listed or 'none'}")
    return lines


def _quoted(name: str | None) -> str:
    return "" if name is None else f' "{name}"'


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


def _growing_sphere(args: argparse.Namespace) -> int:
    from evomesh.experiments.growing_sphere import growing_sphere

    sphere = {name: getattr(args, name) for name in ("steps", "cells", "r0", "r_end", "band", "h_min", "h_max",
                                                      "grade", "seed", "out")}
    result = growing_sphere(**sphere, figures=not args.no_figures, progress=False if args.quiet else None,
                            **_parse_options(args.option))
    if not args.quiet:
        print(result.table())
        print(f"outputs in {args.out}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``evomesh`` command; returns the exit status
    (0 success, 2 bad arguments or failure, with a one-line message; also for
    a missing optional package, such as h5py for .xdmf files)."""
    parser = build_parser()
    args = parser.parse_args(argv)  # argparse exits with status 2 on malformed options
    try:
        if args.command == "growing-circle":
            return _growing_circle(args)
        if args.command == "growing-sphere":
            return _growing_sphere(args)
        if args.command == "adapt":
            return _adapt(args)
        if args.command == "info":
            return _info(args)
    except (ValueError, TypeError, OSError, ImportError) as error:
        lines = str(error).strip().splitlines()
        print(f"evomesh: error: {lines[0] if lines else type(error).__name__}", file=sys.stderr)
        return 2
    parser.error(f"unknown command {args.command!r}")  # pragma: no cover
    return 2  # pragma: no cover


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
