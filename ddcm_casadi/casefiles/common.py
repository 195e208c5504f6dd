"""The pieces every kind's case-file parser uses: validators by section and key, the ``[data]``
specs and the run options (no model kind imported here).

- validators of ``[section] key``: :func:`number`, :func:`positive`, :func:`integer`,
  :func:`nonempty_list` (the :mod:`ddcm_casadi.inputs` toolkit's, named by section and key),
  :func:`vector`, :func:`per_member`; :func:`show` quotes a bad value;
- ``[data]`` / ``[[data]]``: :func:`data_specs` checks them into :class:`DataSpec`\\ s (a file or
  generated Hookean data, built into a :class:`~ddcm_casadi.data.dataset.MaterialDataset` after all
  checks), :func:`hookean_table`, :func:`data_set_count`;
- :func:`run_options`: ``[ddcm] max_outer`` and ``[formulations.NAME]``.

The registry of case kinds and the reading of case files are :mod:`ddcm_casadi.casefiles.base`'s.
Every error is an :class:`~ddcm_casadi.errors.InputError` with a one-line message naming the key.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ddcm_casadi import formulations as registry
from ddcm_casadi import inputs as check
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.data.limits import MAX_DATA_POINTS
from ddcm_casadi.drivers.ddcm_options import MAX_OUTER_RANGE
from ddcm_casadi.errors import InputError
from ddcm_casadi.inputs import show

__all__ = ["HOOKEAN_KEYS", "DataSpec", "data_set_count", "data_specs", "hookean_table", "integer", "nonempty_list",
           "number", "per_member", "positive", "run_options", "show", "vector"]

#: The keys of ``[data] hookean`` (``youngs_modulus`` optional where the model has one).
HOOKEAN_KEYS = frozenset({"strain_min", "strain_max", "points", "youngs_modulus"})


# ------------------------------------------------------------------------------------ scalar checks
def number(section: str, key: str, value: Any) -> float:
    """``value`` as a finite float (:func:`ddcm_casadi.inputs.finite_number` of ``[section] key``)."""
    return check.finite_number(value, f"[{section}] {key}")


def positive(section: str, key: str, value: Any) -> float:
    """``value`` as a finite positive float (:func:`ddcm_casadi.inputs.positive` of ``[section] key``)."""
    return check.positive(value, f"[{section}] {key}")


def integer(section: str, key: str, value: Any, *, low: int | None = None, high: int | None = None,
            what: str = "an integer") -> int:
    """``value`` as an int in ``low..high`` (inclusive); booleans and floats are refused
    (:func:`ddcm_casadi.inputs.integer` of ``[section] key``)."""
    return check.integer(value, f"[{section}] {key}", low=low, high=high, what=what)


def nonempty_list(section: str, key: str, value: Any, *, nonempty: bool = True) -> list:
    """``value`` if it is a list, non-empty unless ``nonempty=False``
    (:func:`ddcm_casadi.inputs.nonempty_list` of ``[section] key``)."""
    return check.nonempty_list(value, f"[{section}] {key}", nonempty=nonempty)


def vector(section: str, key: str, value: Any, d: int) -> np.ndarray:
    """A list of ``d`` finite numbers (a bare number when ``d == 1``)."""
    if d == 1 and not isinstance(value, list):
        value = [value]
    if not isinstance(value, list) or len(value) != d:
        raise InputError(f"[{section}] {key} must be a list of {d} numbers, got {show(value)}")
    return np.array([number(section, key, v) for v in value])


def per_member(section: str, key: str, value: Any, ne: int) -> float | np.ndarray:
    """A positive number, or a list of one positive number per member."""
    if isinstance(value, list):
        if len(value) != ne:
            raise InputError(f"[{section}] {key} must be one number or one per member ({ne}), got {len(value)}")
        return np.array([positive(section, f"{key}[{k}]", v) for k, v in enumerate(value)])
    return positive(section, key, value)


# ------------------------------------------------------------------------------------------ [data]
@dataclass
class DataSpec:
    """A validated data-set description, built into a :class:`MaterialDataset` after all checks."""

    label: str
    c: float
    path: Path | None = None
    youngs_modulus: float | None = None
    strain_min: float = 0.0
    strain_max: float = 0.0
    points: int = 0

    def build(self) -> MaterialDataset:
        """Read the file or generate the Hookean data."""
        if self.path is not None:
            return MaterialDataset.from_file(self.path, c=self.c)
        return MaterialDataset.hookean(self.youngs_modulus, self.strain_min, self.strain_max, self.points, c=self.c)


def data_specs(doc: dict, *, base_dir: Path, default_modulus: Callable[[int], float | None],
               no_default: str = "there is no default modulus") -> list[DataSpec]:
    """Validate ``[data]`` / ``[[data]]`` (no file is read yet).

    Parameters
    ----------
    doc : dict
        The case document.
    base_dir : Path
        Folder against which relative data paths are resolved.
    default_modulus : callable
        ``default_modulus(k)`` is the Hookean modulus of set ``k`` when the table gives none, or
        ``None`` if there is no single one (then the table must give it).
    no_default : str
        Why there is no default modulus, for the message when a table gives none.
    """
    ddcm = doc.get("ddcm", {})
    data_doc = doc.get("data")
    ddcm_c = positive("ddcm", "c", ddcm["c"]) if "c" in ddcm else None
    if data_doc is None:
        return []
    tables = data_doc if isinstance(data_doc, list) else [data_doc]
    specs = []
    for k, table in enumerate(tables):
        label = "data" if len(tables) == 1 else f"data {k}"
        if "c" in table:
            c = positive(label, "c", table["c"])
        elif ddcm_c is not None:
            c = ddcm_c
        else:
            raise InputError(f"[{label}] needs the metric: add [ddcm] c = ... (Pa)")
        if ("path" in table) == ("hookean" in table):
            raise InputError(f"[{label}] needs exactly one of 'path' or 'hookean'")
        if "path" in table:
            if not isinstance(table["path"], str):
                raise InputError(f"[{label}] path must be a string")
            specs.append(DataSpec(label, c, path=base_dir / table["path"]))
            continue
        hk = hookean_table(label, table["hookean"], HOOKEAN_KEYS)
        points = number(label, "hookean.points", hk["points"])
        if points != int(points) or points < 1:
            raise InputError(f"[{label}] hookean.points must be a positive integer, got {show(hk['points'])}")
        if points > MAX_DATA_POINTS:
            raise InputError(f"[{label}] number of data points must be between 1 and {MAX_DATA_POINTS}, "
                             f"got {show(hk['points'])}")
        if "youngs_modulus" in hk:
            E = positive(label, "hookean.youngs_modulus", hk["youngs_modulus"])
        else:
            E = default_modulus(k)
            if E is None:
                raise InputError(f"[{label}] hookean needs youngs_modulus ({no_default})")
        lo = number(label, "hookean.strain_min", hk["strain_min"])
        hi = number(label, "hookean.strain_max", hk["strain_max"])
        if lo > hi:
            raise InputError(f"[{label}] hookean.strain_min must be <= strain_max, got [{lo}, {hi}]")
        specs.append(DataSpec(label, c, youngs_modulus=E, strain_min=lo, strain_max=hi, points=int(points)))
    return specs


def hookean_table(label: str, hk: Any, known: set[str]) -> dict:
    """``[label] hookean``: a table with ``strain_min``, ``strain_max``, ``points`` and only the
    ``known`` keys."""
    if not isinstance(hk, dict):
        raise InputError(f"[{label}] hookean must be a table {{strain_min, strain_max, points}}")
    unknown = sorted(set(hk) - known)
    if unknown:
        raise InputError(f"unknown key {unknown[0]!r} in [{label}] hookean; known: {', '.join(sorted(known))}")
    missing = [key for key in ("strain_min", "strain_max", "points") if key not in hk]
    if missing:
        raise InputError(f"missing key {missing[0]!r} in [{label}] hookean")
    return hk


def data_set_count(doc: dict) -> int:
    """How many data sets ``[data]`` / ``[[data]]`` describes (0 without one)."""
    return len(doc["data"]) if isinstance(doc.get("data"), list) else int("data" in doc)


def run_options(doc: dict) -> tuple[int, dict[str, dict]]:
    """``[ddcm] max_outer`` and the per-formulation options (validated against the registry)."""
    # One alternating projection cannot confirm a fixed point (that takes an unchanged assignment).
    max_outer = integer("ddcm", "max_outer", doc.get("ddcm", {}).get("max_outer", 100), low=MAX_OUTER_RANGE[0],
                        high=MAX_OUTER_RANGE[1])
    options: dict[str, dict] = {}
    for fname, opts in doc.get("formulations", {}).items():
        if not isinstance(opts, dict):
            raise InputError(f"[formulations.{fname}] must be a table of options")
        registry.get(fname, **opts)  # validates the name and every option now, before any work
        options[fname] = dict(opts)
    return max_outer, options
