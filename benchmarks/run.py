"""Benchmark suite: DDCM iterations against their cost floor, data search, FB against QP solvers,
and where the paper's default run spends its time.

    python benchmarks/run.py [--quick] --out DIR

Writes ``DIR/benchmarks.json`` (a list of records with ``name``, ``unknowns``, ``data_points``,
``seconds``, ``floor_seconds``, ``ratio`` and extra fields) and ``DIR/benchmarks.md``. Every
timing is the median of repeated runs, and every comparison is a ratio measured in this process
run (the machines are shared and noisy). ``--quick`` keeps to about 10 minutes on 2 cores; the full
run takes 40 minutes to 2 hours (the 1e6-unknown continuum alone 25-45 minutes and 15 GB).
One record is the default FCLIB method on a generated frictional problem against projected
Gauss-Seidel (``benchmarks/fclib.py`` measures the FCLIB problems themselves).

The floor of one DDCM iteration is one factorisation and solve, with the package's sparse solver
(:func:`ddcm_casadi.linalg.factorize`), of the same saddle-point system the projection solves,
plus one KD-tree query of all material points against the data set; the cached-factor floor
(``cached_floor_seconds``, ``ratio_to_cached_floor``) leaves out the factorisation. DDCM on a 2-D
continuum (``DDCM iteration, 2-D continuum`` records), the linear solvers on its KKT matrix
(``linear solver, ...``) and on its definite stiffness block (SuperLU against pyamg's algebraic
multigrid and CG, where ``pyamg`` is installed) are measured at 1e4 and 1e5 unknowns
(``--quick``) and 1e6 (full run), each in a fresh process; the last record is the paper's first
run (``benchmarks/first_run.py``).
The one-off build (``build, ...`` records and ``build_seconds``: both problems and the
formulation's CasADi Functions) is measured against the same floor, for bars, trusses and a
2-D continuum of 1e4 and 1e5 unknowns (``--quick``) and 1e6 (full run), each in a fresh process.
3-D (issue 28, item 5): ``K_C set-up and solve pair, 3-D block`` records (SuperLU, PARDISO,
pyamg's smoothed aggregation + CG) and ``reduced DDCM iteration, 3-D block`` records against
their floor, at 1e4 dofs of ``K_C`` and 1e5 (``--quick``: AMG without contact only; full run:
every solver but SuperLU, with and without contact) and 5e5 (full run, AMG only).
Issue 28: ``DDCM search cost`` records, restarts + greedy against plain DDCM on the quality
benchmark's noisy truss, their time ratio measured in this run (:func:`search_cost`), and ``first
DDCM solve`` records, a 2-D continuum of 2e4 points without and with contact (:func:`first_solve_record`);
with ``$DDFENICS_PYTHON`` set, ``DDCM iteration against ddfenics`` records (``benchmarks/ddfenics_block.py``:
5e3 points, and 1e5 in the full run; ratio = our seconds per iteration over ddfenics'); with
``$DDCM_PETSC_PYTHON`` set, ``classical FB against PETSc SNESVI`` records (``benchmarks/snesvi.py``:
1e4 unknowns, and 1e5 and 1e6 in the full run; ratio = ours condensed over SNESVI's best tuning,
``factor_ratio`` = our factor of ``K`` with the Delassus matrix over MUMPS's factor of ``K``);
``solve / FB solve`` records, the augmented Lagrangian's and MPCC's solve time over
Fischer-Burmeister's on the continuum examples, classical and DDCM (``hertz2d`` with ``--quick``,
:data:`CONTINUUM_CASES` in the full run; :func:`formulation_ratios`).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ddcm_casadi import MaterialDataset, compare, paper_bar
from ddcm_casadi import formulations as registry
from ddcm_casadi import linalg
from ddcm_casadi.heap import peak_resident_bytes
from ddcm_casadi.factor_updates import ReferenceFactor
from ddcm_casadi.io import prepare_output_dir, write_bytes_atomic, write_json_atomic
from ddcm_casadi.linalg import factorize, solver_name
from ddcm_casadi.problems.build import ProblemPair, build_problems
from ddcm_casadi.validation.reference import ContactQP
from ddcm_casadi.drivers.ddcm_reduced import ReducedProjection, build_classical, build_projection
from ddcm_casadi.drivers.path import DDCMSolver, solve_classical
from ddcm_casadi.models.truss import bar_chain, warren_truss


def median_time(fn, repeats: int, budget: float = 20.0) -> float:
    """Median wall time of up to ``repeats`` calls; calls stop once ``budget`` seconds are spent
    (at least one call)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
        if sum(times) > budget:
            break
    return statistics.median(times)


BAR_STEPS = (0.99, 0.9875, 0.985, 0.9825, 0.98)
TRUSS_STEPS = (0.6, 0.7, 0.8, 0.9, 1.0)


def stopped_bar(n_elements: int, n_data: int, *, steps=BAR_STEPS):
    """A bar pushed at its tip onto 9 stops behind interior nodes (5 load steps)."""
    stops = {max(1, int(n_elements * j / 10)): 0.002 * j for j in range(1, 10)}
    data = MaterialDataset.hookean(200e9, -0.05, 0.01, n_data, c=300e9)
    return bar_chain(length=1.0, elements=n_elements, youngs_modulus=200e9, tip_positions=list(steps),
                     stops=stops, dataset=data, name=f"bar, {n_elements} elements")


def warren(panels: int, n_data: int, *, steps=TRUSS_STEPS):
    """2-D Warren truss on a stepped ground: every 4th bottom node may touch it, at gaps of 0,
    0.1 and 0.2 mm in turn (``panels / 4`` contact pairs)."""
    nodes = np.arange(2, panels - 1, 4)
    gaps = 1e-4 * (np.arange(nodes.size) % 3)
    data = MaterialDataset.hookean(200e9, -0.01, 0.01, n_data, c=200e9)
    return warren_truss(panels=panels, gap=gaps, contact_nodes=nodes, load_factors=steps, dataset=data,
                        name=f"Warren truss on a stepped ground, {panels} panels, {nodes.size} contacts")


def ddcm_iteration(model, repeats: int, formulation: str = "fischer_burmeister", *, search: str = "kdtree",
                   floor: bool = True, reduce: bool = True) -> dict:
    """Seconds per DDCM iteration (projection + data search) along the model's load path, against
    the floor. The projection is built as the driver builds it (:func:`build_projection`: reduced
    where the Kirchdoerfer-Ortiz reduction applies, unless ``reduce`` is False; ``projection_path``
    says which). Full path: the floor is one scipy LU factorisation and solve of the FB
    saddle-point system at the converged state, plus one KD-tree query of every material point
    against the data set. Reduced path: :func:`reduced_floor` (one solve pair with the kept factor
    plus the query: no factorisation is left to make).

    ``seconds`` is the mean over every iteration of the path (the driver's per-step checks and
    the cold first step included); ``iteration_seconds`` the projections and data searches alone
    per iteration. ``first_step_seconds`` and ``later_steps_seconds`` split ``seconds``.
    ``build_seconds`` is the one-off build (problems and the formulation; with the reduction, its
    factorisation and back-solves), ``build_ratio`` its ratio to the floor.
    """
    t0 = time.perf_counter()
    problems = build_problems(model)
    problem_build = time.perf_counter() - t0
    built = build_projection(registry.get(formulation), problems, reduce=reduce)
    build = time.perf_counter() - t0
    reduced = isinstance(built, ReducedProjection)
    system = None if reduced else built.newton_system()
    runs = []
    for _ in range(repeats):
        built.reset()  # cold factorisation cache: every repeat measures the same work
        path = DDCMSolver(problems, built, search=search).solve(formulation_name=formulation)
        its = sum(s.outer_iterations for s in path.steps)
        stats = dict(built.stats or dict(predicted=0, newton=0))
        runs.append((path.solve_seconds / its, path, stats))
    seconds, path, stats = sorted(runs, key=lambda r: r[0])[len(runs) // 2]
    steps = path.steps
    its = np.array([s.outer_iterations for s in steps])
    secs = np.array([s.seconds for s in steps])
    total = float(secs.sum())
    rec = dict(unknowns=0, data_points=len(model.dataset), seconds=seconds, floor_seconds=float("nan"),
               ratio=float("nan"), search=search, steps=len(steps), outer_iterations=int(its.sum()),
               first_step_seconds=float(secs[0] / its[0]),
               later_steps_seconds=float(secs[1:].sum() / its[1:].sum()) if len(steps) > 1 else float("nan"),
               projection_share=float(sum(s.projection_seconds for s in steps)) / total,
               search_share=float(sum(s.search_seconds for s in steps)) / total,
               search_seconds_per_iteration=float(sum(s.search_seconds for s in steps)) / int(its.sum()),
               newton_per_projection=float(sum(s.iterations for s in steps) / its.sum()),
               predicted_share=stats.get("predicted", 0) / max(1, stats.get("predicted", 0) + stats.get("newton", 0)),
               factorizations=stats.get("factorizations", 0), factor_updates=stats.get("updates", 0),
               build_seconds=build, problem_build_seconds=problem_build, converged=bool(path.converged),
               iteration_seconds=float(sum(s.projection_seconds + s.search_seconds for s in steps)) / int(its.sum()),
               projection_path=path.projection_path)
    if reduced:
        red = built.reduction
        rec["unknowns"] = problems.projection.n_x + problems.projection.n_pairs
        rec.update(factor_seconds=red.factor_seconds, back_solves=red.back_solves,
                   back_solve_seconds=red.back_solve_seconds, definite_solver=red.solver)
        if isinstance(red.factor, linalg.AMGFactor):
            rec["cg_iterations_per_solve"] = float(np.mean(red.factor.iterations))
        if floor:
            step = steps[-1]
            low = reduced_floor(problems, built, step.step, (step.strain_star, step.stress_star),
                                (step.strain, step.stress), repeats)
            rec.update(low, ratio_to_cached_floor=seconds / low["cached_floor_seconds"],
                       iteration_ratio_to_cached_floor=rec["iteration_seconds"] / low["cached_floor_seconds"],
                       build_ratio=build / low["cached_floor_seconds"])
            rec["ratio"] = rec["ratio_to_cached_floor"]
        return rec
    if system is None:  # no saddle-point system to measure the floor on
        return rec
    rec["unknowns"] = int(system.unknowns.size)
    if floor:
        step = steps[-1]
        x, p = problems.scaled_start("mpcc", step.u, step.p, step.stress)
        low = iteration_floor(problems, built, step.step, x, p, (step.strain_star, step.stress_star),
                              (step.strain, step.stress), repeats)
        rec.update(low, ratio=seconds / low["floor_seconds"], build_ratio=build / low["floor_seconds"],
                   ratio_to_cached_floor=seconds / low["cached_floor_seconds"])
    return rec


def reduced_floor(problems, built, step: int, data, states, repeats: int) -> dict:
    """The cached-factor floor of a reduced DDCM iteration: one solve with the kept factor of
    ``K_C`` and two right-hand sides (:meth:`Reduction.particular` at the assigned ``data =
    (strain*, stress*)`` of load step ``step``: a solve pair and two sparse products), plus one
    KD-tree query of the ``states = (strain, stress)`` of every material point."""
    params = problems.projection_params(step, *data)
    t_solve = median_time(lambda: built.reduction.particular(params), max(5, repeats))
    t_kd = median_time(lambda: problems.model.dataset.nearest(*states), max(5, repeats))
    return dict(floor_seconds=t_solve + t_kd, cached_floor_seconds=t_solve + t_kd, solve_seconds=t_solve,
                kdtree_seconds=t_kd, linear_solver=solver_name())


def iteration_floor(problems, built, step: int, x, p, data, states, repeats: int) -> dict:
    """The floor of one DDCM iteration: one factorisation and solve, with the faster of the
    package's sparse solver (:func:`ddcm_casadi.linalg.factorize`) and scipy's default SuperLU
    (up to 3e4 unknowns, where it takes seconds at most), of the FB saddle-point system at scaled
    ``(x, p)`` with the assigned ``data = (strain*, stress*)`` at load step ``step``, plus one
    KD-tree query of the ``states = (strain, stress)`` of every material point against the data
    set. ``cached_floor_seconds``: the same without the factorisation (one solve with a kept
    factor plus the query), the floor of an iteration whose active set is unchanged."""
    system = built.newton_system()
    z, P = built.newton_point(problems.projection_params(step, *data), x, p)
    A = system.matrix(z, P)
    rhs = system.residual(z, P) + 1.0
    t0 = time.perf_counter()
    lu = factorize(A)
    lu.solve(rhs)
    t_lu = time.perf_counter() - t0
    if t_lu < 5.0:  # repeat what is cheap (a 1e6 system takes minutes: once)
        t_lu = median_time(lambda: factorize(A).solve(rhs), max(3, repeats))
    if A.shape[0] <= 3 * 10**4:  # the faster of the package's solver and scipy's default SuperLU
        t_lu = min(t_lu, median_time(lambda: spla.splu(A).solve(rhs), max(3, repeats)))
    t_solve = median_time(lambda: lu.solve(rhs), max(3, repeats))
    t_kd = median_time(lambda: problems.model.dataset.nearest(*states), max(3, repeats))
    return dict(floor_seconds=t_lu + t_kd, lu_seconds=t_lu, kdtree_seconds=t_kd, solve_seconds=t_solve,
                cached_floor_seconds=t_solve + t_kd, linear_solver=solver_name())


def continuum_block(divisions: int, data: bool = True):
    """The body of the Hertz example (``examples/cases/hertz2d.toml``: plane strain, P2 triangles,
    a 20 mm square indented by a cylinder, with its 101^3 graded Hookean data) on a uniform
    ``divisions x divisions`` mesh without the contact grading, for sizes set by one number.
    ``data=False``: without the data (the classical problem alone; the data set of 1e6 points
    is not built)."""
    from ddcm_casadi.casefiles.base import read_document
    from ddcm_casadi.casefiles.config import case_from_dict
    from ddcm_casadi.validation.continuum import EXAMPLE

    doc = read_document(EXAMPLE)
    doc["mesh"]["divisions"] = [divisions, divisions]
    doc["mesh"].pop("refine_near", None)
    if not data:
        doc.pop("data", None)
    return case_from_dict(doc, base_dir=EXAMPLE.parent, source=f"hertz block {divisions}x{divisions}").model


#: Models of about ``u`` projection unknowns (``n + m k + 3 nc`` with ``n`` = ``m k`` for bars).
BUILD_MODELS = {
    "bar": lambda u: stopped_bar(max(10, round(u / 3)), 10_000),
    "truss": lambda u: warren(max(8, round(u / 12.75)), 10_000),
    "2-D continuum": lambda u: continuum_block(max(4, round((u / 34) ** 0.5))),
}


def built_problems(model) -> ProblemPair:
    """:func:`build_problems` with both problems built (they are built on first use): the
    ``problem_build`` stage of :func:`build_record`, as it was before they were."""
    problems = build_problems(model)
    for variant in ("classical", "projection"):
        getattr(problems, variant)
    return problems


def build_record(family: str, unknowns: int, repeats: int) -> dict:
    """The one-off build of a DDCM run (both problems, then the projection's Fischer-Burmeister
    system and its piece system) of a ``family`` model of about ``unknowns`` unknowns, against
    the floor of one DDCM iteration (:func:`iteration_floor`, at the zero start with a random
    data assignment, whose states are queried). ``peak_memory_bytes``: the peak resident set
    (Linux ``VmHWM``) of the process, imports and model included.

    Per stage (seconds, and the peak resident set after it): ``model_seconds`` (the case read,
    meshed and assembled, its data and their KD-tree), ``problem_build_seconds``
    (:func:`build_problems`, with the reference scales), ``formulation_build_seconds`` (FB on the
    full projection), ``classical_build_seconds`` (FB on the classical problem),
    ``reduced_build_seconds`` (the projection as the driver builds it, :func:`build_projection`:
    the Kirchdoerfer-Ortiz reduction and FB on the condensed problem) and ``ddcm_setup_seconds``
    (the DDCM driver). ``classical_run_build_seconds`` and ``ddcm_run_build_seconds``: all that
    precedes a classical run's first Newton step and a DDCM run's first iteration."""
    from ddcm_casadi.drivers.ddcm_search import random_assignment

    stages, peaks = {}, {}

    def stage(name, fn):
        t = time.perf_counter()
        out = fn()
        stages[name] = time.perf_counter() - t
        peaks[name] = peak_resident_bytes()
        return out

    model = stage("model", lambda: BUILD_MODELS[family](unknowns))
    problems = stage("problem_build", lambda: built_problems(model))
    fb = registry.get("fischer_burmeister")
    built = stage("formulation_build", lambda: fb.build(problems.projection))
    build = stages["problem_build"] + stages["formulation_build"]
    if problems.has("classical"):
        stage("classical_build", lambda: build_classical(fb, problems))  # condensed where it applies
    reduced = stage("reduced_build", lambda: build_projection(fb, problems))
    stage("ddcm_setup", lambda: DDCMSolver(problems, reduced))
    del reduced
    data = model.dataset
    index = random_assignment(model, np.random.default_rng(0))
    assigned = (data.strain[index], data.stress[index])
    x, p = np.zeros(problems.projection.n_x), np.zeros(problems.projection.n_pairs)
    low = iteration_floor(problems, built, model.n_steps - 1, x, p, assigned, assigned, repeats)
    n = int(built.newton_system().unknowns.size)
    peak = peak_resident_bytes()
    run_builds = dict(ddcm_run_build_seconds=stages["model"] + stages["problem_build"] + stages["reduced_build"]
                      + stages["ddcm_setup"])
    if "classical_build" in stages:
        run_builds["classical_run_build_seconds"] = stages["model"] + stages["problem_build"] + stages["classical_build"]
    return dict(name=f"build, {family}: {model.name}", unknowns=n, data_points=len(data), seconds=build,
                ratio=build / low["floor_seconds"], **low, build_seconds=build,
                **{f"{k}_seconds": v for k, v in stages.items()}, **run_builds,
                **{f"{k}_peak_memory_bytes": v for k, v in peaks.items()},
                build_seconds_per_1e5_unknowns=build * 1e5 / n, peak_memory_bytes=peak)


#: One BLAS thread: on a shared 2-core machine OpenBLAS's threads spin. Measured in a build at
#: 1e5 unknowns: the back-solves of the reduction (SuperLU's solve with several right-hand sides
#: calls BLAS) took 7.4 s with the default threads and 1.8 s with one; a first LAPACK call
#: (eigvalsh of 343 x 343) 3.2 s.
ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


FRESH = """
import json, sys
sys.path.insert(0, sys.argv[1])
import run
out = getattr(run, sys.argv[2])(*json.loads(sys.argv[3]))
print(json.dumps(out if isinstance(out, list) else [out]))
"""


def in_fresh_process(function: str, *args, label: str, unknowns: int, env: dict | None = None) -> list[dict]:
    """The records of ``function(*args)`` (a function of this module) run in a fresh process: its
    peak memory its own, and a size the machine cannot hold (killed for memory, exit status -9)
    reported as a record named ``label`` (of about ``unknowns`` unknowns) with the error, not fatal.
    ``env``: variables added to the process's environment."""
    here = Path(__file__).resolve().parent
    cmd = [sys.executable, "-c", FRESH, str(here), function, json.dumps(args)]
    # Run from this folder: ``python -c`` puts its working directory first on sys.path, and from the
    # repository's root that would import the source tree instead of the installed package.
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=here, env={**os.environ, **(env or {})})
    if proc.returncode == 0:
        return json.loads(proc.stdout.strip().splitlines()[-1])
    return [dict(name=label, unknowns=unknowns, data_points=0,
                 seconds=float("nan"), floor_seconds=float("nan"), ratio=float("nan"),
                 error=f"exit status {proc.returncode}: {(proc.stderr.strip().splitlines() or [''])[-1]}")]


def build_sizes(family: str, sizes, repeats: int) -> list[dict]:
    """:func:`build_record` per size, each in a fresh process (its peak memory its own; a size the
    machine cannot hold is reported, not fatal; one BLAS thread, :data:`ONE_THREAD`), then the
    growth: build seconds per 1e5 unknowns at the largest size that ran against the smallest
    (``ratio`` 1 for linear growth)."""
    out = []
    for u in sizes:
        out += in_fresh_process("build_record", family, u, repeats, env=ONE_THREAD,
                                label=f"build, {family}, about {u:.0e} unknowns", unknowns=u)
    done = [r for r in out if np.isfinite(r["seconds"])]
    if len(done) >= 2:
        small, large = done[0], done[-1]
        a, b = small["build_seconds_per_1e5_unknowns"], large["build_seconds_per_1e5_unknowns"]
        out.append(dict(name=f"build seconds per 1e5 unknowns, {family}: {small['unknowns']} to {large['unknowns']} "
                             "unknowns", unknowns=large["unknowns"], data_points=large["data_points"], seconds=b,
                        floor_seconds=a, ratio=b / a, note="seconds: at the largest size; floor: at the smallest"))
    return out


def continuum_record(unknowns: int, repeats: int, solver: str = "superlu") -> dict:
    """A DDCM iteration on the 2-D continuum (:func:`continuum_block` of about ``unknowns``
    projection unknowns, 21^3 Hookean data, 5 load steps, FB) against both floors
    (:func:`iteration_floor`), with its build, its factorisations and low-rank factor updates,
    and the peak resident memory of the process (Linux ``VmHWM``). ``solver``: the sparse solver
    of :mod:`ddcm_casadi.linalg` for every factorisation, the floor's included."""
    linalg.use_solver(solver)
    model = BUILD_MODELS["2-D continuum"](unknowns)
    rec = ddcm_iteration(model, repeats)
    peak = peak_resident_bytes()
    suffix = "" if solver == "superlu" else f", {solver}"
    return dict(name=f"DDCM iteration, 2-D continuum: {model.name}{suffix}", **rec, peak_memory_bytes=peak)


def pressed_block(divisions: int):
    """:func:`continuum_block` without contact: its top edge pushed down 40 um times the load
    factor by a hard device (5 load steps), no contact pair."""
    from ddcm_casadi.casefiles.base import read_document
    from ddcm_casadi.casefiles.config import case_from_dict
    from ddcm_casadi.validation.continuum import EXAMPLE

    doc = read_document(EXAMPLE)
    doc["mesh"]["divisions"] = [divisions, divisions]
    doc["mesh"].pop("refine_near", None)
    doc.pop("contact")
    doc.pop("hertz", None)
    doc["supports"].append({"boundary": "ymax", "fix": "y", "displacement": [0.0, -4e-5]})
    doc["loading"] = {"load_factors": [0.25, 0.5, 0.75, 1.0, 1.25]}
    return case_from_dict(doc, base_dir=EXAMPLE.parent, source=f"pressed block {divisions}x{divisions}, no contact").model


def reduction_record(unknowns: int, contact: bool, repeats: int, full: bool) -> list[dict]:
    """A reduced DDCM iteration (Kirchdoerfer-Ortiz, :func:`ddcm_iteration`) on the 2-D continuum
    of about ``unknowns`` full-projection unknowns, with contact (:func:`continuum_block`) or
    without (:func:`pressed_block`), against its cached-factor floor (:func:`reduced_floor`:
    ``ratio``), with its build and peak memory; with ``full``, the same path through today's full
    saddle-point projection in the same process (``full_seconds``, ``speedup``) and whether both
    reach the same fixed points (``same_fixed_points``: the same data assignment at every step)."""
    divisions = max(4, round((unknowns / 34) ** 0.5))
    model = continuum_block(divisions) if contact else pressed_block(divisions)
    rec = ddcm_iteration(model, repeats)
    peak = peak_resident_bytes()
    out = dict(name=f"reduced DDCM iteration, 2-D continuum {'with' if contact else 'without'} contact: {model.name}",
               **rec, peak_memory_bytes=peak)
    if full:
        problems = build_problems(model)
        reduced = DDCMSolver(problems, build_projection(registry.get("fischer_burmeister"), problems)).solve()
        slow = DDCMSolver(problems, registry.get("fischer_burmeister").build(problems.projection)).solve()
        its = sum(s.outer_iterations for s in slow.steps)
        out.update(full_seconds=slow.solve_seconds / its, speedup=slow.solve_seconds / its / rec["seconds"],
                   same_fixed_points=all(np.array_equal(a.data_index, b.data_index)
                                         for a, b in zip(slow.steps, reduced.steps)),
                   max_rel_difference_u=max(float(np.max(np.abs(a.u - b.u)) / max(np.max(np.abs(a.u)), 1e-300))
                                            for a, b in zip(slow.steps, reduced.steps)))
    return [out]


def reduction_factor(unknowns: int, repeats: int) -> list[dict]:
    """The reduction's one factorisation, ``K_C`` of the 2-D continuum (about ``unknowns``
    full-projection unknowns), and a solve pair with it: the package's (SuperLU, minimum degree of
    ``K + K^T``, diagonal pivots; ``floor_seconds``) against SuperLU's default (COLAMD, partial
    pivoting) and QDLDL's LDL^T (AMD; where the optional ``qdldl`` package is installed)."""
    model = continuum_block(max(4, round((unknowns / 34) ** 0.5)))
    problems = build_problems(model)
    K = build_projection(registry.get("fischer_burmeister"), problems).reduction.K_u
    rhs = np.cos(np.arange(2 * K.shape[0])).reshape(-1, 2)
    name = "reduction: factorisation and solve pair of K_C, 2-D continuum: {}".format
    kept = {}

    def run(label, factor, solve_pair):
        t = median_time(lambda: kept.__setitem__(label, factor()), repeats)
        return label, t, median_time(lambda: solve_pair(kept[label]), max(5, repeats))

    runs = [run("superlu, minimum degree (default)", lambda: linalg.factorize(K), lambda f: f.solve(rhs)),
            run("superlu, COLAMD", lambda: spla.splu(K), lambda f: f.solve(rhs))]
    if importlib.util.find_spec("qdldl") is not None:
        import qdldl

        runs.append(run("qdldl (AMD, LDL^T)", lambda: qdldl.Solver(K),
                        lambda f: [f.solve(np.ascontiguousarray(rhs[:, j])) for j in range(2)]))
    floor = runs[0][1]
    return [dict(name=name(label), unknowns=int(K.shape[0]), data_points=0, seconds=t, floor_seconds=floor,
                 ratio=t / floor, solve_pair_seconds=ts, nnz=int(K.nnz)) for label, t, ts in runs]


#: Half-width of the 3-D block's contact face (m, about the sphere's axis): pairs on the top face
#: within it only; the Hertz radius at the last step is sqrt(R delta) = 1.1 mm.
CONTACT_3D = 1.25e-3


def block_3d(divisions: int, contact: bool):
    """The body of the 3-D Hertz example (``examples/cases/hertz3d.toml``: a 10 mm quarter cube of
    linear tetrahedra, 6 per hexahedron, 5^6 Hookean data, FB) on a uniform ``divisions^3`` mesh
    without the grading. With ``contact``: the rigid sphere's travel, pairs on the top face within
    :data:`CONTACT_3D` of the axis; without: the top face pushed down by a hard device, 40 um
    times the load factors 0.25 to 1."""
    from ddcm_casadi.casefiles.base import read_document
    from ddcm_casadi.casefiles.config import case_from_dict
    from ddcm_casadi.validation.continuum import EXAMPLE_3D

    doc = read_document(EXAMPLE_3D)
    doc["mesh"]["divisions"] = [divisions] * 3
    doc["mesh"].pop("refine_near", None)
    if contact:
        doc["contact"][0]["boundary"] = {"min": [0.0, 0.0, 0.0], "max": [CONTACT_3D, CONTACT_3D, 0.0]}
    else:
        doc.pop("contact")
        doc.pop("hertz", None)
        doc["supports"].append({"boundary": "zmax", "fix": "z", "displacement": [0.0, 0.0, -4e-5]})
        doc["loading"] = {"load_factors": [0.25, 0.5, 0.75, 1.0]}
    kind = "sphere" if contact else "hard device"
    return case_from_dict(doc, base_dir=EXAMPLE_3D.parent, source=f"3-D block {divisions}^3, {kind}").model


#: Divisions of the 3-D block for about ``u`` dofs of ``K_C`` (``3 (N + 1)^3``).
def divisions_3d(dofs: int) -> int:
    return max(2, round((dofs / 3) ** (1 / 3)) - 1)


def reset_peak_memory() -> None:
    """Set the peak resident set (Linux ``VmHWM``) back to the current resident set."""
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")


def stiffness_solver_3d(dofs: int, solver: str, repeats: int) -> list[dict]:
    """``K_C`` of the 3-D block without contact (:func:`block_3d`, about ``dofs`` dofs): the set-up
    (factorisation, or AMG hierarchy) and a solve pair with ``solver``, to be run in a fresh
    process: ``"superlu"`` (the package's: minimum degree of ``K + K^T``), ``"superlu COLAMD"``
    (scipy's default), ``"pardiso"`` or ``"amg"`` (:class:`~ddcm_casadi.linalg.AMGFactor`,
    smoothed aggregation on the rigid-body modes, CG to :data:`~ddcm_casadi.linalg.DEFINITE_TOL`).
    ``peak_memory_bytes``: the process's peak resident set; ``solver_memory_bytes``: its growth
    from the end of the build to the end of the solves (the factor or hierarchy)."""

    model = block_3d(divisions_3d(dofs), False)
    if importlib.util.find_spec("pyamg") is not None:
        linalg.use_definite_solver("amg")  # the build's scale solves, cheap at every size
    problems = build_problems(model)
    K = build_projection(registry.get("fischer_burmeister"), problems).reduction.K_u
    rhs = np.cos(np.arange(2 * K.shape[0])).reshape(-1, 2)
    base = peak_resident_bytes()
    reset_peak_memory()
    with open("/proc/self/status") as fh:
        resident = next(int(line.split()[1]) for line in fh if line.startswith("VmRSS:")) * 1024
    extra = {}
    if solver == "superlu COLAMD":
        make = lambda: spla.splu(K)
    elif solver == "amg":
        make = lambda: linalg.AMGFactor(K, model.near_null_space())
    else:
        linalg.use_solver(solver)
        make = lambda: linalg.factorize(K)
    kept = {}
    setup = median_time(lambda: kept.__setitem__("f", make()), 1 if K.shape[0] > 3 * 10**4 else repeats)
    factor = kept["f"]
    pair = median_time(lambda: factor.solve(rhs), max(3, repeats))
    x = factor.solve(rhs)
    if solver == "amg":
        extra = dict(cg_iterations=float(np.mean(factor.iterations)), operator_complexity=factor.nnz / K.nnz)
    else:
        extra = dict(factor_nonzeros=int(getattr(factor, "nnz", 0) or 0))
    residual = float(np.max(np.linalg.norm(K @ x - rhs, axis=0) / np.linalg.norm(rhs, axis=0)))
    return [dict(name=f"K_C set-up and solve pair, 3-D block: {model.name}, {solver}", unknowns=int(K.shape[0]),
                 data_points=0, seconds=setup, floor_seconds=float("nan"), ratio=float("nan"), setup_seconds=setup,
                 solve_pair_seconds=pair, relative_residual=residual, nnz=int(K.nnz), **extra,
                 peak_memory_bytes=max(base, peak_resident_bytes()),
                 solver_memory_bytes=peak_resident_bytes() - resident)]


def reduction_record_3d(dofs: int, contact: bool, repeats: int, solver: str) -> list[dict]:
    """A reduced DDCM iteration (FB, :func:`ddcm_iteration`) on the 3-D block (:func:`block_3d`,
    about ``dofs`` dofs of ``K_C``) with or without contact, ``K_C`` solved by ``solver``
    (``"amg"``, or a direct solver of :mod:`ddcm_casadi.linalg`: ``"superlu"``, ``"pardiso"``; the
    build's scale solves too), against its floor (one solve pair with the kept factor or hierarchy
    plus the data search), with the build, the set-up of ``K_C`` and the ``nc`` back-solves of the
    Delassus matrices, and the peak memory."""
    if solver == "amg":
        linalg.use_definite_solver("amg")
    else:
        linalg.use_solver(solver)
    model = block_3d(divisions_3d(dofs), contact)
    rec = ddcm_iteration(model, repeats)
    peak = peak_resident_bytes()
    return [dict(name=f"reduced DDCM iteration, 3-D block {'with' if contact else 'without'} contact: {model.name}, "
                      f"{solver}", **rec,
                 dofs=rec["unknowns"] - model.n_points * model.strain_components - model.n_contacts,
                 material_points=model.n_points, contact_pairs=model.n_contacts, solver=solver,
                 peak_memory_bytes=peak)]


def linear_solvers(unknowns: int, repeats: int, colamd_limit: int) -> list[dict]:
    """One factorisation and solve of the 2-D continuum's projection piece (KKT) matrix (about
    ``unknowns`` unknowns, a third of the contact pairs closed) with every registered solver of
    :mod:`ddcm_casadi.linalg`, and with scipy's default SuperLU (COLAMD, partial pivoting) up to
    ``colamd_limit`` unknowns; ``floor_seconds``: the package's default (SuperLU, ordered by the
    pattern). Also the solve with a kept factor and a rank-``r`` update (:class:`ReferenceFactor`)
    for the ``r`` rows of one pair switching piece (built from its kept columns, then a solve)."""
    model = BUILD_MODELS["2-D continuum"](unknowns)
    problems = build_problems(model)
    system = registry.get("fischer_burmeister").build(problems.projection).system
    rj, _, jacobian, _ = system.branch_system()
    nc, mk = system.nc, model.n_points * model.strain_components
    P = problems.projection_params(model.n_steps - 1, np.zeros(mk), np.zeros(mk))
    z = system.start(np.zeros(problems.projection.n_x), np.zeros(nc), None)

    def piece(closed: int):
        branch = (np.arange(nc) < closed).astype(float)
        return jacobian(rj(z, system.piece_parameters.pack(P, branch=branch, corner=np.zeros(nc)))[1])

    A, A1 = piece(nc // 3), piece(nc // 3 + 1)
    b = np.cos(np.arange(A.shape[0]))
    n = int(A.shape[0])
    previous = linalg.solver_name()
    times = {}
    try:
        for name in linalg.available_solvers():
            linalg.use_solver(name)
            linalg.factorize(2.0 * sp.identity(4, format="csc"))  # untimed: loads the library (MKL)
            times[name] = median_time(lambda: linalg.factorize(A).solve(b), repeats)
            reference = ReferenceFactor(A)
            times[name + ", solve with a kept factor"] = median_time(lambda: reference.solve(b), max(3, repeats))
            up = reference.update(A1)
            if up is not None:
                times[name + f", low-rank update from kept columns and a solve (rank {up.rank})"] = median_time(
                    lambda: reference.update(A1).solve(b), max(3, repeats))
    finally:
        linalg.use_solver(previous)
    if n <= colamd_limit:
        times["scipy splu default (COLAMD)"] = median_time(lambda: spla.splu(A).solve(b), repeats)
    floor = times[previous]
    name = "linear solver, 2-D continuum projection KKT matrix: {}".format
    return ([dict(name=name(label), unknowns=n, data_points=0, seconds=t, floor_seconds=floor, ratio=t / floor,
                  nnz=int(A.nnz), note="floor: factorisation and solve with the default (auto: MUMPS from 5e3 unknowns, else SuperLU ordered by the pattern)")
             for label, t in times.items()]
            + [dict(name=name(label), unknowns=n, data_points=0, seconds=float("nan"), floor_seconds=floor,
                    ratio=float("nan"), nnz=int(A.nnz), error=f"not run: {reason}")
               for label, reason in linalg.unavailable_solvers().items()])


def stiffness_solvers(unknowns: int, repeats: int) -> list[dict]:
    """A definite block like the 2-D continuum projection's: one solve with the classical elastic
    stiffness ``K = B^T W D B`` (:meth:`~ddcm_casadi.models.base.ContactModel.stiffness`, free dofs) by
    the package's default (SuperLU, ordered by the pattern: ``floor_seconds``) against an algebraic
    multigrid preconditioned conjugate gradient (``pyamg``'s smoothed aggregation with the
    rigid-body modes as near-null space, relative residual 1e-10; setup and solve timed together,
    and each apart). Where no pair is in contact the DDCM projection splits into two solves with
    a matrix of this pattern and kind (``B^T W C B``, the metric ``C``): the choice an iterative
    solver of a reduced, definite system would face. Without ``pyamg`` installed the record says
    so (``error``)."""
    model = BUILD_MODELS["2-D continuum"](unknowns)
    K = model.stiffness().tocsc()
    b = np.cos(np.arange(K.shape[0]))
    n = int(K.shape[0])
    name = "linear solver, 2-D continuum stiffness K (definite block): {}".format
    note = "floor: factorisation and solve of K with the default (superlu, ordered by the pattern)"
    floor = median_time(lambda: linalg.factorize(K).solve(b), repeats)
    records = [dict(name=name("superlu (default)"), unknowns=n, data_points=0, seconds=floor, floor_seconds=floor,
                    ratio=1.0, nnz=int(K.nnz), note=note)]
    if importlib.util.find_spec("pyamg") is None:
        return records + [dict(name=name("pyamg smoothed aggregation + CG"), unknowns=n, data_points=0,
                               seconds=float("nan"), floor_seconds=floor, ratio=float("nan"), nnz=int(K.nnz),
                               error="not run: pyamg is not installed (pip install pyamg)")]
    import pyamg

    modes = model.near_null_space()
    Kr = K.tocsr()
    state = {}

    def setup():
        state["ml"] = pyamg.smoothed_aggregation_solver(Kr, B=modes, symmetry="symmetric")

    def solve():
        residuals = []
        state["x"] = state["ml"].solve(b, tol=1e-10, accel="cg", residuals=residuals)
        state["iterations"] = len(residuals) - 1

    t_setup = median_time(setup, repeats)
    t_solve = median_time(solve, repeats)
    error = float(np.linalg.norm(K @ state["x"] - b) / np.linalg.norm(b))
    t = t_setup + t_solve
    return records + [dict(name=name("pyamg smoothed aggregation + CG"), unknowns=n, data_points=0, seconds=t,
                           floor_seconds=floor, ratio=t / floor, nnz=int(K.nnz), note=note,
                           setup_seconds=t_setup, solve_seconds=t_solve, cg_iterations=state["iterations"],
                           relative_residual=error, operator_complexity=float(state["ml"].operator_complexity()),
                           pyamg_version=pyamg.__version__)]


PEAK_MEMORY = """
import sys, time
import numpy as np
from ddcm_casadi import MaterialDataset

def status(key):
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith(key)) / 1024

with open("/proc/self/clear_refs", "w") as fh:
    fh.write("5")  # reset the peak (VmHWM) to the current resident set
base = status("VmRSS:")
n = int(sys.argv[1])
t0 = time.perf_counter()
data = MaterialDataset.hookean(200e9, -0.01, 0.01, n, c=200e9)
build = time.perf_counter() - t0
strain = np.random.default_rng(1).uniform(-0.01, 0.01, 30_000)
t0 = time.perf_counter()
data.nearest(strain, 200e9 * strain)
query = time.perf_counter() - t0
tree = status("VmHWM:") - base
data.search("graph")  # the warm search's neighbour graph, built on first use
graph = status("VmHWM:") - base
print(build, query, tree, graph)
"""


def data_set_memory(n_data: int) -> dict:
    """Build time and peak memory of a data set and its KD-tree (and the warm search's
    neighbour graph), measured in a fresh process: the peak resident set size (Linux ``VmHWM``,
    reset after the imports) above the resident set after the imports."""
    out = subprocess.run([sys.executable, "-c", PEAK_MEMORY, str(n_data)], capture_output=True, text=True,
                         check=True)
    build, query, tree_mb, graph_mb = (float(v) for v in out.stdout.split())
    return dict(name=f"data set of {n_data:.0e} points: build and one query of 3e4 states", unknowns=30_000,
                data_points=n_data, seconds=build + query, floor_seconds=float("nan"), ratio=float("nan"),
                build_seconds=build, query_seconds=query, peak_memory_mb=tree_mb,
                peak_memory_with_graph_mb=graph_mb)


DATA_SIZE = """
import json, sys, time
import numpy as np
from ddcm_casadi import MaterialDataset
from ddcm_casadi.data.metric import Metric

def status(key):
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith(key)) * 1024

def reset_peak():
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")  # the peak (VmHWM) back to the current resident set

n, k, states, warm = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4] == "warm"
rng = np.random.default_rng(0)
metric = Metric(200e9) if k == 1 else Metric.isotropic(200e9, 0.3, 3)

def law(m):
    # one component: equally spaced as in the paper; six: random strains; stress = C strain
    e = np.linspace(-0.01, 0.01, m)[:, None] if k == 1 else rng.uniform(-0.01, 0.01, (m, k))
    return e, e @ metric.matrix.T

def seconds(fn):
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0

q_e, q_s = law(states) if k > 1 else (rng.uniform(-0.01, 0.01, states), None)
q_s = (q_e * 200e9 if k == 1 else q_s) * (1 + 0.01 * rng.standard_normal(q_e.shape))  # 1 % off the law
small = MaterialDataset(*law(10**4), metric)
out = dict(floor=seconds(lambda: small.nearest(q_e, q_s)))
del small
reset_peak()
base = status("VmRSS:")
strain, stress = law(n)
t0 = time.perf_counter()
data = MaterialDataset(strain, stress, metric)
out["build"] = time.perf_counter() - t0
out["cold"] = seconds(lambda: data.nearest(q_e, q_s))
out["peak"] = status("VmHWM:") - base
out["data_bytes"] = strain.nbytes + stress.nbytes
if warm:
    previous = data.nearest(q_e * (1 + 1e-4), q_s)
    out["graph"] = seconds(lambda: data.search("graph"))
    out["peak_with_graph"] = status("VmHWM:") - base
    stats = {}
    out["warm"] = seconds(lambda: data.nearest_warm(q_e, q_s, previous, stats=stats))
    out["certified"] = 1 - stats["fallbacks"] / stats["queries"]
print(json.dumps(out))
"""


def data_size(n_data: int, components: int, *, states: int, warm: bool) -> dict:
    """A data set of ``n_data`` points (one component: equally spaced on a Hookean line as in the
    paper; six: random Mandel strains of 3-D isotropic elasticity) in a fresh process: build
    seconds, cold KD-tree search of ``states`` states 1 % off the law (reported per 1e5 states)
    against the floor, the same search in a set of 1e4 points, and the peak resident memory
    above the imports (Linux ``VmHWM``), data arrays included. With ``warm``, also the warm
    search's neighbour graph (seconds, peak memory) and the warm search from the assignment of
    states moved by 1e-4 (relative), with the share of its answers certified without the tree."""
    cmd = [sys.executable, "-c", DATA_SIZE, str(n_data), str(components), str(states), "warm" if warm else "cold"]
    r = json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True).stdout)
    per = 1e5 / states
    rec = dict(name=f"data search, {n_data:.0e} points x {components} components: build, search of 1e5 states",
               unknowns=states, data_points=n_data, seconds=r["cold"] * per, floor_seconds=r["floor"] * per,
               ratio=r["cold"] / r["floor"], build_seconds=r["build"], search_seconds_per_1e5_states=r["cold"] * per,
               peak_memory_bytes=r["peak"], data_bytes=r["data_bytes"],
               peak_bytes_per_point=r["peak"] / n_data, note="floor: the same states against 1e4 points")
    if warm:
        rec.update(graph_seconds=r["graph"], peak_memory_with_graph_bytes=r["peak_with_graph"],
                   warm_search_seconds_per_1e5_states=r["warm"] * per, warm_certified_share=r["certified"])
    return rec


def certified_search(n_data: int, components: int, backends: str | None = None) -> list[dict]:
    """The certified searches (``benchmarks/ann_search.py``: the strip search for one component,
    over a float32 file, alone and through ``MaterialDataset`` (``dataset``), faiss's IVF for six,
    where installed) against the exact KD-tree, each
    backend in a fresh process: build seconds, seconds for 1e5 states near the data answered
    exactly, the share certified by the first search, agreement with an exact search on 200
    states (strips), memory. The floor is the KD-tree's search of the same states (``nan``
    where ``backends`` leaves it out: at 1e9 points it would need 46 GB)."""
    script = Path(__file__).resolve().parent / "ann_search.py"
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, str(script), str(n_data), "--components", str(components), "--out", tmp,
                        *(["--backends", backends] if backends else [])],
                       capture_output=True, text=True, check=True)
        rows = json.loads(next(Path(tmp).glob("ann_search_*.json")).read_text())
    floor = next((r["query_seconds"] for r in rows if r["backend"] == "kdtree" and "error" not in r), float("nan"))
    return [dict(name=f"certified search {r['backend']}, {n_data:.0e} points x {components} components, 1e5 states",
                 unknowns=r.get("queries", 100_000), data_points=n_data, seconds=r.get("query_seconds", float("nan")),
                 floor_seconds=floor, ratio=r.get("query_seconds", float("nan")) / floor, **r)
            for r in rows]


def fb_vs_qp(model, repeats: int, *, max_dofs: dict) -> list[dict]:
    """Classical path: FB Newton against the QP solvers of CasADi on the same model. Solve times
    only (each is built once beforehand); ``max_rel_difference_u`` is the distance to the FB
    solution, relative to ``max |u|``."""
    out = []
    problems = build_problems(model)
    n = model.n_dofs + model.n_contacts
    ref = None
    for predictor in (True, False, "condensed"):
        fb = registry.get("fischer_burmeister", active_set_predictor=bool(predictor))
        # condensed: on the contact pairs (build_classical), K's factor and D_u made at the build
        built = build_classical(fb, problems) if predictor == "condensed" else fb.build(problems.classical)

        def run():
            built.reset()  # cold factorisation cache: every repeat measures the same work
            return solve_classical(problems, built, "fischer_burmeister")

        res = run()
        t = median_time(run, repeats)
        u = res.array("u")
        if ref is None:
            ref, t_fb = (u, t)
        label = {True: "with active-set predictor", False: "plain semismooth Newton"}.get(
            predictor, "condensed on the contact pairs")
        out.append(dict(name=f"classical FB Newton ({label}), {model.name}", unknowns=n, data_points=0,
                        seconds=t, floor_seconds=t_fb, ratio=t / t_fb, converged=bool(res.converged),
                        newton_iterations=int(res.array("iterations").sum()), steps=model.n_steps,
                        path=res.projection_path,
                        max_rel_difference_u=float(np.max(np.abs(u - ref)) / np.max(np.abs(ref)))))
    for solver in ("highs", "osqp", "qpoases"):
        if model.n_dofs > max_dofs.get(solver, np.inf):
            out.append(dict(name=f"classical QP {solver}, {model.name}", unknowns=n, data_points=0,
                            seconds=float("nan"), floor_seconds=t_fb, ratio=float("nan"),
                            skipped=f"above {max_dofs[solver]} unknowns in this run (minutes per solve)"))
            continue
        try:
            qp = ContactQP(model, solver=solver)
        except Exception as exc:  # a plugin that cannot take the problem is reported, not fatal
            out.append(dict(name=f"classical QP {solver}, {model.name}", unknowns=n, data_points=0,
                            seconds=float("nan"), floor_seconds=t_fb, ratio=float("nan"), error=str(exc)))
            continue
        sol = qp.solve()
        t = median_time(qp.solve, repeats)
        err = float(np.max(np.abs(sol.u - ref))) / max(float(np.max(np.abs(ref))), 1e-300)
        out.append(dict(name=f"classical QP {solver}, {model.name}", unknowns=n, data_points=0, seconds=t,
                        floor_seconds=t_fb, ratio=t / t_fb, max_rel_difference_u=err,
                        converged=bool(sol.success.all()), steps=model.n_steps))
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
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-c", "import sys; from ddcm_casadi.commands.compare import main; sys.exit(main(sys.argv[1:]))",
               "--out", tmp]
        command = median_time(lambda: subprocess.run(cmd, check=True, capture_output=True), repeats)
    out = [dict(name="paper example: the whole `ddcm-compare --out DIR` command", unknowns=model.n_dofs,
                data_points=len(model.dataset), seconds=command, floor_seconds=total, ratio=command / total,
                note="process start, imports, 8 runs, results files and figures; floor = the 8 runs"),
           dict(name="paper example, all formulations x variants", unknowns=model.n_dofs, data_points=len(model.dataset),
                seconds=total, floor_seconds=total, ratio=1.0)]
    for (variant, name), r in cmp.results.items():
        t = r.build_seconds + r.solve_seconds
        per_step = r.solve_seconds / len(r.steps)
        its = float(np.sum(r.array("iterations")))
        solves = float(np.sum(r.array("outer_iterations"))) if variant == "ddcm" else float(len(r.steps))
        out.append(dict(name=f"paper example, {variant} {name}", unknowns=model.n_dofs, data_points=len(model.dataset),
                        seconds=t, floor_seconds=total, ratio=t / total, share=t / total,
                        seconds_per_step=per_step, seconds_per_solve=r.solve_seconds / max(solves, 1),
                        seconds_per_inner_iteration=r.solve_seconds / max(its, 1)))
    return out


def fclib_hyperstatic(contacts: int, freedoms: int) -> dict:
    """The default FCLIB method (:func:`~ddcm_casadi.drivers.fclib.solve_fclib`) on a generated
    problem: a body of ``freedoms`` freedoms (``M = I``, random ``H``) pressed onto ``contacts``
    sticking contacts, so ``W = H^T H`` is singular and the reactions are not unique (plain
    semismooth Newton stalls there); floor: projected Gauss-Seidel to the same 1e-8."""
    from ddcm_casadi.drivers.fclib import solve_fclib
    from ddcm_casadi.problems.fclib import GlobalProblem

    rng = np.random.default_rng(0)
    H = rng.normal(size=(freedoms, 3 * contacts))
    r_bar = np.column_stack([rng.uniform(1, 2, contacts), rng.uniform(-0.1, 0.1, (contacts, 2))]).ravel()
    local = GlobalProblem(sp.identity(freedoms, format="csr"), sp.csr_matrix(H), -H @ r_bar, np.zeros(3 * contacts),
                          rng.uniform(0.3, 0.8, contacts), "hyperstatic").local()
    s = solve_fclib(local, "default", tol=1e-8)
    ref = solve_fclib(local, "pgs", tol=1e-8, max_sweeps=100_000)
    return dict(name=f"FCLIB default method, generated hyperstatic problem, {contacts} contacts", unknowns=3 * contacts,
                data_points=0, seconds=s.seconds, floor_seconds=ref.seconds, ratio=s.seconds / ref.seconds,
                error=s.error, converged=s.converged, newton_iterations=s.iterations, stages="+".join(
                    st["stage"] for st in s.log), pgs_sweeps=ref.sweeps, pgs_error=ref.error)


def case_block(name: str, divisions: int):
    """An example case of ``ddcm_casadi.cases`` (``examples/cases``) on a uniform
    ``divisions x divisions`` mesh, without its grading."""
    from ddcm_casadi import cases
    from ddcm_casadi.casefiles.base import read_document
    from ddcm_casadi.casefiles.config import case_from_dict

    path = Path(cases.__file__).resolve().parent / name
    doc = read_document(path)
    doc["mesh"]["divisions"] = [divisions, divisions]
    doc["mesh"].pop("refine_near", None)
    return case_from_dict(doc, base_dir=path.parent, source=f"{path.stem} {divisions}x{divisions}").model


#: 2-D continua for the first DDCM solve, by the material points asked: without contact (the
#: hard-device block, 2 points per square) and with contact (the Hertz block, 6 per square).
FIRST_SOLVE_MODELS = {
    "without contact": lambda points: case_block("hard_device_block.toml", max(2, round((points / 2) ** 0.5))),
    "with contact": lambda points: case_block("hertz2d.toml", max(2, round((points / 6) ** 0.5))),
}


def first_solve_record(family: str, points: int) -> dict:
    """The first DDCM solve (FB) of a 2-D continuum of about ``points`` material points
    (:data:`FIRST_SOLVE_MODELS`), to be run in a fresh process: ``seconds`` the solver's set-up
    and its first solve of the load path, against the second solve of a new solver of the same
    problems (``floor_seconds``); ``build_seconds`` the problems and the formulation before them.
    The set-up builds nothing for a search it does not run (the exact branch enumeration: only
    affine problems with 1 to 4 contact pairs, on first use)."""
    model = FIRST_SOLVE_MODELS[family](points)
    t0 = time.perf_counter()
    problems = build_problems(model)
    built = registry.get("fischer_burmeister").build(problems.projection)
    t1 = time.perf_counter()
    solver = DDCMSolver(problems, built)
    setup = time.perf_counter() - t1
    first = solver.solve(formulation_name="fischer_burmeister")
    t2 = time.perf_counter()
    second = DDCMSolver(problems, built).solve(formulation_name="fischer_burmeister")
    again = time.perf_counter() - t2
    seconds = setup + first.solve_seconds
    return dict(name=f"first DDCM solve, 2-D continuum {family}: {model.name}", unknowns=problems.projection.n_x,
                data_points=len(model.dataset), seconds=seconds, floor_seconds=again, ratio=seconds / again,
                material_points=model.n_points, contact_pairs=model.n_contacts, build_seconds=t1 - t0,
                setup_seconds=setup, first_step_seconds=first.steps[0].seconds, converged=bool(first.converged),
                same_states=bool(all(np.array_equal(a.data_index, b.data_index)
                                     for a, b in zip(first.steps, second.steps))),
                note="seconds: set-up and first solve; floor: a second solver's solve of the same problems")


#: The searches of :func:`search_cost`: plain DDCM and the better search it is measured against.
SEARCH_COST_ROWS = ("plain", "restarts 1 (kick) + greedy")


def search_cost(noise_levels, seeds, repeats: int) -> list[dict]:
    """Restarts + greedy against plain DDCM on the noisy truss of the quality benchmark
    (``benchmarks/ddcm_quality.py``: a Warren truss with 3 contacts, 2001 noisy data, 7 load steps,
    FB), each run on freshly built problems as there (``compare``), the two alternated: per noise
    level, the seconds of each summed over the data sets (the fastest of ``repeats``, the least
    disturbed by other processes on a shared machine; wall time, and the process's CPU time),
    their ratio (issue 28's target: at most 3; ``median_ratio``: the same with the median of the
    repeats) and the ratio of ``Z_E`` projections. ``steps_not_worse``: steps whose restarts +
    greedy objective is at most plain's. ``cpu_ratio``, ``cpu_median_ratio``: the same with the
    process's CPU time."""
    from ddcm_quality import ddcm_objective, noisy_truss  # benchmarks/ is a folder of scripts
    from ddcm_casadi.validation.quality_rungs import CONFIGURATIONS

    out = []
    for noise in noise_levels:
        wall, cpu = {n: 0.0 for n in SEARCH_COST_ROWS}, {n: 0.0 for n in SEARCH_COST_ROWS}
        median, cpu_median = {n: 0.0 for n in SEARCH_COST_ROWS}, {n: 0.0 for n in SEARCH_COST_ROWS}
        projections, objective = {n: 0 for n in SEARCH_COST_ROWS}, {n: [] for n in SEARCH_COST_ROWS}
        for seed in seeds:
            model = noisy_truss(noise, seed)
            times, paths = {n: [] for n in SEARCH_COST_ROWS}, {}
            for _ in range(repeats):
                for name in SEARCH_COST_ROWS:
                    problems = build_problems(model)
                    built = registry.get("fischer_burmeister").build(problems.projection)
                    t0, c0 = time.perf_counter(), time.process_time()
                    path = DDCMSolver(problems, built, options=CONFIGURATIONS[name]).solve()
                    times[name].append((time.perf_counter() - t0, time.process_time() - c0))
                    paths[name] = path  # every repeat finds the same states
            for name in SEARCH_COST_ROWS:
                wall[name] += min(t[0] for t in times[name])
                cpu[name] += min(t[1] for t in times[name])
                median[name] += statistics.median(t[0] for t in times[name])
                cpu_median[name] += statistics.median(t[1] for t in times[name])
                projections[name] += sum(s.projections for s in paths[name].steps)
                objective[name].append(ddcm_objective(model, paths[name]))
        plain, better = SEARCH_COST_ROWS
        obj_plain, obj_better = np.concatenate(objective[plain]), np.concatenate(objective[better])
        out.append(dict(name=f"DDCM search cost: {better} / {plain}, noisy Warren truss, {noise:.0%} noise, "
                             f"{len(seeds)} data sets", unknowns=problems.projection.n_x, data_points=len(model.dataset),
                        seconds=wall[better], floor_seconds=wall[plain], ratio=wall[better] / wall[plain],
                        median_ratio=median[better] / median[plain],
                        cpu_seconds=cpu[better], cpu_floor_seconds=cpu[plain], cpu_ratio=cpu[better] / cpu[plain],
                        cpu_median_ratio=cpu_median[better] / cpu_median[plain],
                        projections_ratio=projections[better] / projections[plain],
                        steps_not_worse=int(np.sum(obj_better <= obj_plain * (1 + 1e-9))), steps=int(obj_plain.size),
                        note="seconds: restarts + greedy; floor: plain DDCM; target ratio <= 3"))
    return out


def markdown(records: list[dict]) -> str:
    lines = ["| name | unknowns | data points | seconds | floor s | ratio | notes |", "|---|---|---|---|---|---|---|"]
    skip = {"name", "unknowns", "data_points", "seconds", "floor_seconds", "ratio"}
    for r in records:
        notes = ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items() if k not in skip)
        lines.append(f"| {r['name']} | {r['unknowns']} | {r['data_points']} | {r['seconds']:.4g} | "
                     f"{r['floor_seconds']:.4g} | {r['ratio']:.3g} | {notes} |")
    return "\n".join(lines) + "\n"


#: The continuum examples of the full run's formulation records (benchmarks/continuum_timings.py).
CONTINUUM_CASES = ("hertz2d", "hertz3d", "nafems1", "two_spheres", "gmsh_cylinder_on_block", "sphere_shear3d")


def formulation_ratios(case: str) -> list[dict]:
    """Per variant and formulation on the example ``case``: the solve seconds (``seconds``) over
    Fischer-Burmeister's in the same variant (``floor_seconds``), issue 28's targets: the augmented
    Lagrangian at most 3, MPCC at most 10 (:func:`continuum_timings.case_timings`)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is a folder of scripts
    from continuum_timings import CLASSICAL_ONLY, case_timings

    variants = ("classical",) if case in CLASSICAL_ONLY else ("classical", "ddcm")
    rows = case_timings([case], variants, ("augmented_lagrangian", "fischer_burmeister", "mpcc"))
    fb = {r["variant"]: r["solve_seconds"] for r in rows if r["formulation"] == "fischer_burmeister"}
    return [dict(name=f"solve / FB solve, {case}, {r['variant']} {r['formulation']}", unknowns=r["unknowns"],
                 data_points=0, seconds=r["solve_seconds"], floor_seconds=fb[r["variant"]], ratio=r["ratio_to_fb"],
                 build_seconds=r["build_seconds"], cpu_seconds=r["cpu_seconds"], converged=r["converged"],
                 steps=r["steps"], iterations_per_step=r["iterations_per_step"])
            for r in rows if r["formulation"] != "fischer_burmeister"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="smaller sizes and fewer repeats (about 5 minutes)")
    ap.add_argument("--out", required=True, metavar="DIR")
    args = ap.parse_args(argv)
    out = prepare_output_dir(args.out)
    quick = args.quick
    rep = 3
    records: list[dict] = []

    def log(rec):
        records.append(rec)
        print(f"{rec['name']:<55} {rec['unknowns']:>8} {rec['data_points']:>9} {rec['seconds']:10.4g} s  "
              f"ratio {rec['ratio']:8.3g}", file=sys.stderr, flush=True)
        # written after every record: a run stopped or killed late (the full run takes hours) keeps
        # what it measured
        write_json_atomic(out / "benchmarks.json", records)
        write_bytes_atomic(out / "benchmarks.md", markdown(records).encode())

    for n in (300, 3000, 30000):
        model = stopped_bar(n, 10_000)
        log(dict(name=f"DDCM iteration, {model.name}", **ddcm_iteration(model, rep)))
    for panels in ((100, 1000, 8000) if quick else (100, 1000, 8000)):
        model = warren(panels, 10_000)
        log(dict(name=f"DDCM iteration, {model.name}", **ddcm_iteration(model, rep)))
    # The one-off build against one iteration's floor, 1e4 to 1e6 unknowns (issue 15).
    for family in BUILD_MODELS:
        for rec in build_sizes(family, (10**4, 10**5) if quick else (10**4, 10**5, 10**6), rep):
            log(rec)
    # DDCM on a 2-D continuum against its floors, and the linear solvers on its KKT matrix.
    for u in ((10**4, 10**5) if quick else (10**4, 10**5, 10**6)):
        for rec in in_fresh_process("linear_solvers", u, 1 if u > 10**5 else rep, 3 * 10**4,
                                    label=f"linear solvers, 2-D continuum, about {u:.0e} unknowns", unknowns=u):
            log(rec)
        for rec in in_fresh_process("stiffness_solvers", u, 1 if u > 10**5 else rep,
                                    label=f"stiffness solvers, 2-D continuum, about {u:.0e} unknowns", unknowns=u):
            log(rec)
        # PARDISO where pypardiso loads, and MUMPS, up to 1e5 unknowns: at 1e6 PARDISO's DDCM run
        # went past 24 GB (killed), where SuperLU's peaked at 14.4 GB.
        for solver in ("superlu", "pardiso", "mumps") if u <= 10**5 else ("superlu",):
            if solver in linalg.available_solvers():
                for rec in in_fresh_process("continuum_record", u, 1, solver, unknowns=u,
                                            label=f"DDCM iteration, 2-D continuum, about {u:.0e} unknowns, {solver}"):
                    log(rec)
    # The Kirchdoerfer-Ortiz reduction: a DDCM iteration against its cached-factor floor, with
    # and without contact, each in a fresh process; today's full path beside it up to 1e5 (at
    # 1e6 it costs 93 s an iteration). One BLAS thread: on a shared 2-core machine OpenBLAS's
    # threads spin, and a dense product of 1e4 entries stalled for 10-20 ms (0.3 ms alone).
    one_thread = ONE_THREAD
    for u in ((10**4, 10**5) if quick else (10**4, 10**5, 10**6)):
        for contact in (True, False):
            for rec in in_fresh_process("reduction_record", u, contact, 1 if u > 10**5 else rep, u <= 10**5,
                                        label=f"reduced DDCM iteration, 2-D continuum, about {u:.0e} unknowns",
                                        unknowns=u, env=one_thread):
                log(rec)
        for rec in in_fresh_process("reduction_factor", u, 1 if u > 10**5 else rep, env=one_thread,
                                    label=f"reduction factorisation, about {u:.0e} unknowns", unknowns=u):
            log(rec)
    # 3-D (issue 28, item 5): K_C by each solver, then a reduced DDCM iteration against its floor,
    # by dofs of K_C. 5e5 is the largest block whose build fits in 16 GB (about 10 GB); there only
    # AMG runs (a direct factor's fill grows like n^(4/3) in 3-D). SuperLU's minimum degree takes
    # more than 10 minutes and 7 GB at 1e5: up to 1e4. --quick: 1e5 by AMG alone, without contact.
    have_amg = importlib.util.find_spec("pyamg") is not None
    for dofs in ((10**4, 10**5) if quick else (10**4, 10**5, 5 * 10**5)):
        # MUMPS (METIS) up to 1e5 in both runs: 10 s and 1.3 GB of factor at 9.3e4 dofs
        solvers = [s for s in ("superlu", "pardiso", "mumps") if s in linalg.available_solvers()
                   and dofs <= (10**4 if s == "superlu" or (quick and s == "pardiso") else 10**5)] \
            + (["amg"] if have_amg else [])
        for solver in solvers:
            for rec in in_fresh_process("stiffness_solver_3d", dofs, solver, 1 if dofs > 10**4 else rep,
                                        label=f"K_C set-up and solve pair, 3-D block, about {dofs:.0e} dofs, {solver}",
                                        unknowns=dofs, env=one_thread):
                log(rec)
            for contact in (False,) if quick and dofs > 10**4 else (False, True):
                for rec in in_fresh_process("reduction_record_3d", dofs, contact, 1 if dofs > 10**4 else rep, solver,
                                            label=f"reduced DDCM iteration, 3-D block, about {dofs:.0e} dofs, {solver}",
                                            unknowns=dofs, env=one_thread):
                    log(rec)
    for n_data in ((10**4, 10**5, 10**6) if quick else (10**4, 10**5, 10**6, 10**7)):
        log(data_set_memory(n_data))
        model = stopped_bar(3000, n_data)
        cold = ddcm_iteration(model, rep)
        log(dict(name=f"DDCM iteration, {model.name}, {n_data:.0e} data", **cold))
        warm = ddcm_iteration(model, rep, search="warm", floor=False)
        log(dict(name=f"DDCM iteration, {model.name}, {n_data:.0e} data, warm search", **warm))
        log(dict(name=f"warm / cold data search, {model.name}, {n_data:.0e} data", unknowns=cold["unknowns"],
                 data_points=n_data, seconds=warm["search_seconds_per_iteration"],
                 floor_seconds=cold["search_seconds_per_iteration"],
                 ratio=warm["search_seconds_per_iteration"] / cold["search_seconds_per_iteration"],
                 overall_ratio=warm["seconds"] / cold["seconds"]))
    # Data size: 1-D sets with the warm search's graph; 6-D (3-D continua) cold only, as the
    # graph of all 6-D data takes minutes per 1e6 points (a KD-tree query of every datum).
    for n_data, k in (((10**6, 1), (10**6, 6)) if quick else
                      ((10**6, 1), (10**7, 1), (10**8, 1), (10**6, 6), (10**7, 6))):
        log(data_size(n_data, k, states=10**5 if k == 1 else 2 * 10**4, warm=k == 1))
    for n_data, k in (((10**6, 1), (10**5, 6)) if quick else
                      ((10**6, 1), (10**7, 1), (10**8, 1), (10**6, 6), (10**7, 6))):
        for rec in certified_search(n_data, k):
            log(rec)
    if not quick:  # issue 28: 1e9 one-component points, the strip search alone (12 GB + an 8 GB file in /tmp)
        for rec in certified_search(10**9, 1, backends="strips"):
            log(rec)
    for n in ((1000, 10_000) if quick else (1000, 10_000, 100_000)):
        # qpOASES (dense internals) and OSQP take minutes per path above these sizes.
        limits = dict(qpoases=3000, osqp=3000 if quick else 20_000)
        for rec in fb_vs_qp(stopped_bar(n, 10, steps=np.linspace(1.0, 0.97, 4)), rep, max_dofs=limits):
            log(rec)
    for rec in paper_shares(3):
        log(rec)
    log(fclib_hyperstatic(100, 120))
    sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/ is a folder of scripts
    from first_run import first_run

    log(first_run(5 if quick else 9))
    # Issue 28: the better DDCM search at its projection cost, and the first DDCM solve of a
    # continuum with no set-up for a search it does not run.
    for rec in search_cost((0.02,) if quick else (0.01, 0.02, 0.05), (0,) if quick else (0, 1, 2), rep):
        log(rec)
    for family in FIRST_SOLVE_MODELS:
        for rec in in_fresh_process("first_solve_record", family, 2 * 10**4,
                                    label=f"first DDCM solve, 2-D continuum {family}, about 2e4 points",
                                    unknowns=0):
            log(rec)
    # Issue 28: plain DDCM without contact against ddfenics on the same block, where a Python with
    # DOLFINx and ddfenicsx is given ($DDFENICS_PYTHON; benchmarks/ddfenics_block.py).
    from ddfenics_block import peer_record

    peer = os.environ.get("DDFENICS_PYTHON")
    if peer is None:
        print("no $DDFENICS_PYTHON: the ddfenics comparison is left out", file=sys.stderr)
    else:
        for n in ((50,) if quick else (50, 224)):
            log(peer_record(n, peer))
    # Issue 28, item 6: classical FB condensed on the contact pairs against PETSc SNESVI, where a
    # Python with petsc4py is given ($DDCM_PETSC_PYTHON; benchmarks/snesvi.py).
    import snesvi

    petsc = os.environ.get("DDCM_PETSC_PYTHON")
    if petsc is None:
        print("no $DDCM_PETSC_PYTHON: the SNESVI comparison is left out", file=sys.stderr)
    else:
        for divisions in (snesvi.SIZES[:1] if quick else snesvi.FULL_SIZES):
            log(snesvi.peer_record(divisions, petsc))
    # Issue 28, item 2: every formulation's solve time over Fischer-Burmeister's on the continuum
    # examples, classical and DDCM (one BLAS thread, a fresh process per case).
    for case in (("hertz2d",) if quick else CONTINUUM_CASES):
        for rec in in_fresh_process("formulation_ratios", case, label=f"formulations on {case}", unknowns=0,
                                    env={"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}):
            log(rec)
    print(f"wrote benchmarks.json and benchmarks.md to {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
