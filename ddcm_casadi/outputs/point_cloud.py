"""The material points of a continuum run, one by one: a VTU point cloud per load step.

A continuum's material points are its quadrature points (one per P1 element, three per P2
triangle, four per P2 tetrahedron; :mod:`ddcm_casadi.models.continuum.fem`). DDCM assigns a datum to
each of them, so an element's mean of its points' data is no datum at all; this module writes
the points themselves, at their physical (reference) positions, as VTU vertex cells, one file per
step and a ``.pvd`` series per run (``vtu/<variant>_<formulation>_points.pvd``), which ParaView
opens beside the mesh series (representation *Point Gaussian* or *Points*).

Point data of every run (:func:`point_fields`):

- ``displacement``: the displacement at the point (interpolated), for *Warp By Vector* onto the
  deformed configuration, as the mesh series;
- ``region`` (the index of the point's material, the order of ``model.region_names``),
  ``element`` and ``volume`` (the quadrature weight: the volume, or area per unit thickness,
  the point stands for in the reference configuration).

The state, small kinematics:

- ``strain``, ``stress``: the 3 x 3 tensors (9 components, as ParaView reads tensors), and
  ``strain_mandel``, ``stress_mandel``: the Mandel components the solver works with (2-D
  ``[e11, e22, sqrt(2) e12]``, 3-D ``[e11, e22, e33, sqrt(2) e23, sqrt(2) e13, sqrt(2) e12]``);
- ``von_mises`` (and, for DDCM in 2-D, ``von_mises_in_plane``; the plane-strain ``sigma_zz`` is
  :func:`sigma_zz`'s).

The state, finite kinematics (total Lagrangian, :mod:`ddcm_casadi.models.continuum.finite`; the
names say which measure is which, :func:`finite_state`):

- ``green_lagrange_strain`` (``E``), ``second_piola_kirchhoff_stress`` (``S``, the solver's stress)
  as tensors, and their Mandel components ``green_lagrange_strain_mandel``,
  ``second_piola_kirchhoff_stress_mandel``;
- ``deformation_gradient`` (``F = I + du/dX``, 3 x 3; plane strain ``F_33 = 1``), ``J``
  (``det F``, the ratio of current to reference volume);
- ``cauchy_stress`` (``sigma = F S F^T / J``, the true stress, a tensor) and ``von_mises_cauchy``
  (its von Mises stress; for DDCM in 2-D also ``von_mises_cauchy_in_plane``).

In plane strain the 2-D Mandel vectors carry no ``zz`` components: ``E_33 = 0``, and ``S_33`` of a
classical run is its law's (:func:`out_of_plane_stress`: ``nu (sigma_11 + sigma_22)`` for the
linear law, ``dW/dE_33`` at ``E_33 = 0`` for a hyperelastic one, so ``sigma_33 = S_33 / J``). A DDCM
run has no law and 2-D data carry no ``zz`` stress: it is NaN in the stress tensors (state and
datum), as in the mesh series, and so are the von Mises stresses but the ``*_in_plane`` ones
(``zz`` stress 0, the plane-stress formula).

And of a DDCM run (the same names at either kinematics; at finite strain data are ``(E, S)`` pairs):

- ``data_set``, ``data_index``: the assigned datum as a row of one data set
  (``model.dataset.datasets[data_set]``; the global index of the driver's records is
  ``data_index + model.dataset.offsets[data_set]``);
- ``data_strain``, ``data_stress`` (tensors) and ``data_strain_mandel``, ``data_stress_mandel``:
  that row, exactly;
- ``ddcm_distance``: the distance ``sqrt(d^2)`` of the point's state to that datum in its data
  set's metric (:meth:`~ddcm_casadi.data.metric.Metric.distance2`);
- ``beyond_data`` (1 where the state lies beyond the data's range) and ``data_spacings`` (its
  offset from its nearest datum along the data, in local spacings), from
  :meth:`~ddcm_casadi.data.extrapolation.DataCoverage.check`, the check that counts a step's
  ``extrapolated`` points;
- ``material_strain_mandel``, ``material_stress_mandel``: the material states ``z*`` the scheme
  ended at, only for schemes whose states are not data (LCDD, max-ent: ``data_*`` is then the
  datum nearest them).

Files are written atomically (:func:`~ddcm_casadi.outputs.continuum.write_vtu_series`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ddcm_casadi.data import hyperelastic
from ddcm_casadi.data.extrapolation import DataCoverage
from ddcm_casadi.outputs.continuum import mandel_to_tensor, plane_strain_sigma_zz, von_mises, write_vtu_series

if TYPE_CHECKING:
    from ddcm_casadi.drivers.records import PathResult, StepResult
    from ddcm_casadi.models.continuum.model import ContinuumModel

#: The file stem of a run's point cloud: ``<variant>_<formulation>`` and this suffix.
POINTS_SUFFIX = "_points"


def sigma_zz(model: ContinuumModel, variant: str, stress: np.ndarray) -> np.ndarray | None:
    """The plane-strain ``sigma_zz`` per material point of a 2-D run at small kinematics.

    Parameters
    ----------
    model : ContinuumModel
        The model (its dimension and Poisson's ratios).
    variant : str
        ``"classical"`` or ``"ddcm"``.
    stress : ndarray, shape (m, k)
        Mandel stresses per point.

    Returns
    -------
    ndarray, shape (m,), or None
        ``nu (sigma_11 + sigma_22)`` for a classical run, NaN (unknown: no law, and 2-D data
        carry no ``sigma_zz``) for a DDCM run; ``None`` in 3-D, where the Mandel vector carries it.
    """
    if model.dimension != 2:
        return None
    if variant == "classical" and model.poisson_ratio is not None:
        return plane_strain_sigma_zz(stress, model.poisson_ratio)
    return np.full(stress.shape[0], np.nan)


def out_of_plane_stress(model: ContinuumModel, variant: str, strain: np.ndarray,
                        stress: np.ndarray) -> np.ndarray | None:
    """The ``zz`` stress of a 2-D (plane-strain) run per material point, which its Mandel vectors
    do not carry: ``sigma_zz`` at small kinematics (:func:`sigma_zz`), ``S_33`` at finite strain.

    At finite strain ``S_33 = dW/dE_33`` at ``E_33 = E_23 = E_13 = 0`` of each region's law
    (:mod:`ddcm_casadi.data.hyperelastic`, evaluated in 3-D): ``lambda tr E`` for Saint
    Venant-Kirchhoff, ``lambda ln J`` for neo-Hookean.

    Parameters
    ----------
    model : ContinuumModel
        The model (dimension, kinematics, laws, moduli).
    variant : str
        ``"classical"`` or ``"ddcm"``.
    strain, stress : ndarray, shape (m, k)
        Mandel strains and stresses per point (``E`` and ``S`` at finite strain).

    Returns
    -------
    ndarray, shape (m,), or None
        The ``zz`` stress, NaN where unknown (DDCM: no law, and 2-D data carry none); ``None`` in 3-D.
    """
    if not model.finite:
        return sigma_zz(model, variant, stress)
    if model.dimension != 2:
        return None
    out = np.full(strain.shape[0], np.nan)
    if variant != "classical" or model.youngs_modulus is None or model.poisson_ratio is None:
        return out
    law_of_point = np.asarray(model.laws, dtype=object)[model.point_region]
    for law in sorted(set(model.laws)):
        points = np.flatnonzero(law_of_point == law)
        if points.size:
            e = strain[points]
            strain_3d = np.column_stack([e[:, 0], e[:, 1], np.zeros((points.size, 3)), e[:, 2]])  # E_33 = 0
            out[points] = hyperelastic.second_piola(law, strain_3d, model.youngs_modulus[points],
                                                    model.poisson_ratio[points], 3)[:, 2]
    return out


def tensor_von_mises(t: np.ndarray) -> np.ndarray:
    """Von Mises stress ``sqrt(3/2 s:s)`` of ``(n, 3, 3)`` stress tensors (NaN in, NaN out)."""
    dev = t - np.trace(t, axis1=1, axis2=2)[:, None, None] / 3.0 * np.eye(3)
    return np.sqrt(1.5 * np.einsum("nij,nij->n", dev, dev))


def finite_state(model: ContinuumModel, variant: str, u: np.ndarray, strain: np.ndarray,
                 stress: np.ndarray) -> dict[str, np.ndarray]:
    """The finite-strain state of every material point, named by measure (see the module).

    Parameters
    ----------
    model : ContinuumModel
        A model with finite kinematics.
    variant : str
        ``"classical"`` or ``"ddcm"`` (the plane-strain ``S_33``: :func:`out_of_plane_stress`).
    u : ndarray
        The free displacements of the step.
    strain, stress : ndarray, shape (m, k)
        Mandel ``E`` and ``S`` per point (the step's records).

    Returns
    -------
    dict
        ``green_lagrange_strain``, ``second_piola_kirchhoff_stress``, ``cauchy_stress``,
        ``deformation_gradient`` (``(m, 3, 3)``), their Mandel components, ``J`` and
        ``von_mises_cauchy`` (``(m,)``), and for DDCM in 2-D ``von_mises_cauchy_in_plane``.
    """
    d = model.dimension
    H = model.displacement_gradient(u)
    F = np.tile(np.eye(3), (H.shape[0], 1, 1))
    F[:, :d, :d] += H
    J = np.linalg.det(F)  # plane strain: F_33 = 1, so det F is the in-plane determinant
    zz = out_of_plane_stress(model, variant, strain, stress)
    S = mandel_to_tensor(stress, d, zz)
    sigma = hyperelastic.cauchy_stress(stress, F[:, :d, :d], d)
    if zz is not None:
        sigma[:, 2, 2] = zz / J  # F_33 S_33 F_33 / J; the helper leaves the unknown S_33 out
    out = dict(green_lagrange_strain=_tensors(strain, d), second_piola_kirchhoff_stress=S.reshape(-1, 9),
               cauchy_stress=sigma.reshape(-1, 9), deformation_gradient=F.reshape(-1, 9), J=J,
               green_lagrange_strain_mandel=strain, second_piola_kirchhoff_stress_mandel=stress,
               von_mises_cauchy=tensor_von_mises(sigma))
    if zz is not None and np.isnan(zz).any():
        in_plane = sigma.copy()
        in_plane[:, 2, 2] = 0.0
        out["von_mises_cauchy_in_plane"] = tensor_von_mises(in_plane)
    return out


def point_displacement(model: ContinuumModel, u: np.ndarray, step: int | None = None) -> np.ndarray:
    """``(m, d)`` the displacement at every material point (element-major, as the points);
    ``step``: the load step of ``u`` (a hard device's prescribed values)."""
    disc = model.discretisation
    value = np.asarray(disc.basis.interpolate(model.full_displacement(u, step)))  # (d, elements, points per element)
    return value.reshape(disc.dimension, -1).T.copy()


def _tensors(values: np.ndarray, d: int, zz: np.ndarray | None = None) -> np.ndarray:
    return mandel_to_tensor(values, d, zz).reshape(-1, 9)


def point_fields(model: ContinuumModel, variant: str, step: StepResult,
                 coverage: DataCoverage | None = None) -> dict[str, np.ndarray]:
    """The point data of one step at every material point (see the module for the names).

    Parameters
    ----------
    model : ContinuumModel
        The model of the run.
    variant : str
        ``"classical"`` or ``"ddcm"``.
    step : StepResult
        The step (``u``, ``strain``, ``stress``; for DDCM ``data_index``, ``strain_star``, ``stress_star``).
    coverage : DataCoverage, optional
        The data's range (:class:`~ddcm_casadi.data.extrapolation.DataCoverage`), built once per
        model; without it a DDCM step gets no ``beyond_data`` and ``data_spacings``.

    Returns
    -------
    dict
        Name to array, one row per material point (element-major, as ``B``'s rows).
    """
    d, k = model.dimension, model.strain_components
    strain = np.asarray(step.strain, dtype=float).reshape(-1, k)
    stress = np.asarray(step.stress, dtype=float).reshape(-1, k)
    if model.finite:
        out = finite_state(model, variant, step.u, strain, stress)
    else:
        zz = sigma_zz(model, variant, stress)
        out = dict(strain=_tensors(strain, d), stress=_tensors(stress, d, zz), strain_mandel=strain,
                   stress_mandel=stress, von_mises=von_mises(stress, d, zz))
        if zz is not None and np.isnan(zz).any():
            out["von_mises_in_plane"] = von_mises(stress, d)
    out.update(displacement=point_displacement(model, step.u, step.step),
               region=np.asarray(model.point_region, dtype=np.int64),
               element=model.discretisation.element_of_point().astype(np.int64),
               volume=np.asarray(model.volumes, dtype=float))
    if step.data_index is None or model.dataset is None:
        return out
    data = model.dataset
    index = np.asarray(step.data_index, dtype=np.intp).reshape(-1)
    _, data_set = data.point_materials(model.n_points)
    local = index - np.asarray(data.offsets, dtype=np.intp)[data_set]
    datum_strain = np.empty((index.size, k))
    datum_stress = np.empty((index.size, k))
    for s, dataset in enumerate(data.datasets):  # each point's row of its own set, as stored
        pts = np.flatnonzero(data_set == s)
        datum_strain[pts] = np.asarray(dataset.strain).reshape(-1, k)[local[pts]]
        datum_stress[pts] = np.asarray(dataset.stress).reshape(-1, k)[local[pts]]
    unknown_zz = np.full(index.size, np.nan) if d == 2 else None  # 2-D data carry no zz stress
    out.update(data_set=np.asarray(data_set, dtype=np.int64), data_index=local.astype(np.int64),
               data_strain=_tensors(datum_strain, d), data_stress=_tensors(datum_stress, d, unknown_zz),
               data_strain_mandel=datum_strain, data_stress_mandel=datum_stress,
               ddcm_distance=np.sqrt(np.maximum(data.distance2(strain, stress, index), 0.0)))
    if coverage is not None:
        beyond, spacings = coverage.check(strain, stress)
        out.update(beyond_data=beyond, data_spacings=spacings)
    star_e, star_s = (None if a is None else np.asarray(a, dtype=float).reshape(-1, k)
                      for a in (step.strain_star, step.stress_star))
    if star_e is not None and not (np.array_equal(star_e, datum_strain) and np.array_equal(star_s, datum_stress)):
        # LCDD, max-ent: the scheme's states are not data; keep them beside their nearest datum
        out.update(material_strain_mandel=star_e, material_stress_mandel=star_s)
    return out


def write_point_cloud(model: ContinuumModel, run: PathResult, out_dir: str | Path, *, stem: str | None = None,
                      fields: Sequence[Mapping[str, np.ndarray]] | None = None,
                      coverage: DataCoverage | None = None) -> list[Path]:
    """Write one run's material points: a VTU file of vertex cells per step and a ``.pvd`` series.

    Parameters
    ----------
    model : ContinuumModel
        The model of the run.
    run : PathResult
        The run (``variant``, ``formulation``, ``steps``).
    out_dir : str or Path
        The folder (the mesh series' ``vtu/``).
    stem : str, optional
        The run's name, ``<variant>_<formulation>`` by default; the files add :data:`POINTS_SUFFIX`.
    fields : sequence of dict, optional
        The point data of every step if already computed (:func:`point_fields`).
    coverage : DataCoverage, optional
        Without ``fields``: the data's range for ``beyond_data`` (DDCM runs); built here if not given.

    Returns
    -------
    list of Path
        ``<stem>_points_0000.vtu``, ... and last ``<stem>_points.pvd``.
    """
    if fields is None:
        if coverage is None and run.variant == "ddcm" and model.dataset is not None:
            coverage = DataCoverage(model.dataset, model.n_points)
        fields = [point_fields(model, run.variant, s, coverage) for s in run.steps]
    x = model.discretisation.quadrature_points()
    vertices = np.arange(x.shape[0], dtype=np.int64)[:, None]
    steps = [dict(time=float(s.load_parameter), point_data=f) for s, f in zip(run.steps, fields, strict=True)]
    return write_vtu_series(out_dir, points=x, cells=[("vertex", vertices)], steps=steps,
                            name=f"{stem or f'{run.variant}_{run.formulation}'}{POINTS_SUFFIX}")
