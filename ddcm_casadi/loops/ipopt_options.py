"""IPOPT options passed through from users: checked once, before any work, with IPOPT's own reason.

IPOPT reports a bad option (an unknown name, a value out of range, a linear solver that is not
installed) only when the solver is created or first run, and then on the C-level standard output
with a generic exception in Python. :func:`check_ipopt_options` creates and runs a one-variable NLP
with the options, captures that output and turns it into one line naming the option and, where
IPOPT gives it, the valid range or settings.

After a solve, :func:`ipopt_stats` reads IPOPT's statistics (turning a Ctrl-C caught inside IPOPT
back into ``KeyboardInterrupt``) and :func:`iteration_count` its iterations.
"""

from __future__ import annotations

import io
import os
import re
import sys
import tempfile
from contextlib import contextmanager, redirect_stdout
from typing import Any, Iterator, Mapping

import casadi as ca

from ddcm_casadi.errors import InputError

#: Statuses with which IPOPT stops before its first iteration (the iteration count is then undefined).
FAILED_TO_START = frozenset({"Invalid_Option", "Invalid_Problem_Definition", "Not_Enough_Degrees_Of_Freedom",
                             "Unrecoverable_Exception", "NonIpopt_Exception_Thrown", "Insufficient_Memory",
                             "Internal_Error"})

#: Lower bounds that IPOPT itself does not impose but without which no solve can converge.
_AT_LEAST = {"max_iter": 1}


@contextmanager
def _captured_stdout() -> Iterator[list[str]]:
    """Capture what IPOPT prints (its option errors): CasADi's Python build sends it to
    ``sys.stdout``, other builds to file descriptor 1; both are captured."""
    lines: list[str] = []
    sys.stdout.flush()
    saved = os.dup(1)
    text = io.StringIO()
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        try:
            os.dup2(tmp.fileno(), 1)
            with redirect_stdout(text):
                yield lines
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)
            tmp.seek(0)
            lines.extend(text.getvalue().splitlines())
            lines.extend(tmp.read().decode(errors="replace").splitlines())


def _reason(lines: list[str], fallback: str) -> str:
    """IPOPT's explanation in its printed output: the offending setting and its valid range."""
    text = [ln.strip() for ln in lines if ln.strip()]
    for i, ln in enumerate(text):
        m = re.match(r'Setting: "(.*)" is not a valid setting for Option: (\w+)', ln)
        if m:
            detail = ""
            for follow in text[i + 1:i + 8]:
                if "<=" in follow or "<" in follow:
                    detail = f" (valid: {follow.replace('(', 'default ').replace(')', '')})"
                    break
                if follow.startswith("Valid Settings"):
                    settings = [s.split()[0] for s in text[text.index(follow) + 1:] if not s.startswith("Default")
                                and not s.startswith("###")][:12]
                    detail = f" (valid: {', '.join(settings)})"
                    break
            return f"{m.group(2)} = {m.group(1)!r} is not a valid setting{detail}"
        if ln.startswith("Exception message:"):
            return ln.split(":", 1)[1].strip()
        if ln.startswith("EXIT:"):
            return ln.split(":", 1)[1].strip()
    return fallback


def check_ipopt_options(owner: str, options: Mapping[str, Any]) -> None:
    """Refuse IPOPT options that IPOPT would reject, with IPOPT's reason in one line.

    Parameters
    ----------
    owner : str
        Where the options come from, for the message (e.g. ``"formulation 'mpcc'"``).
    options : mapping
        The user's IPOPT options (merged over the formulation's defaults by the caller).

    Raises
    ------
    InputError
        An unknown option, a value of the wrong type or out of IPOPT's range, a value below
        :data:`_AT_LEAST` (``max_iter = 0`` cannot converge), or options with which IPOPT cannot
        start (e.g. a linear solver that is not installed).
    """
    if not isinstance(options, Mapping):
        raise InputError(f"{owner}: option 'ipopt' must be a table of IPOPT options, got {type(options).__name__}")
    for key, value in options.items():
        if not isinstance(key, str):
            raise InputError(f"{owner}: IPOPT option names must be strings, got {key!r}")
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise InputError(f"{owner}: IPOPT option {key!r} must be a number or a string, got {value!r}")
        low = _AT_LEAST.get(key)
        if low is not None and isinstance(value, (int, float)) and value < low:
            raise InputError(f"{owner}: IPOPT option {key!r} must be at least {low}, got {value!r}")
    status, error, lines = _probe(options)
    if error is not None and len(options) > 1:
        # Name the culprit: probe the options one at a time (cheap: a one-variable NLP).
        for key in options:
            single = _probe({key: options[key]})
            if single[1] is not None:
                status, error, lines = single
                options = {key: options[key]}
                break
    if error is not None:
        m = re.search(r"No such IPOPT option: (\S+)", error)
        if m:
            raise InputError(f"{owner}: no such IPOPT option {m.group(1)!r}")
        if "type mismatch" in error:
            (key, value), = options.items() if len(options) == 1 else (("?", "?"),)
            raise InputError(f"{owner}: IPOPT option {key!r} has a value of the wrong type, got {value!r}")
        raise InputError(f"{owner}: invalid IPOPT options: {_reason(lines, error)}")
    if status in FAILED_TO_START:
        raise InputError(f"{owner}: IPOPT cannot start with these options: {_reason(lines, status)}")


def _probe(options: Mapping[str, Any]) -> tuple[str | None, str | None, list[str]]:
    """Create and run a one-variable NLP with ``options``: ``(status, error, printed lines)``."""
    x = ca.SX.sym("x")
    # IPOPT prints why it cannot start only at print level >= 1; the output is captured anyway.
    merged = {"sb": "yes", **dict(options), "print_level": 1}
    with _captured_stdout() as lines:
        try:
            probe = ca.nlpsol("ipopt_options", "ipopt", {"x": x, "f": (x - 1) ** 2},
                              {"ipopt": merged, "print_time": False, "error_on_fail": False})
            probe(x0=0.0)
            status, error = probe.stats()["return_status"], None
        except RuntimeError as exc:
            status, error = None, str(exc).strip().splitlines()[-1]
    return status, error, lines


def iteration_count(stats: Mapping[str, Any]) -> int:
    """IPOPT's iteration count from ``nlpsol.stats()``, 0 when it failed before its first iteration
    (the count is then uninitialised memory, e.g. 3728794826)."""
    if stats.get("return_status") in FAILED_TO_START:
        return 0
    return int(stats.get("iter_count", 0))


#: How IPOPT ends when Ctrl-C arrives during a solve: CasADi catches the KeyboardInterrupt that
#: Python's SIGINT handler raises inside IPOPT's callbacks and hands IPOPT an exception (from an
#: evaluation: NonIpopt_Exception_Thrown) or a stop request (User_Requested_Stop; the package sets
#: no iteration callback that could ask for one).
INTERRUPTED = frozenset({"User_Requested_Stop", "NonIpopt_Exception_Thrown"})


def ipopt_stats(solver: Any) -> dict:
    """``solver.stats()`` after an IPOPT solve (``solver`` a CasADi ``nlpsol`` Function).

    Raises
    ------
    KeyboardInterrupt
        IPOPT stopped on Ctrl-C (:data:`INTERRUPTED`): read as one failed solve, the interrupt
        would be lost and the run would go on.
    """
    stats = solver.stats()
    if stats.get("return_status") in INTERRUPTED:
        raise KeyboardInterrupt
    return stats
