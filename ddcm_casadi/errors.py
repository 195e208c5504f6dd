"""Exceptions raised by ddcm-casadi."""

from __future__ import annotations

from typing import Any


class DDCMError(Exception):
    """Base class of every error raised on purpose by ddcm-casadi."""


class InputError(DDCMError, ValueError):
    """Bad user input: a one-line message naming the offending value."""


class ConvergenceError(DDCMError):
    """A solve did not converge and the caller asked to raise.

    Attributes
    ----------
    diagnostics : dict
        The per-step diagnostics of the failed solve (converged flag, iterations,
        residuals, complementarity error, ...).
    """

    def __init__(self, message: str, diagnostics: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.diagnostics = dict(diagnostics or {})


class PhysicsWarning(UserWarning):
    """Input that runs but is physically odd: an obstacle that starts inside the body, strains far
    beyond the small-strain model (:meth:`~ddcm_casadi.models.base.ContactModel.path_warnings`)."""


def one_line(message: object) -> str:
    """``message`` as a single line (an error message must not spill over several lines).

    Parameters
    ----------
    message : object
        An exception or any text.
    """
    return " ".join(line.strip() for line in str(message).splitlines() if line.strip())
