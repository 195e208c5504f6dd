"""The material points of a continuum run, one by one: a VTU point cloud per load step.

A continuum's material points are its quadrature points (one per P1 element, three per P2
triangle, four per P2 tetrahedron; :mod:`ddcm_casadi.models.continuum.fem`). DDCM assigns a datum to
each of them, so an element's mean of its points' data is no datum at all; this module writes
the points themselves, at their physical (reference) positions, as VTU vertex cells, one file per
step and a ``.pvd`` series per run (``vtu/<variant>_<formulation>_points.pvd``), which ParaView
opens beside the mesh series (representation *Point Gaussian* or *Points*).

Point data of every run (:func:`point_fields`):

- ``strain``, ``stress``: the 3 x 3 tensors (9 components, as ParaView reads tensors), and
  ``strain_mandel``, ``stress_mandel``: the Mandel components the solver works with (2-D
  ``[e11, e22, sqrt(2) e12]``, 3-D ``[e11, e22, e33, sqrt(2) e23, sqrt(2) e13, sqrt(2) e12]``);
- ``von_mises`` (and, for DDCM in 2-D, ``von_mises_in_plane``; the plane-strain ``sigma_zz`` is
  :func:`sigma_zz`'s);
- ``region`` (the index of the point's material, the order of ``model.region_names``),
  ``element`` and ``volume`` (the quadrature weight: the volume, or area per unit thickness,
  the point stands for).

And of a DDCM run:

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

In 2-D the data carry no ``sigma_zz``: the ``zz`` component of a DDCM run's stress tensors (state
and datum) is NaN, as in the mesh series. Files are written atomically
(:func:`~ddcm_casadi.outputs.continuum.write_vtu_series`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ddcm_casadi.data.extrapolation import DataCoverage
from ddcm_casadi.outputs.continuum import mandel_to_tensor, plane_strain_sigma_zz, von_mises, write_vtu_series

if TYPE_CHECKING:
    from ddcm_casadi.drivers.records import PathResult, StepResult
    from ddcm_casadi.models.continuum.model import ContinuumModel

#: The file stem of a run's point cloud: ``<variant>_<formulation>`` and this suffix.
POINTS_SUFFIX = "_points"


def sigma_zz(model: ContinuumModel, variant: str, stress: np.ndarray) -> np.ndarray | None:
    """The plane-strain ``sigma_zz`` per material point of a 2-D run.

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
        The step (``strain``, ``stress``; for DDCM ``data_index``, ``strain_star``, ``stress_star``).
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
    zz = sigma_zz(model, variant, stress)
    out = dict(strain=_tensors(strain, d), stress=_tensors(stress, d, zz), strain_mandel=strain,
               stress_mandel=stress, von_mises=von_mises(stress, d, zz))
    if zz is not None and np.isnan(zz).any():
        out["von_mises_in_plane"] = von_mises(stress, d)
    out.update(region=np.asarray(model.point_region, dtype=np.int64),
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
    unknown_zz = None if zz is None else np.full(index.size, np.nan)
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
