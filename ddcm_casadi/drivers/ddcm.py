"""The DDCM driver: one alternation loop for every data-driven scheme.

Each load step alternates

1. the projection onto ``Z_E`` (:class:`~ddcm_casadi.drivers.ddcm_projection.Projection`: the
   chosen formulation, warm-started, checked against the exact branch enumeration where the
   problem is affine with few contact pairs; built by
   :func:`~ddcm_casadi.drivers.ddcm_reduced.build_projection`, it is by default the
   Kirchdoerfer-Ortiz reduction where that applies: one factor of ``K_C`` for the whole path and
   the formulation on the contact pairs alone, ``PathResult.projection_path``), and
2. the material update of the scheme (:mod:`ddcm_casadi.drivers.scheme`): the nearest datum
   (plain DDCM, with the data search of ``search``), LCDD or max-ent (``variant``),

until the scheme says the material states have settled. Where each step starts, restarts, a
greedy global improvement after the fixed point (:mod:`~ddcm_casadi.drivers.ddcm_improve`) and the
scheme are chosen by :class:`~ddcm_casadi.drivers.ddcm_options.DDCMOptions` (by default the first
step starts from the data point nearest the origin and every later step from the previous one's
material states). Every step is finished by the physical checks
(:func:`~ddcm_casadi.drivers.checks.finish_step`) before it is reported, whatever the scheme.
A step that fails (no fixed point, a projection that did not converge, a physical check) is
bisected (:mod:`~ddcm_casadi.drivers.substeps`): sub-steps of its load, each an alternation from
the previous sub-step's material states and ``Z_E`` solution, from the last converged step, down
to ``min_substep`` of a step; restarts, greedy improvement and the certificate run at the last
sub-step (the step's own load) only.
For one-element problems (and, with ``exact_max``, a few elements) the global DDCM optimum is also
found by enumerating the data assignments (closed forms, :mod:`ddcm_casadi.drivers.ddcm_search`),
with whether the search reached it and the gap.

The exact enumeration, the greedy screen and the elastic start need the affine form of the
problem (:attr:`~ddcm_casadi.problems.contract.ComplementarityProblem.affine`): otherwise they are
skipped, and the steps and the path say so (``StepResult.notes``, ``PathResult.warnings``).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Callable

import numpy as np

from ddcm_casadi.errors import InputError
from ddcm_casadi.parallel import limited_blas
from ddcm_casadi.problems.exact import ExactEnumerator
from ddcm_casadi.data.extrapolation import DataCoverage, coarse_data
from ddcm_casadi.problems.build import ProblemPair
from ddcm_casadi.drivers import ddcm_improve
from ddcm_casadi.drivers.checks import finish_step
from ddcm_casadi.drivers.ddcm_options import DDCMOptions
from ddcm_casadi.drivers.ddcm_projection import Projection
from ddcm_casadi.drivers.ddcm_reduced import path_description
from ddcm_casadi.drivers.ddcm_search import params_projection, point_ranges, start_assignment
from ddcm_casadi.drivers.records import (
    MaterialStates, PathResult, Run, StepResult, check_convergence, count, new_tally,
)
from ddcm_casadi.drivers.schemes import SCHEMES
from ddcm_casadi.drivers.substeps import (
    DEFAULT_MIN_SUBSTEP, accepted, bisect, bisection_enabled, check_min_substep, finish_bisected, interpolate,
    unloaded_start,
)

#: Why a method was skipped on a problem that is not affine.
NOT_AFFINE = "the problem is not affine"


class DDCMSolver:
    """Alternating projections for one model and one built projection formulation.

    Parameters
    ----------
    problems : ProblemPair
        Needs the projection (a material data set).
    built
        The projection formulation, built (on the full projection, or reduced by
        :func:`~ddcm_casadi.drivers.ddcm_reduced.build_projection`).
    options : DDCMOptions, optional
        Iterations, data search, starts, restarts, improvement, certificates, scheme (default
        ``DDCMOptions()``).
    max_outer : int, optional
        Replaces ``options.max_outer`` (validated as it).
    search : str, optional
        Replaces ``options.search``: a backend of :data:`ddcm_casadi.data.search.SEARCHES`.
    enumerate_pairs : int
        Affine problems with at most this many contact pairs consult the exact branch enumeration
        (:attr:`exact`, built on first use: every projection is checked against it where there is
        at least one pair; without pairs a projection is one linear solve, nothing to enumerate).
    global_search : bool
        Report the global optimum where it can be enumerated.
    min_substep : float
        The smallest sub-step of a failed load step, as a fraction of the step
        (:func:`~ddcm_casadi.drivers.substeps.check_min_substep`; default 1/16; 0 or 1: no bisection).
    """

    #: Exact projections remembered per problem (:meth:`_exact_projection`), keys and answers
    #: together at most this many floats (8 MB).
    EXACT_CACHE_VALUES = 1_000_000

    def __init__(self, problems: ProblemPair, built, *, max_outer: int | None = None, enumerate_pairs: int = 4,
                 global_search: bool = True, search: str | None = None, options: DDCMOptions | None = None,
                 min_substep: float = DEFAULT_MIN_SUBSTEP) -> None:
        if problems.projection is None:
            raise InputError("the DDCM variant needs a material data set")
        if options is not None and not isinstance(options, DDCMOptions):
            raise InputError(f"DDCM options must be a DDCMOptions, got {type(options).__name__}")
        options = options if options is not None else DDCMOptions()
        given = {k: v for k, v in dict(max_outer=max_outer, search=search).items() if v is not None}
        self.options = dataclasses.replace(options, **given) if given else options  # validated
        self.problems, self.built = problems, built
        self.min_substep = check_min_substep(min_substep)
        model = problems.model
        self._check_initial(model)
        if self.options.variant == "lcdd" and model.strain_components != 1:
            raise InputError("ddcm variant 'lcdd' is implemented for one-component points (bars, trusses)")
        # The data's range and the exact enumeration (of Signorini pairs' branches; a frictional
        # law's cone has no finite set of pieces), once per problem (not timed with the steps):
        # the solvers of the formulations of one model share them.
        self.coverage = problems.projection.shared(
            ("data_coverage", self.options.search),
            lambda: DataCoverage(model.dataset, model.n_points, self.options.search))
        self.affine = bool(problems.projection.affine)
        self.enumerate_pairs = enumerate_pairs
        enumerable = self.affine and not model.frictional and model.n_contacts <= enumerate_pairs
        # N^m assignments, in logarithms: it overflows a float for a continuum's thousands of points.
        log_assign = float(np.sum(np.log(point_ranges(model)[1].astype(float))))
        self.global_search = (global_search and enumerable
                              and (model.n_points == 1 or (self.options.exact_max > 0
                                                            and log_assign <= np.log(self.options.exact_max) + 1e-12)))
        self.scheme = SCHEMES[self.options.variant](model, self.options)
        # Without pairs a projection is one linear solve: nothing to check it against.
        self.projection = Projection(problems, built, lambda: self.exact, self.EXACT_CACHE_VALUES,
                                     check=enumerable and model.n_contacts > 0)
        #: What is left out for this problem, and why (each step's ``notes``, the path's ``warnings``).
        self.notes = self._skipped(model, enumerate_pairs)

    @property
    def exact(self) -> ExactEnumerator | None:
        """The exact branch enumeration of an affine problem with at most ``enumerate_pairs``
        contact pairs (else None), built on first use (the projection check, the greedy screen,
        the global optimum) and shared by the solvers of one model."""
        projection = self.problems.projection
        model = self.problems.model
        if not (self.affine and not model.frictional and model.n_contacts <= self.enumerate_pairs):
            return None
        return projection.shared(("exact_enumerator", self.enumerate_pairs),
                                 lambda: ExactEnumerator(projection, max_pairs=self.enumerate_pairs))

    @property
    def max_outer(self) -> int:
        """Alternating projections per run (``options.max_outer``)."""
        return self.options.max_outer

    @property
    def search(self) -> str:
        """The data search backend (``options.search``)."""
        return self.options.search

    @property
    def search_stats(self) -> dict:
        """``queries`` and ``fallbacks`` (uncertified states) of the data search, accumulated."""
        return getattr(self.scheme, "stats", {})

    def _check_initial(self, model) -> None:
        """An explicit initial assignment must give every point a datum of its own set."""
        if self.options.initial is None:
            return
        initial = np.asarray(self.options.initial, dtype=np.intp)
        offset, size = point_ranges(model)
        if initial.size != model.n_points:
            raise InputError(f"ddcm option initial has {initial.size} indices, the model has "
                             f"{model.n_points} material points")
        if np.any(initial < offset) or np.any(initial >= offset + size):
            raise InputError("ddcm option initial: an index is outside its point's data set")

    def _skipped(self, model, enumerate_pairs: int) -> list[str]:
        """The notes of the methods skipped because the problem is not affine (none if it is)."""
        if self.affine:
            return []
        o, notes = self.options, []
        if model.n_contacts <= enumerate_pairs:
            notes.append(f"exact branch enumeration and global optimum skipped: {NOT_AFFINE}")
        if o.improve == "greedy" and o.greedy_screen:
            notes.append(f"greedy moves not screened (next-nearest data instead): {NOT_AFFINE}")
        if o.start == "elastic":
            notes.append(f"elastic start replaced by the origin start: {NOT_AFFINE}")
        return notes

    def initial_assignment(self, k: int) -> np.ndarray:
        """The data assignment load step ``k`` starts from when it does not continue the previous
        step's: ``initial`` at the first step if given, else ``start`` (seeded per step; the
        elastic start needs an affine problem, else the origin start)."""
        o = self.options
        if k == 0 and o.initial is not None:
            return np.asarray(o.initial, dtype=np.intp)
        start = "origin" if o.start == "elastic" and not self.affine else o.start
        return start_assignment(self.problems.model, start, k, np.random.default_rng((o.seed, k, 0)), o.search)

    def project_data(self, k: int, strain_star, stress_star, warm: tuple, cost: dict, *, exact: bool = False,
                     known: tuple | None = None):
        """The ``Z_E`` projection of step ``k``'s material states
        (:meth:`~ddcm_casadi.drivers.ddcm_projection.Projection.project`)."""
        return self.projection.project(k, strain_star, stress_star, warm, cost, exact=exact, known=known)

    def _exact_projection(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """The exact projection (:meth:`~ddcm_casadi.drivers.ddcm_projection.Projection.exact_projection`)."""
        return self.projection.exact_projection(params)

    def alternate(self, k: int, start: MaterialStates, x, p, state, *, exact_first: bool = False,
                  known: tuple | None = None) -> tuple[Run, tuple]:
        """The alternation of step ``k`` from the material states ``start`` (the Z_E solves
        warm-started from ``x, p, state``) until the scheme settles, a projection fails, or after
        ``max_outer`` projections. ``exact_first``: the first projection is the exact one where that
        is the formulation's answer (the greedy screen has evaluated it in closed form:
        :meth:`~ddcm_casadi.drivers.ddcm_projection.Projection.exact_solution`; ``known``: its
        ``(x, p, objective)`` where the caller has them). Returns the run and the last ``(x, p, state)``."""
        problems, scheme = self.problems, self.scheme
        scheme.begin(start)
        star = start
        cost, t_search = dict(inner=0, t_project=0.0), 0.0
        converged, message = False, "maximum outer iterations reached"
        for outer in range(1, self.max_outer + 1):
            sol, is_global, err, failed = self.project_data(k, star.strain, star.stress, (x, p, state), cost,
                                                            exact=exact_first and outer == 1, known=known)
            if failed:
                message = failed
                f = problems.fields("mpcc", sol.x, sol.p, self.projection.last_params)  # what it returned
                break
            x, p, state = sol.x, sol.p, sol.state
            t1 = time.perf_counter()
            f = problems.fields("mpcc", sol.x, sol.p, self.projection.last_params)
            update = scheme.update(f["strain"], f["stress"])
            t_search += time.perf_counter() - t1
            star = update.star
            if update.done:
                converged, message = update.converged, update.message
                break
        star = scheme.finish(star)  # f: the fields of the last projection
        distance = (float(0.5 * np.dot(problems.model.volumes, scheme.distance2(f["strain"], f["stress"], star)))
                    if sol.converged else float("inf"))
        run = Run(star=star, sol=sol, fields=f, distance=distance, converged=converged, message=message, outer=outer,
                  inner=cost["inner"], t_project=cost["t_project"], t_search=t_search, error=err, is_global=is_global)
        return run, (x, p, state)

    def _closed_form(self, k: int) -> Callable[[np.ndarray], tuple | None] | None:
        """The exact projection of step ``k``'s parameters from the step's solved directions
        (:func:`~ddcm_casadi.drivers.ddcm_search.params_projection`), where every projection is
        checked against an exact enumeration and the greedy screen solves the directions for the
        step anyway (``2 m k + 1`` right-hand sides: a few checks alone would not repay them);
        else None."""
        opts = self.options
        screens = opts.improve == "greedy" and opts.greedy_screen
        exact = self.exact if self.projection.check and screens else None
        if exact is None:
            return None
        return lambda params: params_projection(self.problems, exact, k, params)

    def solve_step(self, k: int, start: MaterialStates, warm: tuple) -> tuple[StepResult, Run, tuple]:
        """Load step ``k`` from the material states ``start``, the Z_E solves warm-started from
        ``warm = (x, p, state)``: the alternation, then (for a scheme that assigns data) restarts,
        greedy improvement and the global-optimum certificate. Returns the finished step, the
        best run and the ``(x, p, state)`` it ended at."""
        opts, tally = self.options, new_tally()
        best, best_warm = self.alternate(k, start, *warm)
        count(tally, best)
        if self.scheme.assigns_data and (opts.restarts or opts.improve == "greedy"):
            visited = {start.key, best.star.key}
            # The search's many projections of one step are checked against the step's closed
            # forms (one product each instead of a solve with the bordered matrix).
            self.projection.closed_form = self._closed_form(k)
            try:
                best, best_warm = ddcm_improve.restart(self, k, best, best_warm, warm, visited, tally)
                if opts.improve == "greedy" and best.converged:
                    best, best_warm = ddcm_improve.greedy(self, k, best, best_warm, visited, tally)
            finally:
                self.projection.closed_form = None
        step = self._step_result(k, best, tally)
        if self.global_search and self.scheme.assigns_data and best.sol.converged:
            self.projection.certify(k, step)
        return step, best, best_warm

    @limited_blas
    def solve(self, *, formulation_name: str = "", raise_on_failure: bool = False,
              progress: Callable[[StepResult], None] | None = None) -> PathResult:
        """Every load step in turn, each from the previous step's material states and Z_E
        solution (``warm``), or from its own start; a step that fails is bisected
        (:meth:`_bisect`); ``progress(step)`` after each."""
        problems, model = self.problems, self.problems.model
        out = PathResult("ddcm", formulation_name, warnings=list(self.notes), projection_path=path_description(self.built))
        warm = (np.zeros(problems.projection.n_x), np.zeros(problems.projection.n_pairs), None)
        start, self.projection.previous = None, None
        converged = None  # the last converged step: (k, its history, material states, Z_E solution)
        t_all = time.perf_counter()
        for k in range(model.n_steps):
            t0 = time.perf_counter()
            warm_start = start is not None and self.options.warm
            if not warm_start:
                start = self.scheme.states(self.initial_assignment(k))
            step, best, warm_out = self.solve_step(k, start, warm)
            if not accepted(step, best.sol.x, best.sol.p) and bisection_enabled(self.min_substep):
                step, best, warm_out = self._bisect(k, step, best, warm_out, converged)
            if not accepted(step, best.sol.x, best.sol.p) and warm_start:
                step, best, warm_out = self._from_initial(k, step, best, warm_out, warm)
            step.seconds = time.perf_counter() - t0
            out.steps.append(step)
            if progress is not None:
                progress(step)
            check_convergence(step, raise_on_failure, f"ddcm/{formulation_name}")
            start, warm = best.star, warm_out
            if step.converged:
                converged = (k, self.projection.previous, best.star, warm_out)
                self.projection.previous = dict(u=step.u, p=step.p, traction=step.traction, step=k,
                                                strain=step.strain, stress=step.stress)
        out.solve_seconds = time.perf_counter() - t_all
        return out

    def _from_initial(self, k: int, failed: StepResult, best: Run, warm_out: tuple,
                      warm: tuple) -> tuple[StepResult, Run, tuple]:
        """Step ``k`` once more from its initial assignment (:meth:`initial_assignment`) after the
        run from the previous step's assignment failed even in sub-steps: an alternation can cycle
        from one start and settle from another (measured with Coulomb friction at the stick-slip
        transition, whose admissible set is a union of pieces). Returns the new run if it
        settles (its record counts both runs' work), else the failed one."""
        step, retry, retry_warm = self.solve_step(k, self.scheme.states(self.initial_assignment(k)), warm)
        if not accepted(step, retry.sol.x, retry.sol.p):
            return failed, best, warm_out
        for name in ("iterations", "projections", "runs"):
            setattr(step, name, getattr(step, name) + getattr(failed, name))
        step.message += f"; from the initial assignment (the previous step's cycled: {failed.message})"
        return step, retry, retry_warm

    def _bisect(self, k: int, full: StepResult, full_best: Run, full_warm: tuple,
                converged: tuple | None) -> tuple[StepResult, Run, tuple]:
        """Step ``k`` in sub-steps (:func:`~ddcm_casadi.drivers.substeps.bisect`) after its full
        step (``full``, its best run and last ``Z_E`` solution) failed.

        The sub-steps start from the last converged step (``converged``: its index, history,
        material states and ``Z_E`` solution), or before any from the unloaded state
        (:func:`~ddcm_casadi.drivers.substeps.unloaded`) with the step's initial assignment. A
        sub-step short of the step's load is one alternation with the projections' load entries
        interpolated, finished by the physical checks at its own load; the last one is the
        step's full :meth:`solve_step`. Returns the last sub-step's record, run and solution
        (converged) or the full step's (not), with the costs of every attempt.
        """
        problems = self.problems
        P, names = problems.projection.parameters, problems.model.load_names()
        previous = self.projection.previous
        if converged is None:
            j, history = None, None
            star0 = self.scheme.states(self.initial_assignment(k))
            warm0 = (np.zeros(problems.projection.n_x), np.zeros(problems.projection.n_pairs), None)
        else:
            j, history, star0, warm0 = converged
        target = problems.projection_params(k, star0.strain, star0.stress, previous)
        start = (unloaded_start(problems.projection, target, names) if j is None
                 else problems.projection_params(j, star0.strain, star0.stress, history))
        if start is None:  # no clean unloaded start (see substeps.unloaded_start): not bisected
            return full, full_best, full_warm
        tried: list[tuple[StepResult, Run, tuple]] = []

        def attempt(t_from: float, t_to: float, sub: tuple) -> tuple[bool, tuple]:
            star, warm = sub
            if t_to == 1.0:
                step, best, warm_out = self.solve_step(k, star, warm)
            else:
                self.projection.substep = lambda params: interpolate(P, start, params, t_to, names)
                try:
                    tally = new_tally()
                    best, warm_out = self.alternate(k, star, *warm)
                    count(tally, best)
                    load = P.get(interpolate(P, start, target, t_to, names), "f")
                    step = self._step_result(k, best, tally, load=load)
                finally:
                    self.projection.substep = None
            tried.append((step, best, warm_out))
            return accepted(step, best.sol.x, best.sol.p), (best.star, warm_out)

        bisection = bisect(attempt, (star0, warm0), self.min_substep)
        step, best, warm_out = tried[-1] if bisection.converged else (full, full_best, full_warm)
        others = [full] + [s for s, _, _ in tried]
        return finish_bisected(step, bisection, others), best, warm_out

    def _step_result(self, k: int, run: Run, tally: dict, *, load: np.ndarray | None = None) -> StepResult:
        """The record of step ``k`` from its best run, finished (:meth:`finish`; ``load``: a
        sub-step's ``f``)."""
        model, sol, f, star = self.problems.model, run.sol, run.fields, run.star
        distance = run.distance
        if not np.isfinite(distance):  # a failed projection: report the distance of what it returned
            distance = float(0.5 * np.dot(model.volumes, self.scheme.distance2(f["strain"], f["stress"], star)))
        step = StepResult(step=k, load_parameter=float(model.load_parameter[k]), u=f["u"], p=f["p"],
                          converged=run.converged, iterations=tally["inner"], outer_iterations=run.outer,
                          residual=sol.residual, complementarity=sol.complementarity,
                          penetration=sol.penetration, seconds=0.0, message=run.message,
                          strain=f["strain"], stress=f["stress"], strain_star=star.strain.copy(),
                          stress_star=star.stress.copy(), data_index=star.index.copy(),
                          distance=distance, projection_error=run.error,
                          projection_global=run.is_global, projection_seconds=tally["t_project"],
                          search_seconds=tally["t_search"], projections=tally["projections"], runs=tally["runs"],
                          improvements=tally["improvements"], notes="; ".join(self.notes),
                          traction=f.get("traction"), slip=f.get("slip"))
        self.finish(step, load=load)
        return step

    def finish(self, step: StepResult, *, load: np.ndarray | None = None) -> None:
        """:func:`~ddcm_casadi.drivers.checks.finish_step` with this solver's problem, penalty
        stiffness and data range, then how coarse the data are for the step's states
        (:meth:`~ddcm_casadi.data.extrapolation.DataCoverage.coarseness`, a flag). ``load``: the
        step's ``f`` when it is a sub-step's (:mod:`~ddcm_casadi.drivers.substeps`)."""
        nearest = None if step.strain is None else self.scheme.nearest_index(step.strain, step.stress)
        finish_step(step, self.problems.projection, self.problems.model,
                    penalty_stiffness=getattr(self.built, "penalty_stiffness", None), coverage=self.coverage,
                    load=load, nearest=nearest)
        if step.data_index is not None and step.strain is not None:  # how coarse the data are here
            step.datum_share, step.datum_spread, step.state_spacings = self.coverage.coarseness(
                step.strain, step.stress, step.data_index)
            step.coarse_data = coarse_data(step.datum_share, step.datum_spread, step.state_spacings,
                                           self.problems.model.n_points)
