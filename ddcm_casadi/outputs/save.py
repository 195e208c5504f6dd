"""The output layer: a comparison's figures and field files, from what its model declares.

A model kind says which figures (:meth:`~ddcm_casadi.models.base.ContactModel.figures`) and field files
(:meth:`~ddcm_casadi.models.base.ContactModel.field_outputs`) it has; this module draws and writes them
with the functions registered under those names (:mod:`ddcm_casadi.outputs.drawings`), each file written
atomically. ``results.csv`` and ``results.json`` are :mod:`ddcm_casadi.run`'s. Matplotlib is
imported only when a figure is drawn.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Mapping

from ddcm_casadi.outputs import plots  # registers the drawings of bars and trusses and the contact history of any model
from ddcm_casadi.outputs import continuum_results as _continuum_results  # noqa: F401 - registers the continuum's drawings, VTU
from ddcm_casadi.outputs.drawings import drawing, field_writer
from ddcm_casadi.drivers.harness import Comparison, compare
from ddcm_casadi.models.base import ContactModel, FigureSpec
from ddcm_casadi.parallel import map_forked

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def require_matplotlib() -> None:
    """Import matplotlib now (raises ``ImportError`` if it is missing): called before a run whose
    figures will be drawn, so that a missing matplotlib cannot leave results without figures."""
    import matplotlib.figure  # noqa: F401 - imported for its side effect only


def draw(cmp: Comparison, spec: FigureSpec) -> Figure:
    """Draw one figure a model declares.

    Parameters
    ----------
    cmp : Comparison
        The results to draw.
    spec : FigureSpec
        Which drawing (looked up in :func:`ddcm_casadi.outputs.drawings.drawing`) and its options.

    Returns
    -------
    Figure
        A matplotlib figure (not yet saved).
    """
    return drawing(spec.drawing)(cmp, **spec.options)


def save_figures(cmp: Comparison, out_dir: str | Path, *, jobs: int = 1) -> list[Path]:
    """Draw the figures the model declares into ``out_dir``, each written atomically, side by side
    in up to ``jobs`` processes (:func:`ddcm_casadi.parallel.map_forked`).

    The paper's one-element bar draws Fig. 2 (``fig2a_tip_displacement.png``,
    ``fig2b_contact_pressure.png``); a truss ``structure_classical.png`` and ``structure_ddcm.png``
    and ``contact_history.png``; a continuum the pressure profile, the deformed bodies and the
    contact history.

    Returns
    -------
    list of Path
        The files written, in the order the model declares them.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)  # the examples' output/<name>/ may not exist yet
    specs: Mapping[str, FigureSpec] = cmp.model.figures(cmp.results)
    return map_forked(lambda item: plots.save_figure(draw(cmp, item[1]), out_dir / item[0]), list(specs.items()),
                      jobs=jobs)


def save_outputs(cmp: Comparison, out_dir: str | Path, *, figures: bool = True, jobs: int = 1) -> list[Path]:
    """Write the outputs that suit the model besides ``results.csv`` and ``results.json``: its field
    files (VTU series of a continuum), then its figures unless ``figures`` is false.

    Parameters
    ----------
    cmp : Comparison
        The results to write.
    out_dir : str or Path
        The folder (created if needed).
    figures : bool
        Draw the figures (:func:`save_figures`).
    jobs : int
        Processes drawing the figures side by side.

    Returns
    -------
    list of Path
        The files written.
    """
    out_dir = Path(out_dir)
    written: list[Path] = []
    for name in cmp.model.field_outputs():
        written += field_writer(name)(cmp, out_dir)
    if figures:
        written += save_figures(cmp, out_dir, jobs=jobs)
    return written


def compare_and_plot(model: ContactModel, out_dir: str | Path | None = None,
                     formulations: Iterable[str] | Mapping[str, dict] | None = None, **options) -> Comparison:
    """:func:`~ddcm_casadi.drivers.harness.compare`, then the figures that suit the model in ``out_dir``
    (if given; matplotlib is imported only then).

    Parameters
    ----------
    model : ContactModel
        The model to run.
    out_dir : str or Path, optional
        Where to draw the figures.
    formulations : optional
        As for :func:`~ddcm_casadi.drivers.harness.compare`.
    **options
        Further keyword arguments of :func:`~ddcm_casadi.drivers.harness.compare`.
    """
    cmp = compare(model, formulations, **options)
    if out_dir is not None:
        save_figures(cmp, out_dir)
    return cmp
