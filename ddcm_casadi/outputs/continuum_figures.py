"""Figures of continuum results, and :func:`fit_rate` for the slopes of convergence plots.

- :func:`figure_pressure_profile`: contact pressure along the contact surface, several runs and
  optionally the Hertz solution;
- :func:`figure_deformed_body`: the deformed body coloured by a stress-like quantity (2-D or 3-D),
  with its rigid obstacles;
- :func:`figure_convergence`: log-log error series against mesh (or data) size.

Save them with :func:`ddcm_casadi.outputs.plots.save_figure`. Every input is checked before
anything is drawn (:mod:`ddcm_casadi.outputs.array_checks`); matplotlib is imported only by the
functions that draw. Re-exported by :mod:`ddcm_casadi.outputs.continuum`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ddcm_casadi.errors import InputError
from ddcm_casadi.outputs.array_checks import as_float, connectivity, coordinates

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def _profile(what: str, d: Any, keys: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(d, Mapping) or any(k not in d for k in keys):
        raise InputError(f"{what} must be a dict with keys {list(keys)}")
    x, p = as_float(f"{what} x", d["x"]), as_float(f"{what} pressure", d["pressure"])
    if x.ndim != 1 or x.shape != p.shape:
        raise InputError(f"{what} x and pressure must be 1-D of equal length, got {x.shape} and {p.shape}")
    order = np.argsort(x, kind="stable")
    return x[order], p[order]


def _mm_label(label: str) -> str:
    """The axis is drawn in mm: show a trailing metre unit as millimetres."""
    for m, mm in (("(m)", "(mm)"), ("[m]", "[mm]")):
        if label.endswith(m):
            return label[: -len(m)] + mm
    return label


def figure_pressure_profile(runs: Sequence[Mapping[str, Any]], *,
                            hertz: Mapping[str, Any] | None = None, xlabel: str = "x (m)",
                            ylabel: str = "contact pressure (MPa)", title: str = "") -> Figure:
    """Contact pressure along the contact surface, several runs and optionally the Hertz solution.

    Parameters
    ----------
    runs : list of dict
        ``{"label": str, "x": (nc,) m, "pressure": (nc,) Pa, "converged": bool,
        "style": dict (optional, matplotlib keyword arguments, e.g. ``{"marker": "o", "ls": ""}``
        for data-driven runs)}``. Drawn as lines by default, sorted by x. A run that did not
        converge is still drawn, circled in red, and labelled "... (NOT CONVERGED)" in red.
    hertz : dict, optional
        ``{"x": array, "pressure": array, "label": str}``: a dashed black line.
    xlabel : str
        Label of the coordinate; the axis is in mm, so a trailing "(m)" is shown as "(mm)".
    ylabel : str
        Label of the pressure axis (in MPa), e.g. which pressure at finite strain (nominal or true).
    title : str
        Axes title.

    Returns
    -------
    Figure
        Pressure in MPa against x in mm.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.6), constrained_layout=True)
    ax = fig.add_subplot()
    if hertz is not None:
        x, p = _profile("hertz", hertz, ("x", "pressure"))
        ax.plot(x * 1e3, p * 1e-6, "k--", lw=1.0, label=str(hertz.get("label", "Hertz")), zorder=1)
    failed = []
    for i, run in enumerate(runs):
        x, p = _profile(f"runs[{i}]", run, ("label", "x", "pressure", "converged"))
        style = {"lw": 1.4} | dict(run.get("style") or {})
        label = str(run["label"])
        if not run["converged"]:
            label += " (NOT CONVERGED)"
            failed.append(label)
        ax.plot(x * 1e3, p * 1e-6, label=label, zorder=2, **style)
        if not run["converged"]:
            ax.plot(x * 1e3, p * 1e-6, "o", ms=9, mfc="none", mec="red", mew=1.5, zorder=3)
    ax.set_xlabel(_mm_label(xlabel))
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if ax.get_legend_handles_labels()[1]:
        for text in ax.legend(fontsize=8).get_texts():
            if text.get_text() in failed:
                text.set_color("red")
    return fig


def _nice_scale(x: float) -> float:
    """``x`` rounded down to two significant digits (the largest displacement stays <= 5 %)."""
    p = 10.0 ** (np.floor(np.log10(x)) - 1)
    return float(np.floor(x / p * (1 + 1e-12)) * p)


def _boundary_edges(tri: np.ndarray) -> np.ndarray:
    """Edges that belong to one triangle only: the outline of a 2-D mesh."""
    edges = np.sort(tri[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    return unique[count == 1]


def _draw_obstacles(ax, obstacles: Sequence[Mapping[str, Any]], lo: np.ndarray,
                    hi: np.ndarray) -> None:
    from matplotlib.patches import Circle, Polygon

    for i, ob in enumerate(obstacles):
        kind = ob.get("kind") if isinstance(ob, Mapping) else None
        if kind == "circle":
            c, r = as_float(f"obstacles[{i}] center", ob.get("center")), ob.get("radius")
            if c.shape != (2,) or not isinstance(r, (int, float)) or not r > 0:
                raise InputError(f"obstacles[{i}] circle needs center (x, y) and radius > 0")
            ax.add_patch(Circle(tuple(c), float(r), facecolor="0.85", edgecolor="0.2", lw=1.0,
                                zorder=0))
        elif kind == "plane":
            p, n = (as_float(f"obstacles[{i}] {k}", ob.get(k)) for k in ("point", "normal"))
            if p.shape != (2,) or n.shape != (2,) or not np.linalg.norm(n) > 0:
                raise InputError(f"obstacles[{i}] plane needs point (x, y) and a non-zero normal")
            t = np.array([-n[1], n[0]]) / np.linalg.norm(n)
            # long enough to cross the whole view from wherever the point lies
            half = 2.0 * (np.linalg.norm(hi - lo) + np.linalg.norm(p - (lo + hi) / 2))
            ax.plot(*np.array([p - half * t, p + half * t]).T, color="0.2", lw=1.5, zorder=0)
        elif kind == "outline":
            pts = as_float(f"obstacles[{i}] points", ob.get("points"))
            if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 3:
                raise InputError(f"obstacles[{i}] outline needs at least 3 points (x, y)")
            ax.add_patch(Polygon(pts, closed=True, facecolor="0.85", edgecolor="0.2", lw=1.0, zorder=0))
        else:
            raise InputError(f"obstacles[{i}] must be a dict with kind 'circle', 'plane' or 'outline'")


@dataclass
class _Body:
    """The checked inputs of :func:`figure_deformed_body`, with the deformed nodes."""

    x: np.ndarray  # reference nodes (nn, d)
    y: np.ndarray  # magnified deformed nodes (nn, d)
    tri: np.ndarray  # triangles (ne, 3)
    values: np.ndarray  # MPa, per triangle or per node
    per_cell: bool  # values per triangle
    scale: float  # displacement magnification
    dots: np.ndarray | None  # contact points to draw (nc, d)


def _body(points: Any, cells: Any, displacement: Any, values: Any, scale: float | None,
          contact_points: Any) -> _Body:
    """Check the inputs of :func:`figure_deformed_body` and place the deformed body (nothing drawn)."""
    x = coordinates("points", points)
    n_nodes, dim = x.shape
    tri = connectivity("cells", cells, 3, n_nodes)
    u = as_float("displacement", displacement)
    if u.shape != x.shape or not np.all(np.isfinite(u)):
        raise InputError(f"displacement must be finite with shape {x.shape}, got {u.shape}")
    v = as_float("values", values) * 1e-6  # Pa -> MPa
    if v.ndim != 1 or len(v) not in (len(tri), n_nodes):
        raise InputError(f"values must have shape ({len(tri)},) per triangle or ({n_nodes},) "
                         f"per node, got {v.shape}")
    size = float(np.max(np.ptp(x, axis=0)))
    umax = float(np.max(np.linalg.norm(u, axis=1)))
    if scale is None:
        scale = _nice_scale(0.05 * size / umax) if umax > 0 and size > 0 else 1.0
    elif not (isinstance(scale, (int, float)) and np.isfinite(scale) and scale >= 0):
        raise InputError(f"scale must be a finite number >= 0, got {scale!r}")
    y = x + scale * u

    dots = None
    if contact_points is not None:
        c = np.asarray(contact_points)
        if c.size == 0:
            dots = np.empty((0, dim))
        elif c.ndim == 1 and c.dtype.kind in "iu":
            dots = y[connectivity("contact_points", c[:, None], 1, n_nodes)[:, 0]]
        else:
            dots = coordinates("contact_points", c, (dim,))
    return _Body(x=x, y=y, tri=tri, values=v, per_cell=len(v) == len(tri), scale=scale, dots=dots)


def _draw_body_2d(fig: Figure, b: _Body, obstacles: Sequence[Mapping[str, Any]]) -> tuple[Any, Any]:
    """The 2-D body: ``tripcolor`` of the deformed mesh, the undeformed outline, the obstacles
    clipped to the body's view. Returns the axes and the colour scale."""
    from matplotlib.collections import LineCollection
    from matplotlib.tri import Triangulation

    x, y, tri, v = b.x, b.y, b.tri, b.values
    ax = fig.add_subplot()
    mesh = Triangulation(y[:, 0], y[:, 1], tri)
    mappable = (ax.tripcolor(mesh, facecolors=v, cmap="viridis") if b.per_cell
                else ax.tripcolor(mesh, v, shading="gouraud", cmap="viridis"))
    outline = x[_boundary_edges(tri)]
    ax.add_collection(LineCollection(outline, colors="0.4", linewidths=0.8, zorder=3))
    # The view is the body's (reference and deformed); obstacles are clipped to it.
    lo, hi = np.minimum(x.min(0), y.min(0)), np.maximum(x.max(0), y.max(0))
    margin = 0.1 * max(float(np.max(hi - lo)), 1e-300)
    _draw_obstacles(ax, obstacles, lo, hi)
    ax.set_xlim(lo[0] - margin, hi[0] + margin)
    ax.set_ylim(lo[1] - margin, hi[1] + margin)
    ax.set_aspect("equal")
    if b.dots is not None:
        ax.plot(b.dots[:, 0], b.dots[:, 1], "o", color="red", ms=3, zorder=4)
    return ax, mappable


def _draw_body_3d(fig: Figure, b: _Body) -> tuple[Any, Any]:
    """The 3-D body: its deformed surface triangles, equal aspect. Returns the axes and the colour scale."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    y, tri, v = b.y, b.tri, b.values
    ax = fig.add_subplot(projection="3d")
    face = v if b.per_cell else v[tri].mean(axis=1)
    mappable = ScalarMappable(Normalize(face.min(), face.max()), cmap="viridis")
    ax.add_collection3d(Poly3DCollection(y[tri], facecolors=mappable.to_rgba(face),
                                         edgecolors="0.2", linewidths=0.3))
    # Equal aspect: a cube around the deformed body.
    centre, half = (y.min(0) + y.max(0)) / 2, max(float(np.max(np.ptp(y, axis=0))), 1e-300) / 2
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))
    if b.dots is not None:
        ax.scatter(*b.dots.T, color="red", s=6, depthshade=False)
    return ax, mappable


def figure_deformed_body(points: Any, cells: Any, *, displacement: Any, values: Any,
                         value_label: str, scale: float | None = None,
                         contact_points: Any = None,
                         obstacles: Sequence[Mapping[str, Any]] | None = None,
                         title: str = "") -> Figure:
    """The deformed body coloured by a stress-like quantity.

    Parameters
    ----------
    points : array_like, shape (nn, 2) or (nn, 3)
        Reference node coordinates.
    cells : array_like of int, shape (ne, 3)
        2-D: the triangles (corner nodes); 3-D: the boundary triangles of the body's surface.
    displacement : array_like, shape (nn, d)
        Node displacements.
    values : array_like, shape (ne,) or (nn,)
        Per triangle or per node (per triangle if ne == nn), in Pa, e.g. von Mises stress;
        shown in MPa. In 3-D node values are averaged over each surface triangle.
    value_label : str
        Colour bar label (" (MPa)" is appended).
    scale : float, optional
        Displacement magnification. Default: the largest displacement is 5 % of the body's size
        (rounded down to two digits). Given in the title either way.
    contact_points : array_like, optional
        Active contact nodes, drawn as small red dots: either node indices (int, shape (nc,)),
        drawn on the magnified deformed mesh, or coordinates (nc, d) drawn as given (already
        deformed; they match the drawn mesh only if ``scale`` is 1).
    obstacles : list of dict, optional
        2-D rigid obstacles, drawn at their true position (not magnified) and clipped to the
        body's view: ``{"kind": "circle", "center": (x, y), "radius": r}``,
        ``{"kind": "plane", "point": (x, y), "normal": (nx, ny)}`` or
        ``{"kind": "outline", "points": [(x, y), ...]}`` (a closed polygon). Ignored in 3-D.
    title : str
        Title; " (displacements x <scale>)" is added.

    Returns
    -------
    Figure
        2-D: ``tripcolor`` of the deformed mesh with the undeformed outline in thin grey;
        3-D: the deformed surface triangles, equal aspect.
    """
    from matplotlib.figure import Figure

    b = _body(points, cells, displacement, values, scale, contact_points)
    fig = Figure(figsize=(7.0, 5.2), constrained_layout=True)
    if b.x.shape[1] == 2:
        ax, mappable = _draw_body_2d(fig, b, obstacles or [])
    else:
        ax, mappable = _draw_body_3d(fig, b)
    fig.colorbar(mappable, ax=ax, label=f"{value_label} (MPa)", shrink=0.8)
    note = f"displacements x {b.scale:g}"
    # on the figure, not the axes: a long title would run into the colour bar
    fig.suptitle(f"{title}\n({note})" if title else note, fontsize="medium")
    return fig


def figure_convergence(h: Any, errors: Sequence[Any], *, labels: Sequence[str],
                       rates: Mapping[str, float] | None = None, xlabel: str = "h (m)",
                       ylabel: str = "relative error", title: str = "") -> Figure:
    """Log-log plot of error series against mesh size (or data size).

    Parameters
    ----------
    h : array_like
        Abscissae: one 1-D array shared by all series, or one array per series.
    errors : list of array_like
        The error series. Non-positive values cannot be shown on log axes and are left out.
    labels : list of str
        One legend label per series.
    rates : dict, optional
        label -> fitted slope (e.g. from :func:`fit_rate`), shown in the legend.
    xlabel, ylabel, title : str
        Axis labels and title.

    Returns
    -------
    Figure
    """
    from matplotlib.figure import Figure

    series = [as_float(f"errors[{i}]", e) for i, e in enumerate(errors)]
    labels = [str(s) for s in labels]
    if len(labels) != len(series):
        raise InputError(f"labels has {len(labels)} entries for {len(series)} error series")
    rates = dict(rates or {})
    unknown = set(rates) - set(labels)
    if unknown:
        raise InputError(f"rates has labels not in labels: {sorted(unknown)}")
    try:
        grid = np.asarray(h, dtype=float)
    except (TypeError, ValueError):  # ragged: one array per series
        grid = None
    if grid is not None and grid.ndim == 1:
        hs = [grid] * len(series)
    elif grid is not None and grid.ndim != 2:
        raise InputError(f"h must be a 1-D array or one array per series, got shape {grid.shape}")
    else:
        hs = [as_float(f"h[{i}]", a) for i, a in enumerate(h)]
    if len(hs) != len(series):
        raise InputError(f"h has {len(hs)} arrays for {len(series)} error series")

    fig = Figure(figsize=(6.4, 4.6), constrained_layout=True)
    ax = fig.add_subplot()
    for i, (x, e, label) in enumerate(zip(hs, series, labels)):
        if x.ndim != 1 or x.shape != e.shape:
            raise InputError(f"errors[{i}] has shape {e.shape}, h has {x.shape}")
        ok = (x > 0) & (e > 0)
        if label in rates:
            label = f"{label} (rate {rates[label]:.2f})"
        ax.loglog(x[ok], e[ok], "o-", ms=5, label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    if series:
        ax.legend(fontsize=8)
    return fig


def fit_rate(x: Any, y: Any) -> float:
    """Least-squares slope of ``log y`` against ``log x`` (the convergence rate).

    Points where x or y is not positive (or not finite) are ignored.

    Raises
    ------
    InputError
        If x and y differ in shape or fewer than 2 usable points with distinct x remain.
    """
    x, y = as_float("x", x), as_float("y", y)
    if x.ndim != 1 or x.shape != y.shape:
        raise InputError(f"x and y must be 1-D of equal length, got {x.shape} and {y.shape}")
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    lx, ly = np.log(x[ok]), np.log(y[ok])
    dx = lx - lx.mean() if lx.size else lx
    if lx.size < 2 or not np.any(dx):
        raise InputError(f"fit_rate needs >= 2 points with distinct x > 0 and y > 0, got {lx.size}")
    return float(dx @ (ly - ly.mean()) / (dx @ dx))
