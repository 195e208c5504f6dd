"""Case files (TOML) for ``ddcm-compare --config``.

::

    [bar]
    length = 1.0            # m
    area = 1.0              # m^2
    youngs_modulus = 200e9  # Pa

    [obstacle]
    positions = [1.01, 1.0, 0.99]   # m, one per load step

    [data]                  # either a CSV file with header strain,stress ...
    path = "data.csv"       # relative to this file
    # ... or generated Hookean data, as in the paper:
    # hookean = { strain_min = -0.05, strain_max = 0.01, points = 500 }   # E defaults to [bar]

    [ddcm]
    c = 300e9               # Pa
    max_outer = 100

    [formulations.penalty]  # optional per-formulation options
    gamma = 2e15            # Pa/m

Unknown sections or keys are errors (a misspelt option must not be silently ignored).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

import formulations as registry

from .data import MaterialDataset, check_positive
from .errors import InputError
from .model import BarModel, bar_model, paper_bar

_SECTIONS = {
    "bar": {"length", "area", "youngs_modulus"},
    "obstacle": {"positions"},
    "data": {"path", "hookean"},
    "ddcm": {"c", "max_outer"},
    "formulations": None,  # checked against the registry
}
_HOOKEAN = {"strain_min", "strain_max", "points", "youngs_modulus"}


@dataclass
class Case:
    """A model plus run options read from a case file."""

    model: BarModel
    formulation_options: dict[str, dict] = field(default_factory=dict)
    ddcm_max_outer: int = 100
    source: str = "paper example"


def default_case() -> Case:
    """The paper's numerical example (Section 4)."""
    return Case(model=paper_bar())


def _number(section: str, key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"[{section}] {key} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"[{section}] {key} must be finite, got {value!r}")
    return v


def _positive(section: str, key: str, value) -> float:
    return check_positive(f"[{section}] {key}", _number(section, key, value))


def load_case(path: str | Path) -> Case:
    """Read and validate a TOML case file. Raises :class:`InputError` with a one-line message."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"config file not found: {path}")
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"malformed TOML in {path}: {exc}") from None
    except UnicodeDecodeError:
        raise InputError(f"config file is not UTF-8 text: {path}") from None
    except OSError as exc:
        raise InputError(f"cannot read config file {path}: {exc.strerror or exc}") from None
    return case_from_dict(doc, base_dir=path.parent, source=str(path))


def case_from_dict(doc: dict, *, base_dir: Path = Path("."), source: str = "<dict>") -> Case:
    for section, value in doc.items():
        if section not in _SECTIONS:
            raise InputError(f"unknown section [{section}] in {source}; known: {', '.join(_SECTIONS)}")
        if not isinstance(value, dict):
            raise InputError(f"[{section}] must be a table")
        keys = _SECTIONS[section]
        if keys is not None:
            unknown = sorted(set(value) - keys)
            if unknown:
                raise InputError(f"unknown key {unknown[0]!r} in [{section}]; known: {', '.join(sorted(keys))}")
    for needed in ("bar", "obstacle"):
        if needed not in doc:
            raise InputError(f"missing section [{needed}] in {source}")
    bar = doc["bar"]
    for key in ("length", "youngs_modulus"):
        if key not in bar:
            raise InputError(f"missing key {key!r} in [bar]")
    length = _positive("bar", "length", bar["length"])
    area = _positive("bar", "area", bar.get("area", 1.0))
    E = _positive("bar", "youngs_modulus", bar["youngs_modulus"])

    positions = doc["obstacle"].get("positions")
    if not isinstance(positions, list) or not positions:
        raise InputError("[obstacle] positions must be a non-empty list of numbers")
    h = np.array([_number("obstacle", "positions", v) for v in positions])

    ddcm = doc.get("ddcm", {})
    data_doc = doc.get("data")
    dataset = None
    if data_doc is not None:
        if "c" not in ddcm:
            raise InputError("[data] needs the metric: add [ddcm] c = ... (Pa)")
        c = _positive("ddcm", "c", ddcm["c"])
        if ("path" in data_doc) == ("hookean" in data_doc):
            raise InputError("[data] needs exactly one of 'path' or 'hookean'")
        if "path" in data_doc:
            if not isinstance(data_doc["path"], str):
                raise InputError("[data] path must be a string")
            dataset = MaterialDataset.from_csv(base_dir / data_doc["path"], c=c)
        else:
            hk = data_doc["hookean"]
            if not isinstance(hk, dict):
                raise InputError("[data] hookean must be a table {strain_min, strain_max, points}")
            unknown = sorted(set(hk) - _HOOKEAN)
            if unknown:
                raise InputError(f"unknown key {unknown[0]!r} in [data] hookean; known: {', '.join(sorted(_HOOKEAN))}")
            missing = [k for k in ("strain_min", "strain_max", "points") if k not in hk]
            if missing:
                raise InputError(f"missing key {missing[0]!r} in [data] hookean")
            points = _number("data", "hookean.points", hk["points"])
            if points != int(points) or points < 1:
                raise InputError(f"[data] hookean.points must be a positive integer, got {hk['points']!r}")
            dataset = MaterialDataset.hookean(
                _positive("data", "hookean.youngs_modulus", hk.get("youngs_modulus", E)),
                _number("data", "hookean.strain_min", hk["strain_min"]),
                _number("data", "hookean.strain_max", hk["strain_max"]), int(points), c=c)
    elif "c" in ddcm:
        _positive("ddcm", "c", ddcm["c"])
    max_outer = ddcm.get("max_outer", 100)
    if isinstance(max_outer, bool) or not isinstance(max_outer, int) or max_outer < 1:
        raise InputError(f"[ddcm] max_outer must be a positive integer, got {max_outer!r}")

    options: dict[str, dict] = {}
    for name, opts in doc.get("formulations", {}).items():
        if not isinstance(opts, dict):
            raise InputError(f"[formulations.{name}] must be a table of options")
        registry.get(name, **opts)  # validates the name and every option now, before any work
        options[name] = dict(opts)

    model = bar_model(length=length, area=area, youngs_modulus=E, positions=h, dataset=dataset,
                      name=Path(source).stem if source != "<dict>" else "bar")
    return Case(model=model, formulation_options=options, ddcm_max_outer=max_outer, source=source)
