"""Case files for ``ddcm-compare --config``: TOML (``.toml``) or JSON (``.json``), one schema.

A case is the paper's bar (``[bar]``), optionally split into N elements with fixed stops,
a pin-jointed truss in 1-D, 2-D or 3-D (``[structure]``), or a continuum in 2-D (plane strain) or
3-D meshed with triangles or tetrahedra (``[mesh]``). They share ``[data]``, ``[ddcm]``
and ``[formulations.NAME]``.

Each model kind parses its own sections next to its model (the ``[bar]`` format is
``ddcm_casadi.bar.CASE_FORMAT``, the ``[structure]`` format ``ddcm_casadi.truss.CASE_FORMAT``;
both are appended to this documentation below), behind one registry of case kinds
(:func:`ddcm_casadi.casefile.register_case_kind`); the shared machinery (reading files, section
and key checks, validators, ``[data]``, ``[ddcm]``, ``[formulations]``) is
:mod:`ddcm_casadi.casefile`. This module is the public entry point: it imports the kinds, so that
they are registered, and exports :func:`load_case`, :func:`case_from_dict`, :func:`default_case`
and :class:`Case`. A new model kind is one module that calls ``register_case_kind`` and is
imported here.

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

# The model kinds register their case sections when imported (the paper's bar is the default).
from . import bar as _bar
from . import truss as _truss
from .continuum import case as _continuum
from .bar import paper_bar
from .casefile import Case, case_from_dict, case_kinds, load_case, register_case_kind

if __doc__ is not None:  # None under python -OO
    __doc__ += _bar.CASE_FORMAT + _truss.CASE_FORMAT + _continuum.CASE_FORMAT


def default_case() -> Case:
    """The paper's numerical example (Section 4)."""
    return Case(model=paper_bar())


__all__ = ["Case", "case_from_dict", "case_kinds", "default_case", "load_case", "register_case_kind"]
