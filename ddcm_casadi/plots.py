"""Figures of a comparison (the paper's Fig. 2): tip displacement and contact pressure vs obstacle.

Classical results are lines, DDCM results markers, the closed form a dashed black line; a step that
did not converge is circled in red and named in the legend, never drawn as if it were fine, and a
DDCM step that stopped at a local (not the global) minimum is framed by a grey diamond.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .harness import Comparison
from .io import write_bytes_atomic

_MARKERS = {"penalty": "s", "augmented_lagrangian": "^", "fischer_burmeister": "o", "mpcc": "x"}
_STYLES = {"penalty": "-", "augmented_lagrangian": "--", "fischer_burmeister": "-.", "mpcc": ":"}


def _panel(cmp: Comparison, quantity: str, ylabel: str, scale: float, title: str) -> Figure:
    fig = Figure(figsize=(6.4, 4.6), constrained_layout=True)
    ax = fig.add_subplot()
    m = cmp.model
    h = m.load_parameter
    ref = [m.closed_form(k) for k in range(m.n_steps)]
    if ref[0] is not None:
        idx = 0 if quantity == "u" else 1
        ax.plot(h, [r[idx][-1 if quantity == "u" else 0] * scale for r in ref], "k--", lw=1.0,
                label="closed form", zorder=1)
    failed = local = False
    for (variant, name), r in cmp.results.items():
        y = r.array(quantity)
        y = (y[:, -1] if quantity == "u" else y[:, 0]) * scale
        conv = r.array("converged").astype(bool)
        title_f = next(f.title for f in cmp.formulations if f.name == name)
        if variant == "classical":
            ax.plot(h, y, _STYLES.get(name, "-"), lw=1.4, label=f"classical, {title_f}", zorder=2)
        else:
            ax.plot(h, y, _MARKERS.get(name, "o"), ms=6, mfc="none", label=f"DDCM, {title_f}", zorder=3)
        if variant == "ddcm":
            loc = np.array([st.global_optimum is False for st in r.steps])
            if loc.any():
                local = True
                ax.plot(h[loc], y[loc], "D", ms=11, mfc="none", mec="0.3", mew=1, zorder=4)
        if not conv.all():
            failed = True
            ax.plot(h[~conv], y[~conv], "o", ms=14, mfc="none", mec="red", mew=2, zorder=4)
    if local:
        ax.plot([], [], "D", ms=9, mfc="none", mec="0.3", label="DDCM local minimum (not global)")
    if failed:
        ax.plot([], [], "o", ms=10, mfc="none", mec="red", mew=2, label="NOT CONVERGED")
    ax.set_xlabel(f"obstacle position {m.load_parameter_name} [m]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.invert_xaxis()
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    return fig


def figure_displacement(cmp: Comparison) -> Figure:
    """Fig. 2a: bar tip displacement against obstacle position."""
    return _panel(cmp, "u", "tip displacement u [mm]", 1e3, "Tip displacement (Fig. 2a)")


def figure_pressure(cmp: Comparison) -> Figure:
    """Fig. 2b: contact pressure against obstacle position."""
    return _panel(cmp, "p", "contact pressure p [GPa]", 1e-9, "Contact pressure (Fig. 2b)")


def save_figure(fig: Figure, path: str | Path, *, dpi: int = 150) -> Path:
    """Save atomically (temporary file, then rename)."""
    path = Path(path)
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lstrip(".") or "png", dpi=dpi)
    return write_bytes_atomic(path, buf.getvalue())


def save_fig2(cmp: Comparison, out_dir: str | Path) -> list[Path]:
    out_dir = Path(out_dir)
    return [save_figure(figure_displacement(cmp), out_dir / "fig2a_tip_displacement.png"),
            save_figure(figure_pressure(cmp), out_dir / "fig2b_contact_pressure.png")]
