"""Independent checks of DDCM results: is every step a true fixed point of the alternating scheme?

A step is a fixed point when (i) its ``(u, p)`` is the exact projection onto ``Z_E`` of the assigned
data points (checked against :class:`~ddcm_casadi.problems.exact.ExactEnumerator`, which shares no code with
the formulations), and (ii) each assigned data point is the nearest datum to the step's
``(strain, stress)`` under the metric (checked by brute force, not by the KD-tree).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ddcm_casadi.problems.exact import ExactEnumerator
from ddcm_casadi.problems.build import ProblemPair
from ddcm_casadi.drivers.path import PathResult


@dataclass
class FixedPointReport:
    """Per-step errors: ``projection`` (relative to the path's scale) and ``nearest`` (bool)."""

    projection_error_u: np.ndarray
    projection_error_p: np.ndarray
    nearest: np.ndarray


def nearest_by_brute_force(data, step) -> bool:
    """Is each assigned datum the nearest one of its material's set (no KD-tree involved)?

    Every datum's distance is computed with the point's :class:`~ddcm_casadi.data.metric.Metric`.
    """
    n_points = len(step.data_index)
    metrics, material = data.point_materials(n_points)
    sets, offsets = data.datasets, data.offsets
    k = metrics[0].k
    strain = np.asarray(step.strain, float).reshape(n_points, k)
    stress = np.asarray(step.stress, float).reshape(n_points, k)
    ok = True
    for i, j in enumerate(step.data_index):
        d = sets[material[i]]
        jj = j - offsets[material[i]]
        if not 0 <= jj < len(d):
            return False  # assigned a datum of another material
        e_all = d.strain.reshape(len(d), k)
        s_all = d.stress.reshape(len(d), k)
        d2 = metrics[material[i]].distance2(strain[i] - e_all, stress[i] - s_all)
        ok &= bool(d2[jj] <= d2.min() * (1 + 1e-12) + 1e-300)
    return ok


def check_fixed_points(problems: ProblemPair, result: PathResult, *,
                       exact: ExactEnumerator | None = None) -> FixedPointReport:
    """Check every step of a DDCM path; ``exact`` may be passed to reuse its factorisations."""
    model = problems.model
    exact = exact or ExactEnumerator(problems.projection)
    s = problems.scales("mpcc")
    params = np.column_stack([problems.projection_params(st.step, st.strain_star, st.stress_star)
                              for st in result.steps])
    ex = exact.solve(params)  # every step in one call
    err_u, err_p = [], []
    for i, step in enumerate(result.steps):
        f = problems.fields("mpcc", ex.x[:, i], ex.p[:, i], params[:, i])
        err_u.append(float(np.max(np.abs(step.u - f["u"]), initial=0.0)) / s["displacement"])
        err_p.append(float(np.max(np.abs(step.p - f["p"]), initial=0.0)) / s["stress"])
    nearest = [nearest_by_brute_force(model.dataset, step) for step in result.steps]
    return FixedPointReport(np.array(err_u), np.array(err_p), np.array(nearest))
