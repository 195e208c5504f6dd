"""Timings per formulation on the Hertz example (plane strain, P2) at two mesh sizes.

    python benchmarks/continuum_timings.py [--levels 1 2] [--variants classical ddcm]

The example case ``examples/cases/hertz2d.toml`` with ``levels`` gradings of the contact zone
(level 2 is the example's own mesh), every formulation, both variants, its 5 load steps and its
21^3 Hookean data. Prints one row per mesh x variant x formulation: unknowns, converged steps,
build and solve seconds, iterations per step, and the Hertz error of ``p0`` at the last step; then
each run's solve time over Fischer-Burmeister's in the same mesh and variant (the targets of issue
28: augmented Lagrangian at most 3, MPCC at most 10). The machines are shared and noisy: compare
rows of one run, not runs.
"""

from __future__ import annotations

import argparse
import time

from ddcm_casadi import formulations as registry
from ddcm_casadi.validation.continuum import hertz_block
from ddcm_casadi.drivers.harness import compare


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--variants", nargs="+", default=["classical", "ddcm"])
    ap.add_argument("--formulations", nargs="+", default=registry.available())
    args = ap.parse_args(argv)
    rows = []
    print(f"{'mesh':>4} {'unknowns':>8} {'stress':>7} {'variant':9} {'formulation':22} {'conv':>5} "
          f"{'build s':>8} {'solve s':>8} {'its/step':>8} {'p0 err':>7}")
    for lev in args.levels:
        model = hertz_block(lev, degree=2, data=True)
        for variant in args.variants:
            for name in args.formulations:
                t0 = time.perf_counter()
                r = compare(model, [name], variants=[variant])[variant, name]
                total = time.perf_counter() - t0
                m = model.reference.measure(model, r.steps[-1].p)
                row = dict(levels=lev, unknowns=model.n_dofs, stress_unknowns=model.n_points * model.strain_components,
                           variant=variant, formulation=name, converged=sum(s.converged for s in r.steps),
                           steps=len(r.steps), build_seconds=r.build_seconds, solve_seconds=r.solve_seconds,
                           total_seconds=total, iterations_per_step=sum(s.iterations for s in r.steps) / len(r.steps),
                           error_p0=m["error_p0"])
                rows.append(row)
                print(f"L{lev:>3} {row['unknowns']:8d} {row['stress_unknowns']:7d} {variant:9} {name:22} "
                      f"{row['converged']:>2}/{row['steps']:<2} {row['build_seconds']:8.1f} {row['solve_seconds']:8.1f} "
                      f"{row['iterations_per_step']:8.1f} {row['error_p0']:7.2%}", flush=True)
    fb = {(r["levels"], r["variant"]): r["solve_seconds"] for r in rows if r["formulation"] == "fischer_burmeister"}
    if fb:
        print(f"\n{'mesh':>4} {'variant':9} {'formulation':22} {'solve / FB solve':>16}")
    for row in rows:
        ref = fb.get((row["levels"], row["variant"]))
        if ref:
            row["ratio_to_fb"] = row["solve_seconds"] / ref
            print(f"L{row['levels']:>3} {row['variant']:9} {row['formulation']:22} {row['ratio_to_fb']:16.1f}")
    return rows


if __name__ == "__main__":
    main()
