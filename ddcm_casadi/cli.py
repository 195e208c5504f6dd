"""``ddcm-compare``: every contact formulation, classical and DDCM, on one load path.

With no arguments it runs the paper's example (Section 4) and prints a summary table;
--config CASE runs a case file instead (TOML or JSON: the paper's bar, an N-element bar with
stops, or a 1-D/2-D/3-D truss; the format is described in ddcm_casadi/config.py, each model
kind's sections next to its parser in ddcm_casadi/bar.py and ddcm_casadi/truss.py). --out DIR
writes results.csv, results.json (for models other than the one-unknown bar with the per-step
fields of every run: nodal displacements, contact forces, ...) and the figures that suit the model:
all of them or none (a temporary folder moved into place), replacing the previous run's files, in
a folder locked against a second run (ddcm_casadi/io.py, OutputFolder).
--set KEY=VALUE overrides one value of the case file (a dotted key and a TOML value, applied to
the document before it is validated; see ddcm_casadi/overrides.py) and is recorded in results.json.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
import warnings
from typing import NoReturn

import casadi
import numpy as np
import scipy

from ddcm_casadi import formulations as registry

from . import __version__
from .config import Case, default_case, load_case_with_overrides
from .errors import DDCMError, InputError, PhysicsWarning
from .harness import VARIANTS, Comparison, compare
from .io import OutputFolder, write_csv_atomic, write_json_atomic
from .outputs import require_matplotlib, save_outputs
from .parallel import resolve_jobs

EXIT_INPUT = 2
EXIT_NOT_CONVERGED = 3


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, like every other input error."""

    def error(self, message: str) -> NoReturn:
        """Print ``prog: error: message`` on one line and exit with :data:`EXIT_INPUT`.

        Parameters
        ----------
        message : str
            The problem found by :mod:`argparse`.
        """
        self.exit(EXIT_INPUT, f"{self.prog}: error: {_one_line(message)} (see --help)\n")


def _one_line(message: object) -> str:
    """``message`` as a single line (an error message must not spill over several lines)."""
    return " ".join(line.strip() for line in str(message).splitlines() if line.strip())


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="ddcm-compare", description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", metavar="CASE", help="case file, .toml or .json (default: the paper's example)")
    p.add_argument("--set", metavar="KEY=VALUE", action="append", default=[], dest="overrides",
                   help="override a value of the case file: a dotted key (ddcm.c, data.0.c, "
                        "formulations.penalty.gamma) and a TOML value; repeatable, needs --config")
    p.add_argument("--formulations", metavar="A,B", help=f"subset of: {','.join(registry.available())}")
    p.add_argument("--variants", metavar="A,B",
                   help=f"subset of: {','.join(VARIANTS)} (default: those the case supports)")
    p.add_argument("--out", metavar="DIR", help="write results.csv, results.json and the figures here")
    p.add_argument("--no-plots", action="store_true", help="do not draw the figures")
    p.add_argument("--strict", action="store_true",
                   help=f"exit with status {EXIT_NOT_CONVERGED} if any step did not converge")
    p.add_argument("-j", "--jobs", metavar="N", type=_jobs,
                   help="run the formulations side by side in N processes (default: one per available core)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    return p


def _jobs(text: str) -> int:
    """``--jobs``: a positive integer (argparse turns the error into a one-line usage error)."""
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}")
    return n


def _split(arg: str | None, option: str) -> list[str] | None:
    """The comma-separated names in ``arg`` (``None`` if the option was not given)."""
    if arg is None:
        return None
    names = [a.strip() for a in arg.split(",") if a.strip()]
    if not names:
        raise InputError(f"{option} needs a comma-separated list of names, got {arg!r}")
    return names


def _variants(arg: str | None, case: Case) -> list[str]:
    """The variants to run: the ones named in ``--variants``, or by default every one the case supports.

    Raises
    ------
    InputError
        Unknown variant, or one the case cannot run (``ddcm`` without a data set).
    """
    model = case.model
    needs = {"classical": None if model.youngs_modulus is not None else "a Young's modulus",
             "ddcm": None if model.dataset is not None else "a material data set ([data] in the case file)"}
    names = _split(arg, "--variants")
    if names is None:
        return [v for v in VARIANTS if needs[v] is None]
    for v in names:
        if v not in VARIANTS:
            raise InputError(f"unknown variant {v!r}; choose from {', '.join(VARIANTS)}")
        if needs[v] is not None:
            raise InputError(f"variant {v!r} needs {needs[v]}; {case.source} has none")
    return names


class _Progress:
    """Progress on stderr: ``variant/formulation step k/n elapsed``.

    On a terminal one line per run, updated in place after every step. Otherwise (a log) a line
    after a run's first step, then at most one every :attr:`interval` seconds while it goes on,
    and one at its last step and at every step that did not converge: a long run shows its pace.
    """

    #: Seconds between two lines of one run when stderr is not a terminal.
    interval: float = 10.0

    def __init__(self, n_steps: int, enabled: bool, *, in_place: bool = True) -> None:
        self.n, self.enabled = n_steps, enabled
        self.tty = in_place and sys.stderr.isatty()
        self.t0 = time.perf_counter()
        self._last: tuple[tuple[str, str], float] | None = None  # the run and time of the last line

    def __call__(self, variant: str, name: str, step) -> None:
        if not self.enabled:
            return
        done = step.step + 1
        flag = "" if step.converged else "  NOT CONVERGED"
        now = time.perf_counter()
        msg = f"{variant:>9}/{name:<21} step {done:>3}/{self.n}  {now - self.t0:7.2f} s{flag}"
        if self.tty:
            end = "\n" if done == self.n or flag else ""
            print("\r" + msg, end=end, file=sys.stderr, flush=True)
            return
        run = (variant, name)
        if (done == self.n or flag or self._last is None or self._last[0] != run
                or now - self._last[1] >= self.interval):
            # one write per line: the processes of ``--jobs`` share stderr, and print() writes the
            # line and its end separately
            sys.stderr.write(msg + "\n")
            sys.stderr.flush()
            self._last = (run, now)


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
        ``case``, then the model's own record (:meth:`~ddcm_casadi.model.ContactModel.describe`:
        for the paper's bar ``length``, ``area``, ``youngs_modulus``, ``positions``; for any other
        model its ``name``, sizes, ``load_parameter_name`` and values, and the moduli, for trusses
        also ``dimension``, ``n_nodes``, ``n_members``), ``data`` (:func:`describe_dataset`),
        ``ddcm_max_outer``, ``ddcm`` (the search options,
        :meth:`~ddcm_casadi.solvers.ddcm_options.DDCMOptions.describe`) and ``formulations``
        (options with their problem-dependent defaults resolved, e.g. ``gamma_used``).
    """
    m = case.model
    forms = {f.name: f.resolved_options(cmp.problems.classical) for f in cmp.formulations}
    # A dict display, not keywords: a model record may not clash with the run's own keys.
    return {"case": case.source, **m.describe(), "data": describe_dataset(m.dataset),
            "ddcm_max_outer": case.ddcm_max_outer, "ddcm": case.ddcm_options.describe(), "formulations": forms}


def fields(cmp: Comparison) -> dict[str, dict[str, np.ndarray]] | None:
    """Per-step fields of every run, keyed ``"variant/formulation"`` (``None`` for the paper's bar).

    Each run maps the names of :meth:`~ddcm_casadi.harness.Comparison.fields` (``u``,
    ``contact_pressure``, ``contact_force``, ``strain``, ``stress``, for trusses
    ``nodal_displacement`` and ``member_force``, for DDCM the assigned data) to arrays, steps
    first (written as nested lists, non-finite values as null). The one-unknown bar has none: its CSV rows already hold ``u`` and ``p``.
    """
    if cmp.model.scalar:
        return None
    model = cmp.model
    return {f"{variant}/{name}": model.results_fields(cmp.fields(variant, name)) for (variant, name) in cmp.results}


def compare_case(case: Case, names: list[str], variants: list[str], *, progress=None,
                 jobs: int | None = 1) -> Comparison:
    """Run a case as ``ddcm-compare`` does: the formulations ``names`` with the case's options, the
    case's DDCM settings (also what ``ddcm-sweep`` runs per case), in ``jobs`` processes."""
    selection = {n: case.formulation_options.get(n, {}) for n in names}
    return compare(case.model, selection, variants=variants, ddcm_max_outer=case.ddcm_max_outer,
                   ddcm=case.ddcm_options, progress=progress, jobs=jobs)


def versions() -> dict:
    return {"ddcm_casadi": __version__, "casadi": casadi.__version__, "numpy": np.__version__,
            "scipy": scipy.__version__, "python": platform.python_version()}


def run(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.overrides and not args.config:
        raise InputError("--set needs --config CASE (the paper's built-in example has no case file to override)")
    overrides: dict = {}
    if args.config:
        case, overrides = load_case_with_overrides(args.config, args.overrides)
    else:
        case = default_case()
    names = _split(args.formulations, "--formulations") or registry.available()
    for n in names:
        if n not in registry.available():
            raise InputError(f"unknown formulation {n!r}; available: {', '.join(registry.available())}")
    variants = _variants(args.variants, case)
    for message in case.model.path_warnings():  # refuses a meaningless path before anything is written
        print(f"ddcm-compare: warning: {message}", file=sys.stderr)
    # The folder is created, checked and locked before any work, and stays locked until the end.
    folder = OutputFolder(args.out, tool="ddcm-compare", manifest="results.json") if args.out is not None else None
    try:
        return _run_case(args, case, names, variants, overrides, folder)
    finally:
        if folder is not None:
            folder.close()


def _run_case(args, case: Case, names: list[str], variants: list[str], overrides: dict,
              folder: OutputFolder | None) -> int:
    """Run the checked case, print the table and write the outputs into ``folder`` (if any)."""
    draw = folder is not None and not args.no_plots
    if draw:
        # matplotlib only when a plot is drawn, but imported before any result is written: a
        # missing matplotlib must not leave results without their figures.
        require_matplotlib()

    jobs = resolve_jobs(args.jobs, len(names) * len(variants))
    # Runs side by side print their steps as lines: in-place updates of one line would clash.
    progress = _Progress(case.model.n_steps, not args.quiet, in_place=jobs == 1)
    if not args.quiet:
        print(f"ddcm-compare: {case.source}: {case.model.n_steps} steps, "
              f"{len(names)} formulations x {len(variants)} variants"
              + (f", {jobs} processes" if jobs > 1 else ""), file=sys.stderr)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsWarning)  # printed above, in one line each
        cmp = compare_case(case, names, variants, progress=progress, jobs=jobs)
    print(cmp.table())

    if folder is not None:
        # Every output goes to a temporary folder, moved into place once all are written: a
        # failure (a full disk) or Ctrl-C leaves the previous results of the folder as they were.
        rows = cmp.rows()
        doc = dict(parameters=parameters(case, cmp), versions=versions(), summary=cmp.summary(),
                   warnings=list(cmp.warnings))
        if overrides:
            doc["parameters"]["overrides"] = overrides
        per_step = fields(cmp)
        if per_step is not None:
            doc["fields"] = per_step
        with folder.staging() as stage:
            write_csv_atomic(stage / "results.csv", rows)
            written = ["results.csv"]
            outputs = save_outputs(cmp, stage, figures=draw, jobs=jobs)
            written += [p.relative_to(stage).as_posix() for p in outputs]
            written.append("results.json")
            # the manifest: the next run into this folder removes these files if it does not write them
            doc["files"] = written
            write_json_atomic(stage / "results.json", doc)
        print(f"wrote {', '.join(written)} to {folder.path}", file=sys.stderr)
    beyond = [r for r in cmp.results.values() if any(s.extrapolated for s in r.steps)]
    if beyond:  # a flag, not a failure: the fixed points are fixed points, of data that end too soon
        print("WARNING: states beyond the material data (DDCM stresses stop at the data's edge) in "
              + ", ".join(f"{r.variant}/{r.formulation} at {sum(s.extrapolated > 0 for s in r.steps)} steps"
                          for r in beyond), file=sys.stderr)
    failed = [r for r in cmp.results.values() if not r.converged]
    if failed:
        print("WARNING: non-converged steps in " + ", ".join(f"{r.variant}/{r.formulation}" for r in failed),
              file=sys.stderr)
        if args.strict:
            return EXIT_NOT_CONVERGED
    return 0


def run_guarded(prog: str, run_command, argv: list[str] | None, *, interrupted: str = "interrupted") -> int:
    """``run_command(argv)``, with an input error as one line ``prog: error: ...`` and exit status
    :data:`EXIT_INPUT`, and Ctrl-C as ``prog: interrupted`` and status 130 (every command's ``main``)."""
    try:
        return run_command(argv)
    except DDCMError as exc:
        print(f"{prog}: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        print(f"{prog}: {interrupted}", file=sys.stderr)
        return 130


def main(argv: list[str] | None = None) -> int:
    return run_guarded("ddcm-compare", run, argv)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
