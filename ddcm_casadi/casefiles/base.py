"""The registry of case kinds and the reading of case files, shared by every model kind (no model
kind imported here).

A case file (TOML or JSON, one schema) has one top-level section that names its model kind
(``[bar]``, ``[structure]``, ...), the sections only that kind accepts, and the sections every
kind shares:

- ``[data]`` or ``[[data]]``: material data sets (a CSV file, or generated Hookean data);
- ``[ddcm]``: ``c`` (the default metric, Pa), ``max_outer`` (alternating projections per step) and
  the search options ``start``, ``initial``, ``warm``, ``seed``, ``restarts``, ``improve``,
  ``restart_neighbours``, ``greedy_*``, ``exact_max``, ``variant``, ``lcdd_neighbours``, ``maxent_*``
  (:class:`~ddcm_casadi.drivers.ddcm_options.DDCMOptions`);
- ``[formulations.NAME]``: options of one contact formulation (checked against the registry).

Top-level keys (before any section), shared by every kind: ``kinematics`` (``"small"`` or
``"finite"``, where the kind offers it), ``min_substep`` (the smallest sub-step of the automatic
bisection of a failed load step, a fraction of a step, both variants; default 1/16, 0 or 1 turns
it off: :mod:`ddcm_casadi.drivers.substeps`) and ``condense`` (``true``, the default: the classical
problem is solved condensed on its contact pairs where that applies; ``false``: on the full
problem, :func:`~ddcm_casadi.drivers.ddcm_reduced.build_classical`).

A model kind registers itself with :func:`register_case_kind` (its section, the keys of its
sections and a ``parse`` function that builds the :class:`Case`); :func:`case_from_dict` checks
the sections of every kind and dispatches to the one named. The public entry point is
:mod:`ddcm_casadi.casefiles.config`, which imports the kinds so that they are registered; the format of each
kind is documented next to its parser (:mod:`ddcm_casadi.casefiles.bar`, :mod:`ddcm_casadi.casefiles.truss`,
:mod:`ddcm_casadi.casefiles.continuum`).

The validators the parsers use, by section and key, the ``[data]`` specs and the run options are
:mod:`ddcm_casadi.casefiles.common`'s. Every error is an :class:`~ddcm_casadi.errors.InputError`
with a one-line message naming the key.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from ddcm_casadi.errors import InputError
from ddcm_casadi import inputs as check
from ddcm_casadi.inputs import input_file
from ddcm_casadi.casefiles.overrides import apply_overrides
from ddcm_casadi.models.base import KINEMATICS, ContactModel
from ddcm_casadi.drivers.ddcm_options import KEYS as DDCM_OPTION_KEYS
from ddcm_casadi.drivers.ddcm_options import DDCMOptions
from ddcm_casadi.drivers.substeps import DEFAULT_MIN_SUBSTEP, check_min_substep

#: Keys of the sections every kind shares (``None``: checked elsewhere, here against the registry).
#: Top-level keys (not sections): ``kinematics = "small" | "finite"`` (default the kind's first) and
#: ``min_substep`` (the automatic step bisection of both variants, :mod:`ddcm_casadi.drivers.substeps`)
#: and ``condense`` (the classical problem condensed on its contact pairs where that applies).
TOP_LEVEL_KEYS = ("kinematics", "min_substep", "condense")

COMMON_SECTIONS: dict[str, set[str] | None] = {
    "data": {"path", "hookean", "c", "law", "grid", "samples"},
    "ddcm": {"c", "max_outer"} | DDCM_OPTION_KEYS,
    "formulations": None,
}
_SUFFIXES = (".toml", ".json")


@dataclass
class Case:
    """A model plus run options read from a case file."""

    model: ContactModel
    formulation_options: dict[str, dict] = field(default_factory=dict)
    ddcm_max_outer: int = 100
    source: str = "paper example"
    #: ``[ddcm]`` start, seed, restarts, improve, ... (:class:`~ddcm_casadi.drivers.ddcm_options.DDCMOptions`).
    ddcm_options: DDCMOptions = field(default_factory=DDCMOptions)
    #: The top-level ``min_substep``: failed load steps are bisected down to this fraction of a
    #: step, in both variants (:mod:`ddcm_casadi.drivers.substeps`; 0 or 1: off).
    min_substep: float = DEFAULT_MIN_SUBSTEP
    #: The top-level ``condense``: the classical problem condensed on its contact pairs where that
    #: applies (:func:`~ddcm_casadi.drivers.ddcm_reduced.build_classical`).
    condense: bool = True


#: ``parse(doc, *, base_dir, source, name) -> Case`` of a model kind.
CaseParser = Callable[..., Case]


@dataclass(frozen=True)
class CaseKind:
    """A registered model kind of case files (see :func:`register_case_kind`)."""

    section: str
    sections: dict[str, frozenset[str]]
    arrays: frozenset[str]
    tables: frozenset[str]
    parse: CaseParser
    uses: str
    default_name: str
    default: bool
    kinematics: tuple[str, ...] = ("small",)

    @property
    def own_sections(self) -> list[str]:
        """The sections only this kind accepts (besides its own top-level section), in order."""
        return [s for s in self.sections if s != self.section]


_KINDS: dict[str, CaseKind] = {}


def register_case_kind(section: str, *, sections: Mapping[str, set[str]], parse: CaseParser, uses: str,
                       arrays: set[str] | frozenset[str] = frozenset(), tables: set[str] | frozenset[str] = frozenset(),
                       default_name: str | None = None,
                       default: bool = False, kinematics: tuple[str, ...] = ("small",)) -> None:
    """Register a model kind of case files.

    Parameters
    ----------
    section : str
        The top-level section that selects this kind, e.g. ``"bar"``.
    sections : mapping of str to set of str
        The known keys of every section this kind accepts, its own ``section`` first; the others
        (e.g. ``"obstacle"``) belong to this kind only and are refused in a case of another kind.
    parse : callable
        ``parse(doc, *, base_dir, source, name) -> Case``: validates the document (whose section
        names and keys are already checked) and builds the case.
    uses : str
        What a case of this kind uses instead of another kind's sections, for the message that
        refuses them (e.g. ``"[obstacle] positions"``).
    arrays : set of str
        Which of ``sections`` are arrays of tables (``[[stops]]``).
    tables : set of str
        Which of ``sections`` may be one table or an array of tables (``[material]`` or
        ``[[material]]``), as ``[data]`` may.
    default_name : str, optional
        Model name when the document has no file name (default: ``section``).
    default : bool
        The kind assumed when a document names none (the paper's bar): it is named in the
        "missing section" message and listed first.
    kinematics : tuple of str
        The values of the top-level key ``kinematics`` this kind's models take (the first is the
        default); the model is built, then given the case's kinematics.

    Raises
    ------
    ValueError
        The section, or one of its sections, is registered already (a programming error).
    """
    if section not in sections:
        raise ValueError(f"case kind [{section}] must list its own section's keys")
    taken = set(COMMON_SECTIONS)
    for kind in _KINDS.values():
        taken |= set(kind.sections)
    clash = sorted(taken & set(sections))
    if clash:
        raise ValueError(f"case section [{clash[0]}] is registered already")
    if default and any(k.default for k in _KINDS.values()):
        raise ValueError("a default case kind is registered already")
    _KINDS[section] = CaseKind(section=section, sections={k: frozenset(v) for k, v in sections.items()},
                               arrays=frozenset(arrays), tables=frozenset(tables), parse=parse, uses=uses,
                               default_name=default_name or section, default=default,
                               kinematics=tuple(kinematics))


def case_kinds() -> list[CaseKind]:
    """The registered kinds: the default kind first, then the others in registration order."""
    kinds = list(_KINDS.values())
    return [k for k in kinds if k.default] + [k for k in kinds if not k.default]


def _known_sections() -> dict[str, frozenset[str] | None]:
    known: dict[str, frozenset[str] | None] = {}
    for kind in case_kinds():
        known.update(kind.sections)
    known.update({k: None if v is None else frozenset(v) for k, v in COMMON_SECTIONS.items()})
    return known


# ------------------------------------------------------------------------------------ reading files
def _reject_duplicates(pairs: list[tuple[str, Any]]) -> dict:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise InputError(f"duplicate key {key!r} in JSON object")
        out[key] = value
    return out


def read_document(path: Path) -> dict:
    """The parsed sections of a case file (``.toml`` or ``.json``), not yet validated.

    Raises
    ------
    InputError
        Missing, unreadable or malformed file, or an unknown suffix (one line).
    """
    path = input_file(path, "config file")
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
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"malformed TOML in {path}: {exc}") from None
        except RecursionError:
            raise InputError(f"malformed TOML in {path}: nested too deeply") from None
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
    return doc


def load_case(path: str | Path, *, overrides: Iterable[tuple[str, Any]] = ()) -> Case:
    """Read and validate a case file (``.toml`` or ``.json``, same schema).

    Parameters
    ----------
    path : str or Path
        The case file; relative data paths are resolved against its folder.
    overrides : iterable of (str, value)
        Dotted keys and values applied to the document before it is validated
        (:func:`ddcm_casadi.casefiles.overrides.apply_overrides`, ``ddcm-compare --set``).

    Returns
    -------
    Case

    Raises
    ------
    InputError
        Missing, unreadable or malformed file, unknown suffix, or any invalid value (one line).
    """
    path = Path(path)
    doc = apply_overrides(read_document(path), overrides)
    return case_from_dict(doc, base_dir=path.parent, source=str(path))


def _check_sections(doc: dict, source: str) -> None:
    """Known sections with known keys only; tables where tables belong."""
    known = _known_sections()
    arrays = set().union(*(k.arrays for k in _KINDS.values()))
    either = {"data"}.union(*(k.tables for k in _KINDS.values()))
    for section, value in doc.items():
        if section not in known:
            raise InputError(f"unknown section [{section}] in {source}; known: {', '.join(known)}")
        keys = known[section]
        if section in arrays:
            if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
                raise InputError(f"[[{section}]] must be an array of tables")
            tables = value
        elif section in either and isinstance(value, list):
            if not value or not all(isinstance(v, dict) for v in value):
                raise InputError(f"[[{section}]] must be a table or a non-empty array of tables")
            tables = value
        elif isinstance(value, dict):
            tables = [value]
        else:
            raise InputError(f"[{section}] must be a table")
        if keys is not None:
            for k, table in enumerate(tables):
                unknown = sorted(set(table) - keys)
                if unknown:
                    numbered = section in arrays or len(tables) > 1  # as the other messages name them
                    where = f"{section} {k}" if numbered else section
                    raise InputError(f"unknown key {unknown[0]!r} in [{where}]; known: {', '.join(sorted(keys))}")


def _kind_of(doc: dict, source: str) -> CaseKind:
    """The one kind a document names, after refusing another kind's sections."""
    kinds = case_kinds()
    named = [k for k in kinds if k.section in doc]
    if len(named) > 1:
        raise InputError(f"[{named[0].section}] and [{named[1].section}] cannot be combined in {source}; "
                         "a case has one or the other")
    if named:
        kind = named[0]
        for other in kinds:
            if other is kind:
                continue
            for s in other.own_sections:
                if s in doc:
                    raise InputError(f"[{s}] belongs to [{other.section}] cases; a [{kind.section}] uses {kind.uses}")
        return kind
    # No kind named: the one whose own sections are present, else the default kind.
    for kind in kinds:
        if not kind.default and any(s in doc for s in kind.own_sections):
            raise InputError(f"missing section [{kind.section}] in {source}")
    default = next((k for k in kinds if k.default), None)
    if default is None:
        raise InputError(f"no model section in {source}; known: {', '.join(k.section for k in kinds)}")
    raise InputError(f"missing section [{default.section}] in {source}")


def case_from_dict(doc: dict, *, base_dir: Path = Path("."), source: str = "<dict>") -> Case:
    """Validate a parsed case document and build its :class:`Case` (by the kind it names).

    Parameters
    ----------
    doc : dict
        The parsed TOML or JSON document.
    base_dir : Path
        Folder against which relative data paths are resolved.
    source : str
        Where the document came from (for messages and the model name).
    """
    top = {key: doc[key] for key in TOP_LEVEL_KEYS if key in doc}
    doc = {key: value for key, value in doc.items() if key not in TOP_LEVEL_KEYS}
    _check_sections(doc, source)
    kind = _kind_of(doc, source)
    kinematics = check.one_of(top.get("kinematics", kind.kinematics[0]), "kinematics", KINEMATICS)
    if kinematics not in kind.kinematics:
        raise InputError(f"kinematics = {kinematics!r} is not available for [{kind.section}] cases "
                         f"(available: {', '.join(map(repr, kind.kinematics))})")
    ddcm = DDCMOptions.from_mapping(doc.get("ddcm", {}))  # checked before any work
    min_substep = check_min_substep(top.get("min_substep", DEFAULT_MIN_SUBSTEP))
    condense = top.get("condense", True)
    if not isinstance(condense, bool):
        raise InputError(f"condense must be true or false, not {condense!r}")
    name = Path(source).stem if source != "<dict>" else None
    case = kind.parse(doc, base_dir=base_dir, source=source, name=name or kind.default_name)
    if kinematics != case.model.kinematics:
        case.model = dataclasses.replace(case.model, kinematics=kinematics)
    case.ddcm_options = ddcm
    case.min_substep = min_substep
    case.condense = condense
    return case
