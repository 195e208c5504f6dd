"""The paper's Fig. 2 (one-element bar): tip displacement and contact pressure against the obstacle.

Registered as the drawings ``tip_displacement`` and ``contact_pressure``
(:mod:`ddcm_casadi.outputs.drawings`). Classical results are lines, DDCM results markers, the
closed form a dashed black line; flagged steps are framed as :mod:`ddcm_casadi.outputs.marks` says.
Matplotlib is imported only by the functions that draw.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ddcm_casadi.outputs.drawings import register_drawing
from ddcm_casadi.outputs.marks import (
    BEYOND, BEYOND_LABEL, FAILED, FAILED_LABEL, LOCAL, LOCAL_LABEL, MARKERS, STYLES, mark_steps, parameter_label,
    run_title,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ddcm_casadi.drivers.harness import Comparison

#: Fig. 2's margins (figure fractions): where constrained layout put its axes on the paper's
#: figures, fixed. Constrained layout measures every text of the figure in extra passes before
#: drawing it (0.05 s a figure, measured on the paper's first run) to find the same place.
_FIG2_MARGINS = dict(left=0.10, bottom=0.103, right=0.9935, top=0.945)
#: Width of one character of a y tick label (fraction of Fig. 2's width; 10 pt DejaVu Sans digits
#: are 6.4 pt wide, the figure 6.4 in): labels longer than Fig. 2's four characters widen the margin.
_FIG2_CHAR = 6.4 / 72 / 6.4


def _fig2_layout(fig: Figure, ax: Any) -> None:
    """Place Fig. 2's axes at :data:`_FIG2_MARGINS`, the left margin widened for long y tick labels."""
    lo, hi = sorted(ax.get_ylim())
    ticks = [t for t in ax.get_yticks() if lo <= t <= hi]  # the locator also returns ticks out of view
    labels = ax.yaxis.get_major_formatter().format_ticks(ticks)
    extra = max((len(t) for t in labels), default=0) - 4
    fig.subplots_adjust(**{**_FIG2_MARGINS, "left": _FIG2_MARGINS["left"] + _FIG2_CHAR * max(extra, 0)})


def _panel(cmp: Comparison, quantity: str, ylabel: str, scale: float, title: str) -> Figure:
    """One panel of Fig. 2: ``quantity`` (``"u"``: the tip's, ``"p"``: the contact's) times ``scale``."""
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
        title_f = run_title(cmp, name)
        if variant == "classical":
            ax.plot(h, y, STYLES.get(name, "-"), lw=1.4, label=f"classical, {title_f}", zorder=2)
        else:
            ax.plot(h, y, MARKERS.get(name, "o"), ms=6, mfc="none", label=f"DDCM, {title_f}", zorder=3)
        flags = mark_steps(ax, h, y, r, r.array("converged").astype(bool), variant, failed_ms=14, failed_zorder=4)
        failed, local, extrapolated = failed or flags[0], local or flags[1], extrapolated or flags[2]
    if local:
        ax.plot([], [], ls="none", ms=9, label=LOCAL_LABEL, **LOCAL)
    if extrapolated:
        ax.plot([], [], **{**BEYOND, "ms": 10}, label=BEYOND_LABEL)
    if failed:
        ax.plot([], [], ls="none", ms=10, label=FAILED_LABEL, **FAILED)
    ax.set_xlabel(parameter_label(cmp))
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
