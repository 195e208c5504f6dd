"""Drivers along a load path: the classical steps here, the DDCM alternation in
:mod:`ddcm_casadi.drivers.ddcm`; both warm-start each step from the previous one.

The records (:class:`StepResult`, :class:`PathResult`: :mod:`~ddcm_casadi.drivers.records`), the
physical checks (:func:`physical_check`, :func:`clip_roundoff`, :func:`finish_step`:
:mod:`~ddcm_casadi.drivers.checks`) and :class:`DDCMSolver` are importable from here too.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from ddcm_casadi.errors import InputError
from ddcm_casadi.problems.build import ProblemPair
from ddcm_casadi.drivers.checks import (
    PENALTY_PRESSURE_BOUND, PHYSICAL_TOL, ROUNDOFF, clip_roundoff, finish_step, physical_check,
)
from ddcm_casadi.drivers.ddcm import DDCMSolver
from ddcm_casadi.drivers.records import PathResult, StepResult, check_convergence

__all__ = ["DDCMSolver", "PENALTY_PRESSURE_BOUND", "PHYSICAL_TOL", "PathResult", "ROUNDOFF", "StepResult",
           "check_convergence", "clip_roundoff", "finish_step", "physical_check", "solve_classical"]


def solve_classical(problems: ProblemPair, built, formulation_name: str, *, raise_on_failure: bool = False,
                    progress: Callable[[StepResult], None] | None = None) -> PathResult:
    """Classical solution at every load step with a built formulation (warm-started).

    A penalty formulation's penetration ``p / gamma`` is expected by the physical check
    (:func:`physical_check`, with ``built.penalty_stiffness``).
    """
    model = problems.model
    if problems.classical is None:
        raise InputError("the classical variant needs a Young's modulus")
    out = PathResult("classical", formulation_name)
    x = np.zeros(problems.classical.n_x)
    p = np.zeros(problems.classical.n_pairs)
    state, previous = None, None
    t_all = time.perf_counter()
    for k in range(model.n_steps):
        t0 = time.perf_counter()
        params = problems.step_params(k, previous)
        sol = built.solve(params, x, p, state)
        f = problems.fields("mcp", sol.x, sol.p)
        step = StepResult(step=k, load_parameter=float(model.load_parameter[k]), u=f["u"], p=f["p"],
                          converged=sol.converged, iterations=sol.iterations,
                          outer_iterations=sol.outer_iterations, residual=sol.residual,
                          complementarity=sol.complementarity, penetration=sol.penetration,
                          seconds=time.perf_counter() - t0, message=sol.message,
                          strain=f["strain"], stress=f["stress"])
        finish_step(step, problems.classical, model, penalty_stiffness=getattr(built, "penalty_stiffness", None))
        _check_stability(step, problems.classical, sol, params)
        out.steps.append(step)
        if progress is not None:
            progress(step)
        check_convergence(step, raise_on_failure, f"classical/{formulation_name}")
        if step.converged and np.all(np.isfinite(sol.x)):
            x, p, state = sol.x, sol.p, sol.state
            previous = dict(u=step.u, p=step.p)
    out.solve_seconds = time.perf_counter() - t_all
    return out


#: A classical step whose tangent stiffness on the free directions has an eigenvalue below
#: ``-STABILITY_TOL`` times its largest entry is an unstable equilibrium (roundoff: ~1e-14).
STABILITY_TOL = 1e-8


def _check_stability(step: StepResult, problem, sol, params: np.ndarray) -> None:
    """Reject, in place, a converged step of a nonlinear problem that is an unstable equilibrium
    (:meth:`~ddcm_casadi.problems.contract.ComplementarityProblem.stability`): it solves the equations but a
    quasi-static load path cannot rest there (a snap-through truss with horizontal members)."""
    if not step.converged or problem.affine:
        return
    smallest = problem.stability(sol.x, sol.p, params)
    if smallest < -STABILITY_TOL:
        step.converged = False
        step.message = (f"{step.message}, but an unstable equilibrium (tangent stiffness eigenvalue "
                        f"{smallest:.2g} of its largest entry)")
