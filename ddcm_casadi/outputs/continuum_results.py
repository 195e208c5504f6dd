"""Outputs of a continuum comparison: VTU series for ParaView and the figures.

For every run (variant x formulation) one VTU file per step and a ``.pvd`` collection
(``vtu/<variant>_<formulation>.pvd``) with the nodal ``displacement`` and ``contact_pressure``
and, per element (the mean over its quadrature points), ``strain`` and ``stress`` (tensors),
``von_mises``, and for DDCM ``data_stress`` (the assigned data) and ``ddcm_distance`` (the local
distance ``sqrt(d^2)`` of the states to their data). Figures: the contact pressure of every run
at the last step against Hertz (when the model has a Hertz reference) and the deformed body
coloured by the von Mises stress (the contact history is :func:`ddcm_casadi.outputs.plots.figure_contact_history`).

Plane strain (2-D): the out-of-plane stress ``sigma_zz`` is no part of the 2-D Mandel state. For a
classical run it is ``nu (sigma_11 + sigma_22)`` (``e_zz = 0`` with the isotropic law), written in
the ``stress`` tensor and used in ``von_mises``. A DDCM run has no law, and its 2-D data carry only
the three in-plane components, so its ``sigma_zz`` is unknown: NaN in the ``stress`` tensor and in
``von_mises``; the VTU adds ``von_mises_in_plane`` (``sigma_zz = 0``, plane-stress formula), and
the DDCM figure is coloured by it and says so.

The output layer of :class:`~ddcm_casadi.models.continuum.model.ContinuumModel`: the writer and the
drawings are registered (:mod:`ddcm_casadi.outputs.drawings`) under the names the model declares
(``vtu``; ``pressure_profile``, ``deformed_body``), and :mod:`ddcm_casadi.outputs.save` calls them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ddcm_casadi.outputs.drawings import register_drawing, register_field_writer
from ddcm_casadi.outputs.continuum import (
    figure_deformed_body, figure_pressure_profile, mandel_to_tensor, plane_strain_sigma_zz, von_mises,
    write_vtu_series,
)


def _cells(model) -> list[tuple[str, np.ndarray]]:
    disc = model.discretisation
    if disc.degree == 1:
        return [("triangle" if disc.dimension == 2 else "tetra", model.mesh.t.T.copy())]
    # scikit-fem orders a P2 element's dofs as VTK does: vertices, then edges 01, 12, 02(=20) [, 03, 13, 23]
    return [("triangle6" if disc.dimension == 2 else "tetra10", disc.scalar_basis.element_dofs.T.copy())]


def _per_element(model, values: np.ndarray) -> np.ndarray:
    """Mean over each element's quadrature points of per-point values ``(m, ...)``."""
    nq = model.discretisation.points_per_element
    values = np.asarray(values)
    return values.reshape((-1, nq) + values.shape[1:]).mean(axis=1)


def sigma_zz(model, variant: str, stress: np.ndarray) -> np.ndarray | None:
    """The plane-strain ``sigma_zz`` per material point of a 2-D run (``None`` in 3-D, where the
    Mandel vector carries it): ``nu (sigma_11 + sigma_22)`` for a classical run, NaN (unknown)
    for a DDCM run (no law; 2-D data carry no ``sigma_zz``)."""
    if model.dimension != 2:
        return None
    if variant == "classical" and model.poisson_ratio is not None:
        return plane_strain_sigma_zz(stress, model.poisson_ratio)
    return np.full(stress.shape[0], np.nan)


def _step_data(model, run, step) -> dict:
    disc, d, k = model.discretisation, model.dimension, model.strain_components
    pressure = np.zeros(disc.scalar_basis.N)
    np.add.at(pressure, model.contact_dofs, step.p)
    strain = np.asarray(step.strain).reshape(-1, k)
    stress = np.asarray(step.stress).reshape(-1, k)
    zz = sigma_zz(model, run.variant, stress)
    cell = dict(strain=mandel_to_tensor(_per_element(model, strain), d).reshape(-1, 9),
                stress=mandel_to_tensor(_per_element(model, stress), d,
                                        None if zz is None else _per_element(model, zz)).reshape(-1, 9),
                von_mises=_per_element(model, von_mises(stress, d, zz)))
    if zz is not None and np.isnan(zz).any():
        cell["von_mises_in_plane"] = _per_element(model, von_mises(stress, d))
    if step.stress_star is not None:
        star = np.asarray(step.stress_star).reshape(-1, k)
        d2 = model.dataset.distance2(strain, stress, step.data_index)
        cell.update(data_stress=mandel_to_tensor(_per_element(model, star), d).reshape(-1, 9),
                    ddcm_distance=_per_element(model, np.sqrt(np.maximum(d2, 0.0))))
    return dict(time=float(step.load_parameter),
                point_data=dict(displacement=model.dof_displacement(step.u), contact_pressure=pressure),
                cell_data=cell)


@register_field_writer("vtu")
def write_vtu(cmp, out_dir) -> list[Path]:
    """Write the VTU series of every run of a continuum comparison into ``out_dir/vtu/``.

    Parameters
    ----------
    cmp : Comparison
        The results of :func:`~ddcm_casadi.drivers.harness.compare` on a continuum.
    out_dir : str or Path
        The output folder.

    Returns
    -------
    list of Path
        One ``.vtu`` file per step and run, and a ``.pvd`` series per run.
    """
    model = cmp.model
    vtu = Path(out_dir) / "vtu"
    vtu.mkdir(parents=True, exist_ok=True)
    points, cells = model.discretisation.dof_locations(), _cells(model)
    written: list[Path] = []
    for (variant, name), run in cmp.results.items():
        steps = [_step_data(model, run, s) for s in run.steps]
        written += write_vtu_series(vtu, points=points, cells=cells, steps=steps, name=f"{variant}_{name}")
    return written


def _profile_coordinate(model) -> tuple[np.ndarray, np.ndarray]:
    """Pairs and a coordinate along the surface for the pressure figure."""
    if model.reference is not None:
        return model.reference.coordinates(model)
    pairs = np.arange(model.n_contacts)
    return pairs, model.contact_points[:, 0]


@register_drawing("pressure_profile")
def draw_pressure_profile(cmp):
    """The contact pressure of every run at the last step along the surface, with Hertz's for the
    measured force when the model has a Hertz reference (``pressure_profile.png``)."""
    model = cmp.model
    pairs, x = _profile_coordinate(model)
    # show the contact zone: 1.5 x the farthest pair in contact in any run's last step
    active = np.zeros(pairs.size, dtype=bool)
    for r in cmp.results.values():
        active |= model.active_contacts(np.asarray(r.steps[-1].p)[pairs])
    if active.any():
        keep = np.abs(x) <= 1.5 * float(np.max(np.abs(x[active])))
        pairs, x = pairs[keep], x[keep]
    runs, hertz = [], None
    styles = {"classical": dict(ls="-", marker=None), "ddcm": dict(ls="none", marker="o", ms=3)}
    for (variant, name), r in cmp.results.items():
        last = r.steps[-1]
        runs.append(dict(label=f"{variant}/{name}", x=x, pressure=np.asarray(last.p)[pairs],
                         converged=bool(last.converged), style=styles[variant]))
        if hertz is None and model.reference is not None and variant == "classical" and last.converged:
            hertz = model.reference.curve(model, last.p)
    xlabel = "distance from the indenter's axis (m)" if model.reference is not None else "x (m)"
    return figure_pressure_profile(runs, hertz=hertz, xlabel=xlabel, title=f"{model.name}: contact pressure, last step")


@register_drawing("deformed_body")
def draw_deformed_body(cmp, *, variant: str, formulation: str):
    """The deformed body of one run at the last step, coloured by the von Mises stress
    (``deformed_<variant>.png``)."""
    from ddcm_casadi.models.continuum import fem  # scikit-fem only when a 3-D body is drawn (its import takes 0.4 s)

    model, key = cmp.model, (variant, formulation)
    last = cmp.results[key].steps[-1]
    d, k = model.dimension, model.strain_components
    stress = np.asarray(last.stress).reshape(-1, k)
    zz = sigma_zz(model, variant, stress)
    label = "von Mises stress"
    if zz is not None and np.isnan(zz).any():  # DDCM in 2-D: sigma_zz unknown
        zz, label = None, "von Mises stress of the in-plane components (sigma_zz unknown)"
    vm = _per_element(model, von_mises(stress, d, zz))
    disc = model.discretisation
    nn = model.mesh.p.shape[1]  # vertices come first among the scalar dofs
    points = disc.dof_locations()[:nn]
    disp = model.dof_displacement(last.u)[:nn]
    active = model.active_contacts(last.p)
    cdofs = model.contact_dofs[active]
    cdofs = cdofs[cdofs < nn]
    drawn = [ob.drawing(float(ob.travels(model.n_steps)[-1])) for ob in model.obstacles]
    title = f"{key[0]}/{key[1]}: {label}, last step"
    if d == 2:
        cells, values = model.mesh.t.T, vm
    else:
        cells = fem.boundary_triangles(model.mesh)
        counts = np.bincount(model.mesh.t.ravel(), minlength=nn)
        values = np.bincount(model.mesh.t.ravel(), weights=np.repeat(vm, model.mesh.t.shape[0]), minlength=nn)
        values = values / np.maximum(counts, 1)
    return figure_deformed_body(points, cells, displacement=disp, values=values, value_label=label,
                                contact_points=cdofs if cdofs.size else None,
                                obstacles=[o for o in drawn if o is not None], title=title)
