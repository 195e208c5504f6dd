"""Outputs of a continuum comparison: VTU series for ParaView and the figures.

For every run (variant x formulation) two series in ``vtu/``, one VTU file per step each:

- the mesh, ``<variant>_<formulation>.pvd``, at its reference positions: point data
  ``displacement`` (at every node, P2 midpoints included; ParaView's *Warp By Vector* with scale 1
  shows the deformed configuration), and on the contact nodes ``contact_pressure`` (the solvers'
  nodal pressure; zero elsewhere: no contact traction acts there), ``contact_pressure_recovered``
  (the pressure recovered from the boundary elements' stresses,
  :func:`~ddcm_casadi.models.continuum.pressure.pressure_field`), ``contact_gap`` (NaN elsewhere: a gap has no meaning off the
  contact surfaces, and a zero would read as touching; ParaView leaves NaN out of the colour range
  and draws it in its NaN colour) and ``contact_node`` (1 on a contact node, for *Threshold*); a node
  with pairs to several obstacles shows their summed pressure and its smallest gap. Cell data
  where one value per element is the truth, i.e. P1 (one material point per element): ``strain``
  and ``stress`` (tensors), ``von_mises``, and for DDCM ``data_stress`` (the assigned datum) and
  ``ddcm_distance`` (the distance ``sqrt(d^2)`` of the state to it). On P2 an element holds several
  material points, each with its own datum, and their mean is no datum: the cell data are then
  ``strain_element_mean``, ``stress_element_mean``, ``von_mises_element_mean`` (means over the
  element's points, for a look at the body), with no data fields;
- the material points, ``<variant>_<formulation>_points.pvd``
  (:mod:`ddcm_casadi.outputs.point_cloud`): every quadrature point at its position with its
  displacement and state, and for DDCM its datum (data set, row, strain, stress), its distance to it
  and the data-range flag.

At finite strain (``kinematics = "finite"``) the names say which measure is which
(:func:`~ddcm_casadi.outputs.point_cloud.finite_state`): the P1 cell data are
``green_lagrange_strain`` (``E``), ``second_piola_kirchhoff_stress`` (``S``), ``cauchy_stress``
(``sigma = F S F^T / J``), ``deformation_gradient`` (``F``), ``J`` (``det F``),
``von_mises_cauchy`` (and ``von_mises_cauchy_in_plane`` for DDCM in 2-D), with the DDCM
``data_stress`` (the datum's ``S``) and ``ddcm_distance``; on P2 the element means of the states
(``*_element_mean``). The contact pressure is written twice, ``contact_pressure_nominal`` (the
solver's ``p``, force per reference area) and ``contact_pressure_true`` (force per current area,
:meth:`~ddcm_casadi.models.continuum.model.ContinuumModel.true_pressure`), instead of
``contact_pressure``; ``contact_gap`` is the exact gap at the current configuration.

Figures: the contact pressure of every run at the last step against Hertz (when the model has a
Hertz reference; at finite strain the true pressure along the deformed surface), the deformed body
coloured by the von Mises stress (at finite strain of the Cauchy stress, drawn unmagnified), the
total contact force along each moving obstacle's direction of travel against its travel
(``force_indentation``, :func:`obstacle_forces`) and the contact history
(:func:`ddcm_casadi.outputs.plots.figure_contact_history`).

Plane strain (2-D): the out-of-plane stress ``sigma_zz`` is no part of the 2-D Mandel state. For a
classical run it is ``nu (sigma_11 + sigma_22)`` (``e_zz = 0`` with the isotropic law; at finite
strain ``S_33`` of the hyperelastic law,
:func:`~ddcm_casadi.outputs.point_cloud.out_of_plane_stress`), written in the stress tensors and
used in the von Mises stress. A DDCM run has no law, and its 2-D data carry only the three in-plane
components, so its ``sigma_zz`` is unknown: NaN in the stress tensors and in the von Mises stress;
the VTU adds ``von_mises_in_plane`` (``sigma_zz = 0``, plane-stress formula;
``von_mises_cauchy_in_plane`` at finite strain), and the DDCM figure is coloured by it and says so.

The output layer of :class:`~ddcm_casadi.models.continuum.model.ContinuumModel`: the writer and the
drawings are registered (:mod:`ddcm_casadi.outputs.drawings`) under the names the model declares
(``vtu``; ``pressure_profile``, ``deformed_body``, ``force_indentation``), and
:mod:`ddcm_casadi.outputs.save` calls them.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ddcm_casadi.data.extrapolation import DataCoverage
from ddcm_casadi.outputs.drawings import register_drawing, register_field_writer
from ddcm_casadi.outputs.continuum import figure_deformed_body, figure_pressure_profile, von_mises, write_vtu_series
from ddcm_casadi.outputs.marks import (
    BEYOND, BEYOND_LABEL, FAILED, FAILED_LABEL, LOCAL, LOCAL_LABEL, MARKERS, STYLES, mark_steps, run_title,
)
from ddcm_casadi.models.continuum.pressure import measured_pressure, pressure_field, surface_forces
from ddcm_casadi.outputs.point_cloud import finite_state, point_fields, sigma_zz, write_point_cloud

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ddcm_casadi.drivers.harness import Comparison
    from ddcm_casadi.models.continuum.model import ContinuumModel

#: The cell fields of the mesh file on elements of one material point (P1), as the points have them.
CELL_FIELDS = ("strain", "stress", "von_mises", "von_mises_in_plane", "data_stress", "ddcm_distance")
#: On elements of several material points (P2): the means of these over each element's points, ...
MEAN_FIELDS = ("strain", "stress", "von_mises", "von_mises_in_plane")
#: The P1 cell fields at finite strain (:func:`~ddcm_casadi.outputs.point_cloud.finite_state`).
FINITE_CELL_FIELDS = ("green_lagrange_strain", "second_piola_kirchhoff_stress", "cauchy_stress",
                      "deformation_gradient", "J", "von_mises_cauchy", "von_mises_cauchy_in_plane",
                      "data_stress", "ddcm_distance")
#: The P2 element means at finite strain.
FINITE_MEAN_FIELDS = ("green_lagrange_strain", "second_piola_kirchhoff_stress", "cauchy_stress", "J",
                      "von_mises_cauchy", "von_mises_cauchy_in_plane")
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


def _contact_fields(model: ContinuumModel, step) -> dict[str, np.ndarray]:
    """Pressure (summed), gap (smallest) and a flag at every scalar dof of the mesh file; the pairs'
    dofs only (see the module for why the gap is NaN elsewhere). At small kinematics the nodal
    pressure and the recovered one (:func:`~ddcm_casadi.models.continuum.pressure.pressure_field`),
    at finite strain the pressure nominal and true."""
    n = model.discretisation.scalar_basis.N
    gap, node = np.full(n, np.inf), np.zeros(n, dtype=np.uint8)
    dofs = np.asarray(model.contact_dofs, dtype=np.intp)
    p = np.asarray(step.p, dtype=float)
    pressures = {"contact_pressure_nominal": p, "contact_pressure_true": model.true_pressure(step.u, p)} \
        if model.finite else {"contact_pressure": p,
                              "contact_pressure_recovered": pressure_field(model, p, np.asarray(step.stress, float))}
    out = {}
    for name, values in pressures.items():
        out[name] = np.zeros(n)
        np.add.at(out[name], dofs, values)
    np.minimum.at(gap, dofs, np.asarray(model.gap(step.u, step.step), dtype=float))
    node[dofs] = 1
    gap[node == 0] = np.nan
    if model.frictional and step.traction is not None:  # friction force per area and slip as vectors
        d = model.dimension
        force = model.tangential_force_vectors(step.traction) / model.contact_area[:, None]
        slip = model.tangential_force_vectors(step.slip) / model.contact_area[:, None]
        status = np.full(n, -1, dtype=np.int8)
        status[dofs] = model.contact_status(p, step.traction, step.slip)[0]
        for name, values in (("tangential_traction", force), ("slip", slip)):
            out[name] = np.zeros((n, d))
            np.add.at(out[name], dofs, values)
        out["contact_status"] = status
    return dict(out, contact_gap=gap, contact_node=node)


def _step_data(model: ContinuumModel, step, points: dict[str, np.ndarray]) -> dict:
    """The mesh file's data of one step, the cell data from the step's material-point fields
    ``points`` (:func:`~ddcm_casadi.outputs.point_cloud.point_fields`)."""
    fields, means = (FINITE_CELL_FIELDS, FINITE_MEAN_FIELDS) if model.finite else (CELL_FIELDS, MEAN_FIELDS)
    if model.discretisation.points_per_element == 1:  # P1: each element is its one point, exactly
        cell = {key: points[key] for key in fields if key in points}
    else:  # a mean of P2 data is no datum: means of the states only, named so
        cell = {key + ELEMENT_MEAN: _per_element(model, points[key]) for key in means if key in points}
    point = dict(displacement=model.dof_displacement(step.u, step.step), **_contact_fields(model, step))
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


def _profile_coordinate(model: ContinuumModel) -> tuple[np.ndarray, np.ndarray]:
    """Pairs and a coordinate along the surface for the pressure figure."""
    if model.reference is not None:
        return model.reference.coordinates(model)
    pairs = np.arange(model.n_contacts)
    return pairs, model.contact_points[:, 0]


@register_drawing("pressure_profile")
def draw_pressure_profile(cmp: Comparison) -> Figure:
    """The contact pressure of every run at the last step along the surface, with Hertz's for the
    measured force when the model has a Hertz reference (``pressure_profile.png``). At finite
    strain (without a Hertz reference) the true pressure, per current area, at the contact nodes'
    current ``x``."""
    model = cmp.model
    pairs, x = _profile_coordinate(model)
    # show the contact zone: 1.5 x the farthest pair in contact in any run's last step
    active = np.zeros(pairs.size, dtype=bool)
    for r in cmp.results.values():
        active |= model.active_contacts(np.asarray(r.steps[-1].p)[pairs])
    if active.any():
        keep = np.abs(x) <= 1.5 * float(np.max(np.abs(x[active])))
        pairs, x = pairs[keep], x[keep]
    current = model.finite and model.reference is None
    runs, hertz = [], None
    styles = {"classical": dict(ls="-", marker=None), "ddcm": dict(ls="none", marker="o", ms=3)}
    for (variant, name), r in cmp.results.items():
        last = r.steps[-1]
        p, xr = np.asarray(last.p, dtype=float), x
        if not model.finite:  # the pressure the measures use (recovered on linear tetrahedra)
            p = measured_pressure(model, p, np.asarray(last.stress, float))
        if current:
            p = model.true_pressure(last.u, p)
            xr = x + model.dof_displacement(last.u, last.step)[model.contact_dofs[pairs], 0]
        runs.append(dict(label=f"{variant}/{name}", x=xr, pressure=p[pairs],
                         converged=bool(last.converged), style=styles[variant]))
        if hertz is None and model.reference is not None and variant == "classical" and last.converged:
            hertz = model.reference.curve(model, last.p, last.stress)
    xlabel = ("distance from the indenter's axis (m)" if model.reference is not None
              else "current x (m)" if current else "x (m)")
    what = "true contact pressure (per current area)" if current else "contact pressure"
    return figure_pressure_profile(runs, hertz=hertz, xlabel=xlabel, ylabel=f"{what} (MPa)",
                                   title=f"{model.name}: {what}, last step")


@register_drawing("traction_profile")
def draw_traction_profile(cmp: Comparison) -> Figure:
    """The tangential traction of every run at the last step along the surface, against the
    Coulomb bounds ``+-mu p`` (``traction_profile.png``; 2-D: the signed traction along the
    tangent, 3-D: its magnitude)."""
    from matplotlib.figure import Figure as MplFigure

    model = cmp.model
    pairs, x = _profile_coordinate(model)
    order = np.argsort(x)
    pairs, x = pairs[order], x[order]
    fig = MplFigure(figsize=(7, 4.2))
    ax = fig.add_subplot()
    styles = {"classical": dict(ls="-"), "ddcm": dict(ls="none", marker="o", ms=3)}
    bound_drawn = False
    for (variant, name), r in cmp.results.items():
        last = r.steps[-1]
        t = np.asarray(last.traction, float).reshape(model.dimension - 1, model.n_contacts)
        value = t[0] if model.dimension == 2 else np.linalg.norm(t, axis=0)
        ax.plot(x, value[pairs] / 1e6, label=f"{variant}/{name}" + ("" if last.converged else " (not converged)"),
                **styles[variant])
        if variant == "classical" and last.converged and not bound_drawn:
            bound_drawn = True
            bound = model.friction[pairs] * np.asarray(last.p, float)[pairs] / 1e6
            ax.plot(x, bound, color="0.6", lw=0.8, ls="--", label=f"+-mu p (classical/{name})")
            if model.dimension == 2:
                ax.plot(x, -bound, color="0.6", lw=0.8, ls="--")
    ax.set_xlabel("x (m)" if model.reference is None else "distance from the indenter's axis (m)")
    ax.set_ylabel("tangential traction (MPa)" if model.dimension == 2 else "|tangential traction| (MPa)")
    ax.set_title(f"{model.name}: friction traction, last step")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


@register_drawing("deformed_body")
def draw_deformed_body(cmp: Comparison, *, variant: str, formulation: str) -> Figure:
    """The deformed body of one run at the last step, coloured by the von Mises stress
    (``deformed_<variant>.png``); at finite strain of the Cauchy stress, and drawn at its true
    displacements (a magnified finite deformation would be no configuration of the body)."""
    from ddcm_casadi.models.continuum import fem  # scikit-fem only when a 3-D body is drawn (its import takes 0.4 s)

    model, key = cmp.model, (variant, formulation)
    last = cmp.results[key].steps[-1]
    d, k = model.dimension, model.strain_components
    strain = np.asarray(last.strain).reshape(-1, k)
    stress = np.asarray(last.stress).reshape(-1, k)
    if model.finite:
        state = finite_state(model, variant, last.u, strain, stress)
        vm, label = state["von_mises_cauchy"], "von Mises stress (Cauchy)"
        if "von_mises_cauchy_in_plane" in state:  # DDCM in 2-D: sigma_zz unknown
            vm = state["von_mises_cauchy_in_plane"]
            label = "in-plane von Mises stress (Cauchy)"  # sigma_zz unknown
    else:
        zz = sigma_zz(model, variant, stress)
        label = "von Mises stress"
        if zz is not None and np.isnan(zz).any():  # DDCM in 2-D: sigma_zz unknown
            zz, label = None, "in-plane von Mises stress"  # sigma_zz unknown
        vm = von_mises(stress, d, zz)
    vm = _per_element(model, vm)
    disc = model.discretisation
    nn = model.mesh.p.shape[1]  # vertices come first among the scalar dofs
    points = disc.dof_locations()[:nn]
    disp = model.dof_displacement(last.u, last.step)[:nn]
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
                                scale=1.0 if model.finite else None,
                                contact_points=cdofs if cdofs.size else None,
                                obstacles=[o for o in drawn if o is not None], title=title)


# --------------------------------------------------------------------------- force-indentation
def moving_obstacles(model: ContinuumModel) -> list[int]:
    """The obstacles that travel along the load path (and hold contact pairs)."""
    held = set(np.asarray(model.contact_obstacle, dtype=int).tolist()) if model.n_contacts else set()
    return [o for o, ob in enumerate(model.obstacles)
            if o in held and float(np.ptp(ob.travels(model.n_steps))) > 0]


def obstacle_forces(model: ContinuumModel, u: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The total contact force on the body from each obstacle, per step, as modelled: ``sum a_0 p n``
    over the obstacle's pairs, ``a_0 p`` the nodal force (reference area times nominal pressure,
    which is current area times true pressure) along ``n``, the obstacle's normal at the pair's
    current point (:meth:`~ddcm_casadi.models.continuum.model.ContinuumModel.current_normals`; the
    reference normals at small kinematics).

    Parameters
    ----------
    model : ContinuumModel
        The model.
    u : ndarray, shape (n_steps, n_dofs)
        Free displacements per step.
    p : ndarray, shape (n_steps, n_contacts)
        Nominal pressures per step.

    Returns
    -------
    vectors : ndarray, shape (n_steps, n_obstacles, d)
        The force vectors (N; N per unit thickness in 2-D), NaN at a step with non-finite fields.
    along_travel : ndarray, shape (n_steps, n_obstacles)
        Each resolved along its obstacle's direction of travel (positive: pushing the body the way
        the obstacle moves).
    """
    vectors = surface_forces(model, u, p)
    directions = np.stack([ob.offset(1.0) for ob in model.obstacles]) if model.obstacles else np.zeros((0, model.dimension))
    return vectors, np.einsum("kod,od->ko", vectors, directions)


@register_drawing("force_indentation")
def draw_force_indentation(cmp: Comparison) -> Figure:
    """The total contact force along each moving obstacle's direction of travel against its travel
    (:func:`obstacle_forces`), one curve per variant and formulation (classical lines, DDCM markers),
    flagged steps framed as :mod:`ddcm_casadi.outputs.marks` says (``force_indentation.png``)."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    model = cmp.model
    moving = moving_obstacles(model)
    fig = Figure(figsize=(7.0, 2.2 + 2.8 * max(len(moving), 1)), constrained_layout=True)
    axes = fig.subplots(max(len(moving), 1), 1, squeeze=False)[:, 0]
    unit = "N/m (per unit thickness)" if model.dimension == 2 else "N"
    forces = {}
    for key in cmp.results:
        f = cmp.fields(*key)
        forces[key] = (obstacle_forces(model, f["u"], f["contact_pressure"])[1], f["converged"].astype(bool))
    for ax, o in zip(axes, moving):
        ob = model.obstacles[o]
        s = ob.travels(model.n_steps)
        flags = [False, False, False]
        handles = []
        for (variant, name), r in cmp.results.items():
            along, conv = forces[(variant, name)]
            y = along[:, o]
            if variant == "classical":
                style = dict(ls=STYLES.get(name, "-"), color="C0", lw=1.4, marker=".", ms=4)
            else:
                style = dict(ls="none", color="C1", marker=MARKERS.get(name, "o"), ms=5, mfc="none")
            ax.plot(s, y, zorder=2 if variant == "classical" else 3, **style)
            marked = mark_steps(ax, s, y, r, conv, variant, failed_ms=13, failed_zorder=6)
            flags = [a or b for a, b in zip(flags, marked)]
            handles.append(Line2D([], [], label=f"{'classical' if variant == 'classical' else 'DDCM'}, "
                                                f"{run_title(cmp, name)}", **style))
        failed, local, beyond = flags
        if local:
            handles.append(Line2D([], [], ls="none", ms=9, label=LOCAL_LABEL, **LOCAL))
        if beyond:
            handles.append(Line2D([], [], **{**BEYOND, "ms": 10}, label=BEYOND_LABEL))
        if failed:
            handles.append(Line2D([], [], ls="none", ms=10, label=FAILED_LABEL, **FAILED))
        ax.set_xlabel(f"travel of obstacle {ob.name!r} (m)")
        ax.set_ylabel(f"contact force along its travel ({unit})", fontsize=8)
        ax.grid(True, alpha=0.3)
        ax.legend(handles=handles, fontsize=7, ncol=2, loc="best")
        ax.set_title(f"{model.name}: force against indentation, {ob.name!r}"
                     + (" (finite strain; current normals)" if model.finite else ""), fontsize=10)
    if not moving:
        axes[0].text(0.5, 0.5, "no obstacle moves", ha="center", va="center", transform=axes[0].transAxes)
    return fig
