"""``ddcm-sweep SPEC.toml --out DIR``: a parameter sweep or a Monte Carlo study on Dask.

The spec names a base case, a grid of dotted keys to lists of values, optional seeds of generated
data, the variants and formulations, and the figures (format: ddcm_casadi/sweep/spec.py). Each
case runs as one task on a dask.distributed LocalCluster of --workers processes (default: the
cores this process may use), or on an existing cluster (--scheduler ADDRESS). Finished cases
are written to DIR/cases/<id>/ and skipped by a rerun of the same spec (--force reruns them,
--retry-failed reruns failed ones); then DIR/sweep.csv (one row per case x variant x formulation),
DIR/sweep.json (spec, versions, fitted rates) and the figures are written.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ddcm_casadi.commands.base import EXIT_NOT_CONVERGED, Parser, run_guarded
from ddcm_casadi.errors import InputError
from ddcm_casadi.version import __version__
from ddcm_casadi.sweep.runner import run_sweep
from ddcm_casadi.sweep.spec import MAX_CASES, load_spec


def _parser() -> argparse.ArgumentParser:
    p = Parser(prog="ddcm-sweep", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("spec", metavar="SPEC", help="sweep spec, .toml or .json")
    p.add_argument("--out", metavar="DIR", required=True, help="output folder (cases/, sweep.csv, sweep.json, figures)")
    p.add_argument("--workers", metavar="N", type=int, help="worker processes of the LocalCluster (default: cores)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run on an existing Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--max-cases", metavar="N", type=int,
                   help=f"run a spec of more than {MAX_CASES} cases (up to N)")
    p.add_argument("--force", action="store_true", help="rerun every case, finished or not")
    p.add_argument("--retry-failed", action="store_true", help="rerun the cases that failed")
    p.add_argument("--no-plots", action="store_true", help="do not draw the figures")
    p.add_argument("--strict", action="store_true",
                   help=f"exit with status {EXIT_NOT_CONVERGED} if a case failed or was lost, a step did not "
                        "converge, or states went beyond the material data (DATA RANGE EXCEEDED)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    return p


class _Progress:
    """A bar over cases on a terminal; one line per finished case otherwise."""

    def __init__(self, enabled: bool, columns: list[str]) -> None:
        self.enabled, self.columns = enabled, columns
        self.tty = sys.stderr.isatty()
        self.t0 = time.perf_counter()
        self.failed = 0

    def __call__(self, done: int, total: int, case, record, error) -> None:
        if not self.enabled:
            return
        status = "lost" if record is None else record["status"]
        self.failed += status != "ok"
        elapsed = time.perf_counter() - self.t0
        if self.tty:
            width = 30
            bar = "#" * (width * done // total) + "." * (width - width * done // total)
            tail = f"  {self.failed} failed" if self.failed else ""
            end = "\n" if done == total else ""
            print(f"\r[{bar}] {done}/{total} cases  {elapsed:7.1f} s{tail}", end=end, file=sys.stderr, flush=True)
            return
        params = " ".join(f"{c}={case.params.get(c)}" for c in self.columns)
        seconds = "" if record is None else f" {record['seconds']:.2f} s"
        why = "" if status == "ok" else f": {record['error'] if record else error}"
        print(f"ddcm-sweep: {done}/{total} {case.id} {status}{seconds}  {params}{why}", file=sys.stderr, flush=True)


def run(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be a positive integer, got {args.workers}")
    if args.workers is not None and args.scheduler:
        raise InputError("--workers sizes the local cluster; it cannot be combined with --scheduler")

    if not args.out.strip():
        raise InputError(f"--out must be a folder, got {args.out!r}")
    if args.max_cases is not None and args.max_cases < 1:
        raise InputError(f"--max-cases must be a positive integer, got {args.max_cases}")
    spec = load_spec(args.spec, max_cases=args.max_cases)
    if not args.quiet:
        print(f"ddcm-sweep: {spec.path}: {len(spec.cases)} cases ({', '.join(spec.columns)})", file=sys.stderr)
    report = run_sweep(spec, args.out, workers=args.workers, scheduler=args.scheduler, force=args.force,
                       retry_failed=args.retry_failed, figures=not args.no_plots,
                       progress=_Progress(not args.quiet, spec.columns))
    print(f"ddcm-sweep: {report.total} cases: ran {report.ran}, skipped {report.skipped} (finished before), "
          f"failed {len(report.failed)}, lost {len(report.lost)}"
          + (f"; {report.workers} workers" if report.workers else "") + f"; {report.seconds:.1f} s")
    for fit in report.fits:
        print(f"fitted slope {fit['slope']:.3f} of {fit['y']} against {fit['x']} ({fit['series']}, "
              f"{fit['points']} points)")
    for note in report.skipped_figures:
        print(f"ddcm-sweep: figure not drawn: {note}", file=sys.stderr)
    written = ["sweep.csv", "sweep.json", *report.figures]
    print(f"wrote {', '.join(written)} and cases/ to {report.out}", file=sys.stderr)
    if report.lost:
        print(f"WARNING: {len(report.lost)} cases were lost by the cluster; rerun the same command to run them",
              file=sys.stderr)
    if report.failed:
        print(f"WARNING: {len(report.failed)} cases failed (see the message column of sweep.csv)", file=sys.stderr)
    flags = case_flags(report.out)
    if flags["not_converged"]:
        print(f"WARNING: {len(flags['not_converged'])} cases have non-converged steps (converged_steps < steps "
              f"in sweep.csv): {_listing(flags['not_converged'])}", file=sys.stderr)
    if flags["extrapolated"]:
        print(f"WARNING: DATA RANGE EXCEEDED in {len(flags['extrapolated'])} cases: states beyond the material data, "
              f"DDCM stresses stop at the data's edge (extrapolated_steps in sweep.csv): "
              f"{_listing(flags['extrapolated'])}", file=sys.stderr)
    if args.strict and (report.failed or report.lost or flags["not_converged"] or flags["extrapolated"]):
        return EXIT_NOT_CONVERGED
    return 0


def _listing(cases: list[str], most: int = 5) -> str:
    return ", ".join(cases[:most]) + (f" and {len(cases) - most} more" if len(cases) > most else "")


def case_flags(out: Path) -> dict[str, list[str]]:
    """The cases of ``out/sweep.csv`` (finished, ``status = ok``) with non-converged steps
    (``not_converged``) and with states beyond the material data (``extrapolated``), by id."""
    import csv

    flags: dict[str, list[str]] = dict(not_converged=[], extrapolated=[])
    with open(Path(out) / "sweep.csv", newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            if row["status"] != "ok":
                continue
            for flag, raised in (("not_converged", row["steps"] != row["converged_steps"]),
                                 ("extrapolated", row.get("extrapolated_steps") not in (None, "", "0"))):
                if raised and flags[flag][-1:] != [row["case"]]:  # a case's rows are consecutive
                    flags[flag].append(row["case"])
    return flags


def main(argv: list[str] | None = None) -> int:
    return run_guarded("ddcm-sweep", run, argv,
                       interrupted="interrupted; finished cases are kept, rerun the same command to resume")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
