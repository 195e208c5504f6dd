"""Drivers along a load path: the classical steps here, the DDCM alternation in
:mod:`ddcm_casadi.drivers.ddcm`; both warm-start each step from the previous one, and both bisect
a step that fails (:mod:`~ddcm_casadi.drivers.substeps`, down to ``min_substep`` of a step).

The records (:class:`StepResult`, :class:`PathResult`: :mod:`~ddcm_casadi.drivers.records`), the
physical checks (:func:`physical_check`, :func:`clip_roundoff`, :func:`finish_step`:
:mod:`~ddcm_casadi.drivers.checks`) and :class:`DDCMSolver` are importable from here too.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from ddcm_casadi.errors import InputError
from ddcm_casadi.parallel import limited_blas
from ddcm_casadi.problems.build import ProblemPair
from ddcm_casadi.drivers.checks import (
    PENALTY_PRESSURE_BOUND, PHYSICAL_TOL, ROUNDOFF, clip_roundoff, finish_step, physical_check,
)
from ddcm_casadi.drivers.ddcm import DDCMSolver
from ddcm_casadi.drivers.ddcm_reduced import path_description
from ddcm_casadi.drivers.records import PathResult, StepResult, check_convergence
from ddcm_casadi.drivers.substeps import (
    DEFAULT_MIN_SUBSTEP, accepted, bisect, bisection_enabled, check_min_substep, finish_bisected, interpolate,
    unloaded_start,
)

__all__ = ["DDCMSolver", "PENALTY_PRESSURE_BOUND", "PHYSICAL_TOL", "PathResult", "ROUNDOFF", "StepResult",
           "check_convergence", "clip_roundoff", "finish_step", "physical_check", "solve_classical"]


@limited_blas
def solve_classical(problems: ProblemPair, built, formulation_name: str, *, raise_on_failure: bool = False,
                    progress: Callable[[StepResult], None] | None = None,
                    min_substep: float = DEFAULT_MIN_SUBSTEP) -> PathResult:
    """Classical solution at every load step with a built formulation (warm-started): built on
    the full problem, or condensed on the contact pairs by
    :func:`~ddcm_casadi.drivers.ddcm_reduced.build_classical` (``PathResult.projection_path``
    says which).

    A penalty formulation's penetration ``p / gamma`` is expected by the physical check
    (:func:`physical_check`, with ``built.penalty_stiffness``). A step that fails (not converged,
    non-finite, rejected by the physical checks or as an unstable equilibrium) is bisected from
    the last converged state down to ``min_substep`` of a step
    (:mod:`~ddcm_casadi.drivers.substeps`; 0 or 1: off); every sub-step is checked as a step is.
    A step that fails even then is reported as its full step's attempt, not converged, and the
    next step starts from the last converged one.
    """
    model = problems.model
    if problems.classical is None:
        raise InputError("the classical variant needs a Young's modulus")
    min_substep = check_min_substep(min_substep)
    out = PathResult("classical", formulation_name)
    x = np.zeros(problems.classical.n_x)
    p = np.zeros(problems.classical.n_pairs)
    state, previous = None, None
    converged_params = None  # the parameters of the last converged step (None: the unloaded start)
    t_all = time.perf_counter()
    for k in range(model.n_steps):
        t0 = time.perf_counter()
        params = problems.step_params(k, previous)
        step, sol = _classical_step(problems, built, k, params, (x, p, state))
        if not accepted(step, sol.x, sol.p) and bisection_enabled(min_substep):
            start = (unloaded_start(problems.classical, params, model.load_names()) if converged_params is None
                     else converged_params)
            if start is not None:  # None: no clean unloaded start (see substeps.unloaded_start)
                step, sol = _bisect_classical(problems, built, k, params, start, (x, p, state), step, sol,
                                              min_substep)
        step.seconds = time.perf_counter() - t0
        out.steps.append(step)
        if progress is not None:
            progress(step)
        check_convergence(step, raise_on_failure, f"classical/{formulation_name}")
        if accepted(step, sol.x):
            x, p, state = sol.x, sol.p, sol.state
            previous = dict(u=step.u, p=step.p, traction=step.traction, step=k)
            converged_params = params
    out.solve_seconds = time.perf_counter() - t_all
    out.projection_path = path_description(built)  # condensed or full (after any fallback), and why
    return out


def _classical_step(problems: ProblemPair, built, k: int, params: np.ndarray, warm: tuple) -> tuple[StepResult, object]:
    """One classical solve of step ``k`` (or of a sub-step of it) with the parameters ``params``,
    warm-started from ``warm = (x, p, state)``, finished by every check a step gets (the physical
    checks with the load of ``params``, the stability of a nonlinear problem)."""
    model, problem = problems.model, problems.classical
    sol = built.solve(params, *warm)
    f = problems.fields("mcp", sol.x, sol.p, params)
    step = StepResult(step=k, load_parameter=float(model.load_parameter[k]), u=f["u"], p=f["p"],
                      converged=sol.converged, iterations=sol.iterations,
                      outer_iterations=sol.outer_iterations, residual=sol.residual,
                      complementarity=sol.complementarity, penetration=sol.penetration,
                      seconds=0.0, message=sol.message, strain=f["strain"], stress=f["stress"],
                      traction=f.get("traction"), slip=f.get("slip"))
    finish_step(step, problem, model, penalty_stiffness=getattr(built, "penalty_stiffness", None),
                load=problem.parameters.get(params, "f"))
    _check_stability(step, problem, sol, params)
    return step, sol


def _bisect_classical(problems: ProblemPair, built, k: int, params: np.ndarray, start: np.ndarray, warm: tuple,
                      full: StepResult, full_sol, min_substep: float) -> tuple[StepResult, object]:
    """Step ``k`` in sub-steps from the last converged state (``warm``, at the parameters
    ``start``) after its full step (``full``, ``full_sol``) failed: the last sub-step's record
    (converged) or the full step's (not converged), with the costs of every attempt."""
    P, names = problems.classical.parameters, problems.model.load_names()
    tried: list[tuple[StepResult, object]] = []

    def attempt(t_from: float, t_to: float, sub: tuple) -> tuple[bool, tuple]:
        step, sol = _classical_step(problems, built, k, interpolate(P, start, params, t_to, names), sub)
        tried.append((step, sol))
        return accepted(step, sol.x, sol.p), (sol.x, sol.p, sol.state)

    bisection = bisect(attempt, warm, min_substep)
    step, sol = tried[-1] if bisection.converged else (full, full_sol)
    others = [full] + [s for s, _ in tried]
    return finish_bisected(step, bisection, others), sol


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
