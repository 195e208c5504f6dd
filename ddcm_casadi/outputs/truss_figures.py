"""The deformed truss at one load step (:class:`~ddcm_casadi.models.truss.TrussModel`, 1-D, 2-D or 3-D).

Registered as the drawing ``structure`` (:mod:`ddcm_casadi.outputs.drawings`): the undeformed
structure in light grey, the deformed one coloured by member force, its rigid planes and its contact
forces. Matplotlib is imported only by the functions that draw.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ddcm_casadi.outputs.drawings import register_drawing
from ddcm_casadi.outputs.marks import BEYOND, BEYOND_LABEL, run_title

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ddcm_casadi.drivers.harness import Comparison

_MAX_FORCE_LABELS = 10  # above this many active contacts the arrows go unlabelled


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


@dataclass
class _Scene:
    """What the drawing of one step shows, in drawing units (magnified displacements)."""

    X: np.ndarray  # reference nodes
    Y: np.ndarray  # magnified deformed nodes
    F: np.ndarray  # contact forces
    active: np.ndarray  # active contacts
    mag: float  # displacement magnification
    size: float  # the structure's extent
    arrow: float  # arrow length per newton
    supported: np.ndarray  # nodes with a fixed dof
    groups: list  # rigid planes (:func:`_obstacle_groups`)
    mappable: Any  # member-force colour scale (kN)
    colors: np.ndarray  # colour of each member


def _scene(model, fields: dict, k: int, magnification: float | None) -> _Scene:
    """The :class:`_Scene` of step ``k`` from the run's ``fields``."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    X = model.nodes
    U = fields["nodal_displacement"][k]
    N = fields["member_force"][k]
    F = fields["contact_force"][k]
    size = float(np.max(np.ptp(X, axis=0)))
    umax = float(np.max(np.abs(U)))
    if magnification is None:
        magnification = _nice(0.1 * size / umax) if umax > 0 else 1.0
    mag = float(magnification)
    fixed = ~np.isin(np.arange(X.size), model.free_dofs).reshape(X.shape)

    # Member forces: one symmetric colour scale so white is zero force.
    nmax = float(np.max(np.abs(N))) or 1.0
    sm = ScalarMappable(norm=Normalize(-nmax / 1e3, nmax / 1e3), cmap="coolwarm")

    # Contact forces: arrows along +n (the obstacle pushes the node), the largest ~8 % of the size.
    fmax = float(np.max(F)) if F.size else 0.0
    return _Scene(X=X, Y=X + mag * U, F=F, active=model.active_contacts(F / model.contact_area), mag=mag,
                  size=size, arrow=0.08 * size / fmax if fmax > 0 else 0.0,
                  supported=np.flatnonzero(fixed.any(axis=1)),
                  groups=_obstacle_groups(model, model.gap_offsets[k], mag) if model.n_contacts else [],
                  mappable=sm, colors=sm.to_rgba(N / 1e3))


def _draw_scene(fig: Figure, model, s: _Scene) -> Any:
    """Draw the scene in ``fig`` by the model's dimension, with the member-force colour bar; the axes."""
    d = model.dimension
    args = (s.X, s.Y, model.members, s.colors, s.groups, model, s.F, s.active, s.arrow, s.size)
    if d == 3:
        ax = fig.add_subplot(projection="3d")
        _draw_3d(ax, *args)
        ax.scatter(*s.Y[s.supported].T, marker="^", s=60, color="0.3", depthshade=False, zorder=3)
    elif d == 2:
        ax = fig.add_subplot()
        _draw_2d(ax, *args)
        ax.plot(*s.Y[s.supported].T, "^", ms=10, color="0.3", zorder=3, clip_on=False)
    else:
        ax = fig.add_subplot()
        _draw_1d(ax, *args)
        ax.plot(s.Y[s.supported, 0], np.zeros(s.supported.size), ">", ms=12, color="0.3", zorder=3)
    if d == 3:
        fig.colorbar(s.mappable, ax=ax, label="member force [kN] (tension +)", shrink=0.6, pad=0.08)
    else:  # under a wide, flat structure a horizontal bar fits better
        fig.colorbar(s.mappable, ax=ax, label="member force [kN] (tension +)", orientation="horizontal",
                     shrink=0.6, aspect=40)
    return ax


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
    from matplotlib.figure import Figure

    model = cmp.model
    f = cmp.fields(variant, formulation)
    if "nodal_displacement" not in f or "member_force" not in f:  # fields of the model kind
        raise TypeError("figure_structure needs a truss model (ddcm_casadi.models.truss.TrussModel)")
    k = range(model.n_steps)[step]
    s = _scene(model, f, k, magnification)
    d = model.dimension
    fig = Figure(figsize=(9.0, 5.6) if d == 3 else (9.0, 3.6) if d == 1 else (9.0, 5.2),
                 constrained_layout=True)
    ax = _draw_scene(fig, model, s)

    value = model.load_parameter[k]
    F = s.F
    total = f" total contact force {_force_text(float(np.sum(F)))}," if F.size else ""
    ax.set_title(f"{model.name}: {variant}, {run_title(cmp, formulation)}, step {k} "
                 f"({model.load_parameter_name} = {value:.4g})\n"
                 f"{int(np.sum(s.active))}/{F.size} contacts active,{total} displacements x{s.mag:g}",
                 fontsize=9)
    converged = bool(f["converged"][k])
    beyond = int(cmp[variant, formulation].steps[k].extrapolated)
    flags = (["NOT CONVERGED"] if not converged else []) + ([f"{BEYOND_LABEL} ({beyond} states)"] if beyond else [])
    if flags:
        fig.suptitle("; ".join(flags), color="red" if not converged else BEYOND["mec"], fontweight="bold")
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
