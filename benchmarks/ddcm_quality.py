"""DDCM search quality on noisy data: the tables of issue 12 (README, "Better DDCM fixed points").

Usage::

    python benchmarks/ddcm_quality.py [--seeds 5] [--truss-seeds 2] [--reference-restarts 20] [--quick]
                                      [--only NAME ...]

``--seeds 0`` skips table 1, ``--truss-seeds 0`` table 2.

Table 1, noisy paper bar (one element: the global optimum of every step is enumerated): for each
noise level and search (:data:`ddcm_casadi.validation.quality_rungs.CONFIGURATIONS` and the max-ent
settings of :data:`MAXENT`; each ``--only NAME`` keeps one of them, plain always), the share of steps at
the global optimum, the mean over data sets of the max relative error of ``p`` and ``u`` against
the noise-free classical closed form, the cost as ``Z_E`` projections relative to plain
alternating, and wall time.

Table 2, a noisy 2-D Warren truss with three contacts (15 members, 2001 data each: ``2001^15``
assignments, the exact optimum is not affordable): per step, the DDCM objective of each row
(:func:`ddcm_objective`) relative to the best known, the lowest of every row, including two
references, the best of ``R/4`` and of ``R`` kicked restarts + greedy from every step's origin
(``R = --reference-restarts``; the two show how far the reference is from converged); the share of
steps at the best known (within 1e-9), the max relative error of ``p`` and ``u`` against the
noise-free classical solution (FB, ``E = 200 GPa``; mean over data sets), the cost as ``Z_E``
projections relative to plain alternating, the steps converged and the wall time (and relative to
plain: the greedy screen costs time that no projection count shows). Where the time of
"restarts 1 (kick) + greedy" goes (issue 28; process CPU time, 3 data sets x 3 noise levels, one
BLAS thread, fresh problems per run as here): 56 % in the ``Z_E`` projections (the FB Newton solves,
and 18 % the exact check of each by the bordered branch enumeration,
:meth:`~ddcm_casadi.problems.exact.ExactEnumerator.solve`: one solve with every constraint
imposed, then a 6 x 6 block per branch), 25 % in the greedy screen (0.8 ms per sweep: 8 points x
2001 data bounded by the projection without contact constraints, the few that may descend solved
in closed form, :func:`~ddcm_casadi.drivers.ddcm_search.single_moves`), 11 % in the data search
and fields, 4 % in the step checks; at 2.8x plain's projections it costs 3.2-4.4x plain's time
(11-14x before: the enumeration factorised each of the 27 branches' KKT matrices and the screen
evaluated every branch's quadratic for all 16 008 moves). A threaded BLAS made the screen 2-10x
slower on a loaded 2-core machine, hence one thread by default (below).
"""

from __future__ import annotations

import argparse
import os

# One BLAS thread unless the caller sets one: the closed forms of the greedy screen and of the
# enumeration are products of small matrices (16 x 16 by 16 x 16 000 on the truss), which a
# threaded BLAS made 2-10x slower on a loaded 2-core machine (measured; before numpy is imported).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np

from ddcm_casadi import compare
from ddcm_casadi.models import truss
from ddcm_casadi.drivers.harness import _relative_error  # the error measure of Comparison.errors
from ddcm_casadi.validation.quality_rungs import (CONFIGURATIONS, MAXENT_CONFIGURATION, MAXENT_OPTIONS, NOISE_LEVELS, measure,
                                       noisy_dataset)
from ddcm_casadi.drivers.ddcm_options import DDCMOptions

FB = "fischer_burmeister"

#: Max-ent (Kirchdoerfer & Ortiz 2017) settings measured next to the searches: the defaults
#: (K = 32 neighbours, one temperature beta_0), two stages (beta_0 then 2 beta_0), and annealed by
#: x4 per stage until the weights concentrate (a plain DDCM fixed point, reached from the smooth
#: problem).
MAXENT = {
    MAXENT_CONFIGURATION: MAXENT_OPTIONS,
    "max-ent (K=32, 2 stages x2)": DDCMOptions(variant="maxent", maxent_steps=2),
    "max-ent (K=32, x4 to concentration)": DDCMOptions(variant="maxent", maxent_steps=30, maxent_beta_growth=4.0),
}


def table_bar(seeds, only=None) -> None:
    configs = {k: v for k, v in {**CONFIGURATIONS, **MAXENT}.items() if k == "plain" or only is None or k in only}
    print(f"## Noisy paper bar ({len(seeds)} data sets x 21 steps per noise level; 500 data)\n")
    print("| noise | search | steps at global optimum | error p | error u | projections (x plain) | converged | seconds |")
    print("|---|---|---|---|---|---|---|---|")
    for noise in NOISE_LEVELS:
        base = None
        for name, opts in configs.items():
            q = measure(opts, noise, seeds, name=name)
            base = base or q.projections
            share = f"{q.share:.1%}" if q.checked else "-"
            print(f"| {noise:.0%} | {name} | {share} | {q.error_p:.3f} | {q.error_u:.3f} | "
                  f"{q.projections / base:.2f} | {q.converged}/{q.steps} | {q.seconds:.2f} |", flush=True)


def noisy_truss(noise: float, seed: int):
    """The Warren truss (4 panels, 15 members, contacts at the 3 inner bottom nodes, 7 load steps)
    on the paper's noisy data rescaled onto its strain range (2001 data)."""
    data = noisy_dataset(noise, seed, n_data=2001, c=200e9)
    # The ladder's truss data cover [-0.004, 0.004]: rescale the paper's strains onto that range.
    scale = 0.004 / 0.05
    from ddcm_casadi.data.dataset import MaterialDataset
    data = MaterialDataset(data.strain * scale, data.stress * scale, 200e9)
    return truss.warren_truss(panels=4, gap=0.002, contact_nodes=range(1, 4), load_factors=np.linspace(0.5, 3.0, 7),
                              dataset=data, name="noisy Warren truss")


def ddcm_objective(model, r) -> np.ndarray:
    """Per step, the DDCM objective ``1/2 sum_i w_i d^2(z_i, y_i)`` of the reported state ``z`` and
    data ``y = data_index``: the plain scheme's ``distance``; for LCDD and max-ent the objective
    of their state and the datum nearest their material state (a feasible pair of the double
    minimisation, which these variants do not minimise)."""
    data = model.dataset
    return np.array([0.5 * np.dot(model.volumes, data.distance2(s.strain, s.stress, s.data_index)) for s in r.steps])


def reference_options(restarts: int) -> DDCMOptions:
    """The reference search: every step from the origin (independent of the path), ``restarts``
    kicks among the 10 data nearest the best state so far, then the screened greedy search."""
    return DDCMOptions(warm=False, restarts=restarts, restart_neighbours=10, improve="greedy", greedy_budget=200)


def table_truss(seeds, reference_restarts: int, only=None) -> None:
    """Table 2 (see the module's docstring); ``only`` as for :func:`table_bar`."""
    refs = {f"reference: {n} kicked restarts + greedy": reference_options(n)
            for n in sorted({max(1, reference_restarts // 4), reference_restarts})}
    configs = {k: v for k, v in {**CONFIGURATIONS, **MAXENT}.items() if k == "plain" or only is None or k in only}
    configs.update(refs)
    print(f"\n## Noisy 2-D Warren truss with 3 contacts ({len(seeds)} data sets x 7 steps; 2001 data)\n")
    print(f"best known: per step, the lowest objective of every row (references: warm=False, "
          f"{', '.join(str(o.restarts) for o in refs.values())} kicked restarts (K = 10) + greedy)\n")
    print("| noise | search | steps at the best known | objective / best: mean | max | error p | error u "
          "| projections (x plain) | converged | seconds (x plain) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    classical = compare(noisy_truss(0.0, 0), [FB], variants=("classical",))["classical", FB]
    u_ref, p_ref = classical.array("u"), classical.array("p")
    for noise in NOISE_LEVELS:
        rows = {k: dict(objective=[], best=[], error_p=[], error_u=[], projections=0, converged=0, seconds=0.0)
                for k in configs}
        for seed in seeds:
            model = noisy_truss(noise, seed)
            objective = {}
            for name, opts in configs.items():
                r = compare(model, [FB], variants=("ddcm",), ddcm=opts)["ddcm", FB]
                row = rows[name]
                objective[name] = ddcm_objective(model, r)
                row["error_p"].append(float(np.max(_relative_error(r.array("p"), p_ref))))
                row["error_u"].append(float(np.max(_relative_error(r.array("u"), u_ref))))
                row["projections"] += int(np.sum(r.array("projections")))
                row["converged"] += int(np.sum(r.array("converged")))
                row["seconds"] += r.solve_seconds
            best = np.min(list(objective.values()), axis=0)
            for name in configs:
                rows[name]["objective"].append(objective[name])
                rows[name]["best"].append(best)
        base, base_seconds = rows["plain"]["projections"], rows["plain"]["seconds"]
        for name, row in rows.items():
            ratio = np.concatenate(row["objective"]) / np.concatenate(row["best"])
            at_best = int(np.sum(ratio <= 1 + 1e-9))
            print(f"| {noise:.0%} | {name} | {at_best}/{ratio.size} | {np.mean(ratio):.3g} | {np.max(ratio):.3g} | "
                  f"{np.mean(row['error_p']):.3f} | {np.mean(row['error_u']):.3f} | {row['projections'] / base:.2f} | "
                  f"{row['converged']}/{ratio.size} | {row['seconds']:.1f} ({row['seconds'] / base_seconds:.1f}) |",
                  flush=True)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--truss-seeds", type=int, default=2)
    p.add_argument("--reference-restarts", type=int, default=20,
                   help="R: the truss table's references are the best of R/4 and of R kicked restarts + greedy")
    p.add_argument("--quick", action="store_true", help="one data set each, 5 reference restarts")
    p.add_argument("--only", action="append", metavar="NAME",
                   help="a row to run (repeatable; plain, the cost base, and the truss references always run)")
    a = p.parse_args(argv)
    if a.quick:
        a.seeds, a.truss_seeds, a.reference_restarts = 1, 1, 5
    if min(a.seeds, a.truss_seeds) < 0 or a.reference_restarts < 1:
        p.error("--seeds and --truss-seeds must be >= 0, --reference-restarts >= 1")
    only = None if a.only is None else set(a.only)
    unknown = (only or set()) - set(CONFIGURATIONS) - set(MAXENT)
    if unknown:
        p.error(f"unknown rows {sorted(unknown)}; known: {', '.join([*CONFIGURATIONS, *MAXENT])}")
    if a.seeds:
        table_bar(list(range(a.seeds)), only)
    if a.truss_seeds:
        table_truss(list(range(a.truss_seeds)), a.reference_restarts, only)


if __name__ == "__main__":
    main()
