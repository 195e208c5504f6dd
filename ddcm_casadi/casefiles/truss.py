"""The ``[structure]`` case files: pin-jointed trusses (a registered case kind).

The case layer of :mod:`ddcm_casadi.models.truss`: this module reads the sections of a truss case and
builds the model with :func:`~ddcm_casadi.models.truss.truss_model`; the model module knows nothing of
case files. Registered with :func:`ddcm_casadi.casefiles.base.register_case_kind` when imported (by
:mod:`ddcm_casadi.casefiles.config`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from ddcm_casadi.casefiles import common as casefile
from ddcm_casadi.casefiles.base import Case, register_case_kind
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.truss import AXES, Obstacle, member_data, truss_model

#: The ``[structure]`` case-file format (also part of :mod:`ddcm_casadi.casefiles.config`'s documentation).
CASE_FORMAT = """
Trusses
-------
::

    [structure]
    nodes = [[0.0, 0.0], [1.0, 0.0], [0.5, 0.8]]   # 1, 2 or 3 coordinates per node (m)
    members = [[0, 1], [1, 2], [0, 2]]             # node index pairs (nodes count from 0)
    area = 1e-3                 # m^2, one number or one per member
    youngs_modulus = 200e9      # Pa, one number or one per member; optional if DDCM only
    material = [0, 0, 1]        # optional: data set of each member (index into [[data]])
    supports = [[0, "xy"], [1, "y"]]               # (node, fixed axes from "xyz")
    # supports = [[0, "xy"], [1, "y", [0.0, -1e-3]]]  # a third entry prescribes the displacement (m)
                                 # of the fixed axes (a hard device): scaled by the load factors, or
                                 # one vector per step, [[0, -1e-3], [0, -2e-3]]; 0 along free axes
    loads = [[2, [0.0, -1e5]]]                     # (node, reference force vector N), optional
    distributed_loads = [["all", [0.0, -1e3]]]     # (member index or "all", N/m), optional

    [path]
    load_factors = [0.0, 0.5, 1.0]   # loads are scaled by these, one step each; optional if an
                                     # obstacle has per-step offsets (then the loads act in full)

    [[obstacles]]           # rigid planes n . x >= d, one table each (optional)
    normal = [0.0, 1.0]     # outward normal (normalised)
    offset = -0.002         # d (m), or offsets = [...] with one value per step
    nodes = [0, 1]          # the nodes that may touch it
    # friction = 0.3        # Coulomb friction (2-D, 3-D; absent: frictionless)

    [[data]]                # one table per material, in order; or a single [data] table
    hookean = { strain_min = -0.01, strain_max = 0.01, points = 2001 }   # or path = "file.csv"
    c = 200e9               # Pa, per data set; default [ddcm] c

A Hookean set's modulus defaults to the ``youngs_modulus`` of the members that use it. With
several data sets, ``material`` is required. The truss must not be a mechanism: members and
supports must restrain every free degree of freedom. The result is
:func:`~ddcm_casadi.models.truss.truss_model`.
"""


# ------------------------------------------------------------------------------------- case files
def _case_nodes(value: Any) -> np.ndarray:
    rows = casefile.nonempty_list("structure", "nodes", value)
    if all(not isinstance(r, list) for r in rows):
        rows = [[r] for r in rows]  # 1-D: bare coordinates
    if not all(isinstance(r, list) for r in rows):
        raise InputError("[structure] nodes must all be lists of coordinates (or all bare numbers in 1-D)")
    d = len(rows[0])
    if d not in (1, 2, 3):
        raise InputError(f"[structure] nodes[0] must have 1, 2 or 3 coordinates, got {len(rows[0])}")
    if len(rows) < 2:
        raise InputError("[structure] nodes must hold at least two nodes")
    X = np.empty((len(rows), d))
    for i, r in enumerate(rows):
        if len(r) != d:
            raise InputError(f"[structure] nodes[{i}] has {len(r)} coordinates, nodes[0] has {d}")
        X[i] = [casefile.number("structure", f"nodes[{i}]", v) for v in r]
    return X


def _case_members(value: Any, X: np.ndarray) -> np.ndarray:
    nn = X.shape[0]
    rows = casefile.nonempty_list("structure", "members", value)
    M = np.empty((len(rows), 2), dtype=np.intp)
    for k, r in enumerate(rows):
        if not isinstance(r, list) or len(r) != 2:
            raise InputError(f"[structure] members[{k}] must be a pair [node_i, node_j], got {casefile.show(r)}")
        for j in range(2):
            M[k, j] = casefile.integer("structure", f"members[{k}]", r[j], low=0, high=nn - 1, what="a node index")
        if M[k, 0] == M[k, 1] or not np.any(X[M[k, 0]] != X[M[k, 1]]):
            raise InputError(f"[structure] member {k} has zero length (nodes {M[k, 0]} and {M[k, 1]} coincide)")
    return M


def _case_supports(value: Any, nn: int, d: int) -> list[tuple]:
    out = []
    for k, entry in enumerate(casefile.nonempty_list("structure", "supports", value)):
        if not isinstance(entry, list) or len(entry) not in (2, 3) or not isinstance(entry[1], str):
            raise InputError(f"[structure] supports[{k}] must be [node, axes] such as [0, \"xy\"], or "
                             f"[node, axes, displacement], got {casefile.show(entry)}")
        node = casefile.integer("structure", f"supports[{k}]", entry[0], low=0, high=nn - 1, what="a node index")
        axes = entry[1].lower()
        bad = [a for a in axes if a not in AXES[:d]]
        if bad or not axes:
            raise InputError(f"[structure] supports[{k}] axes must be letters from {AXES[:d]!r} in {d}-D, "
                             f"got {casefile.show(entry[1])}")
        if len(entry) == 3:  # a hard device: checked against the load path by truss_model
            displacement = entry[2]
            if not isinstance(displacement, (list, int, float)) or isinstance(displacement, bool):
                raise InputError(f"[structure] supports[{k}] displacement must be {d} numbers or one list of "
                                 f"{d} numbers per step, got {casefile.show(displacement)}")
            out.append((node, axes, displacement))
        else:
            out.append((node, axes))
    return out


def _case_loads(value: Any, nn: int, d: int) -> np.ndarray:
    f = np.zeros((nn, d))
    for k, entry in enumerate(casefile.nonempty_list("structure", "loads", value, nonempty=False)):
        if not isinstance(entry, list) or len(entry) != 2:
            raise InputError(f"[structure] loads[{k}] must be [node, [force vector]], got {casefile.show(entry)}")
        node = casefile.integer("structure", f"loads[{k}]", entry[0], low=0, high=nn - 1, what="a node index")
        f[node] += casefile.vector("structure", f"loads[{k}] force", entry[1], d)
    return f


def _case_distributed_loads(value: Any, ne: int, d: int) -> np.ndarray:
    q = np.zeros((ne, d))
    for k, entry in enumerate(casefile.nonempty_list("structure", "distributed_loads", value, nonempty=False)):
        if not isinstance(entry, list) or len(entry) != 2:
            raise InputError(f"[structure] distributed_loads[{k}] must be [member or \"all\", [load vector]], "
                             f"got {casefile.show(entry)}")
        vec = casefile.vector("structure", f"distributed_loads[{k}] load", entry[1], d)
        if entry[0] == "all":
            q += vec
        elif isinstance(entry[0], str):
            raise InputError(f'[structure] distributed_loads[{k}] must name a member index or "all", '
                             f'got {casefile.show(entry[0])}')
        else:
            q[casefile.integer("structure", f"distributed_loads[{k}]", entry[0], low=0, high=ne - 1,
                       what="a member index")] += vec
    return q


def _case_obstacles(tables: list[dict], X: np.ndarray, M: np.ndarray, n_factors: int | None) -> list[Obstacle]:
    nn, d = X.shape
    connected = np.bincount(M.ravel(), minlength=nn) > 0
    steps = n_factors
    out = []
    for k, ob in enumerate(tables):
        label = f"obstacles {k}"
        for key in ("normal", "nodes"):
            if key not in ob:
                raise InputError(f"missing key {key!r} in [{label}]")
        if ("offset" in ob) == ("offsets" in ob):
            raise InputError(f"[{label}] needs exactly one of 'offset' or 'offsets'")
        normal = casefile.vector(label, "normal", ob["normal"], d)
        if not np.any(normal):
            raise InputError(f"[{label}] normal must be non-zero")
        nodes = [casefile.integer(label, "nodes", v, low=0, high=nn - 1, what="a node index")
                 for v in casefile.nonempty_list(label, "nodes", ob["nodes"])]
        if len(set(nodes)) != len(nodes):
            raise InputError(f"[{label}] nodes lists a node twice")
        loose = [n for n in nodes if not connected[n]]
        if loose:
            raise InputError(f"[{label}] node {loose[0]} belongs to no member")
        if "offset" in ob:
            offset: float | np.ndarray = casefile.number(label, "offset", ob["offset"])
        else:
            raw = casefile.nonempty_list(label, "offsets", ob["offsets"])
            offset = np.array([casefile.number(label, "offsets", v) for v in raw])
            if steps is None:
                steps = offset.size
            elif offset.size != steps:
                what = "[path] load_factors" if n_factors is not None else "the offsets of an earlier obstacle"
                raise InputError(f"[{label}] offsets has {offset.size} values but {what} has {steps} steps")
        friction = None
        if "friction" in ob:
            friction = casefile.number(label, "friction", ob["friction"])
            if friction < 0:
                raise InputError(f"[{label}] friction must be >= 0, got {friction:g}")
        out.append(Obstacle(normal=normal, offset=offset, nodes=nodes, friction=friction))
    return out


def _member_moduli(E: float | np.ndarray | None, material: np.ndarray | None, ne: int):
    """``default_modulus(k)``: the single modulus of the members using data set ``k``, or None."""
    def default(k: int) -> float | None:
        if E is None:
            return None
        if np.ndim(E) == 0:
            return float(E)
        users = np.arange(ne) if material is None else np.flatnonzero(material == k)
        values = np.unique(np.asarray(E)[users])
        return float(values[0]) if values.size == 1 else None
    return default


def parse_case(doc: dict, *, base_dir: Path, source: str, name: str) -> Case:
    """Build the :class:`~ddcm_casadi.casefiles.base.Case` of a ``[structure]`` document (see
    :data:`CASE_FORMAT`); section names and keys are checked already.

    Raises
    ------
    InputError
        A missing or invalid value, or a mechanism (one line, naming the key).
    """
    st = doc["structure"]
    for key in ("nodes", "members", "area", "supports"):
        if key not in st:
            raise InputError(f"missing key {key!r} in [structure]")
    X = _case_nodes(st["nodes"])
    nn, d = X.shape
    M = _case_members(st["members"], X)
    ne = M.shape[0]
    area = casefile.per_member("structure", "area", st["area"], ne)
    E = (casefile.per_member("structure", "youngs_modulus", st["youngs_modulus"], ne)
         if "youngs_modulus" in st else None)
    supports = _case_supports(st["supports"], nn, d)
    loads = _case_loads(st["loads"], nn, d) if "loads" in st else None
    q = _case_distributed_loads(st["distributed_loads"], ne, d) if "distributed_loads" in st else None

    factors = None
    if "load_factors" in doc.get("path", {}):
        raw = casefile.nonempty_list("path", "load_factors", doc["path"]["load_factors"])
        factors = np.array([casefile.number("path", "load_factors", v) for v in raw])
    obstacles = _case_obstacles(doc.get("obstacles", []), X, M, None if factors is None else factors.size)

    n_sets = casefile.data_set_count(doc)
    material = None
    if "material" in st:
        if n_sets == 0:
            raise InputError("[structure] material needs [data] (one [[data]] table per material)")
        raw = casefile.nonempty_list("structure", "material", st["material"])
        if len(raw) != ne:
            raise InputError(f"[structure] material must have one data-set index per member ({ne}), got {len(raw)}")
        material = np.array([casefile.integer("structure", f"material[{k}]", v, low=0, high=n_sets - 1,
                                               what="a data-set index") for k, v in enumerate(raw)], dtype=np.intp)
    elif n_sets > 1:
        raise InputError(f"[structure] material is required with {n_sets} [[data]] tables: "
                         "one data-set index per member")
    if E is None and n_sets == 0:
        raise InputError("[structure] needs youngs_modulus (classical variant) or [data] (DDCM variant)")
    specs = casefile.data_specs(doc, base_dir=base_dir, default_modulus=_member_moduli(E, material, ne),
                                no_default="its members have no single [structure] youngs_modulus to default to")
    max_outer, options = casefile.run_options(doc)

    geometry = dict(nodes=X, members=M, area=area, supports=supports, loads=loads, distributed_loads=q,
                    obstacles=obstacles, load_factors=factors, name=name)
    # The geometry alone first (a placeholder modulus, no data): truss_model finds mechanisms and
    # bad obstacles before any data file is read or data set generated; the data are added after.
    geom = truss_model(youngs_modulus=1.0 if E is None else E, **geometry)
    dataset = member_data([s.build() for s in specs] or None, material)
    model = dataclasses.replace(geom, youngs_modulus=None if E is None else geom.youngs_modulus, dataset=dataset)
    return Case(model=model, formulation_options=options, ddcm_max_outer=max_outer, source=source)


register_case_kind(
    "structure",
    sections={"structure": {"nodes", "members", "area", "youngs_modulus", "material", "supports", "loads",
                            "distributed_loads"},
              "path": {"load_factors"}, "obstacles": {"normal", "offset", "offsets", "nodes", "friction"}},
    arrays={"obstacles"}, parse=parse_case, uses="[path] and [[obstacles]]", default_name="truss",
    kinematics=("small", "finite"))
