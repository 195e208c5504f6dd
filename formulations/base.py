"""What every contact formulation shares: options, the local-solution record and the metrics.

A formulation is a named transformation of the complementarity pairs ``g(x) >= 0, p >= 0, g p = 0``
of a :class:`~ddcm_casadi.problems.contract.ComplementarityProblem` into something a solver can take. It is
built once per problem (:meth:`Formulation.build`) and then solved many times with new parameters.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ddcm_casadi.errors import InputError
from ddcm_casadi.inputs import check_dataclass, positive
from ddcm_casadi.problems.contract import ComplementarityProblem

from .pairs import NewtonSystem


@dataclass
class LocalSolution:
    """One solve of a classical step or of one ``Z_E`` projection (scaled unknowns).

    Attributes
    ----------
    x, p : ndarray
        Scaled smooth unknowns and contact pressures.
    converged : bool
    iterations : int
        Inner iterations (Newton steps, or IPOPT iterations).
    outer_iterations : int
        Uzawa updates or homotopy steps (0 where there are none).
    residual : float
        ``||F||_inf`` (mcp) or ``||h||_inf`` (mpcc), scaled.
    complementarity : float
        ``max |min(g, p)|``, scaled; with friction the largest natural-map residual of Coulomb's
        law (:meth:`~ddcm_casadi.problems.contract.ComplementarityProblem.coulomb_residual`).
    penetration : float
        ``max(0, -g)`` over the normal gaps, scaled.
    objective : float
        Scaled objective (mpcc) or ``nan``.
    state : dict
        Formulation-specific warm-start data (multipliers).
    """

    x: np.ndarray
    p: np.ndarray
    converged: bool
    iterations: int
    outer_iterations: int
    residual: float
    complementarity: float
    penetration: float
    objective: float
    state: dict = field(default_factory=dict)
    message: str = ""


class Metrics:
    """Residual, gap and objective evaluation for one problem
    (:meth:`~ddcm_casadi.problems.contract.ComplementarityProblem.evaluate`: sparse products, nothing built).

    The residual is relative to the terms that cancel in it
    (:meth:`~ddcm_casadi.problems.contract.ComplementarityProblem.relative_residual`).
    """

    def __init__(self, problem: ComplementarityProblem) -> None:
        self._problem = problem

    def __call__(self, x, p, params) -> tuple[float, float, float, float]:
        res, terms, gap, obj = self._problem.evaluate(x, p, params)
        problem = self._problem
        p = np.asarray(p, dtype=float).ravel()
        residual = problem.relative_residual(res, terms)
        if not gap.size:
            return residual, 0.0, 0.0, obj
        if problem.frictional:
            comp = float(np.max(np.abs(problem.coulomb_residual(gap, p, params))))
        else:
            comp = float(np.max(np.abs(np.minimum(gap, p))))
        pen = float(np.max(np.maximum(0.0, -problem.normal(gap))))
        return residual, comp, pen, obj


class Formulation(ABC):
    """Base class of the registered contact formulations.

    Subclasses define a frozen ``Options`` dataclass (documented fields, with their formula) and
    implement :meth:`build`. Options are keyword-only and copied; unknown names are rejected.
    """

    name: ClassVar[str]
    title: ClassVar[str]
    exact: ClassVar[bool] = True
    #: The contact laws (:mod:`ddcm_casadi.models.contact_laws`) and model kinematics this formulation
    #: enforces; :meth:`check_supports` refuses the others.
    supported_contact_laws: ClassVar[frozenset] = frozenset({"signorini"})
    supported_kinematics: ClassVar[frozenset] = frozenset({"small", "finite"})

    @dataclass(frozen=True)
    class Options:
        pass

    def __init__(self, **options: Any) -> None:
        known = {f.name for f in dataclasses.fields(self.Options)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise InputError(f"unknown option {unknown[0]!r} for formulation {self.name!r}; "
                             f"known: {', '.join(sorted(known)) or 'none'}")
        self.options = self.Options(**{k: (tuple(v) if isinstance(v, list) else
                                             dict(v) if isinstance(v, dict) else v) for k, v in options.items()})
        self._validate()

    def _validate(self) -> None:
        """Check every option by its type and name (:func:`ddcm_casadi.inputs.check_dataclass`:
        ``max_*`` an iteration limit, ``*tol`` a tolerance, other ints ``>= 0``, integral floats
        accepted for ints); subclasses add their own rules after this."""
        check_dataclass(self.options, lambda name: option_label(self.name, name), coerce_floats=True)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.options})"

    def penalty_stiffness(self, problem: ComplementarityProblem) -> float | None:
        """The physical penalty stiffness (Pa/m) this formulation regularises contact with, or
        ``None`` if it enforces the pairs exactly (then results are compared with the exact
        solution)."""
        return None

    def resolved_options(self, problem: ComplementarityProblem | None) -> dict:
        """The options with their problem-dependent defaults resolved (for ``results.json``)."""
        return dict(vars(self.options))

    def refusal(self, problem: ComplementarityProblem) -> str:
        """Why this formulation cannot enforce ``problem``'s pairs (one line), or ``""``."""
        if problem.contact_law not in self.supported_contact_laws:
            return (f"formulation {self.name!r} does not support the contact law {problem.contact_law!r} "
                    f"(it supports: {', '.join(sorted(self.supported_contact_laws))})")
        if problem.frictional and problem.kinematics != "small":
            return f"Coulomb friction needs small kinematics (the problem has {problem.kinematics} kinematics)"
        if problem.kinematics not in self.supported_kinematics:
            return (f"formulation {self.name!r} does not support {problem.kinematics} kinematics "
                    f"(it supports: {', '.join(sorted(self.supported_kinematics))})")
        return ""

    def check_supports(self, problem: ComplementarityProblem) -> None:
        """Raise a one-line :class:`InputError` if :meth:`refusal` has a reason (call it before any work)."""
        reason = self.refusal(problem)
        if reason:
            raise InputError(reason)

    def build(self, problem: ComplementarityProblem) -> "BuiltFormulation":
        """Build the CasADi objects for ``problem`` once (after :meth:`check_supports`); returns
        an object with ``solve``."""
        self.check_supports(problem)
        return self._build(problem)

    @abstractmethod
    def _build(self, problem: ComplementarityProblem) -> "BuiltFormulation":
        """The formulation's own build for a supported ``problem``."""


class BuiltFormulation(ABC):
    """A formulation built for one problem: ``solve`` may be called many times.

    ``penalty_stiffness`` is the physical ``gamma`` (Pa/m) of a formulation that regularises contact
    (:meth:`Formulation.penalty_stiffness`), ``None`` for an exact one: the drivers' physical check
    then allows its penetration ``p / gamma``.
    """

    penalty_stiffness: float | None = None

    def __init__(self, problem: ComplementarityProblem) -> None:
        self.problem = problem
        self.metrics = Metrics(problem)

    def reset(self) -> None:
        """Forget caches (factorisations) and counters, for cold-start measurements."""

    @property
    def stats(self) -> dict:
        """Solver counters (e.g. ``predicted`` and ``newton`` projections), if the solver keeps any."""
        return {}

    def newton_system(self) -> "NewtonSystem | None":
        """The Newton system this formulation solves (:class:`~ddcm_casadi.formulations.pairs.NewtonSystem`:
        matrix, residual, unknowns and parameters by name), or ``None`` where a solver other than
        Newton drives it (IPOPT)."""
        return None

    def newton_point(self, params: np.ndarray, x: np.ndarray, p: np.ndarray,
                     state: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(z, P)`` of :meth:`newton_system` at the problem's parameter values ``params`` and the
        scaled point ``(x, p)`` (warm multipliers from ``state``), the formulation's own parameters
        at the values a solve starts from."""
        raise NotImplementedError(f"{type(self).__name__} publishes no Newton system")

    @abstractmethod
    def solve(self, params: np.ndarray, x0: np.ndarray, p0: np.ndarray,
              state: dict | None = None) -> LocalSolution:
        """Solve for ``params`` from the start ``(x0, p0)`` (scaled), with optional warm-start state."""

    def _finish(self, x, p, params, *, converged, iterations, outer=0, state=None, message="") -> LocalSolution:
        residual, comp, pen, obj = self.metrics(x, p, params)
        return LocalSolution(x=np.asarray(x, float), p=np.asarray(p, float), converged=bool(converged),
                             iterations=int(iterations), outer_iterations=int(outer), residual=residual,
                             complementarity=comp, penetration=pen,
                             objective=obj if self.problem.kind == "mpcc" else float("nan"),
                             state=dict(state or {}), message=message)


def option_label(formulation: str, name: str) -> str:
    """How messages name option ``name`` of ``formulation``: ``"option 'tol' of 'penalty'"``."""
    return f"option {name!r} of {formulation!r}"


def positive_option(formulation: str, name: str, value: float | None) -> None:
    """Refuse ``value`` unless it is ``None`` or a finite number > 0 (:func:`ddcm_casadi.inputs.positive`)."""
    if value is not None:
        positive(value, option_label(formulation, name))
