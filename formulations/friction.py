r"""Coulomb friction in every formulation: the per-contact functions and their Newton systems.

A frictional problem (:attr:`~ddcm_casadi.problems.contract.ComplementarityProblem.block`
``b = 1 + (d - 1)``) carries per contact ``c`` the scaled normal gap and tangential slip
``u_c = (g_N, s_T)`` and the scaled pressure and tangential traction ``r_c = (p_N, r_T)``
(:mod:`ddcm_casadi.problems.coulomb`). Coulomb's law is not a potential: a classical frictional
step is a root of a nonsmooth system, not the minimum of an energy, and a data-driven step is
a stationary point (a KKT point) of the distance to the data over the frictional admissible set.
Each formulation writes the law as ``b`` equations per contact, ``Psi(a, b_) = 0`` with
``a = alpha u``, ``b_ = beta r`` (the cone conditions are invariant under positive scalings of
``u`` and ``r``):

Alart--Curnier (the augmented Lagrangian, :func:`alart_curnier`)
    ``b_N - [b_N - a_N]_+ = 0``, ``b_T - P_{B(mu [b_N - a_N]_+)}(b_T - a_T) = 0``: the normal
    pair's min-function and the tangential traction projected onto the disc of the augmented
    normal pressure (the fixed point of an augmented Lagrangian's multiplier update).
natural map (:func:`natural_map`)
    ``b_ - P_{K_mu}(b_ - \hat a) = 0`` with De Saxcé's ``\hat a = a + mu |a_T| e_N``.
Fischer--Burmeister on the second-order cone (:func:`fischer_burmeister_cone`)
    With ``x = (mu b_N, b_T)`` and ``y = (\hat a_N, mu a_T)`` (the maps that take ``K_mu`` and
    ``K_mu^*`` onto the Lorentz cone ``L = {|v_T| <= v_N}``, keeping ``x . y = mu r . \hat u``),
    ``x + y - (x o x + y o y)^{1/2} = 0`` with the Jordan product ``x o y = (x . y, x_N y_T + y_N x_T)``
    and the square root by the spectral decomposition ``w = l_1 e_1 + l_2 e_2``,
    ``l_{1,2} = w_N -+ |w_T|``. It vanishes exactly when ``x in L, y in L, x . y = 0`` (Fukushima,
    Luo and Tseng, 2002). At ``mu = 0`` the maps degenerate; there the contact is frictionless and
    the equations are the scalar FB function of ``(a_N, b_N)`` and ``b_T = 0``.
penalty (:func:`penalty_law`)
    ``b_N = k [-a_N]_+`` and the return map ``b_T = P_{B(mu b_N)}(b_T^0 - k_T a_T)`` from the last
    converged step's traction ``b_T^0`` (the stick spring's elastic predictor, then the return
    onto the cone).

The classical system is ``[F(x, p); Psi] = 0`` in ``(x, p)``; the DDCM projection's is the
stationarity of ``f + eta^T h + theta^T Psi`` with ``Psi = 0`` (a saddle point, as for the
frictionless pairs). Both are solved by semismooth Newton with a line search, and where plain
Newton fails by a smoothing continuation (``|v| -> sqrt(|v|^2 + s^2)``, ``[t]_+`` smoothed,
:func:`~ddcm_casadi.loops.newton.smoothed_newton_solve`).

The MPCC formulation (IPOPT) writes the law as smooth constraints instead
(:func:`coulomb_constraints`, :func:`coulomb_branch`).
"""

from __future__ import annotations

from typing import Callable

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ddcm_casadi.loops.newton import newton_solve, plus, smoothed_newton_solve
from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.problems.maps import Affine
from ddcm_casadi.problems.parameters import Parameters

from .base import BuiltFormulation, LocalSolution
from .pairs import NewtonSystem
from .systems import pair_system

#: Smoothing values of the fallback continuation (ends with 0: the law itself).
FRICTION_SMOOTHING = (1e-2, 1e-4, 1e-6, 1e-8, 0.0)


# ------------------------------------------------------------------------ per-contact maths (SX)
def norm(v: list, s=0.0):
    """``sqrt(|v|^2 + s^2)`` with a finite generalised derivative (zero) at ``v = 0, s = 0``."""
    q = sum(vi**2 for vi in v) + s**2
    origin = q == 0
    return ca.sqrt(q + origin) - origin


def project_disc(v: list, radius, s=0.0) -> list:
    """``v`` projected onto the disc ``|v| <= radius`` (``radius >= 0``)."""
    n = norm(v, s)
    bound = ca.fmax(radius, n)
    factor = radius / (bound + (bound == 0))
    return [factor * vi for vi in v]


def project_cone(y: list, mu, s=0.0) -> list:
    """``y = (y_N, y_T)`` projected onto ``K_mu = {|y_T| <= mu y_N}``: the apex in the polar cone,
    ``y`` inside, else ``t (1, mu y_T/|y_T|)`` with ``t = (y_N + mu |y_T|) / (1 + mu^2)``."""
    yn, yt = y[0], list(y[1:])
    t = norm(yt, s)
    onto = (yn + mu * t) / (1 + mu**2)
    unit = [v / (t + (t == 0)) for v in yt]
    polar, inside = mu * t <= -yn, t <= mu * yn
    out_n = ca.if_else(polar, 0, ca.if_else(inside, yn, onto))
    out_t = [ca.if_else(polar, 0, ca.if_else(inside, v, mu * onto * e)) for v, e in zip(yt, unit)]
    return [out_n] + out_t


def alart_curnier(a: list, b: list, mu, s=0.0, **_) -> list:
    """Alart--Curnier's equations (see the module)."""
    augmented = plus(b[0] - a[0], s)
    trial = [bt - at for at, bt in zip(a[1:], b[1:])]
    tangential = project_disc(trial, mu * augmented, s)
    return [b[0] - augmented] + [bt - pt for bt, pt in zip(b[1:], tangential)]


def natural_map(a: list, b: list, mu, s=0.0, **_) -> list:
    """``b - P_K(b - a_hat)`` with De Saxcé's ``a_hat`` (see the module)."""
    ahat = [a[0] + mu * norm(a[1:], s)] + list(a[1:])
    projected = project_cone([bi - ai for ai, bi in zip(ahat, b)], mu, s)
    return [bi - pi for bi, pi in zip(b, projected)]


def _lorentz_fb(x: list, y: list, s) -> list:
    """``x + y - (x o x + y o y + 2 s^2 e)^{1/2}`` on the Lorentz cone (spectral square root)."""
    wn = sum(v**2 for v in x) + sum(v**2 for v in y) + 2 * s**2
    wt = [2 * (x[0] * xt + y[0] * yt) for xt, yt in zip(x[1:], y[1:])]
    nt = norm(wt)
    root = [ca.sqrt(ca.fmax(lam, 0) + (lam <= 0)) - (lam <= 0) for lam in (wn - nt, wn + nt)]
    unit = [v / (nt + (nt == 0)) for v in wt]
    sqrt_w = [(root[0] + root[1]) / 2] + [(root[1] - root[0]) / 2 * e for e in unit]
    return [xi + yi - ri for xi, yi, ri in zip(x, y, sqrt_w)]


def fischer_burmeister_cone(a: list, b: list, mu, s=0.0, **_) -> list:
    """The second-order-cone FB function on De Saxcé's modified slip (see the module)."""
    ahat_n = a[0] + mu * norm(a[1:], s)
    cone = _lorentz_fb([mu * b[0]] + list(b[1:]), [ahat_n] + [mu * v for v in a[1:]], s)
    q = a[0]**2 + b[0]**2 + 2 * s**2
    origin = q == 0
    frictionless = [ca.sqrt(q + origin) - origin - a[0] - b[0]] + list(b[1:])
    return [ca.if_else(mu > 0, c, f) for c, f in zip(cone, frictionless)]


def penalty_law(a: list, b: list, mu, s=0.0, *, stiffness=1.0, tangential_stiffness=1.0, traction0=()) -> list:
    """``b_N - k [-a_N]_+`` and ``b_T - P_{B(mu b_N)}(b_T^0 - k_T a_T)`` (see the module)."""
    pressure = stiffness * plus(-a[0], s)
    trial = [t0 - tangential_stiffness * at for t0, at in zip(traction0, a[1:])]
    tangential = project_disc(trial, mu * pressure, s)
    return [b[0] - pressure] + [bt - pt for bt, pt in zip(b[1:], tangential)]


#: The per-contact functions by name (the ``coulomb_function`` options choose among them).
FUNCTIONS: dict[str, Callable] = {
    "alart_curnier": alart_curnier, "natural_map": natural_map,
    "fischer_burmeister": fischer_burmeister_cone, "penalty": penalty_law,
}


def cone_traction(p_n, direction: list, mu) -> list:
    """The traction ``r = (p_N, mu p_N rho)`` of a normal pressure ``p_N >= 0`` and a friction
    direction ``|rho| <= 1``: in the cone ``K_mu`` by construction, also at ``mu = 0``."""
    return [p_n] + [mu * p_n * v for v in direction]


def coulomb_constraints(a: list, r: list, direction: list, mu, tau) -> list:
    r"""Coulomb's law as smooth inequalities ``>= 0`` for an NLP solver, relaxed by ``tau > 0``.

    With ``u = (g_N, s_T)`` and the traction ``r = (p_N, mu p_N rho)`` of :func:`cone_traction`
    (a bound ``p_N >= 0``), and ``|s_T|_tau = sqrt(|s_T|^2 + tau^2) - tau`` (smooth, ``0 <= |s_T| -
    |s_T|_tau <= tau``):

    .. math::  g_N \ge 0,\qquad 1 - |\rho|^2 \ge 0,\qquad
               \tau - \bigl(p_N (g_N + \mu |s_T|_\tau) + r_T \cdot s_T\bigr) \ge 0 .

    The first two say ``u_hat in K_mu^*`` and ``r in K_mu``; the bracket is
    ``r . u_hat - mu p_N (|s_T| - |s_T|_tau)`` (De Saxcé's ``u_hat = u + mu |s_T| e_N``,
    :mod:`ddcm_casadi.problems.coulomb`), so the last is the Scholtes relaxation of the cone
    complementarity ``r . u_hat = 0``: every solution of Coulomb's law satisfies it, a point that
    does has ``0 <= r . u_hat <= tau (1 + mu p_N)``, and ``tau -> 0`` gives exactly the law, as
    ``g p <= tau`` does for the normal pairs. Every function is smooth for ``tau > 0`` (no
    ``|s_T|`` at stick), and ``r = (p_N, mu p_N rho)`` keeps an interior at ``mu = 0`` (then
    ``r_T = 0``). Measured against the viscous form ``r_T sqrt(|s_T|^2 + tau^2) + mu p_N s_T = 0``
    and a lifted ``|s_T|`` in :mod:`ddcm_casadi.formulations.mpcc`.
    """
    slip = ca.sqrt(sum(v**2 for v in a[1:]) + tau**2) - tau
    dissipation = r[0] * (a[0] + mu * slip) + sum(rt * at for rt, at in zip(r[1:], a[1:]))
    return [a[0], 1 - sum(v**2 for v in direction), tau - dissipation]


def coulomb_branch(a: list, r: list, mu, is_open, is_stick) -> list:
    """The ``b`` equations of one contact on one branch of Coulomb's law (``is_open``,
    ``is_stick``: 0/1 per contact; neither: slip): open ``r = 0``; stick ``u = 0``; slip
    ``g_N = 0`` and ``r_T + mu p_N s_T / |s_T| = 0`` (the traction on the cone's surface against
    the slip, smooth where ``s_T != 0``). ``if_else`` keeps an unused branch's values (the slip
    direction at ``s_T = 0``) out of the rows and their derivatives."""
    length = norm(a[1:])
    slip = [rt + mu * r[0] * at / (length + (length == 0)) for at, rt in zip(a[1:], r[1:])]
    tangential = [ca.if_else(is_open, rt, ca.if_else(is_stick, at, st, True), True)
                  for at, rt, st in zip(a[1:], r[1:], slip)]
    return [ca.if_else(is_open, r[0], a[0], True)] + tangential


# ------------------------------------------------------------------------ systems
def components(A: Affine, block: int) -> list[Affine]:
    """The rows of a component-major map, one :class:`Affine` per component."""
    nc = A.rows // block
    return [Affine(A.z[j * nc:(j + 1) * nc], A.params[j * nc:(j + 1) * nc]) for j in range(block)]


class CoulombSystem:
    """The Newton system of one per-contact function ``Psi`` (see the module) for a frictional
    problem, built once.

    Parameters
    ----------
    problem : ComplementarityProblem
        Frictional (``block > 1``), small kinematics.
    function : str
        A key of :data:`FUNCTIONS`.
    a_scale, b_scale : float
        ``a = a_scale u``, ``b = b_scale r`` (scaled units).
    law_options : dict
        Keyword arguments of the function other than the traction history (the penalty's
        stiffnesses, in ``b``-units per ``a``-unit).

    Parameters of the system (by name): the problem's, then the smoothing ``smoothing``.
    Unknowns: ``x, p`` (classical); ``x, p, eta, theta`` (projection).
    """

    def __init__(self, problem: ComplementarityProblem, function: str, a_scale: float, b_scale: float,
                 law_options: dict | None = None) -> None:
        self.problem = problem
        nx, npairs, ne, b = problem.n_x, problem.n_pairs, problem.n_residual, problem.block
        self.parameters = problem.parameters.extend(smoothing=1)
        if problem.kind == "mcp":
            self.unknowns = Parameters(x=nx, p=npairs)
        else:
            self.unknowns = Parameters(x=nx, p=npairs, eta=ne, theta=npairs)
        S = pair_system(problem, self.unknowns.size, self.parameters)
        a = [S.affine(f"a{j}", a_scale * m) for j, m in enumerate(components(problem.gap_map, b))]
        r = [S.affine(f"b{j}", b_scale * m) for j, m in enumerate(components(problem.pressure_map, b))]
        mu, s = S.parameter("friction"), S.parameter("smoothing")
        options = dict(law_options or {})
        if function == "penalty":
            nc, P0 = problem.n_contacts, problem.parameters
            start = P0.slice("traction0").start
            options["traction0"] = [S.local(f"t0_{j}", None, sp.csr_matrix(
                (np.full(nc, b_scale), (np.arange(nc), start + j * nc + np.arange(nc))), shape=(nc, P0.size)))
                for j in range(b - 1)]
        psi = FUNCTIONS[function](a, r, mu, s, **options)
        if problem.kind == "mcp":
            built = S.mcp(f"coulomb_{function}", *psi)
        else:
            theta = [S.unknowns(f"theta{j}", self.unknowns.slice("theta").start + j * problem.n_contacts)
                     for j in range(b)]
            built = S.saddle(f"coulomb_{function}", lagrangian=sum(t * e for t, e in zip(theta, psi)), rows=psi)
        self._built = built
        self.name = f"coulomb ({function})"

    def newton_system(self) -> NewtonSystem:
        return NewtonSystem(self.name, self.unknowns, self.parameters, self._built)

    def start(self, x0, p0, state) -> np.ndarray:
        if self.problem.kind == "mcp":
            return self.unknowns.pack(x=x0, p=p0)
        state = state or {}
        return self.unknowns.pack(x=x0, p=p0, eta=state.get("eta", 0.0), theta=state.get("theta", 0.0))

    def state(self, z: np.ndarray) -> dict:
        if self.problem.kind == "mcp":
            return {}
        return dict(eta=self.unknowns.get(z, "eta"), theta=self.unknowns.get(z, "theta"))


class BuiltCoulomb(BuiltFormulation):
    """A frictional problem built for one per-contact function, solved by semismooth Newton with a
    line search and, where plain Newton fails, the smoothing continuation
    :data:`FRICTION_SMOOTHING`, with Newton's relative-increment ``tol``, ``residual_tol`` and
    ``max_iter``; an exact function's solve counts as converged only if the natural-map residual of
    the law is at most ``comp_tol`` (scaled)."""

    def __init__(self, problem: ComplementarityProblem, function: str, a_scale: float, b_scale: float, *,
                 tol: float, residual_tol: float, max_iter: int, comp_tol: float,
                 law_options: dict | None = None, penalty_stiffness: float | None = None) -> None:
        super().__init__(problem)
        self.newton = dict(tol=tol, residual_tol=residual_tol, max_iter=max_iter)
        self.comp_tol = comp_tol
        self.function = function
        self.system = CoulombSystem(problem, function, a_scale, b_scale, law_options)
        self.penalty_stiffness = penalty_stiffness
        self._stats = dict(solves=0, smoothed=0)

    def newton_system(self):
        return self.system.newton_system()

    def newton_point(self, params, x, p, state=None):
        return self.system.start(x, p, state), self.system.parameters.pack(params, smoothing=0.0)

    @property
    def stats(self) -> dict:
        return dict(self._stats)

    def solve(self, params, x0, p0, state=None) -> LocalSolution:
        system = self.system
        built = system._built
        P = system.parameters
        kw = dict(jacobian=built.jacobian, **self.newton)
        z0 = system.start(x0, p0, state)
        res = newton_solve(built.rj, built.r, z0, P.pack(params, smoothing=0.0), **kw)
        s_used, stages = 0.0, 0
        if not res.converged:
            self._stats["smoothed"] += 1
            res, s_used, stages = smoothed_newton_solve(built.rj, built.r, z0, lambda v: P.pack(params, smoothing=v),
                                                        smoothing=FRICTION_SMOOTHING, try_plain=False, **kw)
        self._stats["solves"] += 1
        z = res.z
        x, p = system.unknowns.get(z, "x"), system.unknowns.get(z, "p")
        sol = self._finish(x, p, params, converged=res.converged, iterations=res.iterations, outer=stages,
                           state=system.state(z), message=res.message + (f" (smoothing {s_used:g})" if s_used else ""))
        if sol.converged and self.penalty_stiffness is None and sol.complementarity > self.comp_tol:
            sol.converged, sol.message = False, f"Coulomb residual {sol.complementarity:.1e} > comp_tol"
        return sol
