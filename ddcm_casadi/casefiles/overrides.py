"""Overrides of a case document from the command line: ``--set KEY=VALUE``.

A key is a dotted path into the parsed case document (TOML or JSON, one schema): table keys,
and integer indices into arrays, e.g. ``ddcm.c``, ``data.0.c`` (the first ``[[data]]`` table),
``formulations.penalty.gamma`` or ``obstacle.positions.3``. A value is a TOML value (``2e11``,
``100``, ``true``, ``[1.0, 0.99]``, ``{ points = 500, strain_min = -0.05, strain_max = 0.01 }``,
``"isotropic"``); a bare word such as ``isotropic`` is taken as a string. Missing tables on the
way are created, so ``--set formulations.penalty.gamma=1e14`` works on a case without
``[formulations.penalty]``.

Overrides change the *document*, before :func:`~ddcm_casadi.casefiles.config.case_from_dict` validates it:
an overridden value is checked exactly as if it had been written in the file (an unknown key, a
negative modulus, ... is the same one-line :class:`~ddcm_casadi.errors.InputError`).
"""

from __future__ import annotations

import copy
import re
import sys
from typing import Any, Iterable

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from ddcm_casadi.errors import InputError

_BARE_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_\-]*")


def parse_value(text: str, *, what: str = "--set") -> Any:
    """A TOML value from its text (a bare word that is not a TOML value is a string).

    Raises
    ------
    InputError
        The text is not a TOML value (one line).
    """
    try:
        parsed = tomllib.loads(f"value = {text}")
    except tomllib.TOMLDecodeError:
        if _BARE_WORD.fullmatch(text.strip()):
            return text.strip()
        raise InputError(f"{what}: {text!r} is not a TOML value (strings need quotes, e.g. '\"name\"')") from None
    except RecursionError:
        raise InputError(f"{what}: value nested too deeply") from None
    if len(parsed) != 1:  # a newline in the text started another key
        raise InputError(f"{what}: {text!r} is more than one TOML value")
    return parsed["value"]


def parse_item(item: str) -> tuple[str, Any]:
    """``KEY=VALUE`` as ``(KEY, value)``, the value parsed by :func:`parse_value`."""
    key, sep, text = item.partition("=")
    key = key.strip()
    if not sep or not key:
        raise InputError(f"--set needs KEY=VALUE (a dotted key into the case file), got {item!r}")
    return key, parse_value(text, what=f"--set {key}")


def split_key(key: str, *, what: str = "--set") -> list[str]:
    """The parts of a dotted key (no empty part)."""
    parts = key.split(".")
    if not all(p.strip() for p in parts):
        raise InputError(f"{what}: {key!r} is not a dotted key such as ddcm.c or data.0.c")
    return [p.strip() for p in parts]


def set_value(doc: dict, key: str, value: Any, *, what: str = "--set") -> None:
    """Set ``doc[key]`` in place, ``key`` dotted (tables by name, arrays by index).

    Raises
    ------
    InputError
        An index that is not an integer in range, or a part of the path that is a value, not a
        table or an array (one line).
    """
    parts = split_key(key, what=what)
    node: Any = doc
    for depth, part in enumerate(parts):
        last = depth == len(parts) - 1
        where = ".".join(parts[:depth]) or "the case"
        if isinstance(node, dict):
            if last:
                node[part] = value
            else:
                node = node.setdefault(part, {})
        elif isinstance(node, list):
            if not re.fullmatch(r"\d+", part):
                raise InputError(f"{what} {key}: {where} is an array; index it with a number, got {part!r}")
            index = int(part)
            if index >= len(node):
                raise InputError(f"{what} {key}: index {index} out of range, {where} has {len(node)} entries")
            if last:
                node[index] = value
            else:
                node = node[index]
        else:
            raise InputError(f"{what} {key}: {where} is a value, not a table or an array")


def apply_overrides(doc: dict, items: Iterable[tuple[str, Any]], *, what: str = "--set") -> dict:
    """A copy of ``doc`` with every ``(dotted key, value)`` of ``items`` set, in order.

    Parameters
    ----------
    doc : dict
        A parsed case document (not modified).
    items : iterable of (str, value)
        Dotted keys and their (already parsed) values.
    what : str
        How the overrides are named in messages (``--set``, ``grid key``).

    Returns
    -------
    dict
        The overridden document, not yet validated.
    """
    out = copy.deepcopy(doc)
    for key, value in items:
        set_value(out, key, copy.deepcopy(value), what=what)
    return out
