r"""Noise-robust data-driven schemes: local convexity data-driven (LCDD).

LCDD (Q. He and J.-S. Chen, "A physics-constrained data-driven approach based on locally convex
reconstruction for noisy database", CMAME 363 (2020) 112791) replaces the projection onto the
data by the projection onto the convex hull of the ``k`` data nearest to the state:

.. math::  z^*_i = \arg\min_{y \in \operatorname{conv} N_k(z_i)} d(z_i, y)^2 ,
           \qquad z \leftarrow P_{Z_E}(z^*) ,

``N_k(z_i)`` the ``k`` nearest data of point ``i`` under the metric. The reconstructed material
state averages the noise of its neighbours instead of jumping between noisy data, so on noisy
data the solution is closer to the underlying law (He & Chen report about an order of magnitude).
In the metric's scaled coordinates (:meth:`~ddcm_casadi.metric.Metric.coordinates`, where the
metric distance is Euclidean) the projection onto the hull of ``k`` points in the
``(strain, stress)`` plane is exact and vectorised over points: the state itself if it lies in
one of the triangles of three neighbours, else the nearest point of the segments between two
neighbours (every edge of the hull is one of them). One-component points only (bars, trusses).

The iteration stops when the reconstructed states move less than ``1e-7`` of the data's spread
(alternating projections between convex sets converge, but only in the limit: a step that does
not settle within ``max_outer`` iterations is reported as not converged).
"""

from __future__ import annotations

import itertools
import time

import numpy as np


#: Relative change of the reconstructed states below which LCDD has converged.
LCDD_TOL = 1e-7


def hull_projection(q: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """The nearest point to each ``q[i]`` (2,) in the convex hull of ``Y[i]`` (K, 2), Euclidean;
    ``q``: (m, 2), ``Y``: (m, K, 2)."""
    m, K, _ = Y.shape
    best = Y[:, 0].copy()
    best_d = np.sum((best - q) ** 2, axis=1)
    for a, b in itertools.combinations(range(K), 2):
        ab = Y[:, b] - Y[:, a]
        L = np.sum(ab * ab, axis=1)
        t = np.where(L > 0, np.sum((q - Y[:, a]) * ab, axis=1) / np.where(L > 0, L, 1.0), 0.0).clip(0.0, 1.0)
        y = Y[:, a] + t[:, None] * ab
        d = np.sum((y - q) ** 2, axis=1)
        better = d < best_d
        best[better], best_d[better] = y[better], d[better]
    inside = np.zeros(m, dtype=bool)
    for a, b, c in itertools.combinations(range(K), 3):
        v0, v1, v2 = Y[:, b] - Y[:, a], Y[:, c] - Y[:, a], q - Y[:, a]
        det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
        ok = np.abs(det) > 0
        safe = np.where(ok, det, 1.0)
        s = (v2[:, 0] * v1[:, 1] - v2[:, 1] * v1[:, 0]) / safe
        t = (v0[:, 0] * v2[:, 1] - v0[:, 1] * v2[:, 0]) / safe
        inside |= ok & (s >= 0) & (t >= 0) & (s + t <= 1)
    best[inside] = q[inside]
    return best


def _lcdd_star(model, strain, stress, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The LCDD material states of every point: the projection onto the hull of its k nearest data."""
    data = model.dataset
    rc = np.sqrt(model.metric)  # per point: coordinates (sqrt(c) e, s / sqrt(c))
    near = data.k_nearest(strain, stress, k)
    q = np.column_stack([rc * strain, stress / rc])
    Y = np.stack([rc[:, None] * data.strain[near], data.stress[near] / rc[:, None]], axis=-1)
    y = hull_projection(q, Y)
    return y[:, 0] / rc, y[:, 1] * rc


def solve_noise_robust(solver, *, formulation_name: str = "", raise_on_failure: bool = False, progress=None):
    """The LCDD scheme along the load path with the driver's projection onto ``Z_E``
    (:meth:`DDCMSolver.project_data`) and starts (:class:`DDCMOptions` ``start``, ``initial``, ``warm``)."""
    from .path import PathResult, StepResult, _check_convergence

    problems, model, opts = solver.problems, solver.problems.model, solver.options
    data = model.dataset
    out = PathResult("ddcm", formulation_name)
    x, p, state = np.zeros(problems.projection.n_x), np.zeros(problems.projection.n_pairs), None
    spread = max(float(np.ptp(np.sqrt(model.metric).max() * data.strain)),
                 float(np.ptp(data.stress / np.sqrt(model.metric).min())))
    rc = np.sqrt(model.metric)
    star_e = star_s = None
    t_all = time.perf_counter()
    for k in range(model.n_steps):
        t0 = time.perf_counter()
        if star_e is None or not opts.warm:
            index = solver.initial_assignment(k)
            star_e, star_s = data.strain[index].copy(), data.stress[index].copy()
        cost = dict(inner=0, t_project=0.0)
        converged, message = False, "maximum outer iterations reached"
        for outer in range(1, solver.max_outer + 1):
            sol, is_global, err, failed = solver.project_data(k, star_e, star_s, (x, p, state), cost)
            if failed:
                message = failed
                break
            x, p, state = sol.x, sol.p, sol.state
            f = problems.fields("mpcc", sol.x, sol.p)
            new_e, new_s = _lcdd_star(model, f["strain"], f["stress"], opts.lcdd_neighbours)
            change = float(np.max(np.hypot(rc * (new_e - star_e), (new_s - star_s) / rc)))
            star_e, star_s = new_e, new_s
            if change <= LCDD_TOL * spread:
                converged, message = True, "fixed point (LCDD)"
                break
        f = problems.fields("mpcc", sol.x, sol.p)
        index = data.nearest(star_e, star_s)
        metrics, material = data.point_materials(model.n_points)
        d2 = np.empty(model.n_points)
        for j, mt in enumerate(metrics):
            pts = material == j
            d2[pts] = mt.distance2(f["strain"][pts] - star_e[pts], f["stress"][pts] - star_s[pts])
        step = StepResult(step=k, load_parameter=float(model.load_parameter[k]), u=f["u"], p=f["p"],
                          converged=converged, iterations=cost["inner"], outer_iterations=outer, residual=sol.residual,
                          complementarity=sol.complementarity, penetration=sol.penetration, seconds=0.0,
                          message=message, strain=f["strain"], stress=f["stress"], strain_star=star_e.copy(),
                          stress_star=star_s.copy(), data_index=index, distance=float(0.5 * np.dot(model.volumes, d2)),
                          projection_error=err, projection_global=is_global, projection_seconds=cost["t_project"],
                          projections=outer, runs=1)
        step.seconds = time.perf_counter() - t0
        out.steps.append(step)
        if progress is not None:
            progress(step)
        _check_convergence(step, raise_on_failure, f"ddcm/{formulation_name}")
    out.solve_seconds = time.perf_counter() - t_all
    return out
