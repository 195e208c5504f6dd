"""Drivers along a load path: classical steps, and DDCM alternating projections.

Both warm-start each step from the previous one. The DDCM driver alternates

1. the projection onto ``Z_E`` (solved by the chosen formulation, warm-started with the previous
   solution and its multipliers, and restarted without the multipliers if that fails; for
   problems with few contact pairs the exact branch enumeration of :mod:`ddcm_casadi.exact` is
   consulted and the formulation is restarted on the globally best branch if it stopped on
   another one), and
2. the projection onto the data (vectorised KD-tree nearest neighbour under the metric, or the
   warm-started exact search that starts from the previous assignment, ``search="warm"``),

until the data assignment no longer changes. Where each step starts, restarts from random
assignments, a greedy global improvement after the fixed point, and the noise-robust variants are
chosen by :class:`~ddcm_casadi.solvers.ddcm_options.DDCMOptions` (by default the first step starts
from the data point nearest the origin and every later step from the previous one's assignment).
For one-element problems (and, with ``exact_max``, a few elements) it also finds the global DDCM
optimum by enumerating the data assignments (closed forms, :mod:`ddcm_casadi.solvers.ddcm_search`)
and reports whether the search reached it and the gap.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from ..errors import ConvergenceError, InputError
from ..exact import ExactEnumerator
from ..extrapolation import DataCoverage
from ..problem import ProblemPair
from .ddcm_options import MAX_OUTER_RANGE, DDCMOptions
from .ddcm_search import global_optimum, point_ranges, random_assignment, single_moves, start_assignment


@dataclass
class StepResult:
    """Everything known about one load step of one variant and formulation (physical units)."""

    step: int
    load_parameter: float
    u: np.ndarray
    p: np.ndarray
    converged: bool
    iterations: int
    outer_iterations: int
    residual: float
    complementarity: float
    penetration: float
    seconds: float
    message: str = ""
    # DDCM only
    strain: np.ndarray | None = None
    stress: np.ndarray | None = None
    strain_star: np.ndarray | None = None
    stress_star: np.ndarray | None = None
    data_index: np.ndarray | None = None
    distance: float = float("nan")
    projection_error: float = float("nan")
    projection_global: bool | None = None
    global_optimum: bool | None = None
    global_distance: float = float("nan")
    global_gap: float = float("nan")
    projections: int = 0
    runs: int = 0
    improvements: int = 0
    projection_seconds: float = 0.0
    search_seconds: float = 0.0
    #: Material points whose state is beyond the data (:mod:`ddcm_casadi.extrapolation`): a flag,
    #: not a convergence failure.
    extrapolated: int = 0
    #: The largest offset of a state from its nearest datum along the data, in local data spacings.
    data_spacings: float = float("nan")

    def diagnostics(self) -> dict:
        d = asdict(self)
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in d.items()}


@dataclass
class PathResult:
    """The steps of one variant x formulation along the load path."""

    variant: str
    formulation: str
    steps: list[StepResult] = field(default_factory=list)
    build_seconds: float = 0.0
    solve_seconds: float = 0.0

    @property
    def converged(self) -> bool:
        return all(s.converged for s in self.steps)

    def array(self, name: str) -> np.ndarray:
        """Per-step values of a field, stacked (``u`` and ``p`` give ``(n_steps, n)`` arrays)."""
        return np.array([getattr(s, name) for s in self.steps])


def _check_convergence(step: StepResult, raise_on_failure: bool, label: str) -> None:
    if raise_on_failure and not step.converged:
        raise ConvergenceError(f"{label}: step {step.step} did not converge ({step.message})",
                               step.diagnostics())


#: Relative tolerance of the physical checks of a step (:func:`physical_check`): at least a thousand
#: times the default stopping tests of every formulation (1e-9 to 1e-11, scaled), so a step that met its
#: solver's own test in well-scaled units always passes; what fails is a step whose scaled test
#: passed while the physical answer is wrong by orders of magnitude (degenerate scales, a metric
#: far from the data's modulus).
PHYSICAL_TOL = 1e-6
#: A penalty formulation penetrates by ``p / gamma``: its allowance is that of a contact pressure of
#: this many times the problem's stress scale. Pressures are O(1) in that scale by construction
#: (measured at most 1.0 over the examples: bars, trusses, Hertz), so ten times is generous for a
#: sound solution and still far below a penetration that carries nonsense pressures.
PENALTY_PRESSURE_BOUND = 10.0
#: Roundoff of a value computed from terms of size ``s``: ``64 eps s``, the floor at which Newton
#: accepts a residual (docs/maths.md, Sec. 6). Below it a displacement or a pressure of the wrong
#: sign is zero (:func:`clip_roundoff`).
ROUNDOFF = 64 * np.finfo(float).eps


def _step_scale(values: np.ndarray, reference: float) -> float:
    """The size of the terms a step's ``values`` are computed from: the problem's reference
    magnitude or the step's largest finite value, whichever is larger."""
    v = np.abs(np.asarray(values, dtype=float))
    return max(reference, float(np.max(v[np.isfinite(v)], initial=0.0)))


def clip_roundoff(step: StepResult, problem) -> None:
    """Zero the roundoff of a step's physical fields, in place (before anything reports them).

    A contact pressure in ``(-t_p, 0)`` and a displacement with ``|u| < t_u`` are zero, with
    ``t = ROUNDOFF x`` the step's scale (:data:`ROUNDOFF`; the scale is the problem's stress or
    displacement unit, ``problem.pressure_ref`` / ``problem.gap_ref``, or the step's largest
    value if larger). Removed on the paper's bar, for example: ``p = -9.3e-7 Pa`` (a free step of
    the DDCM augmented Lagrangian; the stress scale is 2e9 Pa) and ``u = -3.1e-35 m`` (the tip at
    an obstacle that just touches it). A pressure negative beyond roundoff is kept (and
    :func:`physical_check` judges it).
    """
    p = np.array(step.p, dtype=float)
    t_p = ROUNDOFF * _step_scale(p, problem.pressure_ref)
    p[(p < 0) & (p > -t_p)] = 0.0
    u = np.array(step.u, dtype=float)
    u[np.abs(u) < ROUNDOFF * _step_scale(u, problem.gap_ref)] = 0.0
    step.p, step.u = p, u


def physical_check(step: StepResult, problem, length_scale: float, *,
                   penalty_stiffness: float | None = None) -> str:
    """Why a step fails in physical units, or ``""``: the one place a step's physics is checked.

    Checked, with ``tol`` = :data:`PHYSICAL_TOL`:

    - finite displacements and contact pressures;
    - penetration ``max(0, -g)`` (m) at most ``tol min(U, L)`` (``U`` the displacement scale,
      ``problem.gap_ref``; ``L`` the model's length scale), plus, for a penalty formulation of
      stiffness ``gamma`` (Pa/m), its expected penetration ``p / gamma`` for pressures up to
      :data:`PENALTY_PRESSURE_BOUND` times the stress scale ``S = problem.pressure_ref``;
    - equilibrium: the residual (relative to the forces that cancel in it,
      :meth:`~ddcm_casadi.problem.ComplementarityProblem.relative_residual`) at most ``tol``;
    - the sign of the contact pressures: ``p >= -tol max(S, max |p|)``.

    Parameters
    ----------
    step : StepResult
        ``penetration`` and ``residual`` scaled as the formulations report them; ``u``, ``p`` in
        physical units.
    problem : ComplementarityProblem
        The problem the step solved (its scales).
    length_scale : float
        The model's characteristic length (m).
    penalty_stiffness : float, optional
        ``gamma`` of a penalty formulation (:meth:`Formulation.penalty_stiffness`); ``None`` for a
        formulation that enforces contact exactly.

    Returns
    -------
    str
        ``"physical check failed: ..."`` naming each failed check and by how much, or ``""``.
    """
    if not (np.all(np.isfinite(step.u)) and np.all(np.isfinite(step.p))):
        return "physical check failed: non-finite displacements or contact pressures"
    failed = []
    penetration = step.penetration * problem.gap_ref
    allowed = PHYSICAL_TOL * min(problem.gap_ref, length_scale)
    if penalty_stiffness:
        allowed += PENALTY_PRESSURE_BOUND * problem.pressure_ref / penalty_stiffness
    if not penetration <= allowed:
        failed.append(f"penetration {penetration:.3g} m > {allowed:.3g} m allowed ({penetration / allowed:.2g} times)")
    if not step.residual <= PHYSICAL_TOL:
        failed.append(f"equilibrium residual {step.residual:.3g} > {PHYSICAL_TOL:g} (relative to the forces)")
    p_min = float(np.min(step.p, initial=0.0))
    floor = PHYSICAL_TOL * _step_scale(step.p, problem.pressure_ref)
    if p_min < -floor:
        failed.append(f"contact pressure {p_min:.3g} Pa < 0 (beyond -{floor:.3g} Pa, {-p_min / floor:.2g} times)")
    return "physical check failed: " + "; ".join(failed) if failed else ""


def finish_step(step: StepResult, problem, model, *, penalty_stiffness: float | None = None,
                coverage=None) -> None:
    """What every driver does to a step before reporting it, in place: :func:`clip_roundoff`,
    :func:`physical_check` (a failure makes a converged step not converged and says why in its
    message) and, with a :class:`~ddcm_casadi.extrapolation.DataCoverage`, the count of states
    beyond the data (``extrapolated``, ``data_spacings``: a flag, not a failure)."""
    clip_roundoff(step, problem)
    failure = physical_check(step, problem, model.length_scale, penalty_stiffness=penalty_stiffness)
    if failure and step.converged:
        step.converged = False
        step.message = f"{step.message}, but {failure}" if step.message else failure
    if coverage is not None and step.strain is not None:
        beyond, spacings = coverage.check(step.strain, step.stress)
        step.extrapolated = int(np.sum(beyond))
        finite = spacings[np.isfinite(spacings)]
        step.data_spacings = float(np.max(finite)) if finite.size else float("nan")


def solve_classical(problems: ProblemPair, built, formulation_name: str, *, raise_on_failure: bool = False,
                    progress: Callable[[StepResult], None] | None = None) -> PathResult:
    """Classical solution at every load step with a built formulation (warm-started).

    A penalty formulation's penetration ``p / gamma`` is expected by the physical check
    (:func:`physical_check`, with ``built.penalty_stiffness``).
    """
    model = problems.model
    if problems.classical is None:
        raise InputError("the classical variant needs a Young's modulus")
    out = PathResult("classical", formulation_name)
    x = np.zeros(problems.classical.n_x)
    p = np.zeros(problems.classical.n_pairs)
    state = None
    t_all = time.perf_counter()
    for k in range(model.n_steps):
        t0 = time.perf_counter()
        sol = built.solve(problems.step_params(k), x, p, state)
        f = problems.fields("mcp", sol.x, sol.p)
        step = StepResult(step=k, load_parameter=float(model.load_parameter[k]), u=f["u"], p=f["p"],
                          converged=sol.converged, iterations=sol.iterations,
                          outer_iterations=sol.outer_iterations, residual=sol.residual,
                          complementarity=sol.complementarity, penetration=sol.penetration,
                          seconds=time.perf_counter() - t0, message=sol.message,
                          strain=f["strain"], stress=f["stress"])
        finish_step(step, problems.classical, model, penalty_stiffness=getattr(built, "penalty_stiffness", None))
        out.steps.append(step)
        if progress is not None:
            progress(step)
        _check_convergence(step, raise_on_failure, f"classical/{formulation_name}")
        if sol.converged and np.all(np.isfinite(sol.x)):
            x, p, state = sol.x, sol.p, sol.state
    out.solve_seconds = time.perf_counter() - t_all
    return out


@dataclass
class _Run:
    """One alternating-projection run of one load step from one initial assignment."""

    index: np.ndarray
    sol: object
    fields: dict
    distance: float
    converged: bool
    message: str
    outer: int
    inner: int
    t_project: float
    t_search: float
    error: float
    is_global: bool | None

    def better_than(self, other: "_Run") -> bool:
        """Fixed points before anything else, then a strictly lower objective (beyond roundoff)."""
        if self.converged != other.converged:
            return self.converged
        return self.distance < other.distance - 1e-12 * abs(other.distance)


class DDCMSolver:
    """Alternating projections for one model and one built projection formulation.

    Parameters
    ----------
    problems : ProblemPair
        Needs the projection (a material data set).
    built
        The projection formulation, built.
    max_outer : int
        Alternating-projection iterations per run.
    enumerate_pairs : int
        Problems with at most this many contact pairs consult the exact branch enumeration.
    global_search : bool
        Report the global optimum where it can be enumerated.
    search : {"kdtree", "warm"}
        The data search.
    options : DDCMOptions, optional
        Starts, restarts, improvement, certificates, variant (default ``DDCMOptions()``).
    """

    #: Data searches: a cold KD-tree query, or the warm-started exact search.
    SEARCHES = ("kdtree", "warm")

    def __init__(self, problems: ProblemPair, built, *, max_outer: int = 100, enumerate_pairs: int = 4,
                 global_search: bool = True, search: str = "kdtree", options: DDCMOptions | None = None) -> None:
        if problems.projection is None:
            raise InputError("the DDCM variant needs a material data set")
        if search not in self.SEARCHES:
            raise InputError(f"unknown data search {search!r}; known: {', '.join(self.SEARCHES)}")
        if options is not None and not isinstance(options, DDCMOptions):
            raise InputError(f"DDCM options must be a DDCMOptions, got {type(options).__name__}")
        self.options = options if options is not None else DDCMOptions()
        self.search = search
        #: ``queries`` and ``fallbacks`` (uncertified states) of the warm search, accumulated.
        self.search_stats: dict = {}
        self.problems = problems
        self.built = built
        # The data's range and the exact enumeration, once per problem (not timed with the steps):
        # the solvers of the formulations of one model share them.
        self.coverage = problems.projection.shared(
            ("data_coverage",), lambda: DataCoverage(problems.model.dataset, problems.model.n_points))
        lo, hi = MAX_OUTER_RANGE
        if isinstance(max_outer, bool) or not isinstance(max_outer, (int, np.integer)) or not lo <= max_outer <= hi:
            raise InputError(f"ddcm max_outer must be an integer in {lo}..{hi}, got {max_outer!r:.60}")
        self.max_outer = int(max_outer)
        model = problems.model
        if self.options.variant == "lcdd" and model.strain_components != 1:
            raise InputError("ddcm variant 'lcdd' is implemented for one-component points (bars, trusses)")
        if self.options.initial is not None:
            initial = np.asarray(self.options.initial, dtype=np.intp)
            offset, size = point_ranges(model)
            if initial.size != model.n_points:
                raise InputError(f"ddcm option initial has {initial.size} indices, the model has "
                                 f"{model.n_points} material points")
            if np.any(initial < offset) or np.any(initial >= offset + size):
                raise InputError("ddcm option initial: an index is outside its point's data set")
        self.exact = (problems.projection.shared(
            ("exact_enumerator", enumerate_pairs), lambda: ExactEnumerator(problems.projection, max_pairs=enumerate_pairs))
            if model.n_contacts <= enumerate_pairs else None)
        # N^m assignments, in logarithms: it overflows a float for a continuum's thousands of points.
        log_assign = float(np.sum(np.log(point_ranges(model)[1].astype(float))))
        self.global_search = (global_search and self.exact is not None
                              and (model.n_points == 1 or (self.options.exact_max > 0
                                                            and log_assign <= np.log(self.options.exact_max) + 1e-12)))

    def initial_assignment(self, k: int) -> np.ndarray:
        """The data assignment load step ``k`` starts from when it does not continue the previous
        step's: ``initial`` at the first step if given, else ``start`` (seeded per step)."""
        o = self.options
        if k == 0 and o.initial is not None:
            return np.asarray(o.initial, dtype=np.intp)
        return start_assignment(self.problems.model, o.start, k, np.random.default_rng((o.seed, k, 0)))

    def _project(self, params, x0, p0, state):
        """Projection onto Z_E, restarted on the exact global branch if it may have stopped elsewhere.

        Returns ``(solution, is_global, error)``: ``is_global`` is True when no better branch is
        known (the solution is at least as good as the formulation restarted on the exact global
        branch); ``error`` is the scaled distance to the exact projection.
        """
        sol = self.built.solve(params, x0, p0, state)
        if not sol.converged and state:
            # Warm multipliers can mislead Newton near many corners (measured: 9 stops at the
            # corner, 1e5 data); the same primal start without them is the next try.
            retry = self.built.solve(params, x0, p0, None)
            if retry.converged:
                retry.iterations += sol.iterations
                retry.message += " (restarted without warm multipliers)"
                sol = retry
            else:
                sol.iterations += retry.iterations
        if self.exact is None:
            return sol, None, float("nan")
        xe, pe, obj = self._exact_projection(params)
        tol = 1e-10 + 1e-8 * abs(obj)
        is_global = bool(sol.converged and sol.objective <= obj + tol)
        if not is_global:
            alt = self.built.solve(params, xe, pe, {"on_branch": True})
            if alt.converged and (not sol.converged or alt.objective < sol.objective):
                sol = alt
            is_global = bool(sol.converged and (not alt.converged or sol.objective <= alt.objective + tol))
        scale = max(1.0, float(np.max(np.abs(np.concatenate([xe, pe])))))
        err = float(np.max(np.abs(np.concatenate([sol.x - xe, sol.p - pe])))) / scale
        return sol, is_global, err

    #: Exact projections remembered per problem (:meth:`_exact_projection`), keys and answers
    #: together at most this many floats (8 MB).
    EXACT_CACHE_VALUES = 1_000_000

    def _exact_projection(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """The exact projection ``(x, p, objective)`` (scaled) for the parameter vector ``params``.

        Remembered per problem (within :attr:`EXACT_CACHE_VALUES`): the DDCM runs of the
        formulations of one model visit the same data assignments (the paper's bar: the same 46
        projections for each of the four), and the enumeration's answer does not depend on the
        formulation. Copies are returned, so that no caller can change a remembered answer.
        """
        cache = self.problems.projection.shared(("exact_projections",), lambda: {"values": 0, "items": {}})
        key = params.tobytes()
        hit = cache["items"].get(key)
        if hit is None:
            ex = self.exact.solve(params)
            hit = (ex.x[:, 0], ex.p[:, 0], float(ex.objective[0]))
            size = params.size + hit[0].size + hit[1].size
            if cache["values"] + size <= self.EXACT_CACHE_VALUES:
                cache["items"][key] = hit
                cache["values"] += size
        return hit[0].copy(), hit[1].copy(), hit[2]

    def project_data(self, k: int, strain_star, stress_star, warm: tuple, cost: dict):
        """The ``Z_E`` projection of step ``k``'s assigned material states (warm-started from
        ``warm = (x, p, state)``): ``(solution, is_global, error, failure)``, ``failure`` the
        message of a projection that did not converge, else ``""``. Adds its Newton iterations
        and seconds to ``cost["inner"]`` and ``cost["t_project"]``."""
        t0 = time.perf_counter()
        params = self.problems.projection_params(k, strain_star, stress_star)
        sol, is_global, err = self._project(params, *warm)
        cost["inner"] += sol.iterations
        cost["t_project"] += time.perf_counter() - t0
        failed = "" if sol.converged else f"Z_E projection did not converge: {sol.message}"
        return sol, is_global, err, failed

    def _alternate(self, k: int, index: np.ndarray, x, p, state) -> tuple[_Run, tuple]:
        """Alternate projections at step ``k`` from the assignment ``index`` (the Z_E solves
        warm-started from ``x, p, state``). Returns the run and the last ``(x, p, state)``."""
        problems, data = self.problems, self.problems.model.dataset
        cost, t_search = dict(inner=0, t_project=0.0), 0.0
        seen = {index.tobytes()}
        converged, message = False, "maximum outer iterations reached"
        for outer in range(1, self.max_outer + 1):
            sol, is_global, err, failed = self.project_data(k, data.strain[index], data.stress[index], (x, p, state),
                                                            cost)
            if failed:
                message = failed
                break
            x, p, state = sol.x, sol.p, sol.state
            t1 = time.perf_counter()
            f = problems.fields("mpcc", sol.x, sol.p)
            if self.search == "warm":
                new_index = data.nearest_warm(f["strain"], f["stress"], index, stats=self.search_stats)
            else:
                new_index = data.nearest(f["strain"], f["stress"])
            t_search += time.perf_counter() - t1
            if np.array_equal(new_index, index):
                converged, message = True, "fixed point"
                break
            key = new_index.tobytes()
            if key in seen:
                message = "data assignment cycles"
                index = new_index
                break
            seen.add(key)
            index = new_index
        f = problems.fields("mpcc", sol.x, sol.p)
        d2 = data.distance2(f["strain"], f["stress"], index)
        distance = float(0.5 * np.dot(self.problems.model.volumes, d2)) if sol.converged else float("inf")
        run = _Run(index=index, sol=sol, fields=f, distance=distance, converged=converged, message=message,
                   outer=outer, inner=cost["inner"], t_project=cost["t_project"], t_search=t_search, error=err, is_global=is_global)
        return run, (x, p, state)

    #: Single-point moves screened per sweep of the greedy search (points x candidates).
    SCREEN_SIZE = 1_000_000

    def _greedy_moves(self, k: int, best: _Run) -> list[np.ndarray]:
        """Candidate assignments of one greedy sweep, most promising first.

        With the exact branch enumeration (few contact pairs) every move of one of the
        ``greedy_points`` worst points to another datum of its set (or, past
        :attr:`SCREEN_SIZE` moves, to one of its nearest data) is screened by the exact objective
        of its projection (closed forms, :func:`~ddcm_casadi.solvers.ddcm_search.single_moves`);
        the moves that lower the objective come first, best first. Without it (as Datasolver.jl)
        the worst points move to their ``greedy_neighbours`` next-nearest data.
        """
        opts, model = self.options, self.problems.model
        data, f = model.dataset, best.fields
        local = model.volumes * data.distance2(f["strain"], f["stress"], best.index)
        order = np.argsort(-local, kind="stable")[:opts.greedy_points or model.n_points]
        if self.exact is None or not opts.greedy_screen:
            near = data.k_nearest(f["strain"], f["stress"], opts.greedy_neighbours + 1)
            moves = []
            for i in order:
                for j in [j for j in near[i] if j != best.index[i]][:opts.greedy_neighbours]:
                    trial = best.index.copy()
                    trial[i] = j
                    moves.append(trial)
            return moves
        offset, size = point_ranges(model)
        per_point = self.SCREEN_SIZE // len(order)
        if np.all(size[order] <= per_point) and np.unique(size[order]).size == 1:
            cand = offset[order][:, None] + np.arange(size[order[0]])[None, :]
        else:
            pts = f["strain"].reshape(model.n_points, -1)[order], f["stress"].reshape(model.n_points, -1)[order]
            cand = data.k_nearest(pts[0].ravel(), pts[1].ravel(), max(2, per_point))
        obj, mine = single_moves(self.problems, self.exact, k, best.index, order, cand)
        flat = np.argsort(obj, axis=None, kind="stable")
        moves = []
        for a in flat:
            i, b = divmod(int(a), cand.shape[1])
            if not obj[i, b] < mine - 1e-12 - 1e-9 * abs(mine):
                break
            trial = best.index.copy()
            trial[order[i]] = cand[i, b]
            moves.append(trial)
            if len(moves) == opts.greedy_neighbours:
                break
        return moves

    def _greedy(self, k: int, best: _Run, warm: tuple, visited: set, tally: dict) -> tuple[_Run, tuple]:
        """Greedy global improvement after a fixed point (see :class:`DDCMOptions` ``improve``):
        rerun the alternating scheme from the candidate moves of :meth:`_greedy_moves`, accept
        only a strictly lower objective and start over from it. The objective never increases."""
        budget = self.options.greedy_budget
        trials = 0
        while trials < budget:
            improved = False
            for trial in self._greedy_moves(k, best):
                key = trial.tobytes()
                if key in visited:
                    continue
                visited.add(key)
                run, state = self._alternate(k, trial, *warm)
                trials += 1
                _count(tally, run)
                visited.add(run.index.tobytes())
                if run.converged and run.better_than(best):
                    best, warm, improved = run, state, True
                    tally["improvements"] += 1
                    break
                if trials >= budget:
                    break
            if not improved:
                break
        return best, warm

    def solve(self, *, formulation_name: str = "", raise_on_failure: bool = False,
              progress: Callable[[StepResult], None] | None = None) -> PathResult:
        if self.options.variant != "plain":
            from .noise_robust import solve_noise_robust

            # The variants report every step to ``progress`` before checking its convergence:
            # each step is finished (physical checks, data range) there, as the plain scheme's.
            return solve_noise_robust(self, formulation_name=formulation_name, raise_on_failure=raise_on_failure,
                                      progress=self._finishing(progress))
        problems, model = self.problems, self.problems.model
        opts = self.options
        out = PathResult("ddcm", formulation_name)
        warm = (np.zeros(problems.projection.n_x), np.zeros(problems.projection.n_pairs), None)
        index = None
        t_all = time.perf_counter()
        for k in range(model.n_steps):
            t0 = time.perf_counter()
            if k == 0 or not opts.warm:
                index = self.initial_assignment(k)
            tally = dict(projections=0, inner=0, runs=0, improvements=0, t_project=0.0, t_search=0.0)
            best, best_warm = self._alternate(k, index, *warm)
            _count(tally, best)
            visited = {index.tobytes(), best.index.tobytes()}
            for r in range(1, opts.restarts + 1):
                rng = np.random.default_rng((opts.seed, k, r))
                if opts.restart_neighbours:
                    # A kick from the best state so far: each point at one of its K nearest data.
                    f = best.fields
                    near = model.dataset.k_nearest(f["strain"], f["stress"], opts.restart_neighbours)
                    start = near[np.arange(near.shape[0]), rng.integers(0, near.shape[1], near.shape[0])]
                else:
                    start = random_assignment(model, rng)
                run, state = self._alternate(k, start, *warm)
                _count(tally, run)
                visited |= {start.tobytes(), run.index.tobytes()}
                if run.better_than(best):
                    best, best_warm = run, state
                    tally["improvements"] += 1
            if opts.improve == "greedy" and best.converged:
                best, best_warm = self._greedy(k, best, best_warm, visited, tally)
            step = self._step_result(k, best, tally)
            if self.global_search and best.sol.converged:
                self._global_optimum(k, step)
            step.seconds = time.perf_counter() - t0
            out.steps.append(step)
            if progress is not None:
                progress(step)
            _check_convergence(step, raise_on_failure, f"ddcm/{formulation_name}")
            index, warm = best.index, best_warm
        out.solve_seconds = time.perf_counter() - t_all
        return out

    def _step_result(self, k: int, run: _Run, tally: dict) -> StepResult:
        model, data, sol, f = self.problems.model, self.problems.model.dataset, run.sol, run.fields
        index = run.index
        distance = run.distance
        if not np.isfinite(distance):  # a failed projection: report the distance of what it returned
            distance = float(0.5 * np.dot(model.volumes, data.distance2(f["strain"], f["stress"], index)))
        step = StepResult(step=k, load_parameter=float(model.load_parameter[k]), u=f["u"], p=f["p"],
                          converged=run.converged, iterations=tally["inner"], outer_iterations=run.outer,
                          residual=sol.residual, complementarity=sol.complementarity,
                          penetration=sol.penetration, seconds=0.0, message=run.message,
                          strain=f["strain"], stress=f["stress"], strain_star=data.strain[index].copy(),
                          stress_star=data.stress[index].copy(), data_index=index.copy(),
                          distance=distance, projection_error=run.error,
                          projection_global=run.is_global, projection_seconds=tally["t_project"],
                          search_seconds=tally["t_search"], projections=tally["projections"], runs=tally["runs"],
                          improvements=tally["improvements"])
        self.finish(step)
        return step

    def finish(self, step: StepResult) -> None:
        """:func:`finish_step` with this solver's problem, penalty stiffness and data range."""
        finish_step(step, self.problems.projection, self.problems.model, penalty_stiffness=getattr(self.built, "penalty_stiffness", None),
                    coverage=self.coverage)

    def _finishing(self, progress: Callable[[StepResult], None] | None) -> Callable[[StepResult], None]:
        """A progress callback that first finishes the step (:meth:`finish`), then reports it."""
        def report(step: StepResult) -> None:
            self.finish(step)
            if progress is not None:
                progress(step)
        return report

    def _global_optimum(self, k: int, step: StepResult) -> None:
        """The global optimum by enumeration of every data assignment (closed forms per branch)."""
        # Shared by the DDCM solvers of one model (one per formulation): the optimum of a step and
        # the exact objective of an assignment do not depend on the formulation.
        best, mine = self.problems.projection.shared(
            ("global_optimum", k, step.data_index.tobytes()),
            lambda: global_optimum(self.problems, self.exact, k, step.data_index))
        energy = self.problems.scales("mpcc")["energy"]
        step.global_distance = best * energy
        step.global_optimum = bool(mine <= best + 1e-12 + 1e-9 * abs(best))
        step.global_gap = step.distance - step.global_distance


def _count(tally: dict, run: _Run) -> None:
    """Add one run's cost to a step's tally."""
    tally["projections"] += run.outer
    tally["inner"] += run.inner
    tally["runs"] += 1
    tally["t_project"] += run.t_project
    tally["t_search"] += run.t_search

