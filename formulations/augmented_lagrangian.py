r"""Augmented Lagrangian formulation with Uzawa (multiplier) iterations (paper, eq. (4)).

Classical (mcp)
    Inner: solve ``F(x, <lambda - gamma g(x)>_+) = 0`` by semismooth Newton; outer (Uzawa):
    ``lambda <- <lambda - gamma g(x)>_+``. At a fixed point ``p = lambda = <p - gamma g>_+``,
    which is exactly ``g >= 0, p >= 0, g p = 0``: exact at convergence for any ``gamma > 0``.
    For the paper's bar the multiplier error contracts by ``(E/l0) / (E/l0 + gamma)`` per update.

DDCM (mpcc)
    The complementarity is written as the nonsmooth equation (exact for any ``gamma > 0``)

    .. math::  c(x, p) = p - \langle p - \gamma\, g(x) \rangle_+ = 0,

    and handled by the method of multipliers: inner, semismooth Newton on the stationarity of
    ``f + mu^T c + (rho/2) ||c||^2 + eta^T h`` in ``(x, p, eta)``; outer, ``mu <- mu + rho c``.
    At convergence ``c = 0`` and the inner stationarity becomes the KKT system of
    ``min f s.t. h = 0, c = 0``: a stationary point of the exact projection onto ``Z_E`` on the
    identified branch (not a penalised one), for any ``gamma > 0`` and ``rho > 0``.

Positive parts use :func:`~ddcm_casadi.solvers.newton.plus`; an inner Newton that cycles at a
kink is completed by a smoothing continuation ``mu -> 0``.

Substituting ``p = <lambda - gamma g>_+`` into the projection (the classical recipe) would not be
exact: its fixed point lies on ``Z_E`` but is the projection onto a line of slope ``-gamma``
through it, not onto ``Z_E``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ddcm_casadi.problem import ComplementarityProblem
from ddcm_casadi.solvers.newton import SparseJacobian, plus, smoothed_newton_solve

from .base import BuiltFormulation, Formulation, LocalSolution, positive_option
from .registry import register


@register
class AugmentedLagrangian(Formulation):
    """Augmented Lagrangian with Uzawa / multiplier updates."""

    name = "augmented_lagrangian"
    title = "augmented Lagrangian"

    @dataclass(frozen=True)
    class Options:
        """Options.

        gamma : float or None
            Augmentation ``gamma`` (Pa/m) in ``<lambda - gamma g>_+``; ``None``: ``100 E / l0``.
        rho : float
            DDCM only: multiplier-method penalty on ``c(x, p)`` (scaled, dimensionless).
        tol : float
            Tolerance on the multiplier update (classical) or on ``||c||_inf`` (DDCM), scaled.
        newton_tol, residual_tol, max_iter :
            Inner Newton tolerances and iteration limit.
        max_updates : int
            Maximum Uzawa / multiplier updates.
        """

        gamma: float | None = None
        rho: float = 100.0
        tol: float = 1e-11
        newton_tol: float = 1e-10
        residual_tol: float = 1e-10
        max_iter: int = 50
        max_updates: int = 500

    DEFAULT_GAMMA_FACTOR = 100.0

    def _validate(self) -> None:
        super()._validate()
        for k in ("gamma", "rho", "tol", "newton_tol", "residual_tol"):
            positive_option(self.name, k, getattr(self.options, k))

    def gamma(self, problem: ComplementarityProblem) -> float:
        return self.options.gamma or self.DEFAULT_GAMMA_FACTOR * problem.contact_stiffness

    def build(self, problem: ComplementarityProblem) -> "_BuiltAL":
        return _BuiltAL(problem, self.options, problem.scaled_penalty(self.gamma(problem)))


class _BuiltAL(BuiltFormulation):
    def __init__(self, problem: ComplementarityProblem, opts: AugmentedLagrangian.Options, gamma: float) -> None:
        super().__init__(problem)
        self.opts = opts
        nx, nc = problem.n_x, problem.n_pairs
        mult = ca.SX.sym("multiplier", nc)
        mu = ca.SX.sym("mu")
        if problem.kind == "mcp":
            p_of_x = plus(mult - gamma * problem.gap, mu)
            z = problem.x
            r = ca.substitute(problem.residual, problem.p, p_of_x)
            P = ca.vertcat(problem.params, mult, mu)
            self._update = ca.Function("uzawa", [z, P], [p_of_x])
        else:
            ne = problem.residual.numel()
            eta = ca.SX.sym("eta", ne)
            rho = ca.SX.sym("rho")
            c = problem.p - plus(problem.p - gamma * problem.gap, mu)
            z = ca.vertcat(problem.x, problem.p, eta)
            lag = problem.objective + ca.dot(mult, c) + 0.5 * rho * ca.dot(c, c) + ca.dot(eta, problem.residual)
            r = ca.gradient(lag, z)
            P = ca.vertcat(problem.params, mult, rho, mu)
            self._c = ca.Function("al_c", [z, P], [c])
            self._ne = ne
        self._rj = ca.Function("al_rj", [z, P], [r, ca.jacobian(r, z)])
        self._r = ca.Function("al_r", [z, P], [r])
        self._jac = SparseJacobian(self._rj)
        self._nx, self._nc = nx, nc

    def solve(self, params, x0, p0, state=None) -> LocalSolution:
        if self.problem.kind == "mcp":
            return self._solve_mcp(params, x0, p0)
        return self._solve_mpcc(params, x0, p0, state or {})

    def _newton(self, z, P):
        o = self.opts
        res, mu, _ = smoothed_newton_solve(self._rj, self._r, z, P, jacobian=self._jac, tol=o.newton_tol,
                                           residual_tol=o.residual_tol, max_iter=o.max_iter)
        return res, np.append(P, mu)

    def _solve_mcp(self, params, x0, p0) -> LocalSolution:
        lam = np.maximum(np.asarray(p0, float), 0.0)
        z = np.asarray(x0, float)
        newton_its, converged, message = 0, False, "maximum multiplier updates reached"
        for k in range(1, self.opts.max_updates + 1):
            P = np.concatenate([params, lam])
            res, Pmu = self._newton(z, P)
            newton_its += res.iterations
            if not res.converged:
                message = f"inner Newton failed at update {k}: {res.message}"
                break
            z = res.z
            lam_new = np.asarray(self._update(z, Pmu), float).ravel()
            change = float(np.max(np.abs(lam_new - lam))) if lam.size else 0.0
            lam = lam_new
            if change <= self.opts.tol * max(1.0, float(np.max(np.abs(lam), initial=0.0))):
                converged, message = True, "converged"
                break
        return self._finish(z, lam, params, converged=converged, iterations=newton_its, outer=k,
                            message=message)

    def _solve_mpcc(self, params, x0, p0, state) -> LocalSolution:
        mu = np.asarray(state.get("mu", np.zeros(self._nc)), float)
        z = np.concatenate([x0, p0, state.get("eta", np.zeros(self._ne))])
        newton_its, converged, message = 0, False, "maximum multiplier updates reached"
        rho = self.opts.rho
        for k in range(1, self.opts.max_updates + 1):
            P = np.concatenate([params, mu, [rho]])
            res, Pmu = self._newton(z, P)
            newton_its += res.iterations
            if not res.converged:
                message = f"inner Newton failed at update {k}: {res.message}"
                break
            z = res.z
            c = np.asarray(self._c(z, Pmu), float).ravel()
            mu = mu + rho * c
            if float(np.max(np.abs(c), initial=0.0)) <= self.opts.tol:
                converged, message = True, "converged"
                break
        nx, nc = self._nx, self._nc
        return self._finish(z[:nx], z[nx:nx + nc], params, converged=converged, iterations=newton_its, outer=k,
                            state=dict(mu=mu, eta=z[nx + nc:]), message=message)
