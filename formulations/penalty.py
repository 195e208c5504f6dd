r"""Penalty formulation (paper, eq. (3)): the contact pressure is a function of the penetration,

.. math::  p = \gamma \langle -g(x) \rangle_+ ,

substituted into the problem, which is then solved by semismooth Newton.

- Classical (mcp): ``F(x, gamma <-g(x)>_+) = 0``.
- DDCM (mpcc): stationarity of ``f(x) + eta^T h(x, gamma <-g(x)>_+)`` in ``(x, eta)``.

The positive part is written with :func:`~ddcm_casadi.solvers.newton.plus` so that a solution at
the kink ``g = 0`` (where semismooth Newton cycles between the two pieces) is reached by a
smoothing continuation ``mu -> 0`` when plain Newton fails.

Not exact: the penetration is ``O(1/gamma)``; for the paper's bar the tip displacement is
``u = gamma w / (E/l0 + gamma)``, a relative error ``(E/l0) / (E/l0 + gamma)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ddcm_casadi.problem import ComplementarityProblem
from ddcm_casadi.solvers.newton import SMOOTHING, SparseJacobian, plus, smoothed_newton_solve

from .base import BuiltFormulation, Formulation, LocalSolution, positive_option
from .registry import register


@register
class Penalty(Formulation):
    """Penalty regularisation of the contact pairs."""

    name = "penalty"
    title = "penalty"
    exact = False

    @dataclass(frozen=True)
    class Options:
        """Options.

        gamma : float or None
            Penalty stiffness ``gamma`` (Pa/m); ``None``: ``1e4 E / l0`` (relative error ~1e-4).
        tol, residual_tol, max_iter :
            Newton tolerances (relative increment, scaled residual) and iteration limit.
        """

        gamma: float | None = None
        tol: float = 1e-9
        residual_tol: float = 1e-9
        max_iter: int = 50

    DEFAULT_GAMMA_FACTOR = 1e4

    def _validate(self) -> None:
        super()._validate()
        for k in ("gamma", "tol", "residual_tol"):
            positive_option(self.name, k, getattr(self.options, k))

    def gamma(self, problem: ComplementarityProblem) -> float:
        """The physical penalty stiffness used for ``problem``."""
        return self.options.gamma or self.DEFAULT_GAMMA_FACTOR * problem.contact_stiffness

    def build(self, problem: ComplementarityProblem) -> "_BuiltPenalty":
        return _BuiltPenalty(problem, self.options, problem.scaled_penalty(self.gamma(problem)))


class _BuiltPenalty(BuiltFormulation):
    def __init__(self, problem: ComplementarityProblem, opts: Penalty.Options, gamma: float) -> None:
        super().__init__(problem)
        self.opts = opts
        mu = ca.SX.sym("mu")
        p_of_x = gamma * plus(-problem.gap, mu)
        residual = ca.substitute(problem.residual, problem.p, p_of_x)
        nx = problem.n_x
        if problem.kind == "mcp":
            z, r = problem.x, residual
        else:
            eta = ca.SX.sym("eta", residual.numel())
            z = ca.vertcat(problem.x, eta)
            r = ca.gradient(problem.objective + ca.dot(eta, residual), z)
        P = ca.vertcat(problem.params, mu)
        self._rj = ca.Function("penalty_rj", [z, P], [r, ca.jacobian(r, z)])
        self._r = ca.Function("penalty_r", [z, P], [r])
        self._p = ca.Function("penalty_p", [problem.x, P], [p_of_x])
        self._jac = SparseJacobian(self._rj)
        self._nx = nx

    def solve(self, params, x0, p0, state=None) -> LocalSolution:
        state = state or {}
        z0 = np.asarray(x0, float)
        if self.problem.kind == "mpcc":
            z0 = np.concatenate([z0, state.get("eta", np.zeros(self.problem.residual.numel()))])
        o = self.opts
        res, mu, stages = smoothed_newton_solve(self._rj, self._r, z0, params, jacobian=self._jac, tol=o.tol,
                                                residual_tol=o.residual_tol, max_iter=o.max_iter)
        x = res.z[:self._nx]
        p = np.asarray(self._p(x, np.append(params, mu)), float).ravel()
        st = {"eta": res.z[self._nx:]} if self.problem.kind == "mpcc" else {}
        return self._finish(x, p, params, converged=res.converged, iterations=res.iterations, outer=stages,
                            state=st, message=res.message + (f" (smoothing mu={mu:g})" if mu else ""))
