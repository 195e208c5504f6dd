"""Automatic step bisection along a load path, shared by both drivers (the classical steps of
:mod:`~ddcm_casadi.drivers.path` and the DDCM loop of :mod:`~ddcm_casadi.drivers.ddcm`).

A load step ``k`` that fails (its solver did not converge, its values are not finite, or a check
after the solve rejected it: the physical checks, an unstable equilibrium) is retried in
sub-steps. The sub-step at the fraction ``t`` of step ``k`` solves the problem whose parameters
are interpolated (:func:`interpolate`) between the last converged step (``t = 0``) and step ``k``
(``t = 1``):

- the **load entries** (the model's :meth:`~ddcm_casadi.models.base.ContactModel.load_names`:
  the obstacle offsets ``gap0`` and the loads ``f``, :data:`LOAD_ENTRIES`, and any a model kind
  adds, such as an obstacle's travel; linear in the load) go linearly from those of the last
  converged step to those of step ``k``;
- every other entry is the target's: the history a model's step takes from the last converged
  step (:meth:`~ddcm_casadi.models.base.ContactModel.step_values`, ``previous``) stays that of the
  last converged *step* through the sub-steps, and the DDCM data entries ``strain_star`` and
  ``stress_star`` are the current assignment.

Before the first converged step the start is the **unloaded** state (:func:`unloaded`): no loads
(``f = 0``), the obstacles at the first step's offsets drawn back to at most touching the
undeformed body (``gap0 = max(gap0, 0)``), any other load entry a model declares zero. With the
gaps ``G u + gap0`` (every model with affine gaps, small or finite kinematics), the reference
configuration, ``u = 0`` with no contact pressure, is an exact equilibrium of that problem (the
internal forces vanish at ``u = 0``), so step 0 is bisected like any other: an obstacle that
starts inside the body moves in linearly from touching. Where the reference configuration
penetrates an obstacle at that start (gaps at the current configuration that depend on an
obstacle's travel), the steps before the first converged one have no clean start and are not
bisected (:func:`unloaded_start`); bisection then starts from the first converged step.

:func:`bisect` walks the fractions: after the full step failed it tries ``t = 1/2`` from the last
converged sub-state, halves the increment on every failure, warm-starts each sub-step from the
previous converged one, doubles the increment after each success (capped at the largest power of
two within what remains, so that every sub-step is a power-of-two fraction of the step) and
stops when ``t = 1`` is reached, or when the next halving would go below ``min_substep``
(:func:`check_min_substep`). Every sub-step gets the checks a step gets, at its own load.

``min_substep``, a fraction of one load step, is the top-level key ``min_substep`` of a case file
(``--set min_substep=0.25``), ``compare(..., min_substep=)``, ``solve_classical(...,
min_substep=)`` and ``DDCMSolver(..., min_substep=)``; the default is :data:`DEFAULT_MIN_SUBSTEP`
(1/16), and ``0`` or ``1`` (no sub-step smaller than the whole step) turns bisection off.

What is reported (:class:`~ddcm_casadi.drivers.records.StepResult`): a step reached through
sub-steps is converged, with ``substeps`` and ``smallest_substep`` and the message ``... reached
in 5 sub-steps (smallest 1/8)``; its iterations, projections and seconds are the totals over every
attempt, the failed ones included. A step that fails at the minimum is reported as its full
step's attempt, not converged, as without bisection, its message saying the smallest fraction
tried and how far the sub-steps got; the next step starts where it would have without bisection.
Bisection cannot cross a limit point under load control (a snap-through): a step past it stays
not converged, or is rejected as an unstable equilibrium, at every fraction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Callable, Generic, Iterable, TypeVar

import numpy as np

from ddcm_casadi import inputs as check
from ddcm_casadi.errors import InputError
from ddcm_casadi.problems.parameters import Parameters
from ddcm_casadi.drivers.records import StepResult

#: The entries of a problem's parameters that are linear in the load in every model: the obstacle
#: offsets and the external loads (a model kind may add more:
#: :meth:`~ddcm_casadi.models.base.ContactModel.load_names`). Every other entry (history, data) is
#: not interpolated.
LOAD_ENTRIES = ("gap0", "f")

#: The default smallest sub-step, as a fraction of one load step: four halvings (1/2, 1/4, 1/8,
#: 1/16): a step none of whose sub-steps converges costs four solves beyond its full step (more
#: when some converge on the way). Measured on ``examples/cases/von_mises.toml`` (README):
#: every step that sub-steps reach is reached with sub-steps of 1/4 at the smallest, and minima of
#: 1/8 down to 1/256 reach no further step (what still fails is the snap-through, a limit point
#: that no sub-step crosses under load control) while the failing runs' time grows with each
#: halving; 1/16 keeps two halvings of margin over what was needed.
DEFAULT_MIN_SUBSTEP = 1.0 / 16.0

#: The smallest positive ``min_substep`` accepted: 2**-20, about a million sub-steps per step.
#: Below it a step could cost millions of solves; ``0`` turns bisection off.
MIN_SUBSTEP_FLOOR = 2.0 ** -20

S = TypeVar("S")


def check_min_substep(value: object, where: str = "min_substep") -> float:
    """``min_substep`` checked: ``0`` (bisection off), or a fraction of one load step in
    ``[2**-20, 1]`` (``1``: no sub-step smaller than the whole step, so bisection is off too; any
    value above ``1/2`` admits no halving).

    Raises
    ------
    InputError
        One line naming ``where``: not a number, outside ``[0, 1]``, or positive below ``2**-20``.
    """
    v = check.in_range(value, where, 0.0, 1.0, why=" (a fraction of one load step; 0 or 1 turns bisection off)")
    if 0.0 < v < MIN_SUBSTEP_FLOOR:
        raise InputError(f"{where} = {v:g} is below 2**-20 (about a million sub-steps per step); "
                         f"use 0 to turn bisection off")
    return v


def bisection_enabled(min_substep: float) -> bool:
    """Whether a failed step is bisected at all: ``min_substep`` admits a half step."""
    return 0.0 < min_substep <= 0.5


def fraction_text(t: float) -> str:
    """A fraction of a load step as text: ``1/8`` for the dyadic fractions bisection makes,
    ``0.3`` otherwise."""
    f = Fraction(t).limit_denominator(1 << 30)
    if f == t and f.denominator <= 1 << 30:
        return str(f.numerator) if f.denominator == 1 else f"{f.numerator}/{f.denominator}"
    return f"{t:.3g}"


def unloaded(parameters: Parameters, target: np.ndarray, names: Iterable[str] = LOAD_ENTRIES) -> np.ndarray:
    """The parameters at load fraction 0 before any converged step: ``target`` (the first step's
    parameters) with no loads, ``f = 0``, the obstacle offsets drawn back to at most touching the
    undeformed body, ``gap0 = max(gap0, 0)``, and any other load entry of ``names`` (a model's
    :meth:`~ddcm_casadi.models.base.ContactModel.load_names`, e.g. an obstacle's travel) zero;
    every other entry as in ``target``.

    With affine gaps ``G u + gap0`` the undeformed body, ``u = 0`` with no contact pressure, is
    an exact equilibrium there. A model whose gaps depend on another load entry (the travel of
    an exact gap at the current configuration) may still penetrate at zero travel: the drivers
    check (:meth:`~ddcm_casadi.problems.contract.ComplementarityProblem.penetrates`) and do not
    bisect a first step that has no such start.
    """
    out = np.array(target, dtype=float, copy=True)
    for name in names:
        if name not in parameters.names:
            continue
        sl = parameters.slice(name)
        out[sl] = np.maximum(out[sl], 0.0) if name == "gap0" else 0.0
    return out


def unloaded_start(problem, target: np.ndarray, names: Iterable[str] = LOAD_ENTRIES) -> np.ndarray | None:
    """:func:`unloaded` for a problem, or ``None`` when the undeformed body penetrates an
    obstacle there (no clean start: the step is not bisected).

    Parameters
    ----------
    problem : ComplementarityProblem
        The classical problem or the projection (its parameters and gaps).
    target : ndarray
        The packed parameters of the step.
    names : iterable of str
        The model's load entries.
    """
    start = unloaded(problem.parameters, target, names)
    return None if problem.penetrates(np.zeros(problem.n_x), start) else start


def interpolate(parameters: Parameters, start: np.ndarray, target: np.ndarray, t: float,
                names: Iterable[str] = LOAD_ENTRIES) -> np.ndarray:
    """The parameters of the sub-step at the fraction ``t`` of a load step.

    Parameters
    ----------
    parameters : Parameters
        The names and layout of the packed vectors (a problem's, or a formulation's extension).
    start : ndarray
        A packed vector at fraction 0 (the last converged step's, or :func:`unloaded`); only its
        load entries are read.
    target : ndarray
        The packed vector of the step (fraction 1), with the history and data entries to use.
    t : float
        The fraction, in ``[0, 1]``.
    names : iterable of str
        The entries interpolated: the model's
        :meth:`~ddcm_casadi.models.base.ContactModel.load_names` (default :data:`LOAD_ENTRIES`,
        those of every model; names the parameters lack are skipped).

    Returns
    -------
    ndarray
        A new vector: ``start + t (target - start)`` on the load entries (exactly ``start`` at
        ``t = 0``), ``target`` everywhere else, and exactly ``target`` at ``t = 1``.
    """
    out = np.array(target, dtype=float, copy=True)
    if t == 1.0:
        return out
    start = np.asarray(start, dtype=float)
    for name in names:
        if name in parameters.names:
            sl = parameters.slice(name)
            out[sl] = start[sl] + t * (out[sl] - start[sl])
    return out


@dataclass
class Bisection(Generic[S]):
    """What :func:`bisect` did.

    Attributes
    ----------
    converged : bool
        The step's fraction 1 was reached.
    state : object
        The last converged sub-state (the step's, when converged).
    reached : float
        The fraction of the step reached.
    substeps : int
        Sub-steps that converged.
    smallest : float
        The smallest fraction used by a converged sub-step if ``converged``, else the smallest
        fraction tried.
    attempts : list of tuple
        ``(t_from, t_to, ok)`` of every sub-step tried, in order.
    """

    converged: bool
    state: S
    reached: float
    substeps: int
    smallest: float
    attempts: list[tuple[float, float, bool]] = field(default_factory=list)

    def message(self) -> str:
        """What the bisection did, to append to the step's message."""
        steps = f"{self.substeps} sub-step{'' if self.substeps == 1 else 's'}"
        if self.converged:
            return f"reached in {steps} (smallest {fraction_text(self.smallest)})"
        return (f"bisection failed down to a fraction of {fraction_text(self.smallest)} of the step "
                f"(smallest fraction tried; reached {fraction_text(self.reached)} in {steps})")


def bisect(attempt: Callable[[float, float, S], tuple[bool, S]], start: S, min_substep: float, *,
           increment: float = 0.5) -> Bisection[S]:
    """Advance through sub-steps of one load step from fraction 0 to 1.

    Parameters
    ----------
    attempt : callable
        ``attempt(t_from, t_to, state) -> (ok, new_state)``: solve the sub-step at the fraction
        ``t_to`` warm-started from ``state``, the converged sub-state at ``t_from``; ``ok`` is False
        for any failure (not converged, non-finite, rejected by a check).
    start : object
        The converged sub-state at fraction 0.
    min_substep : float
        The smallest increment tried (:func:`check_min_substep`); an increment whose half is
        below it is not halved again.
    increment : float
        The first increment, a power of two (``1/2``: the driver has tried the full step).

    Returns
    -------
    Bisection
        Converged or not, the last converged sub-state and what was tried.
    """
    t, dt, state = 0.0, float(increment), start
    out = Bisection(converged=False, state=start, reached=0.0, substeps=0, smallest=1.0)
    used, tried = 1.0, 1.0
    while dt >= min_substep and dt > 0.0:
        # the largest power of two within the increment and what remains: the increments stay
        # powers of two, so what remains is a multiple of the smallest one used (never below it)
        dt = math.ldexp(0.5, math.frexp(min(dt, 1.0 - t))[1])
        t_to = 1.0 if dt == 1.0 - t else t + dt
        ok, new = attempt(t, t_to, state)
        out.attempts.append((t, t_to, ok))
        tried = min(tried, dt)
        if ok:
            t, state = t_to, new
            out.substeps += 1
            used = min(used, dt)
            if t >= 1.0:
                out.converged = True
                break
            dt *= 2.0
        else:
            dt *= 0.5
    out.state, out.reached = state, t
    out.smallest = used if out.converged else tried
    return out


#: The costs of a step that add up over its sub-steps (and its failed attempts).
_COSTS = ("iterations", "outer_iterations", "projections", "runs", "improvements",
          "projection_seconds", "search_seconds")


def add_costs(step: StepResult, others: Iterable[StepResult]) -> None:
    """Add the iterations, projections and seconds of ``others`` (the other attempts of a step:
    its failed full step, its sub-steps) to ``step``, in place."""
    for other in others:
        if other is step:
            continue
        for name in _COSTS:
            setattr(step, name, getattr(step, name) + getattr(other, name))


def finish_bisected(step: StepResult, bisection: Bisection, others: Iterable[StepResult]) -> StepResult:
    """The record of a bisected step, in place: ``step`` (the last sub-step if the bisection
    converged, else the full step's failed attempt) with the costs of ``others`` added, its
    sub-steps and smallest fraction, and what the bisection did appended to its message."""
    add_costs(step, others)
    step.substeps, step.smallest_substep = bisection.substeps, bisection.smallest
    if not bisection.converged:
        step.converged = False
    step.message = f"{step.message}; {bisection.message()}" if step.message else bisection.message()
    return step


def accepted(step: StepResult, *arrays: np.ndarray) -> bool:
    """Whether an attempt is a converged sub-state to go on from: the step converged (its checks
    passed) and ``arrays`` (the solver's unknowns) are finite."""
    return bool(step.converged) and all(np.all(np.isfinite(a)) for a in arrays)


__all__ = ["Bisection", "DEFAULT_MIN_SUBSTEP", "LOAD_ENTRIES", "MIN_SUBSTEP_FLOOR", "accepted", "add_costs",
           "bisect", "bisection_enabled", "check_min_substep", "finish_bisected", "fraction_text",
           "interpolate", "unloaded", "unloaded_start"]
