"""Compatibility module: the moving-front driver, split by job.

Kept so that existing code doing ``from evomesh.driver import ...`` keeps
working. The names live in

* :mod:`evomesh.time_loop` -- :class:`Driver`, :class:`Step`, :class:`Run`, :func:`run`, :func:`front_at`;
* :mod:`evomesh.statistics` -- :func:`step_statistics`, :func:`nn_at`, :data:`STATISTICS_COLUMNS`;
* :mod:`evomesh.reporting` -- :func:`format_table`, :func:`write_csv`, :data:`PAPER_TABLE1`;
* :mod:`evomesh.experiments.growing_circle` -- :func:`growing_circle`, :data:`GROWING_CIRCLE_DEFAULTS`.

Nothing inside evomesh imports this module; new code should import from the
modules above.
"""

from __future__ import annotations

from evomesh.experiments.growing_circle import GROWING_CIRCLE_DEFAULTS, growing_circle
from evomesh.reporting import PAPER_TABLE1, format_table
from evomesh.statistics import STATISTICS_COLUMNS, nn_at, step_statistics
from evomesh.time_loop import Driver, Run, Step, front_at, run

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
    "format_table",
    "front_at",
]
