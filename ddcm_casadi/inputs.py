"""User input: one-line checks of the files and values a case file, ``--set`` or the API gives.

One toolkit for every layer that reads input (case files, the DDCM options, the formulations'
options, the model builders): each checker takes the value and *where* it came from
(``"[bar] length"``, ``"option 'tol' of 'penalty'"``, ``"ddcm option seed"``) and returns the value
normalised, or raises an :class:`~ddcm_casadi.errors.InputError` whose one line names that place,
so the same bad value reads the same from a file, from ``--set`` and from the API.

- files: :func:`input_file`;
- numbers: :func:`finite_number`, :func:`positive`, :func:`in_range`, :func:`tolerance`,
  :func:`integer`, :func:`iteration_limit`;
- others: :func:`boolean`, :func:`one_of`, :func:`string`, :func:`nonempty_list`,
  :func:`number_list`, :func:`table`;
- options dataclasses: :func:`check_dataclass` and :func:`check_fields` check each field by its
  resolved type hint (``X | None``, ``Optional[X]``, ``Literal[...]``, ``tuple``, ``dict``, ...) and
  the name rules (``max_*``: :data:`ITERATION_LIMIT`; ``*tol``: :data:`TOLERANCE`), or by a rule of
  its own.
"""

from __future__ import annotations

import dataclasses
import errno
import functools
import math
import numbers
import os
import stat
import types
import typing
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, Literal, Union

import numpy as np

from ddcm_casadi.errors import InputError


def input_file(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a :class:`~pathlib.Path` if it names a regular file that exists.

    Parameters
    ----------
    path : str or PathLike
        The file a user named.
    what : str
        What the file is, for the message (``"config file"``, ``"data file"``, ...).

    Raises
    ------
    InputError
        One line saying which of these it is: not found (or a dangling symbolic link), a
        directory, a symbolic link loop, not a regular file (a device, a pipe), or not accessible.
    """
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise InputError(f"{what} is a symbolic link loop: {path}") from None
        if exc.errno == errno.ENOENT and os.path.islink(path):
            raise InputError(f"{what} is a dangling symbolic link to {os.readlink(path)}: {path}") from None
        if exc.errno == errno.ENOENT:
            raise InputError(f"{what} not found: {path}") from None
        raise InputError(f"cannot access {what} {path}: {exc.strerror or exc}") from None
    if stat.S_ISDIR(mode):
        raise InputError(f"{what} is a directory, not a file: {path}")
    if not stat.S_ISREG(mode):
        raise InputError(f"{what} is not a regular file: {path}")
    return path


# ------------------------------------------------------------------------------------------ values
#: Range of iteration limits (options named ``max_*``): 0 iterations cannot converge, and a limit
#: beyond a million only hides a solve that does not converge.
ITERATION_LIMIT = (1, 10**6)
#: Range of tolerances (options named ``*tol``), the upper end excluded: relative residuals and
#: complementarity errors are measured in double precision, whose floor is a few ``eps`` = 2.2e-16.
TOLERANCE = (1e-15, 1.0)
#: Why :data:`TOLERANCE` has its lower end, for the message.
_TOLERANCE_WHY = " (a relative tolerance below a few machine epsilons cannot be met)"

#: Where a value came from: a label (``"[bar] length"``, ``"option 'tol' of 'penalty'"``), or, for
#: the fields of a dataclass, a prefix (``"[ddcm]"``: ``"[ddcm] seed"``) or a function of the field's name.
Where = str | Callable[[str], str]
#: A checker of one value: ``rule(value, where) -> normalised value``, or a one-line :class:`InputError`.
Rule = Callable[[Any, str], Any]


def show(value: Any, limit: int = 60) -> str:
    """``repr(value)`` for a message: at most ``limit`` characters, safe for huge integers."""
    try:
        text = repr(value)
    except ValueError:  # an integer with more digits than Python will print
        return "<a number too large to print>"
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _is_bool(value: Any) -> bool:
    return isinstance(value, (bool, np.bool_))


def _real(value: Any) -> float | None:
    """``value`` as a float (``inf`` for an integer beyond the float range) if it is a real number
    (a numpy scalar or 0-d array included, booleans and strings not), else ``None``."""
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf":
        value = value.item()
    if _is_bool(value) or not isinstance(value, numbers.Real):
        return None
    try:
        return float(value)
    except OverflowError:  # an integer beyond the float range (JSON integers are unbounded)
        return math.inf if value > 0 else -math.inf


def finite_number(value: Any, where: str) -> float:
    """``value`` as a finite float (booleans and strings refused); otherwise
    ``"{where} must be a number, got ..."`` or ``"{where} must be finite, got ..."``."""
    v = _real(value)
    if v is None:
        raise InputError(f"{where} must be a number, got {show(value)}")
    if not math.isfinite(v):
        raise InputError(f"{where} must be finite, got {show(value)}")
    return v


def positive(value: Any, where: str) -> float:
    """``value`` as a finite float ``> 0``; otherwise ``"{where} must be finite and positive, got ..."``
    (the value as a float) or ``"{where} must be a number, got ..."``."""
    v = _real(value)
    if v is None:
        raise InputError(f"{where} must be a number, got {show(value)}")
    if not math.isfinite(v) or v <= 0.0:
        raise InputError(f"{where} must be finite and positive, got {show(v)}")
    return v


def _interval(low: float | None, high: float | None, low_open: bool, high_open: bool) -> str:
    left = "(-inf" if low is None else f"{'(' if low_open else '['}{low:g}"
    right = "inf)" if high is None else f"{high:g}{')' if high_open else ']'}"
    return f"{left}, {right}"


def in_range(value: Any, where: str, low: float | None = None, high: float | None = None, *,
             low_open: bool = False, high_open: bool = False, why: str = "") -> float:
    """``value`` as a finite float between ``low`` and ``high``.

    Parameters
    ----------
    low, high : float, optional
        The ends of the range (``None``: unbounded on that side).
    low_open, high_open : bool
        Whether that end is excluded (an open end).
    why : str
        Appended to the range in the message, e.g. ``" (a relative tolerance ...)"``.

    Raises
    ------
    InputError
        ``"{where} must be in [low, high){why}, got ..."`` for a value outside the range or not a
        finite number.
    """
    v = _real(value)
    inside = v is not None and math.isfinite(v) and (
        low is None or (v > low if low_open else v >= low)) and (
        high is None or (v < high if high_open else v <= high))
    if not inside:
        raise InputError(f"{where} must be in {_interval(low, high, low_open, high_open)}{why}, got {show(value)}")
    return float(v)


def tolerance(value: Any, where: str) -> float:
    """A relative tolerance: a float in :data:`TOLERANCE` ``[1e-15, 1)``."""
    return in_range(value, where, *TOLERANCE, high_open=True, why=_TOLERANCE_WHY)


def integer(value: Any, where: str, *, low: int | None = None, high: int | None = None, what: str = "an integer",
            coerce_floats: bool = False) -> int:
    """``value`` as an int in ``low..high`` (inclusive); booleans are refused.

    Parameters
    ----------
    low, high : int, optional
        The inclusive range (``None``: unbounded on that side).
    what : str
        What the value must be, for the message (``"a node index"``).
    coerce_floats : bool
        Accept a float with an integral value (``50.0``) as that integer. Otherwise it is refused
        with a hint: TOML and JSON read ``1e7`` and ``100.0`` as floats.

    Raises
    ------
    InputError
        ``"{where} must be {what} in low..high, got ..."`` (``(>= low)``, ``(<= high)`` for one
        bound), and for an integral float not coerced ``"..., got the float 1e7 (write it without
        a decimal point or exponent: 10000000)"``.
    """
    span = ("" if low is None and high is None else f" (>= {low})" if high is None
            else f" (<= {high})" if low is None else f" in {low}..{high}")
    if isinstance(value, (float, np.floating)) and value.is_integer():
        if not coerce_floats:
            raise InputError(f"{where} must be {what}{span}, got the float {show(value)} "
                             f"(write it without a decimal point or exponent: {int(value)})")
        value = int(value)
    if _is_bool(value) or not isinstance(value, (int, np.integer)):
        raise InputError(f"{where} must be {what}{span}, got {show(value)}")
    if (low is not None and value < low) or (high is not None and value > high):
        raise InputError(f"{where} must be {what}{span}, got {show(value)}")
    return int(value)


def iteration_limit(value: Any, where: str, *, coerce_floats: bool = False) -> int:
    """An iteration limit: an int in :data:`ITERATION_LIMIT` ``1..1e6`` (see :func:`integer`)."""
    return integer(value, where, low=ITERATION_LIMIT[0], high=ITERATION_LIMIT[1], coerce_floats=coerce_floats)


def boolean(value: Any, where: str) -> bool:
    """``value`` as a bool (a numpy bool included); otherwise ``"{where} must be true or false, got ..."``."""
    if not _is_bool(value):
        raise InputError(f"{where} must be true or false, got {show(value)}")
    return bool(value)


def one_of(value: Any, where: str, choices: Iterable[Any]) -> Any:
    """``value`` if it is one of ``choices`` (of the same type: ``True`` is not ``1``); otherwise
    ``"{where} must be one of 'a', 'b', got ..."``."""
    choices = tuple(choices)
    if not any(type(value) is type(c) and value == c for c in choices):
        raise InputError(f"{where} must be one of {', '.join(map(repr, choices))}, got {show(value)}")
    return value


def string(value: Any, where: str) -> str:
    """``value`` if it is a string; otherwise ``"{where} must be a string, got ..."``."""
    if not isinstance(value, str):
        raise InputError(f"{where} must be a string, got {show(value)}")
    return value


def nonempty_list(value: Any, where: str, *, nonempty: bool = True) -> list:
    """``value`` if it is a list (non-empty unless ``nonempty=False``); otherwise
    ``"{where} must be a non-empty list, got ..."``."""
    if not isinstance(value, list) or (nonempty and not value):
        raise InputError(f"{where} must be a {'non-empty ' if nonempty else ''}list, got {show(value)}")
    return value


def number_list(value: Any, where: str, *, integers: bool = False, nonempty: bool = False) -> tuple:
    """A list (tuple, 1-D array) of finite non-negative numbers, as a tuple.

    Parameters
    ----------
    integers : bool
        The entries must be integers (indices: below ``2**63``); floats are refused.
    nonempty : bool
        The list must have an entry.

    Raises
    ------
    InputError
        ``"{where} must be a [non-empty] list of finite non-negative numbers, got ..."`` (``of
        non-negative integers``).
    """
    what = "non-negative integers" if integers else "finite non-negative numbers"
    message = f"{where} must be a {'non-empty ' if nonempty else ''}list of {what}, got {show(value)}"
    if isinstance(value, np.ndarray) and value.ndim == 1:
        value = value.tolist()
    if not isinstance(value, (list, tuple)) or (nonempty and not value):
        raise InputError(message)
    if integers:
        if not all(not _is_bool(v) and isinstance(v, (int, np.integer)) and 0 <= v < 2**63 for v in value):
            raise InputError(message)
        return tuple(int(v) for v in value)
    out = tuple(_real(v) for v in value)
    if not all(v is not None and math.isfinite(v) and v >= 0 for v in out):
        raise InputError(message)
    return out


def table(value: Any, where: str) -> dict:
    """``value`` as a dict (a copy) if it is a mapping; otherwise ``"{where} must be a table, got ..."``."""
    if not isinstance(value, Mapping):
        raise InputError(f"{where} must be a table, got {show(value)}")
    return dict(value)


# -------------------------------------------------------------------------------------- dataclasses
@functools.cache
def _type_hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def check_typed(value: Any, hint: Any, where: str, *, name: str = "", coerce_floats: bool = False) -> Any:
    """``value`` checked against the resolved type ``hint`` and the name rules, normalised.

    Parameters
    ----------
    value : Any
        The value to check.
    hint : type
        A resolved type (:func:`typing.get_type_hints`): ``bool``, ``int``, ``float``, ``str``,
        ``tuple`` or ``tuple[X, ...]`` (a list of non-negative numbers, of integers for ``int``),
        ``dict`` or ``dict[K, V]`` (a table), ``Literal[...]`` (one of its values), ``Any``, or a
        union of these (``X | None``, ``Optional[X]``: ``None`` is accepted; otherwise the first
        member the value passes).
    where : str
        What the value is, for the message.
    name : str
        The field's name, for the name rules: an ``int`` named ``max_*`` is an iteration limit
        (:func:`iteration_limit`), other ``int`` fields are ``>= 0``; a ``float`` named ``*tol``
        is a tolerance (:func:`tolerance`).
    coerce_floats : bool
        Accept integral floats for ``int`` (see :func:`integer`).

    Returns
    -------
    Any
        The value, normalised: ``int``, ``float`` and ``bool`` as such, a list as a tuple, a
        table copied.

    Raises
    ------
    InputError
        The value does not fit (one line).
    TypeError
        ``hint`` is none of the above (a programming error).
    """
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is Union or origin is types.UnionType:
        if value is None and type(None) in args:
            return None
        members = [a for a in args if a is not type(None)]
        errors = []
        for member in members:
            try:
                return check_typed(value, member, where, name=name, coerce_floats=coerce_floats)
            except InputError as exc:
                errors.append(exc)
        raise errors[0]
    if origin is Literal:
        return one_of(value, where, args)
    if hint is Any:
        return value
    if hint is bool:
        return boolean(value, where)
    if hint is int:
        if name.startswith("max_"):
            return iteration_limit(value, where, coerce_floats=coerce_floats)
        return integer(value, where, low=0, coerce_floats=coerce_floats)
    if hint is float:
        return tolerance(value, where) if name.endswith("tol") else finite_number(value, where)
    if hint is str:
        return string(value, where)
    if hint is tuple or origin is tuple:
        return number_list(value, where, integers=bool(args) and args[0] is int)
    if hint is dict or origin is dict:
        return table(value, where)
    raise TypeError(f"cannot check {where}: unsupported type {hint!r}")


def _label(where: Where, name: str) -> str:
    return where(name) if callable(where) else f"{where} {name}"


def check_fields(cls: type, values: Mapping[str, Any], where: Where, *, rules: Mapping[str, Rule] | None = None,
                 coerce_floats: bool = False) -> dict[str, Any]:
    """Values for fields of the dataclass ``cls``, each checked by its resolved type hint
    (:func:`check_typed`) or by its own rule.

    Parameters
    ----------
    cls : type
        A dataclass.
    values : mapping of str to Any
        Field names and values (a subset of the fields).
    where : str or callable
        A prefix (``"[ddcm]"``: messages name ``"[ddcm] seed"``) or ``where(name) -> label``.
    rules : mapping of str to callable, optional
        ``rule(value, label) -> value`` for the fields whose type and name say too little (their
        own range, a registry of names); ``None`` passes without it where the hint allows ``None``.
    coerce_floats : bool
        Accept integral floats for ``int`` fields (see :func:`integer`).

    Returns
    -------
    dict
        The values, normalised.

    Raises
    ------
    InputError
        The first value that does not fit (one line naming it).
    TypeError
        A name that is not a field of ``cls``, or a field type :func:`check_typed` does not know.
    """
    hints = _type_hints(cls)
    rules = rules or {}
    out: dict[str, Any] = {}
    for name, value in values.items():
        if name not in hints:
            raise TypeError(f"{name!r} is not a field of {cls.__name__}")
        label, rule, hint = _label(where, name), rules.get(name), hints[name]
        if rule is None:
            out[name] = check_typed(value, hint, label, name=name, coerce_floats=coerce_floats)
        elif value is None and type(None) in typing.get_args(hint):
            out[name] = None  # the rule checks the values other than None that the hint allows
        else:
            out[name] = rule(value, label)
    return out


def check_dataclass(options: Any, where: Where, *, rules: Mapping[str, Rule] | None = None,
                    coerce_floats: bool = False) -> None:
    """Check every field of a (frozen) dataclass instance in place, and store the normalised values.

    Parameters
    ----------
    options : dataclass instance
        The options; frozen instances are updated with ``object.__setattr__``.
    where, rules, coerce_floats
        As for :func:`check_fields`.

    Raises
    ------
    InputError
        The first field whose value does not fit (one line naming it).
    """
    values = {f.name: getattr(options, f.name) for f in dataclasses.fields(options)}
    for name, value in check_fields(type(options), values, where, rules=rules, coerce_floats=coerce_floats).items():
        object.__setattr__(options, name, value)
