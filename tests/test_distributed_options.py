"""The serial step's recommended options on MPI ranks (evomesh.distributed.step):
demotion, settled and coarse skipping, adaptive grid cells, ring candidates and
the cheap radius, each alone and together, give the serial step's mesh array
for array on any number of ranks.

Plain ``pytest`` runs these on one rank; CI runs them under ``mpiexec -n 2`` and
``-n 4`` too (tools/run-tests.sh).
"""

from __future__ import annotations

import numpy as np
import pytest

import evomesh
from evomesh import _core
from evomesh.meshgen import polygon_mesh
from strategies import crack_mesh, holes_mesh

MPI = pytest.importorskip("mpi4py.MPI")
from evomesh import DistributedMesh  # noqa: E402
from evomesh.distributed.step import _grid_graph, _pack, evolve_distributed  # noqa: E402
from mpi_support import check_everywhere, watchdog  # noqa: E402,F401 (watchdog: an autouse fixture)

COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size

_ARRAYS = ("points", "triangles", "segments", "segment_tags", "segment_is_boundary", "kind", "origin", "required")


def _crack() -> evomesh.Mesh:
    """A notched square with a tagged interior crack."""
    return crack_mesh(17)


_DOMAINS = {
    "L-shape": lambda: polygon_mesh([[(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]], 0.13),
    "two holes": holes_mesh,
    "crack": _crack,
}
_MESHES: dict = {}


def _mesh(name: str) -> evomesh.Mesh:
    if name not in _MESHES:
        _MESHES[name] = _DOMAINS[name]()
    return _MESHES[name]


def _options(option: str, seed: int) -> _core.FrfcOptions:
    """The paper's options with one of the serial step's recommended options
    turned on, or ("all") the recommended options less the spacing repair
    (tests/test_distributed_repair.py) and the quality pass (tests/test_distributed_quality.py)."""
    if option == "all":
        o = _core.FrfcOptions.recommended()
        o.quality = False
        o.repair_ratio = o.gap_repair_ratio = o.refine_gap_ratio = 0.0
    else:
        o = _core.FrfcOptions.paper()
        if option == "demote":
            o.demote_ratio = 1.1
            o.radius = _core.RadiusRule.interpolated  # (its sizes read the demoted flags)
        elif option == "skip":
            o.skip_settled = o.skip_coarse = True
        elif option == "adaptive":
            o.adaptive_cells = True
            o.cell_factor = 2.0
        elif option == "ring":
            o.ring_samples = True
        elif option == "cheap":
            o.radius = _core.RadiusRule.cheap
        else:
            raise AssertionError(option)
    o.seed = seed
    return o


def _delta(points: np.ndarray, kind: str, t: int, box: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """delta at `points`: a moving front (refine in a band, 1 or coarsen
    elsewhere), random, or spikes (a few points asking for 1e-3 of their
    spacing: grids far finer than their triangles and segments, which ask f).
    `box`: the domain's (lower, upper) corners."""
    lo, hi = box
    if kind.startswith("front"):
        centre = lo + np.array([0.25 + 0.25 * t, 0.6]) * (hi - lo)
        distance = np.abs(np.hypot(*(points - centre).T) - 0.25 * (hi - lo).min())
        outside = 1.0 if kind == "front-1" else 2.0
        return np.where(distance < 0.1 * (hi - lo).min(), 0.45, outside)
    # (a function of the coordinates, so every rank computes it for its own points)
    key = np.floor(points[:, 0] * 7919.0 + points[:, 1] * 104729.0 + 31.0 * t)
    u = (np.sin(key) * 43758.5453) % 1.0
    if kind == "random":
        return 0.35 + 2.5 * u
    assert kind == "spikes"
    bottom = (np.abs(points[:, 1] - lo[1]) < 1e-12) & (np.abs(points[:, 0] - lo[0] - 0.5 * (hi - lo)[0]) < 0.1)
    return np.where(bottom, 1e-4, np.where(u < 0.01, 1e-3, 1.5))  # (1e-4: long enough segment grids to ask f)


def _compare_loop(name: str, option: str, kinds: list[str], layout: str = "even") -> list[dict]:
    """A time loop with delta of `kinds`, one per step, on the ranks and serial:
    every gathered step equals the serial one. Returns the steps' stats."""
    mesh = _mesh(name)
    box = (mesh.points.min(axis=0), mesh.points.max(axis=0))
    options = _options(option, seed=3)
    weights = np.random.default_rng(1).uniform(0.1, 10.0, len(mesh.triangles)) if layout == "weighted" else None
    dmesh = DistributedMesh.scatter(mesh if RANK == 0 else None, COMM, weights=weights)
    serial = mesh
    out = []
    for t, kind in enumerate(kinds):
        stats: dict = {}
        dmesh = evolve_distributed(dmesh, lambda xy, t=t, kind=kind: _delta(xy, kind, t, box), options=options,
                                   stats=stats)
        if RANK == 0:
            serial = evomesh.evolve(serial, _delta(serial.points, kind, t, box), options=options)
        gathered = dmesh.gather()
        same = RANK != 0 or all(np.array_equal(getattr(gathered, k), getattr(serial, k)) for k in _ARRAYS)
        check_everywhere(same, f"{option}, step {t} ({kind}) differs from the serial step")
        out.append(stats)
    return out


@pytest.mark.parametrize("name", list(_DOMAINS))
@pytest.mark.parametrize("option", ["demote", "skip", "ring", "cheap", "all"])
def test_each_option_on_ranks_gives_the_serial_meshes(option: str, name: str) -> None:
    _compare_loop(name, option, ["front", "front-1", "random"], layout="weighted" if name == "crack" else "even")


@pytest.mark.parametrize("option", ["adaptive", "all"])
def test_adaptive_cells_on_ranks_give_the_serial_meshes(option: str) -> None:
    """Spikes make grids ask f inside triangles and along a segment."""
    stats = _compare_loop("L-shape", option, ["spikes", "front"])
    assert stats[0]["asking_grids"] > 0


@pytest.mark.parametrize("option", ["demote", "skip", "ring", "cheap", "all"])
def test_each_option_changes_the_step(option: str) -> None:
    """Each option changes the serial step here (so the comparisons above test it)."""
    if RANK != 0:
        return
    mesh = _mesh("two holes")
    box = (mesh.points.min(axis=0), mesh.points.max(axis=0))
    kind = "front-1" if option == "skip" else "front"
    reference = evomesh.evolve(mesh, _delta(mesh.points, kind, 0, box), options=_options("cheap", 3))
    if option == "cheap":
        paper = _core.FrfcOptions.paper()
        paper.seed = 3
        other = evomesh.evolve(mesh, _delta(mesh.points, kind, 0, box), options=paper)
    else:
        options = _options(option, 3)
        options.radius = _core.RadiusRule.cheap if option != "all" else options.radius
        other = evomesh.evolve(mesh, _delta(mesh.points, kind, 0, box), options=options)
    assert other.points.shape != reference.points.shape or not np.array_equal(other.points, reference.points)


def _reference_pack(mesh: evomesh.Mesh, kind: str, options: _core.FrfcOptions) -> dict:
    """_pack's flags on the whole mesh as one rank's part (every fan whole): the serial flags, by global id."""
    box = (mesh.points.min(axis=0), mesh.points.max(axis=0))
    whole = DistributedMesh.scatter(mesh, MPI.COMM_SELF)
    packed = _pack(whole, lambda xy: _delta(xy, kind, 0, box), options, None)
    return dict(gids=packed["part"]["point_gids"], demoted=packed["demoted"], settled=packed["settled"])


@pytest.mark.parametrize("name", list(_DOMAINS))
def test_point_flags_are_the_owners(name: str) -> None:
    """The demoted and settled flags at every point of every rank's part (held
    points and the skeleton) are the serial ones, also where the part does not
    hold a point's whole fan (the owner's flag comes by the halo exchange, and
    by the replicated skeleton)."""
    mesh = _mesh(name)
    box = (mesh.points.min(axis=0), mesh.points.max(axis=0))
    options = _options("all", 3)
    dmesh = DistributedMesh.scatter(mesh if RANK == 0 else None, COMM, halo_rings=2)
    for kind in ("front", "front-1"):
        packed = _pack(dmesh, lambda xy, kind=kind: _delta(xy, kind, 0, box), options, None)
        reference = COMM.bcast(_reference_pack(mesh, kind, options) if RANK == 0 else None)
        at = np.searchsorted(reference["gids"], packed["part"]["point_gids"])
        for flag in ("demoted", "settled"):
            check_everywhere(np.array_equal(packed[flag], reference[flag][at]), f"{kind}: {flag} flags differ")
        if RANK == 0:
            assert reference["demoted"].any() if kind == "front" else reference["settled"].any()


def test_grid_graphs_are_exact_over_their_boxes() -> None:
    """_grid_graph's spacing function gives f exactly (DistributedSpacing.evaluate,
    the serial f bit for bit) anywhere in the bounding boxes of the simplices
    it serves, here every owned triangle and segment, on a thin halo (none)."""
    mesh = _mesh("two holes")
    box = (mesh.points.min(axis=0), mesh.points.max(axis=0))
    dmesh = DistributedMesh.scatter(mesh if RANK == 0 else None, COMM, halo_rings=0)
    options = _options("cheap", 0)
    options.within_domain = False  # (weights up to 8 nn: f far above the spacing, sites from afar)
    packed = _pack(dmesh, lambda xy: 4.0 * _delta(xy, "random", 0, box) - 1.0, options, None)
    part, spacing, f = packed["part"], packed["spacing"], packed["f_part"]
    rng = np.random.default_rng(RANK)
    mine = packed["skeleton"][1]["owner"][np.searchsorted(packed["skeleton"][1]["gid"],
                                                          packed["skeleton"][0]["v"].min(axis=1))] == RANK
    for rows in (part["triangles"][: len(dmesh.triangles)], part["segments"][mine]):
        graph = _grid_graph(COMM, spacing, part, f, rows)
        corners = part["points"][rows]
        lo, hi = corners.min(axis=1), corners.max(axis=1)
        x = (lo[:, None, :] + rng.uniform(0, 1, (len(rows), 4, 2)) * (hi - lo)[:, None, :]).reshape(-1, 2)
        got = graph.evaluate(x)[0] if graph is not None and len(x) else np.zeros(0)
        want = spacing.evaluate(x)
        check_everywhere(np.array_equal(got, want), "f from a grid's graph differs from f")


def test_still_refused() -> None:
    thin = DistributedMesh.scatter(_mesh("L-shape") if RANK == 0 else None, COMM, halo_rings=0)
    with pytest.raises(ValueError, match="halo_rings=0"):
        evomesh.evolve(thin, np.ones(thin.n_owned), options=_options("ring", 0))
    options = _options("all", 0)
    options.gap_repair_ratio = 1.1  # (its walks start in each point's fan; the repair: test_distributed_repair.py)
    with pytest.raises(ValueError, match="the gap repair on a DistributedMesh need a halo"):
        evomesh.evolve(thin, np.ones(thin.n_owned), options=options)
