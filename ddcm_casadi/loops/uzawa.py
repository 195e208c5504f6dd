r"""Multiplier loops: Uzawa with Anderson acceleration, and the method of multipliers.

The augmented Lagrangian formulation (:mod:`ddcm_casadi.formulations.augmented_lagrangian`)
builds the inner systems; these loops drive them. Each loop only sees callables, so it knows
nothing of CasADi, the model or the pairs' scaling.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np


@dataclass
class LoopResult:
    """What a multiplier loop ends with."""

    z: np.ndarray
    multiplier: np.ndarray
    converged: bool
    updates: int
    inner_iterations: int
    message: str
    extra: dict


def anderson_step(history: tuple[list, list], lam: np.ndarray, lam_T: np.ndarray, depth: int) -> np.ndarray:
    """Next multiplier: the Uzawa update ``lam_T``, Anderson-accelerated (``depth`` past iterates).

    Uzawa contracts by about ``(E/l0) / (E/l0 + gamma)`` per update, so small ``gamma`` needs
    thousands of plain updates; Anderson mixing of the last iterates restores a few. The result
    is projected onto ``lam >= 0``.
    """
    lams, fs = history
    lams.append(lam)
    fs.append(lam_T - lam)
    if depth == 0 or len(lams) < 2:
        return lam_T
    del lams[:-depth - 1], fs[:-depth - 1]
    dF = np.diff(np.array(fs), axis=0).T
    dL = np.diff(np.array(lams), axis=0).T
    coef = np.linalg.lstsq(dF, fs[-1], rcond=None)[0]
    candidate = lam_T - (dL + dF) @ coef
    return np.maximum(candidate, 0.0) if np.all(np.isfinite(candidate)) else lam_T


def uzawa(inner: Callable[[np.ndarray, np.ndarray], Any], update: Callable[[np.ndarray, np.ndarray], np.ndarray],
          done: Callable[[np.ndarray, np.ndarray], bool], z0: np.ndarray, lam0: np.ndarray, *,
          anderson: int, max_updates: int) -> LoopResult:
    """Uzawa iterations ``z = inner(lam)``, ``lam <- update(z, lam)`` until ``done(z, lam_T)``.

    ``inner(lam, z_start)`` returns a Newton result (``z``, ``converged``, ``iterations``,
    ``message``); ``update(z, lam)`` the Uzawa update ``lam_T``; ``done(z, lam_T)`` tests
    convergence on the pairs themselves.
    """
    lam, z = np.asarray(lam0, float), np.asarray(z0, float)
    its, converged, message, history, k = 0, False, "maximum multiplier updates reached", ([], []), 0
    for k in range(1, max_updates + 1):
        res = inner(lam, z)
        its += res.iterations
        if not res.converged:
            message = f"inner Newton failed at update {k}: {res.message}"
            break
        z = res.z
        lam_T = update(z, lam)
        if done(z, lam_T):
            lam, converged, message = lam_T, True, "converged"
            break
        lam = anderson_step(history, lam, lam_T, anderson)
    return LoopResult(z, lam, converged, k, its, message, {})


def method_of_multipliers(inner: Callable[[np.ndarray, float, np.ndarray], tuple], *,
                          constraint: Callable[[np.ndarray, np.ndarray, float], np.ndarray],
                          polish: Callable[[np.ndarray, np.ndarray, float], tuple | None],
                          multiplier: Callable[[dict], np.ndarray],
                          done: Callable[[np.ndarray], bool], z0: np.ndarray, lam0: np.ndarray, rho0: float,
                          rho_growth: float, rho_max: float, tol: float, max_updates: int) -> LoopResult:
    r"""The method of multipliers on equality constraints ``c(z) = 0``.

    Inner: ``inner(lam, rho, z_start) -> (z, state, newton_result)`` minimises
    ``f + lam^T c + rho/2 ||c||^2`` (subject to the problem's own equalities); outer:
    ``lam <- lam + rho c``, read from the inner solution's multipliers (``multiplier(state)``,
    the primal-dual form gives it directly). ``rho`` grows by ``rho_growth`` whenever an update
    fails to reduce ``||c||_inf`` by 4x. When ``||c|| > tol`` after an inner solve, ``polish(z,
    lam, rho)`` may return a better point ``(z, state, iterations)`` (e.g. a B-stationary
    corner) or ``None``. Stops when ``done(z)``.
    """
    lam, z, rho, c_prev = np.asarray(lam0, float), np.asarray(z0, float), float(rho0), np.inf
    its, converged, message, state, k = 0, False, "maximum multiplier updates reached", {}, 0
    for k in range(1, max_updates + 1):
        z, state, res = inner(lam, rho, z)
        its += res.iterations
        if not res.converged:  # after smoothing, corner polish and the branch finish
            message = f"inner Newton failed at update {k}: {res.message}"
            break
        c = constraint(z, lam, rho)
        if float(np.max(np.abs(c), initial=0.0)) > tol:
            polished = polish(z, lam, rho)
            if polished is not None:
                z, state, spent = polished
                its += spent
                c = constraint(z, lam, rho)
        lam = np.asarray(multiplier(state), float).copy()  # = lam + rho c at the inner solution
        c_norm = float(np.max(np.abs(c), initial=0.0))
        if done(z):
            converged, message = True, "converged"
            break
        if c_norm > 0.25 * c_prev:
            rho = min(rho * rho_growth, rho_max)
        c_prev = c_norm
    return LoopResult(z, lam, converged, k, its, message, dict(state=state, rho=rho))
