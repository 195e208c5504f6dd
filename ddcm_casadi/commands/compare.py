"""``ddcm-compare``: every contact formulation, classical and DDCM, on one load path.

With no arguments it runs the paper's example (Section 4) and prints a summary table;
--config CASE runs a case file instead (TOML or JSON: the paper's bar, an N-element bar with
stops, or a 1-D/2-D/3-D truss; the format is described in ddcm_casadi/casefiles/config.py, each model
kind's sections next to its parser in ddcm_casadi/casefiles/bar.py and ddcm_casadi/casefiles/truss.py).
The run and its outputs are the library's (ddcm_casadi/run.py, run_case). --out DIR
writes results.csv, results.json (for models other than the one-unknown bar with the per-step
fields of every run: nodal displacements, contact forces, ...) and the figures that suit the model:
all of them or none (a temporary folder moved into place), replacing the previous run's files, in
a folder locked against a second run (ddcm_casadi/io.py, OutputFolder).
--set KEY=VALUE overrides one value of the case file (a dotted key and a TOML value, applied to
the document before it is validated; see ddcm_casadi/casefiles/overrides.py) and is recorded in results.json.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
import time
import warnings
from typing import Iterator

from ddcm_casadi import formulations as registry
from ddcm_casadi.commands.base import (  # noqa: F401 - EXIT_INPUT: the API
    EXIT_INPUT, EXIT_NOT_CONVERGED, Parser, run_guarded,
)
from ddcm_casadi.casefiles.config import default_case, load_case_with_overrides
from ddcm_casadi.errors import InputError, PhysicsWarning
from ddcm_casadi.drivers.harness import VARIANTS, Comparison, coarse_data_warning
from ddcm_casadi.drivers.substeps import fraction_text
from ddcm_casadi.outputs.point_cloud import POINTS_SUFFIX
from ddcm_casadi.parallel import resolve_jobs
from ddcm_casadi.run import CaseRun, run_case, select_formulations, select_variants
from ddcm_casadi.version import __version__


#: ``ddcm-compare --help``: plain text (the module's docstring is for the API documentation).
HELP = """\
Run every contact formulation (penalty, augmented Lagrangian, Fischer-Burmeister, MPCC),
classical and data-driven (DDCM), on one load path, and print a summary table.

With no arguments: the paper's example (a bar against a rigid stop). With --config CASE: a
case file, TOML or JSON, of one of these kinds:

  [bar]         the paper's bar, or an N-element bar with stops
  [structure]   a 1-D, 2-D or 3-D truss against rigid obstacles; the top-level key
                kinematics = "finite" for large displacements (a von Mises truss that snaps)
  [mesh]        a 2-D (plane strain) or 3-D continuum, generated (rectangle, box, disc,
                half_disc, quarter_disc, ball, ball_octant) or read from a mesh file (.msh,
                .vtu, .xdmf), pressed against rigid obstacles (plane, circle, sphere,
                cylinder, punch) or against another body ([[mesh.body]] tables, [[contact]]
                slave/master: mortar pairs), with optional Hertz validation and material
                data for DDCM

The case format: the README's "Case files" section, and in full the documentation of
ddcm_casadi.casefiles.config (python -m pydoc ddcm_casadi.casefiles.config); mesh files and
their named boundaries: docs/meshes.md. Examples: examples/cases/ (hertz2d.toml, hertz3d.toml,
truss2d.toml, von_mises.toml, bar_stops.toml, ...).

--out DIR writes results.csv, results.json and the figures that suit the model (VTU series and
pressure profiles for continua), all or none, in a folder locked against a second run.
--set KEY=VALUE overrides one value of the case file and is recorded in results.json.
A load step that fails is retried in sub-steps (halved down to the top-level case key
min_substep, default 0.0625 = 1/16 of a step; --set min_substep=0 turns it off).
The classical problem is solved condensed on its contact pairs where that applies (--set
condense=false: on the full problem; results.json says which path each run took).
Large continua are announced before they are built, and refused when they cannot fit in memory.
Exit status: 0 done, 2 bad input, 3 with --strict a step that did not converge, 130 Ctrl-C.
"""


def _parser() -> argparse.ArgumentParser:
    p = Parser(prog="ddcm-compare", description=HELP,
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


def _bisection(step) -> str:
    """What the step bisection did at a step, for its progress line (``""``: nothing):
    ``  bisected: 5 sub-steps, smallest 1/8`` or, for a step that failed at the smallest,
    ``  bisected down to 1/16``."""
    if not step.bisected:
        return ""
    if step.converged:
        return f"  bisected: {step.substeps} sub-steps, smallest {fraction_text(step.smallest_substep)}"
    return f"  bisected down to {fraction_text(step.smallest_substep)}"


class _Progress:
    """Progress on stderr: ``variant/formulation step k/n elapsed``.

    On a terminal one line per run, updated in place after every step. Otherwise (a log) a line
    after a run's first step, then at most one every :attr:`interval` seconds while it goes on,
    and one at its last step, at every step that did not converge and at every step that was
    bisected (``bisected: 5 sub-steps, smallest 1/8``): a long run shows its pace.
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
        bisected = _bisection(step)
        now = time.perf_counter()
        msg = f"{variant:>9}/{name:<21} step {done:>3}/{self.n}  {now - self.t0:7.2f} s{flag}{bisected}"
        if self.tty:
            end = "\n" if done == self.n or flag or bisected else ""
            print("\r" + msg, end=end, file=sys.stderr, flush=True)
            return
        run = (variant, name)
        if (done == self.n or flag or bisected or self._last is None or self._last[0] != run
                or now - self._last[1] >= self.interval):
            # one write per line: the processes of ``--jobs`` share stderr, and print() writes the
            # line and its end separately
            sys.stderr.write(msg + "\n")
            sys.stderr.flush()
            self._last = (run, now)


@contextlib.contextmanager
def _build_notices(quiet: bool) -> Iterator[None]:
    """While a case is read and built: its physics warnings as one line each on stderr, and
    (unless ``quiet``) what a large build is and how big (``ddcm_casadi.build``'s INFO lines)."""
    log = logging.getLogger("ddcm_casadi.build")
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("ddcm-compare: %(message)s"))
    level, propagate = log.level, log.propagate
    if not quiet:
        log.addHandler(handler)
        log.setLevel(logging.INFO)
        log.propagate = False
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", PhysicsWarning)
            yield
    finally:
        log.removeHandler(handler)
        log.setLevel(level)
        log.propagate = propagate
    for w in caught:
        if issubclass(w.category, PhysicsWarning):
            print(f"ddcm-compare: warning: {w.message}", file=sys.stderr)
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)


def run(argv: list[str] | None = None) -> int:
    """``ddcm-compare ARGS``: run the case (:func:`ddcm_casadi.run.run_case`), print the table and
    the warnings; returns the exit status."""
    args = _parser().parse_args(argv)
    if args.overrides and not args.config:
        raise InputError("--set needs --config CASE (the paper's built-in example has no case file to override)")
    overrides: dict = {}
    with _build_notices(args.quiet):
        if args.config:
            case, overrides = load_case_with_overrides(args.config, args.overrides)
        else:
            case = default_case()
    names = select_formulations(_split(args.formulations, "--formulations"), case.model.contact_law)
    variants = select_variants(_split(args.variants, "--variants"), case)
    for message in case.model.path_warnings():  # refuses a meaningless path before anything is written
        print(f"ddcm-compare: warning: {message}", file=sys.stderr)
    jobs = resolve_jobs(args.jobs, len(names) * len(variants))
    # Runs side by side print their steps as lines: in-place updates of one line would clash.
    progress = _Progress(case.model.n_steps, not args.quiet, in_place=jobs == 1)

    def start() -> None:
        if not args.quiet:
            print(f"ddcm-compare: {case.source}: {case.model.n_steps} steps, "
                  f"{len(names)} formulations x {len(variants)} variants"
                  + (f", {jobs} processes" if jobs > 1 else ""), file=sys.stderr)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsWarning)  # printed above, in one line each
        # The folder is created, checked and locked before any work, and stays locked until the end.
        result = run_case(case, args.out, formulations=names, variants=variants, figures=not args.no_plots,
                          jobs=jobs, overrides=overrides, progress=progress, on_start=start,
                          on_compared=lambda cmp: print(cmp.table()), tool="ddcm-compare")
    if result.out_dir is not None:
        print(f"wrote {written_summary(result.files)} to {result.out_dir}", file=sys.stderr)
    return _final_warnings(result, strict=args.strict)


def written_summary(files: list[str]) -> str:
    """The files of a run for its ``wrote ...`` line: every file by name but the VTU series, which
    are summarised per folder (``vtu/: 8 mesh series and 8 point-cloud series, 80 files (64 .vtu,
    16 .pvd)``) where the folder's first file stands in the list; ``results.json`` lists them all."""
    parts: list[str] = []
    folders: dict[str, list[str]] = {}
    for name in files:
        folder, sep, rest = name.partition("/")
        if not (sep and rest.endswith((".vtu", ".pvd"))):
            parts.append(name)
            continue
        if folder not in folders:
            folders[folder] = []
            parts.append(folder + "/")  # its place in the list; filled in below
        folders[folder].append(rest)
    for folder, names in folders.items():
        series = [n for n in names if n.endswith(".pvd")]
        clouds = sum(n.endswith(f"{POINTS_SUFFIX}.pvd") for n in series)
        parts[parts.index(folder + "/")] = (
            f"{folder}/: {len(series) - clouds} mesh series and {clouds} point-cloud series, {len(names)} files "
            f"({len(names) - len(series)} .vtu, {len(series)} .pvd)")
    return ", ".join(parts)


def _final_warnings(result: CaseRun, *, strict: bool) -> int:
    """Print the warnings of a finished run on stderr; the exit status (:data:`EXIT_NOT_CONVERGED`
    for a non-converged step with ``strict``)."""
    cmp: Comparison = result.comparison
    beyond = [r for r in cmp.results.values() if any(s.extrapolated for s in r.steps)]
    if beyond:  # a flag, not a failure: the fixed points are fixed points, of data that end too soon
        print("WARNING: states beyond the material data (DDCM stresses stop at the data's edge) in "
              + ", ".join(f"{r.variant}/{r.formulation} at {sum(s.extrapolated > 0 for s in r.steps)} steps"
                          for r in beyond), file=sys.stderr)
    for coarse in filter(None, (coarse_data_warning(r, cmp.model.load_parameter_name) for r in cmp.results.values())):
        print(f"WARNING: {coarse}", file=sys.stderr)
    failed = [r for r in cmp.results.values() if not r.converged]
    if failed:
        print("WARNING: non-converged steps in " + ", ".join(f"{r.variant}/{r.formulation}" for r in failed),
              file=sys.stderr)
        if strict:
            return EXIT_NOT_CONVERGED
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_guarded("ddcm-compare", run, argv)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
