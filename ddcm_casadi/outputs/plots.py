"""Figures of a comparison: the drawings of bars and trusses, the contact history of any model, and
:func:`save_figure`.

Which figures suit a model, the model kind says as data
(:meth:`~ddcm_casadi.models.base.ContactModel.figures`); the drawings are registered under the names
those refer to (:mod:`ddcm_casadi.outputs.drawings`) by the modules that draw them, which this module
imports (so importing it registers them all), and :func:`ddcm_casadi.outputs.save.save_figures` draws
them:

- ``tip_displacement``, ``contact_pressure``: the paper's Fig. 2 (one-element bar), tip displacement
  and contact pressure vs obstacle (:mod:`ddcm_casadi.outputs.bar_figures`);
- ``structure``: any truss (:class:`~ddcm_casadi.models.truss.TrussModel`, 1-D, 2-D or 3-D), the
  deformed structure coloured by member force with its obstacles and contact forces
  (:func:`figure_structure`, :mod:`ddcm_casadi.outputs.truss_figures`);
- ``contact_history``: the contact forces along the load path, any model
  (:func:`figure_contact_history`, :mod:`ddcm_casadi.outputs.contact_history`).

Classical results are lines, DDCM results markers, the closed form a dashed black line; a step that
did not converge is circled in red and named in the legend, never drawn as if it were fine, a
DDCM step that stopped at a local (not the global) minimum is framed by a grey diamond, and a DDCM
step with states beyond the material data (:mod:`ddcm_casadi.data.extrapolation`) by a violet hexagon
(:mod:`ddcm_casadi.outputs.marks`). Matplotlib is imported only by the functions that draw.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

from ddcm_casadi.io import write_bytes_atomic
# Imported for their registrations too (the drawings' names above).
from ddcm_casadi.outputs.bar_figures import figure_displacement, figure_pressure
from ddcm_casadi.outputs.contact_history import figure_contact_history
from ddcm_casadi.outputs.truss_figures import figure_structure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["figure_contact_history", "figure_displacement", "figure_pressure", "figure_structure", "save_figure"]


def save_figure(fig: Figure, path: str | Path, *, dpi: int = 150) -> Path:
    """Save atomically (temporary file, then rename).

    Parameters
    ----------
    fig : Figure
        The figure to save.
    path : str or Path
        The file; its suffix names the format (PNG without one).
    dpi : int
        Resolution.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lstrip(".") or "png", dpi=dpi)
    return write_bytes_atomic(path, buf.getvalue())
