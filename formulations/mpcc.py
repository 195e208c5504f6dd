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

Coulomb friction (``problem.frictional``: per contact the gap and slip ``u = (g_N, s_T)`` and the
traction ``r = (p_N, r_T)``, :mod:`ddcm_casadi.models.coulomb`). The traction is written
``r = (p_N, mu p_N rho)`` with ``p_N >= 0`` (a bound) and ``|rho| <= 1``, so it lies in the cone
by construction, and the cone complementarity ``r in K, u_hat in K^*, r . u_hat = 0`` (De Saxcé)
is relaxed as the normal pairs are (:func:`~ddcm_casadi.formulations.friction.coulomb_constraints`):

.. math::  g_N \ge 0,\quad |\rho|^2 \le 1,\quad
           p_N (g_N + \mu |s_T|_\tau) + r_T \cdot s_T \le \tau,\qquad
           |s_T|_\tau = \sqrt{|s_T|^2 + \tau^2} - \tau .

What a solution means (Coulomb's law is not a potential):

- classical (mcp): ``min 0`` subject to ``F(x, p) = 0`` and the law, a feasibility problem (as
  the frictionless path with affine maps: friction needs small kinematics); any point that
  satisfies the law is a solution, and IPOPT returns the one its path reaches;
- DDCM (mpcc): ``min f`` (the projection's distance to the data) subject to ``h(x, p) = 0`` and
  the law, a KKT point of the projection onto the frictional admissible set (a local one, as
  without friction).

The homotopy (same options, same stopping test, with Coulomb's natural-map residual as the
complementarity measure) ends on a *branch NLP* in ``[x; p]``: per contact open (``r = 0``),
stick (``u = 0``) or slip (``g_N = 0``, ``r_T = -mu p_N s_T / |s_T|``), identified from the
relaxed point (closed where ``g_N <= p_N``; stick where ``|s_T| < mu p_N - |r_T|``), the
statuses parameters of one NLP built once (:func:`~ddcm_casadi.formulations.friction.coulomb_branch`).
A branch solution is accepted when the law's natural-map residual is at most ``comp_tol`` (so
every sign holds) and the residual at most ``residual_tol``; one that is not re-identifies the
statuses at its own point (a primal-dual active-set round). A projection also has degenerate
branches, as the biactive normal pairs: the *corner* (``g_N = 0, r = 0``) and the *edge* (stuck,
``u = 0``, with ``|r_T| = mu p_N``), tried where the rounds switch a contact back and forth or where
the relaxed point is within ``10 sqrt(tau)`` of them, and accepted only if B-stationary (the
distance decreases along none of the pieces that meet there, by the signs of the multipliers;
otherwise the contact leaves along the piece they point to). Where no contact is degenerate the
branch is locally the whole admissible set, so a projection's branch KKT point is one of the
projection. With ``warm_branch`` the next solve first tries the branch NLP of the last solution's
statuses when the start identifies them again.

Measured on 12 generated FCLIB local problems (1-30 contacts, ``mu = 0.3``), IPOPT iterations
summed over the 12: the first relaxed solve (``tau = 1e-2``, after which the branch NLP usually
ends the solve) took 301 in this form, 622 in the viscous form
``r_T sqrt(|s_T|^2 + tau^2) + mu p_N s_T = 0`` (free ``r_T``, the cone
``mu^2 p_N^2 >= |r_T|^2``), 1720 with 4 failures with ``|s_T|`` lifted to a variable
``sigma^2 >= |s_T|^2`` (exact, but degenerate at stick); a plain homotopy down to ``tau = 1e-12``
(no branch NLP) failed 4, 5 and 10 times. With the branch NLP (and ``friction_tau0 = 1e-3``) this
form solves all 12 in 6-28 iterations (``benchmarks/mpcc_friction.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ddcm_casadi.problems.complementarity import BIACTIVE, b_stationarity, identify, imposes_gap, imposes_pressure, signs_hold
from ddcm_casadi.problems.contract import ComplementarityProblem
from ddcm_casadi.evaluate import NumericFunction
from ddcm_casadi.loops.homotopy import scholtes_homotopy
from ddcm_casadi.loops.active_set import ActiveSetSolver
from ddcm_casadi.loops.ipopt_options import check_ipopt_options, ipopt_stats, iteration_count

from .augmented_lagrangian import AugmentedLagrangian
from .base import BuiltFormulation, Formulation, LocalSolution, positive_option
from .ncp import FBSystem
from .friction import BuiltCoulomb, cone_traction, coulomb_branch, coulomb_constraints
from .registry import register

_OK = {"Solve_Succeeded", "Solved_To_Acceptable_Level"}
#: Branch NLPs of an affine classical problem's active-set rounds (:meth:`_BuiltMPCC._active_set`).
#: From the predictor's branch one ends a step; from the start's branch the Hertz examples take 1-5.
ACTIVE_SET_ROUNDS = 8


@dataclass(frozen=True)
class _PieceTolerances:
    """The predictor's piece solves (linear: one step, then roundoff refinement)."""

    tol: float = 1e-9
    residual_tol: float = 1e-10
    max_iter: int = 3


_PIECE_TOLERANCES = _PieceTolerances()


@register
class MPCC(Formulation):
    """Scholtes-relaxed MPCC solved by IPOPT along a homotopy ``tau -> 0``."""

    name = "mpcc"
    title = "MPCC (IPOPT)"
    supported_contact_laws = frozenset({"signorini", "coulomb"})

    @dataclass(frozen=True)
    class Options:
        """Options.

        tau0 : float
            First relaxation ``tau`` of ``g p <= tau`` (scaled).
        friction_tau0 : float
            First relaxation of a frictional problem's ``r . u_hat <= tau`` (scaled; see the
            module). Summed IPOPT iterations from ``1e-2``, ``1e-3``, ``1e-4``: 769, 922, 2555 on 18
            generated FCLIB problems (3-30 contacts, ``mu`` 0.1-1); 274, 191, 311 on 12 others
            (1-30 contacts); 1188, 742 (``1e-2``, ``1e-3``) on the friction rungs' block and
            incline, classical and DDCM.
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
        early_branch : int
            After each relaxed solve, also try the branch NLP of the branch identified there
            (``g_i = 0`` where ``g_i <= p_i``, else ``p_i = 0``; mpecopt's phase II), at most this
            many times while it fails; 0: only when the homotopy converges near a corner or stalls.
            The default tries it after every relaxed solve: a branch NLP costs about one IPOPT
            iteration on a linear model, the relaxed solves near ``tau = 1e-10`` and below 150-450
            (measured on the Hertz example, docs/performance.md 2026-11-26).
            An accepted branch solution passes the same tests (signs, B-stationarity,
            ``comp_tol``, ``residual_tol``) as at the end of the homotopy.
        warm_branch : bool
            From a warm start that is a converged solution, first solve the branch NLP of the
            branch identified there (``g_i = 0`` where ``g_i <= p_i``, else ``p_i = 0``), accepted
            under the same tests as above; the homotopy runs only when that fails.
        active_set : bool
            Classical problems with small kinematics: before the homotopy, solve the branch NLP
            of the branch a cheap classical solve identifies, accepted under the same tests as
            above; the homotopy runs only when that fails. Without friction (one solution) the
            branch is the active-set predictor's (Fischer-Burmeister's piece solves with kept
            factors) and, while the signs fail, the one identified at the branch solution (a
            primal-dual active-set iteration of branch NLPs); with Coulomb friction, the statuses
            of Alart-Curnier's semismooth Newton solution (the augmented Lagrangian's), then the
            branch NLP's own active-set rounds. IPOPT solves the branch NLPs from the start.
        ipopt : dict
            Extra IPOPT options passed through unchanged (copied).
        """

        tau0: float = 1e-2
        friction_tau0: float = 1e-3
        tau_factor: float = 1e-2
        tau_min: float = 1e-24
        comp_tol: float = 1e-11
        residual_tol: float = 1e-10
        max_homotopy: int = 30
        early_branch: int = 30
        warm_branch: bool = True
        active_set: bool = True
        ipopt: dict = field(default_factory=dict)

    def _validate(self) -> None:
        super()._validate()
        for k in ("tau0", "friction_tau0", "comp_tol", "residual_tol"):
            positive_option(self.name, k, getattr(self.options, k))
        if not 0 < self.options.tau_factor < 1:
            from ddcm_casadi.errors import InputError
            raise InputError(f"option 'tau_factor' of 'mpcc' must be in (0, 1), got {self.options.tau_factor!r}")
        if self.options.ipopt:
            check_ipopt_options(f"formulation {self.name!r}", self.options.ipopt)

    def _build(self, problem: ComplementarityProblem) -> BuiltFormulation:
        if problem.frictional:
            return _BuiltCoulombMPCC(problem, self.options)
        return _BuiltMPCC(problem, self.options)


def _ipopt_options(problem: ComplementarityProblem, opts: "MPCC.Options") -> dict:
    """IPOPT's options for ``problem`` (the user's ``ipopt`` last)."""
    ipopt = {"print_level": 0, "sb": "yes", "bound_relax_factor": 0.0, "tol": 1e-12,
             "acceptable_tol": 1e-10, "constr_viol_tol": 1e-12, "max_iter": 500,
             "mu_strategy": "adaptive"}
    if problem.affine:
        # IPOPT ignores the homotopy's warm multipliers without this (a deep relaxed solve then
        # took 150-450 iterations on the Hertz example's projections). Not with finite
        # kinematics: on the von Mises truss the step after the snap then fails.
        ipopt["warm_start_init_point"] = "yes"
    if problem.kind == "mcp":
        # The classical NLP is a feasibility problem: its KKT matrix has a zero Hessian block.
        # MUMPS's automatic ordering (as SCOTCH or PORD) then gives steps on which IPOPT needs
        # 257 iterations of 0.2 s for one relaxed solve of the Hertz example, AMD 14 of 0.01 s
        # (docs/performance.md, 2026-11-26). With the distance objective (DDCM) the automatic
        # ordering is the faster one (38 ms against 117 ms an iteration).
        ipopt["mumps_pivot_order"] = 0
    ipopt.update(dict(opts.ipopt))
    return ipopt


#: CasADi's options of every NLP solver built here.
_NLPSOL = {"print_time": False, "error_on_fail": False, "show_eval_warnings": False}


def _run(solver, args: dict) -> tuple[str, np.ndarray, tuple | None, int]:
    """One IPOPT solve: ``(status, w, warm, iterations)``, ``status`` ``""`` on success (then
    ``warm`` the multipliers ``(lam_x, lam_g)``), else IPOPT's reason and ``w`` the start."""
    sol = solver(**args)
    stats = ipopt_stats(solver)
    its = iteration_count(stats)
    if stats["return_status"] not in _OK:
        return f"IPOPT: {stats['return_status']}", np.asarray(args["x0"], float), None, its
    return ("", np.asarray(sol["x"], float).ravel(),
            (np.asarray(sol["lam_x"], float).ravel(), np.asarray(sol["lam_g"], float).ravel()), its)


def _relaxed(solver, parameters, values, bounds: dict):
    """``relaxed(w, tau, warm)`` of :func:`~ddcm_casadi.loops.homotopy.scholtes_homotopy` for the
    relaxed NLP ``solver`` (parameters ``values`` and ``tau``; ``bounds``: ``lbx``, ``lbg``, ...)."""
    def relaxed(w, tau, warm):
        args = dict(x0=w, p=parameters.pack(values, tau=tau), **bounds)
        if warm is not None:
            args.update(lam_x0=warm[0], lam_g0=warm[1])
        return _run(solver, args)
    return relaxed


class _BuiltMPCC(BuiltFormulation):
    def __init__(self, problem: ComplementarityProblem, opts: MPCC.Options) -> None:
        super().__init__(problem)
        self.opts = opts
        nx, nc = problem.n_x, problem.n_pairs
        # A classical problem with finite kinematics may have several equilibria (a snap-through
        # truss: the stable branch, an unstable one, the inverted one): the feasibility problem
        # then selects the one nearest the start (``anchor``, the previous converged step), the
        # path a quasi-static loading follows. An affine problem's solution is unique: no objective.
        self._anchored = problem.kind == "mcp" and not problem.affine
        # An affine classical problem has one solution: a branch NLP solution whose signs hold is it.
        # Its branch is identified by the active-set predictor's piece solves (kept factors, as
        # Fischer-Burmeister's; pairs compared as g <= p in scaled units, as the MPCC's branches).
        unique = problem.kind == "mcp" and problem.affine
        self._predictor = (ActiveSetSolver(FBSystem(problem, 1.0, 1.0), predictor=True)
                           if unique and opts.active_set else None)
        base = problem.parameters.extend(anchor=nx) if self._anchored else problem.parameters
        self._base = base
        self.parameters = base.extend(tau=1)
        ipopt = _ipopt_options(problem, opts)
        # Finite strain in SX, local terms written out element by element: IPOPT's Hessians of MX
        # maps cost more than the expansion (measured on the 822-dof indentation: 12 s to build and
        # 302 s to solve in MX, 52 s and 17 s in SX). Affine maps in MX, sparse matrices kept whole:
        # SX's symbolic Jacobian of K z cost 17 s per NLP at 8 406 unknowns (the two spheres),
        # MX 0.04 s, same iterations and solutions (docs/performance.md).
        sym = ca.SX if not problem.affine else ca.MX

        def nlp(parameters, rows):
            z, P = sym.sym("z", nx + nc), sym.sym("P", parameters.size)
            # vec: a 1 x 1 symbol sliced past its end is 1 x 0 in CasADi, not 0 x 1 (no pairs)
            x, p, own = z[:nx], ca.vec(z[nx:]), P[:problem.parameters.size]
            residual, gap = problem.residual_map.render(z, own), problem.gap_map.render(z, own)
            objective = (problem.distance.render(z, own) if problem.kind == "mpcc" else
                         0.5 * ca.sumsqr(x - P[base.slice("anchor")]) if self._anchored else sym.zeros(1, 1))
            return {"x": z, "p": P, "f": objective, "g": ca.vertcat(residual, gap, rows(p, gap, P))}

        self._solver = ca.nlpsol("mpcc", "ipopt", nlp(self.parameters, lambda p, gap, P: gap * p - P[self.parameters.slice("tau")]),
                                 {"ipopt": ipopt, **_NLPSOL})
        # Branch NLP: [residual; g; p] with equality bounds chosen per solve.
        # (an inverted element's terms are NaN at finite strain: IPOPT backs off, quietly)
        self._bnlp = ca.nlpsol("bnlp", "ipopt", nlp(base, lambda p, gap, P: p),
                               {"ipopt": ipopt, **_NLPSOL})
        w = ca.vertcat(problem.x, problem.p)
        self._ne = ne = problem.n_residual
        self._lbg = np.concatenate([np.zeros(ne), np.zeros(nc), np.full(nc, -np.inf)])
        self._ubg = np.concatenate([np.zeros(ne), np.full(nc, np.inf), np.zeros(nc)])
        self._lbx = np.concatenate([np.full(nx, -np.inf), np.zeros(nc)])
        self._gap = NumericFunction(ca.Function("gap", [w, problem.params], [problem.gap]))
        self._nx, self._nc = nx, nc

    def solve(self, params, x0, p0, state=None) -> LocalSolution:
        o = self.opts
        nx = self._nx
        w = np.concatenate([x0, np.maximum(p0, 0.0)])
        values = self._base.pack(params, anchor=x0) if self._anchored else params  # the NLPs' parameters
        state = state or {}
        if self._predictor is not None:
            polished, iters, rounds, message = self._active_set(w, params, values)
            if message:
                return self._finish(polished[:nx], polished[nx:], params, converged=True, iterations=iters,
                                    outer=rounds, message=message, state=self._next_state(True, polished, params))
        same_branch = "branch" in state and np.array_equal(state["branch"], self._branch_of(w, params))
        if state.get("on_branch") or same_branch:
            # The start is a branch solution (e.g. the exact global branch of a projection):
            # the relaxed homotopy would forget its branch (with tau0 both g and p may open), so
            # its branch NLP is solved first, accepted only if its signs hold and it is B-stationary.
            polished, iters, ok = self._branch_nlp(w, params, 0.0, values)
            if ok:
                return self._finish(polished[:nx], polished[nx:], params, converged=True, iterations=iters,
                                    outer=1, message="converged (branch NLP from the start's branch)",
                                    state=self._next_state(True, polished, params))
        relaxed = _relaxed(self._solver, self.parameters, values, dict(lbx=self._lbx, lbg=self._lbg, ubg=self._ubg))

        def measure(w):
            residual, comp, _, _ = self.metrics(w[:nx], w[nx:], params)
            return residual, comp

        out = scholtes_homotopy(relaxed, measure=measure, branch_nlp=lambda w, tau: self._branch_nlp(w, params, tau, values),
                                near_corner=lambda w, tau: self._near_corner(w, params, tau), w0=w, tau0=o.tau0,
                                tau_factor=o.tau_factor, tau_min=o.tau_min, comp_tol=o.comp_tol,
                                residual_tol=o.residual_tol, max_homotopy=o.max_homotopy,
                                early_branch=o.early_branch)
        return self._finish(out.w[:nx], out.w[nx:], params, converged=out.converged, iterations=out.iterations,
                            outer=out.steps, message=out.message,
                            state=self._next_state(out.converged, out.w, params))

    def _next_state(self, converged: bool, w: np.ndarray, params: np.ndarray) -> dict:
        """The warm-start state a solution hands on: with ``warm_branch``, its branch, so that the
        next solve from it (the next load step, the next projection of the DDCM iterations) first
        solves that branch's NLP (one IPOPT solve where the homotopy takes several) when the start
        still identifies the same branch under the new parameters. Where a pair changes side (a
        growing contact zone) the homotopy runs as before: a branch NLP on the wrong branch can cost
        IPOPT hundreds of iterations (measured on the Hertz example)."""
        return {"branch": self._branch_of(w, params)} if converged and self.opts.warm_branch else {}

    def _branch_of(self, w: np.ndarray, params: np.ndarray) -> np.ndarray:
        """The side of every pair at ``w``: gap (``g_i <= p_i``) or pressure."""
        return np.asarray(self._gap(w, params), float).ravel() <= w[self._nx:]

    def _active_set(self, w, params, values) -> tuple[np.ndarray, int, int, str]:
        """Branch NLPs of an affine classical problem from ``w``: ``(w, iterations, branch NLPs,
        message)``, ``iterations`` the predictor's linear solves and IPOPT's iterations,
        ``message`` empty unless a branch NLP solution was accepted.

        The first branch is that of the active-set predictor's solution (a primal-dual
        active-set iteration on the piece systems ``F = 0, g_i = 0 or p_i = 0``, each a solve with
        a kept or updated factor), else (no prediction) the one identified at ``w``. A branch
        solution whose signs fail identifies the next branch there (``g_i = 0`` where ``g_i <=
        p_i``, else ``p_i = 0``: a penetrating free pair closes, a pulling contact opens), as a
        primal-dual active-set method does, at most :data:`ACTIVE_SET_ROUNDS` branch NLPs and
        never one twice. An accepted branch NLP solution (IPOPT's, one iteration on these linear
        constraints) satisfies every sign, the complementarity and the residual test, so it is
        the problem's one solution; the homotopy runs when the rounds fail. On the Hertz example a
        step then costs one branch NLP, where the homotopy took 2-4 relaxed solves of 8-21
        iterations and 1-7 branch NLPs (docs/performance.md)."""
        nx, system = self._nx, self._predictor.system
        if self._solves(w, params):
            return w, 0, 0, "converged (the start solves the problem)"
        on_gap, tried, source = self._branch_of(w, params), set(), "the start's branch"
        predicted, iters = self._predictor.branch_finish((system.start(w[:nx], w[nx:], None),), params,
                                                         _PIECE_TOLERANCES)
        if predicted is not None:
            on_gap, source = self._branch_of(predicted.z[:nx + self._nc], params), "the predicted branch"
        while len(tried) < ACTIVE_SET_ROUNDS and on_gap.tobytes() not in tried:
            tried.add(on_gap.tobytes())
            status, w_new, _, its, ok = self._solve_branch(w, params, values, on_gap, ~on_gap)
            iters += its
            if status:
                break
            if ok:
                return w_new, iters, len(tried), f"converged (branch NLP, active set from {source})"
            on_gap = self._branch_of(w_new, params)
        return w, iters, len(tried), ""

    def _solves(self, w, params) -> bool:
        """Does ``w`` pass the tests of an accepted solution: every sign, the complementarity and
        the residual (an unloaded step's start)?"""
        nx = self._nx
        residual, comp, _, _ = self.metrics(w[:nx], w[nx:], params)
        gap = np.asarray(self._gap(w, params), float).ravel()
        return (signs_hold(gap, w[nx:], self.opts.comp_tol) and comp <= self.opts.comp_tol
                and residual <= self.opts.residual_tol)

    def _solve_branch(self, w, params, values, fix_gap, fix_p) -> tuple[str, np.ndarray, np.ndarray | None, int, bool]:
        """The branch NLP imposing ``g = 0`` on ``fix_gap`` and ``p = 0`` on ``fix_p`` from ``w``:
        ``(status, w, lam_g, iterations, signs)``, ``signs`` whether every sign, the
        complementarity and the residual tests hold at the solution (B-stationarity is the
        caller's)."""
        nc, ne = self._nc, self._ne
        inf = np.full(nc, np.inf)
        lbg = np.concatenate([np.zeros(ne), np.where(fix_gap, 0.0, -inf), np.where(fix_p, 0.0, -inf)])
        ubg = np.concatenate([np.zeros(ne), np.where(fix_gap, 0.0, inf), np.where(fix_p, 0.0, inf)])
        status, w_new, warm, its = _run(self._bnlp, dict(x0=w, p=values, lbg=lbg, ubg=ubg))
        if status:
            return status, w_new, None, its, False
        return "", w_new, warm[1], its, self._solves(w_new, params)

    def _near_corner(self, w, params, tau) -> bool:
        """Is some pair within the branch NLP's biactive identification ``10 sqrt(tau)`` of a corner?"""
        gap = self._gap(w, params)
        p = w[self._nx:]
        return bool(np.any(np.maximum(np.abs(gap), np.abs(p)) <= 10.0 * np.sqrt(tau)))

    def _branch_nlp(self, w, params, tau, values):
        """Solve the branch NLP identified at ``w`` (``values``: the NLP's parameters, ``params``
        the problem's); returns ``(w, iterations, accepted)``.

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
        tol = 10.0 * np.sqrt(tau) + 100.0 * float(np.max(np.minimum(np.abs(gap), np.abs(p)), initial=0.0))
        part = identify(gap, p, biactive_tol=tol)
        on_gap = gap <= p
        both = part == BIACTIVE
        iters = 0
        # Biactive first, then the identified branch, then ambiguous pairs all in contact / all free.
        candidates = [(imposes_gap(part), imposes_pressure(part)), (on_gap, ~on_gap),
                      (on_gap | both, ~on_gap & ~both), (on_gap & ~both, ~on_gap | both)]
        tried = set()
        for fix_gap, fix_p in candidates:
            key = (fix_gap.tobytes(), fix_p.tobytes())
            if key in tried:
                continue
            tried.add(key)
            if ne + fix_gap.sum() + fix_p.sum() > nx + nc:
                continue  # over-determined (e.g. a biactive pair of the classical problem)
            status, w_new, lam, its, signs = self._solve_branch(w, params, values, fix_gap, fix_p)
            iters += its
            if status:
                continue
            # CasADi's lam_g is the multiplier of f + lam^T g: the convention of b_stationarity.
            wrong_gap, wrong_p = b_stationarity(lam[ne:ne + nc], lam[ne + nc:], fix_gap & fix_p)
            ok = not (wrong_gap.any() or wrong_p.any()) and signs
            if ok:
                return w_new, iters, True
            if wrong_gap.any() or wrong_p.any():
                # leave the corners that are not B-stationary along the piece their multiplier
                # points to (the pressed block's edge: inner pairs in contact, the edge's biactive)
                candidates.append((fix_gap & ~wrong_gap, fix_p & ~wrong_p))
            elif not both.any():
                break
        return w, iters, False


#: Per-contact statuses of a frictional branch; projections only: the corner (closed without
#: traction) and the edge (stuck with the traction on the cone's surface).
OPEN, STICK, SLIP, CORNER, EDGE = 0, 1, 2, 3, 4
#: IPOPT's iteration limit in a frictional branch NLP: the right branch from a relaxed solution
#: takes 1-4 iterations on the generated FCLIB problems, a wrong one (a slip rule at ``s_T = 0``,
#: an infeasible branch) ran to 500 or into restoration.
BRANCH_MAX_ITER = 30
#: Branch NLPs per attempt (the identified statuses, then those identified at each rejected
#: branch solution).
BRANCH_ROUNDS = 5


class _BuiltCoulombMPCC(BuiltFormulation):
    """A frictional problem as an NLP for IPOPT (see the module): the relaxed NLP in
    ``w = [x; p_N; rho]`` (:func:`~.friction.coulomb_constraints`) along the Scholtes
    homotopy, and the branch NLP in ``[x; p]`` of per-contact statuses (open, stick, slip; a
    projection's corners and edges). Both are built once; the friction coefficients, the load,
    ``tau`` and the statuses are parameters."""

    def __init__(self, problem: ComplementarityProblem, opts: MPCC.Options) -> None:
        super().__init__(problem)
        self.opts = opts
        nx, nc, b = problem.n_x, problem.n_contacts, problem.block
        self._nx, self._nc, self._b = nx, nc, b
        base = problem.parameters
        self.parameters = base.extend(tau=1)
        # Classical problems in MX (the sparse maps kept whole: the build took 9.4 s CPU in SX on
        # sphere_shear3d, about 1 s in MX, same solutions); projections in SX as before: onto the
        # frictional set they are nonconvex, and MX's other roundoff led IPOPT to other local KKT
        # points on the friction rungs' block (docs/performance.md).
        sym = ca.MX if problem.kind == "mcp" else ca.SX
        P = sym.sym("P", self.parameters.size)
        own, tau = P[:base.size], P[self.parameters.slice("tau")]
        mu = own[base.slice("friction")]

        def split(v, start, count):
            return [v[start + j * nc:start + (j + 1) * nc] for j in range(count)]

        def objective(z, P):
            return problem.distance.render(z, P) if problem.kind == "mpcc" else sym.zeros(1, 1)

        # Relaxed NLP: the traction r = (p_N, mu p_N rho) is in the cone by construction.
        w = sym.sym("w", nx + b * nc)
        pn, direction = w[nx:nx + nc], split(w, nx + nc, b - 1)
        r = cone_traction(pn, direction, mu)
        z = ca.vertcat(w[:nx], *r)
        rows = coulomb_constraints(split(problem.gap_map.render(z, own), 0, b), r, direction, mu, tau)
        self._solver = ca.nlpsol("mpcc_coulomb", "ipopt", {
            "x": w, "p": P, "f": objective(z, own), "g": ca.vertcat(problem.residual_map.render(z, own), *rows)},
            {"ipopt": _ipopt_options(problem, opts), **_NLPSOL})
        ne = problem.n_residual
        # |rho_j| <= 1 also as bounds: IPOPT keeps iterates inside bounds (fraction to the boundary),
        # not inside general inequalities; from p_N ~ 0 (a cold start) rho is nearly free and its
        # first step reached 1e6 (the pressed block: 156 iterations, 42 with the bounds).
        unit = np.ones((b - 1) * nc)
        self._bounds = dict(lbx=np.concatenate([np.full(nx, -np.inf), np.zeros(nc), -unit]),
                            ubx=np.concatenate([np.full(nx + nc, np.inf), unit]),
                            lbg=np.zeros(ne + 3 * nc), ubg=np.concatenate([np.zeros(ne), np.full(3 * nc, np.inf)]))
        # Branch NLP in z = [x; p]: the residual, b equations per contact and one more row (p_N at
        # a corner, the cone's surface mu^2 p_N^2 - |r_T|^2 at an edge; free elsewhere), the
        # statuses parameters (a square system for the classical problem).
        # The per-contact rows are one SX Function of the contacts' vectors (MX's if_else takes
        # only a scalar condition), called on the MX maps.
        a_s, r_s, mu_s, flags = (ca.SX.sym(n, k * nc) for n, k in (("a", b), ("r", b), ("mu", 1), ("flags", 4)))
        is_open, is_stick, is_corner, is_edge = split(flags, 0, 4)
        rs = split(r_s, 0, b)
        surface = mu_s**2 * rs[0]**2 - sum(v**2 for v in rs[1:])
        contact_rows = ca.Function("branch_rows", [a_s, r_s, mu_s, flags], [ca.vertcat(
            *coulomb_branch(split(a_s, 0, b), rs, mu_s, is_open, is_stick + is_edge, is_corner),
            ca.if_else(is_corner, rs[0], surface, True))])
        zb = sym.sym("z", nx + b * nc)
        Pb = sym.sym("P", base.size + 4 * nc)
        own = Pb[:base.size]
        self._bnlp = ca.nlpsol("bnlp_coulomb", "ipopt", {
            "x": zb, "p": Pb, "f": objective(zb, own),
            "g": ca.vertcat(problem.residual_map.render(zb, own),
                            contact_rows(problem.gap_map.render(zb, own), zb[nx:], own[base.slice("friction")],
                                         Pb[base.size:]))},
            {"ipopt": {**_ipopt_options(problem, opts), "max_iter": BRANCH_MAX_ITER}, **_NLPSOL})
        self._ne = ne
        # Classical problems: the statuses of Alart-Curnier's semismooth Newton solution (as the
        # augmented Lagrangian's, with its default penalty) start the branch NLPs.
        self._predictor = None
        if problem.kind == "mcp" and problem.affine and opts.active_set:
            al = AugmentedLagrangian.Options()
            gamma = problem.scaled_penalty(AugmentedLagrangian.DEFAULT_GAMMA_FACTOR * problem.contact_stiffness)
            self._predictor = BuiltCoulomb(problem, "alart_curnier", gamma, 1.0, tol=al.newton_tol,
                                           residual_tol=al.residual_tol, max_iter=al.max_iter,
                                           comp_tol=max(al.tol, 1e-9), predictor=True)

    # ------------------------------------------------------------------ variables
    def _blocks(self, x, p, params) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(u, r, mu)``: the scaled gaps and tractions ``(nc, b)`` at ``(x, p)`` and the friction."""
        z = np.concatenate([x, p])
        gap = self.problem.gap_map.value(z, params)
        problem = self.problem
        return problem.contact_blocks(gap), problem.contact_blocks(p), problem.parameters.get(params, "friction")

    def _to_nlp(self, x, p, params) -> np.ndarray:
        """``w = [x; p_N; rho]`` of ``(x, p)``: ``rho = r_T / (mu p_N)`` (0 where ``mu p_N = 0``),
        shrunk into the unit disc."""
        _, r, mu = self._blocks(x, p, params)
        pn = np.maximum(r[:, 0], 0.0)
        bound = mu * pn
        rho = r[:, 1:] / np.where(bound > 0, bound, 1.0)[:, None] * (bound > 0)[:, None]
        rho /= np.maximum(1.0, np.linalg.norm(rho, axis=1))[:, None]
        return np.concatenate([x, pn, self.problem.component_major(rho)])

    def _from_nlp(self, w, params) -> tuple[np.ndarray, np.ndarray]:
        """``(x, p)`` of ``w`` (the traction of :func:`~.friction.cone_traction`)."""
        nx, nc, b = self._nx, self._nc, self._b
        mu = self.problem.parameters.get(params, "friction")
        pn = w[nx:nx + nc]
        rho = w[nx + nc:nx + b * nc].reshape(b - 1, nc)
        return w[:nx], np.concatenate([pn, (mu * pn * rho).ravel()])

    def _status(self, x, p, params, tol: float | None = None) -> np.ndarray:
        """Per contact the status identified at ``(x, p)``: closed where ``g_N <= p_N``; then
        stick where ``|s_T| < mu p_N - |r_T|`` (the slip smaller than the traction's distance to
        the cone's surface), else slip. With ``tol`` (projections), the degenerate ones: a corner
        where ``|g_N|`` and ``|p_N|`` are at most ``tol``, else an edge where ``|s_T|`` and
        ``|mu p_N - |r_T||`` are and ``p_N`` exceeds it."""
        u, r, mu = self._blocks(x, p, params)
        slip, room = np.linalg.norm(u[:, 1:], axis=1), mu * r[:, 0] - np.linalg.norm(r[:, 1:], axis=1)
        status = np.where(u[:, 0] > r[:, 0], OPEN, np.where(slip < room, STICK, SLIP))
        if tol is None:
            return status
        corner = np.maximum(np.abs(u[:, 0]), np.abs(r[:, 0])) <= tol
        edge = (status != OPEN) & (np.maximum(slip, np.abs(room)) <= tol) & (r[:, 0] > tol)
        return np.where(corner, CORNER, np.where(edge, EDGE, status))

    # ------------------------------------------------------------------ solves
    def solve(self, params, x0, p0, state=None) -> LocalSolution:
        o = self.opts
        params = np.asarray(params, float)
        x0, p0 = np.asarray(x0, float), np.asarray(p0, float)
        state = state or {}
        if self._predictor is not None:
            predicted = self._predictor.solve(params, x0, p0)
            if predicted.converged:
                # IPOPT solves the branch NLP of the predicted statuses from the start
                (x, p), iters, ok, status = self._branch_nlp(x0, p0, params, 0.0,
                                                             self._status(predicted.x, predicted.p, params))
                if ok:
                    return self._done(x, p, params, True, predicted.iterations + iters, 1,
                                      "converged (branch NLP of the predicted statuses)", status)
        last = state.get("status")
        if last is not None and np.array_equal(np.where(last < CORNER, last, -1),
                                                np.where(last < CORNER, self._status(x0, p0, params), -1)):
            # The start's statuses are the last solution's (its corners and edges kept): its
            # branch NLP first (one IPOPT solve).
            (x, p), iters, ok, status = self._branch_nlp(x0, p0, params, 0.0, last)
            if ok:
                return self._done(x, p, params, True, iters, 1, "converged (branch NLP from the start's branch)",
                                  status)

        def measure(w):
            residual, comp, _, _ = self.metrics(*self._from_nlp(w, params), params)
            return residual, comp

        accepted = {}

        def branch_nlp(w, tau):
            (x, p), iters, ok, accepted["status"] = self._branch_nlp(*self._from_nlp(w, params), params, tau)
            return (self._to_nlp(x, p, params) if ok else w), iters, ok

        out = scholtes_homotopy(_relaxed(self._solver, self.parameters, params, self._bounds), measure=measure,
                                branch_nlp=branch_nlp, near_corner=lambda w, tau: False,
                                w0=self._to_nlp(x0, p0, params), tau0=o.friction_tau0, tau_factor=o.tau_factor,
                                tau_min=o.tau_min, comp_tol=o.comp_tol, residual_tol=o.residual_tol,
                                max_homotopy=o.max_homotopy, early_branch=o.early_branch)
        x, p = self._from_nlp(out.w, params)
        branch = out.converged and out.message.startswith("converged (branch NLP")
        return self._done(x, p, params, out.converged, out.iterations, out.steps, out.message,
                          accepted.get("status") if branch else None)

    def _done(self, x, p, params, converged, iterations, outer, message, status=None) -> LocalSolution:
        if status is None:
            status = self._status(x, p, params)
        state = {"status": status} if converged and self.opts.warm_branch else {}
        return self._finish(x, p, params, converged=converged, iterations=iterations, outer=outer, state=state,
                            message=message)

    def _branch_nlp(self, x, p, params, tau: float, status: np.ndarray | None = None
                    ) -> tuple[tuple[np.ndarray, np.ndarray], int, bool, np.ndarray]:
        """The branch NLP of ``status`` (default: identified at ``(x, p)``): returns ``((x, p),
        iterations, accepted, status)``. A solution is accepted if Coulomb's natural-map residual
        is at most ``comp_tol`` and the residual at most ``residual_tol`` (it then satisfies the
        law, all its signs included), and a projection's corners and edges are B-stationary
        (:meth:`_leave`). A branch solution that is not is where the identification erred: the
        statuses identified there (an open contact that penetrates closes, a stuck one outside
        the cone slides, a closed one that pulls opens) are tried next, as a primal-dual
        active-set method would, at most :data:`BRANCH_ROUNDS` times and never twice the same. In
        a projection, a contact tried both open and closed that would switch again is tried as a
        corner, one tried both stuck and sliding as an edge, as a biactive normal pair is; a corner
        or edge that is not B-stationary leaves along the piece its multipliers point to. Where
        those rounds fail, a projection's rounds start again from the identification with the
        degenerate statuses within ``10 sqrt(tau) + 100 c`` (``c`` the natural-map residual at
        ``(x, p)``; :meth:`_status`)."""
        starts = [self._status(x, p, params) if status is None else status]
        if status is None and self.problem.kind == "mpcc":
            _, comp, _, _ = self.metrics(x, p, params)
            starts.append(self._status(x, p, params, 10.0 * np.sqrt(tau) + 100.0 * comp))
        z0, iters, tried = np.concatenate([x, p]), 0, set()
        for start in starts:
            z, its, ok, status = self._rounds(z0, start, params, tried)
            iters += its
            if ok:
                return (z[:self._nx], z[self._nx:]), iters, True, status
        return (x, p), iters, False, status

    def _rounds(self, z, status, params, tried: set) -> tuple[np.ndarray, int, bool, np.ndarray]:
        """The active-set rounds of :meth:`_branch_nlp` from ``z`` and ``status`` (at most
        :data:`BRANCH_ROUNDS`, none in ``tried``): ``(z, iterations, accepted, status)``."""
        nx, nc, b, ne = self._nx, self._nc, self._b, self._ne
        projection = self.problem.kind == "mpcc"
        seen = {k: np.zeros(nc, bool) for k in (OPEN, STICK, SLIP)}
        free = np.full(nc, np.inf)
        iters = rounds = 0
        while rounds < BRANCH_ROUNDS and status.tobytes() not in tried:
            rounds += 1
            tried.add(status.tobytes())
            held = (status == CORNER) | (status == EDGE)
            bound = np.concatenate([np.zeros(ne + b * nc), np.where(held, 0.0, free)])
            flags = np.concatenate([params] + [status == k for k in (OPEN, STICK, CORNER, EDGE)])
            run, z, warm, its = _run(self._bnlp, dict(x0=z, p=flags, lbg=-bound, ubg=bound))
            iters += its
            if run:
                break
            residual, comp, _, _ = self.metrics(z[:nx], z[nx:], params)
            left = self._leave(warm[1], status, z, params)
            if comp <= self.opts.comp_tol and residual <= self.opts.residual_tol and np.array_equal(left, status):
                return z, iters, True, status
            for k in seen:
                seen[k] |= status == k
            new = self._status(z[:nx], z[nx:], params)
            if projection:
                opens = (new == OPEN) != (status == OPEN)
                slides = (new == SLIP) & (status == STICK) | (new == STICK) & (status == SLIP)
                closed = seen[STICK] | seen[SLIP]
                new = np.where(held, left, np.where(opens & seen[OPEN] & closed, CORNER,
                                                    np.where(slides & seen[STICK] & seen[SLIP], EDGE, new)))
            status = new
        return z, iters, False, status

    def _leave(self, lam: np.ndarray, status: np.ndarray, z: np.ndarray, params) -> np.ndarray:
        """``status`` with the corners and edges of the branch solution ``z`` that are not
        B-stationary left along the piece their multipliers point to (CasADi's ``lam``, of
        ``f + lam^T g``: a change ``dc`` of one held row changes the distance by ``-lam dc``), within
        ``1e-8 max(1, max |lam|)``; the solution is B-stationary where nothing changes.

        Corner (``g_N = 0, r = 0``): opening must not decrease the distance (``lam_g <= 0``, as for
        a biactive normal pair; else open), nor any traction in the cone, ``-(lam_p, lam_T) in
        K_mu^*`` (``-lam_p >= mu |lam_T|``; else stick. Sufficient: the slip piece allows fewer
        tractions; exact at ``mu = 0``). Edge (``u = 0``, ``|r_T| = mu p_N``): neither sliding against
        the traction (``s_T = -t r_T``, ``t > 0``: ``lam_s . r_T >= 0``; else slip) nor moving it
        into the cone (``lam_h <= 0`` for ``h = mu^2 p_N^2 - |r_T|^2``; else stick)."""
        corner, edge = status == CORNER, status == EDGE
        if not (corner.any() or edge.any()):
            return status
        nc, b, ne = self._nc, self._b, self._ne
        mu = self.problem.parameters.get(params, "friction")
        branch = lam[ne:]
        lam_n, lam_t, lam_x = branch[:nc], branch[nc:b * nc].reshape(b - 1, nc), branch[b * nc:]
        tol = 1e-8 * max(1.0, float(np.max(np.abs(lam), initial=0.0)))
        r_t = z[self._nx + nc:self._nx + b * nc].reshape(b - 1, nc)
        opens = lam_n > tol
        presses = -lam_x < mu * np.linalg.norm(lam_t, axis=0) - tol
        slides = np.sum(lam_t * r_t, axis=0) < -tol * np.linalg.norm(r_t, axis=0)
        enters = lam_x > tol
        out = np.where(corner & opens, OPEN, np.where(corner & presses, STICK, status))
        return np.where(edge & slides, SLIP, np.where(edge & enters, STICK, out))
