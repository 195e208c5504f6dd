"""Classical Signorini against an independent VI solver: ddcm-casadi's Fischer-Burmeister Newton
(active-set predictor, low-rank factor updates) against PETSc's reduced-space active-set VI Newton
(SNES ``vinewtonrsls``) with MUMPS, on the same discrete problem.

    python benchmarks/snesvi.py [--full] [--out DIR] [--peer-python PATH]

The problem is the Hertz example's body (:func:`run.continuum_block`, P2 plane strain, a rigid
cylinder pressed in over 5 steps; 1 step, its last, at 1e6): about 1e4 and 1e5 unknowns, and 1e6
with ``--full``. ddcm-casadi builds it, writes the free-dof stiffness ``K``, the gap operator,
gap offsets and loads to an ``.npz``, and solves it with every available sparse solver of
:mod:`ddcm_casadi.linalg`; ``benchmarks/peers/snesvi_peer.py``, run by a Python that has ``petsc4py``
(the ``dolfinx-solver-real`` wheel, Python >= 3.12; not a dependency of the package), solves the
same ``.npz`` with MUMPS in each tuning of :data:`PEER_TUNINGS`. Ours is built by
:func:`~ddcm_casadi.drivers.ddcm_reduced.build_classical`: condensed on the contact pairs (one
factorisation of ``K`` with the Delassus matrix, ``docs/maths.md`` section 17) where it applies,
its time counted with the solve; ``--also-full`` also solves on the full problem (the comparison
before and after). Each side runs in its own process
(its own peak memory); the solutions must agree to :data:`AGREEMENT` (``u`` relative to
``max |u|``, ``p`` relative to ``max p``). Also the time of one factorisation and solve of ``K``
with each solver on both sides (:func:`factor_times`, and the peer's ``factor`` mode), and of
ours with the Delassus matrix (what the condensed solve needs; issue 28's target: no slower than
MUMPS's factorisation). Every process runs with one thread (:data:`THREADS`).
``benchmarks/run.py`` takes one size at a time as a record (:func:`peer_record`).

``--full`` needs about 3.3 GB a process at 1e6 with MUMPS (the default from 5e3 unknowns) or
PARDISO (SuperLU did not fit under a 16 GB address-space cap): run it under the machine's memory
lock. Without the peer's Python (``--peer-python``, default ``$DDCM_PETSC_PYTHON`` or
``/work/venv-petsc/bin/python``) it prints one line and exits 0. Writes ``DIR/snesvi.json`` and
``DIR/snesvi.md``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ddcm_casadi import formulations as registry
from ddcm_casadi import linalg
from ddcm_casadi.drivers.ddcm_reduced import build_classical
from ddcm_casadi.heap import peak_resident_bytes
from ddcm_casadi.drivers.path import solve_classical
from ddcm_casadi.io import prepare_output_dir, write_bytes_atomic, write_json_atomic
from ddcm_casadi.problems.build import build_problems

HERE = Path(__file__).resolve().parent
#: Mesh divisions of the sizes (about ``8.1 d^2`` unknowns): 1e4, 9.7e4; ``--full`` adds 1e6.
SIZES = (35, 109)
FULL_SIZES = SIZES + (352,)
#: From this many divisions only the last load step is solved (the 1e6 run's cost and memory).
ONE_STEP_FROM = 200
#: MUMPS tunings of the peer: (``ICNTL(7)`` ordering, factor); 0 AMD, 5 METIS.
PEER_TUNINGS = ((0, "lu"), (5, "lu"), (0, "cholesky"), (5, "cholesky"))
#: At 1e6 the fastest only (METIS took 1.8x AMD's time at 1e5, LU 2x Cholesky's at 1e6: 372 s).
LARGE_PEER_TUNINGS = ((0, "cholesky"),)
#: The solutions agree when ``u`` and ``p`` differ by at most this relative to ``max |u|``, ``max p``.
AGREEMENT = 1e-10
DEFAULT_PEER = "/work/venv-petsc/bin/python"


def hertz_model(divisions: int):
    """:func:`run.continuum_block` of ``divisions`` without its material data (the classical
    problem alone is built: the DDCM projection's operators took 1.3 GB of the 5.3 GB peak at
    1e6 unknowns), reduced to its last load step from :data:`ONE_STEP_FROM` divisions on."""
    spec = importlib.util.spec_from_file_location("ddcm_benchmarks_run", HERE / "run.py")
    run = importlib.util.module_from_spec(spec)  # run.py is a sibling script, not a package module
    spec.loader.exec_module(run)
    model = run.continuum_block(divisions, data=False)
    if divisions >= ONE_STEP_FROM:
        model = replace(model, gap_offsets=model.gap_offsets[-1:], loads=model.loads[-1:],
                        load_parameter=model.load_parameter[-1:])
    return model


def write_problem(model, path: str) -> None:
    """The discrete problem the peer solves: ``K``, ``G``, contact areas, ``gap0`` and ``f``."""
    K, G = sp.csr_matrix(model.stiffness()), sp.csr_matrix(model.gap_operator)
    with open(path, "wb") as fh:
        np.savez(fh, n=model.n_dofs, nc=model.n_contacts, K_data=K.data, K_indices=K.indices, K_indptr=K.indptr,
                 G_data=G.data, G_indices=G.indices, G_indptr=G.indptr, area=model.contact_area,
                 gap0=model.gap_offsets, f=model.loads)


def ours(divisions: int, solver: str, problem: str | None, solution: str, condense: bool = True) -> dict:
    """Build the problem, solve its path with FB and the sparse solver ``solver``, write ``u`` and
    ``p`` per step to ``solution`` and the problem to ``problem`` (unless ``None``; after the
    peak memory is read). ``condense``:
    as :func:`~ddcm_casadi.drivers.ddcm_reduced.build_classical` selects (condensed on the contact
    pairs where it applies), else the full problem. ``seconds`` counts the condensation's
    factorisation and Delassus matrix (made at the build) with the solve: the work the peer does
    in its solve; ``build_seconds`` the rest of the build, ``model_seconds`` the model's (meshed
    and assembled) before it."""
    linalg.use_solver(solver)
    t0 = time.perf_counter()
    model = hertz_model(divisions)
    model_seconds = time.perf_counter() - t0
    t0 = time.perf_counter()
    problems = build_problems(model)
    built = build_classical(registry.get("fischer_burmeister"), problems, reduce=condense)
    reduction = getattr(built, "reduction", None)
    condensation = 0.0 if reduction is None else reduction.factor_seconds
    build = time.perf_counter() - t0 - condensation
    t0 = time.perf_counter()
    res = solve_classical(problems, built, "fischer_burmeister")
    seconds = time.perf_counter() - t0 + condensation
    # the peak before the peer's problem file is written: the file is the benchmark's, not the
    # solve's (writing it from this process took the peak at 1e6 from 3.27 to 3.38 GB)
    peak = peak_resident_bytes()
    if problem is not None:
        write_problem(model, problem)
    np.savez(solution, u=res.array("u"), p=res.array("p"))
    stats = built.stats
    return dict(unknowns=model.n_dofs + model.n_contacts, dofs=model.n_dofs, contacts=model.n_contacts,
                steps=model.n_steps, seconds=seconds, build_seconds=build, model_seconds=model_seconds,
                condensation_seconds=condensation,
                path=res.projection_path, converged=bool(res.converged),
                newton_iterations=int(res.array("iterations").sum()), factorisations=stats["factorizations"],
                updates=stats["updates"], solver=solver, peak_memory_bytes=peak)


#: The solvers to run (``--solvers``; empty: every one that runs here).
ONLY: list[str] = []
#: Also solve on the full problem, not condensed (``--also-full``: the comparison before/after).
ALSO_FULL: list[bool] = [False]


def solvers() -> list[str]:
    """The sparse solvers of :mod:`ddcm_casadi.linalg` that run here, but ``"auto"`` (one of them),
    restricted to :data:`ONLY` if given."""
    return [name for name in linalg.available_solvers() if name != "auto" and (not ONLY or name in ONLY)]


def factor_times(divisions: int, repeats: int, names: list[str] | None = None) -> dict:
    """Seconds of one factorisation and solve of the free-dof stiffness ``K`` with each solver of
    ``names`` (default :func:`solvers`; ``"auto"`` left out: it is one of them), and of what the
    condensed classical solve needs with the package's default (``"auto"``): the factor of ``K``
    and the Delassus matrix ``G K^-1 G^T`` (:func:`~ddcm_casadi.linalg.factorize_with_delassus`)
    and a solve (``delassus_seconds``). Median of ``repeats``; loading a library untimed."""
    model = hertz_model(divisions)
    K = sp.csc_matrix(model.stiffness())
    G = sp.csr_matrix(model.gap_operator)
    b = np.cos(np.arange(K.shape[0]))
    previous = linalg.solver_name()

    def median(name: str, make) -> float:
        linalg.use_solver(name)
        linalg.factorize(2.0 * sp.identity(4, format="csc"))  # loads the library (MKL)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            make().solve(b)
            times.append(time.perf_counter() - t0)
        return float(np.median(times))

    try:
        out = {name: median(name, lambda: linalg.factorize(K)) for name in (names or solvers()) if name != "auto"}
        delassus = median("auto", lambda: linalg.factorize_with_delassus(K, G)[0])
    finally:
        linalg.use_solver(previous)
    return dict(dofs=int(K.shape[0]), nnz=int(K.nnz), contacts=int(G.shape[0]), seconds=out,
                delassus_seconds=delassus, default=linalg.chosen_solver(K.shape[0]),
                delassus_default=linalg.delassus_solver(K.shape[0]))


#: Threads of every process (OpenMP, OpenBLAS, MKL): one, as both sides get on a 2-core machine
#: shared with other sessions (MKL's two threads made a PARDISO solve 1.6x slower under load).
THREADS = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}


def _run(cmd: list[str]) -> dict:
    """The JSON of the last line ``cmd`` prints (run with :data:`THREADS`), or its error."""
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=HERE, env={**os.environ, **THREADS})
    if proc.returncode:
        return dict(error=f"exit status {proc.returncode}: {(proc.stderr.strip().splitlines() or [''])[-1]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def fresh(function: str, *args) -> dict:
    """``function(*args)`` of this module in a fresh process (its own peak memory)."""
    return _run([sys.executable, str(HERE / "snesvi.py"), "--call", function, json.dumps(args)])


def peer(python: str, mode: str, problem: str, out: str, ordering: int, factor: str) -> dict:
    """``snesvi_peer.py`` in the peer's Python: PETSc SNESVI on ``problem`` (``mode`` ``"solve"``,
    its solution written to ``out``), or the time of a MUMPS factorisation and solve of ``K``
    (``"factor"``, median of ``out`` repeats)."""
    return _run([python, str(HERE / "peers" / "snesvi_peer.py"), mode, problem, out, str(ordering), factor])


def difference(a: str, b: str) -> dict:
    """The largest differences of ``u`` and ``p`` between two solutions, relative to ``max |u|``
    and ``max p`` of the first."""
    x, y = np.load(a), np.load(b)
    du = float(np.max(np.abs(x["u"] - y["u"])) / np.max(np.abs(x["u"])))
    dp = float(np.max(np.abs(x["p"] - y["p"])) / np.max(np.abs(x["p"])))
    return dict(u=du, p=dp, agree=bool(max(du, dp) <= AGREEMENT))


def compare_size(divisions: int, python: str, tmp: str, repeats: int, names: list[str] | None = None
                 ) -> list[dict]:
    """Every solver of ours (``names``, default :func:`solvers`) and every peer tuning on one size,
    and the per-factorisation times."""
    problem = os.path.join(tmp, f"problem{divisions}.npz")
    records = []
    reference = None
    names = names or solvers()
    for solver, condense in [(name, c) for name in names
                             for c in ((True, False) if ALSO_FULL[0] else (True,))]:
        solution = os.path.join(tmp, f"ours{divisions}-{solver}-{condense}.npz")
        rec = fresh("ours", divisions, solver, problem if reference is None else None, solution, condense)
        rec.update(side="ddcm-casadi FB" + ("" if condense else " (full)"), divisions=divisions, solver=solver)
        if "error" not in rec:
            chosen = (linalg.delassus_solver(rec["dofs"]) if rec["path"].startswith("condensed")
                      else linalg.chosen_solver(rec["unknowns"], symmetric=False))  # FB piece matrix
            rec["default"] = solver in ("auto", chosen)
        if "error" not in rec:
            reference = reference or solution
            rec["difference"] = difference(reference, solution)
        records.append(rec)
    if reference is None:
        return records
    tunings = PEER_TUNINGS if divisions < ONE_STEP_FROM else LARGE_PEER_TUNINGS
    for ordering, factor in tunings:
        solution = os.path.join(tmp, f"peer{divisions}-{ordering}{factor}.npz")
        rec = peer(python, "solve", problem, solution, ordering, factor)
        rec.update(side="PETSc vinewtonrsls + MUMPS", divisions=divisions, solver=f"mumps {factor} ICNTL(7)={ordering}")
        if "error" not in rec:
            rec["difference"] = difference(reference, solution)
        records.append(rec)
    large = divisions >= ONE_STEP_FROM
    factors = fresh("factor_times", divisions, 1 if large else repeats, names)
    for ordering, factor in tunings:
        rec = peer(python, "factor", problem, str(1 if large else repeats), ordering, factor)
        if "seconds" in rec:
            factors.setdefault("seconds", {})[f"PETSc mumps {factor} ICNTL(7)={ordering}"] = rec["seconds"]
            factors.setdefault("peer_peak_memory_bytes", {})[f"mumps {factor} ICNTL(7)={ordering}"] = \
                rec["peak_memory_bytes"]
    records.append(dict(side="factorisation of K", divisions=divisions, **factors))
    return records


def peer_record(divisions: int, python: str, repeats: int = 3) -> dict:
    """One size of :func:`compare_size` as a record of ``benchmarks/run.py``: ``seconds`` ours
    (the package's default solver, condensed on the contact pairs where that applies, the
    condensation counted), ``floor_seconds`` SNESVI's best converged tuning that agrees with ours,
    ``ratio`` ours over SNESVI's (issue 28's target: at most 1/3); ``factor_seconds`` our
    factorisation of ``K`` with the Delassus matrix and a solve, ``peer_factor_seconds``
    MUMPS's fastest factorisation and solve of ``K`` (target: ``factor_ratio`` at most 1)."""
    with tempfile.TemporaryDirectory() as tmp:
        records = compare_size(divisions, python, tmp, repeats, names=["auto"])
    name = f"classical FB against PETSc SNESVI, Hertz P2 {divisions} divisions"
    o = records[0]
    if "error" in o:
        return dict(name=name, unknowns=0, data_points=0, seconds=float("nan"), floor_seconds=float("nan"),
                    ratio=float("nan"), error=o["error"])
    theirs = [r for r in records[1:-1] if "error" not in r and r["converged"] and r["difference"]["agree"]]
    best = min(theirs, key=lambda r: r["seconds"], default=None)
    factors = records[-1] if records[-1]["side"] == "factorisation of K" else {}
    mumps = {k: v for k, v in factors.get("seconds", {}).items() if k.startswith("PETSc mumps")}
    peer_factor = min(mumps.values(), default=float("nan"))
    ours_factor = factors.get("delassus_seconds", float("nan"))
    rec = dict(name=name, unknowns=o["unknowns"], data_points=0, seconds=o["seconds"],
               floor_seconds=best["seconds"] if best else float("nan"),
               ratio=o["seconds"] / best["seconds"] if best else float("nan"),
               peak_memory_bytes=o["peak_memory_bytes"],
               peer_peak_memory_bytes=best["peak_memory_bytes"] if best else float("nan"),
               path=o["path"], converged=o["converged"], newton_iterations=o["newton_iterations"],
               condensation_seconds=o["condensation_seconds"], build_seconds=o["build_seconds"],
               peer_tuning=best["solver"] if best else None,
               peer_newton_iterations=best["newton_iterations"] if best else None,
               difference=best["difference"] if best else None, agree=bool(best and best["difference"]["agree"]),
               factor_seconds=ours_factor, peer_factor_seconds=peer_factor, factor_ratio=ours_factor / peer_factor,
               factor_solver=factors.get("delassus_default"),
               peer_factor_tuning=min(mumps, key=mumps.get) if mumps else None,
               peer_errors=[f"{r['solver']}: {r['error']}" for r in records[1:-1] if "error" in r],
               note="seconds: ours condensed (factor + Delassus + solve); floor: SNESVI's best tuning; "
                    "target ratio <= 1/3, factor_ratio <= 1")
    return rec


#: The functions :func:`fresh` runs in a fresh process.
CALLABLE = {"ours": ours, "factor_times": factor_times}


def markdown(records: list[dict]) -> str:
    lines = ["| divisions | side | solver | unknowns | seconds | Newton | factorisations (+updates) | "
             "peak memory GB | difference u / p |", "|---|---|---|---|---|---|---|---|---|"]
    for r in records:
        if r["side"] == "factorisation of K" or "error" in r:
            continue
        fac = (f"{r['factorisations']} + {r['updates']}" if "updates" in r else f"{r['numeric_factorisations']}")
        d = r.get("difference", {})
        lines.append(f"| {r['divisions']} | {r['side']} | {r['solver']} | {r.get('unknowns', '')} | {r['seconds']:.3g} | "
                     f"{r['newton_iterations']} | {fac} | {r['peak_memory_bytes'] / 1e9:.2f} | "
                     f"{d.get('u', float('nan')):.1e} / {d.get('p', float('nan')):.1e} |")
    lines += ["", "| divisions | dofs | solver | seconds (factorise + solve K) |", "|---|---|---|---|"]
    for r in records:
        if r["side"] == "factorisation of K" and "seconds" in r:
            lines += [f"| {r['divisions']} | {r['dofs']} | {k}{' (auto)' if k == r['default'] else ''} | {v:.3g} |"
                      for k, v in r["seconds"].items()]
            if "delassus_seconds" in r:
                lines.append(f"| {r['divisions']} | {r['dofs']} | {r['delassus_default']} (auto), with the "
                             f"Delassus matrix of {r['contacts']} pairs | {r['delassus_seconds']:.3g} |")
    errors = [f"- {r['side']} {r.get('solver', '')} at {r['divisions']}: {r['error']}" for r in records if "error" in r]
    errors += [f"- {r['side']} {r['solver']} at {r['divisions']}: the solutions differ by more than {AGREEMENT:g}"
               for r in records if not r.get("difference", {}).get("agree", True)]
    return "\n".join(lines + ([""] + errors if errors else [])) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="add the 1e6-unknown size (about 10 GB per process)")
    ap.add_argument("--out", default="benchmark-results", help="output folder")
    ap.add_argument("--peer-python", default=os.environ.get("DDCM_PETSC_PYTHON", DEFAULT_PEER))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--divisions", type=int, nargs="*", help="mesh divisions to run instead (about 8.1 d^2 unknowns)")
    ap.add_argument("--solvers", nargs="*", default=[], help="ddcm-casadi's sparse solvers to run (default: all)")
    ap.add_argument("--also-full", action="store_true", help="also solve ours on the full problem (not condensed)")
    ap.add_argument("--call", nargs=2, metavar=("FUNCTION", "JSON_ARGS"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.call:  # a fresh process of fresh(): one of CALLABLE, its record printed as JSON
        name, arguments = args.call
        if name not in CALLABLE:
            raise SystemExit(f"snesvi: --call takes one of {', '.join(CALLABLE)}")
        print(json.dumps(CALLABLE[name](*json.loads(arguments))))
        return 0
    ONLY[:] = args.solvers
    ALSO_FULL[0] = args.also_full
    if not os.path.exists(args.peer_python):
        print(f"snesvi: skipped, no Python with petsc4py at {args.peer_python} (--peer-python or DDCM_PETSC_PYTHON)")
        return 0
    out = prepare_output_dir(args.out)
    records = []
    with tempfile.TemporaryDirectory() as tmp:
        for divisions in args.divisions or (FULL_SIZES if args.full else SIZES):
            records += compare_size(divisions, args.peer_python, tmp, args.repeats)
            write_json_atomic(out / "snesvi.json", records)
    write_bytes_atomic(out / "snesvi.md", markdown(records).encode())
    print(markdown(records))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
