"""Case files for ``ddcm-compare --config``: TOML (``.toml``) or JSON (``.json``), one schema.

A case is either the paper's bar (``[bar]``), optionally split into N elements with fixed stops,
or a pin-jointed truss in 1-D, 2-D or 3-D (``[structure]``). Both share ``[data]``, ``[ddcm]``
and ``[formulations.NAME]``.

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
    loads = [[2, [0.0, -1e5]]]                     # (node, reference force vector N), optional
    distributed_loads = [["all", [0.0, -1e3]]]     # (member index or "all", N/m), optional

    [path]
    load_factors = [0.0, 0.5, 1.0]   # loads are scaled by these, one step each; optional if an
                                     # obstacle has per-step offsets (then the loads act in full)

    [[obstacles]]           # rigid planes n . x >= d, one table each (optional)
    normal = [0.0, 1.0]     # outward normal (normalised)
    offset = -0.002         # d (m), or offsets = [...] with one value per step
    nodes = [0, 1]          # the nodes that may touch it

    [[data]]                # one table per material, in order; or a single [data] table
    hookean = { strain_min = -0.01, strain_max = 0.01, points = 2001 }   # or path = "file.csv"
    c = 200e9               # Pa, per data set; default [ddcm] c

A Hookean set's modulus defaults to the ``youngs_modulus`` of the members that use it. With
several data sets, ``material`` is required. The truss must not be a mechanism: members and
supports must restrain every free degree of freedom. The result is
:func:`~ddcm_casadi.truss.truss_model`.

JSON files use the same names: ``{"structure": {...}, "path": {...}, "obstacles": [{...}],
"data": [{...}], "ddcm": {...}, "formulations": {"penalty": {...}}}``.

Everything is validated before any work: unknown sections or keys are errors (a misspelt option
must not be silently ignored), every number must be finite, every index an integer in range, and
every error is an :class:`~ddcm_casadi.errors.InputError` with a one-line message naming the key.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from ddcm_casadi import formulations as registry

from .data import MAX_DATA_POINTS, MaterialDataset, check_positive
from .errors import InputError
from .bar import bar_model, paper_bar
from .model import ContactModel
from .truss import AXES, Obstacle, bar_chain, member_data, truss_model

#: Keys of each section (``None``: checked elsewhere). Sections in ``_ARRAYS`` are arrays of tables.
_SECTIONS: dict[str, set[str] | None] = {
    "bar": {"length", "area", "youngs_modulus", "elements"},
    "obstacle": {"positions"},
    "stops": {"node", "clearance"},
    "structure": {"nodes", "members", "area", "youngs_modulus", "material", "supports", "loads",
                  "distributed_loads"},
    "path": {"load_factors"},
    "obstacles": {"normal", "offset", "offsets", "nodes"},
    "data": {"path", "hookean", "c"},
    "ddcm": {"c", "max_outer"},
    "formulations": None,  # checked against the registry
}
_ARRAYS = {"stops", "obstacles"}
_BAR_ONLY = ("obstacle", "stops")
_STRUCTURE_ONLY = ("path", "obstacles")
_HOOKEAN = {"strain_min", "strain_max", "points", "youngs_modulus"}
_SUFFIXES = (".toml", ".json")


@dataclass
class Case:
    """A model plus run options read from a case file."""

    model: ContactModel
    formulation_options: dict[str, dict] = field(default_factory=dict)
    ddcm_max_outer: int = 100
    source: str = "paper example"


def default_case() -> Case:
    """The paper's numerical example (Section 4)."""
    return Case(model=paper_bar())


def _show(value: Any, limit: int = 60) -> str:
    """``repr(value)`` for a message: at most ``limit`` characters, safe for huge integers."""
    try:
        text = repr(value)
    except ValueError:  # an integer with more digits than Python will print
        return "<a number too large to print>"
    return text if len(text) <= limit else text[:limit - 3] + "..."


# ----------------------------------------------------------------------------------- scalar checks
def _number(section: str, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"[{section}] {key} must be a number, got {_show(value)}")
    try:
        v = float(value)
    except OverflowError:  # an integer beyond the float range (JSON integers are unbounded)
        v = math.inf
    if not math.isfinite(v):
        raise InputError(f"[{section}] {key} must be finite, got {_show(value)}")
    return v


def _positive(section: str, key: str, value: Any) -> float:
    return check_positive(f"[{section}] {key}", _number(section, key, value))


def _integer(section: str, key: str, value: Any, *, low: int | None = None, high: int | None = None,
             what: str = "an integer") -> int:
    """``value`` as an int in ``low..high`` (inclusive); booleans and floats are refused."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"[{section}] {key} must be {what}, got {_show(value)}")
    if (low is not None and value < low) or (high is not None and value > high):
        span = f"in {low}..{high}" if high is not None else f"(>= {low})"
        raise InputError(f"[{section}] {key} must be {what} {span}, got {_show(value)}")
    return value


def _list(section: str, key: str, value: Any, *, nonempty: bool = True) -> list:
    if not isinstance(value, list) or (nonempty and not value):
        raise InputError(f"[{section}] {key} must be a {'non-empty ' if nonempty else ''}list, got {_show(value)}")
    return value


def _vector(section: str, key: str, value: Any, d: int) -> np.ndarray:
    """A list of ``d`` finite numbers (a bare number when ``d == 1``)."""
    if d == 1 and not isinstance(value, list):
        value = [value]
    if not isinstance(value, list) or len(value) != d:
        raise InputError(f"[{section}] {key} must be a list of {d} numbers, got {_show(value)}")
    return np.array([_number(section, key, v) for v in value])


def _per_member(section: str, key: str, value: Any, ne: int) -> float | np.ndarray:
    """A positive number, or a list of one positive number per member."""
    if isinstance(value, list):
        if len(value) != ne:
            raise InputError(f"[{section}] {key} must be one number or one per member ({ne}), got {len(value)}")
        return np.array([_positive(section, f"{key}[{k}]", v) for k, v in enumerate(value)])
    return _positive(section, key, value)


# ------------------------------------------------------------------------------------ reading files
def _reject_duplicates(pairs: list[tuple[str, Any]]) -> dict:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise InputError(f"duplicate key {key!r} in JSON object")
        out[key] = value
    return out


def load_case(path: str | Path) -> Case:
    """Read and validate a case file (``.toml`` or ``.json``, same schema; see the module docstring).

    Parameters
    ----------
    path : str or Path
        The case file; relative data paths are resolved against its folder.

    Returns
    -------
    Case

    Raises
    ------
    InputError
        Missing, unreadable or malformed file, unknown suffix, or any invalid value (one line).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"config file not found: {path}")
    suffix = path.suffix.lower()
    if suffix not in _SUFFIXES:
        raise InputError(f"config file must be .toml or .json, got {path.suffix or 'no suffix'!r}: {path}")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"config file is not UTF-8 text: {path}") from None
    except OSError as exc:
        raise InputError(f"cannot read config file {path}: {exc.strerror or exc}") from None
    if suffix == ".toml":
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"malformed TOML in {path}: {exc}") from None
        except RecursionError:
            raise InputError(f"malformed TOML in {path}: nested too deeply") from None
    else:
        try:
            doc = json.loads(text, object_pairs_hook=_reject_duplicates)
        except json.JSONDecodeError as exc:
            raise InputError(f"malformed JSON in {path}: {exc}") from None
        except InputError as exc:
            raise InputError(f"{exc} in {path}") from None
        except ValueError as exc:  # e.g. an integer literal with more digits than Python converts
            raise InputError(f"malformed JSON in {path}: {exc}") from None
        except RecursionError:
            raise InputError(f"malformed JSON in {path}: nested too deeply") from None
        if not isinstance(doc, dict):
            raise InputError(f"the top level of {path} must be a JSON object of sections, got {type(doc).__name__}")
    return case_from_dict(doc, base_dir=path.parent, source=str(path))


def _check_sections(doc: dict, source: str) -> None:
    """Known sections with known keys only; tables where tables belong."""
    for section, value in doc.items():
        if section not in _SECTIONS:
            raise InputError(f"unknown section [{section}] in {source}; known: {', '.join(_SECTIONS)}")
        keys = _SECTIONS[section]
        if section in _ARRAYS:
            if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
                raise InputError(f"[[{section}]] must be an array of tables")
            tables = value
        elif section == "data" and isinstance(value, list):
            if not value or not all(isinstance(v, dict) for v in value):
                raise InputError("[[data]] must be a table or a non-empty array of tables")
            tables = value
        elif isinstance(value, dict):
            tables = [value]
        else:
            raise InputError(f"[{section}] must be a table")
        if keys is not None:
            for k, table in enumerate(tables):
                unknown = sorted(set(table) - keys)
                if unknown:
                    numbered = section in _ARRAYS or len(tables) > 1  # as the other messages name them
                    where = f"{section} {k}" if numbered else section
                    raise InputError(f"unknown key {unknown[0]!r} in [{where}]; known: {', '.join(sorted(keys))}")


def case_from_dict(doc: dict, *, base_dir: Path = Path("."), source: str = "<dict>") -> Case:
    """Validate a parsed case document and build its :class:`Case`.

    Parameters
    ----------
    doc : dict
        The parsed TOML or JSON document.
    base_dir : Path
        Folder against which relative data paths are resolved.
    source : str
        Where the document came from (for messages and the model name).
    """
    _check_sections(doc, source)
    if "bar" in doc and "structure" in doc:
        raise InputError(f"[bar] and [structure] cannot be combined in {source}; a case has one or the other")
    if "structure" in doc:
        for s in _BAR_ONLY:
            if s in doc:
                raise InputError(f"[{s}] belongs to [bar] cases; a [structure] uses [path] and [[obstacles]]")
    elif "bar" in doc:
        for s in _STRUCTURE_ONLY:
            if s in doc:
                raise InputError(f"[{s}] belongs to [structure] cases; a [bar] uses [obstacle] positions")
    elif any(s in doc for s in _STRUCTURE_ONLY):
        raise InputError(f"missing section [structure] in {source}")
    else:
        raise InputError(f"missing section [bar] in {source}")
    name = Path(source).stem if source != "<dict>" else None
    if "bar" in doc:
        return _bar_case(doc, base_dir=base_dir, source=source, name=name or "bar")
    return _structure_case(doc, base_dir=base_dir, source=source, name=name or "truss")


# ----------------------------------------------------------------------------------- shared pieces
@dataclass
class _DataSpec:
    """A validated data-set description, built into a :class:`MaterialDataset` after all checks."""

    label: str
    c: float
    path: Path | None = None
    youngs_modulus: float | None = None
    strain_min: float = 0.0
    strain_max: float = 0.0
    points: int = 0

    def build(self) -> MaterialDataset:
        if self.path is not None:
            return MaterialDataset.from_csv(self.path, c=self.c)
        return MaterialDataset.hookean(self.youngs_modulus, self.strain_min, self.strain_max, self.points, c=self.c)


def _data_specs(doc: dict, *, base_dir: Path, default_modulus) -> list[_DataSpec]:
    """Validate ``[data]`` / ``[[data]]`` (no file is read yet).

    ``default_modulus(k)`` is the Hookean modulus of set ``k`` when the table gives none, or
    ``None`` if there is no single one (then the table must give it).
    """
    ddcm = doc.get("ddcm", {})
    data_doc = doc.get("data")
    ddcm_c = _positive("ddcm", "c", ddcm["c"]) if "c" in ddcm else None
    if data_doc is None:
        return []
    tables = data_doc if isinstance(data_doc, list) else [data_doc]
    specs = []
    for k, table in enumerate(tables):
        label = "data" if len(tables) == 1 else f"data {k}"
        if "c" in table:
            c = _positive(label, "c", table["c"])
        elif ddcm_c is not None:
            c = ddcm_c
        else:
            raise InputError(f"[{label}] needs the metric: add [ddcm] c = ... (Pa)")
        if ("path" in table) == ("hookean" in table):
            raise InputError(f"[{label}] needs exactly one of 'path' or 'hookean'")
        if "path" in table:
            if not isinstance(table["path"], str):
                raise InputError(f"[{label}] path must be a string")
            specs.append(_DataSpec(label, c, path=base_dir / table["path"]))
            continue
        hk = table["hookean"]
        if not isinstance(hk, dict):
            raise InputError(f"[{label}] hookean must be a table {{strain_min, strain_max, points}}")
        unknown = sorted(set(hk) - _HOOKEAN)
        if unknown:
            raise InputError(f"unknown key {unknown[0]!r} in [{label}] hookean; known: {', '.join(sorted(_HOOKEAN))}")
        missing = [key for key in ("strain_min", "strain_max", "points") if key not in hk]
        if missing:
            raise InputError(f"missing key {missing[0]!r} in [{label}] hookean")
        points = _number(label, "hookean.points", hk["points"])
        if points != int(points) or points < 1:
            raise InputError(f"[{label}] hookean.points must be a positive integer, got {_show(hk['points'])}")
        if points > MAX_DATA_POINTS:
            raise InputError(f"[{label}] number of data points must be between 1 and {MAX_DATA_POINTS}, "
                             f"got {_show(hk['points'])}")
        if "youngs_modulus" in hk:
            E = _positive(label, "hookean.youngs_modulus", hk["youngs_modulus"])
        else:
            E = default_modulus(k)
            if E is None:
                raise InputError(f"[{label}] hookean needs youngs_modulus (its members have no single "
                                 "[structure] youngs_modulus to default to)")
        lo = _number(label, "hookean.strain_min", hk["strain_min"])
        hi = _number(label, "hookean.strain_max", hk["strain_max"])
        if lo > hi:
            raise InputError(f"[{label}] hookean.strain_min must be <= strain_max, got [{lo}, {hi}]")
        specs.append(_DataSpec(label, c, youngs_modulus=E, strain_min=lo, strain_max=hi, points=int(points)))
    return specs


def _run_options(doc: dict) -> tuple[int, dict[str, dict]]:
    """``[ddcm] max_outer`` and the per-formulation options (validated against the registry)."""
    max_outer = _integer("ddcm", "max_outer", doc.get("ddcm", {}).get("max_outer", 100), low=1,
                         what="a positive integer")
    options: dict[str, dict] = {}
    for fname, opts in doc.get("formulations", {}).items():
        if not isinstance(opts, dict):
            raise InputError(f"[formulations.{fname}] must be a table of options")
        registry.get(fname, **opts)  # validates the name and every option now, before any work
        options[fname] = dict(opts)
    return max_outer, options


# ---------------------------------------------------------------------------------------------- bar
def _bar_case(doc: dict, *, base_dir: Path, source: str, name: str) -> Case:
    if "obstacle" not in doc:
        raise InputError(f"missing section [obstacle] in {source}")
    bar = doc["bar"]
    for key in ("length", "youngs_modulus"):
        if key not in bar:
            raise InputError(f"missing key {key!r} in [bar]")
    length = _positive("bar", "length", bar["length"])
    area = _positive("bar", "area", bar.get("area", 1.0))
    E = _positive("bar", "youngs_modulus", bar["youngs_modulus"])
    chain = "elements" in bar or "stops" in doc
    elements = _integer("bar", "elements", bar.get("elements", 1), low=1, what="a positive integer")

    positions = doc["obstacle"].get("positions")
    if not isinstance(positions, list) or not positions:
        raise InputError("[obstacle] positions must be a non-empty list of numbers")
    h = np.array([_number("obstacle", "positions", v) for v in positions])

    stops: dict[int, float] = {}
    for k, stop in enumerate(doc.get("stops", [])):
        label = f"stops {k}"
        for key in ("node", "clearance"):
            if key not in stop:
                raise InputError(f"missing key {key!r} in [{label}]")
        if elements < 2:
            raise InputError("[[stops]] tables need [bar] elements >= 2 (stops act on interior nodes)")
        node = _integer(label, "node", stop["node"], low=1, high=elements - 1, what="an interior node index")
        if node in stops:
            raise InputError(f"[{label}] node {node} has two stops")
        clearance = _number(label, "clearance", stop["clearance"])
        if clearance < 0:
            raise InputError(f"[{label}] clearance must be >= 0, got {_show(stop['clearance'])}")
        stops[node] = clearance

    if isinstance(doc.get("data"), list) and len(doc["data"]) > 1:
        raise InputError("[bar] cases take one [data] table (several data sets need a [structure])")
    specs = _data_specs(doc, base_dir=base_dir, default_modulus=lambda k: E)
    max_outer, options = _run_options(doc)

    dataset = specs[0].build() if specs else None
    if chain:
        model = bar_chain(length=length, elements=elements, area=area, youngs_modulus=E, tip_positions=h,
                          stops=stops, dataset=dataset, name=name)
    else:
        model = bar_model(length=length, area=area, youngs_modulus=E, positions=h, dataset=dataset, name=name)
    return Case(model=model, formulation_options=options, ddcm_max_outer=max_outer, source=source)


# ------------------------------------------------------------------------------------------ trusses
def _nodes(value: Any) -> np.ndarray:
    rows = _list("structure", "nodes", value)
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
        X[i] = [_number("structure", f"nodes[{i}]", v) for v in r]
    return X


def _members(value: Any, X: np.ndarray) -> np.ndarray:
    nn = X.shape[0]
    rows = _list("structure", "members", value)
    M = np.empty((len(rows), 2), dtype=np.intp)
    for k, r in enumerate(rows):
        if not isinstance(r, list) or len(r) != 2:
            raise InputError(f"[structure] members[{k}] must be a pair [node_i, node_j], got {_show(r)}")
        for j in range(2):
            M[k, j] = _integer("structure", f"members[{k}]", r[j], low=0, high=nn - 1, what="a node index")
        if M[k, 0] == M[k, 1] or not np.any(X[M[k, 0]] != X[M[k, 1]]):
            raise InputError(f"[structure] member {k} has zero length (nodes {M[k, 0]} and {M[k, 1]} coincide)")
    return M


def _supports(value: Any, nn: int, d: int) -> list[tuple[int, str]]:
    out = []
    for k, entry in enumerate(_list("structure", "supports", value)):
        if not isinstance(entry, list) or len(entry) != 2 or not isinstance(entry[1], str):
            raise InputError(f"[structure] supports[{k}] must be [node, axes] such as [0, \"xy\"], got {_show(entry)}")
        node = _integer("structure", f"supports[{k}]", entry[0], low=0, high=nn - 1, what="a node index")
        axes = entry[1].lower()
        bad = [a for a in axes if a not in AXES[:d]]
        if bad or not axes:
            raise InputError(f"[structure] supports[{k}] axes must be letters from {AXES[:d]!r} in {d}-D, "
                             f"got {_show(entry[1])}")
        out.append((node, axes))
    return out


def _loads(value: Any, nn: int, d: int) -> np.ndarray:
    f = np.zeros((nn, d))
    for k, entry in enumerate(_list("structure", "loads", value, nonempty=False)):
        if not isinstance(entry, list) or len(entry) != 2:
            raise InputError(f"[structure] loads[{k}] must be [node, [force vector]], got {_show(entry)}")
        node = _integer("structure", f"loads[{k}]", entry[0], low=0, high=nn - 1, what="a node index")
        f[node] += _vector("structure", f"loads[{k}] force", entry[1], d)
    return f


def _distributed_loads(value: Any, ne: int, d: int) -> np.ndarray:
    q = np.zeros((ne, d))
    for k, entry in enumerate(_list("structure", "distributed_loads", value, nonempty=False)):
        if not isinstance(entry, list) or len(entry) != 2:
            raise InputError(f"[structure] distributed_loads[{k}] must be [member or \"all\", [load vector]], "
                             f"got {_show(entry)}")
        vec = _vector("structure", f"distributed_loads[{k}] load", entry[1], d)
        if entry[0] == "all":
            q += vec
        elif isinstance(entry[0], str):
            raise InputError(f'[structure] distributed_loads[{k}] must name a member index or "all", got {_show(entry[0])}')
        else:
            q[_integer("structure", f"distributed_loads[{k}]", entry[0], low=0, high=ne - 1,
                       what="a member index")] += vec
    return q


def _obstacles(tables: list[dict], X: np.ndarray, M: np.ndarray, n_factors: int | None) -> list[Obstacle]:
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
        normal = _vector(label, "normal", ob["normal"], d)
        if not np.any(normal):
            raise InputError(f"[{label}] normal must be non-zero")
        nodes = [_integer(label, "nodes", v, low=0, high=nn - 1, what="a node index")
                 for v in _list(label, "nodes", ob["nodes"])]
        if len(set(nodes)) != len(nodes):
            raise InputError(f"[{label}] nodes lists a node twice")
        loose = [n for n in nodes if not connected[n]]
        if loose:
            raise InputError(f"[{label}] node {loose[0]} belongs to no member")
        if "offset" in ob:
            offset: float | np.ndarray = _number(label, "offset", ob["offset"])
        else:
            offset = np.array([_number(label, "offsets", v) for v in _list(label, "offsets", ob["offsets"])])
            if steps is None:
                steps = offset.size
            elif offset.size != steps:
                what = "[path] load_factors" if n_factors is not None else "the offsets of an earlier obstacle"
                raise InputError(f"[{label}] offsets has {offset.size} values but {what} has {steps} steps")
        out.append(Obstacle(normal=normal, offset=offset, nodes=nodes))
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


def _structure_case(doc: dict, *, base_dir: Path, source: str, name: str) -> Case:
    st = doc["structure"]
    for key in ("nodes", "members", "area", "supports"):
        if key not in st:
            raise InputError(f"missing key {key!r} in [structure]")
    X = _nodes(st["nodes"])
    nn, d = X.shape
    M = _members(st["members"], X)
    ne = M.shape[0]
    area = _per_member("structure", "area", st["area"], ne)
    E = _per_member("structure", "youngs_modulus", st["youngs_modulus"], ne) if "youngs_modulus" in st else None
    supports = _supports(st["supports"], nn, d)
    loads = _loads(st["loads"], nn, d) if "loads" in st else None
    q = _distributed_loads(st["distributed_loads"], ne, d) if "distributed_loads" in st else None

    factors = None
    if "load_factors" in doc.get("path", {}):
        raw = _list("path", "load_factors", doc["path"]["load_factors"])
        factors = np.array([_number("path", "load_factors", v) for v in raw])
    obstacles = _obstacles(doc.get("obstacles", []), X, M, None if factors is None else factors.size)

    n_sets = len(doc["data"]) if isinstance(doc.get("data"), list) else int("data" in doc)
    material = None
    if "material" in st:
        if n_sets == 0:
            raise InputError("[structure] material needs [data] (one [[data]] table per material)")
        raw = _list("structure", "material", st["material"])
        if len(raw) != ne:
            raise InputError(f"[structure] material must have one data-set index per member ({ne}), got {len(raw)}")
        material = np.array([_integer("structure", f"material[{k}]", v, low=0, high=n_sets - 1,
                                      what="a data-set index") for k, v in enumerate(raw)], dtype=np.intp)
    elif n_sets > 1:
        raise InputError(f"[structure] material is required with {n_sets} [[data]] tables: "
                         "one data-set index per member")
    if E is None and n_sets == 0:
        raise InputError("[structure] needs youngs_modulus (classical variant) or [data] (DDCM variant)")
    specs = _data_specs(doc, base_dir=base_dir, default_modulus=_member_moduli(E, material, ne))
    max_outer, options = _run_options(doc)

    geometry = dict(nodes=X, members=M, area=area, supports=supports, loads=loads, distributed_loads=q,
                    obstacles=obstacles, load_factors=factors, name=name)
    # The geometry alone first (a placeholder modulus, no data): truss_model finds mechanisms and
    # bad obstacles before any data file is read or data set generated; the data are added after.
    geom = truss_model(youngs_modulus=1.0 if E is None else E, **geometry)
    dataset = member_data([s.build() for s in specs] or None, material)
    model = dataclasses.replace(geom, youngs_modulus=None if E is None else geom.youngs_modulus, dataset=dataset)
    return Case(model=model, formulation_options=options, ddcm_max_outer=max_outer, source=source)
