"""FCLIB frictional contact problems: every frictional method's table and Dolan-More performance
profiles (issue 26; ``docs/maths.md``, section 15).

    python benchmarks/fclib.py --data DIR [--out DIR] [--max-sweeps 3000] [--methods a,b]

For every ``*.hdf5`` in ``--data`` (read by :func:`ddcm_casadi.problems.fclib.read_fclib`) and every
method of :func:`~ddcm_casadi.drivers.fclib.solve_fclib` (the default hybrid, projected
Gauss-Seidel, and every registered formulation that supports Coulomb friction, from the cold
start): seconds, Newton iterations, sweeps, the natural-map error, and whether it is solved at
1e-4 and at 1e-8 (the FCLIB benchmarks' levels). The methods whose work depends on the target
(``default``, ``pgs``) run once per level; a formulation's Newton solve does not, and its one run
counts for both. Writes ``DIR/fclib.json`` (the table), ``DIR/fclib.md`` and
``DIR/fclib_profiles.png``: per level, the fraction of problems each method solves within a factor
``tau`` of the fastest method's time on that problem (Dolan and More, 2002). The machines are shared
and noisy: compare ratios within one run.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from ddcm_casadi.io import prepare_output_dir, write_bytes_atomic, write_json_atomic
from ddcm_casadi.drivers.fclib import frictional_methods, solve_fclib
from ddcm_casadi.problems.fclib import read_fclib

#: The FCLIB benchmarks' levels of the natural-map error.
LEVELS = (1e-8, 1e-4)
#: Methods whose work depends on the target level (the others run once).
LEVEL_DEPENDENT = ("default", "pgs")


def profiles(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dolan-More profiles of ``times`` (problems x methods, ``inf`` where unsolved):
    ``(tau, rho)`` with ``rho[k, s]`` the fraction of problems method ``s`` solves within
    ``tau[k]`` times the best time on that problem (problems no method solves count as unsolved)."""
    best = np.min(times, axis=1, keepdims=True)
    ratios = np.where(np.isfinite(times), times / np.where(np.isfinite(best), best, 1.0), np.inf)
    finite = ratios[np.isfinite(ratios)]
    top = max(float(finite.max()) if finite.size else 1.0, 1.0) * 1.05
    tau = np.concatenate([[1.0], np.geomspace(1.0, top, 400)[1:]])
    rho = np.array([[float(np.mean(ratios[:, s] <= t)) for s in range(times.shape[1])] for t in tau])
    return tau, rho


def figure(rows: list[dict], methods: list[str]):
    """The profiles at :data:`LEVELS`, one panel per level, one curve per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    problems = sorted({r["problem"] for r in rows})
    fig, axes = plt.subplots(1, len(LEVELS), figsize=(11, 4.2), sharey=True)
    summary = {}
    for ax, level in zip(axes, LEVELS):
        key = f"{level:g}"
        times = np.full((len(problems), len(methods)), np.inf)
        for r in rows:
            if r[f"solved_{key}"]:
                times[problems.index(r["problem"]), methods.index(r["method"])] = r[f"seconds_{key}"]
        tau, rho = profiles(times)
        summary[key] = {m: dict(solved=float(rho[-1, s]), fastest=float(rho[0, s])) for s, m in enumerate(methods)}
        for s, m in enumerate(methods):
            ax.step(tau, rho[:, s], where="post", label=m, lw=2.2 if m == "default" else 1.4)
        ax.set_xscale("log", base=2)
        ax.set_xlabel(r"$\tau$ (time / best time on the problem)")
        ax.set_title(f"natural-map error <= {key} ({len(problems)} problems)")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel(r"fraction of problems solved within $\tau$")
    axes[-1].legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    return fig, summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True, help="a folder of FCLIB .hdf5 files")
    parser.add_argument("--max-sweeps", type=int, default=3000, help="projected Gauss-Seidel's sweeps (pgs)")
    parser.add_argument("--methods", default=None, help="a comma-separated subset (default: all)")
    parser.add_argument("--out", type=Path, default=Path("benchmark-results"))
    args = parser.parse_args(argv)
    files = sorted(args.data.glob("*.hdf5"))
    if not files:
        parser.error(f"no .hdf5 files in {args.data}")
    methods = list(frictional_methods())
    if args.methods:
        unknown = sorted(set(args.methods.split(",")) - set(methods))
        if unknown:
            parser.error(f"unknown methods {unknown}; known: {', '.join(methods)}")
        methods = [m for m in methods if m in args.methods.split(",")]
    out = prepare_output_dir(args.out)
    rows = []
    header = ("| problem | contacts | method | seconds (1e-8) | iterations | sweeps | error | solved 1e-4 | "
              "seconds (1e-4) | solved 1e-8 |")
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    print("\n".join(lines), flush=True)
    for path in files:
        t0 = time.perf_counter()
        problem = read_fclib(path)
        local = problem.local()  # the reduction, as each solve does it before its clock starts
        setup = time.perf_counter() - t0
        for method in methods:
            runs = {}
            for level in LEVELS:
                if level != LEVELS[0] and method not in LEVEL_DEPENDENT:
                    runs[level] = runs[LEVELS[0]]
                    continue
                kw = dict(max_sweeps=args.max_sweeps) if method == "pgs" else {}
                runs[level] = solve_fclib(problem, method, tol=level, **kw)
            s = runs[LEVELS[0]]
            row = dict(problem=path.name, kind=type(problem).__name__, contacts=local.n_contacts, method=method,
                       setup_seconds=setup, seconds_1e_8=s.seconds, iterations=s.iterations, sweeps=s.sweeps,
                       error=s.error, message=s.message, stages=[st["stage"] for st in s.log])
            for level in LEVELS:
                key = f"{level:g}"
                row[f"seconds_{key}"] = runs[level].seconds
                row[f"error_{key}"] = runs[level].error
                row[f"solved_{key}"] = bool(runs[level].error <= level)
            rows.append(row)
            line = (f"| {path.stem} | {row['contacts']} | {method} | {s.seconds:.3f} | {s.iterations} | {s.sweeps} | "
                    f"{s.error:.1e} | {'yes' if row['solved_0.0001'] else 'no'} | {row['seconds_0.0001']:.3f} | "
                    f"{'yes' if row['solved_1e-08'] else 'no'} |")
            lines.append(line)
            print(line, flush=True)
    fig, summary = figure(rows, methods)
    from ddcm_casadi.outputs.plots import save_figure

    save_figure(fig, out / "fclib_profiles.png")
    lines += ["", "Dolan-More summary: fraction of problems solved (rho at the largest tau) and fastest on (rho(1)); iterations: Newton's (pgs: sweeps)", "",
              "| method | " + " | ".join(f"solved {k} | fastest {k}" for k in summary) + " |",
              "|---|" + "---|---|" * len(summary)]
    for m in methods:
        lines.append(f"| {m} | " + " | ".join(f"{summary[k][m]['solved']:.2f} | {summary[k][m]['fastest']:.2f}"
                                               for k in summary) + " |")
    print("\n".join(lines[-len(methods) - 4:]))
    write_json_atomic(out / "fclib.json", dict(levels=list(LEVELS), methods=methods, rows=rows, profiles=summary))
    write_bytes_atomic(out / "fclib.md", ("\n".join(lines) + "\n").encode())
    print(f"wrote {out / 'fclib.json'}, {out / 'fclib.md'}, {out / 'fclib_profiles.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
