"""Coulomb friction against frictionless contact: the same meshes and paths, every formulation.

    python benchmarks/friction.py [--quick] [--out DIR]

Per formulation and variant, the frictional run of a continuum (``mu = 0.3``) against the same
run without friction (the ``friction`` key dropped): solve seconds, Newton iterations, seconds per
iteration and their ratios. 2-D: the Cattaneo-Mindlin cylinder (:mod:`ddcm_casadi.validation.mindlin`,
P2), pressed, then pulled sideways; 3-D: a rigid sphere pressed into a box, then moved sideways
(P1, two tangents per contact, no active-set predictor). The target of issue 26: a frictional
Newton step costs at most 2x a frictionless one. Timings are ratios within one run (the machine is
shared and noisy). Writes ``DIR/friction.json``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.data.metric import Metric, isotropic_elasticity
from ddcm_casadi.drivers.harness import compare
from ddcm_casadi.io import write_json_atomic
from ddcm_casadi.models.continuum import mesh as meshes
from ddcm_casadi.models.continuum.inputs import Contact, Material, Support
from ddcm_casadi.models.continuum.mesh_refinement import refine_near
from ddcm_casadi.models.continuum.model import continuum_model
from ddcm_casadi.models.continuum.obstacles import Ball, moving
from ddcm_casadi.validation.friction_rungs import frictional_formulations
from ddcm_casadi.validation.mindlin import mindlin_model


def sphere_model(divisions: int, friction: float | None, data: MaterialDataset | None = None):
    """A 10 mm box under a rigid sphere (R = 50 mm): pressed by 20 um in two steps, then moved
    sideways by 1 and 3 um; ``divisions`` cells along x and y (P1, graded once at the contact)."""
    mesh = meshes.box(0.01, 0.01, 0.01, nx=divisions, ny=divisions, nz=max(divisions * 2 // 3, 2),
                      origin=(-0.005, -0.005, -0.01))
    mesh = refine_near(mesh, (0.0, 0.0, 0.0), 0.0015, levels=1, shrink=1.0, buffer=2)
    motion = [[0.0, 0.0, -1e-5], [0.0, 0.0, -2e-5], [1e-6, 0.0, -2e-5], [3e-6, 0.0, -2e-5]]
    sphere = moving(Ball(center=(0.0, 0.0, 0.05), radius=0.05, name="sphere"), motion)
    return continuum_model(mesh, materials=[Material(youngs_modulus=200e9, poisson_ratio=0.3,
                                                     data=None if data is None else 0)],
                           supports=[Support("zmin", "xyz")], contacts=[Contact(sphere, "zmax", friction=friction)],
                           datasets=[] if data is None else [data], name="sphere sheared on a box")


def _totals(run) -> tuple[float, float, bool]:
    its = float(np.sum(run.array("iterations")))
    return run.solve_seconds, its, bool(all(s.converged for s in run.steps))


def pair_records(label: str, frictional, frictionless, variants=("classical",)) -> list[dict]:
    """Per formulation and variant: the frictional run against the frictionless one."""
    names = frictional_formulations()
    with_mu = compare(frictional, names, variants=variants, jobs=1)
    without = compare(frictionless, names, variants=variants, jobs=1)
    out = []
    for key, r in with_mu.results.items():
        t, its, ok = _totals(r)
        t0, its0, ok0 = _totals(without.results[key])
        out.append(dict(name=f"friction / frictionless, {label}, {key[0]} {key[1]}", unknowns=frictional.n_dofs,
                        data_points=0 if frictional.dataset is None else len(frictional.dataset), seconds=t,
                        floor_seconds=t0, ratio=t / t0, iterations=its, frictionless_iterations=its0,
                        seconds_per_iteration=t / max(its, 1), frictionless_seconds_per_iteration=t0 / max(its0, 1),
                        iteration_ratio=(t / max(its, 1)) / (t0 / max(its0, 1)), converged=ok,
                        frictionless_converged=ok0, contacts=frictional.n_contacts))
    return out


def friction_records(quick: bool, log=None) -> list[dict]:
    """The 2-D and 3-D pairs of runs (classical; DDCM on the 2-D one); ``log(record)`` as each
    pair of runs finishes."""
    records = _Logged(log)
    level = 4 if quick else 6
    records += pair_records(f"Cattaneo-Mindlin 2-D, level {level}", mindlin_model(level),
                            mindlin_model(level, friction=None))
    C = isotropic_elasticity(200e9, 0.49, 2)[0]
    data = MaterialDataset.hookean_grid(C, -0.012, 0.012, 61, c=Metric(C), grading=2)
    records += pair_records("Cattaneo-Mindlin 2-D, level 3, DDCM", _with_data(mindlin_model(3), data),
                            _with_data(mindlin_model(3, friction=None), data), variants=("ddcm",))
    divisions = 8 if quick else 14
    records += pair_records(f"sphere sheared on a box 3-D, {divisions} cells", sphere_model(divisions, 0.3),
                            sphere_model(divisions, None))
    return list(records)


class _Logged(list):
    """A list that hands every record added to ``log``."""

    def __init__(self, log) -> None:
        super().__init__()
        self._log = log

    def __iadd__(self, records):
        for r in records:
            self.append(r)
            if self._log is not None:
                self._log(r)
        return self


def _with_data(model, data: MaterialDataset):
    """``model`` with the material data ``data`` (for its DDCM runs)."""
    from dataclasses import replace

    return replace(model, dataset=data)


def print_row(r: dict) -> None:
    """One Markdown row of a record."""
    print(f"| {r['name'].split(', ', 1)[1]} | {r['unknowns']} | {r['contacts']} | {r['seconds']:.3g} | "
          f"{r['floor_seconds']:.3g} | {r['ratio']:.2f} | {r['iterations']:.0f} ({r['frictionless_iterations']:.0f}) | "
          f"{r['iteration_ratio']:.2f} | {r['converged']}/{r['frictionless_converged']} |", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path, default=Path("benchmark-results"))
    args = ap.parse_args(argv)
    print("| run | unknowns | contacts | seconds | frictionless s | ratio | iterations (frictionless) | "
          "s per iteration ratio | converged |")
    print("|---|---|---|---|---|---|---|---|---|")
    records = friction_records(args.quick, log=print_row)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "friction.json", records)
    print(f"wrote {args.out / 'friction.json'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
