"""Solving FCLIB frictional contact problems (``docs/maths.md``, section 15): one entry point,
:func:`solve_fclib`, over the projected Gauss-Seidel reference, every frictional formulation and
the default hybrid. The problems, their files and their error measure are
:mod:`ddcm_casadi.problems.fclib`'s; this driver composes them with the formulations' solves."""

from __future__ import annotations

import math
import os
import time

import numpy as np

from ddcm_casadi.errors import InputError
from ddcm_casadi.problems.fclib import (
    LocalProblem, GlobalProblem, FclibComplementarity, FrictionSolution, as_complementarity_problem, read_fclib, natural_map_error, solve_projected_gauss_seidel)


# ------------------------------------------------------------------------------- one entry point
#: The formulations :func:`solve_fclib` runs by name: the registered formulation and its options.
FORMULATION_METHODS: dict[str, tuple[str, dict]] = {
    "fischer_burmeister": ("fischer_burmeister", {}),
    "natural_map": ("fischer_burmeister", {"coulomb_function": "natural_map"}),
    "augmented_lagrangian": ("augmented_lagrangian", {}),
    "penalty": ("penalty", {}),
}


def frictional_methods() -> tuple[str, ...]:
    """Every method of :func:`solve_fclib`: ``default``, ``pgs``, :data:`FORMULATION_METHODS`, then
    any other registered formulation that supports the ``coulomb`` contact law."""
    from ddcm_casadi import formulations

    others = [name for name in formulations.enforcing("coulomb") if name not in FORMULATION_METHODS]
    return ("default", "pgs", *FORMULATION_METHODS, *others)

#: The default method's projected Gauss-Seidel target before Newton (the FCLIB benchmarks' loose level).
PGS_TOL = 1e-4
#: The proximal ``eta`` is ``PROXIMAL_FACTOR min(1, e / PGS_TOL)`` times the mean diagonal of ``W``,
#: rounded down to a power of ten (one build per power), never increasing, at least ``10^PROXIMAL_MIN_LEVEL``.
PROXIMAL_FACTOR = 0.1
#: Sweeps (at least) past PGS_TOL that measure projected Gauss-Seidel's rate: the default method
#: goes on with it if that rate reaches ``tol`` in at most PGS_PATIENCE times the sweeps so far.
PGS_PROBE = 5
PGS_PATIENCE = 2.0
PROXIMAL_MIN_LEVEL = -12
#: Proximal steps without a 0.1 % decrease of the best error before the default method goes back to
#: projected Gauss-Seidel.
PROXIMAL_STALL = 3
#: Semismooth Newton iterations per stage of the default method (its own stopping tests at
#: :data:`NEWTON_TOL`; the natural-map error decides).
NEWTON_MAX_ITER = 30
NEWTON_TOL = 1e-12


def _formulation(method: str, options: dict):
    """The formulation of ``method`` (:data:`FORMULATION_METHODS` or a registered name) with ``options``."""
    from ddcm_casadi import formulations

    name, base = FORMULATION_METHODS.get(method, (method, {}))
    return formulations.get(name, **{**base, **options})


def _newton(built, fc: FclibComplementarity, params: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, bool, int]:
    """``(r, converged, iterations)``: the formulation's semismooth Newton (its published system,
    without the smoothing fallback) on ``fc`` from the reactions ``r``."""
    from ddcm_casadi.loops.newton import newton_solve

    system = built.newton_system()
    z0, P = built.newton_point(params, *fc.point(r))
    f = system.functions
    res = newton_solve(f.rj, f.r, z0, P, jacobian=f.jacobian, tol=NEWTON_TOL, residual_tol=NEWTON_TOL,
                       max_iter=NEWTON_MAX_ITER)
    return fc.reactions(system.unpack(res.z)["p"]), res.converged, res.iterations


def _positive_int(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value <= 1_000_000:
        raise InputError(f"{name} must be an integer in 1..1000000, got {value!r}")
    return int(value)


def solve_fclib(source: LocalProblem | GlobalProblem | str | os.PathLike, method: str = "default", *,
                tol: float = 1e-8, r0: np.ndarray | None = None, max_sweeps: int = 1000, max_rounds: int = 3,
                max_proximal: int = 40, newton: str = "augmented_lagrangian", **options) -> FrictionSolution:
    r"""Solve an FCLIB problem to the natural-map error ``tol`` (:func:`natural_map_error`).

    Parameters
    ----------
    source : LocalProblem, GlobalProblem or path
        The problem, or an FCLIB file (:func:`read_fclib`).
    method : str
        ``"default"`` (below); ``"pgs"`` (:func:`solve_projected_gauss_seidel`, ``max_sweeps``);
        or a formulation of :data:`FORMULATION_METHODS` (``fischer_burmeister``: the SOC
        Fischer--Burmeister function, ``natural_map``, ``augmented_lagrangian``: Alart--Curnier,
        ``penalty``; :func:`frictional_methods` lists them all), built on :func:`as_complementarity_problem` and solved once by its semismooth
        Newton from ``r0`` (default: the cold start ``r = 0``).
    tol : float
        The natural-map error to reach, in ``[1e-15, 1)``.
    r0 : (nc, 3) array, optional
        Start reactions.
    max_sweeps, max_rounds, max_proximal : int
        Sweeps per projected Gauss-Seidel stage; rounds and proximal steps per round of the
        default method.
    newton : str
        The formulation of the default method's Newton stages.
    **options
        Options of the formulation (``method`` or ``newton``).

    Returns
    -------
    FrictionSolution
        Reactions, velocities, error, Newton iterations, sweeps, seconds, ``converged``
        (``error <= tol``) and the stages run (``log``).

    Notes
    -----
    The default method is a hybrid in the spirit of Siconos' nonsmooth-Newton hybrids:

    1. projected Gauss-Seidel to :data:`PGS_TOL` (the active set, roughly), then on to ``tol``
       if its rate over :data:`PGS_PROBE` or more sweeps says that takes at most
       :data:`PGS_PATIENCE` times the sweeps so far;
    2. semismooth Newton of the ``newton`` formulation from the best point;
    3. if Newton stalls: proximal-point steps ``r_{k+1}`` = the solution of the problem with
       ``u = W r + q + eta_k (r - r_k)`` (:func:`as_complementarity_problem` with ``proximal``),
       each by the same Newton from ``r_k``; ``eta_k`` shrinks with the error
       (:data:`PROXIMAL_FACTOR`), so the steps approach Newton's on the problem itself while
       ``W + eta I`` keeps the Jacobian nonsingular where ``W`` is only semidefinite (more
       reaction components in contact than the bodies' freedoms: Newton's Jacobian is then
       singular on the stick pieces);
    4. if the proximal steps stall (:data:`PROXIMAL_STALL`): projected Gauss-Seidel from the best
       point to a hundredth of its error, then 2-4 again, at most ``max_rounds`` times.

    The best point met is returned. Nothing guarantees convergence (Coulomb friction is not a
    potential); ``converged`` says (``docs/maths.md``, section 15).
    """
    methods = frictional_methods()
    if method not in methods:
        raise InputError(f"unknown FCLIB method {method!r}; known: {', '.join(methods)}")
    if newton not in methods[2:]:
        raise InputError(f"unknown Newton formulation {newton!r}; known: {', '.join(methods[2:])}")
    if not (isinstance(tol, (int, float)) and 1e-15 <= tol < 1):
        raise InputError(f"tol must be in [1e-15, 1), got {tol!r}")
    max_sweeps, max_rounds, max_proximal = (_positive_int(k, v) for k, v in (
        ("max_sweeps", max_sweeps), ("max_rounds", max_rounds), ("max_proximal", max_proximal)))
    if options and method == "pgs":
        raise InputError(f"method 'pgs' takes no formulation options, got {', '.join(sorted(options))}")
    problem = source if isinstance(source, (LocalProblem, GlobalProblem)) else read_fclib(source)
    local = problem.local()
    if r0 is not None:
        r0 = np.asarray(r0, float).ravel()
        if r0.size != 3 * local.n_contacts or not np.all(np.isfinite(r0)):
            raise InputError(f"r0 must hold 3 finite reactions per contact ({3 * local.n_contacts}), got {r0.size}")
    t0 = time.perf_counter()
    if method == "pgs":
        return solve_projected_gauss_seidel(local, tol=tol, max_sweeps=max_sweeps, r0=r0)
    if method == "default":
        return _solve_default(problem, local, tol, r0, max_sweeps, max_rounds, max_proximal,
                              _formulation(newton, options), t0)
    fc = as_complementarity_problem(problem)
    built = _formulation(method, options).build(fc.problem)
    sol = built.solve(fc.params, *(fc.start() if r0 is None else fc.point(r0)))
    error = fc.error(sol.x, sol.p, local)
    seconds = time.perf_counter() - t0
    r = fc.reactions(sol.p)
    return FrictionSolution(r.reshape(-1, 3), (local.W @ r + local.q).reshape(-1, 3), error, sol.iterations,
                            seconds, bool(error <= tol), method, 0,
                            (dict(stage=method, iterations=sol.iterations, error=error, seconds=seconds),), sol.message)


def _solve_default(problem: LocalProblem | GlobalProblem, local: LocalProblem, tol: float, r0, max_sweeps: int, max_rounds: int,
                   max_proximal: int, formulation, t0: float) -> FrictionSolution:
    """The default method of :func:`solve_fclib` (see there)."""
    log: list[dict] = []
    counts = dict(iterations=0, sweeps=0)

    def stage(name: str, iterations: int, error: float, sweeps: int = 0, **extra) -> None:
        counts["iterations"] += iterations
        counts["sweeps"] += sweeps
        log.append(dict(stage=name, iterations=sweeps or iterations, error=error,
                        seconds=time.perf_counter() - t0, **extra))

    pgs = solve_projected_gauss_seidel(local, tol=max(tol, PGS_TOL), max_sweeps=max_sweeps, r0=r0)
    stage("pgs", 0, pgs.error, pgs.iterations)
    if tol < pgs.error <= PGS_TOL and pgs.iterations:
        # PGS on, if its rate over a few more sweeps reaches tol in at most PGS_PATIENCE times the sweeps so far
        more = solve_projected_gauss_seidel(local, tol=tol, max_sweeps=max(PGS_PROBE, pgs.iterations // 5), r0=pgs.r)
        stage("pgs", 0, more.error, more.iterations)
        rate = (more.error / pgs.error) ** (1.0 / max(more.iterations, 1)) if pgs.error > 0 else 0.0
        needed = math.log(tol / more.error) / math.log(rate) if 0 < rate < 1 and more.error > tol else 0.0
        pgs = more
        if more.error > tol and 0 < rate < 1 and needed <= PGS_PATIENCE * counts["sweeps"]:
            pgs = solve_projected_gauss_seidel(local, tol=tol, max_sweeps=int(2 * needed) + PGS_PROBE, r0=more.r)
            stage("pgs", 0, pgs.error, pgs.iterations)
            if pgs.error > more.error:
                pgs = more
    best_r, best_e = pgs.r.ravel(), pgs.error
    d = local.W.diagonal()
    scale = float(np.mean(d[d > 0])) if np.any(d > 0) else 1.0
    fc = built = None
    proximal: dict[int, tuple] = {}  # one build per power of ten of eta
    for _ in range(max_rounds if best_e > tol else 0):
        if built is None:
            fc = as_complementarity_problem(problem)
            built = formulation.build(fc.problem)
        r, _, its = _newton(built, fc, fc.params, best_r)
        e = natural_map_error(local, r)
        stage("newton", its, e)
        if e < best_e:
            best_r, best_e = r, e
        if best_e <= tol:
            break
        r, e, level, stalls, steps, its = best_r, best_e, None, 0, 0, 0
        while steps < max_proximal and stalls < PROXIMAL_STALL and best_e > tol:
            steps += 1
            wanted = max(PROXIMAL_MIN_LEVEL, math.floor(math.log10(PROXIMAL_FACTOR * min(1.0, e / PGS_TOL))))
            level = wanted if level is None else min(level, wanted)
            if level not in proximal:
                fcp = as_complementarity_problem(problem, proximal=scale * 10.0**level)
                proximal[level] = fcp, formulation.build(fcp.problem)
            fcp, bp = proximal[level]
            sol = bp.solve(fcp.centred(r), *fcp.point(r))  # with the formulation's smoothing fallback
            its += sol.iterations
            if not sol.converged:  # the step's own problem failed: regularise more, from the same centre
                level, stalls = min(level + 1, 0), stalls + 1
                continue
            r = fcp.reactions(sol.p)
            e = natural_map_error(local, r)
            if e < (1 - 1e-3) * best_e:
                best_r, best_e, stalls = r, e, 0
            else:
                stalls += 1
        stage("proximal", its, best_e, steps=steps, eta=scale * 10.0**level if level is not None else 0.0)
        if best_e <= tol:
            break
        pgs = solve_projected_gauss_seidel(local, tol=max(tol, best_e / 100), max_sweeps=max_sweeps, r0=best_r)
        stage("pgs", 0, pgs.error, pgs.iterations)
        if pgs.error < best_e:
            best_r, best_e = pgs.r.ravel(), pgs.error
        if best_e <= tol:
            break
    converged = bool(best_e <= tol)
    return FrictionSolution(best_r.reshape(-1, 3), (local.W @ best_r + local.q).reshape(-1, 3), best_e,
                            counts["iterations"], time.perf_counter() - t0, converged, "default", counts["sweeps"],
                            tuple(log), "converged" if converged else f"error {best_e:.1e} > tol after {len(log)} stages")
