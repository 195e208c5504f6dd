r"""Coulomb friction in every formulation: the per-contact functions and their Newton systems.

A frictional problem (:attr:`~ddcm_casadi.problems.contract.ComplementarityProblem.block`
``b = 1 + (d - 1)``) carries per contact ``c`` the scaled normal gap and tangential slip
``u_c = (g_N, s_T)`` and the scaled pressure and tangential traction ``r_c = (p_N, r_T)``
(:mod:`ddcm_casadi.models.coulomb`). Coulomb's law is not a potential: a classical frictional
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
penalty (:func:`compliant_gaps`)
    ``b_N = k [-a_N]_+`` and the return map ``b_T = P_{B(mu b_N)}(b_T^0 - k a_T)`` from the last
    converged step's traction ``b_T^0`` (the stick spring's elastic predictor, then the return
    onto the cone). This is exactly Coulomb's law on the *compliant* gap and slip
    ``a_N + b_N / k`` and ``a_T + (b_T - b_T^0) / k`` (stick: the spring's slip is the whole
    slip; slip: the traction on the cone opposes the compliant slip), so the penalty is solved
    as Alart--Curnier's function of those, with the same predictor.

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

from ddcm_casadi.factor_updates import UpdatingFactors
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


def compliant_gaps(problem: ComplementarityProblem, stiffness: float) -> Affine:
    """The penalty's compliant gaps and slips ``g + p / k`` and ``s + (r_T - r_T^0) / k``
    (scaled; ``k`` the scaled penalty stiffness, ``r_T^0`` the parameter ``traction0`` in Pa)."""
    nc, npairs = problem.n_contacts, problem.n_pairs
    P = problem.parameters
    t0 = sp.csr_matrix((np.full(npairs - nc, -1.0 / (stiffness * problem.pressure_ref)),
                        (np.arange(nc, npairs), P.slice("traction0").start + np.arange(npairs - nc))),
                       shape=(npairs, P.size))
    return problem.gap_map + problem.pressure_map / stiffness + Affine(sp.csr_matrix((npairs, problem.n_x + npairs)), t0)


#: The per-contact functions by name (the ``coulomb_function`` options choose among them).
FUNCTIONS: dict[str, Callable] = {
    "alart_curnier": alart_curnier, "natural_map": natural_map,
    "fischer_burmeister": fischer_burmeister_cone,
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
    :mod:`ddcm_casadi.models.coulomb`), so the last is the Scholtes relaxation of the cone
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


def coulomb_branch(a: list, r: list, mu, is_open, is_stick, is_corner=0) -> list:
    """The ``b`` equations of one contact on one branch of Coulomb's law (``is_open``,
    ``is_stick``, ``is_corner``: 0/1 per contact; none: slip): open ``r = 0``; stick ``u = 0``;
    slip ``g_N = 0`` and ``r_T + mu p_N s_T / |s_T| = 0`` (the traction on the cone's surface
    against the slip, smooth where ``s_T != 0``); the corner ``g_N = 0, r_T = 0`` (closed without
    traction; ``p_N = 0`` is the caller's extra row; an edge is stick with the cone's surface as
    that row). ``if_else`` keeps an unused branch's values
    (the slip direction at ``s_T = 0``) out of the rows and their derivatives."""
    length = norm(a[1:])
    slip = [rt + mu * r[0] * at / (length + (length == 0)) for at, rt in zip(a[1:], r[1:])]
    free = is_open + is_corner
    tangential = [ca.if_else(free, rt, ca.if_else(is_stick, at, st, True), True)
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
    gap : Affine, optional
        The gaps and slips the law holds for (default the problem's; the penalty's compliant ones,
        :func:`compliant_gaps`).

    Parameters of the system (by name): the problem's, then the smoothing ``smoothing``.
    Unknowns: ``x, p`` (classical); ``x, p, eta, theta`` (projection).
    """

    def __init__(self, problem: ComplementarityProblem, function: str, a_scale: float, b_scale: float,
                 gap: Affine | None = None) -> None:
        self.problem = problem
        nx, npairs, ne, b = problem.n_x, problem.n_pairs, problem.n_residual, problem.block
        self.parameters = problem.parameters.extend(smoothing=1)
        if problem.kind == "mcp":
            self.unknowns = Parameters(x=nx, p=npairs)
        else:
            self.unknowns = Parameters(x=nx, p=npairs, eta=ne, theta=npairs)
        S = pair_system(problem, self.unknowns.size, self.parameters)
        a = [S.affine(f"a{j}", a_scale * m) for j, m in enumerate(components(gap or problem.gap_map, b))]
        r = [S.affine(f"b{j}", b_scale * m) for j, m in enumerate(components(problem.pressure_map, b))]
        mu, s = S.parameter("friction"), S.parameter("smoothing")
        psi = FUNCTIONS[function](a, r, mu, s)
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


#: The pieces of a 2-D contact (:class:`CoulombPieces`), each a parameter per contact (``sign``:
#: the slip direction of a slip piece or of a stick-slip corner).
PIECES = ("open", "stick", "sign", "corner", "edge")


class CoulombPieces:
    r"""The active-set predictor of 2-D Coulomb friction: the law is piecewise linear there.

    Per contact one piece, each linear equations in ``(a, b)`` (scaled gap and slip, pressure and
    traction):

    - open: ``b_N = 0, b_T = 0``;
    - stick: ``a_N = 0, a_T = 0``;
    - slip (direction ``s = +-1``): ``a_N = 0, b_T + s mu b_N = 0`` (the traction on the cone,
      opposing the slip);
    - projections only, the two kinds of corner, a third equation with its own multiplier ``nu``
      (``nu = 0`` on the other pieces): the *corner* ``a_N = 0, b_T = 0, b_N = 0`` (closed with no
      pressure) and the *edge* ``a_N = 0, a_T = 0, b_T + s mu b_N = 0`` (sticking on the cone's
      surface, between stick and slip along ``s``).

    The pieces are parameters (:data:`PIECES` per contact), so one system is built; for a linear
    model its Jacobian depends only on the pieces and the friction coefficients, and where a few
    contacts switch piece its few changed rows are solved by a low-rank update of the last
    factorisation (:class:`~ddcm_casadi.factor_updates.UpdatingFactors`).
    The pieces are chosen by Alart--Curnier's rule at the current point (open where
    ``b_N - a_N <= 0``; stick where ``|b_T - a_T| <= mu (b_N - a_N)``; else slip opposite to
    ``b_T - a_T``) and updated from each piece solution until they repeat: a primal-dual
    active-set iteration, i.e. semismooth Newton on Alart--Curnier's function. A piece solution
    whose pieces repeat satisfies the law exactly (each piece's signs are those of its rule).
    In a classical step a frictional contact whose slip reverses between two piece solutions is
    tried on stick next (its slip is about zero; the rule alone can flip it back and forth for
    ever: measured on the Cattaneo-Mindlin cylinder's sideways steps). Projections have their
    edge piece for this instead.
    Classical: ``[F; pieces] = 0``; projection: the KKT system of the distance on the pieces
    (multipliers ``theta``), whose pieces are locally the admissible set wherever the signs hold
    strictly.

    Corners of a projection. A projection often lands on the boundary between two pieces: closed
    with no pressure (the data's zero-stress datum), or sticking with the traction on the cone.
    There the rule flips the contact between the two pieces forever, and the law's function has
    no multiplier. A contact that flips twice is put on the corner (open/closed) or the edge
    (stick/slip) and kept there while the point is B-stationary, with
    ``L = f + eta.h + theta_N rowN + theta_T rowT + nu rowC``:

    - corner: opening it (``a_N > 0``) does not lower ``f`` if ``theta_N <= 0``; pressing it into
      slip along ``s`` (``b_N > 0``, ``b_T = -s mu b_N``) does not if ``nu - s mu theta_T <= 0``;
    - edge: moving into stick (``s b_T + mu b_N > 0``) does not lower ``f`` if ``s nu <= 0``;
      slipping along ``s`` (``s a_T > 0``) does not if ``s theta_T <= 0``;

    else it moves to the piece that lowers ``f``.

    In 3-D the slip piece ``r_T = -mu p_N s_T/|s_T|`` is not linear in the unknowns (its direction
    is one), so there is no finite set of linear pieces: Newton runs there without a predictor.
    """

    def __init__(self, problem: ComplementarityProblem, a_scale: float, b_scale: float,
                 gap: Affine | None = None) -> None:
        nc = problem.n_contacts
        self.problem, self.scales, self.gap = problem, (a_scale, b_scale), gap or problem.gap_map
        self.projection = problem.kind == "mpcc"
        self.parameters = problem.parameters.extend(**{k: nc for k in PIECES})
        if not self.projection:
            self.unknowns = Parameters(x=problem.n_x, p=problem.n_pairs)
        else:
            self.unknowns = Parameters(x=problem.n_x, p=problem.n_pairs, eta=problem.n_residual,
                                       theta=problem.n_pairs, nu=nc)
        S = pair_system(problem, self.unknowns.size, self.parameters)
        (aN, aT), (bN, bT) = ([S.affine(f"{name}{j}", scale * m) for j, m in enumerate(components(M, 2))]
                              for name, scale, M in (("a", a_scale, self.gap),
                                                     ("b", b_scale, problem.pressure_map)))
        mu = S.parameter("friction")
        is_open, stick, sign, corner, edge = (S.parameter(k) for k in PIECES)
        cone = bT + sign * mu * bN
        rows = [is_open * bN + (1 - is_open) * aN,
                (is_open + corner) * bT + (stick + edge) * aT + sign**2 * (1 - edge) * cone]
        if not self.projection:
            self._built = S.mcp("coulomb_pieces", *rows)
        else:
            start = self.unknowns.slice("theta").start
            theta = [S.unknowns(f"theta{j}", start + j * nc) for j in range(2)]
            nu = S.unknowns("nu", self.unknowns.slice("nu").start)
            third = corner * bN + edge * cone
            self._built = S.saddle("coulomb_pieces", rows=rows + [third + (1 - corner - edge) * nu],
                                   lagrangian=theta[0] * rows[0] + theta[1] * rows[1] + nu * third)
        self.factors = UpdatingFactors()

    def start(self, x0, p0, state) -> np.ndarray:
        if not self.projection:
            return self.unknowns.pack(x=x0, p=p0)
        state = state or {}
        return self.unknowns.pack(x=x0, p=p0, eta=state.get("eta", 0.0), theta=state.get("theta", 0.0), nu=0.0)

    def _ab(self, z: np.ndarray, params: np.ndarray):
        problem, nc = self.problem, self.problem.n_contacts
        a_scale, b_scale = self.scales
        xp = np.asarray(z, float)[:problem.n_x + problem.n_pairs]
        a = a_scale * self.gap.value(xp, params)
        b = b_scale * xp[problem.n_x:]
        return a[:nc], a[nc:], b[:nc], b[nc:]

    def pieces(self, z: np.ndarray, params: np.ndarray) -> dict[str, np.ndarray]:
        """:data:`PIECES` per contact by Alart--Curnier's rule at ``z`` (no corners)."""
        aN, aT, bN, bT = self._ab(z, params)
        mu = self.problem.parameters.get(params, "friction")
        pressure, trial = bN - aN, bT - aT
        is_open = pressure <= 0
        stick = ~is_open & (np.abs(trial) <= mu * pressure)
        sign = np.where(is_open | stick, 0.0, -np.sign(trial))
        zero = np.zeros_like(sign)
        return dict(open=is_open.astype(float), stick=stick.astype(float), sign=sign, corner=zero, edge=zero.copy())

    def _corner_moves(self, z: np.ndarray, params: np.ndarray, pieces: dict) -> dict[str, np.ndarray]:
        """Where a corner or an edge is not B-stationary, the piece that lowers the distance
        (see the class): ``to_open``, ``to_stick``, ``to_slip`` and the slip ``direction``."""
        nc = self.problem.n_contacts
        theta, nu = self.unknowns.get(z, "theta"), self.unknowns.get(z, "nu")
        tN, tT = theta[:nc], theta[nc:]
        _, aT, _, _ = self._ab(z, params)
        mu = self.problem.parameters.get(params, "friction")
        tol = 1e-8 * max(1.0, float(np.max(np.abs(np.concatenate([theta, nu])), initial=0.0)))
        corner, edge, s_edge = pieces["corner"] > 0, pieces["edge"] > 0, pieces["sign"]
        s = np.where(aT != 0, np.sign(aT), np.where(tT != 0, -np.sign(tT), 1.0))
        press = nu - s * mu * tT
        to_open = corner & (tN > tol) & (tN >= press)
        corner_slip = corner & ~to_open & (press > tol)
        to_stick = edge & (s_edge * nu > tol) & (s_edge * nu >= s_edge * tT)
        edge_slip = edge & ~to_stick & (s_edge * tT > tol)
        return dict(to_open=to_open, to_stick=to_stick, to_slip=corner_slip | edge_slip,
                    direction=np.where(edge, s_edge, s))

    def solve(self, z: np.ndarray, params: np.ndarray, newton: dict, max_rounds: int = 40):
        """The active-set iteration from ``z``: ``(z, rounds)`` once the pieces repeat, or ``None``."""
        built = self._built
        pieces = self.pieces(z, params)
        nc = self.problem.n_contacts
        flips = dict(corner=np.zeros(nc, int), edge=np.zeros(nc, int))
        for rounds in range(1, max_rounds + 1):
            res = newton_solve(built.rj, built.r, z, self.parameters.pack(params, **pieces), jacobian=built.jacobian,
                               factors=self.factors, **dict(newton, max_iter=4))
            if not res.converged:
                return None
            z = res.z
            new = self.pieces(z, params)
            # a slip that reverses between two piece solutions is about zero: try stick (the rule
            # alone can flip such contacts back and forth for ever)
            mu = self.problem.parameters.get(params, "friction")
            reversed_ = (new["sign"] * pieces["sign"] < 0) & (pieces["edge"] == 0) & (mu > 0) & (not self.projection)
            new["stick"] = np.where(reversed_, 1.0, new["stick"])
            new["sign"] = np.where(reversed_, 0.0, new["sign"])
            if self.projection:
                new = self._with_corners(z, params, pieces, new, flips)
            if all(np.array_equal(new[k], pieces[k]) for k in PIECES):
                return z, rounds
            pieces = new
        return None

    def _with_corners(self, z, params, pieces: dict, new: dict, flips: dict) -> dict:
        """The next pieces of a projection: the rule's, with corners and edges entered after two
        flips and left where B-stationarity fails (see the class)."""
        held = (pieces["corner"] > 0) | (pieces["edge"] > 0)
        moves = self._corner_moves(z, params, pieces)
        was_slip = (pieces["sign"] != 0) & ~held
        flips["corner"] += ((new["open"] != pieces["open"]) & ~held)
        flips["edge"] += (((new["stick"] > 0) & was_slip) | ((new["sign"] != 0) & (pieces["stick"] > 0))) & ~held
        enter_corner = (flips["corner"] >= 2) & ~held
        enter_edge = (flips["edge"] >= 2) & ~held & ~enter_corner
        leave = moves["to_open"] | moves["to_stick"] | moves["to_slip"]
        keep = held & ~leave
        corner = (keep & (pieces["corner"] > 0)) | enter_corner
        edge = (keep & (pieces["edge"] > 0)) | enter_edge
        edge_sign = np.where(enter_edge, np.where(pieces["sign"] != 0, pieces["sign"], new["sign"]), pieces["sign"])
        out = dict(open=np.where(corner | edge, 0.0, np.where(moves["to_open"], 1.0, new["open"])),
                   stick=np.where(corner | edge | moves["to_open"] | moves["to_slip"], 0.0,
                                  np.where(moves["to_stick"], 1.0, new["stick"])),
                   sign=np.where(edge, edge_sign, np.where(corner | moves["to_open"] | moves["to_stick"], 0.0,
                                                           np.where(moves["to_slip"], moves["direction"], new["sign"]))),
                   corner=corner.astype(float), edge=edge.astype(float))
        for kind in ("corner", "edge"):
            flips[kind][enter_corner | enter_edge | leave] = 0
        return out


#: The functions whose Jacobian is piecewise constant for a linear model.
PIECEWISE_CONSTANT = frozenset({"alart_curnier", "natural_map"})

#: Functions whose failed solves are finished on :func:`natural_map` (same roots): the SOC FB
#: function's second derivatives grow without bound where a spectral value of ``x o x + y o y``
#: vanishes (a contact at the cone's apex or a sticking contact with zero traction), so that the
#: projection's saddle-point Newton often converges only with smoothing there.
POLISHED = frozenset({"fischer_burmeister", "alart_curnier"})


class BuiltCoulomb(BuiltFormulation):
    """A frictional problem built for one per-contact function, solved by semismooth Newton with a
    line search and, where plain Newton fails, the smoothing continuation
    :data:`FRICTION_SMOOTHING`, with Newton's relative-increment ``tol``, ``residual_tol`` and
    ``max_iter``; an exact function's solve counts as converged only if the natural-map residual of
    the law is at most ``comp_tol`` (scaled)."""

    def __init__(self, problem: ComplementarityProblem, function: str, a_scale: float, b_scale: float, *,
                 tol: float, residual_tol: float, max_iter: int, comp_tol: float,
                 compliance: float | None = None, penalty_stiffness: float | None = None,
                 predictor: bool = False) -> None:
        super().__init__(problem)
        self.gap = None if compliance is None else compliant_gaps(problem, compliance)
        # the functions share their roots, and in 2-D those are piecewise linear
        self.pieces = (CoulombPieces(problem, a_scale, b_scale, self.gap)
                       if predictor and problem.block == 2 and problem.affine else None)
        self.newton = dict(tol=tol, residual_tol=residual_tol, max_iter=max_iter)
        self.comp_tol = comp_tol
        self.function = function
        self.system = CoulombSystem(problem, function, a_scale, b_scale, self.gap)
        self.penalty_stiffness = penalty_stiffness
        self._stats = dict(solves=0, predicted=0, smoothed=0, polished=0)
        self._scales = (a_scale, b_scale)
        self._polish: CoulombSystem | None = None
        self._factors = UpdatingFactors()

    def newton_system(self):
        return self.system.newton_system()

    def newton_point(self, params, x, p, state=None):
        return self.system.start(x, p, state), self.system.parameters.pack(params, smoothing=0.0)

    def _law_residual(self, sol: LocalSolution, params: np.ndarray) -> float:
        """The natural-map residual of the law the formulation enforces: Coulomb's on the problem's
        gaps (the solution's ``complementarity``), or on the penalty's compliant ones."""
        if self.gap is None:
            return sol.complementarity
        gap = self.gap.value(np.concatenate([sol.x, sol.p]), params)
        return float(np.max(np.abs(self.problem.coulomb_residual(gap, sol.p, params)), initial=0.0))

    def _polished(self, res, params, kw):
        """Newton on the natural map's system from the last (smoothed) iterate: the same roots,
        without the SOC function's unbounded second derivatives (:data:`POLISHED`). Returns the
        better of the two results and the smoothing to report (0 if polished)."""
        if self._polish is None:
            self._polish = CoulombSystem(self.problem, "natural_map", *self._scales, self.gap)
        built = self._polish._built
        kw = dict(kw, jacobian=built.jacobian, factors=UpdatingFactors())
        trial = newton_solve(built.rj, built.r, res.z, self._polish.parameters.pack(params, smoothing=0.0), **kw)
        if not trial.converged:
            return res, 0.0
        self._stats["polished"] += 1
        trial.iterations += res.iterations
        trial.message = f"{trial.message} (finished on the natural map)"
        return trial, 0.0

    @property
    def stats(self) -> dict:
        return dict(self._stats)

    def solve(self, params, x0, p0, state=None) -> LocalSolution:
        system = self.system
        built = system._built
        P = system.parameters
        # Alart-Curnier's and the natural map's Jacobians are piecewise constant: successive Newton
        # steps differ in a few contacts' rows, solved by low-rank updates; the SOC FB function's
        # change in every closed contact's rows at every step (measured on the 3-D sphere: the
        # updates cost it more than they saved)
        factors = self._factors if self.function in PIECEWISE_CONSTANT else None
        kw = dict(jacobian=built.jacobian, factors=factors, **self.newton)
        z0 = system.start(x0, p0, state)
        if self.pieces is not None:
            pieces = self.pieces
            predicted = pieces.solve(pieces.start(x0, p0, state), params, self.newton)
            if predicted is not None:
                zp, get = predicted[0], pieces.unknowns.get
                warm = {} if self.problem.kind == "mcp" else dict(eta=get(zp, "eta"), theta=get(zp, "theta"))
                sol = self._finish(get(zp, "x"), get(zp, "p"), params, converged=True, iterations=predicted[1],
                                   state=warm, message="converged (active-set predictor)")
                if self._law_residual(sol, params) <= self.comp_tol:
                    self._stats["solves"] += 1
                    self._stats["predicted"] += 1
                    return sol
        res = newton_solve(built.rj, built.r, z0, P.pack(params, smoothing=0.0), **kw)
        s_used, stages = 0.0, 0
        if not res.converged and self.function in POLISHED:
            res, _ = self._polished(res, params, kw)
        if not res.converged:
            self._stats["smoothed"] += 1
            res, s_used, stages = smoothed_newton_solve(built.rj, built.r, z0, lambda v: P.pack(params, smoothing=v),
                                                        smoothing=FRICTION_SMOOTHING, try_plain=False, **kw)
            if not res.converged and self.function in POLISHED:
                res, s_used = self._polished(res, params, kw)
        self._stats["solves"] += 1
        z = res.z
        x, p = system.unknowns.get(z, "x"), system.unknowns.get(z, "p")
        sol = self._finish(x, p, params, converged=res.converged, iterations=res.iterations, outer=stages,
                           state=system.state(z), message=res.message + (f" (smoothing {s_used:g})" if s_used else ""))
        residual = self._law_residual(sol, params)
        if sol.converged and residual > self.comp_tol:
            sol.converged, sol.message = False, f"Coulomb residual {residual:.1e} > comp_tol"
        return sol
