"""Robustness sweep: hard load paths, extreme units and awkward data, every formulation and variant.

    python benchmarks/robustness_sweep.py [--steps 300] [--out DIR] [--quick]

Per case x variant x formulation it records the share of converged steps, iteration statistics,
the worst error against the closed form (classical) and whether every DDCM step is a valid fixed
point (ddcm_casadi.validation.fixed_points), and wall time. Writes DIR/sweep.json and DIR/sweep.md (atomically).
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from ddcm_casadi import MaterialDataset, bar_model, compare
from ddcm_casadi.io import prepare_output_dir, write_bytes_atomic, write_json_atomic
from ddcm_casadi.validation.fixed_points import check_fixed_points


def cases(steps: int, rng: np.random.Generator) -> dict:
    s = np.linspace(-0.05, 0.01, 500)

    def bar(L=1.0, E=200e9, h=None, data=None):
        h = L + 0.01 * L * np.linspace(1, -1, steps) if h is None else h
        data = data or MaterialDataset.hookean(E, -0.05, 0.01, 500, c=1.5 * E)
        return bar_model(length=L, area=1.0, youngs_modulus=E, positions=h, dataset=data)

    cycle = np.array([1.0, 0.995, 1.0, 1.0, 1.005, 1.0])
    return {
        "paper_units": lambda: bar(),
        "E=1e6 Pa, L=1e-3 m": lambda: bar(L=1e-3, E=1e6),
        "E=1e12 Pa, L=1e2 m": lambda: bar(L=1e2, E=1e12),
        "E=1e6 Pa, L=1e2 m": lambda: bar(L=1e2, E=1e6),
        "E=1e12 Pa, L=1e-3 m": lambda: bar(L=1e-3, E=1e12),
        "start in contact, unload": lambda: bar(h=1.0 + 0.01 * np.linspace(-1, 1, steps)),
        "random jumps": lambda: bar(h=1.0 + 0.01 * rng.uniform(-1, 1, steps)),
        "repeatedly at h = l0": lambda: bar(h=np.resize(cycle, steps)),
        "sparse data (20)": lambda: bar(data=MaterialDataset.hookean(200e9, -0.05, 0.01, 20, c=300e9)),
        "noisy data": lambda: bar(data=MaterialDataset(s, 200e9 * s + rng.normal(0, 2e8, s.size), 300e9)),
        "non-linear data": lambda: bar(data=MaterialDataset(s, 4e9 * np.tanh(s / 0.02), 300e9)),
        "dense data (1e5)": lambda: bar(data=MaterialDataset.hookean(200e9, -0.05, 0.01, 100_000, c=300e9)),
    }


def run(steps: int, quick: bool) -> list[dict]:
    rng = np.random.default_rng(7)
    records = []
    for name, make in cases(steps, rng).items():
        if quick and "dense" in name:
            continue
        model = make()
        t0 = time.perf_counter()
        cmp = compare(model)
        seconds = time.perf_counter() - t0
        forms = {f.name: f for f in cmp.formulations}
        for (variant, form), r in cmp.results.items():
            its = r.array("iterations")
            rec = dict(case=name, variant=variant, formulation=form, steps=len(r.steps),
                       converged=float(np.mean(r.array("converged"))), iterations_mean=float(its.mean()),
                       iterations_median=float(np.median(its)), iterations_max=int(its.max()),
                       seconds=r.build_seconds + r.solve_seconds, case_seconds=seconds)
            if variant == "classical":
                err = cmp.errors(variant, form)
                rec["max_error"] = float(max(err["u"].max(), err["p"].max()))
            else:
                rep = check_fixed_points(cmp.problems, r)
                # A penalised projection tilts the contact branch by about c / (gamma l0).
                gamma = forms[form].penalty_stiffness(cmp.problems.classical)
                tol = 1e-8 if gamma is None else model.dataset.c / (gamma * model.length_scale)
                valid = (np.maximum(rep.projection_error_u, rep.projection_error_p) <= tol) & rep.nearest
                rec["valid_fixed_points"] = float(np.mean(valid & r.array("converged").astype(bool)))
                rec["outer_iterations_mean"] = float(np.mean(r.array("outer_iterations")))
            records.append(rec)
        print(f"{name:<26} {seconds:7.1f} s", file=sys.stderr, flush=True)
    return records


def markdown(records: list[dict]) -> str:
    lines = ["| case | variant | formulation | converged | valid / max err | its mean (max) | s |",
             "|---|---|---|---|---|---|---|"]
    for r in records:
        q = f"{r['valid_fixed_points']:.0%} valid" if r["variant"] == "ddcm" else f"{r['max_error']:.1e}"
        lines.append(f"| {r['case']} | {r['variant']} | {r['formulation']} | {r['converged']:.0%} | {q} | "
                     f"{r['iterations_mean']:.1f} ({r['iterations_max']}) | {r['seconds']:.2f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--out", default="sweep-out")
    ap.add_argument("--quick", action="store_true", help="skip the 1e5-point data set")
    args = ap.parse_args(argv)
    out = prepare_output_dir(args.out)
    records = run(args.steps, args.quick)
    write_json_atomic(out / "sweep.json", records)
    write_bytes_atomic(out / "sweep.md", markdown(records).encode())
    print(markdown(records))
    return 0


if __name__ == "__main__":
    sys.exit(main())
