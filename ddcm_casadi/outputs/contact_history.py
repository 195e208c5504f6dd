"""The contact forces along the load path, for any model (registered as the drawing ``contact_history``).

Classical runs are lines (one style per formulation), DDCM runs markers; the closed form, where the
model has one, is dashed black; flagged steps are framed as :mod:`ddcm_casadi.outputs.marks` says.
Matplotlib is imported only by the functions that draw.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ddcm_casadi.outputs.drawings import register_drawing
from ddcm_casadi.outputs.marks import (
    BEYOND, BEYOND_LABEL, FAILED, FAILED_LABEL, LOCAL, LOCAL_LABEL, MARKERS, STYLES, mark_steps, parameter_label,
    run_title,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ddcm_casadi.drivers.harness import Comparison

_MAX_PAIRS_DRAWN = 8  # above this many contact pairs the history shows totals, not every pair


def _curves(force: np.ndarray, per_pair: bool) -> np.ndarray:
    """The curves drawn (kN): one per pair, or the total."""
    return force / 1e3 if per_pair else np.sum(force, axis=1, keepdims=True) / 1e3


def _draw_runs(ax: Any, ax2: Any, cmp: Comparison, h: np.ndarray, per_pair: bool) -> tuple[list, list[bool]]:
    """Each run's curves on ``ax`` (and its active-contact count on ``ax2`` for totals).

    Returns
    -------
    handles : list of Line2D
        One legend entry per run.
    flags : list of bool
        Whether any step was ``[failed, local, beyond]``.
    """
    from matplotlib.lines import Line2D

    m = cmp.model
    pair_colors = [f"C{i % 10}" for i in range(m.n_contacts)]
    flags = [False, False, False]
    handles = []
    for (variant, name), r in cmp.results.items():
        f = cmp.fields(variant, name)
        y = _curves(f["contact_force"], per_pair)
        conv = f["converged"].astype(bool)
        for j in range(y.shape[1]):
            c = pair_colors[j] if per_pair else "C0"
            if variant == "classical":
                ax.plot(h, y[:, j], STYLES.get(name, "-"), color=c, lw=1.4, zorder=2)
            else:
                ax.plot(h, y[:, j], MARKERS.get(name, "o"), color=c, ms=5, mfc="none", zorder=3)
            marked = mark_steps(ax, h, y[:, j], r, conv, variant, failed_ms=13, failed_zorder=6)
            flags = [a or b for a, b in zip(flags, marked)]
        if ax2 is not None:
            n_active = np.sum(m.active_contacts(f["contact_pressure"]), axis=1)
            if variant == "classical":
                ax2.plot(h, n_active, STYLES.get(name, "-"), color="C3", lw=1.0, alpha=0.7, drawstyle="steps-mid")
            else:
                ax2.plot(h, n_active, MARKERS.get(name, "o"), color="C3", ms=4, mfc="none", alpha=0.7)
        c = "k" if per_pair else "C0"  # per pair, colour means the pair and style the run
        style = dict(color=c, ls=STYLES.get(name, "-"), lw=1.4) if variant == "classical" else \
            dict(color=c, ls="none", marker=MARKERS.get(name, "o"), mfc="none")
        handles.append(Line2D([], [], label=f"{'classical' if variant == 'classical' else 'DDCM'}, "
                                            f"{run_title(cmp, name)}", **style))
    return handles, flags


def _key(nc: int, per_pair: bool, pair_labels: list[str] | None, closed_form: bool, flags: list[bool]) -> list:
    """The legend entries after the runs': closed form, pairs (or the count axis), flagged steps."""
    from matplotlib.lines import Line2D

    handles = []
    if closed_form:
        handles.append(Line2D([], [], color="k", ls="--", lw=1.0, label="closed form"))
    if per_pair:
        labels = list(pair_labels) if pair_labels is not None else [f"pair {j}" for j in range(nc)]
        if len(labels) != nc:
            raise ValueError(f"pair_labels has {len(labels)} labels for {nc} contact pairs")
        for j in range(nc):
            handles.append(Line2D([], [], color=f"C{j % 10}", lw=4, label=labels[j]))
    else:
        handles.append(Line2D([], [], color="C3", lw=1.0, label="active contacts (right axis)"))
    failed, local, extrapolated = flags
    if local:
        handles.append(Line2D([], [], ls="none", ms=9, label=LOCAL_LABEL, **LOCAL))
    if extrapolated:
        handles.append(Line2D([], [], **{**BEYOND, "ms": 10}, label=BEYOND_LABEL))
    if failed:
        handles.append(Line2D([], [], ls="none", ms=10, label=FAILED_LABEL, **FAILED))
    return handles


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

    m = cmp.model
    h = np.asarray(m.load_parameter, dtype=float)
    nc = m.n_contacts
    per_pair = nc <= _MAX_PAIRS_DRAWN
    fig = Figure(figsize=(7.6, 5.0), constrained_layout=True)
    ax = fig.add_subplot()
    ax2 = None if per_pair else ax.twinx()
    ref = [m.closed_form(k) for k in range(m.n_steps)]
    if ref[0] is not None:
        y = _curves(np.array([r[1] for r in ref]) * m.contact_area[None, :], per_pair)
        for j in range(y.shape[1]):
            ax.plot(h, y[:, j], "k--", lw=1.0, zorder=5)
    handles, flags = _draw_runs(ax, ax2, cmp, h, per_pair)
    handles += _key(nc, per_pair, pair_labels, ref[0] is not None, flags)
    ax.set_xlabel(parameter_label(cmp))
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
