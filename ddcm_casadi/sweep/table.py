"""The rows of ``sweep.csv``: one per case x variant x formulation, summary metrics only.

The metrics of a run (:func:`summary_rows`) come from :meth:`~ddcm_casadi.drivers.harness.Comparison.summary`
plus what a study plots:

- ``max_error_u``, ``max_error_p``: max over steps of ``|value - reference| / max |reference|``
  against the model's closed form (``*_vs_exact``: against the exact solution, for penalised runs);
- ``error_u_vs_classical``, ``error_p_vs_classical`` (DDCM): the same norm of the DDCM solution
  against the classical run of the same formulation in the same case (models without a closed form);
- ``distance_mean``, ``distance_max`` (DDCM): the objective, the distance to the data;
- ``local_minimum_steps`` (DDCM): how many steps stopped at a local, not the global, minimum;
- ``steps``, ``converged_steps``, iterations, residuals, ``data_points``, build and solve seconds;
- ``extrapolated_steps`` (DDCM): the steps with states beyond the material data (DATA RANGE
  EXCEEDED in the table of ``ddcm-compare``), ``max_extrapolated_states`` the most such states
  in one step; 0 for a run inside its data;
- ``hertz_force``, ``hertz_error_p0``, ``hertz_error_a``, ``hertz_error_l2`` (continuum cases
  with a ``[hertz]`` reference): the contact force and the errors against Hertz at the last step
  (the columns of ``results.csv``), so a mesh-refinement sweep can be plotted.

Wall times (``build_seconds``, ``solve_seconds``, ``case_seconds``) are measurements: they differ
between two runs of the same case, every other value is reproducible.
"""

from __future__ import annotations

import json
import math

import numpy as np

from ddcm_casadi.drivers.harness import _relative_error

METRICS = ("steps", "converged_steps", "max_error_u", "max_error_p", "max_error_u_vs_exact", "max_error_p_vs_exact",
           "error_u_vs_classical", "error_p_vs_classical", "distance_mean", "distance_max", "local_minimum_steps",
           "iterations_mean", "iterations_max", "outer_iterations_mean", "max_residual", "max_complementarity",
           "data_points", "extrapolated_steps", "max_extrapolated_states", "hertz_force", "hertz_error_p0", "hertz_error_a", "hertz_error_l2",
           "build_seconds", "solve_seconds")
#: The per-step columns of ``results.csv`` whose last step is a metric of ``sweep.csv``.
LAST_STEP = ("hertz_force", "hertz_error_p0", "hertz_error_a", "hertz_error_l2")
#: Columns that are wall-time measurements (not reproducible from run to run).
TIMINGS = ("build_seconds", "solve_seconds", "case_seconds")
_FROM_SUMMARY = ("steps", "converged_steps", "max_error_u", "max_error_p", "max_error_u_vs_exact",
                 "max_error_p_vs_exact", "iterations_mean", "iterations_max", "outer_iterations_mean",
                 "max_residual", "max_complementarity", "extrapolated_steps", "max_extrapolated_states",
                 "build_seconds", "solve_seconds")


def _finite_stat(values: np.ndarray, stat) -> float | None:
    values = np.asarray(values, float)
    values = values[np.isfinite(values)]
    return float(stat(values)) if values.size else None


def summary_rows(cmp, summary: list[dict], step_rows: list[dict] | None = None) -> list[dict]:
    """The metrics of every variant x formulation of a :class:`~ddcm_casadi.drivers.harness.Comparison`
    (``summary``: its :meth:`~ddcm_casadi.drivers.harness.Comparison.summary`, computed once;
    ``step_rows``: the rows of ``results.csv``, for the :data:`LAST_STEP` columns)."""
    dataset = cmp.model.dataset
    last: dict[tuple, dict] = {}
    for step in step_rows or []:
        last[(step.get("variant"), step.get("formulation"))] = step  # in step order: the last one stays
    rows = []
    for rec in summary:
        variant, name = rec["variant"], rec["formulation"]
        row = dict(variant=variant, formulation=name)
        row.update({k: rec.get(k) for k in _FROM_SUMMARY})
        final = last.get((variant, name), {})
        row.update({k: final[k] for k in LAST_STEP if k in final})
        if variant == "ddcm":
            r = cmp.results[(variant, name)]
            distance = r.array("distance")
            row.update(distance_mean=_finite_stat(distance, np.mean), distance_max=_finite_stat(distance, np.max),
                       local_minimum_steps=len(rec["local_minimum_steps"]))
            classical = cmp.results.get(("classical", name))
            if classical is not None:
                row["error_u_vs_classical"] = float(np.max(_relative_error(r.array("u"), classical.array("u"))))
                row["error_p_vs_classical"] = float(np.max(_relative_error(r.array("p"), classical.array("p"))))
        row["data_points"] = None if dataset is None else len(dataset)
        rows.append(row)
    return rows


def _cell(value):
    """A swept value as one CSV cell (tables and arrays as JSON)."""
    return json.dumps(value) if isinstance(value, (list, dict)) else value


def case_rows(record: dict, columns: list[str]) -> list[dict]:
    """The ``sweep.csv`` rows of one finished case (its ``case.json`` record).

    A failed case gives one row per requested variant x formulation (one row if the spec left
    them to the case) with ``status = "failed"`` and the message.
    """
    head = dict(case=record["id"], status=record["status"])
    head.update({c: _cell(record["params"].get(c)) for c in columns})
    out = []
    runs = record.get("rows") or [dict(variant=v, formulation=f)
                                  for v in (record.get("variants") or [None])
                                  for f in (record.get("formulations") or [None])]
    for run in runs:
        row = dict(head, variant=run.get("variant"), formulation=run.get("formulation"))
        row.update({m: run.get(m) for m in METRICS})
        row.update(case_seconds=record.get("seconds"), message=record.get("error") or "")
        out.append(row)
    return out


def numeric(value) -> float:
    """A cell as a float (``nan`` for empty or non-numeric cells)."""
    if isinstance(value, bool) or value is None:
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def series(rows: list[dict], x: str, y: str, columns: list[str]) -> dict[str, tuple[np.ndarray, list[np.ndarray]]]:
    """``y`` against ``x`` per variant, formulation and value of the other swept parameters (seeds
    pooled): ``{label: (x values sorted, [the y values at each x])}``, finite values of finished
    runs only."""
    others = [c for c in columns if c not in (x, "seed")]
    groups: dict[str, dict[float, list[float]]] = {}
    for row in rows:
        xv, yv = numeric(row.get(x)), numeric(row.get(y))
        if row.get("status") != "ok" or not (math.isfinite(xv) and math.isfinite(yv)):
            continue
        label = f"{row['variant']}/{row['formulation']}"
        label += "".join(f", {c}={row.get(c)}" for c in others)
        groups.setdefault(label, {}).setdefault(xv, []).append(yv)
    return {label: (np.array(sorted(g)), [np.array(g[k]) for k in sorted(g)]) for label, g in groups.items()}


def fit_loglog(x: np.ndarray, y: np.ndarray) -> tuple[float, float] | None:
    """Least-squares line ``log10 y = slope log10 x + intercept`` over the positive points
    (``None`` with fewer than two distinct positive ``x``)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    keep = (x > 0) & (y > 0) & np.isfinite(x) & np.isfinite(y)
    if np.unique(x[keep]).size < 2:
        return None
    slope, intercept = np.polyfit(np.log10(x[keep]), np.log10(y[keep]), 1)
    return float(slope), float(intercept)


def fits(rows: list[dict], figures, columns: list[str]) -> list[dict]:
    """The fitted log-log slopes of the ``rate`` figures: per series, of the median over seeds."""
    out = []
    for fig in figures:
        if fig.kind != "rate":
            continue
        for label, (xs, ys) in series(rows, fig.x, fig.y, columns).items():
            line = fit_loglog(xs, np.array([np.median(v) for v in ys]))
            if line is not None:
                out.append(dict(figure=fig.file, series=label, x=fig.x, y=fig.y, slope=line[0], intercept=line[1],
                                points=int(xs.size)))
    return out
