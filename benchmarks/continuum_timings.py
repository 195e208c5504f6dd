"""Timings per formulation on the continuum examples, and each one's solve time over Fischer-Burmeister's.

    python benchmarks/continuum_timings.py [--cases hertz2d hertz3d ...] [--variants classical ddcm]
    python benchmarks/continuum_timings.py --levels 1 2          # the Hertz block at two gradings

``--cases`` (default: the continuum examples that run in seconds to a minute, see :data:`CASES`;
:data:`CLASSICAL_ONLY` in DDCM only when named alone) runs each case file of ``examples/cases`` with every formulation in each variant the case has
(DDCM needs a ``[data]`` section), one run at a time in this process, and prints per run the
unknowns, converged steps, build and solve seconds (wall, as ``ddcm-compare`` reports them), the
process CPU seconds of the whole run (build included), iterations per step and the solve time over
Fischer-Burmeister's in the same case and variant (issue 28's targets: augmented Lagrangian at
most 3, MPCC at most 10). ``--levels`` keeps the former study: the Hertz block of
``examples/cases/hertz2d.toml`` at ``levels`` gradings, 21^3 Hookean data, with the Hertz error of
``p0`` at the last step. One BLAS thread unless the caller sets one (a threaded BLAS stalls on a
shared 2-core machine). The machines are shared and noisy: compare rows of one run, not runs.
"""

from __future__ import annotations

import argparse
import os
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from pathlib import Path  # noqa: E402

from ddcm_casadi import compare, formulations as registry  # noqa: E402
from ddcm_casadi.casefiles.config import load_case_with_overrides  # noqa: E402
from ddcm_casadi.validation.continuum import hertz_block  # noqa: E402

CASES_DIR = Path(__file__).resolve().parent.parent / "examples" / "cases"
#: The continuum examples timed by default: every one with a ``[mesh]`` whose eight runs take at
#: most a few minutes here (mindlin2d's DDCM runs take more than 15 minutes; finite strain: issue 25).
CASES = ("hertz2d", "hertz3d", "nafems1", "block_groups", "hard_device_block", "two_spheres",
         "gmsh_cylinder_on_block", "sphere_shear3d")
#: Cases timed in the classical variant only: sphere_shear3d's frictional projections keep the full
#: saddle-point path (30 135 unknowns), and its DDCM Fischer-Burmeister run alone took over 20 minutes.
CLASSICAL_ONLY = frozenset({"sphere_shear3d"})


def timed_run(model, name: str, variant: str) -> dict:
    """One formulation in one variant on ``model``: its record (wall build and solve seconds as the
    harness measures them, the process CPU seconds of the whole call)."""
    cpu = time.process_time()
    r = compare(model, [name], variants=[variant])[variant, name]
    return dict(variant=variant, formulation=name, converged=sum(s.converged for s in r.steps), steps=len(r.steps),
                build_seconds=r.build_seconds, solve_seconds=r.solve_seconds, cpu_seconds=time.process_time() - cpu,
                iterations_per_step=sum(s.iterations for s in r.steps) / max(1, len(r.steps)))


def with_ratios(rows: list[dict], key: tuple[str, ...]) -> list[dict]:
    """Each row's ``ratio_to_fb``: its solve seconds over Fischer-Burmeister's in the rows of the
    same ``key`` values (case or mesh, and variant)."""
    fb = {tuple(r[k] for k in key): r["solve_seconds"] for r in rows if r["formulation"] == "fischer_burmeister"}
    for r in rows:
        ref = fb.get(tuple(r[k] for k in key))
        r["ratio_to_fb"] = r["solve_seconds"] / ref if ref else float("nan")
    return rows


def case_timings(cases, variants, formulations) -> list[dict]:
    """The records of :func:`timed_run` for every case file named in ``cases`` (of ``examples/cases``)."""
    rows = []
    print(f"{'case':24} {'unknowns':>8} {'variant':9} {'formulation':22} {'conv':>5} {'build s':>8} {'solve s':>8} "
          f"{'cpu s':>7} {'its/step':>8}")
    for case_name in cases:
        case, _ = load_case_with_overrides(CASES_DIR / f"{case_name}.toml", [])
        model = case.model
        for variant in variants:
            if (model.dataset if variant == "ddcm" else model.youngs_modulus) is None or (
                    variant == "ddcm" and case_name in CLASSICAL_ONLY and len(cases) > 1):
                continue
            for name in formulations:
                row = dict(case=case_name, unknowns=model.n_dofs, **timed_run(model, name, variant))
                rows.append(row)
                print(f"{case_name:24} {row['unknowns']:8d} {variant:9} {name:22} {row['converged']:>2}/{row['steps']:<2} "
                      f"{row['build_seconds']:8.3f} {row['solve_seconds']:8.3f} {row['cpu_seconds']:7.2f} "
                      f"{row['iterations_per_step']:8.1f}", flush=True)
    return with_ratios(rows, ("case", "variant"))


def level_timings(levels, variants, formulations) -> list[dict]:
    """The Hertz block at ``levels`` gradings (P2, 21^3 data), with the Hertz error of ``p0``."""
    rows = []
    for lev in levels:
        model = hertz_block(lev, degree=2, data=True)
        for variant in variants:
            for name in formulations:
                cpu = time.process_time()
                r = compare(model, [name], variants=[variant])[variant, name]
                m = model.reference.measure(model, r.steps[-1].p)
                row = dict(case=f"L{lev}", unknowns=model.n_dofs, variant=variant, formulation=name,
                           converged=sum(s.converged for s in r.steps), steps=len(r.steps),
                           build_seconds=r.build_seconds, solve_seconds=r.solve_seconds,
                           cpu_seconds=time.process_time() - cpu,
                           iterations_per_step=sum(s.iterations for s in r.steps) / len(r.steps), error_p0=m["error_p0"])
                rows.append(row)
                print(f"L{lev:>3} {row['unknowns']:8d} {variant:9} {name:22} {row['converged']:>2}/{row['steps']:<2} "
                      f"{row['build_seconds']:8.2f} {row['solve_seconds']:8.2f} {row['iterations_per_step']:8.1f} "
                      f"{row['error_p0']:7.2%}", flush=True)
    return with_ratios(rows, ("case", "variant"))


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="+", default=None, help=f"case files of examples/cases (default: {' '.join(CASES)})")
    ap.add_argument("--levels", type=int, nargs="+", default=None, help="the Hertz block at these gradings instead")
    ap.add_argument("--variants", nargs="+", default=["classical", "ddcm"])
    ap.add_argument("--formulations", nargs="+", default=registry.available())
    args = ap.parse_args(argv)
    if args.levels:
        rows = level_timings(args.levels, args.variants, args.formulations)
    else:
        rows = case_timings(args.cases or CASES, args.variants, args.formulations)
    print(f"\n{'case':24} {'variant':9} {'formulation':22} {'solve / FB solve':>16}")
    for row in rows:
        print(f"{row['case']:24} {row['variant']:9} {row['formulation']:22} {row['ratio_to_fb']:16.1f}")
    return rows


if __name__ == "__main__":
    main()
