"""Fischer-Burmeister NCP function and the Newton systems built on it (shared by formulations).

``Phi(a, b) = sqrt(a^2 + b^2) - a - b`` vanishes exactly when ``a >= 0, b >= 0, a b = 0``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ddcm_casadi.problem import ComplementarityProblem
from ddcm_casadi.solvers.evaluate import NumericFunction
from ddcm_casadi.solvers.newton import SparseJacobian, newton_solve, smoothed_newton_solve


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
    """

    def __init__(self, problem: ComplementarityProblem, a_scale: float, b_scale: float, *,
                 gap=None, proximal: bool = False) -> None:
        self.problem = problem
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
            self._ab = NumericFunction(ca.Function("fb_ab", [z, problem.params], [a, b]))
            self._ne = ne
            self._branch = None  # built on first use (see branch_finish)
            self._pieces = (problem, a, b, z, eta, theta, nu)
        self.rj = NumericFunction(ca.Function("fb_rj", [z, P], [r, ca.jacobian(r, z)]))
        self.r = NumericFunction(ca.Function("fb_r", [z, P], [r]))
        self.phi = NumericFunction(ca.Function("fb_phi", [z, P], [phi]))
        self.jacobian = SparseJacobian(self.rj)

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
        if not self.corner:
            res, mu, stages = smoothed_newton_solve(self.rj, self.r, z0, params, smoothing=opts.smoothing, **kw)
            x, p, st = self.split(res.z)
            return x, p, st, res, mu, stages
        none = np.zeros(nc)
        # smoothed_newton_solve appends mu last; the selector follows it, so wrap the Functions.
        rj = lambda z, P: self.rj(z, np.concatenate([P, none]))  # noqa: E731
        r = lambda z, P: self.r(z, np.concatenate([P, none]))  # noqa: E731
        best = newton_solve(rj, r, z0, np.append(params, 0.0), **kw)
        total, mu, stages = best.iterations, 0.0, 0
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
            finish = self.branch_finish((best.z, z0), params, opts, corner_tol=corner_tol)
            if finish is not None:
                total += finish.iterations
                best, mu = finish, 0.0
        best.iterations = total
        x, p, st = self.split(best.z)
        return x, p, st, best, mu, stages

    def _branch_system(self):
        """The KKT system with each pair on one piece: ``-a_i = 0`` (``branch_i = 1``) or
        ``-b_i = 0``, multiplier ``theta_i``, ``nu = 0``. Built once, when first needed: most
        problems never need it, and its Jacobian costs as much to build as the FB one."""
        if self._branch is None:
            problem, a, b, z, eta, theta, nu = self._pieces
            branch = ca.SX.sym("branch", self.nc)
            piece = -(branch * a + (1 - branch) * b)
            lag = problem.objective + ca.dot(eta, problem.residual) + ca.dot(theta, piece)
            r = ca.vertcat(ca.gradient(lag, ca.vertcat(problem.x, problem.p)), problem.residual, piece, nu)
            P = ca.vertcat(problem.params, branch)
            rj = NumericFunction(ca.Function("fb_branch_rj", [z, P], [r, ca.jacobian(r, z)]))
            self._branch = (rj, NumericFunction(ca.Function("fb_branch_r", [z, P], [r])), SparseJacobian(rj))
        return self._branch

    def branch_finish(self, starts, params, opts, *, corner_tol: float = 1e-3, max_switches: int | None = None):
        """Primal-dual active-set finish on the pieces of ``Z_E`` (see the class notes).

        Returns the converged Newton result, or ``None`` if no start leads to a solution whose
        signs hold (then the caller reports the failure).
        """
        npar = self.problem.params.numel()
        P = np.asarray(params, float)[:npar]
        branch_rj, branch_r, branch_jac = self._branch_system()
        kw = dict(jacobian=branch_jac, tol=opts.tol, residual_tol=opts.residual_tol, max_iter=opts.max_iter)
        max_switches = 2 * self.nc + 5 if max_switches is None else max_switches
        for z in starts:
            if not np.all(np.isfinite(z)):
                continue
            a, b = (np.asarray(v, float).ravel() for v in self._ab(z, P))
            branch = (a <= b).astype(float)
            seen, total = set(), 0
            for _ in range(max_switches):
                seen.add(branch.tobytes())
                res = newton_solve(branch_rj, branch_r, z, np.concatenate([P, branch]), **kw)
                total += res.iterations
                if not res.converged:
                    break
                a, b = (np.asarray(v, float).ravel() for v in self._ab(res.z, P))
                other = np.where(branch > 0, b, a)  # the sign the piece leaves free
                if np.all(other > 0):
                    res.iterations, res.message = total, "converged (branch finish)"
                    return res
                if np.all(other >= -1e-12 * max(1.0, float(np.max(np.abs(other))))):
                    # Biactive pairs: a corner, accepted only if B-stationary.
                    corner = self._corner(res.z, np.asarray(params, float), corner_tol, dict(kw, jacobian=self.jacobian))
                    if corner is not None:
                        corner.iterations += total
                        return corner
                    break
                z = res.z
                branch = np.where(other < 0, 1.0 - branch, branch)
                if branch.tobytes() in seen:
                    break
        return None

    def polish_corner(self, z, params, opts, *, corner_tol: float = 1e-3):
        """The biactive-branch solution near ``z`` if it is B-stationary, else ``None``."""
        kw = dict(jacobian=self.jacobian, tol=opts.tol, residual_tol=opts.residual_tol, max_iter=opts.max_iter)
        return self._corner(z, params, corner_tol, kw) if self.corner else None

    def _creeping(self, z, params, corner_tol) -> bool:
        a, b = (np.asarray(v, float).ravel() for v in self._ab(z, params[:self.problem.params.numel()]))
        near = np.maximum(np.abs(a), np.abs(b)) <= corner_tol
        return bool(np.any(np.minimum(np.abs(a), np.abs(b))[near] > 1e-14))

    def _corner(self, z, params, corner_tol, kw):
        """Newton on the biactive branch of the pairs near a corner; ``None`` unless B-stationary."""
        if not np.all(np.isfinite(z)):
            return None
        a, b = (np.asarray(v, float).ravel() for v in self._ab(z, params[:self.problem.params.numel()]))
        sel = (np.maximum(np.abs(a), np.abs(b)) <= corner_tol).astype(float)
        if not sel.any():
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
        if np.any(theta[on] > scale) or np.any(nu[on] > scale):
            return None
        res.message = "converged (biactive corner)"
        return res
