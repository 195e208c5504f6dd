"""A Pratt truss footbridge settling onto three intermediate piers (2-D).

The physics: an 18 m, 12-panel Pratt truss (panels 1.5 m, height 2.25 m = span / 8) is pinned at
its left end and on a roller at its right end. Its chords are steel (``E = 200 GPa``,
``A = 4000 mm^2``), its verticals and diagonals aluminium (``E = 70 GPa``, ``A = 2000 mm^2``).
It carries its own weight and a deck load of 40 kN/m on the bottom chord, both growing with a
load factor from 0 to 1. Under the bottom-chord nodes at the quarter points and at midspan stand
rigid piers (planes ``y >= -clearance``, normal ``[0, 1]``) with clearances of 15, 30 and 20 mm.
As the bridge sags it lands first on the left pier, then on the right one and finally on the
midspan pier; each pier that touches takes part of the load and stiffens the bridge, which is
why the midspan pier, furthest from the undeformed chord, closes last although midspan sags most.

For DDCM each material has its own Hookean data set (metric ``c = E`` of that material): the
steel data cover ``|strain| <= 1e-3`` (chord strains stay below ``5e-4``), the aluminium data
``|strain| <= 2e-3`` (web strains stay below ``1.3e-3``), 2001 points each. The strain spacing of the data
bounds how closely DDCM can reproduce the classical member and contact forces (relative error of
order ``spacing / max strain``).

Run ``python examples/truss_bridge.py``: it prints the summary table and writes its figures to
``examples/output/truss_bridge/``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ddcm_casadi import MaterialDataset
from ddcm_casadi.drivers.harness import Comparison
from ddcm_casadi.outputs.save import compare_and_plot
from ddcm_casadi.models.truss import Obstacle, TrussModel, truss_model

NAME = "truss_bridge"
PANELS = 12
SPAN = 18.0  # m
HEIGHT = SPAN / 8
DECK_LOAD = 40e3  # N/m on the bottom chord at load factor 1
STEEL_DENSITY = 7850.0  # kg/m^3, also used for the aluminium members (a conservative self-weight)
PIERS = {3: 0.015, 9: 0.020, 6: 0.030}  # bottom-chord node: clearance (m)
STRAIN_LIMIT = {0: 1e-3, 1: 2e-3}  # per material: data range |strain| <= limit
CHORD, WEB = 0, 1  # material indices


def geometry(panels: int = PANELS, span: float = SPAN, height: float = HEIGHT
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nodes, members and member material of a Pratt truss.

    Bottom-chord nodes are ``0..panels`` (left to right), top-chord nodes ``panels + i`` above
    bottom node ``i`` for ``i = 1..panels-1``. The diagonals slope down towards midspan, so under
    gravity they are in tension and the verticals in compression (Pratt).
    """
    a = span / panels
    bottom = np.column_stack([a * np.arange(panels + 1), np.zeros(panels + 1)])
    top = np.column_stack([a * np.arange(1, panels), np.full(panels - 1, height)])
    nodes = np.vstack([bottom, top])

    def t(i: int) -> int:
        return panels + i

    chords = [(i, i + 1) for i in range(panels)] + [(t(i), t(i + 1)) for i in range(1, panels - 1)]
    chords += [(0, t(1)), (panels, t(panels - 1))]  # inclined end posts
    web = [(i, t(i)) for i in range(1, panels)]
    web += [(t(i), i + 1) for i in range(1, panels // 2)]
    web += [(t(i), i - 1) for i in range(panels // 2 + 1, panels)]
    members = np.array(chords + web, dtype=np.intp)
    material = np.array([CHORD] * len(chords) + [WEB] * len(web), dtype=np.intp)
    return nodes, members, material


def build_model(*, quick: bool = False) -> TrussModel:
    """The bridge, its piers, the load path and two data sets (``quick``: 6 steps, coarser data)."""
    nodes, members, material = geometry()
    area = np.where(material == CHORD, 4e-3, 2e-3)
    modulus = np.where(material == CHORD, 200e9, 70e9)
    loads = np.zeros_like(nodes)
    loads[1:PANELS, 1] = -DECK_LOAD * SPAN / PANELS  # deck load lumped on the inner bottom nodes
    weight = np.zeros_like(nodes[members[:, 0]])
    weight[:, 1] = -STEEL_DENSITY * 9.81 * area  # N/m along each member
    piers = [Obstacle(normal=[0.0, 1.0], offset=-clearance, nodes=[node]) for node, clearance in PIERS.items()]
    n_data = 401 if quick else 2001  # strain spacing 2 * limit / (n_data - 1)
    data = [MaterialDataset.hookean(E, -STRAIN_LIMIT[mat], STRAIN_LIMIT[mat], n_data, c=E)
            for mat, E in ((CHORD, 200e9), (WEB, 70e9))]
    return truss_model(nodes=nodes, members=members, area=area, youngs_modulus=modulus,
                       supports=[(0, "xy"), (PANELS, "y")], loads=loads, distributed_loads=weight,
                       obstacles=piers, load_factors=np.linspace(0.0, 1.0, 6 if quick else 41),
                       dataset=data, material=material, name="Pratt truss bridge on piers")


def max_abs_strain(cmp: Comparison, material: int | None = None) -> float:
    """Largest ``|strain|`` of one material (or all) over every run and step."""
    return cmp.max_abs_strain(None if material is None else geometry()[2] == material)


def main(out_dir: str | Path | None = None, *, quick: bool = False) -> Comparison:
    """Every formulation, classical and DDCM (``quick``: fewer steps and data, for the tests);
    the three figures go to ``out_dir`` if given."""
    return compare_and_plot(build_model(quick=quick), out_dir)


if __name__ == "__main__":
    t0 = time.perf_counter()
    result = main(Path(__file__).resolve().parent / "output" / NAME)
    print(result.table())
    for mat, label in ((CHORD, "chords (steel)"), (WEB, "web (aluminium)")):
        print(f"max |strain| {label}: {max_abs_strain(result, mat):.3g} (data range +-{STRAIN_LIMIT[mat]:g})")
    f = result.fields("classical", "fischer_burmeister")
    print("pier reactions at the last step [kN]:", np.round(f["contact_force"][-1] / 1e3, 1))
    print(f"wall time {time.perf_counter() - t0:.1f} s")
