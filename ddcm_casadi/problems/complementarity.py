r"""The branches of complementarity pairs, their sign tests and B-stationarity (one place).

A pair ``g >= 0, p >= 0, g p = 0`` (gap and contact pressure) is on one of three pieces:

- ``FREE``: ``p = 0`` imposed, ``g >= 0`` left free;
- ``CONTACT``: ``g = 0`` imposed, ``p >= 0`` left free;
- ``BIACTIVE``: both imposed (``g = p = 0``, grazing contact; the corner of ``Z_E``).

On a fixed assignment of pieces the problem is smooth (for a linear model a QP or a linear
system); its solution is a solution of the complementarity problem when the free signs hold.
For a projection (``min f`` subject to the pairs) a solution with biactive pairs is a local
minimum only if it is optimal on every piece through it, i.e. *B-stationary*: with the
Lagrangian ``f + lam_g^T g + lam_p^T p`` of the imposed equalities, every biactive pair has
``lam_g <= 0`` and ``lam_p <= 0`` (a positive multiplier means that opening the pair lowers
``f``). The exact enumeration (:mod:`ddcm_casadi.problems.exact`), the MPCC branch NLP
(:mod:`ddcm_casadi.formulations.mpcc`) and the active-set corner polish
(:mod:`ddcm_casadi.loops.active_set`) all use these functions, with this sign convention.
"""

from __future__ import annotations

import numpy as np

FREE, CONTACT, BIACTIVE = 0, 1, 2


def identify(gap: np.ndarray, pressure: np.ndarray, *, biactive_tol: float = -1.0) -> np.ndarray:
    """The piece each pair lies on: ``CONTACT`` where ``g <= p``, else ``FREE``; ``BIACTIVE``
    where both ``|g|`` and ``|p|`` are within ``biactive_tol`` (negative: never)."""
    gap, pressure = np.asarray(gap, float), np.asarray(pressure, float)
    part = np.where(gap <= pressure, CONTACT, FREE)
    near = (np.abs(gap) <= biactive_tol) & (np.abs(pressure) <= biactive_tol)
    return np.where(near, BIACTIVE, part)


def imposes_gap(partition: np.ndarray) -> np.ndarray:
    """Pairs whose piece imposes ``g = 0``."""
    return np.asarray(partition) != FREE


def imposes_pressure(partition: np.ndarray) -> np.ndarray:
    """Pairs whose piece imposes ``p = 0``."""
    return np.asarray(partition) != CONTACT


def free_sign(gap: np.ndarray, pressure: np.ndarray, on_gap: np.ndarray) -> np.ndarray:
    """The sign each single piece leaves free: ``p`` where ``g = 0`` is imposed, else ``g``."""
    return np.where(on_gap, pressure, gap)


def signs_hold(gap: np.ndarray, pressure: np.ndarray, tol: float) -> bool:
    """``g >= -tol`` and ``p >= -tol`` for every pair."""
    return bool(np.all(np.asarray(gap) >= -tol) and np.all(np.asarray(pressure) >= -tol))


def b_stationarity(gap_multiplier: np.ndarray, pressure_multiplier: np.ndarray, biactive: np.ndarray, *,
                   rel_tol: float = 1e-8) -> tuple[np.ndarray, np.ndarray]:
    """The biactive pairs that break B-stationarity: ``(wrong_gap, wrong_pressure)``.

    ``wrong_gap``: ``lam_g > tol`` (the gap wants to open), ``wrong_pressure``: ``lam_p > tol``
    (the pressure does); where both are positive the larger decides, so that a caller leaving
    the corner knows along which piece. ``tol = rel_tol max(1, max |lam|)`` over
    every pair (multipliers carry the roundoff of the largest). The point is
    B-stationary when neither array has a true entry.
    """
    lg, lp = np.asarray(gap_multiplier, float), np.asarray(pressure_multiplier, float)
    on = np.asarray(biactive, bool)
    tol = rel_tol * max(1.0, float(np.max(np.abs(np.concatenate([lg, lp])), initial=0.0)))
    wrong_gap = on & (lg > tol) & (lg >= lp)
    wrong_pressure = on & (lp > tol) & ~wrong_gap
    return wrong_gap, wrong_pressure
