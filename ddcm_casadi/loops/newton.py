"""Damped (semismooth) Newton with a merit-function line search and scipy's sparse LU.

The residual and its sparse Jacobian come from one CasADi ``Function`` built once per problem;
the linear algebra is :func:`ddcm_casadi.linalg.factorize` (scipy's SuperLU by default) on the
CasADi sparsity pattern (no dense N x N matrices).
Convergence is declared when the relative increment (as in the paper) *and* the residual are small.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict

from dataclasses import dataclass
from typing import Callable

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ddcm_casadi.linalg import SingularMatrix, factorize
from ddcm_casadi.evaluate import NumericFunction


@dataclass
class NewtonResult:
    z: np.ndarray
    converged: bool
    iterations: int
    residual: float
    increment: float
    message: str = ""


class SparseJacobian:
    """Converts the Jacobian output of a CasADi Function to scipy CSC, reusing its pattern.

    ``pattern``: the output's pattern as a scipy CSC matrix, when the caller built it (reading it
    back from CasADi costs about 0.1 microseconds per nonzero); its number of nonzeros is checked.
    """

    def __init__(self, fun, index: int = 1, *, pattern: sp.csc_matrix | None = None) -> None:
        sparsity = fun.sparsity_out(index)
        if pattern is not None and pattern.nnz == sparsity.nnz() and pattern.shape == sparsity.shape:
            self.shape = pattern.shape
            self.indptr = np.asarray(pattern.indptr, dtype=np.int64)
            self.indices = np.asarray(pattern.indices, dtype=np.int64)
            return
        colind, row = sparsity.get_ccs()
        self.shape = (sparsity.size1(), sparsity.size2())
        self.indptr = np.asarray(colind, dtype=np.int64)
        self.indices = np.asarray(row, dtype=np.int64)

    def __call__(self, J: np.ndarray) -> sp.csc_matrix:
        """``J``: the Jacobian's nonzeros, as a :class:`NumericFunction` returns them."""
        return sp.csc_matrix((np.asarray(J, dtype=float), self.indices, self.indptr), shape=self.shape)


class JacobianFactors:
    """Factorisations of the Jacobians Newton met, kept by their values (at most ``size``).

    A linear model's semismooth Jacobian is piecewise constant: it changes only when a pair
    changes piece, so the Newton steps and the multiplier updates of one active set share one
    factorisation (the classical augmented Lagrangian's inner solves: 75 factorisations in 33
    updates on the Hertz example, most of them repeats). A repeat is recognised by a hash of the
    matrix's pattern and values, so a kept factor is the one a new factorisation would give.
    """

    def __init__(self, size: int = 4) -> None:
        self.size = int(size)
        self._factors: OrderedDict[bytes, object] = OrderedDict()

    def factor(self, J: sp.csc_matrix):
        """The factor of ``J`` (kept, or computed and kept); raises :class:`SingularMatrix`."""
        h = hashlib.blake2b(digest_size=16)
        for part in (np.asarray(J.shape, np.int64), J.indptr, J.indices, J.data):
            h.update(np.ascontiguousarray(part).tobytes())
        key = h.digest()
        lu = self._factors.pop(key, None)
        if lu is None:
            lu = factorize(J, iterated=True)
        self._factors[key] = lu
        while len(self._factors) > self.size:
            self._factors.popitem(last=False)
        return lu


def solve_linear(J: sp.csc_matrix, rhs: np.ndarray, factors: JacobianFactors | None = None) -> np.ndarray:
    """Sparse LU solve; a singular (semismooth) Jacobian falls back to a tiny Levenberg shift.
    ``factors``: reuse the factorisations of Jacobians met before."""
    return _factor_and_solve(J, rhs, factors)[0]


def _factor_and_solve(J: sp.csc_matrix, rhs: np.ndarray, factors: JacobianFactors | None = None):
    """``(J^-1 rhs, factor)``, the factor ``None`` where the Levenberg fallback solved instead."""
    try:
        lu = factors.factor(J) if factors is not None else factorize(J, iterated=True)
        d = lu.solve(rhs)  # Newton corrects an inexact step
        if np.all(np.isfinite(d)):
            return d, lu
    except SingularMatrix:
        pass
    scale = max(float(abs(J).max()), 1.0) if J.nnz else 1.0
    shift = 1e-12 * scale
    Jt = J.T.tocsc()
    return spla.spsolve((Jt @ J + shift * sp.identity(J.shape[0], format="csc")).tocsc(), Jt @ rhs), None


#: Unknowns from which Newton reuses its last factorisation (chord steps, :func:`newton_solve`):
#: there a factorisation costs several residual evaluations (the 2-D finite-strain projection of
#: 1e5 unknowns: 1.8 s against 0.35 s for the residual and its Jacobian together).
CHORD_MIN_SIZE = 20_000
#: A chord step is kept only if it cuts ``||r||_2`` at least this much (one digit); else Newton
#: factorises the current Jacobian.
CHORD_CONTRACTION = 0.1


#: Roundoff allowance, in machine epsilons, on the terms that cancel in a residual row.
ROUNDOFF_ULPS = 64


def roundoff_floor(J: sp.csc_matrix, z: np.ndarray) -> float:
    """The smallest residual that can be evaluated at ``z``: ``64 eps max_i (|J| |z|)_i``.

    ``|J| |z|`` is the size of the linear terms that cancel in each row (for a stiff penalty
    ``gamma g`` with ``g ~ 0`` it is ``gamma |u|``); below that the residual is roundoff, and an
    absolute tolerance in scaled units could never be met. Newton accepts a residual at this
    floor when its increment has converged.
    """
    if not z.size or not J.nnz:
        return 0.0
    return ROUNDOFF_ULPS * float(np.finfo(float).eps) * float(np.max(abs(J) @ np.abs(z)))


def newton_solve(rj: NumericFunction, r: NumericFunction, z0: np.ndarray, params: np.ndarray, *,
                 jacobian: SparseJacobian | None = None, tol: float = 1e-9, residual_tol: float = 1e-9,
                 max_iter: int = 50, armijo: float = 1e-4, max_backtracks: int = 40,
                 factors: JacobianFactors | None = None) -> NewtonResult:
    """Solve ``r(z; params) = 0`` by Newton with an Armijo line search on ``0.5 ||r||^2``.

    Parameters
    ----------
    rj : NumericFunction or callable
        ``(z, params) -> (r, J)``, ``J`` the nonzeros of the sparse Jacobian.
    r : NumericFunction or callable
        ``(z, params) -> r`` (for the line search).
    tol : float
        Tolerance on the relative increment ``||dz||_inf / max(1, ||z||_inf)`` (the paper's test).
    residual_tol : float
        Tolerance on ``||r||_inf``; both tests must pass. A residual at the roundoff floor of
        its terms (:func:`roundoff_floor`) passes too.
    factors : JacobianFactors, optional
        Reuse the factorisations of Jacobians met before (a piecewise constant Jacobian).

    From :data:`CHORD_MIN_SIZE` unknowns each step first tries the last factorisation (a chord
    step ``dz = -J_old^-1 r(z)``, kept if it cuts ``||r||_2`` by :data:`CHORD_CONTRACTION`), and
    the Jacobian is evaluated and factorised only when that fails: the same equations and
    tests, fewer factorisations.
    """
    to_csc = jacobian or SparseJacobian(rj)
    z = np.array(z0, dtype=float)
    res, J = rj(z, params)
    res = np.asarray(res, dtype=float).ravel()
    rnorm = float(np.max(np.abs(res))) if res.size else 0.0
    increment = np.inf
    history: list[np.ndarray] = []
    chord = z.size >= CHORD_MIN_SIZE
    lu = None  # the last factorisation, for chord steps
    for it in range(1, max_iter + 1):
        if not np.all(np.isfinite(res)):
            return NewtonResult(z, False, it - 1, np.inf, increment, "non-finite residual")
        step = _chord_step(lu, r, z, res, params) if lu is not None else None
        if step is not None:  # the old factor still contracts: no Jacobian, no factorisation
            history.append(z)
            dz, res, J = step[0], step[1], None
            z = z + dz
        else:
            if J is None:
                res, J = rj(z, params)
                res = np.asarray(res, dtype=float).ravel()
            dz, lu = _factor_and_solve(to_csc(J), -res, factors)
            lu = lu if chord else None
            if not np.all(np.isfinite(dz)):
                return NewtonResult(z, False, it, rnorm, increment, "non-finite Newton step")
            phi = 0.5 * float(res @ res)
            t, trial = 1.0, None
            for _ in range(max_backtracks):
                trial = np.asarray(r(z + t * dz, params), dtype=float).ravel()
                if np.all(np.isfinite(trial)) and 0.5 * float(trial @ trial) <= (1.0 - 2.0 * armijo * t) * phi:
                    break
                t *= 0.5
            else:
                t, trial = 1.0, None  # no decrease: take the full (semismooth) step; cycles are caught below
            history.append(z)
            dz = t * dz
            z = z + dz
            if chord:  # the Jacobian waits until a chord step fails
                res, J = (np.asarray(r(z, params), dtype=float).ravel() if trial is None else trial), None
            else:
                res, J = rj(z, params)
                res = np.asarray(res, dtype=float).ravel()
        increment = float(np.max(np.abs(dz))) / max(1.0, float(np.max(np.abs(z)))) if z.size else 0.0
        rnorm = float(np.max(np.abs(res))) if res.size else 0.0
        if increment <= tol and rnorm > residual_tol and J is None and np.all(np.isfinite(res)):
            res, J = rj(z, params)  # the roundoff floor needs the Jacobian here
            res = np.asarray(res, dtype=float).ravel()
        if increment <= tol and (rnorm <= residual_tol or (J is not None and rnorm <= roundoff_floor(to_csc(J), z))):
            return NewtonResult(z, True, it, rnorm, increment, "converged")
        if len(history) >= 2 and np.max(np.abs(z - history[-2])) <= 1e-13 * (1.0 + np.max(np.abs(z))):
            # Newton returned to the iterate of two steps ago: it cycles between two pieces
            # of a nonsmooth residual (a solution at a kink). Let the caller smooth.
            return NewtonResult(z, False, it, rnorm, increment, "cycling between pieces")
    return NewtonResult(z, False, max_iter, rnorm, increment, "maximum iterations reached")


def _chord_step(lu, r, z: np.ndarray, res: np.ndarray, params) -> tuple[np.ndarray, np.ndarray] | None:
    """``(dz, r(z + dz))`` for the chord step ``dz = -J_old^-1 r(z)`` if it cuts ``||r||_2`` by
    :data:`CHORD_CONTRACTION`, else ``None``. Near a solution the Jacobian hardly changes and a
    chord step contracts like a Newton step for the price of a solve and a residual."""
    dz = -lu.solve(res)
    if not np.all(np.isfinite(dz)):
        return None
    trial = np.asarray(r(z + dz, params), dtype=float).ravel()
    if not np.all(np.isfinite(trial)) or float(np.linalg.norm(trial)) > CHORD_CONTRACTION * float(np.linalg.norm(res)):
        return None
    return dz, trial


#: Default smoothing continuation, tried when Newton on the nonsmooth system (mu = 0) fails.
SMOOTHING = (1e-2, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 0.0)


def smoothed_newton_solve(rj: NumericFunction, r: NumericFunction, z0: np.ndarray,
                          pack: Callable[[float], np.ndarray], *, smoothing: tuple = SMOOTHING,
                          try_plain: bool = True, **kw) -> tuple[NewtonResult, float, int]:
    """Newton on a nonsmooth system with a smoothing parameter ``mu``.

    ``pack(mu)`` gives the system's parameter vector for a smoothing ``mu`` (the caller knows
    where ``mu`` sits among its named parameters). First ``mu = 0`` (generalised Jacobian). If
    that fails (a solution at a kink makes semismooth Newton cycle between pieces), a
    continuation ``mu -> 0`` along ``smoothing`` is run, each stage warm-started. Returns
    ``(result, mu, stages)`` where ``result`` is the last converged stage (or the last attempt)
    and ``mu`` its smoothing parameter; ``result.converged`` is True only if the unsmoothed
    problem (``mu = 0``) was solved.
    """
    if try_plain:
        res = newton_solve(rj, r, z0, pack(0.0), **kw)
        if res.converged:
            return res, 0.0, 0
    else:  # the caller has already tried mu = 0
        res = NewtonResult(np.array(z0, dtype=float), False, 0, np.inf, np.inf,
                           "no stage of the smoothing continuation converged")
    iterations = res.iterations
    z = z0
    best, best_mu, stages = res, 0.0, 0
    for mu in smoothing:
        stages += 1
        trial = newton_solve(rj, r, z, pack(mu), **kw)
        iterations += trial.iterations
        if trial.converged:
            z, best, best_mu = trial.z, trial, mu
    if best_mu > 0:
        # Only a smoothed problem was solved: say so, the caller decides (e.g. a corner polish).
        best.converged = False
        best.message = f"converged only with smoothing mu={best_mu:g}"
    best.iterations = iterations
    return best, best_mu, stages


def plus(x, mu=0.0):
    """Chen-Harker-Kanzow-Smale smoothing of ``max(0, x)``: ``(x + sqrt(x^2 + 4 mu^2)) / 2``.

    Exactly ``max(0, x)`` at ``mu = 0``, with the generalised derivative 1/2 at ``x = 0`` (the
    square root is evaluated as ``sqrt(s + 1) - 1`` where ``s = 0``, so CasADi never forms 0/0).
    """
    s = x**2 + 4 * mu**2
    origin = s == 0
    return 0.5 * (x + ca.sqrt(s + origin) - origin)
