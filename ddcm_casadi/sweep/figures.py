"""Figures of a sweep (the only module of the sweep that imports matplotlib).

- ``rate``: ``y`` against ``x`` on log-log axes, the median over seeds per ``x``, with the
  least-squares line ``log10 y = s log10 x + b`` and its slope ``s`` in the legend
  (:func:`~ddcm_casadi.sweep.table.fit_loglog`);
- ``band``: the median over seeds and the 5-95 % band (percentiles of the seeds' values at
  each ``x``), ``y`` on a log axis unless ``logy = false``.

One line per variant, formulation and value of the other swept parameters.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ddcm_casadi.outputs.plots import save_figure
from ddcm_casadi.sweep.table import fit_loglog, series

_MARKERS = ("o", "s", "^", "D", "v", "x")


def figure(spec_figure, rows: list[dict], columns: list[str]) -> Figure:
    """The figure of one ``[[figures]]`` table from the rows of ``sweep.csv``."""
    fig = Figure(figsize=(6.4, 4.6), constrained_layout=True)
    ax = fig.add_subplot()
    positive = False
    for k, (label, (xs, ys)) in enumerate(series(rows, spec_figure.x, spec_figure.y, columns).items()):
        marker = _MARKERS[k % len(_MARKERS)]  # coinciding lines stay visible
        median = np.array([np.median(v) for v in ys])
        if spec_figure.kind == "rate":
            line = fit_loglog(xs, median)
            (handle,) = ax.loglog(xs, median, f"{marker}-", ms=6, mfc="none", label=label)
            if line is not None:
                slope, intercept = line
                keep = xs > 0
                ax.loglog(xs[keep], 10 ** (intercept + slope * np.log10(xs[keep])), "--", lw=1,
                          color=handle.get_color(), label=f"fit: slope {slope:.2f}")
        else:
            lo = np.array([np.percentile(v, 5) for v in ys])
            hi = np.array([np.percentile(v, 95) for v in ys])
            n = max(len(v) for v in ys)
            (handle,) = ax.plot(xs, median, f"{marker}-", ms=5, mfc="none", label=f"{label}: median of {n}")
            ax.fill_between(xs, lo, hi, alpha=0.25, color=handle.get_color(), label="5-95 %")
            positive |= bool(np.any(median > 0))
    if spec_figure.kind == "band" and spec_figure.logy and positive:
        ax.set_yscale("log")  # (values <= 0, e.g. an exact classical run, are not drawn)
    ax.set_xlabel(spec_figure.x)
    ax.set_ylabel(spec_figure.y)
    ax.set_title(spec_figure.title or f"{spec_figure.y} against {spec_figure.x}")
    ax.grid(True, which="both", alpha=0.3)
    if ax.has_data():
        ax.legend(fontsize=7)
    return fig


def save_figures(spec, rows: list[dict], out: Path, skipped: list[str] | None = None) -> list[Path]:
    """Draw every figure of the spec into ``out`` (atomically); returns the paths written.

    A figure with nothing to draw (no finished run with a finite ``y`` and ``x``, e.g. a Hertz
    metric of a case without a ``[hertz]`` reference) is not written: ``"file: reason"`` is
    appended to ``skipped``."""
    written = []
    for f in spec.figures:
        if not series(rows, f.x, f.y, spec.columns):
            if skipped is not None:
                skipped.append(f"{f.file}: no finished case has a value of {f.y} (empty column of sweep.csv)")
            continue
        written.append(save_figure(figure(f, rows, spec.columns), Path(out) / f.file))
    return written
