"""``ddcm-validate``: run the verification ladder (:mod:`ddcm_casadi.validation.ladder`).

Writes ``DIR/validation.json`` (a list of checks with ``name``, ``quantity``, ``value``,
``reference``, ``tolerance``, ``passed`` and ``note``) and ``DIR/validation.md``. Exit status 0 when
every check passed, 1 when any failed, 2 for bad input.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings

from ddcm_casadi.commands.base import EXIT_INPUT, Parser
from ddcm_casadi.errors import DDCMError, PhysicsWarning
from ddcm_casadi.io import prepare_output_dir, write_bytes_atomic, write_json_atomic
from ddcm_casadi.validation.ladder import as_records, markdown, run_ladder

EXIT_FAILED = 1


def main(argv: list[str] | None = None) -> int:
    """``ddcm-validate ARGS``: run the ladder, print its report; returns the exit status."""
    p = Parser(prog="ddcm-validate", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", metavar="DIR", help="write validation.json and validation.md here")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    args = p.parse_args(argv)
    try:
        out = prepare_output_dir(args.out) if args.out is not None else None  # --out "" is an error
        t0 = time.perf_counter()
        say = None if args.quiet else (lambda msg: print(f"ddcm-validate: {msg}", file=sys.stderr, flush=True))
        with warnings.catch_warnings():
            # the ladder's verification models impose large strains on purpose (toy geometries)
            warnings.simplefilter("ignore", PhysicsWarning)
            checks = run_ladder(progress=say)
        report = markdown(checks)
        if out is not None:
            write_json_atomic(out / "validation.json", as_records(checks))
            write_bytes_atomic(out / "validation.md", report.encode())
    except DDCMError as exc:
        print(f"ddcm-validate: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return EXIT_INPUT
    print(report)
    failed = [c for c in checks if not c.passed]
    if not args.quiet:
        print(f"ddcm-validate: {len(checks) - len(failed)}/{len(checks)} checks passed in "
              f"{time.perf_counter() - t0:.0f} s" + (f"; written to {out}" if out else ""), file=sys.stderr)
    return EXIT_FAILED if failed else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
