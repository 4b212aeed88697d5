"""Reporting of run statistics: the text table (optionally beside the paper's
Table 1) and the CSV file."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any, Mapping, Sequence

from evomesh.statistics import STATISTICS_COLUMNS

__all__ = ["PAPER_TABLE1", "format_table", "write_csv"]

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


def write_csv(rows: Sequence[Mapping[str, Any]], path: str | Path) -> Path:
    """Write statistics rows as CSV (header :data:`STATISTICS_COLUMNS`)."""
    path = Path(path)
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(STATISTICS_COLUMNS)
        for row in rows:
            writer.writerow([_csv_value(c, row[c]) for c in STATISTICS_COLUMNS])
    return path


def _csv_value(name: str, value: Any) -> str:
    if name in ("iteration", "points", "original_points", "triangles"):
        return str(int(value))
    return repr(float(value))
