"""Comparison harness: every formulation x {classical, DDCM} on the same load path.

>>> from ddcm_casadi import paper_bar, compare
>>> result = compare(paper_bar(), formulations=["fischer_burmeister", "mpcc"])  # doctest: +SKIP
>>> print(result.table())                                                       # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass, field
from typing import Callable, Iterable, Mapping

import numpy as np

from ddcm_casadi import formulations as registry
from ddcm_casadi.formulations.base import Formulation

from ddcm_casadi.errors import InputError, PhysicsWarning
from ddcm_casadi.models.base import ContactModel
from ddcm_casadi.parallel import map_forked, resolve_jobs
from ddcm_casadi.drivers.ddcm_reduced import build_classical, build_projection
from ddcm_casadi.problems.build import ProblemPair, build_problems
from ddcm_casadi.drivers.ddcm_options import KEYS, DDCMOptions
from ddcm_casadi.drivers.path import DDCMSolver, PathResult, StepResult, solve_classical
from ddcm_casadi.drivers.substeps import DEFAULT_MIN_SUBSTEP, check_min_substep, fraction_text

VARIANTS = ("classical", "ddcm")
_COLUMNS = ("variant", "formulation", "step", "h", "u", "p", "max_abs_u", "total_contact_force",
            "active_contacts", "converged", "iterations", "outer_iterations", "substeps", "smallest_substep",
            "residual", "complementarity", "penetration", "strain_star", "stress_star", "data_index",
            "distance", "extrapolated", "data_spacings", "datum_share", "state_spacings", "coarse_data",
            "global_optimum", "global_distance",
            "projection_global", "projection_error",
            "error_u", "error_p", "seconds", "message")


def resolve_formulations(formulations: Iterable[str | Formulation] | Mapping[str, Mapping] | None,
                         contact_law: str = "signorini") -> list[Formulation]:
    """Formulation instances from names, instances, or ``{name: options}`` (options are copied);
    ``None``: every registered one that enforces ``contact_law``."""
    if formulations is None:
        return [registry.get(name) for name in registry.enforcing(contact_law)]
    if isinstance(formulations, Mapping):
        return [registry.get(name, **dict(opts or {})) for name, opts in formulations.items()]
    out = []
    for f in formulations:
        out.append(f if isinstance(f, Formulation) else registry.get(str(f)))
    if not out:
        raise InputError("no formulation selected")
    return out


def _nanmax(a: np.ndarray) -> float:
    a = np.asarray(a, float)
    return float(np.nanmax(a)) if np.any(np.isfinite(a)) else float("nan")


#: A note of the table lists at most this many values, then summarises (a count and the first ones).
NOTE_VALUES = 3


def _distinct(values: list) -> list[str]:
    """``values`` as text with the fewest significant digits, at least 4, that keep distinct values
    distinct (``0.99`` and ``0.98999`` must not both print ``0.99``)."""
    distinct = len(set(values))
    for digits in range(4, 18):
        text = [f"{v:.{digits}g}" for v in values]
        if len(set(text)) == distinct:
            return text
    return [repr(v) for v in values]


def _listing(values: list, name: str | None = None) -> str:
    """The first :data:`NOTE_VALUES` of ``values`` (``name=`` first if given), ``...`` if there are more."""
    text = _distinct(values)
    shown = ", ".join(text[:NOTE_VALUES]) + (", ..." if len(text) > NOTE_VALUES else "")
    return f"{name}={shown}" if name else shown


def _note(what: str, values: list, name: str | None = None) -> str:
    """A note of the table about some steps: every value when there are few (``what at h=0.992``;
    steps without ``name``), else their count and the first few (``what at 1000 steps (h=0.99,
    0.989, 0.988, ...)``), so that a note stays one short line however long the path."""
    if len(values) <= NOTE_VALUES:
        return f"{what} at " + (_listing(values, name) if name else f"steps {_listing(values)}")
    return f"{what} at {len(values)} steps ({_listing(values, name)})"


def _relative_error(values: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per-step error relative to the largest reference magnitude along the path."""
    scale = float(np.max(np.abs(reference), initial=0.0)) or 1.0
    return np.max(np.abs(values - reference), axis=1, initial=0.0) / scale


@dataclass
class Comparison:
    """Results of :func:`compare`: one :class:`PathResult` per variant and formulation."""

    model: ContactModel
    problems: ProblemPair
    formulations: list[Formulation]
    results: dict[tuple[str, str], PathResult] = field(default_factory=dict)
    #: What is physically odd about the load path (:meth:`ContactModel.path_warnings`).
    warnings: list[str] = field(default_factory=list)

    def __getitem__(self, key: tuple[str, str]) -> PathResult:
        return self.results[key]

    # ------------------------------------------------------------- references
    def reference(self, variant: str, formulation: str) -> tuple[np.ndarray, np.ndarray] | None:
        """Closed-form ``(u, p)`` per step to compare with, where the model has one.

        The exact classical solution for every formulation, except a classical formulation that
        regularises contact with a penalty stiffness (:meth:`Formulation.penalty_stiffness`) on a
        model that knows the penalty solution in closed form
        (:meth:`ContactModel.penalty_closed_form`): that one is compared with its own closed form.
        """
        m = self.model
        if m.closed_form(0) is None:
            return None
        pairs = self._penalty_reference(variant, formulation)
        if pairs is None:
            pairs = [m.closed_form(k) for k in range(m.n_steps)]
        return np.array([a for a, _ in pairs]), np.array([b for _, b in pairs])

    def _penalty_reference(self, variant: str, formulation: str) -> list[tuple] | None:
        """The penalty closed form ``(u, p)`` per step of a classical penalised run, or ``None``
        (an exact formulation, or a model without a penalty closed form)."""
        form = self._formulation(formulation)
        if variant != "classical" or form is None or self.problems.classical is None:
            return None
        gamma = form.penalty_stiffness(self.problems.classical)
        m = self.model
        if gamma is None or m.penalty_closed_form(0, gamma) is None:
            return None
        return [m.penalty_closed_form(k, gamma) for k in range(m.n_steps)]

    def _formulation(self, name: str) -> Formulation | None:
        return next((f for f in self.formulations if f.name == name), None)

    def errors(self, variant: str, formulation: str) -> dict[str, np.ndarray] | None:
        """Per-step relative errors of ``u`` and ``p`` against :meth:`reference`."""
        ref = self.reference(variant, formulation)
        if ref is None or (variant, formulation) not in self.results:
            return None
        r = self.results[(variant, formulation)]
        return dict(u=_relative_error(r.array("u"), ref[0]), p=_relative_error(r.array("p"), ref[1]))

    # ---------------------------------------------------------------- outputs
    def arrays(self, variant: str, formulation: str) -> dict[str, np.ndarray]:
        """Per-step arrays (``load_parameter``, ``u``, ``p``, ``converged``, ...) of one run."""
        r = self.results[(variant, formulation)]
        names = [f.name for f in dataclasses.fields(StepResult)]
        return {n: r.array(n) for n in names if getattr(r.steps[0], n) is not None}

    def fields(self, variant: str, formulation: str) -> dict[str, np.ndarray]:
        """Per-step fields of one run (physical units), stacked over steps.

        ``u`` (n_steps, n_dofs) free displacements, ``contact_pressure`` and ``contact_force``
        (n_steps, n_contacts), ``strain`` and ``stress`` (n_steps, n_points); the model kind's own
        fields (:meth:`ContactModel.extra_fields`, for trusses ``nodal_displacement`` (n_steps,
        n_nodes, dim) and ``member_force``); with a hard device ``hard_device_force`` (n_steps,
        n_supports, dim: per prescribed support, the resultant force the device exerts on the body,
        :meth:`ContactModel.hard_device_forces`); with Coulomb friction ``tangential_traction`` and
        ``slip`` (n_steps, n_contacts (d - 1), component-major) and ``contact_status`` (n_steps,
        n_contacts: 0 open, 1 stick, 2 slip); for DDCM the assigned ``strain_star``,
        ``stress_star`` and ``data_index``.
        """
        r, m = self.results[(variant, formulation)], self.model
        p = r.array("p")
        out = dict(load_parameter=r.array("load_parameter"), u=r.array("u"), contact_pressure=p,
                   contact_force=m.contact_area * p, strain=r.array("strain"), stress=r.array("stress"),
                   converged=r.array("converged"))
        out.update(m.extra_fields(out["u"], out["stress"]))
        if m.frictional:  # Coulomb friction: tangential tractions and slips (component-major), statuses
            out.update(tangential_traction=r.array("traction"), slip=r.array("slip"))
            out["contact_status"] = m.contact_status(p, out["tangential_traction"], out["slip"])
        if m.prescribed is not None:  # (n_steps, n_supports, d): the force of the hard device on the body
            out["hard_device_force"] = np.array([m.hard_device_forces(s.step, s.u, s.stress, s.p) for s in r.steps])
        if variant == "ddcm":
            for k in ("strain_star", "stress_star", "data_index"):
                out[k] = r.array(k)
        return out

    def max_abs_strain(self, points=None) -> float:
        """Largest ``|strain|`` over every run and step, of all material points or of ``points``
        (an index or boolean mask): compare it with the data range."""
        keep = slice(None) if points is None else points
        return max(float(np.max(np.abs(r.array("strain")[:, keep]))) for r in self.results.values())

    @property
    def scalar_model(self) -> bool:
        """The model's :attr:`ContactModel.scalar`: the CSV holds ``u`` and ``p`` themselves."""
        return self.model.scalar

    def rows(self) -> list[dict]:
        """One flat record per variant x formulation x step (the rows of ``results.csv``).

        The model describes each step's solution (:meth:`ContactModel.step_summary`): for the
        paper's bar ``u`` and ``p`` are the tip displacement and the contact pressure; for larger
        models the columns summarise the step (``max_abs_u``, ``total_contact_force``,
        ``active_contacts``) and :meth:`fields` holds the full per-step fields. When some step
        was bisected (:mod:`~ddcm_casadi.drivers.substeps`), every row has ``substeps`` and
        ``smallest_substep``.
        """
        rows = []
        m = self.model
        bisected = any(s.bisected for r in self.results.values() for s in r.steps)
        for (variant, name), r in self.results.items():
            err = self.errors(variant, name)
            for s in r.steps:
                row = dict(variant=variant, formulation=name, step=s.step)
                row[m.load_parameter_name if m.load_parameter_name not in row else "load_parameter"] = s.load_parameter
                row.update(m.step_summary(s.u, s.p, s.stress, s.step, traction=s.traction))
                row.update(m.hard_device_summary(s.step, s.u, s.stress, s.p))  # none without one
                row.update(converged=s.converged, iterations=s.iterations, outer_iterations=s.outer_iterations,
                           residual=s.residual, complementarity=s.complementarity, penetration=s.penetration,
                           seconds=s.seconds)
                if bisected:  # the columns of step bisection only when some step was bisected
                    row.update(substeps=s.substeps, smallest_substep=s.smallest_substep)
                if variant == "ddcm":
                    if m.scalar:
                        row.update(strain_star=float(s.strain_star[0]), stress_star=float(s.stress_star[0]),
                                   data_index=int(s.data_index[0]))
                    row.update(distance=s.distance, extrapolated=s.extrapolated, data_spacings=s.data_spacings,
                               datum_share=s.datum_share, state_spacings=s.state_spacings, coarse_data=s.coarse_data,
                               projection_error=s.projection_error, projection_global=s.projection_global,
                               global_optimum=s.global_optimum, global_distance=s.global_distance,
                               global_gap=s.global_gap, projections=s.projections)
                if err is not None:
                    row.update(error_u=float(err["u"][s.step]), error_p=float(err["p"][s.step]))
                row["message"] = s.message
                rows.append(row)
        columns = [c for c in _COLUMNS if any(c in r for r in rows)]
        columns += [c for r in rows for c in r if c not in columns]
        return [{c: r.get(c) for c in dict.fromkeys(columns)} for r in rows]

    def summary(self) -> list[dict]:
        """Per variant x formulation: accuracy, iterations, convergence and wall time; with the
        step bisection (:mod:`~ddcm_casadi.drivers.substeps`) ``bisected_steps`` (the converged
        steps reached through sub-steps) and, per step, ``substeps`` and ``smallest_substep``."""
        out = []
        for (variant, name), r in self.results.items():
            err = self.errors(variant, name)
            its = r.array("iterations")
            rec = dict(variant=variant, formulation=name,
                       steps=len(r.steps), converged_steps=int(sum(s.converged for s in r.steps)),
                       non_converged_steps=[s.step for s in r.steps if not s.converged],
                       iterations_mean=float(np.mean(its)), iterations_max=int(np.max(its)),
                       outer_iterations_mean=float(np.mean(r.array("outer_iterations"))),
                       build_seconds=r.build_seconds, solve_seconds=r.solve_seconds,
                       max_error_u=float(np.max(err["u"])) if err else None,
                       max_error_p=float(np.max(err["p"])) if err else None,
                       max_complementarity=float(np.max(r.array("complementarity"))),
                       max_residual=float(np.max(r.array("residual"))),
                       # automatic step bisection (ddcm_casadi.drivers.substeps): per step, the
                       # sub-steps and the smallest fraction used (tried, for a step that failed)
                       bisected_steps=[s.step for s in r.steps if s.bisected and s.converged],
                       substeps=[s.substeps for s in r.steps],
                       smallest_substep=[s.smallest_substep for s in r.steps])
            if r.projection_path:  # reduced / condensed on the contact pairs, or the full problem, and why
                rec["projection_path"] = r.projection_path
            if err is not None and self._penalty_reference(variant, name) is not None:
                # compared with its own (penalty) closed form above; the exact one as well here
                ref = [self.model.closed_form(k) for k in range(self.model.n_steps)]
                rec["max_error_u_vs_exact"] = float(np.max(_relative_error(r.array("u"), np.array([a for a, _ in ref]))))
                rec["max_error_p_vs_exact"] = float(np.max(_relative_error(r.array("p"), np.array([b for _, b in ref]))))
            if variant == "ddcm":
                glob = [s.global_optimum for s in r.steps]
                rec.update(local_minimum_steps=[s.step for s in r.steps if s.global_optimum is False],
                           local_minimum_h=[s.load_parameter for s in r.steps if s.global_optimum is False],
                           global_checked=all(g is not None for g in glob),
                           projection_not_global_steps=[s.step for s in r.steps if s.projection_global is False],
                           max_projection_error=_nanmax(r.array("projection_error")),
                           projections=int(sum(s.projections for s in r.steps)),
                           max_global_gap=_nanmax(r.array("global_gap")),
                           # states beyond the data (a flag, not a failure: ddcm_casadi.data.extrapolation)
                           extrapolated_steps=int(sum(s.extrapolated > 0 for s in r.steps)),
                           extrapolated_h=[s.load_parameter for s in r.steps if s.extrapolated > 0],
                           max_extrapolated_states=int(max(s.extrapolated for s in r.steps)),
                           max_data_spacings=_nanmax(r.array("data_spacings")),
                           # data too coarse for the states (a flag: ddcm_casadi.data.extrapolation.coarse_data)
                           coarse_data_steps=[s.step for s in r.steps if s.coarse_data],
                           coarse_data_h=[s.load_parameter for s in r.steps if s.coarse_data],
                           max_datum_share=_nanmax(r.array("datum_share")),
                           max_state_spacings=_nanmax(r.array("state_spacings")),
                           coarse_data=next((s.coarse_data for s in reversed(r.steps) if s.coarse_data), ""))
            out.append(rec)
        return out

    def table(self) -> str:
        """A readable summary table."""
        head = (f"{'variant':<10} {'formulation':<22} {'conv':>7} {'err u':>9} {'err p':>9} {'its/step':>8} {'outer':>6} "
                f"{'max res':>8} {'max comp':>8} {'build s':>8} {'solve s':>8}  notes")
        lines = [head, "-" * len(head)]
        for rec in self.summary():
            e = lambda v: "    -    " if v is None else f"{v:9.1e}"  # noqa: E731
            notes = []
            if "max_error_u_vs_exact" in rec:
                notes.append(f"errors vs own closed form; vs exact: u {rec['max_error_u_vs_exact']:.1e}, "
                             f"p {rec['max_error_p_vs_exact']:.1e}")
            name = self.model.load_parameter_name
            if rec["non_converged_steps"]:
                notes.append(_note("NOT CONVERGED", rec["non_converged_steps"]))
            if rec["bisected_steps"]:  # steps reached only through sub-steps
                reached = rec["bisected_steps"]
                most = max(rec["substeps"][k] for k in reached)
                smallest = min(rec["smallest_substep"][k] for k in reached)
                notes.append(_note("bisected", reached)
                             + f" (up to {most} sub-steps, smallest {fraction_text(smallest)})")
            if rec.get("extrapolated_steps"):
                notes.append(f"DATA RANGE EXCEEDED at {rec['extrapolated_steps']} step"
                             f"{'s' if rec['extrapolated_steps'] > 1 else ''} (max {rec['max_extrapolated_states']} "
                             f"of {self.model.n_points} states; {_listing(rec['extrapolated_h'], name)})")
            if rec.get("coarse_data_steps"):
                notes.append(_note("DATA TOO COARSE", rec["coarse_data_h"], name) + f": {rec['coarse_data']}")
            if rec.get("local_minimum_h"):
                notes.append(_note("local minimum", rec["local_minimum_h"], name))
            if rec.get("projection_not_global_steps"):
                notes.append(_note("projection not global", rec["projection_not_global_steps"]))
            lines.append(f"{rec['variant']:<10} {rec['formulation']:<22} {rec['converged_steps']:>3}/{rec['steps']:<3} "
                         f"{e(rec['max_error_u'])} {e(rec['max_error_p'])} {rec['iterations_mean']:8.1f} "
                         f"{rec['outer_iterations_mean']:6.1f} {rec['max_residual']:8.1e} {rec['max_complementarity']:8.1e} "
                         f"{rec['build_seconds']:8.3f} {rec['solve_seconds']:8.3f}  "
                         + "; ".join(notes))
        if self.model.closed_form(0) is not None:
            lines.append("errors: max over steps of |value - closed form| / max |closed form|; "
                         "DDCM against the classical closed form")
        lines.append("max res / max comp: scaled equilibrium residual and max |min(g, p)| over all steps")
        return "\n".join(lines)


def as_ddcm_options(ddcm: DDCMOptions | Mapping | None) -> DDCMOptions:
    """:class:`DDCMOptions` from options, a mapping of their names (copied), or ``None`` (defaults)."""
    if ddcm is None or isinstance(ddcm, DDCMOptions):
        return ddcm or DDCMOptions()
    if not isinstance(ddcm, Mapping):
        raise InputError(f"ddcm options must be DDCMOptions or a mapping, got {type(ddcm).__name__}")
    unknown = sorted(set(ddcm) - KEYS)
    if unknown:
        raise InputError(f"unknown ddcm option {unknown[0]!r}")
    return DDCMOptions(**dict(ddcm))


def compare(model: ContactModel, formulations=None, *, variants: Iterable[str] = VARIANTS,
            raise_on_failure: bool = False, ddcm_max_outer: int | None = None, ddcm_search: str | None = None,
            ddcm: DDCMOptions | None = None,
            progress: Callable[[str, str, StepResult], None] | None = None, jobs: int | None = 1,
            min_substep: float = DEFAULT_MIN_SUBSTEP, condense: bool = True) -> Comparison:
    """Run every formulation in every variant along the model's load path.

    Parameters
    ----------
    model : ContactModel
        The model description (classical needs a modulus, DDCM a data set).
    formulations : list of names or instances, or {name: options}, optional
        Default: every registered formulation with default options.
    variants : iterable of {"classical", "ddcm"}
    raise_on_failure : bool
        Raise :class:`~ddcm_casadi.errors.ConvergenceError` at the first non-converged step.
    ddcm_max_outer : int, optional
        Alternating-projection iterations per DDCM load step: replaces ``ddcm.max_outer``.
    ddcm_search : str, optional
        Data search backend of the DDCM iterations (:data:`ddcm_casadi.data.search.SEARCHES`:
        ``"kdtree"``, ``"graph"``): replaces ``ddcm.search``.
    ddcm : DDCMOptions or mapping, optional
        Iterations, data search, where DDCM steps start (also an explicit initial assignment),
        restarts, greedy improvement, certificates and noise-robust variants
        (:class:`~ddcm_casadi.drivers.ddcm_options.DDCMOptions`; default: its defaults).
    progress : callable, optional
        Called as ``progress(variant, formulation, step_result)`` after every step (with ``jobs >
        1``, in the process that runs the step).
    jobs : int or None
        Processes that run the formulation x variant runs side by side, this one included
        (:func:`ddcm_casadi.parallel.map_forked`): 1 (default) runs them here one after the other,
        ``None`` uses every available core. Results are the same; each run's timings are its own
        (on a shared machine, runs side by side may slow each other).
    min_substep : float
        A load step that fails is bisected automatically, in both variants, down to sub-steps of
        this fraction of a step (:mod:`ddcm_casadi.drivers.substeps`; default 1/16; 0 or 1: off).
    condense : bool
        Solve the classical problem condensed on its contact pairs where that applies (the
        default; :func:`~ddcm_casadi.drivers.ddcm_reduced.build_classical`, the same solutions to
        round-off), or always on the full problem (``False``).

    Returns
    -------
    Comparison
    """
    variants = list(variants)
    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        raise InputError(f"unknown variant {bad[0]!r}; choose from {', '.join(VARIANTS)}")
    if jobs is not None and (isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or jobs < 1):
        raise InputError(f"jobs must be a positive integer or None (every core), got {jobs!r}")
    min_substep = check_min_substep(min_substep)
    ddcm = as_ddcm_options(ddcm)
    given = {k: v for k, v in dict(max_outer=ddcm_max_outer, search=ddcm_search).items() if v is not None}
    ddcm = dataclasses.replace(ddcm, **given) if given else ddcm  # checked as the options are
    forms = resolve_formulations(formulations, model.contact_law)
    odd = model.path_warnings()  # refuses a meaningless path before any work
    for message in odd:
        warnings.warn(message, PhysicsWarning, stacklevel=2)
    problems = build_problems(model)
    out = Comparison(model=model, problems=problems, formulations=forms, warnings=odd)
    runs = [(variant, form) for variant in variants
            if problems.has("classical" if variant == "classical" else "projection")
            for form in forms]
    for variant, form in runs:  # refuse an unsupported contact law or kinematics before any work
        form.check_supports(problems.classical if variant == "classical" else problems.projection)

    def run(task):
        variant, form = task
        cb = (lambda s: progress(variant, form.name, s)) if progress else None
        t0 = time.perf_counter()
        if variant == "classical":
            built = build_classical(form, problems, reduce=condense)
            build = time.perf_counter() - t0
            r = solve_classical(problems, built, form.name, raise_on_failure=raise_on_failure, progress=cb,
                                min_substep=min_substep)
        else:
            built = build_projection(form, problems, reduce=ddcm.reduce)
            solver = DDCMSolver(problems, built, options=ddcm, min_substep=min_substep)
            build = time.perf_counter() - t0
            r = solver.solve(formulation_name=form.name, raise_on_failure=raise_on_failure, progress=cb)
        r.build_seconds = build
        return r

    for (variant, form), r in zip(runs, map_forked(run, runs, jobs=resolve_jobs(jobs, len(runs)))):
        out.results[(variant, form.name)] = r
        coarse = coarse_data_warning(r, model.load_parameter_name)
        if coarse:
            out.warnings.append(coarse)
            warnings.warn(coarse, PhysicsWarning, stacklevel=2)
    return out


def coarse_data_warning(result: PathResult, name: str | None = None) -> str:
    """The warning of a DDCM run whose data are too coarse for its states at some steps
    (:func:`~ddcm_casadi.data.extrapolation.coarse_data`), or ``""``.

    Parameters
    ----------
    result : PathResult
        One variant x formulation run.
    name : str, optional
        The model's load parameter, to list the steps by.
    """
    steps = [s for s in result.steps if s.coarse_data]
    if not steps:
        return ""
    where = _note("at", [s.load_parameter for s in steps], name)[3:] if name else _note("at", [s.step for s in steps])[3:]
    return (f"{result.variant}/{result.formulation}: the material data are too coarse for the states {where} "
            f"- {steps[-1].coarse_data}; DDCM rounds each state to a datum, so expect contact forces well "
            f"below the classical ones: use more data points, denser towards zero strain")
