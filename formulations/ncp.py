"""Fischer-Burmeister NCP function and the Newton systems built on it (shared by formulations).

``Phi(a, b) = sqrt(a^2 + b^2) - a - b`` vanishes exactly when ``a >= 0, b >= 0, a b = 0``.
This module only *builds* the systems (CasADi Functions with named parameters, from the problem's
sparse matrices and one pair's expressions: :class:`~ddcm_casadi.formulations.pairs.PairSystem`);
the loops that solve them (predictor, semismooth Newton, corner polish, smoothing, branch finish)
are in :mod:`ddcm_casadi.loops.active_set`.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.problems.maps import Affine
from ddcm_casadi.problems.parameters import Parameters

from .pairs import NewtonSystem
from .systems import pair_system


def fischer_burmeister(a, b, mu=0.0):
    """``sqrt(a^2 + b^2 + 2 mu^2) - a - b`` with a finite generalised derivative at the origin."""
    s = a**2 + b**2 + 2 * mu**2
    origin = s == 0
    return ca.sqrt(s + origin) - origin - a - b


def _saddle_terms(first, b, theta, nu, sel, target=0) -> dict:
    """The projection's saddle-point system (:meth:`PairSystem.saddle`) with the pair equations
    ``first = target`` (multiplier ``theta``) and, on the corner pairs ``sel``, ``b = 0``
    (multiplier ``nu``; ``nu = 0`` elsewhere): the stationarity of
    ``f + eta.h + theta.first + nu.(sel b)`` in ``(x, p)``, ``h``, ``first - target`` and
    ``sel b + (1 - sel) nu``, all per pair. The FB system and its piece systems differ only in
    ``first``."""
    return dict(lagrangian=theta * first + nu * sel * b, rows=(first - target, sel * b + (1 - sel) * nu))


class FBSystem:
    """Newton system of the Fischer-Burmeister reformulation of a problem's pairs (built once).

    The pairs are ``a = a_scale * gap`` and ``b = b_scale * p`` (scaled units). ``gap`` may be
    replaced (the penalty passes the compliant gap ``g + p / gamma``). With ``proximal=True`` (the
    augmented Lagrangian) the ``Phi`` block of the DDCM system becomes
    ``Phi - (theta - lam) / rho = 0``, the primal-dual form of minimising
    ``f + lam Phi + rho/2 Phi^2``: its level sets ``Phi = s != 0`` are smooth.

    Corners. A projection that lands on the corner ``a = b = 0`` of ``Z_E`` (common: every datum in
    the corner's normal cone projects there) needs an unbounded ``theta`` in the saddle-point
    system, and Newton only creeps towards it. The DDCM system therefore carries a selector
    ``s_i in {0, 1}`` per pair (a parameter, so nothing is rebuilt): where ``s_i = 1`` the equation
    ``Phi_i = 0`` is replaced by the two equations ``a_i = 0`` and ``b_i = 0`` with multipliers
    ``theta_i`` and ``nu_i`` (the biactive branch); elsewhere ``nu_i = 0``. A corner found by
    plain Newton is accepted only if it is B-stationary, ``theta_i <= 0`` and ``nu_i <= 0``
    (a local minimum on both branches).

    Branch finish. Near a pair on one branch with a tiny partner (``a = 0 < b << 1``) ``Phi``
    rounds its corner at the scale ``b``, the Hessian grows like ``theta / b`` and Newton stalls at
    its roundoff floor or needs smoothing; with many pairs this happens often. When everything
    else fails, the DDCM system is finished by a primal-dual active-set iteration on the pieces of
    ``Z_E``: each pair is put on the branch its iterate lies on (``a_i = 0`` where ``a_i <= b_i``,
    else ``b_i = 0``), Newton solves that smooth KKT system, pairs whose other sign is violated
    switch branch, until the signs hold. A strictly complementary result is a KKT point of a convex
    piece that solves the ``Phi`` system exactly (there ``grad Phi = -grad a_i`` or ``-grad b_i``,
    so ``theta`` is the same multiplier); biactive pairs go to the corner polish.

    Active-set predictor (``predictor=True``). Between DDCM iterations only
    the assigned data change, and between load steps only the loads; the active set mostly stays.
    Before semismooth Newton, the system of the piece the start lies on is solved (the branch
    system above; for ``mcp``, ``F = 0`` with ``a_i = 0`` or ``b_i = 0``). For a linear model its
    Jacobian does not depend on the unknowns or the parameters, so its LU factorisation is computed
    once per active set and reused (a few are cached): a solve is then two triangular solves (the
    second one refines roundoff and gives Newton's increment test). Pairs whose other sign is
    violated switch piece (a primal-dual active-set iteration, as in the branch finish). A result
    is accepted only if every pair is strictly complementary with the right signs (then it is an
    exact root of the system Newton solves, see the branch finish) or it is a B-stationary corner.
    The FB residual is not re-evaluated there: its stationarity rows carry
    ``theta * (a / sqrt(a^2 + b^2) - 1)``, whose roundoff at ``a = 0 < b`` times a large ``theta``
    can exceed ``residual_tol`` (measured: 9e-9 on a 100-panel truss, where Newton therefore needs
    300 iterations and the branch finish). Otherwise semismooth Newton runs from the original
    start, as without the predictor.

    Parameters (:attr:`parameters`, by name): the problem's, then ``lam`` and ``rho`` (proximal
    only), the smoothing ``mu`` and, for projections, the corner selector ``corner``. The caller
    supplies the *base* (:attr:`base_parameters`: the problem's and the proximal ones) and
    :meth:`pack` adds the rest.
    """

    def __init__(self, problem: ComplementarityProblem, a_scale: float, b_scale: float, *,
                 gap: Affine | None = None, proximal: bool = False) -> None:
        self.problem = problem
        self.proximal = bool(proximal)
        gap = problem.gap_map if gap is None else gap
        nc, nx, ne = problem.n_pairs, problem.n_x, problem.n_residual
        self.nc = nc
        base = problem.parameters.extend(lam=nc, rho=1) if proximal else problem.parameters
        self.base_parameters = base
        # The pair arguments a = a_scale gap, b = b_scale p, affine in [x; p].
        self._a, self._b = a_scale * gap, b_scale * problem.pressure_map
        if problem.kind == "mcp":
            if proximal:
                raise ValueError("the proximal FB system is for projections (mpcc) only")
            P = base.extend(mu=1)
            self.unknowns = Parameters(x=nx, p=nc)
            S = pair_system(problem, self.unknowns.size, P)
            a, b = S.affine("a", self._a), S.affine("b", self._b)
            phi = fischer_burmeister(a, b, S.parameter("mu"))
            built = S.mcp("fb", phi)
            self.corner = False
        else:
            P = base.extend(mu=1, corner=nc)
            self.unknowns = Parameters(x=nx, p=nc, eta=ne, theta=nc, nu=nc)
            S = pair_system(problem, self.unknowns.size, P)
            a, b = S.affine("a", self._a), S.affine("b", self._b)
            theta, nu = (S.unknowns(name, self.unknowns.slice(name).start) for name in ("theta", "nu"))
            sel = S.parameter("corner")
            phi = fischer_burmeister(a, b, S.parameter("mu"))
            target = (1 - sel) * (theta - S.parameter("lam")) / S.parameter("rho") if proximal else 0
            built = S.saddle("fb", **_saddle_terms(sel * a + (1 - sel) * phi, b, theta, nu, sel, target))
            self.corner = True
        self.parameters = P
        self._branch = None
        self.piece_parameters: Parameters | None = None
        self.rj, self.r, self.jacobian = built.rj, built.r, built.jacobian
        self._built = built
        self._phi_source, self._phi = (S, phi), None

    @property
    def phi(self):
        """``(z, P) -> Phi(a, b; mu)`` per pair (built on first use: only the augmented Lagrangian's
        multiplier update needs it)."""
        if self._phi is None:
            S, phi = self._phi_source
            self._phi = S.values("fb_phi", [phi])
        return self._phi

    # ------------------------------------------------------------------ parameters by name
    def pack(self, base: np.ndarray, *, mu: float = 0.0, corner: np.ndarray | None = None) -> np.ndarray:
        """The system's parameters from the base ones, the smoothing and the corner selector."""
        if not self.corner:
            return self.parameters.pack(base, mu=mu)
        return self.parameters.pack(base, mu=mu, corner=np.zeros(self.nc) if corner is None else corner)

    def problem_values(self, base: np.ndarray) -> np.ndarray:
        """The problem's own parameters within a base vector."""
        return self.base_parameters.prefix(base, self.problem.parameters)

    def ab(self, z: np.ndarray, problem_values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The scaled pair arguments ``a = alpha g``, ``b = beta p`` at ``z`` (``problem_values``:
        the problem's own parameters, :meth:`problem_values`): affine, two sparse products."""
        zxp = np.asarray(z, float)[:self.unknowns.slice("p").stop]  # [x; p] lead the unknowns
        return self._a.value(zxp, problem_values), self._b.value(zxp, problem_values)

    # ---------------------------------------------------------------------- unknowns
    def start(self, x0, p0, state) -> np.ndarray:
        """The system's unknowns from a primal start and warm multipliers (``eta``, ``theta``)."""
        if not self.corner:
            return self.unknowns.pack(x=x0, p=p0)
        state = state or {}
        return self.unknowns.pack(x=x0, p=p0, eta=state.get("eta", 0.0), theta=state.get("theta", 0.0), nu=0.0)

    def split(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
        """``(x, p, multipliers)`` from the system's unknowns."""
        get = self.unknowns.get
        multipliers = dict(eta=get(z, "eta"), theta=get(z, "theta")) if self.corner else {}
        return get(z, "x"), get(z, "p"), multipliers

    def corner_multipliers(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(theta, nu)``: the multipliers of ``a = 0`` and ``b = 0`` on the biactive branch."""
        return self.unknowns.get(z, "theta"), self.unknowns.get(z, "nu")

    def newton_system(self, name: str) -> NewtonSystem:
        """The system Newton solves, by name (:class:`~ddcm_casadi.formulations.pairs.NewtonSystem`)."""
        return NewtonSystem(name, self.unknowns, self.parameters, self._built)

    def branch_system(self):
        """The system with each pair on one piece: ``-a_i = 0`` (``branch_i = 1``) or ``-b_i = 0``.

        ``mpcc``: the KKT system of the piece, multiplier ``theta_i``; ``nu = 0`` except on the
        pairs selected by the parameter ``corner``, which are held at the biactive corner with
        the rows of the corner system (``a_i = 0`` with ``theta_i``, ``b_i = 0`` with ``nu_i``,
        the sign convention of :meth:`corner_multipliers`). ``mcp``: ``F = 0`` and the pieces.
        Built once, when first needed. Returns ``(rj, r, jacobian, linear)``; ``linear`` says that
        the Jacobian depends on neither the unknowns nor the problem's parameters (then one
        factorisation serves every solve on the same pieces). Built with the system when the
        predictor is on, else on first use (most solves never need it).
        """
        if self._branch is None:
            problem, nc = self.problem, self.nc
            P = problem.parameters.extend(branch=nc, corner=nc)
            self.piece_parameters = P
            S = pair_system(problem, self.unknowns.size, P)
            a, b = S.affine("a", self._a), S.affine("b", self._b)
            branch, sel = S.parameter("branch"), S.parameter("corner")
            piece = -(branch * a + (1 - branch) * b)
            if problem.kind == "mcp":
                built = S.mcp("fb_branch", piece)
            else:
                theta, nu = (S.unknowns(name, self.unknowns.slice(name).start) for name in ("theta", "nu"))
                built = S.saddle("fb_branch", **_saddle_terms(sel * a + (1 - sel) * piece, b, theta, nu, sel))
            self._branch = (built.rj, built.r, built.jacobian, built.linear)
        return self._branch
