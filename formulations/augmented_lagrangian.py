r"""Augmented Lagrangian formulation with Uzawa (multiplier) iterations (paper, eq. (4)).

Classical (mcp)
    Inner: solve ``F(x, <lambda - gamma g(x)>_+) = 0`` by semismooth Newton; outer (Uzawa):
    ``lambda <- <lambda - gamma g(x)>_+``. At a fixed point ``p = lambda = <p - gamma g>_+``,
    which is exactly ``g >= 0, p >= 0, g p = 0``: exact at convergence for any ``gamma > 0``.
    For the paper's bar the multiplier error contracts by ``(E/l0) / (E/l0 + gamma)`` per update.

DDCM (mpcc)
    The complementarity is written as one nonsmooth equation per pair, exact for any
    ``gamma > 0``,

    .. math::  c(x, p) = \Phi(\gamma\, g(x),\, p) = 0, \qquad
               \Phi(a, b) = \sqrt{a^2 + b^2} - a - b ,

    and handled by the method of multipliers: inner, minimise ``f + lam^T c + (rho/2) ||c||^2``
    subject to ``h = 0`` (solved in primal-dual form, ``theta = lam + rho c``); outer (Uzawa on the
    multiplier), ``lam <- lam + rho c``. At convergence ``c = 0`` and the inner stationarity is the
    KKT system of ``min f s.t. h = 0, c = 0``: a stationary point of the exact projection onto
    ``Z_E`` (not a penalised one), for any ``gamma > 0`` and ``rho > 0``.

    Why ``Phi`` and not the min-function ``p - <p - gamma g>_+`` (same zero set): the inner
    problems target the level sets ``c = s`` with ``s -> 0``; those of the min-function have a
    corner, where semismooth Newton cycles, those of ``Phi`` are smooth.

The classical positive part uses :func:`~ddcm_casadi.loops.newton.plus`; an inner Newton that
cycles at a kink is completed by a smoothing continuation ``mu -> 0``.

DDCM branch finish. Near a pair on one branch with a small partner, e.g. ``a = 0`` and
``0 < b << 1`` (dense data: the datum nearest the obstacle carries a tiny stress), ``Phi`` rounds
the corner at the scale ``b``: ``theta d2Phi/da2 ~ theta / b``, so the Lagrangian Hessian in ``x``
grows like ``gamma^2 theta / b`` (1e6 and more). Then (i) the Armijo search on ``||r||^2`` stalls
after a multiplier update although the full Newton step converges, and (ii) the stationarity rows
cannot be evaluated below ``|Hessian| * eps * |x|`` (3e-10 with ``|x| = 1``), above the inner
``residual_tol``. When the inner Newton fails, the update is therefore finished on the branch
the iterate lies on (``a_i = 0`` where ``a_i <= b_i``, else ``b_i = 0``): Newton on that smooth
system (same tolerances), with pairs whose sign fails switching branch, accepted only if strictly
complementary (``b_i > 0``, resp. ``a_i > 0``) or a B-stationary corner
(:meth:`ddcm_casadi.loops.active_set.ActiveSetSolver.branch_finish`, the last stage of every inner
solve). There ``Phi`` is smooth, ``Phi = 0`` and its gradient is ``-grad a_i`` (resp.
``-grad b_i``), so the branch KKT point with its multiplier ``theta`` solves the ``Phi``-KKT
system exactly, and ``lam = theta`` is a fixed point of the multiplier update (``c = 0``): the
result is the exact projection, as at ordinary convergence.

Substituting ``p = <lambda - gamma g>_+`` into the projection (the classical recipe) would not be
exact: its fixed point lies on ``Z_E`` but is the projection onto a line of slope ``-gamma``
through it, not onto ``Z_E``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.problems.parameters import Parameters
from ddcm_casadi.loops.active_set import ActiveSetSolver
from ddcm_casadi.loops.newton import SMOOTHING, JacobianFactors, plus, smoothed_newton_solve
from ddcm_casadi.loops.uzawa import method_of_multipliers, uzawa

from .base import BuiltFormulation, Formulation, LocalSolution, positive_option
from .friction import BuiltCoulomb
from .ncp import FBSystem
from .pairs import NewtonSystem
from .systems import pair_system
from .registry import register


@register
class AugmentedLagrangian(Formulation):
    """Augmented Lagrangian with Uzawa / multiplier updates."""

    name = "augmented_lagrangian"
    title = "augmented Lagrangian"
    supported_contact_laws = frozenset({"signorini", "coulomb"})

    @dataclass(frozen=True)
    class Options:
        """Options.

        gamma : float or None
            Augmentation ``gamma`` (Pa/m) in ``<lambda - gamma g>_+``; ``None``: ``100 E / l0``.
        rho : float
            DDCM only: initial multiplier-method penalty on ``c(x, p)`` (scaled, dimensionless);
            multiplied by ``rho_growth`` whenever an update fails to reduce ``||c||_inf`` by 4x
            (the usual safeguard of the method of multipliers), up to ``rho_max``.
        rho_growth, rho_max : float
        tol : float
            Stop when ``max |min(g, p)|`` and the penetration are below ``tol`` (scaled).
        newton_tol, residual_tol, max_iter :
            Inner Newton tolerances and iteration limit.
        smoothing : tuple of float
            Fallback smoothing continuation of the inner Newton.
        anderson : int
            Classical only: depth of the Anderson acceleration of the Uzawa updates (0: plain Uzawa).
        max_updates : int
            Maximum Uzawa / multiplier updates.
        predictor : bool
            Classical, small strain: before the Uzawa loop, the active-set predictor (the
            primal-dual active-set iteration on ``F = 0`` with ``g_i = 0`` or ``p_i = 0`` from the
            start's branches, one kept factorisation per active set); its result is accepted only
            if it passes the loop's own stopping test, and then ``p = <p - gamma g>_+`` is a
            fixed point of the update. DDCM: each inner solve first tries the active-set predictor (the primal-dual
            active-set iteration on the pieces of ``Z_E`` from the start's branches, one kept
            factorisation per active set; :class:`~ddcm_casadi.loops.active_set.ActiveSetSolver`).
            Its result is accepted only if every sign holds strictly or it is a B-stationary
            corner; then ``c = 0`` exactly, ``theta`` is a fixed point of the multiplier update
            and the loop stops after one update. Otherwise semismooth Newton on the proximal
            system runs as without it. Measured on the Hertz example: 0.69 s against 45 s for the
            DDCM run, the same fixed points (docs/performance.md, 2026-11-26).
        """

        gamma: float | None = None
        rho: float = 1e4
        rho_growth: float = 10.0
        rho_max: float = 1e10
        tol: float = 1e-11
        newton_tol: float = 1e-10
        residual_tol: float = 1e-10
        max_iter: int = 50
        max_updates: int = 500
        smoothing: tuple = SMOOTHING
        anderson: int = 5
        predictor: bool = True

    DEFAULT_GAMMA_FACTOR = 100.0

    def _validate(self) -> None:
        super()._validate()
        for k in ("gamma", "rho", "rho_growth", "rho_max", "tol", "newton_tol", "residual_tol"):
            positive_option(self.name, k, getattr(self.options, k))

    def gamma(self, problem: ComplementarityProblem) -> float:
        return self.options.gamma or self.DEFAULT_GAMMA_FACTOR * problem.contact_stiffness

    def resolved_options(self, problem: ComplementarityProblem | None) -> dict:
        opts = super().resolved_options(problem)
        if problem is not None:
            opts["gamma_used"] = self.gamma(problem)
        return opts

    def _build(self, problem: ComplementarityProblem) -> BuiltFormulation:
        gamma = problem.scaled_penalty(self.gamma(problem))
        if problem.frictional:  # Alart-Curnier: the multiplier update's fixed point, by semismooth Newton
            o = self.options
            return BuiltCoulomb(problem, "alart_curnier", gamma, 1.0, tol=o.newton_tol, residual_tol=o.residual_tol,
                                max_iter=o.max_iter, comp_tol=max(o.tol, 1e-9), predictor=o.predictor)
        return _BuiltAL(problem, self.options, gamma)


class _BuiltAL(BuiltFormulation):
    """The inner systems; the loops are :func:`ddcm_casadi.loops.uzawa.uzawa` (classical) and
    :func:`ddcm_casadi.loops.uzawa.method_of_multipliers` (DDCM)."""

    def __init__(self, problem: ComplementarityProblem, opts: AugmentedLagrangian.Options, gamma: float) -> None:
        super().__init__(problem)
        self.opts = opts
        self._nc = problem.n_pairs
        if problem.kind == "mcp":
            P = problem.parameters.extend(multiplier=problem.n_pairs, mu=1)
            self.parameters = P
            S = pair_system(problem, problem.n_x, P)
            p_of_x = plus(S.parameter("multiplier") - gamma * S.affine("gap", problem.gap_map), S.parameter("mu"))
            built = S.eliminated("al", p_of_x)
            self._rj, self._r, self._jac = built.rj, built.r, built.jacobian
            self._update = S.values("uzawa", [p_of_x])
            self._system = NewtonSystem("augmented_lagrangian (inner)", Parameters(x=problem.n_x), P, built)
            # A linear model's inner Jacobian depends only on the active set: Newton steps and
            # Uzawa updates on one active set share a factorisation.
            self._factors = JacobianFactors() if problem.affine else None
            # The predictor's piece systems (F = 0 with a_i = 0 or b_i = 0), scaled as the DDCM
            # system. A linear model only: with finite kinematics the loop's path picks the
            # equilibrium (a snap-through truss has several), as without the predictor.
            self.solver = (ActiveSetSolver(FBSystem(problem, gamma, 1.0), predictor=True)
                           if opts.predictor and problem.affine else None)
        else:
            self.system = FBSystem(problem, gamma, 1.0, proximal=True)
            self.solver = ActiveSetSolver(self.system, predictor=opts.predictor)
        # The inner solver reads these names from its options.
        self._inner = _InnerOptions(opts.newton_tol, opts.residual_tol, opts.max_iter, opts.smoothing)

    def newton_system(self):
        """The inner Newton system (the multipliers are its parameters)."""
        return self._system if self.problem.kind == "mcp" else self.system.newton_system("augmented_lagrangian (inner)")

    def newton_point(self, params, x, p, state=None):
        state = state or {}
        if self.problem.kind == "mcp":
            return np.asarray(x, float), self.parameters.pack(params, multiplier=np.maximum(p, 0.0), mu=0.0)
        base = self.system.base_parameters.pack(params, lam=state.get("lam", 0.0), rho=state.get("rho", self.opts.rho))
        return self.system.start(x, p, state), self.system.pack(base)

    def solve(self, params, x0, p0, state=None) -> LocalSolution:
        if self.problem.kind == "mcp":
            return self._solve_mcp(params, x0, p0)
        return self._solve_mpcc(params, x0, p0, state or {})

    def _solve_mcp(self, params, x0, p0) -> LocalSolution:
        o, P = self.opts, self.parameters

        def inner(lam, z):
            return smoothed_newton_solve(self._rj, self._r, z, lambda mu: P.pack(params, multiplier=lam, mu=mu),
                                         smoothing=o.smoothing, jacobian=self._jac, tol=o.newton_tol,
                                         residual_tol=o.residual_tol, max_iter=o.max_iter,
                                         factors=self._factors)[0]

        def update(z, lam):
            return np.asarray(self._update(z, P.pack(params, multiplier=lam, mu=0.0)), float).ravel()

        def done(z, lam_T):
            # F(x, lam_T) = 0 holds by construction; stop on the pairs themselves (scale-free in gamma).
            residual, comp, pen, _ = self.metrics(z, lam_T, params)
            return comp <= o.tol and pen <= o.tol and residual <= o.residual_tol

        if self.solver is not None:
            system = self.solver.system
            start = system.start(np.asarray(x0, float), np.maximum(np.asarray(p0, float), 0.0), None)
            predicted, spent = self.solver.branch_finish((start,), params, self._inner)
            if predicted is not None:
                x, p, _ = system.split(predicted.z)
                if done(x, p):  # p = <p - gamma g>_+: a fixed point of the Uzawa update
                    return self._finish(x, p, params, converged=True, iterations=spent, outer=0,
                                        message="converged (active-set predictor)")
        out = uzawa(inner, update, done, np.asarray(x0, float), np.maximum(np.asarray(p0, float), 0.0),
                    anderson=o.anderson, max_updates=o.max_updates)
        return self._finish(out.z, out.multiplier, params, converged=out.converged, iterations=out.inner_iterations,
                            outer=out.updates, message=out.message)

    def _solve_mpcc(self, params, x0, p0, state) -> LocalSolution:
        o, system = self.opts, self.system
        base = lambda lam, rho: system.base_parameters.pack(params, lam=lam, rho=rho)  # noqa: E731

        def inner(lam, rho, z):
            _, _, st, res, _, _ = self.solver.solve(z, base(lam, rho), self._inner)
            return res.z, st, res

        def constraint(z, lam, rho):
            return np.asarray(system.phi(z, system.pack(base(lam, rho))), float).ravel()

        def polish(z, lam, rho):
            # A projection onto the corner g = p = 0 needs an unbounded multiplier: the updates
            # would only creep. Finish on the biactive branch when it is B-stationary.
            corner = self.solver.polish_corner(z, base(lam, rho), self._inner)
            return None if corner is None else (corner.z, system.split(corner.z)[2], corner.iterations)

        def done(z):
            x, p, _ = system.split(z)
            _, comp, pen, _ = self.metrics(x, p, params)
            return comp <= o.tol and pen <= o.tol  # on the pairs: c's scale depends on gamma

        out = method_of_multipliers(inner, constraint=constraint, polish=polish,
                                    multiplier=lambda st: st["theta"], done=done,
                                    z0=system.start(x0, p0, state),
                                    lam0=np.asarray(state.get("lam", np.zeros(self._nc)), float), rho0=o.rho,
                                    rho_growth=o.rho_growth, rho_max=o.rho_max, tol=o.tol, max_updates=o.max_updates)
        x, p, st = system.split(out.z)
        st = dict(st, lam=out.multiplier, rho=out.extra["rho"])
        return self._finish(x, p, params, converged=out.converged, iterations=out.inner_iterations,
                            outer=out.updates, state=st, message=out.message)


class _InnerOptions:
    def __init__(self, tol, residual_tol, max_iter, smoothing) -> None:
        self.tol, self.residual_tol, self.max_iter, self.smoothing = tol, residual_tol, max_iter, smoothing
