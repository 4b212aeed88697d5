"""Type stubs of the compiled module evomesh._core (cpp/bindings/module.cpp).

Array arguments are converted by pybind11 (``forcecast``, C order): any array
like of the right shape is accepted. Returned arrays are new numpy arrays of
the dtypes given here; indices are int64, flags and point kinds uint8.
"""

from collections.abc import Callable, Sequence
from typing import Any, ClassVar, TypedDict

import numpy as np
from numpy.typing import ArrayLike, NDArray
from typing_extensions import NotRequired

POINT_KINDS: tuple[tuple[str, int], ...]
PACKING_CLASS_RING: int
PACKING_CLASS_NEW: int
MAX_MIN_ANGLE: float
DEFAULT_CORNER_ANGLE: float
STRAIGHT_ULPS: float

class SampleMode:
    """Where samples are drawn (Section 3.2 step 2; Section 5's variations)."""

    random: ClassVar[SampleMode]
    barycentre: ClassVar[SampleMode]
    midpoints: ClassVar[SampleMode]
    barycentre_midpoints: ClassVar[SampleMode]
    __members__: ClassVar[dict[str, SampleMode]]
    def __init__(self, value: int) -> None: ...
    def __int__(self) -> int: ...
    def __index__(self) -> int: ...
    def __eq__(self, other: object) -> bool: ...
    def __ne__(self, other: object) -> bool: ...
    def __hash__(self) -> int: ...
    @property
    def name(self) -> str: ...
    @property
    def value(self) -> int: ...

class RadiusRule:
    """Sample sphere radius: exact f(x)/2, or the paper's cheap bound."""

    exact: ClassVar[RadiusRule]
    cheap: ClassVar[RadiusRule]
    interpolated: ClassVar[RadiusRule]
    __members__: ClassVar[dict[str, RadiusRule]]
    def __init__(self, value: int) -> None: ...
    def __int__(self) -> int: ...
    def __index__(self) -> int: ...
    def __eq__(self, other: object) -> bool: ...
    def __ne__(self, other: object) -> bool: ...
    def __hash__(self) -> int: ...
    @property
    def name(self) -> str: ...
    @property
    def value(self) -> int: ...

class FrfcOptions:
    """Options of FRFC (evolve(method='frfc')); fields as in C++ evomesh::Frfc_options."""

    fields: ClassVar[tuple[str, ...]]
    cell_factor: float
    radius: RadiusRule
    radius_scale: float
    boundary_scale: float
    ring_samples: bool
    repair_ratio: float
    gap_repair_ratio: float
    refine_gap_ratio: float
    demote_ratio: float
    samples: SampleMode
    adaptive_cells: bool
    skip_coarse: bool
    skip_settled: bool
    filter_samples: bool
    max_samples: float
    threads: int
    seed: int
    quality: bool
    within_domain: bool
    min_angle: float
    crowding_angle: float
    quality_max_fraction: float
    quality_max_extra: float
    incremental: bool
    quality_rounds: bool
    def __init__(self) -> None: ...
    @staticmethod
    def paper() -> FrfcOptions: ...
    @staticmethod
    def recommended() -> FrfcOptions: ...
    def validate(self) -> None: ...
    def __copy__(self) -> FrfcOptions: ...
    def __deepcopy__(self, memo: dict[int, object]) -> FrfcOptions: ...
    def __eq__(self, other: object) -> bool: ...
    def __getstate__(self) -> dict[str, object]: ...
    def __setstate__(self, state: dict[str, object]) -> None: ...

class DrfcOptions:
    """Options of DRFC (evolve(method='drfc')); fields as in C++ evomesh::Drfc_options."""

    fields: ClassVar[tuple[str, ...]]
    min_angle: float
    radius_scale: float
    threads: int
    max_samples: float
    quality: bool
    within_domain: bool
    crowding_angle: float
    quality_max_fraction: float
    quality_max_extra: float
    quality_rounds: bool
    def __init__(self) -> None: ...
    @staticmethod
    def paper() -> DrfcOptions: ...
    @staticmethod
    def recommended() -> DrfcOptions: ...
    def validate(self) -> None: ...
    def __copy__(self) -> DrfcOptions: ...
    def __deepcopy__(self, memo: dict[int, object]) -> DrfcOptions: ...
    def __eq__(self, other: object) -> bool: ...
    def __getstate__(self) -> dict[str, object]: ...
    def __setstate__(self, state: dict[str, object]) -> None: ...

class EvolveResult(TypedDict):
    """What :func:`frfc` and :func:`drfc` return (a plain dict at run time)."""

    points: NDArray[np.float64]  # (n, 2)
    triangles: NDArray[np.int64]  # (t, 3)
    segments: NDArray[np.int64]  # (s, 2)
    segment_is_boundary: NDArray[np.uint8]  # (s,)
    kind: NDArray[np.uint8]  # (n,)
    origin: NDArray[np.int64]  # (n,), -1 for a new point
    input_f: NDArray[np.float64]  # (n_input,)
    input_nn: NDArray[np.float64]  # (n_input,)
    output_nn: NotRequired[NDArray[np.float64]]  # (n,), Euclidean nn of the output points
    output_nn_grew: NotRequired[NDArray[np.int64]]  # where nn within the domain is larger
    output_nn_grown: NotRequired[NDArray[np.float64]]  # its value there
    parent_triangle: NDArray[np.int64]  # (n,), input triangle of a new point, -1 for kept ones
    segment_tags: NotRequired[NDArray[np.int64]]  # when the input had tags
    triangle_tags: NotRequired[NDArray[np.int64]]
    required: NotRequired[NDArray[np.uint8]]
    barycentric: NDArray[np.float64]  # (n, 3), its coordinates there
    stats: dict[str, float]

class RefineResult(TypedDict):
    """What :func:`drfc_refine` returns (a plain dict at run time)."""

    points: NDArray[np.float64]
    triangles: NDArray[np.int64]
    segments: NDArray[np.int64]
    segment_is_boundary: NDArray[np.uint8]
    kind: NDArray[np.uint8]
    origin: NDArray[np.int64]
    f: NDArray[np.float64]
    stats: dict[str, float]

class SpacingFunction:
    def __init__(
        self,
        sites: ArrayLike,
        weights: ArrayLike,
        min_sites_per_part: int = 0,
        triangles: ArrayLike | None = None,
        site_ids: ArrayLike | None = None,
        shift: float = 0.0,
    ) -> None: ...
    def evaluate(
        self, x: ArrayLike, threads: int = 0, certified: bool = True
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """(f, site): f at the (k, 2) points x and the index of the site attaining it."""
    @property
    def n_sites(self) -> int: ...
    @property
    def n_hidden(self) -> int: ...
    @property
    def n_filtered(self) -> int: ...
    @property
    def n_parts(self) -> int: ...

def prepare_mesh(
    points: ArrayLike,
    triangles: ArrayLike,
    segments: ArrayLike | None = None,
    check_planar: bool = True,
    segment_tags: ArrayLike | None = None,
    required: ArrayLike | None = None,
    reference_planarity: bool = False,
) -> tuple[
    NDArray[np.int64], NDArray[np.int64], NDArray[np.uint8], NDArray[np.uint8], int, NDArray[np.int64], dict[str, float]
]:
    """Orient triangles CCW, build segments, check planarity, classify points.
    Returns (triangles, segments, segment_is_boundary, kind, n_flipped, segment_tags, {stage: seconds}).
    reference_planarity: the older check (a constrained Delaunay triangulation of every edge)."""

def quality_summary(
    points: ArrayLike, triangles: ArrayLike
) -> tuple[float, float, float, float, int, NDArray[np.int64]]: ...
def first_inverted_triangle(points: ArrayLike, triangles: ArrayLike) -> int: ...
def first_flat_triangles(
    points: ArrayLike, triangles: ArrayLike, min_relative_height: float, min_height_ulps: float
) -> tuple[int, int]: ...

def first_pinched_boundary(
    points: ArrayLike, boundary: ArrayLike, corner: ArrayLike, min_ulps: float
) -> tuple[int, int]: ...

def nn_spacing(
    points: ArrayLike, triangles: ArrayLike | None = None, euclidean: ArrayLike | None = None
) -> NDArray[np.float64]: ...
def edge_over_size_around(points: ArrayLike, triangles: ArrayLike, h: ArrayLike) -> NDArray[np.float64]: ...
def edge_over_size_classes(
    points: ArrayLike, triangles: ArrayLike, h: ArrayLike, above: float, below: float, at_least: float
) -> NDArray[np.uint8]: ...
def delta_from_size(
    points: ArrayLike,
    triangles: ArrayLike,
    h: ArrayLike,
    nn: ArrayLike,
    keep_fine_clusters: bool,
    delta_min: float,
    delta_max: float,
    n_checked: int | None = None,
    ids: ArrayLike | None = None,
) -> NDArray[np.float64]: ...

SIZE_RULE_RINGS: int

def check_size_delta(delta: ArrayLike, h: ArrayLike, nn: ArrayLike, delta_min: float, delta_max: float) -> None: ...
def near_seeds(
    triangles: ArrayLike, points: ArrayLike, seeds: ArrayLike, rings: int, through: ArrayLike | None = None
) -> NDArray[np.uint8]: ...
def sharing_a_triangle(triangles: ArrayLike, marked: ArrayLike) -> NDArray[np.uint8]: ...
def nn_within_domain(
    points: ArrayLike, triangles: ArrayLike, euclidean: ArrayLike | None = None
) -> tuple[NDArray[np.float64], NDArray[np.int64]]: ...
def default_thread_count() -> int: ...
def environment_thread_count() -> int: ...
def available_cpu_count() -> int: ...
def _parallel_counts(reset: bool = False) -> dict[str, int]: ...

class ThreadLimit:
    def __init__(self, threads: int) -> None: ...
    @property
    def threads(self) -> int: ...
    def __enter__(self) -> ThreadLimit: ...
    def __exit__(self, *args: object) -> None: ...

def step_spacing(
    points: ArrayLike,
    triangles: ArrayLike,
    segments: ArrayLike,
    segment_is_boundary: ArrayLike,
    kind: ArrayLike,
    delta: ArrayLike,
    within_domain: bool = True,
    segment_tags: ArrayLike | None = None,
    required: ArrayLike | None = None,
    nn: ArrayLike | None = None,
    nn_grew: ArrayLike | None = None,
    point_gids: ArrayLike | None = None,
    triangle_gids: ArrayLike | None = None,
    segment_keys: ArrayLike | None = None,
) -> dict[str, NDArray[np.float64]]: ...
def chain_table(
    points: ArrayLike,
    segments: ArrayLike,
    segment_is_boundary: ArrayLike,
    kind: ArrayLike,
    segment_tags: ArrayLike | None = None,
    required: ArrayLike | None = None,
    point_gids: ArrayLike | None = None,
    segment_keys: ArrayLike | None = None,
    curved_tags: ArrayLike | None = None,
    corner_angle: float = ...,
    project: Callable[..., Any] | None = None,
) -> dict[str, NDArray[Any]]: ...
def part_input_spheres(
    part: dict[str, Any], f: ArrayLike, options: FrfcOptions, demoted: ArrayLike | None = None
) -> tuple[NDArray[np.float64], NDArray[np.uint8], NDArray[np.uint8]]: ...
def part_point_flags(
    part: dict[str, Any], nn: ArrayLike, f: ArrayLike, delta: ArrayLike, options: FrfcOptions
) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]: ...
def part_asking_spacing(
    part: dict[str, Any], f: ArrayLike, cell_factor: float
) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]: ...
def part_segment_candidates(
    part: dict[str, Any],
    delta: ArrayLike,
    f: ArrayLike,
    options: FrfcOptions,
    settled: ArrayLike | None = None,
    spacing: SpacingFunction | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.uint8], NDArray[np.int64]]: ...
def part_interior_candidates(
    part: dict[str, Any],
    delta: ArrayLike,
    f: ArrayLike,
    options: FrfcOptions,
    sampled: ArrayLike,
    demoted: ArrayLike | None = None,
    settled: ArrayLike | None = None,
    ring_from: ArrayLike | None = None,
    spacing: SpacingFunction | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.uint8], NDArray[np.int64]]: ...
def part_candidate_radii(
    part: dict[str, Any],
    f: ArrayLike,
    spacing: SpacingFunction | None,
    options: FrfcOptions,
    on_segment: bool,
    centres: ArrayLike,
    parent: ArrayLike,
    demoted: ArrayLike | None = None,
) -> NDArray[np.float64]: ...
def part_ring_candidates(
    part: dict[str, Any], f: ArrayLike, options: FrfcOptions, points: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.uint8]]: ...
def repair_targets(repair_ratio: float, delta: ArrayLike, nn: ArrayLike) -> NDArray[np.float64]: ...
def repair_kept_distances(kept: ArrayLike, queries: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
def repair_decisions(
    at: ArrayLike,
    target2: ArrayLike,
    nn2: ArrayLike,
    xadj: ArrayLike,
    candidates: ArrayLike,
    kept2: ArrayLike,
    added: ArrayLike,
) -> NDArray[np.int64]: ...
def part_gap_candidates(
    part: dict[str, Any], points: ArrayLike, delta: ArrayLike, nn: ArrayLike, seed: int
) -> tuple[NDArray[np.float64], NDArray[np.uint8], NDArray[np.uint8]]: ...
def gap_targets(
    delta: ArrayLike, nn: ArrayLike, demoted: ArrayLike, kept: ArrayLike, gap_ratio: float, refine_ratio: float
) -> NDArray[np.float64]: ...
def gap_decisions(
    at: ArrayLike,
    delta: ArrayLike,
    nn: ArrayLike,
    demoted: ArrayLike,
    directions: ArrayLike,
    inside: ArrayLike,
    kept2: ArrayLike,
    gap_ratio: float,
    refine_ratio: float,
    added: ArrayLike,
) -> NDArray[np.int64]: ...
def hilbert_keys(ix: ArrayLike, iy: ArrayLike, order: int) -> NDArray[np.int64]: ...
def part_curve_kinds(part: dict[str, Any]) -> NDArray[np.uint8]: ...
def part_project_segment_candidates(
    part: dict[str, Any], centres: ArrayLike, parent: ArrayLike, radius: ArrayLike
) -> tuple[NDArray[np.float64], float]: ...
def part_pieces(
    part: dict[str, Any], candidate_segment: ArrayLike, kept_candidate: ArrayLike, kept_point: ArrayLike
) -> tuple[NDArray[np.int64], NDArray[np.uint8], NDArray[np.int64]]: ...
def part_parent_triangles(
    points: ArrayLike,
    triangles: ArrayLike,
    triangle_keys: ArrayLike,
    queries: ArrayLike,
    fallback: ArrayLike | None = None,
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """(triangle containing each query of least key, -1 if outside; barycentric coordinates (k, 3))."""
def chain_feature_sizes(
    points: ArrayLike,
    triangles: ArrayLike,
    triangle_gids: ArrayLike,
    segments: ArrayLike,
    segment_chain: ArrayLike,
    chain_ids: ArrayLike,
    chain_ends: ArrayLike,
    point: ArrayLike,
    before: ArrayLike,
    after: ArrayLike,
    along: ArrayLike,
    two_sided: ArrayLike,
    point_chain: ArrayLike,
    limit: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.uint8]]: ...
def lexical_first_mis(
    centers: ArrayLike, radii: ArrayLike, order: ArrayLike, n_forced: int = 0
) -> NDArray[np.uint8]: ...
def packing_order(classes: ArrayLike, radii: ArrayLike) -> NDArray[np.int64]: ...
def lexical_first_mis_in_rounds(
    centers: ArrayLike, radii: ArrayLike, order: ArrayLike, n_forced: int, part: ArrayLike, n_parts: int
) -> dict[str, Any]: ...

class MisPart:
    def __init__(self, centers: ArrayLike, radii: ArrayLike, order: ArrayLike, owned: ArrayLike) -> None: ...
    def sweep(self, state: ArrayLike) -> tuple[NDArray[np.uint8], NDArray[np.int64]]: ...
    @property
    def undecided(self) -> int: ...

def frfc(
    points: ArrayLike,
    triangles: ArrayLike,
    segments: ArrayLike,
    segment_is_boundary: ArrayLike,
    kind: ArrayLike,
    delta: ArrayLike,
    options: FrfcOptions = ...,
    segment_tags: ArrayLike | None = None,
    triangle_tags: ArrayLike | None = None,
    required: ArrayLike | None = None,
    curved_tags: ArrayLike | None = None,
    corner_angle: float = ...,
    project: Callable[[NDArray[np.float64], NDArray[np.int64]], ArrayLike] | None = None,
    nn: ArrayLike | None = None,
    nn_grew: ArrayLike | None = None,
    point_gids: ArrayLike | None = None,  # global ids: None = the array positions
    triangle_gids: ArrayLike | None = None,
    segment_keys: ArrayLike | None = None,
    strictly_delaunay: bool = False,  # the triangles certified strictly Delaunay by a step (Mesh._delaunay)
) -> EvolveResult:
    """Functional-Refining-Functional-Coarsening (Section 3.2): one step; returns a dict of arrays and stats."""

def drfc(
    points: ArrayLike,
    triangles: ArrayLike,
    segments: ArrayLike,
    segment_is_boundary: ArrayLike,
    kind: ArrayLike,
    delta: ArrayLike,
    options: DrfcOptions = ...,
    segment_tags: ArrayLike | None = None,
    triangle_tags: ArrayLike | None = None,
    required: ArrayLike | None = None,
    curved_tags: ArrayLike | None = None,
    corner_angle: float = ...,
    project: Callable[[NDArray[np.float64], NDArray[np.int64]], ArrayLike] | None = None,
    nn: ArrayLike | None = None,
    nn_grew: ArrayLike | None = None,
    point_gids: ArrayLike | None = None,  # global ids: None = the array positions
    triangle_gids: ArrayLike | None = None,
    segment_keys: ArrayLike | None = None,
    strictly_delaunay: bool = False,
) -> EvolveResult:
    """Delaunay-Refining-Functional-Coarsening (Section 5); returns the same dict as frfc."""

def drfc_refine(
    points: ArrayLike,
    triangles: ArrayLike,
    segments: ArrayLike,
    segment_is_boundary: ArrayLike,
    kind: ArrayLike,
    delta: ArrayLike,
    options: DrfcOptions = ...,
    segment_tags: ArrayLike | None = None,
    triangle_tags: ArrayLike | None = None,
    required: ArrayLike | None = None,
    curved_tags: ArrayLike | None = None,
    corner_angle: float = ...,
    project: Callable[[NDArray[np.float64], NDArray[np.int64]], ArrayLike] | None = None,
) -> RefineResult:
    """DRFC step 1 alone: Delaunay refinement with Ruppert's rules and rule 4 (Section 5)."""

def constrained_delaunay(points: ArrayLike, pieces: ArrayLike, boundary: ArrayLike) -> NDArray[np.int64]: ...
def convex_hull_vertices(points: ArrayLike) -> NDArray[np.int64]: ...
def supports_on_left(a: ArrayLike, b: ArrayLike, points: ArrayLike) -> NDArray[np.uint8]: ...
def local_constrained_delaunay(
    points: ArrayLike, pieces: ArrayLike, boundary: ArrayLike
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.uint8], NDArray[np.uint8]]: ...
def quality_triangulate(
    points: ArrayLike,
    pieces: ArrayLike,
    boundary: ArrayLike,
    min_angle: float = ...,
    crowding_angle: float = ...,
    max_fraction: float = ...,
    max_extra: float = ...,
    quality_rounds: bool = ...,
) -> dict[str, Any]:
    """The quality pass alone (Section 6; in rounds with quality_rounds=True)."""

def triangulate_selection(
    points: ArrayLike,
    kind: ArrayLike,
    required: ArrayLike,
    fresh: ArrayLike,
    pieces: ArrayLike,
    boundary: ArrayLike,
    piece_tags: ArrayLike,
    options: FrfcOptions,
    curved_tags: ArrayLike | None = ...,
    corner_angle: float = ...,
    project: Callable[..., Any] | None = ...,
    batches: Sequence[int] = ...,
) -> dict[str, Any]:
    """The step's last stage on a selection (quality pass or CDT, curve fit); the distributed step's root."""

class SupermeshResult(TypedDict):
    """What :func:`supermesh` returns (a plain dict at run time)."""

    offsets: NDArray[np.int64]  # (n_new_triangles + 1,), pairs of new triangle t: offsets[t]:offsets[t+1]
    old_triangle: NDArray[np.int64]  # (pairs,)
    area: NDArray[np.float64]  # (pairs,), |t n s|
    mass: NDArray[np.float64]  # (pairs, 3, 3), int phi^new_a phi^old_b; (0, 3, 3) when mass=False
    identical: NDArray[np.int64]  # (n_new_triangles,), the old triangle a new one is (three kept points), else -1

def supermesh(
    old_points: ArrayLike,
    old_triangles: ArrayLike,
    new_points: ArrayLike,
    new_triangles: ArrayLike,
    origin: ArrayLike,
    parent_triangle: ArrayLike,
    mass: bool = True,
    threads: int = 0,
    shortcut: bool = True,
) -> SupermeshResult:
    """Local supermesh of new over old (cpp/src/supermesh.cpp), seeded by the step's origin and parent_triangle;
    shortcut=False clips the new triangles that are old ones too (for the tests)."""

def p1_mass_matrix(
    points: ArrayLike, triangles: ArrayLike, threads: int = 0
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """The P1 mass matrix in compressed rows: (data, indices, indptr), columns sorted in each row."""

def mixed_mass_times(
    offsets: ArrayLike,
    old_triangle: ArrayLike,
    mass: ArrayLike,
    old_triangles: ArrayLike,
    new_triangles: ArrayLike,
    n_new_points: int,
    values: ArrayLike,
) -> NDArray[np.float64]:
    """A supermesh's mixed mass matrix times old values (n_old_points, columns): (n_new_points, columns)."""

def solve_p1_mass(
    data: ArrayLike, indices: ArrayLike, indptr: ArrayLike, rhs: ArrayLike, threads: int = 0
) -> tuple[NDArray[np.float64], int]:
    """M u = rhs (n, columns) for a P1 mass matrix in compressed rows, to rounding: (u, iterations)."""

def locate_points(
    points: ArrayLike, triangles: ArrayLike, queries: ArrayLike
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """(triangle index per query, -1 if outside; barycentric coordinates (k, 3))."""

class MovedTriangulation(TypedDict):
    """What :func:`triangulate_moved` returns (a plain dict at run time)."""

    triangles: NDArray[np.int64]  # (m, 3) counter-clockwise, inside the domain
    triangle_tags: NDArray[np.int64]  # (m,)
    unused: NDArray[np.int64]  # points in no triangle of the domain
    on_piece: NDArray[np.int64]  # (j, 2): (point, piece) for points inside a piece
    conflict: int  # a piece whose side met another region's fill, or -1
    crossing: int  # a piece that crossed an earlier one, or -1

def triangulate_moved(
    points: ArrayLike, pieces: ArrayLike, boundary: ArrayLike, left: ArrayLike, right: ArrayLike
) -> MovedTriangulation:
    """Constrained Delaunay triangulation of the moved points with the pieces as constraints, regions
    flood-filled from the pieces' sides (cpp/src/motion.cpp)."""

# Tetrahedral meshes (cpp/bindings/bind_tet.cpp).
def tet_nn_spacing(points: ArrayLike, threads: int = 0) -> NDArray[np.float64]: ...
def tet_orientations(points: ArrayLike, tetrahedra: ArrayLike) -> NDArray[np.int8]: ...
def cone_envelope_3(
    sites: ArrayLike, weights: ArrayLike, queries: ArrayLike, brute_force: bool = False, threads: int = 0
) -> tuple[NDArray[np.float64], int]: ...
def delaunay_tetrahedra(points: ArrayLike) -> NDArray[np.int64]: ...
def tet_step(
    points: ArrayLike,
    tetrahedra: ArrayLike,
    boundary: ArrayLike,
    boundary_tet: ArrayLike,
    steiner: ArrayLike,
    required: ArrayLike,
    weight: ArrayLike,
    facets: ArrayLike,
    edge_facets: ArrayLike,
    edge_ends: ArrayLike,
    neighbours: ArrayLike,
    boundary_facet: ArrayLike,
    cell_factor: float,
    radius_scale: float,
    boundary_clearance: float,
    max_radius_edge: float,
    sliver_angle: float,
    max_samples: float,
    seed: int,
    threads: int,
    cap: Callable[[NDArray[np.float64], NDArray[np.int64]], ArrayLike] | None = None,
) -> dict[str, Any]: ...
def tet_domain_incidences(
    points: ArrayLike, facets: ArrayLike, edge_facets: ArrayLike, edge_ends: ArrayLike, neighbours: ArrayLike
) -> NDArray[np.int64]: ...
def check_tet_options(
    cell_factor: float,
    radius_scale: float,
    boundary_clearance: float,
    max_radius_edge: float,
    sliver_angle: float,
    max_samples: float,
    threads: int,
) -> None: ...
def tet_supermesh(
    old_points: ArrayLike,
    old_tetrahedra: ArrayLike,
    new_points: ArrayLike,
    new_tetrahedra: ArrayLike,
    origin: ArrayLike,
    parent_tet: ArrayLike,
    threads: int = 0,
) -> dict[str, Any]: ...
def tet_intersection_volume(t: ArrayLike, s: ArrayLike) -> float: ...
