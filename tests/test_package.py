"""The package's structure: an acyclic import graph, no submodule hidden by a
function, the typing marker."""

from __future__ import annotations

import ast
import importlib
import importlib.util
import pkgutil
from pathlib import Path

import evomesh

PACKAGE_DIR = Path(evomesh.__file__).resolve().parent


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE_DIR.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PACKAGE_DIR.rglob("*.py"))}


def _resolve(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    if not node.level:
        return node.module or ""
    base = module.split(".")
    base = base if is_package else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _is_module(name: str, known: set[str]) -> bool:
    if name in known:
        return True
    try:
        return importlib.util.find_spec(name) is not None  # e.g. the compiled evomesh._core
    except (ImportError, ValueError):
        return False


def _imports(module: str, path: Path, known: set[str]) -> set[str]:
    """evomesh modules imported anywhere in the file: at module level, inside
    functions, under ``if TYPE_CHECKING`` alike. ``from evomesh import x``
    imports the submodule evomesh.x if there is one, else a name of the
    package evomesh (its __init__)."""
    targets: set[str] = set()
    is_package = path.name == "__init__.py"
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(node, module, is_package)
            for alias in node.names:
                full = f"{base}.{alias.name}"
                targets.add(full if _is_module(full, known) else base)
    found: set[str] = set()
    for name in targets:
        if name != "evomesh" and not name.startswith("evomesh."):
            continue
        while name not in known and "." in name:
            if _is_module(name, known):  # compiled (evomesh._core): imports no evomesh module
                break
            name = name.rsplit(".", 1)[0]  # "import evomesh.x.NAME" style: the module holding NAME
        if name in known and name != module:
            found.add(name)
    return found


def import_graph() -> dict[str, set[str]]:
    """module -> the evomesh modules it imports (module names as in sys.modules)."""
    modules = _modules()
    known = set(modules)
    return {name: _imports(name, path, known) for name, path in modules.items()}


def _find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    WHITE, GREY, BLACK = 0, 1, 2
    colour = dict.fromkeys(graph, WHITE)
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        colour[node] = GREY
        stack.append(node)
        for nxt in sorted(graph[node]):
            if colour[nxt] == GREY:
                return stack[stack.index(nxt) :] + [nxt]
            if colour[nxt] == WHITE:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        stack.pop()
        colour[node] = BLACK
        return None

    for node in sorted(graph):
        if colour[node] == WHITE:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


def test_the_graph_sees_the_modules_and_their_imports():
    graph = import_graph()
    assert {"evomesh", "evomesh.time_loop", "evomesh.io", "evomesh.experiments.growing_circle"} <= set(graph)
    # a module-level and a function-level import are both seen
    assert "evomesh.time_loop" in graph["evomesh.io"]
    assert "evomesh.plotting" in graph["evomesh.io"]


def test_import_graph_is_acyclic():
    graph = import_graph()
    cycle = _find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_find_cycle_finds_one():
    assert _find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _find_cycle({"a": {"b"}, "b": set()}) is None


def _packages() -> list[str]:
    return ["evomesh"] + [
        info.name for info in pkgutil.walk_packages(evomesh.__path__, "evomesh.") if info.ispkg
    ]


def test_no_submodule_is_hidden_by_an_attribute():
    for package_name in _packages():
        package = importlib.import_module(package_name)
        for info in pkgutil.iter_modules(package.__path__):
            attribute = getattr(package, info.name, None)
            assert attribute is None or type(attribute) is type(evomesh), (
                f"{package_name}.{info.name} is hidden by {attribute!r}"
            )
            module = importlib.import_module(f"{package_name}.{info.name}")
            assert module.__name__ == f"{package_name}.{info.name}"


def test_public_names_of_the_package_are_kept():
    names = {
        "Mesh", "PointKind", "evolve", "delaunay_refine", "FRFC_DEFAULTS", "DRFC_DEFAULTS", "FrfcOptions",
        "DrfcOptions", "SampleMode", "RadiusRule", "nn_spacing", "spacing", "SpacingFunction",
        "lexical_first_mis", "quality", "Quality", "Front", "CircleFront", "PointFront", "LevelSetFront",
        "SpacingLaw", "transfer", "run", "Run", "Step", "Driver", "step_statistics", "growing_circle",
        "unit_square_mesh", "Lineage",
    }  # fmt: skip
    assert names <= set(evomesh.__all__)  # names stay; new ones may join
    for name in names:
        assert hasattr(evomesh, name), name
    from evomesh import time_loop

    assert evomesh.run is time_loop.run and evomesh.Driver is time_loop.Driver


def test_typing_marker_and_stubs_are_in_the_package():
    assert (PACKAGE_DIR / "py.typed").is_file()
    assert (PACKAGE_DIR / "_core.pyi").is_file()
