"""evomesh: simultaneous refinement and coarsening of triangle meshes.

Implements Li, Teng and Ungor, "Simultaneous Refinement and Coarsening for
Adaptive Meshing": one call to :func:`evolve` refines where delta < 1 and
coarsens where delta > 1, keeping the mesh well shaped and as many old points
as it can.
"""

from evomesh.distributed import DistributedMesh
from evomesh.distributed.lineage import DistributedLineage
from evomesh.evolution import (
    DRFC_DEFAULTS,
    FRFC_DEFAULTS,
    DrfcOptions,
    FrfcOptions,
    QualityWarning,
    RadiusRule,
    SampleMode,
    delaunay_refine,
    evolve,
)
from evomesh.geometry import Arc, BoundaryGeometry, Circle, SignedDistance
from evomesh.interface import INTERFACE_TAG, LevelSet
from evomesh.mesh import Lineage, Mesh, PointKind
from evomesh.mesh_quality import Quality, quality
from evomesh.packing import lexical_first_mis
from evomesh.spacing_function import SpacingFunction, nn_spacing, spacing
from evomesh.tet_evolution import TetOptions
from evomesh.tet_mesh import TetLineage, TetMesh, TetPointKind, box_mesh, unit_cube_mesh
from evomesh.tet_polyhedra import convex_polyhedron_mesh, octahedron_mesh, tilted_box_mesh

__all__ = [
    "Mesh",
    "DistributedMesh",
    "DistributedLineage",
    "PointKind",
    "BoundaryGeometry",
    "Circle",
    "Arc",
    "SignedDistance",
    "LevelSet",
    "INTERFACE_TAG",
    "Lineage",
    "QualityWarning",
    "default_thread_count",
    "evolve",
    "delaunay_refine",
    "FRFC_DEFAULTS",
    "DRFC_DEFAULTS",
    "FrfcOptions",
    "DrfcOptions",
    "SampleMode",
    "RadiusRule",
    "nn_spacing",
    "spacing",
    "SpacingFunction",
    "lexical_first_mis",
    "quality",
    "Quality",
    "TetMesh",
    "TetPointKind",
    "TetLineage",
    "TetOptions",
    "unit_cube_mesh",
    "box_mesh",
    "convex_polyhedron_mesh",
    "tilted_box_mesh",
    "octahedron_mesh",
]

__version__ = "0.1.0"

from evomesh._core import default_thread_count  # noqa: E402
from evomesh.distributed import transfer as distributed_transfer  # noqa: E402,F401 (registers transfer on DistributedMesh with field_transfer)

# Moving-front workflow.
from evomesh.experiments.growing_circle import growing_circle  # noqa: E402
from evomesh.field_transfer import (  # noqa: E402
    DomainChange,
    RegionExchange,
    domain_change,
    region_exchange,
    transfer,
    transfer_cells,
)
from evomesh.fronts import CircleFront, Front, LevelSetFront, PointFront, SpacingLaw  # noqa: E402
from evomesh.meshgen import unit_square_mesh  # noqa: E402
from evomesh.statistics import step_statistics  # noqa: E402
from evomesh.time_loop import Driver, Run, Step, run  # noqa: E402

__all__ += [
    "Front",
    "CircleFront",
    "PointFront",
    "LevelSetFront",
    "SpacingLaw",
    "transfer",
    "transfer_cells",
    "domain_change",
    "DomainChange",
    "region_exchange",
    "RegionExchange",
    "run",
    "Run",
    "Step",
    "Driver",
    "step_statistics",
    "growing_circle",
    "unit_square_mesh",
]
