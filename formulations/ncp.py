"""Fischer-Burmeister NCP function and the Newton systems built on it (shared by formulations).

``Phi(a, b) = sqrt(a^2 + b^2) - a - b`` vanishes exactly when ``a >= 0, b >= 0, a b = 0``.
"""

from __future__ import annotations

from collections import OrderedDict

import casadi as ca
import numpy as np
import scipy.sparse.linalg as spla

from ddcm_casadi.problem import ComplementarityProblem
from ddcm_casadi.solvers.evaluate import NumericFunction
from ddcm_casadi.solvers.newton import NewtonResult, SparseJacobian, newton_solve, smoothed_newton_solve


def fischer_burmeister(a, b, mu=0.0):
    """``sqrt(a^2 + b^2 + 2 mu^2) - a - b`` with a finite generalised derivative at the origin."""
    s = a**2 + b**2 + 2 * mu**2
    origin = s == 0
    return ca.sqrt(s + origin) - origin - a - b


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

    Active-set predictor (``predictor=True``, not with ``proximal``). Between DDCM iterations only
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
    """

    #: Factorisations of piece systems kept per system (one per active set).
    LU_CACHE = 4

    def __init__(self, problem: ComplementarityProblem, a_scale: float, b_scale: float, *,
                 gap=None, proximal: bool = False, predictor: bool = True) -> None:
        self.problem = problem
        self.predictor = bool(predictor) and not proximal
        self.stats = {"predicted": 0, "newton": 0}
        gap = problem.gap if gap is None else gap
        mu = ca.SX.sym("mu")
        a, b = a_scale * gap, b_scale * problem.p
        phi = fischer_burmeister(a, b, mu)
        nx, nc = problem.n_x, problem.n_pairs
        self.nc = nc
        extra = []
        if problem.kind == "mcp":
            if proximal:
                raise ValueError("the proximal FB system is for projections (mpcc) only")
            z = ca.vertcat(problem.x, problem.p)
            r = ca.vertcat(problem.residual, phi)
            self.split = lambda z: (z[:nx], z[nx:nx + nc], {})
            P = ca.vertcat(problem.params, mu)
            self.corner = False
            eta = theta = nu = None
        else:
            ne = problem.residual.numel()
            eta, theta, nu = ca.SX.sym("eta", ne), ca.SX.sym("theta", nc), ca.SX.sym("nu", nc)
            sel = ca.SX.sym("corner", nc)
            z = ca.vertcat(problem.x, problem.p, eta, theta, nu)
            first = sel * a + (1 - sel) * phi
            lag = problem.objective + ca.dot(eta, problem.residual) + ca.dot(theta, first) + ca.dot(nu, sel * b)
            grad = ca.gradient(lag, ca.vertcat(problem.x, problem.p))
            target = 0
            if proximal:
                lam, rho = ca.SX.sym("lam", nc), ca.SX.sym("rho")
                extra = [lam, rho]
                target = (1 - sel) * (theta - lam) / rho
            r = ca.vertcat(grad, problem.residual, first - target, sel * b + (1 - sel) * nu)
            self.split = lambda z: (z[:nx], z[nx:nx + nc], dict(eta=z[nx + nc:nx + nc + ne],
                                                              theta=z[nx + nc + ne:nx + 2 * nc + ne]))
            P = ca.vertcat(problem.params, *extra, mu, sel)
            self.corner = True
            self._ne = ne
        self._ab = NumericFunction(ca.Function("fb_ab", [z, problem.params], [a, b]))
        self._branch = None  # built on first use (see _branch_system)
        self._pieces = (problem, a, b, z, eta, theta, nu)
        self._lu: OrderedDict[bytes, object] = OrderedDict()
        if self.predictor:
            self._branch_system()  # part of the build, not of the first solve
        self.rj = NumericFunction(ca.Function("fb_rj", [z, P], [r, ca.jacobian(r, z)]))
        self.r = NumericFunction(ca.Function("fb_r", [z, P], [r]))
        self.phi = NumericFunction(ca.Function("fb_phi", [z, P], [phi]))
        self.jacobian = SparseJacobian(self.rj)

    def reset(self) -> None:
        """Forget the cached factorisations and the counters (for cold-start measurements)."""
        self._lu.clear()
        self.stats = {"predicted": 0, "newton": 0}

    @property
    def n_params(self) -> int:
        return self.problem.params.numel()

    def start(self, x0, p0, state) -> np.ndarray:
        if self.problem.kind == "mcp":
            return np.concatenate([x0, p0])
        state = state or {}
        eta = state.get("eta", np.zeros(self.problem.residual.numel()))
        theta = state.get("theta", np.zeros(self.nc))
        return np.concatenate([x0, p0, eta, theta, np.zeros(self.nc)])

    def solve(self, z0, params, opts, *, corner_tol: float = 1e-3):
        """Semismooth Newton, a corner (biactive) polish, then smoothing; returns
        ``(x, p, state, result, mu, stages)``."""
        nc = self.nc
        kw = dict(jacobian=self.jacobian, tol=opts.tol, residual_tol=opts.residual_tol, max_iter=opts.max_iter)
        spent = 0
        if self.predictor:
            predicted, spent = self._active_set(z0, params, opts, corner_tol=corner_tol, max_switches=opts.max_iter)
            if predicted is not None:
                self.stats["predicted"] += 1
                predicted.message = predicted.message.replace("active set", "active-set predictor")
                x, p, st = self.split(predicted.z)
                return x, p, st, predicted, 0.0, 0
        self.stats["newton"] += 1
        if not self.corner:
            res, mu, stages = smoothed_newton_solve(self.rj, self.r, z0, params, smoothing=opts.smoothing, **kw)
            res.iterations += spent
            x, p, st = self.split(res.z)
            return x, p, st, res, mu, stages
        none = np.zeros(nc)
        # smoothed_newton_solve appends mu last; the selector follows it, so wrap the Functions.
        rj = lambda z, P: self.rj(z, np.concatenate([P, none]))  # noqa: E731
        r = lambda z, P: self.r(z, np.concatenate([P, none]))  # noqa: E731
        best = newton_solve(rj, r, z0, np.append(params, 0.0), **kw)
        total, mu, stages = spent + best.iterations, 0.0, 0
        if not best.converged or self._creeping(best.z, params, corner_tol):
            polished = self._corner(best.z, params, corner_tol, kw)
            if polished is not None:
                total += polished.iterations
                best = polished
        if not best.converged:
            best, mu, stages = smoothed_newton_solve(rj, r, z0, params, smoothing=opts.smoothing,
                                                     try_plain=False, **kw)
            total += best.iterations
            polished = self._corner(best.z, params, corner_tol, kw)
            if polished is not None:
                total += polished.iterations
                best, mu = polished, 0.0
        if not best.converged:
            finish, spent = self.branch_finish((best.z, z0), params, opts, corner_tol=corner_tol)
            total += spent
            if finish is not None:
                best, mu = finish, 0.0
        best.iterations = total
        x, p, st = self.split(best.z)
        return x, p, st, best, mu, stages

    def _branch_system(self):
        """The system with each pair on one piece: ``-a_i = 0`` (``branch_i = 1``) or ``-b_i = 0``.

        ``mpcc``: the KKT system of the piece, multiplier ``theta_i``, ``nu = 0``. ``mcp``:
        ``F = 0`` and the pieces. Built once, when first needed. Returns ``(rj, r, jacobian,
        linear)``; ``linear`` says that the Jacobian depends on neither the unknowns nor the
        parameters (then one factorisation serves every solve on the same pieces). Built with the
        system when the predictor is on, else on first use (most solves never need it).
        """
        if self._branch is None:
            problem, a, b, z, eta, theta, nu = self._pieces
            branch = ca.SX.sym("branch", self.nc)
            piece = -(branch * a + (1 - branch) * b)
            if problem.kind == "mcp":
                r = ca.vertcat(problem.residual, piece)
            else:
                lag = problem.objective + ca.dot(eta, problem.residual) + ca.dot(theta, piece)
                r = ca.vertcat(ca.gradient(lag, ca.vertcat(problem.x, problem.p)), problem.residual, piece, nu)
            P = ca.vertcat(problem.params, branch)
            J = ca.jacobian(r, z)
            linear = not ca.depends_on(J, ca.vertcat(z, problem.params))
            rj = NumericFunction(ca.Function("fb_branch_rj", [z, P], [r, J]))
            self._branch = (rj, NumericFunction(ca.Function("fb_branch_r", [z, P], [r])), SparseJacobian(rj),
                            linear)
        return self._branch

    def _solve_piece(self, z, P, branch, kw) -> NewtonResult | None:
        """Newton on the piece system ``branch`` (parameters ``P`` without the branch); for a linear
        model with a cached factorisation. ``None`` if the piece system is singular."""
        rj, r, jac, linear = self._branch_system()
        Pb = np.concatenate([P, branch])
        if not linear:
            return newton_solve(rj, r, z, Pb, **dict(kw, jacobian=jac))
        key = branch.tobytes()
        lu = self._lu.pop(key, None)
        if lu is None:
            res, J = rj(z, Pb)
            try:
                lu = spla.splu(jac(J))
            except RuntimeError:  # singular piece (degenerate active set)
                return None
        else:
            res = r(z, Pb)
        self._lu[key] = lu
        while len(self._lu) > self.LU_CACHE:
            self._lu.popitem(last=False)
        z = np.array(z, dtype=float)
        rnorm, increment, it = float(np.max(np.abs(res), initial=0.0)), np.inf, 0
        # Exact Jacobian of a linear system: the first step solves it, the next ones refine roundoff.
        for it in range(1, min(3, kw["max_iter"]) + 1):
            dz = -lu.solve(res)
            if not np.all(np.isfinite(dz)):
                return None
            z = z + dz
            increment = float(np.max(np.abs(dz), initial=0.0)) / max(1.0, float(np.max(np.abs(z), initial=0.0)))
            res = r(z, Pb)
            rnorm = float(np.max(np.abs(res), initial=0.0))
            if increment <= kw["tol"] and rnorm <= kw["residual_tol"]:
                return NewtonResult(z, True, it, rnorm, increment, "converged")
        return NewtonResult(z, False, it, rnorm, increment, "piece system: refinement stalled")

    def _signs(self, z, P, branch):
        """The sign each piece leaves free: ``b_i`` where ``a_i = 0`` is imposed, else ``a_i``."""
        a, b = self._ab(z, P)
        return np.where(branch > 0, b, a)

    def branch_finish(self, starts, params, opts, *, corner_tol: float = 1e-3, max_switches: int | None = None):
        """Primal-dual active-set finish on the pieces of ``Z_E`` (see the class notes).

        Returns ``(result, spent)``: the converged Newton result, or ``None`` if no start leads to
        a solution whose signs hold (then the caller reports the failure), and the linear solves
        and Newton steps spent on every start.
        """
        max_switches = 2 * self.nc + 5 if max_switches is None else max_switches
        spent = 0
        for z in starts:
            res, work = self._active_set(z, params, opts, corner_tol=corner_tol, max_switches=max_switches)
            spent += work
            if res is not None:
                res.iterations = spent
                res.message = res.message.replace("active set", "branch finish")
                return res, spent
        return None, spent

    def _active_set(self, z, params, opts, *, corner_tol: float,
                    max_switches: int) -> tuple[NewtonResult | None, int]:
        """Primal-dual active-set iteration from ``z``: solve the piece system of the branches ``z``
        lies on, switch the pairs whose free sign is violated, until every sign holds.

        A sign-consistent result is accepted if strictly complementary; with biactive pairs (signs
        hold to 1e-12 relative) it is accepted for ``mcp`` (any sign-consistent point solves the
        pairs) and, for ``mpcc``, only after the corner polish finds it B-stationary. If the
        iteration cycles, the pairs that switched back and forth are the biactive candidates: the
        corner polish on them decides. A piece solve that misses its tolerance still chooses the
        switches but is never accepted. ``None`` if a piece is singular, the corner is not
        B-stationary or ``max_switches`` is reached. Returns ``(result, spent)``, ``spent`` the
        linear solves and Newton steps (counted also when it fails).
        """
        if not np.all(np.isfinite(z)):
            return None, 0
        P = np.asarray(params, float)[:self.n_params]
        kw = dict(tol=opts.tol, residual_tol=opts.residual_tol, max_iter=opts.max_iter)
        a, b = self._ab(z, P)
        branch = (a <= b).astype(float)
        seen, total, flips, releases = set(), 0, np.zeros(self.nc, dtype=int), 3
        closest, violation = None, np.inf  # the iterate with the smallest sign violation
        for _ in range(max_switches):
            seen.add(branch.tobytes())
            res = self._solve_piece(z, P, branch, kw)
            if res is None or not np.all(np.isfinite(res.z)):
                return None, total
            total += res.iterations
            other = self._signs(res.z, P, branch)
            roundoff = 1e-12 * max(1.0, float(np.max(np.abs(other), initial=0.0)))
            worst = -float(np.min(other, initial=np.inf))
            if not res.converged:
                # An ill-conditioned piece (a far-off start) may miss residual_tol; its solution
                # still says which pairs to switch, but it cannot be accepted.
                if worst <= roundoff:
                    return None, total
            elif np.all(other > 0):
                res.iterations, res.message = total, "converged (active set)"
                return res, total
            elif worst <= roundoff:
                if not self.corner:  # mcp: signs hold to roundoff; the caller checks the residual
                    res.iterations, res.message = total, "converged (active set)"
                    return res, total
                res, total, _ = self._corner_after(res.z, params, np.abs(other) <= roundoff, kw, total)
                return res, total
            if worst < violation:
                closest, violation = res.z, worst
            z = res.z
            switch = other < 0
            flips += switch
            branch = np.where(switch, 1.0 - branch, branch)
            if branch.tobytes() in seen:
                # Cycling between pieces: the solution is at the corner of the pairs that switch
                # back and forth, if anywhere.
                if not self.corner:
                    return None, total
                res, total, wrong = self._corner_after(closest, params, flips >= 2, kw, total)
                if res is not None or wrong is None or releases == 0:
                    return res, total
                # Not B-stationary: leave the corner along the piece its multipliers point to
                # (an active-set step), then go on switching.
                releases -= 1
                z, wrong_theta, wrong_nu = wrong
                branch = np.where(wrong_theta, 0.0, np.where(wrong_nu, 1.0, branch))
                seen, flips[:] = set(), 0
                closest, violation = None, np.inf
        return None, total

    def _corner_after(self, z, params, selection, kw, iterations):
        """Biactive pairs ``selection``: the corner polish from ``z``, accepted only if B-stationary.

        Returns ``(result, spent, wrong)``: ``result`` is ``None`` unless B-stationary; ``wrong``
        is ``(z, wrong_theta, wrong_nu)`` of a converged but not B-stationary corner, else ``None``.
        """
        out = self._corner_solve(z, np.asarray(params, float), selection, dict(kw, jacobian=self.jacobian))
        if out is None:
            return None, iterations, None
        res, wrong_theta, wrong_nu = out
        res.iterations += iterations
        if wrong_theta.any() or wrong_nu.any():
            return None, res.iterations, (res.z, wrong_theta, wrong_nu)
        res.message = "converged (biactive corner)"
        return res, res.iterations, None

    def polish_corner(self, z, params, opts, *, corner_tol: float = 1e-3):
        """The biactive-branch solution near ``z`` if it is B-stationary, else ``None``."""
        kw = dict(jacobian=self.jacobian, tol=opts.tol, residual_tol=opts.residual_tol, max_iter=opts.max_iter)
        return self._corner(z, params, corner_tol, kw) if self.corner else None

    def _creeping(self, z, params, corner_tol) -> bool:
        a, b = self._ab(z, params[:self.n_params])
        near = np.maximum(np.abs(a), np.abs(b)) <= corner_tol
        return bool(np.any(np.minimum(np.abs(a), np.abs(b))[near] > 1e-14))

    def _corner(self, z, params, corner_tol, kw):
        """Newton on the biactive branch of the pairs within ``corner_tol`` of a corner; ``None``
        unless B-stationary."""
        if not np.all(np.isfinite(z)):
            return None
        a, b = self._ab(z, params[:self.n_params])
        return self._corner_after(z, params, np.maximum(np.abs(a), np.abs(b)) <= corner_tol, kw, 0)[0]

    def _corner_solve(self, z, params, selection, kw):
        """Newton on the biactive branch of ``selection``: ``(result, wrong_theta, wrong_nu)``,
        the pairs whose multiplier breaks B-stationarity (``theta_i > 0``: ``a_i`` wants to
        open, ``nu_i > 0``: ``b_i`` does; the larger decides); ``None`` if Newton fails."""
        sel = np.asarray(selection, dtype=float)
        if not sel.any() or not np.all(np.isfinite(z)):
            return None
        P = np.concatenate([params, [0.0], sel])
        res = newton_solve(self.rj, self.r, z, P, **kw)
        if not res.converged:
            return None
        nx, ne, nc = self.problem.n_x, self._ne, self.nc
        theta = res.z[nx + nc + ne:nx + 2 * nc + ne]
        nu = res.z[nx + 2 * nc + ne:]
        scale = 1e-8 * max(1.0, float(np.max(np.abs(np.concatenate([theta, nu])))))
        on = sel > 0
        wrong_theta = on & (theta > scale) & (theta >= nu)
        wrong_nu = on & (nu > scale) & ~wrong_theta
        return res, wrong_theta, wrong_nu
