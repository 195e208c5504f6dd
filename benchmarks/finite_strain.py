"""Finite-strain DDCM against its floor, and Newton iterations per load step on the examples.

    python benchmarks/finite_strain.py [--quick] [--out DIR]

1. **A finite-strain DDCM iteration against its floor.** A plane-strain Neo-Hookean block
   (P1, ``n x n`` elements, bonded at its base) pressed by a rigid plane, DDCM with
   Fischer-Burmeister on ``(E, S)`` data of the same law (a graded 41^3 grid). One DDCM iteration is one projection (Newton
   on the saddle point of the nonlinear projection, assembled element by element) and one data
   search; its cost is ``(projection_seconds + search_seconds) / projections`` of the run. The
   floor is one factorisation and one solve of the same Newton matrix at the last state
   (:func:`ddcm_casadi.linalg.factorize`), plus one KD-tree search of every material point,
   measured in this process. ``--quick``: 4e3 and 9e3 saddle-point unknowns; full: also 2e4
   and 1e5 (the target of issue 25: at most 3x the floor). Newton iterations per projection
   count its chord steps (from 2e4 unknowns Newton reuses its last factorisation,
   :data:`ddcm_casadi.loops.newton.CHORD_MIN_SIZE`).
2. **Newton iterations per load step** of every formulation and variant on the finite-strain
   examples (``examples/cases/seal2d_finite.toml``, ``examples/cases/indentation3d_finite.toml``)
   at their default step sizes, with the sub-steps bisection took.

Writes ``DIR/finite_strain.json`` and prints a table. The machines are shared and noisy: compare
ratios within one run.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from ddcm_casadi.casefiles.config import case_from_dict, load_case_with_overrides
from ddcm_casadi.drivers.harness import VARIANTS, compare
from ddcm_casadi.formulations.registry import available as available_formulations
from ddcm_casadi.formulations.registry import get as get_formulation
from ddcm_casadi.io import write_json_atomic
from ddcm_casadi.linalg import factorize
from ddcm_casadi.problems.build import build_problems
from ddcm_casadi.run import compare_case

HERE = Path(__file__).resolve().parent
EXAMPLES = HERE.parent / "examples" / "cases"


def indented_block(divisions: int) -> dict:
    """The case document of the benchmark's block (unit square, E = 1, nu = 0.3, half model): bonded
    at its base, pressed by a rigid plane by 1 % a step, so that it barrels (a state that varies
    from point to point)."""
    return {"kinematics": "finite",
            "mesh": {"shape": "rectangle", "size": [1.0, 1.0], "divisions": [divisions, divisions]},
            "material": {"youngs_modulus": 1.0, "poisson_ratio": 0.3, "law": "neo_hookean"},
            "supports": [{"boundary": "ymin", "fix": "xy"}, {"boundary": "xmin", "fix": "x"}],
            "contact": [{"boundary": "ymax", "obstacle": "plane", "point": [0.0, 1.0], "normal": [0.0, -1.0],
                         "direction": [0.0, -1.0], "travel": [0.0, 0.01, 0.02]}],
            "data": {"law": "neo_hookean", "grid": {"strain_min": -0.3, "strain_max": 0.3, "points": 41,
                                                    "grading": 2}, "c": "estimated"}}


def median(fn, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def ddcm_against_floor(divisions: int) -> dict:
    """One record: the DDCM iteration's cost, its floor and their ratio (see the module)."""
    case = case_from_dict(indented_block(divisions))
    model = case.model
    t0 = time.perf_counter()
    result = compare(model, ["fischer_burmeister"], variants=["ddcm"])["ddcm", "fischer_burmeister"]
    wall = time.perf_counter() - t0
    steps = result.steps
    projections = sum(s.projections for s in steps)
    per_iteration = sum(s.projection_seconds + s.search_seconds for s in steps) / max(projections, 1)
    newton = sum(s.iterations for s in steps) / max(projections, 1)
    # the floor: the same Newton matrix at the last state, factorised and solved once, plus a search
    problems = build_problems(model)
    built = get_formulation("fischer_burmeister").build(problems.projection)
    last = steps[-1]
    x, p = problems.scaled_start("mpcc", last.u, last.p, last.stress)
    params = problems.projection_params(last.step, last.strain_star, last.stress_star)
    z, P = built.newton_point(params, x, p)
    system = built.newton_system()
    r, J = system.functions.rj(z, P)
    A = system.functions.jacobian(J)
    factor_seconds = median(lambda: factorize(A, iterated=True))
    F = factorize(A, iterated=True)
    solve_seconds = median(lambda: F.solve(r))
    k = model.strain_components
    strain, stress = np.reshape(last.strain, (-1, k)), np.reshape(last.stress, (-1, k))
    search_seconds = median(lambda: model.dataset.nearest(strain, stress))
    assemble_seconds = median(lambda: system.functions.rj(z, P))
    floor = factor_seconds + solve_seconds + search_seconds
    return dict(name="finite-strain DDCM iteration, 2-D Neo-Hookean block", divisions=divisions,
                dofs=model.n_dofs, points=model.n_points, unknowns=int(A.shape[0]), matrix_nonzeros=int(A.nnz),
                data_points=len(model.dataset), converged=f"{sum(s.converged for s in steps)}/{len(steps)}",
                projections=projections, newton_per_projection=newton, seconds=per_iteration,
                floor_seconds=floor, ratio=per_iteration / floor, factor_seconds=factor_seconds,
                solve_seconds=solve_seconds, search_seconds=search_seconds, assemble_seconds=assemble_seconds,
                run_seconds=wall)


def newton_per_step(path: Path) -> list[dict]:
    """Newton iterations per load step of every run of a case file (sub-steps counted)."""
    case, _ = load_case_with_overrides(path, [])
    cmp = compare_case(case, available_formulations(), VARIANTS)  # with the case's formulation options
    rows = []
    for (variant, name), r in cmp.results.items():
        steps = r.steps
        rows.append(dict(name=f"Newton iterations per step, {path.stem}", variant=variant, formulation=name,
                         converged=f"{sum(s.converged for s in steps)}/{len(steps)}",
                         iterations_per_step=float(np.mean([s.iterations for s in steps])),
                         max_iterations_per_step=int(max(s.iterations for s in steps)),
                         outer_per_step=float(np.mean([s.outer_iterations for s in steps])),
                         substeps=int(sum(getattr(s, "substeps", 1) for s in steps)), seconds=r.solve_seconds))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="4e3 and 9e3 unknowns and the 2-D example only")
    ap.add_argument("--out", type=Path, default=None, help="folder for finite_strain.json")
    args = ap.parse_args(argv)
    records = []
    for divisions in ((20, 30) if args.quick else (20, 30, 45, 100)):
        rec = ddcm_against_floor(divisions)
        records.append(rec)
        print(f"{rec['unknowns']:>8} unknowns: DDCM iteration {rec['seconds']:.3f} s, floor {rec['floor_seconds']:.3f} s "
              f"(factor {rec['factor_seconds']:.3f}, solve {rec['solve_seconds']:.3f}, search "
              f"{rec['search_seconds']:.3f}), ratio {rec['ratio']:.2f}, Newton {rec['newton_per_projection']:.2f} "
              f"per projection, assembly {rec['assemble_seconds']:.3f} s", flush=True)
    cases = ["seal2d_finite.toml"] + ([] if args.quick else ["indentation3d_finite.toml"])
    for name in cases:
        for rec in newton_per_step(EXAMPLES / name):
            records.append(rec)
            print(f"{name:28} {rec['variant']:9} {rec['formulation']:22} {rec['converged']:>6} "
                  f"{rec['iterations_per_step']:6.1f} its/step (max {rec['max_iterations_per_step']}), "
                  f"{rec['substeps']} sub-steps, {rec['seconds']:.1f} s", flush=True)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        write_json_atomic(args.out / "finite_strain.json", records)
    else:
        json.dump(records, sys.stdout, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
