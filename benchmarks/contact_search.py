"""The cost of the contact search between two bodies, at 1e5 and 1e6 unknowns.

    python benchmarks/contact_search.py [--quick] [--out DIR]

Two boxes of tetrahedra stacked with non-matching meshes (the lower ``n x n x n/2`` cubes, the
upper ``(n-1) x (n-1) x (n-1)/2``), their touching faces a slave/master pair
(:mod:`ddcm_casadi.models.continuum.mortar`). Measured, per size, in one process:

- ``search``: the KD-tree of the master facets and the ball query of every slave facet
  (:func:`~ddcm_casadi.models.continuum.mortar.candidate_facets`);
- ``coupling``: the whole :func:`~ddcm_casadi.models.continuum.mortar.mortar_coupling` (search,
  the facing and distance filters, Sutherland-Hodgman clipping, quadrature, the sparse weights);
- ``strain operator``: :func:`~ddcm_casadi.models.continuum.fem.strain_operator` of the same mesh,
  the assembly every model build does anyway, as the yardstick (compare ratios within one run:
  the machines are shared and noisy).

``--quick``: about 1e5 unknowns only. Writes ``DIR/contact_search.json``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from ddcm_casadi.io import write_json_atomic
from ddcm_casadi.models.continuum import fem
from ddcm_casadi.models.continuum import mesh as meshes
from ddcm_casadi.models.continuum.bodies import join
from ddcm_casadi.models.continuum.mortar import Surface, candidate_facets, mortar_coupling

#: Cubes per edge of the lower box: about 1e5 and 1e6 unknowns (three per node) in the two boxes.
SIZES = {"1e5": 32, "1e6": 69}


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def measure(n: int) -> dict:
    (mesh, t_mesh) = _timed(lambda: join(dict(
        lower=meshes.box(1.0, 1.0, 0.5, nx=n, ny=n, nz=n // 2, origin=(0.0, 0.0, -0.5)),
        upper=meshes.box(1.0, 1.0, 0.5, nx=n - 1, ny=n - 1, nz=(n - 1) // 2, origin=(0.0, 0.0, 0.0)))))
    slave, master = mesh.boundaries["upper/zmin"], mesh.boundaries["lower/zmax"]
    x = mesh.p.T
    S, M = Surface.of(mesh, slave), Surface.of(mesh, master)
    reach = 0.05
    _, _, c_s = S.geometry(x)
    _, _, c_m = M.geometry(x)
    (cand, t_search) = _timed(lambda: candidate_facets(c_s, S.radii(x, c_s), c_m, M.radii(x, c_m), reach))
    (coupling, t_coupling) = _timed(lambda: mortar_coupling(x, S, M, reach))
    disc = fem.Discretisation.create(mesh, 1)
    (_, t_strain) = _timed(lambda: fem.strain_operator(disc))
    loads = np.asarray(coupling.master_weights.T @ coupling.area).ravel()
    return dict(cubes=n, unknowns=3 * mesh.p.shape[1], elements=mesh.t.shape[1], slave_facets=int(slave.size),
                master_facets=int(master.size), candidates=int(cand[0].size), facet_pairs=coupling.facet_pairs,
                pairs=int(coupling.nodes.size), mesh_seconds=t_mesh, search_seconds=t_search,
                coupling_seconds=t_coupling, strain_operator_seconds=t_strain,
                coupling_over_strain_operator=t_coupling / t_strain,
                patch_error=float(abs(loads.sum() - 1.0)))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="about 1e5 unknowns only")
    parser.add_argument("--out", type=Path, default=Path("benchmark-results"))
    args = parser.parse_args(argv)
    rows = {}
    print("| size | unknowns | slave facets | facet pairs | pairs | search s | coupling s | strain operator s | ratio |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, n in SIZES.items():
        if args.quick and label != "1e5":
            continue
        r = measure(n)
        rows[label] = r
        print(f"| {label} | {r['unknowns']} | {r['slave_facets']} | {r['facet_pairs']} | {r['pairs']} | "
              f"{r['search_seconds']:.3f} | {r['coupling_seconds']:.3f} | {r['strain_operator_seconds']:.2f} | "
              f"{r['coupling_over_strain_operator']:.3f} |", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "contact_search.json", rows)
    print(f"wrote {args.out / 'contact_search.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
