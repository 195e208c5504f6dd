"""A continuum from the Python API: a cylinder pressed into a steel block (plane strain), classical
and DDCM, against Hertz.

The physics: a 20 mm x 10 mm steel block (``E = 200 GPa``, ``nu = 0.3``, P2 triangles) on a rigid
base is indented by a rigid cylinder of radius 50 mm moving down by up to 10 um. The classical
variant solves the linear law; DDCM sees only Hookean data in Mandel components (3 in plane
strain), on a grid graded towards zero strain. Each result is compared with Hertz at its own force
(:class:`~ddcm_casadi.models.continuum.hertz.HertzReference`), and the DDCM force with the
classical one: the Hertz columns cannot show an error of the force itself.

Run ``python examples/continuum_api.py`` (about 20 s; ``main(quick=True)``: 2 s): it prints the comparison table and the
forces and writes the VTU series and the figures to ``examples/output/continuum_api/``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ddcm_casadi import MaterialDataset, compare
from ddcm_casadi.data.metric import isotropic_elasticity
from ddcm_casadi.drivers.harness import Comparison
from ddcm_casadi.models.continuum import Circle, Contact, HertzReference, Material, Support, continuum_model, mesh
from ddcm_casadi.outputs.save import save_outputs

NAME = "continuum_api"
E, NU = 200e9, 0.3


def build_model(*, quick: bool = False):
    """The block, the cylinder's travel and the data (``quick``: a coarser mesh and grid)."""
    body = mesh.rectangle(0.02, 0.01, nx=12 if quick else 20, ny=6 if quick else 10, origin=(-0.01, -0.01))
    # The contact half-width is about 0.5 mm: grade the mesh towards the first point of contact.
    body = mesh.refine_near(body, (0.0, 0.0), 0.0015, levels=2 if quick else 3, shrink=1.0, buffer=3)
    stiffness = isotropic_elasticity(E, NU, 2)[0]
    data = MaterialDataset.hookean_grid(stiffness, -5e-3, 5e-3, 41 if quick else 81, c=stiffness, grading=2)
    cylinder = Circle((0.0, 0.05), 0.05, travel=np.linspace(0.0, 1e-5, 3 if quick else 5))
    return continuum_model(body, degree=2, materials=[Material(youngs_modulus=E, poisson_ratio=NU, data=0)],
                           supports=[Support("ymin", "xy")], contacts=[Contact(cylinder, "ymax")],
                           datasets=[data], reference=HertzReference(E, NU), name="cylinder on a block")


def main(out_dir: str | Path | None = None, *, quick: bool = False) -> Comparison:
    """Classical and DDCM with Fischer-Burmeister; outputs to ``out_dir`` if given."""
    cmp = compare(build_model(quick=quick), ["fischer_burmeister"])
    if out_dir is not None:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        save_outputs(cmp, out_dir)
    return cmp


def hertz(cmp: Comparison) -> dict[str, dict]:
    """Per run, the last step against Hertz at its own force
    (:meth:`~ddcm_casadi.models.continuum.hertz.HertzReference.measure`: ``force`` in N/m,
    ``error_p0``, ``error_a``, ...)."""
    model, out = cmp.model, {}
    for variant, name in cmp.results:
        f = cmp.fields(variant, name)
        out[f"{variant}/{name}"] = model.reference.measure(model, f["contact_pressure"][-1], f["stress"][-1])
    return out


if __name__ == "__main__":
    t0 = time.perf_counter()
    result = main(Path(__file__).resolve().parent / "output" / NAME)
    print(result.table())
    for run, m in hertz(result).items():
        print(f"{run}: force {m['force'] / 1e3:.1f} kN/m, against Hertz at that force: p0 {m['error_p0']:.1%}, "
              f"a {m['error_a']:.1%}")
    print(f"wall time {time.perf_counter() - t0:.1f} s")
