"""Plain DDCM without contact against ddfenics, on the same discrete problem (issue 28, item 1).

    python benchmarks/ddfenics_block.py --out DIR [--divisions 50 224] [--peer-python PATH]

The problem: the Hertz example's body (a 20 mm square in plane strain, E = 200 GPa, nu = 0.3,
``x = 0`` fixes x, the bottom fixes x and y) without the indenter, P1 triangles on a uniform
``n x n`` grid (``2 n^2`` material points: 5 000 at ``n = 50``, 100 352 at ``n = 224``), a traction
of 1 GPa pressing the top, one load step; the example's Hookean data on the regular 21^3 grid of
Mandel strains with the isotropic metric. Both tools start every point from the zero state and run
the Kirchdoerfer-Ortiz alternation to its fixed point: here the reduced projection (``K_C``
factorised once, one solve pair per iteration; ``docs/maths.md`` section 17) and our KD-tree; in
ddfenics ``DDProblemInfinitesimalStrain`` (one MUMPS factorisation, two solves per iteration) and
scikit-learn's KD-tree.

Each tool runs in a fresh process (ours: this script with ``--ours``; ddfenics:
``benchmarks/peers/ddfenics_block.py`` under ``--peer-python``, a Python with DOLFINx 0.11 from the
``dolfinx-solver-real`` wheel, ``ddfenicsx`` and ``fetricksx``; without it only our side runs, and
the script says so). Records: seconds per iteration (ours: the alternation after the set-up, the
driver's checks included, also split into projection and search; ddfenics: its own timers of the
equilibrium and data projections, without its stopping test and the first call's compilation, and
``loop_seconds_per_iteration`` with them), set-up seconds, peak memory of each process, iterations, the
share of points on the same datum and the relative difference of the final distances
``sqrt(sum_i w_i |z_i - z*_i|^2_C)``. The machine is shared: compare the ratios of one run.
Writes ``DIR/ddfenics_block.json`` and ``DIR/ddfenics_block.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ddcm_casadi import formulations as registry
from ddcm_casadi.casefiles.config import case_from_dict
from ddcm_casadi.drivers.ddcm_options import DDCMOptions
from ddcm_casadi.drivers.ddcm_reduced import build_projection
from ddcm_casadi.drivers.path import DDCMSolver
from ddcm_casadi.heap import peak_resident_bytes
from ddcm_casadi.io import prepare_output_dir, write_bytes_atomic, write_json_atomic
from ddcm_casadi.problems.build import build_problems

PEER = Path(__file__).resolve().parent / "peers" / "ddfenics_block.py"
#: ddfenics' stopping test: the relative change of the distance between two iterations.
PEER_TOL = 1e-12
PEER_MAXIT = 1000


def block_model(divisions: int):
    """The block of the module docstring on a ``divisions x divisions`` grid."""
    doc = {
        "mesh": {"shape": "rectangle", "size": [0.02, 0.02], "divisions": [divisions, divisions],
                 "origin": [0.0, -0.02], "degree": 1},
        "material": {"youngs_modulus": 200e9, "poisson_ratio": 0.3},
        "supports": [{"boundary": "xmin", "fix": "x"}, {"boundary": "ymin", "fix": "xy"}],
        "loads": [{"boundary": "ymax", "traction": [0.0, -1e9]}],
        "data": {"hookean": {"strain_min": -0.012, "strain_max": 0.012, "points": 21}, "c": "isotropic"},
    }
    return case_from_dict(doc, source=f"block {divisions}x{divisions}, P1, traction 1 GPa").model


def distance(model, step) -> float:
    """``sqrt(sum_i w_i |z_i - z*_i|^2_C)`` of a converged step (ddfenics' ``global_dist``)."""
    local = model.dataset.distance2(step.strain, step.stress, step.data_index)
    return float(np.sqrt(np.sum(model.volumes * local)))


def ours(divisions: int, work: Path) -> dict:
    """Our side, in this (fresh) process: writes the peer's problem file and our assignment."""
    t0 = time.perf_counter()
    model = block_model(divisions)
    ds = model.dataset
    np.savez(work / "problem.npz", points=model.mesh.p.T, cells=model.mesh.t.T, strain=ds.strain, stress=ds.stress,
             C=ds.metric.matrix, traction=np.array([0.0, -1e9]), tol=PEER_TOL, maxit=PEER_MAXIT)
    zero = int(np.flatnonzero(np.all(ds.strain == 0.0, axis=1) & np.all(ds.stress == 0.0, axis=1))[0])
    problems = build_problems(model)
    built = build_projection(registry.get("fischer_burmeister"), problems)
    solver = DDCMSolver(problems, built, options=DDCMOptions(initial=(zero,) * model.n_points))
    setup = time.perf_counter() - t0
    path = solver.solve()
    step = path.steps[-1]
    np.save(work / "ours.npy", np.asarray(step.data_index, dtype=np.int64))
    its = int(step.outer_iterations)
    return dict(points=int(model.n_points), dofs=int(model.n_dofs), data_points=len(ds), iterations=its,
                solve_seconds=path.solve_seconds, seconds_per_iteration=path.solve_seconds / its,
                projection_seconds_per_iteration=step.projection_seconds / its,
                search_seconds_per_iteration=step.search_seconds / its, setup_seconds=setup,
                peak_memory_bytes=peak_resident_bytes(),
                converged=bool(path.converged), distance=distance(model, step),
                projection_path=path.projection_path)


def run_pair(divisions: int, peer_python: str | None) -> dict:
    """Ours, then the peer's, each in a fresh process, and how they compare."""
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        subprocess.run([sys.executable, __file__, "--ours", str(divisions), "--work", str(work)], check=True)
        rec = dict(divisions=divisions, ours=json.loads((work / "ours.json").read_text()))
        if peer_python is None:
            return rec
        subprocess.run([peer_python, "-W", "ignore", str(PEER), str(work / "problem.npz"), str(work / "peer.json"),
                        str(work / "peer.npy")], check=True, stdout=subprocess.DEVNULL)
        peer = json.loads((work / "peer.json").read_text())
        a, b = np.load(work / "ours.npy"), np.load(work / "peer.npy")
        o = rec["ours"]
        rec.update(ddfenics=peer, same_datum_share=float(np.mean(a == b)),
                   distance_relative_difference=abs(o["distance"] - peer["distance"]) / max(peer["distance"], 1e-300),
                   time_ratio=o["seconds_per_iteration"] / peer["seconds_per_iteration"],
                   memory_ratio=o["peak_memory_bytes"] / peer["peak_memory_bytes"])
        return rec


def peer_record(divisions: int, peer_python: str) -> dict:
    """:func:`run_pair` as a record of ``benchmarks/run.py``: ``seconds`` ours per iteration,
    ``floor_seconds`` ddfenics', ``ratio`` theirs (issue 28's target: at most 0.5)."""
    r = run_pair(divisions, peer_python)
    o, p = r["ours"], r["ddfenics"]
    return dict(name=f"DDCM iteration against ddfenics, 2-D block {divisions}x{divisions}, P1, no contact",
                unknowns=o["dofs"], data_points=o["data_points"], seconds=o["seconds_per_iteration"],
                floor_seconds=p["seconds_per_iteration"], ratio=r["time_ratio"], memory_ratio=r["memory_ratio"],
                peak_memory_bytes=o["peak_memory_bytes"], peer_peak_memory_bytes=p["peak_memory_bytes"],
                setup_seconds=o["setup_seconds"], peer_setup_seconds=p["setup_seconds"],
                iterations=o["iterations"], peer_iterations=p["iterations"], same_datum_share=r["same_datum_share"],
                distance_relative_difference=r["distance_relative_difference"],
                note="seconds: ddcm-casadi per iteration; floor: ddfenics per iteration; target ratio <= 0.5")


def markdown(records: list[dict]) -> str:
    rows = ["| points | dofs | iterations (ours / ddfenics) | s / iteration, ours (projection + search) | "
            "s / iteration, ddfenics (whole loop) | ratio | set-up s (ours / ddfenics) | peak GB (ours / ddfenics) | "
            "same datum | distance difference |", "|" + "---|" * 10]
    for r in records:
        o, p = r["ours"], r.get("ddfenics")
        if p is None:
            rows.append(f"| {o['points']} | {o['dofs']} | {o['iterations']} / - | {o['seconds_per_iteration']:.3g} "
                        f"({o['projection_seconds_per_iteration']:.3g} + {o['search_seconds_per_iteration']:.3g}) | - | - | "
                        f"{o['setup_seconds']:.3g} / - | {o['peak_memory_bytes'] / 1e9:.2f} / - | - | - |")
            continue
        rows.append(f"| {o['points']} | {o['dofs']} | {o['iterations']} / {p['iterations']} | "
                    f"{o['seconds_per_iteration']:.3g} ({o['projection_seconds_per_iteration']:.3g} + "
                    f"{o['search_seconds_per_iteration']:.3g}) | {p['seconds_per_iteration']:.3g} "
                    f"({p['loop_seconds_per_iteration']:.3g}) | "
                    f"**{r['time_ratio']:.2f}** | {o['setup_seconds']:.3g} / {p['setup_seconds']:.3g} | "
                    f"{o['peak_memory_bytes'] / 1e9:.2f} / {p['peak_memory_bytes'] / 1e9:.2f} | "
                    f"{r['same_datum_share']:.4f} | {r['distance_relative_difference']:.1e} |")
    return "\n".join(rows) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", metavar="DIR")
    ap.add_argument("--divisions", type=int, nargs="+", default=[50, 224])
    ap.add_argument("--peer-python", default=os.environ.get("DDFENICS_PYTHON"),
                    help="a Python with DOLFINx 0.11 and ddfenicsx (default: $DDFENICS_PYTHON)")
    ap.add_argument("--ours", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--work", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.ours is not None:
        work = Path(args.work)
        write_json_atomic(work / "ours.json", ours(args.ours, work))
        return 0
    if args.out is None:
        ap.error("--out DIR is required")
    out = prepare_output_dir(args.out)
    peer = args.peer_python
    if peer is None:
        print("ddfenics_block: no --peer-python (or $DDFENICS_PYTHON): only our side runs", file=sys.stderr)
    records = []
    for n in args.divisions:
        records.append(run_pair(n, peer))
        r = records[-1]
        print(f"block {n}x{n}: ours {r['ours']['seconds_per_iteration']:.3g} s/iteration"
              + (f", ddfenics {r['ddfenics']['seconds_per_iteration']:.3g} (ratio {r['time_ratio']:.2f}),"
                 f" same datum {r['same_datum_share']:.4f}" if "ddfenics" in r else ""), file=sys.stderr, flush=True)
    files = {"ddfenics_block.json": json.dumps(records, indent=1).encode(), "ddfenics_block.md": markdown(records).encode()}
    for name, data in files.items():
        write_bytes_atomic(out / name, data)
    print(f"wrote {' and '.join(files)} to {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
