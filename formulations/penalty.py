r"""Penalty formulation (paper, eq. (3)): the contact pressure is a function of the penetration,

.. math::  p = \gamma \langle -g(x) \rangle_+ .

Classical (mcp)
    Substituted into equilibrium, ``F(x, gamma <-g(x)>_+) = 0``, solved by semismooth Newton.

DDCM (mpcc)
    The projection onto the penalised admissible set. That set has a corner at ``g = p = 0``
    where the projection of many data points lands, and there the substituted stationarity system
    has no root (Newton cycles between the two pieces). The penalty law is therefore written as the
    equivalent *compliant* complementarity

    .. math::  p \ge 0, \quad g + p/\gamma \ge 0, \quad p\,(g + p/\gamma) = 0,

    and solved like the Fischer-Burmeister projection (saddle-point Newton on
    ``f + eta^T h + theta^T Phi(alpha (g + p/gamma), beta p)``), which handles the corner.

Not exact: the penetration is ``O(1/gamma)``; for the paper's bar the tip displacement is
``u = gamma w / (E/l0 + gamma)``, a relative error ``(E/l0) / (E/l0 + gamma)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.problems.parameters import Parameters
from ddcm_casadi.loops.active_set import ActiveSetSolver
from ddcm_casadi.loops.newton import SMOOTHING, plus, smoothed_newton_solve

from .base import BuiltFormulation, Formulation, LocalSolution, positive_option
from .friction import BuiltCoulomb
from .ncp import FBSystem
from .pairs import NewtonSystem
from .systems import pair_system
from .registry import register


@register
class Penalty(Formulation):
    """Penalty regularisation of the contact pairs."""

    name = "penalty"
    title = "penalty"
    supported_contact_laws = frozenset({"signorini", "coulomb"})
    exact = False

    @dataclass(frozen=True)
    class Options:
        """Options.

        gamma : float or None
            Penalty stiffness ``gamma`` (Pa/m); ``None``: ``1e4 E / l0`` (relative error ~1e-4).
        tol, residual_tol, max_iter :
            Newton tolerances (relative increment, scaled residual) and iteration limit.
        smoothing : tuple of float
            Fallback smoothing continuation ``mu -> 0`` (see :mod:`ddcm_casadi.loops.newton`).
        comp_tol : float
            DDCM: the compliant pairs must satisfy ``max |min(g + p/gamma, p)| <= comp_tol`` (scaled).
        active_set_predictor : bool
            DDCM: the active-set predictor of the compliant pairs' FB system (see
            :class:`ddcm_casadi.formulations.ncp.FBSystem`).
        """

        gamma: float | None = None
        tol: float = 1e-9
        residual_tol: float = 1e-9
        max_iter: int = 50
        smoothing: tuple = SMOOTHING
        comp_tol: float = 1e-9
        active_set_predictor: bool = True

    DEFAULT_GAMMA_FACTOR = 1e4

    def _validate(self) -> None:
        super()._validate()
        for k in ("gamma", "tol", "residual_tol", "comp_tol"):
            positive_option(self.name, k, getattr(self.options, k))

    def gamma(self, problem: ComplementarityProblem) -> float:
        """The physical penalty stiffness used for ``problem``."""
        return self.options.gamma or self.DEFAULT_GAMMA_FACTOR * problem.contact_stiffness

    def penalty_stiffness(self, problem: ComplementarityProblem) -> float:
        return self.gamma(problem)

    def resolved_options(self, problem: ComplementarityProblem | None) -> dict:
        opts = super().resolved_options(problem)
        if problem is not None:
            opts["gamma_used"] = self.gamma(problem)
        return opts

    def _build(self, problem: ComplementarityProblem) -> BuiltFormulation:
        gamma = problem.scaled_penalty(self.gamma(problem))
        if problem.frictional:  # normal and tangential springs, the return map onto the cone
            o = self.options
            return BuiltCoulomb(problem, "alart_curnier", gamma, 1.0, tol=o.tol, residual_tol=o.residual_tol,
                                max_iter=o.max_iter, comp_tol=o.comp_tol, compliance=gamma,
                                penalty_stiffness=self.penalty_stiffness(problem), predictor=o.active_set_predictor)
        built = (_BuiltPenalty if problem.kind == "mcp" else _BuiltCompliantProjection)(problem, self.options, gamma)
        built.penalty_stiffness = self.penalty_stiffness(problem)  # its expected penetration is p / gamma
        return built


class _BuiltPenalty(BuiltFormulation):
    """Classical: substitution ``p = gamma <-g>_+`` and semismooth Newton in ``x``."""

    def __init__(self, problem: ComplementarityProblem, opts: Penalty.Options, gamma: float) -> None:
        super().__init__(problem)
        self.opts = opts
        P = problem.parameters.extend(mu=1)
        self.parameters = P
        S = pair_system(problem, problem.n_x, P)
        p_of_x = gamma * plus(-S.affine("gap", problem.gap_map), S.parameter("mu"))
        built = S.eliminated("penalty", p_of_x)
        self._rj, self._r, self._jac = built.rj, built.r, built.jacobian
        self._p = S.values("penalty_p", [p_of_x])
        self._system = NewtonSystem("penalty", Parameters(x=problem.n_x), P, built)

    def newton_system(self):
        return self._system

    def newton_point(self, params, x, p, state=None):
        return np.asarray(x, float), self.parameters.pack(params, mu=0.0)

    def solve(self, params, x0, p0, state=None) -> LocalSolution:
        o = self.opts
        P = self.parameters
        res, mu, stages = smoothed_newton_solve(self._rj, self._r, np.asarray(x0, float),
                                                lambda mu: P.pack(params, mu=mu),
                                                smoothing=o.smoothing, jacobian=self._jac, tol=o.tol,
                                                residual_tol=o.residual_tol, max_iter=o.max_iter)
        p = np.asarray(self._p(res.z, P.pack(params, mu=0.0)), float).ravel()
        return self._finish(res.z, p, params, converged=res.converged, iterations=res.iterations, outer=stages,
                            message=res.message + (f" (smoothing mu={mu:g})" if mu else ""))


class _BuiltCompliantProjection(BuiltFormulation):
    """DDCM: projection with the compliant pairs ``p ⟂ g + p/gamma`` (Fischer-Burmeister Newton)."""

    def __init__(self, problem: ComplementarityProblem, opts: Penalty.Options, gamma: float) -> None:
        super().__init__(problem)
        self.opts = opts
        compliant_gap = problem.gap_map + problem.pressure_map / gamma
        self.system = FBSystem(problem, problem.fb_alpha * problem.gap_ref, problem.fb_beta * problem.pressure_ref,
                               gap=compliant_gap)
        self.solver = ActiveSetSolver(self.system, predictor=opts.active_set_predictor)
        S = pair_system(problem, problem.n_x + problem.n_pairs, problem.parameters)
        self._pairs = S.values("compliant_pairs", [ca.fmin(S.affine("gap", compliant_gap),
                                                           S.affine("p", problem.pressure_map))])

    def newton_system(self):
        return self.system.newton_system("penalty (compliant pairs)")

    def newton_point(self, params, x, p, state=None):
        return self.system.start(x, p, state), self.system.pack(params)

    def reset(self) -> None:
        self.solver.reset()

    @property
    def stats(self) -> dict:
        return dict(self.solver.stats)

    def solve(self, params, x0, p0, state=None) -> LocalSolution:
        x, p, st, res, mu, stages = self.solver.solve(self.system.start(x0, p0, state), params, self.opts)
        sol = self._finish(x, p, params, converged=res.converged, iterations=res.iterations, outer=stages,
                           state=st, message=res.message + (f" (smoothing mu={mu:g})" if mu else ""))
        # The penalty law itself (the compliant pairs) must hold, as FB checks its pairs.
        comp = float(np.max(np.abs(np.asarray(self._pairs(np.concatenate([x, p]), params), float)), initial=0.0))
        if sol.converged and comp > self.opts.comp_tol:
            sol.converged, sol.message = False, f"compliant complementarity {comp:.1e} > comp_tol"
        return sol
