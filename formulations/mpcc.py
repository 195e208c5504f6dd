r"""Exact MPCC formulation solved by IPOPT (``casadi.nlpsol``) with a Scholtes homotopy.

The pairs are kept as constraints and relaxed (Scholtes):

.. math::  g(x) \ge 0, \qquad p \ge 0, \qquad g_i(x)\, p_i \le \tau, \qquad \tau \to 0 .

- Classical (mcp): ``min 0`` s.t. ``F(x, p) = 0`` and the relaxed pairs (a feasibility problem).
- DDCM (mpcc): ``min f(x)`` s.t. ``h(x, p) = 0`` and the relaxed pairs.

Practice (as in nosnoc): variables, constraints and objective are already nondimensional (the
problem is scaled by the model), ``bound_relax_factor = 0`` so ``p >= 0`` is not relaxed, each
homotopy step is warm-started from the previous one, and the homotopy stops on the
complementarity residual ``max |min(g, p)| <= comp_tol``, not on a step count. A relaxed problem
that IPOPT reports infeasible is retried from the last good point with a smaller reduction of
``tau`` (recovery), cold-started.

Interior-point iterates keep ``g`` and ``p`` strictly positive, so at a degenerate (grazing) pair
``g p <= tau`` only gives ``min(g, p) ~ sqrt(tau)``, which stalls near ``1e-9``. When the homotopy
stalls, the branch is identified (``g_i = 0`` where ``g_i <= p_i``, else ``p_i = 0``) and the
*branch NLP* (BNLP; as in mpecopt) is solved with those equalities and no bounds; pairs with both
``g`` and ``p`` small are tried first as biactive (``g = p = 0``, accepted only if B-stationary).
A BNLP solution is accepted only if the dropped signs hold (``g >= 0``, ``p >= 0`` within
``comp_tol``). The result is
a stationary point, not always the global one: the DDCM driver checks the other branches.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ddcm_casadi.problem import ComplementarityProblem
from ddcm_casadi.solvers.evaluate import NumericFunction

from .base import BuiltFormulation, Formulation, LocalSolution, positive_option
from .registry import register

_OK = {"Solve_Succeeded", "Solved_To_Acceptable_Level"}


@register
class MPCC(Formulation):
    """Scholtes-relaxed MPCC solved by IPOPT along a homotopy ``tau -> 0``."""

    name = "mpcc"
    title = "MPCC (IPOPT)"

    @dataclass(frozen=True)
    class Options:
        """Options.

        tau0 : float
            First relaxation ``tau`` of ``g p <= tau`` (scaled).
        tau_factor : float
            ``tau <- tau_factor * tau`` between homotopy steps (0 < factor < 1).
        comp_tol : float
            Stop when ``max |min(g, p)| <= comp_tol`` (scaled).
        residual_tol : float
            ... and ``||F||_inf`` (or ``||h||_inf``) ``<= residual_tol``.
        tau_min : float
            Smallest ``tau``; below it (or when the homotopy stalls) the branch NLP is solved.
        max_homotopy : int
            Maximum number of IPOPT solves along the homotopy (with recoveries).
        ipopt : dict
            Extra IPOPT options passed through unchanged (copied).
        """

        tau0: float = 1e-2
        tau_factor: float = 1e-2
        tau_min: float = 1e-24
        comp_tol: float = 1e-11
        residual_tol: float = 1e-10
        max_homotopy: int = 30
        ipopt: dict = field(default_factory=dict)

    def _validate(self) -> None:
        super()._validate()
        for k in ("tau0", "comp_tol", "residual_tol"):
            positive_option(self.name, k, getattr(self.options, k))
        if not 0 < self.options.tau_factor < 1:
            from ddcm_casadi.errors import InputError
            raise InputError(f"option 'tau_factor' of 'mpcc' must be in (0, 1), got {self.options.tau_factor!r}")

    def build(self, problem: ComplementarityProblem) -> "_BuiltMPCC":
        return _BuiltMPCC(problem, self.options)


class _BuiltMPCC(BuiltFormulation):
    def __init__(self, problem: ComplementarityProblem, opts: MPCC.Options) -> None:
        super().__init__(problem)
        self.opts = opts
        nx, nc = problem.n_x, problem.n_pairs
        tau = ca.SX.sym("tau")
        w = ca.vertcat(problem.x, problem.p)
        objective = problem.objective if problem.kind == "mpcc" else ca.SX(0)
        g = ca.vertcat(problem.residual, problem.gap, problem.gap * problem.p - tau)
        ipopt = {"print_level": 0, "sb": "yes", "bound_relax_factor": 0.0, "tol": 1e-12,
                 "acceptable_tol": 1e-10, "constr_viol_tol": 1e-12, "max_iter": 500,
                 "mu_strategy": "adaptive"}
        ipopt.update(dict(opts.ipopt))
        self._solver = ca.nlpsol("mpcc", "ipopt", {"x": w, "p": ca.vertcat(problem.params, tau),
                                                   "f": objective, "g": g},
                                 {"ipopt": ipopt, "print_time": False, "error_on_fail": False})
        ne = problem.residual.numel()
        # Branch NLP: [residual; g; p] with equality bounds chosen per solve.
        gb = ca.vertcat(problem.residual, problem.gap, problem.p)
        self._bnlp = ca.nlpsol("bnlp", "ipopt", {"x": w, "p": problem.params, "f": objective, "g": gb},
                               {"ipopt": ipopt, "print_time": False, "error_on_fail": False})
        self._ne = ne = problem.residual.numel()
        self._lbg = np.concatenate([np.zeros(ne), np.zeros(nc), np.full(nc, -np.inf)])
        self._ubg = np.concatenate([np.zeros(ne), np.full(nc, np.inf), np.zeros(nc)])
        self._lbx = np.concatenate([np.full(nx, -np.inf), np.zeros(nc)])
        self._gap = NumericFunction(ca.Function("gap", [w, problem.params], [problem.gap]))
        self._nx, self._nc = nx, nc

    def solve(self, params, x0, p0, state=None) -> LocalSolution:
        o = self.opts
        nx = self._nx
        w = np.concatenate([x0, np.maximum(p0, 0.0)])
        lam_x = lam_g = None
        tau, last_good_tau = o.tau0, None
        iterations = steps = 0
        converged, message = False, "maximum homotopy steps reached"
        comp_prev, stalls = np.inf, 0
        while steps < o.max_homotopy:
            steps += 1
            args = dict(x0=w, p=np.append(params, tau), lbx=self._lbx, lbg=self._lbg, ubg=self._ubg)
            if lam_x is not None:
                args.update(lam_x0=lam_x, lam_g0=lam_g)
            sol = self._solver(**args)
            stats = self._solver.stats()
            iterations += int(stats.get("iter_count", 0))
            if stats["return_status"] not in _OK:
                if last_good_tau is None or lam_x is None:
                    if last_good_tau is None and tau < 1.0:
                        tau = min(1.0, tau * 100.0)  # recovery: relax more and retry
                        lam_x = lam_g = None
                        continue
                    message = f"IPOPT: {stats['return_status']}"
                    break
                # recovery: back off from the last good point, cold start, smaller reduction
                tau = np.sqrt(tau * last_good_tau)
                lam_x = lam_g = None
                continue
            w = np.asarray(sol["x"], float).ravel()
            lam_x = np.asarray(sol["lam_x"], float).ravel()
            lam_g = np.asarray(sol["lam_g"], float).ravel()
            last_good_tau = tau
            residual, comp, _, _ = self.metrics(w[:nx], w[nx:], params)
            if comp <= o.comp_tol and residual <= o.residual_tol:
                converged, message = True, "converged"
                if self._near_corner(w, params, tau):
                    # min(g, p) <= comp_tol bounds only the smaller of the two: near a corner the
                    # larger may still be far from 0. Finish on the identified branch.
                    polished, iters, ok = self._branch_nlp(w, params, tau)
                    iterations += iters
                    if ok:
                        w, message = polished, "converged (branch NLP polish)"
                break
            stalls = stalls + 1 if comp > 0.5 * comp_prev else 0
            comp_prev = comp
            if stalls >= 2 or tau * o.tau_factor < o.tau_min:
                message = "homotopy stalled"
                break
            tau *= o.tau_factor
        if not converged and last_good_tau is not None:
            w, iters, ok = self._branch_nlp(w, params, last_good_tau)
            iterations += iters
            steps += 1
            if ok:
                converged, message = True, "converged (branch NLP)"
        return self._finish(w[:nx], w[nx:], params, converged=converged, iterations=iterations, outer=steps,
                            message=message)

    def _near_corner(self, w, params, tau) -> bool:
        """Is some pair within the branch NLP's biactive identification ``10 sqrt(tau)`` of a corner?"""
        gap = self._gap(w, params)
        p = w[self._nx:]
        return bool(np.any(np.maximum(np.abs(gap), np.abs(p)) <= 10.0 * np.sqrt(tau)))

    def _branch_nlp(self, w, params, tau):
        """Solve the branch NLP identified at ``w``; returns ``(w, iterations, accepted)``.

        Pairs with both ``g`` and ``p`` below ``10 sqrt(tau) + 100 max_i min(g_i, p_i)`` are first
        tried as biactive (``g = p = 0``); that branch is accepted only if B-stationary (both
        multipliers of the lower bounds non-positive in CasADi's sign convention), so a generous
        identification cannot pin a free or a contact pair to the corner. Where the identification
        is ambiguous (a classical pair near grazing cannot be biactive), both single branches are
        tried; each is accepted only if every sign holds.
        """
        nx, nc, ne = self._nx, self._nc, self._ne
        gap = np.asarray(self._gap(w, params), float).ravel()
        p = w[nx:]
        on_gap = gap <= p
        tol = 10.0 * np.sqrt(tau) + 100.0 * float(np.max(np.minimum(np.abs(gap), np.abs(p)), initial=0.0))
        both = (np.abs(gap) <= tol) & (np.abs(p) <= tol)
        iters = 0
        # Biactive first, then the identified branch, then ambiguous pairs all in contact / all free.
        candidates = [(on_gap | both, ~on_gap | both), (on_gap, ~on_gap),
                      (on_gap | both, ~on_gap & ~both), (on_gap & ~both, ~on_gap | both)]
        tried = set()
        for fix_gap, fix_p in candidates:
            key = (fix_gap.tobytes(), fix_p.tobytes())
            if key in tried:
                continue
            tried.add(key)
            if ne + fix_gap.sum() + fix_p.sum() > nx + nc:
                continue  # over-determined (e.g. a biactive pair of the classical problem)
            inf = np.full(nc, np.inf)
            lbg = np.concatenate([np.zeros(ne), np.where(fix_gap, 0.0, -inf), np.where(fix_p, 0.0, -inf)])
            ubg = np.concatenate([np.zeros(ne), np.where(fix_gap, 0.0, inf), np.where(fix_p, 0.0, inf)])
            sol = self._bnlp(x0=w, p=params, lbg=lbg, ubg=ubg)
            stats = self._bnlp.stats()
            iters += int(stats.get("iter_count", 0))
            if stats["return_status"] not in _OK:
                continue
            w_new = np.asarray(sol["x"], float).ravel()
            lam = np.asarray(sol["lam_g"], float).ravel()
            bi = fix_gap & fix_p
            lam_gap, lam_p = lam[ne:ne + nc][bi], lam[ne + nc:][bi]
            lam_tol = 1e-8 * max(1.0, float(np.max(np.abs(lam), initial=0.0)))
            b_stationary = not (np.any(lam_gap > lam_tol) or np.any(lam_p > lam_tol))
            residual, comp, pen, _ = self.metrics(w_new[:nx], w_new[nx:], params)
            signs_ok = pen <= self.opts.comp_tol and float(np.min(w_new[nx:], initial=0.0)) >= -self.opts.comp_tol
            if b_stationary and signs_ok and comp <= self.opts.comp_tol and residual <= self.opts.residual_tol:
                return w_new, iters, True
            if not both.any():
                break
        return w, iters, False
