"""The library entry point: run a case and write its results.

:func:`run_case` is what ``ddcm-compare`` (:mod:`ddcm_casadi.commands.compare`), ``ddcm-sweep``
(:mod:`ddcm_casadi.sweep.runner`, on each worker) and the Python API run::

    from ddcm_casadi import run_case
    from ddcm_casadi.casefiles.config import load_case

    run = run_case(load_case("examples/cases/truss2d.toml"), "results", formulations=["fischer_burmeister"])
    run.comparison.table(), run.document["summary"], run.files

It checks the selection, locks the output folder, runs every formulation in every variant
(:func:`~ddcm_casadi.drivers.harness.compare`) and writes, all or nothing (:class:`~ddcm_casadi.io.OutputFolder`):
``results.csv`` (:meth:`~ddcm_casadi.drivers.harness.Comparison.rows`), the model's field files and figures
(:func:`~ddcm_casadi.outputs.save.save_outputs`) and ``results.json``, whose one builder is
:func:`results_document`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

import numpy as np

from ddcm_casadi import formulations as registry
from ddcm_casadi.casefiles.base import Case
from ddcm_casadi.errors import InputError
from ddcm_casadi.drivers.harness import VARIANTS, Comparison, compare
from ddcm_casadi.io import MANIFEST_FORMAT_KEY, OutputFolder, write_csv_atomic, write_json_atomic
from ddcm_casadi.outputs.save import require_matplotlib, save_outputs
from ddcm_casadi.linalg import DATA_BYTES_PER_VALUE, factor_bytes
from ddcm_casadi.parallel import physical_memory, resolve_jobs  # noqa: F401 - physical_memory: the API
from ddcm_casadi.version import versions

if TYPE_CHECKING:
    from ddcm_casadi.drivers.harness import StepResult

RESULTS_CSV = "results.csv"
RESULTS_JSON = "results.json"
#: The identity of a ``results.json`` written by this package (its ``format``): only such a
#: manifest makes a rerun remove the files it lists.
RESULTS_FORMAT = "ddcm-casadi results"

#: ``progress(variant, formulation, step_result)`` after every step of every run.
Progress = Callable[[str, str, "StepResult"], None]


@dataclass
class CaseRun:
    """What :func:`run_case` did.

    Attributes
    ----------
    case : Case
        The case that was run.
    comparison : Comparison
        Its results.
    rows : list of dict
        The rows of ``results.csv``.
    document : dict
        The content of ``results.json`` (:func:`results_document`).
    files : list of str
        The files written, relative to ``out_dir`` (empty when nothing was written).
    out_dir : Path or None
        The output folder, if any.
    """

    case: Case
    comparison: Comparison
    rows: list[dict]
    document: dict
    files: list[str] = field(default_factory=list)
    out_dir: Path | None = None


# -------------------------------------------------------------------------------------- memory
def estimate_bytes(model, runs: int = 1) -> int:
    """A rough estimate of the memory the runs of ``model`` need at once, in bytes.

    The sparse factor of the stiffness matrix dominates: ``nnz(K)`` times a fill factor
    (``n^(1/3)`` for a 3-D continuum, six Mandel components; ``log2 n`` otherwise, as nested
    dissection gives), 12 bytes an entry (value and index), per run at once; plus the operators
    and, for data-driven runs, the data (with the search tree, about three copies of it).

    Parameters
    ----------
    model : ContactModel
        The built model.
    runs : int
        Runs held in memory at once (processes of ``--jobs``).

    Returns
    -------
    int
        Bytes, an estimate (within a factor of a few).
    """
    B = model.strain_operator
    n = max(int(model.n_dofs), 2)
    nnz_k = (abs(B).T @ abs(B)).nnz if B.nnz else n
    per_run = factor_bytes(n, nnz_k, model.strain_components >= 6) + 12.0 * (B.nnz + model.gap_operator.nnz)
    data = 0.0
    if model.dataset is not None:
        data = DATA_BYTES_PER_VALUE * sum(np.asarray(d.strain).size for d in model.dataset.datasets)
    return int(per_run * max(int(runs), 1) + data)


def check_memory(model, runs: int = 1) -> None:
    """Refuse, before any work, a case whose estimated memory (:func:`estimate_bytes`) exceeds the
    machine's physical memory (:func:`physical_memory`).

    Raises
    ------
    InputError
        One line with the estimate, the machine's memory and what to reduce.
    """
    have = physical_memory()
    if have is None:
        return
    need = estimate_bytes(model, runs)
    if need > have:
        raise InputError(f"this case needs about {need / 2**30:.3g} GiB ({model.n_dofs} unknowns"
                         + (f", {runs} runs at once" if runs > 1 else "")
                         + f") but the machine has {have / 2**30:.3g} GiB of memory: use a coarser mesh, "
                         "fewer data points or fewer --jobs")


# ----------------------------------------------------------------------------------- selection
def select_formulations(names: Sequence[str] | None, contact_law: str = "signorini") -> list[str]:
    """The formulations to run: ``names`` (checked), or every registered one that enforces the
    case's ``contact_law`` (a named one that does not is refused by the formulation itself).

    Raises
    ------
    InputError
        An unknown formulation (the message lists the known ones).
    """
    available = registry.available()
    if names is None:
        return registry.enforcing(contact_law)
    for name in names:
        if name not in available:
            raise InputError(f"unknown formulation {name!r}; available: {', '.join(available)}")
    return list(names)


def select_variants(names: Sequence[str] | None, case: Case) -> list[str]:
    """The variants to run: ``names``, or by default every one the case supports.

    Raises
    ------
    InputError
        Unknown variant, or one the case cannot run (``ddcm`` without a data set).
    """
    model = case.model
    needs = {"classical": None if model.youngs_modulus is not None else "a Young's modulus",
             "ddcm": None if model.dataset is not None else "a material data set ([data] in the case file)"}
    if names is None:
        return [v for v in VARIANTS if needs[v] is None]
    for v in names:
        if v not in VARIANTS:
            raise InputError(f"unknown variant {v!r}; choose from {', '.join(VARIANTS)}")
        if needs[v] is not None:
            raise InputError(f"variant {v!r} needs {needs[v]}; {case.source} has none")
    return list(names)


# ------------------------------------------------------------------------------ results.json
def describe_dataset(dataset) -> dict | None:
    """The ``data`` record of ``results.json`` (the data set's own :meth:`describe`), or ``None``."""
    return None if dataset is None else dataset.describe()


def parameters(case: Case, cmp: Comparison) -> dict:
    """The ``parameters`` record of ``results.json``: model, data and resolved formulation options.

    Parameters
    ----------
    case : Case
        The case that was run.
    cmp : Comparison
        Its results (for the formulations' resolved options).

    Returns
    -------
    dict
        ``case``, then the model's own record (:meth:`~ddcm_casadi.models.base.ContactModel.describe`:
        for the paper's bar ``length``, ``area``, ``youngs_modulus``, ``positions``; for any other
        model its ``name``, sizes, ``load_parameter_name`` and values, and the moduli, for trusses
        also ``dimension``, ``n_nodes``, ``n_members``), ``data`` (:func:`describe_dataset`),
        ``ddcm_max_outer``, ``ddcm`` (the search options,
        :meth:`~ddcm_casadi.drivers.ddcm_options.DDCMOptions.describe`), ``min_substep`` (the
        smallest sub-step of the step bisection, :mod:`~ddcm_casadi.drivers.substeps`), ``condense``
        (the classical problem condensed on its contact pairs where that applies) and
        ``formulations`` (options with their problem-dependent defaults resolved, e.g. ``gamma_used``).
    """
    m = case.model
    # the options depend on the model's contact stiffness, which both problems share: read them
    # from a problem the runs built (a DDCM-only run never builds the classical problem)
    ran = {variant for variant, _ in cmp.results}
    problems = cmp.problems
    problem = problems.classical if "classical" in ran or not problems.has("projection") else problems.projection
    forms = {f.name: f.resolved_options(problem) for f in cmp.formulations}
    # A dict display, not keywords: a model record may not clash with the run's own keys.
    return {"case": case.source, **m.describe(), "data": describe_dataset(m.dataset),
            "ddcm_max_outer": case.ddcm_max_outer, "ddcm": case.ddcm_options.describe(),
            "min_substep": case.min_substep, "condense": case.condense, "formulations": forms}


def fields(cmp: Comparison) -> dict[str, dict[str, np.ndarray]] | None:
    """Per-step fields of every run, keyed ``"variant/formulation"`` (``None`` for the paper's bar).

    Each run maps the names of :meth:`~ddcm_casadi.drivers.harness.Comparison.fields` (``u``,
    ``contact_pressure``, ``contact_force``, ``strain``, ``stress``, for trusses
    ``nodal_displacement`` and ``member_force``, for DDCM the assigned data) to arrays, steps
    first (written as nested lists, non-finite values as null), as much of them as the model keeps
    (:meth:`~ddcm_casadi.models.base.ContactModel.results_fields`), and with a hard device always
    ``hard_device_force`` (steps, supports, dim: the force the device exerts on the body, N; the
    supports are named in ``parameters.hard_device``). The one-unknown bar has none: its CSV
    rows already hold ``u`` and ``p``.
    """
    model = cmp.model
    if model.scalar:
        return None
    out = {}
    for variant, name in cmp.results:
        full = cmp.fields(variant, name)
        kept = model.results_fields(full)
        if "hard_device_force" in full:  # kept by every model kind (a continuum keeps a summary only)
            kept = {**kept, "hard_device_force": full["hard_device_force"]}
        out[f"{variant}/{name}"] = kept
    return out


def results_document(case: Case, cmp: Comparison, *, files: Sequence[str],
                     overrides: Mapping[str, Any] | None = None) -> dict:
    """The ``results.json`` document of a run (the one builder: ``ddcm-compare`` and ``ddcm-sweep``).

    Parameters
    ----------
    case : Case
        The case that was run.
    cmp : Comparison
        Its results.
    files : sequence of str
        The files the run writes, relative to its folder, ``results.json`` included: the manifest
        by which the next run into the folder removes what it does not write itself.
    overrides : mapping, optional
        The values that override the case file (``--set``, a sweep case's parameters), recorded
        as ``parameters.overrides`` when there are any.

    Returns
    -------
    dict
        ``parameters`` (:func:`parameters`), ``versions``, ``summary``
        (:meth:`~ddcm_casadi.drivers.harness.Comparison.summary`: per run, also the steps reached
        through sub-steps, ``bisected_steps``, and per step ``substeps`` and ``smallest_substep``),
        ``warnings`` (physically odd input),
        ``fields`` (:func:`fields`; not for the one-unknown bar), ``files`` and ``format``
        (:data:`RESULTS_FORMAT`: the identity by which a rerun trusts the manifest).
    """
    params = parameters(case, cmp)
    if overrides:
        params["overrides"] = dict(overrides)
    doc = dict(parameters=params, versions=versions(), summary=cmp.summary(), warnings=list(cmp.warnings))
    per_step = fields(cmp)
    if per_step is not None:
        doc["fields"] = per_step
    doc["files"] = list(files)
    doc[MANIFEST_FORMAT_KEY] = RESULTS_FORMAT
    return doc


# ---------------------------------------------------------------------------------- the entry
def compare_case(case: Case, formulations: Sequence[str], variants: Sequence[str], *,
                 progress: Progress | None = None, jobs: int | None = 1) -> Comparison:
    """Run the formulations ``formulations`` of a case in ``variants``, with the case's formulation
    options, DDCM settings, step bisection (``min_substep``) and ``condense``, in ``jobs`` processes (nothing
    written)."""
    selection = {n: case.formulation_options.get(n, {}) for n in formulations}
    return compare(case.model, selection, variants=list(variants), ddcm_max_outer=case.ddcm_max_outer,
                   ddcm=case.ddcm_options, progress=progress, jobs=jobs, min_substep=case.min_substep,
                   condense=case.condense)


def write_results(case: Case, cmp: Comparison, out_dir: str | Path, *, rows: list[dict] | None = None,
                  figures: bool = True, jobs: int = 1, overrides: Mapping[str, Any] | None = None
                  ) -> tuple[dict, list[str]]:
    """Write a run's results into ``out_dir``, each file atomically: ``results.csv``, the model's
    field files and figures (:func:`~ddcm_casadi.outputs.save.save_outputs`), then ``results.json``.

    Parameters
    ----------
    case, cmp : Case, Comparison
        The case that was run and its results.
    out_dir : str or Path
        An existing folder (:func:`run_case` gives the staging folder of a locked one).
    rows : list of dict, optional
        ``cmp.rows()`` if already computed.
    figures : bool
        Draw the figures.
    jobs : int
        Processes drawing the figures.
    overrides : mapping, optional
        Recorded in ``results.json`` (:func:`results_document`).

    Returns
    -------
    tuple of (dict, list of str)
        The ``results.json`` document and the files written, relative to ``out_dir``.
    """
    out_dir = Path(out_dir)
    write_csv_atomic(out_dir / RESULTS_CSV, cmp.rows() if rows is None else rows)
    written = [RESULTS_CSV]
    written += [p.relative_to(out_dir).as_posix() for p in save_outputs(cmp, out_dir, figures=figures, jobs=jobs)]
    written.append(RESULTS_JSON)
    doc = results_document(case, cmp, files=written, overrides=overrides)
    write_json_atomic(out_dir / RESULTS_JSON, doc)
    return doc, written


def run_case(case: Case, out_dir: str | Path | None = None, *, formulations: Sequence[str] | None = None,
             variants: Sequence[str] | None = None, figures: bool = True, jobs: int | None = 1,
             overrides: Mapping[str, Any] | None = None, progress: Progress | None = None,
             on_start: Callable[[], None] | None = None, on_compared: Callable[[Comparison], None] | None = None,
             tool: str = "ddcm_casadi") -> CaseRun:
    """Run a case and write its results: the library entry point of every front end.

    Parameters
    ----------
    case : Case
        The case (:func:`ddcm_casadi.casefiles.config.load_case`, :func:`~ddcm_casadi.casefiles.config.default_case`,
        or ``Case(model=...)``).
    out_dir : str or Path, optional
        Where to write ``results.csv``, ``results.json``, the field files (VTU) and the figures. The
        folder is locked before any work and written all or nothing
        (:class:`~ddcm_casadi.io.OutputFolder`); a rerun removes the files of the previous run that
        it does not write. Without it nothing is written.
    formulations : sequence of str, optional
        The formulations to run (default: every registered one).
    variants : sequence of str, optional
        ``"classical"`` and/or ``"ddcm"`` (default: those the case supports).
    figures : bool
        Draw the model's figures (matplotlib is imported only then, before any work).
    jobs : int or None
        Processes running the formulations side by side, then drawing the figures (``None``: one
        per core; never more than the runs).
    overrides : mapping, optional
        The values that override the case file, recorded in ``results.json``.
    progress : callable, optional
        ``progress(variant, formulation, step_result)`` after every step.
    on_start : callable, optional
        Called once the input is checked and the folder locked, before the runs (``ddcm-compare``
        says what it runs).
    on_compared : callable, optional
        Called with the comparison before anything is written (``ddcm-compare`` prints its table).
    tool : str
        The name the folder's lock gives to a second run into it.

    Returns
    -------
    CaseRun
        The comparison, ``results.csv``'s rows, ``results.json``'s document and the files written.

    Raises
    ------
    InputError
        Bad selection, a meaningless load path, a case too big for the machine's memory
        (:func:`check_memory`), a folder in use or that cannot be written (one line).
    """
    names = select_formulations(formulations, case.model.contact_law)
    chosen = select_variants(variants, case)
    jobs = resolve_jobs(jobs, len(names) * len(chosen))
    case.model.path_warnings()  # refuses a meaningless path before the folder is touched
    check_memory(case.model, jobs)  # refuses what cannot fit, as well
    folder = OutputFolder(out_dir, tool=tool, manifest=RESULTS_JSON, identity=RESULTS_FORMAT) if out_dir is not None else None
    try:
        draw = folder is not None and figures
        if draw:
            # imported before any result is written: a missing matplotlib must not leave results
            # without their figures
            require_matplotlib()
        if on_start is not None:
            on_start()
        cmp = compare_case(case, names, chosen, progress=progress, jobs=jobs)
        if on_compared is not None:
            on_compared(cmp)
        rows = cmp.rows()
        if folder is None:
            # nothing written: the document lists what the tables of a run take (ddcm-sweep's
            # workers return it, and the client writes those two files)
            doc = results_document(case, cmp, files=[RESULTS_CSV, RESULTS_JSON], overrides=overrides)
            return CaseRun(case=case, comparison=cmp, rows=rows, document=doc)
        # Every output goes to a temporary folder, moved into place once all are written: a
        # failure (a full disk) or Ctrl-C leaves the previous results of the folder as they were.
        with folder.staging() as stage:
            doc, written = write_results(case, cmp, stage, rows=rows, figures=draw, jobs=jobs, overrides=overrides)
        return CaseRun(case=case, comparison=cmp, rows=rows, document=doc, files=written, out_dir=folder.path)
    finally:
        if folder is not None:
            folder.close()
