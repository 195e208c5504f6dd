"""Case files for ``ddcm-compare --config``: TOML (``.toml``) or JSON (``.json``), one schema.

A case is the paper's bar (``[bar]``), optionally split into N elements with fixed stops,
a pin-jointed truss in 1-D, 2-D or 3-D (``[structure]``), or a continuum in 2-D (plane strain) or
3-D meshed with triangles or tetrahedra (``[mesh]``). They share ``[data]``, ``[ddcm]``
and ``[formulations.NAME]``.

Each model kind's sections are parsed by a case module of its own, in the case layer (the
``[bar]`` format is ``ddcm_casadi.casefiles.bar.CASE_FORMAT``, the ``[structure]`` format
``ddcm_casadi.casefiles.truss.CASE_FORMAT``, the ``[mesh]`` format
``ddcm_casadi.casefiles.continuum.CASE_FORMAT``; all are appended to this documentation below), behind
one registry of case kinds keyed by section (:func:`ddcm_casadi.casefiles.base.register_case_kind`); the
shared machinery is :mod:`ddcm_casadi.casefiles.base` (reading files, section and key checks, ``[ddcm]``)
and :mod:`ddcm_casadi.casefiles.common` (validators, ``[data]``, ``[formulations]``). The model modules
never import a case module.
This module is the public entry point: it imports the case modules, so that they are registered,
and exports :func:`load_case`, :func:`load_case_with_overrides`, :func:`case_from_dict`,
:func:`default_case` and :class:`Case`. A new model kind's case files are one module that calls
``register_case_kind`` and is imported here.

Shared sections
---------------
``[data]`` (one data set) or ``[[data]]`` (one table per material): ``path`` (a CSV file with
header ``strain,stress``, or a ``.npy`` array with those columns, read memory-mapped; relative to
the case file) or ``hookean = {strain_min, strain_max,
points, youngs_modulus}`` (the modulus defaults to the model's), and ``c`` (Pa, default
``[ddcm] c``). ``[ddcm]``: ``c`` and ``max_outer`` (default 100). ``[formulations.NAME]``: the
options of one formulation (see ``ddcm_casadi.formulations``).

JSON files use the same names: ``{"structure": {...}, "path": {...}, "obstacles": [{...}],
"data": [{...}], "ddcm": {...}, "formulations": {"penalty": {...}}}``.

Everything is validated before any work: unknown sections or keys are errors (a misspelt option
must not be silently ignored), every number must be finite, every index an integer in range, and
every error is an :class:`~ddcm_casadi.errors.InputError` with a one-line message naming the key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

# The case modules register their kinds when imported (the paper's bar is the default).
from ddcm_casadi.casefiles import bar as _bar
from ddcm_casadi.casefiles import truss as _truss
from ddcm_casadi.models.bar import paper_bar
from ddcm_casadi.casefiles.base import Case, case_from_dict, case_kinds, load_case, register_case_kind
from ddcm_casadi.casefiles import continuum as _continuum
from ddcm_casadi.casefiles.overrides import parse_item

if __doc__ is not None:  # None under python -OO
    __doc__ += _bar.CASE_FORMAT + _truss.CASE_FORMAT + _continuum.CASE_FORMAT


def default_case() -> Case:
    """The paper's numerical example (Section 4)."""
    return Case(model=paper_bar())


def load_case_with_overrides(path: str | Path, items: Iterable[str]) -> tuple[Case, dict]:
    """Read a case file, apply ``--set KEY=VALUE`` items, validate and build the case.

    Parameters
    ----------
    path : str or Path
        The case file (TOML or JSON).
    items : iterable of str
        ``KEY=VALUE`` overrides (:func:`ddcm_casadi.casefiles.overrides.parse_item`), applied in order.

    Returns
    -------
    tuple of (Case, dict)
        The case and the overrides as ``{key: parsed value}`` (for ``results.json``).
    """
    pairs = [parse_item(item) for item in items]
    return load_case(path, overrides=pairs), dict(pairs)


__all__ = ["Case", "case_from_dict", "case_kinds", "default_case", "load_case", "load_case_with_overrides",
           "register_case_kind"]
