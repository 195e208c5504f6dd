"""The ``[bar]`` case files: the paper's bar and N-element bars with stops (a registered case kind).

The case layer of :mod:`ddcm_casadi.models.bar`: this module reads the sections of a bar case and builds
the model with :func:`~ddcm_casadi.models.bar.bar_model` or :func:`~ddcm_casadi.models.truss.bar_chain`; the model
modules know nothing of case files. Registered with :func:`ddcm_casadi.casefiles.base.register_case_kind`
when imported (by :mod:`ddcm_casadi.casefiles.config`); it is the default kind.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ddcm_casadi.casefiles import common as casefile
from ddcm_casadi.casefiles.base import Case, register_case_kind
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.bar import bar_model
from ddcm_casadi.models.truss import bar_chain

#: The ``[bar]`` case-file format (also part of :mod:`ddcm_casadi.casefiles.config`'s documentation).
CASE_FORMAT = """
The paper's bar
---------------
::

    [bar]
    length = 1.0            # m
    area = 1.0              # m^2 (default 1)
    youngs_modulus = 200e9  # Pa
    # elements = 10         # optional: an N-element bar (ddcm_casadi.models.truss.bar_chain)
    # tip_displacement = [0.25, 0.5, 0.75, 1.0]   # instead of [obstacle]: a hard device displaces
                            # the tip, m, one value per load step (elements >= 2)

    [obstacle]
    positions = [1.01, 1.0, 0.99]   # m, tip obstacle position, one per load step

    # [[stops]]             # optional, with elements >= 2: a rigid stop behind an interior node,
    # node = 3              # u_node >= -clearance
    # clearance = 0.004     # m
    # side = "behind"       # or "ahead": a stop ahead of the node, u_node <= clearance

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
(:func:`~ddcm_casadi.models.bar.bar_model`); with either it is
:func:`~ddcm_casadi.models.truss.bar_chain` (``elements`` defaults to 1). With ``tip_displacement``
(a prescribed tip displacement, a hard device) it is :func:`~ddcm_casadi.models.truss.bar_chain`
with ``tip_displacements``, reporting per step the force the device exerts on the tip
(``hard_device_force_x(node N)``).
"""


# ------------------------------------------------------------------------------------- case files
def parse_case(doc: dict, *, base_dir: Path, source: str, name: str) -> Case:
    """Build the :class:`~ddcm_casadi.casefiles.base.Case` of a ``[bar]`` document (see
    :data:`CASE_FORMAT`); section names and keys are checked already.

    Raises
    ------
    InputError
        A missing or invalid value (one line, naming the key).
    """
    bar = doc["bar"]
    device = "tip_displacement" in bar
    if "obstacle" in doc and device:
        raise InputError("[obstacle] and [bar] tip_displacement both act on the bar's tip: give one "
                         "(stops on the way are [[stops]])")
    if "obstacle" not in doc and not device:
        raise InputError(f"missing section [obstacle] (or [bar] tip_displacement, a hard device) in {source}")
    for key in ("length", "youngs_modulus"):
        if key not in bar:
            raise InputError(f"missing key {key!r} in [bar]")
    length = casefile.positive("bar", "length", bar["length"])
    area = casefile.positive("bar", "area", bar.get("area", 1.0))
    E = casefile.positive("bar", "youngs_modulus", bar["youngs_modulus"])
    chain = "elements" in bar or "stops" in doc or device
    elements = casefile.integer("bar", "elements", bar.get("elements", 1), low=1, what="a positive integer")

    if device:
        values = bar["tip_displacement"]
        if not isinstance(values, list) or not values:
            raise InputError("[bar] tip_displacement must be a non-empty list of numbers (m), one per load step")
        h = np.array([casefile.number("bar", "tip_displacement", v) for v in values])
        if elements < 2:
            raise InputError("[bar] tip_displacement needs elements >= 2: a one-element bar with a prescribed tip "
                             "has no unknown left to solve for (its strain is the displacement over the length)")
    else:
        positions = doc["obstacle"].get("positions")
        if not isinstance(positions, list) or not positions:
            raise InputError("[obstacle] positions must be a non-empty list of numbers")
        h = np.array([casefile.number("obstacle", "positions", v) for v in positions])

    stops: dict[int, float] = {}
    ahead: dict[int, float] = {}
    for k, stop in enumerate(doc.get("stops", [])):
        label = f"stops {k}"
        for key in ("node", "clearance"):
            if key not in stop:
                raise InputError(f"missing key {key!r} in [{label}]")
        if elements < 2:
            raise InputError("[[stops]] tables need [bar] elements >= 2 (stops act on interior nodes)")
        node = casefile.integer(label, "node", stop["node"], low=1, high=elements - 1,
                                what="an interior node index")
        side = stop.get("side", "behind")
        if side not in ("behind", "ahead"):
            raise InputError(f"[{label}] side must be \"behind\" or \"ahead\", got {casefile.show(side)}")
        table = stops if side == "behind" else ahead
        if node in table:
            raise InputError(f"[{label}] node {node} has two stops {side}")
        clearance = casefile.number(label, "clearance", stop["clearance"])
        if clearance < 0:
            raise InputError(f"[{label}] clearance must be >= 0, got {casefile.show(stop['clearance'])}")
        table[node] = clearance

    if casefile.data_set_count(doc) > 1:
        raise InputError("[bar] cases take one [data] table (several data sets need a [structure])")
    specs = casefile.data_specs(doc, base_dir=base_dir, default_modulus=lambda k: E)
    max_outer, options = casefile.run_options(doc)

    dataset = specs[0].build() if specs else None
    if device:
        model = bar_chain(length=length, elements=elements, area=area, youngs_modulus=E, tip_displacements=h,
                          stops=stops, stops_ahead=ahead, dataset=dataset, name=name)
    elif chain:
        model = bar_chain(length=length, elements=elements, area=area, youngs_modulus=E, tip_positions=h,
                          stops=stops, stops_ahead=ahead, dataset=dataset, name=name)
    else:
        model = bar_model(length=length, area=area, youngs_modulus=E, positions=h, dataset=dataset, name=name)
    return Case(model=model, formulation_options=options, ddcm_max_outer=max_outer, source=source)


register_case_kind(
    "bar",
    sections={"bar": {"length", "area", "youngs_modulus", "elements", "tip_displacement"}, "obstacle": {"positions"},
              "stops": {"node", "clearance", "side"}},
    arrays={"stops"}, parse=parse_case, uses="[obstacle] positions", default=True)
