"""The paper's model kind: a 1-D bar of one element pushed by a moving rigid obstacle.

One unknown (the tip displacement ``u``), one material point (strain ``u / l0``) and one contact
pair with the gap ``g = w - u``, ``w = h - l0``. The classical solution, the penalty solution and
the exact projection of a datum onto ``Z_E`` are known in closed form (see the methods).

The model describes itself to the front ends (:meth:`BarModel.describe`,
:meth:`BarModel.penalty_closed_form`, :meth:`BarModel.save_figures`), and this module parses the
``[bar]`` case files (registered with :func:`ddcm_casadi.casefile.register_case_kind`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from . import casefile
from .casefile import Case
from .data import MaterialDataset, check_positive
from .errors import InputError
from .model import ContactModel
from .truss import bar_chain

#: The ``[bar]`` case-file format (also part of :mod:`ddcm_casadi.config`'s documentation).
CASE_FORMAT = """
The paper's bar
---------------
::

    [bar]
    length = 1.0            # m
    area = 1.0              # m^2 (default 1)
    youngs_modulus = 200e9  # Pa
    # elements = 10         # optional: an N-element bar (ddcm_casadi.truss.bar_chain)

    [obstacle]
    positions = [1.01, 1.0, 0.99]   # m, tip obstacle position, one per load step

    # [[stops]]             # optional, with elements >= 2: a rigid stop behind an interior node,
    # node = 3              # u_node >= -clearance
    # clearance = 0.004     # m

    [data]                  # either a CSV file with header strain,stress ...
    path = "data.csv"       # relative to this file
    # ... or generated Hookean data, as in the paper:
    # hookean = { strain_min = -0.05, strain_max = 0.01, points = 500 }   # E defaults to [bar]

    [ddcm]
    c = 300e9               # Pa
    max_outer = 100

    [formulations.penalty]  # optional per-formulation options
    gamma = 2e15            # Pa/m

Without ``elements`` and ``[[stops]]`` this is the one-unknown bar of the paper
(:func:`~ddcm_casadi.bar.bar_model`); with either it is
:func:`~ddcm_casadi.truss.bar_chain` (``elements`` defaults to 1).
"""


@dataclass(frozen=True, eq=False)
class BarModel(ContactModel):
    """The paper's 1-D bar against a moving rigid obstacle (one unknown: the tip displacement).

    Gap ``g = w - u`` with ``w = h - length``; strain ``u / length``; ``stress = -p``.
    """

    area: float = 1.0
    length: float = 1.0

    def closed_form(self, step: int):
        """``u = min(0, w)``, ``p = -E u / length`` (paper, eq. (1))."""
        if self.youngs_modulus is None:
            return None
        w = self.gap_offsets[step, 0]
        u = min(0.0, w)
        return np.array([u]), np.array([-self.youngs_modulus[0] * u / self.length])

    def penalty_closed_form(self, step: int, gamma: float):
        """Penalty solution: ``u = gamma w / (E/length + gamma)`` for ``w < 0``, else ``u = 0``."""
        w = self.gap_offsets[step, 0]
        k = self.youngs_modulus[0] / self.length
        u = gamma * w / (k + gamma) if w < 0 else 0.0
        return np.array([u]), np.array([gamma * max(0.0, u - w)])

    def projection_closed_form(self, step: int, strain_star: float, stress_star: float):
        """Exact projection of one data point onto ``Z_E``: the nearer of the free and contact branches.

        Returns ``(u, p, d2)`` with ``d2`` the squared DDCM distance per unit volume.
        """
        metric = self.dataset.metric
        w = self.gap_offsets[step, 0]
        L = self.length
        u_free, p_free = min(L * strain_star, w), 0.0
        u_cont, p_cont = w, max(0.0, -stress_star)

        def d2(u, p):  # strain u / L, stress -p
            return float(metric.distance2(u / L - strain_star, -p - stress_star)[0])

        cand = [(d2(u_free, p_free), u_free, p_free), (d2(u_cont, p_cont), u_cont, p_cont)]
        best = min(cand)
        return best[1], best[2], best[0]

    # ------------------------------------------------------------ self-description
    def describe(self) -> dict:
        """The bar's record in ``results.json``: ``length``, ``area``, ``youngs_modulus`` and the
        obstacle ``positions`` (one per step)."""
        return dict(length=self.length, area=self.area,
                    youngs_modulus=None if self.youngs_modulus is None else float(self.youngs_modulus[0]),
                    positions=self.load_parameter.tolist())

    def figures(self, cmp) -> dict:
        """The paper's Fig. 2: tip displacement and contact pressure against the obstacle position
        (:func:`ddcm_casadi.plots.figure_displacement`, :func:`~ddcm_casadi.plots.figure_pressure`)."""
        from .plots import figure_displacement, figure_pressure  # matplotlib only when a plot is drawn

        return {"fig2a_tip_displacement.png": lambda: figure_displacement(cmp),
                "fig2b_contact_pressure.png": lambda: figure_pressure(cmp)}


def bar_model(*, length: float, area: float = 1.0, youngs_modulus: float | None = None,
              positions, dataset: MaterialDataset | None = None, name: str = "bar") -> BarModel:
    """A 1-D bar of ``length`` fixed at ``x = 0`` and pushed by a rigid obstacle at ``x = h``.

    Parameters
    ----------
    length, area : float
        Undeformed length ``l0`` (m) and cross-section ``A`` (m^2).
    youngs_modulus : float, optional
        ``E`` (Pa) for the classical variant.
    positions : array_like
        Obstacle positions ``h`` (m), one per load step.
    dataset : MaterialDataset, optional
        Material data for the DDCM variant.
    """
    L = check_positive("length", length)
    A = check_positive("area", area)
    E = None if youngs_modulus is None else check_positive("youngs_modulus", youngs_modulus)
    h = np.asarray(positions, dtype=float).ravel()
    if h.size == 0:
        raise InputError("obstacle positions are empty")
    if not np.all(np.isfinite(h)):
        raise InputError("obstacle positions must be finite (no NaN or infinity)")
    return BarModel(
        strain_operator=sp.csr_matrix(np.array([[1.0 / L]])),
        volumes=np.array([A * L]),
        gap_operator=sp.csr_matrix(np.array([[-1.0]])),
        contact_area=np.array([A]),
        gap_offsets=(h - L)[:, None],
        loads=np.zeros((h.size, 1)),
        load_parameter=h,
        youngs_modulus=None if E is None else np.array([E]),
        dataset=dataset,
        length_scale=L,
        name=name,
        load_parameter_name="h",
        area=A,
        length=L,
    )


def paper_bar(*, n_data: int = 500, c: float = 300e9) -> BarModel:
    """The numerical example of the paper (Section 4).

    ``E = 200 GPa``, ``l0 = 1 m``, ``h`` from 1.01 m down to 0.99 m in 21 steps, 500 Hookean data
    points with strain in ``[-0.05, 0.01]`` and ``c = 300 GPa``.
    """
    E = 200e9
    data = MaterialDataset.hookean(E, -0.05, 0.01, n_data, c=c)
    return bar_model(length=1.0, area=1.0, youngs_modulus=E, positions=np.linspace(1.01, 0.99, 21),
                     dataset=data, name="paper bar")


# ------------------------------------------------------------------------------------- case files
def parse_case(doc: dict, *, base_dir: Path, source: str, name: str) -> Case:
    """Build the :class:`~ddcm_casadi.casefile.Case` of a ``[bar]`` document (see
    :data:`CASE_FORMAT`); section names and keys are checked already.

    Raises
    ------
    InputError
        A missing or invalid value (one line, naming the key).
    """
    if "obstacle" not in doc:
        raise InputError(f"missing section [obstacle] in {source}")
    bar = doc["bar"]
    for key in ("length", "youngs_modulus"):
        if key not in bar:
            raise InputError(f"missing key {key!r} in [bar]")
    length = casefile.positive("bar", "length", bar["length"])
    area = casefile.positive("bar", "area", bar.get("area", 1.0))
    E = casefile.positive("bar", "youngs_modulus", bar["youngs_modulus"])
    chain = "elements" in bar or "stops" in doc
    elements = casefile.integer("bar", "elements", bar.get("elements", 1), low=1, what="a positive integer")

    positions = doc["obstacle"].get("positions")
    if not isinstance(positions, list) or not positions:
        raise InputError("[obstacle] positions must be a non-empty list of numbers")
    h = np.array([casefile.number("obstacle", "positions", v) for v in positions])

    stops: dict[int, float] = {}
    for k, stop in enumerate(doc.get("stops", [])):
        label = f"stops {k}"
        for key in ("node", "clearance"):
            if key not in stop:
                raise InputError(f"missing key {key!r} in [{label}]")
        if elements < 2:
            raise InputError("[[stops]] tables need [bar] elements >= 2 (stops act on interior nodes)")
        node = casefile.integer(label, "node", stop["node"], low=1, high=elements - 1,
                                what="an interior node index")
        if node in stops:
            raise InputError(f"[{label}] node {node} has two stops")
        clearance = casefile.number(label, "clearance", stop["clearance"])
        if clearance < 0:
            raise InputError(f"[{label}] clearance must be >= 0, got {casefile.show(stop['clearance'])}")
        stops[node] = clearance

    if casefile.data_set_count(doc) > 1:
        raise InputError("[bar] cases take one [data] table (several data sets need a [structure])")
    specs = casefile.data_specs(doc, base_dir=base_dir, default_modulus=lambda k: E)
    max_outer, options = casefile.run_options(doc)

    dataset = specs[0].build() if specs else None
    if chain:
        model = bar_chain(length=length, elements=elements, area=area, youngs_modulus=E, tip_positions=h,
                          stops=stops, dataset=dataset, name=name)
    else:
        model = bar_model(length=length, area=area, youngs_modulus=E, positions=h, dataset=dataset, name=name)
    return Case(model=model, formulation_options=options, ddcm_max_outer=max_outer, source=source)


casefile.register_case_kind(
    "bar",
    sections={"bar": {"length", "area", "youngs_modulus", "elements"}, "obstacle": {"positions"},
              "stops": {"node", "clearance"}},
    arrays={"stops"}, parse=parse_case, uses="[obstacle] positions", default=True)
