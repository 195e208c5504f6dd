"""The ``Z_E`` projection of the DDCM driver, checked against the exact branch enumeration where
there is one, and the global-optimum certificate of a step.

The projection is the chosen formulation, warm-started with the previous solution and its
multipliers, restarted (a nonlinear problem whose warm start has passed an obstacle) from the
unloaded state resting on the obstacles, or else without the multipliers, if that fails. For affine problems with few
contact pairs (:class:`~ddcm_casadi.problems.exact.ExactEnumerator`) the exact projection is known: the
formulation is restarted on the globally best branch if it stopped on another one, and the gap
is reported (``projection_global``, ``projection_error``).
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from ddcm_casadi.drivers.ddcm_search import global_optimum
from ddcm_casadi.formulations.base import LocalSolution, Metrics


class Projection:
    """The ``Z_E`` projection of one model with one built formulation.

    Parameters
    ----------
    problems : ProblemPair
        Needs the projection problem.
    built
        The projection formulation, built.
    exact : callable
        Returns the exact branch enumeration (affine problems with few contact pairs, shared by
        the formulations of one model; built on its first call) or None.
    cache_values : int
        Exact projections remembered per problem, keys and answers together at most this many floats.
    check : bool
        Check every projection against the exact one (restarting on its branch when it is better).
        Without it a converged projection is reported global only where the problem is convex
        (affine without contact pairs), with no error.
    """

    def __init__(self, problems, built, exact: Callable[[], object], cache_values: int, *, check: bool) -> None:
        self.problems, self.built, self._exact, self.cache_values = problems, built, exact, cache_values
        self.check = check
        problem = problems.projection
        self._convex = bool(problem.affine and problem.n_pairs == 0)
        #: The last converged step's physical fields (the history a model's step may depend on,
        #: :meth:`~ddcm_casadi.models.base.ContactModel.step_values`); set by the driver.
        self.previous: dict | None = None
        #: Applied to the parameters of every projection when set: the driver's sub-step of a load
        #: step interpolates their load entries (:func:`~ddcm_casadi.drivers.substeps.interpolate`).
        self.substep: Callable[[np.ndarray], np.ndarray] | None = None
        #: The parameters of the last projection (:meth:`project`): the fields of its solution
        #: are those of these parameters (a hard device's prescribed displacements).
        self.last_params: np.ndarray | None = None
        #: Set by the driver while it searches a step beyond its first run (restarts, greedy):
        #: the exact projection of a parameter vector from closed forms kept for the step
        #: (:func:`~ddcm_casadi.drivers.ddcm_search.params_projection`), or None where they do
        #: not apply; :meth:`exact_projection` then needs no solve.
        self.closed_form: Callable[[np.ndarray], tuple | None] | None = None
        self._metrics = Metrics(problem)

    def solve(self, params: np.ndarray, x0, p0, state):
        """Projection onto Z_E, restarted on the exact global branch if it may have stopped elsewhere.

        Returns ``(solution, is_global, error)``: ``is_global`` is True when no better branch is
        known (the solution is at least as good as the formulation restarted on the exact global
        branch); ``error`` is the scaled distance to the exact projection.
        """
        problem = self.problems.projection
        sol = self.built.solve(params, x0, p0, state)
        if not sol.converged and not problem.affine and problem.penetrates(x0, params):
            # A nonlinear projection whose warm start has passed an obstacle and failed from it
            # (a snap-through put the solution beyond an unstable equilibrium): restart from the
            # unloaded state resting on the obstacles. Only after the warm start: its least-norm
            # step moves the contact nodes alone, which crushes a fine mesh's surface elements
            # (a 45 x 45 block pressed 1 % of its height: the top row to 55 %; Newton stalled
            # there, 150 s, while from the warm start it converged in 6 iterations).
            restart = self.built.solve(params, *problem.restoration_start(x0, params), None)
            restart.iterations += sol.iterations
            if restart.converged:
                restart.message += " (restarted from the unloaded state on the obstacles)"
            sol, state = restart, None
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
        if getattr(self.built, "closed_form", False):
            # the reduced projection without pairs: the unique solution of an equality-constrained
            # QP in closed form, the enumeration's only branch (docs/maths.md, section 17)
            return sol, bool(sol.converged), 0.0
        if not self.check:
            return sol, (bool(sol.converged) if self._convex else None), float("nan")
        xe, pe, obj = self.exact_projection(params)
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

    @property
    def exact(self):
        """The exact branch enumeration (built on first use), or None."""
        return self._exact()

    def exact_projection(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """The exact projection ``(x, p, objective)`` (scaled) for the parameter vector ``params``.

        Remembered per problem (within ``cache_values``): the DDCM runs of the formulations of
        one model visit the same data assignments (the paper's bar: the same 46 projections for
        each of the four), and the enumeration's answer does not depend on the formulation.
        Copies are returned, so that no caller can change a remembered answer. Where
        :attr:`closed_form` answers, its answer (fresh arrays, not remembered).
        """
        if self.closed_form is not None:
            hit = self.closed_form(params)
            if hit is not None:
                return hit
        cache = self.problems.projection.shared(("exact_projections",), lambda: {"values": 0, "items": {}})
        key = params.tobytes()
        hit = cache["items"].get(key)
        if hit is None:
            ex = self.exact.solve(params)
            hit = (ex.x[:, 0], ex.p[:, 0], float(ex.objective[0]))
            size = params.size + hit[0].size + hit[1].size
            if cache["values"] + size <= self.cache_values:
                cache["items"][key] = hit
                cache["values"] += size
        return hit[0].copy(), hit[1].copy(), hit[2]

    @property
    def enumerated(self) -> bool:
        """Whether the exact projection is the formulation's own answer (:meth:`exact_solution`):
        every projection is checked against the enumeration and the formulation enforces the
        contact pairs exactly (no penalty's regularised contact)."""
        return self.check and self.built.penalty_stiffness is None

    def exact_solution(self, params: np.ndarray, state: dict | None, known: tuple | None = None):
        """The exact projection (:meth:`exact_projection`, or ``known``: ``(x, p, objective)``
        of ``params`` found by the caller) as the solution, without the formulation's solve, or
        None where it is not the formulation's answer (not :attr:`enumerated`, or no
        sign-feasible branch). What the checked formulation returns, to the formulation's
        tolerance: a converged solve on another branch is restarted on this one. ``state`` (the
        warm start's multipliers) is passed on as the solution's warm-start data. Returns
        ``(solution, is_global, error)`` as :meth:`solve`."""
        if not self.enumerated:
            return None
        x, p, objective = known if known is not None else self.exact_projection(params)
        if not (np.isfinite(objective) and np.all(np.isfinite(x)) and np.all(np.isfinite(p))):
            return None
        residual, comp, pen, obj = self._metrics(x, p, params)
        sol = LocalSolution(x=x, p=p, converged=True, iterations=0, outer_iterations=0, residual=residual,
                            complementarity=comp, penetration=pen, objective=obj, state=dict(state or {}),
                            message="exact projection (branch enumeration)")
        return sol, True, 0.0

    def project(self, k: int, strain_star, stress_star, warm: tuple, cost: dict, *, exact: bool = False,
                known: tuple | None = None):
        """The ``Z_E`` projection of step ``k``'s material states (or of a sub-step of it, with
        :attr:`substep` set), warm-started from ``warm = (x, p, state)``: ``(solution, is_global,
        error, failure)``, ``failure`` the message of a projection that did not converge, else
        ``""``. Adds its Newton iterations and seconds to ``cost["inner"]`` and ``cost["t_project"]``.
        ``exact``: the exact projection where it is the formulation's answer (:meth:`exact_solution`;
        for states whose exact projection the caller has evaluated: ``known``, its ``(x, p,
        objective)`` where the caller has them too), else the formulation's solve."""
        t0 = time.perf_counter()
        params = self.problems.projection_params(k, strain_star, stress_star, self.previous)
        if self.substep is not None:
            params = self.substep(params)
        self.last_params = params
        given = self.exact_solution(params, warm[2], known) if exact else None
        sol, is_global, err = given if given is not None else self.solve(params, *warm)
        cost["inner"] += sol.iterations
        cost["t_project"] += time.perf_counter() - t0
        failed = "" if sol.converged else f"Z_E projection did not converge: {sol.message}"
        return sol, is_global, err, failed

    def certify(self, k: int, step) -> None:
        """The global optimum of step ``k`` by enumeration of every data assignment (closed forms
        per branch): ``step.global_distance``, ``global_optimum``, ``global_gap``."""
        # Shared by the DDCM solvers of one model (one per formulation): the optimum of a step and
        # the exact objective of an assignment do not depend on the formulation.
        best, mine = self.problems.projection.shared(
            ("global_optimum", k, step.data_index.tobytes()),
            lambda: global_optimum(self.problems, self.exact, k, step.data_index))
        energy = self.problems.scales("mpcc")["energy"]
        step.global_distance = best * energy
        step.global_optimum = bool(mine <= best + 1e-12 + 1e-9 * abs(best))
        step.global_gap = step.distance - step.global_distance
