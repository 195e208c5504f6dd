"""The record of one verified claim, :class:`Check`, and the reports of a list of them.

Every rung of the verification ladder (:mod:`ddcm_casadi.validation.ladder`, :mod:`ddcm_casadi.validation.quality_rungs`,
:mod:`ddcm_casadi.validation.continuum`) returns checks: ``name``, ``quantity``, ``value``,
``reference``, ``tolerance`` and ``passed = |value - reference| <= tolerance``. Kept apart from the
ladder so that the rungs and the ladder that lists them import it, not each other.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np


@dataclass
class Check:
    """One verified claim."""

    name: str
    quantity: str
    value: float
    reference: float
    tolerance: float
    passed: bool
    note: str = ""

    @classmethod
    def make(cls, name: str, quantity: str, value: float, reference: float, tolerance: float,
             note: str = "") -> "Check":
        value, reference = float(value), float(reference)
        ok = bool(np.isfinite(value) and abs(value - reference) <= tolerance)
        return cls(name, quantity, value, reference, float(tolerance), ok, note)


def as_records(checks: list[Check]) -> list[dict]:
    """The checks as plain dicts (``validation.json``)."""
    return [asdict(c) for c in checks]


def markdown(checks: list[Check]) -> str:
    """The checks as a Markdown table, with their notes below (``validation.md``)."""
    passed = sum(c.passed for c in checks)
    lines = [f"# Validation: {passed}/{len(checks)} checks passed", "",
             "| case | quantity | value | reference | tolerance | passed |", "|---|---|---|---|---|---|"]
    for c in checks:
        tol = "inf" if math.isinf(c.tolerance) else f"{c.tolerance:.1e}"
        val = f"{c.value:.3g}" if abs(c.value) >= 1e-3 or c.value == 0 else f"{c.value:.2e}"
        lines.append(f"| {c.name} | {c.quantity} | {val} | {c.reference:g} | {tol} | "
                     f"{'yes' if c.passed else '**NO**'} |")
    notes = [c for c in checks if c.note]
    if notes:
        lines += ["", "Notes:", ""] + [f"- {c.name}, {c.quantity}: {c.note}" for c in notes]
    return "\n".join(lines) + "\n"


def fitted_rate(sizes, errors) -> tuple[float, float]:
    """``(slope, standard error)`` of the least-squares line through ``(log size, log error)``:
    an observed convergence rate, fitted rather than eyeballed."""
    x, y = np.log(np.asarray(sizes, float)), np.log(np.asarray(errors, float))
    slope, icpt = np.polyfit(x, y, 1)
    resid = y - (slope * x + icpt)
    se = float(np.sqrt(np.sum(resid**2) / max(x.size - 2, 1) / np.sum((x - x.mean()) ** 2)))
    return float(slope), se
