"""The MPCC formulation with Coulomb friction against the augmented Lagrangian (Alart--Curnier) on
generated FCLIB local problems: build and solve times, iterations (IPOPT's; Newton's), the
natural-map error, and a warm load step (+1 %) from the solution.

    python benchmarks/mpcc_friction.py [--contacts 1 3 10 30] [--seeds 3] [--mu 0.3] [--out DIR]

Problems: ``W = A A^T / (3 nc) + I / 2`` with ``A`` standard normal (SPD, dense), ``q`` normal with
normal components of mean ``-1/2`` (most contacts pressed). Writes ``DIR/mpcc_friction.json``;
the machines are shared and noisy: compare ratios within one run.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ddcm_casadi import formulations
from ddcm_casadi.io import write_json_atomic
from ddcm_casadi.problems.fclib import LocalProblem, as_complementarity_problem, natural_map_error

NAMES = ("augmented_lagrangian", "mpcc")


def generated(nc: int, seed: int, mu: float) -> LocalProblem:
    rng = np.random.default_rng(100 * nc + seed)
    A = rng.normal(size=(3 * nc, 3 * nc))
    q = rng.normal(size=3 * nc)
    q[0::3] -= 0.5
    return LocalProblem(sp.csr_matrix(A @ A.T / (3 * nc) + 0.5 * np.eye(3 * nc)), q, np.full(nc, mu))


def timed(function, *args):
    t0 = time.perf_counter()
    out = function(*args)
    return out, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--contacts", type=int, nargs="+", default=[1, 3, 10, 30])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--mu", type=float, default=0.3)
    parser.add_argument("--out", type=Path, default=Path("benchmark-results"))
    args = parser.parse_args(argv)
    rows = []
    print("| contacts | seed | formulation | build s | solve s | iterations | converged | error | "
          "warm step s | warm iterations | warm error |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for nc in args.contacts:
        for seed in range(args.seeds):
            local = generated(nc, seed, args.mu)
            fc = as_complementarity_problem(local)
            P = fc.problem.parameters
            step = P.pack(friction=args.mu, traction0=0.0, q=1.01 * P.get(fc.params, "q"))
            stepped = LocalProblem(local.W, 1.01 * local.q, local.mu)
            for name in NAMES:
                built, build_s = timed(formulations.get(name).build, fc.problem)
                sol, solve_s = timed(built.solve, fc.params, *fc.start())
                warm, warm_s = timed(built.solve, step, sol.x, sol.p, sol.state)
                row = dict(contacts=nc, seed=seed, formulation=name, build_seconds=build_s, solve_seconds=solve_s,
                           iterations=sol.iterations, converged=sol.converged, error=fc.error(sol.x, sol.p),
                           message=sol.message, warm_seconds=warm_s, warm_iterations=warm.iterations,
                           warm_converged=warm.converged,
                           warm_error=natural_map_error(stepped, fc.reactions(warm.p)))
                rows.append(row)
                print(f"| {nc} | {seed} | {name} | {build_s:.3f} | {solve_s:.3f} | {sol.iterations} | "
                      f"{'yes' if sol.converged else 'no'} | {row['error']:.1e} | {warm_s:.3f} | {warm.iterations} | "
                      f"{row['warm_error']:.1e} |", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "mpcc_friction.json", dict(mu=args.mu, rows=rows))
    print(f"wrote {args.out / 'mpcc_friction.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
