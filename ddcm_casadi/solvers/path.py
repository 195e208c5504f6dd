"""Drivers along a load path: classical steps, and DDCM alternating projections.

Both warm-start each step from the previous one. The DDCM driver alternates

1. the projection onto ``Z_E`` (solved by the chosen formulation, warm-started with the previous
   solution and its multipliers, and restarted without the multipliers if that fails; for
   problems with few contact pairs the exact branch enumeration of :mod:`ddcm_casadi.exact` is
   consulted and the formulation is restarted on the globally best branch if it stopped on
   another one), and
2. the projection onto the data (vectorised KD-tree nearest neighbour under the metric, or the
   warm-started exact search that starts from the previous assignment, ``search="warm"``),

until the data assignment no longer changes. The first step starts from the data point nearest
the origin. For one-element problems it also finds the global DDCM optimum by enumerating the data
set and reports whether the alternating scheme reached it.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from ..errors import ConvergenceError, InputError
from ..exact import ExactEnumerator
from ..problem import ProblemPair


@dataclass
class StepResult:
    """Everything known about one load step of one variant and formulation (physical units)."""

    step: int
    load_parameter: float
    u: np.ndarray
    p: np.ndarray
    converged: bool
    iterations: int
    outer_iterations: int
    residual: float
    complementarity: float
    penetration: float
    seconds: float
    message: str = ""
    # DDCM only
    strain: np.ndarray | None = None
    stress: np.ndarray | None = None
    strain_star: np.ndarray | None = None
    stress_star: np.ndarray | None = None
    data_index: np.ndarray | None = None
    distance: float = float("nan")
    projection_error: float = float("nan")
    projection_global: bool | None = None
    global_optimum: bool | None = None
    global_distance: float = float("nan")
    projection_seconds: float = 0.0
    search_seconds: float = 0.0

    def diagnostics(self) -> dict:
        d = asdict(self)
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in d.items()}


@dataclass
class PathResult:
    """The steps of one variant x formulation along the load path."""

    variant: str
    formulation: str
    steps: list[StepResult] = field(default_factory=list)
    build_seconds: float = 0.0
    solve_seconds: float = 0.0

    @property
    def converged(self) -> bool:
        return all(s.converged for s in self.steps)

    def array(self, name: str) -> np.ndarray:
        """Per-step values of a field, stacked (``u`` and ``p`` give ``(n_steps, n)`` arrays)."""
        return np.array([getattr(s, name) for s in self.steps])


def _check_convergence(step: StepResult, raise_on_failure: bool, label: str) -> None:
    if raise_on_failure and not step.converged:
        raise ConvergenceError(f"{label}: step {step.step} did not converge ({step.message})",
                               step.diagnostics())


def solve_classical(problems: ProblemPair, built, formulation_name: str, *, raise_on_failure: bool = False,
                    progress: Callable[[StepResult], None] | None = None) -> PathResult:
    """Classical solution at every load step with a built formulation (warm-started)."""
    model = problems.model
    if problems.classical is None:
        raise InputError("the classical variant needs a Young's modulus")
    out = PathResult("classical", formulation_name)
    x = np.zeros(problems.classical.n_x)
    p = np.zeros(problems.classical.n_pairs)
    state = None
    t_all = time.perf_counter()
    for k in range(model.n_steps):
        t0 = time.perf_counter()
        sol = built.solve(problems.step_params(k), x, p, state)
        f = problems.fields("mcp", sol.x, sol.p)
        step = StepResult(step=k, load_parameter=float(model.load_parameter[k]), u=f["u"], p=f["p"],
                          converged=sol.converged, iterations=sol.iterations,
                          outer_iterations=sol.outer_iterations, residual=sol.residual,
                          complementarity=sol.complementarity, penetration=sol.penetration,
                          seconds=time.perf_counter() - t0, message=sol.message,
                          strain=f["strain"], stress=f["stress"])
        out.steps.append(step)
        if progress is not None:
            progress(step)
        _check_convergence(step, raise_on_failure, f"classical/{formulation_name}")
        if sol.converged and np.all(np.isfinite(sol.x)):
            x, p, state = sol.x, sol.p, sol.state
    out.solve_seconds = time.perf_counter() - t_all
    return out


class DDCMSolver:
    """Alternating projections for one model and one built projection formulation."""

    #: Data searches: a cold KD-tree query, or the warm-started exact search.
    SEARCHES = ("kdtree", "warm")

    def __init__(self, problems: ProblemPair, built, *, max_outer: int = 100, enumerate_pairs: int = 4,
                 global_search: bool = True, search: str = "kdtree") -> None:
        if problems.projection is None:
            raise InputError("the DDCM variant needs a material data set")
        if search not in self.SEARCHES:
            raise InputError(f"unknown data search {search!r}; known: {', '.join(self.SEARCHES)}")
        self.search = search
        #: ``queries`` and ``fallbacks`` (uncertified states) of the warm search, accumulated.
        self.search_stats: dict = {}
        self.problems = problems
        self.built = built
        self.max_outer = int(max_outer)
        model = problems.model
        self.exact = (ExactEnumerator(problems.projection, max_pairs=enumerate_pairs)
                      if model.n_contacts <= enumerate_pairs else None)
        self.global_search = (global_search and self.exact is not None and model.n_points == 1
                              and model.strain_components == 1)

    def _project(self, params, x0, p0, state):
        """Projection onto Z_E, restarted on the exact global branch if it may have stopped elsewhere.

        Returns ``(solution, is_global, error)``: ``is_global`` is True when no better branch is
        known (the solution is at least as good as the formulation restarted on the exact global
        branch); ``error`` is the scaled distance to the exact projection.
        """
        sol = self.built.solve(params, x0, p0, state)
        if not sol.converged and state:
            # Warm multipliers can mislead Newton near many corners (measured: 9 stops at the
            # corner, 1e5 data); the same primal start without them is the next try.
            retry = self.built.solve(params, x0, p0, None)
            if retry.converged:
                retry.iterations += sol.iterations
                retry.message += " (restarted without warm multipliers)"
                sol = retry
            else:
                sol.iterations += retry.iterations
        if self.exact is None:
            return sol, None, float("nan")
        ex = self.exact.solve(params)
        xe, pe, obj = ex.x[:, 0], ex.p[:, 0], float(ex.objective[0])
        tol = 1e-10 + 1e-8 * abs(obj)
        is_global = bool(sol.converged and sol.objective <= obj + tol)
        if not is_global:
            alt = self.built.solve(params, xe, pe, {"on_branch": True})
            if alt.converged and (not sol.converged or alt.objective < sol.objective):
                sol = alt
            is_global = bool(sol.converged and (not alt.converged or sol.objective <= alt.objective + tol))
        scale = max(1.0, float(np.max(np.abs(np.concatenate([xe, pe])))))
        err = float(np.max(np.abs(np.concatenate([sol.x - xe, sol.p - pe])))) / scale
        return sol, is_global, err

    def solve(self, *, formulation_name: str = "", raise_on_failure: bool = False,
              progress: Callable[[StepResult], None] | None = None) -> PathResult:
        problems, model = self.problems, self.problems.model
        data = model.dataset
        out = PathResult("ddcm", formulation_name)
        origin = np.zeros(model.n_points * model.strain_components)
        index = data.nearest(origin, origin)
        x = np.zeros(problems.projection.n_x)
        p = np.zeros(problems.projection.n_pairs)
        state = None
        t_all = time.perf_counter()
        for k in range(model.n_steps):
            t0 = time.perf_counter()
            inner, t_project, t_search = 0, 0.0, 0.0
            seen = {index.tobytes()}
            converged, message = False, "maximum outer iterations reached"
            for outer in range(1, self.max_outer + 1):
                t1 = time.perf_counter()
                params = problems.projection_params(k, data.strain[index], data.stress[index])
                sol, is_global, err = self._project(params, x, p, state)
                t_project += time.perf_counter() - t1
                inner += sol.iterations
                if not sol.converged:
                    message = f"Z_E projection did not converge: {sol.message}"
                    break
                x, p, state = sol.x, sol.p, sol.state
                t1 = time.perf_counter()
                f = problems.fields("mpcc", sol.x, sol.p)
                if self.search == "warm":
                    new_index = data.nearest_warm(f["strain"], f["stress"], index, stats=self.search_stats)
                else:
                    new_index = data.nearest(f["strain"], f["stress"])
                t_search += time.perf_counter() - t1
                if np.array_equal(new_index, index):
                    converged, message = True, "fixed point"
                    break
                key = new_index.tobytes()
                if key in seen:
                    message = "data assignment cycles"
                    index = new_index
                    break
                seen.add(key)
                index = new_index
            f = problems.fields("mpcc", sol.x, sol.p)
            d2 = data.distance2(f["strain"], f["stress"], index)
            step = StepResult(step=k, load_parameter=float(model.load_parameter[k]), u=f["u"], p=f["p"],
                              converged=converged, iterations=inner, outer_iterations=outer,
                              residual=sol.residual, complementarity=sol.complementarity,
                              penetration=sol.penetration, seconds=0.0, message=message,
                              strain=f["strain"], stress=f["stress"], strain_star=data.strain[index].copy(),
                              stress_star=data.stress[index].copy(), data_index=index.copy(),
                              distance=float(0.5 * np.dot(model.volumes, d2)), projection_error=err,
                              projection_global=is_global, projection_seconds=t_project, search_seconds=t_search)
            if self.global_search:
                self._global_optimum(k, step)
            step.seconds = time.perf_counter() - t0
            out.steps.append(step)
            if progress is not None:
                progress(step)
            _check_convergence(step, raise_on_failure, f"ddcm/{formulation_name}")
        out.solve_seconds = time.perf_counter() - t_all
        return out

    def _global_optimum(self, k: int, step: StepResult) -> None:
        """One-element problems: the data point whose exact projection is nearest (enumeration)."""
        data, problems = self.problems.model.dataset, self.problems
        P = problems.projection_params(k, data.strain[None, :], data.stress[None, :])
        ex = self.exact.solve(P)
        energy = problems.scales("mpcc")["energy"]
        j = int(np.argmin(ex.objective))
        best = float(ex.objective[j])
        mine = float(ex.objective[int(step.data_index[0])])
        step.global_distance = best * energy
        step.global_optimum = bool(mine <= best + 1e-12 + 1e-9 * abs(best))
