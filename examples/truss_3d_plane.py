"""A double-layer space grid pressed down onto a rigid floor ``z >= 0`` (3-D).

The physics: a steel double-layer grid (square-on-square offset, 6 x 3 modules of 1.5 m, depth
0.8 m; chords ``A = 1000 mm^2``, web diagonals ``A = 500 mm^2``, ``E = 200 GPa``) rests on four
corner columns. Its bottom layer hangs 8 mm above a rigid floor, the plane ``z = 0`` with normal
``[0, 0, 1]``. Loads on the top nodes (stored goods, heavier towards the ``+x, +y`` corner) grow
with a load factor from 0 to 1; the grid sags between its columns and four inner bottom-layer
nodes land on the floor one after another, each one shortening the spans and so slowing the sag
of the others.

Four contact candidates keep the problem small enough that the DDCM driver checks every
projection against the exact branch enumeration (at most four pairs, ``3^4`` branches).
For DDCM the steel data are Hookean with ``|strain| <= 1.5e-3`` (2001 points, metric ``c = E``);
the members stay within about ``1.1e-3``.

Run ``python examples/truss_3d_plane.py``: it prints the summary table and writes its figures to
``examples/output/truss_3d_plane/``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ddcm_casadi import MaterialDataset
from ddcm_casadi.drivers.harness import Comparison
from ddcm_casadi.outputs.save import compare_and_plot
from ddcm_casadi.models.truss import Obstacle, TrussModel, truss_model

NAME = "truss_3d_plane"
NX, NY = 6, 3  # modules along x and y
MODULE = 1.5  # m
DEPTH = 0.8  # m
CLEARANCE = 0.008  # m, bottom layer above the floor
TOP_LOAD = 25e3  # N per top node at load factor 1 (before the x, y gradient)
GRADIENT = (0.5, 1.0, 0.5, 1.0)  # load factor (a + b x / Lx) (c + d y / Ly) over the top nodes
CONTACT = [(2, 1), (4, 1), (2, 2), (4, 2)]  # bottom-layer (i, j) nodes that can touch the floor
STRAIN_LIMIT = 1.5e-3


def bottom(i: int, j: int) -> int:
    """Index of bottom-layer node ``(i, j)``, ``0 <= i <= NX``, ``0 <= j <= NY``."""
    return j * (NX + 1) + i


def top(i: int, j: int) -> int:
    """Index of top-layer node ``(i, j)`` above the centre of module ``(i, j)``."""
    return (NX + 1) * (NY + 1) + j * NX + i


def geometry() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nodes, members and a chord (0) / web (1) flag per member."""
    nodes = [(i * MODULE, j * MODULE, CLEARANCE) for j in range(NY + 1) for i in range(NX + 1)]
    nodes += [((i + 0.5) * MODULE, (j + 0.5) * MODULE, CLEARANCE + DEPTH) for j in range(NY) for i in range(NX)]
    chords = [(bottom(i, j), bottom(i + 1, j)) for j in range(NY + 1) for i in range(NX)]
    chords += [(bottom(i, j), bottom(i, j + 1)) for j in range(NY) for i in range(NX + 1)]
    chords += [(top(i, j), top(i + 1, j)) for j in range(NY) for i in range(NX - 1)]
    chords += [(top(i, j), top(i, j + 1)) for j in range(NY - 1) for i in range(NX)]
    web = [(top(i, j), bottom(i + di, j + dj)) for j in range(NY) for i in range(NX)
           for di, dj in ((0, 0), (1, 0), (0, 1), (1, 1))]  # each top node on the four below it
    members = np.array(chords + web, dtype=np.intp)
    kind = np.array([0] * len(chords) + [1] * len(web), dtype=np.intp)
    return np.array(nodes), members, kind


def build_model(*, quick: bool = False, contact=CONTACT, gradient=GRADIENT, strain_limit: float = STRAIN_LIMIT,
                load_factors=None) -> TrussModel:
    """The grid, its floor, the load path and the data (``quick``: 6 steps, coarser data).

    ``contact`` (bottom-layer ``(i, j)`` nodes), ``gradient``, ``strain_limit`` and
    ``load_factors`` vary the example (the tests use a ten-contact variant)."""
    nodes, members, kind = geometry()
    loads = np.zeros_like(nodes)
    for j in range(NY):
        for i in range(NX):
            # heavier towards +x, +y, so the inner nodes touch down at different load factors
            x, y = (i + 0.5) / NX, (j + 0.5) / NY
            loads[top(i, j), 2] = -TOP_LOAD * (gradient[0] + gradient[1] * x) * (gradient[2] + gradient[3] * y)
    corners = [bottom(0, 0), bottom(NX, 0), bottom(0, NY), bottom(NX, NY)]
    # pinned columns: no rigid-body motion (x, y fixed at one corner, y at the next), free to rotate
    supports = [(corners[0], "xyz"), (corners[1], "yz"), (corners[2], "z"), (corners[3], "z")]
    floor = Obstacle(normal=[0.0, 0.0, 1.0], offset=0.0, nodes=[bottom(i, j) for i, j in contact])
    n_data = 401 if quick else 2001
    data = MaterialDataset.hookean(200e9, -strain_limit, strain_limit, n_data, c=200e9)
    if load_factors is None:
        load_factors = np.linspace(0.0, 1.0, 6 if quick else 31)
    return truss_model(nodes=nodes, members=members, area=np.where(kind == 0, 1e-3, 5e-4),
                       youngs_modulus=200e9, supports=supports, loads=loads, obstacles=[floor],
                       load_factors=load_factors, dataset=data,
                       name="double-layer grid on a floor")



def main(out_dir: str | Path | None = None, *, quick: bool = False) -> Comparison:
    """Every formulation, classical and DDCM (``quick``: fewer steps and data, for the tests);
    the three figures go to ``out_dir`` if given."""
    return compare_and_plot(build_model(quick=quick), out_dir)


if __name__ == "__main__":
    t0 = time.perf_counter()
    result = main(Path(__file__).resolve().parent / "output" / NAME)
    print(result.table())
    print(f"max |strain| = {result.max_abs_strain():.3g} (data range +-{STRAIN_LIMIT:g})")
    f = result.fields("classical", "fischer_burmeister")
    print("floor contact forces at the last step [kN]:", np.round(f["contact_force"][-1] / 1e3, 1))
    print(f"wall time {time.perf_counter() - t0:.1f} s")
