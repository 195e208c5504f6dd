"""FCLIB frictional contact problems: the reference solver's table (the baseline the frictional
formulations of issue 26 will be compared with).

    python benchmarks/fclib.py --data DIR [--tol 1e-8] [--max-sweeps 3000] [--out DIR]

For every ``*.hdf5`` in ``--data``: read it (:func:`ddcm_casadi.problems.fclib.read_fclib`; a global
problem is reduced to its local one), solve it with the projected Gauss-Seidel reference
(:func:`~ddcm_casadi.problems.fclib.solve_projected_gauss_seidel`) and report contacts, sweeps,
seconds, the natural-map error, and whether it is solved at 1e-4 and at 1e-8 (the FCLIB
benchmarks' levels; ``docs/maths.md``, section 15). Writes ``DIR/fclib.json``; the machines are shared and noisy: compare ratios
within one run.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from ddcm_casadi.io import write_json_atomic
from ddcm_casadi.problems.fclib import read_fclib, solve_projected_gauss_seidel


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True, help="a folder of FCLIB .hdf5 files")
    parser.add_argument("--tol", type=float, default=1e-8)
    parser.add_argument("--max-sweeps", type=int, default=3000)
    parser.add_argument("--out", type=Path, default=Path("benchmark-results"))
    args = parser.parse_args(argv)
    files = sorted(args.data.glob("*.hdf5"))
    if not files:
        parser.error(f"no .hdf5 files in {args.data}")
    rows = []
    print("| problem | kind | contacts | sweeps | seconds | error | solved 1e-4 | solved 1e-8 |")
    print("|---|---|---|---|---|---|---|---|")
    for path in files:
        t0 = time.perf_counter()
        problem = read_fclib(path)
        local = problem.local()
        setup = time.perf_counter() - t0
        s = solve_projected_gauss_seidel(local, tol=args.tol, max_sweeps=args.max_sweeps)
        row = dict(problem=path.name, kind=type(problem).__name__, contacts=local.n_contacts, sweeps=s.iterations,
                   seconds=s.seconds, setup_seconds=setup, error=s.error, solved_1e_4=s.error <= 1e-4,
                   solved_1e_8=s.error <= 1e-8)
        rows.append(row)
        print(f"| {path.name} | {row['kind']} | {row['contacts']} | {s.iterations} | {s.seconds:.2f} | {s.error:.2e} | "
              f"{'yes' if row['solved_1e_4'] else 'no'} | {'yes' if row['solved_1e_8'] else 'no'} |", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "fclib.json", dict(solver="projected_gauss_seidel", tol=args.tol, rows=rows))
    print(f"wrote {args.out / 'fclib.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
