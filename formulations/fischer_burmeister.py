r"""Fischer-Burmeister (FB) reformulation, solved by semismooth Newton.

The pairs become equations through

.. math::  \Phi_\mu(a, b) = \sqrt{a^2 + b^2 + 2\mu^2} - a - b, \qquad a = \alpha g,\; b = \beta p,

whose roots at ``mu = 0`` are exactly ``a >= 0, b >= 0, a b = 0`` (paper, eq. (5)).

- Classical (mcp): Newton on ``[F(x, p); Phi(alpha g, beta p)] = 0``.
- DDCM (mpcc): Newton on the stationarity of the saddle point (paper, eq. (7))
  ``L = f(x) + eta^T h(x, p) + theta^T Phi(alpha g, beta p)`` in ``(x, p, eta, theta)``; the
  Jacobian is the Hessian of ``L`` (eq. (8)), formed by CasADi.

Grazing contact (``a = b = 0``, e.g. the paper's step ``h = l0``): ``Phi`` has no derivative there
and CasADi's derivative of ``sqrt`` at 0 is NaN. We use an element of Clarke's generalised Jacobian
instead: at ``a^2 + b^2 + 2 mu^2 = 0`` the square root is evaluated as
``sqrt(s + 1) - 1`` (same value, 0), whose derivatives are ``dPhi/da = dPhi/db = -1`` and whose
second derivatives are finite (Facchinei & Pang, the element with ``(xi, zeta) = (0, 0)``). If
Newton with ``mu = 0`` fails, a smoothing continuation ``mu -> 0`` is run from the last iterate
(:func:`ddcm_casadi.loops.newton.smoothed_newton_solve`; the loops are in
:mod:`ddcm_casadi.loops.active_set`). A projection that lands on the corner
``g = p = 0`` of ``Z_E`` is finished on the biactive branch and accepted only if B-stationary
(see :class:`ddcm_casadi.formulations.ncp.FBSystem`).
Newton is globalised by an Armijo line search on ``0.5 ||r||^2``.

Active-set predictor (option ``active_set_predictor``, on by default). Before Newton, the system
of the pieces the start lies on (``a_i = 0`` or ``b_i = 0`` per pair) is solved, switching the pairs
whose other sign is violated (a primal-dual active-set iteration). For a linear model each piece
system is linear with a constant matrix, factorised once per active set and cached: along a load
path, and between DDCM iterations, a solve is then two triangular solves. A predicted solution is
accepted only if it is strictly complementary (or a B-stationary corner): it then solves the FB
system exactly, since at ``a = 0 < b`` ``Phi = 0`` and ``grad Phi = -grad a``. Otherwise Newton runs
as without the predictor.
"""

from __future__ import annotations

from dataclasses import dataclass

from ddcm_casadi.inputs import one_of
from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.loops.active_set import ActiveSetSolver
from ddcm_casadi.loops.newton import SMOOTHING

from .base import BuiltFormulation, Formulation, LocalSolution, option_label, positive_option
from .friction import BuiltCoulomb
from .ncp import FBSystem, fischer_burmeister  # noqa: F401  (re-exported)
from .registry import register


@register
class FischerBurmeister(Formulation):
    """Fischer-Burmeister complementarity function with semismooth Newton."""

    name = "fischer_burmeister"
    title = "Fischer-Burmeister"
    supported_contact_laws = frozenset({"signorini", "coulomb"})

    @dataclass(frozen=True)
    class Options:
        """Options.

        alpha : float or None
            Gap scaling ``alpha`` (1/m); ``None``: the paper's ``100 m^-1`` for ``l0 = 1 m``
            (``1 / (0.01 l0)``).
        beta : float or None
            Pressure scaling ``beta`` (1/Pa); ``None``: ``1/c`` (the paper's choice).
        tol : float
            Relative-increment tolerance of Newton (the paper: 1e-9).
        residual_tol : float
            Tolerance on the scaled residual ``||r||_inf``.
        max_iter : int
            Newton iterations per solve.
        smoothing : tuple of float
            ``mu`` values of the fallback smoothing continuation (ends with 0).
        comp_tol : float
            A solve counts as converged only if ``max |min(g, p)| <= comp_tol`` (scaled) as well.
        active_set_predictor : bool
            Before Newton, solve the system of the pieces the start lies on (``a_i = 0`` where
            ``a_i <= b_i``, else ``b_i = 0``) with a factorisation cached per active set, switching
            the pairs whose other sign is violated; accepted only if strictly complementary or a
            B-stationary corner (see :class:`ddcm_casadi.formulations.ncp.FBSystem`).
        coulomb_function : {"fischer_burmeister", "natural_map"}
            With Coulomb friction: the second-order-cone FB function on De Saxce's modified slip,
            or the natural map ``r - P_K(r - u_hat)`` (a min-type function;
            :mod:`ddcm_casadi.formulations.friction`).
        """

        alpha: float | None = None
        beta: float | None = None
        tol: float = 1e-9
        residual_tol: float = 1e-9
        max_iter: int = 50
        smoothing: tuple = SMOOTHING
        comp_tol: float = 1e-9
        active_set_predictor: bool = True
        coulomb_function: str = "fischer_burmeister"

    def _validate(self) -> None:
        super()._validate()
        for k in ("alpha", "beta", "tol", "residual_tol", "comp_tol"):
            positive_option(self.name, k, getattr(self.options, k))
        one_of(self.options.coulomb_function, option_label(self.name, "coulomb_function"),
               ("fischer_burmeister", "natural_map"))

    def _build(self, problem: ComplementarityProblem) -> BuiltFormulation:
        o = self.options
        if problem.frictional:
            return BuiltCoulomb(problem, o.coulomb_function, (o.alpha or problem.fb_alpha) * problem.gap_ref,
                                (o.beta or problem.fb_beta) * problem.pressure_ref, tol=o.tol,
                                residual_tol=o.residual_tol, max_iter=o.max_iter, comp_tol=o.comp_tol,
                                predictor=o.active_set_predictor)
        return _BuiltFB(problem, o)


class _BuiltFB(BuiltFormulation):
    def __init__(self, problem: ComplementarityProblem, opts: FischerBurmeister.Options) -> None:
        super().__init__(problem)
        self.opts = opts
        self.system = FBSystem(problem, (opts.alpha or problem.fb_alpha) * problem.gap_ref,
                               (opts.beta or problem.fb_beta) * problem.pressure_ref)
        self.solver = ActiveSetSolver(self.system, predictor=opts.active_set_predictor)

    def newton_system(self):
        return self.system.newton_system("fischer_burmeister")

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
        if sol.converged and sol.complementarity > self.opts.comp_tol:
            sol.converged, sol.message = False, f"complementarity {sol.complementarity:.1e} > comp_tol"
        return sol
