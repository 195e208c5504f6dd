"""Figures of a comparison: the drawing code of bars and trusses, and the contact history of any model.

Which figures suit a model, the model kind says as data
(:meth:`~ddcm_casadi.models.base.ContactModel.figures`); the drawings here are registered under the names
those refer to (:mod:`ddcm_casadi.outputs.drawings`: ``tip_displacement``, ``contact_pressure``,
``structure``, ``contact_history``), and :func:`ddcm_casadi.outputs.save.save_figures` draws them.
Matplotlib is imported only by the functions that draw.

- The paper's Fig. 2 (one-element bar): tip displacement and contact pressure vs obstacle.
- Any truss (:class:`~ddcm_casadi.models.truss.TrussModel`, 1-D, 2-D or 3-D): the deformed structure
  coloured by member force with its obstacles and contact forces (:func:`figure_structure`), and
  the contact forces along the load path (:func:`figure_contact_history`, any model).

Classical results are lines, DDCM results markers, the closed form a dashed black line; a step that
did not converge is circled in red and named in the legend, never drawn as if it were fine, a
DDCM step that stopped at a local (not the global) minimum is framed by a grey diamond, and a DDCM
step with states beyond the material data (:mod:`ddcm_casadi.data.extrapolation`) by a violet hexagon.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ddcm_casadi.outputs.drawings import register_drawing
from ddcm_casadi.io import write_bytes_atomic

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ddcm_casadi.drivers.harness import Comparison

_MARKERS = {"penalty": "s", "augmented_lagrangian": "^", "fischer_burmeister": "o", "mpcc": "x"}
_STYLES = {"penalty": "-", "augmented_lagrangian": "--", "fischer_burmeister": "-.", "mpcc": ":"}
#: The frame of a DDCM step with states beyond the data, and its legend entry.
_BEYOND = dict(ls="none", marker="h", ms=16, mfc="none", mec="darkviolet", mew=1.5, zorder=4)
_BEYOND_LABEL = "DATA RANGE EXCEEDED"


def _beyond(r) -> np.ndarray:
    """Which steps of a run have states beyond the data (all false for classical runs)."""
    return np.array([st.extrapolated > 0 for st in r.steps], dtype=bool)


#: Fig. 2's margins (figure fractions): where constrained layout put its axes on the paper's
#: figures, fixed. Constrained layout measures every text of the figure in extra passes before
#: drawing it (0.05 s a figure, measured on the paper's first run) to find the same place.
_FIG2_MARGINS = dict(left=0.10, bottom=0.103, right=0.9935, top=0.945)
#: Width of one character of a y tick label (fraction of Fig. 2's width; 10 pt DejaVu Sans digits
#: are 6.4 pt wide, the figure 6.4 in): labels longer than Fig. 2's four characters widen the margin.
_FIG2_CHAR = 6.4 / 72 / 6.4


def _fig2_layout(fig: Figure, ax) -> None:
    """Place Fig. 2's axes at :data:`_FIG2_MARGINS`, the left margin widened for long y tick labels."""
    lo, hi = sorted(ax.get_ylim())
    ticks = [t for t in ax.get_yticks() if lo <= t <= hi]  # the locator also returns ticks out of view
    labels = ax.yaxis.get_major_formatter().format_ticks(ticks)
    extra = max((len(t) for t in labels), default=0) - 4
    fig.subplots_adjust(**{**_FIG2_MARGINS, "left": _FIG2_MARGINS["left"] + _FIG2_CHAR * max(extra, 0)})


def _panel(cmp: Comparison, quantity: str, ylabel: str, scale: float, title: str) -> Figure:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.6))
    ax = fig.add_subplot()
    m = cmp.model
    h = m.load_parameter
    ref = [m.closed_form(k) for k in range(m.n_steps)]
    if ref[0] is not None:
        idx = 0 if quantity == "u" else 1
        ax.plot(h, [r[idx][-1 if quantity == "u" else 0] * scale for r in ref], "k--", lw=1.0,
                label="closed form", zorder=1)
    failed = local = extrapolated = False
    for (variant, name), r in cmp.results.items():
        y = r.array(quantity)
        y = (y[:, -1] if quantity == "u" else y[:, 0]) * scale
        conv = r.array("converged").astype(bool)
        title_f = _title(cmp, name)
        if variant == "classical":
            ax.plot(h, y, _STYLES.get(name, "-"), lw=1.4, label=f"classical, {title_f}", zorder=2)
        else:
            ax.plot(h, y, _MARKERS.get(name, "o"), ms=6, mfc="none", label=f"DDCM, {title_f}", zorder=3)
        if variant == "ddcm":
            loc = np.array([st.global_optimum is False for st in r.steps])
            if loc.any():
                local = True
                ax.plot(h[loc], y[loc], "D", ms=11, mfc="none", mec="0.3", mew=1, zorder=4)
        beyond = _beyond(r)
        if beyond.any():
            extrapolated = True
            ax.plot(h[beyond], y[beyond], **_BEYOND)
        if not conv.all():
            failed = True
            ax.plot(h[~conv], y[~conv], "o", ms=14, mfc="none", mec="red", mew=2, zorder=4)
    if local:
        ax.plot([], [], "D", ms=9, mfc="none", mec="0.3", label="DDCM local minimum (not global)")
    if extrapolated:
        ax.plot([], [], **{**_BEYOND, "ms": 10}, label=_BEYOND_LABEL)
    if failed:
        ax.plot([], [], "o", ms=10, mfc="none", mec="red", mew=2, label="NOT CONVERGED")
    ax.set_xlabel(_param_label(cmp))
    ax.set_ylabel(ylabel)
    # At the top edge, where matplotlib's automatic placement puts it (no ticks or labels on top),
    # without measuring the x axis at every draw to find that out.
    ax.set_title(title, y=1.0)
    ax.invert_xaxis()
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    _fig2_layout(fig, ax)
    return fig


@register_drawing("tip_displacement")
def figure_displacement(cmp: Comparison) -> Figure:
    """Fig. 2a: bar tip displacement against obstacle position."""
    return _panel(cmp, "u", "tip displacement u [mm]", 1e3, "Tip displacement (Fig. 2a)")


@register_drawing("contact_pressure")
def figure_pressure(cmp: Comparison) -> Figure:
    """Fig. 2b: contact pressure against obstacle position."""
    return _panel(cmp, "p", "contact pressure p [GPa]", 1e-9, "Contact pressure (Fig. 2b)")


def save_figure(fig: Figure, path: str | Path, *, dpi: int = 150) -> Path:
    """Save atomically (temporary file, then rename)."""
    path = Path(path)
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lstrip(".") or "png", dpi=dpi)
    return write_bytes_atomic(path, buf.getvalue())




# --------------------------------------------------------------------------- trusses
_MAX_PAIRS_DRAWN = 8  # above this many contact pairs the history shows totals, not every pair
_MAX_FORCE_LABELS = 10


def _title(cmp: Comparison, formulation: str) -> str:
    return next((f.title for f in cmp.formulations if f.name == formulation), formulation)


def _param_label(cmp: Comparison) -> str:
    name = cmp.model.load_parameter_name
    return f"obstacle position {name} [m]" if name == "h" else name


def _nice(x: float) -> float:
    """The largest of 1, 2, 5 x 10^k not above ``x`` (a readable magnification factor)."""
    if not np.isfinite(x) or x <= 0:
        return 1.0
    k = np.floor(np.log10(x))
    m = x / 10 ** k
    return float((5 if m >= 5 else 2 if m >= 2 else 1) * 10 ** k)


def _force_text(force: float) -> str:
    return f"{force / 1e3:.3g} kN"


def _obstacle_groups(model, gap0: np.ndarray, mag: float) -> list[tuple[np.ndarray, float, np.ndarray]]:
    """Rigid planes to draw: ``(normal, level, pair indices)``.

    A plane is drawn at its *magnified* clearance from its nodes (level ``n.X - mag * g0`` along
    ``n``) so that a node in contact touches it in the magnified picture as it does in reality.
    Pairs with the same normal and drawn level share one plane.
    """
    X = model.nodes[model.contact_nodes]
    n = model.contact_normals
    level = np.einsum("ij,ij->i", n, X) - mag * gap0
    tol = 1e-9 * max(float(np.max(np.ptp(model.nodes, axis=0))), 1e-300)
    groups: list[tuple[np.ndarray, float, list[int]]] = []
    for i in range(n.shape[0]):
        for normal, lev, members in groups:
            if np.allclose(normal, n[i]) and abs(lev - level[i]) <= tol:
                members.append(i)
                break
        else:
            groups.append((n[i], float(level[i]), [i]))
    return [(nrm, lev, np.asarray(idx)) for nrm, lev, idx in groups]


@register_drawing("structure")
def figure_structure(cmp: Comparison, variant: str, formulation: str, step: int = -1, *,
                     magnification: float | None = None) -> Figure:
    """The deformed truss at one step, coloured by member force, with obstacles and contact forces.

    Parameters
    ----------
    cmp : Comparison
        Results of :func:`~ddcm_casadi.drivers.harness.compare` on a
        :class:`~ddcm_casadi.models.truss.TrussModel` (1-D, 2-D or 3-D).
    variant, formulation : str
        Which run to draw, e.g. ``"ddcm", "fischer_burmeister"``.
    step : int
        Load step (negative counts from the end).
    magnification : float, optional
        Displacement scale factor. Default: a round number that makes the largest displacement
        about 10 % of the structure's size.

    Returns
    -------
    Figure
        Undeformed structure in light grey, deformed structure coloured by member force (red
        tension, blue compression), rigid planes hatched (drawn at their magnified clearance),
        contact forces as arrows along the obstacle normal (length proportional to the force),
        labelled in kN. A step that did not converge says so in red.
    """
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    model = cmp.model
    f = cmp.fields(variant, formulation)
    if "nodal_displacement" not in f or "member_force" not in f:  # fields of the model kind
        raise TypeError("figure_structure needs a truss model (ddcm_casadi.models.truss.TrussModel)")
    k = range(model.n_steps)[step]
    X = model.nodes
    U = f["nodal_displacement"][k]
    N = f["member_force"][k]
    F = f["contact_force"][k]
    converged = bool(f["converged"][k])
    d = model.dimension
    size = float(np.max(np.ptp(X, axis=0)))
    umax = float(np.max(np.abs(U)))
    if magnification is None:
        magnification = _nice(0.1 * size / umax) if umax > 0 else 1.0
    mag = float(magnification)
    Y = X + mag * U
    fixed = ~np.isin(np.arange(X.size), model.free_dofs).reshape(X.shape)
    supported = np.flatnonzero(fixed.any(axis=1))

    # Member forces: one symmetric colour scale so white is zero force.
    nmax = float(np.max(np.abs(N))) or 1.0
    norm = Normalize(-nmax / 1e3, nmax / 1e3)
    cmap = "coolwarm"
    sm = ScalarMappable(norm=norm, cmap=cmap)
    colors = sm.to_rgba(N / 1e3)

    # Contact forces: arrows along +n (the obstacle pushes the node), the largest ~8 % of the size.
    fmax = float(np.max(F)) if F.size else 0.0
    active = model.active_contacts(F / model.contact_area)
    arrow = 0.08 * size / fmax if fmax > 0 else 0.0
    gap0 = model.gap_offsets[k]
    groups = _obstacle_groups(model, gap0, mag) if model.n_contacts else []

    fig = Figure(figsize=(9.0, 5.6) if d == 3 else (9.0, 3.6) if d == 1 else (9.0, 5.2),
                 constrained_layout=True)
    if d == 3:
        ax = fig.add_subplot(projection="3d")
        _draw_3d(ax, X, Y, model.members, colors, groups, model, F, active, arrow, size)
        ax.scatter(*Y[supported].T, marker="^", s=60, color="0.3", depthshade=False, zorder=3)
    elif d == 2:
        ax = fig.add_subplot()
        _draw_2d(ax, X, Y, model.members, colors, groups, model, F, active, arrow, size)
        ax.plot(*Y[supported].T, "^", ms=10, color="0.3", zorder=3, clip_on=False)
    else:
        ax = fig.add_subplot()
        _draw_1d(ax, X, Y, model.members, colors, groups, model, F, active, arrow, size)
        ax.plot(Y[supported, 0], np.zeros(supported.size), ">", ms=12, color="0.3", zorder=3)
    if d == 3:
        fig.colorbar(sm, ax=ax, label="member force [kN] (tension +)", shrink=0.6, pad=0.08)
    else:  # under a wide, flat structure a horizontal bar fits better
        fig.colorbar(sm, ax=ax, label="member force [kN] (tension +)", orientation="horizontal",
                     shrink=0.6, aspect=40)

    value = model.load_parameter[k]
    total = f" total contact force {_force_text(float(np.sum(F)))}," if F.size else ""
    ax.set_title(f"{model.name}: {variant}, {_title(cmp, formulation)}, step {k} "
                 f"({model.load_parameter_name} = {value:.4g})\n"
                 f"{int(np.sum(active))}/{F.size} contacts active,{total} displacements x{mag:g}",
                 fontsize=9)
    beyond = int(cmp[variant, formulation].steps[k].extrapolated)
    flags = (["NOT CONVERGED"] if not converged else []) + ([f"{_BEYOND_LABEL} ({beyond} states)"] if beyond else [])
    if flags:
        fig.suptitle("; ".join(flags), color="red" if not converged else _BEYOND["mec"], fontweight="bold")
    return fig


def _draw_1d(ax, X, Y, members, colors, groups, model, F, active, arrow, size) -> None:
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Rectangle

    x0, x1 = X[:, 0], Y[:, 0]
    z = np.zeros_like(x0)
    ax.add_collection(LineCollection([[(x0[i], 0), (x0[j], 0)] for i, j in members], colors="0.85",
                                     linewidths=9, zorder=1))
    ax.add_collection(LineCollection([[(x1[i], 0), (x1[j], 0)] for i, j in members], colors=colors,
                                     linewidths=4, zorder=2))
    ax.plot(x1, z, "k|", ms=8, zorder=3)
    h = 0.08 * size
    for normal, level, idx in groups:
        # n x = level; the obstacle fills the side n x < level
        xs = level / normal[0]
        depth = -np.sign(normal[0]) * 0.012 * size
        ax.add_patch(Rectangle((min(xs, xs + depth), -h), abs(depth), 2 * h, facecolor="none",
                               edgecolor="0.3", hatch="////", lw=0, zorder=1))
        ax.plot([xs, xs], [-h, h], color="0.15", lw=2.5, zorder=2)
    for i in np.flatnonzero(active):
        node = model.contact_nodes[i]
        n = model.contact_normals[i, 0]
        tip = x1[node]
        length = arrow * F[i]
        y = 0.5 * h  # above the bar, so the arrow is not hidden by it
        ax.annotate("", xy=(tip, y), xytext=(tip - n * length, y),
                    arrowprops=dict(arrowstyle="-|>", color="k", lw=1.5), zorder=4)
        if np.sum(active) <= _MAX_FORCE_LABELS:
            # beside the arrow's tail, away from the obstacle line
            ax.text(tip - n * (length + 0.01 * size), y, _force_text(F[i]), ha="right" if n > 0 else "left",
                    va="center", fontsize=7)
    ax.set_xlim(min(x0.min(), x1.min()) - 0.06 * size, max(x0.max(), x1.max()) + 0.06 * size)
    ax.set_ylim(-2 * h, 2.5 * h)
    ax.set_yticks([])
    ax.set_xlabel("x [m] (displacements magnified)")


def _plane_extent(pts: np.ndarray, t: np.ndarray, size: float) -> tuple[float, float]:
    s = pts @ t
    pad = max(0.04 * size, 0.5 * float(np.ptp(s)) * 0.1)
    return float(s.min() - pad), float(s.max() + pad)


def _draw_2d(ax, X, Y, members, colors, groups, model, F, active, arrow, size) -> None:
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Polygon

    ax.add_collection(LineCollection(X[members], colors="0.8", linewidths=1.0, zorder=1))
    ax.add_collection(LineCollection(Y[members], colors=colors, linewidths=2.2, zorder=2))
    ax.plot(Y[:, 0], Y[:, 1], "o", ms=2.5, color="0.2", zorder=3)
    pts_all = [X, Y]
    for normal, level, idx in groups:
        t = np.array([-normal[1], normal[0]])
        a, b = _plane_extent(Y[model.contact_nodes[idx]], t, size)
        p0, p1 = level * normal + a * t, level * normal + b * t
        depth = 0.025 * size * normal
        ax.add_patch(Polygon([p0, p1, p1 - depth, p0 - depth], closed=True, facecolor="none",
                             edgecolor="0.35", hatch="////", lw=0, zorder=1))
        ax.plot([p0[0], p1[0]], [p0[1], p1[1]], color="0.15", lw=3, solid_capstyle="butt", zorder=2)
        pts_all.append(np.array([p0 - depth, p1 - depth]))
    label = np.sum(active) <= _MAX_FORCE_LABELS
    for i in np.flatnonzero(active):
        n = model.contact_normals[i]
        tip = Y[model.contact_nodes[i]]
        tail = tip - n * arrow * F[i]
        ax.annotate("", xy=tip, xytext=tail, arrowprops=dict(arrowstyle="-|>", color="k", lw=1.5), zorder=4)
        pts_all.append(tail[None, :])
        if label:
            ax.text(*(tail - 0.01 * size * n), _force_text(F[i]), ha="center",
                    va="top" if n[1] > 0.5 else "bottom" if n[1] < -0.5 else "center", fontsize=7)
    pts = np.vstack(pts_all)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.05 * size
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - 2 * pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def _draw_3d(ax, X, Y, members, colors, groups, model, F, active, arrow, size) -> None:
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    # mplot3d's depth sorting puts a translucent plane over lines seen through it: fix the order.
    ax.computed_zorder = False
    ax.view_init(elev=20, azim=-60)
    ax.add_collection3d(Line3DCollection(X[members], colors="0.82", linewidths=0.6, zorder=1))
    pts_all = [X, Y]
    for normal, level, idx in groups:
        # two tangent directions spanning the plane
        helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
        t1 = np.cross(normal, helper)
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(normal, t1)
        nodes = Y[model.contact_nodes[idx]]
        a1, b1 = _plane_extent(nodes, t1, 2.5 * size)
        a2, b2 = _plane_extent(nodes, t2, 2.5 * size)
        corners = np.array([level * normal + s * t1 + r * t2 for s, r in ((a1, a2), (b1, a2), (b1, b2), (a1, b2))])
        ax.add_collection3d(Poly3DCollection([corners], facecolors=(0.55, 0.55, 0.55, 0.3),
                                             edgecolors="0.3", linewidths=1.0, zorder=0))
        pts_all.append(corners)
    ax.add_collection3d(Line3DCollection(Y[members], colors=colors, linewidths=2.0, zorder=2))
    cn = Y[model.contact_nodes]
    ax.scatter(cn[:, 0], cn[:, 1], cn[:, 2], s=10, color="k", depthshade=False, zorder=3)
    label = np.sum(active) <= _MAX_FORCE_LABELS
    for i in np.flatnonzero(active):
        n = model.contact_normals[i]
        tip = Y[model.contact_nodes[i]]
        vec = n * arrow * F[i]
        tail = tip - vec
        ax.quiver(*tail, *vec, color="k", arrow_length_ratio=0.3, linewidths=2.0, zorder=4)
        pts_all.append(tail[None, :])
        if label:
            ax.text(*(tail - 0.02 * size * n), " " + _force_text(F[i]), fontsize=7, ha="left", va="top", zorder=5)
    pts = np.vstack(pts_all)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(np.maximum(hi - lo, 0.05 * size), zoom=1.15)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m] (displacements magnified)")


@register_drawing("contact_history")
def figure_contact_history(cmp: Comparison, *, pair_labels: list[str] | None = None) -> Figure:
    """Contact forces against the load parameter, for every variant and formulation.

    With at most 8 contact pairs every pair is drawn (one colour per pair, labelled by
    ``pair_labels``, default ``pair 0``, ``pair 1``, ...; a truss names its nodes); with more, the
    total contact force, with the number of active contacts on a second axis. Classical runs are
    lines (one style per formulation), DDCM runs markers; the closed form, where the model has
    one, is dashed black; non-converged steps are circled in red.
    """
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    m = cmp.model
    h = np.asarray(m.load_parameter, dtype=float)
    nc = m.n_contacts
    per_pair = nc <= _MAX_PAIRS_DRAWN
    fig = Figure(figsize=(7.6, 5.0), constrained_layout=True)
    ax = fig.add_subplot()
    ax2 = None if per_pair else ax.twinx()
    pair_colors = [f"C{i % 10}" for i in range(nc)]

    def curves(force: np.ndarray) -> np.ndarray:
        return force / 1e3 if per_pair else np.sum(force, axis=1, keepdims=True) / 1e3

    ref = [m.closed_form(k) for k in range(m.n_steps)]
    if ref[0] is not None:
        y = curves(np.array([r[1] for r in ref]) * m.contact_area[None, :])
        for j in range(y.shape[1]):
            ax.plot(h, y[:, j], "k--", lw=1.0, zorder=5)
    failed = local = extrapolated = False
    handles = []
    for (variant, name), r in cmp.results.items():
        f = cmp.fields(variant, name)
        y = curves(f["contact_force"])
        conv = f["converged"].astype(bool)
        for j in range(y.shape[1]):
            c = pair_colors[j] if per_pair else "C0"
            if variant == "classical":
                ax.plot(h, y[:, j], _STYLES.get(name, "-"), color=c, lw=1.4, zorder=2)
            else:
                ax.plot(h, y[:, j], _MARKERS.get(name, "o"), color=c, ms=5, mfc="none", zorder=3)
            if not conv.all():
                failed = True
                ax.plot(h[~conv], y[~conv, j], "o", ms=13, mfc="none", mec="red", mew=2, zorder=6)
            if variant == "ddcm":
                loc = np.array([st.global_optimum is False for st in r.steps])
                if loc.any():
                    local = True
                    ax.plot(h[loc], y[loc, j], "D", ms=11, mfc="none", mec="0.3", mew=1, zorder=4)
            beyond = _beyond(r)
            if beyond.any():
                extrapolated = True
                ax.plot(h[beyond], y[beyond, j], **_BEYOND)
        if ax2 is not None:
            n_active = np.sum(m.active_contacts(f["contact_pressure"]), axis=1)
            if variant == "classical":
                ax2.plot(h, n_active, _STYLES.get(name, "-"), color="C3", lw=1.0, alpha=0.7, drawstyle="steps-mid")
            else:
                ax2.plot(h, n_active, _MARKERS.get(name, "o"), color="C3", ms=4, mfc="none", alpha=0.7)
        c = "k" if per_pair else "C0"  # per pair, colour means the pair and style the run
        style = dict(color=c, ls=_STYLES.get(name, "-"), lw=1.4) if variant == "classical" else \
            dict(color=c, ls="none", marker=_MARKERS.get(name, "o"), mfc="none")
        handles.append(Line2D([], [], label=f"{'classical' if variant == 'classical' else 'DDCM'}, "
                                            f"{_title(cmp, name)}", **style))
    if ref[0] is not None:
        handles.append(Line2D([], [], color="k", ls="--", lw=1.0, label="closed form"))
    if per_pair:
        labels = list(pair_labels) if pair_labels is not None else [f"pair {j}" for j in range(nc)]
        if len(labels) != nc:
            raise ValueError(f"pair_labels has {len(labels)} labels for {nc} contact pairs")
        for j in range(nc):
            handles.append(Line2D([], [], color=pair_colors[j], lw=4, label=labels[j]))
    else:
        handles.append(Line2D([], [], color="C3", lw=1.0, label="active contacts (right axis)"))
    if local:
        handles.append(Line2D([], [], ls="none", marker="D", ms=9, mfc="none", mec="0.3",
                              label="DDCM local minimum (not global)"))
    if extrapolated:
        handles.append(Line2D([], [], **{**_BEYOND, "ms": 10}, label=_BEYOND_LABEL))
    if failed:
        handles.append(Line2D([], [], ls="none", marker="o", ms=10, mfc="none", mec="red", mew=2,
                              label="NOT CONVERGED"))
    ax.set_xlabel(_param_label(cmp))
    ax.set_ylabel("contact force [kN]" if per_pair else "total contact force [kN]")
    if ax2 is not None:
        ax2.set_ylabel("active contacts", color="C3")
        ax2.set_ylim(-0.3, nc + 0.3)
        ax2.yaxis.get_major_locator().set_params(integer=True)
    if h.size > 1 and h[-1] < h[0]:
        ax.invert_xaxis()  # read the load path left to right
    ax.grid(True, alpha=0.3)
    ax.set_title(f"{m.name}: contact force{'s per node' if per_pair else ' (total of %d pairs)' % nc}",
                 fontsize=10)
    ax.legend(handles=handles, fontsize=7, ncol=2, loc="upper left")
    return fig
