r"""The Scholtes homotopy ``tau -> 0`` for MPCCs relaxed as ``g p <= tau`` (driving IPOPT).

The MPCC formulation (:mod:`ddcm_casadi.formulations.mpcc`) builds the relaxed NLP and the
branch NLP once; this loop decides the relaxations, the warm starts, the recoveries and when to
finish on a branch. It sees only callables.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass
class HomotopyResult:
    w: np.ndarray
    converged: bool
    iterations: int
    steps: int
    message: str


def scholtes_homotopy(relaxed: Callable, *, measure: Callable[[np.ndarray], tuple[float, float]],
                      branch_nlp: Callable[[np.ndarray, float], tuple[np.ndarray, int, bool]],
                      near_corner: Callable[[np.ndarray, float], bool], w0: np.ndarray, tau0: float,
                      tau_factor: float, tau_min: float, comp_tol: float, residual_tol: float,
                      max_homotopy: int, early_branch: int = 0) -> HomotopyResult:
    """Solve relaxed problems along ``tau <- tau_factor tau`` until ``max |min(g, p)| <= comp_tol``.

    ``relaxed(w, tau, warm) -> (status, w, warm, iterations)`` solves one relaxed NLP from
    ``w`` with warm multipliers ``warm`` (``None``: cold); ``status`` is ``""`` on success, else
    the solver's reason. A failed relaxed solve is retried:
    before any success with a larger ``tau`` (up to 1), after one from the geometric mean of the
    failed and the last good ``tau``, cold-started. The homotopy stops on the complementarity
    residual (``measure(w) -> (residual, comp)``), not on a step count; a converged point near a
    corner (``near_corner(w, tau)``) is finished on its identified branch, since
    ``min(g, p) <= comp_tol`` bounds only the smaller of the two, and a stalled homotopy (two
    steps that do not halve ``comp``, or ``tau < tau_min``) ends with the branch NLP
    (``branch_nlp(w, tau) -> (w, iterations, accepted)``).

    ``early_branch > 0``: after each successful relaxed solve that is not yet complementary, the
    branch NLP of the identified branch is tried as well (phase II of mpecopt), at most
    ``early_branch`` times while it fails; an accepted branch solution ends the homotopy. It is
    held to the same tests as the final branch NLP (signs, B-stationarity, ``comp_tol``,
    ``residual_tol``), so it changes the cost, not what counts as a solution.
    """
    w, warm = np.asarray(w0, float), None
    tau, last_good_tau = tau0, None
    iterations = steps = 0
    converged, message = False, "maximum homotopy steps reached"
    comp_prev, stalls = np.inf, 0
    while steps < max_homotopy:
        steps += 1
        status, w_new, warm_new, its = relaxed(w, tau, warm)
        iterations += its
        if status:
            if last_good_tau is None or warm is None:
                if last_good_tau is None and tau < 1.0:
                    tau, warm = min(1.0, tau * 100.0), None  # recovery: relax more and retry
                    continue
                message = status
                break
            # recovery: back off from the last good point, cold start, smaller reduction
            tau, warm = np.sqrt(tau * last_good_tau), None
            continue
        w, warm, last_good_tau = w_new, warm_new, tau
        residual, comp = measure(w)
        if comp <= comp_tol and residual <= residual_tol:
            converged, message = True, "converged"
            if near_corner(w, tau):
                polished, its, accepted = branch_nlp(w, tau)
                iterations += its
                if accepted:
                    w, message = polished, "converged (branch NLP polish)"
            break
        if early_branch > 0:
            polished, its, accepted = branch_nlp(w, tau)
            iterations += its
            if accepted:
                w, converged, message = polished, True, "converged (branch NLP, identified early)"
                break
            early_branch -= 1
        stalls = stalls + 1 if comp > 0.5 * comp_prev else 0
        comp_prev = comp
        if stalls >= 2 or tau * tau_factor < tau_min:
            message = "homotopy stalled"
            break
        tau *= tau_factor
    if not converged and last_good_tau is not None:
        w, its, accepted = branch_nlp(w, last_good_tau)
        iterations += its
        steps += 1
        if accepted:
            converged, message = True, "converged (branch NLP)"
    return HomotopyResult(w, converged, iterations, steps, message)
