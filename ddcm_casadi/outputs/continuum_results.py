"""Outputs of a continuum comparison: VTU series for ParaView and the figures.

For every run (variant x formulation) two series in ``vtu/``, one VTU file per step each:

- the mesh, ``<variant>_<formulation>.pvd``: point data ``displacement`` (at every node, P2
  midpoints included), and on the contact nodes ``contact_pressure`` (zero elsewhere: no contact
  traction acts there), ``contact_gap`` (NaN elsewhere: a gap has no meaning off the contact
  surfaces, and a zero would read as touching; ParaView leaves NaN out of the colour range and
  draws it in its NaN colour) and ``contact_node`` (1 on a contact node, for *Threshold*); a node
  with pairs to several obstacles shows their summed pressure and its smallest gap. Cell data
  where one value per element is the truth, i.e. P1 (one material point per element): ``strain``
  and ``stress`` (tensors), ``von_mises``, and for DDCM ``data_stress`` (the assigned datum) and
  ``ddcm_distance`` (the distance ``sqrt(d^2)`` of the state to it). On P2 an element holds several
  material points, each with its own datum, and their mean is no datum: the cell data are then
  ``strain_element_mean``, ``stress_element_mean``, ``von_mises_element_mean`` (means over the
  element's points, for a look at the body), with no data fields;
- the material points, ``<variant>_<formulation>_points.pvd``
  (:mod:`ddcm_casadi.outputs.point_cloud`): every quadrature point at its position with its state,
  and for DDCM its datum (data set, row, strain, stress), its distance to it and the data-range flag.

Figures: the contact pressure of every run at the last step against Hertz (when the model has a
Hertz reference) and the deformed body coloured by the von Mises stress (the contact history is
:func:`ddcm_casadi.outputs.plots.figure_contact_history`).

Plane strain (2-D): the out-of-plane stress ``sigma_zz`` is no part of the 2-D Mandel state. For a
classical run it is ``nu (sigma_11 + sigma_22)`` (``e_zz = 0`` with the isotropic law), written in
the ``stress`` tensor and used in ``von_mises``. A DDCM run has no law, and its 2-D data carry only
the three in-plane components, so its ``sigma_zz`` is unknown: NaN in the ``stress`` and
``data_stress`` tensors and in ``von_mises``; the VTU adds ``von_mises_in_plane`` (``sigma_zz =
0``, plane-stress formula), and the DDCM figure is coloured by it and says so.

The output layer of :class:`~ddcm_casadi.models.continuum.model.ContinuumModel`: the writer and the
drawings are registered (:mod:`ddcm_casadi.outputs.drawings`) under the names the model declares
(``vtu``; ``pressure_profile``, ``deformed_body``), and :mod:`ddcm_casadi.outputs.save` calls them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ddcm_casadi.data.extrapolation import DataCoverage
from ddcm_casadi.outputs.drawings import register_drawing, register_field_writer
from ddcm_casadi.outputs.continuum import figure_deformed_body, figure_pressure_profile, von_mises, write_vtu_series
from ddcm_casadi.outputs.point_cloud import point_fields, sigma_zz, write_point_cloud

#: The cell fields of the mesh file on elements of one material point (P1), as the points have them.
CELL_FIELDS = ("strain", "stress", "von_mises", "von_mises_in_plane", "data_stress", "ddcm_distance")
#: On elements of several material points (P2): the means of these over each element's points, ...
MEAN_FIELDS = ("strain", "stress", "von_mises", "von_mises_in_plane")
#: ... named with this suffix: means, not data.
ELEMENT_MEAN = "_element_mean"


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


def _contact_fields(model, step) -> dict[str, np.ndarray]:
    """Pressure (summed), gap (smallest) and a flag at every scalar dof of the mesh file; the pairs'
    dofs only (see the module for why the gap is NaN elsewhere)."""
    n = model.discretisation.scalar_basis.N
    pressure, gap, node = np.zeros(n), np.full(n, np.inf), np.zeros(n, dtype=np.uint8)
    dofs = np.asarray(model.contact_dofs, dtype=np.intp)
    np.add.at(pressure, dofs, np.asarray(step.p, dtype=float))
    np.minimum.at(gap, dofs, np.asarray(model.gap(step.u, step.step), dtype=float))
    node[dofs] = 1
    gap[node == 0] = np.nan
    return dict(contact_pressure=pressure, contact_gap=gap, contact_node=node)


def _step_data(model, step, points: dict[str, np.ndarray]) -> dict:
    """The mesh file's data of one step, the cell data from the step's material-point fields
    ``points`` (:func:`~ddcm_casadi.outputs.point_cloud.point_fields`)."""
    if model.discretisation.points_per_element == 1:  # P1: each element is its one point, exactly
        cell = {key: points[key] for key in CELL_FIELDS if key in points}
    else:  # a mean of P2 data is no datum: means of the states only, named so
        cell = {key + ELEMENT_MEAN: _per_element(model, points[key]) for key in MEAN_FIELDS if key in points}
    point = dict(displacement=model.dof_displacement(step.u), **_contact_fields(model, step))
    return dict(time=float(step.load_parameter), point_data=point, cell_data=cell)


@register_field_writer("vtu")
def write_vtu(cmp, out_dir) -> list[Path]:
    """Write the VTU series of every run of a continuum comparison into ``out_dir/vtu/``: the mesh's
    and the material points' (:func:`~ddcm_casadi.outputs.point_cloud.write_point_cloud`).

    Parameters
    ----------
    cmp : Comparison
        The results of :func:`~ddcm_casadi.drivers.harness.compare` on a continuum.
    out_dir : str or Path
        The output folder.

    Returns
    -------
    list of Path
        Per run: the mesh's ``.vtu`` files (one per step) and ``.pvd`` series, then the points'.
    """
    model = cmp.model
    vtu = Path(out_dir) / "vtu"
    vtu.mkdir(parents=True, exist_ok=True)
    points, cells = model.discretisation.dof_locations(), _cells(model)
    written: list[Path] = []
    coverage = None
    for (variant, name), run in cmp.results.items():
        if variant == "ddcm" and coverage is None and model.dataset is not None:
            coverage = DataCoverage(model.dataset, model.n_points)  # once for every DDCM run
        fields = [point_fields(model, variant, s, coverage if variant == "ddcm" else None) for s in run.steps]
        steps = [_step_data(model, s, f) for s, f in zip(run.steps, fields)]
        written += write_vtu_series(vtu, points=points, cells=cells, steps=steps, name=f"{variant}_{name}")
        written += write_point_cloud(model, run, vtu, stem=f"{variant}_{name}", fields=fields)
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
