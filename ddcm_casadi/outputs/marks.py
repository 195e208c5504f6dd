"""What the comparison figures share: the style of each formulation's curve, the frames that flag a
step, and the axis and legend labels.

Classical results are lines (one style per formulation), DDCM results markers (one marker per
formulation); a step that did not converge is circled in red, a DDCM step that stopped at a local
(not the global) minimum is framed by a grey diamond, and a DDCM step with states beyond the
material data (:mod:`ddcm_casadi.data.extrapolation`) by a violet hexagon. Used by
:mod:`ddcm_casadi.outputs.bar_figures` and :mod:`ddcm_casadi.outputs.contact_history`; imports no
matplotlib (the axes are passed in).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from ddcm_casadi.drivers.harness import Comparison

#: The marker of each formulation's DDCM results, and the line style of its classical results.
MARKERS = {"penalty": "s", "augmented_lagrangian": "^", "fischer_burmeister": "o", "mpcc": "x"}
STYLES = {"penalty": "-", "augmented_lagrangian": "--", "fischer_burmeister": "-.", "mpcc": ":"}
#: The frame of a DDCM step with states beyond the data, and its legend entry.
BEYOND = dict(ls="none", marker="h", ms=16, mfc="none", mec="darkviolet", mew=1.5, zorder=4)
BEYOND_LABEL = "DATA RANGE EXCEEDED"
#: The frame of a DDCM step at a local minimum (drawn at ``ms=11``, in the legend at ``ms=9``).
LOCAL = dict(marker="D", mfc="none", mec="0.3")
LOCAL_LABEL = "DDCM local minimum (not global)"
#: The ring around a step that did not converge (its size and layer are the figure's).
FAILED = dict(marker="o", mfc="none", mec="red", mew=2)
FAILED_LABEL = "NOT CONVERGED"


def beyond_data(run: Any) -> np.ndarray:
    """Which steps of a run have states beyond the data (all false for classical runs)."""
    return np.array([st.extrapolated > 0 for st in run.steps], dtype=bool)


def run_title(cmp: Comparison, formulation: str) -> str:
    """The title of formulation ``formulation`` in ``cmp`` (its name if it has none)."""
    return next((f.title for f in cmp.formulations if f.name == formulation), formulation)


def parameter_label(cmp: Comparison) -> str:
    """The load parameter's axis label: the obstacle position ``h`` in metres, else its name."""
    name = cmp.model.load_parameter_name
    return f"obstacle position {name} [m]" if name == "h" else name


def mark_steps(ax: Any, h: np.ndarray, y: np.ndarray, run: Any, converged: np.ndarray, variant: str, *,
               failed_ms: float, failed_zorder: float) -> tuple[bool, bool, bool]:
    """Frame the flagged steps of one curve ``y(h)`` of ``run``: local minima (DDCM), states beyond
    the data, steps that did not converge (a ring of ``failed_ms`` at layer ``failed_zorder``).

    Returns
    -------
    tuple of bool
        Whether any step was ``(failed, local, beyond)``, for the legend's entries.
    """
    local = beyond = False
    if variant == "ddcm":
        loc = np.array([st.global_optimum is False for st in run.steps])
        if loc.any():
            local = True
            ax.plot(h[loc], y[loc], ls="none", ms=11, mew=1, zorder=4, **LOCAL)
    out = beyond_data(run)
    if out.any():
        beyond = True
        ax.plot(h[out], y[out], **BEYOND)
    failed = not converged.all()
    if failed:
        ax.plot(h[~converged], y[~converged], ls="none", ms=failed_ms, zorder=failed_zorder, **FAILED)
    return failed, local, beyond
