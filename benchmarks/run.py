"""Benchmark suite: DDCM iterations against their cost floor, data search, FB against QP solvers,
and where the paper's default run spends its time.

    python benchmarks/run.py [--quick] --out DIR

Writes ``DIR/benchmarks.json`` (a list of records with ``name``, ``unknowns``, ``data_points``,
``seconds``, ``floor_seconds``, ``ratio`` and extra fields) and ``DIR/benchmarks.md``. Every
timing is the median of repeated runs, and every comparison is a ratio measured in this process
run (the machines are shared and noisy). ``--quick`` keeps to about 5 minutes on 2 cores.

The floor of one DDCM iteration is one sparse LU factorisation and solve (scipy) of the same
saddle-point system the projection solves, plus one KD-tree query of all material points against
the data set.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import tracemalloc

import numpy as np
import scipy.sparse.linalg as spla

import formulations
from ddcm_casadi import MaterialDataset, compare, paper_bar
from ddcm_casadi.io import prepare_output_dir, write_bytes_atomic, write_json_atomic
from ddcm_casadi.problem import build_problems
from ddcm_casadi.reference import ContactQP
from ddcm_casadi.solvers.path import DDCMSolver
from ddcm_casadi.truss import bar_chain, warren_truss


def median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def stopped_bar(n_elements: int, n_data: int, *, steps=(0.985,)):
    stops = {max(1, int(n_elements * j / 10)): 0.002 * j for j in range(1, 10)}
    data = MaterialDataset.hookean(200e9, -0.05, 0.01, n_data, c=300e9)
    return bar_chain(length=1.0, elements=n_elements, youngs_modulus=200e9, tip_positions=list(steps),
                     stops=stops, dataset=data, name=f"bar, {n_elements} elements")


def warren(panels: int, n_data: int, *, contacts: int = 5, steps=(1.0,)):
    """2-D Warren truss with ``panels`` panels on a plane under ``contacts`` bottom nodes."""
    nodes = np.unique(np.linspace(1, panels - 1, contacts).astype(int))
    data = MaterialDataset.hookean(200e9, -0.01, 0.01, n_data, c=200e9)
    return warren_truss(panels=panels, gap=0.002 * panels / 4, contact_nodes=nodes, load_factors=steps,
                        dataset=data)


def ddcm_iteration(model, repeats: int, formulation: str = "fischer_burmeister") -> dict:
    """Seconds per DDCM iteration (projection + data search) against its floor."""
    problems = build_problems(model)
    built = formulations.get(formulation).build(problems.projection)
    solver = DDCMSolver(problems, built)
    runs = []
    for _ in range(repeats):
        path = solver.solve(formulation_name=formulation)
        step = path.steps[-1]
        runs.append((path.solve_seconds / sum(s.outer_iterations for s in path.steps), path))
    seconds, path = sorted(runs, key=lambda r: r[0])[len(runs) // 2]
    step = path.steps[-1]
    # The same saddle-point system at the converged state, factorised and solved by scipy.
    system = built.system
    x, p = problems.scaled_start("mpcc", step.u, step.p, step.stress)
    z = system.start(x, p, None)
    P = np.concatenate([problems.projection_params(step.step, step.strain_star, step.stress_star),
                        [0.0], np.zeros(problems.projection.n_pairs)])
    r, J = system.rj(z, P)
    A = system.jacobian(J)
    rhs = np.asarray(r, float).ravel() + 1.0
    t_lu = median_time(lambda: spla.splu(A).solve(rhs), max(3, repeats))
    data = model.dataset
    t_kd = median_time(lambda: data.nearest(step.strain, step.stress), max(3, repeats))
    floor = t_lu + t_kd
    return dict(unknowns=int(A.shape[0]), data_points=len(data), seconds=seconds, floor_seconds=floor,
                ratio=seconds / floor, lu_seconds=t_lu, kdtree_seconds=t_kd,
                newton_per_projection=float(sum(s.iterations for s in path.steps)
                                            / sum(s.outer_iterations for s in path.steps)),
                outer_iterations=int(sum(s.outer_iterations for s in path.steps)),
                converged=bool(path.converged))


def data_search(n_points: int, n_data: int, repeats: int) -> dict:
    """Cold KD-tree query of ``n_points`` states against the warm-started exact search, and the
    tree's build time and peak memory."""
    rng = np.random.default_rng(1)
    tracemalloc.start()
    t0 = time.perf_counter()
    data = MaterialDataset.hookean(200e9, -0.01, 0.01, n_data, c=200e9)
    build = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    strain = rng.uniform(-0.01, 0.01, n_points)
    stress = 200e9 * strain * (1 + 0.01 * rng.standard_normal(n_points))
    t = median_time(lambda: data.nearest(strain, stress), repeats)
    # Warm start as between two DDCM iterations: the previous states differ slightly.
    previous = data.nearest(strain * (1 + 1e-3), stress * (1 - 1e-3))
    t0 = time.perf_counter()
    data._graph()
    graph = time.perf_counter() - t0
    stats: dict = {}
    t_warm = median_time(lambda: data.nearest_warm(strain, stress, previous, stats=stats), repeats)
    fallback = stats["fallbacks"] / max(1, stats["queries"])
    return dict(unknowns=n_points, data_points=n_data, seconds=t, floor_seconds=t, ratio=1.0,
                build_seconds=build, peak_memory_mb=peak / 2**20, warm_seconds=t_warm,
                warm_over_cold=t_warm / t, warm_fallback_share=fallback, graph_build_seconds=graph)


def fb_vs_qp(model, repeats: int) -> list[dict]:
    """Classical path: FB Newton against the QP solvers of CasADi, same model, same accuracy."""
    out = []
    cmp = compare(model, ["fischer_burmeister"], variants=["classical"])
    fb = cmp["classical", "fischer_burmeister"]
    t_fb = median_time(lambda: compare(model, ["fischer_burmeister"], variants=["classical"]), repeats)
    n = model.n_dofs + model.n_contacts
    out.append(dict(name=f"classical FB Newton, {model.name}", unknowns=n, data_points=0, seconds=t_fb,
                    floor_seconds=t_fb, ratio=1.0, converged=bool(fb.converged)))
    for solver in ("highs", "osqp", "qpoases"):
        if model.n_dofs > 3000 and solver == "qpoases":
            continue  # dense active-set internals: minutes at this size
        try:
            qp = ContactQP(model, solver=solver)
        except Exception as exc:  # a plugin that cannot take the problem is reported, not fatal
            out.append(dict(name=f"classical QP {solver}, {model.name}", unknowns=n, data_points=0,
                            seconds=float("nan"), floor_seconds=t_fb, ratio=float("nan"), error=str(exc)))
            continue
        sol = qp.solve()
        t = median_time(qp.solve, repeats)
        err = float(np.max(np.abs(sol.u - fb.array("u")))) / max(float(np.max(np.abs(fb.array("u")))), 1e-300)
        out.append(dict(name=f"classical QP {solver}, {model.name}", unknowns=n, data_points=0, seconds=t,
                        floor_seconds=t_fb, ratio=t / t_fb, max_rel_difference_u=err,
                        converged=bool(sol.success.all())))
    return out


def paper_shares(repeats: int) -> list[dict]:
    """Wall time of the default ``ddcm-compare`` run and the share of each formulation."""
    model = paper_bar()
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        cmp = compare(model)
        runs.append((time.perf_counter() - t0, cmp))
    total, cmp = sorted(runs, key=lambda r: r[0])[len(runs) // 2]
    out = [dict(name="paper example, all formulations x variants", unknowns=model.n_dofs, data_points=len(model.dataset),
                seconds=total, floor_seconds=total, ratio=1.0)]
    for (variant, name), r in cmp.results.items():
        t = r.build_seconds + r.solve_seconds
        per_step = r.solve_seconds / len(r.steps)
        its = float(np.sum(r.array("iterations")))
        out.append(dict(name=f"paper example, {variant} {name}", unknowns=model.n_dofs, data_points=len(model.dataset),
                        seconds=t, floor_seconds=total, ratio=t / total, share=t / total,
                        seconds_per_step=per_step, seconds_per_inner_iteration=r.solve_seconds / max(its, 1)))
    return out


def markdown(records: list[dict]) -> str:
    lines = ["| name | unknowns | data points | seconds | floor s | ratio | notes |", "|---|---|---|---|---|---|---|"]
    skip = {"name", "unknowns", "data_points", "seconds", "floor_seconds", "ratio"}
    for r in records:
        notes = ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items() if k not in skip)
        lines.append(f"| {r['name']} | {r['unknowns']} | {r['data_points']} | {r['seconds']:.4g} | "
                     f"{r['floor_seconds']:.4g} | {r['ratio']:.3g} | {notes} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="smaller sizes and fewer repeats (about 5 minutes)")
    ap.add_argument("--out", required=True, metavar="DIR")
    args = ap.parse_args(argv)
    out = prepare_output_dir(args.out)
    quick = args.quick
    rep = 1 if quick else 3
    records: list[dict] = []

    def log(rec):
        records.append(rec)
        print(f"{rec['name']:<55} {rec['unknowns']:>8} {rec['data_points']:>9} {rec['seconds']:10.4g} s  "
              f"ratio {rec['ratio']:8.3g}", file=sys.stderr, flush=True)

    bars = (300, 3000, 30000)
    for n in bars:
        log(dict(name=f"DDCM iteration, {stopped_bar(n, 10).name}", **ddcm_iteration(stopped_bar(n, 10_000), rep)))
    for panels in ((100, 1000) if quick else (100, 1000, 10000)):
        model = warren(panels, 10_000)
        log(dict(name=f"DDCM iteration, {model.name}", **ddcm_iteration(model, rep)))
    for n_data in ((10**4, 10**5, 10**6) if quick else (10**4, 10**5, 10**6, 10**7)):
        log(dict(name=f"DDCM iteration, bar 300 elements, {n_data:.0e} data",
                 **ddcm_iteration(stopped_bar(300, n_data), rep)))
        log(dict(name=f"KD-tree query of 3e4 states, {n_data:.0e} data", **data_search(30_000, n_data, 3)))
    for n in ((1000, 10_000) if quick else (1000, 10_000, 100_000)):
        for rec in fb_vs_qp(stopped_bar(n, 10, steps=np.linspace(1.0, 0.97, 4)), rep):
            log(rec)
    for rec in paper_shares(3):
        log(rec)
    write_json_atomic(out / "benchmarks.json", records)
    write_bytes_atomic(out / "benchmarks.md", markdown(records).encode())
    print(f"wrote benchmarks.json and benchmarks.md to {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
