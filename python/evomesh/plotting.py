"""Figures in the style of the paper's Figure 4: spacing spheres, packing, mesh."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from evomesh.fronts import Front, LevelSetFront
from evomesh.mesh import Mesh
from evomesh.spacing_function import _require_mesh, as_delta, spacing

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure, SubFigure

__all__ = ["plot_step", "plot_mesh", "draw_front", "plot_tet_slice", "tet_slice"]

_FRONT_STYLE: dict[str, Any] = {"color": "crimson", "linewidth": 1.4, "linestyle": "--", "zorder": 5}
_KEPT_COLOR = "0.55"
_NEW_COLOR = "darkorange"


#: Above this many triangles a panel shows fields (delta, share of new points,
#: spacing) with colour bars instead of single elements, which would blur into a
#: grey texture and make multi-megabyte PNGs.
DENSE_TRIANGLES = 20000


def _figure(panels: int, size: float = 5.0) -> tuple[Figure, np.ndarray]:
    # Figure without pyplot: no global state, works with any backend (Agg here).
    from matplotlib.figure import Figure

    fig = Figure(figsize=(size * panels, size + 0.6), layout="constrained")
    axes = fig.subplots(1, panels, sharex=True, sharey=True, squeeze=False)[0]
    return fig, axes


def _frame(ax: Axes, mesh: Mesh) -> None:
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    pad = 0.02 * float((hi - lo).max())
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def _circles(ax: Axes, centers: np.ndarray, radii: np.ndarray, **style: Any) -> None:
    from matplotlib.collections import EllipseCollection

    diameters = 2.0 * radii
    ax.add_collection(
        EllipseCollection(
            diameters,
            diameters,
            np.zeros(len(radii)),
            units="xy",
            offsets=centers,
            offset_transform=ax.transData,
            **style,
        )
    )


def draw_front(ax: Axes, front: Front | None, t: float | None = None, mesh: Mesh | None = None) -> None:
    """Draw a front on a matplotlib axes: its polylines, or the zero contour of a
    level set (sampled on a 256 x 256 grid over the mesh's bounding box)."""
    if front is None:
        return
    if isinstance(front, LevelSetFront):
        if mesh is None:
            return
        lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
        x, y = np.meshgrid(np.linspace(lo[0], hi[0], 256), np.linspace(lo[1], hi[1], 256))
        phi = front.value(np.c_[x.ravel(), y.ravel()], t).reshape(x.shape)
        if phi.min() < 0 < phi.max():
            ax.contour(x, y, phi, levels=[0.0], colors=_FRONT_STYLE["color"], linewidths=_FRONT_STYLE["linewidth"],
                       linestyles=_FRONT_STYLE["linestyle"], zorder=5)
        return
    for line in front.polylines(t):
        ax.plot(line[:, 0], line[:, 1], **_FRONT_STYLE)


def plot_step(
    old: Mesh,
    new: Mesh,
    delta: ArrayLike,
    *,
    front: Front | None = None,
    t: float | None = None,
    packing_scale: float = 1.0,
    title: str | None = None,
    size: float = 5.0,
) -> Figure:
    """One step in three panels, like a row of the paper's Figure 4.

    1. The new spacing function as spheres: at every old point p a circle of
       diameter f(p), f = :func:`evomesh.spacing` (old, delta), coloured by
       delta (blue: refine, red: coarsen).
    2. The selected packing: circles of radius ``packing_scale`` f(x) / 2 at
       the new points (grey: kept from the old mesh, orange: new points).
    3. The new mesh.

    Parameters
    ----------
    old, new : Mesh
    delta : array_like, shape (old.n_points,)
    front : Front, optional
        Drawn on every panel at time t.
    packing_scale : float
        Radius scale of the packing spheres (evolve's ``radius_scale``).
    title : str, optional
    size : float
        Panel size in inches.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.colors import LogNorm

    _require_mesh(old)
    _require_mesh(new)
    d = as_delta(old, delta)
    fig, (a1, a2, a3) = _figure(3, size)
    for ax in (a1, a2, a3):
        _frame(ax, new)
    lo, hi = min(d.min(), 1 / d.max(), 0.5), max(d.max(), 1 / d.min(), 2.0)
    norm = LogNorm(vmin=lo, vmax=hi)  # symmetric around delta = 1
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable

    kept = new.origin >= 0
    fig.colorbar(ScalarMappable(norm=norm, cmap="coolwarm"), ax=a1, shrink=0.8, label="delta (<1 refine, >1 coarsen)")
    from evomesh.mesh_quality import quality

    q = quality(new)
    if max(old.n_triangles, new.n_triangles) > DENSE_TRIANGLES:
        # Too many elements to see one by one: fields, rasterised, with colour bars.
        a1.tripcolor(old.points[:, 0], old.points[:, 1], old.triangles, d, shading="gouraud", cmap="coolwarm",
                     norm=norm, rasterized=True)
        a1.set_title(f"delta at {old.n_points} old points", fontsize=10)
        share_new = (~kept)[new.triangles].mean(axis=1)
        shown = a2.tripcolor(new.points[:, 0], new.points[:, 1], new.triangles, facecolors=share_new, cmap="Oranges",
                             vmin=0, vmax=1, rasterized=True)
        fig.colorbar(shown, ax=a2, shrink=0.8, label="share of new vertices")
        a2.set_title(f"{int(kept.sum())} kept, {int((~kept).sum())} new points", fontsize=10)
        spacing_new = new.nn_spacing
        shown = a3.tripcolor(new.points[:, 0], new.points[:, 1], new.triangles, spacing_new, shading="gouraud",
                             cmap="viridis", norm=LogNorm(vmin=spacing_new.min(), vmax=spacing_new.max()),
                             rasterized=True)
        fig.colorbar(shown, ax=a3, shrink=0.8, label="spacing nn")
    else:
        f = spacing(old, d)
        f_old, f_new = f(old.points), f(new.points)
        colors = colormaps["coolwarm"](norm(d))
        colors[:, 3] = 0.35
        _circles(a1, old.points, 0.5 * f_old, facecolors=colors, edgecolors="0.25", linewidths=0.3)
        a1.set_title(f"spacing spheres: {old.n_points} old points\n(blue: refine, red: coarsen)", fontsize=10)
        face = np.where(kept[:, None], np.array([0.55, 0.55, 0.55, 0.45]), np.array([1.0, 0.55, 0.0, 0.6]))
        _circles(a2, new.points, 0.5 * packing_scale * f_new, facecolors=face, edgecolors="0.2", linewidths=0.3)
        a2.set_title(f"selected packing: {int(kept.sum())} kept (grey), {int((~kept).sum())} new (orange)",
                     fontsize=10)
        a3.triplot(new.points[:, 0], new.points[:, 1], new.triangles, color="0.15", linewidth=0.35)
        a3.plot(new.points[~kept, 0], new.points[~kept, 1], ".", color=_NEW_COLOR, markersize=2.0)
    a3.set_title(
        f"mesh: {new.n_points} points, {new.n_triangles} triangles\nmin angle {q.min_angle:.2f} deg", fontsize=10
    )
    for ax in (a1, a2, a3):
        draw_front(ax, front, t, new)
    if title:
        fig.suptitle(title, fontsize=12)
    return fig


def plot_mesh(
    mesh: Mesh, *, front: Front | None = None, t: float | None = None, ax: Axes | None = None, title: str | None = None
) -> Figure | SubFigure:
    """The mesh (and a front); returns the Figure (new unless ``ax`` is given)."""
    _require_mesh(mesh)
    fig: Figure | SubFigure
    if ax is None:
        fig, (ax,) = _figure(1)
    else:
        fig = ax.figure
    _frame(ax, mesh)
    if mesh.n_triangles > DENSE_TRIANGLES:
        spacing_nn = mesh.nn_spacing
        from matplotlib.colors import LogNorm
        from matplotlib.tri import Triangulation

        shown = ax.tripcolor(Triangulation(mesh.points[:, 0], mesh.points[:, 1], mesh.triangles), spacing_nn,
                             shading="gouraud", cmap="viridis",
                             norm=LogNorm(vmin=float(spacing_nn.min()), vmax=float(spacing_nn.max())))
        shown.set_rasterized(True)
        fig.colorbar(shown, ax=ax, shrink=0.8, label="spacing nn")
    else:
        ax.triplot(mesh.points[:, 0], mesh.points[:, 1], mesh.triangles, color="0.15", linewidth=0.35)
    draw_front(ax, front, t, mesh)
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def save(fig: Figure, path: str | Path, dpi: int = 110) -> Path:
    """Save a figure (PNG by suffix) and release it."""
    path = Path(path)
    fig.savefig(path, dpi=dpi)
    fig.clear()
    return path


# The six edges of a tetrahedron, as vertex pairs.
_TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])


def tet_slice(points: np.ndarray, tetrahedra: np.ndarray, axis: int, value: float) -> tuple[np.ndarray, np.ndarray]:
    """The cut of each tetrahedron by the plane x[axis] = value: polygons of 3
    or 4 corners in the other two coordinates (rows padded with NaN to 4,
    counter-clockwise about their centre), shape (k, 4, 2), and the index of
    the tetrahedron of each."""
    p = np.asarray(points, dtype=np.float64)[np.asarray(tetrahedra)]
    side = p[:, :, axis] - value
    # Half-open (a point on the plane counts as below): every point of the
    # plane inside the mesh is in exactly one polygon, also where faces lie on it.
    cut = (side.min(axis=1) <= 0) & (side.max(axis=1) > 0)
    p, side = p[cut], side[cut]
    others = [a for a in range(3) if a != axis]
    a, b = _TET_EDGES[:, 0], _TET_EDGES[:, 1]
    sa, sb = side[:, a], side[:, b]
    crossing = (sa <= 0) != (sb <= 0)  # exactly one end below the plane
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(crossing, sa / (sa - sb), np.nan)
    corners = p[:, a][:, :, others] + t[:, :, None] * (p[:, b][:, :, others] - p[:, a][:, :, others])
    centre = np.nanmean(corners, axis=1)
    angle = np.arctan2(corners[:, :, 1] - centre[:, None, 1], corners[:, :, 0] - centre[:, None, 0])
    order = np.argsort(np.where(crossing, angle, np.inf), axis=1)[:, :4]
    polygons = np.take_along_axis(corners, order[:, :, None], axis=1)
    return polygons, np.flatnonzero(cut)


def plot_tet_slice(mesh: Any, *, axis: int = 2, value: float = 0.5, sphere: tuple[Any, float] | None = None,
                   ax: Axes | None = None, title: str | None = None) -> Figure | SubFigure:
    """A slice of a :class:`evomesh.TetMesh`: its tetrahedra cut by the plane
    x[axis] = value, drawn as polygons (those with a new point in orange), and
    the circle of a sphere (centre, radius) on that plane; returns the Figure."""
    from matplotlib.collections import PolyCollection

    fig: Figure | SubFigure
    if ax is None:
        fig, (ax,) = _figure(1)
    else:
        fig = ax.figure
    polygons, tets = tet_slice(mesh.points, mesh.tetrahedra, axis, value)
    new = (mesh.origin[mesh.tetrahedra[tets]] < 0).any(axis=1)
    shapes = [poly[~np.isnan(poly[:, 0])] for poly in polygons]
    faces = np.where(new[:, None], np.array([1.0, 0.85, 0.7, 1.0]), np.array([0.93, 0.93, 0.93, 1.0]))
    ax.add_collection(PolyCollection(shapes, facecolors=faces, edgecolors="0.2", linewidths=0.3))
    others = [a for a in range(3) if a != axis]
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    ax.set_xlim(lo[others[0]], hi[others[0]])
    ax.set_ylim(lo[others[1]], hi[others[1]])
    ax.set_aspect("equal")
    names = "xyz"
    ax.set_xlabel(names[others[0]])
    ax.set_ylabel(names[others[1]])
    if sphere is not None:
        centre, radius = np.asarray(sphere[0], dtype=np.float64), float(sphere[1])
        gap = radius**2 - (value - centre[axis]) ** 2
        if gap > 0:
            _circles(ax, centre[others][None], np.array([np.sqrt(gap)]), facecolors="none",
                     edgecolors=_FRONT_STYLE["color"], linewidths=_FRONT_STYLE["linewidth"], linestyles="--", zorder=5)
    if title:
        ax.set_title(title, fontsize=10)
    return fig
